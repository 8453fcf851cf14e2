//! The scaling table of BENCHMARKS.md (issue 19, point 4): the time to surface a network
//! from scratch and to update the surface after one more curve, against the surface's size
//! (the unit sphere's latitude–longitude network of 6 meridians and 5 parallels, 2 k … 200 k
//! vertices) and against the network's size (the same network with 5 … 100 curves, the
//! default vertex budget), with the exponent of a power law fitted to each column. Writes the
//! rows as CSV to the path given (for `benches/scaling_plot.py`).
//!
//! Columns (ms, best of `runs`):
//! - `cold`: from scratch, symbolic factorisations computed;
//! - `warm`: from scratch again with the factorisations' patterns kept (the same network);
//! - `exact`: the update after meridian 1 is added to the network without it, exact policy
//!   (`reuse_tolerance` 0: faces kept only when bit for bit the same, at the same edge; the
//!   surface a run from scratch gives; at the default edge, which the budget changes with the
//!   network, none is);
//! - `provisional`: the same update with `reuse_tolerance` 0.5 (one pass, the kept faces'
//!   weights from the last surface);
//! - `again`: the same network once more with the tolerance (the system unchanged: the
//!   factorisation kept, back-substitutions only: a monitored structure's epochs).
//!
//! And the two phases of a live update against the network's size (issue 35, point 3; 150
//! and 200 curves added for issue 51): the same grids' curves sampled as a device would give
//! them (distance along, frames whose x is the tangent and z the surface normal, exact),
//! then, after the network without meridian 1, the update that adds it as the live worker
//! runs it:
//! - `curves`: the network reconstructed (pre-filter, the loop-closure test, the regression
//!   local to 3 samples either side of the new curve's nodes as the daemon's
//!   `LIVE_LOCAL_WINDOW` (10 before issue 51), Poisson: what the view's `curves` event
//!   publishes);
//! - `surface`: the nodes' uncertainty (left to the second phase since issue 51) and the
//!   surface, provisional (τ = 0.5, after the surface of the network without the meridian);
//! - `update`: both (what `network.glb` waits for);
//! - `settle`: what the worker does next while idle: the whole network's regression and the
//!   exact surface (τ = 0), replacing the provisional update.
//!
//! `cargo run --release -p sfs-geometry --example scaling [-- [--phases] target/scaling.csv]`
//! (`--phases`: the live update's table alone, a few minutes instead of a quarter of an hour;
//! `--curves=N`: its row of N curves alone).

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use sfs_geometry::curve::{Curve, Samples, Tag};
use sfs_geometry::network::{NetworkParams, Reconstructor};
use sfs_geometry::surface::analytic::sphere_grid;
use sfs_geometry::surface::cycles::{NetworkSegments, Segment};
use sfs_geometry::surface::fit::{SurfaceParams, Surfacer};
use std::collections::BTreeMap;
use std::time::Instant;

const COLUMNS: [&str; 5] = ["cold", "warm", "exact", "provisional", "again"];
/// The columns of the live update's phases.
const PHASES: [&str; 4] = ["curves", "surface", "update", "settle"];

/// Wall time of `f`, ms.
fn ms<T>(f: impl FnOnce() -> T) -> (f64, T) {
    let t0 = Instant::now();
    let out = f();
    (t0.elapsed().as_secs_f64() * 1e3, out)
}

/// One row: the vertex count, faces touched by the new curve (of all), and the columns' times.
fn row(net: &NetworkSegments, p: &SurfaceParams, runs: usize) -> (usize, String, [f64; 5]) {
    let mut without = net.clone();
    without.segments.retain(|s| s.curve != 1);
    let mut best = [f64::MAX; 5];
    let (mut nv, mut touched) = (0, String::new());
    for _ in 0..runs {
        let mut s = Surfacer::new();
        let (cold, out) = ms(|| s.run(net, p).expect("a surface"));
        let (warm, _) = ms(|| s.run(net, p).expect("a surface"));
        nv = out.positions.len();
        let mut s = Surfacer::new();
        s.run(&without, p).expect("a surface");
        let (exact, _) = ms(|| s.run(net, p).expect("a surface"));
        let q = SurfaceParams {
            reuse_tolerance: 0.5,
            ..*p
        };
        let mut s = Surfacer::new();
        s.run(&without, &q).expect("a surface");
        let (provisional, out) = ms(|| s.run(net, &q).expect("a surface"));
        let faces = out.cycles.patches.len();
        touched = format!("{} of {faces}", faces - out.faces_kept);
        // The new faces take their weights from that surface: once more, then the same.
        s.run(net, &q).expect("a surface");
        let (again, _) = ms(|| s.run(net, &q).expect("a surface"));
        for (b, t) in best.iter_mut().zip([cold, warm, exact, provisional, again]) {
            *b = b.min(t);
        }
    }
    (nv, touched, best)
}

