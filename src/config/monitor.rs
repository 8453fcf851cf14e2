//! `[monitor]`: the layout and settings of an instrumented structure.

use super::{ConfigError, ConfigFile};
use crate::monitor::alarm::AlarmMetric;
use crate::monitor::settings::{AlarmSpec, MonitorConfig};
use serde::Deserialize;
use sfs_geometry::network::NetworkParams;
use sfs_geometry::surface::fit::SurfaceParams;
use std::path::Path;
use std::path::PathBuf;

/// `[monitor]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MonitorToml {
    pub epoch_hz: Option<f64>,
    /// The node placed at the origin (the structure's fixed point, e.g. a riser's foot).
    pub anchor: Option<u32>,
    pub x_azimuth_deg: Option<f64>,
    pub reference_s: Option<f64>,
    /// A fixed reference shape ([`crate::monitor::metrics::ReferenceFile`]), relative to the
    /// configuration file's directory.
    pub reference_file: Option<PathBuf>,
    pub smoothing_s: Option<f64>,
    pub latest_every: Option<usize>,
    /// Surface the shape in `latest.glb` (with the `[surface]` settings).
    pub surface: Option<bool>,
    /// Run the regression on SO(3) in each epoch (with the `[network]` settings).
    pub regression: Option<bool>,
    pub metrics_max_mb: Option<f64>,
    pub metrics_keep: Option<usize>,
    /// Serve the metrics over HTTP (Prometheus text format) on this port; off when absent.
    pub http_port: Option<u16>,
    /// The address to bind; default 127.0.0.1 (this machine only).
    pub http_address: Option<String>,
    #[serde(default)]
    pub alarm: Vec<AlarmToml>,
    #[serde(default)]
    pub curve: Vec<MonitorCurveToml>,
    #[serde(default)]
    pub sensor: Vec<crate::monitor::layout::LayoutSensor>,
}

/// `[[monitor.alarm]]`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlarmToml {
    pub metric: String,
    pub threshold: f64,
    pub hysteresis: Option<f64>,
}

/// `[[monitor.curve]]`: its index is its place in the list.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MonitorCurveToml {
    pub nodes: Vec<u32>,
    pub node_s: Vec<f64>,
    pub length: f64,
}

