//! The assembled mesh before any solve: the network's samples as constrained vertices (copies
//! along creases, guide curves' samples after them), every cycle's patch tessellated at the
//! target edge (or kept from the last surface) with its planar cotangent weights and areas,
//! and the target edge itself (the configured one, or the default within the vertex budget).

use super::super::cotmatrix::{cotmatrix, voronoi_areas, SparseRows};
use super::super::creases;
use super::super::cycles::{cycles, Cycles, NetworkSegments};
use super::super::faces::{Face, FaceKey, Faces, Weights};
use super::super::tessellate::{tessellate, Embedding, TessellateError};
use super::super::SurfaceProblem;
use super::SurfaceParams;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::sync::Arc;

pub(super) struct Assembly {
    pub(super) positions: Vec<Vector3<f64>>,
    pub(super) normals: Vec<Vector3<f64>>,
    pub(super) constrained: usize,
    /// The guide curves' samples between nodes, after the constrained vertices: per guide
    /// curve, its vertices.
    pub(super) guides: Vec<(usize, std::ops::Range<usize>)>,
    /// Their count (`constrained..constrained + guided`).
    pub(super) guided: usize,
    /// `#V`: the vertex each one is a copy of along a crease (itself for most).
    pub(super) primary: Vec<usize>,
    /// Crease corners and darts ([`creases::Split`]).
    pub(super) corners: Vec<u32>,
    pub(super) darts: Vec<u32>,
    pub(super) triangles: Vec<[usize; 3]>,
    /// The cotangent weights and areas of the pass being solved, summed from the pieces'
    /// (empty until the first pass).
    pub(super) lc: SparseRows,
    pub(super) mass: Vec<f64>,
    /// The tessellated patches, in patch order.
    pub(super) pieces: Vec<Piece>,
}

/// One tessellated patch of the assembly.
pub(super) struct Piece {
    /// Local → global ids: the boundary loop first (the patch's order), then its own free
    /// vertices.
    pub(super) g: Vec<usize>,
    pub(super) key: FaceKey,
    pub(super) face: Face,
    /// Kept from the previous surface.
    pub(super) kept: bool,
    /// Built from this boundary, or kept from the same one bit for bit (what a run from
    /// scratch would have built).
    pub(super) exact: bool,
}

/// The tessellated cycles of a network, before any solve.
pub(super) struct Tessellation {
    pub(super) asm: Assembly,
    pub(super) skipped: usize,
    pub(super) cycles: Cycles,
    pub(super) problems: Vec<SurfaceProblem>,
    /// The target edge, m.
    pub(super) edge: f64,
    /// The edge the budget estimated for the network before a count over it corrected it
    /// ([`Faces::estimate`]), m.
    pub(super) estimate: f64,
    /// The edge and the rims' samples are those a run from scratch takes (not held from the
    /// last surface).
    pub(super) exact: bool,
}

