//! Regression on SO(3)ᴺ over the whole network (§4.3 of the paper): minimise
//! `ξ·E_N + Σ_curves (E₀ + λE₁ + μE₂)` with the simplified chordal costs
//!
//! - `E₀ = Σ ‖X_i − A_i‖²_F` (stay close to the pre-filtered frames),
//! - `E₁ = (1/h) Σ ‖X_i − X_{i+1}‖²_F` (stretching),
//! - `E₂ = (1/h³) Σ ‖skew(X_iᵀ(X_{i+1} + X_{i−1}))‖²_F` (bending),
//! - `E_N = Σ ‖X_i e₃ − X̃_j e₃‖²` over every two frames of different curves at a node,
//!
//! A node on a crease (issue 18) has one normal per face: the crease curve's frame carries the
//! face the device rested on, a curve arriving from the other face carries that face's, and a
//! curve crossing the edge carries, after the pre-filter's Gaussian, a normal between the two.
//! Tying them all would drag the crease's frames towards the mean of the faces (45° off on a
//! box) and the error would spread along every curve at the node by the bending term. So at a
//! node a crease passes through, `E_N` ties only the frames whose pre-filtered normals already
//! agree within [`CREASE_PAIR_DEG`] (the same face, measured twice); the others keep their own
//! normals, and the crease's other face is found after the positions
//! ([`super::crease`]). Away from creases every pair is tied, as in the paper.
//!
//! sums periodic on closed curves (whose last sample is their first), by Levenberg–Marquardt
//! on the manifold: updates `X ← X·exp(ω̂)`, the normal matrix (3×3 blocks, banded per curve
//! plus the node couplings) factorised by sparse Cholesky with its symbolic factorisation
//! reused across iterations and runs.
//!
//! Live updates (issue 19) may regress locally ([`RegressionSolver::run_local`]): only the
//! frames of the curves that changed and those near the nodes they pass through move, the
//! rest are constants at the last run's frames; a whole-network run settles it later.
//!
//! Units: `E₁` carries `1/h` and `E₂` `1/h³`, so the weights are set from smoothing lengths:
//! `λ = ℓ₁²/h` and `μ = ℓ₂⁴/h` make the terms compare with `E₀` as a smoothing spline of
//! lengths `ℓ₁`, `ℓ₂` would, whatever the sampling step (see [`RegressionParams`]).

use super::prefilter::UniformCurve;
use crate::sparse_llt::{CachedPattern, SpdPattern};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use std::collections::HashMap;

/// At a node a crease curve passes through, two frames' normals are tied by `E_N` only when
/// their pre-filtered normals already agree within this angle, degrees: the frames on the
/// crease's two faces (and those of curves crossing it, whose normals the pre-filter smooths
/// across the edge) keep their own normals.
pub const CREASE_PAIR_DEG: f64 = 30.0;

/// Regression parameters (documented defaults, chosen by measurement: BENCHMARKS.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegressionParams {
    /// Stretching smoothing length ℓ₁, m (λ = ℓ₁²/h). Default 0 (no stretching term: it pulls
    /// frames towards a constant orientation).
    pub stretch_length: f64,
    /// Bending smoothing length ℓ₂, m (μ = ℓ₂⁴/h). Default `None`: `bend_fraction` of the
    /// sampling step h, so that the smoothing follows the resolution of the reconstruction.
    pub bend_length: Option<f64>,
    /// ℓ₂ in units of h when `bend_length` is `None`. Default 0.5, chosen by measurement on
    /// the simulator's scenes (BENCHMARKS.md): longer lengths help smooth, noisy networks
    /// and flatten the detail of bumpy ones.
    pub bend_fraction: f64,
    /// Weight of the node normal consistency ξ. Default 1e4 (the paper's).
    pub xi: f64,
    pub max_iterations: usize,
    /// Stop when the gradient norm falls below this. Default 1e-9.
    pub gradient_tolerance: f64,
    /// Stop when an iteration lowers the energy by less than this fraction. Default 1e-9.
    pub relative_tolerance: f64,
    /// Stop when each of the last [`STALL_ITERATIONS`] iterations lowered the energy by less
    /// than this fraction: Gauss–Newton converges only linearly where the residuals stay
    /// large (a noisy network of thousands of nodes: 50 iterations, each a factorisation,
    /// to gain 1e-6 of the energy), and the frames then creep along a flat valley of it
    /// (0.08 mm at most on the 100-curve grid of BENCHMARKS.md, its nodes 10 mm uncertain).
    /// Default 1e-7: no capture at hand stalls before it converges (they take 3–7
    /// iterations), so their results are the same.
    pub stall_tolerance: f64,
}

/// How many slow iterations in a row end the regression ([`RegressionParams::stall_tolerance`]).
pub const STALL_ITERATIONS: usize = 3;

/// A local run ([`RegressionSolver::run_local`]) frees the kept curves' frames near a node the
/// new curve passes only where at most this many curves hold it: at a node of `k` curves the
/// new tie moves each of the others by about a `k`-th of what it pulls, and freeing them ties
/// every pair of them in the local problem (a grid's pole of 50 meridians: 1 225 pairs).
/// Measured on the scaling example's grids (issue 51; the update that adds meridian 1, with
/// `local_window` 3, against the whole network's regression): at 20, 50 and 100 curves the
/// poles' 9, 24 and 49 meridians are kept, the frames within 0.03°, 0.012° and 0.006° of
/// the whole network's and the points within 3e-6, 1e-6 and 6e-7 m (at 10 curves, 5 at a
/// pole, everything near it moves: 4e-5°, 6e-9 m).
pub const CROWDED: usize = 8;

impl Default for RegressionParams {
    fn default() -> Self {
        RegressionParams {
            stretch_length: 0.0,
            bend_length: None,
            bend_fraction: 0.5,
            xi: 1e4,
            max_iterations: 50,
            gradient_tolerance: 1e-9,
            relative_tolerance: 1e-9,
            stall_tolerance: 1e-7,
        }
    }
}

/// What the regression did.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct RegressionReport {
    pub iterations: usize,
    pub energy_initial: f64,
    pub energy_final: f64,
    pub gradient_norm: f64,
    pub converged: bool,
    /// Frames the run moved: all of them, unless it was limited to the neighbourhood of what
    /// changed ([`RegressionSolver::run_local`]); the others kept the last run's.
    pub frames_moved: usize,
    /// Frames of the network (a closed curve's first and last sample are one).
    pub frames: usize,
}

/// Keeps the symbolic factorisation of the normal matrix between iterations and runs.
#[derive(Debug, Default)]
pub struct RegressionSolver {
    pattern: CachedPattern,
    /// The pattern of the last local run's (smaller) system, kept apart so that the whole
    /// network's symbolic factorisation survives local runs.
    local_pattern: CachedPattern,
}

/// One residual block: the movable variables it touches (up to three, in order; constants
/// have no Jacobian) and where its residuals and Jacobian rows start in [`Terms`].
#[derive(Clone, Copy)]
struct Term {
    vars: [usize; 3],
    nvars: u8,
    rows: u8,
    /// First residual in `Terms::res`.
    res: usize,
    /// First Jacobian row in `Terms::jac`: `rows` rows for each variable in turn.
    jac: usize,
}

