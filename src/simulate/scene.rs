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
//! direction) picks the face the device rests on. The operator stops at a node where a curve
//! turns sharply about the normal and turns the device in place. Open arcs run `from` → `to` (the points are snapped onto the section; with two ways
//! round a loop, the one through `via`, else the shorter); open pieces without `from`/`to`
//! run end to end. Nodes: every crossing of two curves and every end of an open curve.

use super::mesh::{Section, TriMesh};
use super::operator::{CurveKind, CurveSpec};
use super::surface::{Faces, Surface};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

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
    ("bowl", include_str!("../../config/scenes/bowl.toml")),
    ("box", include_str!("../../config/scenes/box.toml")),
    ("bumpy", include_str!("../../config/scenes/bumpy.toml")),
    (
        "bumpy-cube",
        include_str!("../../config/scenes/bumpy-cube.toml"),
    ),
    ("cone", include_str!("../../config/scenes/cone.toml")),
    (
        "ellipsoid-dense",
        include_str!("../../config/scenes/ellipsoid-dense.toml"),
    ),
    ("lilium", include_str!("../../config/scenes/lilium.toml")),
    (
        "parallel",
        include_str!("../../config/scenes/parallel.toml"),
    ),
    ("relief", include_str!("../../config/scenes/relief.toml")),
    ("roof", include_str!("../../config/scenes/roof.toml")),
    (
        "sphere-cube",
        include_str!("../../config/scenes/sphere-cube.toml"),
    ),
    (
        "sphere-octa",
        include_str!("../../config/scenes/sphere-octa.toml"),
    ),
    ("torus", include_str!("../../config/scenes/torus.toml")),
    (
        "torus-hour",
        include_str!("../../config/scenes/torus-hour.toml"),
    ),
    (
        "torus-loops",
        include_str!("../../config/scenes/torus-loops.toml"),
    ),
];

/// The built-in scenes whose meshes are the paper's (not shipped: [`PAPER_DATA_ENV`]).
pub const PAPER_SCENES: [&str; 2] = ["bumpy-cube", "lilium"];

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

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SurfaceToml {
    kind: String,
    center: Option<[f64; 3]>,
    radius: Option<f64>,
    major: Option<f64>,
    minor: Option<f64>,
    z0: Option<f64>,
    r0: Option<f64>,
    z1: Option<f64>,
    r1: Option<f64>,
    a: Option<f64>,
    rim: Option<f64>,
    path: Option<PathBuf>,
    paper: Option<String>,
    generate: Option<String>,
    fit_xy: Option<[f64; 2]>,
    scale: Option<f64>,
    base_z: Option<f64>,
    #[serde(default)]
    flip_normals: bool,
    size: Option<[f64; 3]>,
    length: Option<f64>,
    width: Option<f64>,
    height: Option<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct CurveToml {
    #[serde(default = "section_kind")]
    kind: String,
    normal: Option<[f64; 3]>,
    offset: Option<f64>,
    through: Option<[[f64; 3]; 3]>,
    near: Option<[f64; 3]>,
    from: Option<[f64; 3]>,
    to: Option<[f64; 3]>,
    via: Option<[f64; 3]>,
    points: Option<Vec<[f64; 3]>>,
    rest: Option<[f64; 3]>,
    #[serde(default)]
    closed: bool,
    #[serde(default)]
    boundary: bool,
    #[serde(default)]
    crease: bool,
    #[serde(default)]
    guide: bool,
}

fn section_kind() -> String {
    "section".into()
}

/// How the truth file refers to the surface, so that `sfs eval` can rebuild it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum SurfaceRef {
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    Torus {
        center: [f64; 3],
        major: f64,
        minor: f64,
    },
    Frustum {
        z0: f64,
        r0: f64,
        z1: f64,
        r1: f64,
    },
    Paraboloid {
        a: f64,
        rim: f64,
    },
    /// A box of sizes `size` centred at `center` (its six faces).
    Box {
        center: [f64; 3],
        size: [f64; 3],
    },
    /// A gable roof ([`Faces::gable`]).
    Gable {
        length: f64,
        width: f64,
        height: f64,
    },
    /// `x ↦ scale · x + translate` applied to the file's vertices.
    Mesh {
        path: PathBuf,
        scale: f64,
        translate: [f64; 3],
        flip_normals: bool,
    },
    /// The same, applied to a [`procedural`](super::procedural) mesh.
    Generated {
        generate: String,
        scale: f64,
        translate: [f64; 3],
        flip_normals: bool,
    },
}

