//! The live view's costs (issue 16 point 6), measured end to end.
//!
//! `cargo bench --bench view` runs every part; `-- preview`, `-- latency` or `-- stalled` one
//! (`SFS_BENCH_SEEDS=1,2,3` picks the seeds of the second; default 1,2,3).
//!
//! - **preview**: what the preview of the curve being scanned costs the pipeline on the phone
//!   capture `replay-logs/bowl-phone.bin` (200 Hz): the capture decoded and acquired with the
//!   preview off and on, publishing a preview to a [`View`] every 0.1 s of session time as the
//!   session does (best of 7 runs each); the difference per second of capture, as a share of
//!   one core.
//! - **latency**: from the `E` packet to the browser having drawn the new network. The LILIUM
//!   scene (Morphorider, `sfs simulate --scene lilium --seed S`) replayed at ×10 with
//!   surfacing (`sfs replay … --pace x10 --view`), watched by Debian's chromium, headless,
//!   through chromedriver; the page measures each curve from the wall-clock time of its `E`
//!   (in the `network` event) to its network drawn. Beside it, the daemon's own figure (E to
//!   `network.glb` in place, `report.json` `live.latency_ms`). And, issue 35, each curve's
//!   time from its `E` to its curves drawn before their surface (the `curves` event), against
//!   the surface drawn. Needs chromium and chromedriver.
//! - **stalled**: the daemon's own latency on the same replay (seed 1) with nobody looking,
//!   and with 200 clients that ask for the event stream and never read a byte (32 are
//!   served, the rest refused), alternately, three runs each.

#[path = "../tests/common/view.rs"]
#[allow(dead_code)]
mod view;
#[path = "../tests/common/webdriver.rs"]
#[allow(dead_code)]
mod webdriver;

use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::report::Percentiles;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Acquires `bytes` with the preview `on`, publishing it to `view` every `period` s of session
/// time; wall time, s.
fn acquire(bytes: &[u8], on: bool, view: &sfs::view::View, period: f64) -> f64 {
    let t0 = Instant::now();
    let mut dec = device_protocol::Decoder::new();
    let mut acq = Acquisition::new(AcquisitionConfig {
        preview: on,
        ..Default::default()
    });
    let mut next = 0.0;
    for e in dec.feed(bytes) {
        acq.event(&e);
        if on && acq.session_time() >= next {
            next = acq.session_time() + period;
            if acq.curve_open() {
                view.preview(acq.preview());
            }
        }
    }
    std::hint::black_box(acq.finish());
    t0.elapsed().as_secs_f64()
}

fn preview() {
    let path = root().join("replay-logs/bowl-phone.bin");
    let bytes = std::fs::read(&path).unwrap();
    let view = sfs::view::View::new("bench", sfs::metrics::SessionMetrics::new(None));
    let scan = Acquisition::scan_bytes(&bytes, AcquisitionConfig::default());
    let samples: usize = scan.counts.samples as usize;
    let duration = scan
        .curves
        .iter()
        .flat_map(|c| c.samples.t.last())
        .fold(0.0f64, |a, &b| a.max(b));
    let best = |on: bool| {
        (0..7)
            .map(|_| acquire(&bytes, on, &view, 0.1))
            .fold(f64::INFINITY, f64::min)
    };
    let (off, on) = (best(false), best(true));
    let share = (on - off).max(0.0) / duration;
    println!(
        "preview, {}: {samples} samples over {duration:.0} s of session ({:.0} Hz)",
        path.display(),
        samples as f64 / duration
    );
    println!(
        "  acquisition without preview {:.1} ms, with preview published every 0.1 s {:.1} ms",
        off * 1e3,
        on * 1e3
    );
    println!(
        "  preview cost: {:.3} ms per second of capture = {:.4} % of one core (target ≤ 2 %)",
        share * 1e3,
        share * 100.0
    );
}

/// Simulates the LILIUM scene (Morphorider) with `seed` into `dir`; the capture's path.
fn lilium(seed: u64, dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let prefix = dir.join("lilium");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "warn", "simulate", "--scene", "lilium", "--seed"])
        .arg(seed.to_string())
        .arg("--out")
        .arg(&prefix)
        .current_dir(root())
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    prefix.with_extension("bin")
}

