//! Monitoring mode: fixed arrays of accelerometer + magnetometer sensors on a structure
//! (a riser, a sail, a panel) stream continuously; the shape is reconstructed epoch by epoch
//! with the scanning engine (frames on SO(3), Poisson network).
//!
//! - [`settings`]: the resolved `[monitor]` section.
//! - [`layout`]: where the sensors are (curve, rest arc length) and where the curves cross.
//! - [`epoch`]: one epoch's orientations → the shape.
//! - [`metrics`]: displacement and curvature change from a reference shape.
//! - [`alarm`]: thresholds with hysteresis on the metrics.
//! - [`run`]: the monitoring loop of a session (epochs → shape → metrics → alarms → files).
//! - the metrics for a Prometheus scraper: [`crate::metrics::MonitorMetrics`], served by the
//!   view's server at `/metrics` (`[monitor] http_port`).

pub mod alarm;
pub mod epoch;
pub mod layout;
pub mod metrics;
pub mod run;
pub mod settings;
