//! One pass's factorised system and its solves: the free block of the normal matrix with the
//! constraints hard, or the whole system with them soft; the biharmonic propagation of
//! positions and normals from the curves; the fit of the positions to a target Laplacian.

use super::super::cotmatrix::SparseRows;
use super::assembly::Assembly;
use super::energy::data_weights;
use super::{Method, SurfaceParams};
use crate::sparse_llt::{CachedPattern, SolveError};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::sync::Arc;

/// One pass's factorised system: the free block of the normal matrix (hard constraints), or
/// with soft constraints the whole system, whose one factorisation serves the propagations
/// and the fit (normal control only).
pub(super) enum System {
    Free(FreeSolver),
    Soft(SoftSolver),
}

impl System {
    /// Factorises the normal matrix `q` (`#V` by `#V`, the first `c` vertices constrained),
    /// reusing the symbolic factorisations in the caches, and with faces reused
    /// ([`SurfaceParams::reuse_tolerance`] > 0) the numeric one when the system is the last
    /// one again (a monitored structure: back-substitutions only).
    pub(super) fn precompute(
        q: &SparseRows,
        c: usize,
        g: usize,
        p: &SurfaceParams,
        pattern: &mut CachedPattern,
        soft_pattern: &mut CachedPattern,
    ) -> Result<System, SolveError> {
        Ok(match (p.soft, p.method) {
            (Some(omega), Method::NormalControl) => System::Soft(SoftSolver::with_pattern(
                q,
                data_weights(q, c, g, omega, p.guide_weight),
                soft_pattern,
                p.reuse_tolerance > 0.0,
            )?),
            _ => System::Free(FreeSolver::with_pattern(
                q,
                c,
                data_weights(q, c, g, 0.0, p.guide_weight)[c..].to_vec(),
                pattern,
                p.reuse_tolerance > 0.0,
            )?),
        })
    }

    /// The biharmonic propagation of the normals from the curves (`nstar`, `#V` unit
    /// normals on return), and of the positions in the first pass (every pass for the
    /// comparison methods).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn propagate(
        &self,
        q: &SparseRows,
        pass: usize,
        method: Method,
        asm: &mut Assembly,
        nstar: &mut [Vector3<f64>],
        data: &[Vector3<f64>],
        zero: &[Vector3<f64>],
    ) {
        let c = asm.constrained;
        nstar.clone_from_slice(&asm.normals);
        match self {
            System::Free(solver) => {
                if pass == 0 || method != Method::NormalControl {
                    asm.positions[..data.len()].copy_from_slice(data);
                    solver.solve_pair(q, &mut asm.positions, nstar);
                } else {
                    solver.solve(q, zero, nstar);
                }
            }
            System::Soft(soft) => {
                if pass == 0 {
                    asm.positions[..data.len()].copy_from_slice(data);
                    soft.solve_pair(&mut asm.positions, nstar);
                } else {
                    soft.solve(None, nstar);
                }
                // The curves keep their measured normals (the free ones are propagated).
                nstar[..c].copy_from_slice(&asm.normals[..c]);
            }
        }
        for (i, n) in nstar.iter_mut().enumerate() {
            *n = n.try_normalize(1e-12).unwrap_or_else(|| {
                if i < c {
                    asm.normals[i]
                } else {
                    Vector3::z()
                }
            });
        }
    }

    /// The positions that fit the target `b` (`#V` right-hand sides), the curves' positions
    /// `data` held (hard) or pulled at (soft).
    pub(super) fn fit(
        &self,
        q: &SparseRows,
        b: &[Vector3<f64>],
        positions: &mut [Vector3<f64>],
        data: &[Vector3<f64>],
    ) {
        match self {
            System::Soft(soft) => {
                positions[..data.len()].copy_from_slice(data);
                soft.solve(Some(b), positions);
            }
            System::Free(solver) => {
                // The guides' data (the constrained vertices never move).
                positions[..data.len()].copy_from_slice(data);
                solver.solve(q, b, positions)
            }
        }
    }
}

/// Soft positional constraints: `(Q + W) X = B + W X*` over every vertex, `W` the diagonal of
/// the data weights of the first vertices (the curves' samples, then the guide curves') and
/// `X*` their data (see [`SurfaceParams::soft`]).
pub(super) struct SoftSolver {
    weights: Vec<f64>,
    factor: Arc<crate::sparse_llt::SpdFactor>,
}

