//! The reconstruction on noise-free input (exact frames, dense samples taken from the truth
//! polylines): the error converges as h → 0, and at h = 0.8 % of the diagonal the mean is within
//! 0.05 % of the diagonal (paper, synthetic: BOWL 0.10 %, BUMPY 0.08 %). Bad input: curves that
//! cannot be used are left out with a reason, a network in two parts is placed per part.

use nalgebra::Vector3;
use sfs::scan::{Scan, Tag};
use sfs::simulate::scene::{self, Scene};
use sfs::simulate::truth::Truth;
use sfs::simulate::{self, Profile};
use sfs_geometry::network::{Network, NetworkParams, Reconstructor};

fn load(name: &str) -> (Scene, Truth) {
    let s = scene::builtin(name).unwrap_or_else(|e| panic!("{e}"));
    let t = simulate::run(
        &s,
        device_protocol::DeviceKind::SensorArray,
        Profile::Default,
        1,
    )
    .truth;
    (s, t)
}

fn score(t: &Truth, scan: &Scan, h: f64) -> f64 {
    let mut p = NetworkParams::default();
    p.prefilter.h = h;
    reconstructed(t, scan, &p).0
}

/// `scan`'s network with `p`, and its curves' mean error against `t` (% of the diagonal).
fn reconstructed(t: &Truth, scan: &Scan, p: &NetworkParams) -> (f64, Network) {
    let net = Reconstructor::new()
        .run(&scan.curves, p)
        .expect("a network");
    let rec = sfs::gltf_out::as_read_network(&net.positions);
    (sfs::eval::evaluate(t, &rec).unwrap().curves.mean_pct, net)
}

#[test]
fn exact_input_converges_and_meets_the_target() {
    converges(&["bowl", "sphere-octa", "cone", "bumpy", "relief"]);
}

#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn exact_input_converges_and_meets_the_target_on_the_paper_scenes() {
    converges(&["bumpy-cube", "lilium"]);
}

fn converges(names: &[&str]) {
    for &name in names {
        let (s, t) = load(name);
        let scan = s.exact_scan();
        let diag = t.bbox_diagonal;
        let errs: Vec<f64> = [0.032, 0.016, 0.008]
            .iter()
            .map(|f| score(&t, &scan, f * diag))
            .collect();
        eprintln!("{name}: mean error at h = 3.2 / 1.6 / 0.8 % of the diagonal: {errs:.4?} %");
        assert!(errs[2] <= 0.05, "{name}: {:.4} % at h = 0.8 %", errs[2]);
        assert!(errs[2] < errs[0], "{name}: no convergence: {errs:?}");
    }
}

#[test]
fn unusable_curves_are_left_out_with_a_reason_and_parts_placed_separately() {
    let (s, _) = load("sphere-octa");
    let mut scan = s.exact_scan();
    // A curve with one tag, a curve shorter than 2h, and a separate loop with its own nodes.
    let mut one_tag = scan.curves[0].clone();
    one_tag.index = 3;
    one_tag.tags.truncate(1);
    let mut short = scan.curves[1].clone();
    short.index = 4;
    short.tags = vec![
        Tag {
            node: 0,
            d: 0.0,
            t: 0.0,
            uncertain: false,
        },
        Tag {
            node: 9,
            d: 0.001,
            t: 1.0,
            uncertain: false,
        },
    ];
    let mut apart = scan.curves[2].clone();
    apart.index = 5;
    for tag in &mut apart.tags {
        tag.node += 100;
    }
    scan.curves.extend([one_tag, short, apart]);
    let net = Reconstructor::new()
        .run(&scan.curves, &NetworkParams::default())
        .unwrap();
    assert_eq!(net.report.curves_used, 4);
    assert_eq!(net.report.curves_left_out, 2);
    assert_eq!(net.report.components, 2);
    use sfs_geometry::network::prefilter::PrefilterError;
    use sfs_geometry::network::NetworkWarning;
    let w = &net.warnings;
    assert!(
        w.iter().any(|w| matches!(
            w,
            NetworkWarning::LeftOut(PrefilterError::TooFewNodes { curve: 3, .. })
        )),
        "{w:?}"
    );
    assert!(
        w.iter().any(|w| matches!(
            w,
            NetworkWarning::LeftOut(PrefilterError::TooShort { curve: 4, .. })
        )),
        "{w:?}"
    );
    assert!(
        w.contains(&NetworkWarning::InParts { components: 2 }),
        "{w:?}"
    );
    for c in &net.positions.curves {
        assert!(c
            .points
            .iter()
            .chain(&c.normals)
            .all(|v: &Vector3<f64>| v.iter().all(|x| x.is_finite())));
    }
}

