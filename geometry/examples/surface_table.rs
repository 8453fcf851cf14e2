//! The paper's Table 1 (Stanko et al. 2016): distance from the analytic surface over the free
//! vertices, for the unit sphere (cube network and three great circles) and the torus
//! R = 4, r = 2 (4 meridians + 2 parallels), by biharmonic, triharmonic and the paper's method.
//!
//! `cargo run --release -p sfs-geometry --example surface_table [-- SPACING]` (default: network samples every
//! 0.02 on the sphere, 0.1 on the torus, interior edges 1.35× that, about the paper's counts).
//! `SFS_REWEIGHT=N` sets the reweighting passes of "ours"; `SFS_SPLIT=1` also prints, for the
//! tori, the errors of the free vertices outside and inside the tube's axis circle (distance,
//! signed distance, propagated-normal angle).

use nalgebra::Vector3;
use sfs_geometry::surface::analytic::{
    sphere_circles, sphere_cube, sphere_distance, torus, torus_distance, torus_with_parallels, R,
};
use sfs_geometry::surface::cycles::NetworkSegments;
use sfs_geometry::surface::fit::{surface, Method, SurfaceParams};
use std::time::Instant;

fn main() {
    sfs_geometry::sparse_llt::single_threaded();
    let s: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.02);
    let reweight: usize = std::env::var("SFS_REWEIGHT")
        .ok()
        .and_then(|a| a.parse().ok())
        .unwrap_or(SurfaceParams::default().reweight);
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
            Box::new(sphere_distance),
        ),
        (
            "sphere, three circles",
            sphere_circles(s),
            1.35 * s,
            Box::new(sphere_distance),
        ),
        (
            "torus R = 4, r = 2 (parallels at top and bottom)",
            torus(5.0 * s),
            1.35 * 5.0 * s,
            Box::new(torus_distance),
        ),
        (
            "torus R = 4, r = 2 (parallels at the equators)",
            torus_with_parallels(5.0 * s, 0.0),
            1.35 * 5.0 * s,
            Box::new(torus_distance),
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
                    soft: None,
                    ..Default::default()
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
                        let (mut ao, mut ai, mut so) = (vec![], vec![], vec![]);
                        for (p, n) in out
                            .positions
                            .iter()
                            .zip(&out.propagated)
                            .skip(out.constrained)
                        {
                            let rho = (p.x * p.x + p.y * p.y).sqrt();
                            let c = nalgebra::Vector3::new(p.x / rho * R, p.y / rho * R, 0.0);
                            let a = (p - c).normalize().angle(n).to_degrees();
                            if rho > R {
                                ao.push(a)
                            } else {
                                ai.push(a)
                            }
                            if rho > R {
                                so.push((p - c).norm() - 2.0)
                            }
                        }
                        eprintln!("  signed outer {:.3}", m(&so));
                        eprintln!("  normal error outer {:.2}°, inner {:.2}°", m(&ao), m(&ai));
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
