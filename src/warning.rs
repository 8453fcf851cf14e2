//! The warnings of a session: every problem met on the way (a keypad sequence the grammar
//! refuses, a sample stream acquisition has to bridge, a curve the reconstruction leaves out,
//! a face the surfacer cannot accept), typed, with the curve, node and time as fields where
//! they have them. Their text (`Display`) is what the log, `scan.json` and `report.json` say;
//! their [`code`](Warning::code) is a stable name of the kind, for machines.

use crate::keypad;
use device_protocol::DeviceKind;
use sfs_geometry::network::NetworkWarning;
use sfs_geometry::surface::fit::SurfaceError;
use sfs_geometry::surface::SurfaceProblem;
use std::collections::{BTreeMap, HashSet};

/// A problem met by a session.
#[derive(Debug, Clone, PartialEq)]
pub enum Warning {
    /// A keypad sequence the grammar refuses.
    Keypad(keypad::Warning),
    /// Something acquisition had to bridge or leave out.
    Acquisition(AcquisitionWarning),
    /// The reconstruction of the network.
    Network(NetworkWarning),
    /// A problem of the surface (a face or patch left out, triangles dropped).
    Surface(SurfaceProblem),
    /// No surface at all.
    NoSurface(SurfaceError),
    /// `network.glb` could not be encoded.
    GlbNotWritten(crate::gltf_out::GltfError),
    /// The surface could not be encoded: `network.glb` holds the curves alone.
    SurfaceNotWritten(crate::gltf_out::GltfError),
    /// Monitoring: sensors streamed that the layout does not place (ignored), said once for
    /// all of them.
    UnknownSensors {
        sensors: Vec<u16>,
        /// The layout's sensors.
        placed: Vec<u16>,
        /// No sensor of the layout streamed at all (no epoch): the wrong layout.
        none_placed: bool,
    },
}

impl Warning {
    /// A stable name of the kind of problem.
    pub fn code(&self) -> &'static str {
        match self {
            Warning::Keypad(w) => w.issue.code(),
            Warning::Acquisition(w) => w.code(),
            Warning::Network(w) => w.code(),
            Warning::Surface(p) => p.code(),
            Warning::NoSurface(_) => "no_surface",
            Warning::GlbNotWritten(_) => "glb_not_written",
            Warning::SurfaceNotWritten(_) => "surface_not_written",
            Warning::UnknownSensors { .. } => "unknown_sensors",
        }
    }

    /// The curve it names, by scan index.
    pub fn curve(&self) -> Option<usize> {
        match self {
            Warning::Keypad(w) => w.curve,
            Warning::Acquisition(w) => w.curve(),
            Warning::Network(w) => w.curve(),
            _ => None,
        }
    }

    /// The node it names.
    pub fn node(&self) -> Option<u32> {
        match self {
            Warning::Keypad(w) => w.node,
            Warning::Network(w) => w.node(),
            _ => None,
        }
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Warning::Keypad(w) => w.fmt(f),
            Warning::Acquisition(w) => w.fmt(f),
            Warning::Network(w) => w.fmt(f),
            Warning::Surface(p) => write!(f, "surface: {p}"),
            Warning::NoSurface(e) => write!(f, "no surface: {e}"),
            Warning::GlbNotWritten(e) => write!(f, "network.glb not written: {e}"),
            Warning::SurfaceNotWritten(e) => write!(
                f,
                "the surface is left out of network.glb (it holds the curves): {e}"
            ),
            Warning::UnknownSensors {
                sensors,
                placed,
                none_placed,
            } => {
                write!(
                    f,
                    "monitor: {} sensor(s) streamed that the layout does not place, ignored: {sensors:?}",
                    sensors.len()
                )?;
                if *none_placed {
                    write!(f, "; no sensor of the layout ({placed:?}) streamed at all: the wrong layout for this array, or one numbered otherwise ([monitor] layout)")
                } else {
                    write!(f, " (the layout places {placed:?}): sensors added to the array since the layout was made, or numbered otherwise")
                }
            }
        }
    }
}

