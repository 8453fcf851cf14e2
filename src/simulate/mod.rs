//! The simulator: captures of known shapes, so that tests, benchmarks and the demo run without
//! a device. An [`operator`] turns curves on a surface into true device states and key presses;
//! a [`device`] model renders them as the exact bytes of the wire format.
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs::simulate::{self, operator::{CurveSpec, OperatorParams}, device::DeviceParams, rng::Rng};
//! // A 20 cm straight line on a table, from node 0 to node 1.
//! let points: Vec<_> = (0..=20).map(|i| Vector3::new(i as f64 * 0.01, 0.0, 0.0)).collect();
//! let curve = CurveSpec { normals: vec![Vector3::z(); points.len()], points, tags: vec![(0, 0), (20, 1)], kind: Default::default() };
//! let mut rng = Rng::new(1);
//! let script = simulate::operator::perform(&[curve], &OperatorParams::default(), 100.0, 0.02, &mut rng);
//! let (bytes, truth) = simulate::device::render(&script, &DeviceParams::morphorider(), &mut rng);
//! assert!(!bytes.is_empty() && truth.t.len() > 300);
//! ```

pub mod device;
pub mod mesh;
pub mod operator;
pub mod planted;
pub mod procedural;
pub use sfs_geometry::rng;
pub mod scene;
pub mod shapes;
pub mod structure;
pub mod surface;
pub mod truth;

use device::{render, DeviceParams, Disturbance, LinkFaults, SampleTruth};
use device_protocol::DeviceKind;
use nalgebra::{Rotation3, Vector3};
pub use operator::Mistakes;
use operator::{perform, OperatorParams, Script};
use rng::Rng;
use scene::Scene;
use truth::{um, Truth, TruthCurve, TruthSensor};

/// What `sfs simulate` adds on top of the device's own noise (`--profile default|field`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Profile {
    /// Documented default noise, link faults at 0.05 % of packets each (corrupted, lost).
    Default,
    /// What real sessions bring: 3× the noise, a 2° mounting offset, an uncalibrated phone
    /// gyroscope (about 1.7°/s of bias per axis, wandering 0.03°/s per √s), the hand tilting
    /// the resting device by 3–5° while an index is typed, a ferromagnetic object near part of
    /// the surface, wheel skids, a 0.3 s stall of the sample stream in the middle of a move, a
    /// wrong node index undone with U, a curve cancelled with C and rescanned, a device reboot
    /// (2 s of silence) while it is carried and turned between curves, the clock wrapping
    /// mid-session, twice the link faults, a capture that starts mid-packet, and the hand
    /// easing the device into and out of each node over half a second, standing 1.5 s after
    /// each Enter.
    Field,
}

impl Profile {
    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Profile::Default => "default",
            Profile::Field => "field",
        }
    }
}

/// The simulated bytes and their truth.
#[derive(Debug, Clone)]
pub struct Simulation {
    pub bytes: Vec<u8>,
    pub truth: Truth,
    /// Per sample sent: true orientation, curve, distance.
    pub samples: SampleTruth,
}

/// Simulates a scan of `scene` by `device` (Morphorider, phone or sensor array).
pub fn run(scene: &Scene, device: DeviceKind, profile: Profile, seed: u64) -> Simulation {
    run_with(scene, device, profile, seed, &Mistakes::default())
}

/// One fault of the field profile (each can be turned off to measure what it costs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// 3× the sensor noise.
    Noise,
    /// The 2° mounting offset.
    Mounting,
    /// The phone's uncalibrated, wandering gyroscope bias.
    GyroBias,
    /// The hand tilting the resting device while typing.
    Tilt,
    /// The device put down turned at each curve's start and turned in place.
    Turns,
    /// The ferromagnetic object near part of the surface.
    Magnet,
    /// A wrong index undone with U.
    WrongIndex,
    /// A curve cancelled with C and rescanned.
    Cancel,
    /// The reboot while carried and turned.
    Reboot,
    /// The device clock wrapping.
    ClockWrap,
    /// Wheel skids: three, each turning the wheel at 20 % of the motion for 0.6 s.
    Skids,
    /// The stall of the sample stream mid-move.
    Stall,
    /// Twice the link faults (corrupted and lost packets).
    Link,
    /// The capture starting mid-packet.
    MidPacket,
    /// The hand easing the device into each node and out of it over half a second, and
    /// standing 1.5 s after each Enter (issue 33: what an independent simulator's operator
    /// does, and what no accelerometer pulse shows).
    GentleStops,
}