impl SurfaceRef {
    /// Rebuilds the surface.
    pub fn build(&self) -> Result<Surface, super::mesh::MeshError> {
        Ok(match self {
            SurfaceRef::Sphere { center, radius } => Surface::Sphere {
                center: Vector3::from(*center),
                radius: *radius,
            },
            SurfaceRef::Torus {
                center,
                major,
                minor,
            } => Surface::Torus {
                center: Vector3::from(*center),
                major: *major,
                minor: *minor,
            },
            SurfaceRef::Frustum { z0, r0, z1, r1 } => Surface::Frustum {
                z0: *z0,
                r0: *r0,
                z1: *z1,
                r1: *r1,
            },
            SurfaceRef::Paraboloid { a, rim } => Surface::Paraboloid { a: *a, rim: *rim },
            SurfaceRef::Box { center, size } => Surface::Faces(Box::new(Faces::cuboid(
                Vector3::from(*center),
                Vector3::from(*size),
            ))),
            SurfaceRef::Gable {
                length,
                width,
                height,
            } => Surface::Faces(Box::new(Faces::gable(*length, *width, *height))),
            SurfaceRef::Mesh {
                path,
                scale,
                translate,
                flip_normals,
            } => {
                let m = TriMesh::load_obj(path)?;
                Surface::Mesh(Box::new(placed(m, *scale, translate, *flip_normals)))
            }
            SurfaceRef::Generated {
                generate,
                scale,
                translate,
                flip_normals,
            } => {
                let m = super::procedural::generate(generate).ok_or_else(|| {
                    super::mesh::MeshError::Unknown {
                        name: generate.clone(),
                    }
                })?;
                Surface::Mesh(Box::new(placed(m, *scale, translate, *flip_normals)))
            }
        })
    }
}

