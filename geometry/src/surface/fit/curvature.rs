//! The mean-curvature guide of formula (1) (Stanko et al. 2016).

use super::assembly::Assembly;
use nalgebra::Vector3;

/// The mean-curvature vectors of formula (1), as Sullivan's conormal integral evaluated with
/// the propagated normals: at each vertex, `−(1/A) Σ n̂ × (v_b − v_a)` over the edges
/// `a → b` opposite to it in its counter-clockwise triangles, `A` the area of its star. With
/// outward normals this estimates `Δv = −2Hn`: −2.000 on a unit icosphere (tested).
///
/// One deviation from the paper, by measurement: formula (1) takes `n̂` as the normalised
/// sum of the vertex's normal and both edge ends', which tilts the conormals only about
/// two-thirds as much as the surface does at the edge: on the unit icosphere it gives
/// −1.333 instead of −2 (with the star area; ×3 with the Voronoi area the paper names).
/// Here `n̂` is the normal at the edge's midpoint, `normalise(n_a + n_b)`.
pub fn mean_curvature_vectors(
    v: &[Vector3<f64>],
    n: &[Vector3<f64>],
    f: &[[usize; 3]],
) -> Vec<Vector3<f64>> {
    let mut area = vec![0.0; v.len()];
    let mut h = vec![Vector3::zeros(); v.len()];
    for t in f {
        let ta = 0.5 * (v[t[1]] - v[t[0]]).cross(&(v[t[2]] - v[t[0]])).norm();
        for k in 0..3 {
            let (o, a, b) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let nn = (n[a] + n[b]).try_normalize(1e-12).unwrap_or(n[o]);
            h[o] += nn.cross(&(v[b] - v[a]));
            area[o] += ta;
        }
    }
    for (x, a) in h.iter_mut().zip(area) {
        *x = if a > 0.0 {
            *x / a * -1.0
        } else {
            Vector3::zeros()
        };
    }
    h
}

/// The normal-control fit's right-hand side `Σ_k Lc_kᵀ t_k` (`#V`) over the energy's `rows`:
/// the target Laplacian `t_k` is the mean-curvature vector of formula (1) on the propagated
/// positions and normals (`nstar`), projected on the propagated normal.
pub(super) fn normal_control_target(
    asm: &Assembly,
    nstar: &[Vector3<f64>],
    rows: &[bool],
) -> Vec<Vector3<f64>> {
    let h = mean_curvature_vectors(&asm.positions, nstar, &asm.triangles);
    let mut b = vec![Vector3::zeros(); asm.positions.len()];
    for (k, r) in asm.lc.rows.iter().enumerate() {
        if !rows[k] {
            continue;
        }
        let tk = nstar[k] * h[k].dot(&nstar[k]);
        for &(i, w) in r {
            b[i] += tk * w;
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::cotmatrix::tests::icosphere;

    #[test]
    fn formula_one_estimates_the_laplacian_on_the_sphere() {
        let (v, f) = icosphere(4);
        let h = mean_curvature_vectors(&v, &v, &f);
        for (i, x) in h.iter().enumerate() {
            // Δv = −2Hn = −2v on the unit sphere.
            let normal = x.dot(&v[i]);
            let tangential = (x - v[i] * normal).norm();
            assert!(
                (normal + 2.0).abs() < 0.03 && tangential < 0.05,
                "vertex {i}: {x}"
            );
        }
    }
}
