//! Pre-filter (§4.2 of the paper): per curve, outlier removal, averaging of duplicates, and
//! Gaussian-weighted resampling at a uniform step per segment (`N = round(L/h)` per segment,
//! so that every node lands on a sample).
//!
//! The kernel `exp(−½((t_k − d_i)/(σh))²)` is truncated at 3σh and evaluated over the raw
//! samples sorted by distance, found by binary search: no all-pairs loop. Each raw sample's
//! weight (from its flags) and its share of the curve (half the distance to its neighbours: a
//! quadrature weight, so that where the operator slowed down the denser samples do not pull
//! the mean; the paper weights by the kernel alone) multiply the kernel.

use crate::curve::Curve;
use crate::qmethod::StructureTensor;
use nalgebra::{Quaternion, UnitQuaternion};

/// Pre-filter parameters (documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrefilterParams {
    /// Target sampling step h, m. Default 0.01.
    pub h: f64,
    /// Kernel width in units of h. Default 0.3 (the paper uses 0.2–0.5).
    pub sigma: f64,
    /// Outlier threshold on |q_i · q_{i±1}|. Default 0.9.
    pub alpha: f64,
}

impl Default for PrefilterParams {
    fn default() -> Self {
        PrefilterParams {
            h: 0.01,
            sigma: 0.3,
            alpha: 0.9,
        }
    }
}

/// A curve resampled uniformly per segment.
#[derive(Debug, Clone, PartialEq)]
pub struct UniformCurve {
    pub index: usize,
    pub kind: crate::curve::CurveKind,
    /// Distance of every sample from the first node, m.
    pub d: Vec<f64>,
    /// Orientation of the frame [T B N] at every sample.
    pub q: Vec<UnitQuaternion<f64>>,
    /// `(sample index, node)` of every tag, in order (first at 0, last at the end).
    pub nodes: Vec<(usize, u32)>,
    /// Step of the segment that starts at each node (one per segment).
    pub h: Vec<f64>,
    /// Reliability of every sample in [0, 1]: the kernel-weighted mean of the raw samples'
    /// weights (low where every raw sample was flagged, e.g. near a magnet), lowered further
    /// across gaps in the data. The regression trusts the data that much.
    pub w: Vec<f64>,
    /// Raw samples removed as outliers.
    pub outliers: usize,
    /// Samples at a node where the curve's tangent jumps (a crease's corner, a curve crossing
    /// a crease, a corner where the device turned in place: [`KINK_DEG`]), with the frame
    /// arriving there (`q` holds the one leaving); `0` for a closed curve whose loop closes at
    /// such a node (its last sample arrives).
    pub kinks: Vec<(usize, UnitQuaternion<f64>)>,
}

/// At a node a crease passes through, a curve whose tangent turns by more than this (between
/// the samples half a step to two steps before and after) has a kink there: each side is
/// resampled from its own samples, degrees. At any other node, only where the device also
/// turned in place by more than this while it stood there (a boundary's corner: issue 52;
/// rolled over a bend, it turns as it moves) or, for a loop's closing node, where its ends
/// turn by more than [`CLOSING_KINK_DEG`].
pub const KINK_DEG: f64 = 15.0;

/// A loop closing at a node no crease passes through kinks there when its tangents leaving
/// and arriving (compared as for [`KINK_DEG`]) turn by more than this, degrees: a boundary's
/// corner (the independent simulator's saddle: 85°), not a tight bend (the bumpy cube's
/// sections, closing on a rounded edge: 22°).
pub const CLOSING_KINK_DEG: f64 = 45.0;

impl UniformCurve {
    /// The frame arriving at sample `j` (the one leaving it, `q[j]`, unless a kink is there).
    pub fn arriving(&self, j: usize) -> UnitQuaternion<f64> {
        self.kinks
            .iter()
            .find(|k| k.0 == j && j > 0)
            .map_or(self.q[j], |k| k.1)
    }

    /// A kink at sample `j`.
    pub fn kinked(&self, j: usize) -> bool {
        self.kinks.iter().any(|k| k.0 == j)
    }

    /// The step of the edge from sample `j` to `j + 1` (the nodes' samples increase along
    /// the curve: a binary search).
    pub fn edge_h(&self, j: usize) -> f64 {
        let seg = segment_of(&self.nodes, self.h.len().max(1), j);
        self.h[seg]
    }

