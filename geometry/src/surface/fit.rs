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

use super::cotmatrix::{cotmatrix, voronoi_areas, SparseRows};
use super::creases;
use super::cycles::{cycles, Cycles, NetworkSegments};
use super::faces::{Face, FaceKey, Faces, Weights};
use super::tessellate::{tessellate, Embedding};
use super::SurfaceProblem;
use crate::sparse_llt::{CachedPattern, SolveError};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::sync::Arc;

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
    /// its creases, each side with its own vertices ([`creases`]); mapping every vertex to
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

struct Assembly {
    positions: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    constrained: usize,
    /// The guide curves' samples between nodes, after the constrained vertices: per guide
    /// curve, its vertices.
    guides: Vec<(usize, std::ops::Range<usize>)>,
    /// Their count (`constrained..constrained + guided`).
    guided: usize,
    /// `#V`: the vertex each one is a copy of along a crease (itself for most).
    primary: Vec<usize>,
    /// Crease corners and darts ([`creases::Split`]).
    corners: Vec<u32>,
    darts: Vec<u32>,
    triangles: Vec<[usize; 3]>,
    /// The cotangent weights and areas of the pass being solved, summed from the pieces'
    /// (empty until the first pass).
    lc: SparseRows,
    mass: Vec<f64>,
    /// The tessellated patches, in patch order.
    pieces: Vec<Piece>,
}

/// One tessellated patch of the assembly.
struct Piece {
    /// Local → global ids: the boundary loop first (the patch's order), then its own free
    /// vertices.
    g: Vec<usize>,
    key: FaceKey,
    face: Face,
    /// Kept from the previous surface.
    kept: bool,
    /// Built from this boundary, or kept from the same one bit for bit (what a run from
    /// scratch would have built).
    exact: bool,
}

/// The sum of per-piece weights (each piece's local → global ids and one of its weights)
/// into global `#V by #V` cotangent rows and `#V` areas.
fn sum_weights<'a>(
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
fn surface_weights(
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

/// The kept faces and the policy of their reuse ([`SurfaceParams::reuse_tolerance`], in
/// target edges), for one run.
struct Reuse<'a> {
    faces: &'a mut Faces,
    tolerance: f64,
}

