//! The open curve and its finalisation: the raw samples kept until its `E`, then read back
//! (calibrated with the sensor model of each sample, oriented, flagged), the device's motion
//! (Morphorider: wheel skids filled, heading bridged across magnetic disturbances, standing
//! from the wheel; phone: [`super::phone`]), the distances, and the [`Curve`].

use super::preview::PreviewPath;
use super::{interp, quat_array, quat_of, skid, Acquisition};
use crate::keypad::CurveKind;
use crate::orientation::disturbance::{
    acc_motion, bridge_heading, close_gaps, disturbed_windows, mag_disturbed, norm_dip, END_SAMPLES,
};
use crate::orientation::flags;
use crate::orientation::triad::triad;
use crate::scan::{Curve, Samples, Tag};
use crate::sensor::SensorModel;
use crate::warning::AcquisitionWarning;
use device_protocol::DeviceKind;
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::BTreeMap;

/// Curves longer than this are not smoothed (the smoother keeps about 350 bytes per sample:
/// 90 MB here, 21 minutes of a 200 Hz phone): they keep the causal filter's orientations, and
/// the log says so.
const MAX_SMOOTHED_SAMPLES: usize = 250_000;

/// Morphorider curves longer than this are not searched for wheel skids (the search keeps
/// about 64 bytes per sample: 64 MB here, 2.8 hours at 100 Hz); the log says so.
const MAX_SKID_CHECKED_SAMPLES: usize = 1_000_000;

/// One sample of an open curve as received: raw counts and what was measured causally, 64
/// bytes (calibration is applied when the curve is finalised, with the sensor model of the
/// sample: [`OpenCurve::models`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Raw {
    /// Session time, s.
    pub(super) t: f64,
    /// Morphorider: `[session wheel distance (m), 0, 0, 0]`; phone: the filter's orientation
    /// at this sample, `[w, i, j, k]`.
    pub(super) x: [f64; 4],
    /// Raw counts of the accelerometer, magnetometer and gyroscope (zero on a Morphorider).
    pub(super) acc: [i16; 3],
    pub(super) mag: [i16; 3],
    pub(super) gyro: [i16; 3],
    pub(super) flags: u8,
}
const _: () = assert!(std::mem::size_of::<Raw>() <= 64);

/// Samples per chunk of an open curve (4 MB): a long curve grows a chunk at a time (no
/// reallocation that holds the old and the new buffer at once) and is given back chunk by
/// chunk as it is finalised.
const CHUNK: usize = 1 << 16;

/// The raw samples of an open curve, in chunks of [`CHUNK`].
#[derive(Debug, Clone, Default)]
pub(super) struct RawSamples {
    chunks: Vec<Vec<Raw>>,
    len: usize,
}

