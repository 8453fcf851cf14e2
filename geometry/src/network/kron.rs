//! Kron reduction of the Poisson Laplacian onto the nodes (issue 51): every run of samples
//! between two tags is a path in the graph, so its unknowns can be eliminated exactly, leaving
//! a Laplacian over the nodes alone (the Schur complement: each run a single edge of the
//! series conductance `W = 1/Σ_k 1/w_k`) and, per run, a tridiagonal system for its samples.
//!
//! A solve of `L x = b` over every unknown is then
//! 1. per run, `z = T⁻¹ b_I` (`T`: the run's #interior by #interior tridiagonal block of `L`),
//!    added to its end nodes' right-hand side through the edges to them: `b_a += w_a z_first`,
//!    `b_b += w_b z_last` (the Schur complement's right-hand side, `b_N − L_NI T⁻¹ b_I`);
//! 2. the node system `S x_N = b_N` (#nodes square, factorised by sparse Cholesky with its
//!    symbolic factorisation kept while its pattern stays the same);
//! 3. per run, `x_I = T⁻¹ (b_I + w_a x_a e_first + w_b x_b e_last)`.
//!
//! The same solution as a factorisation of the whole Laplacian, in a different order of
//! arithmetic; its cost is the node system's plus O(samples), where the whole Laplacian's
//! symbolic factorisation (a new pattern at every live update) alone took most of Poisson.
//!
//! Where the right-hand side is edge data (Poisson's: `b = Dᵀ W v`), steps 1 and 3 have a
//! closed form, [`Series`]: a run is one edge of its series conductance and its data summed,
//! and its samples follow the data with the misfit shared in proportion to each edge's
//! resistance. No tridiagonal solve, and what a run gives the node system is the run's alone
//! (kept with it while it stays the same). [`NodeSystem`] is step 2 by itself.
//!
//! ```
//! use sfs_geometry::network::kron::{KronReduced, Run};
//! // A path 0 – 2 – 3 – 1 with nodes 0 and 1 (unknowns 0..2 are nodes): unit weights, the
//! // node 0 held by a gauge; the data pulls each edge by +1.
//! let chain = vec![0, 2, 3, 1];
//! let w = vec![1.0; 3];
//! let runs = Run::along(&chain, &w, 2);
//! let mut cache = sfs_geometry::sparse_llt::CachedPattern::default();
//! let k = KronReduced::new(4, 2, &runs, 1.0, &mut cache).unwrap();
//! // Right-hand side of the edges' data (+1 on each edge: b_end += 1, b_start −= 1).
//! let mut b = vec![[-1.0], [1.0], [0.0], [0.0]];
//! k.solve(&mut b);
//! let x: Vec<f64> = b.iter().map(|v| v[0]).collect();
//! for (got, want) in x.iter().zip([0.0, 3.0, 1.0, 2.0]) {
//!     assert!((got - want).abs() < 1e-12, "{x:?}");
//! }
//! ```

use crate::sparse_llt::{CachedPattern, SolveError, SpdFactor};
use nalgebra::Vector3;
use std::borrow::Cow;
use std::ops::Range;
use std::sync::Arc;

/// A run of samples along one curve between two tags (or a curve's end), in the curve's own
/// sample indices: the samples of the tags at its ends, and the samples between them. Its
/// edges are those from its first sample to its last ([`edges`](Self::edges)). It depends
/// on the curve's tags alone, so a curve's spans are kept with it while its tags stay.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Span {
    pub start: Option<usize>,
    pub end: Option<usize>,
    pub interior: Range<usize>,
}

impl Span {
    /// The spans of a curve of `node_at.len()` samples, `node_at[j]` the node tagged at
    /// sample `j` (if any). A span between two tags of the same node on adjacent samples (an
    /// edge of a node to itself) has no interior and no edge: it constrains nothing and is
    /// left out.
    pub fn along<T: PartialEq + Copy>(node_at: &[Option<T>]) -> Vec<Span> {
        let mut spans = Vec::new();
        let mut from: Option<usize> = None;
        for (j, at) in node_at.iter().enumerate() {
            if let Some(node) = at {
                let first = from.map_or(0, |s| s + 1);
                let to_itself = from.is_some_and(|s| node_at[s] == Some(*node));
                if j > 0 && !(first == j && to_itself) {
                    spans.push(Span {
                        start: from,
                        end: Some(j),
                        interior: first..j,
                    });
                }
                from = Some(j);
            }
        }
        let first = from.map_or(0, |s| s + 1);
        if first < node_at.len() {
            spans.push(Span {
                start: from,
                end: None,
                interior: first..node_at.len(),
            });
        }
        spans
    }

