//! Cycles from normals (Stanko et al. 2016, §3.2): the faces of the curve network.
//!
//! At every node the incident segments are sorted by angle around the node's normal; a face
//! is traced by leaving each node along the segment that comes next *clockwise* after the one
//! it arrived by, so that every face lies on the left of its boundary seen from outside (the
//! side the normals point to). Every segment is traversed once in each direction, so the
//! directed segments fall into faces exactly. Faces made only of boundary-tagged segments
//! whose corners show the surface lying on the other side are the outer faces (holes), not
//! patches.
//!
//! The cell complex is then checked: every segment in at most two patches, no face that uses
//! a segment in both directions (a dangling curve or a bridge), and the Euler characteristic
//! `V − E + F` (outer faces counted as caps) even and at most 2 per connected part. Failures
//! are explained in words naming the nodes and curves, and faces that fail are not patches.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs_geometry::curve::CurveKind;
//! use sfs_geometry::surface::cycles::{cycles, NetworkSegments};
//! // A square in the plane z = 0 seen from +z: χ = 4 − 4 + 2 = 2.
//! let p = |x: f64, y: f64| Vector3::new(x, y, 0.0);
//! let mut net = NetworkSegments::default();
//! let pts = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
//! for (k, (a, b)) in [(0u32, 1u32), (1, 2), (2, 3), (3, 0)].into_iter().enumerate() {
//!     let line = vec![pts[a as usize], pts[b as usize]];
//!     net.push(k, CurveKind::Boundary, (a, b), line, vec![Vector3::z(); 2]);
//! }
//! for n in 0..4 {
//!     net.set_normal(n, Vector3::z());
//! }
//! // Tagged as boundary: the side facing +z is the patch, the other the outside.
//! let c = cycles(&net);
//! assert_eq!((c.patches.len(), c.outer.len(), c.euler), (1, 1, 2));
//! assert!(c.problems.is_empty());
//! ```

use super::{Span, SurfaceProblem};
use crate::curve::CurveKind;
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// One segment of a curve between two consecutive node tags.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Scan index of the curve and position of the segment in it (0 = first).
    pub curve: usize,
    pub k: usize,
    /// What its curve means for the surface.
    pub kind: CurveKind,
    /// Nodes at its start and end.
    pub a: u32,
    pub b: u32,
    /// Its points from `a` to `b` (at least two).
    pub points: Vec<Vector3<f64>>,
    /// Unit surface normals at the points (of a crease: the face the device rested on).
    pub normals: Vec<Vector3<f64>>,
    /// A crease's other face: its unit normals at the points (empty for other kinds, or a
    /// crease whose other face is unknown, which is then surfaced as an interior curve).
    pub across: Vec<Vector3<f64>>,
}

impl Segment {
    /// Lies on the boundary of the surface.
    pub fn boundary(&self) -> bool {
        self.kind == CurveKind::Boundary
    }

    /// A sharp edge with both faces' normals: the surface is split along it.
    pub fn crease(&self) -> bool {
        self.kind == CurveKind::Crease && self.across.len() == self.points.len()
    }

    /// Keeps the points (and their normals) at the increasing indices `keep`.
    fn keep(&mut self, keep: &[usize]) {
        if keep.len() == self.points.len() {
            return;
        }
        let pick = |v: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
            keep.iter().filter_map(|&k| v.get(k).copied()).collect()
        };
        let n = self.points.len();
        if self.normals.len() == n {
            self.normals = pick(&self.normals);
        }
        if self.across.len() == n {
            self.across = pick(&self.across);
        }
        self.points = pick(&self.points);
    }

    /// Direction leaving its start (`at_end = false`) or its end, along the segment: from the
    /// end point to the first point at least 1 % of the segment's length away (robust to
    /// repeated points).
    fn leaving(&self, at_end: bool) -> Vector3<f64> {
        let pts = &self.points;
        let n = pts.len();
        let len: f64 = pts.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let (p0, rest): (Vector3<f64>, Box<dyn Iterator<Item = &Vector3<f64>>>) = if at_end {
            (pts[n - 1], Box::new(pts[..n - 1].iter().rev()))
        } else {
            (pts[0], Box::new(pts[1..].iter()))
        };
        let mut last = Vector3::zeros();
        for q in rest {
            last = q - p0;
            if last.norm() >= 0.01 * len {
                break;
            }
        }
        last
    }
}

