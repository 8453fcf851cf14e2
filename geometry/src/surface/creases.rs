//! The surface split along creases (issue 18; Morigi & Rucci 2011's sharpness, Orbay & Kara
//! 2012's crease curves): which normal each patch sees along a crease, and the sectors at the
//! nodes.
//!
//! A crease segment carries two normals per sample: the face the device rested on
//! ([`Segment::normals`]) and the other ([`Segment::across`]). Each of the two patches beside
//! it takes the one whose face lies on its side: the face with normal `n` runs from the crease
//! in the direction `n × t` (`t` along the patch's boundary, the patch on its left), so the
//! patch whose interior (seen from a boundary sample: towards its boundary's centroid) lies
//! further along `n × t` takes `n`. The decision is made once per segment from both patches'
//! views, so the two sides always take different normals.
//!
//! At a node, the corners of the patches around it fall into *sectors*: two corners are in one
//! sector when they share a segment that is not a crease. A node with no crease, or with one
//! crease segment ending there (a *dart* when the node is inside the surface: the crease ends
//! inside a face), has one sector; two
//! crease segments make two (a node along a crease); three or more make a *corner* (Morigi's
//! classification by the number of sharp curves at a vertex). Each sector is a vertex of its
//! own (same position, its own normal: the mean of its patches' normals there), so the
//! patches on either side of a crease are solved with their own boundary normals and meet
//! with G⁰ continuity; the surface is cut along the crease (a viewer shows a sharp edge) and
//! whole again once the copies are identified ([`super::fit::Surfaced::primary`]).

use super::cycles::{Cycle, Cycles, NetworkSegments, Segment};
use crate::union_find::UnionFind;
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// How the patches of a network meet along its creases.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Split {
    /// Per patch, per half-edge: the sector of the patch's corner at the half-edge's start node
    /// (0 for a node with one sector).
    pub corner_sector: Vec<Vec<usize>>,
    /// Per patch, per half-edge: it runs along a crease and the patch takes the crease's other
    /// face (`across`).
    pub takes_across: Vec<Vec<bool>>,
    /// The normal of every sector of the nodes with more than one, in sector order.
    pub sectors: BTreeMap<u32, Vec<Vector3<f64>>>,
    /// Nodes where three or more crease segments meet.
    pub corners: Vec<u32>,
    /// Nodes where one crease segment ends inside a face (not on the boundary).
    pub darts: Vec<u32>,
}

impl Split {
    /// No crease anywhere: one sector per node, no patch takes an other face.
    pub fn is_smooth(&self) -> bool {
        self.sectors.is_empty() && self.takes_across.iter().flatten().all(|x| !x)
    }
}

/// Splits the patches of `cyc` along the creases of `net` (see the module docs).
pub fn split(net: &NetworkSegments, cyc: &Cycles) -> Split {
    let patches = &cyc.patches;
    let takes_across = sides(net, patches);
    let (corners, darts) = corners_and_darts(net);
    let (corner_sector, sectors) = sectors(net, patches, &takes_across);
    Split {
        corner_sector,
        takes_across,
        sectors,
        corners,
        darts,
    }
}

