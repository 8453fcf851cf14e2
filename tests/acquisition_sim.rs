//! Acquisition against simulated captures with known truth: orientation errors of the
//! Morphorider while still and while rolling, tag distances, the phone's fusion and segment
//! rescaling, keypad corrections, and a device reboot mid-session.

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::orientation::flags;
use sfs::scan::Scan;
use sfs::simulate::device::{render, DeviceParams, SampleTruth};
use sfs::simulate::operator::{perform, CurveSpec, OperatorParams, Script};
use sfs::simulate::rng::Rng;

const R: f64 = 0.3;

fn dome() -> Vec<CurveSpec> {
    sfs::simulate::shapes::dome(R)
}

fn acquire(bytes: &[u8], cfg: AcquisitionConfig) -> Scan {
    Acquisition::scan_bytes(bytes, cfg)
}

/// Index of the truth sample at scan time `t` (session time starts at the first sample).
fn truth_index(truth: &SampleTruth, t: f64) -> usize {
    let t_abs = t + truth.t[0];
    let i = truth.t.partition_point(|&x| x < t_abs - 2e-6);
    assert!(
        (truth.t[i] - t_abs).abs() < 2e-6,
        "no truth sample at t = {t}"
    );
    i
}

fn quat(a: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(a[0], a[1], a[2], a[3]))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Errors {
    still: Vec<f64>,
    rolling: Vec<f64>,
}

fn orientation_errors(scan: &Scan, truth: &SampleTruth, mounting: &Rotation3<f64>) -> Errors {
    let mut e = Errors {
        still: vec![],
        rolling: vec![],
    };
    let mount = UnitQuaternion::from_rotation_matrix(mounting);
    for c in &scan.curves {
        for (i, q) in c.samples.q.iter().enumerate() {
            let k = truth_index(truth, c.samples.t[i]);
            // Without a configured mounting the estimate is the sensor's frame: truth · mounting.
            let err = quat(q).angle_to(&(truth.q[k] * mount)).to_degrees();
            if truth.standing[k] {
                e.still.push(err);
            } else {
                e.rolling.push(err);
            }
        }
    }
    e
}

fn simulate(curves: &[CurveSpec], p: &DeviceParams, seed: u64) -> (Script, Vec<u8>, SampleTruth) {
    let mut rng = Rng::new(seed);
    let script = perform(
        curves,
        &OperatorParams::default(),
        p.rate_hz,
        p.jitter,
        &mut rng,
    );
    let (bytes, truth) = render(&script, p, &mut rng);
    (script, bytes, truth)
}

#[test]
fn morphorider_orientation_error_still_and_rolling() {
    let p = DeviceParams::morphorider();
    let (_, bytes, truth) = simulate(&dome(), &p, 11);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    assert_eq!(scan.curves.len(), 3, "{:?}", scan.warnings);
    assert!(scan.warnings.is_empty(), "{:?}", scan.warnings);
    let e = orientation_errors(&scan, &truth, &Rotation3::identity());
    let (still, rolling) = (median(e.still.clone()), median(e.rolling.clone()));
    eprintln!(
        "Morphorider median error: still {still:.3}°, rolling {rolling:.3}° ({} / {} samples)",
        e.still.len(),
        e.rolling.len()
    );
    assert!(e.still.len() > 500 && e.rolling.len() > 2000);
    assert!(still <= 1.5, "still: median {still:.2}°");
    assert!(rolling <= 3.0, "rolling: median {rolling:.2}°");
}

#[test]
fn mounting_offset_is_corrected_by_calibration() {
    let mut p = DeviceParams::morphorider();
    p.mounting = Rotation3::from_euler_angles(0.0, 0.0, 2f64.to_radians());
    let (_, bytes, truth) = simulate(&dome(), &p, 12);
    // Uncorrected: the 2° yaw offset shows in every sample.
    let raw = acquire(&bytes, AcquisitionConfig::default());
    let e_raw = orientation_errors(&raw, &truth, &Rotation3::identity());
    // Corrected by the configured mounting rotation.
    let mut cfg = AcquisitionConfig::default();
    cfg.calibration.mounting = p.mounting;
    let fixed = acquire(&bytes, cfg);
    let e_fixed = orientation_errors(&fixed, &truth, &Rotation3::identity());
    let (m_raw, m_fixed) = (median(e_raw.still), median(e_fixed.still));
    assert!(
        m_raw > 1.5,
        "the offset should be visible uncorrected: {m_raw:.2}°"
    );
    assert!(m_fixed < 1.0, "corrected: {m_fixed:.2}°");
}