/// `m` scaled, moved and, when asked, flipped, as the scene placed it.
fn placed(mut m: TriMesh, scale: f64, translate: &[f64; 3], flip: bool) -> TriMesh {
    m.transform(scale, Vector3::from(*translate));
    if flip {
        m.flip();
    }
    m
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

fn need(v: Option<f64>, k: &str) -> Result<f64, (String, String)> {
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

/// The mesh a `mesh` surface names: `path` (relative to the scene file), `paper` (in
/// [`PAPER_DATA_ENV`]) or `generate` (a [`procedural`](super::procedural) mesh), and what
/// the truth file will call it.
fn mesh_source(
    s: &SurfaceToml,
    base: Option<&Path>,
) -> Result<(TriMesh, MeshSource), (String, String)> {
    let given = [s.path.is_some(), s.paper.is_some(), s.generate.is_some()];
    if given.iter().filter(|g| **g).count() != 1 {
        return Err((
            "path".into(),
            "a mesh needs one of path (an OBJ file beside the scene), paper (one of the \
             paper's meshes) or generate (relief or bumpy)"
                .into(),
        ));
    }
    if let Some(g) = &s.generate {
        let m = super::procedural::generate(g).ok_or((
            "generate".to_string(),
            format!(
                "unknown mesh {g:?}: {}",
                super::procedural::NAMES.join(" or ")
            ),
        ))?;
        return Ok((m, MeshSource::Generated(g.clone())));
    }
    let (key, path) = if let Some(file) = &s.paper {
        let dir = std::env::var_os(PAPER_DATA_ENV).ok_or((
            "paper".to_string(),
            format!(
                "{file} is one of the paper's meshes, which are not shipped (no licence allows \
                 it): set {PAPER_DATA_ENV} to the directory that holds it (libigl's tutorial data)"
            ),
        ))?;
        ("paper", PathBuf::from(dir).join(file))
    } else {
        let rel = s.path.clone().unwrap_or_default();
        let path = match base {
            Some(b) => b.join(rel),
            None if rel.is_absolute() => rel,
            None => {
                return Err((
                    "path".into(),
                    "a built-in scene has no directory a relative path could be in".into(),
                ))
            }
        };
        ("path", path)
    };
    let m = TriMesh::load_obj(&path).map_err(|e| (key.to_string(), e.to_string()))?;
    let path = std::fs::canonicalize(&path).unwrap_or(path);
    Ok((m, MeshSource::File(path)))
}

/// Where a scene's mesh came from.
enum MeshSource {
    File(PathBuf),
    Generated(String),
}

fn build_surface(
    s: &SurfaceToml,
    base: Option<&Path>,
) -> Result<(Surface, SurfaceRef), (String, String)> {
    let positive = |v: Option<f64>, k: &str| -> Result<f64, (String, String)> {
        let x = need(v, k)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err((k.into(), format!("{x} must be positive")))
        }
    };
    let center = s.center.unwrap_or([0.0; 3]);
    let r = match s.kind.as_str() {
        "sphere" => SurfaceRef::Sphere {
            center,
            radius: positive(s.radius, "radius")?,
        },
        "torus" => {
            let (major, minor) = (positive(s.major, "major")?, positive(s.minor, "minor")?);
            if minor >= major {
                return Err((
                    "minor".into(),
                    "must be smaller than major (a ring torus)".into(),
                ));
            }
            SurfaceRef::Torus {
                center,
                major,
                minor,
            }
        }
        "frustum" => {
            let (z0, z1) = (need(s.z0, "z0")?, need(s.z1, "z1")?);
            if z1 <= z0 {
                return Err(("z1".into(), "must be above z0".into()));
            }
            SurfaceRef::Frustum {
                z0,
                r0: positive(s.r0, "r0")?,
                z1,
                r1: positive(s.r1, "r1")?,
            }
        }
        "paraboloid" => SurfaceRef::Paraboloid {
            a: positive(s.a, "a")?,
            rim: positive(s.rim, "rim")?,
        },
        "box" => {
            let size = s
                .size
                .ok_or(("size".to_string(), "required for a box".to_string()))?;
            for (k, x) in size.iter().enumerate() {
                positive(Some(*x), &format!("size[{k}]"))?;
            }
            SurfaceRef::Box { center, size }
        }
        "gable" => SurfaceRef::Gable {
            length: positive(s.length, "length")?,
            width: positive(s.width, "width")?,
            height: positive(s.height, "height")?,
        },
        "mesh" => {
            let (mut m, source) = mesh_source(s, base)?;
            let (lo, hi) = m.bounds();
            let scale = match (s.fit_xy, s.scale) {
                (Some(_), Some(_)) => {
                    return Err(("scale".into(), "give fit_xy or scale, not both".into()))
                }
                (Some([w, d]), None) => (w / (hi.x - lo.x)).min(d / (hi.y - lo.y)),
                (None, Some(k)) => k,
                (None, None) => 1.0,
            };
            if !(scale.is_finite() && scale > 0.0) {
                return Err(("scale".into(), format!("{scale} is not a positive factor")));
            }
            // Centre in xy; the lowest point at base_z (default: centred in z too).
            let c = (lo + hi) / 2.0 * scale;
            let tz = match s.base_z {
                Some(b) => b - lo.z * scale,
                None => -c.z,
            };
            let translate = [-c.x, -c.y, tz];
            m.transform(scale, Vector3::from(translate));
            if s.flip_normals {
                m.flip();
            }
            let r = match source {
                MeshSource::File(path) => SurfaceRef::Mesh {
                    path,
                    scale,
                    translate,
                    flip_normals: s.flip_normals,
                },
                MeshSource::Generated(generate) => SurfaceRef::Generated {
                    generate,
                    scale,
                    translate,
                    flip_normals: s.flip_normals,
                },
            };
            return Ok((Surface::Mesh(Box::new(m)), r));
        }
        other => {
            return Err((
                "kind".into(),
                format!(
                "unknown surface {other:?}: sphere, torus, frustum, paraboloid, box, gable or mesh"
            ),
            ))
        }
    };
    Ok((
        r.build().map_err(|e| ("path".to_string(), e.to_string()))?,
        r,
    ))
}

/// A polyline with normals (and the plane it lies in, for exact snapping).
#[derive(Debug, Clone)]
struct Piece {
    points: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    closed: bool,
    plane: Option<(Vector3<f64>, f64)>,
    kind: CurveKind,
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

/// Cumulative arc lengths.
fn arclen(p: &[Vector3<f64>]) -> Vec<f64> {
    let mut c = vec![0.0; p.len()];
    for i in 1..p.len() {
        c[i] = c[i - 1] + (p[i] - p[i - 1]).norm();
    }
    c
}

/// The closest point of a polyline to `x`: (segment index, parameter in it, distance).
fn closest(p: &[Vector3<f64>], x: &Vector3<f64>) -> (usize, f64, f64) {
    sfs_geometry::curve::closest_on_polyline(p, x)
}

/// Resamples a polyline at about `h` (both ends kept), interpolating normals, and snaps the
/// points onto an analytic surface.
fn resample(
    points: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    h: f64,
    s: &Surface,
    plane: Option<&Vector3<f64>>,
) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let c = arclen(points);
    let total = *c.last().unwrap_or(&0.0);
    let n = ((total / h).ceil() as usize).max(1);
    let mut out_p = Vec::with_capacity(n + 1);
    let mut out_n = Vec::with_capacity(n + 1);
    let mut seg = 0;
    for k in 0..=n {
        let target = total * k as f64 / n as f64;
        while seg + 2 < c.len() && c[seg + 1] < target {
            seg += 1;
        }
        let len = c[seg + 1] - c[seg];
        let t = if len > 0.0 {
            ((target - c[seg]) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = points[seg] + (points[seg + 1] - points[seg]) * t;
        let nn = (normals[seg] + (normals[seg + 1] - normals[seg]) * t).normalize();
        let (p, nn) = match plane {
            Some(pl) => s.snap_in_plane(p, nn, pl),
            None => (p, nn),
        };
        out_p.push(p);
        out_n.push(nn);
    }
    // On flat faces a point on an edge has two normals: take, at every point, the face of the
    // chord towards its neighbour (the one the curve runs on).
    if let (Surface::Faces(_), Some(_)) = (s, plane) {
        let m = out_p.len();
        for i in 0..m {
            let j = if i + 1 < m {
                i + 1
            } else {
                i.saturating_sub(1)
            };
            if let Some((_, g)) = s.implicit(&((out_p[i] + out_p[j]) / 2.0)) {
                out_n[i] = g;
            }
        }
    }
    (out_p, out_n)
}

/// Why a scene curve cannot be built (its key is named by [`SceneError`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CurveError {
    #[error("kind = \"mesh-boundary\" needs a mesh surface")]
    NotAMesh,
    #[error("the mesh has no boundary")]
    NoBoundary,
    #[error("unknown curve kind {0:?}: section, polyline or mesh-boundary")]
    UnknownKind(String),
    #[error("kind = \"polyline\" needs a surface of flat faces (box or gable)")]
    NotFaces,
    #[error("a polyline needs `points`, at least two")]
    NoPoints,
    #[error("polyline segment {0} does not lie on a face")]
    OffFaces(usize),
    #[error(
        "polyline segment {0} runs along an edge: say which face the device rests on with `rest`"
    )]
    AlongEdge(usize),
    #[error("normal must be a non-zero vector")]
    ZeroNormal,
    #[error("the three `through` points are collinear")]
    Collinear,
    #[error("give either normal (+ offset) or through")]
    NoPlane,
    #[error("the plane does not cut the surface")]
    NoCut,
    #[error("closed = true, but this section is not a loop")]
    NotALoop,
    #[error("give both from and to, or neither")]
    HalfArc,
    #[error("from and to are the same point of the section")]
    EmptyArc,
    #[error("boundary, crease and guide: at most one of them")]
    TwoKinds,
}

