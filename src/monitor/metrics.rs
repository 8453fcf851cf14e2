//! How far a monitored structure is from its reference shape: per epoch, the largest and mean
//! displacement of the resampled curve points (the shapes placed with the anchor node at the
//! origin; orientation is absolute, from gravity and the magnetic field), and the largest
//! change of curvature (angle turned per metre along the curves).
//!
//! The reference is the mean shape over the first epochs ([`ReferenceBuilder`]), or any shape.

use crate::network::poisson::Positions;
use nalgebra::Vector3;

/// A shape relative to its anchor: per curve (by layout index), its points and curvatures.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    pub curves: Vec<(usize, Vec<Vector3<f64>>)>,
}

impl Shape {
    /// The shape of `p` with node `anchor` at the origin (`None` if the anchor is not in it).
    pub fn anchored(p: &Positions, anchor: u32) -> Option<Shape> {
        let o = *p.nodes.get(&anchor)?;
        Some(Shape {
            curves: p
                .curves
                .iter()
                .map(|c| (c.index, c.points.iter().map(|x| x - o).collect()))
                .collect(),
        })
    }
}

/// Curvature (angle per length) at the interior points of a polyline.
fn curvature(p: &[Vector3<f64>]) -> Vec<f64> {
    (1..p.len().saturating_sub(1))
        .map(|j| {
            let (a, b) = (p[j] - p[j - 1], p[j + 1] - p[j]);
            let len = 0.5 * (a.norm() + b.norm());
            if len > 0.0 {
                a.angle(&b) / len
            } else {
                0.0
            }
        })
        .collect()
}

/// The metrics of one epoch against the reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Metrics {
    /// Largest displacement of a curve point from the reference, m.
    pub max_displacement: f64,
    /// Mean displacement over the points, m.
    pub mean_displacement: f64,
    /// Largest change of curvature, rad/m.
    pub max_curvature_change: f64,
    /// Curve points compared (curves absent from either shape, or resampled differently,
    /// are not).
    pub points: usize,
}

/// Compares `now` with `reference`, curve by curve.
pub fn compare(reference: &Shape, now: &Shape) -> Metrics {
    let mut m = Metrics::default();
    let mut sum = 0.0;
    for (index, pts) in &now.curves {
        let Some((_, r)) = reference.curves.iter().find(|(i, _)| i == index) else {
            continue;
        };
        if r.len() != pts.len() {
            continue;
        }
        for (a, b) in pts.iter().zip(r) {
            let d = (a - b).norm();
            m.max_displacement = m.max_displacement.max(d);
            sum += d;
            m.points += 1;
        }
        for (ka, kb) in curvature(pts).iter().zip(curvature(r)) {
            m.max_curvature_change = m.max_curvature_change.max((ka - kb).abs());
        }
    }
    if m.points > 0 {
        m.mean_displacement = sum / m.points as f64;
    }
    m
}

/// The mean shape of the first epochs.
#[derive(Debug, Clone, Default)]
pub struct ReferenceBuilder {
    sum: Option<Shape>,
    count: usize,
}

impl ReferenceBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an epoch's shape; shapes whose curves differ from the first (a curve left out,
    /// resampled otherwise) are skipped, and `false` is returned.
    pub fn add(&mut self, s: &Shape) -> bool {
        match &mut self.sum {
            None => {
                self.sum = Some(s.clone());
                self.count = 1;
                true
            }
            Some(sum) => {
                let same = sum.curves.len() == s.curves.len()
                    && sum
                        .curves
                        .iter()
                        .zip(&s.curves)
                        .all(|(a, b)| a.0 == b.0 && a.1.len() == b.1.len());
                if !same {
                    return false;
                }
                for (a, b) in sum.curves.iter_mut().zip(&s.curves) {
                    for (x, y) in a.1.iter_mut().zip(&b.1) {
                        *x += y;
                    }
                }
                self.count += 1;
                true
            }
        }
    }

    /// Epochs averaged so far.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The mean shape (`None` before the first epoch).
    pub fn reference(&self) -> Option<Shape> {
        let mut s = self.sum.clone()?;
        let k = self.count as f64;
        for (_, pts) in &mut s.curves {
            for p in pts.iter_mut() {
                *p /= k;
            }
        }
        Some(s)
    }
}
