//! Issue 20, point 2: what `deploy/` installs agrees with the binary — the unit's command line
//! is one `sfs` accepts, its exit-code policy and group match the README's and the udev
//! rule's, the rule names devices by the kinds the protocol defines, and `systemd-analyze
//! verify` accepts the unit (reported as ignored where systemd is not installed, unless
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
#[cfg_attr(
    not(sfs_systemd_analyze),
    ignore = "needs systemd-analyze (Debian: apt-get install systemd)"
)]
fn issue_20_systemd_analyze_verifies_the_unit() {
    let out = std::process::Command::new("systemd-analyze")
        .arg("--version")
        .output()
        .expect("systemd-analyze runs (Debian: apt-get install systemd)");
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

/// Every metric `/metrics` can carry (the label families given a value so that they are
/// encoded): name → type.
fn exported() -> std::collections::BTreeMap<String, String> {
    let mon = sfs::metrics::MonitorMetrics::default();
    let m = sfs::metrics::SessionMetrics::new(Some(&mon));
    let l = |k: &str, v: &str| vec![(k.to_string(), v.to_string())];
    m.link_packets.get_or_create(&l("type", "HELLO")).inc();
    m.link_rejected.get_or_create(&l("reason", "crc")).inc();
    mon.alarm
        .get_or_create(&l("metric", "max_displacement"))
        .set(1);
    mon.sensor_left_out.get_or_create(&l("sensor", "3")).set(1);
    m.encode()
        .lines()
        .filter_map(|line| {
            let mut f = line.strip_prefix("# TYPE ")?.split_whitespace();
            Some((f.next()?.to_owned(), f.next()?.to_owned()))
        })
        .collect()
}

/// The `sfs_…` metric names in `text`, each checked against the exporter: a gauge by its
/// name, a counter by its name with `_total`.
fn check_names(text: &str, what: &str) -> std::collections::BTreeSet<String> {
    let known = exported();
    let mut names = std::collections::BTreeSet::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(k) = text[i..].find("sfs_") {
        let start = i + k;
        let word_start =
            start == 0 || !(bytes[start - 1].is_ascii_alphanumeric() || bytes[start - 1] == b'_');
        let end = start
            + text[start..]
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(text.len() - start);
        if word_start {
            names.insert(text[start..end].to_owned());
        }
        i = end;
    }
    for n in &names {
        let ok = match n.strip_suffix("_total") {
            Some(base) => known.get(base).is_some_and(|t| t == "counter"),
            None => known.get(n).is_some_and(|t| t != "counter"),
        };
        assert!(ok, "{what} names {n}, which sfs does not export: {known:?}");
    }
    names
}

#[test]
fn issue_20_the_alerting_rules_name_exported_metrics_and_cover_the_cases() {
    let rules = std::fs::read_to_string(deploy("prometheus/sfs-rules.yml")).unwrap();
    let names = check_names(&rules, "sfs-rules.yml");
    for n in [
        "sfs_alarm",
        "sfs_sensors_left_out_epochs",
        "sfs_epochs_total",
        "sfs_link_lost_packets_total",
    ] {
        assert!(names.contains(n), "no rule on {n}");
    }
    for alert in [
        "SfsAlarmRaised",
        "SfsSensorsLeftOut",
        "SfsNoEpoch",
        "SfsLinkLosses",
        "SfsSessionStopped",
    ] {
        assert!(
            rules.contains(&format!("alert: {alert}\n")),
            "no alert {alert}"
        );
    }
    assert!(rules.contains("[30s]"), "no epoch for 30 s");
}

#[test]
fn issue_20_the_dashboard_names_exported_metrics_and_shows_the_monitoring() {
    let text = std::fs::read_to_string(deploy("grafana/sfs-monitoring.json")).unwrap();
    let dash: serde_json::Value = serde_json::from_str(&text).unwrap();
    fn exprs(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    match (k.as_str(), x) {
                        ("expr" | "definition", serde_json::Value::String(s)) => {
                            out.push(s.clone())
                        }
                        _ => exprs(x, out),
                    }
                }
            }
            serde_json::Value::Array(a) => a.iter().for_each(|x| exprs(x, out)),
            _ => {}
        }
    }
    let mut all = Vec::new();
    exprs(&dash, &mut all);
    let names = check_names(&all.join("\n"), "sfs-monitoring.json");
    for n in [
        "sfs_max_displacement_meters",
        "sfs_max_curvature_change_radians_per_meter",
        "sfs_sensor_left_out",
        "sfs_alarm",
        "sfs_epoch_latency_seconds",
    ] {
        assert!(names.contains(n), "no panel on {n}");
    }
    // Every panel draws something.
    for p in dash["panels"].as_array().unwrap() {
        assert!(
            !p["targets"].as_array().unwrap().is_empty(),
            "{}",
            p["title"]
        );
    }
}

#[test]
#[cfg_attr(
    not(sfs_promtool),
    ignore = "needs promtool (Debian: apt-get install prometheus)"
)]
fn issue_20_promtool_checks_and_tests_the_rules() {
    std::process::Command::new("promtool")
        .arg("--version")
        .output()
        .expect("promtool runs (Debian: apt-get install prometheus)");
    let dir = deploy("prometheus");
    for args in [
        ["check", "rules", "sfs-rules.yml"],
        ["test", "rules", "sfs-rules.test.yml"],
    ] {
        let out = std::process::Command::new("promtool")
            .args(args)
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "promtool {args:?}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