impl CurveToml {
    /// What the curve means, from its `boundary` / `crease` / `guide` flags.
    fn kind(&self) -> Result<CurveKind, CurveError> {
        match (self.boundary, self.crease, self.guide) {
            (false, false, false) => Ok(CurveKind::Interior),
            (true, false, false) => Ok(CurveKind::Boundary),
            (false, true, false) => Ok(CurveKind::Crease),
            (false, false, true) => Ok(CurveKind::Guide),
            _ => Err(CurveError::TwoKinds),
        }
    }
}

fn piece(s: &Surface, tess: &TriMesh, c: &CurveToml, h: f64) -> Result<Piece, CurveError> {
    if c.kind == "mesh-boundary" {
        let Surface::Mesh(m) = s else {
            return Err(CurveError::NotAMesh);
        };
        let loops = m.boundary_loops();
        let lp = loops
            .iter()
            .max_by_key(|l| l.len())
            .ok_or(CurveError::NoBoundary)?;
        let mut points: Vec<Vector3<f64>> = lp.iter().map(|&i| m.v[i as usize]).collect();
        let mut normals: Vec<Vector3<f64>> = lp.iter().map(|&i| m.n[i as usize]).collect();
        points.push(points[0]);
        normals.push(normals[0]);
        let (points, normals) = resample(&points, &normals, h, s, None);
        return Ok(Piece {
            points,
            normals,
            closed: true,
            plane: None,
            kind: c.kind()?,
        });
    }
    if c.kind == "polyline" {
        return polyline(s, c, h);
    }
    if c.kind != "section" {
        return Err(CurveError::UnknownKind(c.kind.clone()));
    }
    let (normal, offset) = match (c.normal, c.through) {
        (Some(n), None) => {
            let n = v3(n);
            let l = n.norm();
            if !(l > 0.0 && l.is_finite()) {
                return Err(CurveError::ZeroNormal);
            }
            (n / l, c.offset.unwrap_or(0.0) / l)
        }
        (None, Some([a, b, q])) => {
            let (a, b, q) = (v3(a), v3(b), v3(q));
            let n = (b - a).cross(&(q - a));
            let l = n.norm();
            if l.is_nan() || l < 1e-12 {
                return Err(CurveError::Collinear);
            }
            (n / l, (n / l).dot(&a))
        }
        _ => return Err(CurveError::NoPlane),
    };
    let pieces: Vec<Section> = tess.slice(&normal, offset);
    if pieces.is_empty() {
        return Err(CurveError::NoCut);
    }
    let hint = c.near.or(c.from).map(v3).unwrap_or_else(Vector3::zeros);
    let sec = pieces
        .into_iter()
        .min_by(|a, b| {
            closest(&a.points, &hint)
                .2
                .total_cmp(&closest(&b.points, &hint).2)
        })
        .expect("non-empty");
    let mut pts = sec.points;
    let mut nrm = sec.normals;
    if sec.closed {
        pts.push(pts[0]);
        nrm.push(nrm[0]);
    }
    let (pts, nrm) = match (c.from, c.to) {
        (Some(f), Some(t)) => arc(
            &pts,
            &nrm,
            sec.closed,
            &v3(f),
            &v3(t),
            c.via.map(v3).as_ref(),
        )?,
        (None, None) => {
            if c.closed && !sec.closed {
                return Err(CurveError::NotALoop);
            }
            (pts, nrm)
        }
        _ => return Err(CurveError::HalfArc),
    };
    let closed = c.closed && c.from.is_none();
    let (points, normals) = resample(&pts, &nrm, h, s, Some(&normal));
    Ok(Piece {
        points,
        normals,
        closed,
        plane: Some((normal, offset)),
        kind: c.kind()?,
    })
}

