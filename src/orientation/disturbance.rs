//! The session's robust reference of the magnetic field (median norm and median dip angle,
//! from constant-size histograms) and the per-sample disturbance tests.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::orientation::disturbance::{FieldReference, Thresholds};
//! let mut r = FieldReference::new();
//! let up = Vector3::new(0.0, 0.0, 9.81);
//! for _ in 0..100 { r.add(&up, &Vector3::new(0.0, 20.0, -43.0)); }
//! let th = Thresholds::default();
//! assert!(!r.mag_disturbed(&up, &Vector3::new(0.0, 20.0, -43.0), &th));
//! assert!(r.mag_disturbed(&up, &Vector3::new(0.0, 40.0, -43.0), &th));
//! ```

use crate::sensor::G;
use nalgebra::Vector3;

/// Tolerances of the disturbance tests (documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// `| |a| − g |` above this (m/s²) flags motion acceleration. Default 0.6 m/s² (6 % of g).
    pub acc_tol: f64,
    /// Relative deviation of the field norm from the reference. Default 0.08.
    pub mag_norm_rel: f64,
    /// Deviation of the dip angle from the reference, degrees. Default 4°.
    pub mag_dip_deg: f64,
    /// The same two tolerances for the field averaged over a window of
    /// [`WINDOW_HALF`] either side ([`disturbed_windows`]): the averaging takes the noise
    /// away, so the fringe of a magnet's reach, which turns the heading by several degrees
    /// while moving the norm and dip by about 1 % and 1°, is caught. Defaults 1.5 % and 1.5°.
    pub mag_norm_rel_window: f64,
    pub mag_dip_deg_window: f64,
}

/// Half-width of the windows of [`disturbed_windows`], s.
pub const WINDOW_HALF: f64 = 0.25;

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            acc_tol: 0.6,
            mag_norm_rel: 0.08,
            mag_dip_deg: 4.0,
            mag_norm_rel_window: 0.015,
            mag_dip_deg_window: 1.5,
        }
    }
}

/// Whether the accelerometer norm is off g by more than the tolerance.
#[inline]
pub fn acc_motion(acc: &Vector3<f64>, th: &Thresholds) -> bool {
    (acc.norm() - G).abs() > th.acc_tol
}

/// Dip (inclination) of the field below the horizontal plane defined by `acc`, degrees.
#[inline]
pub fn dip_deg(acc: &Vector3<f64>, mag: &Vector3<f64>) -> Option<f64> {
    let (a, m) = (acc.norm(), mag.norm());
    if !(a > 1e-9 && m > 1e-9 && a.is_finite() && m.is_finite()) {
        return None;
    }
    let s = (-(mag.dot(acc)) / (a * m)).clamp(-1.0, 1.0);
    Some(s.asin().to_degrees())
}

/// Fixed-size histogram for a median in constant memory.
#[derive(Debug, Clone)]
struct Histogram {
    lo: f64,
    step: f64,
    bins: Vec<u64>,
    n: u64,
}

impl Histogram {
    fn new(lo: f64, hi: f64, step: f64) -> Self {
        Histogram {
            lo,
            step,
            bins: vec![0; ((hi - lo) / step).ceil() as usize],
            n: 0,
        }
    }
    fn add(&mut self, x: f64) {
        if !x.is_finite() {
            return;
        }
        let i = ((x - self.lo) / self.step).floor();
        let i = (i.max(0.0) as usize).min(self.bins.len() - 1);
        self.bins[i] += 1;
        self.n += 1;
    }
    fn median(&self) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let half = self.n.div_ceil(2);
        let mut acc = 0;
        for (i, &c) in self.bins.iter().enumerate() {
            acc += c;
            if acc >= half {
                return Some(self.lo + (i as f64 + 0.5) * self.step);
            }
        }
        None
    }
}

/// Median field norm (µT) and dip (degrees) of the samples seen so far.
#[derive(Debug, Clone)]
pub struct FieldReference {
    norm: Histogram,
    dip: Histogram,
}

impl Default for FieldReference {
    fn default() -> Self {
        Self::new()
    }
}

impl FieldReference {
    pub fn new() -> Self {
        FieldReference {
            norm: Histogram::new(0.0, 250.0, 0.05),
            dip: Histogram::new(-90.0, 90.0, 0.05),
        }
    }

