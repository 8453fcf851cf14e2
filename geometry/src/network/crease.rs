//! The other face of a crease curve (issue 18).
//!
//! A crease curve (key `K`) runs along a sharp edge with the device resting on one of the two
//! faces: its measured normal `N` is that face's, `A`. The other face, `B`, is never touched
//! by the device along the crease; it is known only from the curves that meet the crease at
//! its nodes: a curve leaving the node into face `B` has its tangent in `B` there, and `B`
//! contains the crease's tangent `T`, so `B`'s normal is perpendicular to both.
//!
//! In the crease's own frame `[T B N]` (`B = N × T`, the left of travel) a direction `w` leaving
//! the node is seen in the `(B, N)` plane, at angle `φ = atan2(w·N, w·B)`:
//!
//! - `|w·N|` small against `|(w·B, w·N)|` (within [`IN_FACE_DEG`]): `w` lies in face `A`, and
//!   the sign of `w·B` says on which side of the crease face `A` lies (`s = ±1`). Every
//!   direction of the curve's nodes votes: a curve rests on one face all along (a box's top
//!   perimeter keeps the top on its left).
//! - otherwise `w` lies in face `B`. Unfolding the surface about the crease takes face `A`'s
//!   flat continuation (`−s B`) onto `w`; the same rotation about `T` takes `N` to `B`'s normal,
//!   which is `sin θ B + cos θ N` with `θ = π − φ` (`s = +1`) or `θ = −φ` (`s = −1`).
//!   (The sign cannot come from `N` alone: on a box, `B`'s normal is perpendicular to `N`.)
//!
//! `θ` is estimated at both ends of every segment (directions averaged over the samples
//! [`WINDOW`] sampling steps from the node, beyond the pre-filter's blur of the kink), and
//! interpolated along the segment in arc length: a rotation about the crease's own tangent,
//! so the other face's normal follows the crease's frames (interpolation on SO(3) relative
//! to them). An end with no direction into face `B` takes the segment's other end, or the
//! neighbouring segments'; the free end of a crease (a dart: it ends inside a face) has
//! `θ = 0`, the crease fading out. A crease whose side or angle is not known anywhere keeps
//! no other face and is surfaced as a smooth curve, with a warning naming it.

use super::poisson::{CurvePositions, Positions};
use crate::curve::CurveKind;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// A direction within this angle of face `A`'s plane lies in face `A`, degrees.
pub const IN_FACE_DEG: f64 = 20.0;

/// Directions at least this far from the crease's line count (nearer: the crease's own
/// continuation), degrees.
pub const OFF_LINE_DEG: f64 = 20.0;

/// Directions and frames are averaged over the samples this many sampling steps from the
/// node (from, to).
pub const WINDOW: (f64, f64) = (3.0, 8.0);

/// Why a crease keeps no other face.
#[derive(Debug, Clone, PartialEq)]
pub enum CreaseUnknown {
    /// No curve leaves any of its nodes into the face it rested on (which side of the edge
    /// that face lies is unknown).
    Side { curve: usize },
    /// No curve leaves any of its nodes into the other face.
    OtherFace { curve: usize },
}

impl CreaseUnknown {
    pub fn curve(&self) -> usize {
        match self {
            CreaseUnknown::Side { curve } | CreaseUnknown::OtherFace { curve } => *curve,
        }
    }
}

impl std::fmt::Display for CreaseUnknown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CreaseUnknown::Side { curve } => write!(
                f,
                "crease curve {curve}: no curve leaves its nodes into the face the device rested on, so the side of that face is unknown; surfaced as a smooth curve"
            ),
            CreaseUnknown::OtherFace { curve } => write!(
                f,
                "crease curve {curve}: no curve leaves its nodes into the other face, whose normal is unknown; surfaced as a smooth curve"
            ),
        }
    }
}

/// Fills `across` of every crease curve of `p` (see the module docs); the creases that keep
/// none, and why.
pub fn other_faces(p: &mut Positions) -> Vec<CreaseUnknown> {
    let mut out = Vec::new();
    if p.curves.iter().all(|c| c.kind != CurveKind::Crease) {
        return out;
    }
    let arcs: Vec<Vec<f64>> = p.curves.iter().map(|d| arclen(&d.points)).collect();
    // Where each node is tagged: (curve, tag).
    let mut at: NodeTags = BTreeMap::new();
    for (dj, d) in p.curves.iter().enumerate() {
        for (k, &(_, node)) in d.nodes.iter().enumerate() {
            at.entry(node).or_default().push((dj, k));
        }
    }
    for ci in 0..p.curves.len() {
        if p.curves[ci].kind != CurveKind::Crease {
            continue;
        }
        match other_face(&p.curves, &arcs, &at, ci) {
            Ok(across) => p.curves[ci].across = across,
            Err(e) => {
                p.curves[ci].across.clear();
                out.push(e);
            }
        }
    }
    out
}

