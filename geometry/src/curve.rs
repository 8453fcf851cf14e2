//! The input of the reconstruction: tagged curves of frames. Per curve, the raw samples
//! (session time, distance along the curve, orientation of the frame `[T B N]`, flags,
//! weight) and the node tags, as acquisition hands them over (the application writes them as
//! `scan.json`: columnar arrays, so a long scan stays compact).
//!
//! Distances `d` are metres from the curve's first tag (the start node): samples taken while
//! the device stood at the start node before its tag have `d ≈ 0`, and the curve runs over
//! `[tags[0].d, tags.last().d]`. Quaternions are `[w, x, y, z]`, frame → world (x east,
//! y magnetic north, z up).
//!
//! ```
//! use sfs_geometry::curve::{Curve, CurveKind, Samples, Tag};
//! let tag = |node, d| Tag { node, d, t: d, uncertain: false };
//! let c = Curve {
//!     index: 0, kind: CurveKind::Interior, closed: false,
//!     tags: vec![tag(1, 0.0), tag(2, 0.5)],
//!     segment_lengths: vec![None],
//!     samples: Samples::default(),
//! };
//! assert_eq!(c.nodes(), [1, 2]);
//! assert_eq!(c.length(), 0.5);
//! assert!(!c.boundary());
//! ```

#[cfg(feature = "serde")]
use serde::{Deserialize, Serialize};

/// First index given to anonymous nodes (tags whose index was lost on the link); they are
/// numbered upwards in the order they occur and can never collide with a typed index (the
/// keypad's largest is 999 999).
pub const ANONYMOUS_NODE_BASE: u32 = 1_000_000;

/// Whether `node` is an anonymous node (see [`ANONYMOUS_NODE_BASE`]).
pub fn is_anonymous(node: u32) -> bool {
    node >= ANONYMOUS_NODE_BASE
}

/// A node tag: the operator pressed Enter at node `node`.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize, Deserialize))]
pub struct Tag {
    pub node: u32,
    /// Distance along the curve, m.
    pub d: f64,
    /// Session time of the Enter press, s.
    pub t: f64,
    /// Packets were lost on the link while this index was typed (a digit may be missing):
    /// the reconstruction detaches such a tag if the network's loops refuse it.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "std::ops::Not::not")
    )]
    pub uncertain: bool,
}

/// Raw samples of one curve, as parallel arrays.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize, Deserialize))]
pub struct Samples {
    /// Session time, s (monotonic across clock wraps and reboots).
    pub t: Vec<f64>,
    /// Distance along the curve, m (may decrease when the device rolls backwards).
    pub d: Vec<f64>,
    /// Orientation `[w, x, y, z]`, frame → world.
    pub q: Vec<[f64; 4]>,
    /// Flag bits of the sample (the application's orientation flags: standing, disturbed, …).
    pub flags: Vec<u8>,
    /// Weight of each orientation in averaging, in [0, 1], from the flags.
    pub w: Vec<f64>,
}

impl Samples {
    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

/// What a curve means for the surface: the start key that began it (`B`, `I`, `K`, `G`), or
/// the configuration's override by curve index. Written in lower case (`"crease"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Serialize, Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum CurveKind {
    /// `B`: lies on the boundary of the surface.
    Boundary,
    /// `I`: a smooth curve inside the surface, interpolated (G¹ across it).
    #[default]
    Interior,
    /// `K`: a sharp edge, interpolated; the surface's normal jumps across it (each side keeps
    /// its own). The device rests on one of the two faces.
    Crease,
    /// `G`: gives the surface its general form, approximated rather than interpolated.
    Guide,
}

impl CurveKind {
    /// Every kind, in the order of their keys `B`, `I`, `K`, `G`.
    pub const ALL: [CurveKind; 4] = [
        CurveKind::Boundary,
        CurveKind::Interior,
        CurveKind::Crease,
        CurveKind::Guide,
    ];

    /// The kind a start key begins, if `key` is one.
    pub fn of_key(key: u8) -> Option<CurveKind> {
        CurveKind::ALL.into_iter().find(|k| k.key() == key)
    }

    /// The start key of this kind.
    pub fn key(self) -> u8 {
        match self {
            CurveKind::Boundary => b'B',
            CurveKind::Interior => b'I',
            CurveKind::Crease => b'K',
            CurveKind::Guide => b'G',
        }
    }

