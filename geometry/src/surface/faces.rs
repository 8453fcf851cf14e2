//! The faces of a surface kept across updates (issue 19): each cycle's tessellation and
//! weights, so that the next surface of a grown or moved network rebuilds only the faces
//! that changed.
//!
//! A face is known again by its cycle: the same segments (curve, end nodes, direction,
//! sample count), the same sides of its creases and the same corner sectors, at the same
//! target edge. What it keeps:
//! - its planar tessellation ([`PatchMesh`]) and the planar cotangent weights and areas of it
//!   (the first pass's weights);
//! - the weights of its part of the last surface computed (`#V_face` cotangent rows and
//!   areas from the 3D positions), which a provisional update starts from.
//!
//! Whether a known face is reused is the [`SurfaceParams::reuse_tolerance`] policy: `0`
//! (exact) reuses it only when its boundary (positions and normals, the tessellation's
//! whole input) is bit for bit the one it was built from, so the surface is the one a run
//! from scratch gives; `τ > 0` reuses it while no boundary sample moved more than `τ` target
//! edges since it was built (its planar layout then lags the boundary; the solve still takes
//! the boundary where it is now).
//!
//! ```
//! use sfs_geometry::surface::analytic::sphere_cube;
//! use sfs_geometry::surface::fit::{SurfaceParams, Surfacer};
//! let net = sphere_cube(0.1);
//! let mut s = Surfacer::new();
//! let first = s.run(&net, &SurfaceParams::default()).unwrap();
//! let again = s.run(&net, &SurfaceParams::default()).unwrap();
//! // The same network again: every face kept, the same surface bit for bit.
//! assert_eq!(again.faces_kept, 6);
//! assert_eq!(first.positions, again.positions);
//! ```
//!
//! [`SurfaceParams::reuse_tolerance`]: super::fit::SurfaceParams::reuse_tolerance

use super::cotmatrix::SparseRows;
use super::tessellate::PatchMesh;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::sync::Arc;

/// One half-edge of a face's cycle as the cache knows it: curve, start and end node of the
/// segment, direction, sample count, the crease side taken, the corner sector at its start.
pub(crate) type EdgeKey = (usize, u32, u32, bool, usize, bool, usize);

/// What identifies a face: its half-edges in order.
pub(crate) type FaceKey = Vec<EdgeKey>;

/// Cotangent weights (`#V_face by #V_face`, local ids, libigl's sign) and mixed Voronoi
/// areas (`#V_face`) of one face.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Weights {
    pub l: SparseRows,
    pub areas: Vec<f64>,
}

/// A face as kept.
#[derive(Debug, Clone)]
pub(crate) struct Face {
    /// The boundary it was tessellated from (points and normals in the patch's order).
    pub poly: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    pub mesh: Arc<PatchMesh>,
    pub planar: Arc<Weights>,
    /// The weights of its part of the last surface (absent until one was computed).
    pub surface: Option<Arc<Weights>>,
}

impl Face {
    /// Whether this face can stand for one with boundary `poly`, `normals` under the
    /// tolerance `tol` (m; 0: bit for bit).
    pub fn fits(&self, poly: &[Vector3<f64>], normals: &[Vector3<f64>], tol: f64) -> bool {
        if poly.len() != self.poly.len() {
            return false;
        }
        if tol <= 0.0 {
            return poly == self.poly.as_slice() && normals == self.normals.as_slice();
        }
        poly.iter()
            .zip(&self.poly)
            .all(|(a, b)| (a - b).norm_squared() <= tol * tol)
    }
}

/// The faces of the last surface, by cycle, and the target edge they were built at.
#[derive(Debug, Default)]
pub(crate) struct Faces {
    pub by_key: HashMap<FaceKey, Face>,
    /// The target edge of the kept faces, m.
    pub edge: Option<f64>,
    /// The edge the vertex budget estimated for their network, m: `edge` itself, unless the
    /// surface came out over the budget and was tessellated again at a longer edge.
    pub estimate: Option<f64>,
    /// The samples each segment kept for the patch rims (its decimation), by curve, end
    /// nodes and sample count.
    pub samples: HashMap<(usize, u32, u32, usize), Vec<usize>>,
}

