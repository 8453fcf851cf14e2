//! Meshes the project makes, for the mesh scenes that run from the repository alone (the
//! paper's LILIUM and BUMPY CUBE carry no licence that allows shipping them): a relief height
//! field over a disk (`relief`, the kind of object LILIUM is) and a bumpy closed surface
//! (`bumpy`, the kind BUMPY CUBE is). Both are deterministic functions of nothing, so a scene
//! built from them, or from their OBJ files written by [`TriMesh::to_obj`], is the same
//! bit for bit.
//!
//! ```
//! let m = sfs::simulate::procedural::relief();
//! assert_eq!(m.boundary_loops().len(), 1);
//! let b = sfs::simulate::procedural::bumpy();
//! assert!(b.boundary_loops().is_empty());
//! ```

use super::mesh::TriMesh;
use nalgebra::Vector3;
use std::collections::HashMap;

/// The generators by the name a scene gives them (`[surface] generate = "…"`).
pub const NAMES: [&str; 3] = ["relief", "bumpy", "ellipsoid"];

/// The generated mesh called `name`, if there is one.
pub fn generate(name: &str) -> Option<TriMesh> {
    match name {
        "relief" => Some(relief()),
        "bumpy" => Some(bumpy()),
        "ellipsoid" => Some(ellipsoid()),
        _ => None,
    }
}

/// Rings of the relief's disk.
const RELIEF_RINGS: usize = 40;

/// The relief's height over the plane at `(x, y)`, metres: two hills and a saddle-shaped
/// ripple on a disk of radius 0.5 m (slopes up to about 30°).
pub fn relief_height(x: f64, y: f64) -> f64 {
    let bump =
        |cx: f64, cy: f64, h: f64, s2: f64| h * (-((x - cx).powi(2) + (y - cy).powi(2)) / s2).exp();
    bump(0.08, -0.05, 0.16, 0.05)
        + bump(-0.22, 0.2, 0.07, 0.015)
        + 0.025 * (5.0 * x).cos() * (4.0 * y + 0.5).sin()
}

/// A height field over the disk of radius 0.5 m centred at the origin
/// ([`relief_height`]): 40 concentric rings of 6k vertices each (4 921 vertices, 9 600
/// triangles), normals up.
pub fn relief() -> TriMesh {
    let r_max = 0.5;
    let k_max = RELIEF_RINGS;
    let mut v = vec![Vector3::new(0.0, 0.0, relief_height(0.0, 0.0))];
    // ring k (k ≥ 1) has 6k vertices starting at index 1 + 3k(k − 1).
    let start = |k: usize| if k == 0 { 0 } else { 1 + 3 * k * (k - 1) };
    let count = |k: usize| if k == 0 { 1 } else { 6 * k };
    for k in 1..=k_max {
        let r = r_max * k as f64 / k_max as f64;
        for j in 0..count(k) {
            let a = std::f64::consts::TAU * j as f64 / count(k) as f64;
            let (x, y) = (r * a.cos(), r * a.sin());
            v.push(Vector3::new(x, y, relief_height(x, y)));
        }
    }
    let mut f = Vec::new();
    for k in 1..=k_max {
        // Walk the inner ring (k − 1) and the outer ring (k) together by angle.
        let (ni, no) = (count(k - 1), count(k));
        let (si, so) = (start(k - 1), start(k));
        // The centre (a ring of one) only fans.
        let (mut i, mut o) = (usize::from(ni == 1), 0usize);
        while i < ni || o < no {
            let ai = if ni == 1 {
                f64::MAX
            } else {
                (i + 1) as f64 / ni as f64
            };
            let ao = (o + 1) as f64 / no as f64;
            let (a, b) = ((si + i % ni) as u32, (so + o % no) as u32);
            if o < no && (ao <= ai || i >= ni) {
                f.push([a, b, (so + (o + 1) % no) as u32]);
                o += 1;
            } else {
                f.push([a, b, (si + (i + 1) % ni) as u32]);
                i += 1;
            }
        }
    }
    let mut m = TriMesh { v, f, n: vec![] };
    m.compute_normals();
    m
}

/// Subdivisions of the bumpy surface's icosahedron.
const BUMPY_LEVELS: usize = 5;

/// The bumpy surface's radius in the direction `d` (unit), metres: a rounded cube of about
/// 0.3 m half-diagonal with bumps of a few millimetres to a centimetre.
pub fn bumpy_radius(d: &Vector3<f64>) -> f64 {
    // d⁴ sums to 1 on the axes and 1/3 on the diagonals: subtracting it pushes the corners out.
    let cube = 1.0 - 0.18 * (d.x.powi(4) + d.y.powi(4) + d.z.powi(4));
    let bumps = 0.035 * (7.0 * d.x).sin() * (7.0 * d.y).sin() * (7.0 * d.z).sin()
        + 0.02 * (5.0 * d.x + 0.3).cos() * (6.0 * d.y).cos();
    0.3 * (cube + bumps)
}

