//! Surfacing the curve network with normal control (Stanko et al. 2016), in the order the data
//! flows:
//!
//! - [`cycles`]: the faces of the network, traced from the node normals, and the checks of
//!   the cell complex they form.
//! - [`creases`]: the patches split along crease curves (each side its own normals; corners
//!   and darts).
//! - [`tessellate`]: each cycle triangulated in its plane (constrained Delaunay, spade), with
//!   the boundary developed when the projection folds or shrinks it.
//! - [`cotmatrix`]: the cotangent Laplacian and mixed Voronoi areas.
//! - [`fit`]: biharmonic propagation of positions and normals, the mean-curvature guide and
//!   the fit (hard or soft constraints), one factorisation shared, reweighting from 3D.
//! - [`faces`]: the faces kept between surfaces of a growing or moving network (issue 19):
//!   exact reuse, or provisional surfaces within a tolerance.
//! - [`analytic`]: the paper's test networks with exact normals (tests, benches, Table 1).

pub mod analytic;
pub mod cotmatrix;
pub mod creases;
pub mod cycles;
pub mod faces;
pub mod fit;
pub mod tessellate;

use nalgebra::Vector3;

/// A run of a curve between two nodes (a segment of the network), as the problems name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Span {
    pub curve: usize,
    pub a: u32,
    pub b: u32,
}

impl std::fmt::Display for Span {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "curve {} between nodes {} and {}",
            self.curve, self.a, self.b
        )
    }
}

/// A problem the surfacer met (a face it could not trace or accept, a patch it could not
/// tessellate, triangles it left out), naming nodes and curves; its text is its `Display`,
/// its kind a stable [`code`](SurfaceProblem::code).
#[derive(Debug, Clone, PartialEq)]
pub enum SurfaceProblem {
    /// A node with no normal, nor any from its curves: its segments are left out.
    NoNormal { node: u32, curve: usize },
    /// A segment leaves a node along the node's normal: it cannot be ordered around it.
    AlongNormal { span: Span, node: u32 },
    /// A face traced from the normals does not close.
    FaceOpen { along: Span },
    /// The faces do not form a closed surface (`V − E + F` over the parts).
    NotClosed {
        vertices: usize,
        edges: i64,
        faces: usize,
        euler: i64,
        components: usize,
    },
    /// A node normal points against its neighbours'.
    NormalFlipped { node: u32, neighbours: Vec<u32> },
    /// A face runs along a segment in both directions.
    BothDirections { nodes: Vec<u32>, along: Span },
    /// A face turns clockwise around its normals.
    Clockwise { nodes: Vec<u32> },
    /// A patch that cannot be tessellated is left open.
    NotTessellated {
        nodes: Vec<u32>,
        reason: tessellate::TessellateError,
    },
    /// A patch that overlaps itself in the plane, tessellated on a disk.
    OnDisk { nodes: Vec<u32> },
    /// Triangles that came out with zero area, left out.
    ZeroArea { triangles: usize },
}

impl SurfaceProblem {
    /// A stable name of the kind of problem (for machines reading `report.json`).
    pub fn code(&self) -> &'static str {
        match self {
            SurfaceProblem::NoNormal { .. } => "node_without_normal",
            SurfaceProblem::AlongNormal { .. } => "segment_along_normal",
            SurfaceProblem::FaceOpen { .. } => "face_not_closed",
            SurfaceProblem::NotClosed { .. } => "not_a_closed_surface",
            SurfaceProblem::NormalFlipped { .. } => "normal_flipped",
            SurfaceProblem::BothDirections { .. } => "face_both_directions",
            SurfaceProblem::Clockwise { .. } => "face_clockwise",
            SurfaceProblem::NotTessellated { .. } => "patch_not_tessellated",
            SurfaceProblem::OnDisk { .. } => "patch_on_disk",
            SurfaceProblem::ZeroArea { .. } => "zero_area_triangles",
        }
    }
}

impl std::fmt::Display for SurfaceProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SurfaceProblem::NoNormal { node, curve } => write!(
                f,
                "node {node} (curve {curve}) has no normal, nor have its curves there: its segments are left out"
            ),
            SurfaceProblem::AlongNormal { span, node } => write!(
                f,
                "{span} leaves node {node} along its normal: it cannot be ordered around the node"
            ),
            SurfaceProblem::FaceOpen { along } => {
                write!(f, "the face starting along {along} does not close")
            }
            SurfaceProblem::NotClosed {
                vertices,
                edges,
                faces,
                euler,
                components,
            } => write!(
                f,
                "the faces traced from the normals do not form a closed surface: V − E + F = {vertices} − {edges} + {faces} = {euler} over {components} part(s) (expected even and at most {}); normals that disagree across a node or curves that cross without a node can cause this",
                2 * components
            ),
            SurfaceProblem::NormalFlipped { node, neighbours } => write!(
                f,
                "the normal at node {node} points against those of its neighbours (nodes {neighbours:?}): flipped?"
            ),
            SurfaceProblem::BothDirections { nodes, along } => write!(
                f,
                "the face through nodes {nodes:?} runs along {along} in both directions: the curve ends without closing a cycle (a dangling curve), is the only link between two parts, or a node normal disagrees with the curves; it is not surfaced"
            ),
            SurfaceProblem::Clockwise { nodes } => write!(
                f,
                "the face through nodes {nodes:?} turns clockwise around their normals (a node normal is flipped, or curves cross without a node); it is not surfaced"
            ),
            SurfaceProblem::NotTessellated { nodes, reason } => write!(
                f,
                "the patch through nodes {nodes:?} cannot be tessellated: {reason}; it is left open"
            ),
            SurfaceProblem::OnDisk { nodes } => write!(
                f,
                "the patch through nodes {nodes:?} overlaps itself seen along its average normal and developed; it was tessellated on a disk"
            ),
            SurfaceProblem::ZeroArea { triangles } => write!(
                f,
                "{triangles} triangle(s) came out with zero area and were left out"
            ),
        }
    }
}

/// A triangle mesh, world frame (z up): the surfacer's output.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceMesh {
    /// #V positions.
    pub positions: Vec<Vector3<f64>>,
    /// #V unit normals.
    pub normals: Vec<Vector3<f64>>,
    /// #F triangles, counter-clockwise seen from the normals' side.
    pub triangles: Vec<[u32; 3]>,
}
