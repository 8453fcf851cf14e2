//! Issue 20, point 2: what `deploy/` installs agrees with the binary — the unit's command line
//! is one `sfs` accepts, its exit-code policy and group match the README's and the udev
//! rule's, the rule names devices by the kinds the protocol defines, and `systemd-analyze
//! verify` accepts the unit (skipped where systemd is not installed, unless
//! `SFS_REQUIRE_SYSTEMD` is set, as `.ci/run` does).

use clap::Parser;
use std::path::{Path, PathBuf};

fn deploy(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("deploy")
        .join(name)
}

/// The values of `key=` in the unit's text, in order.
fn values<'a>(unit: &'a str, key: &str) -> Vec<&'a str> {
    unit.lines()
        .filter_map(|l| l.strip_prefix(key)?.strip_prefix('='))
        .map(str::trim)
        .collect()
}

#[test]
fn issue_20_the_unit_runs_a_command_sfs_accepts_as_a_notify_service() {
    let unit = std::fs::read_to_string(deploy("sfs@.service")).unwrap();
    assert_eq!(values(&unit, "Type"), ["notify"]);
    assert_eq!(values(&unit, "Restart"), ["on-failure"]);
    assert!(!values(&unit, "WatchdogSec").is_empty());
    assert_eq!(values(&unit, "DynamicUser"), ["yes"]);
    assert_eq!(values(&unit, "ProtectSystem"), ["strict"]);
    assert_eq!(values(&unit, "StateDirectory"), ["sfs/%i"]);
    assert!(values(&unit, "DeviceAllow").len() >= 2);
    // Restarting does not mend a usage or configuration error.
    assert_eq!(
        values(&unit, "RestartPreventExitStatus"),
        [sfs::exit::USAGE.to_string().as_str()]
    );
    // The command line, its specifiers filled in as systemd would, parses; it continues the
    // session rather than splitting it.
    let [exec] = values(&unit, "ExecStart")[..] else {
        panic!("one ExecStart")
    };
    let line = exec.replace("%S", "/var/lib").replace("%i", "panel");
    let args: Vec<&str> = line.split_whitespace().collect();
    assert!(args[0].ends_with("/sfs"), "{line}");
    let cli = sfs::cli::Cli::try_parse_from(&args).unwrap_or_else(|e| panic!("{line}: {e}"));
    match cli.command {
        sfs::cli::Command::Run(r) => {
            assert!(r.continue_existing, "{line}");
            assert_eq!(r.session.as_deref(), Some(Path::new("/var/lib/sfs/panel")));
            assert_eq!(r.config.as_deref(), Some(Path::new("/etc/sfs/panel.toml")));
        }
        other => panic!("{line}: not sfs run but {other:?}"),
    }
}

#[test]
fn issue_20_the_udev_rule_names_devices_by_their_kind_for_the_units_group() {
    let unit = std::fs::read_to_string(deploy("sfs@.service")).unwrap();
    let groups = values(&unit, "SupplementaryGroups");
    let rules = std::fs::read_to_string(deploy("99-sfs.rules")).unwrap();
    let lines: Vec<&str> = rules
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .collect();
    assert!(!lines.is_empty());
    for l in lines {
        assert!(l.contains(r#"SUBSYSTEM=="tty""#), "{l}");
        let kind = l
            .split("SYMLINK+=\"sfs-")
            .nth(1)
            .and_then(|r| r.split('-').next())
            .unwrap_or_else(|| panic!("no sfs-<kind>- symlink: {l}"));
        assert!(
            device_protocol::DeviceKind::from_name(kind).is_some(),
            "{kind} is not a device kind: {l}"
        );
        let group = l
            .split("GROUP=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap();
        assert!(groups.contains(&group), "{group} not in {groups:?}");
        assert!(l.contains(r#"MODE="0660""#), "{l}");
    }
}

#[test]
fn issue_20_systemd_analyze_verifies_the_unit() {
    let Ok(out) = std::process::Command::new("systemd-analyze")
        .arg("--version")
        .output()
    else {
        assert!(
            std::env::var_os("SFS_REQUIRE_SYSTEMD").is_none(),
            "systemd-analyze is missing"
        );
        eprintln!("skipping: systemd-analyze is not installed");
        return;
    };
    assert!(out.status.success());
    // An instance of the template, its binary the one just built.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("deploy-verify");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let unit = std::fs::read_to_string(deploy("sfs@.service"))
        .unwrap()
        .replace("/usr/local/bin/sfs", env!("CARGO_BIN_EXE_sfs"));
    std::fs::write(dir.join("sfs@.service"), unit).unwrap();
    std::os::unix::fs::symlink("sfs@.service", dir.join("sfs@demo.service")).unwrap();
    let out = std::process::Command::new("systemd-analyze")
        .arg("verify")
        .arg(dir.join("sfs@demo.service"))
        .output()
        .unwrap();
    let said =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    // Unknown keys are only warnings to systemd: none is accepted here.
    assert!(out.status.success() && said.trim().is_empty(), "{said}");
}