impl ConfigFile {
    /// The monitoring layout and settings (`None` without a `[monitor]` section).
    pub(super) fn monitor_config(
        &self,
        file: &Path,
        surface: Option<SurfaceParams>,
        network: &NetworkParams,
    ) -> Result<Option<MonitorConfig>, ConfigError> {
        let Some(m) = &self.monitor else {
            return Ok(None);
        };
        let err = |key: String, reason: String| ConfigError::new(file, key, reason);
        let layout = crate::monitor::layout::Layout {
            curves: m
                .curve
                .iter()
                .enumerate()
                .map(|(index, c)| crate::monitor::layout::LayoutCurve {
                    index,
                    nodes: c.nodes.clone(),
                    node_s: c.node_s.clone(),
                    length: c.length,
                })
                .collect(),
            sensors: m.sensor.clone(),
        };
        if layout.curves.is_empty() {
            return Err(err(
                "monitor.curve".into(),
                "a monitoring layout needs at least one [[monitor.curve]]".into(),
            ));
        }
        layout.validate().map_err(|e| match &e {
            crate::monitor::layout::LayoutError::Curve { curve, .. } => {
                err(format!("monitor.curve[{curve}]"), e.to_string())
            }
            crate::monitor::layout::LayoutError::Sensor { sensor, .. } => {
                let k = m
                    .sensor
                    .iter()
                    .position(|s| s.sensor == *sensor)
                    .unwrap_or(0);
                err(format!("monitor.sensor[{k}]"), e.to_string())
            }
        })?;
        let epoch_hz = m.epoch_hz.unwrap_or(5.0);
        if !(epoch_hz.is_finite() && (0.01..=100.0).contains(&epoch_hz)) {
            return Err(err(
                "monitor.epoch_hz".into(),
                format!("{epoch_hz} is out of range [0.01, 100]"),
            ));
        }
        let anchor = m.anchor.unwrap_or(layout.curves[0].nodes[0]);
        if !layout.curves.iter().any(|c| c.nodes.contains(&anchor)) {
            return Err(err(
                "monitor.anchor".into(),
                format!("node {anchor} is on no curve of the layout"),
            ));
        }
        let x_azimuth_deg = m.x_azimuth_deg.unwrap_or(90.0);
        if !(x_azimuth_deg.is_finite() && (-360.0..=360.0).contains(&x_azimuth_deg)) {
            return Err(err(
                "monitor.x_azimuth_deg".into(),
                format!("{x_azimuth_deg} is out of range [-360, 360] degrees"),
            ));
        }
        let reference_s = m.reference_s.unwrap_or(10.0);
        if !(reference_s.is_finite() && (0.0..=86_400.0).contains(&reference_s)) {
            return Err(err(
                "monitor.reference_s".into(),
                format!("{reference_s} is out of range [0, 86400] s"),
            ));
        }
        let reference = match &m.reference_file {
            None => None,
            Some(_) if m.reference_s.is_some() => {
                return Err(err(
                    "monitor.reference_file".into(),
                    "give reference_s (a reference built from the first seconds) or reference_file, not both".into(),
                ))
            }
            Some(p) => {
                let key = || "monitor.reference_file".to_string();
                let path = if p.is_relative() {
                    file.parent().unwrap_or(Path::new("")).join(p)
                } else {
                    p.clone()
                };
                let text = super::read_limited(&path, super::MAX_NAMED_FILE)
                    .map_err(|e| err(key(), format!("{}: {e}", path.display())))?;
                let r = crate::monitor::metrics::ReferenceFile::parse(&text)
                    .map_err(|e| err(key(), format!("{}: {e}", path.display())))?;
                if r.anchor != anchor {
                    return Err(err(
                        key(),
                        format!(
                            "{}: anchored at node {}, the configuration at node {anchor}",
                            path.display(),
                            r.anchor
                        ),
                    ));
                }
                let step = crate::monitor::epoch::EpochParams::default().step;
                Some(
                    r.shape(&layout.curves, step)
                        .map_err(|e| err(key(), format!("{}: {e}", path.display())))?,
                )
            }
        };
        let smoothing_s = m.smoothing_s.unwrap_or(0.0);
        if !(smoothing_s.is_finite() && (0.0..=3600.0).contains(&smoothing_s)) {
            return Err(err(
                "monitor.smoothing_s".into(),
                format!("{smoothing_s} is out of range [0, 3600] s"),
            ));
        }
        let latest_every = m.latest_every.unwrap_or(5);
        if latest_every == 0 {
            return Err(err(
                "monitor.latest_every".into(),
                "must be at least 1".into(),
            ));
        }
        let surface = match m.surface {
            Some(true) => Some(surface.ok_or_else(|| {
                err(
                    "monitor.surface".into(),
                    "true, but [surface] enabled = false".into(),
                )
            })?),
            _ => None,
        }
        .map(|mut sp| {
            // A monitored structure's cycles never change: every face is kept from the first
            // epoch, whose weights stay (back-substitutions only), unless a tolerance is set.
            if self.surface.reuse_tolerance.is_none() {
                sp.reuse_tolerance = f64::INFINITY;
            }
            sp
        });
        let regression = match m.regression {
            Some(true) => Some(network.regression),
            _ => None,
        };
        let max_mb = m.metrics_max_mb.unwrap_or(64.0);
        if !(max_mb.is_finite() && (0.01..=1e6).contains(&max_mb)) {
            return Err(err(
                "monitor.metrics_max_mb".into(),
                format!("{max_mb} is out of range [0.01, 1e6] MB"),
            ));
        }
        let mut alarms = Vec::new();
        for (k, a) in m.alarm.iter().enumerate() {
            let key = |f: &str| format!("monitor.alarm[{k}].{f}");
            let Some(metric) = AlarmMetric::from_name(&a.metric) else {
                return Err(err(
                    key("metric"),
                    format!(
                        "{:?} is not one of {:?}",
                        a.metric,
                        AlarmMetric::ALL.map(AlarmMetric::name)
                    ),
                ));
            };
            if !(a.threshold.is_finite() && a.threshold > 0.0) {
                return Err(err(
                    key("threshold"),
                    format!("{} is not positive", a.threshold),
                ));
            }
            let h = a.hysteresis.unwrap_or(0.1 * a.threshold);
            if !(h.is_finite() && (0.0..a.threshold).contains(&h)) {
                return Err(err(
                    key("hysteresis"),
                    format!("{h} is not in [0, threshold = {})", a.threshold),
                ));
            }
            alarms.push(AlarmSpec {
                metric,
                threshold: a.threshold,
                hysteresis: h,
            });
        }
        let http = match m.http_port {
            None => None,
            Some(0) => {
                return Err(err(
                    "monitor.http_port".into(),
                    "0 is not a port; leave the key out to serve no metrics".into(),
                ))
            }
            Some(port) => {
                let address = m.http_address.as_deref().unwrap_or("127.0.0.1");
                let ip: std::net::IpAddr = address.parse().map_err(|e| {
                    err(
                        "monitor.http_address".into(),
                        format!("{address:?} is not an IP address: {e}"),
                    )
                })?;
                Some(std::net::SocketAddr::new(ip, port))
            }
        };
        Ok(Some(MonitorConfig {
            http,
            layout,
            epoch_hz,
            anchor,
            x_azimuth_deg,
            reference_s,
            reference,
            smoothing_s,
            latest_every,
            surface,
            regression,
            metrics_max_bytes: (max_mb * 1e6) as u64,
            metrics_keep: m.metrics_keep.unwrap_or(4).min(1000),
            alarms,
        }))
    }
}