#[test]
fn tags_land_at_the_wheel_distance_of_the_enter_press() {
    let mut p = DeviceParams::morphorider();
    p.slip_sigma = 0.0; // measured distances are true distances
    let (script, bytes, _) = simulate(&dome(), &p, 13);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    let tick = 0.1 / 1024.0;
    let wobble = OperatorParams::default().stand_wobble;
    for (c, truth) in scan.curves.iter().zip(&script.curves) {
        assert_eq!(
            c.nodes(),
            truth.tags.iter().map(|t| t.0).collect::<Vec<_>>()
        );
        let s0 = truth.tags[0].1;
        for (tag, &(node, s, _, _)) in c.tags.iter().zip(&truth.tags) {
            let err = (tag.d - (s - s0)).abs();
            assert!(
                err <= tick + 2.0 * wobble,
                "curve {}, node {node}: tag at {:.4} m, truth {:.4} m",
                c.index,
                tag.d,
                s - s0
            );
        }
        assert!((c.length() - truth.length).abs() < tick + 2.0 * wobble);
    }
}

#[test]
fn stationary_flags_follow_the_operator() {
    let p = DeviceParams::morphorider();
    let (_, bytes, truth) = simulate(&dome(), &p, 14);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    let (mut agree, mut n) = (0, 0);
    for c in &scan.curves {
        for (i, f) in c.samples.flags.iter().enumerate() {
            let k = truth_index(&truth, c.samples.t[i]);
            agree += ((f & flags::STATIONARY != 0) == truth.standing[k]) as usize;
            n += 1;
        }
    }
    let rate = agree as f64 / n as f64;
    assert!(
        rate > 0.9,
        "stationary flags agree with the truth on {:.1} % of samples",
        100.0 * rate
    );
}

#[test]
fn magnetic_disturbance_is_flagged() {
    let mut p = DeviceParams::morphorider();
    // A ferromagnetic object near the pole.
    p.disturbances.push(sfs::simulate::device::Disturbance {
        center: Vector3::new(0.0, 0.0, R),
        radius: 0.05,
        field_ut: Vector3::new(15.0, 0.0, 5.0),
    });
    let (_, bytes, truth) = simulate(&dome(), &p, 15);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    let (mut near, mut near_flagged, mut far, mut far_flagged) = (0, 0, 0, 0);
    for c in &scan.curves {
        for (i, f) in c.samples.flags.iter().enumerate() {
            let k = truth_index(&truth, c.samples.t[i]);
            let pos = truth.q[k] * Vector3::z() * R; // on the sphere, position = R · normal
            let flagged = f & flags::MAG_DISTURBED != 0;
            if (pos - Vector3::new(0.0, 0.0, R)).norm() < 0.05 {
                near += 1;
                near_flagged += flagged as usize;
            } else if (pos - Vector3::new(0.0, 0.0, R)).norm() > 0.12 {
                far += 1;
                far_flagged += flagged as usize;
            }
        }
    }
    assert!(near > 50);
    assert!(
        near_flagged as f64 > 0.9 * near as f64,
        "{near_flagged}/{near} near the magnet flagged"
    );
    assert!(
        (far_flagged as f64) < 0.02 * far as f64,
        "{far_flagged}/{far} far from it flagged"
    );
    assert!(
        scan.counts.mag_disturbed as usize
            == scan
                .curves
                .iter()
                .map(|c| c
                    .samples
                    .flags
                    .iter()
                    .filter(|f| *f & flags::MAG_DISTURBED != 0)
                    .count())
                .sum::<usize>()
    );
}

#[test]
fn phone_fusion_and_segment_lengths() {
    let p = DeviceParams::phone();
    let (script, bytes, truth) = simulate(&dome(), &p, 16);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    assert_eq!(scan.curves.len(), 3, "{:?}", scan.warnings);
    let e = orientation_errors(&scan, &truth, &Rotation3::identity());
    let (still, moving) = (median(e.still), median(e.rolling));
    eprintln!("phone median error: still {still:.3}°, moving {moving:.3}°");
    assert!(
        still <= 1.5 && moving <= 2.0,
        "still {still:.2}°, moving {moving:.2}°"
    );
    // Tags at the measured segment lengths (3 mm measurement noise per segment).
    for (c, t) in scan.curves.iter().zip(&script.curves) {
        assert!(
            c.segment_lengths.iter().all(|l| l.is_some()),
            "curve {}: {:?}",
            c.index,
            c.segment_lengths
        );
        let s0 = t.tags[0].1;
        for (tag, &(_, s, _, _)) in c.tags.iter().zip(&t.tags) {
            assert!(
                (tag.d - (s - s0)).abs() < 0.02,
                "curve {}: {:.4} vs {:.4}",
                c.index,
                tag.d,
                s - s0
            );
        }
        // Within a segment, the distance of moving samples follows the truth closely.
        for (i, &d) in c.samples.d.iter().enumerate() {
            let k = truth_index(&truth, c.samples.t[i]);
            if truth.curve[k] == Some(c.index) && !truth.standing[k] {
                let err = (d - (truth.s[k] - s0)).abs();
                assert!(
                    err < 0.03,
                    "curve {}: sample at {d:.3} m, truth {:.3} m",
                    c.index,
                    truth.s[k] - s0
                );
            }
        }
    }
}