/// Arc length at each sample.
fn arclen(points: &[Vector3<f64>]) -> Vec<f64> {
    let mut s = vec![0.0; points.len()];
    for j in 1..points.len() {
        s[j] = s[j - 1] + (points[j] - points[j - 1]).norm();
    }
    s
}

/// The mean of `f(j)` over the samples of `c` between `WINDOW` steps from sample `i` going
/// `dir` (±1), not past sample `stop`; `None` when there is no sample there.
fn window_mean(
    c: &CurvePositions,
    s: &[f64],
    i: usize,
    dir: isize,
    stop: usize,
    f: impl Fn(usize) -> Vector3<f64>,
) -> Option<Vector3<f64>> {
    let n = c.points.len();
    if n < 2 {
        return None;
    }
    let step = s[n - 1] / (n - 1) as f64;
    let reach = (s[i] - s[stop]).abs();
    // Within half the way to the stop, and at least one sample.
    let (lo, hi) = (
        (WINDOW.0 * step).min(0.25 * reach),
        (WINDOW.1 * step).min(0.5 * reach),
    );
    let mut sum = Vector3::zeros();
    let mut j = i as isize;
    loop {
        j += dir;
        if j < 0 || j as usize >= n {
            break;
        }
        let ju = j as usize;
        let d = (s[ju] - s[i]).abs();
        if d > hi + 1e-12 {
            break;
        }
        if d >= lo - 1e-12 {
            sum += f(ju);
        }
        if ju == stop {
            break;
        }
    }
    if sum.norm() > 0.0 {
        Some(sum)
    } else {
        None
    }
}

/// What the directions at one end of a crease segment say.
#[derive(Default)]
struct EndVotes {
    /// Σ sign(w·B)·ρ over the directions in face A.
    side: f64,
    /// Σ ρ·(cos φ, sin φ) over the directions in face B (φ in the (B, N) plane).
    into_b: Option<(f64, f64)>,
}

/// Per node, where it is tagged: (curve, tag).
type NodeTags = BTreeMap<u32, Vec<(usize, usize)>>;

/// The other face of crease `ci` of `curves` (`arcs`: every curve's arc lengths; `at`: where
/// each node is tagged).
fn other_face(
    curves: &[CurvePositions],
    arcs: &[Vec<f64>],
    at: &NodeTags,
    ci: usize,
) -> Result<Vec<Vector3<f64>>, CreaseUnknown> {
    let c = &curves[ci];
    let curve = c.index;
    // Per segment, per end: the votes.
    let mut ends: Vec<[EndVotes; 2]> = Vec::new();
    let mut side_total = 0.0;
    for w in c.nodes.windows(2) {
        let ((i0, a), (i1, b)) = (w[0], w[1]);
        let mut votes: [EndVotes; 2] = Default::default();
        for (e, (i, node, dir, stop)) in [(i0, a, 1isize, i1), (i1, b, -1isize, i0)]
            .into_iter()
            .enumerate()
        {
            let end = CreaseEnd {
                ci,
                i,
                node,
                dir,
                stop,
            };
            if let Some(v) = end_votes(curves, arcs, at, &end) {
                side_total += v.side;
                votes[e] = v;
            }
        }
        ends.push(votes);
    }
    if side_total == 0.0 {
        return Err(CreaseUnknown::Side { curve });
    }
    let open = c.nodes.first().map(|x| x.1) != c.nodes.last().map(|x| x.1);
    let theta =
        end_angles(&ends, side_total.signum(), open).ok_or(CreaseUnknown::OtherFace { curve })?;
    Ok(turn_between_ends(c, &arcs[ci], &theta))
}

/// One end of a segment of a crease: curve `ci`, its sample `i` at `node`, the segment
/// running in direction `dir` (±1) to sample `stop`.
struct CreaseEnd {
    ci: usize,
    i: usize,
    node: u32,
    dir: isize,
    stop: usize,
}