/// Residual blocks, each touching up to three variables: their Jacobians and the residuals,
/// stored flat (one allocation each for millions of rows); the data term E₀ in closed form
/// (its Gauss–Newton block is `2w·I`).
struct Terms {
    terms: Vec<Term>,
    res: Vec<f64>,
    /// Rows of 3 (one per residual and variable): ∂r/∂ω of the variable's frame.
    jac: Vec<[f64; 3]>,
    e0_energy: f64,
    /// Jᵀr of E₀ per variable.
    e0_grad: Vec<Vector3<f64>>,
}

impl Terms {
    /// Appends a block with residuals `r` and, for each variable, its Jacobian rows (one per
    /// residual); variables past `movable` (constants) keep no Jacobian.
    fn push(&mut self, movable: usize, r: &[f64], vars: &[(usize, &[[f64; 3]])]) {
        let mut t = Term {
            vars: [0; 3],
            nvars: 0,
            rows: r.len() as u8,
            res: self.res.len(),
            jac: self.jac.len(),
        };
        self.res.extend_from_slice(r);
        for &(v, rows) in vars {
            if v < movable {
                t.vars[usize::from(t.nvars)] = v;
                t.nvars += 1;
                self.jac.extend_from_slice(rows);
            }
        }
        self.terms.push(t);
    }

    /// The residuals of block `t`.
    fn residuals(&self, t: &Term) -> &[f64] {
        &self.res[t.res..t.res + usize::from(t.rows)]
    }

    /// The variables of block `t` with their Jacobian rows.
    fn jacobians<'a>(&'a self, t: &'a Term) -> impl Iterator<Item = (usize, &'a [[f64; 3]])> + 'a {
        let rows = usize::from(t.rows);
        t.vars[..usize::from(t.nvars)]
            .iter()
            .enumerate()
            .map(move |(k, &v)| (v, &self.jac[t.jac + k * rows..t.jac + (k + 1) * rows]))
    }
}

fn hat(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

fn vee_skew(m: &Matrix3<f64>) -> Vector3<f64> {
    // skew(M) = (M − Mᵀ)/2 = hat(s) with s = vee.
    Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    ) * 0.5
}

fn flat(m: &Matrix3<f64>) -> [f64; 9] {
    let mut o = [0.0; 9];
    for (i, x) in m.iter().enumerate() {
        o[i] = *x;
    }
    o
}

/// Parameters with the bending length resolved.
struct Resolved {
    stretch_length: f64,
    bend: f64,
    xi: f64,
}

struct Problem {
    /// Targets and current frames, per variable.
    a: Vec<Matrix3<f64>>,
    /// The variables `0..movable` move; the rest (a local run's fixed frames that a kept term
    /// touches, [`restrict`]) are constants at their frames in `x`.
    movable: usize,
    /// Reliability of each target (weight of its E₀ term).
    w: Vec<f64>,
    /// (var i, var i+1, step h) per edge; (prev, mid, next, h) per bending triple.
    edges: Vec<(usize, usize, f64)>,
    triples: Vec<(usize, usize, usize, f64)>,
    /// Node pairs of different curves.
    pairs: Vec<(usize, usize)>,
    /// Variable of (curve, sample).
    var_of: Vec<Vec<usize>>,
}

/// The nodes a crease curve passes through.
pub(crate) fn crease_nodes(curves: &[UniformCurve]) -> std::collections::HashSet<u32> {
    curves
        .iter()
        .filter(|c| c.kind == crate::curve::CurveKind::Crease)
        .flat_map(|c| c.nodes.iter().map(|x| x.1))
        .collect()
}

/// Whether `E_N` ties two frames of different curves at a node, their unit normals' dot
/// product `dot`: everywhere but at a node a crease passes through (`crease`), where only the
/// frames already on the same face (normals within [`CREASE_PAIR_DEG`]) are tied.
pub(crate) fn tied(crease: bool, dot: f64) -> bool {
    !(crease && dot < CREASE_PAIR_DEG.to_radians().cos())
}

fn problem(curves: &[UniformCurve]) -> Problem {
    // Every variable free: the local problem of all of them, in the same order.
    let layout = Layout::of(curves);
    let (mut pb, _) = local_problem(curves, &layout, &vec![true; layout.total]);
    pb.var_of = curves
        .iter()
        .enumerate()
        .map(|(k, c)| (0..c.q.len()).map(|j| layout.var(k, j)).collect())
        .collect();
    pb
}

/// The variables of [`problem`]: each curve's first variable and whether it is closed (its
/// last sample the variable of its first; a loop that closes at a kink keeps its last frame,
/// arriving, apart from its first).
struct Layout {
    base: Vec<usize>,
    closed: Vec<bool>,
    len: Vec<usize>,
    total: usize,
}

impl Layout {
    fn of(curves: &[UniformCurve]) -> Layout {
        let (mut base, mut closed, mut len) = (Vec::new(), Vec::new(), Vec::new());
        let mut total = 0;
        for c in curves {
            let n = c.q.len();
            let cl = n > 2
                && c.nodes.first().map(|x| x.1) == c.nodes.last().map(|x| x.1)
                && !c.kinked(0);
            base.push(total);
            closed.push(cl);
            len.push(n);
            total += if cl { n - 1 } else { n };
        }
        Layout {
            base,
            closed,
            len,
            total,
        }
    }

    /// The variable of sample `j` of curve `k`.
    fn var(&self, k: usize, j: usize) -> usize {
        let m = if self.closed[k] {
            self.len[k] - 1
        } else {
            self.len[k]
        };
        self.base[k] + if self.closed[k] { j % m } else { j }
    }

    /// The curve and (first) sample of variable `v`.
    fn owner(&self, v: usize) -> (usize, usize) {
        let k = self.base.partition_point(|&b| b <= v) - 1;
        (k, v - self.base[k])
    }
}

/// A restricted problem's variables: the free ones first, in their order, then each fixed one
/// a kept term touches, as the terms first touch it.
struct Numbering {
    /// The variable of the whole problem behind each.
    of: Vec<usize>,
    /// The number of each variable of the whole problem (`usize::MAX`: none yet).
    new: Vec<usize>,
}

impl Numbering {
    fn of(free: &[bool]) -> Numbering {
        let of: Vec<usize> = (0..free.len()).filter(|&v| free[v]).collect();
        let mut new = vec![usize::MAX; free.len()];
        for (k, &v) in of.iter().enumerate() {
            new[v] = k;
        }
        Numbering { of, new }
    }

    /// The number of variable `v` of the whole problem, given it on first touch.
    fn map(&mut self, v: usize) -> usize {
        if self.new[v] == usize::MAX {
            self.new[v] = self.of.len();
            self.of.push(v);
        }
        self.new[v]
    }
}

