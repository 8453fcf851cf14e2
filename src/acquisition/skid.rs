//! Wheel skids (Morphorider): stretches where the wheel turned less than the device travelled,
//! found where the wheel's speed drops and comes back while the accelerometer says the device
//! rolled on, and filled with the speed on either side.
//!
//! On a slippery patch, or lifted by a bump, the wheel stops turning while the hand rolls the
//! device on: in the independent simulator's rough captures it stands still for 0.3–0.5 s at
//! 60–90 mm/s, and the segment reads 16–29 mm short (issue 33). The wheel alone cannot tell
//! this from the hand pausing. The accelerometer can, two ways:
//! - on a curved surface, rolling turns the device, and gravity's direction in the device
//!   turns with it (on lilium 6–10 rad per metre); a paused device does not turn. Across a
//!   skid it turns as far as rolling on at the flanks' speed would turn it; across a pause,
//!   only as far as the wheel's own distance would.
//! - on a flat stretch gravity's direction stays put, and so does its share along the travel
//!   axis (body x, the tangent T): a hand that slows the device down then shows as a pulse
//!   there, whose integral over the transition is the change of speed. A skid has none.
//!
//! ## The test
//! The wheel's speed `v` by central differences over ±[`SPEED_HALF_WINDOW`]. A *dip* is a run
//! of samples slower than [`DIP`] times the speed before it (the median over [`FLANK`] s, up to
//! [`FLANK_GAP`] s before the run), at most [`MAX_SKID`] s long, with the speed after it (the
//! same flank) within a factor [`AGREE`] of the speed before and both at least [`MIN_SPEED`],
//! and no tag typed within a flank of it: the device was rolling on both sides.
//!
//! *Turning*: gravity's direction (mean over [`TURN_WINDOW`]) turns per metre of wheel on each
//! flank; across the dip (between the windows a gap away from it) it turned by an angle nearer
//! to that rate times the distance rolled on at the flanks' mean speed (a skid) or to that
//! rate times the wheel's distance (a pause). Decided so where the two predictions differ by
//! [`SIGNIFICANT`] times the angle's noise (from the samples' spread); else:
//!
//! *Change of speed*: at each of the dip's two edges, `∫ (f_x − baseline) dt` over
//! ±[`TRANSITION`] s (the baseline: the line through `f_x`'s means over the two flanks) against
//! the wheel's change of speed there; a skid when the accelerometer felt less than [`FELT`] of
//! it at both edges, each change being at least [`SIGNIFICANT`] times the integral's noise.
//!
//! ## The fill
//! Over the dip widened by the speed's window, the wheel's speed becomes the straight line from
//! the speed before to the speed after; every later sample moves on by what that added.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::acquisition::skid::fill_skids;
//! // 4 s at 100 Hz rolling at 80 mm/s on a level plane (the accelerometer reads gravity
//! // only: no change of speed), the wheel still for 0.3 s from t = 2 s: 24 mm lost.
//! let t: Vec<f64> = (0..400).map(|i| i as f64 * 0.01).collect();
//! let mut wheel: Vec<f64> = t
//!     .iter()
//!     .map(|&t| 0.08 * (t - (t - 2.0).clamp(0.0, 0.3)))
//!     .collect();
//! // A little noise, as any accelerometer has.
//! let acc: Vec<Vector3<f64>> = (0..400)
//!     .map(|i| Vector3::new(0.02 * ((i * 7919) % 13) as f64 - 0.12, 0.0, 9.81))
//!     .collect();
//! let skids = fill_skids(&t, &mut wheel, &acc, &[0.0, 3.99]);
//! assert_eq!(skids.len(), 1);
//! assert!((skids[0].added_m - 0.024).abs() < 0.001);
//! assert!((wheel[399] - 0.08 * 3.99).abs() < 0.001);
//! ```

use super::speed::{median, sd_of_differences};
use nalgebra::Vector3;

