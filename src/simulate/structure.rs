//! Deforming instrumented structures for the monitoring mode: a sensor array (device kind 3)
//! fixed on a flexible riser (a long vertical tube bending to and fro) or on a square panel
//! (bulging in and out), streaming continuously, with the truth at regular epochs.
//!
//! - Riser: length `L`, sensors every 0.5 m along one generatrix (a curve from node 0 at the
//!   foot to node 1 at the top); the centreline stays inextensible: its tangent turns by
//!   `θ(s, t) = θ_tip(t) (2u − u²)` with `u = s/L`, in the x–z plane, so the tip moves
//!   sideways by about `2/3 θ_tip L`; `θ_tip` swings sinusoidally.
//! - Panel: `z = a(t) sin(πx) sin(πy)` on `[0, 1]²` m; three curves along x and three along y
//!   at 0.25, 0.5 and 0.75 m, crossing at 9 nodes and ending at 12 nodes on the edges;
//!   sensors every 0.1 m of their rest length (the material stretches slightly as it bulges).

use super::device::Earth;
use super::rng::Rng;
use crate::sensor::G;
use device_protocol::{ArraySample, DeviceKind, Hello, Packet, Status};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Which structure (`--structure riser|panel`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StructureKind {
    Riser,
    Panel,
}

impl StructureKind {
    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            StructureKind::Riser => "riser",
            StructureKind::Panel => "panel",
        }
    }
}

pub use crate::monitor::layout::{LayoutCurve, LayoutSensor};

/// The truth at one instant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Epoch {
    /// Session time, s.
    pub t: f64,
    /// Per sensor (by index): position, m.
    pub positions: Vec<[f64; 3]>,
    /// Per sensor: orientation of its frame [T B N] → world, `[w, x, y, z]`.
    pub q: Vec<[f64; 4]>,
    /// Riser: the top's lateral displacement from the rest (vertical) position, m.
    pub tip_displacement: Option<f64>,
}

/// `PREFIX.truth.json` of a structure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StructureTruth {
    pub structure: String,
    pub seed: u64,
    pub sensors: Vec<LayoutSensor>,
    pub curves: Vec<LayoutCurve>,
    /// Rest length of the riser (for the "% of its length" figures), or the panel's size.
    pub size: f64,
    pub epochs: Vec<Epoch>,
}

struct Model {
    kind: StructureKind,
    sensors: Vec<LayoutSensor>,
    curves: Vec<LayoutCurve>,
    size: f64,
}

const RISER_LENGTH: f64 = 20.0;
const RISER_TIP_ANGLE: f64 = 0.15; // rad: tip swings about ±2 m
const RISER_PERIOD: f64 = 60.0;
const PANEL_BULGE: f64 = 0.05; // m
const PANEL_PERIOD: f64 = 30.0;

fn model(kind: StructureKind) -> Model {
    match kind {
        StructureKind::Riser => {
            let n = (RISER_LENGTH / 0.5) as usize;
            Model {
                kind,
                sensors: (0..=n)
                    .map(|k| LayoutSensor {
                        sensor: k as u16,
                        curve: 0,
                        s: k as f64 * 0.5,
                    })
                    .collect(),
                curves: vec![LayoutCurve {
                    index: 0,
                    nodes: vec![0, 1],
                    node_s: vec![0.0, RISER_LENGTH],
                    length: RISER_LENGTH,
                }],
                size: RISER_LENGTH,
            }
        }
        StructureKind::Panel => {
            let lines = [0.25, 0.5, 0.75];
            let mut curves = Vec::new();
            let mut sensors = Vec::new();
            // Nodes: crossings 0..9 (row-major), then edge ends.
            let crossing = |i: usize, j: usize| (i * 3 + j) as u32;
            let mut next_end = 9u32;
            for dir in 0..2 {
                for (li, _) in lines.iter().enumerate() {
                    let index = curves.len();
                    let start = next_end;
                    let end = next_end + 1;
                    next_end += 2;
                    let mut nodes = vec![start];
                    let mut node_s = vec![0.0];
                    for (k, &c) in lines.iter().enumerate() {
                        nodes.push(if dir == 0 {
                            crossing(li, k)
                        } else {
                            crossing(k, li)
                        });
                        node_s.push(c);
                    }
                    nodes.push(end);
                    node_s.push(1.0);
                    curves.push(LayoutCurve {
                        index,
                        nodes,
                        node_s,
                        length: 1.0,
                    });
                    for k in 0..=10 {
                        sensors.push(LayoutSensor {
                            sensor: sensors.len() as u16,
                            curve: index,
                            s: k as f64 * 0.1,
                        });
                    }
                }
            }
            Model {
                kind,
                sensors,
                curves,
                size: 1.0,
            }
        }
    }
}

