//! Every shipped configuration passes `sfs config check`; a broken one names key and reason.

use std::process::Command;

fn check(path: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["config", "check"])
        .arg(path)
        .output()
        .unwrap()
}

#[test]
fn shipped_configs_are_valid() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/config");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let out = check(&p);
            assert!(
                out.status.success(),
                "{}: {}",
                p.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            n += 1;
        }
    }
    assert!(n >= 3, "expected the shipped configurations, found {n}");
}

#[test]
fn bad_config_names_key_and_reason() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let p = dir.join(format!("bad-{}.toml", std::process::id()));
    std::fs::write(
        &p,
        "[source]\nkind = \"serial\"\npath = \"/dev/x\"\nwatchdog_ms = 5\n",
    )
    .unwrap();
    let out = check(&p);
    assert_eq!(out.status.code(), Some(sfs::exit::USAGE));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("source.watchdog_ms"), "{err}");
    assert!(err.contains("minimum 100"), "{err}");
}

#[test]
fn demo_config_runs_the_shipped_replay_from_any_directory() {
    let out_dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("demo-run-{}", std::process::id()));
    let cfg = concat!(env!("CARGO_MANIFEST_DIR"), "/config/demo.toml");
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .current_dir(std::env::temp_dir())
        .args(["--log", "off", "run", "--config", cfg, "--session"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("report.json")).unwrap())
            .unwrap();
    assert!(r["link"]["packets"]["RIDER_SAMPLE"].as_u64().unwrap() > 0);
    // A replay is not live: nothing to capture.
    assert!(!out_dir.join("capture.bin").exists());
}

/// The shipped monitoring configurations describe the simulator's structures, so that
/// `sfs simulate --structure riser|panel` streams can be monitored with them as they are.
#[test]
fn shipped_monitoring_layouts_are_the_simulators() {
    use sfs::simulate::structure::{run, StructureKind};
    for (name, kind) in [
        ("riser", StructureKind::Riser),
        ("panel", StructureKind::Panel),
    ] {
        let file = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/config"))
            .join(format!("{name}.toml"));
        let m = sfs::config::load(&file)
            .unwrap()
            .monitor
            .expect("a [monitor] section");
        let (_, truth) = run(kind, 1, 0.2, 10.0);
        // `sfs config check` says what the layout is.
        let out = String::from_utf8_lossy(&check(&file).stdout).into_owned();
        let curves = truth.curves.len();
        let summary = format!(
            "monitor: {} sensors on {curves} curve{}",
            truth.sensors.len(),
            if curves == 1 { "" } else { "s" }
        );
        assert!(out.contains(&summary), "{name}: {out}");
        assert_eq!(m.layout.curves, truth.curves, "{name}");
        assert_eq!(m.layout.sensors.len(), truth.sensors.len(), "{name}");
        for (a, b) in m.layout.sensors.iter().zip(&truth.sensors) {
            assert_eq!((a.sensor, a.curve), (b.sensor, b.curve), "{name}");
            assert!((a.s - b.s).abs() < 1e-9, "{name}: sensor {}", a.sensor);
        }
    }
}

/// Issue 50 point 7: `sfs config check` reports every error of a file, each with its key (an
/// unknown key in one section, a bad value in another, a bad address in a third); a syntax
/// error with its line and column; and it warns of a view others can reach with no token.
#[test]
fn issue_50_config_check_reports_every_error() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let p = dir.join(format!("three-errors-{}.toml", std::process::id()));
    std::fs::write(
        &p,
        "[source]\nkind = \"serial\"\npath = \"/dev/x\"\nwatchdog_ms = 5\n\n\
         [acquisition]\nstationary_window_s = -1.0\n\n\
         [view]\naddress = \"nowhere\"\n\n\
         [surface]\nno_such_key = 1\n",
    )
    .unwrap();
    let out = check(&p);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    for key in [
        "source.watchdog_ms",
        "acquisition.stationary_window_s",
        "view.address",
        "no_such_key",
    ] {
        assert!(err.contains(key), "{key} not named:\n{err}");
    }
    // A syntax error: where it is.
    std::fs::write(&p, "[source]\nkind = \"serial\"\npath = /dev/x\n").unwrap();
    let out = check(&p);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3, column 8"), "{err}");
    // A view on every interface with no token: valid, with a warning; with a token, none.
    std::fs::write(&p, "[view]\naddress = \"0.0.0.0:8040\"\n").unwrap();
    let out = check(&p);
    assert!(out.status.success());
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("warning: view.address 0.0.0.0:8040") && said.contains("view.token"),
        "{said}"
    );
    std::fs::write(
        &p,
        "[view]\naddress = \"0.0.0.0:8040\"\ntoken = \"a-long-secret-token-0123\"\n",
    )
    .unwrap();
    let out = check(&p);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!String::from_utf8_lossy(&out.stdout).contains("warning"));
    let _ = std::fs::remove_file(&p);
}