/// Per patch, per half-edge: whether the patch takes the other face of the crease it runs
/// along (the patch on the side the measured face turns towards takes the measured one).
fn sides(net: &NetworkSegments, patches: &[Cycle]) -> Vec<Vec<bool>> {
    // Where each half-edge is used: (patch, position).
    let mut used: BTreeMap<(usize, bool), (usize, usize)> = BTreeMap::new();
    for (pi, p) in patches.iter().enumerate() {
        for (e, h) in p.edges.iter().enumerate() {
            used.insert((h.segment, h.forward), (pi, e));
        }
    }
    let mut takes_across: Vec<Vec<bool>> =
        patches.iter().map(|p| vec![false; p.edges.len()]).collect();
    let centroids: Vec<Vector3<f64>> = patches
        .iter()
        .map(|p| {
            let poly = p.polyline(net);
            poly.iter().sum::<Vector3<f64>>() / poly.len().max(1) as f64
        })
        .collect();
    for (si, s) in net.segments.iter().enumerate() {
        if !s.crease() {
            continue;
        }
        // The middle sample and the tangent there, along the segment.
        let m = s.points.len();
        let j = m / 2;
        let (p0, p1) = (s.points[j.saturating_sub(1)], s.points[(j + 1).min(m - 1)]);
        let Some(t) = (p1 - p0).try_normalize(1e-300) else {
            continue;
        };
        let (na, nb) = (s.normals[j], s.across[j]);
        // How much further the patch lies along n × t (its travel direction ±t) with the
        // measured face than with the other.
        let prefers_measured = |forward: bool| -> Option<f64> {
            let &(pi, _) = used.get(&(si, forward))?;
            let th = if forward { t } else { -t };
            let d = centroids[pi] - s.points[j];
            let d = d - t * t.dot(&d);
            Some(na.cross(&th).dot(&d) - nb.cross(&th).dot(&d))
        };
        let score = prefers_measured(true).unwrap_or(0.0) - prefers_measured(false).unwrap_or(0.0);
        // score ≥ 0: the patch on the forward side takes the measured face.
        for forward in [true, false] {
            if let Some(&(pi, e)) = used.get(&(si, forward)) {
                takes_across[pi][e] = (score >= 0.0) != forward;
            }
        }
    }
    takes_across
}

/// The crease corners (nodes where three or more crease segments meet) and darts (one crease
/// segment ending inside a face, not on the boundary).
fn corners_and_darts(net: &NetworkSegments) -> (Vec<u32>, Vec<u32>) {
    let mut crease_ends: BTreeMap<u32, usize> = BTreeMap::new();
    for s in net.segments.iter().filter(|s| s.crease()) {
        *crease_ends.entry(s.a).or_default() += 1;
        *crease_ends.entry(s.b).or_default() += 1;
    }
    let on_boundary: std::collections::BTreeSet<u32> = net
        .segments
        .iter()
        .filter(|s| s.boundary())
        .flat_map(|s| [s.a, s.b])
        .collect();
    let corners: Vec<u32> = crease_ends
        .iter()
        .filter(|(_, &n)| n >= 3)
        .map(|(&v, _)| v)
        .collect();
    let darts: Vec<u32> = crease_ends
        .iter()
        .filter(|(v, &n)| n == 1 && !on_boundary.contains(v))
        .map(|(&v, _)| v)
        .collect();
    (corners, darts)
}

/// Per patch, per half-edge: the sector of the patch's corner at the half-edge's start node.
type CornerSectors = Vec<Vec<usize>>;

