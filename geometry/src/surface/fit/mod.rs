//! The surface of a curve network with normal control (Stanko et al. 2016, §3.3–3.4):
//! cycles → one planar triangulation per cycle → biharmonic propagation of positions and of
//! normals (`L²V = 0`, `L²N = 0` with the network's samples as hard constraints) → the mean
//! curvature guide of formula (1) → positions minimising `‖LV − 2H‖²`.
//!
//! ## Conventions
//! - `L = M⁻¹ Lc` with `Lc` the cotangent matrix ([`super::cotmatrix`], libigl's sign, rows
//!   sum to 0) and `M` the mixed Voronoi areas, both computed from each patch's *planar*
//!   triangulation (as the paper does; its stated weakness), summed over the patches.
//! - Both energies are discretised with the vertex areas, `Σ_k M_k |(LV)_k − t_k|²`, whose
//!   normal matrix is `Q = Lcᵀ M⁻¹ Lc` (`#V by #V`, symmetric positive semi-definite): the
//!   biharmonic systems and the final fit share `Q`, so one symbolic and one numeric sparse
//!   Cholesky factorisation of its free block serve all three solves. Rows of vertices on
//!   a hole's rim (an open ring) are left out of the energy.
//! - The guide `t_k` is the mean-curvature vector of formula (1) ([`mean_curvature_vectors`],
//!   with the edge-midpoint normal, see there), computed on the propagated positions with the
//!   propagated normals, projected onto the propagated normal (so its sign survives: the
//!   paper's `h(v)·n*` takes the norm, which loses concave regions).
//!
//! - The positional constraints are hard, or soft with a weight ω ([`SurfaceParams::soft`]:
//!   the whole system `Q + ω'D` is then factorised, once per pass, for every solve).
//!
//! Every vertex on the network is a sample of it (shared by the patches on both sides), so
//! the mesh is watertight along the curves.
//!
//! ## Layout, in the order of the steps
//! - `assembly.rs`: the target edge, the constrained vertices (with copies along creases)
//!   and every cycle's patch tessellated, or kept from the last surface;
//! - `energy.rs`: the energy's rows, the weights summed from the pieces (planar, then the
//!   surface's: the reweighting), the normal matrix `Q` and the data weights;
//! - `system.rs`: one pass's factorised system, the propagation and the fit (and the
//!   triharmonic comparison method);
//! - `curvature.rs`: the mean-curvature guide of formula (1), the normal-control target;
//! - `output.rs`: the output mesh;
//! - this file: the settings, the results and the passes that tie the steps together.

use super::cycles::{Cycles, NetworkSegments};
use super::faces::{Faces, Weights};
use super::SurfaceProblem;
use crate::sparse_llt::{CachedPattern, SolveError};
use assembly::Assembly;
use assembly::{tessellation, Tessellation};
use curvature::normal_control_target;
use energy::{energy_rows, normal_matrix, sum_weights, surface_weights};
use nalgebra::Vector3;
use output::output;
use std::sync::Arc;
use system::{triharmonic, weld, System};

mod assembly;
mod curvature;
mod energy;
mod output;
mod system;

pub use assembly::{
    budget_edge, default_edge, BOUNDARY_STEP, EDGE_PER_DIAGONAL, MAX_VERTICES, WORKERS,
};
pub use curvature::mean_curvature_vectors;

