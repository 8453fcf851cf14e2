//! Acquisition: decoded packets → calibrated samples → orientations → keypad-tagged curves
//! (the [`Scan`]).
//!
//! Feed every decoder [`Event`] to [`Acquisition::event`]; it reports when a curve ends (or a
//! late SEGMENT_LENGTH changes a finished one). Raw samples of the open curve are kept until
//! its `E`, compactly (raw counts, time, wheel or filter orientation: 64 bytes a sample, in
//! chunks given back as the curve is finalised); a curve that reaches
//! [`AcquisitionConfig::max_curve_samples`] is ended there with a warning (a curve left open
//! for a day must not take the memory). Then the curve is finalised: orientations
//! (Morphorider: [`triad`] per sample; phone: the [`Ahrs`] output, computed causally as
//! samples arrive), distances, flags.
//!
//! The same node tagged twice in a row closes a loop through it (a closed curve with one
//! node) when the device travelled at least [`AcquisitionConfig::loop_distance`] of wheel
//! (Morphorider) or turned through [`AcquisitionConfig::loop_turn`] (phone, which measures no
//! distance: going round a closed curve turns its tangent, and so the device, through at
//! least 360° — Fenchel's theorem) since the first; otherwise it is a repeated Enter (see
//! [`crate::keypad`]).
//!
//! Time: the device clock (`t_us`, wrapping, restarting at power-up) becomes a monotonic
//! session time in seconds: increments are `t_us` differences (wraps included), and a reboot
//! adds nothing. Distance: Morphorider, wheel ticks × circumference / ticks per revolution
//! (backwards motion kept, a reboot's counter reset bridged, a skid filled from the speed
//! either side where the accelerometer says the device rolled on, [`skid`]); phone, the
//! integral of the
//! speed's shape between two tags (its start and stop fitted to the accelerometer, [`speed`];
//! where no fit holds, time while moving by the standing mask), scaled per segment to its
//! measured length (SEGMENT_LENGTH or configuration) or to the nominal speed.

use crate::keypad::{CurveKind, KeyEvent, Keypad};
use crate::orientation::ahrs::{Ahrs, AhrsParams};
use crate::orientation::disturbance::{
    acc_motion, bridge_heading, disturbed_windows, mag_disturbed, norm_dip, FieldReference,
    Thresholds, END_SAMPLES,
};
use crate::orientation::flags;
use crate::orientation::rest;
use crate::orientation::smoother::{self, SmootherParams};
use crate::orientation::triad::triad;
use crate::scan::{ArrayEpoch, Curve, DeviceInfo, Samples, Scan, Tag};
use crate::sensor::{saturated, CalibrationSpec, Scales, SensorModel};
use crate::warning::{AcquisitionWarning, Warning};
use device_protocol::{DeviceKind, Event, Hello, Packet};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::BTreeMap;

pub mod skid;
pub mod speed;

/// Settings of acquisition (documented defaults; `[acquisition]` and `[calibration]` in the
/// configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct AcquisitionConfig {
    /// Device calibration (default: no correction, the wire format's axes for the HELLO's kind).
    pub calibration: CalibrationSpec,
    pub thresholds: Thresholds,
    /// Half-width of the window that decides whether the device stands still, s. Default 0.25.
    pub stationary_window: f64,
    /// Morphorider: the wheel moving less than this (m) over the window counts as still (the
    /// operator's hand is never perfectly still). Default 2 mm.
    pub stationary_distance: f64,
    /// Phone: gyroscope below this (rad/s) over the window counts as still. Default 3°/s.
    pub stationary_gyro: f64,
    /// Phone: a still run counts as standing only within this many seconds of the typing of
    /// a node index (first digit to Enter). Default 1 s. A phone sliding slowly over a large,
    /// gently curved surface turns as little as a standing one (0.5°/s on a 6 m radius at
    /// 5 cm/s), so a still run may cover a whole curve; only the operator's stand at the
    /// node is taken out of the moving time. 2 s (the default before issue 17) took up to a
    /// second of sliding on each side of a node as standing on the simulated spheres and
    /// torus (BENCHMARKS.md, "Field accuracy"). Where the accelerometer shows the stop before
    /// the typing (or the start after it) within 3 s, the stand runs to that pulse instead,
    /// still or not (the hand tilting the device, a turn in place). Since issue 33 a phone's
    /// distances follow the speed fitted to the accelerometer ([`speed`]); this mask is their
    /// fallback where no fit holds, and the samples' standing flags.
    pub stand_margin: f64,
    /// Phone: speed assumed where no segment length is known, m/s. Default 0.05.
    pub nominal_speed: f64,
    /// Curve kinds set by curve index (configuration `[curves] kinds`), over the start key's.
    pub kinds: std::collections::BTreeMap<usize, CurveKind>,
    /// Phone: measured segment lengths per curve index (m), from the configuration.
    pub segment_lengths: BTreeMap<usize, Vec<f64>>,
    pub ahrs: AhrsParams,
    /// Morphorider: bridge the heading across stretches of a curve where the field is
    /// disturbed ([`bridge_heading`]), from their clean ends. Default on.
    pub bridge_heading: bool,
    /// Morphorider: fill the stretches where the wheel skidded ([`skid`]) from the speed
    /// either side. Default on.
    pub fill_skids: bool,
    /// Phone: smooth each finished curve's orientations forward and backward ([`smoother`]);
    /// off, a curve keeps the causal filter's. Default on.
    pub smooth: bool,
    pub smoother: SmootherParams,
    /// Sensor arrays: averaging window, s. Default 1.
    pub array_window: f64,
    /// Largest node index the keypad accepts; a larger one is not tagged. Default 999 999.
    pub max_node: u32,
    /// A curve that reaches this many samples is ended there, with a warning naming it.
    /// Default 2 000 000 (5.5 h at 100 Hz; 128 MB held).
    pub max_curve_samples: usize,
    /// Morphorider: wheel travel (m) between two tags of the same node that makes them a loop
    /// through it rather than a repeated Enter. Default 0.05.
    pub loop_distance: f64,
    /// Phone: the angle (rad) the device turned through between two tags of the same node
    /// that makes them a loop. Default π (a loop turns through 2π at least).
    pub loop_turn: f64,
    /// Integrate the curve being scanned for the live view ([`Acquisition::preview`]); off
    /// (no cost) unless a view is served. Not a configuration key: `--view` sets it.
    pub preview: bool,
}

impl Default for AcquisitionConfig {
    fn default() -> Self {
        AcquisitionConfig {
            calibration: CalibrationSpec::default(),
            thresholds: Thresholds::default(),
            stationary_window: 0.25,
            stationary_distance: 0.002,
            stationary_gyro: 3f64.to_radians(),
            stand_margin: 1.0,
            nominal_speed: 0.05,
            kinds: Default::default(),
            segment_lengths: BTreeMap::new(),
            ahrs: AhrsParams::default(),
            bridge_heading: true,
            fill_skids: true,
            smooth: true,
            smoother: SmootherParams::default(),
            array_window: 1.0,
            max_node: crate::keypad::MAX_NODE,
            max_curve_samples: 2_000_000,
            loop_distance: 0.05,
            loop_turn: std::f64::consts::PI,
            preview: false,
        }
    }
}

pub use crate::warning::{LOGGED_PER_KIND, MAX_WARNINGS};

/// Largest wheel advance between consecutive samples taken as real motion, m.
pub const MAX_WHEEL_STEP: f64 = 0.5;

/// "curve ended" lines logged per minute of session time: an operator ends a curve every half
/// minute or so, a key storm thousands; the rest are counted and said in one line.
const CURVE_LINES_PER_MINUTE: u32 = 10;

/// The log's rate limit for "curve ended" lines (session time, so a replay logs what the
/// session did).
#[derive(Debug, Default)]
struct CurveLines {
    window: f64,
    logged: u32,
    left_out: u64,
}

impl CurveLines {
    /// Whether the line of a curve ended at session time `t` is logged.
    fn allow(&mut self, t: f64) -> bool {
        if !(self.window..self.window + 60.0).contains(&t) {
            if self.left_out > 0 {
                tracing::info!(
                    curves = self.left_out,
                    "{} more curves ended within a minute (their lines left out of the log)",
                    self.left_out
                );
            }
            *self = CurveLines {
                window: t,
                ..Default::default()
            };
        }
        if self.logged < CURVE_LINES_PER_MINUTE {
            self.logged += 1;
            true
        } else {
            self.left_out += 1;
            false
        }
    }
}

/// The curve being scanned ([`Acquisition::open_curve`]).
#[derive(Debug, Clone, PartialEq)]
pub struct OpenCurveInfo {
    pub index: usize,
    /// As started (the configuration's override applies when the curve ends).
    pub kind: CurveKind,
    /// Nodes tagged so far.
    pub nodes: Vec<u32>,
    pub samples: usize,
    /// Wheel distance since the first tag (Morphorider), m.
    pub distance_m: Option<f64>,
}

