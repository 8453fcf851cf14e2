//! Poisson network reconstruction (§5 of the paper): positions from tangents. One unknown per
//! sample, each node a single unknown shared by every curve through it; least squares of
//! `(x_{j+1} − x_j)/h − (T_j + T_{j+1})/2` over every edge of every curve (the midpoint rule,
//! exact to second order on a circular arc); one gauge vertex per connected component. The
//! normal matrix is a weighted graph Laplacian. Each run of samples between two tags is a
//! path in it, eliminated exactly ([`super::kron`]): in closed form, its edges in series
//! ([`super::kron::Series`]: one edge between its tags, its samples placed along it once the
//! nodes are solved). What is factorised, by sparse Cholesky, is the Laplacian of the nodes
//! alone, its symbolic factorisation kept and reused while the pattern (the network's
//! topology) stays the same. What a solve reads of each curve (its edges' data, its runs'
//! sums, its tangents and normals: 160 bytes a sample) is kept while the curve is the same to
//! the bit, and found again only where its frames changed, so that a live update, which turns
//! a few frames of many curves (issue 51), finds again only theirs.

use super::kron::{KronReduced, NodeSystem, Run, Series, Span, Tridiagonal};
use super::prefilter::UniformCurve;
use crate::sparse_llt::{CachedPattern, SolveError};
use nalgebra::{UnitQuaternion, Vector3};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

/// Positions and normals of one reconstructed curve.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvePositions {
    pub index: usize,
    pub kind: crate::curve::CurveKind,
    pub points: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    pub tangents: Vec<Vector3<f64>>,
    /// A crease's other face: its unit normals at the samples ([`super::crease`]); empty for
    /// other kinds.
    pub across: Vec<Vector3<f64>>,
    /// `(sample index, node)`.
    pub nodes: Vec<(usize, u32)>,
    /// The curve's own distance at every sample (the scan's `d`: the wheel's, or the phone's
    /// from its speed), m; empty where the curve was not resampled from a scan.
    pub d: Vec<f64>,
    /// Each point's uncertainty, m ([`super::marginals`]); empty until it is computed.
    pub sigma_m: Vec<f64>,
}

impl CurvePositions {
    /// Lies on the boundary of the surface.
    pub fn boundary(&self) -> bool {
        self.kind == crate::curve::CurveKind::Boundary
    }
}

/// The reconstructed network.
#[derive(Debug, Clone, PartialEq)]
pub struct Positions {
    pub curves: Vec<CurvePositions>,
    pub nodes: BTreeMap<u32, Vector3<f64>>,
    /// Connected components (each placed with its own gauge).
    pub components: usize,
    /// What the least squares left unexplained: the loops' misfit.
    pub misfit: Misfit,
}

/// The Poisson least squares' residual: `chi2 = Σ_e w_e |x_b − x_a − h_e t_e|²` over every
/// edge (`w_e = 1/h_e²`, so each term is the squared tangent residual, dimensionless), and
/// the loops that can leave one (the network's cycle rank, edges − unknowns + components).
/// A network without loops fits exactly: `chi2 = 0`, `loops = 0`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Misfit {
    pub chi2: f64,
    /// `chi2`'s terms summed per segment (between consecutive tags) of each curve (in the
    /// order of the curves solved).
    pub chi2_segments: Vec<Vec<f64>>,
    pub loops: usize,
    /// Mean step of the edges, m (the residual's scale: [`super::marginals`]).
    pub mean_h: f64,
}

/// The loops' misfit as a function of a yaw `ψ` common to every frame
/// ([`PoissonSolver::yaw_form`]): `chi2(ψ) = uᵀ M u` with `u = (cos ψ, sin ψ)` and `M` the sum
/// of `per_curve` (each curve's edges' share, 2 by 2, symmetric; the same weights as
/// [`Misfit::chi2`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct YawForm {
    /// Per curve (in the order of the curves solved), its edges' share of `M`.
    pub per_curve: Vec<nalgebra::Matrix2<f64>>,
    /// The network's cycle rank ([`Misfit::loops`]).
    pub loops: usize,
}

/// The loops' misfit as a function of a scale per curve ([`PoissonSolver::scale_form`]): each
/// curve's edge data `h t` read `(1 + s_c) h t`, the misfit is
/// `chi2(s) = chi2 + 2 bᵀ s + sᵀ H s` (the same weights as [`Misfit::chi2`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ScaleForm {
    /// `H`, #curves by #curves, symmetric positive semi-definite. A scale common to every
    /// curve only scales the misfit (`chi2(t 1) = (1 + t)² chi2`): `H 1 = b`, `1ᵀ b = chi2`.
    pub h: nalgebra::DMatrix<f64>,
    /// `b`, one per curve (in the order of the curves solved).
    pub b: nalgebra::DVector<f64>,
    /// The misfit as measured (`s = 0`).
    pub chi2: f64,
    /// The network's cycle rank ([`Misfit::loops`]).
    pub loops: usize,
}

/// Keeps the symbolic factorisation between solves, and what [`solve`](Self::solve) reads of
/// each curve while the curve stays the same (issue 51: a live update changes a few curves of
/// many).
#[derive(Debug, Default)]
pub struct PoissonSolver {
    pattern: CachedPattern,
    /// The last solve's curves' [`Prepared`], by scan index.
    prepared: HashMap<usize, Arc<Prepared>>,
    /// Curves prepared anew so far (for tests and benchmarks).
    prepared_count: usize,
}

/// What Poisson reads of one curve and nothing else: its tangents and normals, its edges'
/// weights and data, its runs between tags, their edges in series and their factorised
/// blocks (for the slides). Kept while the curve's frames, steps, tags and kinks are the same
/// to the bit, found again where its frames alone changed ([`Prepared::refresh`]): the same
/// arithmetic on the same bits, so a kept one is what would be found again.
#[derive(Debug, Default)]
struct Prepared {
    q: Vec<UnitQuaternion<f64>>,
    h: Vec<f64>,
    nodes: Vec<(usize, u32)>,
    kinks: Vec<(usize, UnitQuaternion<f64>)>,
    tangents: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    /// Each edge's weight `1/h²` (edge `j`: from sample `j` to `j + 1`).
    w: Vec<f64>,
    /// Each edge's data `h t` ([`edge_data`]).
    v: Vec<Vector3<f64>>,
    spans: Vec<Span>,
    /// Each span's edges in series ([`Series`]).
    series: Vec<Series>,
    /// The sums over each span's edges before each sample ([`Span::series`]).
    cum_r: Vec<f64>,
    cum_v: Vec<Vector3<f64>>,
    /// Its edges between two unknowns (all but those between two tags of one node on
    /// adjacent samples), and their steps summed (the misfit's scale: [`Misfit::mean_h`]).
    used: usize,
    h_sum: f64,
    /// Each span's block; `None` for a span with no node (its ridge is the network's gauge).
    blocks: Vec<Option<Tridiagonal>>,
}