    /// Its edges (edge `j`: from sample `j` to `j + 1`): `interior.len() − 1`, one more for
    /// each end present.
    pub fn edges(&self) -> Range<usize> {
        let first = self.start.unwrap_or(self.interior.start);
        let last = self.end.unwrap_or(self.interior.end.saturating_sub(1));
        first..last.max(first)
    }

    /// Its edges' series (`w`, `v`: the curve's edges' weights and data, edge `j` from sample
    /// `j` to `j + 1`), and at each of its samples from its first (its start tag's, or its
    /// first interior one) to its last interior one, the sums over its edges before it:
    /// `cum_r[j] = Σ 1/w_e`, `cum_v[j] = Σ v_e` (indexed by the curve's samples).
    pub fn series(
        &self,
        w: &[f64],
        v: &[Vector3<f64>],
        cum_r: &mut [f64],
        cum_v: &mut [Vector3<f64>],
    ) -> Series {
        let (mut r, mut sum) = (0.0, Vector3::zeros());
        // Edge e starts at sample e: the sums before it.
        for e in self.edges() {
            cum_r[e] = r;
            cum_v[e] = sum;
            r += w[e].recip();
            sum += v[e];
        }
        // The last interior sample of a run with no end (no edge after it).
        if let (None, Some(last)) = (self.end, self.interior.clone().last()) {
            cum_r[last] = r;
            cum_v[last] = sum;
        }
        Series { r, v: sum }
    }
}

/// A run's edges in series, in closed form: for edge data `v` with weights `w` along a path,
/// the least squares `Σ_e w_e |x_{e+1} − x_e − v_e|²` with the path's ends `x_a`, `x_b` held
/// is one edge of conductance `W = 1/R`, `R = Σ_e 1/w_e`, and data `V = Σ_e v_e`: its
/// minimum is `W |x_b − x_a − V|²`, at `x_j = x_a + P_j + R_j λ`, `λ = W (x_b − x_a − V)`
/// (`P_j`, `R_j` the sums over the edges before sample `j`: each edge takes the data's
/// misfit in proportion to its resistance). The Schur complement of the module's solve, for
/// a right-hand side that is edge data (Poisson's): no tridiagonal solve, and what a run
/// gives the node system depends on the run alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Series {
    /// `R = Σ_e 1/w_e` (summed in order along the run, as [`Run::conductance`]'s).
    pub r: f64,
    /// `V = Σ_e v_e`.
    pub v: Vector3<f64>,
}

impl Series {
    /// `W = 1/R`: [`Run::conductance`]'s, to the bit.
    pub fn conductance(&self) -> f64 {
        1.0 / self.r
    }

    /// The samples of `span` between its ends (its interior), written to `out` (indexed by
    /// the curve's samples), given its ends (`None`: no tag there) and the sums before each
    /// sample ([`Span::series`]). With one end the run follows its data from it; with none
    /// (a curve without tags) from its first sample at the origin (its gauge).
    pub fn place(
        &self,
        span: &Span,
        ends: (Option<Vector3<f64>>, Option<Vector3<f64>>),
        cum_r: &[f64],
        cum_v: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) {
        let at = span.interior.clone();
        match ends {
            (Some(a), Some(b)) => {
                let lambda = (b - a - self.v) / self.r;
                for j in at {
                    out[j] = a + cum_v[j] + lambda * cum_r[j];
                }
            }
            (Some(a), None) => {
                for j in at {
                    out[j] = a + cum_v[j];
                }
            }
            (None, Some(b)) => {
                for j in at {
                    out[j] = b - (self.v - cum_v[j]);
                }
            }
            (None, None) => {
                for j in at {
                    out[j] = cum_v[j];
                }
            }
        }
    }

    /// Its least squares' minimum with its ends at `a` and `b`: `W |b − a − V|²`.
    pub fn misfit(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        (b - a - self.v).norm_squared() / self.r
    }
}

