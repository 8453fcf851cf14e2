//! `sfs replay` end to end through the real binary: statistics against a capture built with
//! known faults, the summary, and the exit-code policy on bad input.

mod common;
use common::*;

#[test]
fn replay_counts_every_fault() {
    let dir = tmpdir("replay-faults");
    let (bytes, exp) = fault_stream(1000);
    let cap = dir.join("faults.bin");
    std::fs::write(&cap, &bytes).unwrap();
    let out = sfs()
        .args(["replay", cap.to_str().unwrap(), "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&format!("{} bytes", bytes.len())),
        "{stdout}"
    );
    let report = read_report(&dir.join("out"));
    assert_eq!(report["ended"], "end_of_input");
    let link = &report["link"];
    assert_link(link, bytes.len(), &exp);
    assert_eq!(link["status"]["flags"], 2);
    assert_eq!(link["status"]["flag_names"][0], "magnetometer_saturated");
    assert_eq!(link["status"]["dropped"], 12);
    assert_eq!(link["hello"]["kind"], "morphorider");
}

#[test]
fn missing_capture_is_one_line_error_with_input_exit_code() {
    let dir = tmpdir("replay-missing");
    let missing = dir.join("no-such-capture.bin");
    let out = sfs()
        .args(["--log", "off", "replay"])
        .arg(&missing)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::INPUT));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains(missing.to_str().unwrap()), "{err}");
}

#[test]
fn directory_as_capture_is_an_input_error() {
    let dir = tmpdir("replay-dir");
    let out = sfs()
        .args(["--log", "off", "replay"])
        .arg(&dir)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::INPUT));
}

#[test]
fn unwritable_output_is_an_output_error() {
    let dir = tmpdir("replay-unwritable");
    let cap = dir.join("c.bin");
    std::fs::write(&cap, fault_stream(10).0).unwrap();
    let blocker = dir.join("file-not-dir");
    std::fs::write(&blocker, b"x").unwrap();
    let out = sfs()
        .args(["--log", "off", "replay"])
        .arg(&cap)
        .arg("--out")
        .arg(blocker.join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::OUTPUT));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("file-not-dir"), "{err}");
}

#[test]
fn bad_usage_exits_2() {
    let out = sfs().args(["replay"]).output().unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::USAGE));
    let out = sfs()
        .args(["replay", "x.bin", "--out", "o", "--pace", "slow"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::USAGE));
}

#[test]
fn realtime_pace_follows_device_clock() {
    let dir = tmpdir("replay-realtime");
    let mut b = Builder::new();
    b.packet(hello());
    for i in 0..60 {
        b.sample(i); // 10 ms apart: 0.59 s of device time
    }
    let cap = dir.join("c.bin");
    std::fs::write(&cap, &b.bytes).unwrap();
    let t0 = std::time::Instant::now();
    let out = sfs()
        .args(["--log", "off", "replay", "--pace", "realtime"])
        .arg(&cap)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let wall = t0.elapsed().as_secs_f64();
    assert!(out.status.success());
    assert!(
        wall >= 0.55,
        "paced replay took only {wall:.3} s for 0.59 s of device time"
    );
    let link = &read_report(&dir.join("out"))["link"];
    assert_eq!(link["packets"]["RIDER_SAMPLE"], 60);
}

/// Regression: `sfs replay … | head` closed the pipes and the binary panicked (tracing and
/// println! on a broken pipe) before writing its report.
#[test]
fn closed_output_pipes_neither_panic_nor_lose_the_report() {
    let dir = tmpdir("replay-closed-pipes");
    let cap = dir.join("c.bin");
    std::fs::write(&cap, fault_stream(500).0).unwrap();
    let mut child = sfs()
        .args(["replay"])
        .arg(&cap)
        .arg("--out")
        .arg(dir.join("out"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    drop(child.stderr.take());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0));
    assert!(dir.join("out/report.json").exists());
}

