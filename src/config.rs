//! Resolved configuration, read from `config/*.toml` (serde). Every error names the key and the
//! reason. Command-line flags are kept apart (`cli`) and applied on top by `main`.
//!
//! ```toml
//! [source]
//! kind = "serial"          # "serial" | "replay" | "stdin"
//! path = "/dev/ttyUSB0"    # serial port, or capture file for "replay"
//! baud = 115200
//! watchdog_ms = 3000       # silence that counts as a disconnect
//! pace = "fast"            # replay only: "fast" | "realtime" | "x10" (10× real time)
//! ```
//!
//! A relative `path` of a capture file is relative to the configuration file's directory.
//!
//! ```toml
//! [calibration]                      # of the device; vectors in sensor axes
//! acc_bias = [0.0, 0.0, 0.0]         # m/s², subtracted
//! acc_scale = [1.0, 1.0, 1.0]        # per axis, after the bias
//! mag_hard_iron = [0.0, 0.0, 0.0]    # µT, subtracted
//! mag_soft_iron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
//! gyro_bias = [0.0, 0.0, 0.0]        # rad/s
//! axes = ["x", "y", "z"]             # sensor axes giving T, B, N (default: per device kind)
//! mounting_deg = [0.0, 0.0, 0.0]     # rotation about T, B, N (roll, pitch, yaw), degrees
//!
//! [acquisition]
//! acc_tolerance = 0.6                # m/s²: | |a| - g | above flags motion acceleration
//! mag_norm_tolerance = 0.08          # relative: field norm off the session's median
//! mag_dip_tolerance_deg = 4.0        # field dip off the session's median
//! stationary_window_s = 0.25         # half-width of the standing-still test
//! stationary_distance = 0.002        # Morphorider: still if the wheel moves less (m)
//! stationary_gyro_deg_s = 3.0        # phone: still below this rotation rate
//! stand_margin_s = 2.0               # phone: standing only this close to typing an index
//! heading_bias_tau_s = 0.0           # phone: learn the gyro bias in motion from the heading
//! tilt_bias_tau_s = 0.0              #   and tilt corrections (time constants; 0 = off)
//! nominal_speed = 0.05               # phone: m/s where no segment length is known
//! array_window_s = 1.0               # sensor arrays: averaging window
//! [acquisition.segment_lengths]      # phone: measured segment lengths (m) per curve index
//! "0" = [0.30, 0.25]
//!
//! [network]                          # curve-network reconstruction
//! h = 0.01                           # sampling step, m
//! sigma = 0.3                        # pre-filter kernel width, in h
//! alpha = 0.9                        # outlier threshold on |q_i · q_i±1|
//! regression = true                  # false: pre-filter only
//! bend_fraction = 0.5                # bending smoothing length ℓ₂ in h (or bend_length in m)
//! stretch_length = 0.0               # stretching smoothing length ℓ₁, m
//! xi = 1e4                           # weight of the node normal consistency
//!
//! [surface]                          # surfacing with normal control
//! enabled = true                     # false: write the network only
//! edge = 0.01                        # target edge inside patches, m (default: the samples'
//!                                    # spacing, at least 1/120 of the network's diagonal)
//! max_vertices = 20000               # the default edge grows to keep about this many vertices
//! reweight = 1                       # passes with cotangent weights from the 3D surface
//! soft = 0.3                         # soft positional constraints of weight ω; 0: hard
//!
//! [monitor]                          # instrumented structures (sensor arrays)
//! epoch_hz = 5.0                     # shapes per second
//! anchor = 0                         # the node at the origin (default: curve 0's first)
//! x_azimuth_deg = 90.0               # the structure's x axis, clockwise from magnetic north
//!                                    #   (default: x east, y north, z up)
//! reference_s = 10.0                 # the mean shape of the first seconds is the reference,
//! # reference_file = "reference.json" #   or a fixed one (a session's reference.json, or a design)
//! smoothing_s = 0.0                  # smooth each sensor across epochs (time constant, s)
//! latest_every = 5                   # latest.glb replaced every this many epochs
//! surface = false                    # true: latest.glb with the surface ([surface] settings)
//! regression = false                 # true: the regression on SO(3) over the network in each
//!                                    #   epoch ([network] settings)
//! metrics_max_mb = 64.0              # metrics.csv rotated past this size …
//! metrics_keep = 4                   # … keeping this many old files
//! http_port = 9464                   # Prometheus metrics at http://127.0.0.1:9464/metrics
//! http_address = "127.0.0.1"         #   (off without http_port; 0.0.0.0 to serve others)
//! [[monitor.alarm]]                  # any number; metric: max_displacement,
//! metric = "max_displacement"        #   mean_displacement or max_curvature_change
//! threshold = 0.5                    # m (rad/m for curvature): raised above it …
//! hysteresis = 0.05                  # … cleared below threshold − hysteresis
//! [[monitor.curve]]                  # curve 0, 1, … in order
//! nodes = [0, 1]                     # nodes along it
//! node_s = [0.0, 20.0]               # their rest arc lengths, m
//! length = 20.0
//! [[monitor.sensor]]
//! sensor = 0                         # the id in ARRAY_SAMPLE packets
//! curve = 0
//! s = 0.0                            # rest arc length on the curve, m
//!
//! [output]                           # what `sfs run` writes into the session directory
//! live = true                        # rebuild network.glb and report.json after every curve
//! snapshots = false                  # also keep snapshots/curve-NNN.glb per curve
//! capture_max_mb = 256.0             # capture.bin rotated past this size (default: never;
//! capture_keep = 8                   #   256 MB and 8 kept when monitoring) … keeping this many
//! ```