/// The curves of `net` as a device samples them: per curve its segments in order, a sample
/// per point with its distance along the curve and the frame whose x is the tangent and z
/// the normal, a tag at every node (session time: 0.1 m/s).
fn curves_of(net: &NetworkSegments) -> Vec<Curve> {
    let mut by_curve: BTreeMap<usize, Vec<&Segment>> = BTreeMap::new();
    for s in &net.segments {
        by_curve.entry(s.curve).or_default().push(s);
    }
    by_curve
        .into_iter()
        .map(|(index, mut segs)| {
            segs.sort_by_key(|s| s.k);
            let (mut points, mut normals) = (Vec::new(), Vec::new());
            let mut ends = vec![(0, segs[0].a)];
            for s in &segs {
                let skip = usize::from(!points.is_empty());
                points.extend_from_slice(&s.points[skip..]);
                normals.extend_from_slice(&s.normals[skip..]);
                ends.push((points.len() - 1, s.b));
            }
            let mut d = vec![0.0];
            for w in points.windows(2) {
                d.push(d.last().unwrap() + (w[1] - w[0]).norm());
            }
            let mut samples = Samples::default();
            for i in 0..points.len() {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(points.len() - 1));
                let x: Vector3<f64> = (points[b] - points[a]).normalize();
                let z = (normals[i] - x * x.dot(&normals[i])).normalize();
                let m = Matrix3::from_columns(&[x, z.cross(&x), z]);
                let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
                samples.t.push(d[i] / 0.1);
                samples.d.push(d[i]);
                samples.q.push([q.w, q.i, q.j, q.k]);
                samples.flags.push(0);
                samples.w.push(1.0);
            }
            let tags: Vec<Tag> = ends
                .iter()
                .map(|&(i, node)| Tag {
                    node,
                    d: d[i],
                    t: d[i] / 0.1,
                    uncertain: false,
                })
                .collect();
            Curve {
                index,
                kind: segs[0].kind,
                closed: tags[0].node == tags[tags.len() - 1].node,
                segment_lengths: vec![None; tags.len() - 1],
                tags,
                samples,
            }
        })
        .collect()
}

