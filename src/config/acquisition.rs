//! `[calibration]` and `[acquisition]`: the device's calibration and how samples become tagged curves.

use super::{ConfigError, ConfigFile};
use crate::acquisition::AcquisitionConfig;
use crate::sensor::{AxisMap, CalibrationSpec};
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// `[calibration]`, as written (see the module documentation).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationToml {
    #[serde(default = "zero3")]
    pub acc_bias: [f64; 3],
    #[serde(default = "one3")]
    pub acc_scale: [f64; 3],
    #[serde(default = "zero3")]
    pub mag_hard_iron: [f64; 3],
    #[serde(default = "eye3")]
    pub mag_soft_iron: [[f64; 3]; 3],
    #[serde(default = "zero3")]
    pub gyro_bias: [f64; 3],
    pub axes: Option<Vec<String>>,
    #[serde(default = "zero3")]
    pub mounting_deg: [f64; 3],
}

impl Default for CalibrationToml {
    fn default() -> Self {
        CalibrationToml {
            acc_bias: zero3(),
            acc_scale: one3(),
            mag_hard_iron: zero3(),
            mag_soft_iron: eye3(),
            gyro_bias: zero3(),
            axes: None,
            mounting_deg: zero3(),
        }
    }
}

fn zero3() -> [f64; 3] {
    [0.0; 3]
}
fn one3() -> [f64; 3] {
    [1.0; 3]
}
fn eye3() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

/// `[acquisition]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AcquisitionToml {
    pub acc_tolerance: Option<f64>,
    pub mag_norm_tolerance: Option<f64>,
    pub mag_dip_tolerance_deg: Option<f64>,
    pub stationary_window_s: Option<f64>,
    pub stationary_distance: Option<f64>,
    pub stationary_gyro_deg_s: Option<f64>,
    pub stand_margin_s: Option<f64>,
    pub heading_bias_tau_s: Option<f64>,
    pub tilt_bias_tau_s: Option<f64>,
    pub smooth: Option<bool>,
    pub nominal_speed: Option<f64>,
    pub array_window_s: Option<f64>,
    pub max_node: Option<u32>,
    pub max_curve_samples: Option<u64>,
    pub loop_distance: Option<f64>,
    pub loop_turn_deg: Option<f64>,
    #[serde(default)]
    pub segment_lengths: BTreeMap<String, Vec<f64>>,
}

