//! The simulator: captures of known shapes, so that tests, benchmarks and the demo run without
//! a device. An [`operator`] turns curves on a surface into true device states and key presses;
//! a [`device`] model renders them as the exact bytes of the wire format.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::simulate::{self, operator::{CurveSpec, OperatorParams}, device::DeviceParams, rng::Rng};
//! // A 20 cm straight line on a table, from node 0 to node 1.
//! let points: Vec<_> = (0..=20).map(|i| Vector3::new(i as f64 * 0.01, 0.0, 0.0)).collect();
//! let curve = CurveSpec { normals: vec![Vector3::z(); points.len()], points, tags: vec![(0, 0), (20, 1)], boundary: false };
//! let mut rng = Rng::new(1);
//! let script = simulate::operator::perform(&[curve], &OperatorParams::default(), 100.0, 0.02, &mut rng);
//! let (bytes, truth) = simulate::device::render(&script, &DeviceParams::morphorider(), &mut rng);
//! assert!(!bytes.is_empty() && truth.t.len() > 300);
//! ```

pub mod device;
pub mod mesh;
pub mod operator;
pub mod rng;
pub mod scene;
pub mod shapes;
pub mod surface;
