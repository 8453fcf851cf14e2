//! Phone curves: the smoother's orientations, where the operator stands (around the typing of
//! each node index: a still gyroscope alone may be a phone sliding straight), the speed between
//! the stands, and the distances (scaled per segment to its measured length or to the nominal
//! speed).

use super::open_curve::{stationary_mask, OpenCurve, ReadBack, TYPING_ROLL_M};
use super::{interp, quat_array, quat_of, speed, Acquisition};
use crate::orientation::disturbance::{disturbed_windows, norm_dip};
use crate::orientation::flags;
use crate::orientation::rest;
use crate::orientation::smoother;
use crate::orientation::triad::triad;
use crate::scan::{Curve, Samples};
use crate::warning::AcquisitionWarning;
use nalgebra::{UnitQuaternion, Vector3};

/// What [`Acquisition::phone_motion`] found of a phone curve's motion.
#[derive(Debug, Default)]
pub(super) struct PhoneMotion {
    /// The speed's shape at each sample ([`speed::speed_shape`]), where the accelerometer gives
    /// it.
    pub(super) speed: Option<Vec<f64>>,
    /// The tags entered late, in order.
    pub(super) late: Vec<LateTag>,
}

/// A tag whose index was typed at the node and entered once the device had gone on: it went
/// `distance` (m) from `from` (its set-off) to `to` (its stop, or the Enter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LateTag {
    /// The tag's place in its curve.
    pub(super) tag: usize,
    pub(super) from: f64,
    pub(super) to: f64,
    pub(super) distance: f64,
}

impl Acquisition {
    /// Phone: a finished curve's distances, from the speed's shape where `motion` has it (the
    /// tags entered late placed where the device set off), else from the standing mask.
    pub(super) fn phone_distances(&self, curve: &mut Curve, motion: &PhoneMotion) {
        let nominal = self.cfg.nominal_speed;
        match &motion.speed {
            Some(v) => distances_by_speed(curve, v, nominal, &motion.late),
            None => phone_distances(curve, nominal),
        }
    }

    /// Phone: flags where the operator stands (the smoother's orientations replacing the
    /// causal filter's first, on curves it smooths); returns the speed's shape between the
    /// stands where the accelerometer gives it ([`speed`]), and the tags entered late.
    pub(super) fn phone_motion(
        &mut self,
        rb: &mut ReadBack,
        o: &OpenCurve,
        smoothing: bool,
        field_ref: Option<(f64, f64)>,
        bias: Vector3<f64>,
    ) -> PhoneMotion {
        let w = self.cfg.stationary_window;
        let mut speed_shape = None;
        let mut late = Vec::new();
        let s = &mut rb.s;
        let mut still = if smoothing {
            let [gyros, accs, mags] = &rb.imu;
            let imu = [&gyros[..], &accs[..], &mags[..]];
            let bias_s = self.smooth_phone(s, imu, field_ref, bias, &o.typing);
            // Still: the window's mean rate (the smoothed bias taken off) is small; a hand
            // rocking the standing device back and forth averages out.
            let mut cum = Vec::with_capacity(s.t.len() + 1);
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
            let gyro_still = &rb.gyro_still;
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
            let lin: Vec<Vector3<f64>> = rb.imu[1]
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
                // An index typed at the node and entered once the device had gone on (a late
                // Enter): named, and the tag put where the device set off.
                late = late_set_offs(&s.t, &along, &o.tags, &o.typing);
                for l in &late {
                    let (i0, i1) = (
                        s.t.partition_point(|&x| x < l.from),
                        s.t.partition_point(|&x| x <= l.to),
                    );
                    still[i0..i1].iter_mut().for_each(|m| *m = false);
                    let (node, t, _) = o.tags[l.tag];
                    self.warn(AcquisitionWarning::LateEnter {
                        curve: o.index,
                        node,
                        t,
                        rolled_m: l.distance,
                        moved_m: l.distance,
                    });
                }
                let stretches = stretches(&o.tags, &o.typing);
                let fallback: Vec<f64> = still.iter().map(|&x| if x { 0.0 } else { 1.0 }).collect();
                speed_shape = Some(speed::speed_shape(&s.t, &along, &stretches, &fallback));
            }
        }
        for (f, st) in s.flags.iter_mut().zip(still) {
            if st {
                *f |= flags::STATIONARY;
            }
        }
        PhoneMotion {
            speed: speed_shape,
            late,
        }
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
}

