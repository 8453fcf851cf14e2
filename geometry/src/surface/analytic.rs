//! Analytic curve networks with exact normals (the paper's Table 1 test shapes), for tests,
//! benchmarks and `geometry/examples/surface_table.rs`, with the distance to their true surface.

use super::cycles::NetworkSegments;
use nalgebra::Vector3;
use std::f64::consts::{PI, TAU};

/// Distance from the unit sphere.
pub fn sphere_distance(p: &Vector3<f64>) -> f64 {
    (p.norm() - 1.0).abs()
}

/// Distance from the torus `R = 4, r = 2` around z.
pub fn torus_distance(p: &Vector3<f64>) -> f64 {
    let q = (p.x * p.x + p.y * p.y).sqrt() - R;
    ((q * q + p.z * p.z).sqrt() - RR).abs()
}

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
        net.push(idx, crate::curve::CurveKind::Interior, (a, b), pts, nrm);
    }
}

/// The unit sphere's network of a cube's 12 edges (great-circle arcs), samples every
/// `spacing`, normals radial.
pub fn sphere_cube(spacing: f64) -> NetworkSegments {
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

/// The unit sphere's network of three great circles in the coordinate planes.
pub fn sphere_circles(spacing: f64) -> NetworkSegments {
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

/// The torus' radii.
pub const R: f64 = 4.0;
pub const RR: f64 = 2.0;

/// Point and outward normal of the torus at angles `u` (around the axis) and `v` (around
/// the tube).
pub fn torus_point(u: f64, v: f64) -> (Vector3<f64>, Vector3<f64>) {
    let n = Vector3::new(u.cos() * v.cos(), u.sin() * v.cos(), v.sin());
    let p = Vector3::new(u.cos() * R, u.sin() * R, 0.0) + n * RR;
    (p, n)
}

/// The torus `R = 4, r = 2` with 4 meridians and 2 parallels (top and bottom circles).
pub fn torus(spacing: f64) -> NetworkSegments {
    torus_with_parallels(spacing, PI / 2.0)
}

/// The torus with 4 meridians and the 2 parallels at `v0` and `v0 − π`.
pub fn torus_with_parallels(spacing: f64, v0: f64) -> NetworkSegments {
    // Meridians at u = 0, π/2, π, 3π/2; parallels at v0 and v0 − π.
    let mut net = NetworkSegments::default();
    let node = |i: usize, top: bool| (2 * i + usize::from(!top)) as u32;
    for i in 0..4 {
        let u = i as f64 * PI / 2.0;
        // Meridian from the first parallel around and back: v = v0 − 2π t.
        let f = move |t: f64| torus_point(u, v0 - TAU * t);
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
        let v: f64 = if top { v0 } else { v0 - PI };
        let f = move |t: f64| torus_point(TAU * t, v);
        let nodes: Vec<(f64, u32)> = (0..=4)
            .map(|i| (i as f64 / 4.0, node(i % 4, top)))
            .collect();
        curve(&mut net, k, &f, &nodes, TAU * (R + RR * v.cos()), spacing);
    }
    for i in 0..4 {
        for top in [true, false] {
            let u = i as f64 * PI / 2.0;
            let v = if top { v0 } else { v0 - PI };
            net.set_normal(node(i, top), torus_point(u, v).1);
        }
    }
    net
}

/// Distance from the surface of the box `[−h, h]` (`h` its half sizes), centred at the origin.
pub fn box_distance(p: &Vector3<f64>, h: &Vector3<f64>) -> f64 {
    let q = p.abs() - h;
    let outside = q.sup(&Vector3::zeros()).norm();
    let inside = q.max().min(0.0);
    (outside + inside).abs()
}

/// The network of a box of sizes `size` centred at the origin (issue 18): its twelve edges
/// as crease curves (each with both faces' normals: measured on one, `across` the other,
/// alternating which), and one smooth curve across each face through its middle, ending at
/// the middles of two opposite edges (the top, front, bottom and back curves in the plane
/// x = 0, the ±x faces' in y = 0): 8 corners (nodes 0–7), 8 edge middles (8–15), 12
/// patches. Node normals are the means of the faces around them. Samples every `spacing`.
pub fn box_network(size: [f64; 3], spacing: f64) -> NetworkSegments {
    use crate::curve::CurveKind;
    let h = Vector3::from(size) / 2.0;
    let corner = |i: u32| {
        Vector3::new(
            if i & 1 == 0 { -h.x } else { h.x },
            if i & 2 == 0 { -h.y } else { h.y },
            if i & 4 == 0 { -h.z } else { h.z },
        )
    };
    // The outward normals of the faces containing a point of the surface.
    let faces_at = |p: &Vector3<f64>| -> Vec<Vector3<f64>> {
        (0..3)
            .filter(|&k| (p[k].abs() - h[k]).abs() < 1e-12)
            .map(|k| {
                let mut n = Vector3::zeros();
                n[k] = p[k].signum();
                n
            })
            .collect()
    };
    let mut net = NetworkSegments::default();
    let mut middles: Vec<Vector3<f64>> = Vec::new();
    let mut idx = 0;
    let mut add = |net: &mut NetworkSegments,
                   kind: CurveKind,
                   pts: &[(Vector3<f64>, u32)],
                   normal: Vector3<f64>,
                   across: Option<Vector3<f64>>| {
        for w in pts.windows(2) {
            let ((pa, a), (pb, b)) = (w[0], w[1]);
            let m = (((pb - pa).norm() / spacing).round() as usize).max(2);
            let points: Vec<Vector3<f64>> = (0..=m)
                .map(|k| pa + (pb - pa) * (k as f64 / m as f64))
                .collect();
            let across = across.map_or_else(Vec::new, |n| vec![n; m + 1]);
            net.push_crease(idx, kind, (a, b), points, vec![normal; m + 1], across);
        }
        idx += 1;
    };
    // Edges along axis k: from corner i (bit k clear) to i | bit k, with a middle node on the
    // edges along x and y.
    let mut edge = 0;
    for k in 0..3 {
        let bit = 1u32 << k;
        for i in (0..8u32).filter(|i| i & bit == 0) {
            let (pa, pb) = (corner(i), corner(i | bit));
            let faces = faces_at(&((pa + pb) / 2.0));
            let (rest, other) = if edge % 2 == 0 {
                (faces[0], faces[1])
            } else {
                (faces[1], faces[0])
            };
            edge += 1;
            let mut pts = vec![(pa, i)];
            if k < 2 {
                middles.push((pa + pb) / 2.0);
                pts.push(((pa + pb) / 2.0, 7 + middles.len() as u32));
            }
            pts.push((pb, i | bit));
            add(&mut net, CurveKind::Crease, &pts, rest, Some(other));
        }
    }
    // One curve across each face, between the middles of two opposite edges.
    let middle = |p: Vector3<f64>| -> u32 {
        8 + middles
            .iter()
            .position(|m| (m - p).norm() < 1e-12)
            .expect("an edge middle") as u32
    };
    for k in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut n = Vector3::zeros();
            n[k] = sign;
            // Across the face: along the axis j, in the plane through the centre.
            let (j, l) = match k {
                0 => (2, 1),
                1 => (2, 0),
                _ => (1, 0),
            };
            let mut pa = n.component_mul(&h);
            pa[j] = -h[j];
            pa[l] = 0.0;
            let mut pb = pa;
            pb[j] = h[j];
            add(
                &mut net,
                CurveKind::Interior,
                &[(pa, middle(pa)), (pb, middle(pb))],
                n,
                None,
            );
        }
    }
    for i in 0..8 {
        let p = corner(i);
        net.set_normal(i, faces_at(&p).iter().sum::<Vector3<f64>>().normalize());
    }
    for (m, p) in middles.iter().enumerate() {
        net.set_normal(
            8 + m as u32,
            faces_at(p).iter().sum::<Vector3<f64>>().normalize(),
        );
    }
    net
}

