//! Fisher's F test: does a fit of `d1` parameters explain more of a misfit than chance would,
//! against what is left per each of `d2` degrees of freedom?
//!
//! Under the null hypothesis (the parameters explain nothing but noise) the statistic
//! `F = (explained / d1) / (left / d2)` follows the F distribution with `(d1, d2)` degrees of
//! freedom; [`upper_tail`] is the chance of an `F` as large or larger, through the
//! regularised incomplete beta function, `P(F > f) = I_x(d2 / 2, d1 / 2)` with
//! `x = d2 / (d2 + d1 f)`.
//!
//! ```
//! use sfs_geometry::f_test::upper_tail;
//! // F(2, d2)'s tail has a closed form, (d2 / (d2 + 2 f))^(d2 / 2).
//! let p = upper_tail(3.0, 2.0, 10.0);
//! assert!((p - (10.0_f64 / 16.0).powf(5.0)).abs() < 1e-12);
//! // Twenty times the noise per parameter is no chance.
//! assert!(upper_tail(20.0, 11.0, 21.0) < 1e-6);
//! ```

/// `P(F > f)` for the F distribution with `(d1, d2)` degrees of freedom (both positive); 1 for
/// `f ≤ 0`, NaN for degrees of freedom that are not positive or an `f` that is NaN.
pub fn upper_tail(f: f64, d1: f64, d2: f64) -> f64 {
    if !(d1 > 0.0 && d2 > 0.0) || f.is_nan() {
        return f64::NAN;
    }
    if f <= 0.0 {
        return 1.0;
    }
    if f.is_infinite() {
        return 0.0;
    }
    regularized_beta(d2 / (d2 + d1 * f), 0.5 * d2, 0.5 * d1)
}

/// `I_x(a, b)`, the regularised incomplete beta function, for `0 ≤ x ≤ 1` and `a, b > 0`: its
/// continued fraction where it converges fast (`x < (a + 1) / (a + b + 2)`), otherwise
/// through `I_x(a, b) = 1 − I_{1−x}(b, a)`.
fn regularized_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front =
        (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_fraction(x, a, b) / a
    } else {
        1.0 - front * beta_fraction(1.0 - x, b, a) / b
    }
}

/// The continued fraction of the incomplete beta function (modified Lentz's method).
fn beta_fraction(x: f64, a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-300;
    const EPS: f64 = 1e-15;
    let guard = |v: f64| if v.abs() < TINY { TINY } else { v };
    let mut c = 1.0;
    let mut d = 1.0 / guard(1.0 - (a + b) * x / (a + 1.0));
    let mut h = d;
    for m in 1..=300 {
        let m = f64::from(m);
        // The even step, then the odd one.
        let even = m * (b - m) * x / ((a + 2.0 * m - 1.0) * (a + 2.0 * m));
        d = 1.0 / guard(1.0 + even * d);
        c = guard(1.0 + even / c);
        h *= d * c;
        let odd = -(a + m) * (a + b + m) * x / ((a + 2.0 * m) * (a + 2.0 * m + 1.0));
        d = 1.0 / guard(1.0 + odd * d);
        c = guard(1.0 + odd / c);
        let step = d * c;
        h *= step;
        if (step - 1.0).abs() < EPS {
            break;
        }
    }
    h
}

/// `ln Γ(x)` for `x > 0` (Lanczos' approximation, g = 7, nine terms; relative error below
/// 1e-15 over the degrees of freedom used here).
fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(π x).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut sum = C[0];
    for (i, &c) in C.iter().enumerate().skip(1) {
        sum += c / (x + i as f64);
    }
    let t = x + G + 0.5;
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_gamma_of_integers_and_a_half_is_exact() {
        let mut factorial = 1.0_f64;
        for n in 1..20 {
            assert!(
                (ln_gamma(f64::from(n)) - factorial.ln()).abs() < 1e-12,
                "Γ({n})"
            );
            factorial *= f64::from(n);
        }
        let half = std::f64::consts::PI.sqrt().ln();
        assert!((ln_gamma(0.5) - half).abs() < 1e-13);
        assert!((ln_gamma(1.5) - (0.5 * std::f64::consts::PI.sqrt()).ln()).abs() < 1e-13);
    }

    /// The tails with closed forms: `d1 = 2`, `d2 = 2`, and `F(1, 1)` (a Cauchy variable,
    /// squared), over the range of `f` a test meets; and `P(F(d1, d2) > f) = 1 − P(F(d2, d1) >
    /// 1 / f)` where neither has one.
    #[test]
    fn the_tail_matches_its_closed_forms() {
        for &f in &[0.01_f64, 0.3, 1.0, 2.5, 7.0, 40.0, 900.0] {
            for &d2 in &[1.0_f64, 3.0, 16.0, 21.0, 60.0] {
                let want = (d2 / (d2 + 2.0 * f)).powf(0.5 * d2);
                let got = upper_tail(f, 2.0, d2);
                assert!(
                    (got - want).abs() < 1e-12 * want.max(1e-3),
                    "F(2, {d2}) > {f}: {got} for {want}"
                );
            }
            for &d1 in &[1.0_f64, 3.0, 11.0, 40.0] {
                let want = 1.0 - (d1 * f / (d1 * f + 2.0)).powf(0.5 * d1);
                let got = upper_tail(f, d1, 2.0);
                assert!(
                    (got - want).abs() < 1e-12,
                    "F({d1}, 2) > {f}: {got} for {want}"
                );
            }
            let cauchy = 1.0 - 2.0 / std::f64::consts::PI * f.sqrt().atan();
            assert!((upper_tail(f, 1.0, 1.0) - cauchy).abs() < 1e-12);
            for &(d1, d2) in &[(11.0, 21.0), (7.0, 16.0), (11.0, 3.0), (4.5, 9.5)] {
                let p = upper_tail(f, d1, d2);
                let q = upper_tail(1.0 / f, d2, d1);
                assert!(
                    (p + q - 1.0).abs() < 1e-12,
                    "({d1}, {d2}) at {f}: {p} + {q}"
                );
                assert!((0.0..=1.0).contains(&p));
            }
        }
    }

    #[test]
    fn the_tail_falls_with_f_and_says_so_at_the_ends() {
        let mut last = 1.0;
        for i in 0..200 {
            let p = upper_tail(0.05 * f64::from(i), 11.0, 21.0);
            assert!(p <= last + 1e-15, "not falling at {i}");
            last = p;
        }
        assert_eq!(upper_tail(0.0, 3.0, 4.0), 1.0);
        assert_eq!(upper_tail(-1.0, 3.0, 4.0), 1.0);
        assert_eq!(upper_tail(f64::INFINITY, 3.0, 4.0), 0.0);
        assert!(upper_tail(f64::NAN, 3.0, 4.0).is_nan());
        assert!(upper_tail(1.0, 0.0, 4.0).is_nan());
    }
}
