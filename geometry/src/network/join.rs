//! Nodes joined after the fact (issue 34): a node tagged on one curve only, lying where
//! another curve passes, joins that curve as if it had been tagged there while it was
//! scanned.
//!
//! Stanko et al. 2017 (§7) name the limit this removes: a node exists only where the operator
//! tagged it on every curve through it, so a new curve across old ones, or a tag forgotten on
//! one curve of a crossing, left the network untied there (and the surface with an open face).
//!
//! ## The test
//! In the reconstructed network ([`Positions`]), every node (anonymous nodes,
//! [`ANONYMOUS_NODE_BASE`] and above, aside) against every curve that does not tag it: the
//! closest approach of the curve's polyline to the node, the curve's own distance `d` there
//! (interpolated between its samples: the wheel's for a Morphorider, the phone's from its
//! speed), its faces and its tangent there. The node joins the curve of least distance among
//! those that
//! - come within the reach: [`JoinParams::distance_m`], or for a node a single curve tags
//!   (*lonely*: a crossing certainly missing its other curve) more where the network is noisy
//!   ([`find_joins_within`]);
//! - agree in normal within [`JoinParams::normal_deg`] (a crease's two faces span the normals
//!   between them; where two creases meet, at a corner, each face of the node is matched by
//!   one of the curve's within the reach);
//! - cross the node's curves (tangents more than [`ALONGSIDE_DEG`] apart as lines): a curve
//!   running alongside one of them, 20 mm away, is not a crossing;
//! - and leave no segment shorter than one and a half of the curve's steps (a node is
//!   already there).
//!
//! [`apply_joins`] then puts the tag into the scan. The passes that make the joins settle,
//! the parts put together and the refusals are [`super::Reconstructor::run_joined`]'s.
//!
//! ```
//! use sfs_geometry::network::join::{find_joins, JoinParams};
//! use sfs_geometry::network::poisson::{CurvePositions, Positions};
//! use sfs_geometry::curve::CurveKind;
//! use nalgebra::Vector3;
//! // Two straight curves on the plane z = 0 crossing at (0.5, 0.5): the first tags node 9 at
//! // the crossing, the second (nodes 2 → 3) passes it untagged.
//! let line = |index, a: Vector3<f64>, b: Vector3<f64>, nodes: Vec<(usize, u32)>| {
//!     let points: Vec<Vector3<f64>> = (0..=100).map(|k| a + (b - a) * (k as f64 / 100.0)).collect();
//!     CurvePositions {
//!         index,
//!         kind: CurveKind::Interior,
//!         normals: vec![Vector3::z(); 101],
//!         tangents: vec![(b - a).normalize(); 101],
//!         across: Vec::new(),
//!         d: (0..=100).map(|k| k as f64 / 100.0).collect(),
//!         points,
//!         nodes,
//!     }
//! };
//! let a = line(0, Vector3::new(0.0, 0.5, 0.0), Vector3::new(1.0, 0.5, 0.0), vec![(0, 0), (50, 9), (100, 1)]);
//! let b = line(1, Vector3::new(0.5, 0.0, 0.0), Vector3::new(0.5, 1.0, 0.0), vec![(0, 2), (100, 3)]);
//! let nodes = [(0, a.points[0]), (9, a.points[50]), (1, a.points[100]), (2, b.points[0]), (3, b.points[100])]
//!     .into_iter()
//!     .collect();
//! let net = Positions { curves: vec![a, b], nodes, components: 2 };
//! let joins = find_joins(&net, &JoinParams::default());
//! assert_eq!(joins.len(), 1);
//! assert_eq!((joins[0].node, joins[0].curve), (9, 1));
//! assert!((joins[0].d - 0.5).abs() < 1e-9 && joins[0].distance_m < 1e-9);
//! ```

use super::poisson::{CurvePositions, Positions};
use crate::curve::{Curve, CurveKind, Tag, ANONYMOUS_NODE_BASE};
use nalgebra::Vector3;

/// Settings of the joins (`[network] join_distance`, `join_normal_deg`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoinParams {
    /// Closest approach within which a node joins a curve, m. Default 0.015; 0 turns the
    /// joins (and the proposals) off.
    pub distance_m: f64,
    /// Largest angle between the node's normal and the curve's there, degrees. Default 15.
    pub normal_deg: f64,
    /// [`Reconstructor::run_joined`](super::Reconstructor::run_joined) reaches this many
    /// times the network's closure misfit ([`super::NetworkReport::closure_misfit_m`]) when
    /// that is more than `distance_m`: a noisy network's curves miss their crossings by more.
    /// Default 2; 0 when `[network] join_distance` is set (the distance is then the operator's).
    pub noise_factor: f64,
}