/// The votes of the other curves at one end of a crease segment: every direction leaving
/// the node along a curve (but this end's own), in the crease's frame there (T along its
/// travel); `None` when the crease has no frame there.
fn end_votes(
    curves: &[CurvePositions],
    arcs: &[Vec<f64>],
    at: &NodeTags,
    end: &CreaseEnd,
) -> Option<EndVotes> {
    let &CreaseEnd {
        ci,
        i,
        node,
        dir,
        stop,
    } = end;
    let c = &curves[ci];
    let s = &arcs[ci];
    let in_face = IN_FACE_DEG.to_radians().sin();
    let off_line = OFF_LINE_DEG.to_radians().sin();
    let t = window_mean(c, s, i, dir, stop, |j| c.tangents[j])?;
    let nn = window_mean(c, s, i, dir, stop, |j| c.normals[j]).unwrap_or(c.normals[i]);
    let t = t.try_normalize(1e-12)?;
    let nn = (nn - t * nn.dot(&t)).try_normalize(1e-12)?;
    let bb = nn.cross(&t);
    let mut votes = EndVotes::default();
    let mut into = (0.0, 0.0);
    for &(dj, k) in at.get(&node).map_or(&[][..], |v| v.as_slice()) {
        let d = &curves[dj];
        let di = d.nodes[k].0;
        for ddir in [1isize, -1] {
            // Along its segment to the next (or previous) tag of d.
            let stop_k = if ddir > 0 {
                d.nodes.get(k + 1)
            } else {
                k.checked_sub(1).and_then(|k| d.nodes.get(k))
            };
            let Some(&(dstop, _)) = stop_k else { continue };
            if dj == ci && di == i && dstop == stop {
                continue; // this very end
            }
            let Some(wv) = window_mean(d, &arcs[dj], di, ddir, dstop, |j| {
                d.tangents[j] * ddir as f64
            }) else {
                continue;
            };
            let Some(wv) = wv.try_normalize(1e-12) else {
                continue;
            };
            let (wb, wn) = (wv.dot(&bb), wv.dot(&nn));
            let rho = wb.hypot(wn);
            if rho < off_line {
                continue;
            }
            if wn.abs() < in_face * rho {
                votes.side += wb.signum() * rho;
            } else {
                into.0 += wb;
                into.1 += wn;
            }
        }
    }
    if into.0.hypot(into.1) > 0.0 {
        votes.into_b = Some(into);
    }
    Some(votes)
}

/// The angle of the other face at each end of each segment (from the measured normal,
/// towards the side `sgn` says), from the votes into it; the free ends of an open crease
/// with none are a dart (0); missing ends from the segment's other end, then from the
/// nearest segment. `None` when no end has any.
fn end_angles(ends: &[[EndVotes; 2]], sgn: f64, open: bool) -> Option<Vec<[Option<f64>; 2]>> {
    let theta_of = |(cb, sn): (f64, f64)| -> f64 {
        let phi = sn.atan2(cb);
        if sgn > 0.0 {
            PI - phi
        } else {
            -phi
        }
    };
    let last = ends.len().saturating_sub(1);
    let mut theta: Vec<[Option<f64>; 2]> = ends
        .iter()
        .enumerate()
        .map(|(g, v)| {
            let mut t = [v[0].into_b.map(theta_of), v[1].into_b.map(theta_of)];
            if open && g == 0 && t[0].is_none() {
                t[0] = Some(0.0);
            }
            if open && g == last && t[1].is_none() {
                t[1] = Some(0.0);
            }
            t
        })
        .collect();
    for t in &mut theta {
        let (a, b) = (t[0], t[1]);
        t[0] = a.or(b);
        t[1] = b.or(a);
    }
    let known: Vec<usize> = (0..theta.len())
        .filter(|&g| theta[g][0].is_some())
        .collect();
    if known.is_empty() {
        return None;
    }
    for g in 0..theta.len() {
        if theta[g][0].is_none() {
            let k = *known
                .iter()
                .min_by_key(|&&k| k.abs_diff(g))
                .expect("non-empty");
            let v = if k < g { theta[k][1] } else { theta[k][0] };
            theta[g] = [v, v];
        }
    }
    Some(theta)
}