/// Settings of the surfacer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceParams {
    /// Target edge length inside the patches, m. `None`: [`default_edge`], lengthened if
    /// needed so that the surface has about `max_vertices` vertices at most.
    pub edge: Option<f64>,
    /// Vertex budget of the default edge (memory and time are linear in it; a given `edge`
    /// is not limited). Default [`MAX_VERTICES`].
    pub max_vertices: usize,
    /// What to solve for.
    pub method: Method,
    /// Passes that recompute the cotangent weights and areas from the surface of the previous
    /// pass (the paper's weights come from the planar triangulations, its stated weakness):
    /// the normals are propagated again, the guide recomputed on the previous surface and the
    /// fit solved again. Default 1: on the unit sphere's cube network it takes the mean
    /// distance from 0.019 to 0.0002 (`cargo run --release -p sfs-geometry --example surface_table`); more
    /// passes measured worse there.
    pub reweight: usize,
    /// The positional constraints on the network's samples: `None` hard (they are
    /// interpolated exactly, for exact input), `Some(ω)` soft (the paper's §4.5 for noisy
    /// scans: `+ ω' Σ |v_s − v_s*|²`, with `ω' = ω ·` the mean diagonal of the normal matrix
    /// over the constrained vertices, so that ω is dimensionless). Soft, the propagations are
    /// soft too (the normals' data term has the same weight), so that one factorisation per
    /// pass serves all solves; the curves keep their measured normals for the guide.
    pub soft: Option<f64>,
    /// The weight of the guide curves' samples (curves of kind guide: approximated, not
    /// interpolated), relative as `soft`'s: `+ ω_g' Σ |v_g − v_g*|²` over their samples
    /// between nodes (and likewise for their normals); their nodes, shared with the curves
    /// they cross, are held as every node is. Default [`GUIDE_WEIGHT`].
    pub guide_weight: f64,
    /// Which faces of the previous surface a [`Surfacer`] reuses (issue 19, [`super::faces`]),
    /// in target edges: `0` (default) only faces whose boundary is bit for bit the same (the
    /// surface is then the one a run from scratch gives); `τ > 0` also faces whose boundary
    /// samples moved less than `τ` edges since they were built, the edge and the rims'
    /// samples held while they can be, and the surface is made in one pass, the kept faces
    /// weighted as in the last surface (reweighted already), the others from their planar
    /// tessellation: *provisional* ([`Surfaced::provisional`]), for a quick look that an exact
    /// run settles later. `f64::INFINITY`: every face whose cycle is unchanged (a monitored
    /// structure, whose cycles never change: from the second surface on, the same system).
    pub reuse_tolerance: f64,
}

/// Default [`SurfaceParams::guide_weight`]: a third of the scans' [`SurfaceParams::soft`]
/// (0.3). On the unit sphere's three circles with one a guide rippled ±5 mm off the sphere
/// (a 16 cm wave) the surface takes about half of the ripple (1.7 mm mean from the guide);
/// a guide's errors of longer wavelength it follows, as the form it gives (test
/// `issue_18_a_guide_curve_is_approximated_within_its_own_error`).
pub const GUIDE_WEIGHT: f64 = 0.1;

impl Default for SurfaceParams {
    fn default() -> Self {
        SurfaceParams {
            edge: None,
            max_vertices: MAX_VERTICES,
            method: Method::NormalControl,
            reweight: 1,
            soft: None,
            guide_weight: GUIDE_WEIGHT,
            reuse_tolerance: 0.0,
        }
    }
}

/// The surfaces the paper compares (its Table 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// `L²V = 0`, positions constrained only.
    Biharmonic,
    /// `L³V = 0`, positions constrained only.
    Triharmonic,
    /// The paper's method: propagated normals and the mean-curvature guide.
    NormalControl,
}

/// A surface and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Surfaced {
    /// `#V` positions: the first `constrained` are the network's samples.
    pub positions: Vec<Vector3<f64>>,
    /// `#V` unit normals of the final surface (area-weighted face normals).
    pub normals: Vec<Vector3<f64>>,
    /// `#V` propagated normals `N*` (unit).
    pub propagated: Vec<Vector3<f64>>,
    /// `#F` triangles, counter-clockwise seen from the normals' side.
    pub triangles: Vec<[u32; 3]>,
    pub constrained: usize,
    /// `#V`: the vertex each one is a copy of (itself for most). The surface is cut along
    /// its creases, each side with its own vertices ([`creases`](super::creases)); mapping every vertex to
    /// its primary welds it whole again (same positions).
    pub primary: Vec<usize>,
    /// Nodes where three or more creases meet, and where one ends inside a face.
    pub corners: Vec<u32>,
    pub darts: Vec<u32>,
    /// How far the surface passes from each guide curve.
    pub guides: Vec<GuideFit>,
    pub cycles: Cycles,
    /// Patches that could not be tessellated (with the reason, naming the nodes), and any
    /// other problem: each also in `problems`.
    pub skipped: usize,
    pub problems: Vec<SurfaceProblem>,
    /// Faces whose tessellation was kept from the previous surface ([`super::faces`]).
    pub faces_kept: usize,
    /// One pass from the weights of the previous surface ([`SurfaceParams::reuse_tolerance`]
    /// above 0): not the surface a run from scratch gives, which a later exact run settles.
    pub provisional: bool,
}