impl Default for JoinParams {
    fn default() -> Self {
        JoinParams {
            distance_m: 0.015,
            normal_deg: 15.0,
            noise_factor: 2.0,
        }
    }
}

/// What the reconstruction does with nodes tagged on one curve and with crossings nobody
/// tagged (`[network] join_distance`, `join_normal_deg`, `join_untagged`, `refuse`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JoinSettings {
    pub params: JoinParams,
    /// Crossings nobody tagged ([`Proposal`]s) are joined too, each under a fresh node index
    /// above every tagged one. Default false: they are only proposed.
    pub untagged: bool,
    /// Pairs of curves (scan indices, either order) never joined to each other, nor proposed.
    pub refuse: Vec<(usize, usize)>,
}

impl JoinSettings {
    /// Joins are looked for at all.
    pub fn enabled(&self) -> bool {
        self.params.distance_m > 0.0
    }

    /// The operator refused joins between curves `a` and `b`.
    pub fn refuses(&self, a: usize, b: usize) -> bool {
        self.refuse
            .iter()
            .any(|&(x, y)| (x, y) == (a, b) || (x, y) == (b, a))
    }
}

/// A join kept in the reconstruction (`report.json`'s `network.joined[]`).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct JoinReport {
    pub node: u32,
    /// Scan index of the curve joined (split at the node).
    pub curve: usize,
    /// Arc length of the node from the joined curve's first tag, m (after the passes).
    pub arc_length_m: f64,
    /// Closest approach of the curve to the node when the join was found, m.
    pub distance_m: f64,
    /// Angle between the node's normal and the curve's there, degrees.
    pub normal_deg: f64,
    /// The network's closure misfit without the join: root mean square, per degree of
    /// freedom of its loops, of what a segment of mean stiffness misses by, m
    /// ([`super::closure::LoopFit::others_m`]); `None` when no other loop can judge it.
    pub misfit_before_m: Option<f64>,
    /// The misfit of the loops the join closes, same measure, m
    /// ([`super::closure::LoopFit::own_m`]). A join is kept when it is at most
    /// [`REFUSE_RATIO`] × `misfit_before_m` (or [`MISFIT_FLOOR_M`]).
    pub misfit_after_m: Option<f64>,
    /// A crossing nobody tagged, joined under a fresh node (`join_untagged`).
    pub untagged: bool,
}

/// A join undone (`report.json`'s `network.joins_refused[]`), and why.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct RefusedJoin {
    pub node: u32,
    pub curve: usize,
    pub distance_m: f64,
    pub misfit_before_m: Option<f64>,
    pub misfit_after_m: Option<f64>,
    pub reason: String,
}

impl RefusedJoin {
    /// `j` refused by the operator's `[network] refuse` list.
    pub fn configured(j: &Join) -> Self {
        RefusedJoin {
            node: j.node,
            curve: j.curve,
            distance_m: j.distance_m,
            misfit_before_m: None,
            misfit_after_m: None,
            reason: format!(
                "joins between curves {} and {} are refused in the configuration ([network] refuse)",
                j.home, j.curve
            ),
        }
    }
}

/// Two curves whose reconstructed paths cross with no node there (`network.proposed[]`).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Proposal {
    /// Scan indices, the lower first.
    pub curves: [usize; 2],
    /// Midpoint of the closest approach, m.
    pub point: [f64; 3],
    /// Closest approach, m.
    pub distance_m: f64,
    /// Angle between their normals there, degrees.
    pub normal_deg: f64,
    /// Each curve's own distance there (where a tag would go), m.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub d: [f64; 2],
}

/// A join whose loops misfit more than this many times the network's other loops (per
/// degree of freedom, as a length) is refused: a χ² of 3 degrees of freedom at 9× its mean
/// is far beyond noise (p < 10⁻⁵).
pub const REFUSE_RATIO: f64 = 3.0;
/// The network's misfit is taken as at least this when judging a join, m (exact data have
/// none, and a discretisation's 10 µm must not refuse anything).
pub const MISFIT_FLOOR_M: f64 = 0.001;
/// Passes of find, join and reconstruct at most (each pass one reconstruction).
pub const MAX_PASSES: usize = 8;
/// A slid tag keeps at least this far from its curve's other tags, m (or a quarter of the
/// segment, when shorter).
pub const SLIDE_MARGIN_M: f64 = 0.002;
/// A pass settles when no joined tag moves more than this along its curve, m.
pub const SETTLED_M: f64 = 0.0005;