/// The segments of a network and the normals at its nodes: the input of [`cycles`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetworkSegments {
    pub segments: Vec<Segment>,
    /// Unit normal at each node (e.g. the mean of the curves' normals there).
    pub normals: BTreeMap<u32, Vector3<f64>>,
}

impl NetworkSegments {
    /// Adds the segment of curve `curve` (of kind `kind`) from node `a` to node `b` through
    /// `points` with surface `normals` (one per point).
    ///
    /// Interior points that coincide with the point before them (or with the end) are dropped,
    /// with their normals: a patch boundary needs distinct points.
    pub fn push(
        &mut self,
        curve: usize,
        kind: CurveKind,
        (a, b): (u32, u32),
        points: Vec<Vector3<f64>>,
        normals: Vec<Vector3<f64>>,
    ) {
        self.push_crease(curve, kind, (a, b), points, normals, Vec::new());
    }

    /// As [`push`](Self::push), with a crease's other face's normals `across` (one per point,
    /// or none).
    pub fn push_crease(
        &mut self,
        curve: usize,
        kind: CurveKind,
        (a, b): (u32, u32),
        points: Vec<Vector3<f64>>,
        normals: Vec<Vector3<f64>>,
        across: Vec<Vector3<f64>>,
    ) {
        let k = self.segments.iter().filter(|s| s.curve == curve).count();
        self.push_kth(curve, k, kind, (a, b), points, normals, across);
    }

    /// [`push_crease`](Self::push_crease) of the curve's `k`-th segment (`k` the curve's
    /// segments pushed before it: a caller that pushes many counts them, instead of every
    /// push counting over the network's).
    #[allow(clippy::too_many_arguments)]
    fn push_kth(
        &mut self,
        curve: usize,
        k: usize,
        kind: CurveKind,
        (a, b): (u32, u32),
        points: Vec<Vector3<f64>>,
        normals: Vec<Vector3<f64>>,
        across: Vec<Vector3<f64>>,
    ) {
        let mut s = Segment {
            curve,
            k,
            kind,
            a,
            b,
            points,
            normals,
            across,
        };
        s.keep(&distinct(&s.points));
        self.segments.push(s);
    }

    /// A copy whose segments have distinct consecutive points (see [`push`](Self::push)),
    /// whatever was written into the public fields.
    pub fn cleaned(&self) -> Self {
        let mut out = self.clone();
        for s in &mut out.segments {
            let keep = distinct(&s.points);
            s.keep(&keep);
        }
        out
    }

    /// A copy whose segments keep, of their interior samples, only those at least `step`
    /// (arc length) after the last one kept and before the end: the patch boundaries of a
    /// surface whose triangles are much larger than the network's sampling. Deterministic per
    /// segment, so the patches on both sides still share every boundary vertex.
    pub fn decimated(&self, step: f64) -> Self {
        self.keeping(&self.decimation(step))
    }

    /// Per segment, the samples [`decimated`](Self::decimated) keeps (indices, both ends
    /// included).
    pub fn decimation(&self, step: f64) -> Vec<Vec<usize>> {
        self.segments
            .iter()
            .map(|s| {
                let m = s.points.len();
                if m <= 2 {
                    return (0..m).collect();
                }
                let total: f64 = s.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
                let mut keep = vec![0];
                let (mut run, mut along) = (0.0, 0.0);
                for k in 1..m - 1 {
                    let l = (s.points[k] - s.points[k - 1]).norm();
                    run += l;
                    along += l;
                    if run >= step && total - along >= 0.5 * step {
                        keep.push(k);
                        run = 0.0;
                    }
                }
                keep.push(m - 1);
                keep
            })
            .collect()
    }

