//! Accelerometer bias and per-axis scale from static poses: each pose's mean reading `a`
//! satisfies `|diag(s)(a − b)| = g`. Gauss–Newton on the six unknowns from at least six poses
//! (ideally the device resting on each of its six faces).

use crate::sensor::G;
use nalgebra::{Matrix6, Vector3, Vector6};

/// Result of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct AccelFit {
    pub bias: Vector3<f64>,
    pub scale: Vector3<f64>,
    /// RMS of `|diag(s)(a − b)| − g` over the poses, m/s².
    pub residual: f64,
    pub poses: usize,
}

/// Why the fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AccelFitError {
    #[error("{got} static poses found; at least 6 (in different orientations) are needed")]
    TooFewPoses { got: usize },
    #[error("the static poses do not constrain every axis (rest the device on each face)")]
    Degenerate,
}

/// Fits bias and scale to the mean readings of static poses (m/s², sensor axes).
pub fn fit(poses: &[Vector3<f64>]) -> Result<AccelFit, AccelFitError> {
    if poses.len() < 6 {
        return Err(AccelFitError::TooFewPoses { got: poses.len() });
    }
    let mut p = Vector6::new(0.0, 0.0, 0.0, 1.0, 1.0, 1.0); // b, s
    for _ in 0..50 {
        let (jtj, jtr) = normal_equations(&p, poses);
        // A touch of damping keeps weakly constrained directions from running away.
        let damped = jtj + Matrix6::identity() * (1e-9 * jtj.trace());
        let Some(step) = damped.lu().solve(&jtr) else {
            return Err(AccelFitError::Degenerate);
        };
        p -= step;
        if step.norm() < 1e-12 {
            break;
        }
    }
    // Every direction of the parameters must be observed (gravity seen along each axis both
    // ways), or the bias is not determined.
    let (jtj, _) = normal_equations(&p, poses);
    let eig = nalgebra::SymmetricEigen::new(jtj);
    let (lo, hi) = eig
        .eigenvalues
        .iter()
        .fold((f64::MAX, 0.0f64), |(lo, hi), &l| (lo.min(l), hi.max(l)));
    let observed = lo > 1e-6 * hi;
    if !observed
        || p.iter().any(|x| !x.is_finite())
        || p.fixed_rows::<3>(3).iter().any(|&s| s <= 0.0)
    {
        return Err(AccelFitError::Degenerate);
    }
    let bias = Vector3::new(p[0], p[1], p[2]);
    let scale = Vector3::new(p[3], p[4], p[5]);
    let residual = (poses
        .iter()
        .map(|a| ((a - bias).component_mul(&scale).norm() - G).powi(2))
        .sum::<f64>()
        / poses.len() as f64)
        .sqrt();
    Ok(AccelFit {
        bias,
        scale,
        residual,
        poses: poses.len(),
    })
}

/// `JᵀJ` and `Jᵀr` of the residuals `|diag(s)(a − b)| − g` at `p = (b, s)`.
fn normal_equations(p: &Vector6<f64>, poses: &[Vector3<f64>]) -> (Matrix6<f64>, Vector6<f64>) {
    let b = Vector3::new(p[0], p[1], p[2]);
    let s = Vector3::new(p[3], p[4], p[5]);
    let mut jtj = Matrix6::zeros();
    let mut jtr = Vector6::zeros();
    for a in poses {
        let u = (a - b).component_mul(&s);
        let n = u.norm();
        if n < 1e-9 {
            continue;
        }
        // d|u|/db_i = −s_i u_i / n ; d|u|/ds_i = (a_i − b_i) u_i / n
        let mut j = Vector6::zeros();
        for i in 0..3 {
            j[i] = -s[i] * u[i] / n;
            j[3 + i] = (a[i] - b[i]) * u[i] / n;
        }
        jtj += j * j.transpose();
        jtr += j * (n - G);
    }
    (jtj, jtr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn six_faces_recover_bias_and_scale() {
        let b = Vector3::new(0.12, -0.08, 0.2);
        let s = Vector3::new(1.02, 0.97, 1.01);
        let mut poses = Vec::new();
        for axis in 0..3 {
            for sign in [-1.0, 1.0] {
                let mut g = Vector3::zeros();
                g[axis] = sign * G;
                poses.push(g.component_div(&s) + b);
            }
        }
        // And two tilted poses.
        for g in [Vector3::new(1.0, 1.0, 1.0), Vector3::new(-1.0, 0.5, 1.0)] {
            poses.push((g.normalize() * G).component_div(&s) + b);
        }
        let f = fit(&poses).unwrap();
        assert!((f.bias - b).norm() < 1e-6, "{}", f.bias);
        assert!((f.scale - s).norm() < 1e-6, "{}", f.scale);
        assert!(f.residual < 1e-6);
    }

    #[test]
    fn one_face_only_is_degenerate() {
        let poses: Vec<_> = (0..8)
            .map(|i| Vector3::new(0.01 * i as f64, 0.0, G))
            .collect();
        assert!(fit(&poses).is_err());
    }
}
