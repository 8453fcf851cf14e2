//! Sensor model: raw counts → SI vectors in the Darboux-frame axes of the device.
//!
//! `value = calibration(counts × scale from HELLO)`, then the axis mapping and the mounting
//! rotation bring the vector from the sensor's axes to the frame `[T B N]` (x = direction of
//! travel T, y = B = N × T, z = outward normal N).
//!
//! Calibration, applied in this order, in sensor axes:
//! - accelerometer: `a = diag(acc_scale) · (a_raw − acc_bias)` (m/s²);
//! - magnetometer: `m = mag_soft_iron · (m_raw − mag_hard_iron)` (µT);
//! - gyroscope: `w = w_raw − gyro_bias` (rad/s).
//!
//! Then `v_frame = mounting · axes · v_sensor`, where `axes` is a signed permutation
//! (default per device kind, from the wire format's sensor axes) and `mounting` a small
//! rotation (the Morphorider's wheel is not perfectly aligned with its sensor).
//!
//! ```
//! use sfs::sensor::{AxisMap, Calibration};
//! use device_protocol::DeviceKind;
//! // The phone travels along its y axis with its screen (z) outwards: T = y, B = −x, N = z.
//! let cal = Calibration::default_for(DeviceKind::Phone);
//! assert_eq!(cal.axes, AxisMap::parse(&["y", "-x", "z"]).unwrap());
//! ```

use device_protocol::DeviceKind;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// Standard gravity, m/s².
pub const G: f64 = 9.806_65;

/// Which signed sensor axis becomes each frame axis (T, B, N): a proper rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisMap {
    /// `frame = m · sensor`.
    pub m: Matrix3<f64>,
}

/// Why axis names do not make a mapping.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AxisError {
    #[error("expected 3 axis names for T, B, N, got {got}")]
    Count { got: usize },
    #[error("{name:?} is not one of x, y, z, -x, -y, -z")]
    Unknown { name: String },
    #[error("an axis is used twice")]
    Repeated,
    #[error("the mapping is a reflection (left-handed); flip the sign of one axis")]
    Reflection,
}

impl AxisMap {
    pub fn identity() -> Self {
        AxisMap {
            m: Matrix3::identity(),
        }
    }

    /// Parses three signed axis names (`"x"`, `"-y"`, …) for T, B, N. Errors say why.
    pub fn parse<S: AsRef<str>>(names: &[S]) -> Result<Self, AxisError> {
        if names.len() != 3 {
            return Err(AxisError::Count { got: names.len() });
        }
        let mut m = Matrix3::<f64>::zeros();
        for (row, name) in names.iter().enumerate() {
            let n = name.as_ref().trim();
            let (sign, axis) = match n.strip_prefix('-') {
                Some(a) => (-1.0, a),
                None => (1.0, n.strip_prefix('+').unwrap_or(n)),
            };
            let col = match axis {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => return Err(AxisError::Unknown { name: n.to_owned() }),
            };
            m[(row, col)] = sign;
        }
        let det = m.determinant();
        if (det - 1.0).abs() > 1e-9 {
            return Err(if det.abs() < 0.5 {
                AxisError::Repeated
            } else {
                AxisError::Reflection
            });
        }
        Ok(AxisMap { m })
    }

    /// The names of the mapping (inverse of [`parse`](Self::parse)).
    pub fn names(&self) -> [String; 3] {
        std::array::from_fn(|row| {
            let col = (0..3).find(|&c| self.m[(row, c)] != 0.0).unwrap_or(row);
            let sign = if self.m[(row, col)] < 0.0 { "-" } else { "" };
            format!("{sign}{}", ["x", "y", "z"][col])
        })
    }
}

/// Calibration of one device (see the module documentation for the model).
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub acc_bias: Vector3<f64>,
    pub acc_scale: Vector3<f64>,
    pub mag_hard_iron: Vector3<f64>,
    pub mag_soft_iron: Matrix3<f64>,
    pub gyro_bias: Vector3<f64>,
    pub axes: AxisMap,
    /// Rotation from the mapped sensor axes to the rolling frame.
    pub mounting: Rotation3<f64>,
}

impl Calibration {
    /// No correction, with the wire format's axes for `kind`:
    /// Morphorider x = travel, y = left, z = away from the surface → identity;
    /// phone y = travel, z = out of the screen → T = y, B = −x, N = z;
    /// array sensor x = along the ribbon, z = away → identity.
    pub fn default_for(kind: DeviceKind) -> Self {
        let axes = match kind {
            DeviceKind::Phone => AxisMap::parse(&["y", "-x", "z"]).expect("valid"),
            _ => AxisMap::identity(),
        };
        Calibration {
            acc_bias: Vector3::zeros(),
            acc_scale: Vector3::repeat(1.0),
            mag_hard_iron: Vector3::zeros(),
            mag_soft_iron: Matrix3::identity(),
            gyro_bias: Vector3::zeros(),
            axes,
            mounting: Rotation3::identity(),
        }
    }

