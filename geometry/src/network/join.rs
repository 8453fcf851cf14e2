//! Nodes joined after the fact (issue 34): a node tagged on one curve only, lying where
//! another curve passes, joins that curve as if it had been tagged there while it was
//! scanned.
//!
//! Stanko et al. 2017 (§7) name the limit this removes: a node exists only where the operator
//! tagged it on every curve through it, so a new curve across old ones, or a tag forgotten on
//! one curve of a crossing, left the network untied there (and the surface with an open face).
//!
//! ## The test
//! In the reconstructed network ([`Positions`]), a *lonely* node is one that a single curve
//! tags (anonymous nodes, [`ANONYMOUS_NODE_BASE`] and above, are not). For each other curve,
//! the closest approach of its polyline to the node: the distance, the curve's own distance
//! `d` there (interpolated between its samples: the wheel's for a Morphorider, the phone's
//! from its speed) and its normal there. The node joins the curve of least distance among
//! those within [`JoinParams::distance_m`] whose normal agrees with the node's within
//! [`JoinParams::normal_deg`], unless the split would leave a segment shorter than two of the
//! curve's steps (a node is already there). [`apply_joins`] then puts the tag into the scan.
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
use crate::curve::{Curve, Tag, ANONYMOUS_NODE_BASE};
use nalgebra::Vector3;

/// Settings of the joins (`[network] join_distance`, `join_normal_deg`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoinParams {
    /// Closest approach within which a node joins a curve, m. Default 0.015.
    pub distance_m: f64,
    /// Largest angle between the node's normal and the curve's there, degrees. Default 15.
    pub normal_deg: f64,
}

impl Default for JoinParams {
    fn default() -> Self {
        JoinParams {
            distance_m: 0.015,
            normal_deg: 15.0,
        }
    }
}

/// A node joined to a curve that passes it untagged.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Join {
    pub node: u32,
    /// Scan index of the curve joined.
    pub curve: usize,
    /// The curve's own distance at the closest approach (where its tag goes), m.
    pub d: f64,
    /// Arc length from the curve's first tag, m.
    pub arc_length_m: f64,
    /// Closest approach, m.
    pub distance_m: f64,
    /// Angle between the node's normal and the curve's there, degrees.
    pub normal_deg: f64,
}

/// The closest approach of `c`'s polyline to `p`: `(distance, d there, normal there)`.
fn closest_approach(c: &CurvePositions, p: &Vector3<f64>) -> Option<(f64, f64, Vector3<f64>)> {
    let n = c.points.len().min(c.normals.len()).min(c.d.len());
    let mut best: Option<(f64, f64, Vector3<f64>)> = None;
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
            let d = c.d[j] + (c.d[j + 1] - c.d[j]) * u;
            let normal = (c.normals[j] * (1.0 - u) + c.normals[j + 1] * u)
                .try_normalize(1e-12)
                .unwrap_or(c.normals[j]);
            best = Some((dist, d, normal));
        }
    }
    best.filter(|b| b.0.is_finite() && b.1.is_finite())
}

/// The joins of the lonely nodes of `net` (see the module docs), in node order.
pub fn find_joins(net: &Positions, p: &JoinParams) -> Vec<Join> {
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
        if node >= ANONYMOUS_NODE_BASE || curves.len() != 1 {
            continue;
        }
        let home = &net.curves[curves[0]];
        let (Some(pos), Some(normal)) = (
            net.nodes.get(&node),
            home.nodes
                .iter()
                .find(|x| x.1 == node)
                .and_then(|x| home.normals.get(x.0)),
        ) else {
            continue;
        };
        let best = net
            .curves
            .iter()
            .enumerate()
            .filter(|&(ci, _)| ci != curves[0])
            .filter_map(|(_, c)| {
                let (dist, d, n) = closest_approach(c, pos)?;
                let angle = normal.angle(&n).to_degrees();
                let step = c.d.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
                let clear = c
                    .nodes
                    .iter()
                    .filter_map(|x| c.d.get(x.0))
                    .all(|&dn| (dn - d).abs() >= 2.0 * step);
                (dist <= p.distance_m && angle <= p.normal_deg && clear).then(|| Join {
                    node,
                    curve: c.index,
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
