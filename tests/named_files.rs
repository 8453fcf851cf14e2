//! Issue 31, point 4: the files a command line or a configuration names (a configuration, a
//! scene, a reference shape, a replayed capture) are read only when they are regular files of
//! a bounded size, and never opened in a way that can block: a directory, a FIFO, a device or
//! an oversized file is refused at once with exit 2, naming the key or the path; `sfs run`
//! refuses what `sfs config check` refuses.

mod common;
use common::tmpdir;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `sfs ARGS` for at most 20 s (killed after: a command that reads for ever or blocks
/// fails the test instead of hanging it): exit code and standard error.
fn sfs(args: &[&str], cwd: &Path) -> (Option<i32>, String) {
    let mut child = common::sfs()
        .args(["--log", "warn"])
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            let mut err = String::new();
            use std::io::Read;
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            return (st.code(), err);
        }
        if t0.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("sfs {args:?} still running after 20 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn mkfifo(p: &Path) {
    let st = Command::new("mkfifo").arg(p).status().unwrap();
    assert!(st.success());
}

#[test]
fn issue_31_a_configuration_that_is_no_regular_file_is_refused_at_once() {
    let dir = tmpdir("named-config");
    let fifo = dir.join("fifo.toml");
    mkfifo(&fifo);
    let big = dir.join("big.toml");
    std::fs::write(&big, "# padding\n".repeat(200_000)).unwrap();
    for (file, why) in [
        ("/dev/zero", "not a regular file"),
        ("fifo.toml", "not a regular file"),
        (".", "not a regular file"),
        ("big.toml", "more than the 1048576 a configuration may have"),
    ] {
        let (code, err) = sfs(&["config", "check", file], &dir);
        assert_eq!(code, Some(2), "config check {file}: {err}");
        assert!(err.contains(file) && err.contains(why), "{file}: {err}");
        let (code, err) = sfs(&["run", "--config", file, "--session", "s"], &dir);
        assert_eq!(code, Some(2), "run --config {file}: {err}");
        assert!(err.contains(why), "{file}: {err}");
        let (code, err) = sfs(&["replay", "x.bin", "--config", file, "--out", "o"], &dir);
        assert_eq!(code, Some(2), "replay --config {file}: {err}");
    }
}

#[test]
fn issue_31_sfs_run_refuses_the_replay_source_config_check_refuses() {
    let dir = tmpdir("named-replay");
    for (name, path) in [("zero", "/dev/zero"), ("dir", "."), ("missing", "nope.bin")] {
        let cfg = dir.join(format!("{name}.toml"));
        std::fs::write(
            &cfg,
            format!("[source]\nkind = \"replay\"\npath = \"{path}\"\n"),
        )
        .unwrap();
        let cfg = cfg.display().to_string();
        let (code, err) = sfs(&["config", "check", &cfg], &dir);
        assert_eq!(code, Some(2), "{err}");
        assert!(err.contains("source.path"), "{err}");
        let (code, err2) = sfs(&["run", "--config", &cfg, "--session", name], &dir);
        assert_eq!(code, Some(2), "{err2}");
        assert_eq!(
            err.lines().last(),
            err2.lines().last(),
            "the same refusal from both"
        );
    }
}

#[test]
fn issue_31_a_reference_file_or_scene_that_is_no_regular_file_is_refused() {
    let dir = tmpdir("named-reference");
    let fifo = dir.join("reference.json");
    mkfifo(&fifo);
    let riser = std::fs::read_to_string(root().join("config/riser.toml")).unwrap();
    let cfg = dir.join("riser.toml");
    std::fs::write(
        &cfg,
        riser.replace("reference_s = 10.0", "reference_file = \"reference.json\""),
    )
    .unwrap();
    let (code, err) = sfs(&["config", "check", "riser.toml"], &dir);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("monitor.reference_file") && err.contains("not a regular file"),
        "{err}"
    );
    // Scenes: a FIFO, a directory, a device.
    let scene_fifo = dir.join("scene.toml");
    mkfifo(&scene_fifo);
    std::fs::create_dir_all(dir.join("d.toml")).unwrap();
    for scene in ["scene.toml", "d.toml", "/dev/zero"] {
        let (code, err) = sfs(&["simulate", "--scene", scene, "--out", "x"], &dir);
        assert_eq!(code, Some(2), "{scene}: {err}");
        assert!(err.contains("not a regular file"), "{scene}: {err}");
    }
}