/// A polyline on flat faces through `points` (closed: back to the first), sampled about every
/// `h` with its corners kept; each segment's normal is its face's (along an edge, the face
/// whose normal is nearest `rest`: the one the device rests on), a corner's the mean of its
/// two segments'.
fn polyline(s: &Surface, c: &CurveToml, h: f64) -> Result<Piece, CurveError> {
    let Surface::Faces(faces) = s else {
        return Err(CurveError::NotFaces);
    };
    let mut corners: Vec<Vector3<f64>> = c
        .points
        .as_ref()
        .ok_or(CurveError::NoPoints)?
        .iter()
        .map(|p| v3(*p))
        .collect();
    if corners.len() < 2 {
        return Err(CurveError::NoPoints);
    }
    if c.closed {
        corners.push(corners[0]);
    }
    let scale = corners.iter().map(|p| p.norm()).fold(1.0, f64::max);
    let mut normals = Vec::new();
    for (k, w) in corners.windows(2).enumerate() {
        let on: Vec<usize> = faces
            .faces_at(&w[0], 1e-9 * scale)
            .into_iter()
            .filter(|f| faces.faces_at(&w[1], 1e-9 * scale).contains(f))
            .collect();
        let n = match on.len() {
            0 => return Err(CurveError::OffFaces(k)),
            1 => faces.planes[on[0]].0,
            _ => {
                let rest = v3(c.rest.ok_or(CurveError::AlongEdge(k))?);
                on.iter()
                    .map(|&f| faces.planes[f].0)
                    .max_by(|a, b| a.dot(&rest).total_cmp(&b.dot(&rest)))
                    .expect("two faces")
            }
        };
        normals.push(n);
    }
    let (mut points, mut nrm) = (Vec::new(), Vec::new());
    for (k, w) in corners.windows(2).enumerate() {
        let m = (((w[1] - w[0]).norm() / h).ceil() as usize).max(1);
        for j in 0..m {
            points.push(w[0] + (w[1] - w[0]) * (j as f64 / m as f64));
            let n = if j == 0 && k > 0 {
                (normals[k - 1] + normals[k]).normalize()
            } else {
                normals[k]
            };
            nrm.push(n);
        }
    }
    let last = normals.len() - 1;
    points.push(*corners.last().expect("two"));
    nrm.push(if c.closed {
        (normals[last] + normals[0]).normalize()
    } else {
        normals[last]
    });
    if c.closed {
        nrm[0] = nrm[nrm.len() - 1];
    }
    Ok(Piece {
        points,
        normals: nrm,
        closed: c.closed,
        plane: None,
        kind: c.kind()?,
    })
}

