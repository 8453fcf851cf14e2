//! TRIAD with gravity as the primary observation: the accelerometer fixes the tilt exactly,
//! the magnetometer only the heading (its dip angle, often disturbed, plays no part).
//!
//! In frame coordinates, `up = a/|a|` (a resting accelerometer measures the reaction to
//! gravity, pointing up), `east = m × up / |m × up|`, `north = up × east`. The rows of the
//! frame-to-world matrix are `east, north, up`, so its columns are the frame axes T, B, N in
//! world coordinates (x east, y magnetic north, z up).
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::orientation::triad::triad;
//! // Lying flat, travel direction pointing north: T = y_world, B = −x_world, N = z_world.
//! let acc = Vector3::new(0.0, 0.0, 9.81);
//! let mag = Vector3::new(20.0, 0.0, -40.0); // north-and-down field seen along +T
//! let q = triad(&acc, &mag).unwrap();
//! let t = q * Vector3::x();
//! assert!((t - Vector3::y()).norm() < 1e-12);
//! ```

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Orientation from one accelerometer and one magnetometer vector (frame axes). `None` when
/// a vector is zero or not finite, or the field is parallel to gravity (no heading).
pub fn triad(acc: &Vector3<f64>, mag: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let a = acc.norm();
    if !(a.is_finite() && a > 1e-9 && mag.iter().all(|x| x.is_finite())) {
        return None;
    }
    let up = acc / a;
    let east = mag.cross(&up);
    let en = east.norm();
    // The horizontal part of the field must be a measurable fraction of it.
    if !(en > 1e-6 * mag.norm() && en > 1e-12) {
        return None;
    }
    let east = east / en;
    let north = up.cross(&east);
    let world_from_frame =
        Matrix3::from_rows(&[east.transpose(), north.transpose(), up.transpose()]);
    // Orthonormal by construction: the direct conversion is exact.
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(world_from_frame),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn recovers_random_orientations_exactly_without_noise() {
        let field = Vector3::new(0.0, 20.0, -43.0);
        let g = Vector3::new(0.0, 0.0, 9.81);
        let mut s = 0x1234_5678_u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..1000 {
            let truth = UnitQuaternion::from_scaled_axis(Vector3::new(r(), r(), r()) * 3.0);
            let acc = truth.inverse() * g;
            let mag = truth.inverse() * field;
            let q = triad(&acc, &mag).unwrap();
            assert!(q.angle_to(&truth) < 1e-9, "{}", q.angle_to(&truth));
        }
    }

    #[test]
    fn dip_error_does_not_tilt() {
        // A disturbed dip changes nothing: tilt from gravity, heading from the horizontal part.
        let truth =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(0.3, -0.2, 1.0));
        let g = Vector3::new(0.0, 0.0, 9.81);
        let acc = truth.inverse() * g;
        let q1 = triad(&acc, &(truth.inverse() * Vector3::new(0.0, 20.0, -43.0))).unwrap();
        let q2 = triad(&acc, &(truth.inverse() * Vector3::new(0.0, 20.0, -10.0))).unwrap();
        assert!(q1.angle_to(&q2) < 1e-9);
    }

    #[test]
    fn degenerate_inputs_give_none() {
        let z = Vector3::zeros();
        let up = Vector3::new(0.0, 0.0, 9.81);
        assert!(triad(&z, &Vector3::x()).is_none());
        assert!(triad(&up, &Vector3::new(0.0, 0.0, -40.0)).is_none());
        assert!(triad(&up, &Vector3::new(f64::NAN, 0.0, 1.0)).is_none());
    }
}