    /// [`edge_h`](Self::edge_h) of every edge in order (from sample 0 to 1, 1 to 2, …), in
    /// one pass along the tags.
    pub fn edge_steps(&self) -> impl Iterator<Item = f64> + '_ {
        let segments = self.h.len().max(1);
        // The tags at samples up to j (`segment_of`'s partition point).
        let mut upto = 0;
        (0..self.q.len().saturating_sub(1)).map(move |j| {
            while upto < self.nodes.len() && self.nodes[upto].0 <= j {
                upto += 1;
            }
            self.h[upto.saturating_sub(1).min(segments - 1)]
        })
    }

    /// Length, m.
    pub fn length(&self) -> f64 {
        self.d.last().copied().unwrap_or(0.0) - self.d.first().copied().unwrap_or(0.0)
    }
}

/// Why a curve cannot be resampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrefilterError {
    #[error("curve {curve}: {tags} node tag(s); at least two are needed")]
    TooFewNodes { curve: usize, tags: usize },
    #[error("curve {curve}: {length:.4} m long, shorter than 2h = {min:.4} m")]
    TooShort { curve: usize, length: f64, min: f64 },
    #[error("curve {curve}: no usable orientation (every sample flagged invalid)")]
    NoSamples { curve: usize },
    #[error(
        "curve {curve}: node {node} at {d:.4} m comes before the previous node (backwards segment)"
    )]
    Backwards { curve: usize, node: u32, d: f64 },
    #[error("curve {curve}: nodes {a} and {b} are tagged {length:.4} m apart (less than 1 mm)")]
    EmptySegment {
        curve: usize,
        a: u32,
        b: u32,
        length: f64,
    },
    #[error("curve {curve}: {length:.1} m long at h = {h} m would take more than {max} samples")]
    TooLong {
        curve: usize,
        length: f64,
        h: f64,
        max: usize,
    },
}

impl PrefilterError {
    /// The curve it is about.
    pub fn curve(&self) -> usize {
        match *self {
            PrefilterError::TooFewNodes { curve, .. }
            | PrefilterError::TooShort { curve, .. }
            | PrefilterError::NoSamples { curve }
            | PrefilterError::Backwards { curve, .. }
            | PrefilterError::EmptySegment { curve, .. }
            | PrefilterError::TooLong { curve, .. } => curve,
        }
    }
}

/// Shortest segment between two consecutive node tags, m.
pub const MIN_SEGMENT: f64 = 0.001;

/// Most uniform samples one curve may have (a corrupted distance must not exhaust memory).
pub const MAX_SAMPLES_PER_CURVE: usize = 1_000_000;

fn quat(a: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(a[0], a[1], a[2], a[3]))
}

/// Resamples one curve.
pub fn prefilter(c: &Curve, p: &PrefilterParams) -> Result<UniformCurve, PrefilterError> {
    prefilter_with_kinks(c, p, &[])
}

/// Resamples one curve, allowing kinks ([`KINK_DEG`]) at the nodes `kink_nodes` (those a
/// crease passes through) and at its corners turned in place.
pub fn prefilter_with_kinks(
    c: &Curve,
    p: &PrefilterParams,
    kink_nodes: &[u32],
) -> Result<UniformCurve, PrefilterError> {
    let length = check(c, p)?;
    let (raw, outliers) = usable_samples(c, p);
    if raw.is_empty() {
        return Err(PrefilterError::NoSamples { curve: c.index });
    }
    let (uniq, turns) = merge_duplicates(raw);
    let ds: Vec<f64> = uniq.iter().map(|u| u.0).collect();
    let spacing = quadrature_weights(&ds);
    let grid = UniformGrid::of(c, p);
    let closed = c.tags.first().map(|t| t.node) == c.tags.last().map(|t| t.node);
    let kink_at = grid.kinks(kink_nodes, closed, &uniq, &ds, &turns);
    let UniformGrid { d, nodes, hs } = grid;
    // The distances each sample's kernel may use: between the kinks around it (the standing
    // samples at a kink, turning from one way to the other, on neither side).
    let eps = |j: usize| 0.1 * hs[segment_of(&nodes, hs.len(), j)];
    let range_of = |j: usize, arriving: bool| -> (f64, f64) {
        let mut lo = f64::NEG_INFINITY;
        let mut hi = f64::INFINITY;
        for &kk in &kink_at {
            let dk = d[kk];
            // (A loop closing at a kink, at sample 0, bounds only its first sample.)
            if (kk < j || (kk == j && !arriving)) && (kk > 0 || j == 0) {
                lo = lo.max(dk + eps(kk));
            }
            if kk > j || (kk == j && arriving) {
                hi = hi.min(dk - eps(kk.saturating_sub(1)));
            }
        }
        (lo, hi)
    };
    // Gaussian-weighted q-method means.
    let mut q = Vec::with_capacity(d.len());
    let mut rel = Vec::with_capacity(d.len());
    let mut kinks = Vec::new();
    let mut last = uniq[0].1;
    for (k, &t) in d.iter().enumerate() {
        let width = p.sigma * hs[segment_of(&nodes, hs.len(), k)];
        // At an interior kink: the frame arriving first (from the samples before), then the
        // one leaving.
        if kink_at.contains(&k) && k > 0 {
            let (lo_d, hi_d) = range_of(k, true);
            let (m, _) = kernel_mean(&uniq, &ds, &spacing, t, width, length, (lo_d, hi_d), &last);
            kinks.push((k, m));
        }
        let (lo_d, hi_d) = range_of(k, false);
        let (mean, reliability) =
            kernel_mean(&uniq, &ds, &spacing, t, width, length, (lo_d, hi_d), &last);
        last = mean;
        q.push(mean);
        rel.push(reliability.clamp(0.0, 1.0));
    }
    if kink_at.contains(&0) && closed {
        kinks.insert(0, (0, *q.last().expect("samples")));
    }
    Ok(UniformCurve {
        index: c.index,
        kind: c.kind,
        d,
        q,
        nodes,
        h: hs,
        w: rel,
        outliers,
        kinks,
    })
}