/// The arc from the point nearest `f` to the point nearest `t` (through `via`, else the
/// shorter way round a loop).
type Polyline = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);
fn arc(
    p: &[Vector3<f64>],
    n: &[Vector3<f64>],
    closed: bool,
    f: &Vector3<f64>,
    t: &Vector3<f64>,
    via: Option<&Vector3<f64>>,
) -> Result<Polyline, CurveError> {
    // Insert the exact closest points, then walk between them.
    let split = |p: &[Vector3<f64>],
                 n: &[Vector3<f64>],
                 x: &Vector3<f64>|
     -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>, usize) {
        let (i, u, _) = closest(p, x);
        let q = p[i] + (p[i + 1] - p[i]) * u;
        let m = (n[i] + (n[i + 1] - n[i]) * u).normalize();
        let mut pp = p.to_vec();
        let mut nn = n.to_vec();
        pp.insert(i + 1, q);
        nn.insert(i + 1, m);
        (pp, nn, i + 1)
    };
    let (p1, n1, _) = split(p, n, f);
    let (p2, n2, _) = split(&p1, &n1, t);
    let fi = p2
        .iter()
        .position(|q| (q - closest_point(&p2, f)).norm() < 1e-12)
        .unwrap_or(0);
    let ti = p2
        .iter()
        .position(|q| (q - closest_point(&p2, t)).norm() < 1e-12)
        .unwrap_or(p2.len() - 1);
    if fi == ti {
        return Err(CurveError::EmptyArc);
    }
    let forward = |a: usize, b: usize| -> Polyline {
        let m = p2.len() - 1; // closed: last == first
        let mut pp = Vec::new();
        let mut nn = Vec::new();
        let mut i = a;
        loop {
            pp.push(p2[i]);
            nn.push(n2[i]);
            if i == b {
                break;
            }
            i = if closed { (i + 1) % m } else { i + 1 };
        }
        (pp, nn)
    };
    if !closed {
        let (a, b) = (fi.min(ti), fi.max(ti));
        let (mut pp, mut nn) = forward(a, b);
        if fi > ti {
            pp.reverse();
            nn.reverse();
        }
        return Ok((pp, nn));
    }
    let m = p2.len() - 1;
    let (fi, ti) = (fi % m, ti % m);
    let one = forward(fi, ti);
    let (mut other_p, mut other_n) = forward(ti, fi);
    other_p.reverse();
    other_n.reverse();
    let len = |x: &[Vector3<f64>]| *arclen(x).last().unwrap_or(&0.0);
    let pick_one = match via {
        Some(v) => closest(&one.0, v).2 <= closest(&other_p, v).2,
        None => len(&one.0) <= len(&other_p),
    };
    Ok(if pick_one { one } else { (other_p, other_n) })
}

