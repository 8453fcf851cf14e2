//! Rests from window statistics: the spread of a signal over a sliding window (its RMS
//! deviation from the window's mean) against the noise measured in the same session, not a
//! per-sample threshold. A device at rest shows only its sensor noise; a moving one, more. A
//! steady slow turn keeps the gyroscope as steady as a rest (its mean is off by the rate, which
//! an unknown bias hides): a rest must also keep its gravity and field directions
//! ([`turn_rate`]).
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::orientation::rest::{noise_floor, window_stats};
//! // 1 s of noise-free rest, then 1 s turning at a varying rate, at 100 Hz.
//! let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.01).collect();
//! let w: Vec<Vector3<f64>> = t.iter().map(|&t| Vector3::z() * if t < 1.0 { 0.0 } else { t.sin() }).collect();
//! let s = window_stats(&t, &w, 0.1);
//! assert!(s.spread[50] < 1e-12 && s.spread[150] > 1e-3);
//! assert!(noise_floor(&s.spread) < 1e-12);
//! ```

use super::triad::triad;
use nalgebra::Vector3;

/// Per sample, the statistics of the window `[t − half, t + half]` around it.
#[derive(Debug, Clone, Default)]
pub struct WindowStats {
    /// Mean of the window.
    pub mean: Vec<Vector3<f64>>,
    /// RMS deviation from that mean, `sqrt(mean |x − x̄|²)` (all axes together).
    pub spread: Vec<f64>,
}

/// [`WindowStats`] of `x` sampled at times `t` (non-decreasing, same length), in O(n) (prefix
/// sums, two pointers). Non-finite values count as zero.
pub fn window_stats(t: &[f64], x: &[Vector3<f64>], half: f64) -> WindowStats {
    let n = t.len().min(x.len());
    let clean = |v: &Vector3<f64>| {
        if v.iter().all(|c| c.is_finite()) {
            *v
        } else {
            Vector3::zeros()
        }
    };
    // Prefix sums of x and |x|², centred on the first sample to keep the sums small.
    let origin = x.first().map(clean).unwrap_or_default();
    let mut sx = Vec::with_capacity(n + 1);
    let mut sq = Vec::with_capacity(n + 1);
    sx.push(Vector3::zeros());
    sq.push(0.0);
    for v in &x[..n] {
        let d = clean(v) - origin;
        sx.push(sx.last().copied().unwrap_or_default() + d);
        sq.push(sq.last().copied().unwrap_or_default() + d.norm_squared());
    }
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut out = WindowStats {
        mean: Vec::with_capacity(n),
        spread: Vec::with_capacity(n),
    };
    for i in 0..n {
        while t[lo] < t[i] - half {
            lo += 1;
        }
        while hi < n && t[hi] <= t[i] + half {
            hi += 1;
        }
        let k = (hi - lo) as f64;
        let m = (sx[hi] - sx[lo]) / k;
        let var = (sq[hi] - sq[lo]) / k - m.norm_squared();
        out.mean.push(m + origin);
        out.spread.push(var.max(0.0).sqrt());
    }
    out
}

/// The noise of a device's sensors: the spread of their quietest windows
/// ([`noise_floor`]), all three axes together (σ per axis is the spread / √3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseFloors {
    /// Gyroscope, rad/s.
    pub gyro: f64,
    /// Accelerometer, m/s².
    pub acc: f64,
    /// Magnetometer, µT.
    pub mag: f64,
}

impl NoiseFloors {
    /// σ of one sample per axis (the spreads are over three axes).
    pub fn per_axis(&self) -> NoiseFloors {
        let k = 3f64.sqrt();
        NoiseFloors {
            gyro: self.gyro / k,
            acc: self.acc / k,
            mag: self.mag / k,
        }
    }

    /// The lesser of each (the session's floors so far and one more curve's).
    pub fn min(&self, o: &NoiseFloors) -> NoiseFloors {
        NoiseFloors {
            gyro: self.gyro.min(o.gyro),
            acc: self.acc.min(o.acc),
            mag: self.mag.min(o.mag),
        }
    }
}

/// Half-width of the windows whose statistics decide rest, s.
pub const HALF_WINDOW: f64 = 0.2;
/// A window whose spreads are within this factor of the noise floors is at rest.
pub const SPREAD_FACTOR: f64 = 2.0;