/// A node joined to a curve that passes it untagged.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Join {
    pub node: u32,
    /// Scan index of the curve joined.
    pub curve: usize,
    /// Scan index of the curve that tags the node.
    pub home: usize,
    /// The curve's own distance at the closest approach (where its tag goes), m.
    pub d: f64,
    /// Arc length from the curve's first tag, m.
    pub arc_length_m: f64,
    /// Closest approach, m.
    pub distance_m: f64,
    /// Angle between the node's normal and the curve's there, degrees.
    pub normal_deg: f64,
}

/// The faces of `c` at the point `u` of the way from sample `j` to `j + 1`: its normal, and
/// a crease's other face where it is known ([`super::crease`]).
fn faces(c: &CurvePositions, j: usize, u: f64) -> Vec<Vector3<f64>> {
    let at = |x: &[Vector3<f64>]| -> Option<Vector3<f64>> {
        let (a, b) = (x.get(j)?, x.get(j + 1).unwrap_or(x.get(j)?));
        (a * (1.0 - u) + b * u).try_normalize(1e-12).or(Some(*a))
    };
    at(&c.normals).into_iter().chain(at(&c.across)).collect()
}

/// The angle from `x` to the normals a crease with faces `f` and `g` takes: the arc between
/// them (where a crease's tag is missing, the regression blends the normals of the curves
/// meeting there across it), radians.
fn angle_to_arc(x: &Vector3<f64>, f: &Vector3<f64>, g: &Vector3<f64>) -> f64 {
    let ends = x.angle(f).min(x.angle(g));
    let Some(axis) = f.cross(g).try_normalize(1e-9) else {
        return ends;
    };
    // The projection of x on the arc's great circle, if it falls between f and g.
    let Some(q) = (x - axis * axis.dot(x)).try_normalize(1e-12) else {
        return ends;
    };
    if (q.angle(f) + q.angle(g) - f.angle(g)).abs() < 1e-9 {
        x.angle(&q).min(ends)
    } else {
        ends
    }
}

/// The least angle between the faces `a` and `b`, degrees: a set of two faces (a crease's)
/// spans the arc between them ([`angle_to_arc`]).
fn face_angle(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    let to = |x: &Vector3<f64>, set: &[Vector3<f64>]| match set {
        [f, g] => angle_to_arc(x, f, g),
        _ => set.iter().map(|y| x.angle(y)).fold(f64::INFINITY, f64::min),
    };
    let ab = a.iter().map(|x| to(x, b)).fold(f64::INFINITY, f64::min);
    let ba = b.iter().map(|y| to(y, a)).fold(f64::INFINITY, f64::min);
    ab.min(ba).to_degrees()
}

/// Whether a point with faces `own` (on a curve of kind `kind`) may lie on curve `c` near
/// `x`, by their normals: a face of `c` at a sample within `reach` of `x` within `normal_deg`
/// of a face of the point. Where both are creases (two creases meet at a corner, where each
/// has two faces), each of the point's faces must be matched by a face of `c` within the
/// reach: along the side of a box's rim an upright edge matches one face, at the corner both.
/// Returns the least angle matched, degrees, if it fits.
fn normals_fit(
    own: &[Vector3<f64>],
    kind: CurveKind,
    c: &CurvePositions,
    samples: impl Iterator<Item = usize>,
    normal_deg: f64,
) -> Option<f64> {
    let near: Vec<Vec<Vector3<f64>>> = samples.map(|j| faces(c, j, 0.0)).collect();
    if kind == CurveKind::Crease && c.kind == CurveKind::Crease && own.len() >= 2 {
        let mut worst: f64 = 0.0;
        for f in own {
            let best = near
                .iter()
                .map(|g| face_angle(std::slice::from_ref(f), g))
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(best);
        }
        return (worst <= normal_deg).then_some(worst);
    }
    let best = near
        .iter()
        .map(|g| face_angle(own, g))
        .fold(f64::INFINITY, f64::min);
    (best <= normal_deg).then_some(best)
}

