//! Issue 16, the live view in a real browser: Debian's chromium, headless (WebGL through
//! SwiftShader), driven through chromedriver (W3C WebDriver), reading the page's
//! `window.sfsView`:
//! - the page of a replayed session: no error on the console, the scene holds the session's
//!   curves, nodes, surface and closure marks (`target/view/cone.png` for a person to look at);
//! - a session watched while it runs: the curve being scanned drawn dashed and growing, every
//!   curve's network drawn after its `E`, the preview replaced by it
//!   (`target/view/live.png`, taken mid-curve).
//!
//! Skipped when chromium or chromedriver is not installed, unless `SFS_REQUIRE_BROWSER` is set
//! (`.ci/run` installs both and sets it).

mod common;
use common::view::{ended_report, serve_ended, serve_replay_on_a_free_port};
use common::webdriver::{available, Browser};
use common::*;
use std::path::PathBuf;
use std::time::Duration;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The curves of `report.json`, their boundary flags and nodes; the marked tags of its
/// closure misfit as (curve, node), sorted.
fn expected(report: &serde_json::Value) -> (usize, usize, Vec<u64>, Vec<(u64, u64)>) {
    let curves = report["curves"].as_array().unwrap();
    let boundary = curves.iter().filter(|c| c["boundary"] == true).count();
    let mut nodes: Vec<u64> = curves
        .iter()
        .flat_map(|c| c["nodes"].as_array().unwrap())
        .map(|n| n.as_u64().unwrap())
        .collect();
    nodes.sort();
    nodes.dedup();
    let mut marked: Vec<(u64, u64)> = report["network"]["closure"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| {
            c["tags"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|t| t["marked"] == true)
                .map(|t| (c["curve"].as_u64().unwrap(), t["node"].as_u64().unwrap()))
        })
        .collect();
    marked.sort();
    (curves.len(), boundary, nodes, marked)
}

/// What the page drew, in the same terms.
fn drawn(state: &serde_json::Value) -> (usize, usize, Vec<u64>, Vec<(u64, u64)>) {
    let curves = state["curves"].as_array().unwrap();
    let boundary = curves.iter().filter(|c| c["boundary"] == true).count();
    let mut nodes: Vec<u64> = state["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap())
        .collect();
    nodes.sort();
    let mut marked: Vec<(u64, u64)> = state["marked"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["curve"].as_u64().unwrap(), t["node"].as_u64().unwrap()))
        .collect();
    marked.sort();
    (curves.len(), boundary, nodes, marked)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_16_the_page_shows_a_replayed_session_in_a_real_browser() {
    available();
    let dir = tmpdir("view-browser");
    let out = dir.join("out");
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/cone-morphorider.bin"),
        &out,
        None,
        &[],
    );
    // The replay ends (and keeps serving).
    let report = ended_report(&out, Duration::from_secs(60));
    let browser = Browser::start(&dir.join("profile")).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let seen = browser
        .watch(Duration::from_secs(30), |s| {
            s["updates"].as_u64() >= Some(1) && s["events"]["status"].as_u64() >= Some(1)
        })
        .await;
    let state = seen.last().unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    assert_eq!(state["ready"], true);
    assert_eq!(drawn(state), expected(&report));
    assert_eq!(
        state["closure"].as_array().unwrap().len(),
        report["network"]["closure"].as_array().unwrap().len()
    );
    assert_eq!(
        state["surfaceTriangles"], report["surface"]["triangles"],
        "{}",
        report["surface"]
    );
    assert!(state["orientation"]["t"].is_array(), "no device glyph");
    // Opened after the end, the page lists the latest warnings of the session.
    let warnings = report["warnings"].as_array().unwrap().len().min(20);
    assert_eq!(state["warnings"].as_u64(), Some(warnings as u64));
    let png = root().join("target/view/cone.png");
    browser.screenshot(&png).await;
    let bytes = std::fs::read(&png).unwrap();
    assert!(
        bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
        "{} bytes",
        bytes.len()
    );
    browser.close().await;
}