/// The unit sphere's latitude–longitude network: `meridians` half great circles from the
/// south pole (node 0) to the north pole (node 1) and `parallels` closed circles between,
/// crossing at nodes `2 + meridian · parallels + parallel`; `meridians · (parallels + 1)`
/// patches, normals radial, samples every `spacing`. For the scaling tables (network size).
pub fn sphere_grid(meridians: usize, parallels: usize, spacing: f64) -> NetworkSegments {
    let mut net = NetworkSegments::default();
    let node = |m: usize, p: usize| (2 + m * parallels + p) as u32;
    let lat = |p: usize| -PI / 2.0 + PI * (p + 1) as f64 / (parallels + 1) as f64;
    let point = |lon: f64, la: f64| {
        let v = Vector3::new(la.cos() * lon.cos(), la.cos() * lon.sin(), la.sin());
        (v, v)
    };
    for m in 0..meridians {
        let lon = TAU * m as f64 / meridians as f64;
        let f = move |t: f64| point(lon, -PI / 2.0 + PI * t);
        let mut nodes = vec![(0.0, 0u32)];
        for p in 0..parallels {
            nodes.push(((lat(p) + PI / 2.0) / PI, node(m, p)));
        }
        nodes.push((1.0, 1));
        curve(&mut net, m, &f, &nodes, PI, spacing);
    }
    for p in 0..parallels {
        let la = lat(p);
        let f = move |t: f64| point(TAU * t, la);
        let nodes: Vec<(f64, u32)> = (0..=meridians)
            .map(|m| (m as f64 / meridians as f64, node(m % meridians, p)))
            .collect();
        curve(&mut net, meridians + p, &f, &nodes, TAU * la.cos(), spacing);
    }
    net.set_normal(0, -Vector3::z());
    net.set_normal(1, Vector3::z());
    for m in 0..meridians {
        for p in 0..parallels {
            net.set_normal(
                node(m, p),
                point(TAU * m as f64 / meridians as f64, lat(p)).0,
            );
        }
    }
    net
}