impl SoftSolver {
    fn with_pattern(
        q: &SparseRows,
        weights: Vec<f64>,
        cache: &mut CachedPattern,
        keep: bool,
    ) -> Result<Self, SolveError> {
        let n = q.n();
        let w = |i: usize| weights.get(i).copied().unwrap_or(0.0);
        let mut entries = Vec::new();
        let mut vals = Vec::new();
        for i in 0..n {
            let mut has_diag = false;
            for &(j, v) in &q.rows[i] {
                if j <= i {
                    entries.push((i, j));
                    vals.push(if i == j { v + w(i) } else { v });
                    has_diag |= i == j;
                }
            }
            if !has_diag {
                entries.push((i, i));
                vals.push(w(i));
            }
        }
        let factor = cache.factor_kept(n, entries, &vals, keep)?;
        Ok(SoftSolver { weights, factor })
    }

    /// Two propagations at once (`b = 0`), as [`solve`](Self::solve).
    fn solve_pair(&self, x: &mut [Vector3<f64>], y: &mut [Vector3<f64>]) {
        let rhs = |v: &[Vector3<f64>]| -> Vec<[f64; 3]> {
            (0..v.len())
                .map(|i| {
                    let r = v[i] * self.weights.get(i).copied().unwrap_or(0.0);
                    [r.x, r.y, r.z]
                })
                .collect()
        };
        let (mut rx, mut ry) = (rhs(x), rhs(y));
        self.factor.solve_two(&mut rx, &mut ry);
        for (i, (r, s)) in rx.iter().zip(&ry).enumerate() {
            x[i] = Vector3::new(r[0], r[1], r[2]);
            y[i] = Vector3::new(s[0], s[1], s[2]);
        }
    }

    /// `x ← (Q + W)⁻¹ (b + W data)`, `data` the first entries of `x` on entry (`b = 0` when
    /// `None`).
    fn solve(&self, b: Option<&[Vector3<f64>]>, x: &mut [Vector3<f64>]) {
        let mut rhs: Vec<[f64; 3]> = (0..x.len())
            .map(|i| {
                let mut r = b.map_or(Vector3::zeros(), |b| b[i]);
                if let Some(&w) = self.weights.get(i) {
                    r += x[i] * w;
                }
                [r.x, r.y, r.z]
            })
            .collect();
        self.factor.solve(&mut rhs);
        for (xi, r) in x.iter_mut().zip(&rhs) {
            *xi = Vector3::new(r[0], r[1], r[2]);
        }
    }
}

/// Solves `(Q_ff + W_g) X_f = B_f − Q_fc X_c + W_g X*_g` for the free vertices (indices
/// `c..`), in place in `x`: `W_g` the data weights of the guide curves' samples (the first
/// free vertices), `X*_g` their data, read from `x` on entry.
pub(super) struct FreeSolver {
    c: usize,
    /// Weights of the guide samples `c..c + guide.len()`.
    guide: Vec<f64>,
    factor: Arc<crate::sparse_llt::SpdFactor>,
}

impl FreeSolver {
    /// Factorises the free block of `q` (plus the guide weights), reusing the symbolic
    /// factorisation in `cache` when the pattern is the same (a new pass of weights over the
    /// same triangles).
    fn with_pattern(
        q: &SparseRows,
        c: usize,
        guide: Vec<f64>,
        cache: &mut CachedPattern,
        keep: bool,
    ) -> Result<Self, SolveError> {
        let nf = q.n() - c;
        let mut entries = Vec::new();
        let mut vals = Vec::new();
        for i in c..q.n() {
            let wg = guide.get(i - c).copied().unwrap_or(0.0);
            let mut has_diag = false;
            for &(j, w) in &q.rows[i] {
                if j >= c && j <= i {
                    entries.push((i - c, j - c));
                    vals.push(if i == j { w + wg } else { w });
                    has_diag |= i == j;
                }
            }
            if !has_diag && wg > 0.0 {
                entries.push((i - c, i - c));
                vals.push(wg);
            }
        }
        let count = entries.len();
        let (symbolic, numeric) = (cache.symbolic_count(), cache.numeric_count());
        let factor = cache.factor_kept(nf, entries, &vals, keep)?;
        if cache.symbolic_count() > symbolic {
            tracing::debug!(
                "surface: symbolic factorisation of {nf} free unknowns, {count} entries, fill {}",
                factor.fill()
            );
        }
        if cache.numeric_count() == numeric {
            tracing::debug!("surface: the same system again, its factorisation kept");
        }
        Ok(FreeSolver { c, guide, factor })
    }

