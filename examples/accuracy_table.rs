//! The accuracy table of BENCHMARKS.md: every shipped scene simulated (both devices, both
//! profiles, the given seeds), acquired and reconstructed with the default configuration, and
//! scored with the paper's metric (mean distance of the curve points to the truth network
//! after rigid registration, % of the bounding-box diagonal).
//!
//! `cargo run --release --example accuracy_table -- [--seeds 1,2,3] [--devices morphorider,phone]
//! [--profiles default,field] [--scenes a,b] [--study] [--config FILE] [--no-skids]`
//!
//! `--config FILE`: the acquisition and network settings of a configuration file instead of
//! the defaults. `--no-skids`: the Morphorider's wheel skids left unfilled.
//!
//! Each cell runs the library as `sfs simulate` + `sfs replay` + `sfs eval` do (in process,
//! two cells at a time).
//!
//! `--study`: what each fault costs and where the error comes from. Per device and profile,
//! the mean error over the seeds with every fault of the field profile, then with each fault
//! turned off in turn, then with the true orientations (estimated distances), the true
//! distances (estimated orientations) and both, put into the acquired curves sample by sample
//! from the simulator's truth.

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Fault, Mistakes, Profile};
use sfs_geometry::network::{NetworkParams, Reconstructor};

#[path = "shared/mod.rs"]
mod shared;
use shared::{config, list, parallel};

const SCENES: &[&str] = &[
    "sphere-cube",
    "sphere-octa",
    "torus",
    "cone",
    "bowl",
    "lilium",
    "bumpy-cube",
];

/// A variant of a cell: faults of the field profile turned off, true orientations or
/// distances put in.
#[derive(Debug, Clone, Default)]
struct Variant {
    without: Vec<Fault>,
    true_q: bool,
    true_d: bool,
}

impl Variant {
    fn name(&self) -> String {
        let mut parts: Vec<String> = self
            .without
            .iter()
            .map(|f| format!("no {}", f.name()))
            .collect();
        if self.true_q {
            parts.push("true q".into());
        }
        if self.true_d {
            parts.push("true d".into());
        }
        if parts.is_empty() {
            "as simulated".into()
        } else {
            parts.join(", ")
        }
    }
}

/// Mean and max error in % of the diagonal of one cell with `settings` (acquisition,
/// network), or why there is none.
fn variant(
    name: &str,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    v: &Variant,
    settings: &(AcquisitionConfig, NetworkParams),
) -> Result<(f64, f64), String> {
    let s = scene::builtin(name).map_err(|e| e.to_string())?;
    let sim = simulate::run_without(&s, device, profile, seed, &Mistakes::default(), &v.without);
    let mut scan = Acquisition::scan_bytes(&sim.bytes, settings.0.clone());
    if v.true_q || v.true_d {
        let missed = sim.samples.put_into(&mut scan.curves, v.true_q, v.true_d);
        if missed > 0 {
            eprintln!(
                "{name} {} seed {seed}: {missed} samples without truth",
                device.name()
            );
        }
    }
    let net = sfs_geometry::network::join::run_joined(
        &mut Reconstructor::new(),
        &scan.curves,
        &settings.1,
        &Default::default(),
    )
    .map_err(|e| format!("{:?}", e.warnings))?;
    let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
        .map_err(|e| e.to_string())?;
    Ok((e.curves.mean_pct, e.curves.max_pct))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds = shared::seeds(&args, "1");
    let devices = shared::devices(&args);
    let profiles = shared::profiles(&args);
    let scenes = list(&args, "--scenes", &SCENES.join(","));
    let settings = config(&args);
    if args.iter().any(|a| a == "--study") {
        return study(&scenes, &devices, &profiles, &seeds, &settings);
    }
    let mut columns = Vec::new();
    for &d in &devices {
        for &p in &profiles {
            for &seed in &seeds {
                columns.push((d, p, seed));
            }
        }
    }
    let jobs: Vec<(String, DeviceKind, Profile, u64)> = scenes
        .iter()
        .flat_map(|s| {
            columns
                .iter()
                .map(move |&(d, p, seed)| (s.clone(), d, p, seed))
        })
        .collect();
    let results = parallel(&jobs, |(s, d, p, seed)| {
        variant(s, *d, *p, *seed, &Variant::default(), &settings)
    });
    print!("| scene |");
    for (d, p, seed) in &columns {
        print!(" {} {} s{seed} |", d.name(), p.name());
    }
    println!();
    println!("|---|{}", "---|".repeat(columns.len()));
    for (k, s) in scenes.iter().enumerate() {
        print!("| {s} |");
        for j in 0..columns.len() {
            match &results[k * columns.len() + j] {
                Ok((mean, max)) => print!(" {mean:.3} / {max:.2} |"),
                Err(e) => print!(" failed: {e} |"),
            }
        }
        println!();
    }
}

/// The fault study (`--study`): one table per device and profile, a column per variant, the
/// mean error over the seeds per scene and the mean over the scenes.
fn study(
    scenes: &[String],
    devices: &[DeviceKind],
    profiles: &[Profile],
    seeds: &[u64],
    settings: &(AcquisitionConfig, NetworkParams),
) {
    for &device in devices {
        for &profile in profiles {
            let mut variants = vec![Variant::default()];
            if profile == Profile::Field {
                for f in Fault::ALL {
                    let relevant = match f {
                        Fault::GyroBias => device == DeviceKind::Phone,
                        Fault::Skids => device == DeviceKind::Morphorider,
                        _ => true,
                    };
                    if relevant {
                        variants.push(Variant {
                            without: vec![f],
                            ..Variant::default()
                        });
                    }
                }
            }
            for (q, d) in [(true, false), (false, true), (true, true)] {
                variants.push(Variant {
                    true_q: q,
                    true_d: d,
                    ..Variant::default()
                });
            }
            let jobs: Vec<(usize, usize, u64)> = (0..scenes.len())
                .flat_map(|s| {
                    (0..variants.len()).flat_map(move |v| seeds.iter().map(move |&x| (s, v, x)))
                })
                .collect();
            let results = parallel(&jobs, |&(s, v, seed)| {
                variant(&scenes[s], device, profile, seed, &variants[v], settings)
            });
            println!(
                "\n{} {}, mean error % of the diagonal, mean over seeds {:?}\n",
                device.name(),
                profile.name(),
                seeds
            );
            print!("| scene |");
            for v in &variants {
                print!(" {} |", v.name());
            }
            println!();
            println!("|---|{}", "---|".repeat(variants.len()));
            let mut sums = vec![0.0; variants.len()];
            for (si, s) in scenes.iter().enumerate() {
                print!("| {s} |");
                for (vi, sum) in sums.iter_mut().enumerate() {
                    let vals: Vec<f64> = jobs
                        .iter()
                        .zip(&results)
                        .filter(|((a, b, _), _)| *a == si && *b == vi)
                        .filter_map(|(_, r)| r.as_ref().ok().map(|x| x.0))
                        .collect();
                    if vals.len() == seeds.len() {
                        let m = vals.iter().sum::<f64>() / vals.len() as f64;
                        *sum += m / scenes.len() as f64;
                        print!(" {m:.3} |");
                    } else {
                        *sum = f64::NAN;
                        print!(" failed |");
                    }
                }
                println!();
            }
            print!("| **mean** |");
            for m in sums {
                print!(" **{m:.3}** |");
            }
            println!();
        }
    }
}