/// Waits until the view at `port` answers.
async fn served(port: u16) {
    let t0 = Instant::now();
    while reqwest::get(format!("http://127.0.0.1:{port}/status"))
        .await
        .is_err()
    {
        assert!(t0.elapsed() < Duration::from_secs(20), "no view served");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// `OUT/report.json` once the replay has ended.
fn ended(out: &Path) -> serde_json::Value {
    tokio::task::block_in_place(|| view::ended_report(out, Duration::from_secs(600)))
}

/// The daemon's `live.latency_ms` on `capture` at ×10 with `clients` stalled event streams.
async fn daemon_latency(capture: &Path, out: &Path, clients: usize) -> serde_json::Value {
    let _ = std::fs::remove_dir_all(out);
    let port = view::free_port();
    let mut daemon = view::serve_replay(capture, out, Some("x10"), port, &[]);
    served(port).await;
    let mut stalled = Vec::new();
    for _ in 0..clients {
        use std::io::Write;
        if let Ok(mut s) = std::net::TcpStream::connect(("127.0.0.1", port)) {
            let req = format!("GET /events HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n");
            let _ = s.write_all(req.as_bytes());
            stalled.push(s);
        }
    }
    let report = ended(out);
    view::interrupt(&mut daemon);
    drop(stalled);
    report["live"]["latency_ms"].clone()
}

fn stalled() {
    let dir = root().join("target/bench-view/stalled");
    let capture = lilium(1, &dir);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    println!("stalled clients, LILIUM seed 1 at x10 with surfacing: the daemon's E to network.glb");
    for run in 1..=3 {
        for clients in [0, 200] {
            let l = rt.block_on(daemon_latency(&capture, &dir.join("out"), clients));
            println!(
                "  run {run}, {clients:>3} stalled clients: p50 {:.0} / p95 {:.0} ms",
                l["p50"].as_f64().unwrap_or(f64::NAN),
                l["p95"].as_f64().unwrap_or(f64::NAN)
            );
        }
    }
}

/// What one replay measured.
struct Measured {
    /// Per curve: E to drawn in the page, and the `network` event's arrival to drawn, ms.
    page: Vec<(f64, f64)>,
    /// Per curve: E to its curves drawn before their surface (the `curves` event, issue 35), ms.
    curves: Vec<f64>,
    /// `report.json` `live` (`latency_ms`, `curves_latency_ms`).
    daemon: serde_json::Value,
    /// `preview` events the page received per second of wall time a curve was open.
    preview_hz: f64,
}

async fn latency_of(seed: u64, dir: &Path) -> Measured {
    let capture = lilium(seed, dir);
    let browser = webdriver::Browser::start(&dir.join("profile")).await;
    let port = view::free_port();
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    let mut daemon = view::serve_replay(&capture, &out, Some("x10"), port, &[]);
    served(port).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let report = ended(&out);
    let state = browser
        .watch(Duration::from_secs(30), |s| {
            s["events"]["network"].as_u64() >= s["events"]["curve"].as_u64()
                && s["latencies"].as_array().map(Vec::len)
                    == s["events"]["curve"].as_u64().map(|n| n as usize)
                && s["curveLatencies"].as_array().map(Vec::len)
                    == s["events"]["curve"].as_u64().map(|n| n as usize)
        })
        .await
        .pop()
        .unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    browser.close().await;
    view::interrupt(&mut daemon);
    let page: Vec<(f64, f64)> = state["latencies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| (l["ms"].as_f64().unwrap(), l["page_ms"].as_f64().unwrap()))
        .collect();
    let curves: Vec<f64> = state["curveLatencies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["ms"].as_f64().unwrap())
        .collect();
    // Curves were open for their samples at the device's rate, replayed 10 times faster.
    let rate = report["link"]["hello"]["rate_hz"].as_f64().unwrap_or(100.0);
    let open_s: f64 = report["curves"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["samples"].as_f64().unwrap() / rate / 10.0)
        .sum();
    Measured {
        page,
        curves,
        daemon: report["live"].clone(),
        preview_hz: state["events"]["preview"].as_f64().unwrap() / open_s,
    }
}

fn latency() {
    if !webdriver::installed() {
        eprintln!("view latency: not measured, chromium or chromedriver is not installed");
        return;
    }
    let seeds: Vec<u64> = std::env::var("SFS_BENCH_SEEDS")
        .unwrap_or_else(|_| "1,2,3".into())
        .split(',')
        .map(|s| {
            s.trim()
                .parse()
                .expect("SFS_BENCH_SEEDS: seeds separated by commas")
        })
        .collect();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    println!("latency, LILIUM Morphorider at x10 with surfacing, E to the network drawn in the page (target p95 <= 150 ms)");
    for seed in seeds {
        let dir = root().join(format!("target/bench-view/seed-{seed}"));
        let Measured {
            page,
            curves,
            daemon,
            preview_hz,
        } = rt.block_on(latency_of(seed, &dir));
        let total: Vec<f64> = page.iter().map(|l| l.0).collect();
        let own: Vec<f64> = page.iter().map(|l| l.1).collect();
        let (p, o, c) = (
            Percentiles::of(&total),
            Percentiles::of(&own),
            Percentiles::of(&curves),
        );
        let ms = |what: &str, k: &str| daemon[what][k].as_f64().unwrap_or(f64::NAN);
        println!(
            "  seed {seed}: E to drawn, {} curves: p50 {:.0} / p95 {:.0} / max {:.0} ms; of which the page (event to drawn) p50 {:.0} / p95 {:.0} ms; daemon (E to network.glb) p50 {:.0} / p95 {:.0} ms",
            p.n, p.p50, p.p95, p.max, o.p50, o.p95, ms("latency_ms", "p50"), ms("latency_ms", "p95")
        );
        println!(
            "    E to the curves drawn (issue 35): p50 {:.0} / p95 {:.0} / max {:.0} ms, p95 {:.2} x that of the surface drawn (target <= 0.4); daemon (E to the curves published) p50 {:.1} / p95 {:.1} ms",
            c.p50, c.p95, c.max, c.p95 / p.p95, ms("curves_latency_ms", "p50"), ms("curves_latency_ms", "p95")
        );
        println!("    E to drawn per curve, ms: {total:.0?}");
        println!("    E to the curves drawn per curve, ms: {curves:.0?}");
        println!("    of which the page, ms: {own:.0?}");
        println!(
            "    preview events while a curve was open: {preview_hz:.1} per second (target >= 5)"
        );
    }
}

fn main() {
    let which: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let wants = |part: &str| which.is_empty() || which.iter().any(|w| w == part);
    if wants("preview") {
        preview();
    }
    if wants("latency") {
        latency();
    }
    if wants("stalled") {
        stalled();
    }
}
