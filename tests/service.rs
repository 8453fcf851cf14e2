//! Issue 20: running as a service — the log lines an operator's journal or log store gets.

mod common;
use common::*;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::process::{Command, Stdio};

fn demo() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("replay-logs/cone-morphorider.bin")
}

/// Replays the demo with standard error into a file; its lines.
fn replay_logging(
    dir: &Path,
    args: &[&str],
    env: impl Fn(&std::fs::File) -> Vec<(String, String)>,
) -> Vec<String> {
    let log = dir.join("stderr.log");
    let file = std::fs::File::create(&log).unwrap();
    let vars = env(&file);
    let status = sfs()
        .args(args)
        .arg("replay")
        .arg(demo())
        .arg("--out")
        .arg(dir.join("out"))
        .envs(vars)
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(Stdio::from(file))
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<String> = text.lines().map(str::to_owned).collect();
    assert!(lines.len() > 5, "{text}");
    lines
}

#[test]
fn issue_20_every_json_log_line_names_the_session() {
    let dir = tmpdir("service-json");
    let lines = replay_logging(&dir, &["--log-format", "json"], |_| Vec::new());
    let session = dir.join("out").display().to_string();
    for line in &lines {
        let v: serde_json::Value =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert_eq!(v["session"], session.as_str(), "{line}");
        assert!(v["timestamp"].is_string(), "{line}");
    }
}

#[test]
fn issue_20_under_journald_human_lines_have_no_timestamp() {
    let stamped = |line: &str| {
        // 2026-12-02T13:11:58.130557Z  INFO …
        line.len() > 20 && line.as_bytes()[4] == b'-' && line.as_bytes()[10] == b'T'
    };
    let dir = tmpdir("service-journal");
    // JOURNAL_STREAM naming standard error, as systemd sets it.
    let lines = replay_logging(&dir, &[], |f| {
        let m = f.metadata().unwrap();
        vec![("JOURNAL_STREAM".into(), format!("{}:{}", m.dev(), m.ino()))]
    });
    assert!(lines.iter().all(|l| !stamped(l)), "{lines:#?}");
    assert!(lines.iter().any(|l| l.contains("INFO")), "{lines:#?}");
    assert!(lines.iter().all(|l| !l.contains('\x1b')), "no colours");
    // Inherited from a parent whose output went elsewhere: timestamps kept.
    let dir = tmpdir("service-journal-elsewhere");
    let lines = replay_logging(&dir, &[], |_| vec![("JOURNAL_STREAM".into(), "1:2".into())]);
    assert!(lines.iter().all(|l| stamped(l)), "{lines:#?}");
}

