//! Where the sensors of an instrumented structure are: on which curve, at which rest arc
//! length, and where the curves cross (nodes). Written by the simulator into its truth file,
//! read from the monitoring configuration.

use serde::{Deserialize, Serialize};

/// A sensor's place in the layout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayoutSensor {
    pub sensor: u16,
    pub curve: usize,
    /// Rest arc length from the curve's first node, m.
    pub s: f64,
}

/// A curve of the layout: its node sequence and rest length.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayoutCurve {
    pub index: usize,
    pub nodes: Vec<u32>,
    /// Rest arc length of each node along the curve, m.
    pub node_s: Vec<f64>,
    pub length: f64,
}

/// A whole layout.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Layout {
    pub sensors: Vec<LayoutSensor>,
    pub curves: Vec<LayoutCurve>,
}

/// What is wrong with a layout, naming the curve or sensor.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LayoutError {
    #[error("curve {curve}: {reason}")]
    Curve { curve: usize, reason: String },
    #[error("sensor {sensor}: {reason}")]
    Sensor { sensor: u16, reason: String },
}

impl Layout {
    /// Checks that every curve has at least two nodes at increasing arc lengths within
    /// `[0, length]`, that curve indices are `0..n`, and that every sensor sits on a known
    /// curve within its length, once.
    pub fn validate(&self) -> Result<(), LayoutError> {
        for (k, c) in self.curves.iter().enumerate() {
            let bad = |reason: String| LayoutError::Curve {
                curve: c.index,
                reason,
            };
            if c.index != k {
                return Err(bad(format!(
                    "listed {k}-th: curves are numbered 0, 1, 2, …"
                )));
            }
            if c.nodes.len() < 2 || c.nodes.len() != c.node_s.len() {
                return Err(bad(format!(
                    "{} nodes and {} node arc lengths; at least two of each, as many",
                    c.nodes.len(),
                    c.node_s.len()
                )));
            }
            if !(c.length.is_finite() && c.length > 0.0) {
                return Err(bad(format!("length {} is not positive", c.length)));
            }
            let increasing = c.node_s.windows(2).all(|w| w[1] > w[0]);
            if !increasing
                || c.node_s.iter().any(|s| !s.is_finite())
                || c.node_s[0] < 0.0
                || *c.node_s.last().expect("two") > c.length + 1e-9
            {
                return Err(bad(format!(
                    "node arc lengths {:?} must increase within [0, {}]",
                    c.node_s, c.length
                )));
            }
        }
        let mut seen = std::collections::BTreeSet::new();
        for s in &self.sensors {
            let bad = |reason: String| LayoutError::Sensor {
                sensor: s.sensor,
                reason,
            };
            if !seen.insert(s.sensor) {
                return Err(bad("listed twice".into()));
            }
            let Some(c) = self.curves.get(s.curve) else {
                return Err(bad(format!("on curve {}, which the layout lacks", s.curve)));
            };
            if !(s.s.is_finite() && (0.0..=c.length + 1e-9).contains(&s.s)) {
                return Err(bad(format!(
                    "at {} m, outside curve {} (0 to {} m)",
                    s.s, c.index, c.length
                )));
            }
        }
        Ok(())
    }
}