/// What the surfacer did, for `report.json`.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SurfaceReport {
    pub patches: usize,
    pub holes: usize,
    /// Faces that failed a check of the cell complex, and patches that could not be
    /// tessellated (each explained in `problems`).
    pub rejected: usize,
    pub skipped: usize,
    /// `V − E + F` of the network's cell complex (2 for a sphere-like network).
    pub euler: i64,
    /// Nodes where three or more creases meet (corners) and where one ends (darts).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
    pub corners: Vec<u32>,
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
    pub darts: Vec<u32>,
    /// How far the surface passes from each guide curve.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Vec::is_empty"))]
    pub guides: Vec<GuideFit>,
    pub vertices: usize,
    pub constrained: usize,
    pub triangles: usize,
    /// Serialised as their texts.
    #[cfg_attr(feature = "serde", serde(serialize_with = "crate::serialize_texts"))]
    pub problems: Vec<SurfaceProblem>,
    /// Faces whose tessellation was kept from the previous surface.
    pub faces_kept: usize,
    /// A provisional surface (see [`Surfaced::provisional`]).
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "std::ops::Not::not"))]
    pub provisional: bool,
    pub time_ms: f64,
}

impl Surfaced {
    /// The report of this surface, with the time it took.
    pub fn report(&self, time_ms: f64) -> SurfaceReport {
        SurfaceReport {
            patches: self.cycles.patches.len() - self.skipped,
            holes: self.cycles.outer.len(),
            rejected: self.cycles.rejected.len(),
            skipped: self.skipped,
            euler: self.cycles.euler,
            corners: self.corners.clone(),
            darts: self.darts.clone(),
            guides: self.guides.clone(),
            vertices: self.positions.len(),
            constrained: self.constrained,
            triangles: self.triangles.len(),
            problems: self.problems.clone(),
            faces_kept: self.faces_kept,
            provisional: self.provisional,
            time_ms,
        }
    }

    /// The output mesh.
    pub fn mesh(&self) -> super::SurfaceMesh {
        super::SurfaceMesh {
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            triangles: self.triangles.clone(),
        }
    }
}

/// How far the surface passes from a guide curve: at each of its samples between nodes, the
/// distance from the sample to the surface's vertex there (the surface passes at least that
/// near), m.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct GuideFit {
    pub curve: usize,
    pub samples: usize,
    pub mean_m: f64,
    pub max_m: f64,
}

/// Why there is no surface at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    #[error("no cycle of the network could be surfaced{}", if .0.is_empty() { String::new() } else { format!(": {}", .0.iter().map(|p| p.to_string()).collect::<Vec<_>>().join("; ")) })]
    NoPatch(Vec<SurfaceProblem>),
    #[error("the surface system cannot be solved: {0}")]
    Solve(#[from] SolveError),
}

/// Surfaces the network (see the module docs). Patches that fail are reported and left open.
pub fn surface(net: &NetworkSegments, p: &SurfaceParams) -> Result<Surfaced, SurfaceError> {
    Surfacer::new().run(net, p)
}

/// Keeps what one surface can give the next (as the daemon runs it after every curve, or a
/// monitor at every epoch): the symbolic factorisations (when the mesh's pattern is unchanged
/// only the numeric ones are redone), the faces ([`super::faces`], reused as
/// [`SurfaceParams::reuse_tolerance`] says) and, reusing faces, the last numeric
/// factorisation (the same system again: back-substitutions only).
#[derive(Debug, Default)]
pub struct Surfacer {
    pattern: CachedPattern,
    soft_pattern: CachedPattern,
    faces: Faces,
}

impl Surfacer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Numeric factorisations computed so far (one per pass that changed the system).
    pub fn numeric_factorisations(&self) -> usize {
        self.pattern.numeric_count() + self.soft_pattern.numeric_count()
    }

    /// Surfaces the network (see the module docs and [`surface`]).
    pub fn run(
        &mut self,
        net: &NetworkSegments,
        p: &SurfaceParams,
    ) -> Result<Surfaced, SurfaceError> {
        surface_with(
            net,
            p,
            &mut self.pattern,
            &mut self.soft_pattern,
            &mut self.faces,
        )
    }
}