/// The segment (between two node tags) that uniform sample `j` lies in: the last whose start
/// node is at or before it, of `segments` (the nodes' samples increase: a binary search).
fn segment_of(nodes: &[(usize, u32)], segments: usize, j: usize) -> usize {
    nodes
        .partition_point(|&(i, _)| i <= j)
        .saturating_sub(1)
        .min(segments - 1)
}

/// Whether a curve can be resampled: two tags at least, long enough, its tags in order and
/// apart, not too long for the step. Returns its length.
fn check(c: &Curve, p: &PrefilterParams) -> Result<f64, PrefilterError> {
    if c.tags.len() < 2 {
        return Err(PrefilterError::TooFewNodes {
            curve: c.index,
            tags: c.tags.len(),
        });
    }
    let length = c.length();
    if length.is_nan() || length < 2.0 * p.h {
        return Err(PrefilterError::TooShort {
            curve: c.index,
            length,
            min: 2.0 * p.h,
        });
    }
    for w in c.tags.windows(2) {
        if w[1].d < w[0].d {
            return Err(PrefilterError::Backwards {
                curve: c.index,
                node: w[1].node,
                d: w[1].d,
            });
        }
    }
    // A segment of (almost) no length has no step to sample it with (and would stall the
    // kernel search below): two nodes tagged without moving.
    if let Some(w) = c.tags.windows(2).find(|w| {
        let l = w[1].d - w[0].d;
        l.is_nan() || l < MIN_SEGMENT
    }) {
        return Err(PrefilterError::EmptySegment {
            curve: c.index,
            a: w[0].node,
            b: w[1].node,
            length: w[1].d - w[0].d,
        });
    }
    if length / p.h > MAX_SAMPLES_PER_CURVE as f64 {
        return Err(PrefilterError::TooLong {
            curve: c.index,
            length,
            h: p.h,
            max: MAX_SAMPLES_PER_CURVE,
        });
    }
    Ok(length)
}

/// A raw sample: distance, orientation, weight.
type RawSample = (f64, UnitQuaternion<f64>, f64);

/// The usable raw samples in time order (weighted, at a finite distance), without the
/// outliers (far from both neighbours in time order, by `p.alpha`); and how many outliers.
fn usable_samples(c: &Curve, p: &PrefilterParams) -> (Vec<RawSample>, usize) {
    let s = &c.samples;
    let mut raw: Vec<RawSample> = (0..s.len())
        .filter(|&i| s.w.get(i).copied().unwrap_or(1.0) > 0.0 && s.d[i].is_finite())
        .map(|i| (s.d[i], quat(&s.q[i]), s.w.get(i).copied().unwrap_or(1.0)))
        .collect();
    let mut outliers = 0;
    if raw.len() >= 3 {
        let keep: Vec<bool> = (0..raw.len())
            .map(|i| {
                if i == 0 || i + 1 == raw.len() {
                    return true;
                }
                let dot = |a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>| {
                    a.coords.dot(&b.coords).abs()
                };
                !(dot(&raw[i].1, &raw[i - 1].1) < p.alpha
                    && dot(&raw[i].1, &raw[i + 1].1) < p.alpha)
            })
            .collect();
        outliers = keep.iter().filter(|k| !**k).count();
        let mut it = keep.iter();
        raw.retain(|_| *it.next().expect("same length"));
    }
    (raw, outliers)
}