    /// A copy whose segments keep the samples `keep` lists for them (one list per segment,
    /// increasing indices, both ends included).
    pub fn keeping(&self, keep: &[Vec<usize>]) -> Self {
        let mut out = self.clone();
        for (s, k) in out.segments.iter_mut().zip(keep) {
            if k.len() < s.points.len() {
                s.keep(k);
            }
        }
        out
    }

    pub fn set_normal(&mut self, node: u32, n: Vector3<f64>) {
        self.normals.insert(node, n);
    }

    /// The segments of reconstructed curves (`crate::network::poisson::Positions`), with node
    /// normals averaged over the curves through each node (both faces of a crease: a box's
    /// corner takes the mean of its three faces).
    pub fn from_positions(p: &crate::network::poisson::Positions) -> Self {
        let mut net = NetworkSegments::default();
        let mut sums: BTreeMap<u32, Vector3<f64>> = BTreeMap::new();
        // Each curve's segments pushed so far (issue 51: counted over the network's at every
        // push, 126 ms of a 200-curve grid's update).
        let mut pushed: std::collections::HashMap<usize, usize> = Default::default();
        for c in &p.curves {
            let crease = c.across.len() == c.points.len();
            for w in c.nodes.windows(2) {
                let ((i, a), (j, b)) = (w[0], w[1]);
                if j > i {
                    let k = pushed.entry(c.index).or_default();
                    net.push_kth(
                        c.index,
                        std::mem::replace(k, *k + 1),
                        c.kind,
                        (a, b),
                        c.points[i..=j].to_vec(),
                        c.normals[i..=j].to_vec(),
                        if crease {
                            c.across[i..=j].to_vec()
                        } else {
                            Vec::new()
                        },
                    );
                }
            }
            for &(i, n) in &c.nodes {
                let sum = sums.entry(n).or_insert_with(Vector3::zeros);
                *sum += c.normals[i];
                if crease {
                    *sum += c.across[i];
                }
            }
        }
        for (n, s) in sums {
            if let Some(u) = s.try_normalize(1e-12) {
                net.normals.insert(n, u);
            }
        }
        net
    }
}

/// The indices of the points to keep: interior points within a billionth of the segment's
/// length of the previous kept point or of the last point are dropped.
fn distinct(points: &[Vector3<f64>]) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let len: f64 = points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let eps = 1e-9 * len.max(f64::MIN_POSITIVE);
    let last = points[n - 1];
    let mut keep = vec![0];
    for i in 1..n - 1 {
        let prev = points[*keep.last().expect("first kept")];
        if (points[i] - prev).norm() > eps && (points[i] - last).norm() > eps {
            keep.push(i);
        }
    }
    keep.push(n - 1);
    keep
}

/// A segment traversed forwards (`a → b`) or backwards.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct HalfEdge {
    pub segment: usize,
    pub forward: bool,
}

impl HalfEdge {
    fn twin(self) -> Self {
        HalfEdge {
            segment: self.segment,
            forward: !self.forward,
        }
    }

    /// The node it leaves from.
    pub(crate) fn start(self, net: &NetworkSegments) -> u32 {
        let s = &net.segments[self.segment];
        if self.forward {
            s.a
        } else {
            s.b
        }
    }
}

/// A face: its half-edges in order, the face on their left seen from the normals' side.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    pub edges: Vec<HalfEdge>,
}

impl Cycle {
    /// Nodes at the start of each half-edge.
    pub fn nodes(&self, net: &NetworkSegments) -> Vec<u32> {
        self.edges.iter().map(|h| h.start(net)).collect()
    }

    /// Its boundary polyline (closed; the last point is not repeated).
    pub fn polyline(&self, net: &NetworkSegments) -> Vec<Vector3<f64>> {
        let mut out = Vec::new();
        for h in &self.edges {
            let pts = &net.segments[h.segment].points;
            if h.forward {
                out.extend_from_slice(&pts[..pts.len() - 1]);
            } else {
                out.extend(pts[1..].iter().rev());
            }
        }
        out
    }
}