/// The samples of `c` within `reach` of `x`.
fn samples_near<'a>(
    c: &'a CurvePositions,
    x: &'a Vector3<f64>,
    reach: f64,
) -> impl Iterator<Item = usize> + 'a {
    c.points
        .iter()
        .enumerate()
        .filter(move |(_, p)| (*p - x).norm() <= reach)
        .map(|(j, _)| j)
}

/// Where a curve comes closest to a point.
struct Approach {
    distance: f64,
    /// The curve's own distance there, m.
    d: f64,
    faces: Vec<Vector3<f64>>,
    tangent: Vector3<f64>,
}

/// The closest approach of `c`'s polyline to `p`.
fn closest_approach(c: &CurvePositions, p: &Vector3<f64>) -> Option<Approach> {
    let n = c.points.len().min(c.normals.len()).min(c.d.len());
    let mut best: Option<(f64, usize, f64)> = None;
    for j in 0..n.saturating_sub(1) {
        let (a, b) = (c.points[j], c.points[j + 1]);
        let ab = b - a;
        let len2 = ab.norm_squared();
        let u = if len2 > 0.0 {
            ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dist = (a + ab * u - p).norm();
        if best.as_ref().is_none_or(|x| dist < x.0) {
            best = Some((dist, j, u));
        }
    }
    let (dist, j, u) = best?;
    let d = c.d[j] + (c.d[j + 1] - c.d[j]) * u;
    let tangent = c
        .tangents
        .get(j)
        .zip(c.tangents.get(j + 1))
        .map_or(c.points[j + 1] - c.points[j], |(a, b)| {
            a * (1.0 - u) + b * u
        });
    (dist.is_finite() && d.is_finite()).then(|| Approach {
        distance: dist,
        d,
        faces: faces(c, j, u),
        tangent,
    })
}

/// The angle between two tangents as lines (0 to 90°), degrees.
fn line_angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let x = a.angle(b).to_degrees();
    x.min(180.0 - x)
}

/// The joins of the lonely nodes of `net` (see the module docs), in node order.
pub fn find_joins(net: &Positions, p: &JoinParams) -> Vec<Join> {
    find_joins_within(net, p, p.distance_m)
}

/// As [`find_joins`], a node tagged on one curve only reaching `lonely_reach` (at least
/// [`JoinParams::distance_m`]; [`Reconstructor::run_joined`](super::Reconstructor::run_joined)
/// scales it with the network's noise). A node two curves or more already share (a third
/// curve passes it untagged) reaches [`JoinParams::distance_m`] only: a complete crossing
/// with a third curve near is the rarer event, and it wants the stronger evidence.
pub fn find_joins_within(net: &Positions, p: &JoinParams, lonely_reach: f64) -> Vec<Join> {
    let mut on: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for &(_, node) in &c.nodes {
            let list = on.entry(node).or_default();
            if !list.contains(&ci) {
                list.push(ci);
            }
        }
    }
    let mut out = Vec::new();
    for (&node, curves) in &on {
        if node >= ANONYMOUS_NODE_BASE {
            continue;
        }
        let home_index = net.curves[curves[0]].index;
        let reach = if curves.len() == 1 {
            lonely_reach.max(p.distance_m)
        } else {
            p.distance_m
        };
        // The node's faces and tangents: those of every curve through it; a crease's kind if
        // one is.
        let mut own = Vec::new();
        let mut along = Vec::new();
        let mut kind = net.curves[curves[0]].kind;
        for &ci in curves {
            let c = &net.curves[ci];
            if let Some(x) = c
                .nodes
                .iter()
                .find(|x| x.1 == node && x.0 < c.normals.len())
            {
                own.extend(faces(c, x.0, 0.0));
                along.extend(c.tangents.get(x.0));
            }
            if c.kind == CurveKind::Crease {
                kind = CurveKind::Crease;
            }
        }
        let Some(pos) = net.nodes.get(&node).filter(|_| !own.is_empty()) else {
            continue;
        };
        let best = net
            .curves
            .iter()
            .enumerate()
            .filter(|&(ci, _)| !curves.contains(&ci))
            .filter_map(|(_, c)| {
                let Approach {
                    distance: dist,
                    d,
                    faces: theirs,
                    tangent,
                } = closest_approach(c, pos)?;
                // Crossing, not running alongside one of the node's curves.
                if along
                    .iter()
                    .any(|t| line_angle(t, &tangent) < ALONGSIDE_DEG)
                {
                    return None;
                }
                let angle = if kind == CurveKind::Crease && c.kind == CurveKind::Crease {
                    // Two creases meet at a corner: both faces of the node matched near it.
                    let reach = reach.max(dist * 1.01);
                    normals_fit(&own, kind, c, samples_near(c, pos, reach), f64::INFINITY)?
                } else {
                    face_angle(&own, &theirs)
                };
                let step = c.d.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
                let clear = c
                    .nodes
                    .iter()
                    .filter_map(|x| c.d.get(x.0))
                    .all(|&dn| (dn - d).abs() >= 1.5 * step);
                (dist <= reach && angle <= p.normal_deg && clear).then(|| Join {
                    node,
                    curve: c.index,
                    home: home_index,
                    d,
                    arc_length_m: d - c.d[0],
                    distance_m: dist,
                    normal_deg: angle,
                })
            })
            .min_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
        out.extend(best);
    }
    out
}

