//! Scenes as data (`config/scenes/*.toml`): a surface and curves that are plane sections of it,
//! crossing at nodes that are found, not declared.
//!
//! ```toml
//! name = "sphere-octa"
//! description = "Unit sphere, three orthogonal great circles: 6 nodes, 12 arcs, 8 triangles."
//! spacing = 0.002                      # m between the truth polyline's points
//!
//! [surface]
//! kind = "sphere"                      # sphere | torus | frustum | paraboloid | mesh
//! center = [0.0, 0.0, 0.0]
//! radius = 1.0
//!
//! [[curve]]
//! normal = [0.0, 0.0, 1.0]             # the section plane: normal · x = offset …
//! offset = 0.0
//! # through = [[1,1,1], [1,1,-1], [0,0,0]]   # … or through three points
//! near = [1.0, 0.0, 0.0]               # which piece of the section, if several
//! closed = true                        # the whole loop; else an arc `from` → `to`
//! boundary = true                      # lies on the surface's boundary (key B) …
//! # crease = true                      # … or is a sharp edge (K), or a guide curve (G);
//! # guide = true                       #   none of them: an interior curve (I)
//! ```
//!
//! Surfaces: `sphere` (`center`, `radius`), `torus` (`center`, `major`, `minor`, axis z),
//! `frustum` (`z0`, `r0`, `z1`, `r1`, axis z), `paraboloid` (`a`, `rim`: z = ρ²/2a, normal up),
//! `box` (`center`, `size` = [x, y, z]), `gable` (a roof: `length` along its ridge on x,
//! `width` from eave to eave, `height` of the ridge over the eaves), `mesh` (`path` relative
//! to the scene file, `fit_xy` = [width, depth] in metres or `scale`, `base_z`,
//! `flip_normals`). A curve may also be `kind = "mesh-boundary"`: the mesh's boundary loop;
//! or, on a box or gable, `kind = "polyline"` through `points` (straight between them,
//! `closed` back to the first), whose normal is its face's; along an edge, `rest` (a
//! direction) picks the face the device rests on; `tag_points = true` makes its points nodes. The operator stops at a node where a curve
//! turns sharply about the normal and turns the device in place. Open arcs run `from` → `to` (the points are snapped onto the section; with two ways
//! round a loop, the one through `via`, else the shorter); open pieces without `from`/`to`
//! run end to end. Nodes: every crossing of two curves and every end of an open curve.
//!
//! Layout: this file reads the scene (built in, or a file) and ties it together;
//! `surface_spec.rs` the `[surface]` table → the surface and its [`SurfaceRef`];
//! `curve_spec.rs` each `[[curve]]` → a polyline with exact normals; `network.rs` the nodes.

use super::operator::{CurveKind, CurveSpec};
use super::surface::Surface;
use curve_spec::{piece, CurveToml};
use nalgebra::Vector3;
use network::network;
use serde::Deserialize;
use std::path::Path;
use surface_spec::{build_surface, SurfaceToml};

mod curve_spec;
mod network;
mod surface_spec;

pub use surface_spec::SurfaceRef;

/// A scene error: the scene (a file, or a built-in scene by name), the key when one is to
/// blame, and why.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {}{reason}", key.as_deref().map(|k| format!("{k}: ")).unwrap_or_default())]
pub struct SceneError {
    /// The file's path, or "built-in scene NAME".
    pub origin: String,
    pub key: Option<String>,
    pub reason: String,
}

/// The scenes built into the binary (`config/scenes/*.toml`), by name: `sfs simulate --scene
/// NAME` runs from any directory. The paper's LILIUM and BUMPY CUBE name meshes that are not
/// shipped (see [`PAPER_DATA_ENV`]).
pub const BUILTIN: &[(&str, &str)] = &[
    ("bowl", include_str!("../../../config/scenes/bowl.toml")),
    ("box", include_str!("../../../config/scenes/box.toml")),
    ("bumpy", include_str!("../../../config/scenes/bumpy.toml")),
    (
        "bumpy-cube",
        include_str!("../../../config/scenes/bumpy-cube.toml"),
    ),
    ("cone", include_str!("../../../config/scenes/cone.toml")),
    (
        "ellipsoid-dense",
        include_str!("../../../config/scenes/ellipsoid-dense.toml"),
    ),
    (
        "ellipsoid-grid",
        include_str!("../../../config/scenes/ellipsoid-grid.toml"),
    ),
    ("lilium", include_str!("../../../config/scenes/lilium.toml")),
    (
        "parallel",
        include_str!("../../../config/scenes/parallel.toml"),
    ),
    ("relief", include_str!("../../../config/scenes/relief.toml")),
    ("roof", include_str!("../../../config/scenes/roof.toml")),
    (
        "roof-loop",
        include_str!("../../../config/scenes/roof-loop.toml"),
    ),
    (
        "sphere-cube",
        include_str!("../../../config/scenes/sphere-cube.toml"),
    ),
    (
        "sphere-octa",
        include_str!("../../../config/scenes/sphere-octa.toml"),
    ),
    ("torus", include_str!("../../../config/scenes/torus.toml")),
    (
        "torus-hour",
        include_str!("../../../config/scenes/torus-hour.toml"),
    ),
    (
        "torus-loops",
        include_str!("../../../config/scenes/torus-loops.toml"),
    ),
];