impl Prepared {
    /// Found again for `c`, whose unknown at each sample is `vars` (for the blocks' errors),
    /// in the buffers of the curve's last (a live update: no memory asked of the system, none
    /// given back).
    fn refill(&mut self, c: &UniformCurve, vars: &[usize]) -> Result<(), SolveError> {
        let x = Vector3::x();
        self.q.clone_from(&c.q);
        self.h.clone_from(&c.h);
        self.nodes.clone_from(&c.nodes);
        self.kinks.clone_from(&c.kinks);
        self.tangents.clear();
        self.tangents.extend(c.q.iter().map(|q| q * x));
        self.normals.clear();
        self.normals.extend(c.q.iter().map(|q| q * Vector3::z()));
        curve_edges(c, &x, &self.tangents, &mut self.w, &mut self.v);
        let mut node_at = vec![None; c.q.len()];
        for &(i, nd) in &c.nodes {
            if let Some(at) = node_at.get_mut(i) {
                *at = Some(nd);
            }
        }
        self.spans = Span::along(&node_at);
        let m = c.q.len();
        self.cum_r.clear();
        self.cum_r.resize(m, 0.0);
        self.cum_v.clear();
        self.cum_v.resize(m, Vector3::zeros());
        self.series.clear();
        self.blocks.clear();
        (self.used, self.h_sum) = (0, 0.0);
        for s in &self.spans {
            let series = s.series(&self.w, &self.v, &mut self.cum_r, &mut self.cum_v);
            self.series.push(series);
            self.used += s.edges().len();
            self.h_sum += self.w[s.edges()]
                .iter()
                .map(|w| w.sqrt().recip())
                .sum::<f64>();
            let run = Run::of(s, vars, &self.w);
            let block = (!run.alone())
                .then(|| Tridiagonal::of(&run, 0.0))
                .transpose()?;
            self.blocks.push(block);
        }
        Ok(())
    }

    /// Brought to `c`: kept as it is when `c` has the same frames, steps, tags and kinks to
    /// the bit (`false` returned); where only frames changed (a live update's local
    /// regression turns a few near the new curve's nodes), found again at those samples, at
    /// their edges and along the runs they are in, the rest kept; else found again whole.
    /// The same arithmetic on the same bits either way.
    fn refresh(&mut self, c: &UniformCurve, vars: &[usize]) -> Result<bool, SolveError> {
        let same_bits = |a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>| {
            a.coords
                .iter()
                .zip(b.coords.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        };
        let same_shape = self.nodes == c.nodes
            && self.h.len() == c.h.len()
            && self
                .h
                .iter()
                .zip(&c.h)
                .all(|(a, b)| a.to_bits() == b.to_bits())
            && self.q.len() == c.q.len()
            && self.kinks.len() == c.kinks.len()
            && (self.kinks.iter().zip(&c.kinks)).all(|(a, b)| a.0 == b.0 && same_bits(&a.1, &b.1));
        if !same_shape {
            self.refill(c, vars)?;
            return Ok(true);
        }
        let x = Vector3::x();
        // The edges whose data changed (edge j: from sample j to j + 1).
        let mut edges: Vec<usize> = Vec::new();
        for (j, (kept, now)) in self.q.iter_mut().zip(&c.q).enumerate() {
            if same_bits(kept, now) {
                continue;
            }
            *kept = *now;
            self.tangents[j] = now * x;
            self.normals[j] = now * Vector3::z();
            if j > 0 && edges.last() != Some(&(j - 1)) {
                edges.push(j - 1);
            }
            if j + 1 < c.q.len() {
                edges.push(j);
            }
        }
        if edges.is_empty() {
            return Ok(false);
        }
        for &j in &edges {
            // As `curve_edges`: its step, and the frame arriving at its end.
            let h = c.edge_h(j);
            let arriving = if c.kinked(j + 1) {
                c.arriving(j + 1) * x
            } else {
                self.tangents[j + 1]
            };
            self.v[j] = (self.tangents[j] + arriving) * (0.5 * h);
        }
        // The runs of those edges, in series again (their weights, and so their blocks, are
        // the same: the steps are).
        let mut next = 0;
        for (s, series) in self.spans.iter().zip(&mut self.series) {
            let range = s.edges();
            while next < edges.len() && edges[next] < range.start {
                next += 1;
            }
            if next < edges.len() && range.contains(&edges[next]) {
                *series = s.series(&self.w, &self.v, &mut self.cum_r, &mut self.cum_v);
            }
        }
        Ok(true)
    }

    /// Its edges in a network's unknowns (`vars`: its unknown at each sample).
    fn edges<'a>(&'a self, vars: &'a [usize]) -> impl Iterator<Item = Edge> + 'a {
        self.w
            .iter()
            .zip(&self.v)
            .enumerate()
            .map(move |(j, (&w, &v))| Edge {
                a: vars[j],
                b: vars[j + 1],
                w,
                v,
            })
    }
}

#[derive(Clone, Copy)]
struct Edge {
    a: usize,
    b: usize,
    w: f64,
    v: Vector3<f64>,
}

/// Ridge on each slide, relative to its edges' weight: a slide no loop constrains stays
/// within about a thousandth of its gap.
const SLIDE_RIDGE: f64 = 1e-6;

impl PoissonSolver {
    /// Symbolic factorisations computed so far (for tests and benchmarks).
    pub fn symbolic_count(&self) -> usize {
        self.pattern.symbolic_count()
    }

    /// Numeric factorisations of the node system computed so far (for tests and benchmarks).
    pub fn numeric_count(&self) -> usize {
        self.pattern.numeric_count()
    }

    /// Curves whose edges and runs were found anew so far, the others kept from the solve
    /// before (for tests and benchmarks).
    pub fn prepared_count(&self) -> usize {
        self.prepared_count
    }

    /// The node system's pattern, with its last numeric factorisation kept (a live update's
    /// loop test factorises through it: `closure::Kept::node_system`).
    pub(crate) fn node_pattern(&mut self) -> &mut CachedPattern {
        &mut self.pattern
    }

    pub fn new() -> Self {
        Self::default()
    }

    /// Reconstructs positions from the curves' frames.
    pub fn solve(&mut self, curves: &[UniformCurve]) -> Result<Positions, SolveError> {
        self.solve_sliding(curves, &[]).map(|(p, _)| p)
    }