/// A run of samples between two tags (or a curve's end) in a network's unknowns: the node
/// unknowns at its ends, its interior unknowns (consecutive: no node among them), and the
/// weights of its edges in order (`interior.len() − 1` between the interior samples, one more
/// for each end present).
#[derive(Debug, Clone, PartialEq)]
pub struct Run<'w> {
    pub start: Option<usize>,
    pub end: Option<usize>,
    pub interior: Range<usize>,
    pub weights: &'w [f64],
}

impl<'w> Run<'w> {
    /// The runs of one curve: `vars` its unknown at each sample (the nodes' below `nodes`,
    /// the others numbered consecutively along it), `weights` its edges' (`vars.len() − 1`).
    /// See [`Span::along`].
    pub fn along(vars: &[usize], weights: &'w [f64], nodes: usize) -> Vec<Run<'w>> {
        let node_at: Vec<Option<usize>> = vars.iter().map(|&v| (v < nodes).then_some(v)).collect();
        Span::along(&node_at)
            .iter()
            .map(|s| Run::of(s, vars, weights))
            .collect()
    }

    /// `span` of a curve in a network's unknowns: `vars` the curve's unknown at each sample
    /// (the others than its tags' numbered consecutively along it), `weights` its edges'.
    pub fn of(span: &Span, vars: &[usize], weights: &'w [f64]) -> Run<'w> {
        let interior = match span.interior.clone() {
            r if r.is_empty() => 0..0,
            r => vars[r.start]..vars[r.end - 1] + 1,
        };
        debug_assert_eq!(interior.len(), span.interior.len(), "consecutive unknowns");
        Run {
            start: span.start.map(|s| vars[s]),
            end: span.end.map(|e| vars[e]),
            interior,
            weights: &weights[span.edges()],
        }
    }

    /// No node at either end (a curve without tags): its block carries its component's gauge.
    pub fn alone(&self) -> bool {
        self.start.is_none() && self.end.is_none()
    }

    /// The series conductance between its two ends; `None` when it has not two distinct ends
    /// (a curve's end, or a loop back to the node it left: no coupling in the node system).
    pub fn conductance(&self) -> Option<(usize, usize, f64)> {
        match (self.start, self.end) {
            (Some(a), Some(b)) if a != b => Some((
                a,
                b,
                1.0 / self.weights.iter().map(|w| w.recip()).sum::<f64>(),
            )),
            _ => None,
        }
    }
}

/// One run's tridiagonal block `T` factorised as `L D Lᵀ` (unit lower bidiagonal `L`).
#[derive(Debug, Clone)]
pub struct Tridiagonal {
    /// The pivots `D`.
    d: Vec<f64>,
    /// `L`'s subdiagonal (`len − 1`).
    l: Vec<f64>,
}

impl Tridiagonal {
    /// Of the run's interior, with `ridge` added to its first unknown (a gauge): the ridge
    /// of a run with no node at all ([`KronReduced::new`]'s).
    pub fn of(run: &Run, ridge: f64) -> Result<Self, SolveError> {
        let m = run.interior.len();
        let off = usize::from(run.start.is_some());
        // Edge k of the interior (between interior k and k+1) is weights[off + k]; the edge
        // into interior k from before is weights[off + k − 1] (or the start's).
        let before = |k: usize| -> f64 {
            if k == 0 {
                if off == 1 {
                    run.weights[0]
                } else {
                    0.0
                }
            } else {
                run.weights[off + k - 1]
            }
        };
        let after = |k: usize| -> f64 { run.weights.get(off + k).copied().unwrap_or(0.0) };
        let mut d = Vec::with_capacity(m);
        let mut l = Vec::with_capacity(m.saturating_sub(1));
        for k in 0..m {
            let mut diag = before(k) + after(k) + if k == 0 { ridge } else { 0.0 };
            if k > 0 {
                let b = -before(k);
                let lk = b / d[k - 1];
                diag -= lk * b;
                l.push(lk);
            }
            if !(diag.is_finite() && diag > 0.0) {
                return Err(SolveError::NonPositivePivot {
                    index: run.interior.start + k,
                });
            }
            d.push(diag);
        }
        Ok(Tridiagonal { d, l })
    }

    /// `r ← T⁻¹ r`, each of the K columns.
    fn solve<const K: usize>(&self, r: &mut [[f64; K]]) {
        for (k, &l) in self.l.iter().enumerate() {
            let prev = r[k];
            axpy(&mut r[k + 1], -l, &prev);
        }
        for (rk, &d) in r.iter_mut().zip(&self.d) {
            rk.iter_mut().for_each(|v| *v /= d);
        }
        for (k, &l) in self.l.iter().enumerate().rev() {
            let next = r[k + 1];
            axpy(&mut r[k], -l, &next);
        }
    }
}

/// `y ← y + a x`.
fn axpy<const K: usize>(y: &mut [f64; K], a: f64, x: &[f64; K]) {
    y.iter_mut().zip(x).for_each(|(y, x)| *y += a * x);
}

/// The Laplacian over `n` unknowns, of which `0..nodes` are nodes, reduced onto the nodes
/// (see the module's documentation), with one gauge per connected component: on its lowest
/// node, or on the first sample of a run with no node at all.
pub struct KronReduced<'a> {
    runs: &'a [Run<'a>],
    blocks: Vec<Cow<'a, Tridiagonal>>,
    system: NodeSystem,
}

