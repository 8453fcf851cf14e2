//! Runs the phone-mode orientation filter (`sfs::orientation::ahrs`) over raw IMU samples:
//! standard input holds records of 10 little-endian f64 (`dt` s, gyroscope xyz rad/s,
//! accelerometer xyz m/s², magnetometer xyz µT; NaN magnetometer = none), standard output gets
//! one `[w, x, y, z]` quaternion (4 f64, sensor → world: x east, y magnetic north, z up) per
//! record. Used by `benches/broad.py` to score the filter on the BROAD recordings.

use nalgebra::Vector3;
use sfs::orientation::ahrs::{Ahrs, AhrsParams};
use std::io::{Read, Write};

fn main() -> std::io::Result<()> {
    let mut input = Vec::new();
    std::io::stdin().read_to_end(&mut input)?;
    // Parameter studies: SFS_AHRS_<NAME>=value overrides a default (not for production use).
    let mut p = AhrsParams::default();
    let env = |k: &str| {
        std::env::var(format!("SFS_AHRS_{k}"))
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
    };
    if let Some(v) = env("TAU_ACC") {
        p.tau_acc = v;
    }
    if let Some(v) = env("TAU_MAG") {
        p.tau_mag = v;
    }
    if let Some(v) = env("TAU_BIAS") {
        p.tau_bias = v;
    }
    if let Some(v) = env("TAU_HEADING_BIAS") {
        p.tau_heading_bias = v;
    }
    if let Some(v) = env("TAU_TILT_BIAS") {
        p.tau_tilt_bias = v;
    }
    if let Some(v) = env("REST_MIN") {
        p.rest_min = v;
    }
    let mut f = Ahrs::new(p);
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for rec in input.chunks_exact(80) {
        let v: Vec<f64> = rec
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        let gyro = Vector3::new(v[1], v[2], v[3]);
        let acc = Vector3::new(v[4], v[5], v[6]);
        let mag = Vector3::new(v[7], v[8], v[9]);
        let q = f.update(
            v[0],
            &gyro,
            &acc,
            mag.iter().all(|x| x.is_finite()).then_some(&mag),
        );
        for x in [q.w, q.i, q.j, q.k] {
            out.write_all(&x.to_le_bytes())?;
        }
    }
    out.flush()
}