    /// The loops' misfit of the frames turned about their own normals by a yaw `ψ` (the
    /// tangents read `cos ψ T + sin ψ B`): the residual is linear in `(cos ψ, sin ψ)`, so the
    /// misfit is a quadratic form in them, found with one factorisation and the solves of the
    /// tangents' and the binormals' data ([`YawForm`]; [`super::mounting::estimate_yaw`]).
    pub fn yaw_form(&mut self, curves: &[UniformCurve]) -> Result<YawForm, SolveError> {
        let (node_var, var_of, n) = unknowns(curves);
        let (x, y) = (Vector3::x(), Vector3::y());
        let (along, edge_at) = edges(curves, &var_of, &x, &axes(curves, &x));
        let (across, _) = edges(curves, &var_of, &y, &axes(curves, &y));
        let w: Vec<f64> = along.iter().map(|e| e.w).collect();
        let runs = runs(curves, &var_of, &w, node_var.len());
        let f = KronReduced::new(n, node_var.len(), &runs, ridge(&along), &mut self.pattern)?;
        let mut x = [vec![[0.0; 3]; n], vec![[0.0; 3]; n]];
        for (x, e) in x.iter_mut().zip([&along, &across]) {
            add_rhs(x, e.iter().copied());
            f.solve(x);
        }
        let mut per_curve = vec![nalgebra::Matrix2::<f64>::zeros(); curves.len()];
        let mut used = 0usize;
        for ((ea, eb), &(ci, _)) in along.iter().zip(&across).zip(&edge_at) {
            if ea.a == ea.b {
                continue;
            }
            used += 1;
            let r = |x: &[[f64; 3]], e: &Edge| Vector3::from(x[e.b]) - Vector3::from(x[e.a]) - e.v;
            let (ra, rb) = (r(&x[0], ea), r(&x[1], eb));
            let m = &mut per_curve[ci];
            m[(0, 0)] += ea.w * ra.norm_squared();
            m[(0, 1)] += ea.w * ra.dot(&rb);
            m[(1, 1)] += ea.w * rb.norm_squared();
        }
        for m in &mut per_curve {
            m[(1, 0)] = m[(0, 1)];
        }
        Ok(YawForm {
            per_curve,
            loops: (used + f.components()).saturating_sub(n),
        })
    }

    /// The loops' misfit with each curve's distances scaled ([`ScaleForm`]): the residual
    /// of data `v` is `P v` (`P` the least squares' projection), linear in the data, so with
    /// `r_c` the residual of curve `c`'s edge data alone, `H_cd = ⟨r_c, r_d⟩ = ⟨v_c, r_d⟩`
    /// and `b_c = ⟨v_c, r⟩`. One factorisation and a solve per curve.
    pub fn scale_form(&mut self, curves: &[UniformCurve]) -> Result<ScaleForm, SolveError> {
        let (node_var, var_of, n) = unknowns(curves);
        let nodes = node_var.len();
        let x = Vector3::x();
        let (edges, edge_at) = edges(curves, &var_of, &x, &axes(curves, &x));
        let w: Vec<f64> = edges.iter().map(|e| e.w).collect();
        let (runs, run_starts) = runs_by_curve(curves, &var_of, &w, nodes);
        let f = KronReduced::new(n, nodes, &runs, ridge(&edges), &mut self.pattern)?;
        let k = curves.len();
        // Each curve's edges: a range of `edges`.
        let mut start = vec![0usize; k + 1];
        for &(ci, _) in &edge_at {
            start[ci + 1] += 1;
        }
        for c in 0..k {
            start[c + 1] += start[c];
        }
        let own = |c: usize| edges[start[c]..start[c + 1]].iter().filter(|e| e.a != e.b);
        // The misfit and b from one whole solve.
        let mut x = vec![[0.0; 3]; n];
        add_rhs(&mut x, edges.iter().copied());
        f.solve(&mut x);
        let x: Vec<Vector3<f64>> = x.into_iter().map(Vector3::from).collect();
        let measured = misfit(
            curves,
            edge_at.iter().copied().zip(edges.iter().copied()),
            &x,
            &[],
            &[],
            &[],
            f.components(),
        );
        let residual = |e: &Edge| e.v - (x[e.b] - x[e.a]);
        let b = nalgebra::DVector::from_iterator(
            k,
            (0..k).map(|c| own(c).map(|e| e.w * e.v.dot(&residual(e))).sum()),
        );
        // H_cd = ⟨v_c, v_d⟩ − g_cᵀ L⁻¹ g_d (g_c: curve c's right-hand side), through the node
        // system: each curve's right-hand side reduced onto the nodes and solved there.
        let mut h = nalgebra::DMatrix::zeros(k, k);
        let mut g = vec![[0.0; 3]; n];
        let mut reduced: Vec<Vec<(usize, [f64; 3])>> = Vec::with_capacity(k);
        let mut solved: Vec<Vec<[f64; 3]>> = Vec::with_capacity(k);
        for c in 0..k {
            add_rhs(&mut g, edges[start[c]..start[c + 1]].iter().copied());
            let mut nb: Vec<[f64; 3]> = g[..nodes].to_vec();
            let interior = f.reduce(&g, run_starts[c]..run_starts[c + 1], &mut nb);
            for e in own(c) {
                g[e.a] = [0.0; 3];
                g[e.b] = [0.0; 3];
            }
            h[(c, c)] = own(c).map(|e| e.w * e.v.norm_squared()).sum::<f64>() - interior;
            let mut y = nb.clone();
            f.solve_nodes(&mut y);
            // Curve c's reduced right-hand side lives on its own nodes.
            reduced.push(
                nb.into_iter()
                    .enumerate()
                    .filter(|(_, v)| v.iter().any(|&x| x != 0.0))
                    .collect::<Vec<_>>(),
            );
            solved.push(y);
        }
        let dot = |a: &[(usize, [f64; 3])], b: &[[f64; 3]]| -> f64 {
            a.iter()
                .map(|&(i, p)| p[0] * b[i][0] + p[1] * b[i][1] + p[2] * b[i][2])
                .sum()
        };
        for c in 0..k {
            for d in c..k {
                let v = dot(&reduced[c], &solved[d]);
                h[(c, d)] -= v;
                if d != c {
                    h[(d, c)] -= v;
                }
            }
        }
        Ok(ScaleForm {
            h,
            b,
            chi2: measured.chi2,
            loops: measured.loops,
        })
    }