    /// The name written in `scan.json`, `report.json` and the configuration.
    pub fn name(self) -> &'static str {
        match self {
            CurveKind::Boundary => "boundary",
            CurveKind::Interior => "interior",
            CurveKind::Crease => "crease",
            CurveKind::Guide => "guide",
        }
    }

    /// The kind of a [`name`](Self::name).
    pub fn of_name(name: &str) -> Option<CurveKind> {
        CurveKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

impl std::fmt::Display for CurveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One accepted curve. Serialised with its `kind` and, for readers of the format before
/// curve kinds, `boundary` (`kind == "boundary"`); read back from either.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Deserialize), serde(from = "CurveFile"))]
pub struct Curve {
    /// Index in scan order (accepted curves only).
    pub index: usize,
    /// What the curve means for the surface.
    pub kind: CurveKind,
    /// First and last tag are the same node.
    pub closed: bool,
    /// Node tags in order of travel (at least two).
    pub tags: Vec<Tag>,
    /// Measured segment lengths (m), one per pair of consecutive tags, when known
    /// (SEGMENT_LENGTH packets or configuration; phone).
    pub segment_lengths: Vec<Option<f64>>,
    pub samples: Samples,
}

/// A curve as written: `kind`, or (files before curve kinds) only `boundary`.
#[cfg(feature = "serde")]
#[derive(Deserialize)]
struct CurveFile {
    index: usize,
    kind: Option<CurveKind>,
    #[serde(default)]
    boundary: bool,
    closed: bool,
    tags: Vec<Tag>,
    segment_lengths: Vec<Option<f64>>,
    samples: Samples,
}

#[cfg(feature = "serde")]
impl From<CurveFile> for Curve {
    fn from(c: CurveFile) -> Curve {
        Curve {
            index: c.index,
            kind: c.kind.unwrap_or(if c.boundary {
                CurveKind::Boundary
            } else {
                CurveKind::Interior
            }),
            closed: c.closed,
            tags: c.tags,
            segment_lengths: c.segment_lengths,
            samples: c.samples,
        }
    }
}

#[cfg(feature = "serde")]
impl Serialize for Curve {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("Curve", 7)?;
        st.serialize_field("index", &self.index)?;
        st.serialize_field("kind", &self.kind)?;
        st.serialize_field("boundary", &self.boundary())?;
        st.serialize_field("closed", &self.closed)?;
        st.serialize_field("tags", &self.tags)?;
        st.serialize_field("segment_lengths", &self.segment_lengths)?;
        st.serialize_field("samples", &self.samples)?;
        st.end()
    }
}

impl Curve {
    /// Lies on the boundary of the surface (`B`).
    pub fn boundary(&self) -> bool {
        self.kind == CurveKind::Boundary
    }

    /// The node sequence as scanned.
    pub fn nodes(&self) -> Vec<u32> {
        self.tags.iter().map(|t| t.node).collect()
    }

    /// Length from the first to the last tag, m.
    pub fn length(&self) -> f64 {
        match (self.tags.first(), self.tags.last()) {
            (Some(a), Some(b)) => b.d - a.d,
            _ => 0.0,
        }
    }
}

/// The closest point of the polyline `p` to `x`: `(segment index, parameter in it from 0 to
/// 1, distance)`, the first segment of least distance; a single point's distance, and `(0, 0,
/// ∞)` for none.
pub fn closest_on_polyline(
    p: &[nalgebra::Vector3<f64>],
    x: &nalgebra::Vector3<f64>,
) -> (usize, f64, f64) {
    let mut best = closest_among(p, x, 0..p.len().saturating_sub(1));
    if p.len() == 1 {
        best = (0, 0.0, (p[0] - x).norm());
    }
    best
}

/// As [`closest_on_polyline`], over the segments `segments` of `p` alone (each `i` the
/// segment from point `i` to `i + 1`, in increasing order): the same result wherever the
/// closest segment is among them.
pub fn closest_among(
    p: &[nalgebra::Vector3<f64>],
    x: &nalgebra::Vector3<f64>,
    segments: impl Iterator<Item = usize>,
) -> (usize, f64, f64) {
    let mut best = (0, 0.0, f64::INFINITY);
    for i in segments.filter(|&i| i + 1 < p.len()) {
        let (a, b) = (p[i], p[i + 1]);
        let ab = b - a;
        let l2 = ab.norm_squared();
        let t = if l2 > 0.0 {
            ((x - a).dot(&ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (a + ab * t - x).norm();
        if d < best.2 {
            best = (i, t, d);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// The closest point among some segments is the whole polyline's, to the bit, wherever
    /// those segments hold it (a spiral passing a point twice: the nearer pass is kept).
    #[test]
    fn the_closest_among_segments_holding_it_is_the_polylines() {
        let p: Vec<Vector3<f64>> = (0..400)
            .map(|i| {
                let t = i as f64 * 0.05;
                Vector3::new(t.cos() * (1.0 + 0.01 * t), t.sin() * (1.0 + 0.01 * t), 0.0)
            })
            .collect();
        for x in [Vector3::new(1.05, 0.02, 0.01), Vector3::new(-0.3, 1.0, 0.0)] {
            let whole = closest_on_polyline(&p, &x);
            let (j, u, d) = whole;
            let around = j.saturating_sub(3)..(j + 4).min(p.len() - 1);
            let got = closest_among(&p, &x, around.clone());
            assert_eq!(
                (got.0, got.1.to_bits(), got.2.to_bits()),
                (j, u.to_bits(), d.to_bits())
            );
            // Without the closest segment, another (farther) one.
            let other = closest_among(&p, &x, (0..p.len() - 1).filter(|i| !around.contains(i)));
            assert!(other.2 > d);
        }
    }
}
