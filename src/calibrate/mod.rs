//! `sfs calibrate CAPTURE`: fits the magnetometer's hard and soft iron ([`ellipsoid`]) from a
//! capture of the device turned through many orientations, the accelerometer's bias and scale
//! ([`accel`]) from its rests ([`rests`]: still by thresholds from the capture's own noise,
//! not turning), and the gyroscope's bias from the same rests, then prints the fit quality,
//! the rests found and used, and a `[calibration]` snippet for the configuration, in which a
//! fit it calls poor is commented out with the reason.
//!
//! The fits work in sensor axes on values scaled by the HELLO's LSB sizes, before any axis
//! mapping, exactly where the configured calibration is applied.

pub mod accel;
pub mod ellipsoid;
pub mod rests;

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
    /// A sensor array's capture: the sensors it holds samples of (empty for other devices).
    pub array_sensors: std::collections::BTreeSet<u16>,
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
    #[error("{}: --sensor {sensor}: the capture has no sensor {sensor} ({})", path.display(), if have.is_empty() { "it is not a sensor array's: give no --sensor".to_string() } else { format!("its sensors: {}", have.iter().map(u16::to_string).collect::<Vec<_>>().join(", ")) })]
    NoSensor {
        path: std::path::PathBuf,
        sensor: u16,
        have: Vec<u16>,
    },
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
                Packet::ArraySample(s) => {
                    rec.array_sensors.insert(s.sensor);
                    let Some((sa, _, sm)) = scales.filter(|_| s.sensor == sensor) else {
                        continue;
                    };
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

/// A magnetometer fit covering less than this fraction of directions is not usable (the
/// device was turned about one axis, or too little: the sphere is not pinned down).
pub const MIN_COVERAGE: f64 = 0.6;

/// The field magnitudes a magnetometer fit may find, µT: the Earth's field is 25–65 µT
/// everywhere; outside these bounds the device was not turned (the fit is of noise) or the
/// scales are wrong.
pub const FIELD_RANGE_UT: (f64, f64) = (20.0, 70.0);

/// A magnetometer fit whose residual, relative to the field, is above this is not usable: the
/// samples do not lie on an ellipsoid (a fixed sensor's noise, or a field that changed while
/// the device was turned). A turned device, even a noisy phone's, stays under 5 %.
pub const MAX_MAG_RESIDUAL: f64 = 0.1;

/// The accelerometer's z bias and scale are poorly determined unless a rest tilted it past
/// this angle, degrees.
pub const MIN_TILT_DEG: f64 = 70.0;

/// What `sfs calibrate` found.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub samples: usize,
    /// The rests found and used (the accelerometer's poses, the gyroscope's bias).
    pub rests: rests::Rests,
    pub mag: Result<ellipsoid::EllipsoidFit, ellipsoid::FitError>,
    pub acc: Result<accel::AccelFit, accel::AccelFitError>,
    /// Mean gyroscope reading over the rests (phone).
    pub gyro_bias: Option<Vector3<f64>>,
}

impl Calibration {
    /// Why the magnetometer fit is not to be used, if it is not.
    pub fn mag_poor(&self) -> Option<String> {
        match &self.mag {
            Ok(m) if !(FIELD_RANGE_UT.0..=FIELD_RANGE_UT.1).contains(&m.radius) => Some(format!(
                "a field of {:.2} µT is not the Earth's ({:.0}–{:.0} µT): the device was not turned through orientations, or its scales are wrong",
                m.radius, FIELD_RANGE_UT.0, FIELD_RANGE_UT.1
            )),
            Ok(m) if m.rel_residual > MAX_MAG_RESIDUAL => Some(format!(
                "a residual of {:.1} % of the field (at most {:.0} %): the samples do not lie on an ellipsoid (a device that was not turned, or a field that changed meanwhile)",
                100.0 * m.rel_residual,
                100.0 * MAX_MAG_RESIDUAL
            )),
            Ok(m) if m.coverage < MIN_COVERAGE => Some(format!(
                "only {:.0} % of directions covered (at least {:.0} %): the device was turned about too few axes; turn it through every orientation",
                100.0 * m.coverage,
                100.0 * MIN_COVERAGE
            )),
            Ok(_) => None,
            Err(e) => Some(e.to_string()),
        }
    }

    /// Whether at least one fit is usable (printed as configuration, not as a comment).
    pub fn usable(&self) -> bool {
        self.mag_poor().is_none() || self.acc.is_ok() || self.gyro_bias.is_some()
    }

