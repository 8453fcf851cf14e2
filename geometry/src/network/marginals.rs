//! Marginal uncertainty of the Poisson network (issue 49): how far each node and each curve
//! point may be from the truth, from the reconstruction itself.
//!
//! The Poisson least squares ([`super::poisson`]) reads every edge as
//! `x_b − x_a = h t + ε`. A curve's samples between two tags are a chain: eliminating them
//! (a Schur complement, exact) leaves a Laplacian over the nodes alone, `L` (#nodes by #nodes,
//! sparse, one edge per segment of conductance `1/R`, `R = Σ h²` over the segment's edges),
//! factorised with its symbolic factorisation kept. Each segment's drift `δ_s` (its
//! displacement's error, variance `v_s = s_s² R_s` per axis, independent between segments)
//! reaches the nodes through `L⁻¹`: the nodes' covariance is `Σ = K (Σ_s v_s g_s g_sᵀ) K`,
//! `K = L⁻¹`, `g_s = (e_b − e_a)/R_s`, per axis. Every segment's redundancy `1 − R_eff/R`
//! (the share of its drift the loops leave in the residual) comes from the entries of `K` on
//! the factor's pattern ([`crate::selected_inverse`]); so do `Σ`'s diagonal and its entries
//! across the segments: `Σ = K M K` with `M = Gᵀ V G` a Laplacian on the same segments is
//! `−d/dt (L + tM)⁻¹`, one selected inversion on dual numbers
//! ([`crate::selected_inverse::SelectedPattern::sandwich`]; memory the factor's fill, never
//! #nodes × #segments nor #nodes², and no solve per node). A point between two
//! tags is the bridge between their nodes: its covariance is theirs weighted by where it lies
//! (`α = r_b/R`, `β = r_a/R`, `r_a`, `r_b` its resistances to each) plus `s_s² r_a r_b / R`.
//!
//! Each segment's variance `s_s²` comes from its residual over its redundancy (a slip or a
//! magnet raises one stretch), pooled with the network's (the Poisson residual `χ²` over
//! `3 × loops`, itself pooled with the device's prior: a network without loops has only the
//! prior), then calibrated per device ([`NoisePrior`]): `loop_share × s_s² + floor`.
//!
//! The rigid motion is removed as `sfs eval` removes it (one registration on the truth, no
//! scaling): the least-squares rigid motion of the nodes, each weighted by the length of
//! curve around it (half of each of its segments), is subtracted, per connected part, and
//! the covariance of what is left is `(I − H) Σ (I − H)ᵀ` with `H` that fit's projection.
//! Each node's and point's σ is the RMS 3-D distance, `√trace` of its 3 × 3 block.
//!
//! Left out: a sliding tag's freedom (issue 34's joins; the slide is a handful of the
//! network's thousands of unknowns).
//!
//! ```
//! use sfs_geometry::network::marginals::{chain_bridge, NoisePrior};
//! // A point a quarter along a segment of resistance 4: 1 to one end, 3 to the other.
//! let (alpha, beta, bridge) = chain_bridge(1.0, 3.0);
//! assert_eq!((alpha, beta), (0.75, 0.25));
//! assert_eq!(bridge, 0.75);
//! assert!(NoisePrior::default().tau2 > 0.0);
//! ```

use super::poisson::Positions;
use super::prefilter::UniformCurve;
use crate::sparse_llt::{CachedPattern, SolveError};
use nalgebra::{Matrix3, Matrix6, SMatrix, Vector3};
use std::collections::BTreeMap;