/// `sfs ports --probe --json` on `paths` while a device on a pseudo-terminal writes `bytes`
/// over and over; the probes by path.
fn probe_while_sending(
    link: &Path,
    bytes: Vec<u8>,
    extra: &[&str],
) -> (i32, std::collections::HashMap<String, serde_json::Value>) {
    use std::io::Write;
    let mut dev = common::pty::plug(link);
    let mut child = sfs()
        .args(["ports", "--probe", "--probe-secs", "1.5", "--json"])
        .arg(link)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if !bytes.is_empty() {
            for c in bytes.chunks(64) {
                let _ = dev.master.write_all(c);
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let mut out = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut out).unwrap();
    let rows: Vec<serde_json::Value> = serde_json::from_str(&out).unwrap_or_default();
    let by_path = rows
        .into_iter()
        .map(|r| (r["path"].as_str().unwrap_or_default().to_owned(), r))
        .collect();
    (status.code().unwrap_or(-1), by_path)
}

#[test]
fn issue_20_ports_probe_reports_the_hello_and_tells_other_streams_apart() {
    let dir = tmpdir("service-ports");
    // A Morphorider: HELLO then samples.
    let mut b = Builder::new();
    b.packet(hello());
    for i in 0..20 {
        b.sample(i);
    }
    let link = dir.join("sfs-morphorider-7");
    let (code, ports) = probe_while_sending(&link, b.bytes.clone(), &[]);
    assert_eq!(code, 0);
    let probe = &ports[&link.display().to_string()]["probe"];
    assert_eq!(probe["result"], "hello", "{probe}");
    assert_eq!(probe["device"], "morphorider");
    assert_eq!(probe["device_id"], 7);
    assert_eq!(probe["firmware"], 1);
    assert_eq!(probe["rate_hz"], 100);
    // Joined between two HELLOs: samples only.
    let mut b = Builder::new();
    for i in 0..20 {
        b.sample(i);
    }
    let (_, ports) = probe_while_sending(&link, b.bytes.clone(), &[]);
    let probe = &ports[&link.display().to_string()]["probe"];
    assert_eq!(probe["result"], "speaks", "{probe}");
    assert!(probe["packets"].as_u64().unwrap() > 0);
    assert!(probe["text"].as_str().unwrap().contains("every 5 s"));
    // Another device's text, and nothing at all.
    let nmea = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n".repeat(4);
    let (_, ports) = probe_while_sending(&link, nmea, &[]);
    assert_eq!(
        ports[&link.display().to_string()]["probe"]["result"],
        "other"
    );
    let (_, ports) = probe_while_sending(&link, Vec::new(), &[]);
    assert_eq!(
        ports[&link.display().to_string()]["probe"]["result"],
        "silent"
    );
    // A port that is not there: named, exit 3.
    let missing = dir.join("no-such-port");
    let (code, _) = probe_while_sending(&link, Vec::new(), &[missing.to_str().unwrap()]);
    assert_eq!(code, 3);
}

/// The datagrams `sfs` sends to a fake `NOTIFY_SOCKET`, with when they arrived.
struct NotifySocket {
    path: std::path::PathBuf,
    rx: std::sync::mpsc::Receiver<(std::time::Instant, String)>,
    seen: Vec<(std::time::Instant, String)>,
}

impl NotifySocket {
    fn bind(path: std::path::PathBuf) -> Self {
        let _ = std::fs::remove_file(&path);
        let sock = std::os::unix::net::UnixDatagram::bind(&path).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = sock.recv(&mut buf) {
                let msg = String::from_utf8_lossy(&buf[..n]).into_owned();
                if tx.send((std::time::Instant::now(), msg)).is_err() {
                    break;
                }
            }
        });
        NotifySocket {
            path,
            rx,
            seen: Vec::new(),
        }
    }

    /// Waits up to `timeout` for a datagram holding `line`; when it came.
    fn wait_for(&mut self, line: &str, timeout: std::time::Duration) -> Option<std::time::Instant> {
        let end = std::time::Instant::now() + timeout;
        loop {
            let left = end.checked_duration_since(std::time::Instant::now())?;
            let (at, msg) = self.rx.recv_timeout(left).ok()?;
            self.seen.push((at, msg.clone()));
            if msg.lines().any(|l| l == line) {
                return Some(at);
            }
        }
    }

    /// The arrival times of `line` among the datagrams already received.
    fn drain(&mut self, line: &str) -> Vec<std::time::Instant> {
        let mut at = Vec::new();
        while let Ok((t, msg)) = self.rx.try_recv() {
            if msg.lines().any(|l| l == line) {
                at.push(t);
            }
            self.seen.push((t, msg));
        }
        at
    }

    /// The arrival times of `line` from now during `time`.
    fn collect(&mut self, line: &str, time: std::time::Duration) -> Vec<std::time::Instant> {
        let end = std::time::Instant::now() + time;
        let mut at = Vec::new();
        while let Some(left) = end.checked_duration_since(std::time::Instant::now()) {
            match self.rx.recv_timeout(left) {
                Ok((t, msg)) => {
                    if msg.lines().any(|l| l == line) {
                        at.push(t);
                    }
                    self.seen.push((t, msg));
                }
                Err(_) => break,
            }
        }
        at
    }
}

/// Whether process `pid` has `pts` open.
fn has_open(pid: u32, pts: &str) -> bool {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| {
            d.filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
                .any(|t| t == Path::new(pts))
        })
        .unwrap_or(false)
}

/// The largest gap between consecutive instants, and from the last to `end`.
fn largest_gap(
    at: &[std::time::Instant],
    start: std::time::Instant,
    end: std::time::Instant,
) -> std::time::Duration {
    let mut prev = start;
    let mut worst = std::time::Duration::ZERO;
    for &t in at.iter().chain([end].iter()) {
        worst = worst.max(t.saturating_duration_since(prev));
        prev = t;
    }
    worst
}

