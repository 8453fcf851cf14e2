//! One epoch of a monitored structure: the sensors' orientations (averaged over the epoch by
//! acquisition) → each curve of the layout resampled at a uniform step per segment, its
//! frames interpolated along the rest arc length (slerp between the two nearest sensors) →
//! optionally the regression on SO(3) → positions by the Poisson step, nodes shared. The same
//! engine as scanning, fed by a fixed layout instead of a rolling device.
//!
//! ```
//! use nalgebra::{UnitQuaternion, Vector3};
//! use sfs::monitor::epoch::{EpochParams, EpochReconstructor};
//! use sfs::monitor::layout::{Layout, LayoutCurve, LayoutSensor};
//! use std::collections::BTreeMap;
//! // A straight 2 m bar along x with three sensors, from node 0 to node 1.
//! let layout = Layout {
//!     curves: vec![LayoutCurve { index: 0, nodes: vec![0, 1], node_s: vec![0.0, 2.0], length: 2.0 }],
//!     sensors: (0..3).map(|k| LayoutSensor { sensor: k, curve: 0, s: k as f64 }).collect(),
//! };
//! let q: BTreeMap<u16, UnitQuaternion<f64>> = (0..3).map(|k| (k, UnitQuaternion::identity())).collect();
//! let shape = EpochReconstructor::new().run(&layout, &q, &EpochParams::default()).unwrap();
//! let d = shape.positions.nodes[&1] - shape.positions.nodes[&0];
//! assert!((d - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-9);
//! ```

use super::layout::{Layout, LayoutCurve};
use nalgebra::UnitQuaternion;
use sfs_geometry::network::poisson::{PoissonSolver, Positions};
use sfs_geometry::network::prefilter::UniformCurve;
use sfs_geometry::network::regression::{RegressionParams, RegressionSolver};
use std::collections::BTreeMap;

/// Settings of an epoch's reconstruction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochParams {
    /// Largest resampling step along the curves, m. Default 0.05.
    pub step: f64,
    /// The regression over the network (`None`: the interpolated frames as they are).
    pub regression: Option<RegressionParams>,
}

impl Default for EpochParams {
    fn default() -> Self {
        EpochParams {
            step: 0.05,
            regression: None,
        }
    }
}

/// The shape at one epoch.
#[derive(Debug, Clone)]
pub struct EpochShape {
    pub positions: Positions,
    /// Sensors of the layout with no orientation this epoch (their curve is interpolated
    /// across them).
    pub missing: Vec<u16>,
    /// Curves left out (no sensor with an orientation), with the reason.
    pub left_out: Vec<String>,
}

/// Why an epoch cannot be reconstructed at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpochError {
    #[error("no curve of the layout has a sensor with an orientation")]
    NoCurve,
    #[error("the Poisson step failed: {0}")]
    Poisson(String),
}

/// Keeps the symbolic factorisations between epochs (the layout does not change).
#[derive(Debug, Default)]
pub struct EpochReconstructor {
    poisson: PoissonSolver,
    regression: RegressionSolver,
}

impl EpochReconstructor {
    pub fn new() -> Self {
        Self::default()
    }

    /// The shape of `layout` given the orientation of each sensor (frame [T B N] → world) by
    /// sensor id; sensors absent from `q` are missing.
    pub fn run(
        &mut self,
        layout: &Layout,
        q: &BTreeMap<u16, UnitQuaternion<f64>>,
        p: &EpochParams,
    ) -> Result<EpochShape, EpochError> {
        let mut uniform = Vec::with_capacity(layout.curves.len());
        let mut missing = Vec::new();
        let mut left_out = Vec::new();
        for c in &layout.curves {
            let mut on: Vec<(f64, UnitQuaternion<f64>)> = Vec::new();
            for s in layout.sensors.iter().filter(|s| s.curve == c.index) {
                match q.get(&s.sensor) {
                    Some(r) => on.push((s.s, *r)),
                    None => missing.push(s.sensor),
                }
            }
            if on.is_empty() {
                left_out.push(format!(
                    "curve {}: no sensor on it has an orientation; left out",
                    c.index
                ));
                continue;
            }
            on.sort_by(|a, b| a.0.total_cmp(&b.0));
            uniform.push(resample(c, &on, p.step));
        }
        if uniform.is_empty() {
            return Err(EpochError::NoCurve);
        }
        if let Some(rp) = &p.regression {
            self.regression.run(&mut uniform, rp);
        }
        let positions = self
            .poisson
            .solve(&uniform)
            .map_err(|e| EpochError::Poisson(e.to_string()))?;
        missing.sort_unstable();
        Ok(EpochShape {
            positions,
            missing,
            left_out,
        })
    }
}

/// The frame at rest arc length `x` from the sensors `on` (sorted by arc length).
fn frame_at(on: &[(f64, UnitQuaternion<f64>)], x: f64) -> UnitQuaternion<f64> {
    let k = on.partition_point(|(s, _)| *s <= x);
    if k == 0 {
        return on[0].1;
    }
    if k == on.len() {
        return on[k - 1].1;
    }
    let ((s0, q0), (s1, q1)) = (on[k - 1], on[k]);
    let t = if s1 > s0 { (x - s0) / (s1 - s0) } else { 0.0 };
    q0.try_slerp(&q1, t, 1e-9)
        .unwrap_or(if t < 0.5 { q0 } else { q1 })
}

/// The rest arc lengths at which curve `c` is sampled, from its first node to its last: a
/// uniform step of at most `step` per segment between nodes, nodes on samples. Also the
/// segment steps, and each node's sample.
pub fn samples(c: &LayoutCurve, step: f64) -> (Vec<f64>, Vec<f64>, Vec<(usize, u32)>) {
    let (mut x, mut h, mut nodes) = (Vec::new(), Vec::new(), vec![(0, c.nodes[0])]);
    for k in 0..c.nodes.len() - 1 {
        let (a, b) = (c.node_s[k], c.node_s[k + 1]);
        let n = ((b - a) / step.max(1e-6)).ceil().max(1.0) as usize;
        let hk = (b - a) / n as f64;
        h.push(hk);
        // A segment's first sample is the previous one's last (the node between them).
        for j in usize::from(k > 0)..=n {
            x.push(a + j as f64 * hk);
        }
        nodes.push((x.len() - 1, c.nodes[k + 1]));
    }
    (x, h, nodes)
}

/// Curve `c` at its [`samples`], frames interpolated from the sensors `on`.
fn resample(c: &LayoutCurve, on: &[(f64, UnitQuaternion<f64>)], step: f64) -> UniformCurve {
    let (x, h, nodes) = samples(c, step);
    let s0 = c.node_s[0];
    let d: Vec<f64> = x.iter().map(|x| x - s0).collect();
    let q = x.iter().map(|&x| frame_at(on, x)).collect();
    let w = vec![1.0; d.len()];
    UniformCurve {
        index: c.index,
        kind: sfs_geometry::curve::CurveKind::Interior,
        d,
        q,
        nodes,
        h,
        w,
        outliers: 0,
        kinks: Vec::new(),
    }
}