/// What the device's noise is, calibrated (issue 49; BENCHMARKS.md "Trust"): the variance of
/// a stretch of curve is `loop_share × τ²_loops + floor_tau2` per metre, `τ²_loops` what the
/// loops say (pooled with `tau2` over `dof` pseudo-loops). Calibrated on our own simulator's
/// unfaulted captures (6 scenes, both profiles, seeds 1–4), and checked on the validation set:
/// the loops do not see a drift common to every curve (a wheel's scale, a heading bias), and
/// on the phone part of what misfits them moves the nodes little. Fitted again with the
/// mounting's yaw turned back ([`super::mounting::estimate_yaw`]), which takes from the loops'
/// misfit what it took from the nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct NoisePrior {
    /// The loops' drift expected, m²/m (per axis, per metre of curve: a stretch of length ℓ
    /// drifts by `√(τ² ℓ)` per axis): all a network without loops has.
    pub tau2: f64,
    /// Weight of `tau2`, in loops (pseudo-observations).
    pub dof: f64,
    /// Share of the loops' drift that moves the nodes.
    pub loop_share: f64,
    /// Drift the loops cannot see, m²/m (a stretch of length ℓ drifts by `√(floor × ℓ)` per
    /// axis besides).
    pub floor: f64,
    /// The spread of a curve's distance scale the loops do not see, a fraction: a wheel's
    /// curves each read a little long or short, and the loops take out their differences
    /// ([`super::curve_scale`]) but never their mean, the network's size. A node `r` from its
    /// part's centre is then off by `σ_size r`, `σ_size` this spread over the curves'
    /// (length-weighted) `√#curves`. 0 for a device whose lengths have no common scale.
    pub size: f64,
}

impl NoisePrior {
    /// The Morphorider's (and the default).
    pub const MORPHORIDER: NoisePrior = NoisePrior {
        tau2: 2e-5,
        dof: 2.0,
        loop_share: 1.0,
        floor: 4e-6,
        size: 0.005,
    };
    /// The phone's.
    pub const PHONE: NoisePrior = NoisePrior {
        tau2: 3e-5,
        dof: 2.0,
        loop_share: 0.875,
        floor: 3e-6,
        size: 0.0,
    };
}

impl Default for NoisePrior {
    fn default() -> Self {
        NoisePrior::MORPHORIDER
    }
}

impl NoisePrior {
    /// With the environment's `SFS_CALIBRATE_LOOP_SHARE`, `SFS_CALIBRATE_FLOOR` and
    /// `SFS_CALIBRATE_SIZE` in place of `loop_share`, `floor` and `size`: for the calibration
    /// runs only (BENCHMARKS.md "Trust").
    pub fn overridden(mut self) -> Self {
        if let Some(v) = std::env::var("SFS_CALIBRATE_LOOP_SHARE")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            self.loop_share = v;
        }
        if let Some(v) = std::env::var("SFS_CALIBRATE_FLOOR")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            self.floor = v;
        }
        if let Some(v) = std::env::var("SFS_CALIBRATE_SIZE")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            self.size = v;
        }
        self
    }
}

/// Each node's and point's uncertainty.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Uncertainty {
    /// σ of each node (RMS 3-D distance to the truth after the rigid motion), m.
    pub nodes: BTreeMap<u32, f64>,
    pub noise: Noise,
}

/// The noise the uncertainty rests on.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Noise {
    /// The drift used, m²/m (per axis per metre of curve, the network's mean):
    /// `loop_share × τ²_loops + floor` ([`NoisePrior`]).
    pub tau2: f64,
    /// What the loops alone say (`χ² / 3 loops`, per metre), m²/m; `None` without loops.
    pub tau2_loops: Option<f64>,
    /// `tau2_loops` over the device's expected (`NoisePrior::tau2`): about 1 where the loops
    /// misfit as the device's noise does, far above where a loop does not close (a wrong
    /// tag, a slip); `None` without loops.
    pub ratio: Option<f64>,
    /// The network's independent loops.
    pub loops: usize,
    /// The segment whose loops misfit most beside the others ([`Peak`]); `None` without
    /// loops.
    pub peak: Option<Peak>,
    /// RMS of the nodes' σ, m.
    pub sigma_rms_m: f64,
}

/// The segment whose residual stands out most from the network's: its residual variance
/// over the typical segment's (the redundancy-weighted median), each over its redundancy.
/// About 1 for noise alike everywhere; a wrong tag or a slip puts tens on its segments.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Peak {
    /// Scan index of the curve.
    pub curve: usize,
    /// The segment's first tag, its position in the curve's tags.
    pub tag: usize,
    pub ratio: f64,
}

/// Column `i` of `Σ = K M K` (`K e_i`, then `K M K e_i`: two solves), for a pair off the
/// selected pattern (the ends of a segment of no length).
fn column(
    f: &crate::sparse_llt::SpdFactor,
    segments: &[Segment],
    weight_of: &[f64],
    i: usize,
) -> Vec<f64> {
    let n = f.n();
    let mut col = vec![[0.0]; n];
    col[i][0] = 1.0;
    f.solve(&mut col);
    let mut q = vec![[0.0]; n];
    for (sg, &w) in segments.iter().zip(weight_of) {
        if sg.spans() {
            let d = w * (col[sg.b][0] - col[sg.a][0]);
            q[sg.b][0] += d;
            q[sg.a][0] -= d;
        }
    }
    f.solve(&mut q);
    q.into_iter().map(|x| x[0]).collect()
}

