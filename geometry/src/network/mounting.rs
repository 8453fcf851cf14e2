//! The device's mounting offset, estimated from the network: a small rotation common to every
//! frame in the device's own axes (the sensor tilted in its housing, or the housing on its
//! wheel), of which the node normals show the roll about T and the pitch about B.
//!
//! At a node the curves through it rest on the same surface, so their normals agree (the
//! regression's `E_N`). A frame turned in its own axes by a roll `ρ` about T and a pitch `π`
//! about B reads the normal `N + π T − ρ B` (to first order): at a node where two curves
//! cross, their normals differ by `π (T₁ − T₂) − ρ (B₁ − B₂)` besides their noise, the same
//! `ρ`, `π` at every node. Two crossing directions are enough to tell them apart; curves that
//! never cross at an angle leave them unknown (a singular system: no estimate). Turning every
//! frame back by the estimate leaves the regression the noise alone to tie at the nodes; the
//! pitch otherwise tilts every tangent out of the surface by `π` between the nodes, where the
//! regression's ties do not reach.
//!
//! The yaw `ψ` about N turns the tangents within the surface and is not seen at the nodes;
//! the loops see it ([`estimate_yaw`]): a closed section whose tangents all turn by `ψ` misses
//! its start by about `L sin ψ`, and curves crossing on a curved surface no longer meet where
//! they are tagged. The loops' misfit of the frames turned by `ψ` is a quadratic form in
//! `(cos ψ, sin ψ)` ([`super::poisson::YawForm`]), so its minimum is an eigenvector of a 2 by 2
//! matrix. On a plane every turn in the surface is a rigid motion, and nothing is estimated.
//!
//! ```
//! use nalgebra::{UnitQuaternion, Vector3};
//! use sfs_geometry::network::mounting;
//! use sfs_geometry::network::prefilter::UniformCurve;
//! // A grid of four straight curves on the plane z = 0 (two along x, two along y, crossing
//! // at nodes 1–4), every frame pitched by 2° in its own axes.
//! let offset = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 2f64.to_radians());
//! let curve = |index: usize, yaw: f64, ends: (u32, u32)| UniformCurve {
//!     index,
//!     kind: Default::default(),
//!     d: vec![0.0, 0.1, 0.2],
//!     q: vec![UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * offset; 3],
//!     nodes: vec![(0, ends.0), (2, ends.1)],
//!     h: vec![0.1, 0.1],
//!     w: vec![1.0; 3],
//!     outliers: 0,
//!     kinks: Vec::new(),
//! };
//! let across = std::f64::consts::FRAC_PI_2;
//! let mut curves = vec![
//!     curve(0, 0.0, (1, 2)),
//!     curve(1, 0.0, (3, 4)),
//!     curve(2, across, (1, 3)),
//!     curve(3, across, (2, 4)),
//! ];
//! let est = mounting::estimate(&curves).unwrap();
//! assert!((est.pitch_deg - 2.0).abs() < 1e-6 && est.roll_deg.abs() < 1e-6, "{est:?}");
//! mounting::apply(&mut curves, &est);
//! assert!(curves[0].q[0].angle() < 1e-9);
//! ```

use super::prefilter::UniformCurve;
use super::regression;
use nalgebra::{Matrix2, UnitQuaternion, Vector2, Vector3};
use std::collections::BTreeMap;

/// The estimated offset: the rotation that turned every frame in its own axes (the frames
/// read `true · offset`), degrees, with its standard errors and what it rests on.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MountingEstimate {
    /// About T.
    pub roll_deg: f64,
    /// About B.
    pub pitch_deg: f64,
    /// Standard errors of the two, from the pairs' residual.
    pub roll_sigma_deg: f64,
    pub pitch_sigma_deg: f64,
    /// Pairs of frames at a node it was estimated from.
    pub pairs: usize,
    /// Whether the frames were turned back by it ([`apply`]): when it is at least
    /// [`SIGNIFICANT`] of its standard errors.
    pub applied: bool,
}

/// An offset is applied when it is at least this many of its standard errors (in either of
/// its two angles): an estimate within its noise would only add that noise to every frame.
pub const SIGNIFICANT: f64 = 3.0;

/// Fewest node pairs an estimate rests on.
pub const MIN_PAIRS: usize = 4;

/// A pair whose normals disagree by more than this many times the median pair's, at the
/// first estimate, is left out ([`estimate`]).
pub const OUTLIER: f64 = 4.0;

/// The yaw about N estimated from the loops ([`estimate_yaw`]): the frames read
/// `true · Rz(yaw)`, degrees, with its standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct YawEstimate {
    pub yaw_deg: f64,
    /// The larger of the loops' noise's (as if independent per edge) and the spread of the
    /// curves' shares (each curve's errors hang together along it).
    pub yaw_sigma_deg: f64,
    /// Whether the frames were turned back by it ([`apply_yaw`]): at least [`SIGNIFICANT`]
    /// standard errors, and at most [`MAX_YAW_DEG`].
    pub applied: bool,
}