    /// The human summary and the configuration snippet: usable fits as keys, poor ones
    /// commented out with the reason.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let v = |x: &Vector3<f64>| format!("[{:.6}, {:.6}, {:.6}]", x.x, x.y, x.z);
        let r = &self.rests;
        let _ = writeln!(s, "# sfs calibrate: {} samples", self.samples);
        let _ = writeln!(
            s,
            "# rests: {} found, {} used{}; accelerometer noise {:.4} m/s² (still below {:.4}), magnetometer still below {:.3} µT{}",
            r.found,
            r.used(),
            if r.turning > 0 {
                format!(" ({} refused: turning)", r.turning)
            } else {
                String::new()
            },
            r.acc_noise,
            r.acc_threshold,
            r.mag_threshold,
            r.gyro_threshold
                .map(|g| format!(", gyroscope still below {:.3} °/s", g.to_degrees()))
                .unwrap_or_default()
        );
        let _ = writeln!(s, "[calibration]");
        match (&self.mag, self.mag_poor()) {
            (Ok(m), poor) => {
                let _ = writeln!(
                    s,
                    "# magnetometer: field {:.2} µT, residual {:.2} %, {:.0} % of directions covered",
                    m.radius,
                    100.0 * m.rel_residual,
                    100.0 * m.coverage,
                );
                let hash = match &poor {
                    Some(why) => {
                        let _ = writeln!(s, "# NOT USABLE, left commented out: {why}");
                        "# "
                    }
                    None => "",
                };
                let w = &m.soft_iron;
                let _ = writeln!(s, "{hash}mag_hard_iron = {}", v(&m.hard_iron));
                let _ = writeln!(
                    s,
                    "{hash}mag_soft_iron = [[{:.6}, {:.6}, {:.6}], [{:.6}, {:.6}, {:.6}], [{:.6}, {:.6}, {:.6}]]",
                    w[(0, 0)], w[(0, 1)], w[(0, 2)], w[(1, 0)], w[(1, 1)], w[(1, 2)], w[(2, 0)], w[(2, 1)], w[(2, 2)]
                );
            }
            (Err(e), _) => {
                let _ = writeln!(s, "# magnetometer: not fitted: {e}");
            }
        }
        match &self.acc {
            Ok(a) => {
                let _ = writeln!(
                    s,
                    "# accelerometer: {} rests, residual {:.4} m/s²",
                    a.poses, a.residual
                );
                tilt_warning(&mut s, r);
                let _ = writeln!(s, "acc_bias = {}", v(&a.bias));
                let _ = writeln!(s, "acc_scale = {}", v(&a.scale));
            }
            Err(e) => {
                let _ = writeln!(s, "# accelerometer: not fitted: {e}");
                tilt_warning(&mut s, r);
            }
        }
        match &self.gyro_bias {
            Some(g) => {
                let _ = writeln!(s, "# gyroscope: mean over the {} rests", r.used());
                let _ = writeln!(s, "gyro_bias = {}", v(g));
            }
            None if !r.gyros.is_empty() || r.gyro_threshold.is_some() => {
                let _ = writeln!(s, "# gyroscope: not fitted: no rest found");
            }
            None => {}
        }
        if !self.usable() {
            let _ = writeln!(
                s,
                "# nothing usable was fitted: calibrate again, resting the device still on each face and turning it through every orientation in between"
            );
        }
        s
    }
}

/// Warns when no rest tilted the device past [`MIN_TILT_DEG`] from lying flat.
fn tilt_warning(s: &mut String, r: &rests::Rests) {
    let tilt = r.max_tilt_deg();
    if r.used() > 0 && tilt < MIN_TILT_DEG {
        let _ = writeln!(
            s,
            "# WARNING: never tilted past {MIN_TILT_DEG:.0}° from lying flat (at most {tilt:.0}°): the accelerometer's z bias and scale are poorly determined; rest the device on its sides and ends too"
        );
    }
}

/// Calibrates from a recording.
pub fn calibrate(rec: &Recording) -> Calibration {
    // The ellipsoid fit's cost grows with the samples; 20 000 spread over the capture suffice.
    let step = (rec.mag.len() / 20_000).max(1);
    let mags: Vec<Vector3<f64>> = rec.mag.iter().step_by(step).copied().collect();
    let rests = rests::rests(rec);
    let gyro_bias = (!rests.gyros.is_empty())
        .then(|| rests.gyros.iter().sum::<Vector3<f64>>() / rests.gyros.len() as f64);
    Calibration {
        samples: rec.t.len(),
        mag: ellipsoid::fit(&mags),
        acc: accel::fit(&rests.poses),
        gyro_bias,
        rests,
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
    let is_array = !rec.array_sensors.is_empty();
    if (is_array && !rec.array_sensors.contains(&sensor)) || (!is_array && sensor != 0) {
        return Err(CalibrateError::NoSensor {
            path: path.to_owned(),
            sensor,
            have: rec.array_sensors.into_iter().collect(),
        });
    }
    Ok(calibrate(&rec))
}