impl ConfigFile {
    /// The acquisition settings (calibration included) this configuration describes.
    pub(super) fn acquisition_config(&self, file: &Path) -> Result<AcquisitionConfig, ConfigError> {
        let err = |key: &str, reason: String| ConfigError::new(file, key.to_owned(), reason);
        let a = &self.acquisition;
        let mut out = AcquisitionConfig {
            calibration: self.calibration_spec(file)?,
            ..AcquisitionConfig::default()
        };
        let positive = |key: &str, v: Option<f64>, max: f64| -> Result<Option<f64>, ConfigError> {
            match v {
                Some(x) if !(x.is_finite() && x > 0.0 && x <= max) => {
                    Err(err(key, format!("{x} is out of range (0, {max}]")))
                }
                v => Ok(v),
            }
        };
        let th = &mut out.thresholds;
        if let Some(x) = positive("acquisition.acc_tolerance", a.acc_tolerance, 20.0)? {
            th.acc_tol = x;
        }
        if let Some(x) = positive("acquisition.mag_norm_tolerance", a.mag_norm_tolerance, 1.0)? {
            th.mag_norm_rel = x;
        }
        if let Some(x) = positive(
            "acquisition.mag_dip_tolerance_deg",
            a.mag_dip_tolerance_deg,
            90.0,
        )? {
            th.mag_dip_deg = x;
        }
        if let Some(x) = positive(
            "acquisition.stationary_window_s",
            a.stationary_window_s,
            10.0,
        )? {
            out.stationary_window = x;
        }
        if let Some(x) = positive(
            "acquisition.stationary_distance",
            a.stationary_distance,
            1.0,
        )? {
            out.stationary_distance = x;
        }
        if let Some(x) = positive(
            "acquisition.stationary_gyro_deg_s",
            a.stationary_gyro_deg_s,
            90.0,
        )? {
            out.stationary_gyro = x.to_radians();
        }
        if let Some(x) = positive("acquisition.stand_margin_s", a.stand_margin_s, 60.0)? {
            out.stand_margin = x;
        }
        // 0 turns the bias learning in motion off.
        let off_or_positive = |key: &str, v: Option<f64>| match v {
            Some(0.0) => Ok(Some(0.0)),
            v => positive(key, v, 3600.0),
        };
        if let Some(x) = off_or_positive("acquisition.heading_bias_tau_s", a.heading_bias_tau_s)? {
            out.ahrs.tau_heading_bias = x;
        }
        if let Some(x) = off_or_positive("acquisition.tilt_bias_tau_s", a.tilt_bias_tau_s)? {
            out.ahrs.tau_tilt_bias = x;
        }
        if let Some(x) = a.smooth {
            out.smooth = x;
        }
        if let Some(x) = positive("acquisition.nominal_speed", a.nominal_speed, 10.0)? {
            out.nominal_speed = x;
        }
        if let Some(x) = positive("acquisition.array_window_s", a.array_window_s, 3600.0)? {
            out.array_window = x;
        }
        if let Some(m) = a.max_node {
            if !(1..=crate::keypad::MAX_NODE).contains(&m) {
                return Err(err(
                    "acquisition.max_node",
                    format!("{m} is out of range [1, {}]", crate::keypad::MAX_NODE),
                ));
            }
            out.max_node = m;
        }
        if let Some(m) = a.max_curve_samples {
            const MAX: u64 = 1 << 30;
            if !(2..=MAX).contains(&m) {
                return Err(err(
                    "acquisition.max_curve_samples",
                    format!("{m} is out of range [2, {MAX}]"),
                ));
            }
            out.max_curve_samples = m as usize;
        }
        if let Some(x) = positive("acquisition.loop_distance", a.loop_distance, 100.0)? {
            out.loop_distance = x;
        }
        if let Some(x) = positive("acquisition.loop_turn_deg", a.loop_turn_deg, 360.0)? {
            out.loop_turn = x.to_radians();
        }
        for (k, v) in &a.segment_lengths {
            let key = format!("acquisition.segment_lengths.{k}");
            let idx: usize = k
                .parse()
                .map_err(|_| err(&key, format!("{k:?} is not a curve index (0, 1, 2, …)")))?;
            if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(err(
                    &key,
                    format!("length {x} is not a positive number of metres"),
                ));
            }
            out.segment_lengths.insert(idx, v.clone());
        }
        Ok(out)
    }

    /// `[calibration]`, checked: finite numbers, positive scales, a soft-iron matrix that is
    /// not singular, a small mounting offset, axes `AxisMap` can read.
    fn calibration_spec(&self, file: &Path) -> Result<CalibrationSpec, ConfigError> {
        let err = |key: &str, reason: String| ConfigError::new(file, key.to_owned(), reason);
        let c = &self.calibration;
        let finite = |key: &str, v: &[f64]| -> Result<(), ConfigError> {
            match v.iter().find(|x| !x.is_finite()) {
                Some(x) => Err(err(key, format!("{x} is not a finite number"))),
                None => Ok(()),
            }
        };
        finite("calibration.acc_bias", &c.acc_bias)?;
        finite("calibration.acc_scale", &c.acc_scale)?;
        finite("calibration.mag_hard_iron", &c.mag_hard_iron)?;
        finite("calibration.mag_soft_iron", c.mag_soft_iron.as_flattened())?;
        finite("calibration.gyro_bias", &c.gyro_bias)?;
        finite("calibration.mounting_deg", &c.mounting_deg)?;
        if let Some(x) = c.acc_scale.iter().find(|&&x| x <= 0.0) {
            return Err(err(
                "calibration.acc_scale",
                format!("{x} is not a positive scale"),
            ));
        }
        let soft = Matrix3::from_row_slice(c.mag_soft_iron.as_flattened());
        if soft.determinant().abs() < 1e-6 {
            return Err(err(
                "calibration.mag_soft_iron",
                "the matrix is singular".into(),
            ));
        }
        if let Some(x) = c.mounting_deg.iter().find(|x| x.abs() > 45.0) {
            return Err(err(
                "calibration.mounting_deg",
                format!("{x}° is not a small mounting offset (at most 45°); fix `axes` instead"),
            ));
        }
        let axes = match &c.axes {
            Some(names) => {
                Some(AxisMap::parse(names).map_err(|e| err("calibration.axes", e.to_string()))?)
            }
            None => None,
        };
        let [r, p, y] = c.mounting_deg.map(f64::to_radians);
        let calibration = CalibrationSpec {
            acc_bias: Vector3::from(c.acc_bias),
            acc_scale: Vector3::from(c.acc_scale),
            mag_hard_iron: Vector3::from(c.mag_hard_iron),
            mag_soft_iron: soft,
            gyro_bias: Vector3::from(c.gyro_bias),
            axes,
            // No offset is the identity exactly (Euler angles of zero give a -0.0 entry), as in
            // the default calibration of a session without a configuration file.
            mounting: if c.mounting_deg == [0.0; 3] {
                Rotation3::identity()
            } else {
                Rotation3::from_euler_angles(r, p, y)
            },
        };
        Ok(calibration)
    }
}
