//! Writes `replay-logs/demo-morphorider.bin`: a deterministic simulated Morphorider session on
//! a dome of radius 0.15 m (the equator as a closed boundary curve through nodes 1-2-3-4-1, the
//! meridians 1-0-3 and 2-0-4 over the pole), with a few corrupted packets so that the report
//! shows its reject counters.
//!
//! `cargo run --example demo_log [-- OUT]`. (The scene simulator's `sfs simulate` will
//! supersede this.)

use sfs::simulate::device::{render, DeviceParams, LinkFaults};
use sfs::simulate::operator::{perform, OperatorParams};
use sfs::simulate::rng::Rng;
use sfs::simulate::shapes::dome;

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "replay-logs/demo-morphorider.bin".into());
    let mut rng = Rng::new(2026);
    let mut p = DeviceParams::morphorider();
    p.faults = LinkFaults {
        corrupt: 0.0005,
        lose: 0.0,
    };
    let script = perform(
        &dome(0.15),
        &OperatorParams::default(),
        p.rate_hz,
        p.jitter,
        &mut rng,
    );
    let (bytes, _) = render(&script, &p, &mut rng);
    std::fs::write(&out, &bytes).expect("write the demo log");
    println!("{out}: {} bytes", bytes.len());
}