/// A child killed when dropped (a failed assertion must not leave a stalled daemon behind).
struct Daemon(std::process::Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `sfs run` on a pseudo-terminal as systemd starts `deploy/sfs@.service`: a notify
/// socket and a 2 s watchdog in its environment.
fn start_service(
    dir: &Path,
    extra_env: &[(&str, String)],
) -> (Daemon, common::pty::Device, NotifySocket) {
    let link = dir.join("sfs-morphorider-7");
    let dev = common::pty::plug(&link);
    let notify = NotifySocket::bind(dir.join("notify.sock"));
    let child = sfs()
        .args(["run", "--serial"])
        .arg(&link)
        .arg("--session")
        .arg(dir.join("session"))
        .arg("--continue")
        .env("NOTIFY_SOCKET", &notify.path)
        .env("WATCHDOG_USEC", "2000000")
        .envs(extra_env.iter().map(|(k, v)| (k, v)))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    (Daemon(child), dev, notify)
}

/// Writes `bytes` to the device over about `time`.
fn send_over(dev: &mut common::pty::Device, bytes: &[u8], time: std::time::Duration) {
    use std::io::Write;
    let chunks: Vec<&[u8]> = bytes.chunks(128).collect();
    let pause = time / chunks.len().max(1) as u32;
    for c in chunks {
        dev.master.write_all(c).unwrap();
        std::thread::sleep(pause);
    }
}

fn device_stream(samples: i32) -> Vec<u8> {
    let mut b = Builder::new();
    b.packet(hello());
    for i in 0..samples {
        b.sample(i % 1000);
    }
    b.bytes
}

#[test]
fn issue_20_notify_ready_after_the_port_is_open_watchdog_while_running_stopping_on_signal() {
    use std::time::{Duration, Instant};
    let dir = tmpdir("service-notify");
    let (mut child, mut dev, mut notify) = start_service(&dir, &[]);
    let ready = notify.wait_for("READY=1", Duration::from_secs(20));
    assert!(ready.is_some(), "no READY=1: {:?}", notify.seen);
    // The port was open when it said so.
    assert!(
        has_open(child.0.id(), &dev.pts),
        "READY=1 before the port was opened"
    );
    assert!(notify
        .seen
        .iter()
        .any(|(_, m)| m.contains("STATUS=reading")));
    // Pings while data flows, then while the device is silent: never a gap the watchdog
    // (2 s) would restart it for.
    let start = Instant::now();
    send_over(&mut dev, &device_stream(600), Duration::from_secs(2));
    let mut pings = notify.drain("WATCHDOG=1");
    pings.extend(notify.collect("WATCHDOG=1", Duration::from_millis(2500)));
    let end = Instant::now();
    assert!(
        pings.len() >= 4,
        "{} pings in {:?}",
        pings.len(),
        end - start
    );
    let gap = largest_gap(&pings, start, end);
    assert!(
        gap < Duration::from_millis(1900),
        "a {gap:?} gap between pings"
    );
    // SIGTERM: STOPPING=1, then a clean exit.
    let killed = Command::new("kill")
        .args(["-TERM", &child.0.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    assert!(
        notify
            .wait_for("STOPPING=1", Duration::from_secs(10))
            .is_some(),
        "{:?}",
        notify.seen
    );
    let status = child.0.wait().unwrap();
    assert_eq!(status.code(), Some(0));
    // Started again as systemd restarts it: the same session, continued.
    let capture = dir.join("session/capture.bin");
    let before = std::fs::metadata(&capture).unwrap().len();
    assert!(before > 0);
    let (mut child, mut dev, mut notify) = start_service(&dir, &[]);
    assert!(notify
        .wait_for("READY=1", Duration::from_secs(20))
        .is_some());
    send_over(&mut dev, &device_stream(50), Duration::from_millis(300));
    let _ = Command::new("kill")
        .args(["-TERM", &child.0.id().to_string()])
        .status();
    assert_eq!(child.0.wait().unwrap().code(), Some(0));
    assert!(
        std::fs::metadata(&capture).unwrap().len() > before,
        "the capture was continued"
    );
}

#[test]
fn issue_20_a_stalled_pipeline_stops_the_watchdog_pings() {
    use std::time::{Duration, Instant};
    let dir = tmpdir("service-stall");
    let first = device_stream(300);
    let (mut child, mut dev, mut notify) = start_service(
        &dir,
        &[(
            "SFS_TEST_STALL_AFTER_BYTES",
            (first.len() + 2000).to_string(),
        )],
    );
    assert!(notify
        .wait_for("READY=1", Duration::from_secs(20))
        .is_some());
    let start = Instant::now();
    send_over(&mut dev, &first, Duration::from_secs(1));
    let pings = notify.collect("WATCHDOG=1", Duration::from_millis(1500));
    assert!(!pings.is_empty(), "no pings before the stall");
    assert!(largest_gap(&pings, start, Instant::now()) < Duration::from_millis(1900));
    // Past the stall: the pings stop while the process stays up.
    send_over(&mut dev, &device_stream(200), Duration::from_millis(500));
    std::thread::sleep(Duration::from_millis(500));
    let _ = notify.drain("WATCHDOG=1");
    let after = notify.collect("WATCHDOG=1", Duration::from_secs(5));
    assert!(
        after.is_empty(),
        "{} pings after the stall, at {:?}",
        after.len(),
        after.iter().map(|t| *t - start).collect::<Vec<_>>()
    );
    assert!(
        child.0.try_wait().unwrap().is_none(),
        "the process is still up"
    );
}
