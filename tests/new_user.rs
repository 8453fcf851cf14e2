//! Issue 30: the mistakes a new user made, each answered through the binary with what went
//! wrong and the exit code the policy gives (`sfs::exit`), and the installed binary working
//! from any directory.

mod common;

use common::tmpdir;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `sfs --log warn`: what a new user's terminal shows.
fn sfs() -> Command {
    let mut c = common::sfs();
    c.args(["--log", "warn"]);
    c
}

fn run(c: &mut Command) -> (i32, String, String) {
    let Output {
        status,
        stdout,
        stderr,
    } = c.output().unwrap();
    (
        status.code().unwrap_or(-1),
        String::from_utf8_lossy(&stdout).into_owned(),
        String::from_utf8_lossy(&stderr).into_owned(),
    )
}

fn log(name: &str) -> PathBuf {
    root().join("replay-logs").join(name)
}

#[test]
fn issue_30_resume_of_a_directory_without_a_session_says_so() {
    let dir = tmpdir("resume-nothing");
    for d in [dir.clone(), dir.join("missing")] {
        let (code, _, err) = run(sfs().arg("run").arg("--resume").arg(&d));
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("holds no session") && err.contains(&d.display().to_string()),
            "{err}"
        );
        assert!(!err.contains("--serial"), "{err}");
    }
}

#[test]
fn issue_30_replay_of_a_file_without_packets_says_so() {
    let dir = tmpdir("replay-no-packet");
    let (code, _, err) = run(sfs()
        .arg("replay")
        .arg(root().join("config/demo.toml"))
        .arg("--out")
        .arg(dir.join("out")));
    assert_eq!(code, 5, "{err}");
    assert!(err.contains("no packet"), "{err}");
    // An empty file too.
    let empty = dir.join("empty.bin");
    std::fs::write(&empty, b"").unwrap();
    let (code, _, err) = run(sfs()
        .arg("replay")
        .arg(&empty)
        .arg("--out")
        .arg(dir.join("out2")));
    assert_eq!(code, 5, "{err}");
}

#[test]
fn issue_30_an_array_capture_replayed_without_monitoring_names_the_configuration_it_needs() {
    let dir = tmpdir("replay-array");
    let (code, _, err) = run(sfs()
        .arg("replay")
        .arg(log("riser-array.bin"))
        .arg("--out")
        .arg(dir.join("out")));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("[monitor]") && err.contains("--config"),
        "{err}"
    );
    // With it, the replay is what it always was.
    let (code, _, err) = run(sfs()
        .arg("replay")
        .arg(log("riser-array.bin"))
        .arg("--config")
        .arg(root().join("config/riser.toml"))
        .arg("--out")
        .arg(dir.join("out2")));
    assert_eq!(code, 0, "{err}");
}

/// The cone's network against the bowl's truth: no rigid registration fits (exit 5, the
/// residual in the JSON); against its own truth it fits, and the nodes come in number order.
#[test]
fn issue_30_eval_against_the_truth_of_another_scene_says_no_registration_fits() {
    let dir = tmpdir("eval-other");
    let out = dir.join("cone");
    let (code, _, err) = run(sfs()
        .arg("replay")
        .arg(log("cone-morphorider.bin"))
        .arg("--out")
        .arg(&out));
    assert_eq!(code, 0, "{err}");
    let glb = out.join("network.glb");
    let eval = |truth: &str| {
        run(sfs()
            .arg("eval")
            .arg("--truth")
            .arg(log(truth))
            .arg("--glb")
            .arg(&glb))
    };
    let (code, json, err) = eval("bowl-phone.truth.json");
    assert_eq!(code, 5, "{err}");
    assert!(err.contains("no rigid registration fits"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["registration"]["fits"], false);
    let residual = v["registration"]["residual_rms_pct"].as_f64().unwrap();
    assert!(residual > sfs::eval::MAX_RESIDUAL_PCT, "{residual}");

    let (code, json, err) = eval("cone-morphorider.truth.json");
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["registration"]["fits"], true);
    let residual = v["registration"]["residual_rms_pct"].as_f64().unwrap();
    assert!(residual < 1.0, "{residual}");
    // node_errors_m in number order: "0", "1", …, "9", "10", "11".
    let nodes = &json[json.find("\"node_errors_m\"").unwrap()..];
    let keys: Vec<u32> = nodes
        .lines()
        .skip(1)
        .take_while(|l| !l.trim_start().starts_with('}'))
        .map(|l| l.trim().split('"').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(keys, (0..12).collect::<Vec<u32>>(), "{nodes}");
}

#[test]
fn issue_30_view_addresses_take_a_port_or_localhost_and_a_wrong_one_names_the_forms() {
    // Accepted: the command gets past the flags to its own complaint (no session here).
    let dir = tmpdir("view-forms");
    for form in ["8933", "localhost:8933", "127.0.0.1:8933", "[::1]:8933"] {
        let (code, _, err) = run(sfs()
            .arg("run")
            .args(["--view", form, "--resume"])
            .arg(&dir));
        assert_eq!(code, 2, "{form}: {err}");
        assert!(err.contains("holds no session"), "{form}: {err}");
    }
    for form in ["localhost", "example.org:80", "8933x", "99999"] {
        let (code, _, err) = run(sfs()
            .arg("run")
            .args(["--view", form, "--resume"])
            .arg(&dir));
        assert_eq!(code, 2, "{form}: {err}");
        assert!(
            err.contains("localhost:PORT") && err.contains("IP:PORT") && !err.contains("syntax"),
            "{form}: {err}"
        );
    }
    // The configuration's [view] address takes the same forms.
    let cfg = dir.join("view.toml");
    std::fs::write(&cfg, "[view]\naddress = \"localhost:8933\"\n").unwrap();
    let (code, out, err) = run(sfs().args(["config", "check"]).arg(&cfg));
    assert_eq!(code, 0, "{out}{err}");
}

/// `sfs replay … --view` prints its summary when the replay ends, while the view is still
/// served, not after the interrupt.
#[test]
fn issue_30_a_replay_with_the_view_prints_its_summary_when_it_ends() {
    use std::io::BufRead;
    let dir = tmpdir("replay-view-summary");
    let mut child = sfs()
        .arg("replay")
        .arg(log("cone-morphorider.bin"))
        .arg("--out")
        .arg(dir.join("out"))
        .args(["--view", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout).lines() {
            if tx.send(line.unwrap()).is_err() {
                break;
            }
        }
    });
    let t0 = Instant::now();
    let mut lines = Vec::new();
    while !lines.iter().any(|l: &String| l.starts_with("report:")) {
        let left = Duration::from_secs(60).saturating_sub(t0.elapsed());
        match rx.recv_timeout(left) {
            Ok(l) => lines.push(l),
            Err(_) => {
                let _ = child.kill();
                panic!("no summary in 60 s: {lines:?}");
            }
        }
    }
    assert!(
        child.try_wait().unwrap().is_none(),
        "the view is still served after the summary"
    );
    assert!(lines.iter().any(|l| l.contains("packets")), "{lines:?}");
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let status = child.wait().unwrap();
    assert!(status.success(), "{status}");
}

