//! `[monitor]`: the layout and settings of an instrumented structure.

use super::{ConfigError, ConfigFile};
use crate::monitor::alarm::AlarmMetric;
use crate::monitor::layout::{Layout, LayoutCurve, LayoutError};
use crate::monitor::metrics::Shape;
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
        let layout = layout(m, file)?;
        let in_range = |key: &str, v: f64, range: std::ops::RangeInclusive<f64>, shown: &str| {
            if v.is_finite() && range.contains(&v) {
                Ok(v)
            } else {
                Err(err(
                    format!("monitor.{key}"),
                    format!("{v} is out of range {shown}"),
                ))
            }
        };
        let epoch_hz = in_range(
            "epoch_hz",
            m.epoch_hz.unwrap_or(5.0),
            0.01..=100.0,
            "[0.01, 100]",
        )?;
        let anchor = m.anchor.unwrap_or(layout.curves[0].nodes[0]);
        if !layout.curves.iter().any(|c| c.nodes.contains(&anchor)) {
            return Err(err(
                "monitor.anchor".into(),
                format!("node {anchor} is on no curve of the layout"),
            ));
        }
        let x_azimuth_deg = in_range(
            "x_azimuth_deg",
            m.x_azimuth_deg.unwrap_or(90.0),
            -360.0..=360.0,
            "[-360, 360] degrees",
        )?;
        let reference_s = in_range(
            "reference_s",
            m.reference_s.unwrap_or(10.0),
            0.0..=86_400.0,
            "[0, 86400] s",
        )?;
        let reference = match &m.reference_file {
            None => None,
            Some(_) if m.reference_s.is_some() => {
                return Err(err(
                    "monitor.reference_file".into(),
                    "give reference_s (a reference built from the first seconds) or reference_file, not both".into(),
                ))
            }
            Some(p) => Some(reference_shape(p, file, anchor, &layout)?),
        };
        let smoothing_s = in_range(
            "smoothing_s",
            m.smoothing_s.unwrap_or(0.0),
            0.0..=3600.0,
            "[0, 3600] s",
        )?;
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
        let max_mb = in_range(
            "metrics_max_mb",
            m.metrics_max_mb.unwrap_or(64.0),
            0.01..=1e6,
            "[0.01, 1e6] MB",
        )?;
        let alarms = alarms(m, file)?;
        let http = http(m, file)?;
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

/// The layout of `[[monitor.curve]]` and `[[monitor.sensor]]`, validated (an error names the
/// curve or sensor to blame).
fn layout(m: &MonitorToml, file: &Path) -> Result<Layout, ConfigError> {
    let err = |key: String, reason: String| ConfigError::new(file, key, reason);
    let layout = Layout {
        curves: m
            .curve
            .iter()
            .enumerate()
            .map(|(index, c)| LayoutCurve {
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
        LayoutError::Curve { curve, .. } => err(format!("monitor.curve[{curve}]"), e.to_string()),
        LayoutError::Sensor { sensor, .. } => {
            let k = m
                .sensor
                .iter()
                .position(|s| s.sensor == *sensor)
                .unwrap_or(0);
            err(format!("monitor.sensor[{k}]"), e.to_string())
        }
    })?;
    Ok(layout)
}

/// The fixed reference shape of `reference_file` (`p`, relative to the configuration
/// `file`'s directory), anchored at `anchor` as the configuration is, sampled along the
/// layout's curves.
fn reference_shape(
    p: &Path,
    file: &Path,
    anchor: u32,
    layout: &Layout,
) -> Result<Shape, ConfigError> {
    let err = |reason: String| ConfigError::new(file, "monitor.reference_file", reason);
    let path = if p.is_relative() {
        file.parent().unwrap_or(Path::new("")).join(p)
    } else {
        p.to_path_buf()
    };
    let text = super::read_limited(&path, super::MAX_NAMED_FILE)
        .map_err(|e| err(format!("{}: {e}", path.display())))?;
    let r = crate::monitor::metrics::ReferenceFile::parse(&text)
        .map_err(|e| err(format!("{}: {e}", path.display())))?;
    if r.anchor != anchor {
        return Err(err(format!(
            "{}: anchored at node {}, the configuration at node {anchor}",
            path.display(),
            r.anchor
        )));
    }
    let step = crate::monitor::epoch::EpochParams::default().step;
    r.shape(&layout.curves, step)
        .map_err(|e| err(format!("{}: {e}", path.display())))
}

/// `[[monitor.alarm]]`, checked: a known metric, a positive threshold, a hysteresis below it
/// (a tenth of it by default).
fn alarms(m: &MonitorToml, file: &Path) -> Result<Vec<AlarmSpec>, ConfigError> {
    let mut alarms = Vec::new();
    for (k, a) in m.alarm.iter().enumerate() {
        let err = |f: &str, reason: String| {
            ConfigError::new(file, format!("monitor.alarm[{k}].{f}"), reason)
        };
        let Some(metric) = AlarmMetric::from_name(&a.metric) else {
            return Err(err(
                "metric",
                format!(
                    "{:?} is not one of {:?}",
                    a.metric,
                    AlarmMetric::ALL.map(AlarmMetric::name)
                ),
            ));
        };
        if !(a.threshold.is_finite() && a.threshold > 0.0) {
            return Err(err("threshold", format!("{} is not positive", a.threshold)));
        }
        let h = a.hysteresis.unwrap_or(0.1 * a.threshold);
        if !(h.is_finite() && (0.0..a.threshold).contains(&h)) {
            return Err(err(
                "hysteresis",
                format!("{h} is not in [0, threshold = {})", a.threshold),
            ));
        }
        alarms.push(AlarmSpec {
            metric,
            threshold: a.threshold,
            hysteresis: h,
        });
    }
    Ok(alarms)
}

/// The address the metrics are served on (`http_port`, on `http_address` or 127.0.0.1), if
/// any.
fn http(m: &MonitorToml, file: &Path) -> Result<Option<std::net::SocketAddr>, ConfigError> {
    let err = |key: &str, reason: String| ConfigError::new(file, key, reason);
    match m.http_port {
        None => Ok(None),
        Some(0) => Err(err(
            "monitor.http_port",
            "0 is not a port; leave the key out to serve no metrics".into(),
        )),
        Some(port) => {
            let address = m.http_address.as_deref().unwrap_or("127.0.0.1");
            let ip: std::net::IpAddr = address.parse().map_err(|e| {
                err(
                    "monitor.http_address",
                    format!("{address:?} is not an IP address: {e}"),
                )
            })?;
            Ok(Some(std::net::SocketAddr::new(ip, port)))
        }
    }
}
