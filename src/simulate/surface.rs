//! Ground-truth surfaces of scenes: analytic ones (sphere, torus, cone frustum, paraboloid
//! bowl) given by an implicit function whose gradient is the outward normal, flat faces with
//! sharp edges (a box, a gable roof: issue 18), and triangle meshes. Every surface can be tessellated (to cut plane sections), and a point of a section
//! can be snapped exactly onto the analytic surface while staying in the section's plane.

use super::mesh::TriMesh;
use nalgebra::Vector3;
use std::f64::consts::{PI, TAU};

/// A surface. Analytic surfaces have their axis along z.
#[derive(Debug, Clone)]
pub enum Surface {
    Sphere {
        center: Vector3<f64>,
        radius: f64,
    },
    /// Torus around the z axis through `center`: tube radius `minor` at distance `major`.
    Torus {
        center: Vector3<f64>,
        major: f64,
        minor: f64,
    },
    /// Cone frustum around the z axis: radius `r0` at height `z0`, `r1` at `z1`.
    Frustum {
        z0: f64,
        r0: f64,
        z1: f64,
        r1: f64,
    },
    /// Bowl `z = ρ² / (2 a)` for `ρ ≤ rim`, normal pointing up into the bowl (the side the
    /// device rolls on).
    Paraboloid {
        a: f64,
        rim: f64,
    },
    /// Flat faces meeting at sharp edges, on the boundary of a convex solid.
    Faces(Box<Faces>),
    Mesh(Box<TriMesh>),
}

/// Flat faces of a convex solid: the solid is `n·x ≤ d` for every face plane `(n, d)` (`n`
/// the unit outward normal), the surface the faces' triangles (all of a box; a gable roof's
/// two slopes only).
#[derive(Debug, Clone)]
pub struct Faces {
    pub planes: Vec<(Vector3<f64>, f64)>,
    /// The faces as triangles (vertices shared along the edges, for sections).
    pub mesh: TriMesh,
}

impl Faces {
    /// The box of sizes `size` centred at `center`.
    pub fn cuboid(center: Vector3<f64>, size: Vector3<f64>) -> Faces {
        let h = size / 2.0;
        let v: Vec<Vector3<f64>> = (0..8)
            .map(|i| {
                let s = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
                center + Vector3::new(s(1) * h.x, s(2) * h.y, s(4) * h.z)
            })
            .collect();
        // Each face as a quad around it (−x, +x, −y, +y, −z, +z).
        let quads = [
            [0, 2, 6, 4],
            [1, 5, 7, 3],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 1, 3, 2],
            [4, 6, 7, 5],
        ];
        let mut planes = Vec::new();
        for k in 0..3 {
            for sign in [-1.0, 1.0] {
                let mut n = Vector3::zeros();
                n[k] = sign;
                planes.push((n, n.dot(&center) + h[k]));
            }
        }
        Faces {
            planes,
            mesh: quads_mesh(v, &quads, center),
        }
    }

    /// A gable roof: two slopes meeting at a ridge along x at height `height` over y = 0,
    /// their eaves at z = 0, y = ±width/2, from x = −length/2 to length/2.
    pub fn gable(length: f64, width: f64, height: f64) -> Faces {
        let (l, w) = (length / 2.0, width / 2.0);
        let v = vec![
            Vector3::new(-l, -w, 0.0),
            Vector3::new(l, -w, 0.0),
            Vector3::new(l, 0.0, height),
            Vector3::new(-l, 0.0, height),
            Vector3::new(-l, w, 0.0),
            Vector3::new(l, w, 0.0),
        ];
        let planes = [-1.0, 1.0]
            .iter()
            .map(|&s| {
                let n = Vector3::new(0.0, s * height, w).normalize();
                (n, n.z * height)
            })
            .collect();
        Faces {
            planes,
            mesh: quads_mesh(v, &[[0, 1, 2, 3], [3, 2, 5, 4]], -Vector3::z() * height),
        }
    }

    /// The faces (indices into `planes`) containing `p`, within `tol`.
    pub fn faces_at(&self, p: &Vector3<f64>, tol: f64) -> Vec<usize> {
        (0..self.planes.len())
            .filter(|&k| (self.planes[k].0.dot(p) - self.planes[k].1).abs() <= tol)
            .collect()
    }
}

/// A mesh of quads (each around its face) split into triangles turned counter-clockwise
/// seen from outside (away from the point `inside`), with unit vertex normals.
fn quads_mesh(v: Vec<Vector3<f64>>, quads: &[[u32; 4]], inside: Vector3<f64>) -> TriMesh {
    let f = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .map(|t| {
            let p = t.map(|i| v[i as usize]);
            let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
            if n.dot(&((p[0] + p[1] + p[2]) / 3.0 - inside)) < 0.0 {
                [t[0], t[2], t[1]]
            } else {
                t
            }
        })
        .collect();
    let mut m = TriMesh {
        v,
        f,
        n: Vec::new(),
    };
    m.compute_normals();
    m
}