/// The other face's normal at every sample of crease `c` (`s` its arc lengths): the measured
/// normal turned about the tangent by the angle interpolated along each segment between its
/// ends' (`theta`), the shorter way round.
fn turn_between_ends(
    c: &CurvePositions,
    s: &[f64],
    theta: &[[Option<f64>; 2]],
) -> Vec<Vector3<f64>> {
    let n = c.points.len();
    let mut across = vec![Vector3::zeros(); n];
    for (g, w) in c.nodes.windows(2).enumerate() {
        let ((i0, _), (i1, _)) = (w[0], w[1]);
        let (t0, t1) = (theta[g][0].unwrap_or(0.0), theta[g][1].unwrap_or(0.0));
        let dt = (t1 - t0 + PI).rem_euclid(2.0 * PI) - PI;
        let span = (s[i1] - s[i0]).max(f64::MIN_POSITIVE);
        for j in i0..=i1.min(n - 1) {
            let u = ((s[j] - s[i0]) / span).clamp(0.0, 1.0);
            let th = t0 + dt * u;
            let nn = c.normals[j];
            let t = c.tangents[j];
            let bb = nn.cross(&t).try_normalize(1e-12).unwrap_or_else(|| {
                nn.cross(&Vector3::x())
                    .try_normalize(1e-12)
                    .unwrap_or(Vector3::y())
            });
            across[j] = (bb * th.sin() + nn * th.cos()).normalize();
        }
    }
    across
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curve::CurveKind;

    /// A straight polyline from `a` to `b` with `m` steps, constant normal.
    fn line(
        index: usize,
        kind: CurveKind,
        a: Vector3<f64>,
        b: Vector3<f64>,
        normal: Vector3<f64>,
        nodes: (u32, u32),
        m: usize,
    ) -> CurvePositions {
        let t = (b - a).normalize();
        CurvePositions {
            index,
            kind,
            points: (0..=m)
                .map(|k| a + (b - a) * (k as f64 / m as f64))
                .collect(),
            normals: vec![normal; m + 1],
            tangents: vec![t; m + 1],
            across: Vec::new(),
            nodes: vec![(0, nodes.0), (m, nodes.1)],
            d: Vec::new(),
            sigma_m: Vec::new(),
        }
    }

    /// The top-front edge of a box (x from 0 to 1 at y = 0, z = 0; top face z = 0 on y > 0,
    /// front face y = 0 on z < 0), the crease resting on the top (normal +z) or on the front
    /// (normal −y), travelled either way, with a curve leaving its ends into each face.
    #[test]
    fn the_other_face_of_a_box_edge_from_the_curves_at_its_ends() {
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        for (rest, other) in [(z, -y), (-y, z)] {
            for forward in [true, false] {
                let (a, b) = if forward {
                    (Vector3::zeros(), x)
                } else {
                    (x, Vector3::zeros())
                };
                let edge = line(0, CurveKind::Crease, a, b, rest, (0, 1), 100);
                let mut curves = vec![edge];
                for (k, (p, node)) in [(Vector3::zeros(), 0u32), (x, 1)].into_iter().enumerate() {
                    // Into the top (+y) and down the front (−z), 0.3 long.
                    curves.push(line(
                        1 + 2 * k,
                        CurveKind::Interior,
                        p,
                        p + y * 0.3,
                        z,
                        (node, 10 + node),
                        30,
                    ));
                    curves.push(line(
                        2 + 2 * k,
                        CurveKind::Interior,
                        p,
                        p - z * 0.3,
                        -y,
                        (node, 20 + node),
                        30,
                    ));
                }
                let mut p = Positions {
                    curves,
                    nodes: Default::default(),
                    components: 1,
                    misfit: Default::default(),
                };
                let unknown = other_faces(&mut p);
                assert!(unknown.is_empty(), "{unknown:?}");
                for n in &p.curves[0].across {
                    assert!((n - other).norm() < 1e-9, "rest {rest}: {n} for {other}");
                }
            }
        }
    }

    #[test]
    fn a_crease_with_nothing_at_its_nodes_keeps_no_other_face() {
        let (x, z) = (Vector3::x(), Vector3::z());
        let mut p = Positions {
            curves: vec![line(
                7,
                CurveKind::Crease,
                Vector3::zeros(),
                x,
                z,
                (0, 1),
                50,
            )],
            nodes: Default::default(),
            components: 1,
            misfit: Default::default(),
        };
        assert_eq!(other_faces(&mut p), [CreaseUnknown::Side { curve: 7 }]);
        assert!(p.curves[0].across.is_empty());
    }
}