/// Written as its text.
impl serde::Serialize for Warning {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Something acquisition had to bridge, ignore or leave out, with the curve and time where
/// it has them; its text is its `Display`.
#[derive(Debug, Clone, PartialEq)]
pub enum AcquisitionWarning {
    /// The device rebooted while a curve was open: distance and time are bridged.
    RebootInCurve { curve: usize, t: f64 },
    /// A HELLO whose scales cannot be used: samples are ignored until a valid one.
    UnusableHello {
        device_id: u32,
        error: crate::sensor::ScaleError,
    },
    /// The device kind changed mid-session.
    KindChanged { kind: DeviceKind },
    /// The wheel counter jumped (said once per session; such jumps are ignored).
    WheelJump { t: f64, step_m: f64 },
    /// The wheel skidded: its distance is filled from the speed either side.
    WheelSkid {
        curve: usize,
        t: f64,
        duration_s: f64,
        added_m: f64,
    },
    /// A SEGMENT_LENGTH that is not a positive length.
    BadSegmentLength { t: f64, segment: u16, length_m: f64 },
    /// A SEGMENT_LENGTH before any curve.
    SegmentLengthWithoutCurve { t: f64, segment: u16 },
    /// A SEGMENT_LENGTH for a segment the last curve does not have.
    NoSuchSegment {
        curve: usize,
        t: f64,
        segment: u16,
        segments: usize,
    },
    /// A curve with no samples between its start and end.
    NoSamples { curve: usize, nodes: Vec<u32> },
    /// The wheel went back over a segment.
    WheelBack {
        curve: usize,
        node: u32,
        t: f64,
        back_m: f64,
        segment: usize,
        from: u32,
    },
    /// Morphorider: the device rolled while a node's index was typed (the operator stands to
    /// type it): Enter pressed late, or the index typed early. The tag is placed where the
    /// device stood in that time (issue 49).
    LateEnter {
        curve: usize,
        node: u32,
        t: f64,
        /// How far the device went from the first digit to the Enter, m: the wheel's reading
        /// (Morphorider), the accelerometer's set-off and speed (phone).
        rolled_m: f64,
        /// How far the tag moved back from the Enter (negative: on), m.
        moved_m: f64,
    },
    /// A curve reached the configured maximum number of samples and was ended there.
    CurveTooLong {
        curve: usize,
        t: f64,
        samples: usize,
        nodes: Vec<u32>,
    },
    /// The session ended with a curve open.
    NeverEnded {
        curve: usize,
        nodes: Vec<u32>,
        samples: usize,
    },
    /// The configuration sets the kind of a curve the session does not have.
    KindOfMissingCurve {
        curve: usize,
        kind: sfs_geometry::curve::CurveKind,
        curves: usize,
    },
}

impl AcquisitionWarning {
    /// A stable name of the kind of problem.
    pub fn code(&self) -> &'static str {
        use AcquisitionWarning::*;
        match self {
            RebootInCurve { .. } => "reboot_in_curve",
            UnusableHello { .. } => "unusable_hello",
            KindChanged { .. } => "device_kind_changed",
            WheelJump { .. } => "wheel_jump",
            WheelSkid { .. } => "wheel_skid",
            BadSegmentLength { .. } => "bad_segment_length",
            SegmentLengthWithoutCurve { .. } => "segment_length_without_curve",
            NoSuchSegment { .. } => "no_such_segment",
            NoSamples { .. } => "curve_without_samples",
            WheelBack { .. } => "wheel_back",
            LateEnter { .. } => "late_enter",
            CurveTooLong { .. } => "curve_too_long",
            NeverEnded { .. } => "curve_never_ended",
            KindOfMissingCurve { .. } => "kind_of_missing_curve",
        }
    }

    /// The curve it names.
    pub fn curve(&self) -> Option<usize> {
        use AcquisitionWarning::*;
        match self {
            RebootInCurve { curve, .. }
            | WheelSkid { curve, .. }
            | NoSuchSegment { curve, .. }
            | NoSamples { curve, .. }
            | WheelBack { curve, .. }
            | LateEnter { curve, .. }
            | CurveTooLong { curve, .. }
            | NeverEnded { curve, .. }
            | KindOfMissingCurve { curve, .. } => Some(*curve),
            _ => None,
        }
    }
}