/// Half-width of the central difference that gives the wheel's speed, s.
pub const SPEED_HALF_WINDOW: f64 = 0.03;
/// A dip is slower than this fraction of the speed before it.
pub const DIP: f64 = 0.5;
/// Length of the flanks whose median speed, mean `f_x` and turning a dip is compared with, s.
pub const FLANK: f64 = 0.4;
/// Gap between a dip's edge and its flank (the transition itself), s.
pub const FLANK_GAP: f64 = 0.1;
/// The longest skid, s: a longer dip is the operator pausing.
pub const MAX_SKID: f64 = 1.5;
/// The speeds before and after a skid agree within this factor.
pub const AGREE: f64 = 2.0;
/// Both flanks roll at least this fast, m/s.
pub const MIN_SPEED: f64 = 0.01;
/// Half-width of the window over which the accelerometer's change of speed is summed at
/// each edge of a dip, s.
pub const TRANSITION: f64 = 0.2;
/// The accelerometer felt less than this share of the wheel's change of speed.
pub const FELT: f64 = 0.5;
/// A test decides where what it compares differs by at least this many times its noise.
pub const SIGNIFICANT: f64 = 4.0;
/// Width of the windows whose mean gravity direction is compared, s.
pub const TURN_WINDOW: f64 = 0.1;

/// A skid found and filled.
#[derive(Debug, Clone, PartialEq)]
pub struct Skid {
    /// Start of the filled stretch (sample time), s.
    pub t: f64,
    /// Its duration, s.
    pub duration_s: f64,
    /// Distance added, m.
    pub added_m: f64,
}

/// Sample indices with `t` in `[a, b)` (`t` increasing).
fn span(t: &[f64], a: f64, b: f64) -> std::ops::Range<usize> {
    t.partition_point(|&x| x < a)..t.partition_point(|&x| x < b)
}

/// The median of `v` over the samples with `t` in `[a, b)`, if it has at least three.
fn median_over(t: &[f64], v: &[f64], a: f64, b: f64) -> Option<f64> {
    let r = span(t, a, b);
    (r.len() >= 3).then(|| median(v[r].to_vec())).flatten()
}

/// The mean of `v` over the samples with `t` in `[a, b)`, with its mid time.
fn mean_over(t: &[f64], v: &[f64], a: f64, b: f64) -> Option<(f64, f64)> {
    let r = span(t, a, b);
    (r.len() >= 3).then(|| {
        let n = r.len() as f64;
        (
            (t[r.start] + t[r.end - 1]) / 2.0,
            v[r].iter().sum::<f64>() / n,
        )
    })
}

/// The wheel's speed at every sample, m/s (central differences over ±`SPEED_HALF_WINDOW`).
fn speeds(t: &[f64], wheel: &[f64]) -> Vec<f64> {
    (0..t.len())
        .map(|i| {
            let r = span(t, t[i] - SPEED_HALF_WINDOW, t[i] + SPEED_HALF_WINDOW + 1e-9);
            let (a, b) = (r.start.min(i), (r.end.max(i + 1) - 1).max(i));
            let dt = t[b] - t[a];
            if dt > 0.0 {
                (wheel[b] - wheel[a]) / dt
            } else {
                0.0
            }
        })
        .collect()
}

/// What the tests read of one curve's samples.
struct Signals<'a> {
    t: &'a [f64],
    /// The wheel's speed, m/s.
    v: Vec<f64>,
    /// The accelerometer along the travel axis, m/s².
    fx: Vec<f64>,
    /// Gravity's direction in the device (the accelerometer's, unit).
    up: Vec<Vector3<f64>>,
    /// The median sample interval, s.
    dt: f64,
    /// The noise of one sample of `fx` (m/s²) and of `up` (rad), from their first
    /// differences (robust to pulses and turns: the median).
    fx_noise: f64,
    up_noise: f64,
}

