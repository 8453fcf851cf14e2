//! The paper's Table 1 (Stanko et al. 2016): distance from the analytic surface over the free
//! vertices, for the unit sphere (cube network and three great circles) and the torus
//! R = 4, r = 2 (4 meridians + 2 parallels), by biharmonic, triharmonic and the paper's method.
//!
//! `cargo run --release --example surface_table [-- SPACING]` (default: network samples every
//! 0.02 on the sphere, 0.1 on the torus, interior edges 1.35× that, about the paper's counts).

use nalgebra::Vector3;
use sfs::surface::cycles::NetworkSegments;
use sfs::surface::fit::{surface, Method, SurfaceParams};
use std::f64::consts::{PI, TAU};
use std::time::Instant;

/// Adds a curve sampled from `f(t)`, t ∈ [0, 1], with nodes at the given parameters.
fn curve(
    net: &mut NetworkSegments,
    idx: usize,
    f: &dyn Fn(f64) -> (Vector3<f64>, Vector3<f64>),
    nodes: &[(f64, u32)],
    length: f64,
    spacing: f64,
) {
    for w in nodes.windows(2) {
        let ((t0, a), (t1, b)) = (w[0], w[1]);
        let m = (((t1 - t0) * length / spacing).round() as usize).max(2);
        let (pts, nrm): (Vec<_>, Vec<_>) = (0..=m)
            .map(|k| f(t0 + (t1 - t0) * k as f64 / m as f64))
            .unzip();
        net.push(idx, false, (a, b), pts, nrm);
    }
}

fn sphere_cube(spacing: f64) -> NetworkSegments {
    let corners: Vec<Vector3<f64>> = (0..8)
        .map(|i| {
            Vector3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            )
            .normalize()
        })
        .collect();
    let mut net = NetworkSegments::default();
    let mut idx = 0;
    for a in 0..8u32 {
        for bit in [1u32, 2, 4] {
            let b = a | bit;
            if b == a {
                continue;
            }
            let (pa, pb) = (corners[a as usize], corners[b as usize]);
            let ang = pa.angle(&pb);
            let slerp = move |t: f64| {
                let p = (pa * ((1.0 - t) * ang).sin() + pb * (t * ang).sin()) / ang.sin();
                (p, p)
            };
            curve(&mut net, idx, &slerp, &[(0.0, a), (1.0, b)], ang, spacing);
            idx += 1;
        }
    }
    for (i, c) in corners.iter().enumerate() {
        net.set_normal(i as u32, *c);
    }
    net
}

fn sphere_circles(spacing: f64) -> NetworkSegments {
    // Three great circles in the coordinate planes; nodes at ±x, ±y, ±z.
    let node = |v: Vector3<f64>| -> u32 {
        let k = if v.x.abs() > 0.5 {
            0
        } else if v.y.abs() > 0.5 {
            1
        } else {
            2
        };
        (2 * k + usize::from(v[k] < 0.0)) as u32
    };
    let mut net = NetworkSegments::default();
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    for (idx, (u, w)) in [(0, 1), (1, 2), (2, 0)].into_iter().enumerate() {
        let (eu, ew) = (axes[u], axes[w]);
        let f = move |t: f64| {
            let p = eu * (TAU * t).cos() + ew * (TAU * t).sin();
            (p, p)
        };
        let nodes: Vec<(f64, u32)> = (0..=4)
            .map(|k| {
                let t = k as f64 / 4.0;
                (t, node(f(t).0))
            })
            .collect();
        curve(&mut net, idx, &f, &nodes, TAU, spacing);
    }
    for (k, a) in axes.iter().enumerate() {
        net.set_normal(2 * k as u32, *a);
        net.set_normal(2 * k as u32 + 1, -a);
    }
    net
}

const R: f64 = 4.0;
const RR: f64 = 2.0;

fn torus_point(u: f64, v: f64) -> (Vector3<f64>, Vector3<f64>) {
    let n = Vector3::new(u.cos() * v.cos(), u.sin() * v.cos(), v.sin());
    let p = Vector3::new(u.cos() * R, u.sin() * R, 0.0) + n * RR;
    (p, n)
}

