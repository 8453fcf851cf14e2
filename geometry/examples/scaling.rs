//! The scaling table of BENCHMARKS.md (issue 19, point 4): the time to surface a network from
//! scratch, against the surface's size (the unit sphere's cube network, 2 k … 200 k vertices)
//! and against the network's size (the unit sphere's latitude–longitude network, 5 … 100
//! curves, the default vertex budget), cold (symbolic factorisations computed) and warm (kept
//! from the previous surface of the same network), with the exponent of a power law fitted
//! to each column. Writes the rows as CSV to the path given (for `benches/scaling_plot.py`).
//!
//! `cargo run --release -p sfs-geometry --example scaling [-- target/scaling.csv]`

use sfs_geometry::surface::analytic::{sphere_cube, sphere_grid};
use sfs_geometry::surface::cycles::NetworkSegments;
use sfs_geometry::surface::fit::{SurfaceParams, Surfacer};
use std::time::Instant;

/// Cold and warm wall time (ms, the best of `runs`) and the vertex count.
fn time(net: &NetworkSegments, p: &SurfaceParams, runs: usize) -> (f64, f64, usize) {
    let (mut cold, mut warm, mut nv) = (f64::MAX, f64::MAX, 0);
    for _ in 0..runs {
        let mut s = Surfacer::new();
        let t0 = Instant::now();
        let out = s.run(net, p).expect("a surface");
        cold = cold.min(t0.elapsed().as_secs_f64() * 1e3);
        nv = out.positions.len();
        let t0 = Instant::now();
        s.run(net, p).expect("a surface");
        warm = warm.min(t0.elapsed().as_secs_f64() * 1e3);
    }
    (cold, warm, nv)
}

/// The process's peak resident size so far (`VmHWM`), bytes (0 where /proc is not there).
fn peak_rss() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|k| k.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb * 1024.0)
}

/// The exponent `b` of `y = a xᵇ`, least squares in log–log.
fn exponent(xy: &[(f64, f64)]) -> f64 {
    let n = xy.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) = xy.iter().map(|(x, y)| (x.ln(), y.ln())).unzip();
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx).powi(2)).sum();
    sxy / sxx
}

/// One column of the table: per row its x (vertices or curves), vertex count, cold and warm
/// times (ms).
struct Series {
    name: &'static str,
    rows: Vec<(f64, usize, f64, f64)>,
}

impl Series {
    /// Its rows as CSV lines.
    fn csv(&self) -> String {
        self.rows
            .iter()
            .map(|(x, nv, cold, warm)| format!("{},{x},{nv},{cold:.3},{warm:.3}\n", self.name))
            .collect()
    }

    /// The fitted exponents of the cold and warm times against x.
    fn exponents(&self) -> (f64, f64) {
        let pick = |f: fn(&(f64, usize, f64, f64)) -> f64| -> Vec<(f64, f64)> {
            self.rows.iter().map(|r| (r.0, f(r))).collect()
        };
        (exponent(&pick(|r| r.2)), exponent(&pick(|r| r.3)))
    }
}

fn main() {
    // As the daemon runs (faer's parallel factorisation is slower on this machine's 2 cores).
    sfs_geometry::sparse_llt::single_threaded();
    let csv_path = std::env::args().nth(1);
    // Surface size: the cube network at a spacing for each target count (10 k at 0.02).
    // The sizes grow, so each one's peak resident size is the process's peak after it.
    println!(
        "| vertices | from scratch, cold | from scratch, warm | peak resident size per vertex |"
    );
    println!("|---|---|---|---|");
    let mut by_size = Series {
        name: "vertices",
        rows: Vec::new(),
    };
    for target in [
        2_000.0,
        5_000.0,
        10_000.0,
        20_000.0,
        50_000.0,
        100_000.0,
        200_000.0f64,
    ] {
        let s = 0.02 * (16_000.0 / target).sqrt();
        let p = SurfaceParams {
            edge: Some(1.35 * s),
            max_vertices: usize::MAX,
            ..SurfaceParams::default()
        };
        let runs = if target <= 20_000.0 { 3 } else { 1 };
        let (cold, warm, nv) = time(&sphere_cube(s), &p, runs);
        let per_vertex = peak_rss() / nv as f64 / 1e3;
        println!("| {nv} | {cold:.1} ms | {warm:.1} ms | {per_vertex:.1} kB |");
        by_size.rows.push((nv as f64, nv, cold, warm));
    }
    let (cold, warm) = by_size.exponents();
    println!("| exponent | {cold:.2} | {warm:.2} | |");
    // Network size: the grid at the default edge and budget.
    println!();
    println!("| curves | vertices | from scratch, cold | from scratch, warm |");
    println!("|---|---|---|---|");
    let mut by_curves = Series {
        name: "curves",
        rows: Vec::new(),
    };
    for curves in [5usize, 10, 20, 50, 100] {
        let meridians = curves.div_ceil(2);
        let net = sphere_grid(meridians, curves - meridians, 0.01);
        let (cold, warm, nv) = time(&net, &SurfaceParams::default(), 3);
        println!("| {curves} | {nv} | {cold:.1} ms | {warm:.1} ms |");
        by_curves.rows.push((curves as f64, nv, cold, warm));
    }
    let (cold, warm) = by_curves.exponents();
    println!("| exponent | | {cold:.2} | {warm:.2} |");
    let csv = format!(
        "series,x,vertices,cold_ms,warm_ms\n{}{}",
        by_size.csv(),
        by_curves.csv()
    );
    if let Some(path) = csv_path {
        std::fs::write(&path, csv).expect("the CSV written");
        eprintln!("rows in {path}");
    }
}