#[test]
fn issue_30_a_serial_port_that_does_not_exist_leaves_no_session_behind() {
    let dir = tmpdir("no-port");
    let port = dir.join("ttyNOPE");
    // A directory the session would make.
    let session = dir.join("s");
    let (code, _, err) = run(sfs()
        .arg("run")
        .arg("--serial")
        .arg(&port)
        .arg("--session")
        .arg(&session));
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("ttyNOPE"), "{err}");
    // Issue 50 point 2: where to look for the right one.
    assert!(
        err.contains("`sfs ports`") && err.contains("--probe"),
        "{err}"
    );
    assert!(!session.exists(), "{:?}", std::fs::read_dir(&session).ok());
    // With a configuration (kept as config.toml), in a directory that was already there.
    let there = dir.join("there");
    std::fs::create_dir_all(&there).unwrap();
    std::fs::write(there.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = run(sfs()
        .arg("run")
        .arg("--config")
        .arg(root().join("config/morphorider.toml"))
        .arg("--serial")
        .arg(&port)
        .arg("--session")
        .arg(&there));
    assert_eq!(code, 3, "{err}");
    let left: Vec<String> = std::fs::read_dir(&there)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, vec!["notes.txt".to_string()]);
}

/// A fixed array never turned: no magnetometer fit of the Earth's field can come of it.
#[test]
fn issue_30_calibrating_a_capture_never_turned_refuses_the_fit() {
    for sensor in ["0", "1", "5"] {
        let (code, out, err) = run(sfs()
            .arg("calibrate")
            .arg(log("riser-array.bin"))
            .args(["--sensor", sensor]));
        assert_eq!(code, 5, "sensor {sensor}: {out}{err}");
        assert!(
            out.contains("# mag_hard_iron") && !out.contains("\nmag_hard_iron"),
            "sensor {sensor}: {out}"
        );
        assert!(out.contains("NOT USABLE"), "{out}");
    }
    let (code, out, err) = run(sfs()
        .arg("calibrate")
        .arg(log("riser-array.bin"))
        .args(["--sensor", "99"]));
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains("no sensor 99") && err.contains("its sensors: 0"),
        "{err}"
    );
    let (code, _, err) = run(sfs()
        .arg("calibrate")
        .arg(log("cone-morphorider.bin"))
        .args(["--sensor", "3"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a sensor array"), "{err}");
}

#[test]
fn issue_30_help_of_run_and_replay_says_what_they_write_and_every_source() {
    for cmd in ["run", "replay"] {
        let (code, out, err) = run(sfs().args([cmd, "--help"]));
        assert_eq!(code, 0, "{err}");
        for file in ["report.json", "scan.json", "network.glb"] {
            assert!(out.contains(file), "sfs {cmd} --help: no {file}:\n{out}");
        }
    }
    let (_, out, _) = run(sfs().args(["run", "--help"]));
    for source in ["--serial", "--stdin", "replay", "capture.bin", "--resume"] {
        assert!(out.contains(source), "sfs run --help: no {source}:\n{out}");
    }
}

/// The installed binary, run from a directory that is not the repository: the built-in
/// scenes simulate, `--list` names them, and errors name the file and the reason without a
/// placeholder for a key.
#[test]
fn issue_30_the_binary_works_from_any_directory() {
    let elsewhere = tmpdir("elsewhere");
    let in_dir = |c: &mut Command| {
        c.current_dir(&elsewhere);
        run(c)
    };
    let (code, out, err) = in_dir(sfs().args(["simulate", "--scene", "cone", "--out", "c"]));
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("12 nodes"), "{out}");
    assert!(elsewhere.join("c.bin").is_file() && elsewhere.join("c.truth.json").is_file());
    let (code, out, _) = in_dir(sfs().args(["simulate", "--list"]));
    assert_eq!(code, 0);
    for name in sfs::simulate::scene::names() {
        assert!(out.lines().any(|l| l.starts_with(name)), "{name}: {out}");
    }
    // The simulated capture replays and evaluates there too.
    let (code, _, err) = in_dir(sfs().args(["replay", "c.bin", "--out", "o"]));
    assert_eq!(code, 0, "{err}");
    let (code, _, err) =
        in_dir(sfs().args(["eval", "--truth", "c.truth.json", "--glb", "o/network.glb"]));
    assert_eq!(code, 0, "{err}");
    // A scene file given by path: its errors name the file, and no "-" stands for a key.
    let (code, _, err) = in_dir(sfs().args(["simulate", "--scene", "nope.toml", "--out", "x"]));
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("nope.toml") && !err.contains(": -:"), "{err}");
    let (code, _, err) = in_dir(sfs().args(["simulate", "--scene", "nope", "--out", "x"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cone") && err.contains("PATH.toml"), "{err}");
    std::fs::write(elsewhere.join("bad.toml"), "name = \"x\"\n[surface\n").unwrap();
    let (code, _, err) = in_dir(sfs().args(["simulate", "--scene", "bad.toml", "--out", "x"]));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("bad.toml: line 2") && !err.contains(": -:"),
        "{err}"
    );
    let (code, _, err) = in_dir(sfs().args(["config", "check", "missing.toml"]));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("missing.toml: cannot read") && !err.contains(": -:"),
        "{err}"
    );
    let (code, _, err) = in_dir(sfs().args(["config", "check", "."]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file"), "{err}");
}

/// Issue 50 point 5: a session started from flags alone (`--stdin`, `--serial PATH`) keeps
/// its source in `config.toml`, so that `sfs run --resume DIR` alone continues it: the
/// resumed stdin session appends to the capture and rebuilds the whole scan; a serial
/// session's copy names the port by its absolute path, with the baud and watchdog given.
#[test]
fn issue_50_a_session_started_from_flags_resumes_with_resume_alone() {
    use std::io::Write as _;
    let dir = tmpdir("resume-flags");
    let cone = std::fs::read(log("cone-morphorider.bin")).unwrap();
    let session = dir.join("s");
    let feed = |args: &[&std::ffi::OsStr], bytes: &[u8]| {
        let mut child = common::sfs()
            .args(["--log", "off", "run"])
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        child.stdin.take().unwrap().write_all(bytes).unwrap();
        child.wait_with_output().unwrap()
    };
    let half = cone.len() / 2;
    let out = feed(
        &[
            "--stdin".as_ref(),
            "--session".as_ref(),
            session.as_os_str(),
        ],
        &cone[..half],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let kept = std::fs::read_to_string(session.join("config.toml")).unwrap();
    assert!(kept.contains("kind = \"stdin\""), "{kept}");
    // Resumed with nothing but the directory.
    let out = feed(&["--resume".as_ref(), session.as_os_str()], &cone[half..]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), cone);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("curves: 7 accepted"), "{stdout}");
    // A serial session, on a pseudo-terminal reached through a link: its copy names the
    // port by its absolute path, with the baud and watchdog given.
    let link = dir.join("ttySFS");
    let _device = common::pty::plug(&link);
    let serial = dir.join("serial");
    let mut child = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "run", "--serial"])
        .arg(&link)
        .args(["--baud", "57600", "--watchdog-ms", "250", "--session"])
        .arg(&serial)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    common::wait_for("the session's config.toml", Duration::from_secs(10), || {
        serial.join("config.toml").exists()
    });
    let _ = child.kill();
    let _ = child.wait();
    let kept = std::fs::read_to_string(serial.join("config.toml")).unwrap();
    let t: toml::Table = kept.parse().unwrap();
    assert_eq!(t["source"]["kind"].as_str(), Some("serial"), "{kept}");
    assert_eq!(
        t["source"]["path"].as_str(),
        Some(link.to_str().unwrap()),
        "{kept}"
    );
    assert_eq!(t["source"]["baud"].as_integer(), Some(57600), "{kept}");
    assert_eq!(t["source"]["watchdog_ms"].as_integer(), Some(250), "{kept}");
}
