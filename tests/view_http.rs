//! Issue 16, the live view over HTTP: a shipped replay served with `--view` (the real binary,
//! a real HTTP client): routes and content types, the event sequence (one `curve` and one
//! `network` event per accepted curve, the warnings of report.json), `/network.glb` identical
//! to the file, 404 outside the routes, the limit on event streams, a stalled client.

mod common;
use common::view::{ended_report, free_port, interrupt, Served};
use common::*;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A free loopback port (bound, then released).
/// `sfs replay replay-logs/LOG` served with its view.
fn serve_replay(log: &str, out: &Path, pace: &str, port: u16) -> Served {
    common::view::serve_replay(
        &root().join("replay-logs").join(log),
        out,
        Some(pace),
        port,
        &[],
    )
}

/// The event stream of `url`, read until `until` says so (or 60 s pass): `(event, data)`.
async fn read_events(
    resp: reqwest::Response,
    mut until: impl FnMut(&str, &serde_json::Value) -> bool,
) -> Vec<(String, serde_json::Value)> {
    let mut resp = resp;
    let mut buf = String::new();
    let mut out = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        let chunk = tokio::time::timeout(Duration::from_secs(5), resp.chunk()).await;
        let Ok(Ok(Some(bytes))) = chunk else { break };
        buf.push_str(&String::from_utf8_lossy(&bytes));
        while let Some(k) = buf.find("\n\n") {
            let block: String = buf.drain(..k + 2).collect();
            let mut name = String::new();
            let mut data = String::new();
            for line in block.lines() {
                if let Some(v) = line.strip_prefix("event:") {
                    name = v.trim().to_string();
                } else if let Some(v) = line.strip_prefix("data:") {
                    data.push_str(v.trim_start());
                }
            }
            if name.is_empty() {
                continue; // a keep-alive comment
            }
            let v: serde_json::Value = serde_json::from_str(&data).unwrap_or_default();
            let stop = until(&name, &v);
            out.push((name, v));
            if stop {
                return out;
            }
        }
    }
    out
}