/// The faces of the network and what was wrong with it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cycles {
    /// Faces to surface.
    pub patches: Vec<Cycle>,
    /// Faces bounded by boundary curves on the outside of the surface (holes).
    pub outer: Vec<Cycle>,
    /// Faces that are neither (they failed a check; explained in `problems`).
    pub rejected: Vec<Cycle>,
    /// `V − E + F` over the traced complex (outer faces counted).
    pub euler: i64,
    /// Connected parts of the network.
    pub components: usize,
    /// Each failure in words, naming nodes and curves.
    pub problems: Vec<SurfaceProblem>,
}

fn describe(net: &NetworkSegments, h: HalfEdge) -> Span {
    let s = &net.segments[h.segment];
    Span {
        curve: s.curve,
        a: s.a,
        b: s.b,
    }
}

/// Traces the faces of `net` (see the module docs).
pub fn cycles(net: &NetworkSegments) -> Cycles {
    let mut out = Cycles::default();
    let rot = Rotation::of(net, &mut out.problems);
    let faces = rot.faces(net, &mut out);
    euler_check(net, &rot, faces.len(), &mut out);
    flipped_normals(net, &mut out.problems);
    rot.classify(net, faces, &mut out);
    out
}

/// The rotation system: at each node, the half-edges leaving it, sorted counter-clockwise
/// around the node normal (with the angle of each in the tangent plane).
struct Rotation {
    at: BTreeMap<u32, Vec<(f64, HalfEdge)>>,
    /// Every leaving half-edge's node and position in its node's rotation.
    place: BTreeMap<HalfEdge, (u32, usize)>,
}

impl Rotation {
    /// The rotation system of `net`; a node without a normal takes the mean of its segments'
    /// end normals. Half-edges at a node without any normal, or leaving along it, are
    /// `problems`.
    fn of(net: &NetworkSegments, problems: &mut Vec<SurfaceProblem>) -> Self {
        let mut at: BTreeMap<u32, Vec<(f64, HalfEdge)>> = BTreeMap::new();
        let mut fallback: BTreeMap<u32, Vector3<f64>> = BTreeMap::new();
        for s in &net.segments {
            for (node, n) in [(s.a, s.normals.first()), (s.b, s.normals.last())] {
                if let (false, Some(n)) = (net.normals.contains_key(&node), n) {
                    *fallback.entry(node).or_insert_with(Vector3::zeros) += n;
                }
            }
        }
        let fallback: BTreeMap<u32, Vector3<f64>> = fallback
            .into_iter()
            .filter_map(|(k, v)| v.try_normalize(1e-12).map(|u| (k, u)))
            .collect();
        for (si, s) in net.segments.iter().enumerate() {
            for (forward, node) in [(true, s.a), (false, s.b)] {
                let Some(n) = net.normals.get(&node).or_else(|| fallback.get(&node)) else {
                    problems.push(SurfaceProblem::NoNormal {
                        node,
                        curve: s.curve,
                    });
                    continue;
                };
                let h = HalfEdge {
                    segment: si,
                    forward,
                };
                let d = s.leaving(!forward);
                // Angle in a basis of the tangent plane at the node.
                let e1 = if n.x.abs() < 0.9 {
                    Vector3::x()
                } else {
                    Vector3::y()
                };
                let e1 = (e1 - n * n.dot(&e1)).normalize();
                let e2 = n.cross(&e1);
                let dp = d - n * n.dot(&d);
                if dp.norm() < 1e-12 * d.norm().max(1e-300) || !dp.iter().all(|x| x.is_finite()) {
                    problems.push(SurfaceProblem::AlongNormal {
                        span: describe(net, h),
                        node,
                    });
                }
                let angle = dp.dot(&e2).atan2(dp.dot(&e1));
                at.entry(node).or_default().push((angle, h));
            }
        }
        let mut place: BTreeMap<HalfEdge, (u32, usize)> = BTreeMap::new();
        for (&node, list) in at.iter_mut() {
            list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for (i, (_, h)) in list.iter().enumerate() {
                place.insert(*h, (node, i));
            }
        }
        Rotation { at, place }
    }

