//! The `Scan` model: what acquisition hands to the reconstruction. Per accepted curve, the raw
//! samples (session time, distance along the curve, orientation of the frame `[T B N]`, flags)
//! and the node tags; serialised as `scan.json` (columnar arrays, so a long scan stays compact).
//!
//! Distances `d` are metres from the curve's first tag (the start node): samples taken while
//! the device stood at the start node before its tag have `d ≈ 0`, and the curve runs over
//! `[tags[0].d, tags.last().d]`. Quaternions are `[w, x, y, z]`, frame → world (x east,
//! y magnetic north, z up).

use serde::{Deserialize, Serialize};

/// A node tag: the operator pressed Enter at node `node`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tag {
    pub node: u32,
    /// Distance along the curve, m.
    pub d: f64,
    /// Session time of the Enter press, s.
    pub t: f64,
    /// Packets were lost on the link while this index was typed (a digit may be missing):
    /// the reconstruction detaches such a tag if the network's loops refuse it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub uncertain: bool,
}

/// Raw samples of one curve, as parallel arrays.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Samples {
    /// Session time, s (monotonic across clock wraps and reboots).
    pub t: Vec<f64>,
    /// Distance along the curve, m (may decrease when the device rolls backwards).
    pub d: Vec<f64>,
    /// Orientation `[w, x, y, z]`, frame → world.
    pub q: Vec<[f64; 4]>,
    /// [`crate::orientation::flags`] bits.
    pub flags: Vec<u8>,
    /// Weight of each orientation in averaging, from the flags
    /// ([`crate::orientation::flags::weight`]).
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

/// One accepted curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// Index in scan order (accepted curves only).
    pub index: usize,
    /// Lies on the boundary of the surface (`B`), else interior (`I`).
    pub boundary: bool,
    /// First and last tag are the same node.
    pub closed: bool,
    /// Node tags in order of travel (at least two).
    pub tags: Vec<Tag>,
    /// Measured segment lengths (m), one per pair of consecutive tags, when known
    /// (SEGMENT_LENGTH packets or configuration; phone).
    pub segment_lengths: Vec<Option<f64>>,
    pub samples: Samples,
}

impl Curve {
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

/// The device as announced by its HELLO.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    pub kind: String,
    pub device_id: u32,
    pub firmware: u16,
    pub rate_hz: u16,
}

/// Counts of what acquisition saw and did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    /// Sample packets received.
    pub samples: u64,
    /// Samples that arrived before the first HELLO (cannot be interpreted; dropped).
    pub before_hello: u64,
    /// Samples outside any curve (between curves).
    pub outside_curves: u64,
    /// Samples in accepted curves, and how many of them carry each flag.
    pub in_curves: u64,
    pub stationary: u64,
    pub mag_disturbed: u64,
    pub acc_motion: u64,
    pub saturated: u64,
    pub invalid: u64,
    /// Curves discarded (cancelled, or too few tags).
    pub curves_discarded: u64,
    /// Samples of another device kind than the HELLO's (ignored).
    pub wrong_kind: u64,
    /// Implausible jumps of the wheel counter (ignored).
    pub wheel_glitches: u64,
    /// Sensor-array samples older than the window they fall in (out of time order; ignored).
    #[serde(default)]
    pub array_late: u64,
}

/// Per-sensor orientations of a sensor array, one per averaging window.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ArrayEpoch {
    /// Session time of the window's end, s.
    pub t: f64,
    pub sensor: u16,
    /// `[w, x, y, z]`, sensor frame → world.
    pub q: [f64; 4],
    /// Samples averaged.
    pub samples: u32,
    pub flags: u8,
}

/// Everything acquisition produced.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Scan {
    pub device: Option<DeviceInfo>,
    pub curves: Vec<Curve>,
    /// Grammar violations and acquisition problems, in words naming curve, node and time.
    pub warnings: Vec<String>,
    pub counts: Counts,
    /// Median magnetic field norm (µT) and dip (°) of the session, when measured.
    pub field_reference: Option<[f64; 2]>,
    /// Sensor arrays only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub array: Vec<ArrayEpoch>,
}
