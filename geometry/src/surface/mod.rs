//! Surfacing the curve network with normal control (Stanko et al. 2016), in the order the data
//! flows:
//!
//! - [`cycles`]: the faces of the network, traced from the node normals, and the checks of
//!   the cell complex they form.
//! - [`tessellate`]: each cycle triangulated in its plane (constrained Delaunay, spade), with
//!   the boundary developed when the projection folds or shrinks it.
//! - [`cotmatrix`]: the cotangent Laplacian and mixed Voronoi areas.
//! - [`fit`]: biharmonic propagation of positions and normals, the mean-curvature guide and
//!   the fit (hard or soft constraints), one factorisation shared, reweighting from 3D.
//! - [`analytic`]: the paper's test networks with exact normals (tests, benches, Table 1).

pub mod analytic;
pub mod cotmatrix;
pub mod cycles;
pub mod fit;
pub mod tessellate;

use nalgebra::Vector3;

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