/// Issue 18: the box and the roof from exact frames, through the daemon's pipeline (network,
/// surface with the scans' soft constraints, glb read back): flat faces and sharp edges with
/// the kinds, a pillow without them.
#[test]
fn issue_18_box_and_roof_from_exact_frames() {
    for (name, curves_max, surface_max) in [("box", 0.01, 0.005), ("roof", 0.02, 0.01)] {
        let (s, t) = load(name);
        let run = |smooth: bool| {
            let mut scan = s.exact_scan();
            if smooth {
                for c in &mut scan.curves {
                    c.kind = sfs_geometry::curve::CurveKind::Interior;
                }
            }
            let surface = sfs_geometry::surface::fit::SurfaceParams {
                soft: sfs::pipeline::SCAN_SOFTNESS,
                ..Default::default()
            };
            let products = sfs::pipeline::Pipeline::new().run(
                &scan.curves,
                &NetworkParams::default(),
                Some(&surface),
            );
            let rec = sfs::gltf_out::read_glb(&products.glb.expect("a glb")).unwrap();
            sfs::eval::evaluate(&t, &rec).unwrap()
        };
        let e = run(false);
        let surf = e.surface.clone().expect("a surface");
        let worst = e
            .creases
            .iter()
            .map(|c| c.error_max_deg)
            .fold(0.0, f64::max);
        eprintln!(
            "{name}: curves {:.4} %, surface {:.4} / {:.4} %, dihedral error ≤ {worst:.2}° over {} creases",
            e.curves.mean_pct,
            surf.mean_pct,
            surf.max_pct,
            e.creases.len()
        );
        assert!(
            e.curves.mean_pct <= curves_max,
            "{name}: curves {}",
            e.curves.mean_pct
        );
        assert!(
            surf.mean_pct <= surface_max,
            "{name}: surface {}",
            surf.mean_pct
        );
        assert!(
            !e.creases.is_empty() && worst <= 1.0,
            "{name}: {:?}",
            e.creases
        );
        let smooth = run(true);
        assert!(
            smooth.surface.unwrap().mean_pct > 10.0 * surf.mean_pct,
            "{name}: as smooth as with creases"
        );
    }
}

/// Issue 52: a mounting offset (the sensor pitched by 1.7° and rolled by 0.8° in the device,
/// as the independent simulator's rough Morphorider and phone captures are) on exact frames:
/// the reconstruction estimates it from the normals at the nodes, within 0.1°, and turns it
/// back; the network is then within 1.1 × the exact frames' error (with the estimate off,
/// several times it).
#[test]
fn issue_52_a_mounting_offset_is_estimated_and_turned_back() {
    use nalgebra::UnitQuaternion;
    for name in ["ellipsoid-dense", "relief"] {
        let (s, t) = load(name);
        let exact = s.exact_scan();
        let offset = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -1.7f64.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.8f64.to_radians());
        let turned = turned(&exact, offset);
        let run = |scan: &Scan, no_mounting: bool| {
            let (e, net) = mounted(&t, scan, no_mounting);
            (e, net.report.mounting)
        };
        let (base, _) = run(&exact, true);
        let (off, _) = run(&turned, true);
        let (back, est) = run(&turned, false);
        let est = est.expect("an estimate");
        eprintln!("{name}: exact {base:.4} %, offset {off:.4} %, turned back {back:.4} %; {est:?}");
        assert!(est.applied, "{name}: {est:?}");
        assert!((est.pitch_deg + 1.7).abs() < 0.1, "{name}: {est:?}");
        assert!((est.roll_deg - 0.8).abs() < 0.1, "{name}: {est:?}");
        assert!(
            back <= 1.1 * base,
            "{name}: {back:.4} % against {base:.4} %"
        );
        assert!(
            off > 2.0 * base,
            "{name}: the offset costs only {off:.4} % against {base:.4} %"
        );
    }
}

