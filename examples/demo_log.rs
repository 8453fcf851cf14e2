//! Writes `replay-logs/demo-morphorider.bin`: a deterministic Morphorider session on a dome
//! (upper hemisphere, radius 0.12 m): the equator as a closed boundary curve through nodes
//! 1-2-3-4-1 and two meridians 1-0-3 and 2-0-4 over the pole (node 0).
//!
//! `cargo run --example demo_log [-- OUT]`. A stop-gap until the scene simulator
//! (`sfs simulate`) exists: same wire format, simple noise, two corrupted packets so that the
//! report shows non-zero reject counters.

use device_protocol::*;
use std::f64::consts::PI;

type V = [f64; 3];
fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale(a: V, s: f64) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

struct Rng(u64);
impl Rng {
    fn u(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u1, u2) = (self.u().max(1e-300), self.u());
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

const R: f64 = 0.12; // dome radius, m
const SPEED: f64 = 0.05; // m/s
const RATE: f64 = 100.0; // Hz
const G: f64 = 9.81;
const ACC_SCALE: f32 = (9.81 / 4096.0) as f32;
const MAG_SCALE: f32 = 0.15;
const TICKS: u32 = 1024;
const CIRC_UM: u32 = 100_000;

struct Dev {
    out: Vec<u8>,
    seq: u8,
    t_us: u32,
    wheel_m: f64,
    rng: Rng,
    next_hello: u32,
    next_status: u32,
    corrupt_at: Vec<u32>,
}

impl Dev {
    fn send(&mut self, p: Packet) {
        let start = self.out.len();
        p.encode(self.seq, &mut self.out);
        self.seq = self.seq.wrapping_add(1);
        if let Some(i) = self.corrupt_at.iter().position(|&t| t <= self.t_us) {
            self.corrupt_at.remove(i);
            let k = start + 3;
            self.out[k] ^= 0x24;
        }
    }
    fn hello(&mut self) {
        self.send(Packet::Hello(Hello {
            proto: PROTOCOL_VERSION,
            kind: DeviceKind::Morphorider,
            device_id: 0x5F5_0001,
            firmware: 0x0102,
            rate_hz: RATE as u16,
            acc_scale: ACC_SCALE,
            gyro_scale: 0.0,
            mag_scale: MAG_SCALE,
            ticks_per_rev: TICKS,
            wheel_circumference_um: CIRC_UM,
            sensors: 1,
        }));
    }
    fn key(&mut self, k: u8) {
        self.send(Packet::Key(Key {
            t_us: self.t_us,
            key: k,
        }));
    }
    /// One sample with the device frame [T B N] (columns, world coordinates).
    fn sample(&mut self, frame: [V; 3], centripetal: V) {
        if self.t_us >= self.next_hello {
            self.hello();
            self.next_hello += 5_000_000;
        }
        if self.t_us >= self.next_status {
            self.send(Packet::Status(Status {
                t_us: self.t_us,
                battery_mv: 3950 - (self.t_us / 1_000_000) as u16,
                flags: 0,
                dropped: 0,
            }));
            self.next_status += 2_000_000;
        }
        let incl = 64f64.to_radians();
        let field = [0.0, 48.0 * incl.cos(), -48.0 * incl.sin()]; // µT, x east, y north, z up
        let f = add([0.0, 0.0, G], centripetal); // specific force
        let mut acc = [0i16; 3];
        let mut mag = [0i16; 3];
        for (i, axis) in frame.iter().enumerate() {
            let a = dot(*axis, f) + 0.02 * self.rng.gauss();
            let m = dot(*axis, field) + 0.3 * self.rng.gauss();
            acc[i] = (a / ACC_SCALE as f64).round() as i16;
            mag[i] = (m / MAG_SCALE as f64).round() as i16;
        }
        let wheel = (self.wheel_m / (CIRC_UM as f64 * 1e-6) * TICKS as f64).round() as i32;
        self.send(Packet::RiderSample(RiderSample {
            t_us: self.t_us,
            acc,
            mag,
            wheel,
        }));
        self.t_us += (1e6 / RATE) as u32 + (self.rng.u() * 200.0) as u32; // measured jitter
    }
}

/// Great circle through `a` towards `b` (orthonormal): position angle θ.
fn frame(a: V, b: V, th: f64) -> ([V; 3], V) {
    let n = add(scale(a, th.cos()), scale(b, th.sin()));
    let t = add(scale(a, -th.sin()), scale(b, th.cos()));
    let bn = cross(n, t);
    ([t, bn, n], scale(n, -SPEED * SPEED / R))
}

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "replay-logs/demo-morphorider.bin".into());
    let mut d = Dev {
        out: Vec::new(),
        seq: 0,
        t_us: 1_000_000,
        wheel_m: 0.0,
        rng: Rng(0x5F5_2026),
        next_hello: 0,
        next_status: 0,
        corrupt_at: vec![20_000_000, 41_000_000],
    };
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    // (start key, circle a, circle b, nodes at quarter turns)
    let curves: [(u8, V, V, &[u8]); 3] = [
        (b'B', x, y, &[1, 2, 3, 4, 1]),
        (b'I', x, z, &[1, 0, 3]),
        (b'I', y, z, &[2, 0, 4]),
    ];
    for (start, a, b, nodes) in curves {
        d.key(start);
        let slip = 1.0 + 0.01 * d.rng.gauss();
        for (i, &node) in nodes.iter().enumerate() {
            let th0 = i as f64 * PI / 2.0;
            let (f, c) = frame(a, b, th0);
            // Stand still at the node while typing its index, then Enter.
            for _ in 0..60 {
                d.sample(f, [0.0; 3]);
            }
            d.key(b'0' + node);
            for _ in 0..20 {
                d.sample(f, [0.0; 3]);
            }
            d.key(b'\n');
            for _ in 0..20 {
                d.sample(f, [0.0; 3]);
            }
            if i + 1 == nodes.len() {
                break;
            }
            // Roll a quarter circle.
            let len = R * PI / 2.0;
            let n = (len / SPEED * RATE) as usize;
            for k in 1..=n {
                let th = th0 + (k as f64 / n as f64) * PI / 2.0;
                d.wheel_m += len / n as f64 * slip;
                let (f, _) = frame(a, b, th);
                d.sample(f, c);
            }
        }
        d.key(b'E');
        // Lift the device and carry it to the next start: no samples for 2 s.
        d.t_us += 2_000_000;
    }
    std::fs::write(&out, &d.out).expect("write the demo log");
    println!("{out}: {} bytes", d.out.len());
}