use crate::acquisition::AcquisitionConfig;
use crate::monitor::alarm::AlarmMetric;
use crate::monitor::settings::{AlarmSpec, MonitorConfig};
use crate::sensor::{AxisMap, CalibrationSpec};
use crate::source::{Pace, SerialSpec, SourceSpec};
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Default serial speed (the wire format's default; a phone's Bluetooth serial ignores it).
pub const DEFAULT_BAUD: u32 = 115_200;
/// Default serial silence watchdog.
pub const DEFAULT_WATCHDOG_MS: u64 = 3_000;

/// A configuration error: the file, the key, the reason.
#[derive(Debug, thiserror::Error)]
#[error("{}: {key}: {reason}", file.display())]
pub struct ConfigError {
    pub file: PathBuf,
    /// Dotted key (`source.baud`), or `-` when the file itself is at fault.
    pub key: String,
    pub reason: String,
}

/// The whole configuration file.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub source: SourceConfig,
    #[serde(default)]
    pub calibration: CalibrationConfig,
    #[serde(default)]
    pub acquisition: AcquisitionToml,
    #[serde(default)]
    pub network: NetworkToml,
    #[serde(default)]
    pub surface: SurfaceToml,
    #[serde(default)]
    pub output: OutputToml,
    /// Monitoring of an instrumented structure (see the module documentation).
    pub monitor: Option<MonitorToml>,
}

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

/// `[output]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputToml {
    pub live: Option<bool>,
    pub snapshots: Option<bool>,
    pub capture_max_mb: Option<f64>,
    pub capture_keep: Option<usize>,
}

/// `[surface]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceToml {
    pub enabled: Option<bool>,
    pub edge: Option<f64>,
    pub max_vertices: Option<usize>,
    pub reweight: Option<usize>,
    pub soft: Option<f64>,
}

/// `[network]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkToml {
    pub h: Option<f64>,
    pub sigma: Option<f64>,
    pub alpha: Option<f64>,
    pub regression: Option<bool>,
    pub bend_length: Option<f64>,
    pub bend_fraction: Option<f64>,
    pub stretch_length: Option<f64>,
    pub xi: Option<f64>,
}

/// `[calibration]`, as written (see the module documentation).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationConfig {
    #[serde(default = "zero3")]
    pub acc_bias: [f64; 3],
    #[serde(default = "one3")]
    pub acc_scale: [f64; 3],
    #[serde(default = "zero3")]
    pub mag_hard_iron: [f64; 3],
    #[serde(default = "eye3")]
    pub mag_soft_iron: [[f64; 3]; 3],
    #[serde(default = "zero3")]
    pub gyro_bias: [f64; 3],
    pub axes: Option<Vec<String>>,
    #[serde(default = "zero3")]
    pub mounting_deg: [f64; 3],
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        CalibrationConfig {
            acc_bias: zero3(),
            acc_scale: one3(),
            mag_hard_iron: zero3(),
            mag_soft_iron: eye3(),
            gyro_bias: zero3(),
            axes: None,
            mounting_deg: zero3(),
        }
    }
}

