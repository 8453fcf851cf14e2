//! The cotangent Laplacian and the mixed Voronoi areas of a triangle mesh (Meyer, Desbrun,
//! Schröder & Barr 2003), in libigl's conventions.
//!
//! - [`cotmatrix`]: `#V by #V`, symmetric, off-diagonal `L_ij = ½ (cot α_ij + cot β_ij)` over
//!   the angles opposite edge `ij`, diagonal `L_ii = −Σ_j L_ij`: rows sum to zero and `L` is
//!   negative semi-definite. `L · V ≈ −2 H n A` on a surface (H the mean curvature, A the
//!   vertex area, n the outward normal of counter-clockwise triangles).
//! - [`voronoi_areas`]: the mixed Voronoi area of every vertex (Voronoi inside non-obtuse
//!   triangles, half/quarter of the triangle's area at obtuse ones); they sum to the mesh area.
//!
//! Vertices may be 2D (z = 0, the planar triangulation of a patch) or 3D.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs_geometry::surface::cotmatrix::{cotmatrix, voronoi_areas};
//! // Two triangles forming the unit square.
//! let v = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 0.0),
//!          Vector3::new(1.0, 1.0, 0.0), Vector3::new(0.0, 1.0, 0.0)];
//! let f = [[0, 1, 2], [0, 2, 3]];
//! let l = cotmatrix(&v, &f);
//! assert!((l.get(0, 2) - 0.0).abs() < 1e-12); // the diagonal faces right angles: cot 90° = 0
//! assert!((l.get(0, 1) - 0.5).abs() < 1e-12);
//! assert!(l.row_sums().iter().all(|s| s.abs() < 1e-12));
//! let a = voronoi_areas(&v, &f);
//! assert!((a.iter().sum::<f64>() - 1.0).abs() < 1e-12);
//! ```

use nalgebra::Vector3;

/// A symmetric sparse matrix by rows (each row sorted by column, the diagonal included).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseRows {
    pub rows: Vec<Vec<(usize, f64)>>,
}

impl SparseRows {
    /// Sums `(i, j, value)` triplets into rows of an `n × n` matrix.
    pub fn from_triplets(n: usize, t: impl IntoIterator<Item = (usize, usize, f64)>) -> Self {
        let t: Vec<(usize, usize, f64)> = t.into_iter().collect();
        let mut count = vec![0usize; n];
        for &(i, _, _) in &t {
            count[i] += 1;
        }
        let mut rows: Vec<Vec<(usize, f64)>> =
            count.iter().map(|&c| Vec::with_capacity(c)).collect();
        for (i, j, x) in t {
            rows[i].push((j, x));
        }
        for r in &mut rows {
            r.sort_unstable_by_key(|e| e.0);
            let mut w = 0;
            for k in 0..r.len() {
                if w > 0 && r[w - 1].0 == r[k].0 {
                    r[w - 1].1 += r[k].1;
                } else {
                    r[w] = r[k];
                    w += 1;
                }
            }
            r.truncate(w);
        }
        SparseRows { rows }
    }

    pub fn n(&self) -> usize {
        self.rows.len()
    }

    /// Entry `(i, j)` (0 where not stored).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.rows[i]
            .binary_search_by_key(&j, |e| e.0)
            .map_or(0.0, |k| self.rows[i][k].1)
    }

    pub fn row_sums(&self) -> Vec<f64> {
        self.rows
            .iter()
            .map(|r| r.iter().map(|e| e.1).sum())
            .collect()
    }

    /// `self · x` for a vector field.
    pub fn mul(&self, x: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.rows
            .iter()
            .map(|r| r.iter().map(|&(j, w)| x[j] * w).sum())
            .collect()
    }

    /// `self · diag(1/m) · self` (for symmetric `self`): the bilaplacian `Lᵀ M⁻¹ L`, whose
    /// quadratic form is `∫ |Δ f|² dA` discretised.
    pub fn bilaplacian(&self, m: &[f64]) -> SparseRows {
        let n = self.n();
        let mut t = Vec::new();
        for (k, r) in self.rows.iter().enumerate() {
            let inv = 1.0 / m[k];
            for &(i, a) in r {
                for &(j, b) in r {
                    t.push((i, j, a * b * inv));
                }
            }
        }
        SparseRows::from_triplets(n, t)
    }
}

/// Cotangent of the angle at `o` in the triangle (`o`, `a`, `b`).
fn cot(o: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let (u, v) = (a - o, b - o);
    let s = u.cross(&v).norm();
    u.dot(&v) / s
}

/// The cotangent Laplacian, `#V by #V` (see the module docs). Faces are `#F` index triples.
/// Degenerate triangles (zero area) contribute nothing (callers never produce them).
pub fn cotmatrix(v: &[Vector3<f64>], f: &[[usize; 3]]) -> SparseRows {
    let mut t = Vec::with_capacity(f.len() * 9);
    for tri in f {
        let p = [v[tri[0]], v[tri[1]], v[tri[2]]];
        if (p[1] - p[0]).cross(&(p[2] - p[0])).norm() <= 0.0 {
            continue;
        }
        for k in 0..3 {
            let (i, j, o) = (tri[(k + 1) % 3], tri[(k + 2) % 3], tri[k]);
            let w = 0.5 * cot(&v[o], &v[i], &v[j]);
            t.push((i, j, w));
            t.push((j, i, w));
            t.push((i, i, -w));
            t.push((j, j, -w));
        }
    }
    SparseRows::from_triplets(v.len(), t)
}