    /// `frame = frame_from_sensor · sensor`.
    pub fn frame_from_sensor(&self) -> Matrix3<f64> {
        self.mounting.matrix() * self.axes.m
    }
}

/// Calibration as configured: like [`Calibration`] with the axis mapping optional (default:
/// the wire format's axes of the device kind announced in HELLO).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationSpec {
    pub acc_bias: Vector3<f64>,
    pub acc_scale: Vector3<f64>,
    pub mag_hard_iron: Vector3<f64>,
    pub mag_soft_iron: Matrix3<f64>,
    pub gyro_bias: Vector3<f64>,
    pub axes: Option<AxisMap>,
    pub mounting: Rotation3<f64>,
}

impl Default for CalibrationSpec {
    fn default() -> Self {
        let c = Calibration::default_for(DeviceKind::Morphorider);
        CalibrationSpec {
            acc_bias: c.acc_bias,
            acc_scale: c.acc_scale,
            mag_hard_iron: c.mag_hard_iron,
            mag_soft_iron: c.mag_soft_iron,
            gyro_bias: c.gyro_bias,
            axes: None,
            mounting: c.mounting,
        }
    }
}

impl CalibrationSpec {
    /// The calibration for a device of `kind`.
    pub fn resolve(&self, kind: DeviceKind) -> Calibration {
        Calibration {
            acc_bias: self.acc_bias,
            acc_scale: self.acc_scale,
            mag_hard_iron: self.mag_hard_iron,
            mag_soft_iron: self.mag_soft_iron,
            gyro_bias: self.gyro_bias,
            axes: self.axes.unwrap_or(Calibration::default_for(kind).axes),
            mounting: self.mounting,
        }
    }
}

/// Scales of a device, from its HELLO.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scales {
    pub acc: f64,
    pub gyro: f64,
    pub mag: f64,
    /// Metres per wheel tick, if the device has a wheel.
    pub wheel_m_per_tick: Option<f64>,
}

/// Why a HELLO's scales cannot be used: the sensor, the scale and its unit per count.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScaleError {
    #[error("{0} scale {1} is not positive")]
    NotPositive(&'static str, f64),
    #[error("{0} scale {1} {2} per count is implausible")]
    Implausible(&'static str, f64, &'static str),
    #[error("wheel advance {0} m per tick is implausible")]
    Wheel(f64),
}

impl Scales {
    pub fn from_hello(h: &device_protocol::Hello) -> Self {
        let wheel = (h.ticks_per_rev > 0 && h.wheel_circumference_um > 0)
            .then(|| h.wheel_circumference_um as f64 * 1e-6 / h.ticks_per_rev as f64);
        Scales {
            acc: h.acc_scale as f64,
            gyro: h.gyro_scale as f64,
            mag: h.mag_scale as f64,
            wheel_m_per_tick: wheel,
        }
    }

    /// Whether every scale is finite and positive where the device has the sensor.
    pub fn validate(&self, has_gyro: bool) -> Result<(), ScaleError> {
        use ScaleError::*;
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !ok(self.acc) {
            return Err(NotPositive("accelerometer", self.acc));
        }
        if !ok(self.mag) {
            return Err(NotPositive("magnetometer", self.mag));
        }
        if has_gyro && !ok(self.gyro) {
            return Err(NotPositive("gyroscope", self.gyro));
        }
        // A plausible sensor: full scale (32767 counts) between 1/100 and 1000 units of g,
        // µT and rad/s; a wheel advancing at most 10 cm per tick.
        let full = |x: f64| x * 32767.0;
        if !(0.098..=98_000.0).contains(&full(self.acc)) {
            return Err(Implausible("accelerometer", self.acc, "m/s²"));
        }
        if !(1.0..=1e6).contains(&full(self.mag)) {
            return Err(Implausible("magnetometer", self.mag, "µT"));
        }
        if has_gyro && !(0.01..=1e4).contains(&full(self.gyro)) {
            return Err(Implausible("gyroscope", self.gyro, "rad/s"));
        }
        if let Some(w) = self.wheel_m_per_tick {
            if !(w.is_finite() && w > 0.0 && w <= 0.1) {
                return Err(Wheel(w));
            }
        }
        Ok(())
    }
}

/// Converts raw counts into calibrated vectors in frame axes.
#[derive(Debug, Clone)]
pub struct SensorModel {
    pub scales: Scales,
    pub cal: Calibration,
    frame_from_sensor: Matrix3<f64>,
    mag_matrix: Matrix3<f64>,
}

