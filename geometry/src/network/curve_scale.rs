//! A distance scale per curve, from the loops: a wheel reads each pass a little long or short.
//!
//! A Morphorider's distance is its wheel's turns times a circumference, and the wheel's
//! rolling radius changes with how hard the operator presses it and how the tyre sits: the
//! independent simulator's rough captures read each curve 0.5–1.9 % long or short, the same
//! along the curve (BENCHMARKS.md, Field accuracy III). A curve read 1 % long puts its
//! nodes 1 % too far apart along it, and the loops through it misfit.
//!
//! The misfit is a quadratic form in the curves' scales `s` (each curve's edge data
//! `(1 + s_c) h t`, [`super::poisson::ScaleForm`]). The estimate is the least misfit with a
//! prior on each scale (the device's spread, `sigma`), the misfit weighed by the noise the
//! loops show (`chi2 / (loops − curves)` per degree of freedom left), and the length-weighted
//! mean scale held
//! at 0: a scale common to every curve only scales the misfit, so the loops would shrink the
//! network to a point, and the network's size is the wheel's calibration, not theirs.
//!
//! ```
//! use nalgebra::{DMatrix, DVector};
//! use sfs_geometry::network::curve_scale::estimate;
//! use sfs_geometry::network::poisson::ScaleForm;
//! // Two curves; the loops say the first reads long against the second.
//! let form = ScaleForm {
//!     h: DMatrix::from_row_slice(2, 2, &[1.0, -1.0, -1.0, 1.0]) * 1e4,
//!     b: DVector::from_vec(vec![2.0, -2.0]),
//!     chi2: 1.0,
//!     loops: 10,
//! };
//! let s = estimate(&form, 0.01, &[1.0, 1.0]).unwrap();
//! assert!(s[0] < 0.0 && s[1] > 0.0 && (s[0] + s[1]).abs() < 1e-12);
//! ```

use super::poisson::ScaleForm;
use super::prefilter::UniformCurve;
use nalgebra::{DMatrix, DVector};

/// A wheel's spread of scale from curve to curve: the independent simulator's rough
/// Morphorider reads its curves 0.9 % long or short (RMS; −1.9 to +1.6 %, each the same along
/// its curve to 0.1–0.2 %), ours 0.5 % (BENCHMARKS.md, Field accuracy III).
pub const WHEEL_SIGMA: f64 = 0.01;

/// The scale of each curve (in the order of `form`), `None` with fewer than two curves, no
/// more loops than curves, or a singular system. `sigma` is the prior spread of a curve's
/// scale (a fraction), `lengths` each curve's length (m), the weights of the mean held at 0.
pub fn estimate(form: &ScaleForm, sigma: f64, lengths: &[f64]) -> Option<DVector<f64>> {
    let k = form.b.len();
    let total: f64 = lengths.iter().sum();
    // With as many scales as loops, nothing tells them from the noise.
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if k < 2 || form.loops <= k || !positive(sigma) || lengths.len() != k || !positive(total) {
        return None;
    }
    // A loop's misfit is 3-D, but one cause mostly makes it (a curve's heading turns it within
    // the surface, one direction): a degree of freedom per loop, not three. Counting three
    // trusts the loops three times as much: measured, hardly better on our captures, and worse
    // where a network has barely more loops than curves (BENCHMARKS.md, Field accuracy III).
    let dof = (form.loops - k) as f64;
    // The noise per degree of freedom is what the loops leave once the scales are fitted
    // (the residual variance's unbiased estimate), found with them: from the misfit as
    // measured, then each fit's residual, to a fixed point. Floored, so that exact data
    // (no misfit left) still solves.
    let floor = 1e-9 * form.chi2 / form.loops as f64;
    let mut noise = form.chi2 / dof;
    let mut s = DVector::zeros(k);
    for _ in 0..MAX_ITERATIONS {
        if !positive(noise) {
            return None;
        }
        s = solve(form, sigma, lengths, total, noise)?;
        let left = form.chi2 + 2.0 * form.b.dot(&s) + (s.transpose() * &form.h * &s)[(0, 0)];
        let next = (left.max(0.0) / dof).max(floor);
        let done = (next - noise).abs() <= 1e-3 * noise;
        noise = next;
        if done {
            break;
        }
    }
    s.iter().all(|x| x.is_finite()).then_some(s)
}

/// Most rounds of the noise's fixed point ([`estimate`]).
const MAX_ITERATIONS: usize = 50;

/// Minimises `chi2(s) / noise + |s|² / sigma²` with `Σ L_c s_c = 0` (KKT, k + 1 unknowns).
fn solve(
    form: &ScaleForm,
    sigma: f64,
    lengths: &[f64],
    total: f64,
    noise: f64,
) -> Option<DVector<f64>> {
    let k = form.b.len();
    let mut a = DMatrix::zeros(k + 1, k + 1);
    let mut rhs = DVector::zeros(k + 1);
    for i in 0..k {
        for j in 0..k {
            a[(i, j)] = form.h[(i, j)] / noise;
        }
        a[(i, i)] += 1.0 / (sigma * sigma);
        a[(i, k)] = lengths[i] / total;
        a[(k, i)] = lengths[i] / total;
        rhs[i] = -form.b[i] / noise;
    }
    let s = a.lu().solve(&rhs)?;
    Some(s.rows(0, k).into_owned())
}

/// Scales each curve's distances by `1 + s` (its steps and its samples' distances from its
/// first sample).
pub fn apply(curves: &mut [UniformCurve], scales: &[f64]) {
    for (c, &s) in curves.iter_mut().zip(scales) {
        let k = 1.0 + s;
        if !(k.is_finite() && k > 0.0) {
            continue;
        }
        for h in &mut c.h {
            *h *= k;
        }
        let d0 = c.d.first().copied().unwrap_or(0.0);
        for d in &mut c.d {
            *d = d0 + (*d - d0) * k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn form(h: &[f64], b: &[f64], chi2: f64, loops: usize) -> ScaleForm {
        let k = b.len();
        ScaleForm {
            h: DMatrix::from_row_slice(k, k, h),
            b: DVector::from_row_slice(b),
            chi2,
            loops,
        }
    }

    /// A misfit a common scale would explain (the network's size) moves no curve, and with
    /// no more loops than curves nothing is estimated.
    #[test]
    fn a_common_scale_is_left_to_the_wheels_calibration() {
        // Two independent curves, each explaining its share of the misfit by shrinking.
        let f = form(&[2.0, 0.0, 0.0, 2.0], &[2.0, 2.0], 4.0, 10);
        let s = estimate(&f, 0.01, &[1.0, 1.0]).unwrap();
        assert!(s.iter().all(|x| x.abs() < 1e-12), "{s}");
        let few = form(&[2.0, 0.0, 0.0, 2.0], &[2.0, -2.0], 4.0, 2);
        assert!(estimate(&few, 0.01, &[1.0, 1.0]).is_none());
        assert!(estimate(&f, 0.0, &[1.0, 1.0]).is_none());
    }
}