/// Phone: the tags of a curve whose index was typed at the node but entered after the device
/// set off ([`speed::set_off_before`]) and went more than [`TYPING_ROLL_M`]. `t`, `along` the
/// samples' times and acceleration along the travel direction (m/s²); `tags` `(node, Enter
/// time, _)`, `typing` the `(first digit, Enter)` of every tag typed. A curve's last tag is
/// not looked at (no stretch after it).
fn late_set_offs(
    t: &[f64],
    along: &[f64],
    tags: &[(u32, f64, bool)],
    typing: &[(f64, f64)],
) -> Vec<LateTag> {
    let typed = |enter: f64| typing.iter().find(|ty| ty.1 == enter).copied();
    let mut out = Vec::new();
    for k in 0..tags.len().saturating_sub(1) {
        let Some((a, b)) = typed(tags[k].1) else {
            continue;
        };
        // The set-off looked for from the first digit to the next tag's (or a while after the
        // Enter), where the cruise after it is.
        let next = typed(tags[k + 1].1).map_or(tags[k + 1].1, |ty| ty.0);
        let i0 = t.partition_point(|&x| x < a);
        let i1 = t.partition_point(|&x| x <= next.min(b + SET_OFF_REACH));
        let Some(s) = speed::set_off_before(&t[i0..i1], &along[i0..i1], b) else {
            continue;
        };
        if s.distance > TYPING_ROLL_M {
            out.push(LateTag {
                tag: k,
                from: s.ramp.at,
                to: s.stop.map_or(b, |r| (r.at + r.tau).min(b)),
                distance: s.distance,
            });
        }
    }
    out
}