/// A yaw larger than this is not a mounting offset (the sensor is not turned that far in
/// its housing): something else misfits the loops, and the frames are left as measured.
pub const MAX_YAW_DEG: f64 = 10.0;

/// Fewest curves the yaw's standard error is taken over (the spread of their shares).
pub const MIN_YAW_CURVES: usize = 4;

/// Estimates the yaw about N common to every frame from the loops' misfit as a function of
/// it (`form`, [`super::poisson::PoissonSolver::yaw_form`]): the turn of least misfit. `None`
/// without loops, with fewer than [`MIN_YAW_CURVES`] curves, or where every turn fits alike
/// (a plane).
pub fn estimate_yaw(form: &super::poisson::YawForm) -> Option<YawEstimate> {
    if form.loops == 0 || form.per_curve.len() < MIN_YAW_CURVES {
        return None;
    }
    let m: Matrix2<f64> = form.per_curve.iter().sum();
    if !m.iter().all(|x| x.is_finite()) {
        return None;
    }
    let eig = m.symmetric_eigen();
    let (lo, hi) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    // chi2(ψ* + δ) = λ_lo + (λ_hi − λ_lo) sin² δ.
    let curvature = eig.eigenvalues[hi] - eig.eigenvalues[lo];
    if curvature <= 1e-9 * eig.eigenvalues[hi].abs().max(f64::MIN_POSITIVE) {
        return None;
    }
    let mut u: Vector2<f64> = eig.eigenvectors.column(lo).into();
    if u.x < 0.0 {
        u = -u;
    }
    // The turn that takes the frames back (T → cos ψ T + sin ψ B); the frames read
    // true · Rz(−ψ).
    let psi = u.y.atan2(u.x);
    let du = Vector2::new(-u.y, u.x);
    // Independent noise per edge: var ψ = s² / curvature, s² the misfit per degree of freedom.
    let white = eig.eigenvalues[lo].max(0.0) / (3 * form.loops) as f64 / curvature;
    // The curves' shares of the gradient at ψ* (they sum to 0 there): their spread.
    let cluster = form
        .per_curve
        .iter()
        .map(|mc| (u.dot(&(mc * du))).powi(2))
        .sum::<f64>()
        / (curvature * curvature);
    let sigma = white.max(cluster).sqrt();
    let yaw = -psi;
    if !(yaw.is_finite() && sigma.is_finite()) {
        return None;
    }
    Some(YawEstimate {
        yaw_deg: yaw.to_degrees(),
        yaw_sigma_deg: sigma.to_degrees(),
        applied: yaw.abs() >= SIGNIFICANT * sigma && yaw.to_degrees().abs() <= MAX_YAW_DEG,
    })
}

/// Turns every frame of `curves` (and the frames arriving at their kinks) back by the yaw
/// `est`, about its own N.
pub fn apply_yaw(curves: &mut [UniformCurve], est: &YawEstimate) {
    turn(
        curves,
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -est.yaw_deg.to_radians()),
    );
}

/// The frame pairs at the nodes the regression ties ([`regression::tied`]): every two frames
/// of different curves at a node, at a node a crease passes through only those on the same
/// face.
fn node_pairs(curves: &[UniformCurve]) -> Vec<(UnitQuaternion<f64>, UnitQuaternion<f64>)> {
    let crease = regression::crease_nodes(curves);
    let mut at: BTreeMap<u32, Vec<(usize, UnitQuaternion<f64>)>> = BTreeMap::new();
    for (k, c) in curves.iter().enumerate() {
        for &(i, node) in &c.nodes {
            if let Some(q) = c.q.get(i) {
                at.entry(node).or_default().push((k, *q));
            }
        }
    }
    let mut pairs = Vec::new();
    for (node, frames) in &at {
        for (a, (ka, qa)) in frames.iter().enumerate() {
            for (kb, qb) in &frames[a + 1..] {
                if ka == kb {
                    continue;
                }
                let (na, nb) = (qa * Vector3::z(), qb * Vector3::z());
                if !regression::tied(crease.contains(node), na.dot(&nb)) {
                    continue;
                }
                pairs.push((*qa, *qb));
            }
        }
    }
    pairs
}

