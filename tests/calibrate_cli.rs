//! `sfs calibrate` on a synthetic capture with a known distortion: a phone resting on its six
//! faces (and two tilted poses) and turned through many orientations in between. The printed
//! snippet is valid configuration and recovers the distortion.

use device_protocol::{DeviceKind, Hello, Packet, PhoneSample, RiderSample};
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

/// How the capture is made.
struct Scenario {
    kind: DeviceKind,
    /// Sensor→world rotations of the rests, in order.
    poses: Vec<UnitQuaternion<f64>>,
    /// Accelerometer noise, m/s² (per axis, standard deviation).
    acc_noise: f64,
    /// Rest length, seconds.
    rest_s: f64,
    /// Between rests: a turn about the vertical at this rate (°/s) for this long, flat on the
    /// table, before the tumble to the next rest.
    slow_yaw: Option<(f64, f64)>,
    /// Between rests: tumble (random turns) or turn straight to the next pose.
    tumble: bool,
    seed: u64,
}

impl Default for Scenario {
    /// A phone resting on its six faces and two tilted poses, tumbled in between.
    fn default() -> Self {
        use std::f64::consts::{FRAC_PI_2, PI};
        let e = UnitQuaternion::from_euler_angles;
        Scenario {
            kind: DeviceKind::Phone,
            poses: vec![
                e(0.0, 0.0, 0.0),
                e(PI, 0.0, 0.0),
                e(FRAC_PI_2, 0.0, 0.0),
                e(-FRAC_PI_2, 0.0, 0.0),
                e(0.0, FRAC_PI_2, 0.0),
                e(0.0, -FRAC_PI_2, 0.0),
                e(0.6, 0.4, 1.0),
                e(-0.5, 0.9, -2.0),
                e(0.0, 0.0, 0.0),
            ],
            acc_noise: 0.01,
            rest_s: 3.0,
            slow_yaw: None,
            tumble: true,
            seed: 77,
        }
    }
}

/// 30 rests: the six faces, then 24 orientations spread over the sphere, each at its own
/// heading.
fn thirty_rests(seed: u64) -> Vec<UnitQuaternion<f64>> {
    let mut rng = Rng::new(seed);
    let mut poses = Scenario::default().poses[..6].to_vec();
    while poses.len() < 30 {
        let axis = rng.vec3(1.0).normalize();
        let angle = std::f64::consts::PI * (0.2 + 0.8 * (poses.len() as f64 / 30.0));
        poses.push(UnitQuaternion::from_scaled_axis(axis * angle));
    }
    poses
}

fn capture(truth: &Truth, sc: &Scenario) -> Vec<u8> {
    let mut rng = Rng::new(sc.seed);
    let (acc_lsb, mag_lsb, gyro_lsb) = (16.0 * G / 65536.0, 0.15, 2000f64.to_radians() / 32768.0);
    let mut out = Vec::new();
    let mut seq = 0u8;
    let mut put = |p: Packet, out: &mut Vec<u8>| {
        p.encode(seq, out);
        seq = seq.wrapping_add(1);
    };
    let phone = sc.kind == DeviceKind::Phone;
    put(
        Packet::Hello(Hello {
            proto: 1,
            kind: sc.kind,
            device_id: 9,
            firmware: 1,
            rate_hz: 100,
            acc_scale: acc_lsb as f32,
            gyro_scale: if phone { gyro_lsb as f32 } else { 0.0 },
            mag_scale: mag_lsb as f32,
            ticks_per_rev: if phone { 0 } else { 1024 },
            wheel_circumference_um: if phone { 0 } else { 100_000 },
            sensors: 1,
        }),
        &mut out,
    );
    let field = Vector3::new(0.0, 20.0, -43.0);
    let soft_inv = truth.soft.try_inverse().unwrap();
    let counts = |v: Vector3<f64>, lsb: f64| [0, 1, 2].map(|i| (v[i] / lsb).round() as i16);
    let dt = 0.01;
    let mut t = 0.0;
    let mut q = sc.poses[0];
    let mut emit =
        |q: UnitQuaternion<f64>, w: Vector3<f64>, t: f64, out: &mut Vec<u8>, rng: &mut Rng| {
            let acc_true = q.inverse() * Vector3::new(0.0, 0.0, G);
            let acc =
                acc_true.component_div(&truth.acc_scale) + truth.acc_bias + rng.vec3(sc.acc_noise);
            let mag = soft_inv * (q.inverse() * field) + truth.hard + rng.vec3(0.2);
            let gyro = w + truth.gyro_bias + rng.vec3(0.002);
            let (t_us, acc, mag) = ((t * 1e6) as u32, counts(acc, acc_lsb), counts(mag, mag_lsb));
            let p = if phone {
                Packet::PhoneSample(PhoneSample {
                    t_us,
                    acc,
                    gyro: counts(gyro, gyro_lsb),
                    mag,
                })
            } else {
                Packet::RiderSample(RiderSample {
                    t_us,
                    acc,
                    mag,
                    wheel: 0,
                })
            };
            put(p, out);
        };
    let steps = |s: f64| (s / dt).round() as usize;
    for k in 0..sc.poses.len() {
        for _ in 0..steps(sc.rest_s) {
            t += dt;
            emit(q, Vector3::zeros(), t, &mut out, &mut rng);
        }
        if k + 1 == sc.poses.len() {
            break;
        }
        // A slow turn about the vertical: gravity and the rate constant, the heading not.
        if let Some((rate, secs)) = sc.slow_yaw {
            let w_world = Vector3::z() * rate.to_radians();
            for _ in 0..steps(secs) {
                t += dt;
                let next = UnitQuaternion::from_scaled_axis(w_world * dt) * q;
                emit(next, next.inverse() * w_world, t, &mut out, &mut rng);
                q = next;
            }
        }
        // To the next rest in 6 s, tumbling or straight.
        let from = q;
        let axis = rng.vec3(1.0).normalize();
        let n = steps(6.0);
        for i in 0..n {
            t += dt;
            let u = (i + 1) as f64 / n as f64;
            let turns = if sc.tumble { 2.0 } else { 0.0 };
            let tumble =
                UnitQuaternion::from_scaled_axis(axis * (std::f64::consts::TAU * turns * u));
            let next = from.slerp(&sc.poses[k + 1], u) * tumble;
            let w = (q.inverse() * next).scaled_axis() / dt;
            q = next;
            emit(q, w, t, &mut out, &mut rng);
        }
    }
    out
}