/// What [`Acquisition::event`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Update {
    /// Curve `index` was accepted.
    CurveEnded(usize),
    /// Curve `index` changed after it ended (a late SEGMENT_LENGTH).
    CurveUpdated(usize),
}

/// One sample of an open curve as received: raw counts and what was measured causally, 64
/// bytes (calibration is applied when the curve is finalised, with the sensor model of the
/// sample: [`OpenCurve::models`]).
#[derive(Debug, Clone, Copy)]
struct Raw {
    /// Session time, s.
    t: f64,
    /// Morphorider: `[session wheel distance (m), 0, 0, 0]`; phone: the filter's orientation
    /// at this sample, `[w, i, j, k]`.
    x: [f64; 4],
    /// Raw counts of the accelerometer, magnetometer and gyroscope (zero on a Morphorider).
    acc: [i16; 3],
    mag: [i16; 3],
    gyro: [i16; 3],
    flags: u8,
}
const _: () = assert!(std::mem::size_of::<Raw>() <= 64);

/// Samples per chunk of an open curve (4 MB): a long curve grows a chunk at a time (no
/// reallocation that holds the old and the new buffer at once) and is given back chunk by
/// chunk as it is finalised.
const CHUNK: usize = 1 << 16;

/// The raw samples of an open curve, in chunks of [`CHUNK`].
#[derive(Debug, Clone, Default)]
struct RawSamples {
    chunks: Vec<Vec<Raw>>,
    len: usize,
}

impl RawSamples {
    fn push(&mut self, r: Raw) {
        match self.chunks.last_mut() {
            Some(c) if c.len() < CHUNK => c.push(r),
            _ => {
                let mut c = Vec::with_capacity(CHUNK.min(self.len.max(256).next_power_of_two()));
                c.push(r);
                self.chunks.push(c);
            }
        }
        self.len += 1;
    }

    fn len(&self) -> usize {
        self.len
    }
}

#[derive(Debug, Clone)]
struct OpenCurve {
    index: usize,
    kind: CurveKind,
    tags: Vec<(u32, f64, bool)>,
    /// The travel measure (see [`Acquisition::travel`]) at each tag.
    tag_travel: Vec<f64>,
    /// `(first digit, Enter)` times of every node tag: the operator stands while typing.
    typing: Vec<(f64, f64)>,
    /// Time of the first digit of the index being typed.
    first_digit: Option<f64>,
    raw: RawSamples,
    /// The sensor model of the samples from each index on (a HELLO with other scales can
    /// come in the middle of a curve), with the model's generation
    /// ([`Acquisition::model_generation`]).
    models: Vec<(usize, u64, SensorModel)>,
    segment_lengths: BTreeMap<u16, f64>,
    /// The curve integrated so far, for the live view.
    preview: PreviewPath,
}

/// An open curve's path integrated from its first node (orientations × distances), world
/// frame, relative to the node.
#[derive(Debug, Clone)]
struct PreviewPath {
    at: Vector3<f64>,
    points: Vec<Vector3<f64>>,
    since: f64,
    spacing: f64,
}

impl Default for PreviewPath {
    fn default() -> Self {
        PreviewPath {
            at: Vector3::zeros(),
            points: Vec::new(),
            since: 0.0,
            spacing: PREVIEW_SPACING,
        }
    }
}

/// Distance between the points of a preview, m (at first).
pub const PREVIEW_SPACING: f64 = 0.005;
/// Points a preview holds at most.
pub const PREVIEW_POINTS: usize = 2048;

#[derive(Debug, Clone, Default)]
struct ArraySensor {
    /// The window being averaged: `[window · W, (window + 1) · W)` of session time.
    window: i64,
    acc: Vector3<f64>,
    mag: Vector3<f64>,
    n: u32,
    flags: u8,
    /// Session time of its newest sample, s.
    last_t: f64,
}

/// The acquisition state. See the module documentation.
#[derive(Debug)]
pub struct Acquisition {
    cfg: AcquisitionConfig,
    model: Option<SensorModel>,
    kind: Option<DeviceKind>,
    clock: crate::clock::Clock,
    wheel_last: Option<i32>,
    wheel_m: f64,
    wheel_reset: bool,
    keypad: Keypad,
    key_events: Vec<KeyEvent>,
    open: Option<OpenCurve>,
    scan: Scan,
    field: FieldReference,
    /// Sensor arrays: the field reference as of a window (its median is recomputed once per
    /// window, not once per sensor).
    array_field: Option<(i64, Option<(f64, f64)>)>,
    /// Sensor arrays: the newest window of the grid seen.
    array_grid: Option<i64>,
    ahrs: Ahrs,
    last_sample_t: Option<f64>,
    /// The log's rate limit for "curve ended" lines.
    curve_lines: CurveLines,
    gap: bool,
    array: BTreeMap<u16, ArraySensor>,
    /// Per-curve segment lengths received after the curve ended (phone).
    late_lengths: BTreeMap<usize, BTreeMap<u16, f64>>,
    /// The log's rate limit for the warnings.
    warned: crate::warning::LogLimiter,
    /// Counts the sensor models taken from HELLOs (an open curve notes the one of its
    /// samples).
    model_generation: u64,
    /// Phone: the angle the filter's orientation turned through in the session (rad), summed
    /// over steps of [`TURN_STEP`] seconds, and the orientation at the last step.
    turned: f64,
    turn_anchor: Option<(f64, UnitQuaternion<f64>)>,
    /// Phone: the filter's latest orientation.
    last_q: Option<UnitQuaternion<f64>>,
    /// Morphorider: the latest calibrated acceleration and field (its orientation, on demand).
    last_field: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Events received before the first HELLO, held until it comes (then interpreted with its
    /// scales, in order) — `None` once a HELLO was seen.
    held: Option<Vec<Event>>,
    /// Phone: the session's noise floors (window spreads of the gyroscope, accelerometer and
    /// magnetometer at rest), the least over the curves so far.
    noise: Option<rest::NoiseFloors>,
}

/// Curves longer than this are not smoothed (the smoother keeps about 350 bytes per sample:
/// 90 MB here, 21 minutes of a 200 Hz phone): they keep the causal filter's orientations, and
/// the log says so.
const MAX_SMOOTHED_SAMPLES: usize = 250_000;

/// Morphorider curves longer than this are not searched for wheel skids (the search keeps
/// about 64 bytes per sample: 64 MB here, 2.8 hours at 100 Hz); the log says so.
const MAX_SKID_CHECKED_SAMPLES: usize = 1_000_000;

/// Most events held before the first HELLO. A device sends one every 5 s, so a receiver that
/// joins mid-stream holds about 5 s (10 s if that HELLO is lost on the link) of a 200 Hz
/// stream; past this many, the oldest are interpreted without scales (counted as
/// `before_hello`, their keys kept).
const MAX_HELD: usize = 20_000;

/// Phone: the turning of the device is summed over steps of this many seconds: a step is
/// long enough that the filter's jitter at rest adds little, short enough that a turn and
/// its return are both counted.
const TURN_STEP: f64 = 0.5;

impl Acquisition {
    /// The scan of a whole capture held in memory (decoder and acquisition in one call; for
    /// tests, studies and benchmarks; sessions stream through [`event`](Self::event)).
    pub fn scan_bytes(bytes: &[u8], cfg: AcquisitionConfig) -> Scan {
        let mut dec = device_protocol::Decoder::new();
        let mut acq = Acquisition::new(cfg);
        for e in dec.feed(bytes) {
            acq.event(&e);
        }
        acq.finish()
    }

    pub fn new(cfg: AcquisitionConfig) -> Self {
        Self::starting_at(cfg, &crate::clock::CaptureStart::default())
    }

    /// Acquisition of a capture file that continues an earlier one (a rotated capture: its
    /// session time goes on from `start`).
    pub fn starting_at(cfg: AcquisitionConfig, start: &crate::clock::CaptureStart) -> Self {
        let ahrs = Ahrs::new(cfg.ahrs);
        let keypad = Keypad::with_max_node(cfg.max_node);
        let mut acq = Acquisition {
            cfg,
            model: None,
            kind: None,
            clock: crate::clock::Clock::at(start),
            wheel_last: None,
            wheel_m: 0.0,
            wheel_reset: false,
            keypad,
            key_events: Vec::new(),
            open: None,
            scan: Scan::default(),
            field: FieldReference::new(),
            array_field: None,
            array_grid: None,
            ahrs,
            last_sample_t: None,
            curve_lines: CurveLines::default(),
            gap: false,
            array: BTreeMap::new(),
            late_lengths: BTreeMap::new(),
            warned: Default::default(),
            model_generation: 0,
            turned: 0.0,
            turn_anchor: None,
            last_q: None,
            last_field: None,
            held: Some(Vec::new()),
            noise: None,
        };
        if let Some(h) = start.hello() {
            acq.hello(&h);
            acq.held = None;
        }
        acq
    }

    /// The scan so far (accepted curves only).
    pub fn scan(&self) -> &Scan {
        &self.scan
    }