impl Fault {
    /// Every fault of the field profile.
    pub const ALL: [Fault; 15] = [
        Fault::Noise,
        Fault::Mounting,
        Fault::GyroBias,
        Fault::Tilt,
        Fault::Turns,
        Fault::Magnet,
        Fault::WrongIndex,
        Fault::Cancel,
        Fault::Reboot,
        Fault::ClockWrap,
        Fault::Skids,
        Fault::Stall,
        Fault::Link,
        Fault::MidPacket,
        Fault::GentleStops,
    ];

    /// A short name (`gyro-bias`, …).
    pub fn name(self) -> &'static str {
        match self {
            Fault::Noise => "noise",
            Fault::Mounting => "mounting",
            Fault::GyroBias => "gyro-bias",
            Fault::Tilt => "tilt",
            Fault::Turns => "turns",
            Fault::Magnet => "magnet",
            Fault::WrongIndex => "wrong-index",
            Fault::Cancel => "cancel",
            Fault::Reboot => "reboot",
            Fault::ClockWrap => "clock-wrap",
            Fault::Skids => "skids",
            Fault::Stall => "stall",
            Fault::Link => "link",
            Fault::MidPacket => "mid-packet",
            Fault::GentleStops => "gentle-stops",
        }
    }
}

/// [`run`], with the operator also making the mistakes set in `more` (on top of the
/// profile's).
pub fn run_with(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    more: &Mistakes,
) -> Simulation {
    run_without(scene, device, profile, seed, more, &[])
}

/// [`run_with`], the field profile without the faults in `without` (the study of what each
/// fault costs; the default profile has none of them).
pub fn run_without(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    more: &Mistakes,
    without: &[Fault],
) -> Simulation {
    run_full(scene, device, profile, seed, more, without, None)
}

/// [`run`] with one fault planted ([`planted`]): the capture of the same seed without it, but
/// for the fault; the truth's `faults` says where it is.
pub fn run_planted(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    fault: planted::Planted,
) -> Result<Simulation, planted::NoPlace> {
    run_planted_with(scene, device, profile, seed, &Mistakes::default(), fault)
}

/// [`run_planted`], with the operator also making the mistakes set in `more`.
pub fn run_planted_with(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    more: &Mistakes,
    fault: planted::Planted,
) -> Result<Simulation, planted::NoPlace> {
    if device == DeviceKind::SensorArray {
        return Err(planted::NoPlace {
            kind: fault.name(),
            reason: "a sensor array is not scanned",
        });
    }
    let plan = planted::plan(fault, scene, seed, more)?;
    Ok(run_full(
        scene,
        device,
        profile,
        seed,
        more,
        &[],
        Some(&plan),
    ))
}

fn run_full(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    more: &Mistakes,
    without: &[Fault],
    plan: Option<&planted::Plan>,
) -> Simulation {
    let on = |f: Fault| profile == Profile::Field && !without.contains(&f);
    let mut rng = Rng::new(seed);
    let mut p = match device {
        DeviceKind::Phone => DeviceParams::phone(),
        _ => DeviceParams::morphorider(),
    };
    let mut op = OperatorParams::default();
    let mut events = Vec::new();
    let n = scene.curves.len();
    p.faults = LinkFaults {
        corrupt: 0.0005,
        lose: 0.0005,
    };
    if device == DeviceKind::SensorArray {
        return run_array(scene, profile, seed, &mut rng);
    }
    if profile == Profile::Field {
        field_setup(scene, device, &on, &mut p, &mut op, &mut events);
    }
    let m = &mut op.mistakes;
    m.wrong_index = more.wrong_index.or(m.wrong_index);
    m.cancel_and_rescan = more.cancel_and_rescan.or(m.cancel_and_rescan);
    m.repeated_index = more.repeated_index.or(m.repeated_index);
    if let Some((c, k)) = more.repeated_index {
        events.push(format!(
            "curve {c}: tag {k} typed twice, the repeat undone with U"
        ));
    }
    m.untagged.clone_from(&more.untagged);
    m.drop_after = more.drop_after;
    m.rescan = more.rescan;
    if let Some(plan) = plan {
        plan.act(m);
    }
    let script = perform(&scene.specs(), &op, p.rate_hz, p.jitter, &mut rng);
    for &(c, node) in &script.untagged {
        events.push(format!(
            "curve {c}: node {node} rolled through untagged (a crossing tagged on another curve only)"
        ));
    }
    let duration = script.states.last().map_or(0.0, |s| s.t);
    if profile == Profile::Field {
        field_timeline(&script, n, duration, &on, &mut p, &mut events);
    }
    let faults: Vec<_> = plan
        .map(|plan| plan.realise(scene, &script, &mut p, &op.mistakes))
        .into_iter()
        .collect();
    let (mut bytes, samples) = render(&script, &p, &mut rng);
    if on(Fault::MidPacket) {
        // The capture starts in the middle of the first packet.
        let first = bytes.iter().position(|&b| b == 0).unwrap_or(0);
        bytes.drain(..first / 2 + 1);
        events.push(format!(
            "capture starts {} bytes into the first packet",
            first / 2 + 1
        ));
    }
    let mut truth = truth_of(scene, device, profile, seed, Vec::new(), events);
    truth.faults = faults;
    Simulation {
        bytes,
        truth,
        samples,
    }
}

