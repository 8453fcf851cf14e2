//! The rests of a calibration capture: the spans where the device lay still, each giving one
//! static pose (the accelerometer's mean reading: gravity, for the accelerometer fit) and the
//! gyroscope's mean (its bias).
//!
//! Still means, over windows of [`WINDOW_S`]: the accelerometer steady, the magnetometer
//! steady (its raw vector, so its direction too: a slow turn about the vertical keeps the
//! accelerometer and a constant-rate gyroscope steady, never the magnetometer), and its mean
//! not drifting from one window to the next ([`DRIFT_FACTOR`]), the gyroscope
//! steady, the magnetometer the same at both ends of the rest; and once a first gyroscope bias is known (the median of the candidate rests),
//! turning slower than [`MAX_RATE_DEG_S`]. The thresholds come from the capture's own noise:
//! [`NOISE_QUANTILE`] of the windows' spreads (the quietest windows: rests, if at least that
//! share of the capture is resting) times [`NOISE_FACTOR`].

use super::Recording;
use nalgebra::Vector3;

/// Window length, seconds.
pub const WINDOW_S: f64 = 0.5;
/// Windows in a row that make a rest (1 s).
pub const MIN_WINDOWS: usize = 2;
/// The quantile of the windows' spreads taken as the sensor's noise.
pub const NOISE_QUANTILE: f64 = 0.1;
/// A still window's spread is at most this many times the noise.
pub const NOISE_FACTOR: f64 = 2.5;
/// The magnetometer's mean moves from one window to the next by at most this many times its
/// standard error (√(2/n) of the noise) in a rest: a turn of ~2°/s is seen.
pub const DRIFT_FACTOR: f64 = 4.0;
/// A rest turns slower than this once the first bias is removed, °/s.
pub const MAX_RATE_DEG_S: f64 = 0.5;

/// What the rest detection found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rests {
    /// Mean accelerometer reading of each rest used, m/s² (sensor axes).
    pub poses: Vec<Vector3<f64>>,
    /// Mean gyroscope reading of each rest used, rad/s (empty without a gyroscope).
    pub gyros: Vec<Vector3<f64>>,
    /// Spans that were still by the spreads alone.
    pub found: usize,
    /// Of those, turning: the magnetometer moved between the span's ends, or the rate is
    /// above [`MAX_RATE_DEG_S`] once the first bias is removed.
    pub turning: usize,
    /// The noise measured (per-axis standard deviation of the quietest windows) and the
    /// thresholds derived: accelerometer m/s², magnetometer µT, gyroscope rad/s.
    pub acc_noise: f64,
    pub acc_threshold: f64,
    pub mag_threshold: f64,
    pub gyro_threshold: Option<f64>,
}

impl Rests {
    /// Rests used.
    pub fn used(&self) -> usize {
        self.poses.len()
    }

    /// The largest angle between a rest's gravity and the sensor's z axis, degrees (how far
    /// the device was tilted from lying flat).
    pub fn max_tilt_deg(&self) -> f64 {
        self.poses
            .iter()
            .filter_map(|a| a.try_normalize(1e-9))
            .map(|u| u.z.abs().clamp(0.0, 1.0).acos().to_degrees())
            .fold(0.0, f64::max)
    }
}

/// One window's statistics.
struct Window {
    range: std::ops::Range<usize>,
    acc_mean: Vector3<f64>,
    acc_spread: f64,
    mag_mean: Vector3<f64>,
    mag_spread: f64,
    gyro_mean: Vector3<f64>,
    gyro_spread: f64,
}

/// The largest per-axis standard deviation of `v`, and its mean.
fn spread(v: &[Vector3<f64>]) -> (Vector3<f64>, f64) {
    let m = v.len().max(1) as f64;
    let mean = v.iter().sum::<Vector3<f64>>() / m;
    let var = v
        .iter()
        .map(|x| (x - mean).component_mul(&(x - mean)))
        .sum::<Vector3<f64>>()
        / m;
    (mean, var.max().sqrt())
}