/// Whether a raw triple touches the i16 rails (the sensor saturated).
#[inline]
pub fn saturated(raw: [i16; 3]) -> bool {
    raw.iter().any(|&v| v == i16::MAX || v == i16::MIN)
}

#[inline]
fn v3(raw: [i16; 3], scale: f64) -> Vector3<f64> {
    Vector3::new(raw[0] as f64, raw[1] as f64, raw[2] as f64) * scale
}

impl SensorModel {
    pub fn new(scales: Scales, cal: Calibration) -> Self {
        let f = cal.frame_from_sensor();
        SensorModel {
            scales,
            frame_from_sensor: f,
            mag_matrix: f * cal.mag_soft_iron,
            cal,
        }
    }

    /// Accelerometer, m/s², frame axes.
    #[inline]
    pub fn acc(&self, raw: [i16; 3]) -> Vector3<f64> {
        let a = (v3(raw, self.scales.acc) - self.cal.acc_bias).component_mul(&self.cal.acc_scale);
        self.frame_from_sensor * a
    }

    /// Magnetometer, µT, frame axes.
    #[inline]
    pub fn mag(&self, raw: [i16; 3]) -> Vector3<f64> {
        self.mag_matrix * (v3(raw, self.scales.mag) - self.cal.mag_hard_iron)
    }

    /// Gyroscope, rad/s, frame axes.
    #[inline]
    pub fn gyro(&self, raw: [i16; 3]) -> Vector3<f64> {
        self.frame_from_sensor * (v3(raw, self.scales.gyro) - self.cal.gyro_bias)
    }

    /// Accelerometer in sensor axes, calibrated but not mapped (for `sfs calibrate`).
    pub fn acc_sensor_uncalibrated(&self, raw: [i16; 3]) -> Vector3<f64> {
        v3(raw, self.scales.acc)
    }

    /// Magnetometer in sensor axes, scaled but not calibrated (for `sfs calibrate`).
    pub fn mag_sensor_uncalibrated(&self, raw: [i16; 3]) -> Vector3<f64> {
        v3(raw, self.scales.mag)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_maps_are_proper_rotations() {
        assert!(AxisMap::parse(&["x", "y", "z"]).is_ok());
        assert!(AxisMap::parse(&["y", "-x", "z"]).is_ok());
        assert_eq!(
            AxisMap::parse(&["y", "x", "z"]).unwrap_err(),
            AxisError::Reflection
        );
        assert_eq!(
            AxisMap::parse(&["x", "x", "z"]).unwrap_err(),
            AxisError::Repeated
        );
        assert!(AxisMap::parse(&["x", "w", "z"]).is_err());
        let m = AxisMap::parse(&["-z", "y", "x"]).unwrap();
        assert_eq!(AxisMap::parse(&m.names()).unwrap(), m);
    }

    #[test]
    fn phone_frame_follows_the_wire_format() {
        // Phone slid along its y axis, screen out: travel y → T, screen z → N, B = N × T.
        let cal = Calibration::default_for(DeviceKind::Phone);
        let f = cal.frame_from_sensor();
        let t = f * Vector3::y();
        let n = f * Vector3::z();
        assert_eq!(t, Vector3::x());
        assert_eq!(n, Vector3::z());
        assert_eq!(f * Vector3::z().cross(&Vector3::y()), Vector3::y()); // B = N × T
    }

    #[test]
    fn calibration_inverts_a_known_distortion() {
        let scales = Scales {
            acc: 0.01,
            gyro: 0.001,
            mag: 0.1,
            wheel_m_per_tick: None,
        };
        let mut cal = Calibration::default_for(DeviceKind::Morphorider);
        cal.acc_bias = Vector3::new(0.1, -0.2, 0.3);
        cal.acc_scale = Vector3::new(1.01, 0.99, 1.0);
        cal.mag_hard_iron = Vector3::new(5.0, -3.0, 2.0);
        cal.mag_soft_iron = Matrix3::new(1.1, 0.05, 0.0, 0.05, 0.9, 0.0, 0.0, 0.0, 1.0);
        let model = SensorModel::new(scales, cal.clone());
        let raw_acc = [100, -50, 981];
        let a = model.acc(raw_acc);
        let expect = Vector3::new((1.0 - 0.1) * 1.01, (-0.5 + 0.2) * 0.99, 9.81 - 0.3);
        assert!((a - expect).norm() < 1e-12, "{a} vs {expect}");
        let m = model.mag([200, 100, -400]);
        let expect = cal.mag_soft_iron * (Vector3::new(20.0, 10.0, -40.0) - cal.mag_hard_iron);
        assert!((m - expect).norm() < 1e-12);
    }
}
