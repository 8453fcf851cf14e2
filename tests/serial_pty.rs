//! The serial source through a real pseudo-terminal pair: a writer thread plays a capture into
//! the master end, the session reads the slave by path (through a symlink, as udev's
//! /dev/serial/by-id links), captures and decodes it. Closing the master is an unplug; a new
//! pair behind the same link is the device coming back.

mod common;
use common::pty::*;
use common::*;
use sfs::session;
use sfs::shutdown::Shutdown;
use sfs::source::{SerialSpec, SourceSpec};
use std::path::PathBuf;
use std::time::Duration;

fn start_session(
    spec: SourceSpec,
    dir: PathBuf,
    shutdown: Shutdown,
) -> std::thread::JoinHandle<Result<session::Outcome, session::SessionError>> {
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(session::run(
                spec,
                &dir,
                &sfs::settings::Settings::default(),
                session::Start::New,
                shutdown,
            ))
    })
}

#[test]
fn serial_session_decodes_captures_and_reconnects() {
    let dir = tmpdir("serial-pty");
    let link = dir.join("ttySFS");
    let session_dir = dir.join("session");
    let capture = session_dir.join("capture.bin");
    let (bytes, exp) = fault_stream(3000);
    let half = bytes.len() / 2;
    // Split at a delimiter so that the unplug does not cut a frame (that would be a legitimate
    // loss the expected counts do not model).
    let split = bytes[..half].iter().rposition(|&b| b == 0).unwrap() + 1;

    let mut master = plug(&link);
    let shutdown = Shutdown::new();
    let session = start_session(spec(&link), session_dir.clone(), shutdown.clone());

    play(&mut master, &bytes[..split]);
    wait_for("first half captured", Duration::from_secs(10), || {
        file_len(&capture) == split as u64
    });
    drop(master); // unplug
    std::thread::sleep(Duration::from_millis(300)); // the session sees the loss, retries
    let mut master = plug(&link); // the device comes back on a new pty behind the same link
    play(&mut master, &bytes[split..]);
    wait_for("second half captured", Duration::from_secs(10), || {
        file_len(&capture) == bytes.len() as u64
    });
    shutdown.trigger();
    let outcome = session.join().unwrap().expect("session ran");
    drop(master);

    // Lossless capture: exactly the bytes the device sent, in order.
    assert_eq!(std::fs::read(&capture).unwrap(), bytes);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&outcome.report_path).unwrap()).unwrap();
    let link_stats = &report["link"];
    assert_link(link_stats, bytes.len(), &exp);
    assert_eq!(link_stats["connects"], 2);
    assert!(link_stats["disconnects"].as_u64().unwrap() >= 1);
    assert_eq!(report["ended"], "shutdown");
}

#[test]
fn watchdog_counts_silence_as_disconnect() {
    let dir = tmpdir("serial-watchdog");
    let link = dir.join("ttySFS");
    let mut master = plug(&link);
    let mut s = SerialSpec::new(&link, 115_200);
    s.watchdog = Duration::from_millis(200);
    s.backoff_min = Duration::from_millis(20);
    let shutdown = Shutdown::new();
    let session = start_session(SourceSpec::Serial(s), dir.join("session"), shutdown.clone());
    let mut b = Builder::new();
    b.packet(hello());
    play(&mut master, &b.bytes);
    std::thread::sleep(Duration::from_millis(700)); // silence: more than one watchdog period
    shutdown.trigger();
    let outcome = session.join().unwrap().unwrap();
    let l = &outcome.report.link;
    assert!(l.disconnects >= 1, "silence not detected: {l:?}");
    assert!(l.connects >= 2, "no reconnection after the watchdog: {l:?}");
    assert_eq!(l.packets.total(), 1);
    drop(master);
}

#[test]
fn missing_serial_port_is_an_input_error_naming_the_path() {
    let dir = tmpdir("serial-missing");
    let path = dir.join("ttyNONE");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "run", "--serial"])
        .arg(&path)
        .arg("--session")
        .arg(dir.join("s"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::INPUT));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("ttyNONE"), "{err}");
}

async fn get_text(url: &str) -> Option<String> {
    reqwest::get(url).await.ok()?.text().await.ok()
}