/// Where a point lies on a chain: `r_a`, `r_b` its resistances to the two ends. Returns the
/// ends' weights `(α, β)` in its conditional mean and its bridge variance `r_a r_b / R` (per
/// unit `s²`).
pub fn chain_bridge(r_a: f64, r_b: f64) -> (f64, f64, f64) {
    let r = r_a + r_b;
    if r <= 0.0 {
        return (1.0, 0.0, 0.0);
    }
    (r_b / r, r_a / r, r_a * r_b / r)
}

/// One segment: a stretch of a curve between two consecutive tags.
#[derive(Debug, Clone)]
struct Segment {
    /// Position in the curves, its position among the curve's segments, sample range
    /// `[i0, i1]`.
    curve: usize,
    k: usize,
    i0: usize,
    i1: usize,
    /// Node unknowns (indices into the node list) at its ends.
    a: usize,
    b: usize,
    /// Σ h² over its edges, m².
    r: f64,
    length: f64,
}

impl Segment {
    /// Contributes to the nodes (a segment from a node back to itself, or of no length,
    /// does not).
    fn spans(&self) -> bool {
        self.r > 0.0 && self.a != self.b
    }
}

/// Keeps the node Laplacian's symbolic factorisation between runs.
#[derive(Debug, Default)]
pub struct MarginalsSolver {
    pattern: CachedPattern,
}

impl MarginalsSolver {
    pub fn new() -> Self {
        Self::default()
    }