/// `sfs calibrate` on `bytes`: exit code, the printed snippet.
fn calibrate(name: &str, bytes: &[u8]) -> (i32, String) {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("calib-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cap = dir.join("capture.bin");
    std::fs::write(&cap, bytes).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .arg("calibrate")
        .arg(&cap)
        .output()
        .unwrap();
    let snippet = String::from_utf8(out.stdout).unwrap();
    eprintln!("{name}:\n{snippet}{}", String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), snippet)
}

/// The calibration a snippet configures (as `sfs config check` would read it).
fn configured(name: &str, snippet: &str) -> sfs::sensor::CalibrationSpec {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("calib-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg_path = dir.join("calibrated.toml");
    std::fs::write(&cfg_path, format!("[source]\nkind = \"stdin\"\n{snippet}")).unwrap();
    sfs::config::load(&cfg_path)
        .unwrap()
        .acquisition
        .calibration
}

/// The number after `key` in the rests line (`# rests: N found, M used …`).
fn rests_line(snippet: &str, key: &str) -> usize {
    let line = snippet.lines().find(|l| l.starts_with("# rests:")).unwrap();
    line.split([',', ':', '(', ';'])
        .find_map(|part| part.trim().strip_suffix(key)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("no '{key}' in {line}"))
}

fn truth() -> Truth {
    Truth {
        acc_bias: Vector3::new(0.15, -0.1, 0.25),
        acc_scale: Vector3::new(1.02, 0.98, 1.01),
        hard: Vector3::new(15.0, -8.0, 22.0),
        soft: Matrix3::new(1.08, 0.03, 0.0, 0.03, 0.95, -0.02, 0.0, -0.02, 1.0),
        gyro_bias: Vector3::new(0.004, -0.005, 0.003),
    }
}

/// Issue 21, point 1: a phone turned slowly about the vertical between its rests (5 s at
/// 40°/s on the table): the turns keep the accelerometer and a constant-rate gyroscope steady,
/// not the magnetometer; they are not rests, and the gyroscope bias is the rests' alone.
#[test]
fn issue_21_slow_turns_on_a_table_are_not_rests() {
    let truth = truth();
    let sc = Scenario {
        poses: thirty_rests(5),
        slow_yaw: Some((40.0, 5.0)),
        ..Default::default()
    };
    let (code, snippet) = calibrate("slow-yaw", &capture(&truth, &sc));
    assert_eq!(code, 0);
    assert_eq!(rests_line(&snippet, "used"), 30, "{snippet}");
    let cal = configured("slow-yaw", &snippet);
    let err = (cal.gyro_bias - truth.gyro_bias).norm().to_degrees();
    assert!(err < 0.05, "gyroscope bias {err:.3} °/s off");
    assert!(
        (cal.acc_bias - truth.acc_bias).norm() < 0.02,
        "{}",
        cal.acc_bias
    );
}

/// Issue 21, point 2: a noisy phone (0.08 m/s² accelerometer noise): the stillness threshold
/// follows the noise measured in the capture, the rests are found and the accelerometer and
/// gyroscope fitted.
#[test]
fn issue_21_the_stillness_threshold_follows_the_noise() {
    let truth = truth();
    let sc = Scenario {
        poses: thirty_rests(6),
        acc_noise: 0.08,
        ..Default::default()
    };
    let (code, snippet) = calibrate("noisy", &capture(&truth, &sc));
    assert_eq!(code, 0);
    assert_eq!(rests_line(&snippet, "found"), 30, "{snippet}");
    assert_eq!(rests_line(&snippet, "used"), 30, "{snippet}");
    let cal = configured("noisy", &snippet);
    assert!(
        (cal.acc_bias - truth.acc_bias).norm() < 0.03,
        "acc bias {}",
        cal.acc_bias
    );
    assert!(
        (cal.acc_scale - truth.acc_scale).norm() < 0.005,
        "acc scale {}",
        cal.acc_scale
    );
    let err = (cal.gyro_bias - truth.gyro_bias).norm().to_degrees();
    assert!(err < 0.05, "gyroscope bias {err:.3} °/s off");
}

/// Issue 21, point 3: turned about one axis only (flat on a table): the magnetometer fit is
/// printed commented out with the reason, so the pasted snippet leaves it alone; the phone's
/// gyroscope bias is still usable (exit 0), a Morphorider's capture has nothing usable (exit 5).
#[test]
fn issue_21_a_poor_fit_is_not_printed_as_usable() {
    let truth = truth();
    let flat: Vec<UnitQuaternion<f64>> = (0..12)
        .map(|k| UnitQuaternion::from_euler_angles(0.0, 0.0, k as f64 * 0.5))
        .collect();
    let sc = Scenario {
        poses: flat,
        tumble: false,
        ..Default::default()
    };
    let (code, snippet) = calibrate("one-axis", &capture(&truth, &sc));
    assert_eq!(code, 0, "the gyroscope bias is usable");
    assert!(snippet.contains("# NOT USABLE"), "{snippet}");
    assert!(snippet.contains("# mag_hard_iron = "), "{snippet}");
    assert!(!snippet.contains("\nmag_hard_iron"), "{snippet}");
    let cal = configured("one-axis", &snippet);
    assert_eq!(cal.mag_hard_iron, Vector3::zeros());
    assert_eq!(cal.mag_soft_iron, Matrix3::identity());
    assert!((cal.gyro_bias - truth.gyro_bias).norm().to_degrees() < 0.05);
    let rider = Scenario {
        kind: DeviceKind::Morphorider,
        ..sc
    };
    let (code, snippet) = calibrate("one-axis-rider", &capture(&truth, &rider));
    assert_eq!(code, sfs::exit::UNUSABLE, "{snippet}");
    assert!(snippet.contains("nothing usable"), "{snippet}");
}

/// Issue 21, point 3: never tilted past 60° from lying flat: a warning that the
/// accelerometer's z bias and scale are poorly determined.
#[test]
fn issue_21_a_capture_without_large_tilts_is_warned_about() {
    let truth = truth();
    let mut rng = Rng::new(9);
    let poses: Vec<UnitQuaternion<f64>> = (0..20)
        .map(|k| {
            let tilt = 60f64.to_radians() * (k % 5) as f64 / 4.0;
            let axis = Vector3::new(rng.vec3(1.0).x, rng.vec3(1.0).y, 0.0).normalize();
            UnitQuaternion::from_scaled_axis(axis * tilt)
                * UnitQuaternion::from_euler_angles(0.0, 0.0, k as f64)
        })
        .collect();
    let sc = Scenario {
        poses,
        ..Default::default()
    };
    let (code, snippet) = calibrate("no-tilt", &capture(&truth, &sc));
    assert_eq!(code, 0);
    assert!(snippet.contains("never tilted past 70°"), "{snippet}");
    let full = calibrate("full-tilt", &capture(&truth, &Scenario::default())).1;
    assert!(!full.contains("never tilted"), "{full}");
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
    std::fs::write(&cap, capture(&truth, &Scenario::default())).unwrap();
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