    /// Session time of the latest packet, s.
    pub fn session_time(&self) -> f64 {
        self.clock.now()
    }

    /// The device's latest orientation (frame `[T B N]` → world): TRIAD of the latest
    /// sample on a Morphorider, the filter's on a phone.
    pub fn orientation(&self) -> Option<UnitQuaternion<f64>> {
        match self.kind {
            Some(DeviceKind::Phone) => self.last_q,
            Some(DeviceKind::Morphorider) => self.last_field.and_then(|(a, m)| triad(&a, &m)),
            _ => None,
        }
    }

    /// Whether a curve is open.
    pub fn curve_open(&self) -> bool {
        self.open.is_some()
    }

    /// The curve being scanned, if one is open.
    pub fn open_curve(&self) -> Option<OpenCurveInfo> {
        let o = self.open.as_ref()?;
        let distance_m = match self.kind {
            Some(DeviceKind::Phone) => None,
            _ => Some(
                o.tag_travel
                    .first()
                    .map_or(0.0, |first| self.wheel_m - first),
            ),
        };
        Some(OpenCurveInfo {
            index: o.index,
            kind: o.kind,
            nodes: o.tags.iter().map(|t| t.0).collect(),
            samples: o.raw.len(),
            distance_m,
        })
    }

    /// Sensor arrays: the session time up to which every sensor's windows are complete (the
    /// start of the newest window a sample fell in); `None` before the first sample.
    pub fn array_complete_until(&self) -> Option<f64> {
        self.array_grid.map(|k| k as f64 * self.cfg.array_window)
    }

    /// Takes the sensor-array epochs gathered so far (monitoring consumes them as they come,
    /// so that a month-long session does not keep them all).
    pub fn take_array(&mut self) -> Vec<ArrayEpoch> {
        std::mem::take(&mut self.scan.array)
    }

    fn warn(&mut self, w: AcquisitionWarning) {
        self.note(w.into());
    }

    /// Keeps a warning: logged while its kind is rare (the first [`LOGGED_PER_KIND`] of each
    /// kind, then the 100th, 1000th, … with the count), kept in the scan up to
    /// [`MAX_WARNINGS`] (the rest counted as `warnings_left_out`): a stuck key must not fill
    /// the log, the memory or report.json.
    fn note(&mut self, w: Warning) {
        self.warned.log(&w);
        *self
            .scan
            .counts
            .warnings_by_code
            .entry(w.code())
            .or_insert(0) += 1;
        if self.scan.warnings.len() < MAX_WARNINGS {
            self.scan.warnings.push(w);
        } else {
            self.scan.counts.warnings_left_out += 1;
        }
    }

    /// Processes one decoder event; returns the curves it ended or changed (several when
    /// events held before the first HELLO are interpreted at once).
    ///
    /// Before the first HELLO the scales are unknown: packets are held, in order, and
    /// interpreted when it comes, so that a receiver that joins a stream mid-way (or whose
    /// first HELLO is lost) loses no samples of the curve under way.
    pub fn event(&mut self, ev: &Event) -> Vec<Update> {
        let Some(held) = &mut self.held else {
            return self.interpret(ev).into_iter().collect();
        };
        match ev {
            Event::Packet {
                packet: Packet::Hello(_),
                ..
            } => {
                let held = self.held.take().unwrap_or_default();
                let mut out: Vec<Update> = self.interpret(ev).into_iter().collect();
                out.extend(held.iter().filter_map(|e| self.interpret(e)));
                out
            }
            Event::DeviceReboot => {
                // What came before belongs to another power cycle, whose HELLO never came.
                let mut out = self.release_held();
                self.held = Some(Vec::new());
                out.extend(self.interpret(ev));
                out
            }
            _ => {
                held.push(*ev);
                if held.len() >= MAX_HELD {
                    let out = self.release_held();
                    self.held = Some(Vec::new());
                    return out;
                }
                Vec::new()
            }
        }
    }

    /// Interprets the held events without scales (their samples count as `before_hello`).
    fn release_held(&mut self) -> Vec<Update> {
        let held = self.held.take().unwrap_or_default();
        held.iter().filter_map(|e| self.interpret(e)).collect()
    }

    fn interpret(&mut self, ev: &Event) -> Option<Update> {
        match ev {
            Event::Packet { packet, .. } => self.packet(packet),
            Event::DeviceReboot => {
                self.clock.restart();
                self.wheel_reset = true;
                // The device may have been turned while silent: the filter starts again from
                // the next sample's accelerometer and magnetometer (keeping the gyroscope bias).
                self.ahrs.restart();
                self.last_sample_t = None;
                let t = self.clock.now();
                if let Some(o) = &self.open {
                    let w = AcquisitionWarning::RebootInCurve { curve: o.index, t };
                    self.warn(w);
                }
                None
            }
            Event::SequenceGap { .. } => {
                self.gap = true;
                self.keypad.link_gap(self.clock.now());
                None
            }
            _ => None,
        }
    }

    fn hello(&mut self, h: &Hello) {
        let scales = Scales::from_hello(h);
        let has_gyro = h.kind == DeviceKind::Phone;
        if let Err(e) = scales.validate(has_gyro) {
            self.warn(AcquisitionWarning::UnusableHello {
                device_id: h.device_id,
                error: e,
            });
            self.model = None;
            return;
        }
        let same =
            self.model.as_ref().is_some_and(|m| m.scales == scales) && self.kind == Some(h.kind);
        if same {
            return;
        }
        if self.kind.is_some() && self.kind != Some(h.kind) {
            self.warn(AcquisitionWarning::KindChanged { kind: h.kind });
        }
        let cal = self.cfg.calibration.resolve(h.kind);
        self.model = Some(SensorModel::new(scales, cal));
        self.model_generation += 1;
        self.kind = Some(h.kind);
        self.scan.device = Some(DeviceInfo {
            kind: h.kind.to_string(),
            device_id: h.device_id,
            firmware: h.firmware,
            rate_hz: h.rate_hz,
        });
    }

    fn packet(&mut self, p: &Packet) -> Option<Update> {
        match p {
            Packet::Hello(h) => {
                self.hello(h);
                None
            }
            Packet::RiderSample(s) => {
                self.scan.counts.samples += 1;
                let t = self.clock.advance(s.t_us);
                let model = self.usable(DeviceKind::Morphorider)?;
                let (acc, mag) = (model.acc(s.acc), model.mag(s.mag));
                self.last_field = Some((acc, mag));
                let per_tick = model.scales.wheel_m_per_tick.unwrap_or(0.0);
                let wheel_before = self.wheel_m;
                if let Some(last) = self.wheel_last.filter(|_| !self.wheel_reset) {
                    let step = s.wheel.wrapping_sub(last) as f64 * per_tick;
                    // Between two samples (a few ms, or a gap) the operator's hand moves well
                    // under a metre: a larger jump is a glitch of the counter, bridged.
                    if step.abs() <= MAX_WHEEL_STEP {
                        self.wheel_m += step;
                    } else {
                        self.scan.counts.wheel_glitches += 1;
                        if self.scan.counts.wheel_glitches == 1 {
                            self.warn(AcquisitionWarning::WheelJump { t, step_m: step });
                        }
                    }
                }
                self.wheel_reset = false;
                self.wheel_last = Some(s.wheel);
                let mut f = 0;
                if saturated(s.acc) || saturated(s.mag) {
                    f |= flags::SATURATED;
                }
                if f == 0 && !acc_motion(&acc, &self.cfg.thresholds) {
                    self.field.add(&acc, &mag);
                }
                let step = self.wheel_m - wheel_before;
                let tagged = self.open.as_ref().is_some_and(|o| !o.tags.is_empty());
                if self.cfg.preview && tagged && step != 0.0 {
                    if let Some(q) = triad(&acc, &mag) {
                        self.preview_step(&q, step);
                    }
                }
                self.sample(Raw {
                    t,
                    x: [self.wheel_m, 0.0, 0.0, 0.0],
                    acc: s.acc,
                    mag: s.mag,
                    gyro: [0; 3],
                    flags: f,
                })
            }
            Packet::PhoneSample(s) => {
                self.scan.counts.samples += 1;
                let t = self.clock.advance(s.t_us);
                let model = self.usable(DeviceKind::Phone)?;
                let (acc, gyro, mag) = (model.acc(s.acc), model.gyro(s.gyro), model.mag(s.mag));
                let mut f = 0;
                if saturated(s.acc) || saturated(s.mag) || saturated(s.gyro) {
                    f |= flags::SATURATED;
                }
                let dt = self.last_sample_t.map_or(0.0, |l| t - l);
                self.last_sample_t = Some(t);
                let q = self.ahrs.update(dt, &gyro, &acc, Some(&mag));
                if self.ahrs.mag_rejected {
                    f |= flags::MAG_DISTURBED;
                }
                if !acc_motion(&acc, &self.cfg.thresholds) {
                    self.field.add(&acc, &mag);
                }
                self.turn(t, q);
                if self.cfg.preview {
                    // The preview assumes the nominal speed, but while an index is typed.
                    let typing = self.open.as_ref().is_some_and(|o| o.first_digit.is_some());
                    let step = if typing {
                        0.0
                    } else {
                        self.cfg.nominal_speed * dt
                    };
                    self.preview_step(&q, step);
                }
                self.sample(Raw {
                    t,
                    x: quat_array(&q),
                    acc: s.acc,
                    mag: s.mag,
                    gyro: s.gyro,
                    flags: f,
                })
            }
            Packet::ArraySample(s) => {
                self.scan.counts.samples += 1;
                let t = self.clock.advance(s.t_us);
                let model = self.usable(DeviceKind::SensorArray)?;
                let (acc, mag) = (model.acc(s.acc), model.mag(s.mag));
                let sat = saturated(s.acc) || saturated(s.mag);
                self.array_sample(t, s.sensor, acc, mag, sat);
                None
            }
            Packet::Key(k) => {
                let t = self.clock.advance(k.t_us);
                self.key(t, k.key)
            }
            Packet::SegmentLength(s) => {
                let t = self.clock.advance(s.t_us);
                self.segment_length(t, s.segment, s.length_um as f64 * 1e-6)
            }
            Packet::Status(s) => {
                self.clock.advance(s.t_us);
                None
            }
        }
    }

