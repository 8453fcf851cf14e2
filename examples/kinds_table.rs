//! The curve-kinds table of BENCHMARKS.md (issue 18): the `box` and `roof` scenes simulated
//! (both devices, default profile, the given seeds), acquired, reconstructed and surfaced with
//! the default configuration twice, once with every curve smooth (their kinds set to
//! interior, as `[curves] kinds` would) and once with the kinds the operator keyed, and scored
//! as `sfs eval` scores a `network.glb` read back: surface mean / max distance to the truth
//! surface (% of the diagonal) and the dihedral angle across each crease against the truth's.
//!
//! `cargo run --release --example kinds_table -- [--seeds 1,2,3] [--scenes box,roof]
//! [--devices morphorider,phone] [--profile default|field] [--guide N]`
//!
//! Diagnostics: `SFS_TRUE_D=1` / `SFS_TRUE_Q=1` put the simulator's true distances /
//! orientations into the acquired curves, to split a surface's error by its source.
//!
//! `--guide N`: instead, curve N of each scene made a guide curve (as `[curves] kinds` would),
//! its own error (its points to the truth network, `sfs eval`'s `curves_by_kind`) against the
//! surface's distance from it (`report.json`'s `surface.guides`).

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::curve::CurveKind;
use sfs_geometry::network::NetworkParams;
use sfs_geometry::surface::fit::SurfaceParams;

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

/// A guide curve's own error and the surface's distance from it, mean and max, mm.
#[derive(Debug, Default, Clone, Copy)]
struct GuideScore {
    own_mean: f64,
    own_max: f64,
    surface_mean: f64,
    surface_max: f64,
}

fn score(
    name: &str,
    profile: Profile,
    device: DeviceKind,
    seed: u64,
    smooth: bool,
    guide: Option<usize>,
) -> Result<(Score, GuideScore), String> {
    let s = scene::builtin(name).map_err(|e| e.to_string())?;
    let sim = simulate::run(&s, device, profile, seed);
    let mut scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    // Diagnostics: the simulator's true distances and/or orientations put in.
    let (true_q, true_d) = (
        std::env::var("SFS_TRUE_Q").is_ok(),
        std::env::var("SFS_TRUE_D").is_ok(),
    );
    if true_q || true_d {
        sim.samples.put_into(&mut scan.curves, true_q, true_d);
    }
    if let Some(g) = guide {
        let c = scan.curves.get_mut(g).ok_or("no such curve")?;
        c.kind = CurveKind::Guide;
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
    let fit = products
        .surface
        .as_ref()
        .and_then(|s| s.guides.first().cloned());
    let glb = products.glb.ok_or("no glb")?;
    let rec = sfs::gltf_out::read_glb(&glb).map_err(|e| e.to_string())?;
    let e = sfs::eval::evaluate(&sim.truth, &rec).map_err(|e| e.to_string())?;
    let surf = e.surface.ok_or("no surface")?;
    let n = e.creases.len().max(1) as f64;
    let own = e.curves_by_kind.iter().find(|c| Some(c.curve) == guide);
    let g = match (own, fit) {
        (Some(own), Some(fit)) => GuideScore {
            own_mean: own.distances.mean_m * 1e3,
            own_max: own.distances.max_m * 1e3,
            surface_mean: fit.mean_m * 1e3,
            surface_max: fit.max_m * 1e3,
        },
        _ => GuideScore::default(),
    };
    let score = Score {
        surface_mean: surf.mean_pct,
        surface_max: surf.max_pct,
        dihedral_mean: e.creases.iter().map(|c| c.error_mean_deg).sum::<f64>() / n,
        dihedral_max: e
            .creases
            .iter()
            .map(|c| c.error_max_deg)
            .fold(0.0, f64::max),
        curves_mean: e.curves.mean_pct,
    };
    Ok((score, g))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: Vec<u64> = list(&args, "--seeds", "1,2,3")
        .iter()
        .map(|s| s.parse().expect("a seed"))
        .collect();
    let scenes = list(&args, "--scenes", "box,roof");
    let profile = match list(&args, "--profile", "default")[0].as_str() {
        "field" => Profile::Field,
        _ => Profile::Default,
    };
    let devices: Vec<DeviceKind> = list(&args, "--devices", "morphorider,phone")
        .iter()
        .map(|d| match d.as_str() {
            "phone" => DeviceKind::Phone,
            _ => DeviceKind::Morphorider,
        })
        .collect();
    if let Some(g) = args
        .iter()
        .position(|a| a == "--guide")
        .and_then(|i| args.get(i + 1))
    {
        let g: usize = g.parse().expect("a curve index");
        println!("| scene | device | seed | curve {g} as a guide: its own error mean / max, mm | the surface from it: mean / max, mm |");
        println!("|---|---|---|---|---|");
        for name in &scenes {
            for &device in &devices {
                for &seed in &seeds {
                    match score(name, profile, device, seed, false, Some(g)) {
                        Ok((_, s)) => println!(
                            "| {name} | {} | {seed} | {:.2} / {:.2} | {:.2} / {:.2} |",
                            device.name(),
                            s.own_mean,
                            s.own_max,
                            s.surface_mean,
                            s.surface_max
                        ),
                        Err(e) => eprintln!("{name} {} seed {seed}: {e}", device.name()),
                    }
                }
            }
        }
        return;
    }
    println!("| scene | device | seed | curves mean % | smooth: surface mean / max % | dihedral error mean / max ° | kinds: surface mean / max % | dihedral error mean / max ° |");
    println!("|---|---|---|---|---|---|---|---|");
    for name in &scenes {
        for &device in &devices {
            for &seed in &seeds {
                let cell = |smooth| match score(name, profile, device, seed, smooth, None) {
                    Ok((s, _)) => s,
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