/// The roll and pitch (rad) and their covariance from `pairs` turned back by `(roll, pitch)`:
/// one Gauss–Newton step of `Σ |N₁ − N₂|²` over them. `None` when the pairs cannot tell the
/// two angles apart.
fn step(
    pairs: &[(UnitQuaternion<f64>, UnitQuaternion<f64>)],
    roll: f64,
    pitch: f64,
) -> Option<(f64, f64, Matrix2<f64>, f64)> {
    let back = offset(roll, pitch).inverse();
    let (mut ata, mut atb, mut rr) = (Matrix2::<f64>::zeros(), Vector2::<f64>::zeros(), 0.0);
    for (qa, qb) in pairs {
        let (fa, fb) = (qa * back, qb * back);
        let r = fa * Vector3::z() - fb * Vector3::z();
        // d(N)/d(further roll ρ) = −B, d(N)/d(further pitch π) = T (frames read true · offset,
        // so turning back by more lowers them: N − π T + ρ B; the sign is in the update).
        let jr = -(fa * Vector3::y() - fb * Vector3::y());
        let jp = fa * Vector3::x() - fb * Vector3::x();
        let j = [jr, jp];
        for a in 0..2 {
            atb[a] += j[a].dot(&r);
            for b in 0..2 {
                ata[(a, b)] += j[a].dot(&j[b]);
            }
        }
        rr += r.norm_squared();
    }
    let inv = ata.try_inverse()?;
    // r(δ) ≈ r − J δ (turning back further by δ): δ = (JᵀJ)⁻¹ Jᵀ r.
    let d = inv * atb;
    if !(d.x.is_finite() && d.y.is_finite()) {
        return None;
    }
    Some((roll + d.x, pitch + d.y, inv, rr))
}

/// The rotation of a roll `roll` about T then a pitch `pitch` about B, in the frame's axes.
fn offset(roll: f64, pitch: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll)
}

/// Estimates the offset from the normals at the nodes of `curves` (see the module's
/// documentation); `None` with fewer than [`MIN_PAIRS`] pairs, or pairs that cannot tell roll
/// from pitch (curves that cross nowhere at an angle).
pub fn estimate(curves: &[UniformCurve]) -> Option<MountingEstimate> {
    let mut pairs = node_pairs(curves);
    if pairs.len() < MIN_PAIRS {
        return None;
    }
    // A mistyped node pairs two places of the surface: its normals differ by tens of degrees
    // and would pull the estimate (a bowl with one wrong index: a roll of 9°). Pairs more than
    // OUTLIER times the median misfit away are left out, first as measured, then at the
    // estimate, and the estimate made again each time.
    let (mut roll, mut pitch) = (0.0, 0.0);
    for _ in 0..2 {
        let back = offset(roll, pitch).inverse();
        let misfit = |(qa, qb): &(UnitQuaternion<f64>, UnitQuaternion<f64>)| {
            ((qa * back) * Vector3::z() - (qb * back) * Vector3::z()).norm()
        };
        let mut sorted: Vec<f64> = pairs.iter().map(misfit).collect();
        sorted.sort_by(f64::total_cmp);
        let limit = OUTLIER * sorted[sorted.len() / 2];
        pairs.retain(|p| misfit(p) <= limit);
        if pairs.len() < MIN_PAIRS {
            return None;
        }
        for _ in 0..3 {
            (roll, pitch, _, _) = step(&pairs, roll, pitch)?;
        }
    }
    // The covariance and the residual at the estimate: per pair, the difference of two unit
    // normals lies across them (two equations; its part along them is of second order); two
    // unknowns.
    let (_, _, cov, res) = step(&pairs, roll, pitch)?;
    let dof = (2 * pairs.len()).saturating_sub(2).max(1) as f64;
    let s2 = res / dof;
    let (sr, sp) = ((s2 * cov[(0, 0)]).sqrt(), (s2 * cov[(1, 1)]).sqrt());
    let applied = (roll.abs() >= SIGNIFICANT * sr || pitch.abs() >= SIGNIFICANT * sp)
        && roll.is_finite()
        && pitch.is_finite();
    Some(MountingEstimate {
        roll_deg: roll.to_degrees(),
        pitch_deg: pitch.to_degrees(),
        roll_sigma_deg: sr.to_degrees(),
        pitch_sigma_deg: sp.to_degrees(),
        pairs: pairs.len(),
        applied,
    })
}

/// Turns every frame of `curves` (and the frames arriving at their kinks) back by `est`, in
/// its own axes.
pub fn apply(curves: &mut [UniformCurve], est: &MountingEstimate) {
    turn(
        curves,
        offset(est.roll_deg.to_radians(), est.pitch_deg.to_radians()).inverse(),
    );
}