    /// The sensor model if a HELLO of `kind` was seen; counts the sample otherwise.
    fn usable(&mut self, kind: DeviceKind) -> Option<SensorModel> {
        match (&self.model, self.kind) {
            (None, _) => {
                self.scan.counts.before_hello += 1;
                None
            }
            (Some(m), Some(k)) if k == kind => Some(m.clone()),
            _ => {
                self.scan.counts.wrong_kind += 1;
                None
            }
        }
    }

    /// Keeps a sample of the open curve (counted outside curves when none is open); ends the
    /// curve when it reaches [`AcquisitionConfig::max_curve_samples`].
    fn sample(&mut self, mut raw: Raw) -> Option<Update> {
        if std::mem::take(&mut self.gap) {
            raw.flags |= flags::AFTER_GAP;
        }
        let Some(o) = &mut self.open else {
            self.scan.counts.outside_curves += 1;
            return None;
        };
        if o.models.last().is_none_or(|m| m.1 != self.model_generation) {
            let model = self
                .model
                .clone()
                .expect("samples are kept only with a model");
            o.models.push((o.raw.len(), self.model_generation, model));
        }
        o.raw.push(raw);
        if o.raw.len() < self.cfg.max_curve_samples {
            return None;
        }
        let w = AcquisitionWarning::CurveTooLong {
            curve: o.index,
            t: raw.t,
            samples: o.raw.len(),
            nodes: o.tags.iter().map(|t| t.0).collect(),
        };
        self.warn(w);
        let mut events = std::mem::take(&mut self.key_events);
        events.clear();
        self.keypad
            .end_curve(raw.t, "ended at its largest size", &mut events);
        self.key_events(events)
    }

    /// Moves the open curve's preview by `step` metres along the direction of travel of `q`
    /// (the frame's T axis), adding a point every [`PREVIEW_SPACING`] (or more: the spacing
    /// doubles whenever [`PREVIEW_POINTS`] are reached, so a long curve stays bounded).
    fn preview_step(&mut self, q: &UnitQuaternion<f64>, step: f64) {
        let Some(o) = &mut self.open else { return };
        if o.tags.is_empty() || step == 0.0 {
            return; // from its first node on
        }
        let p = &mut o.preview;
        p.at += q * Vector3::x() * step;
        p.since += step.abs();
        if p.since >= p.spacing {
            p.since = 0.0;
            p.points.push(p.at);
            if p.points.len() >= PREVIEW_POINTS {
                let kept: Vec<_> = p.points.iter().step_by(2).copied().collect();
                p.points = kept;
                p.spacing *= 2.0;
            }
        }
    }

    /// The open curve's preview: its first node and the points integrated from it so far
    /// (world frame, relative to the node), if a curve is open and tagged.
    pub fn preview(&self) -> Option<(usize, u32, Vec<Vector3<f64>>)> {
        let o = self.open.as_ref()?;
        let first = o.tags.first()?.0;
        let mut pts = Vec::with_capacity(o.preview.points.len() + 2);
        pts.push(Vector3::zeros());
        pts.extend(&o.preview.points);
        pts.push(o.preview.at);
        Some((o.index, first, pts))
    }

    /// Phone: adds the turning of the filter's orientation `q` at time `t` to
    /// [`turned`](Self::turned).
    fn turn(&mut self, t: f64, q: UnitQuaternion<f64>) {
        self.last_q = Some(q);
        match self.turn_anchor {
            Some((t0, _)) if t - t0 < TURN_STEP => {}
            Some((_, q0)) => {
                self.turned += q0.angle_to(&q);
                self.turn_anchor = Some((t, q));
            }
            None => self.turn_anchor = Some((t, q)),
        }
    }

    /// The measure of travel whose change between two tags of one node tells a loop from a
    /// repeat: the session wheel distance (m) on a Morphorider, the angle turned (rad) on a
    /// phone.
    fn travel(&self) -> f64 {
        match self.kind {
            Some(DeviceKind::Phone) => {
                let since_anchor = match (self.turn_anchor, self.last_q) {
                    (Some((_, q0)), Some(q)) => q0.angle_to(&q),
                    _ => 0.0,
                };
                self.turned + since_anchor
            }
            _ => self.wheel_m,
        }
    }

    /// Whether the device travelled a loop since the open curve's last tag.
    fn travelled_loop(&self) -> bool {
        let Some(last) = self.open.as_ref().and_then(|o| o.tag_travel.last()) else {
            return false;
        };
        let moved = (self.travel() - last).abs();
        match self.kind {
            Some(DeviceKind::Phone) => moved >= self.cfg.loop_turn,
            _ => moved >= self.cfg.loop_distance,
        }
    }

    fn key(&mut self, t: f64, key: u8) -> Option<Update> {
        if let Some(o) = &mut self.open {
            if key.is_ascii_digit() {
                o.first_digit.get_or_insert(t);
            } else if key != b'\n' && key != b'\r' {
                o.first_digit = None;
            }
        }
        let mut events = std::mem::take(&mut self.key_events);
        events.clear();
        self.keypad.set_travelled(self.travelled_loop());
        self.keypad.key(t, key, &mut events);
        self.key_events(events)
    }

    /// Acts on what the keypad did.
    fn key_events(&mut self, mut events: Vec<KeyEvent>) -> Option<Update> {
        let mut update = None;
        let travel = self.travel();
        for ev in events.drain(..) {
            match ev {
                KeyEvent::Started { curve, kind } => {
                    self.open = Some(OpenCurve {
                        index: curve,
                        kind,
                        tags: Vec::new(),
                        tag_travel: Vec::new(),
                        typing: Vec::new(),
                        first_digit: None,
                        raw: RawSamples::default(),
                        models: Vec::new(),
                        segment_lengths: BTreeMap::new(),
                        preview: PreviewPath::default(),
                    });
                }
                KeyEvent::Tagged {
                    node, t, uncertain, ..
                } => {
                    if let Some(o) = &mut self.open {
                        o.tags.push((node, t, uncertain));
                        o.tag_travel.push(travel);
                        o.typing.push((o.first_digit.take().unwrap_or(t), t));
                    }
                }
                KeyEvent::Untagged { .. } => {
                    if let Some(o) = &mut self.open {
                        o.tags.pop();
                        o.tag_travel.pop();
                    }
                }
                KeyEvent::Discarded { .. } => {
                    if let Some(o) = self.open.take() {
                        self.scan.counts.curves_discarded += 1;
                        self.scan.counts.outside_curves += o.raw.len() as u64;
                    }
                }
                KeyEvent::Ended { curve } => {
                    if let Some(o) = self.open.take() {
                        let c = self.finalise(o);
                        self.scan.curves.push(c);
                        update = Some(Update::CurveEnded(curve));
                    }
                }
                KeyEvent::Warning(w) => self.note(w.into()),
            }
        }
        self.key_events = events;
        update
    }