/// How far after an Enter a set-off and the cruise are looked at, s.
const SET_OFF_REACH: f64 = 3.0;

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
/// digit typed after it (the next tag's Enter where no typing is known). `tags` are `(node,
/// Enter time, _)`, `typing` the `(first digit, Enter)` of every tag typed, in order, undone
/// ones included: an index typed wrong at the next node and undone with `U` is typed standing
/// there, so the stretch ends at its first digit, not at the first digit of the index typed
/// again (our field profile's wrong index undone at a curve's second node: the bowl's seed
/// 5 had the segment's last 3.5 s of standing taken for moving).
fn stretches(tags: &[(u32, f64, bool)], typing: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut k = 0;
    tags.windows(2)
        .map(|p| {
            // Both in time order: the first typing that ends after this tag's Enter, if it
            // ends by the next tag's.
            while k < typing.len() && typing[k].1 <= p[0].1 {
                k += 1;
            }
            let next = typing
                .get(k)
                .filter(|ty| ty.1 <= p[1].1)
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
    distances_by_speed(c, &moving, nominal_speed, &[]);
}

/// The way from a tag's Enter to where the device stood at the next tag, m, of a segment
/// measured `len` from Enter to Enter, the next tag entered `went` on from where it stood (a
/// late Enter: that stretch is the typing's). At least half the length.
fn to_stand(len: f64, went: f64) -> f64 {
    (len - went).max(0.5 * len)
}

/// Phone: a curve's distances made again after a segment's length arrived late: each
/// segment's distances, as its speed shape spread them, scaled to the length now known.
/// `went` (one per tag, m; empty for none) is how far the device went between a tag's
/// set-off and its Enter (a tag entered late, [`late_set_offs`]): the lengths count from
/// Enter to Enter, so the segment before such a tag is that much shorter to where the device
/// stood, and the typing after the set-off keeps its distances ([`distances_by_speed`]).
pub(super) fn rescale_segments(c: &mut Curve, went: &[f64]) {
    let n = c.tags.len();
    if n < 2 {
        return;
    }
    let went = |k: usize| went.get(k).copied().unwrap_or(0.0);
    let old: Vec<f64> = c.tags.iter().map(|g| g.d).collect();
    let mut new = old.clone();
    for k in 0..n - 1 {
        // Segment k: the typing after tag k's set-off, then the way to tag k+1.
        let way = match c.segment_lengths.get(k).copied().flatten() {
            Some(len) => to_stand(len, went(k + 1)),
            None => old[k + 1] - old[k] - went(k),
        };
        new[k + 1] = new[k] + went(k) + way;
    }
    let s = &mut c.samples;
    for d in &mut s.d {
        // The segment the distance lies in (the last one that starts at or before it).
        let k = old[..n - 1].partition_point(|&x| x <= *d).saturating_sub(1);
        let x = *d - old[k];
        let typed = went(k);
        let span = old[k + 1] - old[k] - typed;
        *d = if *d > old[n - 1] {
            // After the last tag (its typing, when entered late).
            new[n - 1] + (*d - old[n - 1])
        } else if x <= typed {
            new[k] + x
        } else if span > 0.0 {
            new[k] + typed + (x - typed) * (new[k + 1] - new[k] - typed) / span
        } else {
            new[k] + x
        };
    }
    for (g, d) in c.tags.iter_mut().zip(new) {
        g.d = d;
    }
}

/// Phone distances from a speed shape (`speed`, one per sample, ≥ 0: [`speed::speed_shape`]):
/// within each segment distance grows with the time integral of the shape, scaled to the
/// segment's measured length, else to `nominal_speed` × the integral.
///
/// A tag entered late (`late`, [`late_set_offs`]) is where the device set off: its segments'
/// lengths, measured from Enter to Enter, give the one before it `distance` less and the
/// typing after the set-off that `distance` (linearly in time).
pub(super) fn distances_by_speed(
    c: &mut Curve,
    speed: &[f64],
    nominal_speed: f64,
    late: &[LateTag],
) {
    let s = &mut c.samples;
    let n = s.t.len();
    let nt = c.tags.len();
    if n == 0 || nt < 2 {
        return;
    }
    // The shape's integral at each sample.
    let mut tau = vec![0.0; n];
    for i in 1..n {
        tau[i] = tau[i - 1] + speed[i] * (s.t[i] - s.t[i - 1]);
    }
    let tag_tau: Vec<f64> = c.tags.iter().map(|g| interp(&s.t, &tau, g.t)).collect();
    let mut late_of: Vec<Option<&LateTag>> = vec![None; nt];
    for l in late.iter().filter(|l| l.tag < nt) {
        late_of[l.tag] = Some(l);
    }
    let went = |k: usize| late_of[k].map_or(0.0, |l| l.distance);
    // Each tag's distance where the device stood at it (`at`) and at its Enter (`enter`).
    let mut at = vec![0.0; nt];
    let mut enter = vec![0.0; nt];
    enter[0] = went(0);
    for k in 0..nt - 1 {
        let len = match c.segment_lengths.get(k).copied().flatten() {
            Some(len) => to_stand(len, went(k + 1)),
            None => nominal_speed * (tag_tau[k + 1] - tag_tau[k]),
        };
        at[k + 1] = enter[k] + len;
        enter[k + 1] = at[k + 1] + went(k + 1);
    }
    // Sample by sample, in time: `j` tags entered so far.
    let mut j = 0;
    for (i, d) in s.d.iter_mut().enumerate() {
        let x = s.t[i];
        while j < nt && c.tags[j].t <= x {
            j += 1;
        }
        *d = match late_of.get(j).copied().flatten() {
            // Typing a late tag's index, after the set-off.
            Some(l) if x >= l.from => {
                let span = l.to - l.from;
                let f = if span > 0.0 {
                    ((x - l.from) / span).min(1.0)
                } else {
                    1.0
                };
                at[j] + f * l.distance
            }
            _ if j == 0 => 0.0,
            _ if j == nt => enter[nt - 1],
            _ => {
                let (a, b) = (tag_tau[j - 1], tag_tau[j]);
                if tau[i] >= b {
                    at[j]
                } else if tau[i] > a {
                    enter[j - 1] + (at[j] - enter[j - 1]) * (tau[i] - a) / (b - a)
                } else {
                    enter[j - 1]
                }
            }
        };
    }
    for (tag, d) in c.tags.iter_mut().zip(at) {
        tag.d = d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::keypad::CurveKind;
    use crate::scan::Tag;

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

    /// Issue 52: an index typed wrong at a node and undone with `U` is typed standing there:
    /// the stretch before the node ends at its first digit, not at the first digit of the
    /// index typed again.
    #[test]
    fn issue_52_a_stretch_ends_at_the_first_digit_typed_at_its_node_undone_or_not() {
        let tags = [(0, 0.0, false), (1, 10.0, false), (2, 20.0, false)];
        let typed = [(-1.0, 0.0), (8.5, 10.0), (18.0, 20.0)];
        assert_eq!(stretches(&tags, &typed), [(0.0, 8.5), (10.0, 18.0)]);
        // At node 1 a wrong index typed from 6 s, entered at 7 s and undone, then node 1's.
        let undone = [(-1.0, 0.0), (6.0, 7.0), (8.5, 10.0), (18.0, 20.0)];
        assert_eq!(stretches(&tags, &undone), [(0.0, 6.0), (10.0, 18.0)]);
        // No typing known for a tag: its Enter.
        assert_eq!(stretches(&tags, &typed[..2]), [(0.0, 8.5), (10.0, 20.0)]);
    }

    /// A phone curve sampled at `t` with tags entered at 0, 2 and 4 s (nodes 0, 1, 2) and
    /// the segment lengths `lengths`; its distances not made yet.
    fn three_tags(t: &[f64], lengths: Vec<Option<f64>>) -> Curve {
        let n = t.len();
        Curve {
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
            segment_lengths: lengths,
            samples: Samples {
                t: t.to_vec(),
                d: vec![0.0; n],
                q: vec![[1.0, 0.0, 0.0, 0.0]; n],
                flags: vec![0; n],
                w: vec![1.0; n],
            },
        }
    }

    /// Samples every 10 ms over 4 s, the speed shape moving on (0.2, 1.4) and (2.2, 3.6) s
    /// (tags entered at 0, 2 and 4 s: [`three_tags`]), and the second tag entered late: its
    /// index typed from 1.5 s, the device set off at 1.6 s and went 4 cm by its Enter.
    fn late_second_tag() -> (Vec<f64>, Vec<f64>, [LateTag; 1]) {
        let t: Vec<f64> = (0..=400).map(|i| i as f64 * 0.01).collect();
        let speed = t
            .iter()
            .map(|&x| f64::from(u8::from((0.2..1.4).contains(&x) || (2.2..3.6).contains(&x))))
            .collect();
        let late = [LateTag {
            tag: 1,
            from: 1.6,
            to: 2.0,
            distance: 0.04,
        }];
        (t, speed, late)
    }

    /// Issue 49: a phone tag entered late is placed where the device set off: its segment
    /// lengths count from Enter to Enter, so the one before gives the distance the device went
    /// while the index was typed to the typing; the samples after the set-off go on linearly to
    /// the Enter.
    #[test]
    fn issue_49_a_late_phone_tag_is_placed_where_the_device_set_off() {
        let (t, speed, late) = late_second_tag();
        let curve = |lengths: Vec<Option<f64>>| three_tags(&t, lengths);
        let at = |c: &Curve, x: f64| interp(&c.samples.t, &c.samples.d, x);
        // Measured, Enter to Enter: 0.34 m and 0.26 m.
        let mut c = curve(vec![Some(0.34), Some(0.26)]);
        distances_by_speed(&mut c, &speed, 0.05, &late);
        let d: Vec<f64> = c.tags.iter().map(|g| g.d).collect();
        for (got, want) in d.iter().zip([0.0, 0.30, 0.60]) {
            assert!((got - want).abs() < 1e-12, "{d:?}");
        }
        assert!((at(&c, 1.55) - 0.30).abs() < 1e-12);
        assert!((at(&c, 1.8) - 0.32).abs() < 1e-9);
        assert!((at(&c, 2.1) - 0.34).abs() < 1e-12);
        assert!(c.samples.d.windows(2).all(|w| w[1] >= w[0]));
        // Not measured: the nominal speed over the moving time, the typing's distance added.
        let mut c = curve(vec![None, None]);
        distances_by_speed(&mut c, &speed, 0.05, &late);
        let d: Vec<f64> = c.tags.iter().map(|g| g.d).collect();
        for (got, want) in d.iter().zip([0.0, 0.06, 0.17]) {
            assert!((got - want).abs() < 1e-3, "{d:?}");
        }
        // No late tag: the Enter is the tag.
        let mut c = curve(vec![Some(0.34), Some(0.26)]);
        distances_by_speed(&mut c, &speed, 0.05, &[]);
        assert!((c.tags[1].d - 0.34).abs() < 1e-12);
    }

    /// Issue 52: the same late tag, its segments' lengths arriving after the curve ended (the
    /// independent simulator's phone sends them so): made again with them, the distances are
    /// those the lengths give when they come in time. Before, the tag went back to its Enter
    /// (the segment before it 4 cm long, the one after 4 cm short), and the loops then took
    /// the one after for a slip (faults/, the rough bumpy cube's late Enter: 0.42 % against
    /// its twin's 0.20 %).
    #[test]
    fn issue_52_a_late_tag_stays_where_the_device_set_off_when_its_lengths_come_late() {
        let (t, speed, late) = late_second_tag();
        let mut in_time = three_tags(&t, vec![Some(0.34), Some(0.26)]);
        distances_by_speed(&mut in_time, &speed, 0.05, &late);
        let mut c = three_tags(&t, vec![None, None]);
        distances_by_speed(&mut c, &speed, 0.05, &late);
        let went = [0.0, 0.04, 0.0];
        // One length, then the other, as they come.
        c.segment_lengths[0] = Some(0.34);
        rescale_segments(&mut c, &went);
        c.segment_lengths[1] = Some(0.26);
        rescale_segments(&mut c, &went);
        for (a, b) in c.tags.iter().zip(&in_time.tags) {
            assert!(
                (a.d - b.d).abs() < 1e-12,
                "{:?} vs {:?}",
                c.tags,
                in_time.tags
            );
        }
        for (i, (a, b)) in c.samples.d.iter().zip(&in_time.samples.d).enumerate() {
            assert!((a - b).abs() < 1e-9, "sample {i} at {} s: {a} vs {b}", t[i]);
        }
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
        let mut c = three_tags(&t, vec![Some(0.3), None]);
        distances_by_speed(&mut c, &speed, 0.05, &[]);
        let before = c.samples.d.clone();
        let second = c.tags[2].d - c.tags[1].d;
        c.segment_lengths[0] = Some(0.6);
        rescale_segments(&mut c, &[]);
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
}