    /// As [`solve`](Self::solve), with some tags free to slide along their curve (issue 34's
    /// joins): each of `slides`, `(curve position in curves, sample index of the tag)`, gets
    /// an unknown `σ`, the node lying at `σ` along the curve's tangent from the curve's
    /// sample there (the chain's point at the tag is `x_node − σ T`). Returns the positions
    /// (the node at its own unknown) and the `σ` of each slide, m: where the curve's loops
    /// put the node along it, to first order (one Gauss–Newton step of the tag's distance).
    ///
    /// The two edges at a sliding tag read `x_b − x_a − h t ± σ T`; `σ` is eliminated by its
    /// Schur complement (`#slides` extra solves with the same factor, a `#slides` square
    /// dense system), with a small ridge so that a tag no loop constrains stays put.
    pub fn solve_sliding(
        &mut self,
        curves: &[UniformCurve],
        slides: &[(usize, usize)],
    ) -> Result<(Positions, Vec<f64>), SolveError> {
        let (node_var, var_of, n) = unknowns(curves);
        let prepared = self.prepare(curves, &var_of)?;
        let nodes = node_var.len();
        let ridge = mean_weight(
            prepared.iter().flat_map(|p| p.w.iter().copied()),
            prepared.iter().map(|p| p.w.len()).sum(),
        );
        // Each run's ends (their unknowns), with its edges in series.
        let ends = |vars: &[usize], s: &Span| (s.start.map(|i| vars[i]), s.end.map(|i| vars[i]));
        // The node system: each run one edge of its series conductance, in the runs' order
        // (the loop test's node Laplacian to the bit: `closure::Kept::node_system`).
        let mut links = Vec::new();
        let mut free = 0;
        let mut node_b = vec![[0.0; 3]; nodes];
        for (p, vars) in prepared.iter().zip(&var_of) {
            for (s, series) in p.spans.iter().zip(&p.series) {
                match ends(vars, s) {
                    (Some(a), Some(b)) if a != b => {
                        links.push((a, b, series.conductance()));
                        let wv = series.v / series.r;
                        for d in 0..3 {
                            node_b[b][d] += wv[d];
                            node_b[a][d] -= wv[d];
                        }
                    }
                    (None, None) => free += 1,
                    _ => {}
                }
            }
        }
        let system = NodeSystem::new(nodes, &links, free, ridge, &mut self.pattern)?;
        system.solve(&mut node_b);
        let at_node: Vec<Vector3<f64>> = node_b.iter().map(|&v| Vector3::from(v)).collect();
        // Each curve's samples: its runs placed between their ends.
        let mut points: Vec<Vec<Vector3<f64>>> = prepared
            .iter()
            .zip(&var_of)
            .map(|(p, vars)| {
                let mut x = vec![Vector3::zeros(); vars.len()];
                for (i, &v) in vars.iter().enumerate().filter(|(_, &v)| v < nodes) {
                    x[i] = at_node[v];
                }
                for (s, series) in p.spans.iter().zip(&p.series) {
                    let (a, b) = ends(vars, s);
                    let ends = (a.map(|a| at_node[a]), b.map(|b| at_node[b]));
                    series.place(s, ends, &p.cum_r, &p.cum_v, &mut x);
                }
                x
            })
            .collect();
        let components = system.components();
        let (misfit, sigma) = if slides.is_empty() {
            let misfit = series_misfit(curves, &prepared, &var_of, &at_node, n, components);
            (misfit, Vec::new())
        } else {
            // The slides' corrections need solves of other right-hand sides than edge data:
            // the runs' blocks, kept with their curves (a run with no node's, whose ridge is
            // the network's gauge, found again).
            let runs: Vec<Run> = prepared
                .iter()
                .zip(&var_of)
                .flat_map(|(p, vars)| p.spans.iter().map(|s| Run::of(s, vars, &p.w)))
                .collect();
            let blocks = (prepared.iter().flat_map(|p| &p.blocks))
                .zip(&runs)
                .map(|(block, run)| match block {
                    Some(b) => Ok(Cow::Borrowed(b)),
                    None => {
                        Tridiagonal::of(run, KronReduced::run_ridge(run, ridge)).map(Cow::Owned)
                    }
                })
                .collect::<Result<Vec<_>, _>>()?;
            let f = KronReduced::with_blocks(n, nodes, &runs, blocks, ridge, &mut self.pattern)?;
            let mut x = vec![Vector3::zeros(); n];
            for (vars, p) in var_of.iter().zip(&points) {
                for (&v, &xi) in vars.iter().zip(p) {
                    x[v] = xi;
                }
            }
            let tangents: Vec<&[Vector3<f64>]> = prepared.iter().map(|p| &p.tangents[..]).collect();
            let sigma = slide(&f, &mut x, curves, &var_of, &tangents, slides);
            let edges = (prepared.iter().zip(&var_of).enumerate()).flat_map(|(ci, (p, vars))| {
                p.edges(vars).enumerate().map(move |(j, e)| ((ci, j), e))
            });
            let misfit = misfit(curves, edges, &x, &tangents, slides, &sigma, components);
            for (vars, p) in var_of.iter().zip(&mut points) {
                for (&v, xi) in vars.iter().zip(p.iter_mut()) {
                    *xi = x[v];
                }
            }
            (misfit, sigma)
        };
        let out_curves = curves
            .iter()
            .zip(&prepared)
            .zip(points)
            .map(|((c, p), points)| CurvePositions {
                index: c.index,
                kind: c.kind,
                points,
                normals: p.normals.clone(),
                tangents: p.tangents.clone(),
                across: Vec::new(),
                nodes: c.nodes.clone(),
                d: c.d.clone(),
                sigma_m: Vec::new(),
            })
            .collect();
        Ok((
            Positions {
                curves: out_curves,
                nodes: node_var.iter().map(|(&nd, &v)| (nd, at_node[v])).collect(),
                components,
                misfit,
            },
            sigma,
        ))
    }
}

impl PoissonSolver {
    /// Each curve's [`Prepared`]: the last solve's where the curve is the same, else found
    /// (`var_of`: each curve's unknowns). Only this solve's curves are kept.
    fn prepare(
        &mut self,
        curves: &[UniformCurve],
        var_of: &[Vec<usize>],
    ) -> Result<Vec<Arc<Prepared>>, SolveError> {
        let mut last = std::mem::take(&mut self.prepared);
        let mut out = Vec::with_capacity(curves.len());
        for (c, vars) in curves.iter().zip(var_of) {
            let mut p = last.remove(&c.index).unwrap_or_default();
            let changed = match Arc::get_mut(&mut p) {
                Some(m) if !m.q.is_empty() => m.refresh(c, vars)?,
                Some(m) => m.refill(c, vars).map(|()| true)?,
                None => {
                    let mut m = Prepared::default();
                    m.refill(c, vars)?;
                    p = Arc::new(m);
                    true
                }
            };
            self.prepared_count += usize::from(changed);
            out.push(p);
        }
        self.prepared = curves
            .iter()
            .zip(&out)
            .map(|(c, p)| (c.index, p.clone()))
            .collect();
        Ok(out)
    }
}

/// The unknowns: one per node (in index order), then one per other sample; `(node → unknown,
/// each curve's unknown per sample, #unknowns)`.
fn unknowns(curves: &[UniformCurve]) -> (BTreeMap<u32, usize>, Vec<Vec<usize>>, usize) {
    // Numbered in a hash map (looked up at every tag), returned in node order.
    let mut node_var: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for c in curves {
        for &(_, n) in &c.nodes {
            let k = node_var.len();
            node_var.entry(n).or_insert(k);
        }
    }
    let mut var_of: Vec<Vec<usize>> = Vec::with_capacity(curves.len());
    let mut n = node_var.len();
    for c in curves {
        let mut v = vec![usize::MAX; c.q.len()];
        for &(i, nd) in &c.nodes {
            v[i] = node_var[&nd];
        }
        for x in v.iter_mut().filter(|x| **x == usize::MAX) {
            *x = n;
            n += 1;
        }
        var_of.push(v);
    }
    (node_var.into_iter().collect(), var_of, n)
}

/// The data of the edge from sample `j` of `c` to the next: `h` times the mean of the frames'
/// `axis` at its two ends (the midpoint rule; into a kink, the frame arriving there), and `h`.
fn edge_data(c: &UniformCurve, j: usize, axis: &Vector3<f64>) -> (Vector3<f64>, f64) {
    let h = c.edge_h(j);
    let arriving = if c.kinked(j + 1) {
        c.arriving(j + 1)
    } else {
        c.q[j + 1]
    };
    ((c.q[j] * axis + arriving * axis) * (0.5 * h), h)
}

/// Each sample's frame's `axis` (`Vector3::x()`: the tangents), curve by curve.
fn axes(curves: &[UniformCurve], axis: &Vector3<f64>) -> Vec<Vec<Vector3<f64>>> {
    curves
        .iter()
        .map(|c| c.q.iter().map(|q| q * axis).collect())
        .collect()
}

/// Every edge of every curve, in order along each, with its data from the frames' `axis`
/// (`Vector3::x()`: the tangents), given at each sample (`along`, [`axes`]) and the
/// (curve position, sample) of each edge's start. The same data as [`edge_data`]'s.
fn edges(
    curves: &[UniformCurve],
    var_of: &[Vec<usize>],
    axis: &Vector3<f64>,
    along: &[Vec<Vector3<f64>>],
) -> (Vec<Edge>, Vec<(usize, usize)>) {
    let total: usize = curves.iter().map(|c| c.q.len().saturating_sub(1)).sum();
    let mut edges = Vec::with_capacity(total);
    let mut edge_at = Vec::with_capacity(total);
    for (ci, c) in curves.iter().enumerate() {
        let (mut w, mut v) = (Vec::new(), Vec::new());
        curve_edges(c, axis, &along[ci], &mut w, &mut v);
        for (j, (w, v)) in w.into_iter().zip(v).enumerate() {
            edges.push(Edge {
                a: var_of[ci][j],
                b: var_of[ci][j + 1],
                w,
                v,
            });
            edge_at.push((ci, j));
        }
    }
    (edges, edge_at)
}

/// The edges of `c` in order (edge `j`: from sample `j` to `j + 1`): their weights `w` and
/// their data `v` from the frames' `axis`, given at each sample (`along`). The same data as
/// [`edge_data`]'s.
fn curve_edges(
    c: &UniformCurve,
    axis: &Vector3<f64>,
    along: &[Vector3<f64>],
    w: &mut Vec<f64>,
    v: &mut Vec<Vector3<f64>>,
) {
    w.clear();
    v.clear();
    for (j, h) in c.edge_steps().enumerate() {
        let arriving = if c.kinked(j + 1) {
            c.arriving(j + 1) * axis
        } else {
            along[j + 1]
        };
        v.push((along[j] + arriving) * (0.5 * h));
        // Residual (x_b − x_a)/h − t, squared: weight 1/h² on (x_b − x_a − h t).
        w.push(1.0 / (h * h));
    }
}

/// The runs of samples between tags of every curve, for the normal matrix's Kron reduction
/// onto the `nodes` ([`KronReduced`]): the edges' least squares is a weighted graph Laplacian
/// (`w` the weights of the edges in the order [`edges`] gives them).
fn runs<'w>(
    curves: &[UniformCurve],
    var_of: &[Vec<usize>],
    w: &'w [f64],
    nodes: usize,
) -> Vec<Run<'w>> {
    runs_by_curve(curves, var_of, w, nodes).0
}

