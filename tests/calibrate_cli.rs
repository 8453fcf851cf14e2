//! `sfs calibrate` on a synthetic capture with a known distortion: a phone resting on its six
//! faces (and two tilted poses) and turned through many orientations in between. The printed
//! snippet is valid configuration and recovers the distortion.

use device_protocol::{DeviceKind, Hello, Packet, PhoneSample};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use sfs::sensor::G;
use sfs::simulate::rng::Rng;
use std::process::Command;

struct Truth {
    acc_bias: Vector3<f64>,
    acc_scale: Vector3<f64>,
    hard: Vector3<f64>,
    soft: Matrix3<f64>,
    gyro_bias: Vector3<f64>,
}

fn capture(truth: &Truth) -> Vec<u8> {
    let mut rng = Rng::new(77);
    let (acc_lsb, mag_lsb, gyro_lsb) = (16.0 * G / 65536.0, 0.15, 2000f64.to_radians() / 32768.0);
    let mut out = Vec::new();
    let mut seq = 0u8;
    let mut put = |p: Packet, out: &mut Vec<u8>| {
        p.encode(seq, out);
        seq = seq.wrapping_add(1);
    };
    put(
        Packet::Hello(Hello {
            proto: 1,
            kind: DeviceKind::Phone,
            device_id: 9,
            firmware: 1,
            rate_hz: 100,
            acc_scale: acc_lsb as f32,
            gyro_scale: gyro_lsb as f32,
            mag_scale: mag_lsb as f32,
            ticks_per_rev: 0,
            wheel_circumference_um: 0,
            sensors: 1,
        }),
        &mut out,
    );
    let field = Vector3::new(0.0, 20.0, -43.0);
    let soft_inv = truth.soft.try_inverse().unwrap();
    let counts = |v: Vector3<f64>, lsb: f64| [0, 1, 2].map(|i| (v[i] / lsb).round() as i16);
    // Poses: sensor→world rotations putting each face down, then two tilted ones.
    let mut poses: Vec<UnitQuaternion<f64>> = vec![
        UnitQuaternion::identity(),
        UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(-std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0),
        UnitQuaternion::from_euler_angles(0.0, -std::f64::consts::FRAC_PI_2, 0.0),
        UnitQuaternion::from_euler_angles(0.6, 0.4, 1.0),
        UnitQuaternion::from_euler_angles(-0.5, 0.9, -2.0),
    ];
    poses.push(poses[0]);
    let dt = 0.01;
    let mut t = 0.0;
    let mut q = poses[0];
    let mut emit =
        |q: UnitQuaternion<f64>, w: Vector3<f64>, t: f64, out: &mut Vec<u8>, rng: &mut Rng| {
            let acc_true = q.inverse() * Vector3::new(0.0, 0.0, G);
            let acc = acc_true.component_div(&truth.acc_scale) + truth.acc_bias + rng.vec3(0.01);
            let mag = soft_inv * (q.inverse() * field) + truth.hard + rng.vec3(0.2);
            let gyro = w + truth.gyro_bias + rng.vec3(0.002);
            put(
                Packet::PhoneSample(PhoneSample {
                    t_us: (t * 1e6) as u32,
                    acc: counts(acc, acc_lsb),
                    gyro: counts(gyro, gyro_lsb),
                    mag: counts(mag, mag_lsb),
                }),
                out,
            );
        };
    for k in 0..poses.len() - 1 {
        // Rest 3 s.
        for _ in 0..300 {
            t += dt;
            emit(q, Vector3::zeros(), t, &mut out, &mut rng);
        }
        // Tumble for 6 s through random orientations, ending at the next pose.
        let axis = rng.vec3(1.0).normalize();
        for i in 0..600 {
            t += dt;
            let u = i as f64 / 599.0;
            let tumble = UnitQuaternion::from_scaled_axis(axis * (std::f64::consts::TAU * 2.0 * u));
            let next = poses[k].slerp(&poses[k + 1], u) * tumble;
            let w = (q.inverse() * next).scaled_axis() / dt;
            q = next;
            emit(q, w, t, &mut out, &mut rng);
        }
    }
    out
}

#[test]
fn calibrate_recovers_a_known_distortion() {
    let truth = Truth {
        acc_bias: Vector3::new(0.15, -0.1, 0.25),
        acc_scale: Vector3::new(1.02, 0.98, 1.01),
        hard: Vector3::new(15.0, -8.0, 22.0),
        soft: Matrix3::new(1.08, 0.03, 0.0, 0.03, 0.95, -0.02, 0.0, -0.02, 1.0),
        gyro_bias: Vector3::new(0.01, -0.02, 0.005),
    };
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("calib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cap = dir.join("turned.bin");
    std::fs::write(&cap, capture(&truth)).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .arg("calibrate")
        .arg(&cap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let snippet = String::from_utf8(out.stdout).unwrap();
    eprintln!("{snippet}");
    // The snippet is valid configuration.
    let cfg_path = dir.join("calibrated.toml");
    std::fs::write(&cfg_path, format!("[source]\nkind = \"stdin\"\n{snippet}")).unwrap();
    let cal = sfs::config::load(&cfg_path)
        .unwrap()
        .acquisition
        .calibration;
    assert!(
        (cal.mag_hard_iron - truth.hard).norm() < 0.5,
        "hard iron {}",
        cal.mag_hard_iron
    );
    let ratio = cal.mag_soft_iron * truth.soft.try_inverse().unwrap();
    let s = ratio.trace() / 3.0;
    assert!(
        (ratio / s - Matrix3::identity()).norm() < 0.02,
        "soft iron {}",
        cal.mag_soft_iron
    );
    assert!(
        (cal.acc_bias - truth.acc_bias).norm() < 0.02,
        "acc bias {}",
        cal.acc_bias
    );
    assert!(
        (cal.acc_scale - truth.acc_scale).norm() < 0.003,
        "acc scale {}",
        cal.acc_scale
    );
    assert!(
        (cal.gyro_bias - truth.gyro_bias).norm() < 0.002,
        "gyro bias {}",
        cal.gyro_bias
    );
    assert!(snippet.contains("% of directions covered"));
}

#[test]
fn capture_without_hello_is_an_input_error_and_nothing_to_fit_is_unusable() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("calib-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.bin");
    std::fs::write(&empty, b"").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .arg("calibrate")
        .arg(&empty)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::INPUT));
    // A HELLO and a few samples lying still: nothing can be fitted.
    let mut b = Vec::new();
    Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::Morphorider,
        device_id: 1,
        firmware: 1,
        rate_hz: 100,
        acc_scale: 0.01,
        gyro_scale: 0.0,
        mag_scale: 0.1,
        ticks_per_rev: 1024,
        wheel_circumference_um: 100_000,
        sensors: 1,
    })
    .encode(0, &mut b);
    let few = dir.join("few.bin");
    std::fs::write(&few, &b).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .arg("calibrate")
        .arg(&few)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::UNUSABLE));
}
