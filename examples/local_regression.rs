//! The local regression of BENCHMARKS.md (issue 19, point 2): each scene simulated, acquired,
//! and reconstructed curve by curve as a live session does, twice — the whole network
//! regressed at every update, and only the frames near the new curve (`[network]
//! local_window`, each update starting from the last local one: no settling in between, the
//! worst case) — and compared: the largest distance between the two networks' points (% of
//! the diagonal) and between their normals (°) over every update, the regression's time summed
//! over the updates, and the frames the local runs moved.
//!
//! `cargo run --release --example local_regression -- [--scenes lilium,torus]
//! [--windows 5,10,30] [--devices morphorider,phone] [--profile default|field] [--seed 1]`

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::network::{NetworkParams, Reconstructor};

#[path = "shared/mod.rs"]
mod shared;
use shared::list;

fn main() {
    sfs_geometry::sparse_llt::single_threaded();
    let args: Vec<String> = std::env::args().collect();
    let scenes = list(&args, "--scenes", "lilium,torus,sphere-octa,cone,bowl");
    let windows: Vec<usize> = list(&args, "--windows", "5,10,30")
        .iter()
        .map(|w| w.parse().expect("--windows: sample counts"))
        .collect();
    let devices = list(&args, "--devices", "morphorider");
    let profile = match list(&args, "--profile", "default")[0].as_str() {
        "field" => Profile::Field,
        _ => Profile::Default,
    };
    let seed: u64 = list(&args, "--seed", "1")[0]
        .parse()
        .expect("--seed: a number");
    println!("| scene | device | window | points (% of diagonal) | normals (°) | regression, whole | regression, local | frames moved |");
    println!("|---|---|---|---|---|---|---|---|");
    for name in &scenes {
        let s = scene::builtin(name).expect("a shipped scene");
        let diag = s.bbox_diagonal();
        for device in &devices {
            let kind = match device.as_str() {
                "phone" => DeviceKind::Phone,
                _ => DeviceKind::Morphorider,
            };
            let sim = simulate::run(&s, kind, profile, seed);
            let scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
            for &window in &windows {
                let (mut local, mut whole) = (Reconstructor::new(), Reconstructor::new());
                let pl = NetworkParams {
                    local_window: window,
                    ..Default::default()
                };
                let pw = NetworkParams::default();
                let (mut pos, mut ang, mut tl, mut tw, mut moved, mut frames) =
                    (0.0f64, 0.0f64, 0.0, 0.0, 0, 0);
                for k in 1..=scan.curves.len() {
                    let curves = &scan.curves[..k];
                    let (Ok(a), Ok(b)) = (local.run(curves, &pl), whole.run(curves, &pw)) else {
                        continue;
                    };
                    tl += a.report.timings_ms.regression;
                    tw += b.report.timings_ms.regression;
                    moved += a.report.regression.frames_moved;
                    frames += a.report.regression.frames;
                    for (ca, cb) in a.positions.curves.iter().zip(&b.positions.curves) {
                        for (pa, pb) in ca.points.iter().zip(&cb.points) {
                            pos = pos.max((pa - pb).norm() / diag);
                        }
                        for (na, nb) in ca.normals.iter().zip(&cb.normals) {
                            ang = ang.max(na.angle(nb).to_degrees());
                        }
                    }
                }
                println!(
                    "| {name} | {device} | {window} | {:.1e} | {ang:.1e} | {tw:.1} ms | {tl:.1} ms | {moved} of {frames} |",
                    pos * 100.0
                );
            }
        }
    }
}