/// Every frame of `curves` (and the frames arriving at their kinks) turned by `back` in its
/// own axes (`q · back`).
fn turn(curves: &mut [UniformCurve], back: UnitQuaternion<f64>) {
    for c in curves {
        for q in c.q.iter_mut() {
            *q *= back;
        }
        for (_, q) in c.kinks.iter_mut() {
            *q *= back;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A grid on the plane z = 0: `m` curves along x and `m` along y, crossing at `m²` nodes,
    /// every frame turned by `noise` (rad, per axis) at random and then by the offset in its
    /// own axes.
    fn grid(m: usize, noise: f64, roll: f64, pitch: f64, seed: u64) -> Vec<UniformCurve> {
        let mut rng = Rng::new(seed);
        let off = offset(roll, pitch);
        let mut curves = Vec::new();
        for (dir, yaw) in [(0, 0.0), (1, std::f64::consts::FRAC_PI_2)] {
            for k in 0..m {
                let q = (0..m)
                    .map(|_| {
                        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
                            * UnitQuaternion::from_scaled_axis(rng.vec3(noise))
                            * off
                    })
                    .collect();
                // Node of the crossing of line k of x with line j of y: k·m + j.
                let nodes = (0..m)
                    .map(|j| {
                        let (a, b) = if dir == 0 { (k, j) } else { (j, k) };
                        (j, (a * m + b) as u32)
                    })
                    .collect();
                curves.push(UniformCurve {
                    index: curves.len(),
                    kind: Default::default(),
                    d: (0..m).map(|j| j as f64 * 0.1).collect(),
                    q,
                    nodes,
                    h: vec![0.1; m - 1],
                    w: vec![1.0; m],
                    outliers: 0,
                    kinks: Vec::new(),
                });
            }
        }
        curves
    }

    /// Issue 52: an offset of 0.8° of roll and −1.7° of pitch (the independent simulator's
    /// rough captures carry up to 2°) is found within 0.35° (about 2.5 standard errors)
    /// through 1° of noise on every frame of a grid of 49 nodes, and applied; a device without
    /// one is left alone.
    #[test]
    fn issue_52_a_mounting_offset_is_found_through_the_noise() {
        let (roll, pitch) = (0.8f64.to_radians(), -1.7f64.to_radians());
        let noise = 1f64.to_radians();
        for seed in 1..=3 {
            let est = estimate(&grid(7, noise, roll, pitch, seed)).expect("an estimate");
            assert_eq!(est.pairs, 49);
            assert!(est.applied, "{est:?}");
            assert!((est.roll_deg - 0.8).abs() < 0.35, "{est:?}");
            assert!((est.pitch_deg + 1.7).abs() < 0.35, "{est:?}");
            let none = estimate(&grid(7, noise, 0.0, 0.0, seed)).expect("an estimate");
            assert!(!none.applied, "{none:?}");
        }
    }

    /// A mistyped node: one curve's frame at a node turned by 40° (a tag at another place of
    /// the surface); the estimate holds.
    #[test]
    fn a_mistyped_node_does_not_pull_the_estimate() {
        let (roll, pitch) = (0.8f64.to_radians(), -1.7f64.to_radians());
        let mut curves = grid(5, 0.5f64.to_radians(), roll, pitch, 4);
        curves[2].q[3] = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 40f64.to_radians())
            * curves[2].q[3];
        let est = estimate(&curves).expect("an estimate");
        assert_eq!(est.pairs, 24, "{est:?}");
        assert!((est.roll_deg - 0.8).abs() < 0.2, "{est:?}");
        assert!((est.pitch_deg + 1.7).abs() < 0.2, "{est:?}");
    }

    /// On a plane every turn of the tangents within the surface is a rigid motion of the
    /// network: the loops cannot see a yaw, and none is estimated.
    #[test]
    fn a_plane_gives_no_yaw() {
        let yawed = |curves: &mut Vec<UniformCurve>| {
            let z = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 2f64.to_radians());
            for c in curves.iter_mut() {
                for q in c.q.iter_mut() {
                    *q *= z;
                }
            }
        };
        for seed in 1..=3 {
            let mut curves = grid(6, 0.5f64.to_radians(), 0.0, 0.0, seed);
            yawed(&mut curves);
            let form = super::super::poisson::PoissonSolver::new()
                .yaw_form(&curves)
                .expect("a form");
            assert!(form.loops > 0);
            let est = estimate_yaw(&form);
            assert!(est.is_none_or(|e| !e.applied), "{est:?}");
        }
    }

    /// Curves that never cross at an angle (all along x, nodes shared end to end) cannot tell
    /// roll from pitch: no estimate.
    #[test]
    fn parallel_curves_give_no_estimate() {
        let mut curves = grid(5, 0.0, 0.01, 0.02, 5);
        curves.truncate(5);
        // Make them share nodes pairwise (a chain of curves along x, each node on two).
        for (k, c) in curves.iter_mut().enumerate() {
            c.nodes = vec![(0, k as u32), (4, k as u32 + 1)];
        }
        assert_eq!(estimate(&curves), None);
    }
}
