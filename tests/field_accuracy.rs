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