fn windows(rec: &Recording) -> Vec<Window> {
    let n = rec.t.len();
    let gyro = rec.gyro.len() == n;
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j < n && rec.t[j] - rec.t[i] < WINDOW_S {
            j += 1;
        }
        if j - i >= 3 {
            let (acc_mean, acc_spread) = spread(&rec.acc[i..j]);
            let (mag_mean, mag_spread) = spread(&rec.mag[i..j]);
            let (gyro_mean, gyro_spread) = if gyro {
                spread(&rec.gyro[i..j])
            } else {
                (Vector3::zeros(), 0.0)
            };
            out.push(Window {
                range: i..j,
                acc_mean,
                acc_spread,
                mag_mean,
                mag_spread,
                gyro_mean,
                gyro_spread,
            });
        }
        i = j.max(i + 1);
    }
    out
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Finds the rests of `rec`.
pub fn rests(rec: &Recording) -> Rests {
    let w = windows(rec);
    let gyro = !rec.gyro.is_empty() && rec.gyro.len() == rec.t.len();
    let threshold =
        |f: fn(&Window) -> f64| NOISE_FACTOR * quantile(w.iter().map(f).collect(), NOISE_QUANTILE);
    let acc_noise = quantile(w.iter().map(|x| x.acc_spread).collect(), NOISE_QUANTILE);
    let acc_threshold = threshold(|x| x.acc_spread).max(1e-6);
    let mag_threshold = threshold(|x| x.mag_spread).max(1e-6);
    let gyro_threshold = gyro.then(|| threshold(|x| x.gyro_spread).max(1e-9));
    let still = |x: &Window| {
        x.acc_spread <= acc_threshold
            && x.mag_spread <= mag_threshold
            && gyro_threshold.is_none_or(|g| x.gyro_spread <= g)
    };
    // A turn too slow to spread a window's readings beyond the noise still moves the
    // magnetometer's mean from one window to the next (a window's mean is √n times quieter).
    let mag_noise = mag_threshold / NOISE_FACTOR;
    let drifts = |a: &Window, b: &Window| {
        let n = a.range.len().min(b.range.len()).max(1) as f64;
        (a.mag_mean - b.mag_mean).amax() > DRIFT_FACTOR * mag_noise * (2.0 / n).sqrt() + 1e-9
    };
    // Runs of still windows, none drifting from the one before.
    let mut spans: Vec<std::ops::Range<usize>> = Vec::new();
    let mut k = 0;
    while k < w.len() {
        if !still(&w[k]) {
            k += 1;
            continue;
        }
        let start = k;
        while k < w.len()
            && still(&w[k])
            && (k == start || (w[k].range.start == w[k - 1].range.end && !drifts(&w[k - 1], &w[k])))
        {
            k += 1;
        }
        if k - start >= MIN_WINDOWS {
            spans.push(start..k);
        }
    }
    let mean = |span: &std::ops::Range<usize>, f: fn(&Window) -> Vector3<f64>| {
        let (mut s, mut m) = (Vector3::zeros(), 0usize);
        for x in &w[span.clone()] {
            let c = x.range.len();
            s += f(x) * c as f64;
            m += c;
        }
        s / m.max(1) as f64
    };
    let mut out = Rests {
        found: spans.len(),
        acc_noise,
        acc_threshold,
        mag_threshold,
        gyro_threshold,
        ..Default::default()
    };
    // A turn slow enough to pass window by window still moves the magnetometer between the
    // span's ends.
    spans.retain(|span| {
        let turning = drifts(&w[span.start], &w[span.end - 1]);
        out.turning += usize::from(turning);
        !turning
    });
    let gyro_means: Vec<Vector3<f64>> = spans.iter().map(|s| mean(s, |x| x.gyro_mean)).collect();
    // The first bias: the median of the candidates, axis by axis (most spans are real rests).
    let bias = Vector3::from_fn(|i, _| quantile(gyro_means.iter().map(|g| g[i]).collect(), 0.5));
    for (span, g) in spans.iter().zip(&gyro_means) {
        if gyro && (g - bias).norm() > MAX_RATE_DEG_S.to_radians() {
            out.turning += 1;
            continue;
        }
        out.poses.push(mean(span, |x| x.acc_mean));
        if gyro {
            out.gyros.push(*g);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::rng::Rng;
    use nalgebra::UnitQuaternion;

    /// Flat on a table at 100 Hz in the magnetic `field`: rests, and every third segment a
    /// turn about the vertical at `rate` °/s, each segment after a shake.
    fn table(rate: f64, field: Vector3<f64>, segments: usize) -> Recording {
        let mut rng = Rng::new(3);
        let bias = Vector3::new(0.002, -0.003, 0.001);
        let mut rec = Recording::default();
        let (mut t, mut yaw) = (0.0, 0.0f64);
        for s in 0..segments {
            let turning = s % 3 == 2;
            for _ in 0..50 {
                t += 0.01;
                rec.t.push(t);
                rec.acc.push(Vector3::new(0.0, 0.0, 9.81) + rng.vec3(2.0));
                rec.mag.push(field + rng.vec3(5.0));
                rec.gyro.push(rng.vec3(1.0));
            }
            for _ in 0..300 {
                t += 0.01;
                let w = if turning { rate.to_radians() } else { 0.0 };
                yaw += w * 0.01;
                let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
                rec.t.push(t);
                rec.acc.push(Vector3::new(0.0, 0.0, 9.81) + rng.vec3(0.01));
                rec.mag.push(q.inverse() * field + rng.vec3(0.2));
                rec.gyro
                    .push(Vector3::new(0.0, 0.0, w) + bias + rng.vec3(0.002));
            }
        }
        rec
    }

    const FIELD: Vector3<f64> = Vector3::new(0.0, 20.0, -43.0);

    #[test]
    fn slow_turns_are_refused_by_the_magnetometer_or_by_their_rate() {
        let truth = Vector3::new(0.002, -0.003, 0.001);
        // 20°/s and 0.8°/s: the magnetometer moves (within a window, or between a span's
        // ends: ~0.14 µT a window at 0.8°/s, 0.8 µT over the span).
        for rate in [20.0, 0.8] {
            let r = rests(&table(rate, FIELD, 12));
            assert_eq!(r.used(), 8, "{rate}°/s: {r:?}");
            let bias = r.gyros.iter().sum::<Vector3<f64>>() / r.gyros.len() as f64;
            assert!((bias - truth).norm() < 1e-4, "{rate}°/s: {bias}");
        }
        // Where the field is vertical a turn about the vertical leaves the magnetometer as it
        // is: the gyroscope's rate, its first bias (the candidates' median) removed, refuses it.
        let r = rests(&table(2.0, Vector3::new(0.0, 0.0, -47.0), 12));
        assert_eq!((r.found, r.used(), r.turning), (12, 8, 4), "{r:?}");
        let bias = r.gyros.iter().sum::<Vector3<f64>>() / r.gyros.len() as f64;
        assert!((bias - truth).norm() < 1e-4, "{bias}");
    }

    #[test]
    fn the_threshold_is_the_noise_of_the_quietest_windows() {
        let r = rests(&table(20.0, FIELD, 12));
        assert!((r.acc_noise - 0.01).abs() < 0.002, "{}", r.acc_noise);
        assert!((r.acc_threshold - NOISE_FACTOR * r.acc_noise).abs() < 1e-12);
        assert!(r.max_tilt_deg() < 1.0);
    }
}