/// Position and frame of a sensor at time `t`.
fn pose(m: &Model, s: &LayoutSensor, t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
    pose_with(m, s, t, true)
}

/// As [`pose`]; without `position` the riser's centreline is not integrated (the position
/// is then zero): the samples need only the frame, and a day of stream is otherwise slow.
fn pose_with(
    m: &Model,
    s: &LayoutSensor,
    t: f64,
    position: bool,
) -> (Vector3<f64>, UnitQuaternion<f64>) {
    match m.kind {
        StructureKind::Riser => {
            let tip = RISER_TIP_ANGLE * (std::f64::consts::TAU * t / RISER_PERIOD).sin();
            let theta = |s: f64| {
                let u = s / RISER_LENGTH;
                tip * (2.0 * u - u * u)
            };
            // Integrate the centreline (Simpson over 1 cm steps).
            let steps = if position {
                ((s.s / 0.01).ceil() as usize).max(1)
            } else {
                0
            };
            let h = s.s / steps as f64;
            let mut p = Vector3::zeros();
            for k in 0..steps {
                let (a, b) = (k as f64 * h, (k + 1) as f64 * h);
                let f = |x: f64| Vector3::new(theta(x).sin(), 0.0, theta(x).cos());
                p += (f(a) + f((a + b) / 2.0) * 4.0 + f(b)) * (h / 6.0);
            }
            let th = theta(s.s);
            let tt = Vector3::new(th.sin(), 0.0, th.cos());
            let n = Vector3::y();
            (p, frame(tt, n))
        }
        StructureKind::Panel => {
            let a = PANEL_BULGE * (std::f64::consts::TAU * t / PANEL_PERIOD).sin();
            let c = &m.curves[s.curve];
            let line = [0.25, 0.5, 0.75][c.index % 3];
            let along_x = c.index < 3;
            let (x, y) = if along_x { (s.s, line) } else { (line, s.s) };
            let pi = std::f64::consts::PI;
            let z = a * (pi * x).sin() * (pi * y).sin();
            let zx = a * pi * (pi * x).cos() * (pi * y).sin();
            let zy = a * pi * (pi * x).sin() * (pi * y).cos();
            let tt = if along_x {
                Vector3::new(1.0, 0.0, zx)
            } else {
                Vector3::new(0.0, 1.0, zy)
            };
            let n = Vector3::new(-zx, -zy, 1.0);
            (Vector3::new(x, y, z), frame(tt, n))
        }
    }
}

fn frame(t: Vector3<f64>, n: Vector3<f64>) -> UnitQuaternion<f64> {
    let t = t.normalize();
    let n = (n - t * n.dot(&t)).normalize();
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(
        &[t, n.cross(&t), n],
    )))
}