impl Signals<'_> {
    /// The accelerometer's change of speed over `[a, b)` against the baseline through
    /// `before` and `after` (`(time, mean f_x)`), m/s, and its noise.
    fn felt(&self, a: f64, b: f64, before: (f64, f64), after: (f64, f64)) -> (f64, f64) {
        let t = self.t;
        let slope = (after.1 - before.1) / (after.0 - before.0).max(1e-9);
        let r = span(t, a, b);
        let noise = self.fx_noise * (r.len() as f64).sqrt() * self.dt;
        let sum = r
            .map(|i| (self.fx[i] - (before.1 + slope * (t[i] - before.0))) * self.dt)
            .sum();
        (sum, noise)
    }

    /// The mean of `up` over the samples with `t` in `[a, b)`, normalised, with the count.
    fn direction(&self, a: f64, b: f64) -> Option<(Vector3<f64>, usize)> {
        let r = span(self.t, a, b);
        let n = r.len();
        (n >= 3)
            .then(|| self.up[r].iter().sum::<Vector3<f64>>().try_normalize(1e-9))
            .flatten()
            .map(|u| (u, n))
    }

    /// Whether the device kept turning through the dip `[a, b)` as its rolling turns it on
    /// the flanks (`wheel`: the wheel's distance; `missing`: what rolling on would add to it,
    /// m): `Some(true)` when gravity's direction turned across the dip by nearer what rolling
    /// on would turn it than what the wheel's own distance would, `Some(false)` for nearer the
    /// wheel's; `None` when the two differ by less than [`SIGNIFICANT`] times their noise (the
    /// angles' and the flanks' rate's: a flat stretch, or one whose rate is not known well).
    fn kept_turning(&self, wheel: &[f64], a: f64, b: f64, missing: f64) -> Option<bool> {
        let (t, w) = (self.t, TURN_WINDOW);
        let at = |x: f64| wheel[t.partition_point(|&y| y < x).min(t.len() - 1)];
        // The noise of the angle between two window means of `n0` and `n1` samples.
        let noise =
            |n0: usize, n1: usize| self.up_noise * (1.0 / n0 as f64 + 1.0 / n1 as f64).sqrt();
        // Turning per metre rolled over a flank `[x0, x1)` and its noise, rad/m.
        let rate = |x0: f64, x1: f64| -> Option<(f64, f64)> {
            let ((u0, n0), (u1, n1)) = (self.direction(x0, x0 + w)?, self.direction(x1 - w, x1)?);
            let dist = at(x1 - w / 2.0) - at(x0 + w / 2.0);
            (dist > 0.0).then(|| (u0.angle(&u1) / dist, noise(n0, n1) / dist))
        };
        let (r0, e0) = rate(a - FLANK_GAP - FLANK, a - FLANK_GAP)?;
        let (r1, e1) = rate(b + FLANK_GAP, b + FLANK_GAP + FLANK)?;
        let (per_m, per_m_noise) = ((r0 + r1) / 2.0, (e0 * e0 + e1 * e1).sqrt() / 2.0);
        // Across the dip: between the windows a gap away from it on either side.
        let (x0, x1) = (a - FLANK_GAP - w / 2.0, b + FLANK_GAP + w / 2.0);
        let (u0, n0) = self.direction(x0 - w / 2.0, x0 + w / 2.0)?;
        let (u1, n1) = self.direction(x1 - w / 2.0, x1 + w / 2.0)?;
        let turned = u0.angle(&u1);
        let measured = at(x1) - at(x0);
        let (paused, rolled) = (per_m * measured, per_m * (measured + missing));
        let spread = noise(n0, n1).hypot((measured + missing) * per_m_noise);
        ((rolled - paused) >= SIGNIFICANT * spread)
            .then(|| (turned - rolled).abs() < (turned - paused).abs())
    }
}

/// The noise of one sample of a signal whose first differences are `d` (absolute values; a
/// difference has twice the variance).
fn noise_of(d: impl Iterator<Item = f64>) -> f64 {
    sd_of_differences(d) / std::f64::consts::SQRT_2
}

/// Finds the skids of one curve's samples and fills them (see the module docs): `t` sample
/// times (s, increasing), `wheel` the wheel's distance (m, changed in place), `acc` the
/// accelerometer in the device's frame `[T B N]` (m/s², specific force: `g` up at rest),
/// `typed` the times of the curve's tags (the operator stands there: a dip within a flank of
/// one is a stop, not a skid). Returns the skids filled, in time order.
pub fn fill_skids(t: &[f64], wheel: &mut [f64], acc: &[Vector3<f64>], typed: &[f64]) -> Vec<Skid> {
    let n = t.len().min(wheel.len()).min(acc.len());
    // The windows below search the times: they must be finite and in order (session times
    // are; anything else is not searched).
    if n < 10 || !t[..n].windows(2).all(|w| w[0].is_finite() && w[0] <= w[1]) {
        return Vec::new();
    }
    let t = &t[..n];
    let finite = |a: &Vector3<f64>| a.iter().all(|x| x.is_finite());
    let up: Vec<Vector3<f64>> = acc[..n]
        .iter()
        .map(|a| {
            a.try_normalize(1e-9)
                .filter(finite)
                .unwrap_or_else(Vector3::z)
        })
        .collect();
    let fx: Vec<f64> = acc[..n]
        .iter()
        .map(|a| if a.x.is_finite() { a.x } else { 0.0 })
        .collect();
    let sig = Signals {
        t,
        v: speeds(t, &wheel[..n]),
        fx_noise: noise_of(fx.windows(2).map(|w| (w[1] - w[0]).abs())),
        up_noise: noise_of(up.windows(2).map(|w| w[0].angle(&w[1]))),
        fx,
        up,
        dt: median(t.windows(2).map(|w| w[1] - w[0]).collect()).unwrap_or(0.01),
    };
    let v = &sig.v;
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        let Some(v_before) = median_over(t, v, t[i] - FLANK_GAP - FLANK, t[i] - FLANK_GAP)
            .filter(|&vb| vb >= MIN_SPEED && v[i] < DIP * vb)
        else {
            i += 1;
            continue;
        };
        // The run slower than DIP × the speed before it.
        let mut j = i;
        while j < n && v[j] < DIP * v_before && t[j] - t[i] <= MAX_SKID {
            j += 1;
        }
        let next = j.max(i + 1);
        if let Some(v_after) = rolled_on(&sig, typed, i, j, v_before) {
            let (a, b) = (t[i], t[j]);
            let v_dip = v[i..j].iter().sum::<f64>() / (j - i) as f64;
            let missing = ((v_before + v_after) / 2.0 - v_dip) * (b - a);
            let skid = match sig.kept_turning(wheel, a, b, missing) {
                Some(turning) => turning,
                None => unfelt(&sig, a, b, [v_before - v_dip, v_after - v_dip]),
            };
            if skid {
                out.push(fill(t, wheel, i, j, v_before, v_after));
            }
        }
        i = next;
    }
    out
}