/// The samples sorted by distance, duplicates (same distance: the device stood still) made
/// one sample: their mean orientation with their mean weight. Beside each, how far the
/// device's tangent turned while it stood there (radians, [`turn_in_place`]; 0 for a sample
/// alone).
fn merge_duplicates(mut raw: Vec<RawSample>) -> (Vec<RawSample>, Vec<f64>) {
    // A stable sort: samples of one distance stay in time order.
    raw.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut uniq: Vec<RawSample> = Vec::with_capacity(raw.len());
    let mut turns: Vec<f64> = Vec::with_capacity(raw.len());
    let mut i = 0;
    while i < raw.len() {
        let mut j = i + 1;
        while j < raw.len() && raw[j].0 == raw[i].0 {
            j += 1;
        }
        if j - i == 1 {
            uniq.push(raw[i]);
            turns.push(0.0);
        } else {
            let mut t = StructureTensor::new();
            for r in &raw[i..j] {
                t.add(&r.1, 1.0);
            }
            let w = raw[i..j].iter().map(|r| r.2).sum::<f64>() / (j - i) as f64;
            if let Some(q) = t.mean() {
                uniq.push((raw[i].0, q, w));
                turns.push(turn_in_place(&raw[i..j]));
            }
        }
        i = j;
    }
    (uniq, turns)
}

/// How far the device turned in place while standing at one distance (samples in time order),
/// radians: the tangent of the last [`TURN_ENDS`] samples against the first's, turned about
/// the first's normal. A hand that tilts the device while typing turns it about a level axis
/// (not counted), and puts it back.
fn turn_in_place(stand: &[RawSample]) -> f64 {
    let k = TURN_ENDS.min(stand.len() / 2);
    if k == 0 {
        return 0.0;
    }
    let mean = |s: &[RawSample], axis: nalgebra::Vector3<f64>| -> nalgebra::Vector3<f64> {
        s.iter().map(|r| r.1 * axis).sum::<nalgebra::Vector3<f64>>()
    };
    let (x, y) = (nalgebra::Vector3::x(), nalgebra::Vector3::y());
    let (Some(t0), Some(t1)) = (
        mean(&stand[..k], x).try_normalize(1e-12),
        mean(&stand[stand.len() - k..], x).try_normalize(1e-12),
    ) else {
        return 0.0;
    };
    let b = mean(&stand[..k], y);
    let Some(b0) = (b - t0 * t0.dot(&b)).try_normalize(1e-12) else {
        return 0.0;
    };
    t1.dot(&b0).atan2(t1.dot(&t0)).abs()
}

/// Samples averaged at either end of a stand to tell its turn ([`turn_in_place`]).
const TURN_ENDS: usize = 5;

/// Quadrature weights of samples at distances `ds` (sorted): the kernel integrates over
/// distance, so each sample stands for the stretch of curve around it (where the operator
/// slowed down, samples are denser; without this the mean is pulled towards them).
fn quadrature_weights(ds: &[f64]) -> Vec<f64> {
    let m = ds.len();
    (0..m)
        .map(|i| {
            let a = if i > 0 { ds[i] - ds[i - 1] } else { 0.0 };
            let b = if i + 1 < m { ds[i + 1] - ds[i] } else { 0.0 };
            match (i > 0, i + 1 < m) {
                (true, true) => (a + b) / 2.0,
                (true, false) => a,
                (false, true) => b,
                (false, false) => 1.0,
            }
        })
        .collect()
}

/// The uniform parameters of a curve: each segment between node tags cut into steps of
/// about `h`.
struct UniformGrid {
    /// The samples' distances.
    d: Vec<f64>,
    /// `(sample, node)` of each tag.
    nodes: Vec<(usize, u32)>,
    /// Each segment's step.
    hs: Vec<f64>,
}

impl UniformGrid {
    fn of(c: &Curve, p: &PrefilterParams) -> Self {
        let mut d = Vec::new();
        let mut nodes = Vec::new();
        let mut hs = Vec::new();
        for (k, w) in c.tags.windows(2).enumerate() {
            let l = w[1].d - w[0].d;
            let n = ((l / p.h).round() as usize).max(1);
            let h = l / n as f64;
            if k == 0 {
                nodes.push((0, w[0].node));
                d.push(w[0].d);
            }
            for j in 1..=n {
                d.push(w[0].d + h * j as f64);
            }
            nodes.push((d.len() - 1, w[1].node));
            hs.push(h);
        }
        UniformGrid { d, nodes, hs }
    }