    /// Phone: replaces the causal orientations of a finished curve (`s.q`) by the smoother's
    /// ([`smoother`]), with rests from window statistics against the session's noise; returns
    /// the smoothed gyroscope bias per sample.
    fn smooth_phone(
        &mut self,
        s: &mut Samples,
        [gyro, acc, mag]: [&[Vector3<f64>]; 3],
        field: Option<(f64, f64)>,
        bias: Vector3<f64>,
        typing: &[(f64, f64)],
    ) -> Vec<Vector3<f64>> {
        let n = s.t.len();
        let (mut rest, floors) = rest::rests(&s.t, gyro, acc, mag, self.noise);
        self.noise = Some(floors);
        // Zero rate only where the operator stands to type: elsewhere a still gyroscope may be
        // a phone sliding slowly, whose turn the bias would absorb (BENCHMARKS.md, "Field
        // accuracy": a great circle on the sphere took 40° of heading so).
        clip_to_intervals(&s.t, &mut rest, typing, self.cfg.stand_margin);
        let nd: Vec<[f32; 2]> = acc.iter().zip(mag).map(|(a, m)| norm_dip(a, m)).collect();
        let disturbed = disturbed_windows(&s.t, &nd, field, &self.cfg.thresholds);
        let sd = floors.per_axis();
        let m = smoother::Measurements {
            t: &s.t,
            gyro,
            acc,
            mag,
            rest: &rest,
            disturbed: &disturbed,
            field,
            gyro_noise: sd.gyro,
            acc_noise: sd.acc,
            mag_noise: sd.mag,
        };
        // Start from the first sample's gravity and field where they give an orientation (the
        // causal filter may not have settled yet), else from the causal filter.
        let q0 = acc
            .first()
            .zip(mag.first())
            .and_then(|(a, m)| triad(a, m))
            .or_else(|| s.q.first().map(quat_of))
            .unwrap_or_else(UnitQuaternion::identity);
        let out = smoother::smooth(&m, q0, bias, &self.cfg.smoother);
        tracing::debug!(
            samples = n,
            rests = rest.iter().filter(|&&r| r).count(),
            refused_gravity = out.refused_gravity,
            refused_heading = out.refused_heading,
            gyro_floor = floors.gyro,
            acc_floor = floors.acc,
            mag_floor = floors.mag,
            "curve smoothed"
        );
        for (dst, q) in s.q.iter_mut().zip(&out.q) {
            *dst = quat_array(q);
        }
        out.bias
    }

    fn segment_length(&mut self, t: f64, segment: u16, len: f64) -> Option<Update> {
        if !(len.is_finite() && len > 0.0) {
            self.warn(AcquisitionWarning::BadSegmentLength {
                t,
                segment,
                length_m: len,
            });
            return None;
        }
        if let Some(o) = &mut self.open {
            o.segment_lengths.insert(segment, len);
            return None;
        }
        let Some(last) = self.scan.curves.last() else {
            self.warn(AcquisitionWarning::SegmentLengthWithoutCurve { t, segment });
            return None;
        };
        let index = last.index;
        let nseg = last.tags.len().saturating_sub(1);
        if segment as usize >= nseg {
            self.warn(AcquisitionWarning::NoSuchSegment {
                curve: index,
                t,
                segment,
                segments: nseg,
            });
            return None;
        }
        self.late_lengths
            .entry(index)
            .or_default()
            .insert(segment, len);
        let lengths = self.late_lengths[&index].clone();
        let curve = self.scan.curves.last_mut().expect("checked");
        for (s, l) in lengths {
            curve.segment_lengths[s as usize] = Some(l);
        }
        if self.kind == Some(DeviceKind::Phone) {
            rescale_segments(curve);
        }
        Some(Update::CurveUpdated(index))
    }

