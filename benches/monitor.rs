//! Speed of one monitoring epoch (issue 8: ≤ 20 ms for 200 sensors): a 2 m × 2 m panel bulged
//! by 5 cm, instrumented with 10 curves along x and 10 along y (crossing at 100 nodes), 10
//! sensors on each (200 in all); one epoch = the layout's frames interpolated and resampled at
//! 5 cm, the Poisson step, with and without the regression; and the optional surface of the
//! shape (81 closed cells) with the default `[surface]` settings, as `latest.glb` gets it.
//! `cargo bench --bench monitor`; targets in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use sfs::monitor::epoch::{EpochParams, EpochReconstructor};
use sfs::monitor::layout::{Layout, LayoutCurve, LayoutSensor};
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::hint::black_box;

const SIZE: f64 = 2.0;
const LINES: usize = 10;

fn panel() -> (Layout, BTreeMap<u16, UnitQuaternion<f64>>) {
    let at = |k: usize| SIZE * (k as f64 + 0.5) / LINES as f64;
    let mut curves = Vec::new();
    let mut sensors = Vec::new();
    let mut q = BTreeMap::new();
    for dir in 0..2 {
        for i in 0..LINES {
            let index = curves.len();
            let nodes = (0..LINES)
                .map(|k| if dir == 0 { i * LINES + k } else { k * LINES + i } as u32)
                .collect();
            curves.push(LayoutCurve {
                index,
                nodes,
                node_s: (0..LINES).map(at).collect(),
                length: SIZE,
            });
            for k in 0..LINES {
                let s = SIZE * (k as f64 + 0.25) / LINES as f64;
                let (x, y) = if dir == 0 { (s, at(i)) } else { (at(i), s) };
                // z = a sin(πx/L) sin(πy/L): tangent along the curve, normal of the surface.
                let a = 0.05;
                let zx = a * PI / SIZE * (PI * x / SIZE).cos() * (PI * y / SIZE).sin();
                let zy = a * PI / SIZE * (PI * x / SIZE).sin() * (PI * y / SIZE).cos();
                let n = Vector3::new(-zx, -zy, 1.0).normalize();
                let t = if dir == 0 {
                    Vector3::new(1.0, 0.0, zx)
                } else {
                    Vector3::new(0.0, 1.0, zy)
                }
                .normalize();
                let b = n.cross(&t);
                let r = Rotation3::from_basis_unchecked(&[t, b, n]);
                let id = sensors.len() as u16;
                sensors.push(LayoutSensor {
                    sensor: id,
                    curve: index,
                    s,
                });
                q.insert(id, UnitQuaternion::from_rotation_matrix(&r));
            }
        }
    }
    (Layout { sensors, curves }, q)
}

fn bench(c: &mut Criterion) {
    sfs_geometry::sparse_llt::single_threaded();
    let (layout, q) = panel();
    layout.validate().expect("a valid layout");
    let mut g = c.benchmark_group(format!("monitor_epoch_{}_sensors", layout.sensors.len()));
    let mut rec = EpochReconstructor::new();
    let p = EpochParams::default();
    g.bench_function("poisson", |b| {
        b.iter(|| black_box(rec.run(&layout, black_box(&q), &p).expect("a shape")))
    });
    let pr = EpochParams {
        regression: Some(Default::default()),
        ..p
    };
    g.bench_function("regression_and_poisson", |b| {
        b.iter(|| black_box(rec.run(&layout, black_box(&q), &pr).expect("a shape")))
    });
    let shape = rec.run(&layout, &q, &p).expect("a shape");
    let segs = sfs_geometry::surface::cycles::NetworkSegments::from_positions(&shape.positions);
    let sp = sfs_geometry::surface::fit::SurfaceParams {
        soft: sfs::pipeline::SCAN_SOFTNESS,
        ..Default::default()
    };
    let mut surfacer = sfs_geometry::surface::fit::Surfacer::new();
    let s = surfacer.run(&segs, &sp).expect("a surface");
    eprintln!("surface: {} vertices", s.mesh().positions.len());
    g.bench_function("surface", |b| {
        b.iter(|| black_box(surfacer.run(black_box(&segs), &sp).expect("a surface")))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
