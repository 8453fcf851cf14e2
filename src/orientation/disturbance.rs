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
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            acc_tol: 0.6,
            mag_norm_rel: 0.08,
            mag_dip_deg: 4.0,
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