/// Half-span of the test that tells a slow steady turn from a rest, s: the gravity and field
/// directions averaged over the `TURN_HALF` before a sample and the `TURN_HALF` after it.
pub const TURN_HALF: f64 = 1.0;
/// A rest turns (by those directions) by less than this, rad/s: 1°/s.
pub const TURN_LIMIT: f64 = std::f64::consts::PI / 180.0;

/// Per sample, the rate at which the device turns as the accelerometer and magnetometer see it,
/// rad/s: the angle between the orientations (TRIAD) of their means over `[t − half, t]` and
/// `[t, t + half]`, over the time between the two windows' centres. A gyroscope steady over a
/// short window does not tell a rest from a steady slow turn (a phone sliding along a great
/// circle); this does, whatever the gyroscope's bias. Where the field's norm changes between
/// the two windows by more than 2 % (a magnet nearby turns the field, not the device) only the
/// turn of gravity counts.
pub fn turn_rate(t: &[f64], acc: &[Vector3<f64>], mag: &[Vector3<f64>], half: f64) -> Vec<f64> {
    let n = t.len().min(acc.len()).min(mag.len());
    let wa = window_stats(&t[..n], &acc[..n], half / 2.0);
    let wm = window_stats(&t[..n], &mag[..n], half / 2.0);
    // The orientation of each window's means, once per sample.
    let frame: Vec<_> = wa
        .mean
        .iter()
        .zip(&wm.mean)
        .map(|(a, m)| triad(a, m))
        .collect();
    // The window centred half / 2 before (first sample from then) and half / 2 after (last
    // sample until then), by two pointers over the sorted times.
    let (mut before, mut until) = (0usize, 0usize);
    (0..n)
        .map(|i| {
            while t[before] < t[i] - half / 2.0 {
                before += 1;
            }
            while until < n && t[until] <= t[i] + half / 2.0 {
                until += 1;
            }
            let (j0, j1) = (before.min(i), until.saturating_sub(1).max(i));
            let span = t[j1] - t[j0];
            if span <= 0.0 {
                return 0.0;
            }
            let (a0, a1) = (wa.mean[j0], wa.mean[j1]);
            let (n0, n1) = (wm.mean[j0].norm(), wm.mean[j1].norm());
            let steady_field = n0 > 0.0 && n1 > 0.0 && (n0 - n1).abs() <= 0.02 * n0.max(n1);
            let angle = match (frame[j0], frame[j1]) {
                (Some(q0), Some(q1)) if steady_field => q0.angle_to(&q1),
                _ if a0.norm() > 0.0 && a1.norm() > 0.0 => a0.angle(&a1),
                _ => 0.0,
            };
            angle / span
        })
        .collect()
}

/// Rests of a stretch of samples (gyroscope and accelerometer windows both within
/// [`SPREAD_FACTOR`] of their floors, and turning by less than [`TURN_LIMIT`] by
/// [`turn_rate`]), and the floors: those measured here, or the lesser of
/// them and `session`'s (a stretch without any rest then borrows the session's).
pub fn rests(
    t: &[f64],
    gyro: &[Vector3<f64>],
    acc: &[Vector3<f64>],
    mag: &[Vector3<f64>],
    session: Option<NoiseFloors>,
) -> (Vec<bool>, NoiseFloors) {
    let wg = window_stats(t, gyro, HALF_WINDOW);
    let wa = window_stats(t, acc, HALF_WINDOW);
    let wm = window_stats(t, mag, HALF_WINDOW);
    let here = NoiseFloors {
        gyro: noise_floor(&wg.spread),
        acc: noise_floor(&wa.spread),
        mag: noise_floor(&wm.spread),
    };
    let floors = session.map_or(here, |s| s.min(&here));
    let turn = turn_rate(t, acc, mag, TURN_HALF);
    let rest = wg
        .spread
        .iter()
        .zip(&wa.spread)
        .zip(&turn)
        .map(|((&g, &a), &w)| {
            g <= SPREAD_FACTOR * floors.gyro && a <= SPREAD_FACTOR * floors.acc && w < TURN_LIMIT
        })
        .collect();
    (rest, floors)
}

