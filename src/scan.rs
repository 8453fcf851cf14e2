//! The `Scan` model: what acquisition produced, serialised as `scan.json`. Its curves are the
//! geometry's input type ([`sfs_geometry::curve`]: per accepted curve, the raw samples and the
//! node tags); around them the device, the counts, the warnings and the sensor-array epochs.

use serde::{Deserialize, Serialize};

pub use sfs_geometry::curve::{Curve, Samples, Tag};

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
    /// Warnings beyond the first `acquisition::MAX_WARNINGS`, counted but not kept.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub warnings_left_out: u64,
    /// Every warning acquisition raised, by kind (kept or not; report.json's
    /// `warnings_by_code` adds the reconstruction's).
    #[serde(skip)]
    pub warnings_by_code: std::collections::BTreeMap<&'static str, u64>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
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
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Scan {
    pub device: Option<DeviceInfo>,
    pub curves: Vec<Curve>,
    /// Grammar violations and acquisition problems, naming curve, node and time (written as
    /// their texts).
    pub warnings: Vec<crate::warning::Warning>,
    pub counts: Counts,
    /// Median magnetic field norm (µT) and dip (°) of the session, when measured.
    pub field_reference: Option<[f64; 2]>,
    /// Sensor arrays only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub array: Vec<ArrayEpoch>,
    /// Curves the operator took out of the network from the keypad (`N C`, or `N B … E`
    /// rescanning it; issue 49), in the order they left. They are no longer in `curves`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dropped: Vec<DroppedCurve>,
}

/// A curve taken out of the network from the keypad.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DroppedCurve {
    pub curve: usize,
    /// The curve that replaced it (`None`: dropped).
    pub by: Option<usize>,
    /// Its nodes, as they were tagged.
    pub nodes: Vec<u32>,
}
