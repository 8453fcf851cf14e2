//! `[surface]`: surfacing with normal control.

use super::{ConfigError, ConfigFile};
use serde::Deserialize;
use std::path::Path;

/// `[surface]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceToml {
    pub enabled: Option<bool>,
    pub edge: Option<f64>,
    pub max_vertices: Option<usize>,
    pub reweight: Option<usize>,
    pub soft: Option<f64>,
    pub guide_weight: Option<f64>,
    pub reuse_tolerance: Option<f64>,
}

impl ConfigFile {
    /// The surfacing settings this configuration describes (`None`: surfacing disabled).
    pub(super) fn surface_params(
        &self,
        file: &Path,
    ) -> Result<Option<sfs_geometry::surface::fit::SurfaceParams>, ConfigError> {
        let s = &self.surface;
        if s.enabled == Some(false) {
            return Ok(None);
        }
        let mut p = sfs_geometry::surface::fit::SurfaceParams::default();
        if let Some(e) = s.edge {
            if !(e.is_finite() && (1e-4..=10.0).contains(&e)) {
                return Err(ConfigError::new(
                    file,
                    "surface.edge",
                    format!("{e} is out of range [0.0001, 10] m"),
                ));
            }
            p.edge = Some(e);
        }
        if let Some(m) = s.max_vertices {
            if !(100..=10_000_000).contains(&m) {
                return Err(ConfigError::new(
                    file,
                    "surface.max_vertices",
                    format!("{m} is out of range [100, 10000000]"),
                ));
            }
            p.max_vertices = m;
        }
        if let Some(r) = s.reweight {
            if r > 10 {
                return Err(ConfigError::new(
                    file,
                    "surface.reweight",
                    format!("{r} passes is more than 10"),
                ));
            }
            p.reweight = r;
        }
        // A data weight: in [0, 1e6].
        let weight = |w: f64, key: &str, zero: &str| {
            if w.is_finite() && (0.0..=1e6).contains(&w) {
                Ok(w)
            } else {
                Err(ConfigError::new(
                    file,
                    format!("surface.{key}"),
                    format!("{w} is out of range [0, 1e6]{zero}"),
                ))
            }
        };
        p.soft = crate::pipeline::SCAN_SOFTNESS;
        if let Some(w) = s.soft {
            let w = weight(w, "soft", " (0: hard constraints)")?;
            p.soft = (w > 0.0).then_some(w);
        }
        if let Some(w) = s.guide_weight {
            p.guide_weight = weight(w, "guide_weight", "")?;
        }
        p.reuse_tolerance = crate::pipeline::LIVE_REUSE_TOLERANCE;
        if let Some(t) = s.reuse_tolerance {
            if t.is_nan() || t < 0.0 {
                return Err(ConfigError::new(
                    file,
                    "surface.reuse_tolerance",
                    format!("{t} is not a tolerance (0, a positive number of edges, or inf)"),
                ));
            }
            p.reuse_tolerance = t;
        }
        Ok(Some(p))
    }
}