#[test]
fn phone_without_lengths_uses_the_nominal_speed() {
    let mut p = DeviceParams::phone();
    p.segment_length_sigma = 0.0; // no SEGMENT_LENGTH packets
    let (script, bytes, _) = simulate(&dome(), &p, 17);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    for (c, t) in scan.curves.iter().zip(&script.curves) {
        // Mean operator speed equals the nominal speed: lengths within the speed variation.
        let rel = (c.length() - t.length).abs() / t.length;
        assert!(
            rel < 0.15,
            "curve {}: {:.3} m vs {:.3} m",
            c.index,
            c.length(),
            t.length
        );
    }
}

#[test]
fn undo_cancel_and_reboot_cost_no_curve() {
    let p = DeviceParams::morphorider();
    let mut rng = Rng::new(18);
    let mut script = perform(
        &dome(),
        &OperatorParams::default(),
        p.rate_hz,
        p.jitter,
        &mut rng,
    );
    // A wrong index typed and undone right after the first tag of curve 1…
    let enter_1 = script.curves[1].tags[0].2;
    script.keys.extend([
        (enter_1 + 0.05, b'7'),
        (enter_1 + 0.1, b'\n'),
        (enter_1 + 0.2, b'U'),
    ]);
    // …and a false start before curve 2: I, a tag, then C.
    let start_2 = script.keys.iter().filter(|k| k.1 == b'I').nth(1).unwrap().0;
    script.keys.extend([
        (start_2 - 0.9, b'I'),
        (start_2 - 0.8, b'5'),
        (start_2 - 0.7, b'\n'),
        (start_2 - 0.6, b'C'),
    ]);
    script.keys.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut bytes, _) = render(&script, &p, &mut rng);
    // The device reboots between curves 1 and 2: a HELLO with a new clock and sequence.
    let cut = bytes.len() * 3 / 4;
    let cut = bytes[..cut].iter().rposition(|&b| b == 0).unwrap() + 1;
    let tail = bytes.split_off(cut);
    let mut reboot = Vec::new();
    device_protocol::Packet::Hello(device_protocol::Hello {
        proto: 1,
        kind: device_protocol::DeviceKind::Morphorider,
        device_id: p.device_id,
        firmware: 0x0100,
        rate_hz: 100,
        acc_scale: p.acc_lsb as f32,
        gyro_scale: 0.0,
        mag_scale: p.mag_lsb as f32,
        ticks_per_rev: p.ticks_per_rev,
        wheel_circumference_um: p.wheel_circumference_um,
        sensors: 1,
    })
    .encode(0, &mut reboot);
    bytes.extend_from_slice(&reboot);
    bytes.extend_from_slice(&tail);
    let scan = acquire(&bytes, AcquisitionConfig::default());
    let nodes: Vec<Vec<u32>> = scan.curves.iter().map(|c| c.nodes()).collect();
    assert_eq!(
        nodes,
        vec![vec![1, 2, 3, 4, 1], vec![1, 0, 3], vec![2, 0, 4]],
        "{:?}",
        scan.warnings
    );
    assert_eq!(scan.counts.curves_discarded, 1);
}

#[test]
fn phone_segment_lengths_from_configuration() {
    let mut p = DeviceParams::phone();
    p.segment_length_sigma = 0.0; // no SEGMENT_LENGTH packets
    let (script, bytes, _) = simulate(&dome(), &p, 19);
    let mut cfg = AcquisitionConfig::default();
    let truth1: Vec<f64> = script.curves[1]
        .tags
        .windows(2)
        .map(|w| w[1].1 - w[0].1)
        .collect();
    cfg.segment_lengths.insert(1, truth1.clone());
    let scan = acquire(&bytes, cfg);
    let c = &scan.curves[1];
    assert_eq!(
        c.segment_lengths,
        truth1.iter().map(|&l| Some(l)).collect::<Vec<_>>()
    );
    for (k, w) in c.tags.windows(2).enumerate() {
        assert!((w[1].d - w[0].d - truth1[k]).abs() < 1e-12);
    }
    // The other curves keep the nominal speed.
    assert!(scan.curves[0].segment_lengths.iter().all(|l| l.is_none()));
}