/// The field profile's faults that set up the device and the operator (each unless `on` says
/// it is left out for the study), and the events they add to the truth.
fn field_setup(
    scene: &Scene,
    device: DeviceKind,
    on: &dyn Fn(Fault) -> bool,
    p: &mut DeviceParams,
    op: &mut OperatorParams,
    events: &mut Vec<String>,
) {
    let n = scene.curves.len();
    // A fault turned off for the study keeps the random draws it makes where it can (a
    // negligible size instead of none), so that the other faults see the same noise.
    if on(Fault::Noise) {
        p.acc_sigma *= 3.0;
        p.mag_sigma *= 3.0;
        p.gyro_sigma *= 3.0;
    }
    if device == DeviceKind::Phone {
        if on(Fault::GyroBias) {
            p.gyro_bias_axis = 1.7f64.to_radians();
            p.gyro_bias_walk = 0.03f64.to_radians();
            events.push(
                "uncalibrated gyroscope: about 1.7°/s of bias per axis, wandering 0.03°/s per √s"
                    .into(),
            );
        } else {
            p.gyro_bias_axis = 1e-12;
            p.gyro_bias_walk = 1e-12;
        }
    }
    if on(Fault::Tilt) {
        op.typing_tilt_deg = 4.0;
        events.push("the hand tilts the device by 3-5° while typing each index".into());
    } else {
        op.typing_tilt_deg = 1e-12;
    }
    if on(Fault::Turns) {
        op.turn_in_place_deg = 45.0;
        events.push(
                "the device put down turned by 22-68° at each curve's start, turned in place before moving"
                    .into(),
            );
    } else {
        op.turn_in_place_deg = 1e-12;
    }
    if on(Fault::GentleStops) {
        op.stop_ramp = 0.5;
        op.pause_after_enter = 1.5;
        events.push(
                "the hand eases the device into and out of each node over 0.5 s, and stands 1.5 s after each Enter"
                    .into(),
            );
    }
    if on(Fault::Mounting) {
        p.mounting = Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(0.2, 0.3, 1.0)),
            2f64.to_radians(),
        );
    }
    if on(Fault::Link) {
        p.faults = LinkFaults {
            corrupt: 0.001,
            lose: 0.001,
        };
    }
    let c = &scene.curves[n.min(2) - 1];
    let center = c.points[c.points.len() / 2];
    let radius = 0.05 * scene.bbox_diagonal();
    if on(Fault::Magnet) {
        p.disturbances.push(Disturbance {
            center,
            radius,
            field_ut: Vector3::new(15.0, 0.0, 5.0),
        });
        events.push(format!(
            "magnetic disturbance of 15.8 µT within {radius:.3} m of ({:.3}, {:.3}, {:.3})",
            center.x, center.y, center.z
        ));
    }
    if scene.curves[0].tags.len() > 2 && on(Fault::WrongIndex) {
        op.mistakes.wrong_index = Some((0, 1));
        events.push("curve 0: a wrong index typed at its second node, undone with U".into());
    }
    let cancel = n.min(2) - 1;
    if on(Fault::Cancel) {
        op.mistakes.cancel_and_rescan = Some(cancel);
        events.push(format!(
            "curve {cancel}: started, cancelled with C, rescanned"
        ));
    }
}