/// As [`runs`], with where each curve's runs start in them (#curves + 1 offsets).
fn runs_by_curve<'w>(
    curves: &[UniformCurve],
    var_of: &[Vec<usize>],
    w: &'w [f64],
    nodes: usize,
) -> (Vec<Run<'w>>, Vec<usize>) {
    let mut out = Vec::new();
    let mut starts = vec![0];
    let mut k = 0;
    for (c, vars) in curves.iter().zip(var_of) {
        let m = c.q.len().saturating_sub(1);
        out.extend(Run::along(vars, &w[k..k + m], nodes));
        starts.push(out.len());
        k += m;
    }
    (out, starts)
}

/// The weight of the gauge on the lowest unknown of each connected component: the edges' mean
/// weight, at least 1.
fn ridge(edges: &[Edge]) -> f64 {
    mean_weight(edges.iter().map(|e| e.w), edges.len())
}

/// [`ridge`] of the edges of `curves`, without their data (the loop-closure test's node
/// Laplacian, shared with Poisson's in a live update: `closure::Kept::node_system`).
pub(crate) fn gauge_weight(curves: &[UniformCurve]) -> f64 {
    let weights = curves
        .iter()
        .flat_map(|c| c.edge_steps().map(|h| 1.0 / (h * h)));
    let count = curves.iter().map(|c| c.q.len().saturating_sub(1)).sum();
    mean_weight(weights, count)
}

/// The mean of `count` edge weights, at least 1.
fn mean_weight(weights: impl Iterator<Item = f64>, count: usize) -> f64 {
    (weights.sum::<f64>() / count.max(1) as f64).max(1.0)
}

/// Adds the edges' data to the right-hand side (#unknowns by 3).
fn add_rhs(rhs: &mut [[f64; 3]], edges: impl IntoIterator<Item = Edge>) {
    for e in edges.into_iter().filter(|e| e.a != e.b) {
        for (d, v) in e.v.iter().enumerate() {
            rhs[e.b][d] += e.w * v;
            rhs[e.a][d] -= e.w * v;
        }
    }
}