fn zero3() -> [f64; 3] {
    [0.0; 3]
}
fn one3() -> [f64; 3] {
    [1.0; 3]
}
fn eye3() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

/// `[acquisition]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AcquisitionToml {
    pub acc_tolerance: Option<f64>,
    pub mag_norm_tolerance: Option<f64>,
    pub mag_dip_tolerance_deg: Option<f64>,
    pub stationary_window_s: Option<f64>,
    pub stationary_distance: Option<f64>,
    pub stationary_gyro_deg_s: Option<f64>,
    pub stand_margin_s: Option<f64>,
    pub heading_bias_tau_s: Option<f64>,
    pub tilt_bias_tau_s: Option<f64>,
    pub nominal_speed: Option<f64>,
    pub array_window_s: Option<f64>,
    #[serde(default)]
    pub segment_lengths: BTreeMap<String, Vec<f64>>,
}

/// `[source]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    #[serde(default = "default_kind")]
    pub kind: String,
    pub path: Option<PathBuf>,
    #[serde(default = "default_baud")]
    pub baud: u32,
    #[serde(default = "default_watchdog_ms")]
    pub watchdog_ms: u64,
    #[serde(default = "default_pace")]
    pub pace: String,
}

impl Default for SourceConfig {
    fn default() -> Self {
        SourceConfig {
            kind: default_kind(),
            path: None,
            baud: DEFAULT_BAUD,
            watchdog_ms: DEFAULT_WATCHDOG_MS,
            pace: default_pace(),
        }
    }
}

fn default_kind() -> String {
    "serial".into()
}
fn default_baud() -> u32 {
    DEFAULT_BAUD
}
fn default_watchdog_ms() -> u64 {
    DEFAULT_WATCHDOG_MS
}
fn default_pace() -> String {
    "fast".into()
}

