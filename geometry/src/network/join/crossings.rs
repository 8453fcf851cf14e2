//! Crossings nobody tagged (issue 34, point 2): two curves whose reconstructed paths cross
//! with no node there, proposed ([`Proposal`]) or, with `join_untagged`, joined.

use super::grid::Grid;
use super::{face_angle, faces, line_angle, JoinParams, Proposal};
use crate::network::poisson::Positions;
use nalgebra::Vector3;

/// Tangents of two curves proposed as crossing make at least this angle (as lines), degrees:
/// curves that run side by side (parallel, or a curve retraced) pass close without crossing,
/// and a proposal, which no tag asked for, wants a clear crossing.
pub const CROSSING_DEG: f64 = 30.0;

/// Closest points of segments `p0 p1` and `q0 q1`: `(distance, u on p, v on q)`, u and v in
/// [0, 1].
fn segment_closest(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> (f64, f64, f64) {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    let (mut u, mut v);
    if a <= 1e-24 && e <= 1e-24 {
        return (r.norm(), 0.0, 0.0);
    }
    if a <= 1e-24 {
        u = 0.0;
        v = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= 1e-24 {
            v = 0.0;
            u = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            u = if denom > 1e-24 * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            v = (b * u + f) / e;
            if v < 0.0 {
                v = 0.0;
                u = (-c / a).clamp(0.0, 1.0);
            } else if v > 1.0 {
                v = 1.0;
                u = ((b - c) / a).clamp(0.0, 1.0);
            }
        }
    }
    ((p0 + d1 * u - (q0 + d2 * v)).norm(), u, v)
}

/// Crossings nobody tagged: pairs of curves of `net` whose paths come within
/// [`JoinParams::distance_m`] of each other, crossing (tangents at least [`CROSSING_DEG`]
/// apart as lines) with normals within [`JoinParams::normal_deg`], and with no node of either
/// curve within twice the join distance. One proposal per crossing (the closest approach of
/// each run of close samples), in the order of the curves. Linear in the samples: a grid of
/// cells the size of the join distance.
pub fn find_crossings(net: &Positions, p: &JoinParams) -> Vec<Proposal> {
    let reach = p.distance_m;
    if reach <= 0.0 || !reach.is_finite() {
        return Vec::new();
    }
    let grid = Grid::of(net, reach, |_| true);
    // Close sample pairs per pair of curves: (a, b) → [(i on a, j on b)].
    let mut close: std::collections::BTreeMap<(usize, usize), Vec<(usize, usize)>> =
        Default::default();
    for (ca, c) in net.curves.iter().enumerate() {
        for (i, x) in c.points.iter().enumerate() {
            for (cb, j) in grid.around(x) {
                if cb > ca && (net.curves[cb].points[j] - x).norm() <= 2.0 * reach {
                    close.entry((ca, cb)).or_default().push((i, j));
                }
            }
        }
    }
    let mut out = Vec::new();
    for ((ca, cb), mut pairs) in close {
        let (a, b) = (&net.curves[ca], &net.curves[cb]);
        pairs.sort_unstable();
        // Runs of close samples along a (a crossing), each refined to its closest segments.
        let mut runs: Vec<Vec<(usize, usize)>> = Vec::new();
        for pr in pairs {
            match runs.last_mut() {
                Some(r) if pr.0 <= r.last().map_or(0, |x| x.0) + 2 => r.push(pr),
                _ => runs.push(vec![pr]),
            }
        }
        for run in runs {
            let mut best: Option<(f64, usize, f64, usize, f64)> = None;
            for &(i, j) in &run {
                for si in i.saturating_sub(1)..=i {
                    for sj in j.saturating_sub(1)..=j {
                        if si + 1 >= a.points.len() || sj + 1 >= b.points.len() {
                            continue;
                        }
                        let (dist, u, v) = segment_closest(
                            &a.points[si],
                            &a.points[si + 1],
                            &b.points[sj],
                            &b.points[sj + 1],
                        );
                        if best.as_ref().is_none_or(|x| dist < x.0) {
                            best = Some((dist, si, u, sj, v));
                        }
                    }
                }
            }
            let Some((dist, si, u, sj, v)) = best else {
                continue;
            };
            if dist > reach || !dist.is_finite() {
                continue;
            }
            let lerp = |x: &[Vector3<f64>], k: usize, t: f64| {
                x.get(k)
                    .zip(x.get(k + 1))
                    .map(|(p, q)| p * (1.0 - t) + q * t)
            };
            let (Some(xa), Some(xb), Some(ta), Some(tb)) = (
                lerp(&a.points, si, u),
                lerp(&b.points, sj, v),
                lerp(&a.tangents, si, u),
                lerp(&b.tangents, sj, v),
            ) else {
                continue;
            };
            let line_angle = line_angle(&ta, &tb);
            let normal_deg = face_angle(&faces(a, si, u), &faces(b, sj, v));
            let point = (xa + xb) * 0.5;
            let near_node = a
                .nodes
                .iter()
                .filter_map(|x| a.points.get(x.0))
                .chain(b.nodes.iter().filter_map(|x| b.points.get(x.0)))
                .any(|q| (q - point).norm() < 2.0 * reach);
            if line_angle < CROSSING_DEG || normal_deg > p.normal_deg || near_node {
                continue;
            }
            let (Some(da), Some(db)) = (
                a.d.get(si)
                    .zip(a.d.get(si + 1))
                    .map(|(x, y)| x + (y - x) * u),
                b.d.get(sj)
                    .zip(b.d.get(sj + 1))
                    .map(|(x, y)| x + (y - x) * v),
            ) else {
                continue;
            };
            out.push(Proposal {
                curves: [a.index, b.index],
                point: [point.x, point.y, point.z],
                distance_m: dist,
                normal_deg,
                d: [da, db],
            });
        }
    }
    out
}