/// The node system `S` alone (step 2 of the module's solve): the Laplacian over the nodes of
/// the runs' series conductances, one gauge per connected component, factorised.
pub struct NodeSystem {
    factor: Arc<SpdFactor>,
    nodes: usize,
    components: usize,
}

impl NodeSystem {
    /// The Laplacian over `nodes` of the `edges` (`(a, b, conductance)`, `a ≠ b`, in the
    /// runs' order: [`Run::conductance`], or [`Series::conductance`]), with `ridge` on the
    /// lowest node of each component, factorised through `cache` (its symbolic
    /// factorisation kept, and its numeric one for the same values again); `free` runs with
    /// no node at all are components of their own.
    pub fn new(
        nodes: usize,
        edges: &[(usize, usize, f64)],
        free: usize,
        ridge: f64,
        cache: &mut CachedPattern,
    ) -> Result<Self, SolveError> {
        let mut sets = crate::union_find::UnionFind::new(nodes);
        for &(a, b, _) in edges {
            sets.union(a, b);
        }
        let gauges: Vec<usize> = sets.roots().collect();
        let mut entries: Vec<(usize, usize)> = (0..nodes).map(|i| (i, i)).collect();
        entries.extend(edges.iter().map(|&(a, b, _)| (a.max(b), a.min(b))));
        let mut vals = vec![0.0; entries.len()];
        for (k, &(a, b, w)) in edges.iter().enumerate() {
            vals[a] += w;
            vals[b] += w;
            vals[nodes + k] -= w;
        }
        for &g in &gauges {
            vals[g] += ridge;
        }
        // Kept: the same node system again (another solve of the same curves, or after a
        // live update's loop test on them) is not factorised again.
        let factor = if nodes > 0 {
            cache.factor_kept(nodes, entries, &vals, true)?
        } else {
            // No node: every run is a curve alone; a 1 by 1 system stands in for the nodes'.
            cache.factor_kept(1, vec![(0, 0)], &[1.0], true)?
        };
        Ok(NodeSystem {
            factor,
            nodes,
            components: gauges.len() + free,
        })
    }

    /// The connected components (each with its gauge).
    pub fn components(&self) -> usize {
        self.components
    }

    /// `node_b ← S⁻¹ node_b` (#nodes by K).
    pub fn solve<const K: usize>(&self, node_b: &mut [[f64; K]]) {
        if self.nodes > 0 {
            self.factor.solve(node_b);
        }
    }
}