/// The page watched while the session runs (the cone replayed at ×5, about 30 s): the dashed
/// preview grows while a curve is scanned; after each `E` the page fetches and draws the new
/// network (one per curve it saw end), and the preview gives way to it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_16_a_running_session_is_drawn_as_it_is_scanned() {
    available();
    let dir = tmpdir("view-browser-live");
    let browser = Browser::start(&dir.join("profile")).await;
    let out = dir.join("out");
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/cone-morphorider.bin"),
        &out,
        Some("x5"),
        &[],
    );
    let status = format!("http://127.0.0.1:{port}/status");
    let t0 = std::time::Instant::now();
    while reqwest::get(&status).await.is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "no view served");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let png = root().join("target/view/live.png");
    let mut shot = false;
    let mut longest_preview = 0;
    let mut preview_grew = false;
    let mut last_preview = 0;
    let mut states = Vec::new();
    let t0 = std::time::Instant::now();
    loop {
        let s = browser.view_state().await;
        let points = s["previewPoints"].as_u64().unwrap_or(0);
        preview_grew |= points > last_preview && last_preview > 0;
        last_preview = points;
        longest_preview = longest_preview.max(points);
        if !shot && points > 100 && s["updates"].as_u64() >= Some(2) {
            // Mid-curve, with a network drawn: for a person to look at.
            browser.screenshot(&png).await;
            shot = true;
        }
        let ended = std::fs::read(out.join("report.json"))
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
            .is_some_and(|r| r["ended"] == "end_of_input");
        states.push(s);
        if ended {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "{}",
            states.last().unwrap()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // The last network: give the page the time to fetch it.
    let report = ended_report(&out, Duration::from_secs(5));
    // (The closure marks come with the status, within 0.2 s of the network.)
    let want = expected(&report);
    let accepted = want.0 as u64;
    let last = browser
        .watch(Duration::from_secs(20), |s| {
            // Every curve seen ending was drawn (a network event ends it; a settled surface
            // comes as a network event of its own, ending none: issue 19), and the last
            // network is the one the outputs hold.
            s["latencies"].as_array().map(|a| a.len() as u64) == s["events"]["curve"].as_u64()
                && drawn(s) == want
        })
        .await
        .pop()
        .unwrap();
    assert_eq!(last["errors"], serde_json::json!([]), "console errors");
    // The page connected during the first curve: it saw (nearly) every curve end.
    let seen = last["events"]["curve"].as_u64().unwrap();
    assert!(seen + 1 >= accepted, "saw {seen} of {accepted} curves end");
    // Each curve it saw end was drawn, with the time from its E to the page.
    let latencies = last["latencies"].as_array().unwrap();
    assert_eq!(latencies.len() as u64, seen, "{last}");
    for l in latencies {
        let ms = l["ms"].as_f64().unwrap();
        assert!(ms > 0.0 && ms < 30_000.0, "{l}");
    }
    // Issue 35: each of them was drawn first without its surface (the `curves` event), sooner.
    let curve_latencies = last["curveLatencies"].as_array().unwrap();
    assert_eq!(curve_latencies.len(), latencies.len(), "{last}");
    for (c, l) in curve_latencies.iter().zip(latencies) {
        assert_eq!(c["curve"], l["curve"]);
        let (c_ms, l_ms) = (c["ms"].as_f64().unwrap(), l["ms"].as_f64().unwrap());
        assert!(
            c_ms > 0.0 && c_ms < l_ms,
            "curves drawn {c_ms} ms, surface {l_ms} ms"
        );
    }
    // The curve being scanned was drawn, growing, and replaced by the network at the end.
    assert!(longest_preview > 100, "{longest_preview} preview points");
    assert!(preview_grew, "the preview never grew");
    assert_eq!(last["previewPoints"], 0);
    assert!(shot, "no moment with a preview and a network to photograph");
    browser.close().await;
}

/// Issue 34: the view marks the joins. A cone scanned with a third of its crossings untagged
/// (Morphorider, seed 1), replayed with the view: the page lists every join of report.json's
/// `network.joined` and marks each joined node and each proposed crossing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_34_the_page_marks_the_joined_nodes() {
    use sfs::simulate::{self, scene};
    available();
    let dir = tmpdir("view-browser-joins");
    let s = scene::builtin("cone").unwrap();
    let m = simulate::Mistakes {
        untagged: simulate::untagged_crossings(&s, 1.0 / 3.0, 1),
        ..Default::default()
    };
    let sim = simulate::run_with(
        &s,
        device_protocol::DeviceKind::Morphorider,
        simulate::Profile::Default,
        1,
        &m,
    );
    let (port, _served, report) = serve_ended(&dir, "cone-untagged", &sim.bytes);
    let joined = report["network"]["joined"].as_array().unwrap().len();
    let proposed = report["network"]["proposed"].as_array().unwrap().len();
    assert!(joined > 0, "{}", report["network"]["joined"]);
    let browser = Browser::start(&dir.join("profile")).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let seen = browser
        .watch(Duration::from_secs(30), |s| {
            s["joins"]["joined"].as_array().map(|a| a.len()) == Some(joined)
                && s["joinMarks"].as_u64() == Some((joined + proposed) as u64)
        })
        .await;
    let state = seen.last().unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    for (a, b) in state["joins"]["joined"]
        .as_array()
        .unwrap()
        .iter()
        .zip(report["network"]["joined"].as_array().unwrap())
    {
        assert_eq!((&a["node"], &a["curve"]), (&b["node"], &b["curve"]));
    }
    browser.close().await;
}