    /// The uncertainty of `positions`, reconstructed from `curves` (the same curves, in the
    /// same order: [`super::poisson::PoissonSolver::solve`]'s input): the nodes' returned,
    /// every point's put in its curve's [`sigma_m`](super::poisson::CurvePositions::sigma_m)
    /// (left as it was when the node Laplacian cannot be factorised).
    pub fn run(
        &mut self,
        curves: &[UniformCurve],
        positions: &mut Positions,
        prior: &NoisePrior,
    ) -> Result<Uncertainty, SolveError> {
        let mean_h = positions.misfit.mean_h.max(1e-12);
        let node_ids: Vec<u32> = positions.nodes.keys().copied().collect();
        let index: BTreeMap<u32, usize> =
            node_ids.iter().enumerate().map(|(k, &n)| (n, k)).collect();
        let n = node_ids.len();
        let segments = segments(curves, &index);
        let mut out = Uncertainty {
            noise: Noise {
                tau2: prior.loop_share * prior.tau2,
                loops: positions.misfit.loops,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut points: Vec<Vec<f64>> = curves.iter().map(|c| vec![0.0; c.q.len()]).collect();
        if n == 0 {
            place(positions, points);
            return Ok(out);
        }
        // The node Laplacian (conductance 1/R per segment) with a gauge per part.
        let mut sets = crate::union_find::UnionFind::new(n);
        let mut entries: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
        let mut vals = vec![0.0; n];
        let mut weight = vec![0.0; n];
        for s in &segments {
            weight[s.a] += 0.5 * s.length;
            weight[s.b] += 0.5 * s.length;
            if !s.spans() {
                continue;
            }
            sets.union(s.a, s.b);
            let g = 1.0 / s.r;
            vals[s.a] += g;
            vals[s.b] += g;
            entries.push((s.a.max(s.b), s.a.min(s.b)));
            vals.push(-g);
        }
        let part: Vec<usize> = (0..n).map(|i| sets.find(i)).collect();
        let mean_g = vals[..n].iter().sum::<f64>() / n as f64;
        for i in 0..n {
            if part[i] == i {
                vals[i] += mean_g.max(1.0);
            }
        }
        // Each segment's redundancy, 1 − R_eff/R: the share of its drift the loops leave in
        // the residual (Σ over the network: its loops). R_eff is the resistance across the
        // segment, from the inverse's entries on the factor's pattern (a selected inversion).
        let selected = crate::selected_inverse::SelectedPattern::new(n, &entries)?;
        let z = selected.inverse(&vals)?;
        let f = self.pattern.factor(n, entries.clone(), &vals)?;
        let red: Vec<f64> = segments
            .iter()
            .map(|sg| {
                if !sg.spans() {
                    // A loop of its own (a closed curve back to its node): all residual.
                    return if sg.r > 0.0 { 1.0 } else { 0.0 };
                }
                let k = |i: usize, j: usize| z.get(i, j).expect("an entry of the Laplacian");
                let r_eff = k(sg.a, sg.a) + k(sg.b, sg.b) - 2.0 * k(sg.a, sg.b);
                (1.0 - r_eff / sg.r).clamp(0.0, 1.0)
            })
            .collect();
        drop(z);
        let loops: f64 = red.iter().sum();
        let chi2_of = |sg: &Segment| {
            positions
                .misfit
                .chi2_segments
                .get(sg.curve)
                .and_then(|v| v.get(sg.k))
                .copied()
                .unwrap_or(0.0)
        };
        // The loops' variance (per unit Σh²), pooled with the prior's; each segment's own
        // from its residual over its redundancy, pooled with the network's: a slip or a
        // magnet raises one stretch, not every curve.
        let s2_prior = prior.tau2 / mean_h;
        let own = (loops > 1e-9).then(|| positions.misfit.chi2 / 3.0 / loops);
        let s2_net = match own {
            Some(o) => (o * loops + s2_prior * prior.dof) / (loops + prior.dof),
            None => s2_prior,
        };
        let s2_seg: Vec<f64> = segments
            .iter()
            .zip(&red)
            .map(|(sg, red)| {
                let s2 = (chi2_of(sg) / 3.0 + SEGMENT_PRIOR_LOOPS * s2_net)
                    / (red + SEGMENT_PRIOR_LOOPS);
                // Per unit Σh², as the loops' part is.
                let floor = if sg.r > 0.0 {
                    prior.floor * sg.length / sg.r
                } else {
                    0.0
                };
                prior.loop_share * s2 + floor
            })
            .collect();
        out.noise.tau2_loops = own.map(|o| o * mean_h);
        out.noise.ratio = own.map(|o| o / s2_prior.max(f64::MIN_POSITIVE));
        out.noise.tau2 = prior.loop_share * s2_net * mean_h;
        out.noise.peak = peak(&segments, &red, &chi2_of, curves);
        // Σ = K M K per axis, M = Σ_s v_s g_s g_sᵀ (v_s = s_s² R_s, g_s = (e_b − e_a)/R_s: a
        // Laplacian on the segments, weights v_s / R_s²): its entries on the factor's
        // pattern, the diagonal and those across the segments, from one selected inversion
        // on dual numbers (never a solve per node, nor #nodes × #segments).
        let weight_of: Vec<f64> = segments
            .iter()
            .zip(&s2_seg)
            .map(|(sg, s2)| {
                if sg.spans() {
                    s2 * sg.r / (sg.r * sg.r)
                } else {
                    0.0
                }
            })
            .collect();
        let mut m_vals = vec![0.0; entries.len()];
        let mut next = n;
        for (sg, &w) in segments.iter().zip(&weight_of) {
            if !sg.spans() {
                continue;
            }
            m_vals[sg.a] += w;
            m_vals[sg.b] += w;
            m_vals[next] = -w;
            next += 1;
        }
        let (_, sigma) = selected.sandwich(&vals, &m_vals)?;
        let sigma_diag: Vec<f64> = (0..n)
            .map(|i| sigma.get(i, i).expect("the diagonal"))
            .collect();
        // Across each segment (a loop back to its node: that node's own; the ends of a
        // segment of no length are in different parts, where it is not read).
        let sigma_seg: Vec<f64> = segments
            .iter()
            .map(|sg| {
                sigma
                    .get(sg.a, sg.b)
                    .unwrap_or_else(|| column(&f, &segments, &weight_of, sg.a)[sg.b])
            })
            .collect();
        // The rigid fit per part: B_i = [I | −[p_i − c]×], weights m_i; Σ m and Σ (m ⊙ d)
        // (the fit's covariance with each node) as K (Σ_s v_s g_s g_sᵀ) K v.
        let pos: Vec<Vector3<f64>> = node_ids.iter().map(|k| positions.nodes[k]).collect();
        let mut rigid = Rigid::new(&part, &weight, &pos);
        let mut v = vec![[0.0; 4]; n];
        for (i, vi) in v.iter_mut().enumerate() {
            let (m, d) = (rigid.m[i], rigid.arm(i));
            *vi = [m, m * d.x, m * d.y, m * d.z];
        }
        // Parts do not couple (L is block diagonal), so one solve serves them all.
        f.solve(&mut v);
        let mut lv = vec![[0.0; 4]; n];
        for (sg, &c) in segments.iter().zip(&weight_of) {
            if !sg.spans() {
                continue;
            }
            // v_s g_s g_sᵀ v = (v_s / R²)(v_b − v_a) at b, minus at a.
            for d in 0..4 {
                let x = c * (v[sg.b][d] - v[sg.a][d]);
                lv[sg.b][d] += x;
                lv[sg.a][d] -= x;
            }
        }
        f.solve(&mut lv);
        rigid.finish(&lv);
        // The network's size, which no loop sees: a node `r` from its part's centre is off by
        // `σ_size r` besides.
        let lengths: Vec<f64> = curves.iter().map(|c| c.length()).collect();
        let total: f64 = lengths.iter().sum();
        let size = if total > 0.0 {
            prior.size * lengths.iter().map(|l| l * l).sum::<f64>().sqrt() / total
        } else {
            0.0
        };
        let size_var = |arm: Vector3<f64>| (size * size) * arm.norm_squared();
        for (i, &id) in node_ids.iter().enumerate() {
            let var = rigid.cov(i, i, sigma_diag[i]).trace().max(0.0) + size_var(rigid.arm(i));
            out.nodes.insert(id, var.sqrt());
        }
        out.noise.sigma_rms_m = rms(out.nodes.values().copied());
        // The points between two tags: the bridge between their nodes.
        for ((sg, s2), &kab) in segments.iter().zip(&s2_seg).zip(&sigma_seg) {
            let c = &curves[sg.curve];
            let caa = rigid.cov(sg.a, sg.a, sigma_diag[sg.a]).trace();
            let cbb = rigid.cov(sg.b, sg.b, sigma_diag[sg.b]).trace();
            // Nodes joined by a segment of no length are in different parts: apart.
            let cab = if part[sg.a] == part[sg.b] {
                rigid.cov(sg.a, sg.b, kab).trace()
            } else {
                0.0
            };
            // The part's centre, from the node at the segment's start.
            let centre = pos[sg.a] - rigid.arm(sg.a);
            let point = |j: usize| {
                positions.curves[sg.curve]
                    .points
                    .get(j)
                    .map_or(0.0, |p| size_var(p - centre))
            };
            let mut r_a = 0.0;
            for j in sg.i0..=sg.i1 {
                let (al, be, bridge) = chain_bridge(r_a, sg.r - r_a);
                let var = al * al * caa
                    + be * be * cbb
                    + 2.0 * al * be * cab
                    + 3.0 * s2 * bridge
                    + point(j);
                if let Some(x) = points[sg.curve].get_mut(j) {
                    *x = var.max(0.0).sqrt();
                }
                if j < sg.i1 {
                    r_a += c.edge_h(j).powi(2);
                }
            }
        }
        place(positions, points);
        Ok(out)
    }
}

/// Each curve's points' σ into its [`sigma_m`](super::poisson::CurvePositions::sigma_m).
fn place(positions: &mut Positions, points: Vec<Vec<f64>>) {
    for (c, s) in positions.curves.iter_mut().zip(points) {
        c.sigma_m = s;
    }
}

/// Weight of the network's variance in each segment's, in loops: a segment closing little
/// of a loop has mostly the network's.
const SEGMENT_PRIOR_LOOPS: f64 = 1.0;

/// Segments closing less of a loop than this are not compared ([`Peak`]): their residual
/// says little.
const PEAK_MIN_REDUNDANCY: f64 = 0.1;

/// The segment whose residual variance (over its redundancy) stands out most from the
/// redundancy-weighted median of all segments'.
fn peak(
    segments: &[Segment],
    red: &[f64],
    chi2_of: &dyn Fn(&Segment) -> f64,
    curves: &[UniformCurve],
) -> Option<Peak> {
    let mut v: Vec<(f64, f64, usize)> = segments
        .iter()
        .zip(red)
        .enumerate()
        .filter(|(_, (sg, red))| sg.r > 0.0 && **red >= PEAK_MIN_REDUNDANCY)
        .map(|(si, (sg, red))| (chi2_of(sg) / 3.0 / red, *red, si))
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    let median = v
        .iter()
        .find(|x| {
            acc += x.1;
            acc >= total / 2.0
        })
        .map_or(0.0, |x| x.0);
    let &(top, _, si) = v.last()?;
    let sg = &segments[si];
    Some(Peak {
        curve: curves[sg.curve].index,
        tag: sg.k,
        ratio: if median > 0.0 { top / median } else { 0.0 },
    })
}

/// Every curve's segments (between consecutive tags), in order.
fn segments(curves: &[UniformCurve], index: &BTreeMap<u32, usize>) -> Vec<Segment> {
    let mut out = Vec::new();
    for (ci, c) in curves.iter().enumerate() {
        for (k, w) in c.nodes.windows(2).enumerate() {
            let ((i0, na), (i1, nb)) = (w[0], w[1]);
            // Every node is in the positions' nodes; one that is not joins nothing.
            let (Some(&a), Some(&b)) = (index.get(&na), index.get(&nb)) else {
                continue;
            };
            let i1 = i1.min(c.q.len().saturating_sub(1));
            let r: f64 = (i0..i1).map(|j| c.edge_h(j).powi(2)).sum();
            let length = c.d.get(i1).zip(c.d.get(i0)).map_or(0.0, |(x, y)| x - y);
            out.push(Segment {
                curve: ci,
                k,
                i0,
                i1,
                a,
                b,
                r,
                length: length.abs(),
            });
        }
    }
    out
}

/// The least-squares rigid motion of the nodes per part, and the covariances it leaves.
/// `e'_i = e_i − B_i M⁻¹ Q`, `Q = Σ_j m_j B_jᵀ e_j`, `M = Σ m_j B_jᵀ B_j` (per part), with
/// `Cov(e_i, e_j) = Σ_ij I`: `Cov(e_i, Q) = Z_i = [(Σm)_i I | −[(Σ m⊙d)_i]×]`,
/// `Cov(Q) = Σ_i m_i B_iᵀ Z_i`.
struct Rigid {
    part: Vec<usize>,
    m: Vec<f64>,
    centre: BTreeMap<usize, Vector3<f64>>,
    pos: Vec<Vector3<f64>>,
    /// Per part: M⁻¹ and Cov(Q).
    minv: BTreeMap<usize, Matrix6<f64>>,
    cq: BTreeMap<usize, Matrix6<f64>>,
    z: Vec<SMatrix<f64, 3, 6>>,
}

impl Rigid {
    fn new(part: &[usize], weight: &[f64], pos: &[Vector3<f64>]) -> Self {
        // A node with no segment (cannot be: every tag starts or ends one) weighs a little.
        let m: Vec<f64> = weight.iter().map(|w| w.max(1e-9)).collect();
        let mut sum: BTreeMap<usize, (f64, Vector3<f64>)> = BTreeMap::new();
        for i in 0..part.len() {
            let e = sum.entry(part[i]).or_insert((0.0, Vector3::zeros()));
            e.0 += m[i];
            e.1 += pos[i] * m[i];
        }
        let centre = sum.iter().map(|(&p, &(w, s))| (p, s / w)).collect();
        Rigid {
            part: part.to_vec(),
            m,
            centre,
            pos: pos.to_vec(),
            minv: BTreeMap::new(),
            cq: BTreeMap::new(),
            z: Vec::new(),
        }
    }

    fn arm(&self, i: usize) -> Vector3<f64> {
        self.pos[i] - self.centre[&self.part[i]]
    }

    fn b(&self, i: usize) -> SMatrix<f64, 3, 6> {
        let mut b = SMatrix::<f64, 3, 6>::zeros();
        b.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        b.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-self.arm(i).cross_matrix()));
        b
    }