/// The problem of `curves` restricted to the variables marked in `free` (as [`restrict`] does
/// to a whole problem), built over the curves with a free frame and the frames at their nodes
/// only; with every variable free, the whole problem ([`problem`], without `var_of`).
fn local_problem(curves: &[UniformCurve], layout: &Layout, free: &[bool]) -> (Problem, Vec<usize>) {
    let mut numbering = Numbering::of(free);
    let movable = numbering.of.len();
    let mut map = |v: usize| numbering.map(v);
    // The curves with a free frame (no term of another touches one but a node pair).
    let touched: Vec<usize> = (0..curves.len())
        .filter(|&k| (0..curves[k].q.len()).any(|j| free[layout.var(k, j)]))
        .collect();
    let mut edges = Vec::new();
    for &k in &touched {
        let c = &curves[k];
        for j in 0..c.q.len() - 1 {
            let (a, b) = (layout.var(k, j), layout.var(k, j + 1));
            if free[a] || free[b] {
                edges.push((map(a), map(b), c.edge_h(j)));
            }
        }
    }
    let mut triples = Vec::new();
    for &k in &touched {
        let c = &curves[k];
        let n = c.q.len();
        let closed = layout.closed[k];
        let m = if closed { n - 1 } else { n };
        let (first, last) = if closed { (0, m) } else { (1, n - 1) };
        for j in first..last {
            let prev = if j == 0 {
                layout.var(k, m - 1)
            } else {
                layout.var(k, j - 1)
            };
            let (mid, next) = (layout.var(k, j), layout.var(k, j + 1));
            // Not across a kink: at one, the frame held is the one leaving it, so the bend
            // before it would read the corner's whole turn (the frame arriving is no variable).
            if c.kinked(j) || c.kinked(j + 1) || !(free[prev] || free[mid] || free[next]) {
                continue;
            }
            let h = if j == 0 {
                c.edge_h(m - 1).max(c.edge_h(0))
            } else {
                (c.edge_h(j - 1) + c.edge_h(j)) / 2.0
            };
            triples.push((map(prev), map(mid), map(next), h));
        }
    }
    // The node pairs, as `problem` orders them: by node, then by the order of the frames.
    let crease_nodes = crease_nodes(curves);
    let mut at_node: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, c) in curves.iter().enumerate() {
        for &(i, nd) in &c.nodes {
            let v = layout.var(k, i);
            let list = at_node.entry(nd).or_default();
            if !list.contains(&v) {
                list.push(v);
            }
        }
    }
    // A frame's normal as `problem` reads it: of its variable's target.
    let normal = |v: usize| {
        let (k, j) = layout.owner(v);
        curves[k].q[j]
            .to_rotation_matrix()
            .matrix()
            .column(2)
            .into_owned()
    };
    let mut keys: Vec<&u32> = at_node.keys().collect();
    keys.sort();
    let mut pairs = Vec::new();
    for key in keys {
        let vs = &at_node[key];
        if !vs.iter().any(|&v| free[v]) {
            continue;
        }
        let crease = crease_nodes.contains(key);
        for i in 0..vs.len() {
            for j in i + 1..vs.len() {
                if !(free[vs[i]] || free[vs[j]]) {
                    continue;
                }
                if tied(crease, normal(vs[i]).dot(&normal(vs[j]))) {
                    pairs.push((map(vs[i]), map(vs[j])));
                }
            }
        }
    }
    let target = |v: usize| -> (Matrix3<f64>, f64) {
        let (k, j) = layout.owner(v);
        let c = &curves[k];
        let n = c.q.len();
        let w = if layout.closed[k] && j == 0 {
            c.w[0].max(c.w[n - 1])
        } else {
            c.w[j]
        };
        (*c.q[j].to_rotation_matrix().matrix(), w.max(1e-4))
    };
    let of = numbering.of;
    let (a, w) = of.iter().map(|&v| target(v)).unzip();
    (
        Problem {
            a,
            movable,
            w,
            edges,
            triples,
            pairs,
            var_of: Vec::new(),
        },
        of,
    )
}

/// The bending length in use: explicit, or a fraction of the mean sampling step.
pub fn bend_length(curves: &[UniformCurve], p: &RegressionParams) -> f64 {
    p.bend_length.unwrap_or_else(|| {
        let hs: Vec<f64> = curves.iter().flat_map(|c| c.h.iter().copied()).collect();
        let h = hs.iter().sum::<f64>() / hs.len().max(1) as f64;
        p.bend_fraction * h
    })
}

/// Weighted residuals and Jacobians at frames `x`.
fn terms(pb: &Problem, x: &[Matrix3<f64>], p: &Resolved) -> Terms {
    let n = pb.edges.len() + pb.triples.len() + pb.pairs.len();
    let mut t = Terms {
        terms: Vec::with_capacity(n),
        res: Vec::with_capacity(9 * pb.edges.len() + 3 * (pb.triples.len() + pb.pairs.len())),
        jac: Vec::with_capacity(18 * pb.edges.len() + 9 * pb.triples.len() + 6 * pb.pairs.len()),
        e0_energy: 0.0,
        e0_grad: Vec::with_capacity(pb.movable),
    };
    let movable = pb.movable;
    let basis = [Vector3::x(), Vector3::y(), Vector3::z()];
    // E0 = Σ w‖X − A‖²_F = Σ w (6 − 2 tr XᵀA); with J_k = √w X ê_k,
    // Jᵀr = −2w vee(skew(XᵀA)) and JᵀJ = 2w I.
    for (i, (xi, ai)) in x.iter().zip(&pb.a).take(pb.movable).enumerate() {
        let w = pb.w[i];
        let m = xi.transpose() * ai;
        t.e0_energy += w * (xi - ai).norm_squared();
        t.e0_grad.push(-2.0 * w * vee_skew(&m));
    }
    // E1.
    if p.stretch_length > 0.0 {
        for &(i, j, h) in &pb.edges {
            let w = (p.stretch_length * p.stretch_length / h / h).sqrt();
            let r = flat(&((x[i] - x[j]) * w));
            // Row e of ∂r/∂ω_k: entry e of X ω̂_k w (negated for the second frame).
            let di: [[f64; 9]; 3] = std::array::from_fn(|k| flat(&(x[i] * hat(&basis[k]) * w)));
            let dj: [[f64; 9]; 3] = std::array::from_fn(|k| flat(&(x[j] * hat(&basis[k]) * w)));
            let ji: [[f64; 3]; 9] = std::array::from_fn(|e| std::array::from_fn(|k| di[k][e]));
            let jj: [[f64; 3]; 9] = std::array::from_fn(|e| std::array::from_fn(|k| -dj[k][e]));
            t.push(movable, &r, &[(i, &ji), (j, &jj)]);
        }
    }
    let rows = |m: Matrix3<f64>| -> [[f64; 3]; 3] {
        std::array::from_fn(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]])
    };
    // E2: ‖skew(M)‖²_F = 2‖s‖², μ/h³ with μ = ℓ⁴/h.
    if p.bend > 0.0 {
        for &(a, b, c, h) in &pb.triples {
            let mu = p.bend.powi(4) / h;
            let w = (2.0 * mu / (h * h * h)).sqrt();
            let xbt = x[b].transpose();
            let pa = xbt * x[a];
            let pc = xbt * x[c];
            let m = pa + pc;
            let s = vee_skew(&m) * w;
            // vee(skew(P ω̂)) = ½(tr P · I − Pᵀ) ω and vee(skew(ω̂ M)) = ½(tr M · I − M) ω.
            let g =
                |pm: &Matrix3<f64>| (Matrix3::identity() * pm.trace() - pm.transpose()) * (0.5 * w);
            let ja = rows(g(&pa));
            let jc = rows(g(&pc));
            let jb = rows(-(Matrix3::identity() * m.trace() - m) * (0.5 * w));
            t.push(movable, s.as_slice(), &[(a, &ja), (b, &jb), (c, &jc)]);
        }
    }
    // E_N.
    let sx = p.xi.sqrt();
    let e3 = Vector3::z();
    for &(i, j) in &pb.pairs {
        let r = (x[i] * e3 - x[j] * e3) * sx;
        let ji = -(x[i] * hat(&e3)) * sx;
        let jj = (x[j] * hat(&e3)) * sx;
        t.push(movable, r.as_slice(), &[(i, &rows(ji)), (j, &rows(jj))]);
    }
    t
}