/// Builds the constrained vertices (nodes, then the samples inside segments) and tessellates
/// every patch with its planar cotangent weights and areas (or keeps it from `reuse`).
fn assemble(
    net: &NetworkSegments,
    cyc: &Cycles,
    edge: f64,
    problems: &mut Vec<SurfaceProblem>,
    reuse: &mut Reuse,
) -> (Assembly, usize) {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut node_id: BTreeMap<u32, usize> = BTreeMap::new();
    for s in &net.segments {
        for (node, p, n) in [
            (s.a, s.points[0], s.normals.first().copied()),
            (
                s.b,
                *s.points.last().expect("two points"),
                s.normals.last().copied(),
            ),
        ] {
            node_id.entry(node).or_insert_with(|| {
                positions.push(p);
                normals.push(
                    net.normals
                        .get(&node)
                        .copied()
                        .or(n)
                        .unwrap_or_else(Vector3::z),
                );
                positions.len() - 1
            });
        }
    }
    // Samples strictly inside each segment (guide curves' after the constrained vertices).
    let guide = |s: &super::cycles::Segment| s.kind == crate::curve::CurveKind::Guide;
    let mut inner: Vec<usize> = Vec::with_capacity(net.segments.len());
    for s in &net.segments {
        inner.push(positions.len());
        if guide(s) {
            continue;
        }
        let m = s.points.len();
        for k in 1..m.saturating_sub(1) {
            positions.push(s.points[k]);
            normals.push(s.normals.get(k).copied().unwrap_or_else(Vector3::z));
        }
    }
    // Split along the creases: every sector of a node but its first, and the other face of
    // every crease segment, a vertex of its own (copies, constrained like their primary).
    let split = creases::split(net, cyc);
    let mut primary: Vec<usize> = (0..positions.len()).collect();
    let mut sector_id: BTreeMap<(u32, usize), usize> = BTreeMap::new();
    for (&node, list) in &split.sectors {
        let first = node_id[&node];
        normals[first] = list[0];
        for (k, &n) in list.iter().enumerate().skip(1) {
            sector_id.insert((node, k), positions.len());
            positions.push(positions[first]);
            normals.push(n);
            primary.push(first);
        }
    }
    let mut inner_across: BTreeMap<usize, usize> = BTreeMap::new();
    for (si, s) in net.segments.iter().enumerate() {
        if !s.crease() {
            continue;
        }
        inner_across.insert(si, positions.len());
        for k in 1..s.points.len().saturating_sub(1) {
            positions.push(s.points[k]);
            normals.push(s.across[k]);
            primary.push(inner[si] + k - 1);
        }
    }
    let constrained = positions.len();
    let mut guides: Vec<(usize, std::ops::Range<usize>)> = Vec::new();
    for (si, s) in net.segments.iter().enumerate() {
        if !guide(s) {
            continue;
        }
        inner[si] = positions.len();
        for k in 1..s.points.len().saturating_sub(1) {
            positions.push(s.points[k]);
            normals.push(s.normals.get(k).copied().unwrap_or_else(Vector3::z));
            primary.push(primary.len());
        }
        match guides.last_mut() {
            Some((c, r)) if *c == s.curve && r.end == inner[si] => r.end = positions.len(),
            _ => guides.push((s.curve, inner[si]..positions.len())),
        }
    }
    let guided = positions.len() - constrained;
    // Global id of point k of segment si, seen from a patch: at the half-edge's start node
    // (k its first point in the patch's order) the patch's sector there, inside the segment
    // the face the patch takes.
    let id = |si: usize, k: usize, sector: usize, across: bool| -> usize {
        let s = &net.segments[si];
        let node = if k == 0 {
            Some(s.a)
        } else if k + 1 == s.points.len() {
            Some(s.b)
        } else {
            None
        };
        match node {
            Some(v) if sector > 0 => sector_id[&(v, sector)],
            Some(v) => node_id[&v],
            None if across => inner_across[&si] + k - 1,
            None => inner[si] + k - 1,
        }
    };
    // Each patch's boundary (global ids, points, normals), then the patches tessellated with
    // their planar weights on worker threads, merged in patch order (deterministic).
    type Loop = (Vec<usize>, Vec<Vector3<f64>>, Vec<Vector3<f64>>);
    let loops: Vec<Loop> = cyc
        .patches
        .iter()
        .enumerate()
        .map(|(pi, cyc)| {
            let (mut ids, mut poly, mut pn) = (Vec::new(), Vec::new(), Vec::new());
            for (e, h) in cyc.edges.iter().enumerate() {
                let s = &net.segments[h.segment];
                let m = s.points.len();
                let across = split.takes_across[pi][e];
                for j in 0..m - 1 {
                    let k = if h.forward { j } else { m - 1 - j };
                    let sector = if j == 0 {
                        split.corner_sector[pi][e]
                    } else {
                        0
                    };
                    let g = id(h.segment, k, sector, across);
                    ids.push(g);
                    poly.push(s.points[k]);
                    pn.push(normals[g]);
                }
            }
            (ids, poly, pn)
        })
        .collect();
    // Each patch's cycle as the kept faces know it; a kept face that fits is reused, the
    // others are tessellated on worker threads.
    let keys: Vec<FaceKey> = cyc
        .patches
        .iter()
        .enumerate()
        .map(|(pi, c)| {
            c.edges
                .iter()
                .enumerate()
                .map(|(e, h)| {
                    let s = &net.segments[h.segment];
                    (
                        s.curve,
                        s.a,
                        s.b,
                        h.forward,
                        s.points.len(),
                        split.takes_across[pi][e],
                        split.corner_sector[pi][e],
                    )
                })
                .collect()
        })
        .collect();
    let tol_m = reuse.tolerance * edge;
    let mut reused: Vec<Option<Face>> = keys
        .iter()
        .zip(&loops)
        .map(|(key, (_, poly, pn))| reuse.faces.take(key, poly, pn, edge, tol_m))
        .collect();
    let misses: Vec<usize> = (0..loops.len()).filter(|&i| reused[i].is_none()).collect();
    let mut built = parallel_map(&misses, |&pi| {
        let (_, poly, pn) = &loops[pi];
        tessellate(poly, pn, edge).map(|mesh| {
            let uv: Vec<Vector3<f64>> = mesh
                .uv
                .iter()
                .map(|p| Vector3::new(p[0], p[1], 0.0))
                .collect();
            let planar = Weights {
                l: cotmatrix(&uv, &mesh.triangles),
                areas: voronoi_areas(&uv, &mesh.triangles),
            };
            Face {
                poly: poly.clone(),
                normals: pn.clone(),
                mesh: Arc::new(mesh),
                planar: Arc::new(planar),
                surface: None,
            }
        })
    })
    .into_iter();
    let mut triangles = Vec::new();
    let mut pieces = Vec::new();
    let mut skipped = 0;
    for (pi, ((cyc, (ids, _, _)), key)) in cyc.patches.iter().zip(&loops).zip(keys).enumerate() {
        let (face, kept) = match reused[pi].take() {
            Some(f) => (f, true),
            None => match built.next().expect("one per miss") {
                Ok(f) => (f, false),
                Err(e) => {
                    problems.push(SurfaceProblem::NotTessellated {
                        nodes: cyc.nodes(net),
                        reason: e,
                    });
                    skipped += 1;
                    continue;
                }
            },
        };
        let mesh = &face.mesh;
        tracing::debug!(
            "patch {:?}: {} boundary points, {} vertices, {} triangles, {:?}, edge {edge:.4}{}",
            cyc.nodes(net),
            mesh.boundary,
            mesh.uv.len(),
            mesh.triangles.len(),
            mesh.embedding,
            if kept { ", kept" } else { "" }
        );
        if mesh.embedding == Embedding::Circle {
            problems.push(SurfaceProblem::OnDisk {
                nodes: cyc.nodes(net),
            });
        }
        // Local → global ids: the boundary first, then new free vertices.
        let mut g: Vec<usize> = ids.clone();
        for _ in mesh.boundary..mesh.uv.len() {
            g.push(positions.len());
            primary.push(positions.len());
            positions.push(Vector3::zeros());
            normals.push(Vector3::zeros());
        }
        triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| g[i])));
        let exact = !kept || face.fits(&loops[pi].1, &loops[pi].2, 0.0);
        pieces.push(Piece {
            g,
            key,
            face,
            kept,
            exact,
        });
    }
    (
        Assembly {
            positions,
            normals,
            constrained,
            guides,
            guided,
            primary,
            corners: split.corners,
            darts: split.darts,
            triangles,
            lc: SparseRows::default(),
            mass: Vec::new(),
            pieces,
        },
        skipped,
    )
}