    /// The next half-edge of a face: arriving at a node by `h`, leave along the one clockwise
    /// after `h`'s twin.
    fn next(&self, net: &NetworkSegments, h: HalfEdge) -> Option<HalfEdge> {
        let (v, i) = *self.place.get(&h.twin())?;
        debug_assert_eq!(v, h.twin().start(net));
        let list = &self.at[&v];
        Some(list[(i + list.len() - 1) % list.len()].1)
    }

    /// Every face traced by [`next`](Self::next) from every half-edge not yet used; a face
    /// that does not close is rejected (`out`).
    fn faces(&self, net: &NetworkSegments, out: &mut Cycles) -> Vec<Cycle> {
        let mut used: BTreeMap<HalfEdge, bool> = self.place.keys().map(|&h| (h, false)).collect();
        let mut faces: Vec<Cycle> = Vec::new();
        let starts: Vec<HalfEdge> = used.keys().copied().collect();
        for h0 in starts {
            if used[&h0] {
                continue;
            }
            let mut edges = vec![];
            let mut h = h0;
            let ok;
            loop {
                if used[&h] {
                    ok = h == h0;
                    break;
                }
                used.insert(h, true);
                edges.push(h);
                match self.next(net, h) {
                    Some(n) => h = n,
                    None => {
                        ok = false;
                        break;
                    }
                }
            }
            if !ok {
                out.problems.push(SurfaceProblem::FaceOpen {
                    along: describe(net, h0),
                });
                out.rejected.push(Cycle { edges });
                continue;
            }
            faces.push(Cycle { edges });
        }
        faces
    }

    /// Sorts the traced `faces` into `out`: rejected if a segment appears in both directions;
    /// outer if all boundary and the surface is on the other side; else a patch (rejected if
    /// it turns clockwise).
    fn classify(&self, net: &NetworkSegments, faces: Vec<Cycle>, out: &mut Cycles) {
        let interior_at: BTreeMap<u32, bool> = self
            .at
            .iter()
            .map(|(&n, l)| {
                (
                    n,
                    l.iter().any(|(_, h)| !net.segments[h.segment].boundary()),
                )
            })
            .collect();
        for f in faces {
            let twice = f
                .edges
                .iter()
                .find(|h| f.edges.contains(&h.twin()))
                .copied();
            if let Some(h) = twice {
                let nodes = f.nodes(net);
                out.problems.push(SurfaceProblem::BothDirections {
                    nodes,
                    along: describe(net, h),
                });
                out.rejected.push(f);
                continue;
            }
            let all_boundary = f.edges.iter().all(|h| net.segments[h.segment].boundary());
            if all_boundary {
                let nodes = f.nodes(net);
                let touches_interior = nodes.iter().any(|n| interior_at[n]);
                let outer = if touches_interior {
                    true
                } else {
                    // Only boundary curves around: the face whose boundary turns clockwise
                    // around the mean normal is the outside.
                    vector_area(&f.polyline(net)).dot(&boundary_normal(net, &f)) < 0.0
                };
                if outer {
                    out.outer.push(f);
                    continue;
                }
            }
            let nodes = f.nodes(net);
            if vector_area(&f.polyline(net)).dot(&boundary_normal(net, &f)) <= 0.0 {
                out.problems.push(SurfaceProblem::Clockwise { nodes });
                out.rejected.push(f);
                continue;
            }
            out.patches.push(f);
        }
    }
}

/// The components (over nodes, by segments) and the Euler characteristic of the traced
/// complex (`faces` closed, the rejected ones in `out` counted too): a problem when it
/// cannot be a set of closed surfaces.
fn euler_check(net: &NetworkSegments, rot: &Rotation, faces: usize, out: &mut Cycles) {
    let nodes: Vec<u32> = rot.at.keys().copied().collect();
    let idx: BTreeMap<u32, usize> = nodes.iter().enumerate().map(|(i, &n)| (n, i)).collect();
    let mut sets = crate::union_find::UnionFind::new(nodes.len());
    let mut edges_used = 0i64;
    for s in &net.segments {
        if let (Some(&a), Some(&b)) = (idx.get(&s.a), idx.get(&s.b)) {
            edges_used += 1;
            sets.union(a, b);
        }
    }
    out.components = sets.roots().count();
    out.euler = nodes.len() as i64 - edges_used + (faces + out.rejected.len()) as i64;
    if out.euler > 2 * out.components as i64 || out.euler % 2 != 0 {
        out.problems.push(SurfaceProblem::NotClosed {
            vertices: nodes.len(),
            edges: edges_used,
            faces: faces + out.rejected.len(),
            euler: out.euler,
            components: out.components,
        });
    }
}

