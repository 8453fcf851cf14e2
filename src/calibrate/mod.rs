//! `sfs calibrate CAPTURE`: fits the magnetometer's hard and soft iron ([`ellipsoid`]) from a
//! capture of the device turned through many orientations, the accelerometer's bias and scale
//! ([`accel`]) from its static poses, and the gyroscope's bias from the same rests, then prints
//! the fit quality and a `[calibration]` snippet for the configuration.
//!
//! The fits work in sensor axes on values scaled by the HELLO's LSB sizes, before any axis
//! mapping, exactly where the configured calibration is applied.

pub mod accel;
pub mod ellipsoid;

use device_protocol::{Decoder, Event, Packet};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::Path;

/// Raw sensor values of a capture, scaled to SI units, sensor axes.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    pub t: Vec<f64>,
    pub acc: Vec<Vector3<f64>>,
    pub mag: Vec<Vector3<f64>>,
    /// Empty without a gyroscope.
    pub gyro: Vec<Vector3<f64>>,
}

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("{}: no HELLO in the capture, so no sample can be scaled", path.display())]
    NoHello { path: std::path::PathBuf },
}

/// Extracts the samples of `sensor` (arrays; ignored for other kinds) from capture bytes.
pub fn recording(bytes: &[u8], sensor: u16) -> Option<Recording> {
    let mut dec = Decoder::new();
    let mut rec = Recording::default();
    let mut scales: Option<(f64, f64, f64)> = None;
    let mut clock = crate::clock::Clock::default();
    let v = |r: [i16; 3], s: f64| Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64) * s;
    for ev in dec.feed(bytes) {
        match ev {
            Event::DeviceReboot => clock.restart(),
            Event::Packet { packet, .. } => match packet {
                Packet::Hello(h) => {
                    scales = Some((h.acc_scale as f64, h.gyro_scale as f64, h.mag_scale as f64))
                }
                Packet::RiderSample(s) => {
                    let Some((sa, _, sm)) = scales else { continue };
                    rec.t.push(clock.advance(s.t_us));
                    rec.acc.push(v(s.acc, sa));
                    rec.mag.push(v(s.mag, sm));
                }
                Packet::PhoneSample(s) => {
                    let Some((sa, sg, sm)) = scales else { continue };
                    rec.t.push(clock.advance(s.t_us));
                    rec.acc.push(v(s.acc, sa));
                    rec.mag.push(v(s.mag, sm));
                    rec.gyro.push(v(s.gyro, sg));
                }
                Packet::ArraySample(s) if s.sensor == sensor => {
                    let Some((sa, _, sm)) = scales else { continue };
                    rec.t.push(clock.advance(s.t_us));
                    rec.acc.push(v(s.acc, sa));
                    rec.mag.push(v(s.mag, sm));
                }
                _ => {}
            },
            _ => {}
        }
    }
    scales.map(|_| rec)
}

/// Mean readings of the static poses: windows of `window` seconds whose accelerometer varies
/// by less than `acc_std` (m/s², per axis) and, with a gyroscope, turns slower than 2°/s;
/// consecutive static windows form one pose. Returns `(acc means, gyro means)`.
pub fn static_poses(
    rec: &Recording,
    window: f64,
    acc_std: f64,
) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let n = rec.t.len();
    let mut poses = Vec::new();
    let mut gyros = Vec::new();
    let (mut sum_a, mut sum_g, mut count) = (Vector3::zeros(), Vector3::zeros(), 0usize);
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j < n && rec.t[j] - rec.t[i] < window {
            j += 1;
        }
        if j - i < 3 {
            i = j.max(i + 1);
            continue;
        }
        let m = (j - i) as f64;
        let mean = rec.acc[i..j].iter().sum::<Vector3<f64>>() / m;
        let var = rec.acc[i..j]
            .iter()
            .map(|a| (a - mean).component_mul(&(a - mean)))
            .sum::<Vector3<f64>>()
            / m;
        let gmean = if rec.gyro.is_empty() {
            Vector3::zeros()
        } else {
            rec.gyro[i..j].iter().sum::<Vector3<f64>>() / m
        };
        let gyro_still = rec.gyro.is_empty()
            || rec.gyro[i..j]
                .iter()
                .all(|g| (g - gmean).norm() < 2f64.to_radians());
        let still = var.iter().all(|v| v.sqrt() < acc_std) && gyro_still;
        if still {
            sum_a += mean * m;
            sum_g += gmean * m;
            count += j - i;
        } else if count > 0 {
            poses.push(sum_a / count as f64);
            gyros.push(sum_g / count as f64);
            (sum_a, sum_g, count) = (Vector3::zeros(), Vector3::zeros(), 0);
        }
        i = j;
    }
    if count > 0 {
        poses.push(sum_a / count as f64);
        gyros.push(sum_g / count as f64);
    }
    (poses, gyros)
}

