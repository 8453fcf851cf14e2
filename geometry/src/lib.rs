//! sfs-geometry: the geometry of shape from sensors, without I/O. Tagged curves of frames in,
//! a curve network and its surface out; no files, sockets, threads or logging set-up here
//! (the application crate `sfs` does those).
//!
//! # Layout, in the order the data flows
//!
//! - [`curve`]: the input, tagged curves of frames (samples: time, distance, orientation,
//!   weight; node tags).
//! - [`qmethod`]: the weighted mean of orientations on SO(3) (Davenport's q-method).
//! - [`network`]: tagged curves → filtered frames (pre-filter, loop-closure test of the tags,
//!   regression on SO(3)) → positions of the network (Poisson), nodes shared
//!   ([`network::Reconstructor`]); above it, the join passes ([`network::join::run_joined`]:
//!   nodes joined after the fact, each pass a reconstruction; the reconstructor knows
//!   nothing of joins).
//! - [`surface`]: network → surface (cycles from normals, tessellation per cycle, cotangent
//!   Laplacian, biharmonic propagation, the mean-curvature-guided fit, [`surface::fit`], in
//!   its steps: assembly, energy, system, curvature guide, output; the faces kept between
//!   surfaces, [`surface::faces`]); [`surface::SurfaceMesh`] is the output mesh.
//! - Shared tools: [`sparse_llt`], the sparse Cholesky with a cached symbolic factorisation
//!   ([`sparse_llt::SpdPattern`]) reused while only values change, and its candidate
//!   fill-reducing order for networks of crossing curves, [`nested_dissection`]; [`union_find`], connected
//!   components; [`rng`], the seeded random numbers of the tests and the simulator;
//!   [`f_test`], Fisher's F test (whether a fit explains more than chance would).
//!
//! Feature `serde`: `Serialize`/`Deserialize` for the input curves and the reports.

pub mod curve;
pub mod f_test;
pub mod nested_dissection;
pub mod network;
pub mod qmethod;
pub mod rng;
pub mod selected_inverse;
pub mod sparse_llt;
pub mod surface;
pub mod union_find;

/// The diagonal of the axis-aligned bounding box of `points`, m (0 for none).
pub fn bbox_diagonal<'a>(points: impl IntoIterator<Item = &'a nalgebra::Vector3<f64>>) -> f64 {
    let mut it = points.into_iter();
    let Some(first) = it.next() else {
        return 0.0;
    };
    let (lo, hi) = it.fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    (hi - lo).norm()
}

/// Serialises a list as the texts (`Display`) of its items: warnings and problems keep their
/// words in the application's JSON.
#[cfg(feature = "serde")]
pub fn serialize_texts<S, T>(items: &[T], s: S) -> Result<S::Ok, S::Error>
where
    S: serde::Serializer,
    T: std::fmt::Display,
{
    s.collect_seq(items.iter().map(|x| x.to_string()))
}
