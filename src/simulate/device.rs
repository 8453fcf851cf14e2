//! Device models: true states → the exact packets a device would send, with seeded sensor
//! noise, quantisation, wheel slip, a mounting offset, periodic HELLO and STATUS, and link
//! faults.

use super::operator::{Script, State};
use super::rng::Rng;
use crate::sensor::{Calibration, G};
use device_protocol::{
    DeviceKind, Hello, Key, Packet, PhoneSample, RiderSample, SegmentLength, Status,
};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// The Earth's field: magnitude and inclination; world x east, y magnetic north, z up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Earth {
    pub field_ut: f64,
    pub inclination_deg: f64,
}

impl Default for Earth {
    /// Central Europe: 48 µT, inclination 64°.
    fn default() -> Self {
        Earth {
            field_ut: 48.0,
            inclination_deg: 64.0,
        }
    }
}

impl Earth {
    pub fn field(&self) -> Vector3<f64> {
        let i = self.inclination_deg.to_radians();
        Vector3::new(0.0, self.field_ut * i.cos(), -self.field_ut * i.sin())
    }
}

/// A ferromagnetic object near part of the surface: an extra field, constant within
/// `radius` of `center`, fading over one more radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disturbance {
    pub center: Vector3<f64>,
    pub radius: f64,
    pub field_ut: Vector3<f64>,
}

impl Disturbance {
    fn at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let d = (p - self.center).norm();
        let w = if d <= self.radius {
            1.0
        } else {
            (2.0 - d / self.radius).max(0.0)
        };
        self.field_ut * w
    }
}

/// Link faults (probabilities per packet).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkFaults {
    /// One byte of the frame changed.
    pub corrupt: f64,
    /// The packet never arrives.
    pub lose: f64,
}

/// Noise and hardware of the simulated device (documented defaults per kind).
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceParams {
    pub kind: DeviceKind,
    pub rate_hz: f64,
    /// Relative jitter of sample instants (recorded by the timestamps).
    pub jitter: f64,
    /// Accelerometer white noise, m/s². Morphorider 0.02, phone 0.03.
    pub acc_sigma: f64,
    /// Magnetometer white noise, µT. Morphorider 0.3, phone 0.4.
    pub mag_sigma: f64,
    /// Gyroscope white noise, rad/s (phone). Default 0.003.
    pub gyro_sigma: f64,
    /// Gyroscope constant bias per axis, standard deviation, rad/s (phone). Default 0.005.
    pub gyro_bias_sigma: f64,
    /// Gyroscope bias per axis of about this size instead (rad/s, ±20 %, random sign), as
    /// an uncalibrated consumer gyroscope has; 0: drawn from `gyro_bias_sigma`. Default 0.
    pub gyro_bias_axis: f64,
    /// Random walk of the gyroscope bias, rad/s per √s per axis. Default 0.
    pub gyro_bias_walk: f64,
    /// LSB sizes announced in HELLO.
    pub acc_lsb: f64,
    pub mag_lsb: f64,
    pub gyro_lsb: f64,
    pub ticks_per_rev: u32,
    pub wheel_circumference_um: u32,
    /// Per-curve wheel slip, standard deviation (relative). Default 0.005.
    pub slip_sigma: f64,
    /// Rotation from the mapped sensor axes to the rolling frame (the calibration's
    /// `mounting`). Default: Morphorider 0.5° about the normal (its wheel is not perfectly
    /// aligned with its sensor), phone none.
    pub mounting: Rotation3<f64>,
    /// Phone: standard deviation of the measured segment lengths, m (0: none sent). Default 0.003.
    pub segment_length_sigma: f64,
    pub earth: Earth,
    /// Ferromagnetic objects near the surface (their fields add up).
    pub disturbances: Vec<Disturbance>,
    pub faults: LinkFaults,
    /// Device clock at the session's start, µs (to put a clock wrap mid-session).
    pub clock_start_us: u32,
    pub device_id: u32,
    /// The device restarts at this session time: it is silent for `reboot_silence` seconds,
    /// then sends a HELLO with its sequence, clock and wheel counter restarted.
    pub reboot_at: Option<f64>,
    /// How long a reboot keeps the device silent, s. Default 0.5.
    pub reboot_silence: f64,
    /// Stalls of the sample stream `(start s, duration s)`: the device drops the samples
    /// (counted in STATUS `dropped`) while the operator goes on moving.
    pub stalls: Vec<(f64, f64)>,
    /// Wheel skids `(start s, duration s, factor)`: the wheel turns only `factor` of the motion.
    pub skids: Vec<(f64, f64, f64)>,
    /// Phone: segments whose measured length reads `factor` × the true one
    /// `(curve, segment, factor)` (a slip, issue 49).
    pub segment_scale: Vec<(usize, usize, f64)>,
}

