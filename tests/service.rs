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
