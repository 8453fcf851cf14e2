//! Threshold alarms with hysteresis: raised when a metric rises above its threshold, cleared
//! only when it falls below the threshold less the hysteresis, so a value dithering around
//! the threshold does not raise it again and again.
//!
//! ```
//! use sfs::monitor::alarm::{Alarm, Transition};
//! let mut a = Alarm::new("max_displacement", 1.0, 0.1);
//! assert_eq!(a.update(0.5), None);
//! assert_eq!(a.update(1.2), Some(Transition::Raised));
//! assert_eq!(a.update(0.95), None); // within the hysteresis band: still raised
//! assert_eq!(a.update(0.85), Some(Transition::Cleared));
//! ```

/// What an update did to an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transition {
    Raised,
    Cleared,
}

/// One metric's alarm.
#[derive(Debug, Clone, PartialEq)]
pub struct Alarm {
    pub metric: String,
    pub threshold: f64,
    pub hysteresis: f64,
    raised: bool,
}

impl Alarm {
    pub fn new(metric: impl Into<String>, threshold: f64, hysteresis: f64) -> Self {
        Alarm {
            metric: metric.into(),
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