/// Simulates `duration` seconds of the structure streaming at `rate_hz` per sensor.
pub fn run(
    kind: StructureKind,
    seed: u64,
    duration: f64,
    rate_hz: f64,
) -> (Vec<u8>, StructureTruth) {
    let m = model(kind);
    let mut rng = Rng::new(seed);
    let field = Earth::default().field();
    let (acc_lsb, mag_lsb) = (16.0 * G / 65536.0, 0.15);
    let mut out = Vec::new();
    let mut seq = 0u8;
    let mut put = |p: Packet, out: &mut Vec<u8>| {
        p.encode(seq, out);
        seq = seq.wrapping_add(1);
    };
    let hello = Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::SensorArray,
        device_id: 0x5F5_0010 + kind as u32,
        firmware: 0x0100,
        rate_hz: rate_hz as u16,
        acc_scale: acc_lsb as f32,
        gyro_scale: 0.0,
        mag_scale: mag_lsb as f32,
        ticks_per_rev: 0,
        wheel_circumference_um: 0,
        sensors: m.sensors.len() as u16,
    });
    let mut epochs = Vec::new();
    let dt = 1.0 / rate_hz;
    let mut next_hello = 0.0;
    let mut next_status = 0.0;
    let mut next_epoch = 0.0;
    let steps = (duration * rate_hz) as usize;
    for k in 0..steps {
        let t = k as f64 * dt;
        if t >= next_hello {
            put(hello, &mut out);
            next_hello += 5.0;
        }
        if t >= next_status {
            put(
                Packet::Status(Status {
                    t_us: (1e6 + t * 1e6) as u64 as u32,
                    battery_mv: 12_000,
                    flags: 0,
                    dropped: 0,
                }),
                &mut out,
            );
            next_status += 2.0;
        }
        let record = t >= next_epoch;
        let mut epoch = Epoch {
            t,
            positions: Vec::new(),
            q: Vec::new(),
            tip_displacement: None,
        };
        for s in &m.sensors {
            // Sensors are sampled one after the other within the period.
            let ts = t + dt * s.sensor as f64 / m.sensors.len() as f64;
            let (_, q) = pose_with(&m, s, ts, false);
            if record {
                let (p0, q0) = pose(&m, s, t);
                epoch.positions.push([p0.x, p0.y, p0.z]);
                epoch.q.push([q0.w, q0.i, q0.j, q0.k]);
            }
            let acc = q.inverse() * Vector3::new(0.0, 0.0, G) + rng.vec3(0.02);
            let mag = q.inverse() * field + rng.vec3(0.3);
            put(
                Packet::ArraySample(ArraySample {
                    // Wraps every 71.6 min, as the device's clock does.
                    t_us: (1e6 + ts * 1e6) as u64 as u32,
                    sensor: s.sensor,
                    acc: super::device::counts(&acc, acc_lsb),
                    mag: super::device::counts(&mag, mag_lsb),
                }),
                &mut out,
            );
        }
        if record {
            if kind == StructureKind::Riser {
                let top = epoch.positions.last().copied().unwrap_or([0.0; 3]);
                epoch.tip_displacement = Some((top[0] * top[0] + top[1] * top[1]).sqrt());
            }
            epochs.push(epoch);
            next_epoch += 1.0;
        }
    }
    let truth = StructureTruth {
        structure: match kind {
            StructureKind::Riser => "riser".into(),
            StructureKind::Panel => "panel".into(),
        },
        seed,
        sensors: m.sensors,
        curves: m.curves,
        size: m.size,
        epochs,
    };
    (out, truth)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn riser_is_inextensible_and_bends_as_specified() {
        let m = model(StructureKind::Riser);
        let t = RISER_PERIOD / 4.0; // full bend
        let ps: Vec<Vector3<f64>> = m.sensors.iter().map(|s| pose(&m, s, t).0).collect();
        let len: f64 = ps.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        assert!((len - RISER_LENGTH).abs() < 0.01, "chord length {len}");
        let tip = ps.last().unwrap();
        // ∫ sin θ ≈ θ_tip L (1 − 1/3) for small θ.
        assert!(
            (tip.x - 2.0 / 3.0 * RISER_TIP_ANGLE * RISER_LENGTH).abs() < 0.05,
            "tip {tip}"
        );
        // Frames: T along the centreline, N ⟂ T.
        for s in &m.sensors {
            let (_, q) = pose(&m, s, t);
            assert!((q * Vector3::z()).dot(&(q * Vector3::x())).abs() < 1e-12);
        }
    }

    #[test]
    fn panel_layout_and_bulge() {
        let m = model(StructureKind::Panel);
        assert_eq!(m.curves.len(), 6);
        assert_eq!(m.sensors.len(), 66);
        let mut nodes: Vec<u32> = m.curves.iter().flat_map(|c| c.nodes.clone()).collect();
        nodes.sort_unstable();
        nodes.dedup();
        assert_eq!(nodes.len(), 9 + 12);
        let centre = m
            .sensors
            .iter()
            .find(|s| s.curve == 1 && (s.s - 0.5).abs() < 1e-9)
            .unwrap();
        let (p, _) = pose(&m, centre, PANEL_PERIOD / 4.0);
        assert!((p.z - PANEL_BULGE).abs() < 1e-12);
    }

    #[test]
    fn stream_decodes_and_truth_has_epochs() {
        let (bytes, truth) = run(StructureKind::Riser, 1, 10.0, 5.0);
        let mut dec = device_protocol::Decoder::new();
        let n = dec
            .feed(&bytes)
            .filter(|e| matches!(e, device_protocol::Event::Packet { .. }))
            .count();
        assert_eq!(n, 50 * 41 + 2 + 5);
        assert_eq!(truth.epochs.len(), 10);
        assert!(truth.epochs.iter().all(|e| e.positions.len() == 41));
    }
}
