//! Lossless capture through the real binary reading standard input: the capture holds exactly
//! the bytes sent, replaying it reproduces the session's statistics, a SIGKILL loses nothing
//! that was read more than a second before, and SIGTERM finishes cleanly.

mod common;
use common::*;
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// `sfs run --stdin --session DIR`, standard input piped, standard output discarded.
fn run_stdin(log: &str, session: impl AsRef<Path>) -> std::process::Child {
    sfs()
        .args(["--log", log, "run", "--stdin", "--session"])
        .arg(session.as_ref())
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap()
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

fn kill(pid: u32, sig: &str) {
    let st = Command::new("kill")
        .args([sig, &pid.to_string()])
        .status()
        .unwrap();
    assert!(st.success());
}

#[test]
fn stdin_session_capture_replays_to_the_same_statistics() {
    let dir = tmpdir("capture-stdin");
    let (bytes, exp) = fault_stream(2000);
    let mut child = run_stdin("warn", dir.join("live"));
    {
        let mut stdin = child.stdin.take().unwrap();
        for c in bytes.chunks(1000) {
            stdin.write_all(c).unwrap();
        }
    } // end of input
    assert!(child.wait().unwrap().success());
    let capture = dir.join("live/capture.bin");
    assert_eq!(
        std::fs::read(&capture).unwrap(),
        bytes,
        "capture differs from input"
    );
    let live = report(&dir.join("live"));
    assert_link(&live["link"], bytes.len(), &exp);
    assert_eq!(live["ended"], "end_of_input");

    let st = sfs()
        .args(["--log", "off", "replay"])
        .arg(&capture)
        .arg("--out")
        .arg(dir.join("replayed"))
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    let mut replayed = report(&dir.join("replayed"))["link"].clone();
    let mut live_link = live["link"].clone();
    // Only the source's own connection counters may differ.
    for l in [&mut replayed, &mut live_link] {
        l["connects"] = 0.into();
        l["disconnects"] = 0.into();
    }
    assert_eq!(replayed, live_link);
}

#[test]
fn resumed_session_appends_to_its_capture() {
    let dir = tmpdir("capture-resume");
    let (bytes, exp) = fault_stream(300);
    let (a, b) = bytes.split_at(bytes.len() / 3);
    let mut child = run_stdin("off", &dir);
    child.stdin.take().unwrap().write_all(a).unwrap();
    assert!(child.wait().unwrap().success());
    // A new session in the same directory is refused (its curves would be lost), naming
    // --resume; the capture is untouched.
    let out = sfs()
        .args(["--log", "off", "run", "--stdin", "--session"])
        .arg(&dir)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(msg.contains("--resume") && msg.contains("capture"), "{msg}");
    assert_eq!(std::fs::read(dir.join("capture.bin")).unwrap(), a);
    let mut child = sfs()
        .args(["--log", "off", "run", "--stdin", "--resume"])
        .arg(&dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(b).unwrap();
    assert!(child.wait().unwrap().success());
    assert_eq!(std::fs::read(dir.join("capture.bin")).unwrap(), bytes);
    // The report counts the whole capture, as one uninterrupted session would.
    assert_link(&report(&dir)["link"], bytes.len(), &exp);
}

#[test]
fn sigkill_loses_at_most_the_last_second() {
    let dir = tmpdir("capture-sigkill");
    let (bytes, _) = fault_stream(2000);
    let (early, late) = bytes.split_at(bytes.len() * 2 / 3);
    let mut child = run_stdin("off", &dir);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(early).unwrap();
    stdin.flush().unwrap();
    std::thread::sleep(Duration::from_millis(1200));
    stdin.write_all(&late[..late.len() / 2]).unwrap(); // within the last second: may be lost
    kill(child.id(), "-KILL");
    let _ = child.wait();
    let captured = std::fs::read(dir.join("capture.bin")).unwrap();
    assert!(
        captured.len() >= early.len(),
        "SIGKILL lost {} bytes older than one second",
        early.len() - captured.len().min(early.len())
    );
    assert_eq!(
        &captured[..],
        &bytes[..captured.len()],
        "capture is not a prefix of the input"
    );
}

#[test]
fn sigterm_finishes_with_report_and_exit_0() {
    let dir = tmpdir("capture-sigterm");
    let (bytes, exp) = fault_stream(500);
    let mut child = run_stdin("off", &dir);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(&bytes).unwrap();
    stdin.flush().unwrap();
    // Wait until everything was read (the capture has it), then ask for an orderly stop.
    let cap = dir.join("capture.bin");
    let t0 = std::time::Instant::now();
    while std::fs::metadata(&cap).map(|m| m.len()).unwrap_or(0) < bytes.len() as u64 {
        assert!(t0.elapsed() < Duration::from_secs(10), "input not captured");
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(100)); // let the pipeline decode what it has
    kill(child.id(), "-TERM");
    let status = child.wait().unwrap();
    drop(stdin);
    assert_eq!(status.code(), Some(0));
    let r = report(&dir);
    assert_eq!(r["ended"], "shutdown");
    assert_link(&r["link"], bytes.len(), &exp);
}