impl Surface {
    /// Implicit value `f` (zero on the surface, about the signed distance nearby) and its
    /// gradient (the outward normal direction). `None` for meshes.
    pub fn implicit(&self, x: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        match *self {
            Surface::Sphere { center, radius } => {
                let d = x - center;
                let n = d.norm().max(1e-300);
                Some((n - radius, d / n))
            }
            Surface::Torus {
                center,
                major,
                minor,
            } => {
                let d = x - center;
                let rho = (d.x * d.x + d.y * d.y).sqrt().max(1e-300);
                let q = ((rho - major).powi(2) + d.z * d.z).sqrt().max(1e-300);
                let g = Vector3::new(
                    (rho - major) / q * d.x / rho,
                    (rho - major) / q * d.y / rho,
                    d.z / q,
                );
                Some((q - minor, g))
            }
            Surface::Frustum { z0, r0, z1, r1 } => {
                let k = (r1 - r0) / (z1 - z0);
                let rho = (x.x * x.x + x.y * x.y).sqrt().max(1e-300);
                let s = (1.0 + k * k).sqrt();
                let f = (rho - (r0 + k * (x.z - z0))) / s;
                let g = Vector3::new(x.x / rho, x.y / rho, -k) / s;
                Some((f, g))
            }
            Surface::Paraboloid { a, .. } => {
                let f = x.z - (x.x * x.x + x.y * x.y) / (2.0 * a);
                let g = Vector3::new(-x.x / a, -x.y / a, 1.0);
                let gn = g.norm();
                Some((f / gn, g / gn))
            }
            Surface::Faces(ref f) => f
                .planes
                .iter()
                .map(|(n, d)| (n.dot(x) - d, *n))
                .max_by(|a, b| a.0.total_cmp(&b.0)),
            Surface::Mesh(_) => None,
        }
    }

    /// Moves `x` onto the surface within the plane `normal · x = offset` (Newton steps along
    /// the gradient projected into the plane), returning the point and the unit outward
    /// normal there. Meshes return `x` and `n` unchanged (section points are exact on them).
    pub fn snap_in_plane(
        &self,
        x: Vector3<f64>,
        n: Vector3<f64>,
        plane: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        if matches!(self, Surface::Mesh(_)) {
            return (x, n);
        }
        let mut p = x;
        for _ in 0..30 {
            let Some((f, g)) = self.implicit(&p) else {
                break;
            };
            let gp = g - plane * g.dot(plane);
            let l2 = gp.norm_squared();
            if l2 < 1e-24 {
                break;
            }
            p -= gp * (f / l2);
            if f.abs() < 1e-13 {
                break;
            }
        }
        let g = self.implicit(&p).map(|(_, g)| g).unwrap_or(n);
        (p, g.normalize())
    }

    /// Distance from `x` to the surface (exact for spheres, tori, frustums, accurate to first
    /// order near a paraboloid; meshes: closest triangle).
    pub fn distance(&self, x: &Vector3<f64>) -> f64 {
        match self {
            Surface::Mesh(m) => mesh_distance(m, x),
            Surface::Faces(f) => mesh_distance(&f.mesh, x),
            s => s.implicit(x).map(|(f, _)| f.abs()).unwrap_or(f64::INFINITY),
        }
    }

    /// A triangle mesh of the surface, fine enough to cut sections from.
    pub fn tessellate(&self) -> TriMesh {
        match self {
            Surface::Mesh(m) => (**m).clone(),
            Surface::Faces(f) => f.mesh.clone(),
            Surface::Sphere { center, radius } => grid(
                256,
                128,
                false,
                |u, v| {
                    let (th, ph) = (TAU * u, PI * v);
                    center
                        + Vector3::new(ph.sin() * th.cos(), ph.sin() * th.sin(), -ph.cos())
                            * *radius
                },
                self,
            ),
            Surface::Torus {
                center,
                major,
                minor,
            } => grid(
                256,
                128,
                true,
                |u, v| {
                    let (th, ph) = (TAU * u, TAU * v);
                    let rho = major + minor * ph.cos();
                    center + Vector3::new(rho * th.cos(), rho * th.sin(), minor * ph.sin())
                },
                self,
            ),
            Surface::Frustum { z0, r0, z1, r1 } => grid(
                256,
                64,
                false,
                |u, v| {
                    let th = TAU * u;
                    let (z, r) = (z0 + (z1 - z0) * v, r0 + (r1 - r0) * v);
                    Vector3::new(r * th.cos(), r * th.sin(), z)
                },
                self,
            ),
            Surface::Paraboloid { a, rim } => grid(
                256,
                96,
                false,
                |u, v| {
                    let th = TAU * u;
                    let r = rim * v;
                    Vector3::new(r * th.cos(), r * th.sin(), r * r / (2.0 * a))
                },
                self,
            ),
        }
    }
}