fn torus(spacing: f64) -> NetworkSegments {
    // Meridians at u = 0, π/2, π, 3π/2; parallels at v = ±π/2 (top and bottom circles).
    let mut net = NetworkSegments::default();
    let node = |i: usize, top: bool| (2 * i + usize::from(!top)) as u32;
    for i in 0..4 {
        let u = i as f64 * PI / 2.0;
        // Meridian from the top (v = π/2) around the outside and back: v = π/2 − 2π t.
        let f = move |t: f64| torus_point(u, PI / 2.0 - TAU * t);
        curve(
            &mut net,
            i,
            &f,
            &[
                (0.0, node(i, true)),
                (0.5, node(i, false)),
                (1.0, node(i, true)),
            ],
            TAU * RR,
            spacing,
        );
    }
    for (k, top) in [(4, true), (5, false)] {
        let v: f64 = if top { PI / 2.0 } else { -PI / 2.0 };
        let f = move |t: f64| torus_point(TAU * t, v);
        let nodes: Vec<(f64, u32)> = (0..=4)
            .map(|i| (i as f64 / 4.0, node(i % 4, top)))
            .collect();
        curve(&mut net, k, &f, &nodes, TAU * R, spacing);
    }
    for i in 0..4 {
        for top in [true, false] {
            let u = i as f64 * PI / 2.0;
            let v = if top { PI / 2.0 } else { -PI / 2.0 };
            net.set_normal(node(i, top), torus_point(u, v).1);
        }
    }
    net
}

fn main() {
    sfs::sparse_llt::single_threaded();
    let s: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.02);
    let reweight: usize = std::env::var("SFS_REWEIGHT")
        .ok()
        .and_then(|a| a.parse().ok())
        .unwrap_or(SurfaceParams::default().reweight);
    let sphere_d = |p: &Vector3<f64>| (p.norm() - 1.0).abs();
    let torus_d = |p: &Vector3<f64>| {
        let q = (p.x * p.x + p.y * p.y).sqrt() - R;
        ((q * q + p.z * p.z).sqrt() - RR).abs()
    };
    type Case = (
        &'static str,
        NetworkSegments,
        f64,
        Box<dyn Fn(&Vector3<f64>) -> f64>,
    );
    let cases: Vec<Case> = vec![
        (
            "sphere, cube network",
            sphere_cube(s),
            1.35 * s,
            Box::new(sphere_d),
        ),
        (
            "sphere, three circles",
            sphere_circles(s),
            1.35 * s,
            Box::new(sphere_d),
        ),
        (
            "torus R = 4, r = 2",
            torus(5.0 * s),
            1.35 * 5.0 * s,
            Box::new(torus_d),
        ),
    ];
    println!("| data | method | #Vf / #Vc | min | max | mean | RMS | time |");
    println!("|---|---|---|---|---|---|---|---|");
    for (name, net, edge, dist) in &cases {
        for (mname, method) in [
            ("ours (normal control)", Method::NormalControl),
            ("biharmonic", Method::Biharmonic),
            ("triharmonic", Method::Triharmonic),
        ] {
            let t0 = Instant::now();
            let r = surface(
                net,
                &SurfaceParams {
                    edge: Some(*edge),
                    method,
                    // The comparison rows as the paper ran them: planar weights.
                    reweight: if method == Method::NormalControl {
                        reweight
                    } else {
                        0
                    },
                },
            );
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            match r {
                Ok(out) => {
                    let d: Vec<f64> = out.positions[out.constrained..].iter().map(dist).collect();
                    let n = d.len() as f64;
                    let mean = d.iter().sum::<f64>() / n;
                    let rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
                    let min = d.iter().copied().fold(f64::MAX, f64::min);
                    let max = d.iter().copied().fold(0.0, f64::max);
                    println!(
                        "| {name} | {mname} | {} / {} | {min:.4} | {max:.4} | {mean:.4} | {rms:.4} | {ms:.0} ms |",
                        d.len(),
                        out.constrained
                    );
                    if std::env::var("SFS_SPLIT").is_ok() {
                        let (mut oi, mut oo) = (vec![], vec![]);
                        for p in &out.positions[out.constrained..] {
                            if (p.x * p.x + p.y * p.y).sqrt() > R {
                                oo.push(dist(p))
                            } else {
                                oi.push(dist(p))
                            }
                        }
                        let m = |v: &Vec<f64>| v.iter().sum::<f64>() / v.len().max(1) as f64;
                        eprintln!(
                            "  outer {} mean {:.4}, inner {} mean {:.4}",
                            oo.len(),
                            m(&oo),
                            oi.len(),
                            m(&oi)
                        );
                    }
                    if !out.problems.is_empty() {
                        eprintln!("  problems: {:?}", out.problems);
                    }
                }
                Err(e) => println!("| {name} | {mname} | failed: {e} |"),
            }
        }
    }
}