impl DeviceParams {
    pub fn morphorider() -> Self {
        DeviceParams {
            kind: DeviceKind::Morphorider,
            rate_hz: 100.0,
            jitter: 0.02,
            acc_sigma: 0.02,
            mag_sigma: 0.3,
            gyro_sigma: 0.0,
            gyro_bias_sigma: 0.0,
            gyro_bias_axis: 0.0,
            gyro_bias_walk: 0.0,
            acc_lsb: 16.0 * G / 65536.0,
            mag_lsb: 0.15,
            gyro_lsb: 0.0,
            ticks_per_rev: 1024,
            wheel_circumference_um: 100_000,
            slip_sigma: 0.005,
            mounting: Rotation3::from_axis_angle(&Vector3::z_axis(), 0.5f64.to_radians()),
            segment_length_sigma: 0.0,
            earth: Earth::default(),
            disturbances: Vec::new(),
            faults: LinkFaults::default(),
            clock_start_us: 1_000_000,
            device_id: 0x5F5_0001,
            reboot_at: None,
            reboot_silence: 0.5,
            stalls: Vec::new(),
            skids: Vec::new(),
            segment_scale: Vec::new(),
        }
    }

    pub fn phone() -> Self {
        DeviceParams {
            kind: DeviceKind::Phone,
            rate_hz: 200.0,
            jitter: 0.1,
            acc_sigma: 0.03,
            mag_sigma: 0.4,
            gyro_sigma: 0.003,
            gyro_bias_sigma: 0.005,
            gyro_bias_axis: 0.0,
            gyro_bias_walk: 0.0,
            acc_lsb: 16.0 * G / 65536.0,
            mag_lsb: 0.15,
            gyro_lsb: 2000f64.to_radians() / 32768.0,
            ticks_per_rev: 0,
            wheel_circumference_um: 0,
            slip_sigma: 0.0,
            mounting: Rotation3::identity(),
            segment_length_sigma: 0.003,
            earth: Earth::default(),
            disturbances: Vec::new(),
            faults: LinkFaults::default(),
            clock_start_us: 2_000_000,
            device_id: 0x5F5_0002,
            reboot_at: None,
            reboot_silence: 0.5,
            stalls: Vec::new(),
            skids: Vec::new(),
            segment_scale: Vec::new(),
        }
    }

    fn hello(&self) -> Hello {
        Hello {
            proto: device_protocol::PROTOCOL_VERSION,
            kind: self.kind,
            device_id: self.device_id,
            firmware: 0x0100,
            rate_hz: self.rate_hz as u16,
            acc_scale: self.acc_lsb as f32,
            gyro_scale: self.gyro_lsb as f32,
            mag_scale: self.mag_lsb as f32,
            ticks_per_rev: self.ticks_per_rev,
            wheel_circumference_um: self.wheel_circumference_um,
            sensors: 1,
        }
    }
}

/// What the simulated device really measured, per sample packet sent (in order).
#[derive(Debug, Clone, Default)]
pub struct SampleTruth {
    /// The script's time of the sample, s.
    pub t: Vec<f64>,
    /// Session time of the sample as acquisition computes it from the timestamps (0 at the
    /// first packet; a reboot's silence not counted), s, up to 1 µs.
    pub session_t: Vec<f64>,
    /// True frame → world.
    pub q: Vec<UnitQuaternion<f64>>,
    pub curve: Vec<Option<usize>>,
    pub s: Vec<f64>,
    pub standing: Vec<bool>,
    /// Wheel reading in metres (after slip and before quantisation).
    pub wheel: Vec<f64>,
    /// Packets the device sent, of which corrupted on the line and lost.
    pub packets_sent: u64,
    pub packets_corrupted: u64,
    pub packets_lost: u64,
    /// Samples the device dropped in a stall (not sent, not in the vectors above).
    pub samples_dropped: u64,
}

