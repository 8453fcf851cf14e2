//! Bad input never panics: streams of arbitrary, well-framed packets (any HELLO scales, NaN
//! included; arbitrary samples; keys from the keypad's alphabet and beyond) go through
//! acquisition and reconstruction; every glb written holds only finite numbers.

mod common;

use device_protocol::*;
use proptest::prelude::*;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs_geometry::network::{NetworkParams, Reconstructor};

fn packet() -> impl Strategy<Value = Packet> {
    let v3 = any::<[i16; 3]>();
    prop_oneof![
        1 => (any::<u8>(), any::<u32>(), any::<u32>(), any::<u32>(), any::<u32>(), any::<u32>()).prop_map(|(k, a, g, m, t, c)| {
            Packet::Hello(Hello {
                proto: 1,
                kind: DeviceKind::from_code(k % 4),
                device_id: 1,
                firmware: 1,
                rate_hz: 100,
                acc_scale: f32::from_bits(a),
                gyro_scale: f32::from_bits(g),
                mag_scale: f32::from_bits(m),
                ticks_per_rev: t % 5000,
                wheel_circumference_um: c,
                sensors: 3,
            })
        }),
        1 => Just(Packet::Hello(Hello {
            proto: 1,
            kind: DeviceKind::Morphorider,
            device_id: 1,
            firmware: 1,
            rate_hz: 100,
            acc_scale: 0.0024,
            gyro_scale: 0.001,
            mag_scale: 0.15,
            ticks_per_rev: 1024,
            wheel_circumference_um: 100_000,
            sensors: 1,
        })),
        30 => (any::<u32>(), v3, v3, any::<i32>()).prop_map(|(t, acc, mag, wheel)| Packet::RiderSample(RiderSample { t_us: t, acc, mag, wheel })),
        10 => (any::<u32>(), v3, v3, v3).prop_map(|(t, acc, gyro, mag)| Packet::PhoneSample(PhoneSample { t_us: t, acc, gyro, mag })),
        5 => (any::<u32>(), 0u16..4, v3, v3).prop_map(|(t, sensor, acc, mag)| Packet::ArraySample(ArraySample { t_us: t, sensor, acc, mag })),
        10 => (any::<u32>(), prop::sample::select(b"BI0123456789\nUCEX".to_vec())).prop_map(|(t, key)| Packet::Key(Key { t_us: t, key })),
        2 => (any::<u32>(), any::<u16>(), any::<u32>()).prop_map(|(t, segment, length_um)| Packet::SegmentLength(SegmentLength { t_us: t, segment, length_um })),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_packets_never_panic_and_outputs_stay_finite(packets in prop::collection::vec(packet(), 0..600)) {
        let mut wire = Vec::new();
        for (i, p) in packets.iter().enumerate() {
            p.encode(i as u8, &mut wire);
        }
        let mut dec = Decoder::new();
        let mut acq = Acquisition::new(AcquisitionConfig::default());
        for e in dec.feed(&wire) {
            acq.event(&e);
        }
        let scan = acq.finish();
        for c in &scan.curves {
            for q in &c.samples.q {
                prop_assert!(q.iter().all(|x| x.is_finite()), "non-finite orientation");
            }
            prop_assert!(c.samples.d.iter().all(|x| x.is_finite()));
        }
        if let Ok(net) = Reconstructor::new().run(&scan.curves, &NetworkParams::default()) {
            let glb = sfs::gltf_out::network_glb(&sfs::gltf_out::network_curves(&net.positions), &net.positions.nodes, None);
            if let Ok(bytes) = glb {
                let back = sfs::gltf_out::read_glb(&bytes).unwrap();
                for c in &back.curves {
                    prop_assert!(c.points.iter().chain(&c.normals).all(|v| v.iter().all(|x| x.is_finite())));
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, failure_persistence: None, ..ProptestConfig::default() })]

    /// Well-formed curves (valid keys) whose samples are garbage: the reconstruction runs on
    /// them and writes only finite numbers.
    #[test]
    fn garbage_samples_in_valid_curves_reconstruct_finitely(
        samples in prop::collection::vec((any::<[i16; 3]>(), any::<[i16; 3]>(), -200i32..200), 20..400),
        nodes in prop::collection::vec(0u32..6, 2..5),
        curves in 1usize..4,
    ) {
        let mut wire = Vec::new();
        let mut seq = 0u8;
        let mut put = |p: Packet, w: &mut Vec<u8>| { p.encode(seq, w); seq = seq.wrapping_add(1); };
        put(common::hello(), &mut wire);
        let mut t = 0u32;
        let mut wheel = 0i32;
        let per = samples.len() / (nodes.len() * curves);
        let mut k = 0;
        for c in 0..curves {
            put(Packet::Key(Key { t_us: t, key: if c % 2 == 0 { b'B' } else { b'I' } }), &mut wire);
            for (ni, n) in nodes.iter().enumerate() {
                for _ in 0..per.max(1) {
                    let (acc, mag, dw) = samples[k % samples.len()];
                    k += 1;
                    t += 10_000;
                    wheel += dw;
                    put(Packet::RiderSample(RiderSample { t_us: t, acc, mag, wheel }), &mut wire);
                }
                for key in (n + c as u32).to_string().bytes().chain([b'\n']) {
                    put(Packet::Key(Key { t_us: t, key }), &mut wire);
                }
                let _ = ni;
            }
            put(Packet::Key(Key { t_us: t, key: b'E' }), &mut wire);
        }
        let mut dec = Decoder::new();
        let mut acq = Acquisition::new(AcquisitionConfig::default());
        for e in dec.feed(&wire) {
            acq.event(&e);
        }
        let scan = acq.finish();
        prop_assert!(scan.curves.len() <= curves);
        if let Ok(net) = Reconstructor::new().run(&scan.curves, &NetworkParams::default()) {
            for c in &net.positions.curves {
                prop_assert!(c.points.iter().chain(&c.normals).all(|v| v.iter().all(|x| x.is_finite())));
            }
            let glb = sfs::gltf_out::network_glb(&sfs::gltf_out::network_curves(&net.positions), &net.positions.nodes, None);
            prop_assert!(glb.is_ok(), "{:?}", glb.err());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, failure_persistence: None, ..ProptestConfig::default() })]

    /// Damaged networks (noisy points and normals, segments dropped, node normals flipped or
    /// missing, points collapsed): the surfacer never panics, and whatever it returns is finite,
    /// non-degenerate and writes a valid glb.
    #[test]
    fn damaged_networks_surface_without_panics(
        noise in 0.0f64..0.2,
        normal_noise in 0.0f64..1.0,
        drop in prop::collection::vec(prop::bool::weighted(0.2), 12),
        flip in prop::collection::vec(prop::bool::weighted(0.15), 6),
        collapse in 0usize..4,
        seed in any::<u64>(),
    ) {
        use sfs_geometry::surface::fit::{surface, SurfaceParams};
        let mut net = sfs_geometry::surface::analytic::sphere_circles(0.15);
        let mut s = seed | 1;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut k = 0;
        net.segments.retain(|_| {
            k += 1;
            !drop[k - 1]
        });
        for seg in &mut net.segments {
            let m = seg.points.len();
            for i in 1..m - 1 {
                seg.points[i] += nalgebra::Vector3::new(r(), r(), r()) * noise;
                seg.normals[i] = (seg.normals[i] + nalgebra::Vector3::new(r(), r(), r()) * normal_noise)
                    .try_normalize(1e-9)
                    .unwrap_or(seg.normals[i]);
            }
            for i in 1..(1 + collapse).min(m - 1) {
                seg.points[i] = seg.points[i - 1];
            }
        }
        for (n, f) in flip.iter().enumerate() {
            if *f {
                if n % 2 == 0 {
                    if let Some(v) = net.normals.get_mut(&(n as u32)) { *v = -*v; }
                } else {
                    net.normals.remove(&(n as u32));
                }
            }
        }
        for soft in [None, Some(0.1)] {
            let res = surface(&net, &SurfaceParams { soft, ..Default::default() });
            if let Ok(out) = res {
                prop_assert!(out.positions.iter().all(|p| p.iter().all(|x| x.is_finite())));
                prop_assert!(out.normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-6));
                let glb = sfs::gltf_out::network_glb(&[], &Default::default(), Some(&out.mesh()));
                prop_assert!(glb.is_ok(), "{:?}", glb.err());
            }
        }
    }
}