/// Issue 49, point 1: the curves coloured by their points' uncertainty (the glb's `_SIGMA_M`),
/// with a legend in mm whose top is at or above the largest node σ of `report.json`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_49_the_view_colours_the_curves_by_their_uncertainty() {
    available();
    let dir = tmpdir("view-browser-sigma");
    let out = dir.join("out");
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/cone-morphorider.bin"),
        &out,
        None,
        &[],
    );
    let report = ended_report(&out, Duration::from_secs(60));
    let top_node_mm = report["nodes_sigma_m"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_f64().unwrap() * 1e3)
        .fold(0.0, f64::max);
    assert!(top_node_mm > 0.0, "{}", report["nodes_sigma_m"]);
    let browser = Browser::start(&dir.join("profile")).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    browser
        .watch(Duration::from_secs(30), |s| {
            s["updates"].as_u64() >= Some(1)
        })
        .await;
    let legend_hidden = "return document.getElementById('sigma-legend').hidden";
    assert_eq!(
        browser.execute(legend_hidden, serde_json::json!([])).await,
        true
    );
    let toggle = browser.find("#show-sigma").await;
    browser.click(&toggle).await;
    let seen = browser
        .watch(Duration::from_secs(10), |s| {
            s["sigmaScaleMm"].as_f64() > Some(0.0)
        })
        .await;
    let state = seen.last().unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    let curves = report["curves"].as_array().unwrap().len() as u64;
    assert_eq!(state["sigmaCurves"].as_u64(), Some(curves));
    let top = state["sigmaScaleMm"].as_f64().unwrap();
    assert!(
        top >= top_node_mm && top <= 10.0 * top_node_mm,
        "{top} mm for {top_node_mm} mm"
    );
    assert_eq!(
        browser.execute(legend_hidden, serde_json::json!([])).await,
        false
    );
    browser
        .screenshot(&root().join("target/view/sigma.png"))
        .await;
    browser.click(&toggle).await;
    let seen = browser
        .watch(Duration::from_secs(10), |s| {
            s["sigmaScaleMm"].as_f64() == Some(0.0)
        })
        .await;
    assert_eq!(seen.last().unwrap()["sigmaCurves"].as_u64(), Some(0));
    browser.close().await;
}