    /// The samples (indices) at a kink: where the mean tangents of the raw samples `uniq` (at
    /// distances `ds`) half a step to two steps before and after turn by more than
    /// [`KINK_DEG`], at the nodes `kink_nodes`, or at others where the samples standing there
    /// turned in place (`turns`, per sample of `uniq`) by more than it too; at a loop's
    /// closing node, by more than [`CLOSING_KINK_DEG`].
    fn kinks(
        &self,
        kink_nodes: &[u32],
        closed: bool,
        uniq: &[RawSample],
        ds: &[f64],
        turns: &[f64],
    ) -> Vec<usize> {
        let (d, hs) = (&self.d, &self.hs);
        let tangent_between = |a: f64, b: f64| -> Option<nalgebra::Vector3<f64>> {
            let (lo, hi) = (
                ds.partition_point(|&x| x < a),
                ds.partition_point(|&x| x <= b),
            );
            let sum: nalgebra::Vector3<f64> = uniq[lo..hi]
                .iter()
                .map(|u| u.1 * nalgebra::Vector3::x())
                .sum();
            sum.try_normalize(1e-12)
        };
        let kink_cos = KINK_DEG.to_radians().cos();
        let mut kink_at: Vec<usize> = Vec::new();
        for (k, &(i, node)) in self.nodes.iter().enumerate() {
            let last_tag = k + 1 == self.nodes.len();
            if last_tag {
                continue;
            }
            let dn = d[i];
            let hb = if k > 0 { hs[k - 1] } else { hs[hs.len() - 1] };
            let ha = hs[k];
            // On a crease, the tangents alone tell. Elsewhere the device turned in place at
            // the node (a corner of a boundary): its samples standing there turn by more than
            // a kink. A loop that closes at a corner is not turned there (it sets off along one
            // side and stops coming in along the other): its two ends' tangents alone tell, by
            // more than a tight bend turns them ([`CLOSING_KINK_DEG`]).
            let limit_cos = if kink_nodes.contains(&node) {
                kink_cos
            } else if closed && k == 0 {
                CLOSING_KINK_DEG.to_radians().cos()
            } else {
                let near = 0.1 * ha.min(hb);
                let (lo, hi) = (
                    ds.partition_point(|&x| x < dn - near),
                    ds.partition_point(|&x| x <= dn + near),
                );
                if !turns[lo..hi].iter().any(|&t| t > KINK_DEG.to_radians()) {
                    continue;
                }
                kink_cos
            };
            let before = if k > 0 {
                tangent_between(dn - 2.0 * hb, dn - 0.5 * hb)
            } else if closed {
                let end = d[d.len() - 1];
                tangent_between(end - 2.0 * hb, end - 0.5 * hb)
            } else {
                None
            };
            let after = tangent_between(dn + 0.5 * ha, dn + 2.0 * ha);
            if let (Some(b), Some(a)) = (before, after) {
                if b.dot(&a) < limit_cos {
                    kink_at.push(i);
                }
            }
        }
        kink_at
    }
}