/// Node normals against their neighbours' (a flipped normal reverses a node's rotation):
/// against every neighbour, clearly (on a coarse network, an octahedron's, correct
/// neighbours are at 90°).
fn flipped_normals(net: &NetworkSegments, problems: &mut Vec<SurfaceProblem>) {
    let mut neighbours: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for s in &net.segments {
        if s.a != s.b {
            neighbours.entry(s.a).or_default().push(s.b);
            neighbours.entry(s.b).or_default().push(s.a);
        }
    }
    for (n, list) in &neighbours {
        let Some(nn) = net.normals.get(n) else {
            continue;
        };
        let closest = list
            .iter()
            .filter_map(|m| net.normals.get(m))
            .map(|m| nn.dot(m))
            .fold(f64::MIN, f64::max);
        if list.len() >= 2 && closest < -0.1 {
            problems.push(SurfaceProblem::NormalFlipped {
                node: *n,
                neighbours: list.clone(),
            });
        }
    }
}

/// Vector area of a closed polygon (half the sum of cross products about its centroid).
pub(crate) fn vector_area(poly: &[Vector3<f64>]) -> Vector3<f64> {
    if poly.is_empty() {
        return Vector3::zeros();
    }
    let c = poly.iter().sum::<Vector3<f64>>() / poly.len() as f64;
    let mut area = Vector3::zeros();
    for i in 0..poly.len() {
        area += (poly[i] - c).cross(&(poly[(i + 1) % poly.len()] - c));
    }
    area * 0.5
}