    /// `km[i] = [(Σ m)_i, (Σ m⊙d)_i]`.
    fn finish(&mut self, km: &[[f64; 4]]) {
        let n = self.part.len();
        self.z = (0..n)
            .map(|i| {
                let mut z = SMatrix::<f64, 3, 6>::zeros();
                z.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(Matrix3::identity() * km[i][0]));
                let v = Vector3::new(km[i][1], km[i][2], km[i][3]);
                z.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&(-v.cross_matrix()));
                z
            })
            .collect();
        let mut mm: BTreeMap<usize, Matrix6<f64>> = BTreeMap::new();
        let mut cq: BTreeMap<usize, Matrix6<f64>> = BTreeMap::new();
        for i in 0..n {
            let b = self.b(i);
            *mm.entry(self.part[i]).or_insert_with(Matrix6::zeros) += b.transpose() * b * self.m[i];
            *cq.entry(self.part[i]).or_insert_with(Matrix6::zeros) +=
                b.transpose() * self.z[i] * self.m[i];
        }
        for (p, m) in mm {
            // A part of one or two nodes (or nodes on a line) leaves a rotation unfixed: the
            // pseudo-inverse fits what it can.
            let minv = m
                .pseudo_inverse(1e-12 * m.norm().max(f64::MIN_POSITIVE))
                .unwrap_or_else(|_| Matrix6::zeros());
            self.minv.insert(p, minv);
        }
        self.cq = cq;
    }

    /// The 3 × 3 covariance of nodes `i` and `k` (same part) after the fit, `kik` = `Σ_ik`
    /// (per axis, before it).
    fn cov(&self, i: usize, k: usize, kik: f64) -> Matrix3<f64> {
        let p = self.part[i];
        let (minv, cq) = (&self.minv[&p], &self.cq[&p]);
        let (bi, bk) = (self.b(i), self.b(k));
        let ai = bi * minv;
        let ak = bk * minv;
        Matrix3::identity() * kik - self.z[i] * ak.transpose() - ai * self.z[k].transpose()
            + ai * cq * ak.transpose()
    }
}