impl SampleTruth {
    /// Puts this truth into acquired curves, sample by sample (matched by session time, within
    /// 0.1 ms): the true orientations (`q`) and/or the true distances from each curve's first
    /// tag (`d`, its tags' too), for studies of where an error comes from; returns the samples
    /// it found no truth for.
    pub fn put_into(&self, curves: &mut [sfs_geometry::curve::Curve], q: bool, d: bool) -> usize {
        let truth = self;
        let near = |t: f64| -> Option<usize> {
            let ts = &truth.session_t;
            let i = ts.partition_point(|&x| x < t);
            [i.wrapping_sub(1), i]
                .into_iter()
                .filter(|&j| j < ts.len())
                .min_by(|&a, &b| (ts[a] - t).abs().total_cmp(&(ts[b] - t).abs()))
                .filter(|&j| (ts[j] - t).abs() < 1e-4)
        };
        let mut missed = 0;
        for c in curves {
            let s0 = c
                .tags
                .first()
                .and_then(|tag| near(tag.t))
                .map(|j| truth.s[j]);
            for i in 0..c.samples.len() {
                let Some(j) = near(c.samples.t[i]) else {
                    missed += 1;
                    continue;
                };
                if q {
                    let tq = truth.q[j];
                    c.samples.q[i] = [tq.w, tq.i, tq.j, tq.k];
                }
                if let (true, Some(s0)) = (d, s0) {
                    c.samples.d[i] = truth.s[j] - s0;
                }
            }
            if let (true, Some(s0)) = (d, s0) {
                for tag in &mut c.tags {
                    if let Some(j) = near(tag.t) {
                        tag.d = truth.s[j] - s0;
                    }
                }
            }
        }
        missed
    }
}

/// Writes packets with sequence numbers, periodic HELLO and STATUS, and link faults.
struct Emitter {
    out: Vec<u8>,
    seq: u8,
    rng: Rng,
    faults: LinkFaults,
    next_hello: f64,
    next_status: f64,
    hello: Hello,
    /// The device clock reads `clock_base_us` at session time `clock_base_t`.
    clock_base_us: u32,
    clock_base_t: f64,
    sent: u64,
    corrupted: u64,
    lost: u64,
    /// Samples dropped since power-up (STATUS `dropped`).
    dropped: u32,
    /// The script time and session time of the last packet emitted.
    session: Option<(f64, f64)>,
    /// The next packet is the first after a reboot (the receiver's clock adds nothing).
    restarted: bool,
}

impl Emitter {
    /// The emitter of a device `p` (its sequence number drawn from `rng`, its link's faults
    /// from a fork of it).
    fn new(p: &DeviceParams, rng: &mut Rng) -> Self {
        Emitter {
            out: Vec::new(),
            seq: (rng.next_u64() % 256) as u8,
            rng: rng.fork(),
            faults: p.faults,
            next_hello: 0.0,
            next_status: 0.0,
            hello: p.hello(),
            clock_base_us: p.clock_start_us,
            clock_base_t: 0.0,
            sent: 0,
            corrupted: 0,
            lost: 0,
            dropped: 0,
            session: None,
            restarted: false,
        }
    }

    /// Emits the keys and the segment lengths (`(time, segment, length)`) due by `t`.
    fn keys_and_lengths_until<'a>(
        &mut self,
        t: f64,
        keys: &mut std::iter::Peekable<impl Iterator<Item = &'a (f64, u8)>>,
        segs: &mut std::iter::Peekable<impl Iterator<Item = &'a (f64, u16, f64)>>,
    ) {
        while let Some(&&(tk, k)) = keys.peek() {
            if tk > t {
                break;
            }
            let t_us = self.t_us(tk);
            self.emit(tk, Packet::Key(Key { t_us, key: k }));
            keys.next();
        }
        while let Some(&&(ts, seg, len)) = segs.peek() {
            if ts > t {
                break;
            }
            let t_us = self.t_us(ts);
            self.emit(
                ts,
                Packet::SegmentLength(SegmentLength {
                    t_us,
                    segment: seg,
                    length_um: (len * 1e6).round() as u32,
                }),
            );
            segs.next();
        }
    }

    fn t_us(&self, t: f64) -> u32 {
        // The device clock wraps every 2³² µs (71.6 min): truncate through u64 (an `as u32`
        // of the float would saturate and stop the clock).
        self.clock_base_us
            .wrapping_add(((t - self.clock_base_t) * 1e6).round() as u64 as u32)
    }

    /// Power cycle at session time `t`: sequence, clock and HELLO start over.
    fn reboot(&mut self, t: f64) {
        self.seq = 0;
        self.clock_base_us = 150_000;
        self.clock_base_t = t;
        self.next_hello = t;
        self.next_status = t;
        self.dropped = 0;
        self.restarted = true;
    }

    /// Session time (as the receiver counts it) of a packet emitted at script time `t`.
    fn session_t(&mut self, t: f64) -> f64 {
        let s = match self.session {
            None => 0.0,
            Some((_, ls)) if self.restarted => ls,
            Some((lt, ls)) => ls + (t - lt),
        };
        self.restarted = false;
        self.session = Some((t, s));
        s
    }

    fn emit(&mut self, t: f64, p: Packet) {
        self.session_t(t);
        if t >= self.next_hello {
            self.next_hello = t + 5.0;
            self.raw(Packet::Hello(self.hello));
        }
        if t >= self.next_status {
            self.next_status = t + 2.0;
            let t_us = self.t_us(t);
            self.raw(Packet::Status(Status {
                t_us,
                battery_mv: 3900u16.saturating_sub((t / 60.0) as u16),
                flags: 0,
                dropped: self.dropped,
            }));
        }
        self.raw(p);
    }

    fn raw(&mut self, p: Packet) {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.sent += 1;
        if self.faults.lose > 0.0 && self.rng.uniform() < self.faults.lose {
            self.lost += 1;
            return;
        }
        let start = self.out.len();
        p.encode(seq, &mut self.out);
        if self.faults.corrupt > 0.0 && self.rng.uniform() < self.faults.corrupt {
            let len = self.out.len() - start - 1; // not the delimiter
            let i = start + (self.rng.next_u64() as usize % len);
            self.out[i] ^= 1 + (self.rng.next_u64() % 255) as u8;
            self.corrupted += 1;
        }
    }
}