impl Config {
    /// Reads and validates `path`. Relative paths inside it are taken relative to the
    /// directory of the file, so a shipped configuration works from any working directory.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: path.to_owned(),
            key: "-".into(),
            reason: format!("cannot read: {e}"),
        })?;
        Self::from_text(&text, path)
    }

    /// As [`load`](Self::load), for the text of a file at `path` (relative paths in it are
    /// relative to its directory).
    pub fn from_text(text: &str, path: &Path) -> Result<Config, ConfigError> {
        let mut cfg = Self::parse(text, path)?;
        let base = path.parent().unwrap_or(Path::new(""));
        if let Some(p) = &mut cfg.source.path {
            if p.is_relative() && cfg.source.kind != "serial" {
                *p = base.join(&*p);
            }
        }
        Ok(cfg)
    }

    /// Parses and validates `text` (read from `file`, for messages).
    pub fn parse(text: &str, file: &Path) -> Result<Config, ConfigError> {
        let cfg: Config = toml::from_str(text).map_err(|e| ConfigError {
            file: file.to_owned(),
            key: e
                .span()
                .map(|s| key_at(text, s.start))
                .unwrap_or_else(|| "-".into()),
            reason: e.message().trim().to_owned(),
        })?;
        cfg.source_spec(file)?;
        cfg.acquisition_config(file)?;
        cfg.network_params(file)?;
        cfg.surface_params(file)?;
        cfg.monitor_config(file)?;
        cfg.capture_rotation(file)?;
        Ok(cfg)
    }

    /// The monitoring layout and settings (`None` without a `[monitor]` section).
    pub fn monitor_config(&self, file: &Path) -> Result<Option<MonitorConfig>, ConfigError> {
        let Some(m) = &self.monitor else {
            return Ok(None);
        };
        let err = |key: String, reason: String| ConfigError {
            file: file.to_owned(),
            key,
            reason,
        };
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
                let text = std::fs::read_to_string(&path)
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
            Some(true) => Some(self.surface_params(file)?.ok_or_else(|| {
                err(
                    "monitor.surface".into(),
                    "true, but [surface] enabled = false".into(),
                )
            })?),
            _ => None,
        };
        let regression = match m.regression {
            Some(true) => Some(self.network_params(file)?.regression),
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

    /// The reconstruction settings this configuration describes.
    pub fn network_params(
        &self,
        file: &Path,
    ) -> Result<sfs_geometry::network::NetworkParams, ConfigError> {
        let n = &self.network;
        let mut p = sfs_geometry::network::NetworkParams::default();
        let check =
            |key: &str, v: Option<f64>, lo: f64, hi: f64| -> Result<Option<f64>, ConfigError> {
                match v {
                    Some(x) if !(x.is_finite() && x >= lo && x <= hi) => Err(ConfigError {
                        file: file.to_owned(),
                        key: format!("network.{key}"),
                        reason: format!("{x} is out of range [{lo}, {hi}]"),
                    }),
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
        Ok(p)
    }

    /// The rotation of a live session's capture (`None`: one file that grows): set by
    /// `[output] capture_max_mb` / `capture_keep`; on by default when monitoring (256 MB, 8
    /// kept), since an unattended run would otherwise fill the disk.
    pub fn capture_rotation(
        &self,
        file: &Path,
    ) -> Result<Option<crate::capture::Rotation>, ConfigError> {
        let o = &self.output;
        let monitoring = self.monitor.is_some();
        let max_mb = match o.capture_max_mb {
            Some(x) => x,
            None if monitoring => 256.0,
            None if o.capture_keep.is_some() => {
                return Err(ConfigError {
                    file: file.to_owned(),
                    key: "output.capture_keep".into(),
                    reason: "needs output.capture_max_mb (the capture is rotated only past a size)"
                        .into(),
                })
            }
            None => return Ok(None),
        };
        if !(max_mb.is_finite() && (0.01..=1e7).contains(&max_mb)) {
            return Err(ConfigError {
                file: file.to_owned(),
                key: "output.capture_max_mb".into(),
                reason: format!("{max_mb} is out of range [0.01, 1e7] MB"),
            });
        }
        Ok(Some(crate::capture::Rotation {
            max_bytes: (max_mb * 1e6) as u64,
            keep: o.capture_keep.unwrap_or(8).min(100_000),
        }))
    }

    /// The surfacing settings this configuration describes (`None`: surfacing disabled).
    pub fn surface_params(
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
                return Err(ConfigError {
                    file: file.to_owned(),
                    key: "surface.edge".into(),
                    reason: format!("{e} is out of range [0.0001, 10] m"),
                });
            }
            p.edge = Some(e);
        }
        if let Some(m) = s.max_vertices {
            if !(100..=10_000_000).contains(&m) {
                return Err(ConfigError {
                    file: file.to_owned(),
                    key: "surface.max_vertices".into(),
                    reason: format!("{m} is out of range [100, 10000000]"),
                });
            }
            p.max_vertices = m;
        }
        if let Some(r) = s.reweight {
            if r > 10 {
                return Err(ConfigError {
                    file: file.to_owned(),
                    key: "surface.reweight".into(),
                    reason: format!("{r} passes is more than 10"),
                });
            }
            p.reweight = r;
        }
        p.soft = crate::pipeline::SCAN_SOFTNESS;
        if let Some(w) = s.soft {
            if !(w.is_finite() && (0.0..=1e6).contains(&w)) {
                return Err(ConfigError {
                    file: file.to_owned(),
                    key: "surface.soft".into(),
                    reason: format!("{w} is out of range [0, 1e6] (0: hard constraints)"),
                });
            }
            p.soft = (w > 0.0).then_some(w);
        }
        Ok(Some(p))
    }

    /// The acquisition settings (calibration included) this configuration describes.
    pub fn acquisition_config(&self, file: &Path) -> Result<AcquisitionConfig, ConfigError> {
        let err = |key: &str, reason: String| ConfigError {
            file: file.to_owned(),
            key: key.to_owned(),
            reason,
        };
        let c = &self.calibration;
        let finite = |key: &str, v: &[f64]| -> Result<(), ConfigError> {
            match v.iter().find(|x| !x.is_finite()) {
                Some(x) => Err(err(key, format!("{x} is not a finite number"))),
                None => Ok(()),
            }
        };
        finite("calibration.acc_bias", &c.acc_bias)?;
        finite("calibration.acc_scale", &c.acc_scale)?;
        finite("calibration.mag_hard_iron", &c.mag_hard_iron)?;
        finite("calibration.mag_soft_iron", c.mag_soft_iron.as_flattened())?;
        finite("calibration.gyro_bias", &c.gyro_bias)?;
        finite("calibration.mounting_deg", &c.mounting_deg)?;
        if let Some(x) = c.acc_scale.iter().find(|&&x| x <= 0.0) {
            return Err(err(
                "calibration.acc_scale",
                format!("{x} is not a positive scale"),
            ));
        }
        let soft = Matrix3::from_row_slice(c.mag_soft_iron.as_flattened());
        if soft.determinant().abs() < 1e-6 {
            return Err(err(
                "calibration.mag_soft_iron",
                "the matrix is singular".into(),
            ));
        }
        if let Some(x) = c.mounting_deg.iter().find(|x| x.abs() > 45.0) {
            return Err(err(
                "calibration.mounting_deg",
                format!("{x}° is not a small mounting offset (at most 45°); fix `axes` instead"),
            ));
        }
        let axes = match &c.axes {
            Some(names) => Some(AxisMap::parse(names).map_err(|e| err("calibration.axes", e))?),
            None => None,
        };
        let [r, p, y] = c.mounting_deg.map(f64::to_radians);
        let calibration = CalibrationSpec {
            acc_bias: Vector3::from(c.acc_bias),
            acc_scale: Vector3::from(c.acc_scale),
            mag_hard_iron: Vector3::from(c.mag_hard_iron),
            mag_soft_iron: soft,
            gyro_bias: Vector3::from(c.gyro_bias),
            axes,
            mounting: Rotation3::from_euler_angles(r, p, y),
        };

        let a = &self.acquisition;
        let mut out = AcquisitionConfig {
            calibration,
            ..AcquisitionConfig::default()
        };
        let positive = |key: &str, v: Option<f64>, max: f64| -> Result<Option<f64>, ConfigError> {
            match v {
                Some(x) if !(x.is_finite() && x > 0.0 && x <= max) => {
                    Err(err(key, format!("{x} is out of range (0, {max}]")))
                }
                v => Ok(v),
            }
        };
        let th = &mut out.thresholds;
        if let Some(x) = positive("acquisition.acc_tolerance", a.acc_tolerance, 20.0)? {
            th.acc_tol = x;
        }
        if let Some(x) = positive("acquisition.mag_norm_tolerance", a.mag_norm_tolerance, 1.0)? {
            th.mag_norm_rel = x;
        }
        if let Some(x) = positive(
            "acquisition.mag_dip_tolerance_deg",
            a.mag_dip_tolerance_deg,
            90.0,
        )? {
            th.mag_dip_deg = x;
        }
        if let Some(x) = positive(
            "acquisition.stationary_window_s",
            a.stationary_window_s,
            10.0,
        )? {
            out.stationary_window = x;
        }
        if let Some(x) = positive(
            "acquisition.stationary_gyro_deg_s",
            a.stationary_gyro_deg_s,
            90.0,
        )? {
            out.stationary_gyro = x.to_radians();
        }
        if let Some(x) = positive("acquisition.stand_margin_s", a.stand_margin_s, 60.0)? {
            out.stand_margin = x;
        }
        // 0 turns the bias learning in motion off.
        let off_or_positive = |key: &str, v: Option<f64>| match v {
            Some(0.0) => Ok(Some(0.0)),
            v => positive(key, v, 3600.0),
        };
        if let Some(x) = off_or_positive("acquisition.heading_bias_tau_s", a.heading_bias_tau_s)? {
            out.ahrs.tau_heading_bias = x;
        }
        if let Some(x) = off_or_positive("acquisition.tilt_bias_tau_s", a.tilt_bias_tau_s)? {
            out.ahrs.tau_tilt_bias = x;
        }
        if let Some(x) = positive("acquisition.nominal_speed", a.nominal_speed, 10.0)? {
            out.nominal_speed = x;
        }
        if let Some(x) = positive("acquisition.array_window_s", a.array_window_s, 3600.0)? {
            out.array_window = x;
        }
        for (k, v) in &a.segment_lengths {
            let key = format!("acquisition.segment_lengths.{k}");
            let idx: usize = k
                .parse()
                .map_err(|_| err(&key, format!("{k:?} is not a curve index (0, 1, 2, …)")))?;
            if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(err(
                    &key,
                    format!("length {x} is not a positive number of metres"),
                ));
            }
            out.segment_lengths.insert(idx, v.clone());
        }
        Ok(out)
    }

    /// The source this configuration describes.
    pub fn source_spec(&self, file: &Path) -> Result<SourceSpec, ConfigError> {
        let s = &self.source;
        let err = |key: &str, reason: String| ConfigError {
            file: file.to_owned(),
            key: format!("source.{key}"),
            reason,
        };
        let need_path = || {
            s.path
                .clone()
                .filter(|p| !p.as_os_str().is_empty())
                .ok_or_else(|| err("path", format!("required when source.kind = {:?}", s.kind)))
        };
        let pace: Pace = s.pace.parse().map_err(|e| err("pace", e))?;
        if s.baud == 0 {
            return Err(err(
                "baud",
                "must be a positive number of bits per second".into(),
            ));
        }
        if s.watchdog_ms < 100 {
            return Err(err(
                "watchdog_ms",
                format!(
                    "{} ms is too short to tell silence from a slow device (minimum 100)",
                    s.watchdog_ms
                ),
            ));
        }
        match s.kind.as_str() {
            "serial" => {
                let mut spec = SerialSpec::new(need_path()?, s.baud);
                spec.watchdog = Duration::from_millis(s.watchdog_ms);
                Ok(SourceSpec::Serial(spec))
            }
            "replay" => Ok(SourceSpec::Replay {
                path: need_path()?,
                pace,
            }),
            "stdin" => Ok(SourceSpec::Stdin),
            other => Err(err(
                "kind",
                format!(
                    "unknown source kind {other:?}: expected \"serial\", \"replay\" or \"stdin\""
                ),
            )),
        }
    }
}

