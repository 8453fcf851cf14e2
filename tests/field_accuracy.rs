//! Issue 17, point 5: the field profile's accuracy with the default configuration, pinned for
//! two scenes per device at the issue's targets (Morphorider ≤ 0.30 % over three seeds, phone
//! ≤ 0.80 % of the diagonal, the paper's metric against the simulator's truth). The whole table is in
//! BENCHMARKS.md (`cargo run --release --example accuracy_table`).

mod common;

use device_protocol::DeviceKind;

/// Mean error of the scene's field capture, % of the diagonal.
fn field_error(name: &str, device: DeviceKind, seed: u64) -> f64 {
    common::field_error(name, device, seed, &[])
}

#[test]
fn issue_17_morphorider_field_accuracy_on_bowl_and_relief() {
    morphorider_meets_the_target(&["bowl", "relief"]);
}

#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn issue_17_morphorider_field_accuracy_on_lilium() {
    morphorider_meets_the_target(&["lilium"]);
}

/// The mean over seeds 1–3 at the target, each seed within 1.5 × (issue 33: one seed is one
/// draw of the wheel's slips; when the simulator's operator began easing into the nodes the
/// bowl's seed 1 went from 0.289 to 0.301 %, its mean from 0.354 to 0.234 %).
fn morphorider_meets_the_target(scenes: &[&str]) {
    for &scene in scenes {
        let e: Vec<f64> = (1..=3)
            .map(|seed| field_error(scene, DeviceKind::Morphorider, seed))
            .collect();
        let mean = e.iter().sum::<f64>() / 3.0;
        eprintln!("{scene} morphorider field: {e:.3?} %, mean {mean:.3} %");
        assert!(
            mean <= 0.30 && e.iter().all(|&x| x <= 0.45),
            "{scene}: {e:.3?} % of the diagonal (target: mean 0.30 %, each 0.45 %)"
        );
    }
}

#[test]
fn issue_17_phone_field_accuracy_on_sphere_octa_and_torus() {
    for scene in ["sphere-octa", "torus"] {
        let e = field_error(scene, DeviceKind::Phone, 1);
        eprintln!("{scene} phone field: {e:.3} %");
        assert!(
            e <= 0.80,
            "{scene}: {e:.3} % of the diagonal (target 0.80 %)"
        );
    }
}

/// Issue 33: the field profile's wheel skids (about 25 mm each, as the independent
/// simulator's) are found from the accelerometer and filled, and the network is the better for
/// it. Sphere-octa, seed 1: the skids the acquisition reports each add 10–40 mm, at least two
/// of the three are found, and nothing else is taken for one.
#[test]
fn issue_33_the_wheel_skids_are_found_and_filled() {
    use sfs::acquisition::{Acquisition, AcquisitionConfig};
    use sfs_geometry::network::{NetworkParams, Reconstructor};
    let s = sfs::simulate::scene::builtin("sphere-octa").expect("shipped scene");
    let sim = sfs::simulate::run(
        &s,
        DeviceKind::Morphorider,
        sfs::simulate::Profile::Field,
        1,
    );
    let skids_made = sim
        .truth
        .events
        .iter()
        .filter(|e| e.contains("wheel skid"))
        .count();
    assert_eq!(skids_made, 3, "{:?}", sim.truth.events);
    let error = |fill: bool| {
        let cfg = AcquisitionConfig {
            fill_skids: fill,
            ..AcquisitionConfig::default()
        };
        let scan = Acquisition::scan_bytes(&sim.bytes, cfg);
        let net = Reconstructor::new()
            .run(&scan.curves, &NetworkParams::default())
            .expect("the field capture reconstructs");
        let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
            .expect("evaluates");
        (e.curves.mean_pct, scan.warnings)
    };
    let (filled, warnings) = error(true);
    let skids: Vec<String> = warnings
        .iter()
        .filter(|w| w.code() == "wheel_skid")
        .map(|w| w.to_string())
        .collect();
    eprintln!("{skids:#?}");
    assert!(
        (2..=3).contains(&skids.len()),
        "{} skids found of 3: {skids:#?}",
        skids.len()
    );
    for s in &skids {
        let mm: f64 = s
            .split("; ")
            .nth(1)
            .and_then(|x| x.split(' ').next())
            .and_then(|x| x.parse().ok())
            .unwrap_or_else(|| panic!("no mm in {s}"));
        assert!((10.0..=40.0).contains(&mm), "{s}");
    }
    let (unfilled, _) = error(false);
    eprintln!("sphere-octa morphorider field s1: {filled:.3} % filled, {unfilled:.3} % not");
    assert!(
        filled < unfilled,
        "filled {filled:.3} %, unfilled {unfilled:.3} %"
    );
}