impl<'a> KronReduced<'a> {
    /// Factorises the node system (`cache` keeps its symbolic factorisation, and its numeric
    /// one for the same values again) and every run's block; `ridge` is the gauges' weight.
    pub fn new(
        n: usize,
        nodes: usize,
        runs: &'a [Run<'a>],
        ridge: f64,
        cache: &mut CachedPattern,
    ) -> Result<Self, SolveError> {
        let blocks = runs
            .iter()
            .map(|r| Tridiagonal::of(r, Self::run_ridge(r, ridge)).map(Cow::Owned))
            .collect::<Result<Vec<_>, _>>()?;
        Self::with_blocks(n, nodes, runs, blocks, ridge, cache)
    }

    /// The ridge of a run's block: `ridge` for a run with no node at all (its gauge).
    pub fn run_ridge(run: &Run, ridge: f64) -> f64 {
        if run.alone() {
            ridge
        } else {
            0.0
        }
    }

    /// As [`new`](Self::new), with every run's block given (`Tridiagonal::of(run,
    /// Self::run_ridge(run, ridge))`, kept from an earlier solve of the same curve).
    pub fn with_blocks(
        n: usize,
        nodes: usize,
        runs: &'a [Run<'a>],
        blocks: Vec<Cow<'a, Tridiagonal>>,
        ridge: f64,
        cache: &mut CachedPattern,
    ) -> Result<Self, SolveError> {
        debug_assert!(runs.iter().all(|r| r.interior.end <= n));
        debug_assert_eq!(blocks.len(), runs.len());
        let edges: Vec<(usize, usize, f64)> = runs.iter().filter_map(Run::conductance).collect();
        let free = runs.iter().filter(|r| r.alone()).count();
        let system = NodeSystem::new(nodes, &edges, free, ridge, cache)?;
        Ok(KronReduced {
            runs,
            blocks,
            system,
        })
    }

    /// The connected components (each with its gauge).
    pub fn components(&self) -> usize {
        self.system.components
    }

    /// Step 1 of [`solve`](Self::solve) for the runs `which` alone: adds to `node_b` (#nodes
    /// by K) what their interiors' part of `b` (#unknowns by K) brings to the node system
    /// (`−L_NI T⁻¹ b_I`), and returns `Σ b_Iᵀ T⁻¹ b_I` over them (summed over the K columns).
    /// The interiors' block of `L` is block diagonal (runs meet only at nodes), so for
    /// right-hand sides `b`, `b'` on the interiors of different runs (and any nodes)
    /// `bᵀ L⁻¹ b' = b̃ᵀ S⁻¹ b̃'` with `b̃` so reduced, and `bᵀ L⁻¹ b = b̃ᵀ S⁻¹ b̃` plus the
    /// returned sum ([`solve_nodes`](Self::solve_nodes) applies `S⁻¹`).
    pub fn reduce<const K: usize>(
        &self,
        b: &[[f64; K]],
        which: std::ops::Range<usize>,
        node_b: &mut [[f64; K]],
    ) -> f64 {
        self.reduce_runs(b, which, node_b, true)
    }

    /// Step 1 for the runs `which`: their `−L_NI T⁻¹ b_I` added to `node_b`, and with
    /// `energy`, `Σ b_Iᵀ T⁻¹ b_I` over them (else 0).
    fn reduce_runs<const K: usize>(
        &self,
        b: &[[f64; K]],
        which: std::ops::Range<usize>,
        node_b: &mut [[f64; K]],
        energy: bool,
    ) -> f64 {
        let mut sum = 0.0;
        let mut z: Vec<[f64; K]> = Vec::new();
        for (run, t) in self.runs[which.clone()].iter().zip(&self.blocks[which]) {
            z.clear();
            z.extend_from_slice(&b[run.interior.clone()]);
            t.solve(&mut z);
            if energy {
                sum += b[run.interior.clone()]
                    .iter()
                    .zip(&z)
                    .map(|(bv, zv)| bv.iter().zip(zv).map(|(x, y)| x * y).sum::<f64>())
                    .sum::<f64>();
            }
            if let (Some(a), Some(first)) = (run.start, z.first()) {
                axpy(&mut node_b[a], run.weights[0], first);
            }
            if let (Some(e), Some(last), Some(&w)) = (run.end, z.last(), run.weights.last()) {
                axpy(&mut node_b[e], w, last);
            }
        }
        sum
    }

    /// `node_b ← S⁻¹ node_b` (#nodes by K): step 2 of [`solve`](Self::solve).
    pub fn solve_nodes<const K: usize>(&self, node_b: &mut [[f64; K]]) {
        self.system.solve(node_b);
    }

    /// `b ← L⁻¹ b` (#unknowns by K).
    pub fn solve<const K: usize>(&self, b: &mut [[f64; K]]) {
        let nodes = self.system.nodes;
        let mut node_b: Vec<[f64; K]> = b[..nodes].to_vec();
        self.reduce_runs(b, 0..self.runs.len(), &mut node_b, false);
        self.solve_nodes(&mut node_b);
        for (run, t) in self.runs.iter().zip(&self.blocks) {
            // Runs meet only at nodes: each interior is solved in place.
            let z = &mut b[run.interior.clone()];
            if z.is_empty() {
                continue;
            }
            if let Some(a) = run.start {
                axpy(&mut z[0], run.weights[0], &node_b[a]);
            }
            if let (Some(e), Some(&w), Some(last)) = (run.end, run.weights.last(), z.last_mut()) {
                axpy(last, w, &node_b[e]);
            }
            t.solve(z);
        }
        b[..nodes].copy_from_slice(&node_b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The dense Laplacian of the runs with the same gauges, solved by nalgebra's Cholesky.
    fn dense(n: usize, runs: &[Run], ridge: f64, b: &[[f64; 1]]) -> Vec<f64> {
        let mut l = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut sets = crate::union_find::UnionFind::new(n);
        for r in runs {
            let chain: Vec<usize> = r
                .start
                .into_iter()
                .chain(r.interior.clone())
                .chain(r.end)
                .collect();
            for (w, e) in r.weights.iter().zip(chain.windows(2)) {
                let (a, b) = (e[0], e[1]);
                sets.union(a, b);
                l[(a, a)] += w;
                l[(b, b)] += w;
                l[(a, b)] -= w;
                l[(b, a)] -= w;
            }
        }
        for g in sets.roots().collect::<Vec<_>>() {
            l[(g, g)] += ridge;
        }
        let rhs = nalgebra::DVector::from_iterator(n, b.iter().map(|v| v[0]));
        l.cholesky()
            .expect("SPD")
            .solve(&rhs)
            .iter()
            .copied()
            .collect()
    }

    #[test]
    fn the_reduced_solve_is_the_whole_laplacians() {
        let mut rng = Rng::new(7);
        for case in 0..20 {
            // Nodes 0..5; curves through some of them with samples between.
            let nodes = 5;
            let mut n = nodes;
            let mut curves = Vec::new();
            for _ in 0..(2 + case % 4) {
                let len = 3 + (rng.uniform() * 12.0) as usize;
                let vars: Vec<usize> = (0..len)
                    .map(|j| {
                        if rng.uniform() < 0.3 && j % 2 == 0 {
                            (rng.uniform() * nodes as f64) as usize % nodes
                        } else {
                            n += 1;
                            n - 1
                        }
                    })
                    .collect();
                let w: Vec<f64> = (1..len).map(|_| 0.5 + rng.uniform() * 2.0).collect();
                curves.push((vars, w));
            }
            let runs: Vec<Run> = curves
                .iter()
                .flat_map(|(vars, w)| Run::along(vars, w, nodes))
                .collect();
            // Nodes no run reaches stay with their gauge alone.
            let b: Vec<[f64; 1]> = (0..n).map(|_| [rng.uniform() - 0.5]).collect();
            let want = dense(n, &runs, 1.3, &b);
            let mut cache = CachedPattern::default();
            let k = KronReduced::new(n, nodes, &runs, 1.3, &mut cache).expect("factorised");
            let mut got = b.clone();
            k.solve(&mut got);
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    (g[0] - w).abs() < 1e-9 * (1.0 + w.abs()),
                    "case {case}: {g:?} vs {w}"
                );
            }
        }
    }

    #[test]
    fn a_loop_back_to_its_node_and_a_curve_without_nodes_are_solved() {
        // Node 0; a loop 0 – 1 – 2 – 0, and a curve 3 – 4 with no node.
        let mut runs = Run::along(&[0, 1, 2, 0], &[1.0, 2.0, 1.0], 1);
        runs.extend(Run::along(&[3, 4], &[1.0], 1));
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0].conductance(), None);
        let mut cache = CachedPattern::default();
        let k = KronReduced::new(5, 1, &runs, 1.0, &mut cache).expect("factorised");
        assert_eq!(k.components(), 2);
        let b = vec![[0.3], [-0.1], [0.2], [-0.5], [0.5]];
        let want = dense(5, &runs, 1.0, &b);
        let mut got = b.clone();
        k.solve(&mut got);
        for (g, w) in got.iter().zip(&want) {
            assert!((g[0] - w).abs() < 1e-12, "{got:?} vs {want:?}");
        }
    }
}