/// Sum of the surface normals along a face's boundary (both faces of a crease: the face's
/// own comes from every crease around it, the others' cancel on a box).
fn boundary_normal(net: &NetworkSegments, f: &Cycle) -> Vector3<f64> {
    f.edges
        .iter()
        .flat_map(|h| {
            let s = &net.segments[h.segment];
            s.normals.iter().chain(&s.across)
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 51: the network of a reconstruction numbers each curve's segments in order along
    /// it (counted per curve as they are pushed, not over the network's at every push), with
    /// each segment's samples between its tags and the mean normal at each node.
    #[test]
    fn issue_51_each_curves_segments_are_numbered_in_order_from_the_positions() {
        use crate::network::poisson::{CurvePositions, Positions};
        let curve = |index: usize, nodes: Vec<(usize, u32)>, n: usize| CurvePositions {
            index,
            kind: CurveKind::Interior,
            points: (0..n)
                .map(|j| Vector3::new(j as f64, index as f64, 0.0))
                .collect(),
            normals: vec![Vector3::z(); n],
            tangents: vec![Vector3::x(); n],
            across: Vec::new(),
            nodes,
            d: Vec::new(),
            sigma_m: Vec::new(),
        };
        let p = Positions {
            curves: vec![
                curve(7, vec![(0, 1), (4, 2), (9, 3)], 10),
                curve(3, vec![(0, 2), (3, 4), (5, 5), (8, 1)], 9),
            ],
            nodes: BTreeMap::new(),
            components: 1,
            misfit: Default::default(),
        };
        let net = NetworkSegments::from_positions(&p);
        let got: Vec<(usize, usize, u32, u32, usize)> = net
            .segments
            .iter()
            .map(|s| (s.curve, s.k, s.a, s.b, s.points.len()))
            .collect();
        assert_eq!(
            got,
            vec![
                (7, 0, 1, 2, 5),
                (7, 1, 2, 3, 6),
                (3, 0, 2, 4, 4),
                (3, 1, 4, 5, 3),
                (3, 2, 5, 1, 4),
            ]
        );
        assert_eq!(net.normals.len(), 5);
        assert!(net
            .normals
            .values()
            .all(|n| (n - Vector3::z()).norm() < 1e-15));
    }

    /// The network of a cube's 12 edges on the unit sphere (great-circle arcs), normals
    /// radial: six four-sided patches, χ = 8 − 12 + 6 = 2. `boundary_top` tags the four edges
    /// between the corners with z > 0 (nodes 4–7) as boundary.
    fn sphere_cube(boundary_top: bool) -> NetworkSegments {
        let mut net = crate::surface::analytic::sphere_cube(0.05);
        for s in &mut net.segments {
            s.kind = if boundary_top && s.a >= 4 && s.b >= 4 {
                CurveKind::Boundary
            } else {
                CurveKind::Interior
            };
        }
        net
    }

    #[test]
    fn sphere_cube_has_six_patches_and_euler_two() {
        let net = sphere_cube(false);
        assert_eq!(net.segments.len(), 12);
        let c = cycles(&net);
        assert!(c.problems.is_empty(), "{:?}", c.problems);
        assert_eq!((c.patches.len(), c.outer.len(), c.euler), (6, 0, 2));
        // Every segment in exactly two patches, once in each direction.
        let mut count: BTreeMap<HalfEdge, usize> = BTreeMap::new();
        for p in &c.patches {
            assert_eq!(p.edges.len(), 4);
            for h in &p.edges {
                *count.entry(*h).or_default() += 1;
            }
        }
        assert_eq!(count.len(), 24);
        assert!(count.values().all(|&n| n == 1));
        // Faces lie to the left seen from outside: each patch's vector area points outwards.
        for p in &c.patches {
            let poly = p.polyline(&net);
            let cen = poly.iter().sum::<Vector3<f64>>() / poly.len() as f64;
            let mut area = Vector3::zeros();
            for i in 0..poly.len() {
                area += (poly[i] - cen).cross(&(poly[(i + 1) % poly.len()] - cen));
            }
            assert!(area.dot(&cen) > 0.0, "patch {:?}", p.nodes(&net));
        }
    }

    #[test]
    fn a_boundary_curve_delimits_an_outer_face() {
        // Remove the top face's interior by tagging its four edges as boundary and dropping
        // nothing: the top face becomes a hole (outer), five patches remain (an open box).
        let net = sphere_cube(true);
        let c = cycles(&net);
        assert!(c.problems.is_empty(), "{:?}", c.problems);
        assert_eq!((c.patches.len(), c.outer.len(), c.euler), (5, 1, 2));
        let mut hole = c.outer[0].nodes(&net);
        hole.sort();
        assert_eq!(hole, [4, 5, 6, 7]);
    }

    #[test]
    fn a_dangling_curve_is_named() {
        let mut net = sphere_cube(false);
        // A curve from node 0 out to a node 8 that nothing else reaches.
        let p0 = net.segments[0].points[0];
        let p8 = (p0 + Vector3::new(0.0, 0.0, 0.3)).normalize();
        let pts = vec![p0, (p0 + p8).normalize(), p8];
        net.push(99, CurveKind::Interior, (0, 8), pts.clone(), pts);
        net.set_normal(8, p8);
        let c = cycles(&net);
        assert_eq!(c.patches.len(), 5, "{:?}", c.problems);
        assert_eq!(c.rejected.len(), 1);
        assert!(
            c.problems.iter().any(|p| matches!(
                p,
                SurfaceProblem::BothDirections { along, .. }
                    if *along == Span { curve: 99, a: 0, b: 8 }
            )),
            "{:?}",
            c.problems
        );
    }

    #[test]
    fn flipped_normal_breaks_the_complex_and_says_so() {
        let mut net = sphere_cube(false);
        let n = net.normals[&3];
        net.set_normal(3, -n);
        let c = cycles(&net);
        assert!(c.patches.len() < 6, "{:?}", c.problems);
        assert!(
            c.problems
                .iter()
                .any(|p| matches!(p, SurfaceProblem::NormalFlipped { node: 3, .. })),
            "{:?}",
            c.problems
        );
    }
}
