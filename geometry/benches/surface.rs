//! Speed of the surfacer (tessellation, weights, both propagations, the guided fit and one
//! reweighting pass) on the unit sphere's cube network at about 10 k and 100 k vertices, cold
//! and with the symbolic factorisations kept (as the daemon runs it).
//! `cargo bench --bench surface`; targets in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion};
use sfs_geometry::surface::analytic::sphere_cube;
use sfs_geometry::surface::fit::{surface, SurfaceParams, Surfacer};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    sfs_geometry::sparse_llt::single_threaded();
    for (spacing, edge) in [(0.026, 0.035), (0.0083, 0.0112)] {
        let net = sphere_cube(spacing);
        let p = SurfaceParams {
            edge: Some(edge),
            ..Default::default()
        };
        let s = surface(&net, &p).expect("a surface");
        let n = s.positions.len();
        let mut g = c.benchmark_group(format!("sphere_cube_{n}_vertices"));
        g.sample_size(10);
        g.bench_function("surface_cold", |b| {
            b.iter(|| black_box(surface(black_box(&net), &p).expect("a surface")))
        });
        // As the daemon runs it: the symbolic factorisations kept from the previous surface.
        let mut warm = Surfacer::new();
        g.bench_function("surface_warm", |b| {
            b.iter(|| black_box(warm.run(black_box(&net), &p).expect("a surface")))
        });
        let p0 = SurfaceParams { reweight: 0, ..p };
        let mut warm0 = Surfacer::new();
        g.bench_function("surface_warm_without_reweighting", |b| {
            b.iter(|| black_box(warm0.run(black_box(&net), &p0).expect("a surface")))
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