/// Polls `/status` until `cond` holds, for at most `limit`; returns it.
async fn status_until(
    port: u16,
    what: &str,
    limit: Duration,
    cond: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t0 = std::time::Instant::now();
    let mut last = serde_json::Value::Null;
    loop {
        if let Some(s) = get_text(&format!("http://127.0.0.1:{port}/status")).await {
            last = serde_json::from_str(&s).unwrap();
            if cond(&last) {
                return last;
            }
        }
        assert!(
            t0.elapsed() < limit,
            "not {what} within {limit:?}: {}",
            last["link"]
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The value of the unlabelled metric `name` in `/metrics`.
async fn metric(port: u16, name: &str) -> f64 {
    let text = get_text(&format!("http://127.0.0.1:{port}/metrics"))
        .await
        .unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in\n{text}"))
}

/// Issue 50 point 2: a device unplugged mid-session is seen while it is away: `/status`
/// `link.state` turns disconnected then reconnecting (with its attempt) within 5 s, the
/// disconnect is counted in `/status` and `/metrics` at once, `sfs_link_up` is 0 until the
/// device is back, then 1.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_50_an_unplugged_device_is_seen_while_it_is_away() {
    let dir = tmpdir("serial-link-state");
    let link = dir.join("ttySFS");
    let port = common::view::free_port();
    let mut dev = plug(&link);
    let _served = common::view::serve_serial(&link, &dir.join("session"), port, &dir.join("log"));
    let mut b = Builder::new();
    b.packet(hello());
    for i in 0..50 {
        b.sample(i);
    }
    status_until(port, "connected", Duration::from_secs(20), |s| {
        s["link"]["state"] == "connected"
    })
    .await;
    write(&mut dev, &b.bytes);
    let s = status_until(port, "connected", Duration::from_secs(20), |s| {
        s["link"]["state"] == "connected" && s["link"]["packets"] == 51
    })
    .await;
    assert_eq!(s["link"]["disconnects"], 0);
    assert_eq!(metric(port, "sfs_link_up").await, 1.0);

    let unplugged = std::time::Instant::now();
    // As udev does for a USB adapter: the device and its link go.
    drop(dev);
    std::fs::remove_file(&link).unwrap();
    let s = status_until(port, "lost", Duration::from_secs(5), |s| {
        matches!(
            s["link"]["state"].as_str(),
            Some("disconnected" | "reconnecting")
        )
    })
    .await;
    eprintln!(
        "/status said the device was lost {:?} after the unplug",
        unplugged.elapsed()
    );
    assert_eq!(s["link"]["disconnects"], 1, "{}", s["link"]);
    assert!(
        s["link"]["since_unix_ms"].as_u64().is_some(),
        "{}",
        s["link"]
    );
    assert!(s["link"]["reason"].as_str().is_some(), "{}", s["link"]);
    // The port is gone: reopening fails, attempt after attempt.
    let s = status_until(port, "reconnecting", Duration::from_secs(5), |s| {
        s["link"]["state"] == "reconnecting" && s["link"]["attempt"].as_u64() >= Some(2)
    })
    .await;
    assert!(
        unplugged.elapsed() < Duration::from_secs(10),
        "{}",
        s["link"]
    );
    assert_eq!(metric(port, "sfs_link_up").await, 0.0);
    assert_eq!(metric(port, "sfs_link_disconnects_total").await, 1.0);

    // Back.
    let mut dev = plug(&link);
    let mut b = Builder::new();
    b.packet(hello());
    status_until(port, "reopened", Duration::from_secs(10), |s| {
        s["link"]["state"] == "connected"
    })
    .await;
    write(&mut dev, &b.bytes);
    let s = status_until(port, "connected again", Duration::from_secs(10), |s| {
        s["link"]["state"] == "connected" && s["link"]["packets"] == 52
    })
    .await;
    assert!(s["link"].get("attempt").is_none(), "{}", s["link"]);
    assert_eq!(metric(port, "sfs_link_up").await, 1.0);
    assert_eq!(metric(port, "sfs_link_disconnects_total").await, 1.0);
    // Silent: still up, said so.
    let s = status_until(port, "silent", Duration::from_secs(3), |s| {
        s["link"]["state"] == "silent"
    })
    .await;
    assert!(s["link"]["for_s"].as_f64().unwrap() >= 1.0, "{}", s["link"]);
    assert_eq!(metric(port, "sfs_link_up").await, 1.0);
}

/// Issue 50 point 2, its third bullet: a port that sends nothing, or bytes but never a valid
/// frame, for 10 s is named as such in the log and in `/status` `link.problem`, with
/// `sfs ports --probe` suggested.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_50_a_port_no_sfs_device_speaks_on_is_named() {
    let dir = tmpdir("serial-unheard");
    let (quiet, noisy) = (dir.join("ttyQUIET"), dir.join("ttyNOISE"));
    let (pq, pn) = (common::view::free_port(), common::view::free_port());
    let _q = plug(&quiet);
    let mut n = plug(&noisy);
    let _sq = common::view::serve_serial(&quiet, &dir.join("q"), pq, &dir.join("q.log"));
    let _sn = common::view::serve_serial(&noisy, &dir.join("n"), pn, &dir.join("n.log"));
    // A modem's chatter: text, no frame.
    status_until(pn, "open", Duration::from_secs(20), |s| {
        s["link"]["state"] == "connected"
    })
    .await;
    write(&mut n, &b"AT\r\nOK\r\n".repeat(100));
    for (port, log, expect) in [
        (pq, dir.join("q.log"), "no byte from"),
        (pn, dir.join("n.log"), "800 bytes"),
    ] {
        let s = status_until(port, "named", Duration::from_secs(20), |s| {
            s["link"]["problem"].is_string()
        })
        .await;
        let problem = s["link"]["problem"].as_str().unwrap();
        assert!(problem.contains(expect), "{problem}");
        assert!(problem.contains("sfs ports --probe"), "{problem}");
        let log = std::fs::read_to_string(&log).unwrap();
        assert_eq!(log.matches(expect).count(), 1, "named once:\n{log}");
    }
}