fn energy(t: &Terms) -> f64 {
    t.e0_energy
        + t.terms
            .iter()
            .map(|b| t.residuals(b).iter().map(|x| x * x).sum::<f64>())
            .sum::<f64>()
}

fn retract(x: &Matrix3<f64>, w: &Vector3<f64>) -> Matrix3<f64> {
    x * Rotation3::from_scaled_axis(*w).matrix()
}

impl RegressionSolver {
    pub fn new() -> Self {
        Self::default()
    }

    /// Regresses the frames of `curves` in place, starting from their own frames (the data).
    pub fn run(
        &mut self,
        curves: &mut [UniformCurve],
        params: &RegressionParams,
    ) -> RegressionReport {
        self.run_from(curves, params, &[])
    }

    /// As [`run`](Self::run), warm-started: `init[k]`, when it has one frame per sample of
    /// `curves[k]`, is where curve `k`'s frames start (e.g. the previous solution, when a new
    /// curve joined the network); the data term still pulls towards `curves[k].q`. The optimum
    /// is the same; fewer iterations reach it.
    ///
    /// Precompute, then solve: the normal matrix's block pattern is built once per run
    /// (`NormalPattern`) and factorised symbolically only when it changed since the last
    /// run; each Levenberg–Marquardt iteration assembles the normal equations
    /// (`normal_equations`) and takes a damped step (`damped_step`).
    pub fn run_from(
        &mut self,
        curves: &mut [UniformCurve],
        params: &RegressionParams,
        init: &[Option<&[UnitQuaternion<f64>]>],
    ) -> RegressionReport {
        let pb = problem(curves);
        let p = Resolved {
            stretch_length: params.stretch_length,
            bend: bend_length(curves, params),
            xi: params.xi,
        };
        let x = start(&pb, curves, init);
        let (x, report) = optimise(&mut self.pattern, &pb, &p, x, params);
        write_back(curves, &pb, &x);
        report
    }

    /// As [`run_from`](Self::run_from) from `previous` (each curve's frames of the last run,
    /// `None` for a curve that is new or changed since), moving only the frames near what
    /// changed (issue 19): every frame of a changed curve, and the frames within `window`
    /// samples of each node a changed curve passes through, or one of `changed_nodes` (the
    /// nodes of curves that left the network, or whose ties changed otherwise); every other
    /// frame keeps its `previous` value. At a node more than [`CROWDED`] curves hold, only
    /// the changed curves' frames move (issue 51). The terms that touch a moving frame are minimised,
    /// the others are constants.
    ///
    /// The node ties are strong and the bending weak at the default lengths (`ℓ₂ = h/2`: a
    /// correction at a node decays by ~0.3 per sample along a curve of full reliability), so
    /// the frames outside the window barely move in a whole-network run; but this is an
    /// approximation of [`run`](Self::run)'s optimum, for live updates that a whole-network
    /// run settles later. When everything changed, it is `run_from(previous)`.
    pub fn run_local(
        &mut self,
        curves: &mut [UniformCurve],
        params: &RegressionParams,
        previous: &[Option<&[UnitQuaternion<f64>]>],
        window: usize,
        changed_nodes: &[u32],
    ) -> RegressionReport {
        let kept = |k: usize| -> Option<&[UnitQuaternion<f64>]> {
            previous
                .get(k)
                .copied()
                .flatten()
                .filter(|q| q.len() == curves[k].q.len())
        };
        // The variables as `problem` numbers them, without building it: the local problem is
        // built over the frames it touches only (issue 51: on a grid of 100 curves the whole
        // problem was most of a live update's regression).
        let layout = Layout::of(curves);
        let mut free = vec![false; layout.total];
        let mut nodes: std::collections::HashSet<u32> = changed_nodes.iter().copied().collect();
        for (k, c) in curves.iter().enumerate() {
            if kept(k).is_none() {
                for j in 0..c.q.len() {
                    free[layout.var(k, j)] = true;
                }
                nodes.extend(c.nodes.iter().map(|x| x.1));
            }
        }
        // The curves at each node: at a node more than CROWDED hold (a grid's pole), the
        // new curve's tie moves each kept frame there by a small share of what it pulls, and
        // freeing them all would tie every pair of them in the local problem.
        let mut holding: HashMap<u32, usize> = HashMap::new();
        for c in curves.iter() {
            let mut at: Vec<u32> = c.nodes.iter().map(|x| x.1).collect();
            at.sort_unstable();
            at.dedup();
            for v in at {
                *holding.entry(v).or_default() += 1;
            }
        }
        let changed: std::collections::HashSet<u32> = changed_nodes.iter().copied().collect();
        for (k, c) in curves.iter().enumerate() {
            let n = c.q.len();
            // A closed curve's last variable is its first: its windows wrap.
            let closed = layout.closed[k];
            let windowed = |v: &u32| {
                nodes.contains(v)
                    && (kept(k).is_none()
                        || changed.contains(v)
                        || holding.get(v).is_none_or(|&h| h <= CROWDED))
            };
            for &(i, _) in c.nodes.iter().filter(|x| windowed(&x.1)) {
                let (i, w) = (i as isize, window as isize);
                for j in i - w..=i + w {
                    let j = if closed {
                        Some(j.rem_euclid(n as isize - 1))
                    } else {
                        (0..n as isize).contains(&j).then_some(j)
                    };
                    if let Some(j) = j {
                        free[layout.var(k, j as usize)] = true;
                    }
                }
            }
        }
        let moving = free.iter().filter(|f| **f).count();
        if moving == free.len() {
            return self.run_from(curves, params, previous);
        }
        let p = Resolved {
            stretch_length: params.stretch_length,
            bend: bend_length(curves, params),
            xi: params.xi,
        };
        let init: Vec<Option<&[UnitQuaternion<f64>]>> = (0..curves.len()).map(kept).collect();
        let mut report = RegressionReport::default();
        let mut solved: Vec<(usize, Matrix3<f64>)> = Vec::new();
        if moving > 0 {
            let (sub, of) = local_problem(curves, &layout, &free);
            // The start: the last run's frames of a kept curve, the targets of a new one (a
            // closed curve's first variable takes its last sample's, as `start` leaves it).
            let xs = of
                .iter()
                .map(|&v| {
                    let (k, j) = layout.owner(v);
                    match init[k] {
                        Some(q0) => {
                            let j = if layout.closed[k] && j == 0 {
                                q0.len() - 1
                            } else {
                                j
                            };
                            *q0[j].to_rotation_matrix().matrix()
                        }
                        None => *curves[k].q[j].to_rotation_matrix().matrix(),
                    }
                })
                .collect();
            let (xs, r) = optimise(&mut self.local_pattern, &sub, &p, xs, params);
            solved = of.iter().copied().zip(xs).take(sub.movable).collect();
            report = r;
        }
        report.frames = layout.total;
        report.frames_moved = moving;
        // The kept frames as they were, to the bit (not through their matrices); the moved
        // ones from the local solution.
        for (c, q0) in curves.iter_mut().zip(&init) {
            if let Some(q0) = q0 {
                c.q.copy_from_slice(q0);
            }
        }
        for (v, x) in solved {
            let (k, j) = layout.owner(v);
            let mut q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(x));
            q.renormalize();
            let c = &mut curves[k];
            c.q[j] = q;
            if layout.closed[k] && j == 0 {
                let last = c.q.len() - 1;
                c.q[last] = q;
            }
        }
        report
    }

    /// Symbolic factorisations of the normal matrix computed so far.
    pub fn symbolic_count(&self) -> usize {
        self.pattern.symbolic_count()
    }
}