/// The noise level of a signal from its window spreads: the 1st percentile (the quietest
/// windows, which are rests when there are any: a curve scanned with few stops has rests on
/// a few per cent of its samples). `0` for no windows.
pub fn noise_floor(spread: &[f64]) -> f64 {
    let mut s: Vec<f64> = spread.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return 0.0;
    }
    let k = (s.len() - 1) / 100;
    *s.select_nth_unstable_by(k, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window statistics equal the direct computation on random data with uneven times.
    #[test]
    fn window_stats_match_the_direct_computation() {
        let mut s = 12345u64;
        let mut u = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut t = vec![0.0];
        for _ in 1..300 {
            let last = *t.last().unwrap();
            t.push(last + 0.002 + 0.01 * u());
        }
        let x: Vec<Vector3<f64>> = (0..300)
            .map(|_| Vector3::new(u(), u() - 3.0, 100.0 + u()))
            .collect();
        let w = window_stats(&t, &x, 0.05);
        for i in 0..300 {
            let idx: Vec<usize> = (0..300).filter(|&j| (t[j] - t[i]).abs() <= 0.05).collect();
            let m: Vector3<f64> =
                idx.iter().map(|&j| x[j]).sum::<Vector3<f64>>() / idx.len() as f64;
            let var: f64 =
                idx.iter().map(|&j| (x[j] - m).norm_squared()).sum::<f64>() / idx.len() as f64;
            assert!((w.mean[i] - m).norm() < 1e-9, "mean at {i}");
            assert!((w.spread[i] - var.sqrt()).abs() < 1e-7, "spread at {i}");
        }
    }

    /// Issue 17 (a phone sliding along a great circle took 40° of heading): 8 s still, then
    /// 8 s turning steadily at 3°/s about a horizontal axis, then 8 s turning at 3°/s about the
    /// vertical (a phone on a table), with sensor noise. The gyroscope is steady throughout;
    /// only the still part is a rest.
    #[test]
    fn issue_17_a_slow_steady_turn_is_no_rest() {
        use nalgebra::UnitQuaternion;
        let mut seed = 99u64;
        let mut noise = |s: f64| {
            let mut v = Vector3::zeros();
            for x in v.iter_mut() {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                *x = s * ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.46;
            }
            v
        };
        let rate = 3f64.to_radians();
        let (g, field) = (Vector3::new(0.0, 0.0, 9.81), Vector3::new(0.0, 20.0, -43.0));
        let (mut t, mut gyro, mut acc, mut mag) = (vec![], vec![], vec![], vec![]);
        let mut q = UnitQuaternion::identity();
        for i in 0..2400 {
            let ti = i as f64 * 0.01;
            let w = if ti < 8.0 {
                Vector3::zeros()
            } else if ti < 16.0 {
                Vector3::x() * rate
            } else {
                q.inverse() * Vector3::z() * rate
            };
            q *= UnitQuaternion::from_scaled_axis(w * 0.01);
            t.push(ti);
            gyro.push(w + Vector3::new(0.01, -0.02, 0.015) + noise(0.003));
            acc.push(q.inverse() * g + noise(0.03));
            mag.push(q.inverse() * field + noise(0.4));
        }
        let (rest, _) = rests(&t, &gyro, &acc, &mag, None);
        let share =
            |a: usize, b: usize| rest[a..b].iter().filter(|&&r| r).count() as f64 / (b - a) as f64;
        assert!(share(100, 700) > 0.95, "still: {}", share(100, 700));
        assert!(share(900, 1500) < 0.05, "pitching: {}", share(900, 1500));
        assert!(share(1700, 2300) < 0.05, "yawing: {}", share(1700, 2300));
        // Without the turn test the gyroscope's spread alone calls the turns rests.
        let wg = window_stats(&t, &gyro, HALF_WINDOW);
        let floor = noise_floor(&wg.spread);
        let steady = wg.spread[900..1500]
            .iter()
            .filter(|&&s| s <= SPREAD_FACTOR * floor);
        assert!(steady.count() > 500);
    }

    #[test]
    fn noise_floor_is_the_quiet_part() {
        let mut spread = vec![1.0; 95];
        spread.extend(vec![0.1; 5]);
        assert_eq!(noise_floor(&spread), 0.1);
        assert_eq!(noise_floor(&[]), 0.0);
        assert_eq!(noise_floor(&[f64::NAN, 2.0]), 2.0);
    }
}