/// A sensor value in counts of `lsb`, clamped to the i16 rails.
pub(crate) fn counts(v: &Vector3<f64>, lsb: f64) -> [i16; 3] {
    [0, 1, 2].map(|i| (v[i] / lsb).round().clamp(i16::MIN as f64, i16::MAX as f64) as i16)
}

/// Renders `script` as the bytes the device would send, with the truth of every sample.
pub fn render(script: &Script, p: &DeviceParams, rng: &mut Rng) -> (Vec<u8>, SampleTruth) {
    let mut em = Emitter::new(p, rng);
    let mut rebooted = false;
    let mut truth = SampleTruth::default();
    let field = p.earth.field();
    let g = Vector3::new(0.0, 0.0, G);
    // Sensor axes → frame axes: frame = mounting · axes · sensor.
    let frame_from_sensor = p.mounting.matrix() * Calibration::default_for(p.kind).axes.m;
    let mut gyro_bias = initial_gyro_bias(p, rng);
    let mut bias_t = 0.0;
    let m_per_tick = if p.ticks_per_rev > 0 {
        p.wheel_circumference_um as f64 * 1e-6 / p.ticks_per_rev as f64
    } else {
        0.0
    };
    let n_curves = script.curves.len();
    let slips: Vec<f64> = (0..n_curves)
        .map(|_| 1.0 + p.slip_sigma * rng.gauss())
        .collect();
    let mut wheel_dev = 0.0;
    let mut last_wheel = 0.0;
    let mut keys = script.keys.iter().peekable();
    let seg_lengths = measured_segment_lengths(script, p, rng);
    let mut segs = seg_lengths.iter().peekable();
    for st in &script.states {
        if let Some(tr) = p.reboot_at {
            if st.t >= tr && !rebooted {
                rebooted = true;
                // The wheel counter restarts with the firmware.
                wheel_dev = 0.0;
                em.reboot(tr + p.reboot_silence);
            }
            if st.t >= tr && st.t < tr + p.reboot_silence {
                last_wheel = st.wheel;
                continue;
            }
        }
        em.keys_and_lengths_until(st.t, &mut keys, &mut segs);
        let mut slip = st.curve.map_or(1.0, |c| slips[c]);
        for &(a, d, f) in &p.skids {
            if st.t >= a && st.t < a + d {
                slip *= f;
            }
        }
        wheel_dev += (st.wheel - last_wheel) * slip;
        last_wheel = st.wheel;
        if p.gyro_bias_walk > 0.0 {
            gyro_bias += rng.vec3(p.gyro_bias_walk * (st.t - bias_t).max(0.0).sqrt());
            bias_t = st.t;
        }
        if p.stalls.iter().any(|&(a, d)| st.t >= a && st.t < a + d) {
            // Dropped inside the device: the wheel goes on counting.
            em.dropped = em.dropped.saturating_add(1);
            truth.samples_dropped += 1;
            continue;
        }
        let sample = sensor_sample(
            st,
            p,
            &field,
            &g,
            &frame_from_sensor,
            &gyro_bias,
            wheel_dev,
            m_per_tick,
            rng,
        );
        let t_us = em.t_us(st.t);
        let packet = match (p.kind, sample) {
            (DeviceKind::Phone, (acc, mag, gyro, _)) => Packet::PhoneSample(PhoneSample {
                t_us,
                acc,
                gyro,
                mag,
            }),
            (_, (acc, mag, _, wheel)) => Packet::RiderSample(RiderSample {
                t_us,
                acc,
                mag,
                wheel,
            }),
        };
        em.emit(st.t, packet);
        truth.t.push(st.t);
        truth.session_t.push(em.session.map_or(0.0, |s| s.1));
        truth.q.push(st.q);
        truth.curve.push(st.curve);
        truth.s.push(st.s);
        truth.standing.push(st.standing);
        truth.wheel.push(wheel_dev);
    }
    for &(tk, k) in keys {
        let t_us = em.t_us(tk);
        em.emit(tk, Packet::Key(Key { t_us, key: k }));
    }
    truth.packets_sent = em.sent;
    truth.packets_corrupted = em.corrupted;
    truth.packets_lost = em.lost;
    (em.out, truth)
}