/// Puts each join's tag into its curve of `curves` (by scan index), between the tags around
/// its distance, at the time the curve's samples reached that distance; a measured length of
/// the segment it splits is shared in proportion. Returns how many were put.
pub fn apply_joins(curves: &mut [Curve], joins: &[Join]) -> usize {
    let mut put = 0;
    for j in joins {
        let Some(c) = curves.iter_mut().find(|c| c.index == j.curve) else {
            continue;
        };
        let Some(k) = c.tags.windows(2).position(|w| w[0].d < j.d && j.d < w[1].d) else {
            continue;
        };
        let (a, b) = (c.tags[k].clone(), c.tags[k + 1].clone());
        // The time the samples between the two tags first reached the distance.
        let s = &c.samples;
        let t = (0..s.len().saturating_sub(1))
            .filter(|&i| s.t[i] >= a.t && s.t[i + 1] <= b.t)
            .find(|&i| s.d[i] <= j.d && j.d <= s.d[i + 1])
            .map(|i| {
                let span = s.d[i + 1] - s.d[i];
                let u = if span > 0.0 {
                    (j.d - s.d[i]) / span
                } else {
                    0.0
                };
                s.t[i] + (s.t[i + 1] - s.t[i]) * u
            })
            .unwrap_or(a.t + (b.t - a.t) * (j.d - a.d) / (b.d - a.d));
        c.tags.insert(
            k + 1,
            Tag {
                node: j.node,
                d: j.d,
                t,
                uncertain: false,
            },
        );
        if k < c.segment_lengths.len() {
            let share = (j.d - a.d) / (b.d - a.d);
            let whole = c.segment_lengths[k];
            c.segment_lengths[k] = whole.map(|l| l * share);
            c.segment_lengths
                .insert(k + 1, whole.map(|l| l * (1.0 - share)));
        }
        put += 1;
    }
    put
}

/// A curve whose tangent is within this of one of a node's curves' there (as lines) runs
/// alongside it and does not join the node, degrees: two curves side by side are a few degrees
/// apart in a noisy network, sections of a surface cross at 15° and more.
pub const ALONGSIDE_DEG: f64 = 10.0;

/// Tangents of two curves proposed as crossing make at least this angle (as lines), degrees:
/// curves that run side by side (parallel, or a curve retraced) pass close without crossing,
/// and a proposal, which no tag asked for, wants a clear crossing.
pub const CROSSING_DEG: f64 = 30.0;

