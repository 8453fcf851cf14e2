//! `report.json`: what a session saw and did. For now the link statistics; later stages add
//! their own objects next to `"link"`.

use crate::link::LinkStats;
use serde::Serialize;
use std::path::Path;

/// The content of `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Version of the sfs that wrote it.
    pub sfs_version: &'static str,
    /// The source, as described to the operator.
    pub source: String,
    /// Why the session ended: `"end_of_input"`, `"shutdown"`, `"capture_failed"`, `"read_error"`.
    pub ended: &'static str,
    /// Wall-clock duration of the session in seconds.
    pub wall_time_s: f64,
    pub link: LinkStats,
}

impl Report {
    /// Writes the report as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut json = serde_json::to_vec_pretty(self).map_err(std::io::Error::other)?;
        json.push(b'\n');
        crate::atomic::write_atomic(path, &json)
    }
}
