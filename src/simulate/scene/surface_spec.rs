//! A scene's surface: its `[surface]` table, checked and built, and the reference the truth
//! file keeps to rebuild it ([`SurfaceRef`]).

use super::super::mesh::TriMesh;
use super::super::surface::{Faces, Surface};
use super::{need, PAPER_DATA_ENV};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SurfaceToml {
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
    /// The same, applied to a [`procedural`](super::super::procedural) mesh.
    Generated {
        generate: String,
        scale: f64,
        translate: [f64; 3],
        flip_normals: bool,
    },
}

impl SurfaceRef {
    /// Rebuilds the surface.
    pub fn build(&self) -> Result<Surface, super::super::mesh::MeshError> {
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
                let m = super::super::procedural::generate(generate).ok_or_else(|| {
                    super::super::mesh::MeshError::Unknown {
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

/// The mesh a `mesh` surface names: `path` (relative to the scene file), `paper` (in
/// [`PAPER_DATA_ENV`]) or `generate` (a [`procedural`](super::super::procedural) mesh), and what
/// the truth file will call it.
pub(super) fn mesh_source(
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
        let m = super::super::procedural::generate(g).ok_or((
            "generate".to_string(),
            format!(
                "unknown mesh {g:?}: {}",
                super::super::procedural::NAMES.join(" or ")
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
pub(super) enum MeshSource {
    File(PathBuf),
    Generated(String),
}

pub(super) fn build_surface(
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