    /// Adds one sample (frame axes; only directions and norms matter).
    pub fn add(&mut self, acc: &Vector3<f64>, mag: &Vector3<f64>) {
        if let Some(d) = dip_deg(acc, mag) {
            self.norm.add(mag.norm());
            self.dip.add(d);
        }
    }

    /// Samples seen.
    pub fn count(&self) -> u64 {
        self.norm.n
    }

    /// `(median norm µT, median dip °)`.
    pub fn reference(&self) -> Option<(f64, f64)> {
        Some((self.norm.median()?, self.dip.median()?))
    }

    /// Whether `mag` deviates from the reference (false while there is none). For many
    /// samples, take [`reference`](Self::reference) once and call [`mag_disturbed`].
    pub fn mag_disturbed(&self, acc: &Vector3<f64>, mag: &Vector3<f64>, th: &Thresholds) -> bool {
        mag_disturbed(self.reference(), acc, mag, th)
    }
}

/// Whether `mag` deviates from `reference` = `(norm µT, dip °)` (false without a reference).
#[inline]
pub fn mag_disturbed(
    reference: Option<(f64, f64)>,
    acc: &Vector3<f64>,
    mag: &Vector3<f64>,
    th: &Thresholds,
) -> bool {
    let Some((norm, dip)) = reference else {
        return false;
    };
    let Some(d) = dip_deg(acc, mag) else {
        return true;
    };
    (mag.norm() - norm).abs() > th.mag_norm_rel * norm || (d - dip).abs() > th.mag_dip_deg
}

/// The field's norm (µT) and dip (°) of one sample, compactly (NaN where the vectors are
/// degenerate): the input of [`disturbed_windows`], 8 bytes a sample.
pub fn norm_dip(acc: &Vector3<f64>, mag: &Vector3<f64>) -> [f32; 2] {
    match dip_deg(acc, mag) {
        Some(d) => [mag.norm() as f32, d as f32],
        None => [f32::NAN; 2],
    }
}

/// Per sample, whether the field averaged over the window `[t − WINDOW_HALF, t + WINDOW_HALF]`
/// deviates from `reference` = `(norm µT, dip °)` by more than the window tolerances of `th`
/// (all false without a reference). `t` non-decreasing; `nd` from [`norm_dip`] (non-finite
/// values are left out of the means). O(n) time, no memory beyond the result.
pub fn disturbed_windows(
    t: &[f64],
    nd: &[[f32; 2]],
    reference: Option<(f64, f64)>,
    th: &Thresholds,
) -> Vec<bool> {
    let n = t.len().min(nd.len());
    let Some((norm, dip)) = reference else {
        return vec![false; n];
    };
    let ok = |v: &[f32; 2]| v[0].is_finite() && v[1].is_finite();
    let (mut lo, mut hi) = (0usize, 0usize);
    let (mut sn, mut sd, mut k) = (0.0f64, 0.0f64, 0usize);
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        while hi < n && t[hi] <= t[i] + WINDOW_HALF {
            if ok(&nd[hi]) {
                sn += nd[hi][0] as f64;
                sd += nd[hi][1] as f64;
                k += 1;
            }
            hi += 1;
        }
        while t[lo] < t[i] - WINDOW_HALF {
            if ok(&nd[lo]) {
                sn -= nd[lo][0] as f64;
                sd -= nd[lo][1] as f64;
                k -= 1;
            }
            lo += 1;
        }
        out.push(
            k > 0
                && ((sn / k as f64 - norm).abs() > th.mag_norm_rel_window * norm
                    || (sd / k as f64 - dip).abs() > th.mag_dip_deg_window),
        );
    }
    out
}

/// Heading of the frame `q`'s axis `axis` (frame → world): the direction of that axis in the
/// horizontal plane, rad (`atan2(x, y)`: 0 north, π/2 east). A turn of the frame by δ about
/// the vertical turns every axis's heading alike, but an axis near the vertical has no
/// heading to speak of: [`level_axis`] picks one that stays clear of it.
fn heading(q: &nalgebra::UnitQuaternion<f64>, axis: &Vector3<f64>) -> f64 {
    let v = q * axis;
    v.x.atan2(v.y)
}

