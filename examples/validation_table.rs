//! The validation table of BENCHMARKS.md (issue 33): the captures of the independent simulator
//! (`../shared/validation/`, beside the repository; never read by the tests), each acquired and
//! reconstructed with the default configuration as `sfs replay` does and scored as `sfs eval`
//! does (curve mean error, % of the truth network's bounding-box diagonal), beside its target
//! and its figure before the field-accuracy work (from that directory's README).
//!
//! `cargo run --release --example validation_table -- [--dir DIR] [--captures a,b]
//! [--config FILE]`
//!
//! Columns: the error now; the target (Morphorider rough 0.30, phone clean 0.40, phone rough
//! 0.80); the figure before the field-accuracy work (baa97be) and at 1b493a8, both from the
//! README; whether the target is met, and whether the capture is within 5 % of its figure
//! before. Runs two captures at a time (about 20 s for the 14).

use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs_geometry::network::{NetworkParams, Reconstructor};
use std::path::{Path, PathBuf};

#[path = "shared/mod.rs"]
mod shared;
use shared::{list, parallel};

/// `(before, at 1b493a8, target)` of each capture, from the README's table.
fn readme_figures(dir: &Path) -> std::collections::HashMap<String, (f64, f64, f64)> {
    let text = std::fs::read_to_string(dir.join("README.md")).unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(|c| c.trim()).collect();
            if cells.len() < 6 {
                return None;
            }
            let num = |s: &str| s.trim_matches('*').parse::<f64>().ok();
            Some((
                cells[1].to_owned(),
                (num(cells[2])?, num(cells[3])?, num(cells[4])?),
            ))
        })
        .collect()
}

/// The curve mean error of one capture, % of the diagonal, or why there is none.
fn score(
    bin: &Path,
    truth: &Path,
    settings: &(AcquisitionConfig, NetworkParams),
) -> Result<f64, String> {
    let bytes = std::fs::read(bin).map_err(|e| format!("{}: {e}", bin.display()))?;
    let truth = sfs::simulate::truth::Truth::load(truth).map_err(|e| e.to_string())?;
    let scan = Acquisition::scan_bytes(&bytes, settings.0.clone());
    let net = Reconstructor::new()
        .run(&scan.curves, &settings.1)
        .map_err(|e| format!("{:?}", e.warnings))?;
    let e = sfs::eval::evaluate(&truth, &sfs::gltf_out::as_read_network(&net.positions))
        .map_err(|e| e.to_string())?;
    Ok(e.curves.mean_pct)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = args
        .iter()
        .position(|a| a == "--dir")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/validation"));
    let settings = shared::config(&args);
    let figures = readme_figures(&dir);
    let mut captures: Vec<String> = match args.iter().any(|a| a == "--captures") {
        true => list(&args, "--captures", ""),
        false => std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                name.strip_suffix(".bin").map(str::to_owned)
            })
            .collect(),
    };
    captures.sort_by_key(|c| (c.contains("phone"), c.contains("rough"), c.clone()));
    let results = parallel(&captures, |c| {
        score(
            &dir.join(format!("{c}.bin")),
            &dir.join(format!("{c}.truth.json")),
            &settings,
        )
    });
    println!("| capture | error | target | before (baa97be) | 1b493a8 | target met | within 5 % of before |");
    println!("|---|---|---|---|---|---|---|");
    let (mut met, mut kept) = (0, 0);
    for (c, r) in captures.iter().zip(&results) {
        let (before, then, target) =
            figures
                .get(c)
                .copied()
                .unwrap_or((f64::NAN, f64::NAN, f64::NAN));
        match r {
            Ok(e) => {
                let ok = *e <= target;
                let held = *e <= before * 1.05;
                met += usize::from(ok);
                kept += usize::from(held);
                println!(
                    "| {c} | {} | {target:.2} | {before:.3} | {then:.3} | {} | {} |",
                    if ok {
                        format!("{e:.3}")
                    } else {
                        format!("**{e:.3}**")
                    },
                    if ok { "yes" } else { "no" },
                    if held { "yes" } else { "no" },
                );
            }
            Err(e) => {
                println!("| {c} | failed: {e} | {target:.2} | {before:.3} | {then:.3} | no | no |")
            }
        }
    }
    println!(
        "\n{met} of {} captures meet their target; {kept} are within 5 % of their figure before the field-accuracy work.",
        captures.len()
    );
}