/// [`reconstructed`] with the defaults, the mounting offset estimated or not.
fn mounted(t: &Truth, scan: &Scan, no_mounting: bool) -> (f64, Network) {
    let p = NetworkParams {
        no_mounting,
        ..NetworkParams::default()
    };
    reconstructed(t, scan, &p)
}

/// `scan` with every frame turned in its own axes by `offset` (the frames read
/// `true · offset`: a sensor turned in its housing).
fn turned(scan: &Scan, offset: nalgebra::UnitQuaternion<f64>) -> Scan {
    use nalgebra::{Quaternion, UnitQuaternion};
    let mut turned = scan.clone();
    for c in &mut turned.curves {
        for q in &mut c.samples.q {
            let r =
                UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])) * offset;
            *q = [r.w, r.i, r.j, r.k];
        }
    }
    turned
}

/// Issue 52: the mounting's yaw about N (1.5°; the independent simulator's rough captures
/// carry up to 2°) is not seen at the nodes but by the loops. It is estimated from their
/// misfit within 0.1°, the frames are turned back, and the network comes back within 1.1×
/// the exact frames' error (several times it without). The exact frames are left alone.
#[test]
fn issue_52_the_mounting_yaw_is_estimated_from_the_loops_and_turned_back() {
    use nalgebra::UnitQuaternion;
    for name in ["ellipsoid-dense", "relief"] {
        let (s, t) = load(name);
        let exact = s.exact_scan();
        let yawed = turned(
            &exact,
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.5f64.to_radians()),
        );
        let run = |scan: &Scan, no_mounting: bool| {
            let (e, net) = mounted(&t, scan, no_mounting);
            (e, net.report.mounting_yaw)
        };
        let (base, none) = run(&exact, false);
        let (off, _) = run(&yawed, true);
        let (back, est) = run(&yawed, false);
        let est = est.expect("an estimate");
        eprintln!(
            "{name}: exact {base:.4} % ({none:?}), yawed {off:.4} %, turned back {back:.4} %; {est:?}"
        );
        assert!(est.applied, "{name}: {est:?}");
        assert!((est.yaw_deg - 1.5).abs() < 0.1, "{name}: {est:?}");
        assert!(
            none.is_none_or(|n| !n.applied || n.yaw_deg.abs() < 0.02),
            "{name}: {none:?}"
        );
        assert!(
            back <= 1.1 * base,
            "{name}: {back:.4} % against {base:.4} %"
        );
        assert!(
            off > 2.0 * base,
            "{name}: the yaw costs only {off:.4} % against {base:.4} %"
        );
    }
}

/// `scan` with the wheel slipping evenly over segment `tag` of curve `curve` (position in
/// the scan): its distances read `fraction` short there, and every later distance as much.
fn slipped(scan: &Scan, curve: usize, tag: usize, fraction: f64) -> Scan {
    let mut slipped = scan.clone();
    let c = &mut slipped.curves[curve];
    let (a, b) = (c.tags[tag].d, c.tags[tag + 1].d);
    let lost = fraction * (b - a);
    let short = |d: f64| {
        if d <= a {
            d
        } else if d <= b {
            a + (1.0 - fraction) * (d - a)
        } else {
            d - lost
        }
    };
    for d in &mut c.samples.d {
        *d = short(*d);
    }
    for g in &mut c.tags {
        g.d = short(g.d);
    }
    slipped
}