#[test]
fn sensor_array_orientations_are_averaged_per_window() {
    use device_protocol::{ArraySample, DeviceKind, Hello, Packet};
    let mut rng = Rng::new(21);
    let (acc_lsb, mag_lsb) = (16.0 * sfs::sensor::G / 65536.0, 0.15);
    let field = sfs::simulate::device::Earth::default().field();
    let truths: Vec<UnitQuaternion<f64>> = (0..4)
        .map(|i| {
            UnitQuaternion::from_euler_angles(0.1 * i as f64, -0.2 + 0.1 * i as f64, 0.5 * i as f64)
        })
        .collect();
    let mut bytes = Vec::new();
    let mut seq = 0u8;
    let mut put = |p: Packet, b: &mut Vec<u8>| {
        p.encode(seq, b);
        seq = seq.wrapping_add(1);
    };
    put(
        Packet::Hello(Hello {
            proto: 1,
            kind: DeviceKind::SensorArray,
            device_id: 3,
            firmware: 1,
            rate_hz: 50,
            acc_scale: acc_lsb as f32,
            gyro_scale: 0.0,
            mag_scale: mag_lsb as f32,
            ticks_per_rev: 0,
            wheel_circumference_um: 0,
            sensors: 4,
        }),
        &mut bytes,
    );
    let counts = |v: Vector3<f64>, lsb: f64| [0, 1, 2].map(|i| (v[i] / lsb).round() as i16);
    for k in 0..250 {
        for (s, q) in truths.iter().enumerate() {
            let acc = q.inverse() * Vector3::new(0.0, 0.0, sfs::sensor::G) + rng.vec3(0.05);
            let mag = q.inverse() * field + rng.vec3(0.4);
            put(
                Packet::ArraySample(ArraySample {
                    t_us: 1_000 + k * 20_000 + s as u32 * 100,
                    sensor: s as u16,
                    acc: counts(acc, acc_lsb),
                    mag: counts(mag, mag_lsb),
                }),
                &mut bytes,
            );
        }
    }
    let scan = acquire(&bytes, AcquisitionConfig::default());
    assert!(scan.array.len() >= 4 * 4, "{} epochs", scan.array.len());
    for e in &scan.array {
        let err = quat(&e.q).angle_to(&truths[e.sensor as usize]).to_degrees();
        assert!(err < 0.6, "sensor {} at {:.1} s: {err:.2}°", e.sensor, e.t);
        assert!(
            (45..=55).contains(&e.samples),
            "{} samples in a 1 s window at 50 Hz",
            e.samples
        );
    }
}

/// Issue 17: a receiver that joins the stream after the first HELLO (the capture starts
/// mid-packet) holds the packets until the next HELLO and interprets them then: the first
/// curve keeps all its samples (they were counted as `before_hello` and dropped, which cost
/// the field profile 0.8 % of the diagonal). A stream that never sends a HELLO still counts
/// its samples as `before_hello` and keeps its keys.
#[test]
fn issue_17_samples_before_the_first_hello_are_held_not_lost() {
    use sfs::simulate::{self, scene, Profile};
    let s = scene::builtin("cone").unwrap();
    let sim = simulate::run(
        &s,
        device_protocol::DeviceKind::Morphorider,
        Profile::Default,
        3,
    );
    let whole = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    // Cut the capture in the middle of the first packet (the HELLO).
    let first = sim.bytes.iter().position(|&b| b == 0).unwrap();
    let cut = Acquisition::scan_bytes(&sim.bytes[first / 2..], AcquisitionConfig::default());
    assert_eq!(whole.counts.before_hello, 0);
    assert_eq!(
        cut.counts.before_hello, 0,
        "samples before the second HELLO were dropped"
    );
    assert_eq!(cut.curves.len(), whole.curves.len());
    for (a, b) in whole.curves.iter().zip(&cut.curves) {
        assert_eq!(a.samples.len(), b.samples.len(), "curve {}", a.index);
        assert_eq!(a.tags, b.tags, "curve {}", a.index);
    }
    // Without any HELLO: nothing can be interpreted, nothing panics, the samples are counted.
    let mut dec = device_protocol::Decoder::new();
    let mut no_hello = Vec::new();
    let mut seq = 0u8;
    for e in dec.feed(&sim.bytes) {
        if let device_protocol::Event::Packet { packet, .. } = e {
            if !matches!(packet, device_protocol::Packet::Hello(_)) {
                packet.encode(seq, &mut no_hello);
                seq = seq.wrapping_add(1);
            }
        }
    }
    let none = Acquisition::scan_bytes(&no_hello, AcquisitionConfig::default());
    assert_eq!(none.counts.before_hello, whole.counts.samples);
    assert!(none.curves.is_empty() || none.curves.iter().all(|c| c.samples.is_empty()));
}
