//! Issue 20: running as a service — the log lines an operator's journal or log store gets.

mod common;
use common::*;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::process::{Command, Stdio};

fn sfs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sfs"))
}

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