impl RawSamples {
    pub(super) fn push(&mut self, r: Raw) {
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

    pub(super) fn len(&self) -> usize {
        self.len
    }
}

#[derive(Debug, Clone)]
pub(super) struct OpenCurve {
    pub(super) index: usize,
    pub(super) kind: CurveKind,
    pub(super) tags: Vec<(u32, f64, bool)>,
    /// The travel measure (see [`Acquisition::travel`]) at each tag.
    pub(super) tag_travel: Vec<f64>,
    /// `(first digit, Enter)` times of every node tag: the operator stands while typing.
    pub(super) typing: Vec<(f64, f64)>,
    /// Time of the first digit of the index being typed.
    pub(super) first_digit: Option<f64>,
    pub(super) raw: RawSamples,
    /// The sensor model of the samples from each index on (a HELLO with other scales can
    /// come in the middle of a curve), with the model's generation
    /// ([`Acquisition::model_generation`]).
    pub(super) models: Vec<(usize, u64, SensorModel)>,
    pub(super) segment_lengths: BTreeMap<u16, f64>,
    /// The curve integrated so far, for the live view.
    pub(super) preview: PreviewPath,
}

/// Which sensors are kept as an open curve's samples are read back, for the steps after.
#[derive(Debug, Clone, Copy)]
struct Plan {
    phone: bool,
    /// Phone: the curve is smoothed (its calibrated sensors are kept for the smoother).
    smoothing: bool,
    /// Morphorider: the curve is searched for wheel skids (its accelerometer is kept).
    skid_check: bool,
}

/// An open curve's raw samples read back: calibrated, oriented and flagged, with what the
/// later steps need of the sensors.
#[derive(Debug)]
pub(super) struct ReadBack {
    pub(super) s: Samples,
    /// Morphorider: the session wheel distance at each sample, m.
    wheel: Vec<f64>,
    /// Morphorider: the accelerometer, when the curve is searched for skids.
    rider_acc: Vec<Vector3<f64>>,
    /// Morphorider: the field's norm and dip at each sample.
    nd: Vec<[f32; 2]>,
    /// Phone, smoothed: the calibrated gyroscope, accelerometer and magnetometer.
    pub(super) imu: [Vec<Vector3<f64>>; 3],
    /// Phone, not smoothed: whether the gyroscope (its bias taken off) is still.
    pub(super) gyro_still: Vec<bool>,
}

impl Acquisition {
    /// Turns an open curve's raw samples into a [`Curve`].
    pub(super) fn finalise(&mut self, mut o: OpenCurve) -> Curve {
        let n = o.raw.len();
        let plan = self.plan(o.index, n);
        let field_ref = self.field.reference();
        let bias = self.ahrs.bias();
        let mut rb = self.read_back(&mut o, plan, field_ref, bias);
        let motion = if plan.phone {
            self.phone_motion(&mut rb, &o, plan.smoothing, field_ref, bias)
        } else {
            self.rider_motion(&mut rb, &o, plan.skid_check, field_ref);
            Default::default()
        };
        let ReadBack {
            s: mut samples,
            wheel,
            ..
        } = rb;
        samples.w = samples.flags.iter().map(|&f| flags::weight(f)).collect();
        let mut curve = self.curve_of(&o, samples);
        if n == 0 {
            self.warn(AcquisitionWarning::NoSamples {
                curve: o.index,
                nodes: curve.nodes(),
            });
        }
        if plan.phone {
            let from_cfg = self.cfg.segment_lengths.get(&o.index);
            for (k, len) in curve.segment_lengths.iter_mut().enumerate() {
                *len = o
                    .segment_lengths
                    .get(&(k as u16))
                    .copied()
                    .or_else(|| from_cfg.and_then(|v| v.get(k).copied()));
            }
            self.phone_distances(&mut curve, &motion);
            let mut went = vec![0.0; curve.tags.len()];
            for l in &motion.late {
                if let Some(w) = went.get_mut(l.tag) {
                    *w = l.distance;
                }
            }
            self.late_went = Some((o.index, went));
        } else if n > 0 {
            self.wheel_distances(&mut curve, &wheel, &o.typing);
        }
        self.count(&curve);
        curve
    }

    /// What is kept of a curve of `n` samples as it is read back; says in the log when a
    /// curve is too long to be smoothed or searched for skids.
    fn plan(&self, curve: usize, n: usize) -> Plan {
        let phone = self.kind == Some(DeviceKind::Phone);
        let smoothing = phone && self.cfg.smooth && (2..=MAX_SMOOTHED_SAMPLES).contains(&n);
        if phone && self.cfg.smooth && n > MAX_SMOOTHED_SAMPLES {
            tracing::warn!(
                curve,
                samples = n,
                "a curve of more than {MAX_SMOOTHED_SAMPLES} samples keeps the causal filter's \
                 orientations (not smoothed)"
            );
        }
        let skid_check = !phone && self.cfg.fill_skids && n <= MAX_SKID_CHECKED_SAMPLES;
        if !phone && self.cfg.fill_skids && !skid_check {
            tracing::warn!(
                curve,
                samples = n,
                "a curve of more than {MAX_SKID_CHECKED_SAMPLES} samples is not searched for \
                 wheel skids"
            );
        }
        Plan {
            phone,
            smoothing,
            skid_check,
        }
    }

