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
//!
//! Layout, in the data's order: this file holds the state machine (events, HELLOs, samples,
//! keys, loops); `preview.rs` the open curve's live path; `open_curve.rs` the raw samples kept
//! until `E` and their finalisation into a [`Curve`](crate::scan::Curve) (orientations, flags,
//! the Morphorider's wheel); `phone.rs` a phone curve's smoothing, stands, speed and distances
//! (with [`speed`]; [`skid`] fills the wheel's skids); `array.rs` the sensor arrays' windows.

use crate::keypad::{CurveKind, KeyEvent, Keypad};
use crate::orientation::ahrs::{Ahrs, AhrsParams};
use crate::orientation::disturbance::{acc_motion, FieldReference, Thresholds};
use crate::orientation::flags;
use crate::orientation::rest;
use crate::orientation::smoother::SmootherParams;
use crate::orientation::triad::triad;
use crate::scan::{DeviceInfo, Scan};
use crate::sensor::{saturated, CalibrationSpec, Scales, SensorModel};
use crate::warning::{AcquisitionWarning, Warning};
use device_protocol::{DeviceKind, Event, Hello, Packet};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::BTreeMap;

mod array;
mod open_curve;
mod phone;
mod preview;
pub mod skid;
pub mod speed;

use array::ArraySensor;
use open_curve::{OpenCurve, Raw, RawSamples};
pub use phone::phone_distances;
use preview::PreviewPath;
pub use preview::{PREVIEW_POINTS, PREVIEW_SPACING};

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
    /// disturbed ([`bridge_heading`](crate::orientation::disturbance::bridge_heading)), from their clean ends. Default on.
    pub bridge_heading: bool,
    /// Morphorider: fill the stretches where the wheel skidded ([`skid`]) from the speed
    /// either side. Default on.
    pub fill_skids: bool,
    /// Phone: smooth each finished curve's orientations forward and backward ([`smoother`](crate::orientation::smoother));
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
    /// Curve `index` was taken out of the network from the keypad (`N C`).
    CurveDropped(usize),
    /// Curve `ended` was accepted, and replaced curve `dropped` (`N B … E`).
    CurveReplaced { ended: usize, dropped: usize },
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
    /// The last finished phone curve's index and, for each of its tags, how far the device
    /// went between its set-off and the tag's Enter (m; 0 but for a tag entered late): a
    /// segment length arriving after the curve ended keeps those tags where the device
    /// stood ([`phone::rescale_segments`]).
    late_went: Option<(usize, Vec<f64>)>,
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
            late_went: None,
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
    /// The device the last HELLO announced.
    pub fn device(&self) -> Option<DeviceKind> {
        self.kind
    }

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
        let update = self.key_events(events);
        if key == b'\n' || key == b'\r' {
            // An Enter that tagged nothing (an index over six digits, its Enter lost on the
            // link) ends that typing too: the next index is typed from its own first digit.
            if let Some(o) = &mut self.open {
                o.first_digit = None;
            }
        }
        update
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
                KeyEvent::Dropped { curve, by } => {
                    if let Some(k) = self.scan.curves.iter().position(|c| c.index == curve) {
                        let c = self.scan.curves.remove(k);
                        let nodes = c.nodes();
                        tracing::info!(
                            curve,
                            ?by,
                            ?nodes,
                            "curve {curve} taken out of the network"
                        );
                        self.scan
                            .dropped
                            .push(crate::scan::DroppedCurve { curve, by, nodes });
                        update = Some(match (by, update) {
                            (Some(_), Some(Update::CurveEnded(ended))) => Update::CurveReplaced {
                                ended,
                                dropped: curve,
                            },
                            _ => Update::CurveDropped(curve),
                        });
                    }
                }
                KeyEvent::Warning(w) => self.note(w.into()),
            }
        }
        self.key_events = events;
        update
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
            let went = match &self.late_went {
                Some((i, went)) if *i == index => &went[..],
                _ => &[],
            };
            phone::rescale_segments(curve, went);
        }
        Some(Update::CurveUpdated(index))
    }

    /// Ends acquisition: an open curve is reported and dropped (it was never ended).
    pub fn finish(mut self) -> Scan {
        self.release_held();
        let mut events = Vec::new();
        self.keypad.flush(&mut events);
        self.key_events(events);
        if let Some(o) = self.open.take() {
            let nodes: Vec<u32> = o.tags.iter().map(|t| t.0).collect();
            self.warn(AcquisitionWarning::NeverEnded {
                curve: o.index,
                nodes,
                samples: o.raw.len(),
            });
            self.scan.counts.curves_discarded += 1;
        }
        // Curves scanned, dropped ones too (their indices are not reused).
        let curves = self.keypad.next_curve();
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interp_clamps_and_interpolates() {
        let x = [0.0, 1.0, 2.0];
        let y = [10.0, 20.0, 40.0];
        assert_eq!(interp(&x, &y, -1.0), 10.0);
        assert_eq!(interp(&x, &y, 1.5), 30.0);
        assert_eq!(interp(&x, &y, 3.0), 40.0);
    }
}
