//! The live preview of the open curve: its path integrated from its first node (orientations
//! × distances) as samples arrive, for the view, before the curve is finalised.

use super::Acquisition;
use nalgebra::{UnitQuaternion, Vector3};

/// An open curve's path integrated from its first node (orientations × distances), world
/// frame, relative to the node.
#[derive(Debug, Clone)]
pub(super) struct PreviewPath {
    at: Vector3<f64>,
    points: Vec<Vector3<f64>>,
    since: f64,
    spacing: f64,
}

impl Default for PreviewPath {
    fn default() -> Self {
        PreviewPath {
            at: Vector3::zeros(),
            points: Vec::new(),
            since: 0.0,
            spacing: PREVIEW_SPACING,
        }
    }
}

/// Distance between the points of a preview, m (at first).
pub const PREVIEW_SPACING: f64 = 0.005;
/// Points a preview holds at most.
pub const PREVIEW_POINTS: usize = 2048;

impl Acquisition {
    /// Moves the open curve's preview by `step` metres along the direction of travel of `q`
    /// (the frame's T axis), adding a point every [`PREVIEW_SPACING`] (or more: the spacing
    /// doubles whenever [`PREVIEW_POINTS`] are reached, so a long curve stays bounded).
    pub(super) fn preview_step(&mut self, q: &UnitQuaternion<f64>, step: f64) {
        let Some(o) = &mut self.open else { return };
        if o.tags.is_empty() || step == 0.0 {
            return; // from its first node on
        }
        let p = &mut o.preview;
        p.at += q * Vector3::x() * step;
        p.since += step.abs();
        if p.since >= p.spacing {
            p.since = 0.0;
            p.points.push(p.at);
            if p.points.len() >= PREVIEW_POINTS {
                let kept: Vec<_> = p.points.iter().step_by(2).copied().collect();
                p.points = kept;
                p.spacing *= 2.0;
            }
        }
    }

    /// The open curve's preview: its first node and the points integrated from it so far
    /// (world frame, relative to the node), if a curve is open and tagged.
    pub fn preview(&self) -> Option<(usize, u32, Vec<Vector3<f64>>)> {
        let o = self.open.as_ref()?;
        let first = o.tags.first()?.0;
        let mut pts = Vec::with_capacity(o.preview.points.len() + 2);
        pts.push(Vector3::zeros());
        pts.extend(&o.preview.points);
        pts.push(o.preview.at);
        Some((o.index, first, pts))
    }
}
