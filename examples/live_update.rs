//! One live update on a long session, by stage (BENCHMARKS.md, sessions of hundreds of
//! curves): a capture acquired, its first `N − 1` curves reconstructed and settled as the live
//! worker leaves them when idle, then the update that adds curve `N` (what the view's `curves`
//! event waits for: the network with the regression local to the new curve's nodes, the join
//! passes, Poisson, the uncertainty), with the stages' times from the report.
//!
//! `cargo run --release --example live_update -- CAPTURE.bin|scan.json N [N …]`; `M:N` for
//! an update that brings curves `M … N − 1` at once, as the worker coalesces them; `a,b,c`
//! for updates to a, b, c curves in a row (settled after each with `SETTLE=1`). E.g. on the
//! built-in `ellipsoid-grid` scene: `sfs simulate --scene ellipsoid-grid --device
//! morphorider --seed 1 --out E`. With `JOINS=1` in the environment, the update's joins and
//! refusals are listed.

use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::pipeline::{for_device, Pipeline, LIVE_LOCAL_WINDOW};
use sfs_geometry::network::NetworkParams;
use std::time::Instant;

fn main() {
    // As the daemon runs (faer's parallel factorisation is slower on this machine's 2 cores).
    sfs_geometry::sparse_llt::single_threaded();
    let mut args = std::env::args().skip(1);
    let (Some(path), counts) = (args.next(), args.collect::<Vec<_>>()) else {
        eprintln!("usage: live_update CAPTURE.bin N|M:N [N|M:N …]");
        std::process::exit(2);
    };
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    // A capture, or a session's scan.json (the curves as the daemon had them).
    #[derive(serde::Deserialize)]
    struct Curves {
        curves: Vec<sfs_geometry::curve::Curve>,
    }
    let curves = if path.ends_with(".json") {
        serde_json::from_slice::<Curves>(&bytes)
            .unwrap_or_else(|e| panic!("{path}: {e}"))
            .curves
    } else {
        Acquisition::scan_bytes(&bytes, AcquisitionConfig::default()).curves
    };
    let np = for_device(
        &NetworkParams {
            local_window: LIVE_LOCAL_WINDOW,
            ..Default::default()
        },
        None,
    );
    println!("{path}: {} curves", curves.len());
    for arg in counts {
        // `a,b,c…`: the updates to a, b, c… curves in a row, none settled unless SETTLE is set
        // (a worker that a faster source keeps busy), each timed.
        if arg.contains(',') {
            let mut p = Pipeline::new().live();
            for n in arg.split(',').filter_map(|x| x.parse::<usize>().ok()) {
                let n = n.clamp(1, curves.len());
                let t0 = Instant::now();
                let mut out = p.reconstruct(&curves[..n], &np);
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                match &out.network {
                    Some(net) => println!(
                        "{n} curves: the update {ms:.0} ms (join passes {:.1} ms; {} passes, {} parts)",
                        net.report.timings_ms.join, net.report.join_passes, net.report.components
                    ),
                    None => println!("{n} curves: no network ({ms:.0} ms)"),
                }
                // With SETTLE in the environment, each update settled after (an idle worker).
                if std::env::var("SETTLE").is_ok() {
                    p.settle(&curves[..n], &mut out, &np, None, || false);
                }
            }
            continue;
        }
        // `N`, or `M:N` for an update that brings curves M … N − 1 at once (coalesced).
        let (m, n) = match arg.split_once(':') {
            Some((m, n)) => (m.parse().ok(), n.parse().ok()),
            None => (None, arg.parse().ok()),
        };
        let n: usize = n.expect("a curve count");
        let n = n.clamp(2, curves.len());
        let m = m.unwrap_or(n - 1).clamp(1, n - 1);
        let mut p = Pipeline::new().live();
        let before = &curves[..m];
        let t = Instant::now();
        let mut out = p.reconstruct(before, &np);
        p.settle(before, &mut out, &np, None, || false);
        let ready = t.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let out = p.reconstruct(&curves[..n], &np);
        let update_ms = t0.elapsed().as_secs_f64() * 1e3;
        let Some(net) = &out.network else {
            println!("{m} → {n} curves: no network ({update_ms:.0} ms)");
            continue;
        };
        let (r, tm) = (&net.report, &net.report.timings_ms);
        println!(
            "{m} → {n} curves: the update {update_ms:.0} ms (pre-filter {:.1}, loop closure {:.1}, regression {:.1}, Poisson {:.1}, uncertainty {:.1}, join passes {:.1} ms; {} passes, {} parts, {} frames moved of {}); the network before it {ready:.1} s",
            tm.prefilter,
            tm.closure,
            tm.regression,
            tm.poisson,
            tm.uncertainty,
            tm.join,
            r.join_passes,
            r.components,
            r.regression.frames_moved,
            r.regression.frames
        );
        if std::env::var("JOINS").is_ok() {
            for j in &r.joined {
                println!(
                    "  joined node {} to curve {} ({:.1} mm away)",
                    j.node,
                    j.curve,
                    j.distance_m * 1e3
                );
            }
            for j in &r.joins_refused {
                println!(
                    "  refused node {} on curve {}: {}",
                    j.node, j.curve, j.reason
                );
            }
        }
    }
}
