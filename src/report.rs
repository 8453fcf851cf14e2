//! `report.json`: what a session saw and did. For now the link statistics; later stages add
//! their own objects next to `"link"`.

use crate::link::LinkStats;
use crate::scan::{Counts, Curve};
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
    /// One object per accepted curve, in scan order.
    pub curves: Vec<CurveSummary>,
    /// What acquisition counted (samples, flags, discarded curves).
    pub acquisition: Counts,
    /// Problems in words naming curve, node and time.
    pub warnings: Vec<String>,
    /// Reconstructed node positions in the glb's frame (y up), by node index.
    pub nodes: std::collections::BTreeMap<String, [f32; 3]>,
    /// Wall time per reconstruction stage, ms.
    pub timings_ms: Option<sfs_geometry::network::Timings>,
    /// What the reconstruction did (curves used, samples, components, node normal agreement).
    pub network: Option<sfs_geometry::network::NetworkReport>,
    /// What the surfacer did (patches, holes, problems naming nodes and curves).
    pub surface: Option<sfs_geometry::surface::fit::SurfaceReport>,
    /// What the live updates measured (latency from the E key to `network.glb`, memory).
    pub live: Option<crate::live::LiveReport>,
    /// What monitoring did (epochs, alarms, the last metrics).
    pub monitor: Option<crate::monitor::run::MonitorReport>,
}

/// A curve in `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct CurveSummary {
    pub index: usize,
    pub boundary: bool,
    /// The node sequence as scanned.
    pub nodes: Vec<u32>,
    pub samples: usize,
    pub length_m: f64,
}

impl From<&Curve> for CurveSummary {
    fn from(c: &Curve) -> Self {
        CurveSummary {
            index: c.index,
            boundary: c.boundary,
            nodes: c.nodes(),
            samples: c.samples.len(),
            length_m: c.length(),
        }
    }
}

impl Report {
    /// Writes the report as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        crate::atomic::write_json(path, self, true)
    }
}