/// The Gaussian-weighted q-method mean of the raw samples around `t` (kernel width `width`)
/// whose distances lie in `range` (all of them if none does), and its reliability; the
/// window widens over gaps in the data.
#[allow(clippy::too_many_arguments)]
fn kernel_mean(
    uniq: &[RawSample],
    ds: &[f64],
    spacing: &[f64],
    t: f64,
    width: f64,
    length: f64,
    range: (f64, f64),
    last: &UnitQuaternion<f64>,
) -> (UnitQuaternion<f64>, f64) {
    let (r_lo, r_hi) = (
        ds.partition_point(|&x| x < range.0),
        ds.partition_point(|&x| x <= range.1),
    );
    let (r_lo, r_hi) = if r_lo < r_hi {
        (r_lo, r_hi)
    } else {
        (0, ds.len())
    };
    let mut radius = (3.0 * width).max(1e-9);
    loop {
        let lo = ds.partition_point(|&x| x < t - radius).max(r_lo);
        let hi = ds.partition_point(|&x| x <= t + radius).min(r_hi).max(lo);
        let mut ten = StructureTensor::new();
        let (mut kw, mut k) = (0.0, 0.0);
        // The kernel widens with the window (3σ = radius), so that a gap in the data is
        // bridged by the nearest samples rather than by weights that underflow.
        let kernel_width = (radius / 3.0).max(1e-12);
        for (u, dd) in uniq[lo..hi].iter().zip(&spacing[lo..hi]) {
            let z = (t - u.0) / kernel_width;
            let kernel = dd.max(1e-12) * (-0.5 * z * z).exp();
            ten.add(&u.1, u.2 * kernel);
            kw += u.2 * kernel;
            k += kernel;
        }
        // A gap in the data: widen the window (and the kernel with it) until it holds
        // samples, up to the whole curve.
        match ten.mean_near(last) {
            Some(m) if ten.weight() > 1e-12 => return (m, (kw / k) * (3.0 * width / radius)),
            _ if radius > 2.0 * length + 1.0 => return (*last, 0.0),
            _ => radius *= 2.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curve::{Samples, Tag};
    use nalgebra::Vector3;

    fn curve(n: usize, speed_profile: impl Fn(f64) -> f64) -> Curve {
        // A frame turning steadily about z while the distance advances unevenly; node 0 at
        // 0 m, node 1 at 0.5 m, node 2 at 1 m.
        let mut s = Samples::default();
        for i in 0..=n {
            let u = i as f64 / n as f64;
            let d = speed_profile(u);
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d);
            s.t.push(u);
            s.d.push(d);
            s.q.push([q.w, q.i, q.j, q.k]);
            s.flags.push(0);
            s.w.push(1.0);
        }
        Curve {
            index: 0,
            kind: crate::curve::CurveKind::Interior,
            closed: false,
            tags: vec![
                Tag {
                    node: 0,
                    d: 0.0,
                    t: 0.0,
                    uncertain: false,
                },
                Tag {
                    node: 1,
                    d: speed_profile(0.5),
                    t: 0.5,
                    uncertain: false,
                },
                Tag {
                    node: 2,
                    d: speed_profile(1.0),
                    t: 1.0,
                    uncertain: false,
                },
            ],
            segment_lengths: vec![None, None],
            samples: s,
        }
    }

    /// The frame turns 1 rad/m: inside, the symmetric kernel is unbiased; within 3σh of an end
    /// it is one-sided and lags by up to about σh·√(2/π) (the paper's method; a real scan
    /// stands still at its end nodes, which removes most of it).
    fn tolerance(d: f64, end: f64) -> f64 {
        let sh = 0.3 * 0.01;
        if d < 3.0 * sh || d > end - 3.0 * sh {
            3e-3
        } else {
            2e-4
        }
    }

    /// Issue 18: a corner at a node a crease passes through. The frame heads along x up to
    /// node 1 (0.5 m), stands there turning 90° about z (a box's corner: the device turned in
    /// place), then heads along y. Allowed a kink there, the node keeps both frames exactly
    /// and the samples either side are their side's; not allowed, they blend across it.
    #[test]
    fn issue_18_a_kink_at_a_crease_node_keeps_both_frames() {
        let mut c = curve(1000, |u| u);
        let turn = |a: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        let mut s = Samples::default();
        let mut push = |t: f64, d: f64, q: UnitQuaternion<f64>| {
            s.t.push(t);
            s.d.push(d);
            s.q.push([q.w, q.i, q.j, q.k]);
            s.flags.push(0);
            s.w.push(1.0);
        };
        for i in 0..=500 {
            push(i as f64, i as f64 / 1000.0, turn(0.0));
        }
        for i in 1..50 {
            push(
                500.0 + i as f64 / 50.0,
                0.5,
                turn(std::f64::consts::FRAC_PI_2 * i as f64 / 50.0),
            );
        }
        for i in 500..=1000 {
            push(
                501.0 + i as f64,
                i as f64 / 1000.0,
                turn(std::f64::consts::FRAC_PI_2),
            );
        }
        c.samples = s;
        let p = PrefilterParams::default();
        let u = prefilter_with_kinks(&c, &p, &[1]).unwrap();
        let (node, _) = u.nodes[1];
        assert_eq!(u.kinks.len(), 1);
        assert_eq!(u.kinks[0].0, node);
        assert!(
            u.arriving(node).angle_to(&turn(0.0)) < 1e-9,
            "{:?}",
            u.arriving(node)
        );
        assert!(u.q[node].angle_to(&turn(std::f64::consts::FRAC_PI_2)) < 1e-9);
        assert!(u.q[node - 1].angle_to(&turn(0.0)) < 1e-9);
        assert!(u.q[node + 1].angle_to(&turn(std::f64::consts::FRAC_PI_2)) < 1e-9);
        // Turned in place, the node kinks on any curve (issue 52), with the same frames.
        assert_eq!(prefilter(&c, &p).unwrap(), u);
        // A node with no turn is no kink.
        let straight = prefilter_with_kinks(&curve(1000, |u| u), &p, &[1]).unwrap();
        assert!(straight.kinks.is_empty());
    }

    /// A curve of straight legs from `legs` (each `(length, frame)`), standing `stand`
    /// samples at each node between two legs, its frame going from the leg's before to the
    /// next one's by `during(before, after, u)` (`u` from 0 to 1); tags at every node.
    /// Samples every millimetre, one per unit of time.
    fn legs_curve(
        legs: &[(f64, UnitQuaternion<f64>)],
        stand: usize,
        during: impl Fn(&UnitQuaternion<f64>, &UnitQuaternion<f64>, f64) -> UnitQuaternion<f64>,
        closed: bool,
    ) -> Curve {
        let mut s = Samples::default();
        let mut push = |d: f64, q: UnitQuaternion<f64>| {
            s.t.push(s.t.len() as f64);
            s.d.push(d);
            s.q.push([q.w, q.i, q.j, q.k]);
            s.flags.push(0);
            s.w.push(1.0);
        };
        let mut tags = vec![0.0];
        let mut d0 = 0.0;
        for (k, &(len, q)) in legs.iter().enumerate() {
            let n = (len * 1000.0).round() as usize;
            // (A leg after a stand begins a millimetre on.)
            for i in usize::from(k > 0)..n {
                push(d0 + len * i as f64 / n as f64, q);
            }
            d0 += len;
            tags.push(d0);
            if let Some((_, next)) = legs.get(k + 1) {
                for i in 0..=stand {
                    push(d0, during(&q, next, i as f64 / stand as f64));
                }
            } else {
                push(d0, q);
            }
        }
        let nodes = tags.len();
        Curve {
            index: 0,
            kind: crate::curve::CurveKind::Boundary,
            closed,
            tags: tags
                .iter()
                .enumerate()
                .map(|(k, &d)| Tag {
                    node: if closed && k + 1 == nodes {
                        0
                    } else {
                        k as u32
                    },
                    d,
                    t: 0.0,
                    uncertain: false,
                })
                .collect(),
            segment_lengths: vec![None; nodes - 1],
            samples: s,
        }
    }

    /// Issue 52: the independent simulator's saddle has a boundary with corners (no crease):
    /// the operator turns the device in place at each corner node. Each corner kinks, the
    /// loop's closing corner too (its two ends' tangents), and the frames either side of a
    /// corner are their side's: before, the kernel blended them at each corner, and the
    /// network cut its corners (the saddle's with true orientations and distances: 0.074–0.079 %
    /// of the diagonal, 0.002–0.027 % with the kinks).
    #[test]
    fn issue_52_a_corner_turned_in_place_kinks_without_a_crease() {
        let turn = |a: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        let right = std::f64::consts::FRAC_PI_2;
        // A square's four sides, 0.3 m each, turning left at each corner.
        let legs: Vec<_> = (0..4).map(|k| (0.3, turn(right * k as f64))).collect();
        let c = legs_curve(&legs, 60, |a, b, u| a.slerp(b, u), true);
        let u = prefilter(&c, &PrefilterParams::default()).unwrap();
        let corners: Vec<usize> = u.nodes[..4].iter().map(|n| n.0).collect();
        let kinked: Vec<usize> = u.kinks.iter().map(|k| k.0).collect();
        assert_eq!(kinked, corners);
        for (k, &j) in corners.iter().enumerate() {
            let leaving = turn(right * k as f64);
            let arriving = turn(right * ((k + 3) % 4) as f64);
            assert!(u.q[j].angle_to(&leaving) < 1e-9, "corner {k} leaving");
            // (The loop arrives at its closing corner at its last sample.)
            let (arrived, before) = match j {
                0 => (u.q[u.q.len() - 1], u.q[u.q.len() - 2]),
                _ => (u.arriving(j), u.q[j - 1]),
            };
            assert!(arrived.angle_to(&arriving) < 1e-9, "corner {k} arriving");
            assert!(u.q[j + 1].angle_to(&leaving) < 1e-9);
            assert!(before.angle_to(&arriving) < 1e-9);
        }
        // The same corners taken rolling (the device turned without standing): no kink but
        // the closing corner, whose ends' tangents are 90° apart.
        let rolled = legs_curve(&legs, 1, |a, _, _| *a, true);
        let u = prefilter(&rolled, &PrefilterParams::default()).unwrap();
        assert_eq!(u.kinks.iter().map(|k| k.0).collect::<Vec<_>>(), vec![0]);
    }

    /// What is not a corner turned in place: the device rolled over a ridge (its frame pitched
    /// 30° about its second axis while it stood at the node: a hand tilting it while typing,
    /// the next leg going down the other side); a loop closing on a bend of 30° (the bumpy
    /// cube's sections, closing on a rounded edge: 22°).
    #[test]
    fn a_tilt_standing_and_a_loop_closing_on_a_bend_are_no_kinks() {
        let pitch = |a: f64| UnitQuaternion::from_axis_angle(&Vector3::y_axis(), a);
        let ridge = [(0.3, pitch(0.0)), (0.3, pitch(30f64.to_radians()))];
        let c = legs_curve(&ridge, 60, |a, b, u| a.slerp(b, u), false);
        let u = prefilter(&c, &PrefilterParams::default()).unwrap();
        assert!(u.kinks.is_empty(), "{:?}", u.kinks);
        // At a crease node, the same bend kinks (the tangents alone).
        let u = prefilter_with_kinks(&c, &PrefilterParams::default(), &[1]).unwrap();
        assert_eq!(u.kinks.len(), 1);
        // Four legs turning 10° at each node as the device rolls on, the loop's ends meeting
        // at 30°: no kink.
        let turn = |a: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        let legs: Vec<_> = [0.0, 10.0, 20.0, 30.0]
            .iter()
            .map(|a: &f64| (0.3, turn(a.to_radians())))
            .collect();
        let c = legs_curve(&legs, 1, |a, _, _| *a, true);
        let u = prefilter(&c, &PrefilterParams::default()).unwrap();
        assert!(u.kinks.is_empty(), "{:?}", u.kinks);
    }

    #[test]
    fn resamples_uniformly_with_nodes_on_samples() {
        let c = curve(2000, |u| u * u); // 0 … 1 m, slow then fast
        let u = prefilter(
            &c,
            &PrefilterParams {
                h: 0.01,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(u.nodes.first().unwrap().0, 0);
        assert_eq!(u.nodes.last().unwrap().0, u.d.len() - 1);
        let mid = u.nodes[1].0;
        assert!((u.d[mid] - 0.25).abs() < 1e-12, "node 1 lands on a sample");
        for (k, (&d, q)) in u.d.iter().zip(&u.q).enumerate() {
            let truth = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d);
            assert!(
                q.angle_to(&truth) < tolerance(d, 1.0),
                "sample {k} at {d}: {}",
                q.angle_to(&truth)
            );
        }
        // Steps: 25 of 1 cm, then 75 of 1 cm.
        assert_eq!(u.h.len(), 2);
        assert!((u.h[0] - 0.01).abs() < 1e-12 && (u.h[1] - 0.01).abs() < 1e-12);
    }

    #[test]
    fn the_steps_along_are_each_edges_step() {
        let mut c = curve(2000, |u| u * u);
        // Segments of different steps: 0.3 m at 7 mm, … (tags at 0, 0.3, 0.55, 1 m).
        c.tags.insert(
            1,
            Tag {
                node: 9,
                d: 0.3,
                t: 0.3,
                uncertain: false,
            },
        );
        c.tags[2].d = 0.55;
        let u = prefilter(
            &c,
            &PrefilterParams {
                h: 0.007,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(u.h.len(), 3);
        let steps: Vec<f64> = u.edge_steps().collect();
        assert_eq!(steps.len(), u.q.len() - 1);
        for (j, h) in steps.iter().enumerate() {
            assert_eq!(h.to_bits(), u.edge_h(j).to_bits(), "edge {j}");
        }
        assert!(u.h.windows(2).any(|w| w[0] != w[1]), "{:?}", u.h);
    }

    #[test]
    fn outliers_and_duplicates() {
        let mut c = curve(1000, |u| u);
        // A spike.
        let spike = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2.0);
        c.samples.q[500] = [spike.w, spike.i, spike.j, spike.k];
        // Standing still at 0.7 m: 300 samples there.
        for _ in 0..300 {
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7);
            c.samples.d.push(0.7);
            c.samples.q.push([q.w, q.i, q.j, q.k]);
            c.samples.t.push(2.0);
            c.samples.flags.push(0);
            c.samples.w.push(1.0);
        }
        let u = prefilter(&c, &PrefilterParams::default()).unwrap();
        assert_eq!(u.outliers, 1);
        for (&d, q) in u.d.iter().zip(&u.q) {
            let err = q.angle_to(&UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d));
            assert!(err < tolerance(d, 1.0), "at {d}: {err}");
        }
    }

    /// Regression: two nodes tagged at the same distance made a segment of step 0, and the
    /// kernel search doubled a zero radius for ever (found by the robustness property test).
    #[test]
    fn a_segment_of_no_length_is_reported_not_looped_on() {
        let mut c = curve(100, |u| u);
        c.tags.insert(
            1,
            Tag {
                node: 7,
                d: 0.25,
                t: 0.25,
                uncertain: false,
            },
        );
        c.tags.insert(
            1,
            Tag {
                node: 6,
                d: 0.25,
                t: 0.25,
                uncertain: false,
            },
        );
        assert!(matches!(
            prefilter(&c, &PrefilterParams::default()),
            Err(PrefilterError::EmptySegment { a: 6, b: 7, .. })
        ));
    }

    #[test]
    fn bad_curves_are_reported() {
        let mut c = curve(100, |u| u);
        c.tags.truncate(1);
        assert!(matches!(
            prefilter(&c, &PrefilterParams::default()),
            Err(PrefilterError::TooFewNodes { .. })
        ));
        let c = curve(100, |u| u * 0.015);
        assert!(matches!(
            prefilter(&c, &PrefilterParams::default()),
            Err(PrefilterError::TooShort { .. })
        ));
    }
}