    /// Turns an open curve's raw samples into a [`Curve`].
    fn finalise(&mut self, mut o: OpenCurve) -> Curve {
        let n = o.raw.len();
        let mut s = Samples {
            t: Vec::with_capacity(n),
            d: vec![0.0; n],
            q: Vec::with_capacity(n),
            flags: Vec::with_capacity(n),
            w: Vec::new(),
        };
        let th = self.cfg.thresholds;
        let phone = self.kind == Some(DeviceKind::Phone);
        // Orientations and per-sample flags, giving the raw samples back a chunk at a time.
        let field_ref = self.field.reference();
        let bias = self.ahrs.bias();
        let mut last_q: Option<UnitQuaternion<f64>> = None;
        let mut missing_before_first = 0;
        // Morphorider: the wheel and the field's norm and dip; phone: the calibrated sensors
        // (for the smoother, on curves it smooths) or whether the gyroscope is still.
        let smoothing = phone && self.cfg.smooth && (2..=MAX_SMOOTHED_SAMPLES).contains(&n);
        if phone && self.cfg.smooth && n > MAX_SMOOTHED_SAMPLES {
            tracing::warn!(
                curve = o.index,
                samples = n,
                "a curve of more than {MAX_SMOOTHED_SAMPLES} samples keeps the causal filter's \
                 orientations (not smoothed)"
            );
        }
        let mut wheel: Vec<f64> = Vec::with_capacity(if phone { 0 } else { n });
        // Morphorider: the accelerometer (for the skids).
        let skid_check = !phone && self.cfg.fill_skids && n <= MAX_SKID_CHECKED_SAMPLES;
        if !phone && self.cfg.fill_skids && !skid_check {
            tracing::warn!(
                curve = o.index,
                samples = n,
                "a curve of more than {MAX_SKID_CHECKED_SAMPLES} samples is not searched for \
                 wheel skids"
            );
        }
        let mut rider_acc: Vec<Vector3<f64>> = Vec::with_capacity(if skid_check { n } else { 0 });
        let mut nd: Vec<[f32; 2]> = Vec::with_capacity(if phone { 0 } else { n });
        let k = if smoothing { n } else { 0 };
        let (mut gyros, mut accs, mut mags) = (
            Vec::with_capacity(k),
            Vec::with_capacity(k),
            Vec::with_capacity(k),
        );
        let mut gyro_still: Vec<bool> = Vec::new();
        let models = std::mem::take(&mut o.models);
        let mut model = 0;
        let raw = std::mem::take(&mut o.raw).chunks.into_iter().flatten();
        for (i, r) in raw.enumerate() {
            while models.get(model + 1).is_some_and(|m| m.0 <= i) {
                model += 1;
            }
            let m = &models[model].2;
            let (acc, mag) = (m.acc(r.acc), m.mag(r.mag));
            s.t.push(r.t);
            s.flags.push(r.flags);
            if acc_motion(&acc, &th) {
                s.flags[i] |= flags::ACC_MOTION;
            }
            if !phone && mag_disturbed(field_ref, &acc, &mag, &th) {
                s.flags[i] |= flags::MAG_DISTURBED;
            }
            let q = if phone {
                let gyro = m.gyro(r.gyro);
                if smoothing {
                    gyros.push(gyro);
                    accs.push(acc);
                    mags.push(mag);
                } else {
                    gyro_still.push((gyro - bias).norm() < self.cfg.stationary_gyro);
                }
                let [w, i, j, k] = r.x;
                Some(UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
                    w, i, j, k,
                )))
            } else {
                wheel.push(r.x[0]);
                if skid_check {
                    rider_acc.push(acc);
                }
                nd.push(norm_dip(&acc, &mag));
                triad(&acc, &mag)
            };
            let q = match q {
                Some(q) => {
                    last_q = Some(q);
                    q
                }
                None => {
                    s.flags[i] |= flags::INVALID;
                    match last_q {
                        Some(q) => q,
                        None => {
                            missing_before_first += 1;
                            UnitQuaternion::identity()
                        }
                    }
                }
            };
            s.q.push(quat_array(&q));
        }
        // Leading invalid samples take the first valid orientation.
        if missing_before_first > 0 && missing_before_first < n {
            let first = s.q[missing_before_first];
            for q in &mut s.q[..missing_before_first] {
                *q = first;
            }
        }
        if skid_check {
            let typed: Vec<f64> = o.tags.iter().map(|tag| tag.1).collect();
            for sk in skid::fill_skids(&s.t, &mut wheel, &rider_acc, &typed) {
                self.warn(AcquisitionWarning::WheelSkid {
                    curve: o.index,
                    t: sk.t,
                    duration_s: sk.duration_s,
                    added_m: sk.added_m,
                });
            }
        }
        drop(rider_acc);
        if !phone && self.cfg.bridge_heading {
            // The fringe of a magnet's reach, which the per-sample tests let through; the
            // heading across each disturbed stretch is bridged from its clean ends.
            let windowed = disturbed_windows(&s.t, &nd, field_ref, &th);
            drop(nd);
            for (f, d) in s.flags.iter_mut().zip(windowed) {
                if d {
                    *f |= flags::MAG_DISTURBED;
                }
            }
            bridge_disturbed(&mut s, &wheel);
        }
        // Stationary.
        let w = self.cfg.stationary_window;
        let mut speed_shape: Option<Vec<f64>> = None;
        if phone {
            let mut still = if smoothing {
                let imu = [&gyros[..], &accs[..], &mags[..]];
                let bias_s = self.smooth_phone(&mut s, imu, field_ref, bias, &o.typing);
                // Still: the window's mean rate (the smoothed bias taken off) is small; a hand
                // rocking the standing device back and forth averages out.
                let mut cum = Vec::with_capacity(n + 1);
                cum.push(Vector3::zeros());
                for (g, b) in gyros.iter().zip(&bias_s) {
                    let last = cum.last().copied().unwrap_or_default();
                    cum.push(last + (g - b));
                }
                let still_rate = self.cfg.stationary_gyro;
                stationary_mask(&s.t, w, |a, b| {
                    ((cum[b + 1] - cum[a]) / (b + 1 - a) as f64).norm() < still_rate
                })
            } else {
                stationary_mask(&s.t, w, |a, b| gyro_still[a..=b].iter().all(|&x| x))
            };
            // A phone moving straight on a flat part does not rotate either: only still runs
            // that contain the typing of a node index count (the operator stands to type).
            keep_runs_touching(&s.t, &mut still, &o.typing);
            clip_to_intervals(&s.t, &mut still, &o.typing, self.cfg.stand_margin);
            if smoothing {
                // The stop before each typing and the start after it, from the accelerometer's
                // pulses (gravity taken off with the smoothed orientation): a phone sliding
                // straight does not turn, and one tilted by the hand or turned in place while
                // standing does, so the gyroscope cannot tell them. Between the two pulses the
                // device stands, whatever it turned.
                let lin: Vec<Vector3<f64>> = accs
                    .iter()
                    .zip(&s.q)
                    .map(|(a, q)| quat_of(q) * a - Vector3::new(0.0, 0.0, crate::sensor::G))
                    .collect();
                // A pulse: the mean of 0.1 s of linear acceleration above 0.3 m/s² (a phone
                // stopped by the hand; well above the noise of such a mean and the tilt's
                // error). A gentler stop finds no pulse and keeps the still run, within the
                // margin.
                let wl = rest::window_stats(&s.t, &lin, 0.05);
                let floor = self.noise.map_or(0.05, |f| f.acc);
                let threshold = (4.0 * floor / 20f64.sqrt()).max(0.3);
                let pulse: Vec<bool> = wl.mean.iter().map(|m| m.norm() > threshold).collect();
                stand_between_pulses(&s.t, &mut still, &o.typing, &pulse, PULSE_REACH);
                // The speed between the stands: its start and stop fitted to the acceleration
                // along the travel direction T (the frame's first axis); the mask above where
                // no fit holds ([`speed`]).
                if speed::sampled_fast_enough(&s.t) {
                    let along: Vec<f64> = lin
                        .iter()
                        .zip(&s.q)
                        .map(|(l, q)| l.dot(&(quat_of(q) * Vector3::x())))
                        .collect();
                    let stretches = stretches(&o.tags, &o.typing);
                    let fallback: Vec<f64> =
                        still.iter().map(|&x| if x { 0.0 } else { 1.0 }).collect();
                    speed_shape = Some(speed::speed_shape(&s.t, &along, &stretches, &fallback));
                }
            }
            for (f, st) in s.flags.iter_mut().zip(still) {
                if st {
                    *f |= flags::STATIONARY;
                }
            }
        } else {
            let tick = self
                .model
                .as_ref()
                .and_then(|m| m.scales.wheel_m_per_tick)
                .unwrap_or(0.0);
            let still_range = self.cfg.stationary_distance.max(1.5 * tick);
            let still = stationary_mask(&s.t, w, |a, b| {
                let (lo, hi) = wheel[a..=b]
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
                hi - lo < still_range
            });
            for (f, st) in s.flags.iter_mut().zip(still) {
                if st {
                    *f |= flags::STATIONARY;
                }
            }
        }
        s.w = s.flags.iter().map(|&f| flags::weight(f)).collect();
        let kind = match self.cfg.kinds.get(&o.index) {
            Some(&k) if k != o.kind => {
                tracing::info!(
                    curve = o.index,
                    started = %o.kind,
                    kind = %k,
                    "curve kind set by the configuration"
                );
                k
            }
            _ => o.kind,
        };
        let mut curve = Curve {
            index: o.index,
            kind,
            closed: o.tags.first().map(|t| t.0) == o.tags.last().map(|t| t.0),
            tags: o
                .tags
                .iter()
                .map(|&(node, t, uncertain)| Tag {
                    node,
                    d: 0.0,
                    t,
                    uncertain,
                })
                .collect(),
            segment_lengths: vec![None; o.tags.len().saturating_sub(1)],
            samples: s,
        };
        if n == 0 {
            self.warn(AcquisitionWarning::NoSamples {
                curve: o.index,
                nodes: curve.nodes(),
            });
        }
        if phone {
            let from_cfg = self.cfg.segment_lengths.get(&o.index);
            for (k, len) in curve.segment_lengths.iter_mut().enumerate() {
                *len = o
                    .segment_lengths
                    .get(&(k as u16))
                    .copied()
                    .or_else(|| from_cfg.and_then(|v| v.get(k).copied()));
            }
            match &speed_shape {
                Some(v) => distances_by_speed(&mut curve, v, self.cfg.nominal_speed),
                None => phone_distances(&mut curve, self.cfg.nominal_speed),
            }
        } else if n > 0 {
            let start = interp(&curve.samples.t, &wheel, curve.tags[0].t);
            for (d, w) in curve.samples.d.iter_mut().zip(&wheel) {
                *d = w - start;
            }
            for tag in &mut curve.tags {
                tag.d = interp(&curve.samples.t, &wheel, tag.t) - start;
            }
            for (k, pair) in curve.tags.windows(2).enumerate() {
                if pair[1].d < pair[0].d {
                    let w = AcquisitionWarning::WheelBack {
                        curve: o.index,
                        node: pair[1].node,
                        t: pair[1].t,
                        back_m: pair[0].d - pair[1].d,
                        segment: k,
                        from: pair[0].node,
                    };
                    self.warn(w);
                }
            }
        }
        let c = &mut self.scan.counts;
        c.in_curves += n as u64;
        for &f in &curve.samples.flags {
            c.stationary += (f & flags::STATIONARY != 0) as u64;
            c.mag_disturbed += (f & flags::MAG_DISTURBED != 0) as u64;
            c.acc_motion += (f & flags::ACC_MOTION != 0) as u64;
            c.saturated += (f & flags::SATURATED != 0) as u64;
            c.invalid += (f & flags::INVALID != 0) as u64;
        }
        self.scan.field_reference = self.field.reference().map(|(n, d)| [n, d]);
        if self
            .curve_lines
            .allow(self.last_sample_t.unwrap_or_default())
        {
            tracing::info!(
                curve = curve.index,
                kind = %curve.kind,
                nodes = ?curve.nodes(),
                samples = n,
                length_m = format!("{:.3}", curve.length()),
                "curve ended"
            );
        }
        curve
    }

    fn array_sample(
        &mut self,
        t: f64,
        sensor: u16,
        acc: Vector3<f64>,
        mag: Vector3<f64>,
        sat: bool,
    ) {
        // Windows on a grid of session time shared by every sensor, so that the epochs of
        // all sensors of one window carry the same time (the window's end). Samples come in
        // time order: the first of a window closes every sensor's earlier one (a sensor that
        // stops sending has its last window closed on time, not when it comes back).
        let th = self.cfg.thresholds;
        let k = (t / self.cfg.array_window).floor() as i64;
        if self.array_grid.is_none_or(|g| k > g) {
            let done: Vec<u16> = self
                .array
                .iter()
                .filter(|(_, st)| st.window < k)
                .map(|(id, _)| *id)
                .collect();
            for id in done {
                let st = self.array.remove(&id).expect("listed");
                self.close_array_window(id, st);
            }
            self.array_grid = Some(k);
        }
        let st = self.array.entry(sensor).or_insert_with(|| ArraySensor {
            window: k,
            ..Default::default()
        });
        if k < st.window {
            // Out of time order: its window is closed already.
            self.scan.counts.array_late += 1;
            return;
        }
        st.last_t = st.last_t.max(t);
        if sat {
            st.flags |= flags::SATURATED;
            return;
        }
        if acc_motion(&acc, &th) {
            st.flags |= flags::ACC_MOTION;
        } else {
            self.field.add(&acc, &mag);
        }
        st.acc += acc;
        st.mag += mag;
        st.n += 1;
    }

    /// The epoch of one sensor's finished window: its mean orientation (TRIAD of the mean
    /// acceleration and field), flagged saturated, moving or magnetically disturbed; a window
    /// whose samples were all saturated gives an epoch without orientation (so that the
    /// sensor is known saturated, not missing).
    fn close_array_window(&mut self, sensor: u16, st: ArraySensor) {
        let t = (st.window + 1) as f64 * self.cfg.array_window;
        if st.n == 0 {
            if st.flags & flags::SATURATED != 0 {
                self.scan.array.push(ArrayEpoch {
                    t,
                    sensor,
                    q: quat_array(&UnitQuaternion::identity()),
                    samples: 0,
                    flags: st.flags | flags::INVALID,
                });
            }
            return;
        }
        let (acc_mean, mag_mean) = (st.acc / st.n as f64, st.mag / st.n as f64);
        let mut f = st.flags;
        // Magnetically disturbed: the window's mean field off the site's (the median over
        // every sensor at rest so far, taken once per window) in norm or dip.
        let reference = match self.array_field {
            Some((w, r)) if w == st.window => r,
            _ => {
                let r = self.field.reference();
                self.array_field = Some((st.window, r));
                r
            }
        };
        if crate::orientation::disturbance::mag_disturbed(
            reference,
            &acc_mean,
            &mag_mean,
            &self.cfg.thresholds,
        ) {
            f |= flags::MAG_DISTURBED;
        }
        let q = match triad(&acc_mean, &mag_mean) {
            Some(q) => q,
            None => {
                f |= flags::INVALID;
                UnitQuaternion::identity()
            }
        };
        self.scan.array.push(ArrayEpoch {
            t,
            sensor,
            q: quat_array(&q),
            samples: st.n,
            flags: f,
        });
    }

    /// End of input for sensor arrays: the window of the shared grid still held is closed
    /// for every sensor, as when the grid moves on, when it is complete (its newest sample
    /// within one sample interval of its end, at the HELLO's rate); an incomplete one is
    /// dropped. Its epochs join [`take_array`](Self::take_array)'s; returns the time up to
    /// which epochs are then complete.
    pub fn close_array(&mut self) -> Option<f64> {
        let grid = self.array_grid?;
        let rate = self.scan.device.as_ref().map_or(0, |d| d.rate_hz);
        let interval = if rate > 0 { 1.0 / rate as f64 } else { 0.0 };
        let end = (grid + 1) as f64 * self.cfg.array_window;
        let newest = self
            .array
            .values()
            .map(|st| st.last_t)
            .fold(f64::MIN, f64::max);
        let held = std::mem::take(&mut self.array);
        if newest + interval < end - 1e-6 {
            return None;
        }
        for (id, st) in held {
            self.close_array_window(id, st);
        }
        self.array_grid = Some(grid + 1);
        Some(end)
    }

    /// Ends acquisition: an open curve is reported and dropped (it was never ended).
    pub fn finish(mut self) -> Scan {
        self.release_held();
        if let Some(o) = self.open.take() {
            let nodes: Vec<u32> = o.tags.iter().map(|t| t.0).collect();
            self.warn(AcquisitionWarning::NeverEnded {
                curve: o.index,
                nodes,
                samples: o.raw.len(),
            });
            self.scan.counts.curves_discarded += 1;
        }
        let curves = self.scan.curves.len();
        let missing: Vec<(usize, CurveKind)> = self
            .cfg
            .kinds
            .range(curves..)
            .map(|(&c, &k)| (c, k))
            .collect();
        for (curve, kind) in missing {
            self.warn(AcquisitionWarning::KindOfMissingCurve {
                curve,
                kind,
                curves,
            });
        }
        self.scan.field_reference = self.field.reference().map(|(n, d)| [n, d]);
        self.scan
    }
}