    /// Two biharmonic fields at once (`b = 0`, one pass over the factor for both).
    fn solve_pair(&self, q: &SparseRows, x: &mut [Vector3<f64>], y: &mut [Vector3<f64>]) {
        let c = self.c;
        let rhs = |v: &[Vector3<f64>]| -> Vec<[f64; 3]> {
            (c..q.n())
                .map(|i| {
                    let wg = self.guide.get(i - c).copied().unwrap_or(0.0);
                    let mut r = v[i] * wg;
                    for &(j, w) in &q.rows[i] {
                        if j < c {
                            r -= v[j] * w;
                        }
                    }
                    [r.x, r.y, r.z]
                })
                .collect()
        };
        let (mut rx, mut ry) = (rhs(x), rhs(y));
        self.factor.solve_two(&mut rx, &mut ry);
        for (i, (r, s)) in rx.iter().zip(&ry).enumerate() {
            x[c + i] = Vector3::new(r[0], r[1], r[2]);
            y[c + i] = Vector3::new(s[0], s[1], s[2]);
        }
    }

    fn solve(&self, q: &SparseRows, b: &[Vector3<f64>], x: &mut [Vector3<f64>]) {
        let c = self.c;
        let mut rhs: Vec<[f64; 3]> = (c..q.n())
            .map(|i| {
                let wg = self.guide.get(i - c).copied().unwrap_or(0.0);
                let mut r = b[i] + x[i] * wg;
                for &(j, w) in &q.rows[i] {
                    if j < c {
                        r -= x[j] * w;
                    }
                }
                [r.x, r.y, r.z]
            })
            .collect();
        self.factor.solve(&mut rhs);
        for (i, r) in rhs.iter().enumerate() {
            x[c + i] = Vector3::new(r[0], r[1], r[2]);
        }
    }
}

/// Moves the copies of each vertex along a crease (constrained, `primary[i] < c`) to their
/// mean: with soft constraints each side pulls its copy a little its own way.
pub(super) fn weld(positions: &mut [Vector3<f64>], primary: &[usize], c: usize) {
    let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, &p) in primary.iter().enumerate().take(c) {
        if p != i {
            groups.entry(p).or_insert_with(|| vec![p]).push(i);
        }
    }
    for members in groups.values() {
        let mean =
            members.iter().map(|&k| positions[k]).sum::<Vector3<f64>>() / members.len() as f64;
        for &k in members {
            positions[k] = mean;
        }
    }
}

/// The triharmonic comparison method: `L³V = 0` as the minimum of `∫|∇ΔV|²`, whose normal
/// matrix is `−Lc M⁻¹ Lc M⁻¹ Lc = −Lc M⁻¹ Q` (symmetric, positive semi-definite since `−Lc`
/// is; `q` the pass's `Q`, `rows` the energy's rows), the curves' samples `data` held and the
/// guides' pulled at with `guide_weight`. Its own factorisation, not cached.
pub(super) fn triharmonic(
    asm: &mut Assembly,
    q: &SparseRows,
    rows: &[bool],
    data: &[Vector3<f64>],
    guide_weight: f64,
    zero: &[Vector3<f64>],
) -> Result<(), SolveError> {
    let (nv, c) = (asm.positions.len(), asm.constrained);
    let mut t = Vec::new();
    for (k, r) in asm.lc.rows.iter().enumerate() {
        if asm.mass[k] <= 0.0 || !rows[k] {
            continue;
        }
        let s = -1.0 / asm.mass[k];
        for &(i, a) in r {
            for &(j, b) in &q.rows[k] {
                t.push((i, j, a * b * s));
            }
        }
    }
    let q3 = SparseRows::from_triplets(nv, t);
    let mut own = CachedPattern::default();
    let guide = data_weights(&q3, c, asm.guided, 0.0, guide_weight)[c..].to_vec();
    asm.positions[..data.len()].copy_from_slice(data);
    FreeSolver::with_pattern(&q3, c, guide, &mut own, false)?.solve(&q3, zero, &mut asm.positions);
    Ok(())
}
