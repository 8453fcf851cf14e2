//! Curve-network reconstruction: tagged curves → filtered frames → positions.
//!
//! - [`prefilter`](mod@prefilter): per-curve outlier removal, duplicates, uniform Gaussian resampling.
//! - [`closure`]: node tags the network's loops refuse (a mistyped or half-lost index) are
//!   detached from their node.
//! - [`regression`]: the frames regressed on SO(3)ᴺ over the whole network.
//! - [`poisson`]: positions of the whole network from its tangents, nodes shared.
//!
//! [`Reconstructor::run`] runs them over a scan, leaving out (with a warning) what cannot be
//! used, and keeps the symbolic factorisations between runs.

pub mod closure;
pub mod poisson;
pub mod prefilter;
pub mod regression;

use crate::scan::Scan;
use poisson::{PoissonSolver, Positions};
use prefilter::{prefilter, PrefilterParams, UniformCurve};
use regression::{RegressionParams, RegressionReport, RegressionSolver};
use serde::Serialize;
use std::time::Instant;

/// Settings of the reconstruction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NetworkParams {
    pub prefilter: PrefilterParams,
    pub regression: RegressionParams,
    /// Skip the regression (pre-filter only), for comparisons.
    pub no_regression: bool,
    /// Skip the loop-closure test of the tags ([`closure`]), for comparisons.
    pub no_closure_check: bool,
}

/// What a reconstruction did, for `report.json`.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct NetworkReport {
    pub curves_used: usize,
    pub curves_left_out: usize,
    pub samples: usize,
    pub components: usize,
    pub outliers_removed: usize,
    /// Tags detached from their node by the loop-closure test (each also a warning).
    pub tags_detached: usize,
    /// Largest angle between the normals of two curves at a shared node, degrees.
    pub max_node_normal_angle_deg: f64,
    /// The regression's iterations and energies.
    pub regression: RegressionReport,
    pub timings_ms: Timings,
}

/// Wall time per stage, ms.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Timings {
    pub prefilter: f64,
    pub regression: f64,
    pub poisson: f64,
}

/// The reconstruction of a scan.
#[derive(Debug, Clone)]
pub struct Network {
    pub positions: Positions,
    pub report: NetworkReport,
    pub warnings: Vec<String>,
}

/// Holds what is reused between reconstructions (symbolic factorisations).
#[derive(Debug, Default)]
pub struct Reconstructor {
    poisson: PoissonSolver,
    regression: RegressionSolver,
}

impl Reconstructor {
    pub fn new() -> Self {
        Self::default()
    }

    /// Reconstructs the accepted curves of `scan`; `None` when no curve can be used.
    pub fn run(&mut self, scan: &Scan, p: &NetworkParams) -> Option<Network> {
        let mut warnings = Vec::new();
        let t0 = Instant::now();
        let mut uniform: Vec<UniformCurve> = Vec::new();
        for c in &scan.curves {
            match prefilter(c, &p.prefilter) {
                Ok(u) => uniform.push(u),
                Err(e) => warnings.push(format!("{e}; left out of the network")),
            }
        }
        let t1 = Instant::now();
        if uniform.is_empty() {
            if !scan.curves.is_empty() {
                warnings.push("no curve could be used: nothing reconstructed".into());
            }
            for w in &warnings {
                tracing::warn!("{w}");
            }
            return None;
        }
        let closure = if p.no_closure_check {
            closure::ClosureReport::default()
        } else {
            let uncertain: std::collections::BTreeSet<(usize, usize)> = scan
                .curves
                .iter()
                .flat_map(|c| {
                    c.tags
                        .iter()
                        .enumerate()
                        .filter(|(_, t)| t.uncertain)
                        .map(|(k, _)| (c.index, k))
                })
                .collect();
            closure::detach_outlier_tags(&mut uniform, |c, k| uncertain.contains(&(c, k)))
        };
        warnings.extend(closure.detached.iter().map(|d| d.to_string()));
        warnings.extend(closure.warnings.iter().cloned());
        let regression = if p.no_regression {
            RegressionReport::default()
        } else {
            self.regression.run(&mut uniform, &p.regression)
        };
        let t2 = Instant::now();
        let positions = match self.poisson.solve(&uniform) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!("Poisson reconstruction failed: {e}");
                warnings.push(format!("Poisson reconstruction failed: {e}"));
                return None;
            }
        };
        let t3 = Instant::now();
        if positions.components > 1 {
            warnings.push(format!(
                "the network falls apart into {} parts with no node in common: each is reconstructed on its own, their relative placement is arbitrary",
                positions.components
            ));
        }
        let report = NetworkReport {
            curves_used: uniform.len(),
            curves_left_out: scan.curves.len() - uniform.len(),
            samples: uniform.iter().map(|u| u.q.len()).sum(),
            components: positions.components,
            outliers_removed: uniform.iter().map(|u| u.outliers).sum(),
            tags_detached: closure.detached.len(),
            max_node_normal_angle_deg: max_node_normal_angle(&positions),
            regression,
            timings_ms: Timings {
                prefilter: (t1 - t0).as_secs_f64() * 1e3,
                regression: (t2 - t1).as_secs_f64() * 1e3,
                poisson: (t3 - t2).as_secs_f64() * 1e3,
            },
        };
        for w in &warnings {
            tracing::warn!("{w}");
        }
        Some(Network {
            positions,
            report,
            warnings,
        })
    }
}

/// Largest angle between normals of different curves at a shared node, degrees.
pub fn max_node_normal_angle(p: &Positions) -> f64 {
    let mut at: std::collections::BTreeMap<u32, Vec<nalgebra::Vector3<f64>>> = Default::default();
    for c in &p.curves {
        for &(i, n) in &c.nodes {
            at.entry(n).or_default().push(c.normals[i]);
        }
    }
    let mut worst: f64 = 0.0;
    for ns in at.values() {
        for a in 0..ns.len() {
            for b in a + 1..ns.len() {
                worst = worst.max(ns[a].angle(&ns[b]).to_degrees());
            }
        }
    }
    worst
}