/// Issue 14: every warning of `report.json` keeps its text and carries a stable code, in the
/// same order: a repeated node tag, an unknown key and a curve never ended give theirs.
#[test]
fn issue_14_warnings_carry_stable_codes() {
    let dir = tmpdir("replay-codes");
    let mut b = Builder::new();
    b.packet(hello());
    for k in *b"B1\n" {
        b.key(k);
    }
    for i in 0..50 {
        b.sample(i);
    }
    for k in *b"1\nX" {
        b.key(k);
    }
    for i in 50..100 {
        b.sample(i);
    }
    for k in *b"2\n" {
        b.key(k);
    }
    let cap = dir.join("keys.bin");
    std::fs::write(&cap, &b.bytes).unwrap();
    let out = sfs()
        .args(["--log", "off", "replay", cap.to_str().unwrap(), "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let report = read_report(&dir.join("out"));
    let texts = strings(&report["warnings"]);
    let codes = strings(&report["warning_codes"]);
    assert_eq!(
        codes,
        ["keypad_repeat", "keypad_unknown_key", "curve_never_ended"],
        "{texts:?}"
    );
    assert!(texts[0].starts_with("curve 0, node 1, t = "), "{texts:?}");
    assert!(texts[0].ends_with("node tagged twice in a row; the repeat is ignored"));
    assert!(texts[1].contains("unknown key 0x58 ('X')"), "{texts:?}");
    assert!(
        texts[2].starts_with("curve 0: the session ended before its E (nodes [1, 2]"),
        "{texts:?}"
    );
}

/// Issue 50 point 1: `sfs replay --out DIR` into a directory that holds a session (a
/// capture.bin) or the outputs of another run or replay refuses (exit 2), says what is there,
/// and changes nothing; `--force` replaces the outputs (a session's capture stays).
#[test]
fn issue_50_replay_refuses_a_directory_with_outputs_unless_forced() {
    let dir = tmpdir("replay-refuse");
    let (bytes, _) = fault_stream(200);
    let cap = dir.join("faults.bin");
    std::fs::write(&cap, &bytes).unwrap();
    // A session: its capture and its report, as `sfs run` leaves them.
    let session = dir.join("session");
    std::fs::create_dir_all(&session).unwrap();
    std::fs::write(session.join("capture.bin"), b"the session's own bytes").unwrap();
    std::fs::write(session.join("report.json"), b"{\"the session's\": 1}").unwrap();
    let replay = |out: &std::path::Path, force: bool| {
        let mut c = sfs();
        c.args(["--log", "off", "replay"])
            .arg(&cap)
            .arg("--out")
            .arg(out);
        if force {
            c.arg("--force");
        }
        c.output().unwrap()
    };
    let out = replay(&session, false);
    assert_eq!(out.status.code(), Some(sfs::exit::USAGE));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("a session")
            && err.contains("capture.bin, report.json")
            && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(session.join("report.json")).unwrap(),
        b"{\"the session's\": 1}"
    );
    assert!(!session.join("network.glb").exists());
    // Forced: the outputs are this capture's, the session's capture is kept.
    let out = replay(&session, true);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(read_report(&session)["link"]["bytes"], bytes.len());
    assert_eq!(
        std::fs::read(session.join("capture.bin")).unwrap(),
        b"the session's own bytes"
    );
    // Another replay's outputs: refused too, and replaced when forced.
    let first = dir.join("first");
    assert!(replay(&first, false).status.success());
    let before = std::fs::read(first.join("report.json")).unwrap();
    let out = replay(&first, false);
    assert_eq!(out.status.code(), Some(sfs::exit::USAGE));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("report.json, scan.json"), "{err}");
    assert_eq!(std::fs::read(first.join("report.json")).unwrap(), before);
    assert!(replay(&first, true).status.success());
}

/// Issue 50 point 1: a replay that fails (here a file of no capture: exit 5) leaves nothing
/// behind: no output directory, no report, and no `report:` line in the summary. Into a
/// directory that was there, what it wrote goes and the rest stays.
#[test]
fn issue_50_a_failed_replay_leaves_nothing_behind() {
    let dir = tmpdir("replay-failed");
    let junk = dir.join("junk.bin");
    std::fs::write(&junk, [0x42u8; 300]).unwrap();
    let out_dir = dir.join("out");
    let replay = || {
        sfs()
            .args(["--log", "off", "replay"])
            .arg(&junk)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap()
    };
    let out = replay();
    assert_eq!(out.status.code(), Some(sfs::exit::UNUSABLE));
    assert!(!out_dir.exists(), "the output directory is left behind");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!stdout.contains("report:"), "{stdout}");
    // An existing directory with a file of the user's: kept, and nothing added.
    std::fs::create_dir_all(&out_dir).unwrap();
    std::fs::write(out_dir.join("notes.txt"), b"mine").unwrap();
    let out = replay();
    assert_eq!(out.status.code(), Some(sfs::exit::UNUSABLE));
    let left: Vec<_> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("notes.txt")]);
}

