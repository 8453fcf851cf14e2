//! The curve-kinds table of BENCHMARKS.md (issue 18): the `box` and `roof` scenes simulated
//! (both devices, default profile, the given seeds), acquired, reconstructed and surfaced with
//! the default configuration twice, once with every curve smooth (their kinds set to
//! interior, as `[curves] kinds` would) and once with the kinds the operator keyed, and scored
//! as `sfs eval` scores a `network.glb` read back: surface mean / max distance to the truth
//! surface (% of the diagonal) and the dihedral angle across each crease against the truth's.
//!
//! `cargo run --release --example kinds_table -- [--seeds 1,2,3] [--scenes box,roof]
//! [--devices morphorider,phone]`

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::curve::CurveKind;
use sfs_geometry::network::NetworkParams;
use sfs_geometry::surface::fit::SurfaceParams;
use std::path::PathBuf;

#[path = "shared/mod.rs"]
mod shared;
use shared::list;

/// Surface mean and max (% of the diagonal), dihedral mean and max error (°), curve mean.
#[derive(Debug, Default, Clone, Copy)]
struct Score {
    surface_mean: f64,
    surface_max: f64,
    dihedral_mean: f64,
    dihedral_max: f64,
    curves_mean: f64,
}

fn score(name: &str, device: DeviceKind, seed: u64, smooth: bool) -> Result<Score, String> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/scenes");
    let s = scene::load(&scene::find(name, &dir)).map_err(|e| e.to_string())?;
    let sim = simulate::run(&s, device, Profile::Default, seed);
    let mut scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    // Diagnostic: the simulator's true distances put in.
    if std::env::var("SFS_TRUE_D").is_ok() {
        sim.samples.put_into(&mut scan.curves, false, true);
    }
    if smooth {
        for c in &mut scan.curves {
            if matches!(c.kind, CurveKind::Crease | CurveKind::Guide) {
                c.kind = CurveKind::Interior;
            }
        }
    }
    let surface = SurfaceParams {
        soft: sfs::pipeline::SCAN_SOFTNESS,
        ..SurfaceParams::default()
    };
    let products =
        sfs::pipeline::Pipeline::new().run(&scan.curves, &NetworkParams::default(), Some(&surface));
    let glb = products.glb.ok_or("no glb")?;
    let rec = sfs::gltf_out::read_glb(&glb).map_err(|e| e.to_string())?;
    let e = sfs::eval::evaluate(&sim.truth, &rec).map_err(|e| e.to_string())?;
    let surf = e.surface.ok_or("no surface")?;
    let n = e.creases.len().max(1) as f64;
    Ok(Score {
        surface_mean: surf.mean_pct,
        surface_max: surf.max_pct,
        dihedral_mean: e.creases.iter().map(|c| c.error_mean_deg).sum::<f64>() / n,
        dihedral_max: e
            .creases
            .iter()
            .map(|c| c.error_max_deg)
            .fold(0.0, f64::max),
        curves_mean: e.curves.mean_pct,
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: Vec<u64> = list(&args, "--seeds", "1,2,3")
        .iter()
        .map(|s| s.parse().expect("a seed"))
        .collect();
    let scenes = list(&args, "--scenes", "box,roof");
    let devices: Vec<DeviceKind> = list(&args, "--devices", "morphorider,phone")
        .iter()
        .map(|d| match d.as_str() {
            "phone" => DeviceKind::Phone,
            _ => DeviceKind::Morphorider,
        })
        .collect();
    println!("| scene | device | seed | curves mean % | smooth: surface mean / max % | dihedral error mean / max ° | kinds: surface mean / max % | dihedral error mean / max ° |");
    println!("|---|---|---|---|---|---|---|---|");
    for name in &scenes {
        for &device in &devices {
            for &seed in &seeds {
                let cell = |smooth| match score(name, device, seed, smooth) {
                    Ok(s) => s,
                    Err(e) => {
                        eprintln!("{name} {} seed {seed}: {e}", device.name());
                        Score::default()
                    }
                };
                let (a, b) = std::thread::scope(|sc| {
                    let h = sc.spawn(|| cell(true));
                    let b = cell(false);
                    (h.join().expect("a cell"), b)
                });
                println!(
                    "| {name} | {} | {seed} | {:.3} | {:.3} / {:.2} | {:.1} / {:.1} | {:.4} / {:.3} | {:.2} / {:.2} |",
                    device.name(),
                    b.curves_mean,
                    a.surface_mean,
                    a.surface_max,
                    a.dihedral_mean,
                    a.dihedral_max,
                    b.surface_mean,
                    b.surface_max,
                    b.dihedral_mean,
                    b.dihedral_max,
                );
            }
        }
    }
}