/// The surface in three stages, precompute then solve (as libigl's
/// `min_quad_with_fixed_precompute` / `_solve`): the tessellation of every cycle
/// ([`tessellation`]); the passes ([`passes`]); last the output mesh ([`output()`]) and the
/// faces kept for the next surface ([`keep_faces`]).
fn surface_with(
    net: &NetworkSegments,
    p: &SurfaceParams,
    pattern: &mut CachedPattern,
    soft_pattern: &mut CachedPattern,
    faces: &mut Faces,
) -> Result<Surfaced, SurfaceError> {
    let mut tt = std::time::Instant::now();
    let Tessellation {
        mut asm,
        skipped,
        cycles: cyc,
        mut problems,
        edge,
        estimate,
        exact: exact_rims,
    } = tessellation(net, p, faces);
    lap("tessellation", &mut tt);
    if asm.triangles.is_empty() {
        return Err(SurfaceError::NoPatch(problems));
    }
    // The curves' samples, then the guide curves'.
    let data: Vec<Vector3<f64>> = asm.positions[..asm.constrained + asm.guided].to_vec();
    // Provisional: one pass, the kept faces weighted as in the last surface (their
    // reweighting already done), the others from their planar tessellation.
    let single = p.reuse_tolerance > 0.0 && p.method == Method::NormalControl && p.reweight > 0;
    // Not the surface a run from scratch gives: one pass, or rims, edge or faces held.
    let provisional = single || !exact_rims || asm.pieces.iter().any(|pc| !pc.exact);
    let (nstar, used) = passes(&mut asm, &data, p, single, [pattern, soft_pattern], &mut tt)?;
    lap("solves", &mut tt);
    let guides = guide_fits(&asm, &data);
    let (triangles, normals) = output(&asm, &nstar, edge, &mut problems)?;
    lap("output", &mut tt);
    let pieces = asm.pieces.len();
    let faces_kept = keep_faces(faces, &mut asm, used, edge, estimate);
    lap("weights kept", &mut tt);
    tracing::debug!(
        "surface: {faces_kept} of {pieces} faces kept{}",
        if provisional { ", provisional" } else { "" }
    );
    Ok(Surfaced {
        positions: asm.positions,
        normals,
        propagated: nstar,
        triangles,
        constrained: asm.constrained,
        guides,
        primary: asm.primary,
        corners: asm.corners,
        darts: asm.darts,
        cycles: cyc,
        skipped,
        problems,
        faces_kept,
        provisional,
    })
}