async fn connect(url: &str) -> reqwest::Response {
    let t0 = Instant::now();
    loop {
        if let Ok(r) = reqwest::get(url).await {
            return r;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "{url} never answered"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

fn content_type(r: &reqwest::Response) -> String {
    r.headers()[reqwest::header::CONTENT_TYPE]
        .to_str()
        .unwrap()
        .to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_16_a_replay_is_served_with_its_events_and_routes() {
    let dir = tmpdir("view-http");
    let out = dir.join("out");
    let port = free_port();
    let mut child = serve_replay("cone-morphorider.bin", &out, "x20", port);
    let base = format!("http://127.0.0.1:{port}");
    let events = connect(&format!("{base}/events")).await;
    assert_eq!(events.status(), 200);
    assert!(content_type(&events).starts_with("text/event-stream"));
    let seen = read_events(events, |name, v| name == "status" && v["state"] == "ended").await;
    // The outputs are written: compare with them.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let accepted = report["curves"].as_array().unwrap().len();
    assert!(accepted >= 5, "{accepted} curves");
    let names = |n: &str| seen.iter().filter(|(e, _)| e == n).count();
    assert_eq!(seen[0].0, "status", "the first event is the status");
    assert_eq!(
        names("curve"),
        accepted,
        "one curve event per accepted curve"
    );
    // One network event per accepted curve, and one per settled surface (issue 19), which
    // ends no curve.
    let ending = seen
        .iter()
        .filter(|(e, v)| e == "network" && v["ended"].as_array().is_some_and(|a| !a.is_empty()))
        .count();
    assert_eq!(ending, accepted, "one network event per accepted curve");
    assert_eq!(
        names("network") - ending,
        report["live"]["settled"].as_u64().unwrap() as usize,
        "one network event per settled surface"
    );
    let curves: Vec<u64> = seen
        .iter()
        .filter(|(e, _)| e == "curve")
        .map(|(_, v)| v["index"].as_u64().unwrap())
        .collect();
    assert_eq!(curves, (0..accepted as u64).collect::<Vec<_>>());
    // Each curve's network event follows its curve event.
    let order: Vec<&str> = seen
        .iter()
        .filter(|(e, v)| {
            e == "curve" || (e == "network" && v["ended"].as_array().is_some_and(|a| !a.is_empty()))
        })
        .map(|(e, _)| e.as_str())
        .collect();
    assert!(
        order.chunks(2).all(|p| p == ["curve", "network"]),
        "{order:?}"
    );
    let mut warned: Vec<String> = seen
        .iter()
        .filter(|(e, _)| e == "warning")
        .map(|(_, v)| v["text"].as_str().unwrap().to_string())
        .collect();
    let mut expected: Vec<String> = report["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    warned.sort();
    expected.sort();
    assert_eq!(warned, expected, "the warnings of report.json");
    // The curve being scanned, integrated as it comes: previews of every curve, the first
    // from the origin (no network yet), each polyline growing.
    let previews: Vec<&serde_json::Value> = seen
        .iter()
        .filter(|(e, v)| e == "preview" && !v.is_null())
        .map(|(_, v)| v)
        .collect();
    let mut previewed: Vec<u64> = previews
        .iter()
        .map(|v| v["curve"].as_u64().unwrap())
        .collect();
    previewed.dedup();
    assert_eq!(previewed, (0..accepted as u64).collect::<Vec<_>>());
    assert_eq!(previews[0]["points"][0], serde_json::json!([0.0, 0.0, 0.0]));
    let lengths: Vec<usize> = previews
        .iter()
        .filter(|v| v["curve"] == 0)
        .map(|v| v["points"].as_array().unwrap().len())
        .collect();
    assert!(
        lengths.windows(2).all(|w| w[1] >= w[0]) && lengths.last() > Some(&50),
        "{lengths:?}"
    );
    // Status events at 5 Hz while the replay ran (about 6 s at x20).
    assert!(names("status") >= 20, "{} status events", names("status"));

    // Routes and content types, while the ended replay is still served.
    let get = |path: &str| reqwest::get(format!("{base}{path}"));
    let glb = get("/network.glb").await.unwrap();
    assert_eq!(content_type(&glb), "model/gltf-binary");
    assert_eq!(
        glb.bytes().await.unwrap().as_ref(),
        std::fs::read(out.join("network.glb")).unwrap().as_slice()
    );
    for (path, kind) in [
        ("/", "text/html"),
        ("/assets/view.js", "text/javascript"),
        ("/assets/three/three.module.js", "text/javascript"),
        ("/assets/three/LICENSE", "text/plain"),
        ("/status", "application/json"),
        ("/metrics", "application/openmetrics-text"),
    ] {
        let r = get(path).await.unwrap();
        assert_eq!(r.status(), 200, "{path}");
        assert!(
            content_type(&r).starts_with(kind),
            "{path}: {}",
            content_type(&r)
        );
    }
    let status: serde_json::Value = get("/status").await.unwrap().json().await.unwrap();
    assert_eq!(status["state"], "ended");
    assert_eq!(status["curves_accepted"], accepted);
    assert_eq!(status["link"]["bytes"], report["link"]["bytes"]);
    // Per curve the closure misfit of report.json (mm), with its marked tags.
    let closure = report["network"]["closure"].as_array().unwrap();
    assert_eq!(closure.len(), accepted, "the cone's network has loops");
    let shown = status["closure"].as_array().unwrap();
    assert_eq!(shown.len(), closure.len());
    for (s, r) in shown.iter().zip(closure) {
        assert_eq!(s["curve"], r["curve"]);
        let mm = r["misfit_m"].as_f64().unwrap() * 1e3;
        assert!(
            (s["misfit_mm"].as_f64().unwrap() - mm).abs() <= 0.051,
            "{s} {r}"
        );
        let marked: Vec<&serde_json::Value> = r["tags"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|t| t["marked"] == true)
            .map(|t| &t["node"])
            .collect();
        let shown_marked: Vec<&serde_json::Value> = s["marked"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| &t["node"])
            .collect();
        assert_eq!(shown_marked, marked);
    }
    // The device's orientation: unit direction of travel and normal, at right angles.
    let axis = |k: &str| -> Vec<f64> {
        status["orientation"][k]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (t, n) = (axis("t"), axis("n"));
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    assert!((dot(&t, &t) - 1.0).abs() < 1e-5 && (dot(&n, &n) - 1.0).abs() < 1e-5);
    assert!(dot(&t, &n).abs() < 1e-5, "{t:?} {n:?}");
    let metrics = get("/metrics").await.unwrap().text().await.unwrap();
    assert!(
        metrics.contains(&format!("sfs_curves_accepted_total {accepted}")),
        "{metrics}"
    );
    assert!(metrics.contains(&format!(
        "sfs_link_received_bytes_total {}",
        report["link"]["bytes"]
    )));
    for path in [
        "/nope",
        "/assets/nope.js",
        "/assets/../Cargo.toml",
        "/assets/%2e%2e/%2e%2e/Cargo.toml",
        "/network.glb/x",
    ] {
        assert_eq!(get(path).await.unwrap().status(), 404, "{path}");
    }
    // The view is read-only.
    let post = reqwest::Client::new()
        .post(format!("{base}/status"))
        .send()
        .await
        .unwrap();
    assert_eq!(post.status(), 405);

    // At most 32 event streams at once; the next is refused.
    let mut open = Vec::new();
    for _ in 0..32 {
        let r = get("/events").await.unwrap();
        assert_eq!(r.status(), 200);
        open.push(r);
    }
    assert_eq!(get("/events").await.unwrap().status(), 503);
    drop(open);
    let t0 = Instant::now();
    while get("/events").await.unwrap().status() != 200 {
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "streams not released"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    interrupt(&mut child);
}

/// A client that opens the event stream and never reads it changes neither the capture nor
/// the outputs of a replay.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_16_a_stalled_client_changes_nothing() {
    let dir = tmpdir("view-stalled");
    let port = free_port();
    let mut child = serve_replay("cone-morphorider.bin", &dir.join("viewed"), "x50", port);
    // A raw connection that asks for the events and never reads a byte.
    let stalled = {
        let t0 = Instant::now();
        loop {
            if let Ok(mut s) = std::net::TcpStream::connect(("127.0.0.1", port)) {
                use std::io::Write;
                let req = format!("GET /events HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n");
                s.write_all(req.as_bytes()).unwrap();
                break s;
            }
            assert!(t0.elapsed() < Duration::from_secs(20));
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    let t0 = Instant::now();
    loop {
        let s: Option<serde_json::Value> =
            match reqwest::get(format!("http://127.0.0.1:{port}/status")).await {
                Ok(r) => r.json().await.ok(),
                Err(_) => None,
            };
        if s.is_some_and(|s| s["state"] == "ended") {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the replay did not end"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    interrupt(&mut child);
    drop(stalled);
    let plain = dir.join("plain");
    replay_to(&root().join("replay-logs/cone-morphorider.bin"), &plain);
    assert_same_files(
        &dir.join("viewed"),
        &plain,
        &["scan.json", "network.glb"],
        "viewed by a stalled client",
    );
}

/// Issue 35: each update publishes its network before its surface. A shipped replay served
/// with every update's network exact (`[network] local_window = 0`, so that the last update's
/// network is the outputs'): every update that brings curves in sends a `curves` event (the
/// same update number and curves) before its `network` event; the last one draws the curves
/// of the final `network.glb`; report.json's `live.curves_latency_ms` counts every curve, each
/// percentile below `latency_ms`'s.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_35_each_update_publishes_its_curves_before_its_surface() {
    let dir = tmpdir("view-curves");
    let out = dir.join("out");
    let config = dir.join("exact.toml");
    std::fs::write(&config, "[network]\nlocal_window = 0\n").unwrap();
    let port = free_port();
    let cfg = config.to_str().unwrap();
    let _child = common::view::serve_replay(
        &root().join("replay-logs/cone-morphorider.bin"),
        &out,
        Some("x20"),
        port,
        &["--config", cfg],
    );
    let events = connect(&format!("http://127.0.0.1:{port}/events")).await;
    let seen = read_events(events, |name, v| name == "status" && v["state"] == "ended").await;
    let report = ended_report(&out, Duration::from_secs(20));
    let accepted = report["curves"].as_array().unwrap().len();
    let ending = |v: &serde_json::Value| v["ended"].as_array().is_some_and(|a| !a.is_empty());
    // The updates that bring curves in, in order: (event, update, curves ended).
    let updates: Vec<(&str, u64, Vec<u64>)> = seen
        .iter()
        .filter(|(e, v)| (e == "curves" || e == "network") && ending(v))
        .map(|(e, v)| {
            let ended = v["ended"].as_array().unwrap().iter();
            (
                e.as_str(),
                v["update"].as_u64().unwrap(),
                ended.map(|x| x["curve"].as_u64().unwrap()).collect(),
            )
        })
        .collect();
    assert_eq!(updates.len(), 2 * accepted, "{updates:?}");
    for pair in updates.chunks(2) {
        assert_eq!(pair[0].0, "curves", "{updates:?}");
        assert_eq!(pair[1].0, "network", "{updates:?}");
        assert_eq!(
            (pair[0].1, &pair[0].2),
            (pair[1].1, &pair[1].2),
            "{updates:?}"
        );
    }
    // The last curves event draws the final network's curves (to 0.01 mm).
    let last = &seen.iter().rev().find(|(e, _)| e == "curves").unwrap().1;
    let glb = sfs::gltf_out::read_glb(&std::fs::read(out.join("network.glb")).unwrap()).unwrap();
    let drawn = last["curves"].as_array().unwrap();
    assert_eq!(drawn.len(), glb.curves.len());
    for (d, c) in drawn.iter().zip(&glb.curves) {
        assert_eq!(d["curve"].as_u64(), Some(c.index as u64));
        assert_eq!(d["kind"], c.kind.name());
        assert_eq!(d["nodes"], serde_json::json!(c.nodes));
        let points = d["points"].as_array().unwrap();
        assert_eq!(points.len(), c.points.len(), "curve {}", c.index);
        for (p, q) in points.iter().zip(&c.points) {
            let q = sfs::gltf_out::to_gltf(q);
            for k in 0..3 {
                let x = p[k].as_f64().unwrap();
                assert!(
                    (x - q[k] as f64).abs() < 1e-5 + 1e-6,
                    "curve {}: {p} {q:?}",
                    c.index
                );
            }
        }
    }
    let nodes = last["nodes"].as_object().unwrap();
    assert_eq!(nodes.len(), glb.nodes.len());
    // Every curve's two latencies, the curves' first.
    let live = &report["live"];
    let (curves, all) = (&live["curves_latency_ms"], &live["latency_ms"]);
    assert_eq!(curves["n"].as_u64(), Some(accepted as u64), "{live}");
    assert_eq!(all["n"].as_u64(), Some(accepted as u64), "{live}");
    for p in ["p50", "p95", "max"] {
        let (c, a) = (curves[p].as_f64().unwrap(), all[p].as_f64().unwrap());
        assert!(c > 0.0 && c < a, "{p}: curves {c} ms, update {a} ms");
    }
}

/// Issue 50 point 3: a monitoring session's view. `/network.glb` is the structure's latest
/// shape, the bytes of `latest.glb`; `/status` carries `monitor` (the latest epoch, the
/// reference, the alarms and every sensor's health); `/monitor.json` the shape and its
/// reference with each point's displacement.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_50_a_monitoring_session_is_served_as_a_structure() {
    let dir = tmpdir("view-monitor");
    let out = dir.join("out");
    let (port, mut served) = common::view::serve_replay_on_a_free_port(
        &root().join("replay-logs/riser-array.bin"),
        &out,
        None,
        &[
            "--config",
            root().join("config/riser.toml").to_str().unwrap(),
        ],
    );
    let report = ended_report(&out, Duration::from_secs(60));
    let at = |p: &str| format!("http://127.0.0.1:{port}{p}");
    let glb = reqwest::get(at("/network.glb")).await.unwrap();
    assert_eq!(glb.status(), 200);
    let glb = glb.bytes().await.unwrap();
    assert_eq!(
        &glb[..],
        &std::fs::read(out.join("latest.glb")).unwrap()[..]
    );
    let status: serde_json::Value = reqwest::get(at("/status"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let m = &status["monitor"];
    assert_eq!(m["epochs"], report["monitor"]["epochs"], "{m}");
    assert_eq!(m["reference_ready"], true, "{m}");
    let layout = std::fs::read_to_string(root().join("config/riser.toml")).unwrap();
    let placed = layout.matches("\nsensor = ").count();
    let sensors = m["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), placed, "{m}");
    assert!(sensors.iter().all(|s| s["health"] == "ok"), "{m}");
    assert_eq!(m["last"], report["monitor"]["last"]);
    let alarms = m["alarms"].as_array().unwrap();
    assert_eq!(
        alarms.len(),
        layout.matches("[[monitor.alarm]]").count(),
        "{m}"
    );
    assert!(
        alarms
            .iter()
            .all(|a| a["metric"].is_string() && a["raised"].is_boolean()),
        "{m}"
    );
    let shape: serde_json::Value = reqwest::get(at("/monitor.json"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let curves = shape["curves"].as_array().unwrap();
    assert!(!curves.is_empty());
    assert_eq!(shape["reference"].as_array().unwrap().len(), curves.len());
    let mut largest = 0f64;
    for c in curves {
        let d = c["displacement_m"]
            .as_array()
            .expect("displacement per point");
        assert_eq!(d.len(), c["points"].as_array().unwrap().len());
        for v in d {
            let v = v.as_f64().unwrap();
            assert!(v.is_finite() && v >= 0.0);
            largest = largest.max(v);
        }
    }
    // The shape drawn is the last epoch's: its largest displacement is the report's (to f32).
    let max = report["monitor"]["last"]["max_displacement"]
        .as_f64()
        .unwrap();
    assert!(
        (largest - max).abs() <= 1e-6 + 1e-5 * max,
        "{largest} vs {max}"
    );
    interrupt(&mut served);
}