/// The built-in scenes whose meshes are the paper's (not shipped: [`PAPER_DATA_ENV`]).
pub const PAPER_SCENES: [&str; 2] = ["bumpy-cube", "lilium"];

/// The built-in scenes of a size for the scaling benchmarks (BENCHMARKS.md, issue 51): the
/// 100-curve grid, 6 h of scanning. The tests that take every scene curve by curve, settling
/// each, leave them out (minutes each); their own tests are lighter.
pub const LARGE_SCENES: [&str; 1] = ["ellipsoid-grid"];

/// The environment variable naming the directory that holds the paper's meshes
/// (`lilium.obj`, `bumpy-cube.obj`: libigl's tutorial data), which a scene names with
/// `[surface] paper = "FILE"`.
pub const PAPER_DATA_ENV: &str = "SFS_PAPER_DATA";

/// Largest scene file read: 1 MB.
pub const MAX_SCENE_BYTES: u64 = 1 << 20;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneToml {
    name: String,
    #[serde(default)]
    description: String,
    spacing: Option<f64>,
    surface: SurfaceToml,
    #[serde(rename = "curve")]
    curves: Vec<CurveToml>,
}

/// One curve of a built scene: a dense polyline with exact normals, and its node tags.
#[derive(Debug, Clone)]
pub struct SceneCurve {
    pub points: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    pub kind: CurveKind,
    pub closed: bool,
    /// `(point index, node index)` in order of travel.
    pub tags: Vec<(usize, u32)>,
}

impl SceneCurve {
    pub fn spec(&self) -> CurveSpec {
        CurveSpec {
            points: self.points.clone(),
            normals: self.normals.clone(),
            tags: self.tags.clone(),
            kind: self.kind,
        }
    }

    /// Lies on the surface's boundary.
    pub fn boundary(&self) -> bool {
        self.kind == CurveKind::Boundary
    }

    pub fn nodes(&self) -> Vec<u32> {
        self.tags.iter().map(|t| t.1).collect()
    }
}

/// A scene ready to be scanned.
#[derive(Debug, Clone)]
pub struct Scene {
    pub name: String,
    pub description: String,
    pub surface: Surface,
    pub surface_ref: SurfaceRef,
    pub curves: Vec<SceneCurve>,
    /// Node positions by index.
    pub nodes: Vec<Vector3<f64>>,
    pub spacing: f64,
}

impl Scene {
    /// Diagonal of the bounding box of the curve network, m.
    pub fn bbox_diagonal(&self) -> f64 {
        let mut lo = Vector3::repeat(f64::MAX);
        let mut hi = Vector3::repeat(f64::MIN);
        for c in &self.curves {
            for p in &c.points {
                lo = lo.inf(p);
                hi = hi.sup(p);
            }
        }
        (hi - lo).norm()
    }

    /// The operator's curves.
    pub fn specs(&self) -> Vec<CurveSpec> {
        self.curves.iter().map(SceneCurve::spec).collect()
    }

    /// The exact scan of the scene: every truth point a sample, with its exact frame (the
    /// tangent from its neighbours, the surface normal), distances its arc length; for the
    /// reconstruction and the surface without any sensor.
    pub fn exact_scan(&self) -> crate::scan::Scan {
        use crate::scan::{Curve, Samples, Scan, Tag};
        use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
        let mut scan = Scan::default();
        for (ci, c) in self.curves.iter().enumerate() {
            let n = c.points.len();
            let mut smp = Samples::default();
            let mut d = 0.0;
            for i in 0..n {
                if i > 0 {
                    d += (c.points[i] - c.points[i - 1]).norm();
                }
                let t = (c.points[(i + 1).min(n - 1)] - c.points[i.saturating_sub(1)]).normalize();
                let nn = c.normals[i];
                let nn = (nn - t * nn.dot(&t)).normalize();
                let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                    Matrix3::from_columns(&[t, nn.cross(&t), nn]),
                ));
                smp.t.push(i as f64);
                smp.d.push(d);
                smp.q.push([q.w, q.i, q.j, q.k]);
                smp.flags.push(0);
                smp.w.push(1.0);
            }
            let tags: Vec<Tag> = c
                .tags
                .iter()
                .map(|&(i, node)| Tag {
                    node,
                    d: smp.d[i],
                    t: i as f64,
                    uncertain: false,
                })
                .collect();
            scan.curves.push(Curve {
                index: ci,
                kind: c.kind,
                closed: c.closed,
                segment_lengths: vec![None; tags.len().saturating_sub(1)],
                tags,
                samples: smp,
            });
        }
        scan
    }
}

