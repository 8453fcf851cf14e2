//! Surfacing the curve network with normal control (Stanko et al. 2016).
//!
//! - [`cotmatrix`]: the cotangent Laplacian and mixed Voronoi areas.
//! - [`cycles`]: the faces of the network, traced from the node normals, and the checks of
//!   the cell complex they form.
//! - [`tessellate`]: each cycle triangulated in its plane (constrained Delaunay, spade).
//!
//! The biharmonic propagation and the mean-curvature guided fit follow in this order.

pub mod analytic;
pub mod cotmatrix;
pub mod cycles;
pub mod fit;
pub mod tessellate;
