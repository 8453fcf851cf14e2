//! Issue 15 point 4: the memory of an open curve is bounded. Alone in its test binary, so that
//! the process's peak resident size is this test's.

mod common;
use common::*;
use device_protocol::{Packet, RiderSample};
use sfs::acquisition::{Acquisition, AcquisitionConfig};

/// Peak resident size of this process so far, bytes (`VmHWM` in `/proc/self/status`).
fn peak_rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    let kb: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    kb * 1024
}

/// A curve of 10 million samples (28 hours at 100 Hz), streamed packet by packet through the
/// decoder and acquisition, ended and finalised, keeps the peak resident size under 1 GB
/// (it took about 490 bytes a sample, 4.9 GB). The curve's maximum size is raised above it
/// for the test (by default such a curve is ended at 2 million samples).
#[test]
fn issue_15_a_ten_million_sample_curve_stays_under_a_gigabyte() {
    const N: i32 = 10_000_000;
    let cfg = AcquisitionConfig {
        max_curve_samples: 20_000_000,
        ..Default::default()
    };
    let mut acq = Acquisition::new(cfg);
    let mut dec = device_protocol::Decoder::new();
    let mut b = Builder::new();
    let mut feed = |b: &mut Builder, acq: &mut Acquisition| {
        for e in dec.feed(&b.bytes) {
            acq.event(&e);
        }
        b.bytes.clear();
    };
    b.packet(hello());
    for k in *b"B1\n" {
        b.key(k);
    }
    let before = peak_rss();
    for i in 0..N {
        // 100 Hz, rolling 3 ticks (0.3 mm) a sample, the device slowly turning.
        b.t = b.t.wrapping_add(10_000);
        let a = (i % 20_000) as i16;
        b.packet(Packet::RiderSample(RiderSample {
            t_us: b.t,
            acc: [a / 10, 0, 4096],
            mag: [100, -a / 10, 300],
            wheel: i.wrapping_mul(3),
        }));
        if i % 4096 == 0 {
            feed(&mut b, &mut acq);
        }
    }
    for k in *b"2\nE" {
        b.key(k);
    }
    feed(&mut b, &mut acq);
    let scan = acq.finish();
    let peak = peak_rss();
    assert_eq!(scan.curves.len(), 1, "{:?}", scan.warnings);
    assert_eq!(scan.curves[0].samples.t.len(), N as usize);
    eprintln!(
        "peak resident size {} MB ({} bytes a sample over the {} MB before the curve)",
        peak >> 20,
        (peak - before) / N as u64,
        before >> 20
    );
    assert!(peak < 1 << 30, "peak resident size {} MB", peak >> 20);
}
