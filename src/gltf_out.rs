//! `network.glb`: the output contract, written through `gltf::json`.
//!
//! glTF 2.0 binary, metres, +Y up: world `(x east, y north, z up)` ↦ glTF `(x, z, −y)`.
//! - A node named `network` whose mesh has one primitive per curve in mode LINE_STRIP
//!   (POSITION with exact min/max, NORMAL = unit surface normal at the sample; primitive extras
//!   `{"curve": index, "kind": "boundary" | "interior" | "crease" | "guide", "boundary": bool,
//!   "nodes": [node sequence]}`, `boundary` kept for readers before curve kinds; the custom
//!   attribute `_SIGMA_M`, float, each point's uncertainty in metres); the node's
//!   extras hold
//!   the node positions `{"nodes": {"<index>": [x, y, z]}}` in the glb's frame.
//! - When a surface exists, a node named `surface`: a triangle mesh (POSITION, NORMAL, u32
//!   indices).
//!
//! Nothing non-finite, no zero normal and no degenerate triangle is written: such input is an
//! error naming the curve (or triangle) and the index.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::gltf_out::{network_glb, NetworkCurve};
//! use sfs_geometry::curve::CurveKind;
//! let c = NetworkCurve { index: 0, kind: CurveKind::Interior, nodes: vec![0, 1],
//!     points: vec![Vector3::zeros(), Vector3::x()], normals: vec![Vector3::z(); 2],
//!     sigma_m: vec![0.001; 2] };
//! let glb = network_glb(&[c], &Default::default(), None).unwrap();
//! assert_eq!(&glb[..4], b"glTF");
//! ```

use gltf::json;
use json::validation::{Checked, USize64};
use nalgebra::Vector3;
use sfs_geometry::curve::CurveKind;
use sfs_geometry::network::poisson::Positions;
use std::collections::BTreeMap;

/// A reconstructed curve, world frame (z up).
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkCurve {
    pub index: usize,
    pub kind: CurveKind,
    pub nodes: Vec<u32>,
    pub points: Vec<Vector3<f64>>,
    /// Unit surface normals at the points.
    pub normals: Vec<Vector3<f64>>,
    /// Each point's uncertainty, m (written as the attribute `_SIGMA_M` when there is one
    /// per point).
    pub sigma_m: Vec<f64>,
}

pub use sfs_geometry::surface::SurfaceMesh;

/// What cannot be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GltfError {
    #[error("curve {curve}: sample {index} is not finite")]
    NonFinitePoint { curve: usize, index: usize },
    #[error("curve {curve}: the uncertainty at sample {index} is negative or not finite")]
    NonFiniteSigma { curve: usize, index: usize },
    #[error("curve {curve}: the normal at sample {index} is zero or not finite")]
    BadNormal { curve: usize, index: usize },
    #[error("curve {curve}: {points} points and {normals} normals")]
    LengthMismatch {
        curve: usize,
        points: usize,
        normals: usize,
    },
    #[error("surface: vertex {index} is not finite or has no normal")]
    BadVertex { index: usize },
    #[error("surface: triangle {index} refers to vertex {vertex}, of {count}")]
    BadIndex {
        index: usize,
        vertex: u32,
        count: usize,
    },
    #[error("surface: triangle {index} is degenerate (zero area)")]
    DegenerateTriangle { index: usize },
    #[error("glTF serialisation failed: {0}")]
    Serialise(String),
}

/// World (z up) → glTF (y up).
/// The curves' custom attribute: each point's uncertainty, m.
pub const SIGMA_ATTRIBUTE: &str = "_SIGMA_M";

#[inline]
pub fn to_gltf(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.z as f32, -v.y as f32]
}

/// glTF (y up) → world (z up).
#[inline]
pub fn from_gltf(v: [f32; 3]) -> Vector3<f64> {
    Vector3::new(v[0] as f64, -v[2] as f64, v[1] as f64)
}

struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    fn view(
        &mut self,
        bytes: &[u8],
        target: json::buffer::Target,
    ) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: Some(Checked::Valid(target)),
            extensions: None,
            extras: None,
        })
    }

    /// An accessor of `count` elements of `type_` (`component` each) over `bytes`, in a view
    /// of its own.
    fn accessor(
        &mut self,
        bytes: &[u8],
        target: json::buffer::Target,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        bounds: Option<(json::Value, json::Value)>,
    ) -> json::Index<json::Accessor> {
        let view = self.view(bytes, target);
        let (min, max) = bounds.map_or((None, None), |(lo, hi)| (Some(lo), Some(hi)));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Checked::Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: None,
            type_: Checked::Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn vec3(&mut self, data: &[[f32; 3]], bounds: bool) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = data
            .iter()
            .flat_map(|v| v.iter().flat_map(|x| x.to_le_bytes()))
            .collect();
        let bounds = bounds.then(|| {
            let mut lo = [f32::MAX; 3];
            let mut hi = [f32::MIN; 3];
            for v in data {
                for k in 0..3 {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            (
                json::Value::from(lo.to_vec()),
                json::Value::from(hi.to_vec()),
            )
        });
        self.accessor(
            &bytes,
            json::buffer::Target::ArrayBuffer,
            data.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            bounds,
        )
    }

    /// Floats, one per vertex (a custom attribute).
    fn scalars(&mut self, data: &[f32]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            json::buffer::Target::ArrayBuffer,
            data.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Scalar,
            None,
        )
    }

    fn indices(&mut self, tris: &[[u32; 3]]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = tris
            .iter()
            .flat_map(|t| t.iter().flat_map(|x| x.to_le_bytes()))
            .collect();
        self.accessor(
            &bytes,
            json::buffer::Target::ElementArrayBuffer,
            tris.len() * 3,
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            None,
        )
    }
}

fn raw(v: serde_json::Value) -> json::extras::Extras {
    json::extras::RawValue::from_string(v.to_string()).ok()
}

fn unit(n: &Vector3<f64>) -> Option<[f32; 3]> {
    let l = n.norm();
    if !(l.is_finite() && l > 1e-12) {
        return None;
    }
    let u = to_gltf(&(n / l));
    // Renormalise in f32 so that the validator's unit-length check holds.
    let l32 = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    Some(u.map(|x| x / l32))
}

fn finite(p: &Vector3<f64>) -> bool {
    p.iter().all(|x| x.is_finite() && x.abs() < 1e30)
}

/// The glb bytes of a network (and optional surface).
pub fn network_glb(
    curves: &[NetworkCurve],
    nodes: &BTreeMap<u32, Vector3<f64>>,
    surface: Option<&SurfaceMesh>,
) -> Result<Vec<u8>, GltfError> {
    let mut b = Builder {
        root: json::Root::default(),
        bin: Vec::new(),
    };
    b.root.asset.generator = Some(format!("sfs {}", env!("CARGO_PKG_VERSION")));
    let mut prims = Vec::new();
    for c in curves {
        prims.extend(b.curve(c)?);
    }
    let mut scene_nodes = Vec::new();
    let node_json: serde_json::Map<String, serde_json::Value> = nodes
        .iter()
        .filter(|(_, p)| finite(p))
        .map(|(k, p)| (k.to_string(), serde_json::json!(to_gltf(p))))
        .collect();
    let mesh = (!prims.is_empty()).then(|| {
        b.root.push(json::Mesh {
            extensions: None,
            extras: None,
            name: Some("network".into()),
            primitives: prims,
            weights: None,
        })
    });
    scene_nodes.push(b.root.push(json::Node {
        mesh,
        name: Some("network".into()),
        extras: raw(serde_json::json!({ "nodes": node_json })),
        ..Default::default()
    }));
    if let Some(s) = surface.filter(|s| !s.triangles.is_empty()) {
        scene_nodes.push(b.surface(s)?);
    }
    b.glb(scene_nodes)
}