/// The cycles of the cleaned network tessellated at the target edge (the configured one, or
/// the default within the vertex budget), their rims decimated to half an edge.
pub(super) fn tessellation(
    net: &NetworkSegments,
    p: &SurfaceParams,
    faces: &mut Faces,
) -> Tessellation {
    let net = &net.cleaned();
    let cyc = cycles(net);
    let mut problems = cyc.problems.clone();
    let mut edge = p
        .edge
        .unwrap_or_else(|| default_edge(net).max(budget_edge(net, &cyc, p.max_vertices)));
    let estimate = edge;
    // Reusing faces, the kept edge holds while the budget's stays within a quarter of what it
    // was for the kept faces (a grown network would otherwise be tessellated anew at every
    // curve; and one over the budget twice, at the estimate and again corrected: issue 51).
    let mut exact = true;
    let mut held = false;
    if let (true, None, Some(kept)) = (p.reuse_tolerance > 0.0, p.edge, faces.edge) {
        if (0.8..=1.25).contains(&(edge / faces.estimate.unwrap_or(kept))) {
            exact &= edge == kept;
            edge = kept;
            held = true;
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
    // asks for. A held edge was so corrected for the kept faces already (a network whose
    // rims alone are over the budget would otherwise be tessellated anew at every curve).
    let nv = asm.positions.len() as f64;
    if p.edge.is_none() && !held && nv > 1.25 * p.max_vertices as f64 {
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
        estimate,
        exact,
    }
}

/// The kept faces and the policy of their reuse ([`SurfaceParams::reuse_tolerance`], in
/// target edges), for one run.
pub(super) struct Reuse<'a> {
    faces: &'a mut Faces,
    tolerance: f64,
}

/// Builds the constrained vertices (nodes, then the samples inside segments) and tessellates
/// every patch with its planar cotangent weights and areas (or keeps it from `reuse`).
/// Returns the assembly and the count of patches that could not be tessellated (each one a
/// problem).
pub(super) fn assemble(
    net: &NetworkSegments,
    cyc: &Cycles,
    edge: f64,
    problems: &mut Vec<SurfaceProblem>,
    reuse: &mut Reuse,
) -> (Assembly, usize) {
    let mut v = Vertices::of(net, cyc);
    let loops = patch_loops(net, cyc, &v);
    let keys = face_keys(net, cyc, &v.split);
    // A kept face that fits its cycle is reused, the others are tessellated on worker
    // threads, merged in patch order (deterministic).
    let tol_m = reuse.tolerance * edge;
    let reused: Vec<Option<Face>> = keys
        .iter()
        .zip(&loops)
        .map(|(key, (_, poly, pn))| reuse.faces.take(key, poly, pn, edge, tol_m))
        .collect();
    let faces = tessellate_misses(&loops, reused, edge);
    let mut triangles = Vec::new();
    let mut pieces = Vec::new();
    let mut skipped = 0;
    let patches = cyc.patches.iter().zip(&loops);
    for ((cyc, (ids, poly, pn)), (key, face)) in patches.zip(keys.into_iter().zip(faces)) {
        let (face, kept) = match face {
            Ok(f) => f,
            Err(e) => {
                problems.push(SurfaceProblem::NotTessellated {
                    nodes: cyc.nodes(net),
                    reason: e,
                });
                skipped += 1;
                continue;
            }
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
            g.push(v.positions.len());
            v.primary.push(v.positions.len());
            v.positions.push(Vector3::zeros());
            v.normals.push(Vector3::zeros());
        }
        triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| g[i])));
        let exact = !kept || face.fits(poly, pn, 0.0);
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
            positions: v.positions,
            normals: v.normals,
            constrained: v.constrained,
            guides: v.guides,
            guided: v.guided,
            primary: v.primary,
            corners: v.split.corners,
            darts: v.split.darts,
            triangles,
            lc: SparseRows::default(),
            mass: Vec::new(),
            pieces,
        },
        skipped,
    )
}

/// The constrained vertices of a network's surface (nodes, the samples inside segments, the
/// copies along creases, then the guide curves' samples), and how a patch names them.
struct Vertices {
    positions: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    /// The vertex each one is a copy of (itself for most).
    primary: Vec<usize>,
    node_id: BTreeMap<u32, usize>,
    /// A node's sectors after its first: `(node, sector)` → the node's copy.
    sector_id: BTreeMap<(u32, usize), usize>,
    /// Per segment, the id of its first sample inside.
    inner: Vec<usize>,
    /// Per crease segment, the id of the first sample inside of its other face's copy.
    inner_across: BTreeMap<usize, usize>,
    /// The vertices before the guide curves' samples.
    constrained: usize,
    /// The guide curves' samples (`constrained..constrained + guided`), per guide curve.
    guides: Vec<(usize, std::ops::Range<usize>)>,
    guided: usize,
    /// The split along the creases.
    split: creases::Split,
}

impl Vertices {
    fn of(net: &NetworkSegments, cyc: &Cycles) -> Self {
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
        let mut inner: Vec<usize> = Vec::with_capacity(net.segments.len());
        for s in &net.segments {
            inner.push(positions.len());
            if is_guide(s) {
                continue;
            }
            let m = s.points.len();
            for k in 1..m.saturating_sub(1) {
                positions.push(s.points[k]);
                normals.push(s.normals.get(k).copied().unwrap_or_else(Vector3::z));
            }
        }
        let primary: Vec<usize> = (0..positions.len()).collect();
        let mut v = Vertices {
            positions,
            normals,
            primary,
            node_id,
            sector_id: BTreeMap::new(),
            inner,
            inner_across: BTreeMap::new(),
            constrained: 0,
            guides: Vec::new(),
            guided: 0,
            split: creases::split(net, cyc),
        };
        v.copies_along_creases(net);
        v.constrained = v.positions.len();
        v.guide_samples(net);
        v
    }

