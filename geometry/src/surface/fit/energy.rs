//! The energy's rows and weights: the vertices whose ring is closed, the cotangent weights
//! and areas summed from the pieces (planar, or of the surface of the last pass: the
//! reweighting), the normal matrix `Q = Lcᵀ M⁻¹ Lc` and the data terms' weights.

use super::super::cotmatrix::{cotmatrix, voronoi_areas, SparseRows};
use super::super::faces::Weights;
use super::assembly::{parallel_map, Assembly, Piece};
use nalgebra::Vector3;
use std::sync::Arc;

/// The vertices that are rows of the energy: those whose ring is closed (every edge around
/// them in two triangles). `#V` flags.
pub(super) fn energy_rows(asm: &Assembly) -> Vec<bool> {
    let nv = asm.positions.len();
    let mut edges: Vec<(usize, usize)> = Vec::with_capacity(3 * asm.triangles.len());
    for t in &asm.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.push((a.min(b), a.max(b)));
        }
    }
    edges.sort_unstable();
    let mut rows = vec![true; nv];
    let mut used = vec![false; nv];
    for t in &asm.triangles {
        for &i in t {
            used[i] = true;
        }
    }
    let mut k = 0;
    while k < edges.len() {
        let mut m = k + 1;
        while m < edges.len() && edges[m] == edges[k] {
            m += 1;
        }
        if m - k != 2 {
            rows[edges[k].0] = false;
            rows[edges[k].1] = false;
        }
        k = m;
    }
    for i in 0..nv {
        if !used[i] {
            rows[i] = false;
        }
    }
    rows
}

/// The sum of per-piece weights (each piece's local → global ids and one of its weights)
/// into global `#V by #V` cotangent rows and `#V` areas.
pub(super) fn sum_weights<'a>(
    nv: usize,
    pieces: impl Iterator<Item = (&'a [usize], &'a Weights)>,
) -> (SparseRows, Vec<f64>) {
    let mut trip = Vec::new();
    let mut mass = vec![0.0; nv];
    for (g, w) in pieces {
        for (i, row) in w.l.rows.iter().enumerate() {
            for &(j, x) in row {
                trip.push((g[i], g[j], x));
            }
        }
        for (i, a) in w.areas.iter().enumerate() {
            mass[g[i]] += a;
        }
    }
    (SparseRows::from_triplets(nv, trip), mass)
}

/// The weights of the part of the surface at `positions` of each of the pieces `which` (on
/// worker threads).
pub(super) fn surface_weights(
    pieces: &[Piece],
    which: &[usize],
    positions: &[Vector3<f64>],
) -> Vec<Arc<Weights>> {
    parallel_map(which, |&i| {
        let pc = &pieces[i];
        let pts: Vec<Vector3<f64>> = pc.g.iter().map(|&i| positions[i]).collect();
        Arc::new(Weights {
            l: cotmatrix(&pts, &pc.face.mesh.triangles),
            areas: voronoi_areas(&pts, &pc.face.mesh.triangles),
        })
    })
}

/// `Σ_k∈rows Lc_kᵀ Lc_k / m_k` and the rows' right-hand side `Σ_k Lc_kᵀ t_k`.
pub(super) fn normal_matrix(lc: &SparseRows, m: &[f64], rows: &[bool]) -> SparseRows {
    // Row i of Q is Σ_k Lc_ik / m_k · (row k of Lc) over its neighbours k (Lc symmetric),
    // gathered with a dense accumulator: linear in the entries, no sort of triplets.
    let n = lc.n();
    let mut acc = vec![0.0; n];
    let mut seen = vec![false; n];
    let mut cols: Vec<usize> = Vec::new();
    let mut out = Vec::with_capacity(n);
    for ri in &lc.rows {
        cols.clear();
        for &(k, a) in ri {
            if !rows[k] || m[k] <= 0.0 {
                continue;
            }
            let f = a / m[k];
            for &(j, b) in &lc.rows[k] {
                if !seen[j] {
                    seen[j] = true;
                    cols.push(j);
                }
                acc[j] += f * b;
            }
        }
        cols.sort_unstable();
        let row: Vec<(usize, f64)> = cols
            .iter()
            .map(|&j| {
                let v = acc[j];
                acc[j] = 0.0;
                seen[j] = false;
                (j, v)
            })
            .collect();
        out.push(row);
    }
    SparseRows { rows: out }
}

/// The weights of the data terms: `omega` (relative) on the first `c` vertices, `omega_g` on
/// the `g` after them (the guide curves' samples), each times the mean diagonal of `q` over
/// its rows so that they are dimensionless. `#(c + g)` weights.
pub(super) fn data_weights(
    q: &SparseRows,
    c: usize,
    g: usize,
    omega: f64,
    omega_g: f64,
) -> Vec<f64> {
    let mean = |r: std::ops::Range<usize>| {
        let n = r.len().max(1) as f64;
        r.map(|i| q.get(i, i)).sum::<f64>() / n
    };
    let (w, wg) = (omega * mean(0..c), omega_g * mean(c..c + g));
    (0..c + g).map(|i| if i < c { w } else { wg }).collect()
}