/// The RMS of `v`.
pub fn rms(v: impl IntoIterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x * x;
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curve::CurveKind;
    use crate::network::poisson::PoissonSolver;
    use crate::rng::Rng;
    use nalgebra::{Rotation3, UnitQuaternion};

    const LINES: usize = 4;
    const PER_SEGMENT: usize = 20;
    const SPACING: f64 = 0.25;

    /// A grid of 2 × LINES straight curves in the plane z = 0, crossing at LINES² nodes,
    /// every sample's frame turned by an independent random rotation of `noise` rad per axis.
    fn grid(noise: f64, rng: &mut Rng) -> (Vec<UniformCurve>, BTreeMap<u32, Vector3<f64>>) {
        let n = PER_SEGMENT * (LINES - 1);
        let len = SPACING * (LINES - 1) as f64;
        let h = len / n as f64;
        let mut curves = Vec::new();
        let mut truth = BTreeMap::new();
        for dir in 0..2 {
            for k in 0..LINES {
                // Along x (dir 0) at y = k·SPACING, or along y (dir 1) at x = k·SPACING.
                let frame = if dir == 0 {
                    UnitQuaternion::identity()
                } else {
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
                };
                let q = (0..=n)
                    .map(|_| {
                        let r = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss());
                        UnitQuaternion::from_scaled_axis(r * noise) * frame
                    })
                    .collect();
                let nodes = (0..LINES)
                    .map(|i| {
                        let id = if dir == 0 {
                            k * LINES + i
                        } else {
                            i * LINES + k
                        };
                        (i * PER_SEGMENT, id as u32)
                    })
                    .collect();
                for i in 0..LINES {
                    let (x, y) = if dir == 0 { (i, k) } else { (k, i) };
                    truth.insert(
                        (y * LINES + x) as u32,
                        Vector3::new(x as f64 * SPACING, y as f64 * SPACING, 0.0),
                    );
                }
                curves.push(UniformCurve {
                    index: curves.len(),
                    kind: CurveKind::Interior,
                    d: (0..=n).map(|j| j as f64 * h).collect(),
                    q,
                    nodes,
                    h: vec![h; LINES - 1],
                    w: vec![1.0; n + 1],
                    outliers: 0,
                    kinks: Vec::new(),
                });
            }
        }
        (curves, truth)
    }

    /// Node errors after the weighted least-squares rigid motion onto the truth.
    fn registered_errors(
        got: &BTreeMap<u32, Vector3<f64>>,
        truth: &BTreeMap<u32, Vector3<f64>>,
        weight: impl Fn(u32) -> f64,
    ) -> BTreeMap<u32, f64> {
        let wsum: f64 = got.keys().map(|&k| weight(k)).sum();
        let cg = got
            .iter()
            .map(|(&k, p)| p * weight(k))
            .sum::<Vector3<f64>>()
            / wsum;
        let ct = got
            .keys()
            .map(|&k| truth[&k] * weight(k))
            .sum::<Vector3<f64>>()
            / wsum;
        let mut h = Matrix3::zeros();
        for (&k, p) in got {
            h += (p - cg) * (truth[&k] - ct).transpose() * weight(k);
        }
        let svd = h.svd(true, true);
        let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
        let mut d = Matrix3::identity();
        d[(2, 2)] = (vt.transpose() * u.transpose()).determinant().signum();
        let r = Rotation3::from_matrix_unchecked(vt.transpose() * d * u.transpose());
        got.iter()
            .map(|(&k, p)| (k, (r * (p - cg) + ct - truth[&k]).norm()))
            .collect()
    }

    #[test]
    fn sigma_matches_the_errors_of_independent_noise() {
        // Monte Carlo over seeded captures of the grid: the predicted σ (from each capture's
        // own loops) against the nodes' true errors once the rigid motion is removed.
        let mut rng = Rng::new(49);
        // The loops' variance alone: no prior, no floor, all of it moving the nodes, and no
        // scale unseen (the noise here is of the tangents only).
        let prior = NoisePrior {
            tau2: 1e-6,
            dof: 1e-9,
            loop_share: 1.0,
            floor: 0.0,
            size: 0.0,
        };
        let (mut err2, mut sig2, mut within2, mut count) = (0.0, 0.0, 0usize, 0usize);
        let mut solver = MarginalsSolver::new();
        let mut poisson = PoissonSolver::new();
        for _ in 0..150 {
            let (curves, truth) = grid(0.02, &mut rng);
            let p = poisson.solve(&curves).unwrap();
            assert_eq!(p.misfit.loops, 9, "{:?}", p.misfit);
            let mut p = p;
            let u = solver.run(&curves, &mut p, &prior).unwrap();
            // Corner nodes carry one segment of each of their 2 curves, the others more:
            // the same weights as the model's (half of each segment's length).
            let weight = |k: u32| {
                let (x, y) = (k as usize % LINES, k as usize / LINES);
                let ends = |i: usize| if i == 0 || i == LINES - 1 { 1.0 } else { 2.0 };
                ends(x) + ends(y)
            };
            let e = registered_errors(&p.nodes, &truth, weight);
            for (k, e) in e {
                let s = u.nodes[&k];
                assert!(s.is_finite() && s > 0.0);
                err2 += e * e;
                sig2 += s * s;
                within2 += usize::from(e <= 2.0 * s);
                count += 1;
            }
        }
        let ratio = (err2 / sig2).sqrt();
        let coverage = within2 as f64 / count as f64;
        assert!((0.9..1.1).contains(&ratio), "RMS error / RMS σ = {ratio}");
        assert!(coverage > 0.9, "within 2σ: {coverage}");
    }

    /// The size no loop sees adds `σ_size r` at a node `r` from the centre, with `σ_size` the
    /// prior's spread over the curves' `√#curves` (here equal lengths: `size / √#curves`).
    #[test]
    fn the_unseen_size_adds_with_the_distance_from_the_centre() {
        let mut rng = Rng::new(7);
        let (curves, _) = grid(0.02, &mut rng);
        let base = NoisePrior::MORPHORIDER;
        let sized = NoisePrior { size: 0.01, ..base };
        let sigma = |prior: &NoisePrior| {
            let mut p = PoissonSolver::new().solve(&curves).unwrap();
            let u = MarginalsSolver::new().run(&curves, &mut p, prior).unwrap();
            (u.nodes, p.nodes)
        };
        let (without, nodes) = sigma(&NoisePrior { size: 0.0, ..base });
        let (with, _) = sigma(&sized);
        let centre = nodes.values().sum::<Vector3<f64>>() / nodes.len() as f64;
        let size = 0.01 / (curves.len() as f64).sqrt();
        for (k, x) in &nodes {
            let added = with[k].powi(2) - without[k].powi(2);
            let want = (size * (x - centre).norm()).powi(2);
            assert!(
                (added - want).abs() <= 1e-9 + 1e-6 * want,
                "node {k}: {added} for {want}"
            );
        }
    }
}
