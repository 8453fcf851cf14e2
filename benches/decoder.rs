//! Decoder throughput on a 100 MB mixed stream with 0.1 % corrupted packets.
//! `cargo bench --bench decoder`; target ≥ 300 MB/s (BENCHMARKS.md).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use device_protocol::*;
use std::hint::black_box;

/// Deterministic xorshift, so the stream is the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// A stream of `target` bytes: mostly samples of the three device kinds, keys, STATUS and
/// HELLO, with one packet in a thousand corrupted by one byte.
pub fn mixed_stream(target: usize, seed: u64) -> (Vec<u8>, usize) {
    let mut rng = Rng(seed | 1);
    let mut out = Vec::with_capacity(target + 64);
    let mut seq = 0u8;
    let mut t = 0u32;
    let mut corrupted = 0;
    while out.len() < target {
        t = t.wrapping_add(10_000);
        let r = rng.next();
        let v = |k: u64| {
            [
                (r >> k) as i16,
                (r >> (k + 16)) as i16,
                (r >> (k + 32)) as i16,
            ]
        };
        let p = match r % 100 {
            0..=59 => Packet::RiderSample(RiderSample {
                t_us: t,
                acc: v(0),
                mag: v(8),
                wheel: (r >> 20) as i32,
            }),
            60..=84 => Packet::PhoneSample(PhoneSample {
                t_us: t,
                acc: v(0),
                gyro: v(4),
                mag: v(8),
            }),
            85..=96 => Packet::ArraySample(ArraySample {
                t_us: t,
                sensor: (r >> 40) as u16 % 200,
                acc: v(0),
                mag: v(8),
            }),
            97 => Packet::Key(Key {
                t_us: t,
                key: b"BI0123456789\nUCE"[(r >> 50) as usize % 16],
            }),
            98 => Packet::Status(Status {
                t_us: t,
                battery_mv: 3900,
                flags: 0,
                dropped: 0,
            }),
            _ => Packet::Hello(Hello {
                proto: 1,
                kind: DeviceKind::Morphorider,
                device_id: 1,
                firmware: 1,
                rate_hz: 100,
                acc_scale: 0.0006,
                gyro_scale: 0.0,
                mag_scale: 0.15,
                ticks_per_rev: 1024,
                wheel_circumference_um: 100_000,
                sensors: 1,
            }),
        };
        let start = out.len();
        p.encode(seq, &mut out);
        seq = seq.wrapping_add(1);
        if rng.next().is_multiple_of(1000) {
            let i = start + (rng.next() as usize % (out.len() - start - 1));
            out[i] ^= 1 + (rng.next() % 255) as u8;
            corrupted += 1;
        }
    }
    (out, corrupted)
}

fn bench(c: &mut Criterion) {
    let (stream, _) = mixed_stream(100 * 1000 * 1000, 0x5f5);
    let mut g = c.benchmark_group("decoder");
    g.throughput(Throughput::Bytes(stream.len() as u64));
    g.sample_size(10);
    g.bench_function("mixed_100MB_0.1pct_corrupt_64KiB_chunks", |b| {
        b.iter(|| {
            let mut dec = Decoder::new();
            let mut packets = 0usize;
            for chunk in stream.chunks(64 * 1024) {
                for e in dec.feed(black_box(chunk)) {
                    if let Event::Packet { .. } = e {
                        packets += 1;
                    }
                }
            }
            black_box(packets)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