/// Logs the time of a stage since `t` (debug), and restarts `t`.
fn lap(what: &str, t: &mut std::time::Instant) {
    tracing::debug!("surface: {what} {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    *t = std::time::Instant::now();
}

/// Per piece, the 3D weights its last pass was solved with (`None`: its planar ones).
type UsedWeights = Vec<Option<Arc<Weights>>>;

/// The passes over the assembled mesh (`data` the positions of its first vertices: the
/// curves' samples, then the guide curves'): per pass, the weights (planar, or the kept
/// faces' from the last surface when `single`; from the surface just computed after the
/// first pass: the reweighting), the normal matrix and its factorisation
/// ([`System::precompute`], symbolic factorisations reused from the caches `[hard, soft]`),
/// the propagation of positions and normals ([`System::propagate`]) and the fit for the
/// method. Returns the propagated normals (`#V`) and the weights each piece was solved with.
fn passes(
    asm: &mut Assembly,
    data: &[Vector3<f64>],
    p: &SurfaceParams,
    single: bool,
    [pattern, soft_pattern]: [&mut CachedPattern; 2],
    tt: &mut std::time::Instant,
) -> Result<(Vec<Vector3<f64>>, UsedWeights), SurfaceError> {
    let nv = asm.positions.len();
    let c = asm.constrained;
    let rows = energy_rows(asm);
    let zero = vec![Vector3::zeros(); nv];
    let mut nstar = asm.normals.clone();
    let mut used: UsedWeights = asm
        .pieces
        .iter()
        .map(|pc| pc.face.surface.clone().filter(|_| single))
        .collect();
    let passes = if single { 0 } else { p.reweight };
    for pass in 0..=passes {
        if pass > 0 {
            // The weights from the surface just computed instead of the planar triangulations.
            let all: Vec<usize> = (0..asm.pieces.len()).collect();
            used = surface_weights(&asm.pieces, &all, &asm.positions)
                .into_iter()
                .map(Some)
                .collect();
        }
        (asm.lc, asm.mass) = sum_weights(
            nv,
            asm.pieces.iter().zip(&used).map(|(pc, w)| {
                let w = w.as_deref().unwrap_or(&pc.face.planar);
                (pc.g.as_slice(), w)
            }),
        );
        lap("weights", tt);
        let q = normal_matrix(&asm.lc, &asm.mass, &rows);
        lap("normal matrix", tt);
        let system = System::precompute(&q, c, asm.guided, p, pattern, soft_pattern)?;
        lap("factorisation", tt);
        // 1. Biharmonic positions (the first pass, and the comparison methods) and normals.
        system.propagate(&q, pass, p.method, asm, &mut nstar, data, &zero);
        lap("propagate", tt);
        // 2. The fit.
        match p.method {
            Method::Biharmonic => {}
            Method::Triharmonic => triharmonic(asm, &q, &rows, data, p.guide_weight, &zero)?,
            Method::NormalControl => {
                let b = normal_control_target(asm, &nstar, &rows);
                system.fit(&q, &b, &mut asm.positions, data);
            }
        }
        lap("fit", tt);
        if matches!(system, System::Soft(_)) {
            weld(&mut asm.positions, &asm.primary, c);
        }
    }
    Ok((nstar, used))
}

/// How near the surface passes to each guide curve's samples (`data` their measured
/// positions, by vertex id).
fn guide_fits(asm: &Assembly, data: &[Vector3<f64>]) -> Vec<GuideFit> {
    asm.guides
        .iter()
        .map(|(curve, r)| {
            let d: Vec<f64> = r
                .clone()
                .map(|i| (asm.positions[i] - data[i]).norm())
                .collect();
            GuideFit {
                curve: *curve,
                samples: d.len(),
                mean_m: d.iter().sum::<f64>() / d.len().max(1) as f64,
                max_m: d.iter().copied().fold(0.0, f64::max),
            }
        })
        .collect()
}

/// Keeps the faces for the next surface, each with the 3D weights its last pass was solved
/// with (so that the same network again is the same system: back-substitutions only), or
/// those of this surface where it had none (a provisional surface's new faces). Returns how
/// many of this surface's faces were kept from the last. `edge` is the surface's target edge,
/// `estimate` the budget's ([`Faces::estimate`]).
fn keep_faces(
    faces: &mut Faces,
    asm: &mut Assembly,
    mut used: UsedWeights,
    edge: f64,
    estimate: f64,
) -> usize {
    let planar: Vec<usize> = (0..used.len()).filter(|&i| used[i].is_none()).collect();
    let mut fresh = surface_weights(&asm.pieces, &planar, &asm.positions).into_iter();
    for &i in &planar {
        used[i] = fresh.next();
    }
    let faces_kept = asm.pieces.iter().filter(|pc| pc.kept).count();
    faces.by_key.clear();
    faces.edge = Some(edge);
    faces.estimate = Some(estimate);
    for (pc, w) in std::mem::take(&mut asm.pieces).into_iter().zip(used) {
        let mut face = pc.face;
        face.surface = w;
        faces.by_key.insert(pc.key, face);
    }
    faces_kept
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 18, point 3: a guide curve is approximated. The unit sphere's three great circles,
    /// one of them a guide measured with a ripple of ±5 mm off the sphere (a 16 cm wave): the
    /// surface passes within the guide's own error of it, nearer the sphere than the guide (an
    /// interior curve is interpolated, ripple and all). Both constraint modes.
    #[test]
    fn issue_18_a_guide_curve_is_approximated_within_its_own_error() {
        let mut net = crate::surface::analytic::sphere_circles(0.02);
        let mut wave_max: f64 = 0.0;
        for s in net.segments.iter_mut().filter(|s| s.curve == 0) {
            s.kind = crate::curve::CurveKind::Guide;
            let m = s.points.len();
            for k in 1..m - 1 {
                let u = k as f64 / (m - 1) as f64;
                let off = 0.005 * (20.0 * std::f64::consts::PI * u).sin();
                s.points[k] *= 1.0 + off;
                wave_max = wave_max.max(off.abs());
            }
        }
        for soft in [None, Some(0.3)] {
            let p = SurfaceParams {
                soft,
                ..SurfaceParams::default()
            };
            let surf = surface(&net, &p).expect("a surface");
            assert!(surf.problems.is_empty(), "{:?}", surf.problems);
            assert_eq!(surf.guides.len(), 1);
            let g = &surf.guides[0];
            assert_eq!(g.curve, 0);
            assert!(
                g.max_m <= wave_max,
                "{soft:?}: {g:?} off a guide {wave_max} off"
            );
            assert!(g.mean_m > 0.1 * wave_max, "{soft:?}: {g:?}: interpolated");
            // Nearer the sphere than the guide's samples.
            let c = surf.constrained;
            let r = c..c + g.samples;
            let off = |i: usize| (surf.positions[i].norm() - 1.0).abs();
            let surf_off = r.clone().map(off).sum::<f64>() / g.samples as f64;
            let guide_off: f64 = net
                .segments
                .iter()
                .filter(|s| s.curve == 0)
                .flat_map(|s| s.points[1..s.points.len() - 1].iter())
                .map(|p| (p.norm() - 1.0).abs())
                .sum::<f64>()
                / g.samples as f64;
            assert!(
                surf_off < 0.8 * guide_off,
                "{soft:?}: the surface is {surf_off:.4} off the sphere there, the guide {guide_off:.4}"
            );
        }
    }
}
