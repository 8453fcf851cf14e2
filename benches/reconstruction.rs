//! Reconstruction speed at about the paper's size (Table 2: 3094 uniform samples): a simulated
//! Morphorider scan of the sphere-octa scene resampled at h = 6 mm (≈ 3.1 k samples), and the
//! torus at h = 1 cm and 3.2 mm (≈ 10 k and 31 k samples) for the cost per sample.
//! `cargo bench --bench reconstruction`; targets in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion};
use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::scan::Scan;
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::network::poisson::PoissonSolver;
use sfs_geometry::network::prefilter::{prefilter, PrefilterParams, UniformCurve};
use sfs_geometry::network::regression::{RegressionParams, RegressionSolver};
use std::hint::black_box;

fn scan(name: &str) -> Scan {
    let s = scene::builtin(name).expect("scene");
    let sim = simulate::run(&s, DeviceKind::Morphorider, Profile::Default, 1);
    Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default())
}

fn uniform(scan: &Scan, p: &PrefilterParams) -> Vec<UniformCurve> {
    scan.curves
        .iter()
        .filter_map(|c| prefilter(c, p).ok())
        .collect()
}

fn bench(c: &mut Criterion) {
    sfs_geometry::sparse_llt::single_threaded();
    for (name, h) in [("sphere-octa", 0.006), ("torus", 0.01), ("torus", 0.0032)] {
        let sc = scan(name);
        let p = PrefilterParams {
            h,
            ..Default::default()
        };
        let u = uniform(&sc, &p);
        let n: usize = u.iter().map(|c| c.q.len()).sum();
        let mut g = c.benchmark_group(format!("{name}_{n}_samples"));
        g.sample_size(if n > 20_000 { 10 } else { 20 });
        g.bench_function("prefilter", |b| {
            b.iter(|| black_box(uniform(black_box(&sc), &p)))
        });
        let rp = RegressionParams::default();
        let mut solver = RegressionSolver::new();
        g.bench_function("regression", |b| {
            b.iter(|| {
                let mut v = u.clone();
                black_box(solver.run(&mut v, &rp))
            })
        });
        let mut poisson = PoissonSolver::new();
        g.bench_function("poisson", |b| {
            b.iter(|| black_box(poisson.solve(black_box(&u)).expect("solve")))
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
