//! One surface from scratch at a given size, timed: the interleaved A/B runs of BENCHMARKS.md
//! (issue 35, point 2). The unit sphere's latitude–longitude network (6 meridians, 5
//! parallels) at the edge for `VERTICES` (default 10 000), surfaced `RUNS` times (default 9) by
//! a new surfacer each (`cold`: symbolic factorisations computed) and once more by the same
//! one (`warm`: patterns kept); hard constraints, or the sessions' soft ones with `soft`.
//! Prints one line: `vertices cold_p50 cold_min warm_p50 warm_min` (ms), and, with `digest`, a
//! hash of the surface's bits (the outputs must not change).
//!
//! `cargo run --release -p sfs-geometry --example surface_ab -- [VERTICES] [RUNS] [soft] [digest]`

use sfs_geometry::surface::analytic::sphere_grid;
use sfs_geometry::surface::fit::{SurfaceParams, Surfacer};
use std::hash::{Hash, Hasher};
use std::time::Instant;

fn main() {
    sfs_geometry::sparse_llt::single_threaded();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let target: f64 = args
        .first()
        .and_then(|a| a.parse().ok())
        .unwrap_or(10_000.0);
    let runs: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(9);
    let soft = args.iter().any(|a| a == "soft");
    let digest = args.iter().any(|a| a == "digest");
    let edge = (4.0 * std::f64::consts::PI / (3f64.sqrt() / 2.0 * target)).sqrt();
    let p = SurfaceParams {
        edge: Some(edge),
        max_vertices: usize::MAX,
        soft: if soft { Some(0.3) } else { None },
        ..SurfaceParams::default()
    };
    let net = sphere_grid(6, 5, 0.5 * edge);
    let (mut cold, mut warm) = (Vec::new(), Vec::new());
    let mut nv = 0;
    let mut hash = 0u64;
    for _ in 0..runs {
        let mut s = Surfacer::new();
        let t0 = Instant::now();
        let out = s.run(&net, &p).expect("a surface");
        cold.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        s.run(&net, &p).expect("a surface");
        warm.push(t0.elapsed().as_secs_f64() * 1e3);
        nv = out.positions.len();
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for v in &out.positions {
            for x in v.iter() {
                x.to_bits().hash(&mut h);
            }
        }
        out.triangles.hash(&mut h);
        hash = h.finish();
    }
    let stat = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[0])
    };
    let ((c50, cmin), (w50, wmin)) = (stat(&mut cold), stat(&mut warm));
    print!("{nv} {c50:.2} {cmin:.2} {w50:.2} {wmin:.2}");
    if digest {
        print!(" {hash:016x}");
    }
    println!();
}