/// The dotted key whose line contains byte offset `at` (best effort, for error messages).
fn key_at(text: &str, at: usize) -> String {
    let mut table = String::new();
    let mut key = String::new();
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        let t = line.trim();
        if t.starts_with('[') {
            table = t.trim_matches(|c| c == '[' || c == ']').trim().to_owned();
            key.clear();
        } else if let Some((k, _)) = t.split_once('=') {
            key = k.trim().to_owned();
        }
        if at < pos + line.len() {
            break;
        }
        pos += line.len();
    }
    match (table.is_empty(), key.is_empty()) {
        (true, true) => "-".into(),
        (true, false) => key,
        (false, true) => table,
        (false, false) => format!("{table}.{key}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(t: &str) -> Result<Config, ConfigError> {
        Config::parse(t, Path::new("x.toml"))
    }

    #[test]
    fn serial_with_defaults() {
        let c = parse("[source]\nkind = \"serial\"\npath = \"/dev/ttyUSB0\"\n").unwrap();
        match c.source_spec(Path::new("x")).unwrap() {
            SourceSpec::Serial(s) => {
                assert_eq!(s.baud, DEFAULT_BAUD);
                assert_eq!(s.watchdog, Duration::from_millis(DEFAULT_WATCHDOG_MS));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn errors_name_the_key() {
        let e =
            parse("[source]\nkind = \"serial\"\npath = \"/dev/x\"\nbaud = \"fast\"\n").unwrap_err();
        assert_eq!(e.key, "source.baud", "{e}");
        let e = parse("[source]\nkind = \"serial\"\n").unwrap_err();
        assert_eq!(e.key, "source.path", "{e}");
        let e = parse("[source]\nkind = \"usb\"\npath = \"/dev/x\"\n").unwrap_err();
        assert_eq!(e.key, "source.kind", "{e}");
        let e =
            parse("[source]\nkind = \"serial\"\npath = \"/dev/x\"\nbaudrate = 9600\n").unwrap_err();
        assert_eq!(e.key, "source.baudrate", "{e}");
        assert!(e.reason.contains("unknown field"), "{e}");
        let e =
            parse("[source]\nkind = \"replay\"\npath = \"a.bin\"\npace = \"slow\"\n").unwrap_err();
        assert_eq!(e.key, "source.pace", "{e}");
    }

    #[test]
    fn monitor_layout_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let curve = "[[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n";
        let sensor = |id: u16, c: usize, s: f64| {
            format!("[[monitor.sensor]]\nsensor = {id}\ncurve = {c}\ns = {s}\n")
        };
        let ok = parse(&format!(
            "{base}[monitor]\nepoch_hz = 2.0\n{curve}{}{}",
            sensor(0, 0, 0.0),
            sensor(1, 0, 20.0)
        ))
        .unwrap();
        let m = ok.monitor_config(Path::new("x")).unwrap().unwrap();
        assert_eq!((m.layout.sensors.len(), m.epoch_hz, m.anchor), (2, 2.0, 0));
        assert_eq!(m.http, None, "no endpoint unless asked for");
        assert_eq!(
            (m.regression, m.surface.is_some()),
            (None, false),
            "off by default"
        );
        let on = parse(&format!(
            "{base}[network]\nxi = 2.0\n[monitor]\nregression = true\nsurface = true\n{curve}"
        ))
        .unwrap()
        .monitor_config(Path::new("x"))
        .unwrap()
        .unwrap();
        assert_eq!(
            on.regression.map(|r| r.xi),
            Some(2.0),
            "with the [network] settings"
        );
        assert!(on.surface.is_some());
        let cases = [
            (format!("[monitor]\n{curve}{}", sensor(0, 1, 0.0)), "monitor.sensor[0]", "curve 1"),
            (
                format!("[monitor]\n{curve}{}{}", sensor(0, 0, 0.0), sensor(0, 0, 1.0)),
                "monitor.sensor[0]",
                "twice",
            ),
            (format!("[monitor]\n{curve}{}", sensor(3, 0, 25.0)), "monitor.sensor[0]", "outside"),
            (
                "[monitor]\n[[monitor.curve]]\nnodes = [0, 1]\nnode_s = [5.0, 1.0]\nlength = 20.0\n"
                    .to_string(),
                "monitor.curve[0]",
                "increase",
            ),
            (format!("[monitor]\nepoch_hz = 0.0\n{curve}"), "monitor.epoch_hz", "out of range"),
            (format!("[monitor]\nanchor = 7\n{curve}"), "monitor.anchor", "node 7"),
            ("[monitor]\nepoch_hz = 1.0\n".to_string(), "monitor.curve", "at least one"),
            (format!("[monitor]\nhttp_port = 0\n{curve}"), "monitor.http_port", "not a port"),
            (
                format!("[surface]\nenabled = false\n[monitor]\nsurface = true\n{curve}"),
                "monitor.surface",
                "enabled = false",
            ),
            (
                format!("[monitor]\nhttp_port = 9464\nhttp_address = \"localhost\"\n{curve}"),
                "monitor.http_address",
                "not an IP",
            ),
            (
                format!("[monitor]\n{curve}[[monitor.alarm]]\nmetric = \"tip\"\nthreshold = 1.0\n"),
                "monitor.alarm[0].metric",
                "not one of",
            ),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
    }

    #[test]
    fn monitor_reference_file_errors_name_the_key_and_the_file() {
        let dir = std::env::temp_dir().join(format!("sfs-config-ref-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("monitor.toml");
        let reference = |anchor: u32, curve: usize| {
            format!(
                r#"{{"format": "sfs-monitor-reference", "version": 1, "anchor": {anchor},
                    "curves": [{{"curve": {curve}, "points": [[0, 0, 0], [0, 0, 20]]}}]}}"#
            )
        };
        std::fs::write(dir.join("good.json"), reference(0, 0)).unwrap();
        std::fs::write(dir.join("anchor.json"), reference(1, 0)).unwrap();
        std::fs::write(dir.join("curve.json"), reference(0, 3)).unwrap();
        std::fs::write(
            dir.join("format.json"),
            r#"{"format": "x", "version": 1, "anchor": 0, "curves": []}"#,
        )
        .unwrap();
        let text = |keys: &str| {
            format!(
                "[source]\nkind = \"stdin\"\n[monitor]\n{keys}\n[[monitor.curve]]\nnodes = [0, 1]\n\
                 node_s = [0.0, 20.0]\nlength = 20.0\n"
            )
        };
        let m = Config::parse(&text("reference_file = \"good.json\""), &file)
            .unwrap()
            .monitor_config(&file)
            .unwrap()
            .unwrap();
        // Relative to the configuration's directory; sampled every 5 cm.
        assert_eq!(m.reference.unwrap().curves[0].1.len(), 401);
        let cases = [
            ("reference_file = \"none.json\"", "none.json"),
            ("reference_file = \"anchor.json\"", "anchored at node 1"),
            (
                "reference_file = \"curve.json\"",
                "curve 3 is not in the layout",
            ),
            (
                "reference_file = \"format.json\"",
                "is not \"sfs-monitor-reference\"",
            ),
            (
                "reference_file = \"good.json\"\nreference_s = 3.0",
                "not both",
            ),
        ];
        for (keys, reason) in cases {
            let e = Config::parse(&text(keys), &file).unwrap_err();
            assert_eq!(e.key, "monitor.reference_file", "{keys}: {e}");
            assert!(e.reason.contains(reason), "{keys}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn surface_and_output_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let cases = [
            ("[surface]\nedge = 0.0\n", "surface.edge", "out of range"),
            (
                "[surface]\nmax_vertices = 10\n",
                "surface.max_vertices",
                "out of range",
            ),
            (
                "[surface]\nreweight = 11\n",
                "surface.reweight",
                "more than 10",
            ),
            ("[surface]\nsoft = -1.0\n", "surface.soft", "out of range"),
            (
                "[output]\nsnapshot = true\n",
                "output.snapshot",
                "unknown field",
            ),
            ("[output]\nlive = \"yes\"\n", "output.live", "bool"),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
        let ok = parse(&format!(
            "{base}[surface]\nmax_vertices = 5000\nsoft = 0\n[output]\nsnapshots = true\n"
        ))
        .unwrap();
        let s = ok.surface_params(Path::new("x")).unwrap().unwrap();
        assert_eq!((s.max_vertices, s.soft), (5000, None));
        assert_eq!(ok.output.snapshots, Some(true));
    }

    #[test]
    fn calibration_and_acquisition_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let cases = [
            ("[calibration]\naxes = [\"y\", \"x\", \"z\"]\n", "calibration.axes", "reflection"),
            ("[calibration]\nacc_scale = [1.0, 0.0, 1.0]\n", "calibration.acc_scale", "positive"),
            (
                "[calibration]\nmag_soft_iron = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]\n",
                "calibration.mag_soft_iron",
                "singular",
            ),
            ("[calibration]\nmounting_deg = [0.0, 90.0, 0.0]\n", "calibration.mounting_deg", "45"),
            ("[calibration]\nacc_bias = [0.0, 0.0]\n", "calibration.acc_bias", ""),
            ("[acquisition]\nnominal_speed = -1.0\n", "acquisition.nominal_speed", "out of range"),
            (
                "[acquisition.segment_lengths]\nfirst = [0.3]\n",
                "acquisition.segment_lengths.first",
                "curve index",
            ),
            ("[acquisition]\nspeed = 1.0\n", "acquisition.speed", "unknown field"),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
        let ok = parse(&format!(
            "{base}[calibration]\naxes = [\"y\", \"-x\", \"z\"]\nmounting_deg = [0.0, 0.0, 2.0]\n\
             [acquisition.segment_lengths]\n\"0\" = [0.3, 0.2]\n"
        ))
        .unwrap();
        let a = ok.acquisition_config(Path::new("x")).unwrap();
        let e = parse(&format!("{base}[network]\nh = -1.0\n")).unwrap_err();
        assert_eq!(e.key, "network.h", "{e}");
        let e = parse(&format!("{base}[network]\nsmoothing = 1.0\n")).unwrap_err();
        assert_eq!(e.key, "network.smoothing", "{e}");
        let n = parse(&format!("{base}[network]\nh = 0.005\nregression = false\n"))
            .unwrap()
            .network_params(Path::new("x"))
            .unwrap();
        assert!(n.no_regression && (n.prefilter.h - 0.005).abs() < 1e-15);
        assert_eq!(a.segment_lengths[&0], vec![0.3, 0.2]);
        assert!((a.calibration.mounting.angle() - 2f64.to_radians()).abs() < 1e-12);
    }
}