/// The gyroscope's bias at the start: about `gyro_bias_axis` per axis with a random sign
/// (an uncalibrated phone), else Gaussian of σ `gyro_bias_sigma`.
fn initial_gyro_bias(p: &DeviceParams, rng: &mut Rng) -> Vector3<f64> {
    if p.gyro_bias_axis > 0.0 {
        Vector3::from_fn(|_, _| {
            let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            sign * p.gyro_bias_axis * rng.range(0.8, 1.2)
        })
    } else {
        rng.vec3(p.gyro_bias_sigma)
    }
}

/// Phone: the segment lengths the app measures, `(time, segment, length)`, each sent right
/// after the Enter that ends its segment (none without a length error to draw).
fn measured_segment_lengths(
    script: &Script,
    p: &DeviceParams,
    rng: &mut Rng,
) -> Vec<(f64, u16, f64)> {
    let mut seg_lengths = Vec::new();
    if p.kind == DeviceKind::Phone && p.segment_length_sigma > 0.0 {
        for (ci, c) in script.curves.iter().enumerate() {
            for (k, w) in c.tags.windows(2).enumerate() {
                // From Enter to Enter (a late Enter moves both ends it bounds).
                let at = |j: usize| c.enter_s.get(j).copied().unwrap_or(c.tags[j].1);
                let scale = p
                    .segment_scale
                    .iter()
                    .filter(|&&(sc, sk, _)| (sc, sk) == (ci, k))
                    .map(|x| x.2)
                    .product::<f64>();
                let len = scale * (at(k + 1) - at(k)) + p.segment_length_sigma * rng.gauss();
                seg_lengths.push((w[1].2 + 1e-4, k as u16, len.max(1e-3)));
            }
        }
    }
    seg_lengths
}

#[allow(clippy::too_many_arguments)]
fn sensor_sample(
    st: &State,
    p: &DeviceParams,
    field: &Vector3<f64>,
    g: &Vector3<f64>,
    frame_from_sensor: &nalgebra::Matrix3<f64>,
    gyro_bias: &Vector3<f64>,
    wheel_dev: f64,
    m_per_tick: f64,
    rng: &mut Rng,
) -> ([i16; 3], [i16; 3], [i16; 3], i32) {
    // world = R · frame = R · F · sensor  ⇒  sensor = (R F)ᵀ · world.
    let r = st.q.to_rotation_matrix();
    let sensor_from_world = (r.matrix() * frame_from_sensor).transpose();
    let mut b = *field;
    for d in &p.disturbances {
        b += d.at(&st.pos);
    }
    let acc = sensor_from_world * (st.acc + g) + rng.vec3(p.acc_sigma);
    let mag = sensor_from_world * b + rng.vec3(p.mag_sigma);
    let gyro = frame_from_sensor.transpose() * st.omega + gyro_bias + rng.vec3(p.gyro_sigma);
    let wheel = if m_per_tick > 0.0 {
        (wheel_dev / m_per_tick).round() as i32
    } else {
        0
    };
    (
        counts(&acc, p.acc_lsb),
        counts(&mag, p.mag_lsb),
        if p.gyro_lsb > 0.0 {
            counts(&gyro, p.gyro_lsb)
        } else {
            [0; 3]
        },
        wheel,
    )
}