    /// Every sector of a node but its first, and the other face of every crease segment, a
    /// vertex of its own (copies, constrained like their primary).
    fn copies_along_creases(&mut self, net: &NetworkSegments) {
        for (&node, list) in &self.split.sectors {
            let first = self.node_id[&node];
            self.normals[first] = list[0];
            for (k, &n) in list.iter().enumerate().skip(1) {
                self.sector_id.insert((node, k), self.positions.len());
                self.positions.push(self.positions[first]);
                self.normals.push(n);
                self.primary.push(first);
            }
        }
        for (si, s) in net.segments.iter().enumerate() {
            if !s.crease() {
                continue;
            }
            self.inner_across.insert(si, self.positions.len());
            for k in 1..s.points.len().saturating_sub(1) {
                self.positions.push(s.points[k]);
                self.normals.push(s.across[k]);
                self.primary.push(self.inner[si] + k - 1);
            }
        }
    }

    /// The guide curves' samples inside segments, after the constrained vertices.
    fn guide_samples(&mut self, net: &NetworkSegments) {
        for (si, s) in net.segments.iter().enumerate() {
            if !is_guide(s) {
                continue;
            }
            self.inner[si] = self.positions.len();
            for k in 1..s.points.len().saturating_sub(1) {
                self.positions.push(s.points[k]);
                let n = s.normals.get(k).copied().unwrap_or_else(Vector3::z);
                self.normals.push(n);
                self.primary.push(self.primary.len());
            }
            let end = self.positions.len();
            match self.guides.last_mut() {
                Some((c, r)) if *c == s.curve && r.end == self.inner[si] => r.end = end,
                _ => self.guides.push((s.curve, self.inner[si]..end)),
            }
        }
        self.guided = self.positions.len() - self.constrained;
    }

    /// Global id of point `k` of segment `si`, seen from a patch: at the half-edge's start
    /// node (`k` its first point in the patch's order) the patch's `sector` there, inside the
    /// segment the face the patch takes (`across`: a crease's other face).
    fn id(&self, net: &NetworkSegments, si: usize, k: usize, sector: usize, across: bool) -> usize {
        let s = &net.segments[si];
        let node = if k == 0 {
            Some(s.a)
        } else if k + 1 == s.points.len() {
            Some(s.b)
        } else {
            None
        };
        match node {
            Some(v) if sector > 0 => self.sector_id[&(v, sector)],
            Some(v) => self.node_id[&v],
            None if across => self.inner_across[&si] + k - 1,
            None => self.inner[si] + k - 1,
        }
    }
}

fn is_guide(s: &super::super::cycles::Segment) -> bool {
    s.kind == crate::curve::CurveKind::Guide
}

/// A patch's boundary loop: global ids, points and normals.
type Loop = (Vec<usize>, Vec<Vector3<f64>>, Vec<Vector3<f64>>);

/// Each patch's boundary loop, in patch order.
fn patch_loops(net: &NetworkSegments, cyc: &Cycles, v: &Vertices) -> Vec<Loop> {
    cyc.patches
        .iter()
        .enumerate()
        .map(|(pi, cyc)| {
            let (mut ids, mut poly, mut pn) = (Vec::new(), Vec::new(), Vec::new());
            for (e, h) in cyc.edges.iter().enumerate() {
                let s = &net.segments[h.segment];
                let m = s.points.len();
                let across = v.split.takes_across[pi][e];
                for j in 0..m - 1 {
                    let k = if h.forward { j } else { m - 1 - j };
                    let sector = if j == 0 {
                        v.split.corner_sector[pi][e]
                    } else {
                        0
                    };
                    let g = v.id(net, h.segment, k, sector, across);
                    ids.push(g);
                    poly.push(s.points[k]);
                    pn.push(v.normals[g]);
                }
            }
            (ids, poly, pn)
        })
        .collect()
}

/// Each patch's cycle as the kept faces know it ([`FaceKey`]).
fn face_keys(net: &NetworkSegments, cyc: &Cycles, split: &creases::Split) -> Vec<FaceKey> {
    cyc.patches
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
        .collect()
}

/// Each patch's face, in patch order: the kept one (from `reused`, with `true`), or its loop
/// tessellated at `edge` with its planar weights (on worker threads).
fn tessellate_misses(
    loops: &[Loop],
    mut reused: Vec<Option<Face>>,
    edge: f64,
) -> Vec<Result<(Face, bool), TessellateError>> {
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
    (0..loops.len())
        .map(|pi| match reused[pi].take() {
            Some(f) => Ok((f, true)),
            None => built.next().expect("one per miss").map(|f| (f, false)),
        })
        .collect()
}

/// `f` over `items` on up to [`WORKERS`] threads, results in the order of `items`.
pub(super) fn parallel_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
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
