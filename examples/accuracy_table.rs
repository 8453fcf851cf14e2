//! The accuracy table of BENCHMARKS.md: every shipped scene simulated (both devices, both
//! profiles, the given seeds), acquired and reconstructed with the default configuration, and
//! scored with the paper's metric (mean distance of the curve points to the truth network
//! after rigid registration, % of the bounding-box diagonal).
//!
//! `cargo run --release --example accuracy_table -- [--seeds 1,2,3] [--devices morphorider,phone]
//! [--profiles default,field] [--scenes a,b]`
//!
//! Each cell runs the library as `sfs simulate` + `sfs replay` + `sfs eval` do (in process,
//! two cells at a time).

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::network::{NetworkParams, Reconstructor};
use std::path::PathBuf;

const SCENES: &[&str] = &[
    "sphere-cube",
    "sphere-octa",
    "torus",
    "cone",
    "bowl",
    "lilium",
    "bumpy-cube",
];

fn list(args: &[String], flag: &str, default: &str) -> Vec<String> {
    args.iter()
        .position(|a| a == flag)
        .and_then(|i| args.get(i + 1))
        .map_or(default, |s| s.as_str())
        .split(',')
        .map(str::to_owned)
        .collect()
}

/// Mean and max error in % of the diagonal, or why there is none.
fn cell(name: &str, device: DeviceKind, profile: Profile, seed: u64) -> Result<(f64, f64), String> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/scenes");
    let s = scene::load(&scene::find(name, &dir)).map_err(|e| e.to_string())?;
    let sim = simulate::run(&s, device, profile, seed);
    let scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    let net = Reconstructor::new()
        .run(&scan.curves, &NetworkParams::default())
        .map_err(|e| format!("{:?}", e.warnings))?;
    let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
        .map_err(|e| e.to_string())?;
    Ok((e.curves.mean_pct, e.curves.max_pct))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: Vec<u64> = list(&args, "--seeds", "1")
        .iter()
        .map(|s| s.parse().expect("--seeds: numbers separated by commas"))
        .collect();
    let devices: Vec<DeviceKind> = list(&args, "--devices", "morphorider,phone")
        .iter()
        .map(|d| match d.as_str() {
            "phone" => DeviceKind::Phone,
            "morphorider" => DeviceKind::Morphorider,
            other => panic!("--devices: {other} is not morphorider or phone"),
        })
        .collect();
    let profiles: Vec<Profile> = list(&args, "--profiles", "default,field")
        .iter()
        .map(|p| match p.as_str() {
            "default" => Profile::Default,
            "field" => Profile::Field,
            other => panic!("--profiles: {other} is not default or field"),
        })
        .collect();
    let scenes = list(&args, "--scenes", &SCENES.join(","));
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
        .flat_map(|s| columns.iter().map(move |&(d, p, seed)| (s.clone(), d, p, seed)))
        .collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(vec![None; jobs.len()]);
    std::thread::scope(|sc| {
        for _ in 0..2 {
            sc.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some((s, d, p, seed)) = jobs.get(i) else {
                    return;
                };
                let r = cell(s, *d, *p, *seed);
                results.lock().unwrap()[i] = Some(r);
            });
        }
    });
    let results = results.into_inner().unwrap();
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
                Some(Ok((mean, max))) => print!(" {mean:.3} / {max:.2} |"),
                Some(Err(e)) => print!(" failed: {e} |"),
                None => print!(" — |"),
            }
        }
        println!();
    }
}