/// Levenberg–Marquardt on problem `pb` from frames `x` (`pb.a.len()` of them; those past
/// `pb.movable` stay): the normal matrix's block pattern built once (`NormalPattern`) and
/// factorised symbolically only when it changed since `pattern`'s last use; each iteration
/// assembles the normal equations (`normal_equations`) and takes a damped step
/// (`damped_step`). The frames reached and what it took.
fn optimise(
    pattern: &mut CachedPattern,
    pb: &Problem,
    p: &Resolved,
    mut x: Vec<Matrix3<f64>>,
    params: &RegressionParams,
) -> (Vec<Matrix3<f64>>, RegressionReport) {
    let n = pb.movable;
    let mut report = RegressionReport {
        frames: n,
        frames_moved: n,
        ..Default::default()
    };
    if n == 0 {
        return (x, report);
    }
    let (normal, entries) = NormalPattern::of(pb, p);
    let symbolic = match pattern.pattern_ordered(3 * n, entries, || normal.order(pb)) {
        Ok((s, _)) => s,
        Err(e) => {
            tracing::error!("regression: {e}");
            return (x, report);
        }
    };
    let mut t = terms(pb, &x, p);
    let slots = normal.slots(&t);
    let e0 = energy(&t);
    report.energy_initial = e0;
    report.energy_final = e0;
    let mut damping = 1e-6;
    let mut e = e0;
    let mut slow = 0;
    for it in 0..params.max_iterations {
        report.iterations = it + 1;
        let (blocks, g) = normal_equations(pb, &t, &slots, &normal);
        let gnorm = g.iter().map(|v| v.norm_squared()).sum::<f64>().sqrt();
        report.gradient_norm = gnorm;
        if gnorm < params.gradient_tolerance {
            report.converged = true;
            break;
        }
        // The most a Gauss–Newton step from here could lower the energy: gᵀH⁻¹g ≤ gᵀD⁻¹g,
        // D the data term's part of H (2w I per frame; every other term adds a positive
        // semi-definite block). Below the tolerance the step would end the run anyway: it is
        // not factorised for (the last of a regression's three factorisations at 100 curves).
        let most: f64 = g
            .iter()
            .zip(&pb.w)
            .map(|(g, w)| g.norm_squared() / (2.0 * w))
            .sum();
        if most < params.relative_tolerance * e {
            report.converged = true;
            break;
        }
        let accepted = match damped_step(
            symbolic,
            &normal,
            &blocks,
            &g,
            &x,
            e,
            &mut damping,
            |trial| {
                let tt = terms(pb, trial, p);
                let et = energy(&tt);
                (tt, et)
            },
        ) {
            Some((trial, tt, et)) => {
                let rel = (e - et) / e.max(1e-300);
                x = trial;
                t = tt;
                e = et;
                damping = (damping / 3.0).max(1e-12);
                slow = if rel < params.stall_tolerance {
                    slow + 1
                } else {
                    0
                };
                if rel < params.relative_tolerance || slow >= STALL_ITERATIONS {
                    report.converged = true;
                }
                true
            }
            None => false,
        };
        if !accepted || report.converged {
            report.converged |= !accepted && gnorm < 1e-6;
            break;
        }
    }
    report.energy_final = e;
    (x, report)
}

/// The part of `pb` that moves when only the variables marked in `free` may: those variables
/// first (in their order, `movable` of them), then the fixed ones that a kept term touches
/// (constants); the terms that touch a free variable. With the variable of `pb` behind each
/// of its variables. What [`local_problem`] builds without the whole problem (its test).
#[cfg(test)]
fn restrict(pb: &Problem, free: &[bool]) -> (Problem, Vec<usize>) {
    let mut numbering = Numbering::of(free);
    let movable = numbering.of.len();
    let mut map = |v: usize| numbering.map(v);
    let edges: Vec<(usize, usize, f64)> = pb
        .edges
        .iter()
        .filter(|e| free[e.0] || free[e.1])
        .map(|&(i, j, h)| (map(i), map(j), h))
        .collect();
    let triples = pb
        .triples
        .iter()
        .filter(|t| free[t.0] || free[t.1] || free[t.2])
        .map(|&(a, b, c, h)| (map(a), map(b), map(c), h))
        .collect();
    let pairs = pb
        .pairs
        .iter()
        .filter(|q| free[q.0] || free[q.1])
        .map(|&(i, j)| (map(i), map(j)))
        .collect();
    let of = numbering.of;
    let sub = Problem {
        a: of.iter().map(|&v| pb.a[v]).collect(),
        movable,
        w: of.iter().map(|&v| pb.w[v]).collect(),
        edges,
        triples,
        pairs,
        var_of: Vec::new(),
    };
    (sub, of)
}

/// The frames the iterations start from: the data, or `init[k]` where it fits curve `k`.
fn start(
    pb: &Problem,
    curves: &[UniformCurve],
    init: &[Option<&[UnitQuaternion<f64>]>],
) -> Vec<Matrix3<f64>> {
    let mut x = pb.a.clone();
    for ((c, vars), start) in curves.iter().zip(&pb.var_of).zip(init) {
        if let Some(q0) = start.filter(|q0| q0.len() == c.q.len()) {
            for (q, &v) in q0.iter().zip(vars) {
                x[v] = *q.to_rotation_matrix().matrix();
            }
        }
    }
    x
}

/// The normal matrix's pattern: the lower triangle of 3×3 blocks coupling the variables
/// that share a residual, in a fixed order (`#blocks`, each a `(row, col)` block with
/// `row ≥ col`), and its scalar entries (`3n` by `3n`, lower triangle).
struct NormalPattern {
    block_keys: Vec<(usize, usize)>,
    block_index: HashMap<(usize, usize), usize>,
    /// The block of each variable's diagonal.
    diag_slot: Vec<usize>,
    /// Scalar entries of the lower triangle.
    entries: usize,
}