/// Closest points of segments `p0 p1` and `q0 q1`: `(distance, u on p, v on q)`, u and v in
/// [0, 1].
fn segment_closest(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> (f64, f64, f64) {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    let (mut u, mut v);
    if a <= 1e-24 && e <= 1e-24 {
        return (r.norm(), 0.0, 0.0);
    }
    if a <= 1e-24 {
        u = 0.0;
        v = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= 1e-24 {
            v = 0.0;
            u = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            u = if denom > 1e-24 * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            v = (b * u + f) / e;
            if v < 0.0 {
                v = 0.0;
                u = (-c / a).clamp(0.0, 1.0);
            } else if v > 1.0 {
                v = 1.0;
                u = ((b - c) / a).clamp(0.0, 1.0);
            }
        }
    }
    ((p0 + d1 * u - (q0 + d2 * v)).norm(), u, v)
}

/// Crossings nobody tagged: pairs of curves of `net` whose paths come within
/// [`JoinParams::distance_m`] of each other, crossing (tangents at least [`CROSSING_DEG`]
/// apart as lines) with normals within [`JoinParams::normal_deg`], and with no node of either
/// curve within twice the join distance. One proposal per crossing (the closest approach of
/// each run of close samples), in the order of the curves. Linear in the samples: a grid of
/// cells the size of the join distance.
pub fn find_crossings(net: &Positions, p: &JoinParams) -> Vec<Proposal> {
    let reach = p.distance_m;
    if reach <= 0.0 || !reach.is_finite() {
        return Vec::new();
    }
    let cell = |x: &Vector3<f64>| -> Option<[i64; 3]> {
        let k = [x.x / reach, x.y / reach, x.z / reach];
        k.iter().all(|v| v.is_finite() && v.abs() < 1e12).then(|| {
            [
                k[0].floor() as i64,
                k[1].floor() as i64,
                k[2].floor() as i64,
            ]
        })
    };
    let mut grid: std::collections::HashMap<[i64; 3], Vec<(usize, usize)>> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for (j, x) in c.points.iter().enumerate() {
            if let Some(k) = cell(x) {
                grid.entry(k).or_default().push((ci, j));
            }
        }
    }
    // Close sample pairs per pair of curves: (a, b) → [(i on a, j on b)].
    let mut close: std::collections::BTreeMap<(usize, usize), Vec<(usize, usize)>> =
        Default::default();
    for (ca, c) in net.curves.iter().enumerate() {
        for (i, x) in c.points.iter().enumerate() {
            let Some(k) = cell(x) else { continue };
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                            continue;
                        };
                        for &(cb, j) in list {
                            if cb > ca && (net.curves[cb].points[j] - x).norm() <= 2.0 * reach {
                                close.entry((ca, cb)).or_default().push((i, j));
                            }
                        }
                    }
                }
            }
        }
    }
    let mut out = Vec::new();
    for ((ca, cb), mut pairs) in close {
        let (a, b) = (&net.curves[ca], &net.curves[cb]);
        pairs.sort_unstable();
        // Runs of close samples along a (a crossing), each refined to its closest segments.
        let mut runs: Vec<Vec<(usize, usize)>> = Vec::new();
        for pr in pairs {
            match runs.last_mut() {
                Some(r) if pr.0 <= r.last().map_or(0, |x| x.0) + 2 => r.push(pr),
                _ => runs.push(vec![pr]),
            }
        }
        for run in runs {
            let mut best: Option<(f64, usize, f64, usize, f64)> = None;
            for &(i, j) in &run {
                for si in i.saturating_sub(1)..=i {
                    for sj in j.saturating_sub(1)..=j {
                        if si + 1 >= a.points.len() || sj + 1 >= b.points.len() {
                            continue;
                        }
                        let (dist, u, v) = segment_closest(
                            &a.points[si],
                            &a.points[si + 1],
                            &b.points[sj],
                            &b.points[sj + 1],
                        );
                        if best.as_ref().is_none_or(|x| dist < x.0) {
                            best = Some((dist, si, u, sj, v));
                        }
                    }
                }
            }
            let Some((dist, si, u, sj, v)) = best else {
                continue;
            };
            if dist > reach || !dist.is_finite() {
                continue;
            }
            let lerp = |x: &[Vector3<f64>], k: usize, t: f64| {
                x.get(k)
                    .zip(x.get(k + 1))
                    .map(|(p, q)| p * (1.0 - t) + q * t)
            };
            let (Some(xa), Some(xb), Some(ta), Some(tb)) = (
                lerp(&a.points, si, u),
                lerp(&b.points, sj, v),
                lerp(&a.tangents, si, u),
                lerp(&b.tangents, sj, v),
            ) else {
                continue;
            };
            let line_angle = line_angle(&ta, &tb);
            let normal_deg = face_angle(&faces(a, si, u), &faces(b, sj, v));
            let point = (xa + xb) * 0.5;
            let near_node = a
                .nodes
                .iter()
                .filter_map(|x| a.points.get(x.0))
                .chain(b.nodes.iter().filter_map(|x| b.points.get(x.0)))
                .any(|q| (q - point).norm() < 2.0 * reach);
            if line_angle < CROSSING_DEG || normal_deg > p.normal_deg || near_node {
                continue;
            }
            let (Some(da), Some(db)) = (
                a.d.get(si)
                    .zip(a.d.get(si + 1))
                    .map(|(x, y)| x + (y - x) * u),
                b.d.get(sj)
                    .zip(b.d.get(sj + 1))
                    .map(|(x, y)| x + (y - x) * v),
            ) else {
                continue;
            };
            out.push(Proposal {
                curves: [a.index, b.index],
                point: [point.x, point.y, point.z],
                distance_m: dist,
                normal_deg,
                d: [da, db],
            });
        }
    }
    out
}