impl Builder {
    /// A curve's line strip (`None` for a curve of fewer than two points), with its index,
    /// kind and nodes as extras.
    fn curve(&mut self, c: &NetworkCurve) -> Result<Option<json::mesh::Primitive>, GltfError> {
        if c.points.len() != c.normals.len() {
            return Err(GltfError::LengthMismatch {
                curve: c.index,
                points: c.points.len(),
                normals: c.normals.len(),
            });
        }
        if c.points.len() < 2 {
            return Ok(None); // a line strip needs two points
        }
        let mut pos = Vec::with_capacity(c.points.len());
        let mut nrm = Vec::with_capacity(c.points.len());
        for (i, (p, n)) in c.points.iter().zip(&c.normals).enumerate() {
            if !finite(p) {
                return Err(GltfError::NonFinitePoint {
                    curve: c.index,
                    index: i,
                });
            }
            pos.push(to_gltf(p));
            nrm.push(unit(n).ok_or(GltfError::BadNormal {
                curve: c.index,
                index: i,
            })?);
        }
        let pa = self.vec3(&pos, true);
        let na = self.vec3(&nrm, false);
        let mut attributes = BTreeMap::new();
        attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), pa);
        attributes.insert(Checked::Valid(json::mesh::Semantic::Normals), na);
        if c.sigma_m.len() == c.points.len() {
            let mut sigma = Vec::with_capacity(c.sigma_m.len());
            for (i, s) in c.sigma_m.iter().enumerate() {
                if !(s.is_finite() && *s >= 0.0 && *s < 1e30) {
                    return Err(GltfError::NonFiniteSigma {
                        curve: c.index,
                        index: i,
                    });
                }
                sigma.push(*s as f32);
            }
            let sa = self.scalars(&sigma);
            attributes.insert(
                Checked::Valid(json::mesh::Semantic::Extras(SIGMA_ATTRIBUTE[1..].into())),
                sa,
            );
        }
        Ok(Some(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: raw(serde_json::json!({
                "curve": c.index,
                "kind": c.kind.name(),
                "boundary": c.kind == CurveKind::Boundary,
                "nodes": c.nodes,
            })),
            indices: None,
            material: None,
            mode: Checked::Valid(json::mesh::Mode::LineStrip),
            targets: None,
        }))
    }

    /// The surface's node: its mesh, checked (finite vertices, unit normals, indices in
    /// range, no triangle degenerate once written in f32).
    fn surface(&mut self, s: &SurfaceMesh) -> Result<json::Index<json::Node>, GltfError> {
        let n = s.positions.len();
        let mut pos = Vec::with_capacity(n);
        let mut nrm = Vec::with_capacity(n);
        for (i, (p, q)) in s.positions.iter().zip(&s.normals).enumerate() {
            if !finite(p) {
                return Err(GltfError::BadVertex { index: i });
            }
            pos.push(to_gltf(p));
            nrm.push(unit(q).ok_or(GltfError::BadVertex { index: i })?);
        }
        if s.normals.len() != n {
            return Err(GltfError::BadVertex {
                index: s.normals.len().min(n),
            });
        }
        for (i, t) in s.triangles.iter().enumerate() {
            if let Some(&v) = t.iter().find(|&&v| v as usize >= n) {
                return Err(GltfError::BadIndex {
                    index: i,
                    vertex: v,
                    count: n,
                });
            }
            // Degenerate in the written (f32) coordinates is what a viewer sees.
            let [a, bb, c] = t.map(|v| Vector3::from(pos[v as usize]).cast::<f64>());
            if (bb - a).cross(&(c - a)).norm() <= 0.0 {
                return Err(GltfError::DegenerateTriangle { index: i });
            }
        }
        let pa = self.vec3(&pos, true);
        let na = self.vec3(&nrm, false);
        let ia = self.indices(&s.triangles);
        let mut attributes = BTreeMap::new();
        attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), pa);
        attributes.insert(Checked::Valid(json::mesh::Semantic::Normals), na);
        let mesh = self.root.push(json::Mesh {
            extensions: None,
            extras: None,
            name: Some("surface".into()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: None,
                indices: Some(ia),
                material: None,
                mode: Checked::Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        });
        Ok(self.root.push(json::Node {
            mesh: Some(mesh),
            name: Some("surface".into()),
            ..Default::default()
        }))
    }

    /// The glb of the scene of `scene_nodes`: the JSON and the binary chunk, each padded to 4
    /// bytes.
    fn glb(mut self, scene_nodes: Vec<json::Index<json::Node>>) -> Result<Vec<u8>, GltfError> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        if !self.bin.is_empty() {
            self.root.push(json::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: None,
                extensions: None,
                extras: None,
            });
        }
        let scene = self.root.push(json::Scene {
            extensions: None,
            extras: None,
            name: None,
            nodes: scene_nodes,
        });
        self.root.scene = Some(scene);
        let json_text = json::serialize::to_string(&self.root)
            .map_err(|e| GltfError::Serialise(e.to_string()))?;
        let mut json_bytes = json_text.into_bytes();
        while json_bytes.len() % 4 != 0 {
            json_bytes.push(b' ');
        }
        let bin_chunk = if self.bin.is_empty() {
            0
        } else {
            8 + self.bin.len()
        };
        let length = 12 + 8 + json_bytes.len() + bin_chunk;
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: length as u32,
            },
            json: std::borrow::Cow::Owned(json_bytes),
            bin: (!self.bin.is_empty()).then_some(std::borrow::Cow::Owned(self.bin)),
        };
        glb.to_vec()
            .map_err(|e| GltfError::Serialise(e.to_string()))
    }
}