/// Issue 50 point 6: the summary says what was made: curves accepted, discarded and left
/// out, nodes, whether a surface was built (or why not), the warnings by code, the verdict
/// and every output's path. A capture cut inside its first curve says so, not a clean line.
#[test]
fn issue_50_the_summary_says_what_was_made() {
    let dir = tmpdir("replay-summary");
    let cone =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("replay-logs/cone-morphorider.bin");
    let summary = |cap: &std::path::Path, out: &std::path::Path| {
        let o = sfs()
            .args(["--log", "off", "replay"])
            .arg(cap)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let out = dir.join("cone");
    let s = summary(&cone, &out);
    let report = read_report(&out);
    let patches = report["surface"]["patches"].as_u64().unwrap();
    for want in [
        "curves: 7 accepted (0 discarded, 0 left out of the network), 12 nodes".to_string(),
        format!("surface: {patches} patches"),
        "warnings: none".to_string(),
        "scan: good (".to_string(),
        format!("report:  {}", out.join("report.json").display()),
        format!(
            "outputs: {}, {}",
            out.join("scan.json").display(),
            out.join("network.glb").display()
        ),
    ] {
        assert!(s.contains(&want), "{want:?} not in:\n{s}");
    }
    // Cut inside its first curve: nothing accepted, why there is no surface, the warning.
    let bytes = std::fs::read(&cone).unwrap();
    let cut = dir.join("cut.bin");
    std::fs::write(&cut, &bytes[..60_000]).unwrap();
    let s = summary(&cut, &dir.join("cut"));
    for want in [
        "curves: 0 accepted (1 discarded",
        "surface: none (no network)",
        "warnings: 1 (curve_never_ended 1",
    ] {
        assert!(s.contains(want), "{want:?} not in:\n{s}");
    }
}

/// Issue 50 point 9: what a live update cannot do yet while the scan goes on (no cycle, a
/// face along one curve both ways) is logged at info ("for now"), never as a warning; what is
/// left when the session ends is a warning, once.
#[test]
fn issue_50_intermediate_states_are_not_warnings() {
    let dir = tmpdir("replay-intermediate");
    let cone =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("replay-logs/cone-morphorider.bin");
    // Live updates come with the view; it serves on after the end, until interrupted.
    let log = |cap: &std::path::Path, out: &std::path::Path| {
        let err = out.with_extension("log");
        let mut child = sfs()
            .args(["--log", "info", "replay"])
            .arg(cap)
            .arg("--out")
            .arg(out)
            .args(["--view", "127.0.0.1:0"])
            // As fast as an update per curve allows (faster, the curves come in one update).
            .args(["--pace", "x50"])
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(&err).unwrap())
            .spawn()
            .unwrap();
        wait_for(
            "the replay's end",
            std::time::Duration::from_secs(60),
            || {
                std::fs::read(out.join("report.json"))
                    .ok()
                    .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
                    .is_some_and(|r| r["ended"] == "end_of_input")
            },
        );
        let _ = std::process::Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status();
        assert!(child.wait().unwrap().success());
        std::fs::read_to_string(err).unwrap()
    };
    let warns = |log: &str, what: &str| {
        log.lines()
            .filter(|l| l.contains(" WARN ") && l.contains(what))
            .count()
    };
    // The whole cone: its first curves close no loop; the last ones do.
    let full = log(&cone, &dir.join("full"));
    assert!(
        full.lines()
            .any(|l| l.contains(" INFO ")
                && l.contains("for now, while the scan goes on: no surface")),
        "the intermediate states are not said at all:\n{full}"
    );
    assert_eq!(warns(&full, ""), 0, "{full}");
    assert_eq!(
        read_report(&dir.join("full"))["warnings"],
        serde_json::json!([])
    );
    // Cut after its third curve: the state it ends in is a warning, once.
    let bytes = std::fs::read(&cone).unwrap();
    let cut = dir.join("cut.bin");
    let at = bytes.len() * 2 / 5;
    let at = bytes[..at].iter().rposition(|&b| b == 0).unwrap() + 1;
    std::fs::write(&cut, &bytes[..at]).unwrap();
    let cut_log = log(&cut, &dir.join("cut"));
    let report = read_report(&dir.join("cut"));
    assert!(
        report["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().is_some_and(|w| w.starts_with("no surface"))),
        "{}",
        report["warnings"]
    );
    assert_eq!(warns(&cut_log, "no surface"), 1, "{cut_log}");
}