/// Mixed Voronoi area of every vertex (see the module docs).
pub fn voronoi_areas(v: &[Vector3<f64>], f: &[[usize; 3]]) -> Vec<f64> {
    let mut a = vec![0.0; v.len()];
    for tri in f {
        let p = [v[tri[0]], v[tri[1]], v[tri[2]]];
        let area = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
        if area <= 0.0 {
            continue;
        }
        let dot = |k: usize| (p[(k + 1) % 3] - p[k]).dot(&(p[(k + 2) % 3] - p[k]));
        if let Some(obtuse) = (0..3).find(|&k| dot(k) < 0.0) {
            for k in 0..3 {
                a[tri[k]] += if k == obtuse { area / 2.0 } else { area / 4.0 };
            }
            continue;
        }
        for k in 0..3 {
            // Voronoi region of vertex k: (|e_ki|² cot at j + |e_kj|² cot at i) / 8.
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (pk, pi, pj) = (p[k], p[i], p[j]);
            a[tri[k]] += ((pi - pk).norm_squared() * cot(&pj, &pk, &pi)
                + (pj - pk).norm_squared() * cot(&pi, &pj, &pk))
                / 8.0;
        }
    }
    a
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A jittered planar grid (`n × n` vertices, CCW triangles seen from +z).
    pub fn grid(n: usize, jitter: f64) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
        let mut v = Vec::new();
        let mut s = 12345u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for y in 0..n {
            for x in 0..n {
                let inner = x > 0 && y > 0 && x + 1 < n && y + 1 < n;
                let j = if inner { jitter } else { 0.0 };
                v.push(Vector3::new(x as f64 + j * r(), y as f64 + j * r(), 0.0));
            }
        }
        let mut f = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = y * n + x;
                f.push([i, i + 1, i + n + 1]);
                f.push([i, i + n + 1, i + n]);
            }
        }
        (v, f)
    }

    /// An icosphere of radius 1 with `k` subdivisions (CCW seen from outside).
    pub fn icosphere(k: usize) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut v: Vec<Vector3<f64>> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
        .collect();
        let mut f: Vec<[usize; 3]> = vec![
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
        for _ in 0..k {
            let mut mid = std::collections::HashMap::new();
            let mut m = |a: usize, b: usize, v: &mut Vec<Vector3<f64>>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push(((v[a] + v[b]) / 2.0).normalize());
                    v.len() - 1
                })
            };
            let mut g = Vec::new();
            for [a, b, c] in f {
                let (ab, bc, ca) = (m(a, b, &mut v), m(b, c, &mut v), m(c, a, &mut v));
                g.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            f = g;
        }
        (v, f)
    }

    type Mesh = (Vec<Vector3<f64>>, Vec<[usize; 3]>);

    fn meshes() -> Vec<(&'static str, Mesh)> {
        let (a, b) = grid(8, 0.0);
        let (c, d) = grid(9, 0.6);
        let (e, g) = icosphere(3);
        vec![
            ("grid", (a, b)),
            ("jittered grid", (c, d)),
            ("icosphere", (e, g)),
        ]
    }

    #[test]
    fn rows_sum_to_zero_and_the_matrix_is_symmetric() {
        for (name, (v, f)) in meshes() {
            let l = cotmatrix(&v, &f);
            for (i, r) in l.rows.iter().enumerate() {
                let s: f64 = r.iter().map(|e| e.1).sum();
                assert!(s.abs() < 1e-12, "{name}: row {i} sums to {s}");
                for &(j, x) in r {
                    assert!((l.get(j, i) - x).abs() < 1e-12, "{name}: ({i}, {j})");
                }
                assert!(l.get(i, i) < 0.0, "{name}: diagonal {i}");
            }
        }
    }

    #[test]
    fn linear_functions_are_harmonic_inside_a_planar_mesh() {
        let (v, f) = grid(9, 0.6);
        let l = cotmatrix(&v, &f);
        let lv = l.mul(&v);
        for (i, p) in v.iter().enumerate() {
            let inner = p.x > 0.5 && p.y > 0.5 && p.x < 7.5 && p.y < 7.5;
            if inner {
                assert!(lv[i].norm() < 1e-12, "vertex {i}: {}", lv[i]);
            }
        }
    }

    #[test]
    fn areas_sum_to_the_mesh_area_and_curvature_of_the_sphere_is_one() {
        for (name, (v, f)) in meshes() {
            let a = voronoi_areas(&v, &f);
            let total: f64 = f
                .iter()
                .map(|t| 0.5 * (v[t[1]] - v[t[0]]).cross(&(v[t[2]] - v[t[0]])).norm())
                .sum();
            let s: f64 = a.iter().sum();
            assert!((s - total).abs() < 1e-9 * total, "{name}: {s} vs {total}");
            assert!(a.iter().all(|&x| x > 0.0), "{name}");
        }
        let (v, f) = icosphere(4);
        let l = cotmatrix(&v, &f);
        let a = voronoi_areas(&v, &f);
        let lv = l.mul(&v);
        for i in 0..v.len() {
            // L v = −2 H n A with H = 1 and n = v on the unit sphere.
            let h = -lv[i].dot(&v[i]) / (2.0 * a[i]);
            assert!((h - 1.0).abs() < 0.02, "vertex {i}: H = {h}");
        }
    }

    #[test]
    fn the_bilaplacian_is_symmetric_with_zero_row_sums() {
        let (v, f) = icosphere(2);
        let l = cotmatrix(&v, &f);
        let q = l.bilaplacian(&voronoi_areas(&v, &f));
        for (i, r) in q.rows.iter().enumerate() {
            assert!(r.iter().map(|e| e.1).sum::<f64>().abs() < 1e-9);
            for &(j, x) in r {
                assert!((q.get(j, i) - x).abs() < 1e-9 * x.abs().max(1.0));
            }
        }
    }
}
