//! `[network]`: the curve-network reconstruction.

use super::{ConfigError, ConfigFile};
use serde::Deserialize;
use std::path::Path;

/// `[network]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkToml {
    pub h: Option<f64>,
    pub sigma: Option<f64>,
    pub alpha: Option<f64>,
    pub regression: Option<bool>,
    pub estimate_mounting: Option<bool>,
    pub estimate_curve_scales: Option<bool>,
    pub repair_slips: Option<bool>,
    pub bend_length: Option<f64>,
    pub bend_fraction: Option<f64>,
    pub stretch_length: Option<f64>,
    pub xi: Option<f64>,
    pub local_window: Option<usize>,
    pub join_distance: Option<f64>,
    pub join_normal_deg: Option<f64>,
    pub join_untagged: Option<bool>,
    pub refuse: Option<Vec<Vec<usize>>>,
}

impl ConfigFile {
    /// The reconstruction settings this configuration describes.
    pub(super) fn network_params(
        &self,
        file: &Path,
    ) -> Result<sfs_geometry::network::NetworkParams, ConfigError> {
        let n = &self.network;
        let mut p = sfs_geometry::network::NetworkParams::default();
        let check =
            |key: &str, v: Option<f64>, lo: f64, hi: f64| -> Result<Option<f64>, ConfigError> {
                match v {
                    Some(x) if !(x.is_finite() && x >= lo && x <= hi) => Err(ConfigError::new(
                        file,
                        format!("network.{key}"),
                        format!("{x} is out of range [{lo}, {hi}]"),
                    )),
                    v => Ok(v),
                }
            };
        if let Some(x) = check("h", n.h, 1e-4, 10.0)? {
            p.prefilter.h = x;
        }
        if let Some(x) = check("sigma", n.sigma, 0.01, 5.0)? {
            p.prefilter.sigma = x;
        }
        if let Some(x) = check("alpha", n.alpha, 0.0, 1.0)? {
            p.prefilter.alpha = x;
        }
        p.no_regression = n.regression == Some(false);
        p.no_mounting = n.estimate_mounting == Some(false);
        p.no_curve_scales = n.estimate_curve_scales == Some(false);
        p.no_slip_repair = n.repair_slips == Some(false);
        if let Some(x) = check("bend_length", n.bend_length, 0.0, 100.0)? {
            p.regression.bend_length = Some(x);
        }
        if let Some(x) = check("bend_fraction", n.bend_fraction, 0.0, 100.0)? {
            p.regression.bend_fraction = x;
        }
        if let Some(x) = check("stretch_length", n.stretch_length, 0.0, 100.0)? {
            p.regression.stretch_length = x;
        }
        if let Some(x) = check("xi", n.xi, 0.0, 1e9)? {
            p.regression.xi = x;
        }
        p.local_window = crate::pipeline::LIVE_LOCAL_WINDOW;
        if let Some(w) = n.local_window {
            if w > 100_000 {
                return Err(ConfigError::new(
                    file,
                    "network.local_window",
                    format!("{w} samples is more than 100000 (0 regresses the whole network every update)"),
                ));
            }
            p.local_window = w;
        }
        Ok(p)
    }

    /// The joins of nodes tagged on one curve (issue 34): `join_distance`,
    /// `join_normal_deg`, `join_untagged`, `refuse`.
    pub(super) fn join_settings(
        &self,
        file: &Path,
    ) -> Result<sfs_geometry::network::join::JoinSettings, ConfigError> {
        let n = &self.network;
        let mut j = sfs_geometry::network::join::JoinSettings::default();
        let range = |key: &str, x: f64, lo: f64, hi: f64| {
            if x.is_finite() && x >= lo && x <= hi {
                Ok(x)
            } else {
                Err(ConfigError::new(
                    file,
                    format!("network.{key}"),
                    format!("{x} is out of range [{lo}, {hi}]"),
                ))
            }
        };
        if let Some(x) = n.join_distance {
            j.params.distance_m = range("join_distance", x, 0.0, 1.0)?;
            j.params.noise_factor = 0.0;
        }
        if let Some(x) = n.join_normal_deg {
            j.params.normal_deg = range("join_normal_deg", x, 0.0, 90.0)?;
        }
        j.untagged = n.join_untagged.unwrap_or(false);
        for pair in n.refuse.iter().flatten() {
            match pair[..] {
                [a, b] if a != b => j.refuse.push((a, b)),
                _ => {
                    return Err(ConfigError::new(
                        file,
                        "network.refuse",
                        format!(
                            "{pair:?} is not a pair of two different curve indices (write refuse = [[3, 7]])"
                        ),
                    ))
                }
            }
        }
        Ok(j)
    }
}