    /// Reads back an open curve's raw samples, giving them back a chunk at a time:
    /// orientations (Morphorider: TRIAD; phone: the causal filter's) and per-sample flags;
    /// samples without an orientation take the last valid one (leading ones the first).
    fn read_back(
        &self,
        o: &mut OpenCurve,
        plan: Plan,
        field_ref: Option<(f64, f64)>,
        bias: Vector3<f64>,
    ) -> ReadBack {
        let n = o.raw.len();
        let th = self.cfg.thresholds;
        let rider = |v: usize| if plan.phone { 0 } else { v };
        let k = if plan.smoothing { n } else { 0 };
        let mut rb = ReadBack {
            s: Samples {
                t: Vec::with_capacity(n),
                d: vec![0.0; n],
                q: Vec::with_capacity(n),
                flags: Vec::with_capacity(n),
                w: Vec::new(),
            },
            wheel: Vec::with_capacity(rider(n)),
            rider_acc: Vec::with_capacity(if plan.skid_check { n } else { 0 }),
            nd: Vec::with_capacity(rider(n)),
            imu: std::array::from_fn(|_| Vec::with_capacity(k)),
            gyro_still: Vec::new(),
        };
        let s = &mut rb.s;
        let mut last_q: Option<UnitQuaternion<f64>> = None;
        let mut missing_before_first = 0;
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
            if !plan.phone && mag_disturbed(field_ref, &acc, &mag, &th) {
                s.flags[i] |= flags::MAG_DISTURBED;
            }
            let q = if plan.phone {
                let gyro = m.gyro(r.gyro);
                if plan.smoothing {
                    let [gyros, accs, mags] = &mut rb.imu;
                    gyros.push(gyro);
                    accs.push(acc);
                    mags.push(mag);
                } else {
                    rb.gyro_still
                        .push((gyro - bias).norm() < self.cfg.stationary_gyro);
                }
                let [w, i, j, k] = r.x;
                Some(UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
                    w, i, j, k,
                )))
            } else {
                rb.wheel.push(r.x[0]);
                if plan.skid_check {
                    rb.rider_acc.push(acc);
                }
                rb.nd.push(norm_dip(&acc, &mag));
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
        rb
    }