/// The slips a network's loops named.
fn slips_of(net: &Network) -> Vec<sfs_geometry::network::closure::Slip> {
    net.warnings
        .iter()
        .filter_map(|w| match w {
            sfs_geometry::network::NetworkWarning::SlipSuspected(s) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

/// Issues 49 and 52: a mounting yaw (1.5°) misfits every loop a little, a wheel that slipped
/// over one segment (8 % short) one loop a lot. With the yaw turned back before the loop
/// closure test, the slip stands out: a wheel's test names it on its segment and lengthens
/// it, no tag is blamed, and the network comes back within 1.2× the exact frames' error.
#[test]
fn issue_49_a_slip_stands_out_once_the_mounting_yaw_is_turned_back() {
    use nalgebra::UnitQuaternion;
    for (name, curve, tag) in [("ellipsoid-dense", 1usize, 1usize), ("relief", 3, 2)] {
        let (s, t) = load(name);
        let exact = s.exact_scan();
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.5f64.to_radians());
        let scan = slipped(&turned(&exact, yaw), curve, tag, 0.08);
        let p = NetworkParams {
            slips: sfs_geometry::network::closure::SlipTest::WHEEL,
            ..NetworkParams::default()
        };
        let (base, _) = reconstructed(&t, &exact, &p);
        let (e, net) = reconstructed(&t, &scan, &p);
        let slips = slips_of(&net);
        let tags = &net.report.tags_detached;
        eprintln!("{name}: exact {base:.4} %, yawed and slipped {e:.4} %; {slips:?}");
        assert_eq!(slips.len(), 1, "{name}: {slips:?}");
        let s = &slips[0];
        assert_eq!(
            (s.curve, s.tag),
            (scan.curves[curve].index, tag),
            "{name}: {s:?}"
        );
        assert!(
            s.lengthened && (s.short_fraction - 0.08).abs() < 0.02,
            "{name}: {s:?}"
        );
        assert_eq!(*tags, 0, "{name}");
        assert!(
            !net.warnings
                .iter()
                .any(|w| matches!(w, sfs_geometry::network::NetworkWarning::TagRefused(_))),
            "{name}: {:?}",
            net.warnings
        );
        assert!(e <= 1.2 * base, "{name}: {e:.4} % against {base:.4} %");
    }
}

/// Issue 49: a wheel that slipped evenly over one segment (its distances read 12 % short) on
/// exact frames: the loops name the slip on that segment, with the fraction missed, and the
/// segment is lengthened by their estimate before the regression and Poisson: the network
/// comes back within 1.2 × the exact frames' error (kept as measured, several times it).
#[test]
fn issue_49_a_slip_named_by_the_loops_is_lengthened_back() {
    for (name, curve, tag) in [("ellipsoid-dense", 1usize, 1usize), ("relief", 3, 2)] {
        let (s, t) = load(name);
        let exact = s.exact_scan();
        let slipped = slipped(&exact, curve, tag, 0.12);
        let index = slipped.curves[curve].index;
        let run = |scan: &Scan, no_slip_repair: bool| {
            let p = NetworkParams {
                no_slip_repair,
                ..NetworkParams::default()
            };
            let (e, net) = reconstructed(&t, scan, &p);
            (e, slips_of(&net))
        };
        let (base, none) = run(&exact, false);
        assert!(none.is_empty(), "{name}: exact frames, {none:?}");
        let (kept, named) = run(&slipped, true);
        let (back, repaired) = run(&slipped, false);
        eprintln!(
            "{name}: exact {base:.4} %, slipped {kept:.4} %, lengthened {back:.4} %; {repaired:?}"
        );
        assert_eq!(named.len(), 1, "{name}: {named:?}");
        assert!(!named[0].lengthened, "{name}: {named:?}");
        assert_eq!(repaired.len(), 1, "{name}: {repaired:?}");
        let s = &repaired[0];
        assert_eq!((s.curve, s.tag), (index, tag), "{name}: {s:?}");
        assert!(s.lengthened, "{name}: {s:?}");
        assert!((s.short_fraction - 0.12).abs() < 0.02, "{name}: {s:?}");
        assert!(
            back <= 1.2 * base,
            "{name}: {back:.4} % against {base:.4} %"
        );
        assert!(
            kept > 2.0 * base,
            "{name}: the slip costs only {kept:.4} % against {base:.4} %"
        );
    }
}

/// `scan` with each curve's distances read `1 + scales[k]` times as long (a wheel whose rolling
/// radius changes from pass to pass).
fn scaled(scan: &Scan, scales: &[f64]) -> Scan {
    let mut out = scan.clone();
    for (c, &s) in out.curves.iter_mut().zip(scales) {
        let d0 = c.samples.d.first().copied().unwrap_or(0.0);
        for d in &mut c.samples.d {
            *d = d0 + (*d - d0) * (1.0 + s);
        }
        for g in &mut c.tags {
            g.d = d0 + (g.d - d0) * (1.0 + s);
        }
    }
    out
}

/// Issue 52: a wheel reads each curve a little long or short (the independent simulator's
/// rough Morphorider: 0.9 % RMS, the same along a curve). The loops estimate each curve's
/// scale: on exact frames with the curves read ±1.5 % in turn (less their length-weighted
/// mean, which the loops cannot see), each scale comes back within 0.3 % of what was put in,
/// and the network within 1.5× the exact one's error, where it is several times that as read.
/// The box has fewer loops than curves (11, 12): its noise counts three degrees of freedom a
/// loop, where one leaves none (`curve_scale::degrees_of_freedom`); no estimate before.
#[test]
fn issue_52_each_curves_scale_is_estimated_from_the_loops() {
    for name in ["ellipsoid-dense", "relief", "box"] {
        let (s, t) = load(name);
        let exact = s.exact_scan();
        // ±1.5 % in turn, less their length-weighted mean: a scale common to every curve is
        // the wheel's calibration, which the loops cannot see.
        let lengths: Vec<f64> = exact
            .curves
            .iter()
            .map(|c| c.samples.d.last().unwrap() - c.samples.d[0])
            .collect();
        let alternate = |k: usize| if k.is_multiple_of(2) { 0.015 } else { -0.015 };
        let total: f64 = lengths.iter().sum();
        let mean = (0..lengths.len())
            .map(|k| alternate(k) * lengths[k])
            .sum::<f64>()
            / total;
        let mut put: Vec<f64> = (0..lengths.len()).map(|k| alternate(k) - mean).collect();
        // No loop sees a scale common to the box's upright curves either (a box stretched
        // upright is still a box): that part of what is put in is left out.
        let upright = |c: &sfs_geometry::curve::Curve| {
            c.samples
                .q
                .iter()
                .all(|&[w, x, y, z]| (2.0 * (x * z - w * y)).abs() > 0.99)
        };
        let up_length: f64 = (exact.curves.iter().zip(&lengths))
            .filter(|(c, _)| upright(c))
            .map(|(_, l)| l)
            .sum();
        let v: Vec<f64> = (exact.curves.iter())
            .map(|c| f64::from(u8::from(upright(c))) - up_length / total)
            .collect();
        assert_eq!(up_length > 0.0, name == "box", "{name}: upright curves");
        if up_length > 0.0 {
            let along = put.iter().zip(&v).map(|(p, v)| p * v).sum::<f64>()
                / v.iter().map(|v| v * v).sum::<f64>();
            for (p, v) in put.iter_mut().zip(&v) {
                *p -= along * v;
            }
        }
        let read = scaled(&exact, &put);
        let with = NetworkParams {
            curve_scale_sigma: Some(sfs_geometry::network::curve_scale::WHEEL_SIGMA),
            ..NetworkParams::default()
        };
        let (base, base_net) = reconstructed(&t, &exact, &with);
        let (off, _) = reconstructed(&t, &read, &NetworkParams::default());
        let (back, net) = reconstructed(&t, &read, &with);
        eprintln!(
            "{name}: exact {base:.4} %, read ±1.5 % {off:.4} %, scales estimated {back:.4} %"
        );
        // Exact distances: nothing to correct.
        for (k, s) in &base_net.report.curve_scales {
            assert!(
                s.abs() < 1e-3,
                "{name}: curve {k} of exact frames scaled by {s}"
            );
        }
        // Each estimate undoes what was put in.
        assert_eq!(net.report.curve_scales.len(), read.curves.len(), "{name}");
        for (k, c) in read.curves.iter().enumerate() {
            let got = net.report.curve_scales[&c.index];
            let want = 1.0 / (1.0 + put[k]) - 1.0;
            assert!(
                (got - want).abs() < 0.003,
                "{name}: curve {}: {got:.4} for {want:.4}",
                c.index
            );
        }
        assert!(
            back <= 1.5 * base + 0.002,
            "{name}: {back:.4} % against {base:.4} %"
        );
        assert!(
            off > 3.0 * base,
            "{name}: the scales cost only {off:.4} % against {base:.4} %"
        );
    }
}
