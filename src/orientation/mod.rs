//! Orientation of every sample: the frame `[T B N]` in the world frame (x east, y magnetic
//! north, z up), as a unit quaternion `q` with `v_world = q · v_frame`.
//!
//! - [`triad`]: absolute orientation from gravity and the magnetic field (Morphorider, arrays),
//!   gravity trusted fully for tilt, the field only for heading.
//! - [`ahrs`]: gyroscope fusion for the phone, driven by measured sample intervals (causal:
//!   the live view, and the start of each curve's smoother).
//! - [`smoother`]: the phone's orientations over a finished curve, forward and backward, the
//!   gyroscope bias as a state.
//! - [`rest`]: rests from window statistics against the noise measured in the session.
//! - [`qmethod`]: the weighted mean of unit quaternions (largest eigenvector of the 4×4
//!   structure tensor), invariant to the sign of each input.
//! - [`disturbance`]: the session's robust field reference and the per-sample flags.

pub mod ahrs;
pub mod disturbance;
pub use sfs_geometry::qmethod;
pub mod rest;
pub mod smoother;
pub mod triad;

/// Per-sample flags (bit set), stored with each raw sample of a scan.
pub mod flags {
    /// The device stood still (at a node, typing its index).
    pub const STATIONARY: u8 = 1 << 0;
    /// The magnetic field's norm or dip is off the session's reference.
    pub const MAG_DISTURBED: u8 = 1 << 1;
    /// The accelerometer's norm is far from g: motion acceleration corrupts the tilt.
    pub const ACC_MOTION: u8 = 1 << 2;
    /// A sensor touched its rails.
    pub const SATURATED: u8 = 1 << 3;
    /// Packets were lost just before this sample.
    pub const AFTER_GAP: u8 = 1 << 4;
    /// The orientation could not be computed from this sample (degenerate vectors); it is
    /// the previous one, with zero weight.
    pub const INVALID: u8 = 1 << 5;

    /// The weight a sample's orientation gets in averaging (the reconstruction's pre-filter):
    /// 1 for a clean sample, less for each doubt: a magnetic disturbance (the heading is wrong)
    /// × 0.05, motion acceleration (the tilt is off) × 0.2, after a gap × 0.5; a saturated or
    /// invalid sample 0. Stationary samples are clean measurements: weight unchanged.
    pub fn weight(f: u8) -> f64 {
        if f & (SATURATED | INVALID) != 0 {
            return 0.0;
        }
        let mut w = 1.0;
        if f & MAG_DISTURBED != 0 {
            w *= 0.05;
        }
        if f & ACC_MOTION != 0 {
            w *= 0.2;
        }
        if f & AFTER_GAP != 0 {
            w *= 0.5;
        }
        w
    }
}
