//! Issue 19, points 1 and 2: the surface state kept across updates and the network regressed
//! near the new curve give, once settled, the network and surface a run from scratch gives —
//! on every shipped scene, curve by curve, as the live worker runs it (a provisional update
//! keeping what faces and frames it can, then settled).

use sfs::pipeline::{exact, exact_network, Pipeline};
use sfs::simulate::scene;

#[test]
fn issue_19_every_shipped_scene_settles_to_the_surface_from_scratch() {
    let names: Vec<&str> = scene::names()
        .filter(|n| !scene::PAPER_SCENES.contains(n) && !scene::LARGE_SCENES.contains(n))
        .collect();
    assert!(names.len() >= 10, "{names:?}");
    settles_curve_by_curve(&names);
}

#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn issue_19_the_paper_scenes_settle_to_the_surface_from_scratch() {
    settles_curve_by_curve(&scene::PAPER_SCENES);
}

fn settles_curve_by_curve(names: &[&str]) {
    // The live settings, at a smaller vertex budget (the property does not depend on it).
    let mut live = sfs::settings::Settings::default()
        .surface
        .expect("surfacing on by default");
    assert!(live.reuse_tolerance > 0.0);
    live.max_vertices = 3000;
    let net = sfs::settings::Settings::default().network;
    assert!(net.local_window > 0);
    let (mut kept, mut local) = (0, 0);
    for name in names {
        let s = scene::builtin(name).unwrap();
        let scan = s.exact_scan();
        let mut pipeline = Pipeline::new();
        for k in 1..=scan.curves.len() {
            let curves = &scan.curves[..k];
            let mut products = pipeline.run(curves, &net, Some(&live));
            let Some(report) = products.surface.clone() else {
                continue;
            };
            kept += report.faces_kept;
            let regressed = &products.network.as_ref().unwrap().report;
            if regressed.provisional {
                local += 1;
                assert!(regressed.regression.frames_moved < regressed.regression.frames);
            }
            assert!(report.provisional, "{name}, {k} curves: not provisional");
            assert!(pipeline.settle(curves, &mut products, &net, Some(&live), || false));
            assert!(!products.network.as_ref().unwrap().report.provisional);
            let settled = products.surface.as_ref().expect("a settled surface");
            assert!(!settled.provisional);
            let fresh = Pipeline::new().run(curves, &exact_network(&net), Some(&exact(&live)));
            assert!(
                products.glb == fresh.glb,
                "{name}, {k} curves: the settled network.glb differs from the one from scratch"
            );
        }
    }
    // Faces were kept and networks regressed locally on the way (the state was exercised,
    // not only rebuilt).
    assert!(
        kept > 0 && local > 0,
        "{kept} faces kept, {local} local regressions"
    );
}

/// Issue 51: a settle asks whether a curve waits between the network's long steps (each pass
/// of the loop-closure test, each join pass), not only once the network is made, and stops
/// there: the live worker's next update no longer waits for a whole settle (the 100-curve
/// grid's from scratch puts 45 lost digits back one pass each). The provisional update is left
/// as it was, and the next settle, undisturbed, is the run from scratch.
#[test]
fn issue_51_a_settle_stops_as_soon_as_a_curve_waits() {
    let mut scan = scene::builtin("bowl").unwrap().exact_scan();
    // The last curve's middle tag typed as a node of the first curve it does not pass: the
    // loop-closure test takes two passes (the wrong index detached, then the loops again).
    let last = scan.curves.len() - 1;
    let on_last: Vec<u32> = scan.curves[last].tags.iter().map(|t| t.node).collect();
    let wrong = scan.curves[0]
        .tags
        .iter()
        .map(|t| t.node)
        .find(|n| !on_last.contains(n))
        .unwrap();
    let mid = scan.curves[last].tags.len() / 2;
    scan.curves[last].tags[mid].node = wrong;
    let curves = &scan.curves[..];
    let net = sfs::settings::Settings::default().network;
    let mut pipeline = Pipeline::new().live();
    // The scan but its last curve, settled; then the update that brings the last curve in
    // (regressed near it: provisional).
    let before = &curves[..curves.len() - 1];
    let mut products = pipeline.reconstruct(before, &net);
    pipeline.settle(before, &mut products, &net, None, || false);
    let mut products = pipeline.reconstruct(curves, &net);
    let provisional = |p: &sfs::pipeline::Products| p.network.as_ref().unwrap().report.provisional;
    assert!(provisional(&products), "the live update is provisional");
    // A curve comes in while the settle runs: the second time it is asked.
    let asked = std::cell::Cell::new(0);
    let waiting = || {
        asked.set(asked.get() + 1);
        asked.get() >= 2
    };
    assert!(!pipeline.settle(curves, &mut products, &net, None, waiting));
    assert_eq!(asked.get(), 2, "stopped where the curve was first seen");
    assert!(provisional(&products), "the update left as it was");
    // Undisturbed, it asks more than once before the network is made, and settles to the
    // network from scratch.
    let asked = std::cell::Cell::new(0);
    let never = || {
        asked.set(asked.get() + 1);
        false
    };
    assert!(pipeline.settle(curves, &mut products, &net, None, never));
    assert!(asked.get() > 2, "asked {} times", asked.get());
    assert!(!provisional(&products));
    let report = &products.network.as_ref().unwrap().report;
    assert_eq!(report.tags_detached, 1, "the wrong index detached");
    let fresh = Pipeline::new().run(curves, &exact_network(&net), None);
    assert_eq!(
        products.glb, fresh.glb,
        "the settled network is the one from scratch"
    );
}