/// A node tagged by one curve only: its position and faces.
struct Lonely {
    curve: usize,
    kind: CurveKind,
    x: Vector3<f64>,
    faces: Vec<Vector3<f64>>,
}

/// The lonely nodes of `net` (see the module docs), with the curve (position) that tags each.
fn lonely_nodes(net: &Positions) -> Vec<Lonely> {
    let mut on: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for &(_, node) in &c.nodes {
            let list = on.entry(node).or_default();
            if !list.contains(&ci) {
                list.push(ci);
            }
        }
    }
    on.into_iter()
        .filter(|(node, curves)| *node < ANONYMOUS_NODE_BASE && curves.len() == 1)
        .filter_map(|(node, curves)| {
            let c = &net.curves[curves[0]];
            let i = c.nodes.iter().find(|x| x.1 == node)?.0;
            let x = *net.nodes.get(&node)?;
            (i < c.normals.len()).then(|| Lonely {
                curve: curves[0],
                kind: c.kind,
                x,
                faces: faces(c, i, 0.0),
            })
        })
        .collect()
}

/// The connected part of every curve of `net` (curves sharing a node are in one part).
fn parts(net: &Positions) -> Vec<usize> {
    let mut sets = crate::union_find::UnionFind::new(net.curves.len());
    let mut first: std::collections::HashMap<u32, usize> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for &(_, node) in &c.nodes {
            let f = *first.entry(node).or_insert(ci);
            sets.union(f, ci);
        }
    }
    (0..net.curves.len()).map(|ci| sets.find(ci)).collect()
}

/// A grid of curve samples with cells the size of the join distance.
struct Grid {
    reach: f64,
    cells: std::collections::HashMap<[i64; 3], Vec<(usize, usize)>>,
}

impl Grid {
    fn key(&self, x: &Vector3<f64>) -> Option<[i64; 3]> {
        let k = x / self.reach;
        k.iter()
            .all(|v| v.is_finite() && v.abs() < 1e12)
            .then(|| [k.x.floor() as i64, k.y.floor() as i64, k.z.floor() as i64])
    }

    /// The samples of the curves `take` of `net`, shifted by `shift`.
    fn of(net: &Positions, reach: f64, take: impl Fn(usize) -> bool) -> Grid {
        let mut g = Grid {
            reach,
            cells: Default::default(),
        };
        for (ci, c) in net.curves.iter().enumerate().filter(|(ci, _)| take(*ci)) {
            for (j, x) in c.points.iter().enumerate() {
                if let Some(k) = g.key(x) {
                    g.cells.entry(k).or_default().push((ci, j));
                }
            }
        }
        g
    }

    /// Whether a curve of the grid passes within the reach of `l` moved by `t`, its normals
    /// fitting ([`normals_fit`]).
    fn meets(&self, net: &Positions, l: &Lonely, t: &Vector3<f64>, normal_deg: f64) -> bool {
        let x = l.x + t;
        let Some(k) = self.key(&x) else { return false };
        let mut near: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    for &(ci, j) in list {
                        if (net.curves[ci].points[j] - x).norm() <= self.reach {
                            near.entry(ci).or_default().push(j);
                        }
                    }
                }
            }
        }
        near.into_iter().any(|(ci, js)| {
            normals_fit(
                &l.faces,
                l.kind,
                &net.curves[ci],
                js.into_iter(),
                normal_deg,
            )
            .is_some()
        })
    }
}