    /// Morphorider: fills the wheel's skids (warning of each), bridges the heading across
    /// magnetic disturbances, and flags where the wheel stands.
    fn rider_motion(
        &mut self,
        rb: &mut ReadBack,
        o: &OpenCurve,
        skid_check: bool,
        field_ref: Option<(f64, f64)>,
    ) {
        let th = self.cfg.thresholds;
        let rider_acc = std::mem::take(&mut rb.rider_acc);
        if skid_check {
            let typed: Vec<f64> = o.tags.iter().map(|tag| tag.1).collect();
            for sk in skid::fill_skids(&rb.s.t, &mut rb.wheel, &rider_acc, &typed) {
                self.warn(AcquisitionWarning::WheelSkid {
                    curve: o.index,
                    t: sk.t,
                    duration_s: sk.duration_s,
                    added_m: sk.added_m,
                });
            }
        }
        drop(rider_acc);
        let s = &mut rb.s;
        if self.cfg.bridge_heading {
            // The fringe of a magnet's reach, which the per-sample tests let through; the
            // heading across each disturbed stretch is bridged from its clean ends.
            let nd = std::mem::take(&mut rb.nd);
            let windowed = disturbed_windows(&s.t, &nd, field_ref, &th);
            drop(nd);
            let mut disturbed: Vec<bool> = s
                .flags
                .iter()
                .zip(windowed)
                .map(|(f, w)| w || f & flags::MAG_DISTURBED != 0)
                .collect();
            // A few samples inside a magnet's reach can look clean: they would be the
            // bridges' ends.
            close_gaps(&mut disturbed, END_SAMPLES);
            for (f, d) in s.flags.iter_mut().zip(disturbed) {
                if d {
                    *f |= flags::MAG_DISTURBED;
                }
            }
            bridge_disturbed(s, &rb.wheel);
        }
        let tick = self
            .model
            .as_ref()
            .and_then(|m| m.scales.wheel_m_per_tick)
            .unwrap_or(0.0);
        let still_range = self.cfg.stationary_distance.max(1.5 * tick);
        let wheel = &rb.wheel;
        let still = stationary_mask(&s.t, self.cfg.stationary_window, |a, b| {
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

    /// The [`Curve`] of an open curve and its samples (distances still zero): its kind as
    /// the configuration sets it, its tags.
    fn curve_of(&self, o: &OpenCurve, samples: Samples) -> Curve {
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
        Curve {
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
            samples,
        }
    }

    /// Morphorider: the distances of a curve's samples and tags along the wheel (`wheel`, the
    /// session distance at each sample) from its first tag; warns where the wheel went back
    /// between two tags.
    fn wheel_distances(&mut self, curve: &mut Curve, wheel: &[f64], typing: &[(f64, f64)]) {
        // Where each tag is on the wheel: at its Enter, unless the device rolled while its
        // index was typed (see `stood_while_typing`).
        let mut at: Vec<f64> = curve
            .tags
            .iter()
            .map(|tag| interp(&curve.samples.t, wheel, tag.t))
            .collect();
        for (k, tag) in curve.tags.iter().enumerate() {
            let Some(&(first, _)) = typing.iter().find(|ty| ty.1 == tag.t) else {
                continue;
            };
            let Some((rolled, stood)) = stood_while_typing(&curve.samples.t, wheel, first, tag.t)
            else {
                continue;
            };
            self.warn(AcquisitionWarning::LateEnter {
                curve: curve.index,
                node: tag.node,
                t: tag.t,
                rolled_m: rolled,
                moved_m: at[k] - stood,
            });
            at[k] = stood;
        }
        let start = at[0];
        for (d, w) in curve.samples.d.iter_mut().zip(wheel) {
            *d = w - start;
        }
        for (tag, w) in curve.tags.iter_mut().zip(&at) {
            tag.d = w - start;
        }
        for (k, pair) in curve.tags.windows(2).enumerate() {
            if pair[1].d < pair[0].d {
                let w = AcquisitionWarning::WheelBack {
                    curve: curve.index,
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

    /// Counts a finished curve's samples and flags into the scan, and logs its line.
    fn count(&mut self, curve: &Curve) {
        let n = curve.samples.t.len();
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
    }
}

/// The device may roll this far while an index is typed (the hand's wobble, a tilt), m.
pub const TYPING_ROLL_M: f64 = 0.015;
/// The device stood where the wheel stayed within this, m.
const STAND_M: f64 = 0.002;
/// ... for this long at least, s.
const TYPING_STAND_S: f64 = 0.2;

/// Morphorider: the operator stands while typing a node's index. Where the wheel `w` (at
/// times `t`) went more than [`TYPING_ROLL_M`] between the first digit (`first`) and the
/// Enter (`enter`), the index was typed at one place and entered at another: returns how far
/// it rolled and where the device stood longest meanwhile (the wheel reading held the most
/// samples within [`STAND_M`]), when it stood there for [`TYPING_STAND_S`] at least (a key
/// press; rolling at 5 cm/s, 2 mm take 40 ms).
fn stood_while_typing(t: &[f64], w: &[f64], first: f64, enter: f64) -> Option<(f64, f64)> {
    let rolled = (interp(t, w, enter) - interp(t, w, first)).abs();
    if rolled <= TYPING_ROLL_M {
        return None;
    }
    let (a, b) = (
        t.partition_point(|&x| x < first),
        t.partition_point(|&x| x <= enter),
    );
    let inside = w.get(a..b.min(w.len()))?;
    if inside.len() < 3 {
        return None;
    }
    let mut sorted = inside.to_vec();
    sorted.sort_by(f64::total_cmp);
    // The widest run of readings within STAND_M of each other (two pointers).
    let (mut best, mut at, mut j) = (0, 0, 0);
    for i in 0..sorted.len() {
        while sorted[i] - sorted[j] > STAND_M {
            j += 1;
        }
        if i + 1 - j > best {
            (best, at) = (i + 1 - j, j);
        }
    }
    let stood_s = best as f64 * (enter - first) / inside.len() as f64;
    (stood_s >= TYPING_STAND_S).then(|| (rolled, sorted[at + best / 2]))
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

/// Samples within `w` seconds of a sample whose whole window `[t − w, t + w]` satisfies
/// `still(first, last)`: a morphological opening in time, so that the edges of a still period
/// are not lost to the window.
pub(super) fn stationary_mask(
    t: &[f64],
    w: f64,
    still: impl Fn(usize, usize) -> bool,
) -> Vec<bool> {
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

#[cfg(test)]
mod late_enter_tests {
    use super::*;

    /// A wheel that stands at 0.10 m for 0.3 s of typing, then rolls 40 mm at 5 cm/s before
    /// the Enter: named, placed at 0.10 m. Standing throughout (a wobble of 0.3 mm): not named.
    /// Rolling throughout (no stand of 0.2 s): not placed.
    #[test]
    fn stood_while_typing_finds_where_the_device_stood() {
        let t: Vec<f64> = (0..=110).map(|i| i as f64 * 0.01).collect();
        let late: Vec<f64> = t
            .iter()
            .map(|&x| 0.10 + if x < 0.3 { 0.0 } else { 0.05 * (x - 0.3) })
            .collect();
        let (rolled, stood) = stood_while_typing(&t, &late, 0.0, 1.1).unwrap();
        assert!((rolled - 0.04).abs() < 1e-9, "{rolled}");
        assert!((stood - 0.10).abs() < 1e-9, "{stood}");
        let still: Vec<f64> = t.iter().map(|&x| 0.1 + 0.0003 * (9.0 * x).sin()).collect();
        assert_eq!(stood_while_typing(&t, &still, 0.0, 1.1), None);
        let rolling: Vec<f64> = t.iter().map(|&x| 0.05 * x).collect();
        assert_eq!(stood_while_typing(&t, &rolling, 0.0, 1.1), None);
    }
}
