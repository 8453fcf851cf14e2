//! Runs the phone-mode orientation filter (`sfs::orientation::ahrs`) over raw IMU samples:
//! standard input holds records of 10 little-endian f64 (`dt` s, gyroscope xyz rad/s,
//! accelerometer xyz m/s², magnetometer xyz µT; NaN magnetometer = none), standard output gets
//! one `[w, x, y, z]` quaternion (4 f64, sensor → world: x east, y magnetic north, z up) per
//! record. Used by `benches/broad.py` to score the filter on the BROAD recordings.
//!
//! `--smooth`: the smoother of finished curves instead (`sfs::orientation::smoother`, the
//! whole recording as one curve: rests and noise floors from its window statistics, the field
//! reference from its median norm and dip, started from the causal filter's bias).
//! `SFS_SMOOTH_SHOW=1` prints on standard error what it refused, its rests, noise floors and
//! bias (`benches/broad/broad.py` passes standard error through).

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
    if std::env::args().any(|a| a == "--smooth") {
        for q in smooth(&input, &mut f) {
            for x in [q.w, q.i, q.j, q.k] {
                out.write_all(&x.to_le_bytes())?;
            }
        }
        return out.flush();
    }
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

/// The smoothed orientations of the whole recording.
fn smooth(input: &[u8], f: &mut Ahrs) -> Vec<nalgebra::UnitQuaternion<f64>> {
    use sfs::orientation::{disturbance::FieldReference, rest, smoother, triad::triad};
    let (mut t, mut gyro, mut acc, mut mag) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut now = 0.0;
    let mut field = FieldReference::new();
    for rec in input.chunks_exact(80) {
        let v: Vec<f64> = rec
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        if v[0].is_finite() && v[0] > 0.0 {
            now += v[0];
        }
        let (g, a, m) = (
            Vector3::new(v[1], v[2], v[3]),
            Vector3::new(v[4], v[5], v[6]),
            Vector3::new(v[7], v[8], v[9]),
        );
        f.update(v[0], &g, &a, m.iter().all(|x| x.is_finite()).then_some(&m));
        field.add(&a, &m);
        t.push(now);
        gyro.push(g);
        acc.push(a);
        mag.push(m);
    }
    let (mut rests, floors) = rest::rests(&t, &gyro, &acc, &mag, None);
    if std::env::var("SFS_SMOOTH_NO_REST").is_ok() {
        rests.iter_mut().for_each(|r| *r = false);
    }
    let sd = floors.per_axis();
    let m = smoother::Measurements {
        t: &t,
        gyro: &gyro,
        acc: &acc,
        mag: &mag,
        rest: &rests,
        disturbed: &[],
        field: field.reference(),
        gyro_noise: sd.gyro,
        acc_noise: sd.acc,
        mag_noise: sd.mag,
    };
    let q0 = acc
        .first()
        .zip(mag.first())
        .and_then(|(a, m)| triad(a, m))
        .unwrap_or_else(nalgebra::UnitQuaternion::identity);
    // Parameter studies: SFS_SMOOTH_<NAME>=value overrides a default (not for production use).
    let mut p = smoother::SmootherParams::default();
    let env = |k: &str| {
        std::env::var(format!("SFS_SMOOTH_{k}"))
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
    };
    if let Some(v) = env("ACC_MOTION") {
        p.acc_motion = v;
    }
    if let Some(v) = env("ACC_TOL") {
        p.acc_tol = v;
    }
    if let Some(v) = env("MAG_HEADING_DEG") {
        p.mag_heading = v.to_radians();
    }
    if let Some(v) = env("BIAS_WALK_DEG") {
        p.bias_walk = v.to_radians();
    }
    if let Some(v) = env("RESTART") {
        p.restart_angle = v;
    }
    if let Some(v) = env("LOST_AFTER") {
        p.lost_after = v;
    }
    if let Some(v) = env("HAND_MOTION") {
        p.hand_motion = v;
    }
    if let Some(v) = env("GATE") {
        p.gate = v;
    }
    let s = smoother::smooth(&m, q0, f.bias(), &p);
    if std::env::var("SFS_SMOOTH_SHOW").is_ok() {
        let rest_share = rests.iter().filter(|&&r| r).count() as f64 / rests.len().max(1) as f64;
        let deg = |b: Option<&Vector3<f64>>| b.copied().unwrap_or_default().map(f64::to_degrees);
        let (b0, b1) = (deg(s.bias.first()), deg(s.bias.last()));
        eprintln!(
            "n {} refused heading {} gravity {} rest {:.0} % floors gyro {:.4} acc {:.4} mag {:.3} bias start {:.2?} end {:.2?} °/s",
            t.len(), s.refused_heading, s.refused_gravity, 100.0 * rest_share, sd.gyro, sd.acc, sd.mag,
            b0.as_slice(), b1.as_slice()
        );
    }
    s.q
}
