//! The Prometheus metrics of a session, written with `prometheus-client` (OpenMetrics text at
//! the view server's `GET /metrics`): in every session the link, curve and latency counters
//! ([`SessionMetrics`]); when monitoring, the latest epoch's gauges and the alarms too
//! ([`MonitorMetrics`], updated by the monitor).
//!
//! ```
//! let m = sfs::metrics::SessionMetrics::new(None);
//! m.curves_accepted.inc();
//! assert!(m.encode().contains("sfs_curves_accepted_total 1"));
//! ```

use crate::link::LinkStats;
use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::{Registry, Unit};
use std::sync::atomic::AtomicU64;
use std::sync::Mutex;

/// A gauge of an `f64`.
pub type GaugeF64 = Gauge<f64, AtomicU64>;
/// Label sets as `(name, value)` pairs.
pub type Labels = Vec<(String, String)>;

/// The counters of every session, and the registry that encodes them (with the monitor's when
/// monitoring).
#[derive(Debug)]
pub struct SessionMetrics {
    registry: Registry,
    pub link_bytes: Counter,
    /// Valid packets by wire-format type (`type` label).
    pub link_packets: Family<Labels, Counter>,
    /// Frames dropped by reason (`reason`: crc, cobs, length, …).
    pub link_rejected: Family<Labels, Counter>,
    pub link_lost: Counter,
    pub link_reboots: Counter,
    pub link_disconnects: Counter,
    /// 1 while the device is connected (`connected` or `silent`), 0 otherwise.
    pub link_up: Gauge,
    pub curves_accepted: Counter,
    pub curves_discarded: Counter,
    pub warnings: Counter,
    /// Live reconstructions that wrote `network.glb`.
    pub updates: Counter,
    /// The latest reconstruction's verdict (issue 49): 0 good, 1 suspect, 2 inconsistent,
    /// −1 nothing reconstructed yet.
    pub scan_verdict: Gauge,
    /// Suspects named (a tag or curve that looks wrong), each once.
    pub suspects: Counter,
    /// From the `E` key packet to `network.glb` in place, seconds: the latest p50 and p95.
    pub latency_p50: GaugeF64,
    pub latency_p95: GaugeF64,
    /// The link totals already counted (the counters move by the difference).
    last_link: Mutex<LinkStats>,
}

impl SessionMetrics {
    /// The session's metrics, with the monitor's registered beside them when given.
    pub fn new(monitor: Option<&MonitorMetrics>) -> SessionMetrics {
        let mut registry = Registry::with_prefix("sfs");
        let m = SessionMetrics {
            registry: Registry::default(),
            link_bytes: Counter::default(),
            link_packets: Family::default(),
            link_rejected: Family::default(),
            link_lost: Counter::default(),
            link_reboots: Counter::default(),
            link_disconnects: Counter::default(),
            link_up: Gauge::default(),
            curves_accepted: Counter::default(),
            curves_discarded: Counter::default(),
            warnings: Counter::default(),
            updates: Counter::default(),
            scan_verdict: Gauge::default(),
            suspects: Counter::default(),
            latency_p50: GaugeF64::default(),
            latency_p95: GaugeF64::default(),
            last_link: Mutex::new(LinkStats::default()),
        };
        registry.register_with_unit(
            "link_received",
            "Bytes received from the device (read, for a replay)",
            Unit::Bytes,
            m.link_bytes.clone(),
        );
        registry.register(
            "link_packets",
            "Valid packets, by type",
            m.link_packets.clone(),
        );
        registry.register(
            "link_rejected",
            "Frames dropped, by reason",
            m.link_rejected.clone(),
        );
        registry.register(
            "link_lost_packets",
            "Packets the device sent that never arrived (sequence gaps)",
            m.link_lost.clone(),
        );
        registry.register(
            "link_reboots",
            "Device restarts seen in the stream",
            m.link_reboots.clone(),
        );
        registry.register(
            "link_disconnects",
            "Times the device was lost (unplug, read error, watchdog)",
            m.link_disconnects.clone(),
        );
        registry.register(
            "link_up",
            "1 while the device is connected (bytes flowing or silent), 0 while it is lost or not yet connected",
            m.link_up.clone(),
        );
        registry.register(
            "curves_accepted",
            "Curves ended with two tags or more",
            m.curves_accepted.clone(),
        );
        registry.register(
            "curves_discarded",
            "Curves cancelled or ended with too few tags",
            m.curves_discarded.clone(),
        );
        registry.register(
            "warnings",
            "Warnings raised (keypad, acquisition, reconstruction)",
            m.warnings.clone(),
        );
        registry.register(
            "updates",
            "Live reconstructions that wrote network.glb",
            m.updates.clone(),
        );
        m.scan_verdict.set(-1);
        registry.register(
            "scan_verdict",
            "The scan's verdict: 0 good, 1 suspect, 2 inconsistent, -1 nothing reconstructed yet",
            m.scan_verdict.clone(),
        );
        registry.register(
            "suspects",
            "Tags or curves named as looking wrong (late Enter, wrong node), each once",
            m.suspects.clone(),
        );
        registry.register_with_unit(
            "latency_p50",
            "From the E key packet to network.glb in place: median so far",
            Unit::Seconds,
            m.latency_p50.clone(),
        );
        registry.register_with_unit(
            "latency_p95",
            "From the E key packet to network.glb in place: 95th percentile so far",
            Unit::Seconds,
            m.latency_p95.clone(),
        );
        if let Some(mon) = monitor {
            mon.register(&mut registry);
        }
        SessionMetrics { registry, ..m }
    }