/// The misfit of the solution without slides, run by run in closed form ([`Series::misfit`]:
/// a run's edges' residuals sum to `W |x_b − x_a − V|²`), each run's in the segment its
/// edges are in (a run at a curve's end, which fits exactly, in none); `at_node` the nodes'
/// positions, `n` the unknowns.
fn series_misfit(
    curves: &[UniformCurve],
    prepared: &[Arc<Prepared>],
    var_of: &[Vec<usize>],
    at_node: &[Vector3<f64>],
    n: usize,
    components: usize,
) -> Misfit {
    let mut chi2 = 0.0;
    let (mut used, mut h_sum) = (0usize, 0.0);
    let mut chi2_segments = Vec::with_capacity(curves.len());
    for ((c, p), vars) in curves.iter().zip(prepared).zip(var_of) {
        let mut per = vec![0.0; c.nodes.len().saturating_sub(1)];
        used += p.used;
        h_sum += p.h_sum;
        // The segment of each run's first edge, as along the edges: the last tag at or
        // before it (the first segment before any).
        let mut seg = 0;
        for (s, series) in p.spans.iter().zip(&p.series) {
            let (Some(a), Some(b)) = (s.start, s.end) else {
                continue;
            };
            while c.nodes.get(seg + 1).is_some_and(|&(i, _)| i <= a) {
                seg += 1;
            }
            let r = series.misfit(&at_node[vars[a]], &at_node[vars[b]]);
            chi2 += r;
            if let Some(x) = per.get_mut(seg) {
                *x += r;
            }
        }
        chi2_segments.push(per);
    }
    Misfit {
        chi2,
        chi2_segments,
        loops: (used + components).saturating_sub(n),
        mean_h: if used == 0 { 0.0 } else { h_sum / used as f64 },
    }
}

/// The residual of the solution `x` (after the slides: an edge at a sliding tag reads
/// `x_b − x_a − h t ± σ T`); `edges` each edge with its (curve position, sample of its start),
/// curve by curve in order along each.
fn misfit(
    curves: &[UniformCurve],
    edges: impl Iterator<Item = ((usize, usize), Edge)>,
    x: &[Vector3<f64>],
    tangents: &[&[Vector3<f64>]],
    slides: &[(usize, usize)],
    sigma: &[f64],
    components: usize,
) -> Misfit {
    let slid: std::collections::HashMap<(usize, usize), f64> =
        slides.iter().zip(sigma).map(|(&at, &s)| (at, s)).collect();
    let mut chi2 = 0.0;
    let mut chi2_segments: Vec<Vec<f64>> = curves
        .iter()
        .map(|c| vec![0.0; c.nodes.len().saturating_sub(1)])
        .collect();
    let mut used = 0usize;
    let mut h_sum = 0.0;
    // The segment of each edge: the edges come curve by curve, in order along each.
    let (mut curve, mut seg) = (usize::MAX, 0);
    for ((ci, j), e) in edges {
        if ci != curve {
            (curve, seg) = (ci, 0);
        }
        while curves[ci].nodes.get(seg + 1).is_some_and(|&(i, _)| i <= j) {
            seg += 1;
        }
        if e.a == e.b {
            continue;
        }
        used += 1;
        h_sum += e.w.sqrt().recip();
        let mut r = x[e.b] - x[e.a] - e.v;
        // Into a sliding tag (sign −1) and out of one (sign +1).
        if !slid.is_empty() {
            if let Some(s) = slid.get(&(ci, j + 1)) {
                r -= tangents[ci][j + 1] * *s;
            }
            if let Some(s) = slid.get(&(ci, j)) {
                r += tangents[ci][j] * *s;
            }
        }
        chi2 += e.w * r.norm_squared();
        if let Some(x) = chi2_segments[ci].get_mut(seg) {
            *x += e.w * r.norm_squared();
        }
    }
    Misfit {
        chi2,
        chi2_segments,
        loops: (used + components).saturating_sub(x.len()),
        mean_h: if used == 0 { 0.0 } else { h_sum / used as f64 },
    }
}