/// What `sfs calibrate` found.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub samples: usize,
    pub mag: Result<ellipsoid::EllipsoidFit, ellipsoid::FitError>,
    pub acc: Result<accel::AccelFit, accel::AccelFitError>,
    /// Mean gyroscope reading over the static poses (phone).
    pub gyro_bias: Option<Vector3<f64>>,
}

impl Calibration {
    /// Whether at least one fit succeeded.
    pub fn any(&self) -> bool {
        self.mag.is_ok() || self.acc.is_ok() || self.gyro_bias.is_some()
    }

    /// The human summary and the configuration snippet.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let v = |x: &Vector3<f64>| format!("[{:.6}, {:.6}, {:.6}]", x.x, x.y, x.z);
        let _ = writeln!(s, "# sfs calibrate: {} samples", self.samples);
        let _ = writeln!(s, "[calibration]");
        match &self.mag {
            Ok(m) => {
                let _ = writeln!(
                    s,
                    "# magnetometer: field {:.2} µT, residual {:.2} %, {:.0} % of directions covered{}",
                    m.radius,
                    100.0 * m.rel_residual,
                    100.0 * m.coverage,
                    if m.coverage < 0.6 { " (LOW: turn the device through more orientations)" } else { "" }
                );
                let w = &m.soft_iron;
                let _ = writeln!(s, "mag_hard_iron = {}", v(&m.hard_iron));
                let _ = writeln!(
                    s,
                    "mag_soft_iron = [[{:.6}, {:.6}, {:.6}], [{:.6}, {:.6}, {:.6}], [{:.6}, {:.6}, {:.6}]]",
                    w[(0, 0)], w[(0, 1)], w[(0, 2)], w[(1, 0)], w[(1, 1)], w[(1, 2)], w[(2, 0)], w[(2, 1)], w[(2, 2)]
                );
            }
            Err(e) => {
                let _ = writeln!(s, "# magnetometer: not fitted: {e}");
            }
        }
        match &self.acc {
            Ok(a) => {
                let _ = writeln!(
                    s,
                    "# accelerometer: {} static poses, residual {:.4} m/s²",
                    a.poses, a.residual
                );
                let _ = writeln!(s, "acc_bias = {}", v(&a.bias));
                let _ = writeln!(s, "acc_scale = {}", v(&a.scale));
            }
            Err(e) => {
                let _ = writeln!(s, "# accelerometer: not fitted: {e}");
            }
        }
        if let Some(g) = &self.gyro_bias {
            let _ = writeln!(s, "# gyroscope: mean over the static poses");
            let _ = writeln!(s, "gyro_bias = {}", v(g));
        }
        s
    }
}

/// Calibrates from a recording.
pub fn calibrate(rec: &Recording) -> Calibration {
    // The ellipsoid fit's cost grows with the samples; 20 000 spread over the capture suffice.
    let step = (rec.mag.len() / 20_000).max(1);
    let mags: Vec<Vector3<f64>> = rec.mag.iter().step_by(step).copied().collect();
    let (poses, gyros) = static_poses(rec, 0.5, 0.05);
    let gyro_bias = (!rec.gyro.is_empty() && !gyros.is_empty())
        .then(|| gyros.iter().sum::<Vector3<f64>>() / gyros.len() as f64);
    Calibration {
        samples: rec.t.len(),
        mag: ellipsoid::fit(&mags),
        acc: accel::fit(&poses),
        gyro_bias,
    }
}

/// Reads and calibrates a capture file.
pub fn calibrate_file(path: &Path, sensor: u16) -> Result<Calibration, CalibrateError> {
    let bytes = std::fs::read(path).map_err(|source| CalibrateError::Read {
        path: path.to_owned(),
        source,
    })?;
    let rec = recording(&bytes, sensor).ok_or_else(|| CalibrateError::NoHello {
        path: path.to_owned(),
    })?;
    Ok(calibrate(&rec))
}