/// A star-shaped closed surface ([`bumpy_radius`]) on an icosahedron subdivided 5 times
/// (10 242 vertices, 20 480 triangles), normals out.
pub fn bumpy() -> TriMesh {
    star(bumpy_radius)
}

/// Semi-axes of the generated ellipsoid, m (those of the independent simulator's
/// `ellipsoid` scenes).
pub const ELLIPSOID_AXES: [f64; 3] = [0.50, 0.35, 0.25];

/// The ellipsoid of semi-axes [`ELLIPSOID_AXES`] on the same subdivided icosahedron as
/// [`bumpy`], normals out.
pub fn ellipsoid() -> TriMesh {
    star(|d| {
        let [a, b, c] = ELLIPSOID_AXES;
        1.0 / ((d.x / a).powi(2) + (d.y / b).powi(2) + (d.z / c).powi(2)).sqrt()
    })
}

/// A star-shaped closed surface of radius `radius(direction)` on an icosahedron subdivided
/// [`BUMPY_LEVELS`] times, normals out.
fn star(radius: impl Fn(&Vector3<f64>) -> f64) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut dirs: Vec<Vector3<f64>> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vector3::from(*p).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..BUMPY_LEVELS {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut split = |a: u32, b: u32, dirs: &mut Vec<Vector3<f64>>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                dirs.push((dirs[a as usize] + dirs[b as usize]).normalize());
                (dirs.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(f.len() * 4);
        for &[a, b, c] in &f {
            let ab = split(a, b, &mut dirs);
            let bc = split(b, c, &mut dirs);
            let ca = split(c, a, &mut dirs);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    let v = dirs.iter().map(|d| d * radius(d)).collect();
    let mut m = TriMesh { v, f, n: vec![] };
    m.compute_normals();
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every edge of a closed mesh has two faces, in opposite directions; of the relief, one
    /// or two, and the one-face edges form the boundary circle.
    fn edge_uses(m: &TriMesh) -> HashMap<(u32, u32), i32> {
        let mut uses = HashMap::new();
        for f in &m.f {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += if a < b { 1 } else { -1 };
            }
        }
        uses
    }

    fn min_angle_deg(m: &TriMesh) -> f64 {
        m.f.iter()
            .flat_map(|f| {
                let p = f.map(|i| m.v[i as usize]);
                (0..3).map(move |k| {
                    let a = (p[(k + 1) % 3] - p[k]).normalize();
                    let b = (p[(k + 2) % 3] - p[k]).normalize();
                    a.dot(&b).clamp(-1.0, 1.0).acos().to_degrees()
                })
            })
            .fold(f64::MAX, f64::min)
    }

    #[test]
    fn the_relief_is_a_consistently_oriented_disk_facing_up() {
        let m = relief();
        assert_eq!(m.v.len(), 1 + 3 * RELIEF_RINGS * (RELIEF_RINGS + 1));
        // Euler characteristic of a disk: V − E + F = 1.
        let uses = edge_uses(&m);
        assert_eq!(m.v.len() as i64 - uses.len() as i64 + m.f.len() as i64, 1);
        // Interior edges are used once each way (sum 0), boundary edges once.
        assert!(uses.values().all(|u| u.abs() <= 1));
        let loops = m.boundary_loops();
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 6 * RELIEF_RINGS);
        for i in &loops[0] {
            let p = m.v[*i as usize];
            assert!((p.xy().norm() - 0.5).abs() < 1e-12);
        }
        assert!(m.n.iter().all(|n| n.z > 0.5), "normals face up");
        assert!(min_angle_deg(&m) > 20.0, "{}", min_angle_deg(&m));
    }

    #[test]
    fn the_bumpy_surface_is_closed_and_faces_out() {
        let m = bumpy();
        assert_eq!(m.v.len(), 10_242);
        assert_eq!(m.f.len(), 20_480);
        let uses = edge_uses(&m);
        assert!(uses.values().all(|u| *u == 0), "every edge once each way");
        assert_eq!(m.v.len() as i64 - uses.len() as i64 + m.f.len() as i64, 2);
        assert!(m.boundary_loops().is_empty());
        assert!(m
            .v
            .iter()
            .zip(&m.n)
            .all(|(p, n)| p.normalize().dot(n) > 0.5));
        assert!(min_angle_deg(&m) > 20.0, "{}", min_angle_deg(&m));
    }
}
