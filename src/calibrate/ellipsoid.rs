//! Magnetometer hard- and soft-iron calibration by an ellipsoid fit.
//!
//! Readings `x` of a constant field, taken in many orientations, lie on an ellipsoid
//! `(x − c)ᵀ A (x − c) = 1`. Least squares on the algebraic form `xᵀ A x + vᵀ x = 1`
//! (9 unknowns: A symmetric, v) gives `c = −A⁻¹v/2` (hard iron) and, with
//! `k = 1 + cᵀ A c`, the symmetric soft-iron matrix `W = F · sqrtm(A/k)` that maps the
//! ellipsoid onto the sphere of radius `F`, the geometric-mean radius of the ellipsoid (so the
//! corrected field keeps its magnitude in µT): calibrated `m = W (x − c)`.

use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};

/// Result of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidFit {
    /// Hard-iron offset, µT.
    pub hard_iron: Vector3<f64>,
    /// Soft-iron matrix (symmetric).
    pub soft_iron: Matrix3<f64>,
    /// Radius of the corrected sphere, µT (the local field's magnitude as measured).
    pub radius: f64,
    /// RMS of `(|W(x − c)| − F) / F` over the samples.
    pub rel_residual: f64,
    /// Fraction of directions covered by the corrected samples (see [`coverage`]).
    pub coverage: f64,
}

/// Why the fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("{got} samples; at least {need} are needed")]
    TooFewSamples { got: usize, need: usize },
    #[error("the samples do not span an ellipsoid (turn the device through more orientations)")]
    Degenerate,
}

/// Fits the ellipsoid through `samples` (sensor axes, µT).
pub fn fit(samples: &[Vector3<f64>]) -> Result<EllipsoidFit, FitError> {
    if samples.len() < 12 {
        return Err(FitError::TooFewSamples {
            got: samples.len(),
            need: 12,
        });
    }
    // Centre and scale the data for conditioning.
    let mean = samples.iter().sum::<Vector3<f64>>() / samples.len() as f64;
    let scale = (samples
        .iter()
        .map(|x| (x - mean).norm_squared())
        .sum::<f64>()
        / samples.len() as f64)
        .sqrt();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(FitError::Degenerate);
    }
    let n = samples.len();
    let mut d = DMatrix::zeros(n, 9);
    for (i, x) in samples.iter().enumerate() {
        let y = (x - mean) / scale;
        let row = [
            y.x * y.x,
            y.y * y.y,
            y.z * y.z,
            2.0 * y.x * y.y,
            2.0 * y.x * y.z,
            2.0 * y.y * y.z,
            y.x,
            y.y,
            y.z,
        ];
        for (j, v) in row.iter().enumerate() {
            d[(i, j)] = *v;
        }
    }
    let ones = DVector::from_element(n, 1.0);
    let p = d
        .svd(true, true)
        .solve(&ones, 1e-12)
        .map_err(|_| FitError::Degenerate)?;
    let a = Matrix3::new(p[0], p[3], p[4], p[3], p[1], p[5], p[4], p[5], p[2]);
    let v = Vector3::new(p[6], p[7], p[8]);
    let eig = SymmetricEigen::new(a);
    if eig.eigenvalues.iter().any(|&l| !(l.is_finite() && l > 0.0)) {
        return Err(FitError::Degenerate);
    }
    let a_inv = eig.eigenvectors
        * Matrix3::from_diagonal(&eig.eigenvalues.map(|l| 1.0 / l))
        * eig.eigenvectors.transpose();
    let c = -a_inv * v / 2.0;
    let k = 1.0 + (c.transpose() * a * c)[0];
    if !(k.is_finite() && k > 0.0) {
        return Err(FitError::Degenerate);
    }
    let sqrt_a = eig.eigenvectors
        * Matrix3::from_diagonal(&eig.eigenvalues.map(|l| (l / k).sqrt()))
        * eig.eigenvectors.transpose();
    // Back to the original units: y = (x − mean)/scale ⇒ x − c_x = scale (y − c).
    let hard_iron = mean + c * scale;
    let unit = sqrt_a / scale; // maps x − c_x to the unit sphere
    let det = unit.determinant();
    if !(det.is_finite() && det > 0.0) {
        return Err(FitError::Degenerate);
    }
    let radius = det.powf(-1.0 / 3.0);
    let soft_iron = unit * radius;
    let corrected: Vec<Vector3<f64>> = samples
        .iter()
        .map(|x| soft_iron * (x - hard_iron))
        .collect();
    let rel_residual = (corrected
        .iter()
        .map(|m| ((m.norm() - radius) / radius).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    Ok(EllipsoidFit {
        hard_iron,
        soft_iron,
        radius,
        rel_residual,
        coverage: coverage(&corrected),
    })
}

/// Fraction of 100 evenly spread directions (a Fibonacci sphere) that have at least two of the
/// vectors among their nearest: 1 means the device was turned through all orientations.
pub fn coverage(vectors: &[Vector3<f64>]) -> f64 {
    const K: usize = 100;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let dirs: Vec<Vector3<f64>> = (0..K)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / K as f64;
            let r = (1.0 - z * z).sqrt();
            let th = golden * i as f64;
            Vector3::new(r * th.cos(), r * th.sin(), z)
        })
        .collect();
    let mut hits = [0u32; K];
    for v in vectors {
        let n = v.norm();
        if n.is_nan() || n <= 0.0 {
            continue;
        }
        let u = v / n;
        let best = (0..K)
            .max_by(|&a, &b| dirs[a].dot(&u).total_cmp(&dirs[b].dot(&u)))
            .expect("K > 0");
        hits[best] += 1;
    }
    hits.iter().filter(|&&h| h >= 2).count() as f64 / K as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::rng::Rng;
    use nalgebra::UnitQuaternion;

    #[test]
    fn recovers_a_known_distortion() {
        let mut rng = Rng::new(5);
        let field = Vector3::new(0.0, 20.0, -43.0);
        let w_true = Matrix3::new(1.10, 0.04, -0.02, 0.04, 0.93, 0.03, -0.02, 0.03, 1.02);
        let c_true = Vector3::new(12.0, -7.0, 30.0);
        let w_inv = w_true.try_inverse().unwrap();
        let samples: Vec<Vector3<f64>> = (0..2000)
            .map(|_| {
                let q = UnitQuaternion::from_scaled_axis(rng.vec3(2.0));
                w_inv * (q * field) + c_true + rng.vec3(0.2)
            })
            .collect();
        let f = fit(&samples).unwrap();
        assert!((f.hard_iron - c_true).norm() < 0.2, "{}", f.hard_iron);
        // The soft iron is recovered up to the overall scale (the field's magnitude is kept).
        let ratio = f.soft_iron * w_inv;
        let s = ratio.trace() / 3.0;
        assert!((ratio / s - Matrix3::identity()).norm() < 0.01, "{ratio}");
        assert!(f.rel_residual < 0.01);
        assert!(f.coverage > 0.9, "{}", f.coverage);
    }

    #[test]
    fn too_few_or_planar_samples_fail() {
        let v = vec![Vector3::new(1.0, 0.0, 0.0); 5];
        assert!(matches!(fit(&v), Err(FitError::TooFewSamples { .. })));
        let planar: Vec<_> = (0..100)
            .map(|i| {
                let a = i as f64 * 0.1;
                Vector3::new(a.cos(), a.sin(), 0.0) * 40.0
            })
            .collect();
        assert!(fit(&planar).is_err() || fit(&planar).unwrap().coverage < 0.3);
    }
}
