//! Issue 16, the live view in a real browser: Debian's chromium, headless (WebGL through
//! SwiftShader), loads the page of a replayed session: no error on the console, the scene holds
//! the session's curves, nodes and surface, and a screenshot is written to
//! `target/view/cone.png` for a person to look at. Skipped when chromium is not installed,
//! unless `SFS_REQUIRE_BROWSER` is set (`.ci/run` installs it and sets it).

mod common;
use common::*;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn chromium() -> Option<PathBuf> {
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Headless chromium on `url` with `args` (virtual time for the page's scripts), its stdout.
fn headless(browser: &PathBuf, profile: &std::path::Path, args: &[&str], url: &str) -> String {
    let out = Command::new(browser)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1280,800",
            "--virtual-time-budget=15000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(url)
        .stderr(Stdio::null())
        .output()
        .unwrap();
    assert!(out.status.success(), "chromium failed: {}", out.status);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

struct Served(std::process::Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn issue_16_the_page_shows_a_replayed_session_in_a_real_browser() {
    let Some(browser) = chromium() else {
        assert!(
            std::env::var_os("SFS_REQUIRE_BROWSER").is_none(),
            "chromium is not installed (SFS_REQUIRE_BROWSER is set)"
        );
        eprintln!("skipping: chromium is not installed");
        return;
    };
    let dir = tmpdir("view-browser");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let out = dir.join("out");
    let _served = Served(
        Command::new(env!("CARGO_BIN_EXE_sfs"))
            .args(["--log", "off", "replay"])
            .arg(root.join("replay-logs/cone-morphorider.bin"))
            .arg("--out")
            .arg(&out)
            .args(["--view", &format!("127.0.0.1:{port}")])
            .stdout(Stdio::null())
            .spawn()
            .unwrap(),
    );
    // The replay ends (and keeps serving).
    wait_for("the replay's end", Duration::from_secs(60), || {
        std::fs::read(out.join("report.json"))
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
            .is_some_and(|r| r["ended"] == "end_of_input")
    });
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let url = format!("http://127.0.0.1:{port}/?once");
    let t0 = Instant::now();
    let dom = headless(&browser, &dir.join("profile-dom"), &["--dump-dom"], &url);
    eprintln!("page loaded in {:.1} s", t0.elapsed().as_secs_f64());
    let start = dom
        .find("<pre id=\"sfs-state\"")
        .unwrap_or_else(|| panic!("no state in the page: {dom}"));
    let json = &dom[start..];
    let json = &json[json.find('>').unwrap() + 1..json.find("</pre>").unwrap()];
    let json = json
        .replace("&quot;", "\"")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&");
    let state: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(state["errors"], serde_json::json!([]), "console errors");
    assert_eq!(state["ready"], true);
    let curves = state["curves"].as_array().unwrap();
    assert_eq!(curves.len(), report["curves"].as_array().unwrap().len());
    let boundary = curves.iter().filter(|c| c["boundary"] == true).count();
    let expected_boundary = report["curves"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["boundary"] == true)
        .count();
    assert_eq!(boundary, expected_boundary);
    let mut nodes: Vec<u64> = report["curves"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| {
            c["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_u64().unwrap())
        })
        .collect();
    nodes.sort();
    nodes.dedup();
    let mut shown: Vec<u64> = state["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap())
        .collect();
    shown.sort();
    assert_eq!(shown, nodes);
    assert_eq!(
        state["surfaceTriangles"], report["surface"]["triangles"],
        "{}",
        report["surface"]
    );
    assert!(
        state["rendered"]["calls"].as_u64().unwrap() > 0,
        "nothing drawn"
    );
    assert!(state["orientation"]["t"].is_array(), "no device glyph");
    // The closure misfit of every curve, and the marked tags (as report.json marks them).
    let closure = report["network"]["closure"].as_array().unwrap();
    assert_eq!(state["closure"].as_array().unwrap().len(), closure.len());
    let marked = |v: &serde_json::Value| -> Vec<(u64, u64)> {
        let mut m: Vec<(u64, u64)> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|t| (t["curve"].as_u64().unwrap(), t["node"].as_u64().unwrap()))
            .collect();
        m.sort();
        m
    };
    let expected: Vec<serde_json::Value> = closure
        .iter()
        .flat_map(|c| {
            c["tags"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|t| t["marked"] == true)
                .map(|t| serde_json::json!({ "curve": c["curve"], "node": t["node"] }))
        })
        .collect();
    assert_eq!(
        marked(&state["marked"]),
        marked(&serde_json::Value::Array(expected))
    );
    // A screenshot for a person to look at.
    let shot = root.join("target/view");
    std::fs::create_dir_all(&shot).unwrap();
    let png = shot.join("cone.png");
    let _ = std::fs::remove_file(&png);
    headless(
        &browser,
        &dir.join("profile-shot"),
        &[&format!("--screenshot={}", png.display())],
        &url,
    );
    let bytes = std::fs::read(&png).unwrap();
    assert!(
        bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
        "{} bytes",
        bytes.len()
    );
}