/// The curves of a reconstructed network as they are written.
pub fn network_curves(p: &Positions) -> Vec<NetworkCurve> {
    p.curves
        .iter()
        .map(|c| NetworkCurve {
            index: c.index,
            kind: c.kind,
            nodes: c.nodes.iter().map(|n| n.1).collect(),
            points: c.points.clone(),
            normals: c.normals.clone(),
            sigma_m: c.sigma_m.clone(),
        })
        .collect()
}

/// A reconstructed network as `sfs eval` reads it back from its glb (no surface).
pub fn as_read_network(p: &Positions) -> ReadNetwork {
    ReadNetwork {
        curves: network_curves(p),
        nodes: p.nodes.clone(),
        surface: None,
    }
}

/// A network read back from a glb (world frame, z up).
#[derive(Debug, Clone, Default)]
pub struct ReadNetwork {
    pub curves: Vec<NetworkCurve>,
    pub nodes: BTreeMap<u32, Vector3<f64>>,
    pub surface: Option<SurfaceMesh>,
}

/// Why a glb cannot be read back.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("not a valid glb: {0}")]
    Glb(#[from] gltf::Error),
    #[error("{0}")]
    Extras(#[from] serde_json::Error),
    #[error("node key {0:?} is not an index")]
    NodeKey(String),
}

/// Reads what [`network_glb`] writes (nodes named `network` and `surface`).
pub fn read_glb(bytes: &[u8]) -> Result<ReadNetwork, ReadError> {
    let g = gltf::Gltf::from_slice(bytes)?;
    let blob = g.blob.as_deref();
    let mut out = ReadNetwork::default();
    for node in g.nodes() {
        let name = node.name().unwrap_or("");
        if name == "network" {
            if let Some(x) = node.extras() {
                let v: serde_json::Value = serde_json::from_str(x.get())?;
                if let Some(m) = v.get("nodes").and_then(|n| n.as_object()) {
                    for (k, p) in m {
                        let a: Vec<f32> = serde_json::from_value(p.clone())?;
                        let idx: u32 = k.parse().map_err(|_| ReadError::NodeKey(k.clone()))?;
                        if a.len() == 3 {
                            out.nodes.insert(idx, from_gltf([a[0], a[1], a[2]]));
                        }
                    }
                }
            }
        }
        let Some(mesh) = node.mesh() else { continue };
        for (pi, prim) in mesh.primitives().enumerate() {
            let reader = prim.reader(|_| blob);
            let pos: Vec<Vector3<f64>> = reader
                .read_positions()
                .map(|it| it.map(from_gltf).collect())
                .unwrap_or_default();
            let nrm: Vec<Vector3<f64>> = reader
                .read_normals()
                .map(|it| it.map(from_gltf).collect())
                .unwrap_or_default();
            let sigma_m: Vec<f64> = prim
                .get(&gltf::Semantic::Extras(SIGMA_ATTRIBUTE[1..].into()))
                .and_then(|a| gltf::accessor::Iter::<f32>::new(a, |_| blob))
                .map(|it| it.map(f64::from).collect())
                .unwrap_or_default();
            match (name, prim.mode()) {
                ("network", gltf::mesh::Mode::LineStrip) => {
                    let extras: serde_json::Value = prim
                        .extras()
                        .as_ref()
                        .and_then(|x| serde_json::from_str(x.get()).ok())
                        .unwrap_or(serde_json::Value::Null);
                    out.curves.push(NetworkCurve {
                        index: extras
                            .get("curve")
                            .and_then(|v| v.as_u64())
                            .unwrap_or(pi as u64) as usize,
                        // Files written before curve kinds say only `boundary`.
                        kind: extras
                            .get("kind")
                            .and_then(|v| v.as_str())
                            .and_then(CurveKind::of_name)
                            .unwrap_or(
                                if extras.get("boundary").and_then(|v| v.as_bool()) == Some(true) {
                                    CurveKind::Boundary
                                } else {
                                    CurveKind::Interior
                                },
                            ),
                        nodes: extras
                            .get("nodes")
                            .and_then(|v| serde_json::from_value(v.clone()).ok())
                            .unwrap_or_default(),
                        points: pos,
                        normals: nrm,
                        sigma_m,
                    });
                }
                ("surface", gltf::mesh::Mode::Triangles) => {
                    let idx: Vec<u32> = reader
                        .read_indices()
                        .map(|i| i.into_u32().collect())
                        .unwrap_or_default();
                    out.surface = Some(SurfaceMesh {
                        positions: pos,
                        normals: nrm,
                        triangles: idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
                    });
                }
                _ => {}
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_and_errors() {
        let c = NetworkCurve {
            index: 3,
            kind: CurveKind::Crease,
            nodes: vec![4, 5],
            points: vec![Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.4, -0.5, 0.6)],
            normals: vec![Vector3::z() * 2.0, Vector3::x()],
            sigma_m: vec![0.0015, 0.0042],
        };
        let mut nodes = BTreeMap::new();
        nodes.insert(4, c.points[0]);
        nodes.insert(5, c.points[1]);
        let surf = SurfaceMesh {
            positions: vec![Vector3::zeros(), Vector3::x(), Vector3::y()],
            normals: vec![Vector3::z(); 3],
            triangles: vec![[0, 1, 2]],
        };
        let glb = network_glb(std::slice::from_ref(&c), &nodes, Some(&surf)).unwrap();
        let r = read_glb(&glb).unwrap();
        assert_eq!(r.curves.len(), 1);
        let rc = &r.curves[0];
        assert_eq!(
            (rc.index, rc.kind, rc.nodes.clone()),
            (3, CurveKind::Crease, vec![4, 5])
        );
        for (a, b) in rc.points.iter().zip(&c.points) {
            assert!((a - b).norm() < 1e-6);
        }
        assert!(
            (rc.normals[0] - Vector3::z()).norm() < 1e-6,
            "normals are unit"
        );
        assert!((r.nodes[&5] - c.points[1]).norm() < 1e-6);
        assert_eq!(rc.sigma_m.len(), 2);
        for (a, b) in rc.sigma_m.iter().zip(&c.sigma_m) {
            assert!((a - b).abs() < 1e-9, "σ {a} for {b}");
        }
        assert_eq!(r.surface.unwrap().triangles, vec![[0, 1, 2]]);

        let mut bad = c.clone();
        bad.points[1].x = f64::NAN;
        assert_eq!(
            network_glb(&[bad], &nodes, None),
            Err(GltfError::NonFinitePoint { curve: 3, index: 1 })
        );
        let mut bad = c.clone();
        bad.sigma_m[0] = f64::INFINITY;
        assert_eq!(
            network_glb(&[bad], &nodes, None),
            Err(GltfError::NonFiniteSigma { curve: 3, index: 0 })
        );
        let mut bad = c.clone();
        bad.normals[0] = Vector3::zeros();
        assert_eq!(
            network_glb(&[bad], &nodes, None),
            Err(GltfError::BadNormal { curve: 3, index: 0 })
        );
        let degenerate = SurfaceMesh {
            triangles: vec![[0, 1, 1]],
            ..surf.clone()
        };
        assert_eq!(
            network_glb(std::slice::from_ref(&c), &nodes, Some(&degenerate)),
            Err(GltfError::DegenerateTriangle { index: 0 })
        );
        let out_of_range = SurfaceMesh {
            triangles: vec![[0, 1, 7]],
            ..surf
        };
        assert!(matches!(
            network_glb(&[c], &nodes, Some(&out_of_range)),
            Err(GltfError::BadIndex { .. })
        ));
    }

    #[test]
    fn y_up_conversion_is_a_rotation() {
        let v = Vector3::new(1.0, 2.0, 3.0);
        assert_eq!(to_gltf(&v), [1.0, 3.0, -2.0]);
        assert!((from_gltf(to_gltf(&v)) - v).norm() < 1e-6);
    }
}
