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
//! loops show (`chi2 / (loops − curves)` per degree of freedom left; `3 loops − curves`
//! where that leaves none, [`degrees_of_freedom`], and then only scales an F test finds
//! significant), and the length-weighted mean scale held at 0: a scale common to every
//! curve only scales the misfit, so the loops would shrink the network to a point, and the
//! network's size is the wheel's calibration, not theirs.
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
use crate::f_test;
use nalgebra::{DMatrix, DVector};

/// A wheel's spread of scale from curve to curve: the independent simulator's rough
/// Morphorider reads its curves 0.9 % long or short (RMS; −1.9 to +1.6 %, each the same along
/// its curve to 0.1–0.2 %), ours 0.5 % (BENCHMARKS.md, Field accuracy III).
pub const WHEEL_SIGMA: f64 = 0.01;

/// The scale of each curve (in the order of `form`), `None` with fewer than two curves, no
/// degree of freedom left ([`degrees_of_freedom`]), scales that explain the misfit no better
/// than chance where the loops are no more than the curves, or a singular system. `sigma` is
/// the prior spread of a curve's scale (a fraction), `lengths` each curve's length (m), the
/// weights of the mean held at 0.
pub fn estimate(form: &ScaleForm, sigma: f64, lengths: &[f64]) -> Option<DVector<f64>> {
    let k = form.b.len();
    let total: f64 = lengths.iter().sum();
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if k < 2 || !positive(sigma) || lengths.len() != k || !positive(total) {
        return None;
    }
    let dof = degrees_of_freedom(form.loops, k)? as f64;
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
    if !s.iter().all(|x| x.is_finite()) {
        return None;
    }
    // Counted three a loop, the loops are trusted more than their one main cause earns: the
    // scales are kept only where they explain the misfit better than chance would (on our
    // field profile's roof, the headings near a magnet made most of it, and scales fitted to
    // them were 0.3–0.5 % the wrong way).
    if three_per_loop(form.loops, k) {
        let left = noise * dof;
        let f = ((form.chi2 - left).max(0.0) / (k - 1) as f64) / (left / dof);
        let chance = f_test::upper_tail(f, (k - 1) as f64, dof);
        if chance.is_nan() || chance > SIGNIFICANCE {
            return None;
        }
    }
    Some(s)
}

/// The degrees of freedom the loops leave once `curves` scales are fitted: one per loop, or,
/// where that leaves none, three per loop; `None` where even three leave none.
///
/// A loop's misfit is 3-D, but one cause mostly makes it (a curve's heading turns it within
/// the surface, one direction): a degree of freedom per loop. Counting three trusts the loops
/// three times as much: measured, hardly better where the one count leaves some, and worse
/// where a network has barely more loops than curves (BENCHMARKS.md, Field accuracy III).
/// Where it leaves none (the box: twelve curves, eleven loops), the misfit's three
/// components are what there is, and [`estimate`] then keeps the scales only where an F test
/// says they explain the misfit ([`SIGNIFICANCE`]).
pub fn degrees_of_freedom(loops: usize, curves: usize) -> Option<usize> {
    if three_per_loop(loops, curves) {
        (3 * loops).checked_sub(curves).filter(|&d| d > 0)
    } else {
        Some(loops - curves)
    }
}

/// Whether the loops' misfit is counted three degrees of freedom a loop: where one a loop
/// leaves none ([`degrees_of_freedom`]; [`estimate`] then tests the scales).
fn three_per_loop(loops: usize, curves: usize) -> bool {
    loops <= curves
}

/// Where the loops are no more than the curves, the chance (Fisher's F test, the `curves − 1`
/// free scales against the degrees of freedom left) below which the scales' share of the
/// misfit is taken as theirs, not the noise's.
pub const SIGNIFICANCE: f64 = 0.01;

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
    /// no degree of freedom left nothing is estimated.
    #[test]
    fn a_common_scale_is_left_to_the_wheels_calibration() {
        // Two independent curves, each explaining its share of the misfit by shrinking.
        let f = form(&[2.0, 0.0, 0.0, 2.0], &[2.0, 2.0], 4.0, 10);
        let s = estimate(&f, 0.01, &[1.0, 1.0]).unwrap();
        assert!(s.iter().all(|x| x.abs() < 1e-12), "{s}");
        let few = form(&[2.0, 0.0, 0.0, 2.0], &[2.0, -2.0], 4.0, 0);
        assert!(estimate(&few, 0.01, &[1.0, 1.0]).is_none());
        assert!(estimate(&f, 0.0, &[1.0, 1.0]).is_none());
    }

    /// One per loop where that leaves some; three per loop where it leaves none (issue 52:
    /// the box's 12 curves and 11 loops had no estimate); none where even three leave none.
    #[test]
    fn three_per_loop_only_where_one_per_loop_leaves_none() {
        assert_eq!(degrees_of_freedom(4, 3), Some(1));
        assert_eq!(degrees_of_freedom(40, 20), Some(20));
        assert_eq!(degrees_of_freedom(11, 12), Some(21));
        assert_eq!(degrees_of_freedom(3, 3), Some(6));
        assert_eq!(degrees_of_freedom(1, 3), None);
        assert_eq!(degrees_of_freedom(0, 2), None);
    }

    /// With no more loops than curves, scales are kept only where they explain the misfit
    /// better than chance: three curves, three loops, the misfit all one curve's scale, then
    /// hardly any of it.
    #[test]
    fn with_few_loops_only_scales_that_explain_the_misfit_are_kept() {
        let h = [1e4, 0.0, 0.0, 0.0, 1e4, 0.0, 0.0, 0.0, 1e4];
        // Curve 0 reads 0.4 % long against the others: b = −H s, chi2 = sᵀHs + what is left.
        let explained = form(&h, &[40.0, -20.0, -20.0], 0.24 + 1e-4, 3);
        let s = estimate(&explained, 0.01, &[1.0, 1.0, 1.0]).expect("kept");
        assert!(s[0] < -0.003 && s[1] > 0.001 && s[2] > 0.001, "{s}");
        // The same misfit, of which a scale would explain a thousandth.
        let noise = form(&h, &[0.4, -0.2, -0.2], 0.24, 3);
        assert!(estimate(&noise, 0.01, &[1.0, 1.0, 1.0]).is_none());
        // With more loops than curves the scales are not tested (as before).
        let more = form(&h, &[0.4, -0.2, -0.2], 0.24, 10);
        assert!(estimate(&more, 0.01, &[1.0, 1.0, 1.0]).is_some());
    }
}
