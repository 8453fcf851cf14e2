//! Curves on analytic surfaces for the operator to scan (until scenes are described as data).

use super::operator::CurveSpec;
use nalgebra::Vector3;

/// A great-circle arc of the sphere of radius `r` centred at the origin, in the plane spanned
/// by the orthonormal `a` and `b`, from angle `th0` to `th1` (radians, `th1 > th0`), sampled
/// with `n` segments. `nodes` are `(angle, node index)` in order of travel.
pub fn sphere_arc(
    r: f64,
    a: Vector3<f64>,
    b: Vector3<f64>,
    (th0, th1): (f64, f64),
    nodes: &[(f64, u32)],
    boundary: bool,
    n: usize,
) -> CurveSpec {
    use super::operator::CurveKind;
    let mut points = Vec::with_capacity(n + 1);
    let mut normals = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let th = th0 + (th1 - th0) * i as f64 / n as f64;
        let u = a * th.cos() + b * th.sin();
        points.push(u * r);
        normals.push(u);
    }
    let tags = nodes
        .iter()
        .map(|&(th, node)| (((th - th0) / (th1 - th0) * n as f64).round() as usize, node))
        .collect();
    CurveSpec {
        points,
        normals,
        tags,
        kind: if boundary {
            CurveKind::Boundary
        } else {
            CurveKind::Interior
        },
    }
}

/// The dome network on the upper hemisphere of radius `r`: the equator as a closed boundary
/// curve through nodes 1-2-3-4-1, and the meridians 1-0-3 and 2-0-4 over the pole (node 0).
pub fn dome(r: f64) -> Vec<CurveSpec> {
    use std::f64::consts::PI;
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    let n = 400;
    vec![
        sphere_arc(
            r,
            x,
            y,
            (0.0, 2.0 * PI),
            &[
                (0.0, 1),
                (PI / 2.0, 2),
                (PI, 3),
                (1.5 * PI, 4),
                (2.0 * PI, 1),
            ],
            true,
            n,
        ),
        sphere_arc(
            r,
            x,
            z,
            (0.0, PI),
            &[(0.0, 1), (PI / 2.0, 0), (PI, 3)],
            false,
            n / 2,
        ),
        sphere_arc(
            r,
            y,
            z,
            (0.0, PI),
            &[(0.0, 2), (PI / 2.0, 0), (PI, 4)],
            false,
            n / 2,
        ),
    ]
}