/// Tessellates a parametrisation over `[0,1]²` (periodic in u; also in v if `periodic_v`),
/// with normals from the surface's gradient. A row where the parametrisation collapses to one
/// point (a sphere's pole, a bowl's bottom) becomes a single vertex with a fan of triangles, so
/// that the mesh has no degenerate triangles for sections to stumble on.
fn grid(
    nu: usize,
    nv: usize,
    periodic_v: bool,
    f: impl Fn(f64, f64) -> Vector3<f64>,
    s: &Surface,
) -> TriMesh {
    let rows = if periodic_v { nv } else { nv + 1 };
    let mut m = TriMesh::default();
    // Vertex index of (i, j); collapsed rows map every i to one vertex.
    let mut index: Vec<Vec<u32>> = Vec::with_capacity(rows);
    for j in 0..rows {
        let v = j as f64 / nv as f64;
        let first = f(0.0, v);
        let collapsed = (1..nu).all(|i| (f(i as f64 / nu as f64, v) - first).norm() < 1e-12);
        let mut row = Vec::with_capacity(nu);
        for i in 0..nu {
            if collapsed && i > 0 {
                row.push(row[0]);
                continue;
            }
            let p = f(i as f64 / nu as f64, v);
            let n = s
                .implicit(&p)
                .map(|(_, g)| g.normalize())
                .unwrap_or(Vector3::z());
            row.push(m.v.len() as u32);
            m.v.push(p);
            m.n.push(n);
        }
        index.push(row);
    }
    for j in 0..nv {
        for i in 0..nu {
            let (j1, i1) = ((j + 1) % rows, (i + 1) % nu);
            let (a, b, c, d) = (index[j][i], index[j][i1], index[j1][i1], index[j1][i]);
            for t in [[a, b, c], [a, c, d]] {
                if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                    m.f.push(t);
                }
            }
        }
    }
    m
}

/// Distance from `x` to the closest triangle of `m` (linear scan).
pub fn mesh_distance(m: &TriMesh, x: &Vector3<f64>) -> f64 {
    m.f.iter()
        .map(|f| {
            point_triangle_distance(
                x,
                &m.v[f[0] as usize],
                &m.v[f[1] as usize],
                &m.v[f[2] as usize],
            )
        })
        .fold(f64::INFINITY, f64::min)
}

/// Distance from `p` to the triangle `abc` (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn point_triangle_distance(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> f64 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).norm();
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).norm();
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (p - (a + ab * v + ac * w)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapping_lands_on_the_surface_in_the_plane() {
        let surfaces = [
            Surface::Sphere {
                center: Vector3::zeros(),
                radius: 1.0,
            },
            Surface::Torus {
                center: Vector3::zeros(),
                major: 4.0,
                minor: 2.0,
            },
            Surface::Frustum {
                z0: 0.0,
                r0: 0.4,
                z1: 0.4,
                r1: 0.15,
            },
            Surface::Paraboloid { a: 0.5, rim: 0.4 },
        ];
        let plane = Vector3::new(0.3, -0.5, 0.8).normalize();
        for s in &surfaces {
            let m = s.tessellate();
            let off = plane.dot(&m.v[m.v.len() / 3]);
            let sec = m.slice(&plane, off);
            assert!(!sec.is_empty());
            for (p, n) in sec[0].points.iter().zip(&sec[0].normals).step_by(7) {
                let (q, nq) = s.snap_in_plane(*p, *n, &plane);
                assert!(s.distance(&q) < 1e-9, "{s:?}");
                assert!((plane.dot(&q) - off).abs() < 1e-9);
                assert!((q - p).norm() < 0.05, "moved {}", (q - p).norm());
                assert!(nq.dot(n) > 0.99, "tessellation normal disagrees");
            }
        }
    }

    #[test]
    fn triangle_distance_regions() {
        let (a, b, c) = (Vector3::zeros(), Vector3::x(), Vector3::y());
        assert!(
            (point_triangle_distance(&Vector3::new(0.2, 0.2, 0.5), &a, &b, &c) - 0.5).abs() < 1e-12
        );
        assert!(
            (point_triangle_distance(&Vector3::new(-1.0, -1.0, 0.0), &a, &b, &c) - 2f64.sqrt())
                .abs()
                < 1e-12
        );
        assert!(
            (point_triangle_distance(&Vector3::new(0.5, -1.0, 0.0), &a, &b, &c) - 1.0).abs()
                < 1e-12
        );
        assert!(
            (point_triangle_distance(&Vector3::new(1.0, 1.0, 0.0), &a, &b, &c) - 0.5f64.sqrt())
                .abs()
                < 1e-12
        );
    }
}