/// The speed after the dip `[i, j)` where the device was rolling on both sides of it
/// (`v_before`): a dip at most [`MAX_SKID`] long, before the curve's end, with no tag typed
/// within a flank of it, and the two speeds within a factor [`AGREE`].
fn rolled_on(sig: &Signals, typed: &[f64], i: usize, j: usize, v_before: f64) -> Option<f64> {
    let t = sig.t;
    let b = *t.get(j)?;
    let a = t[i];
    if b - a > MAX_SKID
        || typed
            .iter()
            .any(|&k| k > a - FLANK_GAP - FLANK && k < b + FLANK_GAP + FLANK)
    {
        return None;
    }
    median_over(t, &sig.v, b + FLANK_GAP, b + FLANK_GAP + FLANK)
        .filter(|&va| va >= MIN_SPEED && va.max(v_before) <= AGREE * va.min(v_before))
}

/// Whether the accelerometer felt less than [`FELT`] of the wheel's change of speed at both
/// edges of the dip `[a, b)` (`drops`: the speed lost at `a`, gained back at `b`), each change
/// significant.
fn unfelt(sig: &Signals, a: f64, b: f64, drops: [f64; 2]) -> bool {
    let t = sig.t;
    let (Some(before), Some(after)) = (
        mean_over(t, &sig.fx, a - FLANK_GAP - FLANK, a - FLANK_GAP),
        mean_over(t, &sig.fx, b + FLANK_GAP, b + FLANK_GAP + FLANK),
    ) else {
        return false;
    };
    [(a, -drops[0]), (b, drops[1])]
        .iter()
        .all(|&(edge, change)| {
            let (f, noise) = sig.felt(edge - TRANSITION, edge + TRANSITION, before, after);
            change.abs() >= SIGNIFICANT * noise && f * change.signum() < FELT * change.abs()
        })
}