/// `f` over `items` on up to [`WORKERS`] threads, results in the order of `items`.
fn parallel_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(WORKERS)
        .min(items.len());
    if workers <= 1 {
        return items.iter().map(f).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut out: Vec<(usize, R)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(item) = items.get(i) else { break };
                        mine.push((i, f(item)));
                    }
                    mine
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a surfacing worker panicked"))
            .collect()
    });
    out.sort_unstable_by_key(|&(i, _)| i);
    out.into_iter().map(|(_, r)| r).collect()
}

/// Threads that tessellate patches at the same time (the machine's cores, at most this).
pub const WORKERS: usize = 4;

/// `Σ_k∈rows Lc_kᵀ Lc_k / m_k` and the rows' right-hand side `Σ_k Lc_kᵀ t_k`.
fn normal_matrix(lc: &SparseRows, m: &[f64], rows: &[bool]) -> SparseRows {
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
fn data_weights(q: &SparseRows, c: usize, g: usize, omega: f64, omega_g: f64) -> Vec<f64> {
    let mean = |r: std::ops::Range<usize>| {
        let n = r.len().max(1) as f64;
        r.map(|i| q.get(i, i)).sum::<f64>() / n
    };
    let (w, wg) = (omega * mean(0..c), omega_g * mean(c..c + g));
    (0..c + g).map(|i| if i < c { w } else { wg }).collect()
}

/// Soft positional constraints: `(Q + W) X = B + W X*` over every vertex, `W` the diagonal of
/// the data weights of the first vertices (the curves' samples, then the guide curves') and
/// `X*` their data (see [`SurfaceParams::soft`]).
struct SoftSolver {
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
struct FreeSolver {
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

/// Default target edge: the mean spacing of the network's samples, but at least
/// [`EDGE_PER_DIAGONAL`] of the network's bounding-box diagonal (about 20 k vertices on a
/// sphere-like network, whatever the sampling).
pub fn default_edge(net: &NetworkSegments) -> f64 {
    let (mut len, mut cnt) = (0.0, 0usize);
    let mut lo = Vector3::repeat(f64::MAX);
    let mut hi = Vector3::repeat(f64::MIN);
    for s in &net.segments {
        len += s
            .points
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .sum::<f64>();
        cnt += s.points.len().saturating_sub(1);
        for p in &s.points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
    }
    if cnt == 0 {
        return 1.0;
    }
    (len / cnt as f64).max((hi - lo).norm() * EDGE_PER_DIAGONAL)
}

/// See [`default_edge`].
pub const EDGE_PER_DIAGONAL: f64 = 1.0 / 120.0;

/// Patch boundaries keep network samples at least this many target edges apart
/// ([`NetworkSegments::decimated`]).
pub const BOUNDARY_STEP: f64 = 0.5;

/// Default vertex budget ([`SurfaceParams::max_vertices`]): about 200 MB and 0.2 s per surface
/// on this project's reference machine (BENCHMARKS.md).
pub const MAX_VERTICES: usize = 20_000;

/// The edge at which the patches of `cyc` take about `max_vertices` vertices: their area is
/// estimated by fans from each boundary's centroid (a lattice of edge `e` has one vertex
/// per `√3/2 e²`).
pub fn budget_edge(net: &NetworkSegments, cyc: &Cycles, max_vertices: usize) -> f64 {
    let mut area = 0.0;
    for c in &cyc.patches {
        let mut pts = Vec::new();
        for h in &c.edges {
            let s = &net.segments[h.segment];
            if h.forward {
                pts.extend(s.points[..s.points.len() - 1].iter().copied());
            } else {
                pts.extend(s.points[1..].iter().rev().copied());
            }
        }
        if pts.len() < 3 {
            continue;
        }
        let centroid = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
        for k in 0..pts.len() {
            let (a, b) = (pts[k] - centroid, pts[(k + 1) % pts.len()] - centroid);
            area += 0.5 * a.cross(&b).norm();
        }
    }
    (area / (3f64.sqrt() / 2.0 * max_vertices.max(1) as f64)).sqrt()
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
/// ([`tessellation`]); per pass, the weights, the normal matrix and its factorisation
/// ([`System::precompute`], symbolic factorisations reused from the caches), then the
/// propagation of positions and normals ([`System::propagate`]) and the fit for the method;
/// last the output mesh ([`output`]).
fn surface_with(
    net: &NetworkSegments,
    p: &SurfaceParams,
    pattern: &mut CachedPattern,
    soft_pattern: &mut CachedPattern,
    faces: &mut Faces,
) -> Result<Surfaced, SurfaceError> {
    let t_tess = std::time::Instant::now();
    let Tessellation {
        mut asm,
        skipped,
        cycles: cyc,
        mut problems,
        edge,
        exact: exact_rims,
    } = tessellation(net, p, faces);
    let lap = |what: &str, t: &mut std::time::Instant| {
        tracing::debug!("surface: {what} {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        *t = std::time::Instant::now();
    };
    let mut tt = t_tess;
    lap("tessellation", &mut tt);
    if asm.triangles.is_empty() {
        return Err(SurfaceError::NoPatch(problems));
    }
    let nv = asm.positions.len();
    let c = asm.constrained;
    let rows = energy_rows(&asm);
    let zero = vec![Vector3::zeros(); nv];
    let mut nstar = asm.normals.clone();
    // The curves' samples, then the guide curves'.
    let data: Vec<Vector3<f64>> = asm.positions[..c + asm.guided].to_vec();
    // Provisional: one pass, the kept faces weighted as in the last surface (their
    // reweighting already done), the others from their planar tessellation.
    let single = p.reuse_tolerance > 0.0 && p.method == Method::NormalControl && p.reweight > 0;
    // Not the surface a run from scratch gives: one pass, or rims, edge or faces held.
    let provisional = single || !exact_rims || asm.pieces.iter().any(|pc| !pc.exact);
    // Per piece, the 3D weights its last pass was solved with (none: planar).
    let mut used: Vec<Option<Arc<Weights>>> = asm
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
        lap("weights", &mut tt);
        let q = normal_matrix(&asm.lc, &asm.mass, &rows);
        lap("normal matrix", &mut tt);
        let system = System::precompute(&q, c, asm.guided, p, pattern, soft_pattern)?;
        lap("factorisation", &mut tt);
        // 1. Biharmonic positions (the first pass, and the comparison methods) and normals.
        system.propagate(&q, pass, p.method, &mut asm, &mut nstar, &data, &zero);
        lap("propagate", &mut tt);
        // 2. The fit.
        match p.method {
            Method::Biharmonic => {}
            Method::Triharmonic => {
                // L³V = 0 as the minimum of ∫|∇ΔV|²: the normal matrix −Lc M⁻¹ Lc M⁻¹ Lc
                // = −Lc M⁻¹ Q (symmetric, positive semi-definite since −Lc is).
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
                let guide = data_weights(&q3, c, asm.guided, 0.0, p.guide_weight)[c..].to_vec();
                asm.positions[..data.len()].copy_from_slice(&data);
                FreeSolver::with_pattern(&q3, c, guide, &mut own, false)?.solve(
                    &q3,
                    &zero,
                    &mut asm.positions,
                );
            }
            Method::NormalControl => {
                let h = mean_curvature_vectors(&asm.positions, &nstar, &asm.triangles);
                // Target Laplacian, projected on the propagated normal; rhs Σ_k Lc_kᵀ t_k.
                let mut b = vec![Vector3::zeros(); nv];
                for (k, r) in asm.lc.rows.iter().enumerate() {
                    if !rows[k] {
                        continue;
                    }
                    let tk = nstar[k] * h[k].dot(&nstar[k]);
                    for &(i, w) in r {
                        b[i] += tk * w;
                    }
                }
                system.fit(&q, &b, &mut asm.positions, &data);
            }
        }
        lap("fit", &mut tt);
        if matches!(system, System::Soft(_)) {
            weld(&mut asm.positions, &asm.primary, c);
        }
    }
    lap("solves", &mut tt);
    let guides: Vec<GuideFit> = asm
        .guides
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
        .collect();
    let (triangles, normals) = output(&asm, &nstar, edge, &mut problems)?;
    lap("output", &mut tt);
    // The faces kept for the next surface, each with the 3D weights its last pass was
    // solved with (so that the same network again is the same system: back-substitutions
    // only), or those of this surface where it had none (a provisional surface's new faces).
    let planar: Vec<usize> = (0..used.len()).filter(|&i| used[i].is_none()).collect();
    let mut fresh = surface_weights(&asm.pieces, &planar, &asm.positions).into_iter();
    for &i in &planar {
        used[i] = fresh.next();
    }
    let faces_kept = asm.pieces.iter().filter(|pc| pc.kept).count();
    lap("weights kept", &mut tt);
    tracing::debug!(
        "surface: {faces_kept} of {} faces kept{}",
        asm.pieces.len(),
        if provisional { ", provisional" } else { "" }
    );
    faces.by_key.clear();
    faces.edge = Some(edge);
    for (pc, w) in std::mem::take(&mut asm.pieces).into_iter().zip(used) {
        let mut face = pc.face;
        face.surface = w;
        faces.by_key.insert(pc.key, face);
    }
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

/// The tessellated cycles of a network, before any solve.
struct Tessellation {
    asm: Assembly,
    skipped: usize,
    cycles: Cycles,
    problems: Vec<SurfaceProblem>,
    /// The target edge, m.
    edge: f64,
    /// The edge and the rims' samples are those a run from scratch takes (not held from the
    /// last surface).
    exact: bool,
}

/// The cycles of the cleaned network tessellated at the target edge (the configured one, or
/// the default within the vertex budget), their rims decimated to half an edge.
fn tessellation(net: &NetworkSegments, p: &SurfaceParams, faces: &mut Faces) -> Tessellation {
    let net = &net.cleaned();
    let cyc = cycles(net);
    let mut problems = cyc.problems.clone();
    let mut edge = p
        .edge
        .unwrap_or_else(|| default_edge(net).max(budget_edge(net, &cyc, p.max_vertices)));
    // Reusing faces, the kept edge holds while the budget's stays within a quarter of it (a
    // grown network would otherwise be tessellated anew at every curve).
    let mut exact = true;
    if let (true, None, Some(kept)) = (p.reuse_tolerance > 0.0, p.edge, faces.edge) {
        if (0.8..=1.25).contains(&(edge / kept)) {
            exact &= edge == kept;
            edge = kept;
        }
    }
    // Boundary vertices about half an edge apart at least: a network sampled far more finely
    // than the surface would otherwise fill each patch's rim with a band of graded triangles.
    // Reusing faces, a segment keeps the samples it kept last time (its decimation would
    // otherwise change with any motion, and with it the faces along it).
    let mut keep = net.decimation(BOUNDARY_STEP * edge);
    if p.reuse_tolerance > 0.0 && faces.edge == Some(edge) {
        for (s, k) in net.segments.iter().zip(&mut keep) {
            if let Some(kept) = faces.samples.get(&(s.curve, s.a, s.b, s.points.len())) {
                exact &= k == kept;
                k.clone_from(kept);
            }
        }
    }
    faces.samples = net
        .segments
        .iter()
        .zip(&keep)
        .map(|(s, k)| ((s.curve, s.a, s.b, s.points.len()), k.clone()))
        .collect();
    let decimated = net.keeping(&keep);
    let mut reuse = Reuse {
        faces,
        tolerance: p.reuse_tolerance,
    };
    let net = &decimated;
    let t0 = std::time::Instant::now();
    let (mut asm, mut skipped) = assemble(net, &cyc, edge, &mut problems, &mut reuse);
    // The budget's area is an estimate (a developed patch can take more room in the plane
    // than on the surface): over it by a quarter, tessellate once more at the edge the count
    // asks for.
    let nv = asm.positions.len() as f64;
    if p.edge.is_none() && nv > 1.25 * p.max_vertices as f64 {
        edge *= (nv / p.max_vertices as f64).sqrt();
        tracing::debug!("surface: {nv} vertices over the budget; edge {edge:.4}");
        problems = cyc.problems.clone();
        (asm, skipped) = assemble(net, &cyc, edge, &mut problems, &mut reuse);
    }
    tracing::debug!(
        "surface: cycles + tessellation + planar weights {:.1} ms",
        t0.elapsed().as_secs_f64() * 1e3
    );
    Tessellation {
        asm,
        skipped,
        cycles: cyc,
        problems,
        edge,
        exact,
    }
}

/// The vertices that are rows of the energy: those whose ring is closed (every edge around
/// them in two triangles). `#V` flags.
fn energy_rows(asm: &Assembly) -> Vec<bool> {
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

/// One pass's factorised system: the free block of the normal matrix (hard constraints), or
/// with soft constraints the whole system, whose one factorisation serves the propagations
/// and the fit (normal control only).
enum System {
    Free(FreeSolver),
    Soft(SoftSolver),
}

impl System {
    /// Factorises the normal matrix `q` (`#V` by `#V`, the first `c` vertices constrained),
    /// reusing the symbolic factorisations in the caches, and with faces reused
    /// ([`SurfaceParams::reuse_tolerance`] > 0) the numeric one when the system is the last
    /// one again (a monitored structure: back-substitutions only).
    fn precompute(
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
    fn propagate(
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
    fn fit(
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

/// Moves the copies of each vertex along a crease (constrained, `primary[i] < c`) to their
/// mean: with soft constraints each side pulls its copy a little its own way.
fn weld(positions: &mut [Vector3<f64>], primary: &[usize], c: usize) {
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

/// `#F` triangles and `#V` unit vertex normals.
type TrianglesAndNormals = (Vec<[u32; 3]>, Vec<Vector3<f64>>);

/// The output mesh: triangles that came out degenerate in 3D are dropped (reported; the
/// threshold, a millionth of a target triangle, keeps them non-degenerate once written in
/// f32), vertex normals from the faces (the propagated normal where they cancel). An error
/// when a vertex is not finite.
fn output(
    asm: &Assembly,
    nstar: &[Vector3<f64>],
    edge: f64,
    problems: &mut Vec<SurfaceProblem>,
) -> Result<TrianglesAndNormals, SurfaceError> {
    let scale = edge * edge;
    let nv = asm.positions.len();
    let mut triangles = Vec::with_capacity(asm.triangles.len());
    let mut vn = vec![Vector3::zeros(); nv];
    let mut degenerate = 0;
    for t in &asm.triangles {
        let [a, b, cc] = t.map(|i| asm.positions[i]);
        let fnrm = (b - a).cross(&(cc - a));
        // Degenerate once written in f32 (the glTF's coordinates) is degenerate too: a sliver
        // between two curves that retrace each other can have an area in f64 and none in f32.
        let [a32, b32, c32] = [a, b, cc].map(|p| p.map(|x| x as f32 as f64));
        if fnrm.norm().is_nan()
            || fnrm.norm() <= 1e-12 * scale
            || !fnrm.iter().all(|x| x.is_finite())
            || (b32 - a32).cross(&(c32 - a32)).norm() <= 0.0
        {
            degenerate += 1;
            continue;
        }
        for &i in t {
            vn[i] += fnrm;
        }
        triangles.push(t.map(|i| i as u32));
    }
    if degenerate > 0 {
        problems.push(SurfaceProblem::ZeroArea {
            triangles: degenerate,
        });
    }
    let normals: Vec<Vector3<f64>> = vn
        .iter()
        .zip(nstar)
        .map(|(v, s)| v.try_normalize(1e-300).unwrap_or(*s))
        .collect();
    if let Some(i) = asm
        .positions
        .iter()
        .position(|p| !p.iter().all(|x| x.is_finite()))
    {
        return Err(SurfaceError::Solve(SolveError::Faer(format!(
            "vertex {i} is not finite"
        ))));
    }
    Ok((triangles, normals))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::cotmatrix::tests::icosphere;

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