/// A network in parts (a crossing left untagged can cut it) has no relative placement of its
/// parts: the Poisson solve gives each its own gauge. The orientations are absolute, so each
/// part's shape is right and only its translation is unknown. This moves each part, greedily
/// from the largest, by the translation that puts the most of its lonely nodes on the placed
/// parts' curves and the placed parts' lonely nodes on its curves (at least two such
/// incidences, and no other translation as good farther than twice the join distance: one
/// incidence leaves the part free to slide along a curve). Candidates come from each
/// incidence along every sample of the curve; each is checked in a grid, so the cost is the
/// lonely nodes squared times the samples. Returns the parts moved; the joins
/// ([`find_joins`]) are then found in the moved network.
pub fn place_parts(net: &mut Positions, p: &JoinParams) -> usize {
    let reach = p.distance_m;
    if net.components < 2 || reach <= 0.0 || !reach.is_finite() {
        return 0;
    }
    let part = parts(net);
    let mut roots: Vec<usize> = part.clone();
    roots.sort_unstable();
    roots.dedup();
    if roots.len() < 2 {
        return 0;
    }
    let size = |r: usize| -> usize {
        net.curves
            .iter()
            .enumerate()
            .filter(|(ci, _)| part[*ci] == r)
            .map(|(_, c)| c.points.len())
            .sum()
    };
    roots.sort_by_key(|&r| std::cmp::Reverse(size(r)));
    let mut placed = vec![roots[0]];
    let mut moved = 0;
    loop {
        let lonely = lonely_nodes(net);
        let mut best: Option<(usize, Vector3<f64>, usize)> = None;
        for &r in roots.iter().filter(|r| !placed.contains(r)) {
            let in_p = |ci: usize| part[ci] == r;
            let in_placed = |ci: usize| placed.contains(&part[ci]);
            let g_placed = Grid::of(net, reach, in_placed);
            let g_part = Grid::of(net, reach, in_p);
            // Incidences: a lonely node of the part on a placed curve (t = curve − node), and
            // a lonely node of a placed part on the part's curves (t = node − curve).
            let ours: Vec<&Lonely> = lonely.iter().filter(|l| in_p(l.curve)).collect();
            let theirs: Vec<&Lonely> = lonely.iter().filter(|l| in_placed(l.curve)).collect();
            if ours.len() + theirs.len() < 2 {
                continue;
            }
            let score = |t: &Vector3<f64>| -> usize {
                ours.iter()
                    .filter(|l| g_placed.meets(net, l, t, p.normal_deg))
                    .count()
                    + theirs
                        .iter()
                        .filter(|l| g_part.meets(net, l, &-t, p.normal_deg))
                        .count()
            };
            let mut top: Vec<(usize, Vector3<f64>)> = Vec::new();
            let mut consider = |t: Vector3<f64>| {
                let s = score(&t);
                if s >= 2 {
                    top.push((s, t));
                }
            };
            for l in &ours {
                for (ci, c) in net
                    .curves
                    .iter()
                    .enumerate()
                    .filter(|(ci, _)| in_placed(*ci))
                {
                    for (j, x) in c.points.iter().enumerate() {
                        if face_angle(&l.faces, &faces(c, j, 0.0)) <= p.normal_deg {
                            consider(x - l.x);
                        }
                    }
                    let _ = ci;
                }
            }
            for l in &theirs {
                for c in net
                    .curves
                    .iter()
                    .enumerate()
                    .filter(|(ci, _)| in_p(*ci))
                    .map(|x| x.1)
                {
                    for (j, x) in c.points.iter().enumerate() {
                        if face_angle(&l.faces, &faces(c, j, 0.0)) <= p.normal_deg {
                            consider(l.x - x);
                        }
                    }
                }
            }
            let Some(&(s, t)) = top.iter().max_by_key(|x| x.0) else {
                continue;
            };
            // Unique: every translation as good lies near this one.
            if top
                .iter()
                .any(|x| x.0 == s && (x.1 - t).norm() > 2.0 * reach)
            {
                continue;
            }
            // The mean of the best translations near it (they spread along the curves within
            // the reach).
            let near: Vec<&Vector3<f64>> = top
                .iter()
                .filter(|x| x.0 == s && (x.1 - t).norm() <= 2.0 * reach)
                .map(|x| &x.1)
                .collect();
            let t = near.iter().copied().sum::<Vector3<f64>>() / near.len() as f64;
            if best.as_ref().is_none_or(|b| s > b.2) {
                best = Some((r, t, s));
            }
        }
        let Some((r, t, _)) = best else { break };
        let mut nodes_moved = std::collections::BTreeSet::new();
        for (ci, c) in net.curves.iter_mut().enumerate() {
            if part[ci] == r {
                c.points.iter_mut().for_each(|x| *x += t);
                nodes_moved.extend(c.nodes.iter().map(|x| x.1));
            }
        }
        for n in nodes_moved {
            if let Some(x) = net.nodes.get_mut(&n) {
                *x += t;
            }
        }
        placed.push(r);
        moved += 1;
    }
    moved
}