/// The names of the built-in scenes, sorted.
pub fn names() -> impl Iterator<Item = &'static str> {
    BUILTIN.iter().map(|(n, _)| *n)
}

/// Whether `arg` names a scene file rather than a built-in scene: it ends in `.toml` or has
/// a directory in it.
pub fn is_path(arg: &str) -> bool {
    let p = Path::new(arg);
    p.extension().is_some_and(|e| e == "toml") || p.components().count() > 1
}

/// A scene from the command line: a built-in scene by name, or a scene file (`PATH.toml`).
pub fn resolve(name_or_path: &str) -> Result<Scene, SceneError> {
    if is_path(name_or_path) {
        load(Path::new(name_or_path))
    } else {
        builtin(name_or_path)
    }
}

/// Builds the built-in scene `name`.
pub fn builtin(name: &str) -> Result<Scene, SceneError> {
    let origin = format!("built-in scene {name}");
    match BUILTIN.iter().find(|(n, _)| *n == name) {
        Some((_, text)) => parse(text, &origin, None),
        None => Err(SceneError {
            origin: name.to_owned(),
            key: None,
            reason: format!(
                "no such built-in scene (they are: {}); a scene file is given as PATH.toml",
                names().collect::<Vec<_>>().join(", ")
            ),
        }),
    }
}

/// Loads and builds a scene file (a regular file of at most [`MAX_SCENE_BYTES`]); a mesh's
/// `path` is relative to the file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let origin = path.display().to_string();
    let text = read_scene_file(path).map_err(|reason| SceneError {
        origin: origin.clone(),
        key: None,
        reason,
    })?;
    parse(&text, &origin, Some(path.parent().unwrap_or(Path::new(""))))
}

fn read_scene_file(path: &Path) -> Result<String, String> {
    crate::named_file::read_text(path, MAX_SCENE_BYTES, "a scene file")
        .map_err(|e| format!("cannot read the scene file: {e}"))
}

/// Builds a scene from its TOML text; `origin` names it in errors, `base` is the directory a
/// mesh's `path` is relative to (none for a built-in scene).
pub fn parse(text: &str, origin: &str, base: Option<&Path>) -> Result<Scene, SceneError> {
    let err = |key: &str, reason: String| SceneError {
        origin: origin.to_owned(),
        key: Some(key.to_owned()),
        reason,
    };
    let t: SceneToml = toml::from_str(text).map_err(|e| SceneError {
        origin: origin.to_owned(),
        key: None,
        reason: toml_error(text, &e),
    })?;
    let (surface, surface_ref) =
        build_surface(&t.surface, base).map_err(|(k, r)| err(&format!("surface.{k}"), r))?;
    let spacing = t.spacing.unwrap_or(0.002);
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(err(
            "spacing",
            format!("{spacing} is not a positive length"),
        ));
    }
    if t.curves.is_empty() {
        return Err(err("curve", "a scene needs curves".into()));
    }
    let tess = surface.tessellate();
    let mut raw = Vec::new();
    for (i, c) in t.curves.iter().enumerate() {
        let key = format!("curve[{i}]");
        let pl = piece(&surface, &tess, c, spacing).map_err(|r| err(&key, r.to_string()))?;
        raw.push(pl);
    }
    let (curves, nodes) =
        network(&surface, raw, spacing).map_err(|(i, r)| err(&format!("curve[{i}]"), r))?;
    Ok(Scene {
        name: t.name,
        description: t.description,
        surface,
        surface_ref,
        curves,
        nodes,
        spacing,
    })
}

pub(super) fn need(v: Option<f64>, k: &str) -> Result<f64, (String, String)> {
    match v {
        Some(x) if x.is_finite() => Ok(x),
        Some(x) => Err((k.into(), format!("{x} is not finite"))),
        None => Err((k.into(), "required for this kind".into())),
    }
}

/// A TOML error as one line: where (line and column) and why.
fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let why = e.message().trim().to_owned();
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {col}: {why}")
        }
        None => why,
    }
}