    /// Moves the link counters to the totals of `stats`.
    pub fn link(&self, stats: &LinkStats) {
        let Ok(mut last) = self.last_link.lock() else {
            return;
        };
        let up = |c: &Counter, now: u64, before: u64| {
            c.inc_by(now.saturating_sub(before));
        };
        up(&self.link_bytes, stats.bytes, last.bytes);
        up(&self.link_lost, stats.lost_packets, last.lost_packets);
        up(&self.link_reboots, stats.reboots, last.reboots);
        up(&self.link_disconnects, stats.disconnects, last.disconnects);
        let (now, before) = (stats.packets.by_name(), last.packets.by_name());
        for ((name, n), (_, b)) in now.iter().zip(&before) {
            if n > b {
                let l = vec![("type".to_string(), name.to_string())];
                self.link_packets.get_or_create(&l).inc_by(n - b);
            }
        }
        let (now, before) = (stats.rejected.by_reason(), last.rejected.by_reason());
        for ((reason, n), (_, b)) in now.iter().zip(&before) {
            if n > b {
                let l = vec![("reason".to_string(), reason.to_string())];
                self.link_rejected.get_or_create(&l).inc_by(n - b);
            }
        }
        *last = stats.clone();
    }

    /// The OpenMetrics text of every metric.
    pub fn encode(&self) -> String {
        let mut s = String::new();
        // Writing into a String cannot fail.
        let _ = encode(&mut s, &self.registry);
        s
    }
}

/// The monitoring gauges of the latest epoch and the session's monitoring counters.
#[derive(Debug, Clone, Default)]
pub struct MonitorMetrics {
    pub epoch_time: GaugeF64,
    pub epochs: Counter,
    pub epochs_failed: Counter,
    pub epochs_late: Counter,
    pub sensors_unknown: Gauge,
    pub max_displacement: GaugeF64,
    pub mean_displacement: GaugeF64,
    pub max_curvature_change: GaugeF64,
    pub sensors_missing: Gauge,
    pub sensors_saturated: Gauge,
    pub sensors_disturbed: Gauge,
    /// Consecutive epochs with a sensor of the layout left out (missing, saturated or
    /// disturbed); 0 while every sensor is in.
    pub sensors_left_out_epochs: Gauge,
    /// From an epoch's window closing to its metrics line (and latest.glb) written, seconds.
    pub epoch_latency: GaugeF64,
    pub alarms_raised: Counter,
    /// 1 while an alarm is raised (`metric`, `threshold` labels).
    pub alarm: Family<Labels, Gauge>,
    /// 1 for each sensor left out of the latest shape (`sensor`, `reason` labels).
    pub sensor_left_out: Family<Labels, Gauge>,
}

impl MonitorMetrics {
    fn register(&self, r: &mut Registry) {
        r.register_with_unit(
            "epoch_time",
            "Session time of the latest epoch",
            Unit::Seconds,
            self.epoch_time.clone(),
        );
        r.register("epochs", "Epochs closed", self.epochs.clone());
        r.register(
            "epochs_failed",
            "Epochs that could not be reconstructed",
            self.epochs_failed.clone(),
        );
        r.register(
            "epochs_late",
            "Sensor epochs ignored because their window had closed",
            self.epochs_late.clone(),
        );
        r.register(
            "sensors_unknown",
            "Sensors streaming that the layout does not place",
            self.sensors_unknown.clone(),
        );
        r.register_with_unit(
            "max_displacement",
            "Largest displacement from the reference shape",
            Unit::Meters,
            self.max_displacement.clone(),
        );
        r.register_with_unit(
            "mean_displacement",
            "Mean displacement from the reference shape",
            Unit::Meters,
            self.mean_displacement.clone(),
        );
        r.register_with_unit(
            "max_curvature_change",
            "Largest change of curvature from the reference shape",
            Unit::Other("radians_per_meter".into()),
            self.max_curvature_change.clone(),
        );
        r.register(
            "sensors_missing",
            "Sensors of the layout without an orientation (no samples, or none usable), saturated and disturbed ones aside",
            self.sensors_missing.clone(),
        );
        r.register(
            "sensors_saturated",
            "Sensors of the layout left out because saturated",
            self.sensors_saturated.clone(),
        );
        r.register(
            "sensors_disturbed",
            "Sensors of the layout left out because their magnetic field is disturbed",
            self.sensors_disturbed.clone(),
        );
        r.register(
            "sensors_left_out_epochs",
            "Consecutive epochs with a sensor of the layout left out (missing, saturated or disturbed)",
            self.sensors_left_out_epochs.clone(),
        );
        r.register_with_unit(
            "epoch_latency",
            "From the latest epoch's window closing to its metrics line and latest.glb written",
            Unit::Seconds,
            self.epoch_latency.clone(),
        );
        r.register("alarms_raised", "Alarms raised", self.alarms_raised.clone());
        r.register(
            "alarm",
            "Whether an alarm is raised (1) or not (0)",
            self.alarm.clone(),
        );
        r.register(
            "sensor_left_out",
            "A sensor of the layout left out of the latest shape, and why",
            self.sensor_left_out.clone(),
        );
    }
}

/// Sets a counter to `total` (counters only go up: a smaller total is ignored).
pub fn count_to(c: &Counter, total: u64) {
    let now = c.get();
    if total > now {
        c.inc_by(total - now);
    }
}