/// The live update that adds meridian 1 to the curves of `net`, after the update without
/// it: the vertices, and the [`PHASES`]' times (ms, best of `runs`).
fn phases(net: &NetworkSegments, runs: usize) -> (usize, [f64; 4]) {
    let curves = curves_of(net);
    let without: Vec<Curve> = curves.iter().filter(|c| c.index != 1).cloned().collect();
    let (np, sp) = (
        NetworkParams {
            local_window: 3,
            ..NetworkParams::default()
        },
        SurfaceParams {
            reuse_tolerance: 0.5,
            ..SurfaceParams::default()
        },
    );
    let mut best = [f64::MAX; 4];
    let mut nv = 0;
    for _ in 0..runs {
        let (mut r, mut s) = (Reconstructor::new(), Surfacer::new());
        let before = r.run(&without, &np).expect("a network");
        s.run(&NetworkSegments::from_positions(&before.positions), &sp)
            .expect("a surface");
        // Phase one without the nodes' uncertainty, which phase two begins with (issue 51).
        let first = NetworkParams {
            defer_uncertainty: true,
            ..np
        };
        let (curves_ms, mut after) = ms(|| r.run(&curves, &first).expect("a network"));
        let (surface_ms, out) = ms(|| {
            r.uncertainty(&mut after, &np);
            s.run(&NetworkSegments::from_positions(&after.positions), &sp)
                .expect("a surface")
        });
        nv = out.positions.len();
        let (settle_ms, _) = ms(|| {
            let whole = r
                .run(&curves, &NetworkParams::default())
                .expect("a network");
            s.run(
                &NetworkSegments::from_positions(&whole.positions),
                &SurfaceParams::default(),
            )
            .expect("a surface")
        });
        for (b, t) in
            best.iter_mut()
                .zip([curves_ms, surface_ms, curves_ms + surface_ms, settle_ms])
        {
            *b = b.min(t);
        }
    }
    (nv, best)
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

/// One sweep of a table: per row its x (vertices or curves), vertex count and its columns'
/// times (ms), the CSV's columns from `first` on ([`COLUMNS`] then [`PHASES`]).
struct Series {
    name: &'static str,
    first: usize,
    rows: Vec<(f64, usize, Vec<f64>)>,
}

impl Series {
    /// Its rows as CSV lines (the other sweeps' columns empty).
    fn csv(&self) -> String {
        let total = COLUMNS.len() + PHASES.len();
        self.rows
            .iter()
            .map(|(x, nv, t)| {
                let mut cols = vec![String::new(); total];
                for (c, v) in cols[self.first..].iter_mut().zip(t) {
                    *c = format!("{v:.3}");
                }
                format!("{},{x},{nv},{}\n", self.name, cols.join(","))
            })
            .collect()
    }

    /// The fitted exponent of each column against x, formatted.
    fn exponents(&self) -> Vec<String> {
        (0..self.rows.first().map_or(0, |r| r.2.len()))
            .map(|c| {
                let xy: Vec<(f64, f64)> = self.rows.iter().map(|r| (r.0, r.2[c])).collect();
                format!("{:.2}", exponent(&xy))
            })
            .collect()
    }
}

fn cells(t: &[f64]) -> String {
    t.iter()
        .map(|v| format!("{v:.1} ms"))
        .collect::<Vec<_>>()
        .join(" | ")
}

fn main() {
    // As the daemon runs (faer's parallel factorisation is slower on this machine's 2 cores).
    sfs_geometry::sparse_llt::single_threaded();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let only: Option<usize> = args
        .iter()
        .find_map(|a| a.strip_prefix("--curves="))
        .and_then(|n| n.parse().ok());
    let phases_only = only.is_some() || args.iter().any(|a| a == "--phases");
    let csv_path = args.into_iter().find(|a| !a.starts_with("--"));
    let header = COLUMNS.join(" | ");
    // Surface size: the grid at an edge for each target count. The sizes grow, so each one's
    // peak resident size is the process's peak after it.
    if !phases_only {
        println!("| vertices | faces touched | {header} | peak resident size per vertex |");
        println!("|---|---|---|---|---|---|---|---|");
    }
    let mut by_size = Series {
        name: "vertices",
        first: 0,
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
    ]
    .into_iter()
    .filter(|_| !phases_only)
    {
        // The unit sphere's area over a lattice of edge e: 4π / (√3/2 e²) vertices.
        let edge = (4.0 * std::f64::consts::PI / (3f64.sqrt() / 2.0 * target)).sqrt();
        let p = SurfaceParams {
            edge: Some(edge),
            max_vertices: usize::MAX,
            ..SurfaceParams::default()
        };
        let runs = if target <= 20_000.0 { 3 } else { 1 };
        let (nv, touched, t) = row(&sphere_grid(6, 5, 0.5 * edge), &p, runs);
        let per_vertex = peak_rss() / nv as f64 / 1e3;
        println!("| {nv} | {touched} | {} | {per_vertex:.1} kB |", cells(&t));
        by_size.rows.push((nv as f64, nv, t.to_vec()));
    }
    if !phases_only {
        println!("| exponent | | {} | |", by_size.exponents().join(" | "));
        // Network size: the grid at the default edge and budget.
        println!();
        println!("| curves | vertices | faces touched | {header} |");
        println!("|---|---|---|---|---|---|---|---|");
    }
    let mut by_curves = Series {
        name: "curves",
        first: 0,
        rows: Vec::new(),
    };
    for curves in [5usize, 10, 20, 50, 100]
        .into_iter()
        .filter(|_| !phases_only)
    {
        let meridians = curves.div_ceil(2);
        let net = sphere_grid(meridians, curves - meridians, 0.01);
        let (nv, touched, t) = row(&net, &SurfaceParams::default(), 3);
        println!("| {curves} | {nv} | {touched} | {} |", cells(&t));
        by_curves.rows.push((curves as f64, nv, t.to_vec()));
    }
    if !phases_only {
        println!("| exponent | | | {} |", by_curves.exponents().join(" | "));
        // The two phases of a live update (issue 35), the same grids.
        println!();
    }
    println!("| curves (a live update) | vertices | E to the curves: network | surface | E to the surface: update | settle |");
    println!("|---|---|---|---|---|---|");
    let mut by_phase = Series {
        name: "session",
        first: COLUMNS.len(),
        rows: Vec::new(),
    };
    // Rows of 150 and 200 curves (issue 51, point 6), one run each: sessions of hundreds of
    // curves.
    for curves in [5usize, 10, 20, 50, 100, 150, 200]
        .into_iter()
        .filter(|c| only.is_none_or(|o| o == *c))
    {
        let meridians = curves.div_ceil(2);
        let runs = if curves > 100 { 1 } else { 3 };
        let (nv, t) = phases(&sphere_grid(meridians, curves - meridians, 0.01), runs);
        println!("| {curves} | {nv} | {} |", cells(&t));
        by_phase.rows.push((curves as f64, nv, t.to_vec()));
    }
    println!("| exponent | | {} |", by_phase.exponents().join(" | "));
    let names: Vec<String> = COLUMNS
        .iter()
        .chain(&PHASES)
        .map(|c| format!("{c}_ms"))
        .collect();
    let csv = format!(
        "series,x,vertices,{}\n{}{}{}",
        names.join(","),
        by_size.csv(),
        by_curves.csv(),
        by_phase.csv()
    );
    if let Some(path) = csv_path {
        std::fs::write(&path, csv).expect("the CSV written");
        eprintln!("rows in {path}");
    }
}