/// Morphorider: bridges the heading across each run of `MAG_DISTURBED` samples of `s`
/// ([`bridge_heading`], along the wheel distance `x`), converting only the run and up to
/// [`END_SAMPLES`] clean neighbours each side (a long curve is not copied), and writing back
/// only the run.
fn bridge_disturbed(s: &mut Samples, x: &[f64]) {
    let n = s.len().min(x.len());
    let disturbed = |i: usize| s.flags[i] & flags::MAG_DISTURBED != 0;
    let mut i = 0;
    let mut runs = Vec::new();
    while i < n {
        if !disturbed(i) {
            i += 1;
            continue;
        }
        let start = i;
        while i < n && disturbed(i) {
            i += 1;
        }
        runs.push((start.saturating_sub(END_SAMPLES), (i + END_SAMPLES).min(n)));
    }
    for (a, b) in runs {
        let mut q: Vec<UnitQuaternion<f64>> = s.q[a..b].iter().map(quat_of).collect();
        let flagged: Vec<bool> = (a..b)
            .map(|k| s.flags[k] & flags::MAG_DISTURBED != 0)
            .collect();
        if bridge_heading(&mut q, &x[a..b], &flagged) > 0 {
            for ((dst, q), _) in s.q[a..b]
                .iter_mut()
                .zip(&q)
                .zip(&flagged)
                .filter(|(_, &f)| f)
            {
                *dst = quat_array(q);
            }
        }
    }
}

fn quat_array(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// The unit quaternion of a stored `[w, x, y, z]` (normalised).
fn quat_of(a: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(a[0], a[1], a[2], a[3]))
}

/// Linear interpolation of `y(x)` at `x0` (`x` non-decreasing), clamped at the ends.
fn interp(x: &[f64], y: &[f64], x0: f64) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let i = x.partition_point(|&v| v <= x0);
    if i == 0 {
        return y[0];
    }
    if i == x.len() {
        return y[x.len() - 1];
    }
    let (x1, x2) = (x[i - 1], x[i]);
    if x2 > x1 {
        y[i - 1] + (y[i] - y[i - 1]) * (x0 - x1) / (x2 - x1)
    } else {
        y[i]
    }
}

/// Samples within `w` seconds of a sample whose whole window `[t − w, t + w]` satisfies
/// `still(first, last)`: a morphological opening in time, so that the edges of a still period
/// are not lost to the window.
fn stationary_mask(t: &[f64], w: f64, still: impl Fn(usize, usize) -> bool) -> Vec<bool> {
    let n = t.len();
    let mut centre = vec![false; n];
    let (mut a, mut b) = (0, 0);
    for i in 0..n {
        while t[a] < t[i] - w {
            a += 1;
        }
        while b + 1 < n && t[b + 1] <= t[i] + w {
            b += 1;
        }
        centre[i] = still(a, b);
    }
    // Dilation: within w of a still centre (two sweeps, forward and backward).
    let mut out = centre.clone();
    let mut last = f64::NEG_INFINITY;
    for i in 0..n {
        if centre[i] {
            last = t[i];
        }
        if t[i] - last <= w {
            out[i] = true;
        }
    }
    let mut next = f64::INFINITY;
    for i in (0..n).rev() {
        if centre[i] {
            next = t[i];
        }
        if next - t[i] <= w {
            out[i] = true;
        }
    }
    out
}

/// Keeps the runs of `mask` that overlap one of the `intervals` (times), and sets the samples
/// inside the intervals.
fn keep_runs_touching(t: &[f64], mask: &mut [bool], intervals: &[(f64, f64)]) {
    let inside = |x: f64| intervals.iter().any(|&(a, b)| x >= a && x <= b);
    let n = t.len();
    let mut i = 0;
    while i < n {
        if !mask[i] {
            mask[i] = inside(t[i]);
            i += 1;
            continue;
        }
        let start = i;
        while i < n && mask[i] {
            i += 1;
        }
        if !(start..i).any(|k| inside(t[k])) {
            mask[start..i].iter_mut().for_each(|m| *m = false);
        }
    }
}

/// How far before the first digit a phone's stop, and after Enter its start, are looked for in
/// the accelerometer's pulses, s: the operator may stand a while, and turn the device in place
/// (a rotation that no rate test tells from sliding), before moving on.
const PULSE_REACH: f64 = 3.0;

/// Around each interval `(a, b)` (the typing of an index): where a pulse lies within `reach`
/// before `a` (the device stopping), the stand runs from the last such pulse to `a`, whatever
/// the device did meanwhile (the hand tilting or turning it in place); likewise from `b` to the
/// first pulse within `reach` after `b` (it starting again). A side without a pulse keeps
/// `mask` as it is.
fn stand_between_pulses(
    t: &[f64],
    mask: &mut [bool],
    intervals: &[(f64, f64)],
    pulse: &[bool],
    reach: f64,
) {
    for &(a, b) in intervals {
        let lo = t.partition_point(|&x| x < a - reach);
        let ia = t.partition_point(|&x| x < a);
        let ib = t.partition_point(|&x| x <= b);
        let hi = t.partition_point(|&x| x <= b + reach);
        if let Some(k) = (lo..ia).rev().find(|&k| pulse[k]) {
            mask[lo..=k].iter_mut().for_each(|m| *m = false);
            mask[k + 1..ia].iter_mut().for_each(|m| *m = true);
        }
        if let Some(k) = (ib..hi).find(|&k| pulse[k]) {
            mask[ib..k].iter_mut().for_each(|m| *m = true);
            mask[k..hi].iter_mut().for_each(|m| *m = false);
        }
    }
}

/// The stretches of a phone curve between its stands: from the Enter of each tag to the first
/// digit of the next (its Enter where no typing is known). `tags` are `(node, Enter time, _)`,
/// `typing` the `(first digit, Enter)` of every tag typed, in order, undone ones included.
fn stretches(tags: &[(u32, f64, bool)], typing: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut k = 0;
    tags.windows(2)
        .map(|p| {
            // Both in time order: the typing that ends at the next tag's Enter.
            while k < typing.len() && typing[k].1 < p[1].1 {
                k += 1;
            }
            let next = typing
                .get(k)
                .filter(|ty| ty.1 == p[1].1)
                .map_or(p[1].1, |ty| ty.0);
            (p[0].1, next)
        })
        .collect()
}

/// Clears `mask` wherever `t` is more than `margin` from every interval (sorted by start).
fn clip_to_intervals(t: &[f64], mask: &mut [bool], intervals: &[(f64, f64)], margin: f64) {
    let mut k = 0;
    for (m, &x) in mask.iter_mut().zip(t) {
        while k < intervals.len() && intervals[k].1 + margin < x {
            k += 1;
        }
        if *m {
            *m = intervals.get(k).is_some_and(|&(a, _)| x >= a - margin);
        }
    }
}