impl std::fmt::Display for AcquisitionWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use AcquisitionWarning::*;
        match self {
            RebootInCurve { curve, t } => write!(
                f,
                "curve {curve}, t = {t:.3} s: the device rebooted during the curve; its distance and time are bridged"
            ),
            UnusableHello { device_id, error } => write!(
                f,
                "HELLO of device {device_id} is unusable: {error}; its samples are ignored until a valid HELLO"
            ),
            KindChanged { kind } => write!(
                f,
                "the device kind changed mid-session (now {kind:?}); later samples use it"
            ),
            WheelJump { t, step_m } => write!(
                f,
                "t = {t:.3} s: the wheel counter jumped {step_m:.3} m between two samples; such jumps are ignored"
            ),
            WheelSkid {
                curve,
                t,
                duration_s,
                added_m,
            } => write!(
                f,
                "curve {curve}, t = {t:.3} s: the wheel skidded for {duration_s:.2} s (its speed fell and came back while the accelerometer says the device rolled on); {:.0} mm are added from the speed either side",
                added_m * 1e3
            ),
            BadSegmentLength {
                t,
                segment,
                length_m,
            } => write!(
                f,
                "t = {t:.3} s: SEGMENT_LENGTH of segment {segment} is {length_m} m; ignored"
            ),
            SegmentLengthWithoutCurve { t, segment } => write!(
                f,
                "t = {t:.3} s: SEGMENT_LENGTH {segment} with no curve scanned yet; ignored"
            ),
            NoSuchSegment {
                curve,
                t,
                segment,
                segments,
            } => write!(
                f,
                "curve {curve}, t = {t:.3} s: SEGMENT_LENGTH for segment {segment}, but the curve has {segments} segment(s); ignored"
            ),
            NoSamples { curve, nodes } => write!(
                f,
                "curve {curve}: no samples between its B/I and E (nodes {nodes:?}); it carries no shape"
            ),
            WheelBack {
                curve,
                node,
                t,
                back_m,
                segment,
                from,
            } => write!(
                f,
                "curve {curve}, node {node}, t = {t:.3} s: the wheel went back {back_m:.3} m over segment {segment} (from node {from}); backwards scanning?"
            ),
            LateEnter {
                curve,
                node,
                t,
                rolled_m,
                moved_m,
            } => write!(
                f,
                "curve {curve}, node {node}, t = {t:.3} s: the device went {:.0} mm while the node's index was typed (Enter pressed late, or the index typed early): the tag is placed where it stood, {:.0} mm {} the Enter; rescan the curve if it is wrong (its number, its start key, … E)",
                rolled_m * 1e3,
                moved_m.abs() * 1e3,
                if *moved_m >= 0.0 { "before" } else { "after" }
            ),
            CurveTooLong {
                curve,
                t,
                samples,
                nodes,
            } => write!(
                f,
                "curve {curve}, t = {t:.3} s: {samples} samples, the most a curve may have (acquisition.max_curve_samples): ended here (nodes {nodes:?}); was its E forgotten?"
            ),
            NeverEnded {
                curve,
                nodes,
                samples,
            } => write!(
                f,
                "curve {curve}: the session ended before its E (nodes {nodes:?}, {samples} samples); not used"
            ),
            KindOfMissingCurve {
                curve,
                kind,
                curves,
            } => write!(
                f,
                "curve {curve}: the configuration makes it a {kind} curve (curves.kinds), but the session has {curves} curves (0 to {}); a wrong index?",
                curves.saturating_sub(1)
            ),
        }
    }
}

impl From<keypad::Warning> for Warning {
    fn from(w: keypad::Warning) -> Self {
        Warning::Keypad(w)
    }
}

impl From<AcquisitionWarning> for Warning {
    fn from(w: AcquisitionWarning) -> Self {
        Warning::Acquisition(w)
    }
}

impl From<NetworkWarning> for Warning {
    fn from(w: NetworkWarning) -> Self {
        Warning::Network(w)
    }
}

/// Warnings kept in a scan and in report.json, of every layer together (acquisition's first);
/// the rest are counted by kind (`warnings_by_code`, `warnings_left_out`).
pub const MAX_WARNINGS: usize = 1000;

/// Warnings of one kind logged in full; after them, a summary line at every power of two.
pub const LOGGED_PER_KIND: u64 = 20;

/// Distinct warning texts remembered (so that a warning every update repeats is logged once).
const REMEMBERED: usize = 4096;

/// The log's rate limit for warnings, the same for every kind and layer: the first
/// [`LOGGED_PER_KIND`] of a kind in full, then one line at the 128th, 256th, … with the count;
/// a text already logged is not logged again (a live session reconstructs the same curves'
/// warnings after every curve).
#[derive(Debug, Default)]
pub struct LogLimiter {
    counts: BTreeMap<&'static str, u64>,
    seen: HashSet<String>,
    /// The warnings are of a scan still going on (a live update's): an open face or a curve
    /// not yet joined is a normal intermediate state, logged at info ("for now: …"); the
    /// final reconstruction's are warnings.
    provisional: bool,
}

impl LogLimiter {
    /// A limiter for the live updates of a scan still going on: its lines are at info level.
    pub fn provisional() -> LogLimiter {
        LogLimiter {
            provisional: true,
            ..LogLimiter::default()
        }
    }

    /// Logs `w` at warn level if the limit allows.
    pub fn log(&mut self, w: &Warning) {
        let text = w.to_string();
        if self.seen.contains(&text) {
            return;
        }
        if self.seen.len() < REMEMBERED {
            self.seen.insert(text.clone());
        }
        let n = self.counts.entry(w.code()).or_insert(0);
        *n += 1;
        if self.provisional && !matches!(w, Warning::Keypad(_) | Warning::Acquisition(_)) {
            if *n <= LOGGED_PER_KIND {
                tracing::info!(kind = w.code(), "for now, while the scan goes on: {text}");
            }
            return;
        }
        if *n <= LOGGED_PER_KIND {
            match w {
                Warning::Keypad(k) => tracing::warn!("keypad: {k}"),
                _ => tracing::warn!("{text}"),
            }
        } else if n.is_power_of_two() && *n >= 128 {
            tracing::warn!(
                kind = w.code(),
                count = *n,
                "{} warnings of this kind so far (only the first {LOGGED_PER_KIND} are logged); the latest: {text}",
                *n
            );
        }
    }
}
