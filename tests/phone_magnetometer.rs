//! Issue 32, point 2: what the phone page's virtual magnetometer costs. Browsers give no
//! magnetometer; the page sends the field a magnetometer would read, made from the browser's
//! orientation against north (device-protocol/README.md, "The phone page"). A simulated phone
//! scan is sent again as the page would send it, without segment lengths (the page measures
//! none), at the simulator's 200 Hz and at the browser's 60 Hz:
//! - with the simulated magnetometer (noise, the Earth's field);
//! - with the virtual one made from the true orientation (a perfect compass);
//! - with the virtual one made from an orientation whose heading wanders by ±3° over 20 s (a
//!   phone's compass fusion on a good day).
//!
//! The virtual field from a perfect compass must cost nothing; the figures of the others, and
//! of the capture as simulated (with the segment lengths its phone app sends), are printed
//! (BENCHMARKS.md, "The phone page").

mod common;
use common::phone::{play_of, Play};
use common::*;
use device_protocol::*;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

/// Where the magnetometer reading comes from.
#[derive(Clone, Copy, PartialEq)]
enum Mag {
    Simulated,
    /// From the orientation, its heading off by `amplitude_deg · sin(2πt / 20 s)`.
    Virtual {
        amplitude_deg: f64,
    },
}

/// `play` as a phone page would send it: HELLO, samples at `rate` Hz (the latest reading at
/// each tick), keys; no segment lengths.
fn encode(play: &Play, rate: f64, mag: Mag) -> Vec<u8> {
    let off = play.clock_offset_us;
    let t_us = |t: f64| ((t * 1e6).round() as i64 + off) as u32;
    let (acc_lsb, gyro_lsb, mag_lsb) = (
        16.0 * 9.80665 / 65536.0,
        2000f64.to_radians() / 32768.0,
        0.15,
    );
    let i = 64f64.to_radians();
    let field = Vector3::new(0.0, 48.0 * i.cos(), -48.0 * i.sin());
    let mut out = Vec::new();
    let mut seq = 0u8;
    let mut emit = |p: Packet, out: &mut Vec<u8>| {
        p.encode(seq, out);
        seq = seq.wrapping_add(1);
    };
    emit(
        Packet::Hello(Hello {
            proto: 1,
            kind: DeviceKind::Phone,
            device_id: 1,
            firmware: 0x0100,
            rate_hz: rate as u16,
            acc_scale: acc_lsb as f32,
            gyro_scale: gyro_lsb as f32,
            mag_scale: mag_lsb as f32,
            ticks_per_rev: 0,
            wheel_circumference_um: 0,
            sensors: 1,
        }),
        &mut out,
    );
    let (mut k, mut next) = (0, play.readings[0].t);
    for r in &play.readings {
        while k < play.keys.len() && play.keys[k].0 <= r.t {
            let key = Key {
                t_us: t_us(play.keys[k].0),
                key: play.keys[k].1,
            };
            emit(Packet::Key(key), &mut out);
            k += 1;
        }
        if r.t + 1e-9 < next {
            continue;
        }
        next += 1.0 / rate;
        let counts = |v: [f64; 3], lsb: f64| [0, 1, 2].map(|j| (v[j] / lsb).round() as i16);
        let m = match mag {
            Mag::Simulated => counts(r.mag, mag_lsb),
            Mag::Virtual { amplitude_deg } => {
                let q = UnitQuaternion::from_quaternion(Quaternion::new(
                    r.q[3], r.q[0], r.q[1], r.q[2],
                ));
                let wander =
                    amplitude_deg.to_radians() * (std::f64::consts::TAU * r.t / 20.0).sin();
                let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), wander);
                let m = (heading * q).inverse() * field;
                counts([m.x, m.y, m.z], mag_lsb)
            }
        };
        let sample = PhoneSample {
            t_us: t_us(r.t),
            acc: counts(r.acc, acc_lsb),
            gyro: counts(r.gyro, gyro_lsb),
            mag: m,
        };
        emit(Packet::PhoneSample(sample), &mut out);
    }
    out
}

fn curve_error(truth: &Path, glb: &Path) -> f64 {
    eval(truth, glb)["curves"]["mean_pct"].as_f64().unwrap()
}

#[test]
fn issue_32_the_virtual_magnetometer_of_a_perfect_compass_costs_nothing() {
    for scene in ["torus-loops", "bumpy", "bowl", "roof"] {
        let dir = tmpdir(&format!("phone-mag-{scene}"));
        let s = sfs::simulate::scene::builtin(scene).unwrap();
        let sim = sfs::simulate::run(&s, DeviceKind::Phone, sfs::simulate::Profile::Default, 1);
        let truth = dir.join("truth.json");
        std::fs::write(&truth, serde_json::to_vec(&sim.truth).unwrap()).unwrap();
        let serial = dir.join("serial.bin");
        std::fs::write(&serial, &sim.bytes).unwrap();
        replay_to(&serial, &dir.join("serial"));
        let with_lengths = curve_error(&truth, &dir.join("serial/network.glb"));
        eprintln!("{scene}: {with_lengths:.3} % as simulated (200 Hz, segment lengths sent)");
        let play = play_of(&sim);
        let mut errors = Vec::new();
        for rate in [200.0, 60.0] {
            for (name, mag) in [
                ("simulated", Mag::Simulated),
                ("virtual", Mag::Virtual { amplitude_deg: 0.0 }),
                ("virtual-3deg", Mag::Virtual { amplitude_deg: 3.0 }),
            ] {
                let run = format!("{rate}-{name}");
                let bin = dir.join(format!("{run}.bin"));
                std::fs::write(&bin, encode(&play, rate, mag)).unwrap();
                replay_to(&bin, &dir.join(&run));
                let e = curve_error(&truth, &dir.join(&run).join("network.glb"));
                eprintln!("{scene} {rate} Hz, {name} magnetometer: {e:.3} %");
                errors.push(e);
            }
            let [simulated, perfect] = [errors[errors.len() - 3], errors[errors.len() - 2]];
            assert!(
                (perfect - simulated).abs() <= 0.1 * simulated,
                "{scene} at {rate} Hz: {perfect:.3} % with the virtual magnetometer, {simulated:.3} % with the simulated one"
            );
        }
    }
}