impl Faces {
    /// The kept face for `key` if it fits the boundary (see [`Face::fits`]) at `edge`.
    pub fn take(
        &mut self,
        key: &FaceKey,
        poly: &[Vector3<f64>],
        normals: &[Vector3<f64>],
        edge: f64,
        tol: f64,
    ) -> Option<Face> {
        if self.edge != Some(edge) {
            return None;
        }
        match self.by_key.get(key) {
            Some(f) if f.fits(poly, normals, tol) => self.by_key.remove(key),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::surface::analytic::{box_network, sphere_grid};
    use crate::surface::cycles::NetworkSegments;
    use crate::surface::fit::{surface, SurfaceParams, Surfaced, Surfacer};

    /// The network without curve `k` (its crossings stay nodes of the others).
    fn without(net: &NetworkSegments, k: usize) -> NetworkSegments {
        let mut out = net.clone();
        out.segments.retain(|s| s.curve != k);
        out
    }

    fn diagonal(s: &Surfaced) -> f64 {
        crate::bbox_diagonal(&s.positions)
    }

    /// The largest distance between the two surfaces' vertices, relative to the diagonal (the
    /// same meshes, vertex for vertex).
    fn deviation(a: &Surfaced, b: &Surfaced) -> f64 {
        assert_eq!(a.positions.len(), b.positions.len());
        assert_eq!(a.triangles, b.triangles);
        let d = a
            .positions
            .iter()
            .zip(&b.positions)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max);
        d / diagonal(a)
    }

    /// Issue 19, point 1: after one more curve the exact policy keeps every face the curve
    /// did not touch and gives the surface a run from scratch gives, on smooth networks,
    /// crease networks (box) and networks with a guide curve, hard and soft constraints.
    #[test]
    fn issue_19_kept_faces_give_the_surface_from_scratch() {
        let mut guided = sphere_grid(4, 3, 0.02);
        for s in guided.segments.iter_mut().filter(|s| s.curve == 5) {
            s.kind = crate::curve::CurveKind::Guide;
        }
        let cases: Vec<(&str, NetworkSegments, usize, f64)> = vec![
            ("sphere grid", sphere_grid(4, 3, 0.02), 1, 0.04),
            ("sphere grid with a guide", guided, 1, 0.04),
            ("box", box_network([0.4, 0.3, 0.2], 0.01), 0, 0.02),
        ];
        for (name, net, drop, edge) in cases {
            for soft in [None, Some(0.3)] {
                let p = SurfaceParams {
                    edge: Some(edge),
                    soft,
                    ..SurfaceParams::default()
                };
                let mut s = Surfacer::new();
                let before = s.run(&without(&net, drop), &p).expect("a surface");
                assert_eq!(before.faces_kept, 0);
                let after = s.run(&net, &p).expect("a surface");
                let scratch = surface(&net, &p).expect("a surface");
                let faces = scratch.cycles.patches.len();
                assert!(
                    after.faces_kept > 0 && after.faces_kept < faces,
                    "{name} {soft:?}: {} of {faces} faces kept",
                    after.faces_kept
                );
                assert!(!after.provisional);
                let dev = deviation(&after, &scratch);
                assert!(dev <= 1e-9, "{name} {soft:?}: {dev:e} of the diagonal");
            }
        }
    }

    /// Issue 51: a network over the vertex budget with its rims alone (a grid of hundreds of
    /// curves: 35 000 vertices against 20 000) is tessellated at the estimate's edge, then
    /// again at a longer one. The next curve's update keeps that edge and the faces the curve
    /// did not touch, where it tessellated every face twice, at the estimate and corrected.
    #[test]
    fn issue_51_over_the_budget_the_next_curve_keeps_the_faces() {
        let net = sphere_grid(6, 5, 0.01);
        let p = SurfaceParams {
            max_vertices: 60,
            reuse_tolerance: 0.5,
            ..SurfaceParams::default()
        };
        let mut s = Surfacer::new();
        let before = s.run(&without(&net, 1), &p).expect("a surface");
        assert!(
            before.positions.len() as f64 > 1.25 * 60.0,
            "over the budget"
        );
        let after = s.run(&net, &p).expect("a surface");
        let faces = after.cycles.patches.len();
        assert!(
            after.faces_kept > faces / 2,
            "{} of {faces} faces kept",
            after.faces_kept
        );
    }

    /// Issue 19, points 1 and 5: with a tolerance the kept faces keep their weights; the same
    /// network again is the same system (its factorisation kept: the surface comes out bit
    /// for bit the same), a moved one keeps every face and follows its curves.
    #[test]
    fn issue_19_a_tolerance_keeps_faces_and_their_factorisation() {
        let net = sphere_grid(4, 3, 0.02);
        for soft in [None, Some(0.3)] {
            let p = SurfaceParams {
                edge: Some(0.04),
                soft,
                reuse_tolerance: f64::INFINITY,
                ..SurfaceParams::default()
            };
            let mut s = Surfacer::new();
            s.run(&without(&net, 1), &p).expect("a surface");
            let first = s.run(&net, &p).expect("a surface");
            assert!(first.provisional && first.faces_kept > 0);
            let scratch = surface(&net, &p).expect("a surface");
            let dev = deviation(&first, &scratch);
            assert!(
                dev <= 2e-3,
                "{soft:?}: provisional {dev:e} of the diagonal off"
            );
            let again = s.run(&net, &p).expect("a surface");
            let numeric = s.numeric_factorisations();
            let third = s.run(&net, &p).expect("a surface");
            assert_eq!(s.numeric_factorisations(), numeric, "refactorised");
            assert_eq!(again.positions, third.positions);
            // The structure bends (a monitored one): every face kept, the curves followed.
            let mut bent = net.clone();
            for seg in &mut bent.segments {
                for p in &mut seg.points {
                    p.x += 0.01 * p.z * p.z;
                }
            }
            let moved = s.run(&bent, &p).expect("a surface");
            assert_eq!(moved.faces_kept, moved.cycles.patches.len());
            assert_eq!(s.numeric_factorisations(), numeric, "refactorised");
            let shifted = moved
                .positions
                .iter()
                .zip(&third.positions)
                .map(|(a, b)| a.x - b.x)
                .fold(0.0, f64::max);
            assert!(
                shifted > 0.005,
                "{soft:?}: the surface did not follow ({shifted})"
            );
        }
    }
}