/// The field profile's faults placed on the operator's timeline (`script` over `n` curves,
/// `duration` s): a reboot, the clock's wrap, wheel skids and a stall of the sample stream.
fn field_timeline(
    script: &Script,
    n: usize,
    duration: f64,
    on: &dyn Fn(Fault) -> bool,
    p: &mut DeviceParams,
    events: &mut Vec<String>,
) {
    // Reboot while carrying the device to the middle curve.
    if n >= 2 && on(Fault::Reboot) {
        let target = n / 2;
        let start = script
            .states
            .iter()
            .position(|s| s.curve == Some(target))
            .unwrap_or(0);
        let carry_mid = script.states[..start]
            .iter()
            .rposition(|s| s.curve.is_some())
            .map_or(0.5, |i| (script.states[i].t + script.states[start].t) / 2.0);
        p.reboot_silence = 2.0;
        p.reboot_at = Some(carry_mid - 1.0);
        events.push(format!(
                "device reboots at t = {:.1} s, silent for 2 s while carried and turned to curve {target}",
                carry_mid - 1.0
            ));
    }
    // The clock wraps mid-way (before the reboot, which restarts it).
    if on(Fault::ClockWrap) {
        let t_wrap = p.reboot_at.map_or(duration / 2.0, |r| r / 2.0);
        p.clock_start_us = u32::MAX - (t_wrap * 1e6) as u32;
        events.push(format!("device clock wraps at t = {t_wrap:.1} s"));
    }
    // Three wheel skids while rolling, each losing about 25 mm of a segment at the mean
    // speed (issue 33: the independent simulator's skids lose 16–29 mm; ours lost 10 mm,
    // below what the network's loops could tell from the orientations' noise).
    let rolling: Vec<f64> = script
        .states
        .iter()
        .filter(|s| s.curve.is_some() && !s.standing)
        .map(|s| s.t)
        .collect();
    for k in 0..if on(Fault::Skids) { 3 } else { 0 } {
        if let Some(&t) = rolling.get(rolling.len() * (2 * k + 1) / 6) {
            p.skids.push((t, 0.6, 0.2));
            events.push(format!("wheel skid at t = {t:.1} s (0.6 s at 20 %)"));
        }
    }
    // The sample stream stalls once in the middle of a move.
    if let Some(&t) = rolling
        .get(rolling.len() * 2 / 5)
        .filter(|_| on(Fault::Stall))
    {
        p.stalls.push((t, 0.3));
        events.push(format!(
                "the sample stream stalls at t = {t:.1} s for 0.3 s (samples dropped, the device moving)"
            ));
    }
}

/// The crossings to leave untagged on one of their curves (issue 34). A crossing is a node
/// that two or more curves pass through; it can be left out on a curve where it is neither
/// the first nor the last tag and which passes it once (so every curve keeps its ends, and
/// the node stays tagged on another curve). Of the crossings that can, `fraction` (rounded to
/// the nearest count) are chosen with `seed`, each left out on one such curve; never at a
/// corner ([`operator::at_corner`]: the operator stands there to turn). Returns
/// `(curve, tag)` pairs for [`Mistakes::untagged`], in scene order.
pub fn untagged_crossings(scene: &Scene, fraction: f64, seed: u64) -> Vec<(usize, usize)> {
    let specs = scene.specs();
    let mut curves_of: std::collections::BTreeMap<u32, Vec<(usize, usize)>> = Default::default();
    for (ci, c) in specs.iter().enumerate() {
        for (k, &(_, node)) in c.tags.iter().enumerate() {
            curves_of.entry(node).or_default().push((ci, k));
        }
    }
    // Per crossing: the (curve, tag) places it could be left out, on curves that pass it once.
    let eligible: Vec<Vec<(usize, usize)>> = curves_of
        .values()
        .filter(|on| {
            let mut cs: Vec<usize> = on.iter().map(|x| x.0).collect();
            cs.dedup();
            cs.len() >= 2
        })
        .map(|on| {
            on.iter()
                .copied()
                .filter(|&(ci, k)| {
                    let once = on.iter().filter(|x| x.0 == ci).count() == 1;
                    once && k > 0
                        && k + 1 < specs[ci].tags.len()
                        && !operator::at_corner(&specs[ci], k)
                })
                .collect::<Vec<_>>()
        })
        .filter(|places| !places.is_empty())
        .collect();
    let count =
        ((fraction.clamp(0.0, 1.0) * eligible.len() as f64).round() as usize).min(eligible.len());
    // Its own stream: the scan's other draws stay those of the seed.
    let mut rng = Rng::new(seed ^ 0x5eed_0034);
    let mut order: Vec<usize> = (0..eligible.len()).collect();
    for i in (1..order.len()).rev() {
        let j = (rng.range(0.0, (i + 1) as f64) as usize).min(i);
        order.swap(i, j);
    }
    let mut out: Vec<(usize, usize)> = order[..count]
        .iter()
        .map(|&e| {
            let places = &eligible[e];
            places[(rng.range(0.0, places.len() as f64) as usize).min(places.len() - 1)]
        })
        .collect();
    out.sort_unstable();
    out
}

