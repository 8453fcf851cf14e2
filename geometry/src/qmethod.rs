//! The q-method: the weighted mean of unit quaternions (Markley et al. 2007), the unit
//! eigenvector of the largest eigenvalue of the 4×4 structure tensor `M = Σ wᵢ qᵢ qᵢᵀ`. It
//! minimises `Σ wᵢ ‖A(q) − A(qᵢ)‖²_F` and is invariant to the sign of every `qᵢ`.
//!
//! ```
//! use nalgebra::{UnitQuaternion, Vector3};
//! use sfs_geometry::qmethod::mean;
//! let a = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.1));
//! let b = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.3));
//! let neg_b = UnitQuaternion::new_unchecked(-b.into_inner());
//! let m = mean([(a, 1.0), (neg_b, 1.0)]).unwrap();
//! assert!((m.angle_to(&UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.2)))) < 1e-9);
//! ```

use nalgebra::{Matrix4, Quaternion, SymmetricEigen, UnitQuaternion, Vector4};

/// Accumulates the structure tensor.
#[derive(Debug, Clone, Copy, Default)]
pub struct StructureTensor {
    m: Matrix4<f64>,
    weight: f64,
}

impl StructureTensor {
    pub fn new() -> Self {
        StructureTensor {
            m: Matrix4::zeros(),
            weight: 0.0,
        }
    }

    /// Adds `w · q qᵀ` (`w ≥ 0`; non-finite or negative weights are ignored).
    #[inline]
    pub fn add(&mut self, q: &UnitQuaternion<f64>, w: f64) {
        if !(w.is_finite() && w > 0.0) {
            return;
        }
        let v: Vector4<f64> = q.as_ref().coords;
        self.m += v * v.transpose() * w;
        self.weight += w;
    }

    /// Total weight added.
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The mean, or `None` when nothing (of positive weight) was added. The sign is chosen
    /// with a non-negative scalar part, so equal inputs give identical outputs.
    pub fn mean(&self) -> Option<UnitQuaternion<f64>> {
        if self.weight <= 0.0 {
            return None;
        }
        // Scale by the largest entry (dividing by a tiny total weight can overflow), and bound
        // the iterations: a non-finite matrix must give `None`, never an endless loop.
        let scale = self.m.amax();
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let eig = SymmetricEigen::try_new(self.m / scale, 1e-15, 1000)?;
        let (i, _) = eig
            .eigenvalues
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))?;
        let v = eig.eigenvectors.column(i);
        let mut q = Quaternion::new(v[3], v[0], v[1], v[2]); // coords are (i, j, k, w)
        if q.w < 0.0 {
            q = -q;
        }
        let n = q.norm();
        (n.is_finite() && n > 0.0).then(|| UnitQuaternion::new_normalize(q))
    }
}

impl StructureTensor {
    /// The mean, by power iteration from `guess` (a nearby mean, e.g. the previous sample's):
    /// when the inputs are clustered the largest eigenvalue dominates and a few products
    /// converge; otherwise it falls back to the full eigen-decomposition ([`mean`](Self::mean)).
    pub fn mean_near(&self, guess: &UnitQuaternion<f64>) -> Option<UnitQuaternion<f64>> {
        if self.weight <= 0.0 {
            return None;
        }
        let mut v: Vector4<f64> = guess.as_ref().coords;
        for _ in 0..12 {
            let w = self.m * v;
            let n = w.norm();
            if !(n.is_finite() && n > 0.0) {
                return self.mean();
            }
            let w = w / n;
            let change = 1.0 - w.dot(&v).abs();
            v = w;
            if change < 1e-15 {
                let mut q = Quaternion::new(v[3], v[0], v[1], v[2]);
                if q.w < 0.0 {
                    q = -q;
                }
                return Some(UnitQuaternion::new_normalize(q));
            }
        }
        self.mean()
    }
}