/// Of the frames' three axes, the one that stays furthest from the vertical over all of `q`
/// (the largest least horizontal part): its heading is defined, and continuous, for every
/// frame of the stretch. A per-frame choice (the tangent, or the second axis where the
/// tangent is steep) switched axes inside a stretch that climbs a wall, and a bridge between
/// two ends measured on different axes was off by up to 90°.
fn level_axis(q: &[nalgebra::UnitQuaternion<f64>]) -> Vector3<f64> {
    let least = |e: &Vector3<f64>| {
        q.iter()
            .map(|f| {
                let v = f * e;
                v.x.hypot(v.y)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()].map(|e| (least(&e), e));
    // The tangent while it never climbs steeply: its heading is the curve's direction on the
    // map, which turns smoothly with the curve (another axis's heading also turns with the
    // surface's slope under the device).
    if axes[0].0 >= STEEP {
        return axes[0].1;
    }
    axes.into_iter()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map_or(Vector3::x(), |(_, e)| e)
}

/// The horizontal part of a unit axis below which its heading is not used (an axis within
/// 17° of the vertical).
const STEEP: f64 = 0.3;

/// Clean samples each end of a bridged stretch averages its heading over (a quarter of a
/// second at 100 Hz: about 2 cm of rolling).
pub const END_SAMPLES: usize = 25;

/// The mean heading of the frames `q`'s axis `axis` (rad, unwrapped about the first's).
fn mean_heading<'a>(
    q: impl ExactSizeIterator<Item = &'a nalgebra::UnitQuaternion<f64>>,
    axis: &Vector3<f64>,
) -> f64 {
    let n = q.len().max(1) as f64;
    let mut q = q.peekable();
    let Some(first) = q.peek() else {
        return 0.0;
    };
    let h0 = heading(first, axis);
    let dh: f64 = q.map(|f| wrap_pi(heading(f, axis) - h0)).sum();
    h0 + dh / n
}

/// `a` brought into [−π, π).
fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// The clean samples next to clean sample `k`, `k` first, up to [`END_SAMPLES`] of them:
/// towards the curve's start (`backwards`) or its end. A bridge's end averages its heading
/// over them (one sample's heading carries the sensors' noise into the whole stretch).
fn clean_next_to(disturbed: &[bool], k: usize, backwards: bool) -> Vec<usize> {
    let clean = |j: &usize| !disturbed[*j];
    if backwards {
        (0..=k).rev().take(END_SAMPLES).take_while(clean).collect()
    } else {
        (k..disturbed.len())
            .take(END_SAMPLES)
            .take_while(clean)
            .collect()
    }
}

/// Marks as disturbed every run of fewer than `gap` clean samples between two disturbed ones
/// (a morphological closing of `disturbed`); returns how many were marked. Inside a magnet's
/// reach a few samples can pass the norm and dip tests (where the magnet's field happens to
/// keep the Earth's norm and dip) while their heading is still turned by tens of degrees: as
/// the clean ends of the stretches either side they pinned the bridged heading to theirs
/// (the validation's rough Morphorider bumpy cube, seed 23: 12 such samples between
/// disturbed runs of 341 and 673 left 14–37° of heading error over 10 s of rolling). A clean
/// run shorter than [`END_SAMPLES`] cannot give a bridge the end it averages over anyway.
pub fn close_gaps(disturbed: &mut [bool], gap: usize) -> usize {
    let n = disturbed.len();
    let mut marked = 0;
    let mut last: Option<usize> = None;
    for i in 0..n {
        if !disturbed[i] {
            continue;
        }
        if let Some(l) = last {
            if i > l + 1 && i - l - 1 < gap {
                for d in &mut disturbed[l + 1..i] {
                    *d = true;
                }
                marked += i - l - 1;
            }
        }
        last = Some(i);
    }
    marked
}

/// Bridges the heading across stretches of disturbed samples (`disturbed[i]`): the field there
/// is not the Earth's, and a TRIAD orientation turns with it about the vertical, by tens of
/// degrees in a magnet's reach. Each stretch's tilt is kept. A magnet's field depends on where
/// the device is, not on how it is turned: while the wheel stands still (a node, a corner) the
/// heading's error stays the same, so the turns measured there are the device's own
/// ([`standing_runs`]) and are kept; only while it rolls is the heading replaced:
///
/// - a stretch with clean samples on both sides: the heading of the level axis moves linearly
///   along `x` (the distance travelled) from one side's to the other's (each side's the mean
///   over up to [`END_SAMPLES`] clean samples), plus the turns made standing;
/// - a stretch at an end of the curve (one clean side): [`least_turning`] from that side;
/// - a curve disturbed throughout is left as measured.
///
/// Returns how many samples were changed.
pub fn bridge_heading(
    q: &mut [nalgebra::UnitQuaternion<f64>],
    x: &[f64],
    disturbed: &[bool],
) -> usize {
    let n = q.len().min(x.len()).min(disturbed.len());
    let standing = standing_runs(&x[..n]);
    let mut changed = 0;
    let mut i = 0;
    while i < n {
        if !disturbed[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < n && disturbed[i] {
            i += 1;
        }
        let (before, after) = (start.checked_sub(1), (i < n).then_some(i));
        let (a, b) = match (before, after) {
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => {
                changed += least_turning(q, disturbed, &standing, a, true, start..i);
                continue;
            }
            (None, Some(b)) => {
                changed += least_turning(q, disturbed, &standing, b, false, (start..i).rev());
                continue;
            }
            (None, None) => continue,
        };
        // Each end: the mean over the clean samples next to it.
        let lo = clean_next_to(&disturbed[..n], a, true)
            .last()
            .copied()
            .unwrap_or(a);
        let hi = clean_next_to(&disturbed[..n], b, false)
            .last()
            .copied()
            .unwrap_or(b);
        let axis = level_axis(&q[lo..=hi]);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let (h0, x0) = (mean_heading(q[lo..=a].iter(), &axis), mean(&x[lo..=a]));
        let (h1, x1) = (mean_heading(q[b..=hi].iter(), &axis), mean(&x[b..=hi]));
        // The measured headings, unwrapped from the first clean end's; the turns made standing
        // (each run's change of heading, to every sample of the stretch after its start).
        let measured = unwrapped(&q[a..=b], &axis, h0);
        let turns = stand_turns(&q[a..=b], &standing[a..=b]);
        let mut turned = vec![0.0; b - a + 1];
        let (mut total, mut base, mut first) = (0.0, 0.0, measured[0]);
        for k in a + 1..=b {
            let r = standing[k];
            if r != 0 && turns.contains_key(&r) {
                if standing[k - 1] != r {
                    (base, first) = (total, measured[k - a]);
                }
                turned[k - a] = base + measured[k - a] - first;
                if standing.get(k + 1) != Some(&r) || k == b {
                    total = base + turns[&r];
                }
            } else {
                turned[k - a] = total;
            }
        }
        let d = wrap_pi(h1 - h0 - total);
        for k in start..i {
            let u = if x1 > x0 {
                ((x[k] - x0) / (x1 - x0)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            let target = h0 + u * d + turned[k - a];
            // A heading grows clockwise seen from above: a turn of −δ about +z adds δ.
            let turn = nalgebra::UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                measured[k - a] - target,
            );
            q[k] = turn * q[k];
            changed += 1;
        }
    }
    changed
}

/// The headings of `q`'s axis `axis`, each unwrapped to within π of the one before, the first
/// to within π of `near`.
fn unwrapped(q: &[nalgebra::UnitQuaternion<f64>], axis: &Vector3<f64>, near: f64) -> Vec<f64> {
    let mut last = near;
    q.iter()
        .map(|f| {
            let h = heading(f, axis);
            last += wrap_pi(h - last);
            last
        })
        .collect()
}

/// Per sample, the stand it belongs to (numbered from 1; 0 for none): a run of at least
/// [`STAND_SAMPLES`] samples where the wheel stood still (its reading unchanged), a node or a
/// corner, where the device may turn in place.
fn standing_runs(x: &[f64]) -> Vec<usize> {
    let n = x.len();
    let mut out = vec![0; n];
    let (mut i, mut run) = (0, 0);
    while i < n {
        let mut j = i + 1;
        while j < n && (x[j] - x[i]).abs() < 1e-7 {
            j += 1;
        }
        if j - i >= STAND_SAMPLES {
            run += 1;
            out[i..j].iter_mut().for_each(|s| *s = run);
        }
        i = j;
    }
    out
}

/// The turns in place among the stands of `standing` ([`standing_runs`]) over the frames `q`:
/// per stand (its number), the change of heading from its first [`TURN_MEAN`] samples to its
/// last, when it is at least [`TURN_MIN_DEG`].
fn stand_turns(
    q: &[nalgebra::UnitQuaternion<f64>],
    standing: &[usize],
) -> std::collections::HashMap<usize, f64> {
    let mut out = std::collections::HashMap::new();
    let n = q.len().min(standing.len());
    let mut i = 0;
    while i < n {
        let r = standing[i];
        let mut j = i + 1;
        while j < n && standing[j] == r {
            j += 1;
        }
        if r != 0 {
            let frames = &q[i..j];
            let axis = level_axis(frames);
            let k = TURN_MEAN.min(frames.len() / 2).max(1);
            let h0 = mean_heading(frames[..k].iter(), &axis);
            let h1 = mean_heading(frames[frames.len() - k..].iter(), &axis);
            let turn = wrap_pi(h1 - h0);
            if turn.abs() >= TURN_MIN_DEG.to_radians() {
                out.insert(r, turn);
            }
        }
        i = j;
    }
    out
}

/// Samples each end of a stand whose mean heading measures its turn ([`stand_turns`]).
const TURN_MEAN: usize = 10;

/// A stand's change of heading below which it is not taken as a turn in place: the hand
/// tilting the device while typing moves the measured heading by up to 12° between two
/// samples of a stand (the independent simulator's rough Morphorider); a turn at a corner
/// or at a curve's start is tens of degrees.
const TURN_MIN_DEG: f64 = 15.0;

/// Samples `a` and `b` stood in the same stand ([`standing_runs`]).
fn same_stand(standing: &[usize], a: usize, b: usize) -> bool {
    standing[a] != 0 && standing[a] == standing[b]
}

/// Samples of an unchanged wheel reading that make a stand ([`standing_runs`]): a fifth of a
/// second at 100 Hz. A slow roll leaves shorter runs between the wheel's ticks, whose
/// headings' noise would add up.
const STAND_SAMPLES: usize = 20;

/// A stretch with one clean end (`anchor`, the clean sample next to it, with the clean
/// samples beyond it towards the curve's start when `clean_backwards`): each frame of
/// `stretch`, walked away from the anchor, is turned about the vertical to the heading that
/// least turns the device from the frame before it (its tilt kept); while the wheel stands
/// (`standing`) the frame keeps the turn of the one before, as a magnet's error does.
/// Holding one end's heading would take the stretch as straight (a 28 cm stretch at the
/// start of a lilium section that curves as it climbs); this keeps every turn about a level
/// axis (the device rolling over the surface's bends, which the accelerometer sees) and drops
/// the turns about the vertical made rolling, which only the magnetometer could show and a
/// magnet fakes: on a box's upright edge, where the heading is the face the device rests on,
/// the clean end's face is kept. The anchor's heading is the mean over up to
/// [`END_SAMPLES`] clean samples. Returns how many frames were turned.
fn least_turning(
    q: &mut [nalgebra::UnitQuaternion<f64>],
    disturbed: &[bool],
    standing: &[usize],
    anchor: usize,
    clean_backwards: bool,
    stretch: impl Iterator<Item = usize>,
) -> usize {
    // The clean samples next to the anchor, away from the stretch.
    let frames: Vec<_> = clean_next_to(disturbed, anchor, clean_backwards)
        .iter()
        .map(|&k| q[k])
        .collect();
    let axis = level_axis(&frames);
    let mean = mean_heading(frames.iter(), &axis);
    let mut delta = heading(&q[anchor], &axis) - mean;
    let turns = stand_turns(q, standing);
    let mut prev_k = anchor;
    let mut prev = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), delta) * q[anchor];
    let mut changed = 0;
    for k in stretch {
        if !(same_stand(standing, prev_k, k) && turns.contains_key(&standing[k])) {
            // max over δ of tr(Rz(δ)·A), A = Q Pᵀ: δ = atan2(A01 − A10, A00 + A11).
            let m = q[k].to_rotation_matrix().into_inner()
                * prev.to_rotation_matrix().matrix().transpose();
            delta = (m[(0, 1)] - m[(1, 0)]).atan2(m[(0, 0)] + m[(1, 1)]);
        }
        q[k] = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), delta) * q[k];
        prev = q[k];
        prev_k = k;
        changed += 1;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    /// Every frame of `q` within `deg` of the truth's.
    fn assert_within(q: &[UnitQuaternion<f64>], truth: &[UnitQuaternion<f64>], deg: f64) {
        for (i, (a, t)) in q.iter().zip(truth).enumerate() {
            let err = a.angle_to(t).to_degrees();
            assert!(err < deg, "sample {i}: {err:.2}° off");
        }
    }

    /// The fringe of a magnet (its field adding 20 % of (15, 0, 5) µT: the heading turns by 8°,
    /// the dip by 1.6°, each sample's test passes) is flagged by the windowed test; the clean
    /// field with noise is not.
    #[test]
    fn disturbed_windows_catch_the_fringe_of_a_magnet() {
        let earth = Vector3::new(0.0, 21.04, -43.14);
        let up = Vector3::new(0.0, 0.0, 9.81);
        let mut seed = 7u64;
        let mut noise = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1.5
        };
        let t: Vec<f64> = (0..600).map(|i| i as f64 * 0.01).collect();
        let mut nd = Vec::new();
        let mut per_sample = 0;
        for i in 0..600 {
            let extra = if (200..400).contains(&i) {
                Vector3::new(15.0, 0.0, 5.0) * 0.2
            } else {
                Vector3::zeros()
            };
            let m = earth + extra + Vector3::new(noise(), noise(), noise());
            nd.push(norm_dip(&up, &m));
            let r = (earth.norm(), dip_deg(&up, &earth).unwrap());
            per_sample += mag_disturbed(Some(r), &up, &m, &Thresholds::default()) as usize;
        }
        let reference = Some((earth.norm(), dip_deg(&up, &earth).unwrap()));
        let w = disturbed_windows(&t, &nd, reference, &Thresholds::default());
        assert!(per_sample < 10, "the per-sample test flags {per_sample}");
        assert!(w[230..370].iter().all(|&d| d), "the fringe is flagged");
        assert!(
            w[..170].iter().chain(&w[430..]).all(|&d| !d),
            "clean samples are not"
        );
        assert!(disturbed_windows(&t, &nd, None, &Thresholds::default())
            .iter()
            .all(|&d| !d));
    }

    /// A section climbing a slope that bends (the tangent pitching from 0 to 40° about a
    /// level axis, the azimuth fixed) while the surface rolls the device by 5° about its
    /// tangent, a magnet turning its first or its last 60 samples by up to 30° about the
    /// vertical (most at the curve's end, fading towards the clean side): bridged from the one
    /// clean side, every frame is back within 1.5° (from 30°). What is left is the vertical
    /// part of the roll about a climbing tangent, which the bridge drops with the magnet's
    /// turn. (Issue 33 left such a stretch as measured: 30° off.)
    #[test]
    fn issue_52_a_stretch_with_one_clean_side_keeps_the_turns_about_level_axes() {
        let n = 150;
        let azimuth = 0.4;
        let truth: Vec<UnitQuaternion<f64>> = (0..n)
            .map(|i| {
                let u = i as f64 / (n - 1) as f64;
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), azimuth)
                    * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.7 * u)
                    * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.087 * u)
            })
            .collect();
        let x: Vec<f64> = (0..n).map(|i| i as f64 * 0.004).collect();
        for at_start in [true, false] {
            let disturbed: Vec<bool> = (0..n)
                .map(|i| if at_start { i < 60 } else { i >= n - 60 })
                .collect();
            let mut q: Vec<UnitQuaternion<f64>> = truth
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let depth = if at_start {
                        60 - i as i64
                    } else {
                        i as i64 - (n as i64 - 61)
                    };
                    let angle = 30f64.to_radians() * (depth.max(0) as f64 / 60.0);
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle) * t
                })
                .collect();
            assert_eq!(bridge_heading(&mut q, &x, &disturbed), 60);
            for (i, (a, t)) in q.iter().zip(&truth).enumerate() {
                let err = a.angle_to(t).to_degrees();
                assert!(err < 1.5, "start {at_start}, sample {i}: {err:.2}° off");
            }
        }
    }

    /// Issue 52: a box's rim, rolled east, stopped at a corner and turned in place by 90°,
    /// then rolled north; a magnet at the corner turns the heading by up to 35° (a function
    /// of where the device is: the same all through the stand). The turn in place is the
    /// device's own and is kept: every frame comes back within a degree. Interpolated across
    /// the stretch instead, the rim's corner was rounded over the stretch (45° off).
    #[test]
    fn issue_52_a_turn_in_place_inside_a_disturbed_stretch_is_kept() {
        // 100 samples rolling east at 4 mm per sample, 60 standing (turning over the middle
        // 40), 100 rolling north.
        let mut x = Vec::new();
        let mut yaw = Vec::new();
        for i in 0..260 {
            let (xi, turned) = match i {
                0..=99 => (i as f64 * 0.004, 0.0),
                100..=159 => (0.4, ((i as f64 - 110.0) / 40.0).clamp(0.0, 1.0)),
                _ => (0.4 + (i - 159) as f64 * 0.004, 1.0),
            };
            x.push(xi);
            // Heading east (π/2), then north (0): a turn of −90° in heading.
            yaw.push(std::f64::consts::FRAC_PI_2 * (1.0 - turned));
        }
        // A frame whose tangent has heading h: Rz(−h) about +z turns north (+y) to it; the
        // body's x is the tangent, so start from the tangent pointing north.
        let base = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let truth: Vec<UnitQuaternion<f64>> = yaw
            .iter()
            .map(|&h| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -h) * base)
            .collect();
        let disturbed: Vec<bool> = x.iter().map(|&xi| (xi - 0.4).abs() < 0.25).collect();
        let mut q: Vec<UnitQuaternion<f64>> = truth
            .iter()
            .zip(&x)
            .map(|(t, &xi)| {
                let e = 35f64.to_radians() * (1.0 - (xi - 0.4).abs() / 0.25).max(0.0);
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), e) * t
            })
            .collect();
        let changed = bridge_heading(&mut q, &x, &disturbed);
        assert_eq!(changed, disturbed.iter().filter(|&&d| d).count());
        assert_within(&q, &truth, 1.0);
    }

    /// A stand whose heading wobbles by a few degrees (a hand typing) is not a turn in place.
    #[test]
    fn stand_turns_takes_only_turns_of_tens_of_degrees() {
        let wobble: Vec<UnitQuaternion<f64>> = (0..40)
            .map(|i| {
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.15 * ((i % 7) as f64 / 7.0))
            })
            .collect();
        let standing = vec![1; 40];
        assert!(stand_turns(&wobble, &standing).is_empty());
        let turning: Vec<UnitQuaternion<f64>> = (0..40)
            .map(|i| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.02 * i as f64))
            .collect();
        let turns = stand_turns(&turning, &standing);
        // From the mean of the first 10 to the mean of the last 10: 30 samples of 0.02 rad,
        // a heading turning the other way (headings grow clockwise).
        assert!((turns[&1] + 0.6).abs() < 1e-9, "{turns:?}");
        assert_eq!(standing_runs(&[0.0; 19]), vec![0; 19]);
        assert_eq!(standing_runs(&[0.0; 20]), vec![1; 20]);
    }

    #[test]
    fn close_gaps_fills_short_clean_runs_between_disturbed_ones_only() {
        let d = |s: &str| s.chars().map(|c| c == 'D').collect::<Vec<bool>>();
        let mut m = d("ccDDcccDDccccccDc");
        assert_eq!(close_gaps(&mut m, 4), 3);
        assert_eq!(m, d("ccDDDDDDDccccccDc"));
        // The clean ends stay clean; with nothing disturbed nothing is marked.
        let mut m = d("cccc");
        assert_eq!(close_gaps(&mut m, 10), 0);
        assert_eq!(m, d("cccc"));
    }

    /// A vertical section climbing a wall: the tangent pitches up to 85° and back while the
    /// second axis stays level; a magnet turns the middle of it by 30° about the vertical.
    /// Bridged on the level axis, every frame is back within a degree. (Bridged as before, on
    /// the tangent where it is not steep and the second axis where it is, the steep frames
    /// were turned by about 90° more.)
    #[test]
    fn bridge_heading_keeps_one_axis_across_a_stretch_that_climbs_a_wall() {
        use nalgebra::UnitQuaternion;
        let n = 200;
        let azimuth = 0.7;
        let truth: Vec<UnitQuaternion<f64>> = (0..n)
            .map(|i| {
                let pitch =
                    85f64.to_radians() * (std::f64::consts::PI * i as f64 / (n - 1) as f64).sin();
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), azimuth)
                    * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -pitch)
            })
            .collect();
        let x: Vec<f64> = (0..n).map(|i| i as f64 * 0.005).collect();
        let disturbed: Vec<bool> = (0..n).map(|i| (60..140).contains(&i)).collect();
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
        let mut q: Vec<UnitQuaternion<f64>> = truth
            .iter()
            .zip(&disturbed)
            .map(|(t, &d)| if d { turn * t } else { *t })
            .collect();
        assert_eq!(bridge_heading(&mut q, &x, &disturbed), 80);
        assert_within(&q, &truth, 1.0);
    }

    #[test]
    fn bridge_heading_undoes_a_turn_of_the_field() {
        let truth: Vec<UnitQuaternion<f64>> = (0..100)
            .map(|i| {
                UnitQuaternion::from_euler_angles(0.3, -0.2, 0.0)
                    .rotation_to(&UnitQuaternion::identity())
                    .inverse()
                    * UnitQuaternion::from_euler_angles(0.0, 0.0, 0.01 * i as f64)
            })
            .map(|q| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.01) * q)
            .collect();
        let x: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
        let disturbed: Vec<bool> = (0..100).map(|i| (40..60).contains(&i)).collect();
        let mut q: Vec<UnitQuaternion<f64>> = truth
            .iter()
            .zip(&disturbed)
            .map(|(q, &d)| {
                if d {
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5) * q
                } else {
                    *q
                }
            })
            .collect();
        assert_eq!(bridge_heading(&mut q, &x, &disturbed), 20);
        for i in 0..100 {
            let e = q[i].angle_to(&truth[i]).to_degrees();
            assert!(e < 0.5, "sample {i}: {e:.2}°");
        }
        // All disturbed: nothing to bridge from.
        let mut q2 = q.clone();
        assert_eq!(bridge_heading(&mut q2, &x, &[true; 100]), 0);
        assert_eq!(q2, q);
    }

    /// Issue 33: each end of a stretch is the mean of the clean headings next to it, not one
    /// sample's: on a straight run whose headings scatter by 4° (a rough Morphorider), a
    /// stretch turned 30° by a magnet comes back within 1.5° (from one sample each end, up to
    /// the scatter itself: 10° on lilium).
    #[test]
    fn bridge_heading_averages_the_noise_of_its_ends() {
        let mut rng = sfs_geometry::rng::Rng::new(3);
        let x: Vec<f64> = (0..300).map(|i| i as f64 * 0.001).collect();
        let disturbed: Vec<bool> = (0..300).map(|i| (100..200).contains(&i)).collect();
        let true_heading = 0.5;
        let mut q: Vec<UnitQuaternion<f64>> = disturbed
            .iter()
            .map(|&d| {
                let h = true_heading + 4f64.to_radians() * rng.gauss() + if d { 0.5 } else { 0.0 };
                // Heading h (from north, clockwise): a turn of −h about +z of the frame whose
                // first axis points north.
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -h)
                    * UnitQuaternion::from_axis_angle(
                        &Vector3::z_axis(),
                        std::f64::consts::FRAC_PI_2,
                    )
            })
            .collect();
        assert_eq!(bridge_heading(&mut q, &x, &disturbed), 100);
        for (i, f) in q.iter().enumerate().take(200).skip(100) {
            let e = (heading(f, &Vector3::x()) - true_heading).to_degrees();
            assert!(e.abs() < 1.5, "sample {i}: {e:.2}°");
        }
    }
}