/// Issue 49, points 2 and 3: a late Enter planted in the cone: the page's bar says the scan
/// is `suspect` and its Suspects list the curve with the keys that rescan it, as
/// `report.json`'s `quality` does; `/status` carries the quality, `/metrics` the verdict's
/// gauge and the suspects' counter.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_49_the_page_shows_the_verdict_and_the_suspects() {
    use sfs::simulate::{self, planted::Planted, scene, Profile};
    available();
    let dir = tmpdir("view-browser-verdict");
    let s = scene::builtin("cone").unwrap();
    let sim = simulate::run_planted(
        &s,
        device_protocol::DeviceKind::Morphorider,
        Profile::Default,
        1,
        Planted::LateEnter,
    )
    .unwrap();
    let (port, _served, report) = serve_ended(&dir, "cone-late-enter", &sim.bytes);
    let q = &report["quality"];
    assert_eq!(q["verdict"], "suspect", "{q}");
    let suspects = q["suspects"].as_array().unwrap();
    let status: serde_json::Value = reqwest::get(format!("http://127.0.0.1:{port}/status"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(status["quality"]["verdict"], "suspect");
    assert_eq!(status["quality"]["suspects"], q["suspects"]);
    let metrics = reqwest::get(format!("http://127.0.0.1:{port}/metrics"))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(metrics.contains("sfs_scan_verdict 1"), "{metrics}");
    assert!(
        metrics.contains(&format!("sfs_suspects_total {}", suspects.len())),
        "{metrics}"
    );
    let browser = Browser::start(&dir.join("profile")).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let seen = browser
        .watch(Duration::from_secs(30), |s| s["verdict"] == "suspect")
        .await;
    let state = seen.last().unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    let drawn = state["suspects"].as_array().unwrap();
    assert_eq!(drawn.len(), suspects.len());
    for (a, b) in drawn.iter().zip(suspects) {
        assert_eq!(
            (&a["curve"], &a["kind"], &a["rescan"]),
            (&b["curve"], &b["kind"], &b["rescan"])
        );
    }
    let listed = browser
        .execute(
            "return document.getElementById('suspects').textContent",
            serde_json::json!([]),
        )
        .await;
    let listed = listed.as_str().unwrap();
    let rescan = suspects[0]["rescan"].as_str().unwrap();
    assert!(
        listed.contains(&format!("rescan with {rescan}")),
        "{listed}"
    );
    let pill = browser
        .execute(
            "return document.getElementById('verdict').textContent",
            serde_json::json!([]),
        )
        .await;
    assert!(pill.as_str().unwrap().starts_with("scan suspect"), "{pill}");
    browser.close().await;
}

/// Issue 48, point 2: the view opened on the machine that runs sfs shows the phone page's QR
/// code, its address with the token and the certificate's fingerprint (fetched from
/// `/status`, never from the `status` events, which carry no token).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_48_the_view_on_this_machine_shows_the_phone_address() {
    available();
    let dir = tmpdir("view-phone-address");
    let view_port = common::view::free_port();
    let d = common::phone::Daemon::start(
        &dir.join("session"),
        false,
        &["--view", &format!("127.0.0.1:{view_port}")],
    );
    let browser = Browser::start(&dir.join("profile")).await;
    browser
        .goto(&format!("http://127.0.0.1:{view_port}/"))
        .await;
    let t0 = std::time::Instant::now();
    let shown = loop {
        let v = browser
            .execute(
                "const a = document.getElementById('phone-url'), q = document.getElementById('phone-qr');
                 return [a.getAttribute('href'), q.naturalWidth, document.getElementById('phone-fingerprint').textContent,
                         document.getElementById('phone').hidden];",
                serde_json::json!([]),
            )
            .await;
        if v[0].is_string() && v[1].as_u64() > Some(0) {
            break v;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "not shown: {v}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    assert_eq!(shown[0], d.url.as_str());
    assert_eq!(shown[3], false);
    let fingerprint = shown[2].as_str().unwrap();
    assert_eq!(fingerprint.len(), 95, "{fingerprint}");
    browser.close().await;
    d.stop();
}

/// Issue 50 point 2: the view's banner turns red within 5 s of the device being unplugged,
/// says it is reconnecting, and turns green again when it is back.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_50_the_banner_turns_red_while_the_device_is_away() {
    use common::pty::{plug, write};
    available();
    let dir = tmpdir("view-link-lost");
    let link = dir.join("ttySFS");
    let port = common::view::free_port();
    let dev = plug(&link);
    let _served = common::view::serve_serial(&link, &dir.join("session"), port, &dir.join("log"));
    let browser = Browser::start(&dir.join("profile")).await;
    let t0 = std::time::Instant::now();
    while reqwest::get(format!("http://127.0.0.1:{port}/status"))
        .await
        .is_err()
    {
        assert!(t0.elapsed() < Duration::from_secs(20), "no view served");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let pill = |s: &serde_json::Value| (s["link"]["cls"].clone(), s["link"]["pill"].clone());
    browser
        .watch(Duration::from_secs(20), |s| {
            s["link"]["state"] == "connected" || s["link"]["state"] == "silent"
        })
        .await;
    let unplugged = std::time::Instant::now();
    drop(dev);
    std::fs::remove_file(&link).unwrap();
    let seen = browser
        .watch(Duration::from_secs(5), |s| s["link"]["cls"] == "lost")
        .await
        .pop()
        .unwrap();
    eprintln!(
        "the banner turned red {:?} after the unplug",
        unplugged.elapsed()
    );
    assert!(unplugged.elapsed() < Duration::from_secs(5));
    let (cls, text) = pill(&seen);
    assert_eq!(cls, "lost");
    assert!(text.as_str().unwrap().starts_with("device lost"), "{text}");
    let colour = browser
        .execute(
            "return getComputedStyle(document.getElementById('state')).backgroundColor;",
            serde_json::json!([]),
        )
        .await;
    assert_eq!(colour, "rgb(198, 40, 40)");
    let reconnecting = browser
        .watch(Duration::from_secs(5), |s| {
            s["link"]["state"] == "reconnecting"
        })
        .await
        .pop()
        .unwrap();
    assert!(
        reconnecting["link"]["pill"]
            .as_str()
            .unwrap()
            .contains("reconnecting (attempt"),
        "{}",
        reconnecting["link"]
    );
    // Back: green again.
    let mut dev = plug(&link);
    browser
        .watch(Duration::from_secs(10), |s| {
            s["link"]["state"] == "connected"
        })
        .await;
    let mut b = Builder::new();
    b.packet(hello());
    write(&mut dev, &b.bytes);
    let back = browser
        .watch(Duration::from_secs(5), |s| {
            s["link"]["cls"] == "running" || s["link"]["cls"] == "silent"
        })
        .await
        .pop()
        .unwrap();
    assert_eq!(back["errors"], serde_json::json!([]), "console errors");
    browser.close().await;
}

/// Issue 50 point 3: the view of a monitoring session shows the structure: its latest shape
/// coloured by displacement over its reference, the alarms and each sensor's health, and none
/// of the scanning interface (`target/view/monitor.png` for a person to look at).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_50_a_monitoring_session_shows_the_structure() {
    available();
    let dir = tmpdir("view-browser-monitor");
    let out = dir.join("out");
    let riser = root().join("config/riser.toml");
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/riser-array.bin"),
        &out,
        None,
        &["--config", riser.to_str().unwrap()],
    );
    let report = ended_report(&out, Duration::from_secs(60));
    let browser = Browser::start(&dir.join("profile")).await;
    browser.goto(&format!("http://127.0.0.1:{port}/")).await;
    let s = browser
        .watch(Duration::from_secs(20), |s| {
            s["monitor"].is_object() && s["monitorStatus"].is_object()
        })
        .await
        .pop()
        .unwrap();
    let m = &s["monitor"];
    let layout = std::fs::read_to_string(&riser).unwrap();
    assert!(m["curves"].as_u64().unwrap() > 0, "{m}");
    assert_eq!(
        m["coloured"], m["curves"],
        "every curve coloured by displacement: {m}"
    );
    assert_eq!(m["referenceCurves"], m["curves"], "{m}");
    let largest = m["largestMm"].as_f64().unwrap();
    let max = report["monitor"]["last"]["max_displacement"]
        .as_f64()
        .unwrap()
        * 1000.0;
    assert!(
        (largest - max).abs() < 0.01,
        "{largest} mm drawn, {max} mm in the report"
    );
    let sensors = s["monitorStatus"]["sensors"].as_object().unwrap();
    assert_eq!(sensors.len(), layout.matches("\nsensor = ").count());
    assert!(sensors.values().all(|h| h == "ok"), "{sensors:?}");
    // The scanning interface is not shown; the monitor's panel is.
    let shown = browser
        .execute(
            "const d = (id) => getComputedStyle(document.getElementById(id)).display;
             return { curve: d('curve'), accepted: d('accepted'), suspects: d('suspects'), closure: d('closure'),
                      monitor: d('monitor'), alarms: document.getElementById('alarms').textContent,
                      epoch: document.getElementById('monitor-epoch').textContent };",
            serde_json::json!([]),
        )
        .await;
    for id in ["curve", "accepted", "suspects", "closure"] {
        assert_eq!(shown[id], "none", "{id} shown: {shown}");
    }
    assert_ne!(shown["monitor"], "none", "{shown}");
    assert!(
        shown["alarms"]
            .as_str()
            .unwrap()
            .contains("max_displacement"),
        "{shown}"
    );
    assert!(
        shown["epoch"].as_str().unwrap().contains("epoch 300"),
        "{shown}"
    );
    assert_eq!(s["errors"], serde_json::json!([]), "console errors");
    browser
        .screenshot(&root().join("target/view/monitor.png"))
        .await;
    browser.close().await;
}