fn closest_point(p: &[Vector3<f64>], x: &Vector3<f64>) -> Vector3<f64> {
    let (i, u, _) = closest(p, x);
    p[i] + (p[i + 1] - p[i]) * u
}

/// Finds the nodes (crossings and open ends), inserts them exactly into the polylines, and
/// tags every curve.
type Network = (Vec<SceneCurve>, Vec<Vector3<f64>>);
fn network(s: &Surface, pieces: Vec<Piece>, h: f64) -> Result<Network, (usize, String)> {
    let tol = h;
    let mut cand: Vec<Vector3<f64>> = Vec::new();
    for (i, a) in pieces.iter().enumerate() {
        if !a.closed {
            cand.push(a.points[0]);
            cand.push(*a.points.last().expect("non-empty"));
        }
        for b in pieces.iter().skip(i + 1) {
            cand.extend(crossings(s, a, b, tol));
        }
    }
    // Merge candidates closer than 2 h; keep the first.
    let mut nodes: Vec<Vector3<f64>> = Vec::new();
    for c in cand {
        if nodes.iter().all(|n| (n - c).norm() > 2.0 * tol) {
            nodes.push(c);
        }
    }
    // Tag each curve; order nodes by first appearance along the curves in scene order.
    let mut order: Vec<Option<u32>> = vec![None; nodes.len()];
    let mut next = 0u32;
    let mut curves = Vec::new();
    for (ci, pc) in pieces.into_iter().enumerate() {
        let mut pts = pc.points;
        let mut nrm = pc.normals;
        let c = arclen(&pts);
        let mut on: Vec<(f64, usize)> = Vec::new();
        for (k, nd) in nodes.iter().enumerate() {
            let (i, u, d) = closest(&pts, nd);
            if d <= tol {
                on.push((c[i] + (c[i + 1] - c[i]) * u, k));
            }
        }
        on.sort_by(|a, b| a.0.total_cmp(&b.0));
        if on.len() < if pc.closed { 1 } else { 2 } {
            return Err((
                ci,
                format!(
                    "crosses {} node(s); a curve needs two ends (or a node on its loop)",
                    on.len()
                ),
            ));
        }
        // Insert the node positions exactly (from the end, so earlier indices stay valid).
        let mut tag_pos: Vec<(f64, usize)> = Vec::new();
        for &(sv, k) in on.iter().rev() {
            let cc = arclen(&pts);
            let i = cc.partition_point(|&x| x <= sv).clamp(1, pts.len() - 1);
            let (a, b) = (cc[i - 1], cc[i]);
            let u = if b > a { (sv - a) / (b - a) } else { 0.0 };
            let nn = (nrm[i - 1] + (nrm[i] - nrm[i - 1]) * u).normalize();
            let near_prev = (nodes[k] - pts[i - 1]).norm() < h * 0.25;
            let near_next = (nodes[k] - pts[i]).norm() < h * 0.25;
            if near_prev {
                pts[i - 1] = nodes[k];
            } else if near_next {
                pts[i] = nodes[k];
            } else {
                pts.insert(i, nodes[k]);
                nrm.insert(i, nn);
            }
            tag_pos.push((sv, k));
        }
        tag_pos.reverse();
        // Point index of each tag.
        let mut tags: Vec<(usize, u32)> = Vec::new();
        for &(_, k) in &tag_pos {
            let idx = pts
                .iter()
                .enumerate()
                .min_by(|a, b| (a.1 - nodes[k]).norm().total_cmp(&(b.1 - nodes[k]).norm()))
                .map(|x| x.0)
                .expect("non-empty");
            let id = *order[k].get_or_insert_with(|| {
                next += 1;
                next - 1
            });
            tags.push((idx, id));
        }
        if pc.closed {
            // Start the loop at its first node; end there again.
            let first = tags[0].0;
            let m = pts.len() - 1; // last == first
            let mut p2: Vec<Vector3<f64>> = (0..m).map(|j| pts[(first + j) % m]).collect();
            let mut n2: Vec<Vector3<f64>> = (0..m).map(|j| nrm[(first + j) % m]).collect();
            p2.push(p2[0]);
            n2.push(n2[0]);
            let mut t2: Vec<(usize, u32)> = tags
                .iter()
                .map(|&(i, id)| ((i + m - first) % m, id))
                .collect();
            t2.sort_by_key(|t| t.0);
            t2.push((m, t2[0].1));
            pts = p2;
            nrm = n2;
            tags = t2;
        } else {
            // Trim to the first and last node.
            let (a, b) = (tags[0].0, tags.last().expect("two").0);
            pts = pts[a..=b].to_vec();
            nrm = nrm[a..=b].to_vec();
            for t in &mut tags {
                t.0 -= a;
            }
        }
        curves.push(SceneCurve {
            points: pts,
            normals: nrm,
            kind: pc.kind,
            closed: pc.closed,
            tags,
        });
    }
    // Node positions by their index.
    let mut by_index = vec![Vector3::zeros(); next as usize];
    for (k, o) in order.iter().enumerate() {
        if let Some(id) = o {
            by_index[*id as usize] = nodes[k];
        }
    }
    Ok((curves, by_index))
}

