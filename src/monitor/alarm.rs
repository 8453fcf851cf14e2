//! Threshold alarms with hysteresis: raised when a metric rises above its threshold, cleared
//! only when it falls below the threshold less the hysteresis, so a value dithering around
//! the threshold does not raise it again and again.
//!
//! ```
//! use sfs::monitor::alarm::{Alarm, AlarmMetric, Transition};
//! let mut a = Alarm::new(AlarmMetric::MaxDisplacement, 1.0, 0.1);
//! assert_eq!(a.update(0.5), None);
//! assert_eq!(a.update(1.2), Some(Transition::Raised));
//! assert_eq!(a.update(0.95), None); // within the hysteresis band: still raised
//! assert_eq!(a.update(0.85), Some(Transition::Cleared));
//! ```

use super::metrics::Metrics;

/// The metric an alarm watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlarmMetric {
    /// Largest displacement of a curve point from the reference, m.
    MaxDisplacement,
    /// Mean displacement over the points, m.
    MeanDisplacement,
    /// Largest change of curvature, rad/m.
    MaxCurvatureChange,
}

impl AlarmMetric {
    pub const ALL: [AlarmMetric; 3] = [
        AlarmMetric::MaxDisplacement,
        AlarmMetric::MeanDisplacement,
        AlarmMetric::MaxCurvatureChange,
    ];

    /// Its name in the configuration, `metrics.csv`, `events.log` and the Prometheus labels.
    pub fn name(self) -> &'static str {
        match self {
            AlarmMetric::MaxDisplacement => "max_displacement",
            AlarmMetric::MeanDisplacement => "mean_displacement",
            AlarmMetric::MaxCurvatureChange => "max_curvature_change",
        }
    }

    /// The metric by its name.
    pub fn from_name(name: &str) -> Option<AlarmMetric> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Its value in an epoch's metrics.
    pub fn of(self, m: &Metrics) -> f64 {
        match self {
            AlarmMetric::MaxDisplacement => m.max_displacement,
            AlarmMetric::MeanDisplacement => m.mean_displacement,
            AlarmMetric::MaxCurvatureChange => m.max_curvature_change,
        }
    }
}

impl std::fmt::Display for AlarmMetric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What an update did to an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transition {
    Raised,
    Cleared,
}

/// One metric's alarm.
#[derive(Debug, Clone, PartialEq)]
pub struct Alarm {
    pub metric: AlarmMetric,
    pub threshold: f64,
    pub hysteresis: f64,
    raised: bool,
}

impl Alarm {
    pub fn new(metric: AlarmMetric, threshold: f64, hysteresis: f64) -> Self {
        Alarm {
            metric,
            threshold,
            hysteresis: hysteresis.max(0.0),
            raised: false,
        }
    }

    /// Whether the alarm is raised.
    pub fn is_raised(&self) -> bool {
        self.raised
    }

    /// Its name in `metrics.csv`: `metric>threshold`.
    pub fn label(&self) -> String {
        format!("{}>{}", self.metric, self.threshold)
    }

    /// Restores a state (a resumed session, from the last line of its metrics).
    pub fn set_raised(&mut self, raised: bool) {
        self.raised = raised;
    }

    /// Feeds the metric's value of an epoch. A non-finite value changes nothing.
    pub fn update(&mut self, value: f64) -> Option<Transition> {
        if !value.is_finite() {
            return None;
        }
        if !self.raised && value > self.threshold {
            self.raised = true;
            Some(Transition::Raised)
        } else if self.raised && value < self.threshold - self.hysteresis {
            self.raised = false;
            Some(Transition::Cleared)
        } else {
            None
        }
    }
}
