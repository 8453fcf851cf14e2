//! `PREFIX.truth.json`: what the simulated device really scanned, for `sfs eval` and tests.

use super::scene::SurfaceRef;
use serde::{Deserialize, Serialize};
use sfs_geometry::curve::CurveKind;
use std::collections::BTreeMap;

/// One curve of the truth network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthCurve {
    /// Scan order (accepted curves).
    pub index: usize,
    /// Node sequence as scanned.
    pub nodes: Vec<u32>,
    /// What the curve means (its start key); absent in truth files written before curve
    /// kinds (see [`TruthCurve::kind`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<CurveKind>,
    /// `kind == "boundary"`.
    pub boundary: bool,
    pub closed: bool,
    /// Dense polyline, m.
    pub points: Vec<[f64; 3]>,
    /// Unit outward surface normals at the points.
    pub normals: Vec<[f64; 3]>,
}

impl TruthCurve {
    /// What the curve means: its `kind`, else (older files) boundary or interior.
    pub fn kind(&self) -> CurveKind {
        self.kind.unwrap_or(if self.boundary {
            CurveKind::Boundary
        } else {
            CurveKind::Interior
        })
    }
}

/// A fixed sensor of an array.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthSensor {
    pub sensor: u16,
    pub curve: usize,
    /// Arc length along the curve from its first node, m.
    pub s: f64,
    pub position: [f64; 3],
    /// Sensor → world, `[w, x, y, z]`.
    pub q: [f64; 4],
}

/// A fault planted in the capture ([`super::planted`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFault {
    /// `wrong-node`, `slip`, `late-enter` or `magnet`.
    pub kind: String,
    /// Scan order of the curve it is on (the program's curve index).
    pub curve: usize,
    /// Where it applies: the position in that curve's tags (`None` for a slip or a magnet).
    pub tag: Option<usize>,
    /// The true node there.
    pub node: Option<u32>,
    /// What was planted, in the kind's own terms.
    pub details: serde_json::Value,
}

/// The whole truth file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    pub scene: String,
    pub description: String,
    pub device: String,
    pub profile: String,
    pub seed: u64,
    /// Node positions by index (as strings, JSON object keys).
    pub nodes: BTreeMap<String, [f64; 3]>,
    pub curves: Vec<TruthCurve>,
    pub surface: SurfaceRef,
    /// Diagonal of the truth network's bounding box, m (the unit of the error metric's %).
    pub bbox_diagonal: f64,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<TruthSensor>,
    /// What the simulation acted out (profile events), in words.
    #[serde(default)]
    pub events: Vec<String>,
    /// Faults planted on purpose (`sfs simulate --fault`), with where they are.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<TruthFault>,
}

/// Why a truth file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum TruthError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file of another kind (a report, a glb, a capture, a structure's truth).
    #[error("{}: this is {what}, not a scene's truth (sfs simulate's PREFIX.truth.json)", path.display())]
    NotATruth {
        path: std::path::PathBuf,
        what: &'static str,
    },
    #[error("{}: {source}", path.display())]
    Format {
        path: std::path::PathBuf,
        #[source]
        source: serde_json::Error,
    },
}

impl Truth {
    /// Reads a truth file.
    pub fn load(path: &std::path::Path) -> Result<Truth, TruthError> {
        let bytes = std::fs::read(path).map_err(|source| TruthError::Read {
            path: path.to_owned(),
            source,
        })?;
        let what = looks_like(&bytes);
        if what != SCENE_TRUTH {
            return Err(TruthError::NotATruth {
                path: path.to_owned(),
                what,
            });
        }
        serde_json::from_slice(&bytes).map_err(|source| TruthError::Format {
            path: path.to_owned(),
            source,
        })
    }
}

/// What [`looks_like`] calls a scene's truth.
pub const SCENE_TRUTH: &str = "a scene's truth";

/// What a file given to `sfs eval` looks like, to name a wrong one: a scene's truth, a
/// structure's, a session's report or scan, a glb, a capture.
pub fn looks_like(bytes: &[u8]) -> &'static str {
    if bytes.starts_with(b"glTF") {
        return "a glTF binary (a network.glb)";
    }
    let Ok(serde_json::Value::Object(v)) = serde_json::from_slice::<serde_json::Value>(bytes)
    else {
        return match std::str::from_utf8(bytes) {
            Ok(_) => "a text file, not a JSON object",
            Err(_) => "a binary file (a capture?)",
        };
    };
    let has = |k: &str| v.contains_key(k);
    if has("scene") && has("curves") {
        SCENE_TRUTH
    } else if has("structure") {
        "a structure's truth (sfs simulate --structure)"
    } else if has("link") && has("quality") {
        "a session's report.json"
    } else if has("registration") {
        "the output of sfs eval"
    } else if has("curves") {
        "a scan.json"
    } else {
        "a JSON object of another kind"
    }
}

/// Rounds to the micrometre (keeps truth files compact; far below every error measured).
pub fn um(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}