/// Weighted mean of `(quaternion, weight)` pairs; `None` if the weights sum to zero.
pub fn mean<I>(items: I) -> Option<UnitQuaternion<f64>>
where
    I: IntoIterator<Item = (UnitQuaternion<f64>, f64)>,
{
    let mut t = StructureTensor::new();
    for (q, w) in items {
        t.add(&q, w);
    }
    t.mean()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn sign_invariant_and_weighted() {
        let qs: Vec<UnitQuaternion<f64>> = (0..10)
            .map(|i| UnitQuaternion::from_scaled_axis(Vector3::new(0.1 * i as f64, 0.02, -0.05)))
            .collect();
        let ws: Vec<f64> = (0..10).map(|i| 1.0 + i as f64).collect();
        let m1 = mean(qs.iter().copied().zip(ws.iter().copied())).unwrap();
        let flipped = qs.iter().enumerate().map(|(i, q)| {
            let q = if i % 3 == 0 {
                UnitQuaternion::new_unchecked(-q.into_inner())
            } else {
                *q
            };
            (q, ws[i])
        });
        let m2 = mean(flipped).unwrap();
        assert!(m1.angle_to(&m2) < 1e-12);
        // The mean minimises the weighted chordal cost: no small perturbation does better.
        let cost = |q: &UnitQuaternion<f64>| -> f64 {
            qs.iter()
                .zip(&ws)
                .map(|(p, w)| {
                    w * (q.to_rotation_matrix().matrix() - p.to_rotation_matrix().matrix())
                        .norm_squared()
                })
                .sum()
        };
        let c = cost(&m1);
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            for s in [-1e-3, 1e-3] {
                let p = m1 * UnitQuaternion::from_scaled_axis(axis * s);
                assert!(cost(&p) >= c - 1e-12);
            }
        }
    }

    #[test]
    fn power_iteration_agrees_with_the_eigen_decomposition() {
        let mut t = StructureTensor::new();
        for i in 0..20 {
            let q = UnitQuaternion::from_scaled_axis(Vector3::new(
                0.01 * i as f64,
                1.0,
                -0.3 + 0.005 * i as f64,
            ));
            let q = if i % 2 == 0 {
                q
            } else {
                UnitQuaternion::new_unchecked(-q.into_inner())
            };
            t.add(&q, 1.0 + i as f64);
        }
        let exact = t.mean().unwrap();
        let guess = exact * UnitQuaternion::from_scaled_axis(Vector3::new(0.05, 0.0, 0.02));
        let fast = t.mean_near(&guess).unwrap();
        assert!(fast.angle_to(&exact) < 1e-9, "{}", fast.angle_to(&exact));
        // A hopeless guess (orthogonal) still ends at the mean.
        let far =
            exact * UnitQuaternion::from_scaled_axis(Vector3::new(std::f64::consts::PI, 0.0, 0.0));
        assert!(t.mean_near(&far).unwrap().angle_to(&exact) < 1e-6);
    }

    /// Regression: kernel weights so small that `M / Σw` overflowed sent the eigen-solver into
    /// an endless loop (found by the robustness property test).
    #[test]
    fn tiny_or_huge_weights_neither_hang_nor_fail() {
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.3, -0.2, 0.1));
        for w in [1e-310, 1e-200, 1e200] {
            let mut t = StructureTensor::new();
            t.add(&q, w);
            t.add(&q, w);
            assert!(t.mean().unwrap().angle_to(&q) < 1e-9, "weight {w}");
            assert!(
                t.mean_near(&UnitQuaternion::identity())
                    .unwrap()
                    .angle_to(&q)
                    < 1e-9,
                "weight {w}"
            );
        }
    }

    #[test]
    fn empty_or_zero_weight_is_none() {
        assert!(mean(std::iter::empty()).is_none());
        assert!(mean([(UnitQuaternion::identity(), 0.0)]).is_none());
        assert!(mean([(UnitQuaternion::identity(), f64::NAN)]).is_none());
    }
}