/// The sectors of each node: the corners of the patches around it joined across the
/// segments that are not creases, numbered in the order their first corner comes. Returns
/// each corner's sector and, for nodes with more than one, each sector's normal (the sum of
/// its corners' normals, `takes_across` saying which face of a crease a corner sees).
fn sectors(
    net: &NetworkSegments,
    patches: &[Cycle],
    takes_across: &[Vec<bool>],
) -> (CornerSectors, BTreeMap<u32, Vec<Vector3<f64>>>) {
    let corners_list: Vec<(usize, usize)> = patches
        .iter()
        .enumerate()
        .flat_map(|(pi, p)| (0..p.edges.len()).map(move |e| (pi, e)))
        .collect();
    let index: BTreeMap<(usize, usize), usize> = corners_list
        .iter()
        .enumerate()
        .map(|(k, &c)| (c, k))
        .collect();
    let mut sets = UnionFind::new(corners_list.len());
    // Each segment end: the corners touching it ((segment, at its end b) → corners).
    let mut touching: BTreeMap<(usize, bool), Vec<usize>> = BTreeMap::new();
    for (pi, p) in patches.iter().enumerate() {
        let k = p.edges.len();
        for e in 0..k {
            let (out, inn) = (p.edges[e], p.edges[(e + k - 1) % k]);
            let corner = index[&(pi, e)];
            // Leaving along `out` from its start; arriving by `inn` at its end.
            touching
                .entry((out.segment, !out.forward))
                .or_default()
                .push(corner);
            touching
                .entry((inn.segment, inn.forward))
                .or_default()
                .push(corner);
        }
    }
    for (&(si, _), list) in &touching {
        if net.segments[si].crease() {
            continue;
        }
        for w in list.windows(2) {
            sets.union(w[0], w[1]);
        }
    }
    let mut sector_of_root: BTreeMap<usize, usize> = BTreeMap::new();
    let mut sums: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
    let mut corner_sector: CornerSectors = patches.iter().map(|p| vec![0; p.edges.len()]).collect();
    for (k, &(pi, e)) in corners_list.iter().enumerate() {
        let p = &patches[pi];
        let h = p.edges[e];
        let s = &net.segments[h.segment];
        let node = h.start(net);
        let list = sums.entry(node).or_default();
        let root = sets.find(k);
        let sector = *sector_of_root.entry(root).or_insert_with(|| {
            list.push(Vector3::zeros());
            list.len() - 1
        });
        corner_sector[pi][e] = sector;
        // The patch's normals at the node: the ends of its two half-edges there.
        let kk = p.edges.len();
        let inn = p.edges[(e + kk - 1) % kk];
        let end_normal = |seg: &Segment, at_b: bool, across: bool| -> Vector3<f64> {
            let v = if across { &seg.across } else { &seg.normals };
            let n = if at_b { v.last() } else { v.first() };
            n.copied().unwrap_or_else(Vector3::zeros)
        };
        list[sector] += end_normal(s, !h.forward, takes_across[pi][e]);
        list[sector] += end_normal(
            &net.segments[inn.segment],
            inn.forward,
            takes_across[pi][(e + kk - 1) % kk],
        );
    }
    let sectors = sums
        .into_iter()
        .filter(|(_, v)| v.len() > 1)
        .map(|(node, v)| {
            let fallback = net.normals.get(&node).copied().unwrap_or_else(Vector3::z);
            (
                node,
                v.into_iter()
                    .map(|n| n.try_normalize(1e-12).unwrap_or(fallback))
                    .collect(),
            )
        })
        .collect();
    (corner_sector, sectors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::analytic::{box_distance, box_network};
    use crate::surface::cycles::cycles;
    use crate::surface::fit::{surface, SurfaceParams};

    const SIZE: [f64; 3] = [0.4, 0.3, 0.2];

    /// The outward normal of the box face nearest `p` (its largest relative coordinate).
    fn face_normal(p: &Vector3<f64>) -> Vector3<f64> {
        let h = Vector3::from(SIZE) / 2.0;
        let r = p.component_div(&h);
        let k = r.iamax();
        let mut n = Vector3::zeros();
        n[k] = r[k].signum();
        n
    }

    #[test]
    fn a_box_has_eight_corners_and_its_edges_split_two_sectors() {
        let net = box_network(SIZE, 0.01);
        let cyc = cycles(&net);
        assert!(cyc.problems.is_empty(), "{:?}", cyc.problems);
        assert_eq!((cyc.patches.len(), cyc.euler), (12, 2));
        let split = split(&net, &cyc);
        assert_eq!(split.corners, (0..8).collect::<Vec<u32>>());
        assert!(split.darts.is_empty());
        // Corners have three sectors (the faces), edge middles two.
        for (node, list) in &split.sectors {
            assert_eq!(list.len(), if *node < 8 { 3 } else { 2 }, "node {node}");
        }
        assert_eq!(split.sectors.len(), 16);
        // Every patch takes, along every crease, the normal of its own face.
        for (pi, p) in cyc.patches.iter().enumerate() {
            let poly = p.polyline(&net);
            let own = face_normal(&(poly.iter().sum::<Vector3<f64>>() / poly.len() as f64));
            for (e, h) in p.edges.iter().enumerate() {
                let s = &net.segments[h.segment];
                let n = if split.takes_across[pi][e] {
                    s.across[1]
                } else {
                    s.normals[1]
                };
                assert!(
                    (n - own).norm() < 1e-12,
                    "patch {pi} edge {e}: {n} for {own}"
                );
            }
        }
    }

    /// Issue 18, point 7: a box from exact data is surfaced with planar faces (flatness within
    /// 1e-4 of the diagonal) and exact, sharp edges; welded, it is a closed, consistently
    /// oriented manifold with no flipped triangle.
    #[test]
    fn issue_18_a_box_is_surfaced_with_flat_faces_and_sharp_edges() {
        let net = box_network(SIZE, 0.005);
        let diag = Vector3::from(SIZE).norm();
        let h = Vector3::from(SIZE) / 2.0;
        let s = surface(&net, &SurfaceParams::default()).expect("a surface");
        assert!(s.problems.is_empty(), "{:?}", s.problems);
        assert_eq!(s.corners.len(), 8);
        let worst = s
            .positions
            .iter()
            .map(|p| box_distance(p, &h))
            .fold(0.0, f64::max);
        assert!(
            worst <= 1e-4 * diag,
            "off the box by {:.2e} of the diagonal",
            worst / diag
        );
        // Every triangle lies on one face and faces outwards.
        for t in &s.triangles {
            let [a, b, c] = t.map(|i| s.positions[i as usize]);
            let n = (b - a).cross(&(c - a)).normalize();
            let own = face_normal(&((a + b + c) / 3.0));
            assert!(n.dot(&own) > 1.0 - 1e-6, "triangle {t:?}: normal {n}");
        }
        // The vertex normals are the faces' (a sharp edge: each side its own).
        for (i, n) in s.normals.iter().enumerate() {
            assert!(n.norm() > 0.999, "vertex {i}");
        }
        for t in &s.triangles {
            let [a, b, c] = t.map(|i| s.positions[i as usize]);
            let own = face_normal(&((a + b + c) / 3.0));
            for &i in t {
                let n = s.normals[i as usize];
                assert!(n.dot(&own) > 1.0 - 1e-9, "vertex {i}: {n} on face {own}");
            }
        }
        assert_closed_manifold(&s);
        // Soft constraints: each side pulls its copies its own way; they are welded.
        let soft = SurfaceParams {
            soft: Some(100.0),
            ..SurfaceParams::default()
        };
        let s = surface(&net, &soft).expect("a surface");
        for (i, &p) in s.primary.iter().enumerate() {
            assert_eq!(s.positions[i], s.positions[p], "copy {i} of {p} apart");
        }
        assert_closed_manifold(&s);
    }

    /// Welded (copies mapped to their primary), every edge is in exactly two triangles, once
    /// each way: closed, manifold, consistently oriented.
    fn assert_closed_manifold(s: &crate::surface::fit::Surfaced) {
        let mut edges: BTreeMap<(usize, usize), i32> = BTreeMap::new();
        for t in &s.triangles {
            let w = t.map(|i| s.primary[i as usize]);
            for k in 0..3 {
                *edges.entry((w[k], w[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "edge {a}–{b} used {n} times one way");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "edge {a}–{b} open or non-manifold"
            );
        }
    }

    /// Issue 18, point 7: a crease network never yields a non-manifold or flipped mesh. The
    /// sphere-cube network with a random half of its edges creases, folded by up to ±35°
    /// (constant, or fading out at both ends), hard or soft: welded, the surface is closed,
    /// manifold and consistently oriented, every triangle faces outwards, and the corners are
    /// the nodes where three creases meet.
    #[test]
    fn issue_18_crease_networks_give_manifold_unflipped_meshes() {
        let mut rng = crate::rng::Rng::new(18);
        for case in 0..16 {
            let mut net = crate::surface::analytic::sphere_cube(0.04);
            for seg in net.segments.iter_mut() {
                if rng.uniform() < 0.5 {
                    continue;
                }
                seg.kind = crate::curve::CurveKind::Crease;
                let fold = rng.range(-35.0, 35.0f64).to_radians();
                let fade = rng.uniform() < 0.5;
                let m = seg.points.len();
                seg.across = (0..m)
                    .map(|j| {
                        let u = j as f64 / (m - 1) as f64;
                        let t = (seg.points[(j + 1).min(m - 1)] - seg.points[j.saturating_sub(1)])
                            .normalize();
                        let a = if fade {
                            fold * (std::f64::consts::PI * u).sin()
                        } else {
                            fold
                        };
                        nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(t), a)
                            * seg.normals[j]
                    })
                    .collect();
            }
            let mut ends: BTreeMap<u32, usize> = BTreeMap::new();
            for seg in net.segments.iter().filter(|s| s.crease()) {
                *ends.entry(seg.a).or_default() += 1;
                *ends.entry(seg.b).or_default() += 1;
            }
            let soft = (case % 2 == 1).then_some(0.3);
            let p = SurfaceParams {
                soft,
                ..SurfaceParams::default()
            };
            let s = surface(&net, &p).expect("a surface");
            assert!(s.problems.is_empty(), "case {case}: {:?}", s.problems);
            let corners: Vec<u32> = ends.iter().filter(|e| *e.1 >= 3).map(|e| *e.0).collect();
            assert_eq!(s.corners, corners, "case {case}");
            for t in &s.triangles {
                let [a, b, c] = t.map(|i| s.positions[i as usize]);
                let n = (b - a).cross(&(c - a));
                assert!(
                    n.dot(&(a + b + c)) > 0.0,
                    "case {case}: triangle {t:?} flipped"
                );
            }
            assert_closed_manifold(&s);
        }
    }

    /// Issue 18, point 7: a crease that fades out at both ends inside the surface (darts): a
    /// sphere-cube edge whose faces meet at up to 30°, nothing at its ends. The darts are
    /// named, the nodes keep one vertex, the edge is sharp in its middle, and no triangle
    /// is flipped; welded, the surface is closed and manifold.
    #[test]
    fn issue_18_darts_fade_a_crease_out_without_flips() {
        let mut net = crate::surface::analytic::sphere_cube(0.02);
        let seg = &mut net.segments[0];
        seg.kind = crate::curve::CurveKind::Crease;
        let m = seg.points.len();
        seg.across = (0..m)
            .map(|j| {
                let u = j as f64 / (m - 1) as f64;
                let t =
                    (seg.points[(j + 1).min(m - 1)] - seg.points[j.saturating_sub(1)]).normalize();
                let angle = 30f64.to_radians() * (std::f64::consts::PI * u).sin();
                nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(t), angle)
                    * seg.normals[j]
            })
            .collect();
        let (a, b) = (seg.a.min(seg.b), seg.a.max(seg.b));
        let cyc = cycles(&net);
        let split = split(&net, &cyc);
        assert_eq!(split.darts, [a, b]);
        assert!(split.corners.is_empty() && split.sectors.is_empty());
        let s = surface(&net, &SurfaceParams::default()).expect("a surface");
        assert!(s.problems.is_empty(), "{:?}", s.problems);
        assert_eq!(s.darts, [a, b]);
        for t in &s.triangles {
            let [p, q, r] = t.map(|i| s.positions[i as usize]);
            let n = (q - p).cross(&(r - p));
            assert!(n.dot(&(p + q + r)) > 0.0, "triangle {t:?} flipped");
        }
        assert_closed_manifold(&s);
        // Sharp in the middle: the two copies of the middle sample have their own normals
        // (the sphere's positions pull the fold back to about half of the normals' 30°).
        let mid = net.segments[0].points[m / 2];
        let copies: Vec<usize> = (0..s.positions.len())
            .filter(|&i| (s.positions[i] - mid).norm() < 1e-12)
            .collect();
        assert_eq!(copies.len(), 2, "{copies:?}");
        let angle = s.normals[copies[0]]
            .angle(&s.normals[copies[1]])
            .to_degrees();
        assert!(angle > 10.0, "{angle:.1}° across the middle");
    }
}
