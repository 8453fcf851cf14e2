//! How far a monitored structure is from its reference shape: per epoch, the largest and mean
//! displacement of the resampled curve points (the shapes placed with the anchor node at the
//! origin; orientation is absolute, from gravity and the magnetic field), and the largest
//! change of curvature (angle turned per metre along the curves).
//!
//! The reference is the mean shape over the first epochs ([`ReferenceBuilder`]), or any shape.

use nalgebra::Vector3;
use sfs_geometry::network::poisson::Positions;

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

    /// Curve `index`'s points, when it has `len` of them (a curve resampled otherwise is not
    /// compared point by point).
    pub fn points_like(&self, index: usize, len: usize) -> Option<&[Vector3<f64>]> {
        self.curves
            .iter()
            .find(|(i, _)| *i == index)
            .map(|(_, p)| p.as_slice())
            .filter(|p| p.len() == len)
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
        let Some(r) = reference.points_like(*index, pts.len()) else {
            continue;
        };
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

/// The `format` of a reference file.
pub const REFERENCE_FORMAT: &str = "sfs-monitor-reference";

/// Why a reference file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    #[error("{0}")]
    Json(#[from] serde_json::Error),
    #[error("format {0:?} is not {REFERENCE_FORMAT:?}")]
    Format(String),
    #[error("version {0} is not supported (1)")]
    Version(u32),
    #[error("curve {curve}: fewer than two points")]
    TooFewPoints { curve: usize },
    #[error("curve {curve}: point {point} is not finite")]
    NotFinite { curve: usize, point: usize },
    #[error("curve {curve} is given twice")]
    Twice { curve: usize },
    #[error("curve {curve} is not in the layout")]
    NotInLayout { curve: usize },
    #[error("curve {curve} of the layout is not in the file")]
    NotInFile { curve: usize },
    #[error("curve {curve}: the polyline has no length")]
    NoLength { curve: usize },
    /// Anchored at another node than the layout's.
    #[error("anchored at node {anchor}")]
    Anchored { anchor: u32 },
}

/// A reference shape on disk (JSON): per curve of the layout, a polyline from its first node
/// to its last, in metres, with the anchor node at the origin. A monitoring session writes
/// the reference it built as `reference.json` in this format; `[monitor] reference_file`
/// reads one (that file, or a design shape).
///
/// ```
/// use sfs::monitor::layout::LayoutCurve;
/// use sfs::monitor::metrics::ReferenceFile;
/// let text = r#"{"format": "sfs-monitor-reference", "version": 1, "anchor": 0,
///                "curves": [{"curve": 0, "points": [[0, 0, 0], [0, 0, 20]]}]}"#;
/// let r = ReferenceFile::parse(text).unwrap();
/// let riser = LayoutCurve { index: 0, nodes: vec![0, 1], node_s: vec![0.0, 20.0], length: 20.0 };
/// // Resampled where an epoch samples the curve (every 5 cm here: 401 points).
/// let shape = r.shape(&[riser], 0.05).unwrap();
/// assert_eq!(shape.curves[0].1.len(), 401);
/// assert!((shape.curves[0].1[200].z - 10.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceFile {
    pub format: String,
    pub version: u32,
    /// The node at the origin.
    pub anchor: u32,
    /// Epochs averaged into it (a reference a session built).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epochs: Option<usize>,
    pub curves: Vec<ReferenceCurve>,
}

/// One curve of a [`ReferenceFile`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceCurve {
    /// Its index in the layout.
    pub curve: usize,
    pub points: Vec<[f64; 3]>,
}

impl ReferenceFile {
    /// The file of `shape`, anchored at `anchor`, the mean of `epochs` epochs.
    pub fn from_shape(shape: &Shape, anchor: u32, epochs: Option<usize>) -> ReferenceFile {
        ReferenceFile {
            format: REFERENCE_FORMAT.into(),
            version: 1,
            anchor,
            epochs,
            curves: shape
                .curves
                .iter()
                .map(|(curve, p)| ReferenceCurve {
                    curve: *curve,
                    points: p.iter().map(|x| [x.x, x.y, x.z]).collect(),
                })
                .collect(),
        }
    }

    /// Parses and checks a reference file (format, version, finite points, at least two per
    /// curve, each curve once).
    pub fn parse(text: &str) -> Result<ReferenceFile, ReferenceError> {
        use ReferenceError::*;
        let r: ReferenceFile = serde_json::from_str(text)?;
        if r.format != REFERENCE_FORMAT {
            return Err(Format(r.format));
        }
        if r.version != 1 {
            return Err(Version(r.version));
        }
        for (k, c) in r.curves.iter().enumerate() {
            if c.points.len() < 2 {
                return Err(TooFewPoints { curve: c.curve });
            }
            if let Some(point) = c
                .points
                .iter()
                .position(|p| p.iter().any(|x| !x.is_finite()))
            {
                return Err(NotFinite {
                    curve: c.curve,
                    point,
                });
            }
            if r.curves[..k].iter().any(|o| o.curve == c.curve) {
                return Err(Twice { curve: c.curve });
            }
        }
        Ok(r)
    }

    /// The reference shape where an epoch samples the curves of `layout` at `step`
    /// ([`super::epoch::samples`]): a polyline with exactly as many points is taken as it
    /// is; any other is resampled at the same fractions of its arc length as the samples
    /// are of the curve's rest length. Every curve of the layout must be in the file.
    pub fn shape(
        &self,
        layout: &[super::layout::LayoutCurve],
        step: f64,
    ) -> Result<Shape, ReferenceError> {
        if let Some(c) = self
            .curves
            .iter()
            .find(|c| !layout.iter().any(|l| l.index == c.curve))
        {
            return Err(ReferenceError::NotInLayout { curve: c.curve });
        }
        let mut curves = Vec::with_capacity(layout.len());
        for l in layout {
            let Some(c) = self.curves.iter().find(|c| c.curve == l.index) else {
                return Err(ReferenceError::NotInFile { curve: l.index });
            };
            let pts: Vec<Vector3<f64>> = c.points.iter().map(|p| Vector3::from(*p)).collect();
            let (x, _, _) = super::epoch::samples(l, step);
            if pts.len() == x.len() {
                curves.push((l.index, pts));
                continue;
            }
            // Cumulative arc length of the polyline.
            let mut acc = vec![0.0];
            for w in pts.windows(2) {
                acc.push(acc.last().unwrap() + (w[1] - w[0]).norm());
            }
            let (total, s0, rest) = (*acc.last().unwrap(), x[0], x.last().unwrap() - x[0]);
            if total <= 0.0 {
                return Err(ReferenceError::NoLength { curve: l.index });
            }
            let at = |u: f64| {
                let a = u * total;
                let j = acc.partition_point(|&v| v <= a).clamp(1, pts.len() - 1);
                let seg = acc[j] - acc[j - 1];
                let t = if seg > 0.0 {
                    (a - acc[j - 1]) / seg
                } else {
                    0.0
                };
                pts[j - 1] + (pts[j] - pts[j - 1]) * t.clamp(0.0, 1.0)
            };
            curves.push((l.index, x.iter().map(|&x| at((x - s0) / rest)).collect()));
        }
        Ok(Shape { curves })
    }
}
