//! The reconstruction of simulated scans, end to end through the bytes (simulator → decoder →
//! acquisition → reconstruction → `eval`), for the failures field sessions bring.

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::scan::Scan;
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::network::NetworkWarning;
use sfs_geometry::network::{NetworkParams, Reconstructor};

fn decode(bytes: &[u8]) -> Scan {
    Acquisition::scan_bytes(bytes, AcquisitionConfig::default())
}

/// Issue 5: in a phone scan of the lilium the link loses digits of node indices: the leading
/// digit of a two-digit index (it arrives as a one-digit node, tying the curve to the wrong
/// node: 3.2 % of the diagonal in the first such capture) and the only digit of another (a tag
/// lost, the measured segment lengths misapplied). Now the keypad keeps the second as an
/// anonymous tag and the loop-closure test detaches the first, naming it. (Seed 59 since the
/// simulator's sample timing was fixed in issue 17; seed 1 before.)
#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn issue5_lost_index_digits_do_not_distort_the_network() {
    lost_index_digits_do_not_distort_the_network("lilium", 59);
}

/// Issue 5's faults on the project's own relief (issue 30: the test runs from the repository
/// alone), in the phone capture of seed RELIEF_SEED.
#[test]
fn issue5_lost_index_digits_do_not_distort_the_network_of_the_relief() {
    lost_index_digits_do_not_distort_the_network("relief", RELIEF_SEED);
}

/// A seed whose phone capture of the relief loses the two digits issue 5 is about.
const RELIEF_SEED: u64 = 301;

fn lost_index_digits_do_not_distort_the_network(name: &str, seed: u64) {
    let s = scene::builtin(name).unwrap_or_else(|e| panic!("{e}"));
    let sim = simulate::run(&s, DeviceKind::Phone, Profile::Default, seed);
    let scan = decode(&sim.bytes);
    // The capture must still hold the two faults this test is about.
    let mut wrong = Vec::new();
    let mut anonymous = Vec::new();
    for (c, (curve, truth)) in scan.curves.iter().zip(&sim.truth.curves).enumerate() {
        for (k, tag) in curve.tags.iter().enumerate() {
            if sfs::keypad::is_anonymous(tag.node) {
                anonymous.push((c, k));
            } else if truth.nodes.get(k) != Some(&tag.node) {
                wrong.push((c, k, tag.node, truth.nodes[k], tag.uncertain));
            }
        }
    }
    let [(wc, wk, wnode, right, uncertain)] = wrong[..] else {
        panic!("the simulator no longer loses one leading digit ({wrong:?}); pick the seed again");
    };
    assert_eq!(
        wnode.to_string(),
        right.to_string()[1..],
        "a leading digit lost"
    );
    assert!(uncertain, "packets were lost while node {right} was typed");
    assert!(
        !anonymous.is_empty(),
        "a tag whose only digit was lost is kept as an anonymous node; pick the seed again"
    );
    let net = Reconstructor::new()
        .run(&scan.curves, &NetworkParams::default())
        .unwrap();
    assert_eq!(net.report.tags_detached, 1, "{:?}", net.warnings);
    assert!(
        net.warnings.iter().any(|w| matches!(
            w,
            NetworkWarning::TagDetached(d) if (d.curve, d.node, d.tag) == (wc, wnode, wk)
        )),
        "{:?}",
        net.warnings
    );
    // Issue 16: the closure misfit the view shows marks that tag, and only it, for the
    // operator to check; the loops then close to a few millimetres.
    let marked: Vec<(usize, usize, u32, bool)> =
        sfs_geometry::network::closure::marked(&net.report.closure)
            .iter()
            .map(|(c, t)| (*c, t.tag, t.node, t.detached))
            .collect();
    assert_eq!(
        marked,
        vec![(wc, wk, wnode, true)],
        "{:?}",
        net.report.closure
    );
    assert_eq!(net.report.closure.len(), scan.curves.len());
    let worst = net
        .report
        .closure
        .iter()
        .map(|c| c.misfit_m)
        .fold(0.0, f64::max);
    assert!(worst < 0.02, "a curve misses its nodes by {worst} m");
    let e =
        sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions)).unwrap();
    assert!(
        e.curves.mean_pct <= 0.40,
        "mean {} % of the diagonal (phone target 0.40 %)",
        e.curves.mean_pct
    );
    // Without the closure test the wrong tag distorts everything.
    let p = NetworkParams {
        no_closure_check: true,
        ..Default::default()
    };
    let net = Reconstructor::new().run(&scan.curves, &p).unwrap();
    let e =
        sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions)).unwrap();
    assert!(e.curves.mean_pct > 1.0, "{}", e.curves.mean_pct);
}

/// Issue 7: a reconstructor fed a growing scan (as the live worker feeds it, one curve more
/// each time) pre-filters only the new curve, gives bit for bit what a fresh reconstructor
/// gives, and warm-started starts closer to the same network.
#[test]
fn a_growing_scan_is_reconstructed_incrementally() {
    let s = scene::builtin("cone").unwrap();
    let sim = simulate::run(&s, DeviceKind::Morphorider, Profile::Default, 1);
    let full = decode(&sim.bytes);
    assert!(full.curves.len() >= 5, "{} curves", full.curves.len());
    let p = NetworkParams::default();
    let mut cold = Reconstructor::new();
    let mut warm = Reconstructor::new();
    let (mut warm_iterations, mut cold_iterations) = (0, 0);
    for k in 1..=full.curves.len() {
        let scan = Scan {
            curves: full.curves[..k].to_vec(),
            ..full.clone()
        };
        let a = cold.run(&scan.curves, &p);
        assert_eq!(cold.prefiltered_last, 1, "after {k} curves");
        let b = warm.run_warm(&scan.curves, &p);
        let fresh = Reconstructor::new().run(&scan.curves, &p);
        let (Ok(a), Ok(b), Ok(fresh)) = (a, b, fresh) else {
            continue;
        };
        // The caches change the time, not the bits.
        for (x, y) in a.positions.curves.iter().zip(&fresh.positions.curves) {
            assert_eq!(x.points, y.points, "curve {} after {k} curves", x.index);
        }
        // Warm: the same optimum, to well under a millimetre.
        for (x, y) in a.positions.curves.iter().zip(&b.positions.curves) {
            for (p, q) in x.points.iter().zip(&y.points) {
                assert!((p - q).norm() < 1e-4, "curve {} after {k} curves", x.index);
            }
        }
        let (ra, rb) = (&a.report.regression, &b.report.regression);
        if k > 1 {
            // The old curves start where they ended: most of the misfit is already gone.
            assert!(
                rb.energy_initial < ra.energy_initial,
                "after {k} curves: warm {rb:?}, cold {ra:?}"
            );
            cold_iterations += ra.iterations;
            warm_iterations += rb.iterations;
        }
    }
    // The energy is nearly quadratic: Gauss–Newton needs about three iterations from the
    // data as from the previous solution (measured 18 and 18 over the cone's 7 curves).
    eprintln!("regression iterations: cold {cold_iterations}, warm {warm_iterations}");
    assert!(warm_iterations <= cold_iterations);
}
