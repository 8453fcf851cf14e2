//! `[output]`: what a session writes (live updates, snapshots, capture rotation).

use super::{ConfigError, ConfigFile};
use serde::Deserialize;
use std::path::Path;

/// `[output]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputToml {
    pub live: Option<bool>,
    pub snapshots: Option<bool>,
    pub capture_max_mb: Option<f64>,
    pub capture_keep: Option<usize>,
}

impl ConfigFile {
    /// The rotation of a live session's capture (`None`: one file that grows): set by
    /// `[output] capture_max_mb` / `capture_keep`; on by default when monitoring (256 MB, 8
    /// kept), since an unattended run would otherwise fill the disk.
    pub(super) fn capture_rotation(
        &self,
        file: &Path,
    ) -> Result<Option<crate::capture::Rotation>, ConfigError> {
        let o = &self.output;
        let monitoring = self.monitor.is_some();
        let max_mb = match o.capture_max_mb {
            Some(x) => x,
            None if monitoring => 256.0,
            None if o.capture_keep.is_some() => {
                return Err(ConfigError::new(
                    file,
                    "output.capture_keep",
                    "needs output.capture_max_mb (the capture is rotated only past a size)",
                ))
            }
            None => return Ok(None),
        };
        if !(max_mb.is_finite() && (0.01..=1e7).contains(&max_mb)) {
            return Err(ConfigError::new(
                file,
                "output.capture_max_mb",
                format!("{max_mb} is out of range [0.01, 1e7] MB"),
            ));
        }
        Ok(Some(crate::capture::Rotation {
            max_bytes: (max_mb * 1e6) as u64,
            keep: o.capture_keep.unwrap_or(8).min(100_000),
        }))
    }
}