fn truth_of(
    scene: &Scene,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    sensors: Vec<TruthSensor>,
    events: Vec<String>,
) -> Truth {
    let v = |p: &Vector3<f64>| [um(p.x), um(p.y), um(p.z)];
    Truth {
        scene: scene.name.clone(),
        description: scene.description.clone(),
        device: device.name().into(),
        profile: match profile {
            Profile::Default => "default".into(),
            Profile::Field => "field".into(),
        },
        seed,
        nodes: scene
            .nodes
            .iter()
            .enumerate()
            .map(|(i, p)| (i.to_string(), v(p)))
            .collect(),
        curves: scene
            .curves
            .iter()
            .enumerate()
            .map(|(i, c)| TruthCurve {
                index: i,
                nodes: c.nodes(),
                kind: Some(c.kind),
                boundary: c.kind == operator::CurveKind::Boundary,
                closed: c.closed,
                points: c.points.iter().map(v).collect(),
                normals: c
                    .normals
                    .iter()
                    .map(|n| [n.x, n.y, n.z].map(|x| (x * 1e9).round() / 1e9))
                    .collect(),
            })
            .collect(),
        surface: scene.surface_ref.clone(),
        bbox_diagonal: scene.bbox_diagonal(),
        sensors,
        events,
        faults: Vec::new(),
    }
}

/// A sensor array fixed on the scene's curves: a sensor every 5 cm along every curve, all
/// streaming for 10 s at 20 Hz each (static structure).
fn run_array(scene: &Scene, profile: Profile, seed: u64, rng: &mut Rng) -> Simulation {
    use device_protocol::{ArraySample, Hello, Packet};
    let noise = if profile == Profile::Field { 3.0 } else { 1.0 };
    let field = device::Earth::default().field();
    let (acc_lsb, mag_lsb) = (16.0 * crate::sensor::G / 65536.0, 0.15);
    let mut sensors = Vec::new();
    for (ci, c) in scene.curves.iter().enumerate() {
        let mut acc_len = 0.0;
        let mut next = 0.0;
        for i in 0..c.points.len() {
            if i > 0 {
                acc_len += (c.points[i] - c.points[i - 1]).norm();
            }
            if acc_len + 1e-12 >= next && i + 1 < c.points.len() {
                let t = (c.points[i + 1] - c.points[i]).normalize();
                let nn = c.normals[i];
                let n = (nn - t * nn.dot(&t)).normalize();
                let m = nalgebra::Matrix3::from_columns(&[t, n.cross(&t), n]);
                let q = nalgebra::UnitQuaternion::from_rotation_matrix(
                    &Rotation3::from_matrix_unchecked(m),
                );
                sensors.push(TruthSensor {
                    sensor: sensors.len() as u16,
                    curve: ci,
                    s: um(acc_len),
                    position: [um(c.points[i].x), um(c.points[i].y), um(c.points[i].z)],
                    q: [q.w, q.i, q.j, q.k],
                });
                next += 0.05;
            }
        }
    }
    let mut bytes = Vec::new();
    let mut seq = 0u8;
    let mut put = |p: Packet, b: &mut Vec<u8>| {
        p.encode(seq, b);
        seq = seq.wrapping_add(1);
    };
    let hello = Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::SensorArray,
        device_id: 0x5F5_0003,
        firmware: 0x0100,
        rate_hz: 20,
        acc_scale: acc_lsb as f32,
        gyro_scale: 0.0,
        mag_scale: mag_lsb as f32,
        ticks_per_rev: 0,
        wheel_circumference_um: 0,
        sensors: sensors.len() as u16,
    });
    for k in 0..200u32 {
        if k % 100 == 0 {
            put(hello, &mut bytes);
        }
        for s in &sensors {
            let q = nalgebra::UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
                s.q[0], s.q[1], s.q[2], s.q[3],
            ));
            let acc =
                q.inverse() * Vector3::new(0.0, 0.0, crate::sensor::G) + rng.vec3(0.02 * noise);
            let mag = q.inverse() * field + rng.vec3(0.3 * noise);
            put(
                Packet::ArraySample(ArraySample {
                    t_us: 1_000_000 + k * 50_000 + s.sensor as u32 * 10,
                    sensor: s.sensor,
                    acc: device::counts(&acc, acc_lsb),
                    mag: device::counts(&mag, mag_lsb),
                }),
                &mut bytes,
            );
        }
    }
    let truth = truth_of(
        scene,
        DeviceKind::SensorArray,
        profile,
        seed,
        sensors,
        Vec::new(),
    );
    Simulation {
        bytes,
        truth,
        samples: SampleTruth::default(),
    }
}
