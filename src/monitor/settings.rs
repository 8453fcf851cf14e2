//! The resolved monitoring settings (the `[monitor]` section of a configuration, checked and
//! with its defaults, as the configuration file gives them).

use super::alarm::AlarmMetric;

/// The resolved `[monitor]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorConfig {
    pub layout: super::layout::Layout,
    /// Epochs per second. Default 5.
    pub epoch_hz: f64,
    /// The node at the origin; default the first curve's first node.
    pub anchor: u32,
    /// The reference frame's x axis: its azimuth, degrees clockwise from magnetic north
    /// (default 90: x east, y magnetic north, z up, the sensors' own world frame). Shapes,
    /// `latest.glb` and reference files are in this frame.
    pub x_azimuth_deg: f64,
    /// Seconds at the start whose mean shape is the reference. Default 10.
    pub reference_s: f64,
    /// A fixed reference instead (`reference_file`), sampled as the epochs are.
    pub reference: Option<super::metrics::Shape>,
    /// Time constant of the smoothing of each sensor's orientation across epochs, s
    /// (0: none, the default).
    pub smoothing_s: f64,
    /// `latest.glb` is replaced every this many epochs. Default 5.
    pub latest_every: usize,
    /// The surface of the shape in `latest.glb` (`None`: the network only, the default).
    pub surface: Option<sfs_geometry::surface::fit::SurfaceParams>,
    /// The regression over the network in each epoch (`None`: the frames interpolated
    /// between the sensors as they are, the default: on the simulator's riser and panel it
    /// changed the sensors' positions by less than 0.1 mm, at 6 ms an epoch for 200 sensors).
    pub regression: Option<sfs_geometry::network::regression::RegressionParams>,
    /// `metrics.csv` is rotated past this size (default 64 MB), keeping `metrics_keep` old
    /// files (default 4).
    pub metrics_max_bytes: u64,
    pub metrics_keep: usize,
    pub alarms: Vec<AlarmSpec>,
    /// Where the Prometheus endpoint listens (`None`: off).
    pub http: Option<std::net::SocketAddr>,
}

/// An alarm of the resolved `[monitor]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmSpec {
    pub metric: AlarmMetric,
    pub threshold: f64,
    pub hysteresis: f64,
}