impl NormalPattern {
    /// The pattern of problem `pb` under the settings `p` (terms of weight zero add none),
    /// and its scalar entries (`(row, col)`, `row ≥ col`, in the order of [`values`](Self::values)).
    fn of(pb: &Problem, p: &Resolved) -> (Self, Vec<(usize, usize)>) {
        let n = pb.movable;
        let mut block_keys: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
        let mut add = |a: usize, b: usize| {
            if a != b && a < n && b < n {
                block_keys.push((a.max(b), a.min(b)));
            }
        };
        if p.stretch_length > 0.0 {
            for &(i, j, _) in &pb.edges {
                add(i, j);
            }
        }
        if p.bend > 0.0 {
            for &(a, b, c, _) in &pb.triples {
                add(a, b);
                add(b, c);
                add(a, c);
            }
        }
        for &(i, j) in &pb.pairs {
            add(i, j);
        }
        block_keys.sort_unstable();
        block_keys.dedup();
        let block_index: HashMap<(usize, usize), usize> = block_keys
            .iter()
            .enumerate()
            .map(|(k, &b)| (b, k))
            .collect();
        let diag_slot: Vec<usize> = (0..n).map(|i| block_index[&(i, i)]).collect();
        let mut entries = Vec::with_capacity(block_keys.len() * 9);
        for &(bi, bj) in &block_keys {
            for a in 0..3 {
                for b in 0..3 {
                    if bi != bj || a >= b {
                        entries.push((3 * bi + a, 3 * bj + b));
                    }
                }
            }
        }
        let pattern = NormalPattern {
            block_keys,
            block_index,
            diag_slot,
            entries: entries.len(),
        };
        (pattern, entries)
    }

    /// The elimination order of the frames' blocks (`n` of them, the movable frames of `pb`),
    /// expanded to their 3 rows each: of approximate minimum degree and the curves' pieces
    /// between nodes first, then a nested dissection across the nodes
    /// ([`crate::nested_dissection::order_interiors_first`]), the one that fills less
    /// ([`crate::sparse_llt::block_order`]). A frame tied to another curve's at a node, and
    /// the next frame along its curve (a bending term reaches over one frame), are not
    /// interior. `None` when the pattern is not one of blocks (not expected).
    fn order(&self, pb: &Problem) -> Option<Vec<usize>> {
        let n = pb.movable;
        let mut adj = vec![Vec::new(); n];
        let mut lower = Vec::with_capacity(self.block_keys.len());
        for &(i, j) in &self.block_keys {
            if i != j {
                adj[i].push(j);
                adj[j].push(i);
                lower.push((i, j));
            }
        }
        let mut tied = vec![false; n];
        for &(i, j) in &pb.pairs {
            for v in [i, j] {
                if v < n {
                    tied[v] = true;
                }
            }
        }
        let mut interior: Vec<bool> = tied.iter().map(|t| !t).collect();
        for vars in &pb.var_of {
            for w in vars.windows(2) {
                if w[0] < n && w[1] < n && tied[w[0]] {
                    interior[w[1]] = false;
                }
            }
        }
        let candidate = crate::nested_dissection::order_interiors_first(&adj, &interior);
        let blocks = crate::sparse_llt::block_order(n, &lower, Some(&candidate)).ok()?;
        Some(
            blocks
                .into_iter()
                .flat_map(|b| [3 * b, 3 * b + 1, 3 * b + 2])
                .collect(),
        )
    }

    /// The block of every (term, variable pair) of `t`: the terms keep their order and
    /// variables across iterations, so the lookups are done once.
    fn slots(&self, t: &Terms) -> Vec<usize> {
        let mut v = Vec::new();
        for b in &t.terms {
            let vars = &b.vars[..usize::from(b.nvars)];
            for vi in vars {
                for vj in vars {
                    if vj <= vi {
                        v.push(self.block_index[&(*vi, *vj)]);
                    }
                }
            }
        }
        v
    }

    /// The entries' values of the normal matrix of `blocks` with `damping` added to its
    /// diagonal (Levenberg–Marquardt: `λ (1 + JᵀJ_ii)`).
    fn values(&self, blocks: &[Matrix3<f64>], damping: f64) -> Vec<f64> {
        let mut vals = Vec::with_capacity(self.entries);
        for (k, &(bi, bj)) in self.block_keys.iter().enumerate() {
            for a in 0..3 {
                for b in 0..3 {
                    if bi != bj || a >= b {
                        let mut v = blocks[k][(a, b)];
                        if bi == bj && a == b {
                            v += damping * (1.0 + blocks[k][(a, a)]);
                        }
                        vals.push(v);
                    }
                }
            }
        }
        vals
    }
}

/// The Gauss–Newton normal equations at the terms `t`: `JᵀJ` by blocks of `pattern`
/// (`#blocks` 3×3 matrices) and the gradient `Jᵀr` (one 3-vector per variable).
fn normal_equations(
    pb: &Problem,
    t: &Terms,
    slots: &[usize],
    pattern: &NormalPattern,
) -> (Vec<Matrix3<f64>>, Vec<Vector3<f64>>) {
    let mut blocks = vec![Matrix3::<f64>::zeros(); pattern.block_keys.len()];
    let mut g = t.e0_grad.clone();
    for (i, w) in pb.w.iter().take(pb.movable).enumerate() {
        blocks[pattern.diag_slot[i]] += Matrix3::identity() * (2.0 * w);
    }
    let mut next_slot = slots.iter();
    for b in &t.terms {
        let r = t.residuals(b);
        for (vi, ji) in t.jacobians(b) {
            let mut jtr = Vector3::zeros();
            for (row, rv) in ji.iter().zip(r) {
                jtr += Vector3::from(*row) * *rv;
            }
            g[vi] += jtr;
            for (vj, jj) in t.jacobians(b) {
                if vj > vi {
                    continue;
                }
                let mut blk = Matrix3::zeros();
                for (ra, rb) in ji.iter().zip(jj) {
                    blk += Vector3::from(*ra) * Vector3::from(*rb).transpose();
                }
                blocks[*next_slot.next().expect("one slot per pair")] += blk;
            }
        }
    }
    (blocks, g)
}