/// Fills the dip `[i, j)` widened by the speed's window: the speed from `v0` to `v1` in a
/// straight line; later samples move on by what it added.
fn fill(t: &[f64], wheel: &mut [f64], i: usize, j: usize, v0: f64, v1: f64) -> Skid {
    let n = t.len();
    let lo = t
        .partition_point(|&x| x < t[i] - SPEED_HALF_WINDOW)
        .min(i)
        .saturating_sub(1);
    let hi = t
        .partition_point(|&x| x <= t[j.min(n - 1)] + SPEED_HALF_WINDOW)
        .min(n - 1);
    let (ta, tb) = (t[lo], t[hi]);
    let mut filled = wheel[lo];
    let mut added = 0.0;
    for k in lo + 1..=hi {
        let mid = (t[k] + t[k - 1]) / 2.0;
        let v = v0 + (v1 - v0) * (mid - ta) / (tb - ta).max(1e-9);
        filled += v * (t[k] - t[k - 1]);
        added = filled - wheel[k];
        wheel[k] = filled;
    }
    for w in &mut wheel[hi + 1..] {
        *w += added;
    }
    Skid {
        t: ta,
        duration_s: tb - ta,
        added_m: added,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sfs_geometry::rng::Rng;

    const G: f64 = 9.81;

    /// A device rolled for 6 s at 100 Hz at 80 mm/s over a cylinder of radius `radius` (m;
    /// infinite: a level plane), its travel axis along the curvature (gravity's direction in
    /// the device turns by 1/radius per metre), with accelerometer noise 0.13 m/s². In the
    /// 0.3 s from t = 3 s the hand either pauses (`pause`: the device stops at once and sets
    /// off again, the accelerometer feeling both) or the wheel skids (the device rolls on,
    /// the wheel stands). Returns `(t, wheel, acc)`.
    fn rolled(radius: f64, pause: bool, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<Vector3<f64>>) {
        let mut rng = Rng::new(seed);
        let (v, dt, stop) = (0.08, 0.01, (3.0, 3.3));
        let t: Vec<f64> = (0..600).map(|i| i as f64 * dt).collect();
        // Distance actually travelled, and what the wheel reads.
        let travelled = |t: f64| match pause {
            true => v * (t - (t - stop.0).clamp(0.0, stop.1 - stop.0)),
            false => v * t,
        };
        let wheel = t
            .iter()
            .map(|&t| v * (t - (t - stop.0).clamp(0.0, stop.1 - stop.0)))
            .collect();
        let acc = t
            .iter()
            .map(|&t| {
                let pitch = travelled(t) / radius;
                // The change of speed of a pause, felt over 40 ms at each edge.
                let a = if !pause {
                    0.0
                } else if (stop.0 - 0.02..stop.0 + 0.02).contains(&t) {
                    -v / 0.04
                } else if (stop.1 - 0.02..stop.1 + 0.02).contains(&t) {
                    v / 0.04
                } else {
                    0.0
                };
                Vector3::new(G * pitch.sin() + a, 0.0, G * pitch.cos()) + rng.vec3(0.13)
            })
            .collect();
        (t, wheel, acc)
    }

    #[test]
    fn a_skid_is_filled_on_a_level_plane_and_on_a_curved_surface() {
        for radius in [f64::INFINITY, 0.3] {
            for seed in 1..=5 {
                let (t, mut wheel, acc) = rolled(radius, false, seed);
                let skids = fill_skids(&t, &mut wheel, &acc, &[0.0, 5.99]);
                assert_eq!(skids.len(), 1, "radius {radius}, seed {seed}: {skids:?}");
                assert!(
                    (skids[0].added_m - 0.024).abs() < 0.002,
                    "radius {radius}, seed {seed}: {:.1} mm added for 24",
                    skids[0].added_m * 1e3
                );
                assert!((wheel[599] - 0.08 * 5.99).abs() < 0.002);
            }
        }
    }

    #[test]
    fn a_pause_is_left_as_the_wheel_read_it() {
        for radius in [f64::INFINITY, 0.3] {
            for seed in 1..=5 {
                let (t, mut wheel, acc) = rolled(radius, true, seed);
                let read = wheel.clone();
                let skids = fill_skids(&t, &mut wheel, &acc, &[0.0, 5.99]);
                assert!(skids.is_empty(), "radius {radius}, seed {seed}: {skids:?}");
                assert_eq!(wheel, read);
            }
        }
    }

    /// The operator stands at a node to type its index: a dip there is never a skid.
    #[test]
    fn a_dip_where_a_tag_was_typed_is_a_stand() {
        let (t, mut wheel, acc) = rolled(f64::INFINITY, false, 1);
        assert!(fill_skids(&t, &mut wheel, &acc, &[0.0, 3.1, 5.99]).is_empty());
    }

    /// Samples with no usable accelerometer reading (zero, NaN), or times out of order,
    /// neither panic nor invent a skid.
    #[test]
    fn unusable_readings_invent_nothing() {
        let (t, mut wheel, mut acc) = rolled(f64::INFINITY, true, 2);
        for a in acc.iter_mut().step_by(7) {
            *a = Vector3::new(f64::NAN, 0.0, 0.0);
        }
        acc[100] = Vector3::zeros();
        assert!(fill_skids(&t, &mut wheel, &acc, &[0.0, 5.99]).is_empty());
        let mut bad_t = t.clone();
        bad_t[300] = f64::NAN;
        bad_t[301] = -1.0;
        assert!(fill_skids(&bad_t, &mut wheel, &acc, &[0.0, 5.99]).is_empty());
        assert!(fill_skids(&t[..5], &mut wheel[..5], &acc[..5], &[]).is_empty());
    }
}