/// The slides' `σ` by their Schur complement, and `x` (the solution without them, #unknowns
/// by 3) corrected for them: `x ← x₀ − L⁻¹ C σ` with `(D − Cᵀ L⁻¹ C) σ = g − Cᵀ x₀`, where
/// `C` (#unknowns by #slides, 3-vectors) couples each slide to the unknowns of its two edges,
/// `D` its own weight and `g` its edges' data. A slide whose edges are missing (a tag at a
/// curve's end) is 0.
fn slide(
    f: &KronReduced,
    x: &mut [Vector3<f64>],
    curves: &[UniformCurve],
    var_of: &[Vec<usize>],
    tangents: &[&[Vector3<f64>]],
    slides: &[(usize, usize)],
) -> Vec<f64> {
    let m = slides.len();
    if m == 0 {
        return Vec::new();
    }
    // Per slide: its coupling (unknown, 3-vector), its own weight and its data.
    let mut coupling: Vec<Vec<(usize, Vector3<f64>)>> = vec![Vec::new(); m];
    let mut dd = nalgebra::DMatrix::<f64>::zeros(m, m);
    let mut g = nalgebra::DVector::<f64>::zeros(m);
    // Edges at the slides: (slide, sign, edge's a, b, weight, data).
    let mut at: Vec<(usize, f64, usize, usize, f64, Vector3<f64>)> = Vec::new();
    for (k, &(ci, i)) in slides.iter().enumerate() {
        let Some(c) = curves.get(ci) else { continue };
        if i >= c.q.len() {
            continue;
        }
        for (j, sign) in [(i.wrapping_sub(1), -1.0), (i, 1.0)] {
            if j >= c.q.len().saturating_sub(1) {
                continue;
            }
            let (a, b) = (var_of[ci][j], var_of[ci][j + 1]);
            if a == b {
                continue;
            }
            let (v, h) = edge_data(c, j, &Vector3::x());
            at.push((k, sign, a, b, 1.0 / (h * h), v));
        }
    }
    let tangent = |k: usize| tangents[slides[k].0][slides[k].1];
    for &(k, sign, a, b, w, v) in &at {
        let t = tangent(k);
        coupling[k].push((b, t * (w * sign)));
        coupling[k].push((a, t * (-w * sign)));
        g[k] += w * sign * t.dot(&v);
        // Other slides on the same edge (two joins one edge apart) couple with this one.
        for &(l, sl, al, bl, _, _) in &at {
            if al == a && bl == b {
                dd[(k, l)] += w * sign * sl * t.dot(&tangent(l));
            }
        }
    }
    // L⁻¹ C, one solve per slide.
    let mut y: Vec<Vec<[f64; 3]>> = Vec::with_capacity(m);
    for ck in &coupling {
        let mut col = vec![[0.0; 3]; x.len()];
        for (v, c) in ck {
            for d in 0..3 {
                col[*v][d] += c[d];
            }
        }
        f.solve(&mut col);
        y.push(col);
    }
    let mut s = dd.clone();
    for k in 0..m {
        g[k] -= coupling[k].iter().map(|(v, c)| c.dot(&x[*v])).sum::<f64>();
        for l in 0..m {
            let cy: f64 = coupling[k]
                .iter()
                .map(|(v, c)| c.dot(&Vector3::from(y[l][*v])))
                .sum();
            s[(k, l)] -= cy;
        }
        s[(k, k)] += SLIDE_RIDGE * dd[(k, k)].max(1.0);
    }
    let Some(sigma) = s.cholesky().map(|ch| ch.solve(&g)) else {
        return vec![0.0; m];
    };
    if sigma.iter().any(|v| !v.is_finite()) {
        return vec![0.0; m];
    }
    for (k, yk) in y.iter().enumerate() {
        for (xi, yi) in x.iter_mut().zip(yk) {
            *xi -= Vector3::from(*yi) * sigma[k];
        }
    }
    sigma.iter().copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    /// A circle of radius r in the xy plane as a closed curve through nodes 0 and 1.
    fn circle(r: f64, n: usize, index: usize, nodes: (u32, u32)) -> UniformCurve {
        let len = std::f64::consts::TAU * r;
        let h = len / n as f64;
        let d: Vec<f64> = (0..=n).map(|j| j as f64 * h).collect();
        let q = d
            .iter()
            .map(|&s| {
                let th = s / r;
                // T = (−sin, cos, 0), N = (cos, sin, 0) (outward), B = N × T = z.
                UnitQuaternion::from_axis_angle(
                    &nalgebra::Vector3::z_axis(),
                    th + std::f64::consts::FRAC_PI_2,
                ) * UnitQuaternion::from_axis_angle(
                    &nalgebra::Vector3::x_axis(),
                    -std::f64::consts::FRAC_PI_2,
                )
            })
            .collect();
        UniformCurve {
            index,
            kind: crate::curve::CurveKind::Interior,
            d,
            q,
            nodes: vec![(0, nodes.0), (n / 2, nodes.1), (n, nodes.0)],
            h: vec![h, h],
            w: vec![1.0; n + 1],
            outliers: 0,
            kinks: Vec::new(),
        }
    }

    #[test]
    fn closed_circle_is_recovered_and_the_pattern_reused() {
        let c = circle(1.0, 400, 0, (0, 1));
        let t = c.q[0] * Vector3::x();
        assert!((t - Vector3::y()).norm() < 1e-12, "frame convention: {t}");
        let mut s = PoissonSolver::new();
        let p = s.solve(std::slice::from_ref(&c)).unwrap();
        assert_eq!(p.components, 1);
        let pts = &p.curves[0].points;
        let centre = pts[..400].iter().sum::<Vector3<f64>>() / 400.0;
        for q in pts {
            let r = (q - centre).norm();
            assert!((r - 1.0).abs() < 1e-4, "radius {r}");
        }
        // Same topology again: the symbolic factorisation is reused.
        s.solve(&[c]).unwrap();
        assert_eq!(s.symbolic_count(), 1);
    }

    /// The scale form is the misfit of the curves scaled and solved again, and a scale common
    /// to every curve scales the misfit (`H 1 = b`).
    #[test]
    fn the_scale_form_is_the_misfit_of_the_scaled_curves() {
        let mut curves = vec![
            circle(1.0, 200, 0, (0, 1)),
            circle(0.9, 180, 1, (0, 1)),
            circle(1.1, 240, 2, (0, 1)),
        ];
        // Frames turned a little along each curve, differently: the loops misfit.
        for (k, c) in curves.iter_mut().enumerate() {
            for (j, q) in c.q.iter_mut().enumerate() {
                let a = 0.05 * ((j as f64) * 0.05 + k as f64).sin();
                *q *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
            }
        }
        let mut solver = PoissonSolver::new();
        let form = solver.scale_form(&curves).unwrap();
        let chi2 = solver.solve(&curves).unwrap().misfit.chi2;
        assert!(chi2 > 1e-6, "the loops misfit: {chi2}");
        assert!(
            (form.chi2 - chi2).abs() <= 1e-9 * chi2,
            "{} {chi2}",
            form.chi2
        );
        let ones = nalgebra::DVector::from_element(3, 1.0);
        let h1 = &form.h * &ones;
        assert!((h1 - &form.b).norm() <= 1e-8 * form.b.norm(), "H 1 = b");
        assert!((form.h.clone() - form.h.transpose()).norm() <= 1e-9 * form.h.norm());
        // The least squares solved again with each curve's edge data scaled (the weights
        // as they were: the form's model).
        let (node_var, var_of, n) = unknowns(&curves);
        let x = Vector3::x();
        let (edges0, edge_at) = edges(&curves, &var_of, &x, &axes(&curves, &x));
        // The edges from the tangents along are each edge's data, to the bit.
        for (e, &(ci, j)) in edges0.iter().zip(&edge_at) {
            let (v, h) = edge_data(&curves[ci], j, &x);
            assert_eq!((e.v, e.w.to_bits()), (v, (1.0 / (h * h)).to_bits()));
        }
        let w: Vec<f64> = edges0.iter().map(|e| e.w).collect();
        let runs = runs(&curves, &var_of, &w, node_var.len());
        let mut cache = CachedPattern::default();
        let f = KronReduced::new(n, node_var.len(), &runs, ridge(&edges0), &mut cache).unwrap();
        for s in [[0.01, -0.02, 0.005], [-0.03, 0.0, 0.02]] {
            let s = nalgebra::DVector::from_row_slice(&s);
            let scaled: Vec<Edge> = edges0
                .iter()
                .zip(&edge_at)
                .map(|(e, &(ci, _))| Edge {
                    v: e.v * (1.0 + s[ci]),
                    ..*e
                })
                .collect();
            let mut x = vec![[0.0; 3]; n];
            add_rhs(&mut x, scaled.iter().copied());
            f.solve(&mut x);
            let direct: f64 = scaled
                .iter()
                .filter(|e| e.a != e.b)
                .map(|e| {
                    e.w * (e.v - (Vector3::from(x[e.b]) - Vector3::from(x[e.a]))).norm_squared()
                })
                .sum();
            let predicted =
                form.chi2 + 2.0 * form.b.dot(&s) + (s.transpose() * &form.h * &s)[(0, 0)];
            assert!(
                (predicted - direct).abs() <= 1e-8 * direct,
                "{predicted} against {direct}"
            );
        }
    }

    /// Issue 51: a curve solved again the same (its frames, steps, tags and kinks) is not
    /// prepared again, and the positions are a fresh solver's to the bit; a curve changed in
    /// one frame is prepared again.
    #[test]
    fn issue_51_a_curve_the_same_is_kept_and_solves_to_the_same_bits() {
        let mut curves = vec![
            circle(1.0, 200, 0, (0, 1)),
            circle(0.9, 180, 1, (0, 1)),
            circle(1.1, 240, 2, (0, 1)),
        ];
        let arriving = curves[2].q[119];
        curves[2].kinks.push((120, arriving));
        let bits = |p: &Positions| -> Vec<u64> {
            let points = p
                .curves
                .iter()
                .flat_map(|c| c.points.iter().chain(&c.tangents));
            (points.flat_map(|v| v.iter().map(|x| x.to_bits())))
                .chain([p.misfit.chi2.to_bits()])
                .collect()
        };
        let mut kept = PoissonSolver::new();
        kept.solve(&curves[..2]).unwrap();
        assert_eq!(kept.prepared_count(), 2);
        for turn in [0.0, 0.01] {
            // Curve 1 turned by `turn` at one sample (or not at all), then solved by the
            // solver that kept the three curves' and by a fresh one.
            let mut now = curves.clone();
            now[1].q[50] *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn);
            let before = kept.prepared_count();
            let got = kept.solve(&now).unwrap();
            let fresh = PoissonSolver::new().solve(&now).unwrap();
            assert_eq!(bits(&got), bits(&fresh), "turn {turn}");
            assert_eq!(got.nodes, fresh.nodes);
            // Curve 2 is new at the first solve; curve 1 is changed at the second.
            assert_eq!(kept.prepared_count() - before, 1, "turn {turn}");
        }
        // Frames turned in place (a live update's local regression) at a curve's ends, at a
        // tag, and at both sides of a kink: found again there alone, to the same bits.
        let mut now = curves.clone();
        kept.solve(&now).unwrap();
        for (ci, js) in [
            (2usize, vec![0, 119, 120, 240]),
            (0, vec![99, 100, 101, 200]),
        ] {
            for j in js {
                now[ci].q[j] *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.02);
            }
            let before = kept.prepared_count();
            let got = kept.solve(&now).unwrap();
            let fresh = PoissonSolver::new().solve(&now).unwrap();
            assert_eq!(bits(&got), bits(&fresh), "curve {ci}");
            assert_eq!(got.nodes, fresh.nodes);
            assert_eq!(kept.prepared_count() - before, 1, "curve {ci}");
        }
        // Curve 0's slides (a join pass) read the kept tangents.
        let (got, sigma) = kept.solve_sliding(&curves, &[(0, 100)]).unwrap();
        let (fresh, fresh_sigma) = PoissonSolver::new()
            .solve_sliding(&curves, &[(0, 100)])
            .unwrap();
        assert_eq!(bits(&got), bits(&fresh));
        assert_eq!(sigma[0].to_bits(), fresh_sigma[0].to_bits());
    }

    /// Issue 51: the runs solved in series in closed form ([`Series`]) are the Kron-reduced
    /// Laplacian's solution, and their misfit the edges' residuals summed, on a network of
    /// every kind of run: between two nodes, back to the node it left, between tags on
    /// adjacent samples (of two nodes, and of one), from a curve's end to its one tag, and a
    /// curve without tags (its own gauge); frames turned so that the loops misfit.
    #[test]
    fn issue_51_the_runs_in_series_solve_as_the_reduced_laplacian() {
        let mut curves = vec![
            circle(1.0, 200, 0, (0, 1)),
            circle(0.9, 180, 1, (0, 1)),
            circle(1.1, 240, 2, (0, 1)),
            circle(0.7, 90, 3, (0, 0)),
            circle(0.5, 60, 4, (0, 0)),
            circle(0.6, 80, 5, (0, 0)),
        ];
        // Curve 2 kinked; curve 3 through node 2 then 3 on adjacent samples, and twice
        // through node 2 on adjacent samples; curve 4 with one tag (node 1) mid-way; curve 5
        // with none.
        let arriving = curves[2].q[119];
        curves[2].kinks.push((120, arriving));
        curves[3].nodes = vec![(0, 0), (30, 2), (31, 3), (60, 2), (61, 2), (90, 0)];
        curves[3].h = vec![curves[3].h[0]; 5];
        curves[4].nodes = vec![(25, 1)];
        curves[4].h.truncate(1);
        curves[5].nodes.clear();
        curves[5].h.truncate(1);
        for (k, c) in curves.iter_mut().enumerate() {
            for (j, q) in c.q.iter_mut().enumerate() {
                let a = 0.05 * ((j as f64) * 0.05 + k as f64).sin();
                *q *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
            }
        }
        let got = PoissonSolver::new().solve(&curves).unwrap();
        // The reduced Laplacian's solve of the edges' data, and their residuals.
        let (node_var, var_of, n) = unknowns(&curves);
        let x = Vector3::x();
        let (edges0, edge_at) = edges(&curves, &var_of, &x, &axes(&curves, &x));
        let w: Vec<f64> = edges0.iter().map(|e| e.w).collect();
        let runs = runs(&curves, &var_of, &w, node_var.len());
        let mut cache = CachedPattern::default();
        let f = KronReduced::new(n, node_var.len(), &runs, ridge(&edges0), &mut cache).unwrap();
        let mut rhs = vec![[0.0; 3]; n];
        add_rhs(&mut rhs, edges0.iter().copied());
        f.solve(&mut rhs);
        let want: Vec<Vector3<f64>> = rhs.into_iter().map(Vector3::from).collect();
        let pairs = edge_at.iter().copied().zip(edges0.iter().copied());
        let want_misfit = misfit(&curves, pairs, &want, &[], &[], &[], f.components());
        assert_eq!(got.components, 2);
        assert_eq!(got.components, f.components());
        let mut worst = 0.0f64;
        for (c, vars) in got.curves.iter().zip(&var_of) {
            for (p, &v) in c.points.iter().zip(vars) {
                worst = worst.max((p - want[v]).norm());
            }
        }
        for (nd, v) in &node_var {
            worst = worst.max((got.nodes[nd] - want[*v]).norm());
        }
        assert!(worst < 1e-12, "positions {worst:e} m apart");
        let (m, w) = (&got.misfit, &want_misfit);
        assert!(w.chi2 > 1e-6, "the loops misfit: {}", w.chi2);
        assert!(
            (m.chi2 - w.chi2).abs() <= 1e-9 * w.chi2,
            "{} {}",
            m.chi2,
            w.chi2
        );
        assert_eq!(
            (m.loops, m.chi2_segments.len()),
            (w.loops, w.chi2_segments.len())
        );
        for (a, b) in m.chi2_segments.iter().zip(&w.chi2_segments) {
            assert_eq!(a.len(), b.len());
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= 1e-9 * w.chi2, "{a:?} {b:?}");
            }
        }
        assert!((m.mean_h - w.mean_h).abs() <= 1e-12 * w.mean_h);
    }

    #[test]
    fn disconnected_parts_each_get_a_gauge() {
        let a = circle(1.0, 100, 0, (0, 1));
        let b = circle(0.5, 100, 1, (2, 3));
        let p = PoissonSolver::new().solve(&[a, b]).unwrap();
        assert_eq!(p.components, 2);
        assert!(p.nodes.values().all(|v| v.iter().all(|x| x.is_finite())));
    }
}
