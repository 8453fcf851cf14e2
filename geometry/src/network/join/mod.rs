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
//! the parts put together and the refusals are [`run_joined`]'s.
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
//!         sigma_m: Vec::new(),
//!     }
//! };
//! let a = line(0, Vector3::new(0.0, 0.5, 0.0), Vector3::new(1.0, 0.5, 0.0), vec![(0, 0), (50, 9), (100, 1)]);
//! let b = line(1, Vector3::new(0.5, 0.0, 0.0), Vector3::new(0.5, 1.0, 0.0), vec![(0, 2), (100, 3)]);
//! let nodes = [(0, a.points[0]), (9, a.points[50]), (1, a.points[100]), (2, b.points[0]), (3, b.points[100])]
//!     .into_iter()
//!     .collect();
//! let net = Positions { curves: vec![a, b], nodes, components: 2, misfit: Default::default() };
//! let joins = find_joins(&net, &JoinParams::default());
//! assert_eq!(joins.len(), 1);
//! assert_eq!((joins[0].node, joins[0].curve), (9, 1));
//! assert!((joins[0].d - 0.5).abs() < 1e-9 && joins[0].distance_m < 1e-9);
//! ```

mod crossings;
mod grid;
mod parts;
pub(crate) mod passes;

pub use crossings::{find_crossings, CROSSING_DEG};
pub use parts::{place_parts, DISTINCT_RATIO};
pub use passes::{run_joined, run_joined_until};

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
    /// [`run_joined`] reaches this many
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
/// The same in a live update (a provisional network: [`NetworkParams::local_window`] above
/// 0), whose settle runs them to [`MAX_PASSES`]: on a noisy network of thousands of nodes
/// the slides jitter by a millimetre from pass to pass, and eight whole reconstructions per
/// update were most of a live update's time.
///
/// [`NetworkParams::local_window`]: crate::network::NetworkParams::local_window
pub const LIVE_MAX_PASSES: usize = 3;
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

/// The closest approach of `c`'s polyline to `p`: over its segments `among` (increasing)
/// alone where given, the same wherever the closest segment is among them.
fn closest_approach(
    c: &CurvePositions,
    p: &Vector3<f64>,
    among: Option<&[usize]>,
) -> Option<Approach> {
    let n = c.points.len().min(c.normals.len()).min(c.d.len());
    if n < 2 {
        return None;
    }
    let (j, u, dist) = match among {
        Some(segments) => crate::curve::closest_among(&c.points[..n], p, segments.iter().copied()),
        None => crate::curve::closest_on_polyline(&c.points[..n], p),
    };
    if !dist.is_finite() {
        return None;
    }
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

/// The curves (positions in `net`) through every node, each once, in node order.
fn curves_at_nodes(net: &Positions) -> std::collections::BTreeMap<u32, Vec<usize>> {
    let mut on: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for &(_, node) in &c.nodes {
            let list = on.entry(node).or_default();
            if !list.contains(&ci) {
                list.push(ci);
            }
        }
    }
    on
}

/// The joins of the lonely nodes of `net` (see the module docs), in node order.
pub fn find_joins(net: &Positions, p: &JoinParams) -> Vec<Join> {
    find_joins_within(net, p, p.distance_m)
}

/// As [`find_joins`], a node tagged on one curve only reaching `lonely_reach` (at least
/// [`JoinParams::distance_m`]; [`run_joined`]
/// scales it with the network's noise). A node two curves or more already share (a third
/// curve passes it untagged) reaches [`JoinParams::distance_m`] only: a complete crossing
/// with a third curve near is the rarer event, and it wants the stronger evidence.
pub fn find_joins_within(net: &Positions, p: &JoinParams, lonely_reach: f64) -> Vec<Join> {
    let mut out = Vec::new();
    // The curves that may come within a node's reach: those with a sample within the reach
    // and a step of it (the closest point lies on a step whose nearer end is that close), in
    // a grid of cells that size; the closest approach of each is then found as before.
    let steps = net.curves.iter().flat_map(|c| {
        let n = c.points.len().min(c.normals.len()).min(c.d.len());
        c.points[..n].windows(2).map(|w| (w[1] - w[0]).norm())
    });
    let cell = lonely_reach.max(p.distance_m) + steps.fold(0.0, f64::max);
    let grid = (cell > 0.0 && cell.is_finite()).then(|| grid::Grid::of(net, cell, |_| true));
    // Each curve's largest step along (for the clearance from its nodes).
    let steps: Vec<f64> = net
        .curves
        .iter()
        .map(|c| c.d.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max))
        .collect();
    for (node, curves) in &curves_at_nodes(net) {
        let node = *node;
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
        // The samples near the node, by curve: a segment within the reach has an end among
        // them (a cell is the reach and a step), so the closest approach within the reach is
        // found on the segments at them alone.
        let near: Option<Vec<(usize, usize)>> = grid.as_ref().map(|g| {
            let mut v: Vec<(usize, usize)> = g.around(pos).collect();
            v.sort_unstable();
            v.dedup();
            v
        });
        let segments_near = |ci: usize| -> Option<Vec<usize>> {
            let near = near.as_ref()?;
            let from = near.partition_point(|x| x.0 < ci);
            let mut segs: Vec<usize> = near[from..]
                .iter()
                .take_while(|x| x.0 == ci)
                .flat_map(|&(_, j)| [j.checked_sub(1), Some(j)])
                .flatten()
                .collect();
            segs.dedup();
            Some(segs)
        };
        let best = net
            .curves
            .iter()
            .enumerate()
            .filter(|&(ci, _)| !curves.contains(&ci))
            .filter_map(|(ci, c)| {
                let among = segments_near(ci);
                if among.as_ref().is_some_and(|s| s.is_empty()) {
                    return None;
                }
                let Approach {
                    distance: dist,
                    d,
                    faces: theirs,
                    tangent,
                } = closest_approach(c, pos, among.as_deref())?;
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
                let step = steps[ci];
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