/// Where curve `b`'s plane cuts curve `a` at a point of `b`.
fn crossings(s: &Surface, a: &Piece, b: &Piece, tol: f64) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    let Some((nb, db)) = b.plane else {
        // A non-planar curve (mesh boundary): crossings are ends of other curves, found as ends.
        return out;
    };
    for w in a.points.windows(2) {
        let (s0, s1) = (nb.dot(&w[0]) - db, nb.dot(&w[1]) - db);
        if (s0 < 0.0) == (s1 < 0.0) || s0 == s1 {
            continue;
        }
        let t = s0 / (s0 - s1);
        let mut p = w[0] + (w[1] - w[0]) * t;
        // On an analytic surface, snap onto the line where both planes meet.
        if let (Some((na, _)), Some(_)) = (a.plane, s.implicit(&p)) {
            let u = na.cross(&nb);
            if u.norm() > 1e-9 {
                let u = u.normalize();
                for _ in 0..30 {
                    let Some((f, g)) = s.implicit(&p) else { break };
                    let gu = g.dot(&u);
                    if gu.abs() < 1e-12 {
                        break;
                    }
                    p -= u * (f / gu);
                    if f.abs() < 1e-13 {
                        break;
                    }
                }
            }
        }
        if closest(&b.points, &p).2 <= tol {
            out.push(p);
        }
    }
    out
}