/// Phone distances: within each segment (between consecutive tags), distance grows with the
/// time spent moving (stationary samples add none), scaled to the segment's measured length,
/// else to `nominal_speed` × moving time. Public for the studies that put a true standing mask
/// into acquired curves (`examples/validation_table.rs --study`).
pub fn phone_distances(c: &mut Curve, nominal_speed: f64) {
    let moving: Vec<f64> = c
        .samples
        .flags
        .iter()
        .map(|&f| if f & flags::STATIONARY == 0 { 1.0 } else { 0.0 })
        .collect();
    distances_by_speed(c, &moving, nominal_speed);
}

/// Phone: a curve's distances made again after a segment's length arrived late: each
/// segment's distances, as its speed shape spread them, scaled to the length now known.
fn rescale_segments(c: &mut Curve) {
    let n = c.tags.len();
    if n < 2 {
        return;
    }
    let old: Vec<f64> = c.tags.iter().map(|g| g.d).collect();
    let mut new = old.clone();
    for k in 0..n - 1 {
        let len = c.segment_lengths.get(k).copied().flatten();
        new[k + 1] = new[k] + len.unwrap_or(old[k + 1] - old[k]);
    }
    let s = &mut c.samples;
    for d in &mut s.d {
        // The segment the distance lies in (the last one that starts at or before it).
        let k = old[..n - 1].partition_point(|&x| x <= *d).saturating_sub(1);
        let span = old[k + 1] - old[k];
        *d = if span > 0.0 {
            new[k] + (*d - old[k]) * (new[k + 1] - new[k]) / span
        } else {
            new[k] + (*d - old[k])
        };
    }
    for (g, d) in c.tags.iter_mut().zip(new) {
        g.d = d;
    }
}

/// Phone distances from a speed shape (`speed`, one per sample, ≥ 0: [`speed::speed_shape`]):
/// within each segment distance grows with the time integral of the shape, scaled to the
/// segment's measured length, else to `nominal_speed` × the integral.
fn distances_by_speed(c: &mut Curve, speed: &[f64], nominal_speed: f64) {
    let s = &mut c.samples;
    let n = s.t.len();
    if n == 0 || c.tags.len() < 2 {
        return;
    }
    // The shape's integral at each sample.
    let mut tau = vec![0.0; n];
    for i in 1..n {
        tau[i] = tau[i - 1] + speed[i] * (s.t[i] - s.t[i - 1]);
    }
    let tag_tau: Vec<f64> = c.tags.iter().map(|g| interp(&s.t, &tau, g.t)).collect();
    let mut start_d = vec![0.0; c.tags.len()];
    for k in 0..c.tags.len() - 1 {
        let dt = tag_tau[k + 1] - tag_tau[k];
        let len = c
            .segment_lengths
            .get(k)
            .copied()
            .flatten()
            .unwrap_or(nominal_speed * dt);
        start_d[k + 1] = start_d[k] + len;
    }
    let d_of = |x: f64| -> f64 {
        let k = tag_tau.partition_point(|&v| v <= x);
        if k == 0 {
            return 0.0;
        }
        if k >= tag_tau.len() {
            return start_d[tag_tau.len() - 1];
        }
        let (a, b) = (tag_tau[k - 1], tag_tau[k]);
        if b > a {
            start_d[k - 1] + (start_d[k] - start_d[k - 1]) * (x - a) / (b - a)
        } else {
            start_d[k - 1]
        }
    };
    for (d, &x) in s.d.iter_mut().zip(&tau) {
        *d = d_of(x);
    }
    for (tag, d) in c.tags.iter_mut().zip(start_d) {
        tag.d = d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 5 (torus phone scan): a phone sliding slowly over a large surface turned less
    /// than the stationary threshold for a whole curve; the still run touched the typing of
    /// its first index, so the whole curve counted as standing and its distances collapsed.
    /// Standing is now clipped to the margin around the typing.
    /// Issue 17: the stand around a typing runs from the device's stop before it to its start
    /// after it, where the accelerometer shows them, whatever the hand did meanwhile (a turn in
    /// place is no still run of the gyroscope); without a pulse the mask stands.
    #[test]
    fn issue_17_the_stand_runs_between_the_pulses_around_the_typing() {
        let t: Vec<f64> = (0..1000).map(|i| i as f64 * 0.01).collect();
        // Still only during the typing (5-6 s): the turn in place before and after is not.
        let mut mask: Vec<bool> = t.iter().map(|&x| (5.0..=6.0).contains(&x)).collect();
        mask[..100].iter_mut().for_each(|m| *m = true); // far away: untouched
        let mut pulse = vec![false; 1000];
        pulse[300] = true; // stopping at 3.0 s
        pulse[780] = true; // starting at 7.8 s
        pulse[950] = true; // beyond the reach
        stand_between_pulses(&t, &mut mask, &[(5.0, 6.0)], &pulse, 3.0);
        assert!(
            mask[200..=300].iter().all(|&m| !m),
            "before the stop: moving"
        );
        assert!(mask[301..780].iter().all(|&m| m), "stop to start: standing");
        assert!(mask[780..].iter().all(|&m| !m), "after the start: moving");
        assert!(
            mask[..100].iter().all(|&m| m),
            "outside the reach: untouched"
        );
        // No pulse: nothing changed.
        let before: Vec<bool> = t.iter().map(|&x| (4.5..=6.5).contains(&x)).collect();
        let mut kept = before.clone();
        stand_between_pulses(&t, &mut kept, &[(5.0, 6.0)], &[false; 1000], 3.0);
        assert_eq!(kept, before);
    }

    #[test]
    fn issue5_standing_is_clipped_to_the_typing() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.5).collect(); // 0 … 49.5 s
        let mut still = vec![true; t.len()];
        clip_to_intervals(&t, &mut still, &[(1.0, 2.0), (40.0, 41.0)], 2.0);
        let kept: Vec<f64> = t
            .iter()
            .zip(&still)
            .filter(|p| *p.1)
            .map(|p| *p.0)
            .collect();
        let expect: Vec<f64> = t
            .iter()
            .copied()
            .filter(|&x| x <= 4.0 || (38.0..=43.0).contains(&x))
            .collect();
        assert_eq!(kept, expect);
        // Samples that were moving stay moving.
        let mut none = vec![false; t.len()];
        clip_to_intervals(&t, &mut none, &[(1.0, 2.0)], 2.0);
        assert!(none.iter().all(|m| !m));
    }

    /// Issue 33: a segment length that arrives after the curve ended scales that segment's
    /// distances as the speed shape spread them (a gentle ramp stays gentle), and moves the
    /// later segments by the difference.
    #[test]
    fn issue_33_a_late_segment_length_scales_its_segment() {
        let t: Vec<f64> = (0..=40).map(|i| i as f64 * 0.1).collect();
        // A speed shape: standing, a ramp, cruising, standing; two segments of 2 s.
        let speed: Vec<f64> = t
            .iter()
            .map(|&x| {
                let u = x % 2.0;
                (u / 0.5).min(1.0) * if u > 1.8 { 0.0 } else { 1.0 }
            })
            .collect();
        let n = t.len();
        let mut c = Curve {
            index: 0,
            kind: CurveKind::Interior,
            closed: false,
            tags: [0.0, 2.0, 4.0]
                .iter()
                .enumerate()
                .map(|(k, &t)| Tag {
                    node: k as u32,
                    d: 0.0,
                    t,
                    uncertain: false,
                })
                .collect(),
            segment_lengths: vec![Some(0.3), None],
            samples: Samples {
                t: t.clone(),
                d: vec![0.0; n],
                q: vec![[1.0, 0.0, 0.0, 0.0]; n],
                flags: vec![0; n],
                w: vec![1.0; n],
            },
        };
        distances_by_speed(&mut c, &speed, 0.05);
        let before = c.samples.d.clone();
        let second = c.tags[2].d - c.tags[1].d;
        c.segment_lengths[0] = Some(0.6);
        rescale_segments(&mut c);
        assert!((c.tags[1].d - 0.6).abs() < 1e-12);
        assert!((c.tags[2].d - c.tags[1].d - second).abs() < 1e-12);
        for i in 0..n {
            let want = if t[i] <= 2.0 {
                2.0 * before[i]
            } else {
                before[i] + 0.3
            };
            assert!(
                (c.samples.d[i] - want).abs() < 1e-9,
                "sample {i}: {} vs {want}",
                c.samples.d[i]
            );
        }
    }

    #[test]
    fn interp_clamps_and_interpolates() {
        let x = [0.0, 1.0, 2.0];
        let y = [10.0, 20.0, 40.0];
        assert_eq!(interp(&x, &y, -1.0), 10.0);
        assert_eq!(interp(&x, &y, 1.5), 30.0);
        assert_eq!(interp(&x, &y, 3.0), 40.0);
    }
}