/// One Levenberg–Marquardt step from `x` (energy `e`): the damped normal equations solved on
/// the `symbolic` factorisation, retracted onto SO(3), kept when `evaluate` gives an energy
/// no higher; otherwise the damping grows and it tries again (10 tries). The accepted frames
/// with what `evaluate` made of them, or `None`.
#[allow(clippy::too_many_arguments)]
fn damped_step<T>(
    symbolic: &SpdPattern,
    pattern: &NormalPattern,
    blocks: &[Matrix3<f64>],
    g: &[Vector3<f64>],
    x: &[Matrix3<f64>],
    e: f64,
    damping: &mut f64,
    evaluate: impl Fn(&[Matrix3<f64>]) -> (T, f64),
) -> Option<(Vec<Matrix3<f64>>, T, f64)> {
    for _ in 0..10 {
        let vals = pattern.values(blocks, *damping);
        let Ok(f) = symbolic.factor(&vals) else {
            *damping *= 10.0;
            continue;
        };
        let mut rhs: Vec<[f64; 1]> = g.iter().flat_map(|v| [[-v.x], [-v.y], [-v.z]]).collect();
        f.solve(&mut rhs);
        // Frames past the gradient's (a local run's constants) stay.
        let trial: Vec<Matrix3<f64>> = x
            .iter()
            .enumerate()
            .map(|(i, xi)| match g.get(i) {
                Some(_) => retract(
                    xi,
                    &Vector3::new(rhs[3 * i][0], rhs[3 * i + 1][0], rhs[3 * i + 2][0]),
                ),
                None => *xi,
            })
            .collect();
        if trial.iter().any(|m| m.iter().any(|v| !v.is_finite())) {
            *damping *= 10.0;
            continue;
        }
        let (tt, et) = evaluate(&trial);
        if et <= e {
            return Some((trial, tt, et));
        }
        *damping *= 4.0;
    }
    None
}

/// The regressed frames back into the curves, re-orthonormalised.
fn write_back(curves: &mut [UniformCurve], pb: &Problem, x: &[Matrix3<f64>]) {
    for (c, vars) in curves.iter_mut().zip(&pb.var_of) {
        for (q, &v) in c.q.iter_mut().zip(vars) {
            // x is a product of exact rotations: convert directly (Shepperd), not by the
            // iterative projection, which can settle on a wrong rotation far from its guess.
            *q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(x[v]));
            q.renormalize();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn arc(
        noise: f64,
        seed: u64,
        index: usize,
        nodes: (u32, u32),
        tilt: f64,
    ) -> (UniformCurve, Vec<UnitQuaternion<f64>>) {
        let mut rng = Rng::new(seed);
        let n = 200;
        let h = 0.005;
        let truth: Vec<UnitQuaternion<f64>> = (0..=n)
            .map(|j| {
                let s = j as f64 * h;
                UnitQuaternion::from_euler_angles(tilt, 0.5 * s, 2.0 * s)
            })
            .collect();
        let q = truth
            .iter()
            .map(|t| t * UnitQuaternion::from_scaled_axis(rng.vec3(noise)))
            .collect();
        (
            UniformCurve {
                index,
                kind: crate::curve::CurveKind::Interior,
                d: (0..=n).map(|j| j as f64 * h).collect(),
                q,
                nodes: vec![(0, nodes.0), (n, nodes.1)],
                h: vec![h],
                w: vec![1.0; n + 1],
                outliers: 0,
                kinks: Vec::new(),
            },
            truth,
        )
    }

    /// Issue 52: a curve that kinks at its middle node (a corner turned in place: the frame
    /// turns 90° about its normal there) keeps exact frames exact. Before, the bend of the
    /// frame just before the kink was read with the frame leaving it, and pulled it 45°
    /// towards the corner's turn.
    #[test]
    fn issue_52_a_kink_bends_no_frame_before_it() {
        let n = 200;
        let h = 0.005;
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let exact: Vec<UnitQuaternion<f64>> = (0..=n)
            .map(|j| {
                if j < n / 2 {
                    UnitQuaternion::identity()
                } else {
                    turn
                }
            })
            .collect();
        let mut curves = vec![UniformCurve {
            index: 0,
            kind: crate::curve::CurveKind::Boundary,
            d: (0..=n).map(|j| j as f64 * h).collect(),
            q: exact.clone(),
            nodes: vec![(0, 0), (n / 2, 1), (n, 2)],
            h: vec![h, h],
            w: vec![1.0; n + 1],
            outliers: 0,
            kinks: vec![(n / 2, UnitQuaternion::identity())],
        }];
        let p = RegressionParams {
            bend_length: Some(0.03),
            ..Default::default()
        };
        RegressionSolver::new().run(&mut curves, &p);
        let worst = curves[0]
            .q
            .iter()
            .zip(&exact)
            .map(|(q, t)| q.angle_to(t).to_degrees())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "a frame {worst}° off");
    }

    #[test]
    fn smooths_noise_and_aligns_node_normals() {
        let (a, ta) = arc(0.02, 1, 0, (0, 1), 0.0);
        let (mut b, tb) = arc(0.02, 2, 1, (0, 2), 0.0);
        // Curve b leaves node 0 in another direction: rotate it about the normal there.
        let turn = UnitQuaternion::from_axis_angle(&(ta[0] * Vector3::z_axis()), 1.0);
        for q in b.q.iter_mut() {
            *q = turn * *q;
        }
        let tb: Vec<UnitQuaternion<f64>> = tb.iter().map(|t| turn * t).collect();
        let mut curves = vec![a, b];
        let err = |c: &[UniformCurve]| -> f64 {
            let e: Vec<f64> = c[0]
                .q
                .iter()
                .zip(&ta)
                .chain(c[1].q.iter().zip(&tb))
                .map(|(q, t)| q.angle_to(t))
                .collect();
            (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
        };
        let before = err(&curves);
        let p = RegressionParams {
            bend_length: Some(0.03),
            ..Default::default()
        };
        let rep = RegressionSolver::new().run(&mut curves, &p);
        let after = err(&curves);
        assert!(rep.energy_final < rep.energy_initial);
        assert!(after < 0.5 * before, "rms {before} → {after}");
        let n0 = curves[0].q[0] * Vector3::z();
        let n1 = curves[1].q[0] * Vector3::z();
        assert!(
            n0.angle(&n1).to_degrees() < 0.5,
            "{}",
            n0.angle(&n1).to_degrees()
        );
    }

    /// Issue 51: the run stops, without factorising for it, when no Gauss–Newton step could
    /// lower the energy by the relative tolerance (a bound from the data term alone). The
    /// energy it stops at is within that tolerance of the optimum (the same network run to a
    /// tolerance of 0, to its 50 iterations or a vanishing gradient), in fewer iterations.
    #[test]
    fn issue_51_the_regression_stops_when_no_step_can_gain_the_tolerance() {
        let (a, _) = arc(0.03, 21, 0, (0, 1), 0.0);
        let (b, _) = arc(0.03, 22, 1, (0, 2), 0.3);
        let (c, _) = arc(0.03, 23, 2, (1, 2), -0.2);
        let p = RegressionParams::default();
        let mut curves = vec![a.clone(), b.clone(), c.clone()];
        let rep = RegressionSolver::new().run(&mut curves, &p);
        let tight = RegressionParams {
            relative_tolerance: 0.0,
            stall_tolerance: 0.0,
            gradient_tolerance: 1e-14,
            ..p
        };
        let mut optimum = vec![a, b, c];
        let best = RegressionSolver::new().run(&mut optimum, &tight);
        assert!(rep.converged);
        assert!(
            rep.iterations < best.iterations,
            "{} iterations, {} to the optimum",
            rep.iterations,
            best.iterations
        );
        let gap = (rep.energy_final - best.energy_final) / best.energy_final;
        assert!((0.0..p.relative_tolerance).contains(&gap), "{gap:e}");
    }

    /// Issue 19, point 2: a curve joins a network of two; the local run moves the new curve
    /// and the window around the nodes it shares, keeps every other frame as it was, and
    /// lands next to the whole network's optimum.
    #[test]
    fn issue_19_a_local_run_moves_the_new_curves_neighbourhood_only() {
        let (a, _) = arc(0.02, 11, 0, (0, 1), 0.0);
        let (b, _) = arc(0.02, 12, 1, (0, 2), 0.1);
        let (c, _) = arc(0.02, 13, 2, (1, 2), 0.2);
        let p = RegressionParams::default();
        let mut before = vec![a.clone(), b.clone()];
        let mut solver = RegressionSolver::new();
        solver.run(&mut before, &p);
        let mut whole = vec![a.clone(), b.clone(), c.clone()];
        RegressionSolver::new().run(&mut whole, &p);
        let mut local = vec![a, b, c];
        let previous = [
            Some(before[0].q.as_slice()),
            Some(before[1].q.as_slice()),
            None,
        ];
        let window = 10;
        let rep = solver.run_local(&mut local, &p, &previous, window, &[]);
        // Curve c (201 frames) and the last 11 frames of a and b (at nodes 1 and 2).
        assert_eq!(rep.frames, 603);
        assert_eq!(rep.frames_moved, 201 + 2 * (window + 1));
        assert!(rep.energy_final < rep.energy_initial);
        for k in 0..2 {
            for j in 0..=200 {
                let kept = local[k].q[j] == before[k].q[j];
                assert_eq!(kept, j < 200 - window, "curve {k}, sample {j}");
            }
        }
        let worst = local
            .iter()
            .zip(&whole)
            .flat_map(|(l, w)| l.q.iter().zip(&w.q).map(|(x, y)| x.angle_to(y)))
            .fold(0.0f64, f64::max);
        assert!(worst.to_degrees() < 0.01, "{}°", worst.to_degrees());
        // Curve b leaves the network: the frames at its nodes move again (a's at node 0,
        // c's at node 2).
        let mut two = vec![local[0].clone(), local[2].clone()];
        let prev: Vec<Vec<UnitQuaternion<f64>>> = two.iter().map(|c| c.q.clone()).collect();
        let previous = [Some(prev[0].as_slice()), Some(prev[1].as_slice())];
        let rep = solver.run_local(&mut two, &p, &previous, window, &[0, 2]);
        assert_eq!(rep.frames_moved, 2 * (window + 1));
    }

    /// Issue 51: the local problem built over the frames it touches is the whole problem
    /// restricted to the free frames, variable for variable and term for term in the same
    /// order (so a local run's arithmetic is what it was): a network with a closed curve,
    /// a crease and a node four curves hold, under random sets of free frames.
    #[test]
    fn issue_51_the_local_problem_is_the_whole_one_restricted() {
        let (a, _) = arc(0.05, 31, 0, (0, 1), 0.0);
        let (b, _) = arc(0.05, 32, 1, (0, 2), 0.4);
        let (mut c, _) = arc(0.05, 33, 2, (1, 2), -0.3);
        c.kind = crate::curve::CurveKind::Crease;
        let (mut d, _) = arc(0.05, 34, 3, (0, 0), 1.2);
        d.nodes.insert(1, (100, 1));
        let curves = vec![a, b, c, d];
        let layout = Layout::of(&curves);
        assert_eq!(layout.closed, [false, false, false, true]);
        let whole = problem(&curves);
        assert_eq!(layout.total, whole.a.len());
        for (k, vars) in whole.var_of.iter().enumerate() {
            for (j, &v) in vars.iter().enumerate() {
                assert_eq!(layout.var(k, j), v);
                let (ok, oj) = layout.owner(v);
                assert_eq!((ok, layout.var(ok, oj)), (k, v));
            }
        }
        let mut rng = Rng::new(5);
        let mut cases: Vec<Vec<bool>> = [0.01, 0.1, 0.5]
            .iter()
            .map(|&share| (0..layout.total).map(|_| rng.uniform() < share).collect())
            .collect();
        // The frames at node 1 (three curves, one a crease) and the last of b.
        let mut at_node = vec![false; layout.total];
        for (k, c) in curves.iter().enumerate() {
            for &(i, nd) in &c.nodes {
                at_node[layout.var(k, i)] |= nd == 1;
            }
        }
        at_node[layout.var(1, 200)] = true;
        cases.push(at_node);
        for (case, free) in cases.iter().enumerate() {
            let (want, want_of) = restrict(&whole, free);
            let (got, got_of) = local_problem(&curves, &layout, free);
            assert_eq!(got_of, want_of);
            assert_eq!(got.movable, want.movable);
            assert_eq!(got.a, want.a);
            assert_eq!(got.w, want.w);
            assert_eq!(got.edges, want.edges);
            assert_eq!(got.triples, want.triples);
            assert_eq!(got.pairs, want.pairs);
            // At the crease node only a and c (17° apart) are tied; d (69°) is not.
            assert!(case < 3 || got.pairs.len() == 1, "{:?}", got.pairs);
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let (a, _) = arc(0.05, 3, 0, (0, 1), 0.3);
        let (b, _) = arc(0.05, 4, 1, (0, 2), -0.2);
        let pb = problem(&[a, b]);
        let p = Resolved {
            stretch_length: 0.02,
            bend: 0.03,
            xi: 1e4,
        };
        let x: Vec<Matrix3<f64>> =
            pb.a.iter()
                .enumerate()
                .map(|(i, m)| retract(m, &Vector3::new(0.01 * i as f64, -0.02, 0.03)))
                .collect();
        let t = terms(&pb, &x, &p);
        let eps = 1e-6;
        // The closed-form data term: dE₀/dω = 2 Jᵀr.
        for v in (0..x.len()).step_by(29) {
            for k in 0..3 {
                let mut w = Vector3::zeros();
                w[k] = eps;
                let mut xp = x.clone();
                xp[v] = retract(&x[v], &w);
                let fd = (terms(&pb, &xp, &p).e0_energy - t.e0_energy) / eps;
                let an = 2.0 * t.e0_grad[v][k];
                assert!(
                    (fd - an).abs() < 1e-4 * (1.0 + an.abs()),
                    "E0 var {v} dir {k}: {fd} vs {an}"
                );
            }
        }
        for (bk, b) in t.terms.iter().enumerate().step_by(37) {
            let r = t.residuals(b);
            for (v, jac) in t.jacobians(b) {
                for k in 0..3 {
                    let mut w = Vector3::zeros();
                    w[k] = eps;
                    let mut xp = x.clone();
                    xp[v] = retract(&x[v], &w);
                    let tp = terms(&pb, &xp, &p);
                    let rp = tp.residuals(&tp.terms[bk]);
                    for (row, (a, b)) in rp.iter().zip(r).enumerate() {
                        let fd = (a - b) / eps;
                        assert!(
                            (fd - jac[row][k]).abs() < 1e-4 * (1.0 + fd.abs()),
                            "block {bk} var {v} dir {k} row {row}: {fd} vs {}",
                            jac[row][k]
                        );
                    }
                }
            }
        }
    }
}
