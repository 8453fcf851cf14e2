//! The `sfs` binary: a thin layer over the library. Parses flags, resolves them with the
//! configuration, installs logging and signal handling, runs, maps errors to exit codes.

use clap::Parser;
use sfs::cli::{
    CalibrateArgs, Cli, Command, ConfigCommand, EvalArgs, PortsArgs, ReplayArgs, RunArgs,
    SimulateArgs,
};
use sfs::config::{self, ConfigError};
use sfs::exit;
use sfs::session::{self, Outcome, SessionError};
use sfs::settings::Settings;
use sfs::shutdown::Shutdown;
use sfs::source::phone::PhoneSpec;
use sfs::source::{SerialSpec, SourceError, SourceSpec};
use std::path::Path;
use std::time::Duration;

fn main() {
    sfs::shutdown::default_signals();
    sfs_geometry::sparse_llt::single_threaded();
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() {
                exit::USAGE
            } else {
                exit::OK
            };
            let _ = e.print();
            std::process::exit(code);
        }
    };
    sfs::logging::init(
        matches!(cli.log_format, sfs::cli::LogFormat::Json),
        cli.log.as_deref(),
    );
    // As many descriptors as the system allows this process (the view's connections are
    // capped well under them, keeping a reserve for the session's files).
    sfs::view::conn::raise_file_limit();
    std::process::exit(match cli.command {
        Command::Replay(a) => replay(a),
        Command::Run(a) => run(a),
        Command::Calibrate(a) => calibrate(a),
        Command::Simulate(a) => simulate(a),
        Command::Eval(a) => eval(a),
        Command::Config(ConfigCommand::Check { file }) => config_check(&file),
        Command::Ports(a) => ports(a),
    });
}

/// Prints to standard output, ignoring a closed pipe (`sfs … | head` must not panic).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// Prints an error line to standard error, ignoring a closed pipe.
macro_rules! complain {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($arg)*);
    }};
}

fn replay(a: ReplayArgs) -> i32 {
    sfs::logging::set_session(&a.out.display().to_string());
    // Nothing the user made is written over unless asked: a session (its outputs belong to
    // its capture), or another run's or replay's outputs.
    let there = outputs_in(&a.out);
    if !there.is_empty() && !a.force {
        let session = there.contains(&session::CAPTURE_FILE);
        complain!(
            "sfs: {} already holds {} ({}): give another --out directory, or --force to replace {}",
            a.out.display(),
            if session {
                "a session"
            } else {
                "the outputs of a run or a replay"
            },
            there.join(", "),
            if session {
                "its outputs with this capture's (its capture.bin stays)"
            } else {
                "them"
            }
        );
        return exit::USAGE;
    }
    let existed = a.out.exists();
    let spec = SourceSpec::Replay {
        path: a.capture.clone(),
        pace: a.pace,
    };
    let settings = match &a.config {
        Some(f) => match config::load(f) {
            Ok(s) => s,
            Err(e) => {
                complain!("sfs: {e}");
                return exit::USAGE;
            }
        },
        None => Settings::default(),
    };
    // Offline: the outputs once, at the end (no live updates), unless the view shows them.
    let view = a.view.or(settings.view);
    let settings = Settings {
        live: view.is_some(),
        view,
        keep_serving: view.is_some(),
        ..settings
    };
    let monitoring = settings.monitor.is_some();
    let capture = a.capture.clone();
    let code = run_session_then(spec, &a.out, &settings, session::Start::New, |o| {
        replay_verdict(o, &capture, monitoring)
    });
    // A failed replay leaves nothing behind: what it wrote goes, and the directory if it made
    // it (what was there before it, with --force, was replaced already).
    if code != exit::OK && code != exit::INTERRUPTED {
        for f in outputs_in(&a.out) {
            if !there.contains(&f) {
                let _ = std::fs::remove_file(a.out.join(f));
            }
        }
        if !existed {
            let _ = std::fs::remove_dir(&a.out);
        }
    }
    code
}

/// A replay that found nothing to work on says so: no packet at all (exit 5), or a sensor
/// array's capture without the monitoring configuration that reconstructs it (exit 2).
fn replay_verdict(o: &Outcome, capture: &Path, monitoring: bool) -> i32 {
    let link = &o.report.link;
    if link.packets.total() == 0 {
        complain!(
            "sfs: {}: no packet of the device protocol found in its {} bytes: is it a capture (the bytes a device sent)?",
            capture.display(),
            link.bytes
        );
        return exit::UNUSABLE;
    }
    let array = link.packets.get(device_protocol::PacketType::ArraySample) > 0
        || link
            .hello
            .as_ref()
            .is_some_and(|h| h.kind_code == device_protocol::DeviceKind::SensorArray.code());
    if array && !monitoring {
        complain!(
            "sfs: {} is a sensor array's capture: it is reconstructed by monitoring, which needs the array's layout from a configuration with a [monitor] section: sfs replay {} --config FILE (config/riser.toml is one)",
            capture.display(),
            capture.display()
        );
        return exit::USAGE;
    }
    exit::OK
}

fn run(a: RunArgs) -> i32 {
    let (dir, resume) = match (&a.session, &a.resume) {
        (Some(d), None) if a.continue_existing && d.join(session::CAPTURE_FILE).exists() => {
            tracing::info!("{} holds a capture: continuing it", d.display());
            (d.clone(), true)
        }
        (Some(d), None) => (d.clone(), false),
        (None, Some(d)) => (d.clone(), true),
        _ => {
            complain!("sfs: give either --session DIR (a new session) or --resume SESSION");
            return exit::USAGE;
        }
    };
    if a.resume.is_some() && !dir.join(session::CAPTURE_FILE).is_file() {
        complain!(
            "sfs: {} holds no session to resume (no {}): start one with --session {}",
            dir.display(),
            session::CAPTURE_FILE,
            dir.display()
        );
        return exit::USAGE;
    }
    sfs::logging::set_session(&dir.display().to_string());
    // A resumed session keeps the configuration it started with.
    let saved = dir.join(session::CONFIG_COPY);
    let config = match (&a.config, resume) {
        (None, true) if saved.is_file() => Some(saved.clone()),
        (c, _) => c.clone(),
    };
    if let (Some(given), true, Ok(kept)) = (&a.config, resume, config::read_config_file(&saved)) {
        if config::read_config_file(given).ok().as_deref() != Some(config::kept_origin(&kept).1) {
            tracing::warn!(
                "{} differs from the configuration the session started with ({}): the curves so far are rebuilt with the new one",
                given.display(),
                saved.display()
            );
        }
    }
    let (spec, settings) = match resolve_run(&a, config.as_deref()) {
        Ok(s) => s,
        Err(e) => {
            complain!("sfs: {e}");
            return exit::USAGE;
        }
    };
    let start = if resume {
        session::Start::Resume
    } else {
        match session_config(&a, config.as_deref()) {
            Ok(Some(kept)) => session::Start::NewWithConfig(kept),
            Ok(None) => session::Start::New,
            Err(e) => {
                complain!("sfs: {e}");
                return exit::USAGE;
            }
        }
    };
    run_session(spec, &dir, &settings, start)
}

/// The configuration a new session keeps as its `config.toml`, so that `--resume DIR` alone
/// continues it: the file given, with what the flags chose over it (the source: `--serial`
/// and its `--baud`, `--watchdog-ms`; `--stdin`; `--phone`; and `--view`) written in.
fn session_config(a: &RunArgs, config: Option<&Path>) -> Result<Option<String>, String> {
    let text = match config {
        Some(f) => config::read_config_file(f).map_err(|e| e.to_string())?,
        None => String::new(),
    };
    let flags = a.serial.is_some()
        || a.stdin
        || a.phone.is_some()
        || a.baud.is_some()
        || a.watchdog_ms.is_some()
        || a.view.is_some();
    if !flags {
        return Ok(config.map(|f| config::kept_config(&text, f)));
    }
    let mut t: toml::Table = text.parse().map_err(|e| format!("{e}"))?;
    let table = |t: &toml::Table, k: &str| -> toml::Table {
        t.get(k)
            .and_then(|v| v.as_table())
            .cloned()
            .unwrap_or_default()
    };
    let mut source = table(&t, "source");
    if let Some(p) = &a.serial {
        let p = std::path::absolute(p).unwrap_or_else(|_| p.clone());
        source = toml::Table::new();
        source.insert("kind".into(), "serial".into());
        source.insert("path".into(), p.display().to_string().into());
    }
    if a.stdin {
        source = toml::Table::new();
        source.insert("kind".into(), "stdin".into());
    }
    if let Some(b) = a.baud {
        source.insert("baud".into(), i64::from(b).into());
    }
    if let Some(w) = a.watchdog_ms {
        source.insert(
            "watchdog_ms".into(),
            i64::try_from(w).unwrap_or(i64::MAX).into(),
        );
    }
    if let Some(addr) = a.phone {
        // The phone page is the source: a [source] would be read before it.
        t.remove("source");
        let mut phone = table(&t, "phone");
        if let Some(addr) = addr {
            phone.insert("address".into(), addr.to_string().into());
        }
        t.insert("phone".into(), phone.into());
    } else if !source.is_empty() {
        t.insert("source".into(), source.into());
    }
    if let Some(v) = a.view {
        let mut view = table(&t, "view");
        view.insert("address".into(), v.to_string().into());
        t.insert("view".into(), view.into());
    }
    let body = toml::to_string(&t).map_err(|e| e.to_string())?;
    Ok(Some(match config {
        // Its relative paths still resolve where it was copied from.
        Some(f) => config::kept_config(
            &format!("# {} with the command line's flags:\n{body}", f.display()),
            f,
        ),
        // The flags' paths are absolute.
        None => format!("# The session's configuration, from the command line's flags:\n{body}"),
    }))
}

/// Flags over the configuration file over the defaults.
fn resolve_run(a: &RunArgs, config: Option<&Path>) -> Result<(SourceSpec, Settings), ConfigError> {
    let cli_err =
        |key: &str, reason: &str| ConfigError::new(Path::new("command line"), key, reason);
    let mut settings = match config {
        // A kept copy resolves its relative paths where it was copied from.
        Some(f) => config::load_kept(f)?,
        None => Settings::default(),
    };
    if a.view.is_some() {
        settings.view = a.view;
    }
    let mut spec = if a.stdin {
        SourceSpec::Stdin
    } else if let Some(p) = &a.serial {
        SourceSpec::Serial(SerialSpec::new(p, settings.serial.baud))
    } else if let Some(addr) = a.phone {
        let mut phone = settings
            .phone
            .clone()
            .unwrap_or_else(PhoneSpec::at_default_address);
        if let Some(addr) = addr {
            phone.addr = addr;
        }
        SourceSpec::Phone(phone)
    } else if let Some(s) = &settings.source {
        s.clone()
    } else if let Some(p) = &settings.phone {
        SourceSpec::Phone(p.clone())
    } else {
        return Err(cli_err(
            "--serial",
            match config {
                Some(_) => {
                    "the configuration has no [source] or [phone]: give --serial PATH, --phone or --stdin"
                }
                None => "give --serial PATH, --phone, --stdin or --config FILE",
            },
        ));
    };
    if let SourceSpec::Serial(s) = &mut spec {
        if let Some(b) = a.baud {
            if b == 0 {
                return Err(cli_err("--baud", "must be positive"));
            }
            s.baud = b;
        }
        if config.is_some() && a.serial.is_some() {
            s.watchdog = settings.serial.watchdog;
        }
        if let Some(w) = a.watchdog_ms {
            if w < 100 {
                return Err(cli_err("--watchdog-ms", "minimum 100"));
            }
            s.watchdog = Duration::from_millis(w);
        }
    }
    Ok((spec, settings))
}

fn calibrate(a: CalibrateArgs) -> i32 {
    match sfs::calibrate::calibrate_file(&a.capture, a.sensor) {
        Ok(c) => {
            {
                use std::io::Write as _;
                let _ = std::io::stdout().lock().write_all(c.render().as_bytes());
            }
            if c.usable() {
                exit::OK
            } else {
                complain!(
                    "sfs: {}: nothing usable could be fitted (see the comments above)",
                    a.capture.display()
                );
                exit::UNUSABLE
            }
        }
        Err(e) => {
            complain!("sfs: {e}");
            match e {
                sfs::calibrate::CalibrateError::NoSensor { .. } => exit::USAGE,
                _ => exit::INPUT,
            }
        }
    }
}

/// `sfs ports`: the listed ports and those given, probed in parallel with --probe.
fn ports(a: PortsArgs) -> i32 {
    use sfs::ports::{self, PortInfo, Probe};
    let mut list = ports::list();
    let mut missing = false;
    for p in &a.paths {
        if !p.exists() {
            complain!("sfs: {}: no such port", p.display());
            missing = true;
            continue;
        }
        // A symlink to a listed port is that port, under the name given.
        let real = std::fs::canonicalize(p).ok();
        let known = list
            .iter()
            .position(|q| real.as_deref() == Some(Path::new(&q.path)));
        let path = p.display().to_string();
        match known {
            Some(k) => list[k].path = path,
            None => list.push(PortInfo {
                path,
                kind: "unknown",
                usb: None,
            }),
        }
    }
    let time = Duration::from_secs_f64(a.probe_secs);
    let probes: Vec<Option<Probe>> = if a.probe {
        std::thread::scope(|s| {
            let handles: Vec<_> = list
                .iter()
                .map(|p| s.spawn(move || ports::probe(Path::new(&p.path), a.baud, time)))
                .collect();
            handles.into_iter().map(|h| h.join().ok()).collect()
        })
    } else {
        vec![None; list.len()]
    };
    if a.json {
        let rows: Vec<serde_json::Value> = list
            .iter()
            .zip(&probes)
            .map(|(p, probe)| {
                let mut v = serde_json::to_value(p).unwrap_or_default();
                if let Some(pr) = probe {
                    v["probe"] = serde_json::to_value(pr).unwrap_or_default();
                    v["probe"]["text"] = pr.to_string().into();
                }
                if let Some(rule) = udev(p, probe.as_ref()) {
                    v["udev"] = rule.into();
                }
                v
            })
            .collect();
        say!("{}", serde_json::Value::Array(rows));
    } else if list.is_empty() {
        say!("no serial ports found");
    }
    if !a.json {
        for (p, probe) in list.iter().zip(&probes) {
            let mut line = format!("{}: {}", p.path, p.kind);
            if let Some(u) = &p.usb {
                line += &format!(" {}", u.id);
                let names: Vec<&str> = [&u.manufacturer, &u.product]
                    .into_iter()
                    .filter_map(|x| x.as_deref())
                    .collect();
                if !names.is_empty() {
                    line += &format!(", {}", names.join(" "));
                }
                if let Some(sn) = &u.serial {
                    line += &format!(", serial {sn}");
                }
            }
            say!("{line}");
            if let Some(pr) = probe {
                say!("  probe: {pr}");
            }
            if let Some(rule) = udev(p, probe.as_ref()) {
                say!("  udev (deploy/99-sfs.rules): {rule}");
            }
        }
    }
    /// The udev line for a USB port whose device sent its HELLO.
    fn udev(p: &PortInfo, probe: Option<&Probe>) -> Option<String> {
        match (p.usb.as_ref(), probe) {
            (Some(u), Some(Probe::Hello { device, .. })) => ports::udev_rule(u, device),
            _ => None,
        }
    }
    if missing {
        exit::INPUT
    } else {
        exit::OK
    }
}

fn with_ext(prefix: &Path, ext: &str) -> std::path::PathBuf {
    let mut s = prefix.to_owned().into_os_string();
    s.push(ext);
    s.into()
}

/// Writes the simulator's outputs, creating the directory; an exit code on failure.
fn write_outputs(files: &[(&Path, &[u8])]) -> Result<(), i32> {
    for (p, b) in files {
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Err(e) = std::fs::create_dir_all(dir) {
                complain!("sfs: cannot create {}: {e}", dir.display());
                return Err(exit::OUTPUT);
            }
        }
        if let Err(e) = sfs::atomic::write_atomic(p, b) {
            complain!("sfs: cannot write {}: {e}", p.display());
            return Err(exit::OUTPUT);
        }
    }
    Ok(())
}

fn simulate(a: SimulateArgs) -> i32 {
    use sfs::simulate::{self, scene};
    if a.list {
        for (name, _) in scene::BUILTIN {
            let line = match scene::builtin(name) {
                Ok(s) => format!(
                    "{name:<12} {} nodes, {} curves: {}",
                    s.nodes.len(),
                    s.curves.len(),
                    s.description
                ),
                Err(e) => format!("{name:<12} not available here: {}", e.reason),
            };
            say!("{line}");
        }
        return exit::OK;
    }
    let Some(out) = a.out.as_deref() else {
        complain!("sfs: --out PREFIX is required");
        return exit::USAGE;
    };
    let (bin, truth) = (with_ext(out, ".bin"), with_ext(out, ".truth.json"));
    if !(0.0..=1.0).contains(&a.untagged) {
        complain!(
            "sfs: --untagged {}: a fraction of the crossings, from 0 to 1",
            a.untagged
        );
        return exit::USAGE;
    }
    if a.structure.is_some() && a.fault.is_some() {
        complain!("sfs: --fault applies to a scanned scene, not to a structure's sensor array");
        return exit::USAGE;
    }
    if a.structure.is_some() && a.untagged > 0.0 {
        complain!("sfs: --untagged applies to a scanned scene, not to a structure's sensor array");
        return exit::USAGE;
    }
    if let Some(kind) = a.structure {
        if !(a.duration.is_finite() && a.duration > 0.0 && a.duration <= 7.0 * 86_400.0) {
            complain!(
                "sfs: --duration: {} s is not between 0 and a week",
                a.duration
            );
            return exit::USAGE;
        }
        let (bytes, t) = simulate::structure::run(kind, a.seed, a.duration, 10.0);
        let json = serde_json::to_vec(&t).unwrap_or_default();
        if let Err(code) = write_outputs(&[(&bin, &bytes), (&truth, &json)]) {
            return code;
        }
        say!(
            "{} (array of {} sensors, seed {}): {} bytes, {:.0} s",
            kind.name(),
            t.sensors.len(),
            a.seed,
            bytes.len(),
            a.duration
        );
        say!("capture: {}\ntruth:   {}", bin.display(), truth.display());
        return exit::OK;
    }
    let arg = a.scene.as_deref().unwrap_or_default();
    let sc = match scene::resolve(arg) {
        Ok(s) => s,
        Err(e) => {
            complain!("sfs: {e}");
            // A file or mesh that is not there is the input; anything else (a directory, a
            // FIFO, a device, an oversized file, a wrong key), the usage.
            let unreadable = (scene::is_path(arg) && !Path::new(arg).exists())
                || matches!(e.key.as_deref(), Some("surface.paper" | "surface.path"));
            return if unreadable { exit::INPUT } else { exit::USAGE };
        }
    };
    let mistakes = simulate::operator::Mistakes {
        untagged: simulate::untagged_crossings(&sc, a.untagged, a.seed),
        ..Default::default()
    };
    let sim = match a.fault {
        None => simulate::run_with(&sc, a.device.0, a.profile, a.seed, &mistakes),
        Some(f) => {
            match simulate::run_planted_with(&sc, a.device.0, a.profile, a.seed, &mistakes, f) {
                Ok(sim) => sim,
                Err(e) => {
                    complain!("sfs: {e} (scene {})", sc.name);
                    return exit::USAGE;
                }
            }
        }
    };
    let json = match serde_json::to_vec(&sim.truth) {
        Ok(j) => j,
        Err(e) => {
            complain!("sfs: cannot serialise the truth: {e}");
            return exit::INTERNAL;
        }
    };
    if let Err(code) = write_outputs(&[(&bin, &sim.bytes), (&truth, &json)]) {
        return code;
    }
    say!(
        "{} ({}, {} profile, seed {}): {} nodes, {} curves, {} bytes, {:.0} s of scanning",
        sc.name,
        a.device.0.name(),
        a.profile.name(),
        a.seed,
        sc.nodes.len(),
        sc.curves.len(),
        sim.bytes.len(),
        sim.samples.t.last().copied().unwrap_or(0.0)
    );
    if !mistakes.untagged.is_empty() {
        say!(
            "{} crossing(s) left untagged on one of their curves (listed in the truth's events)",
            mistakes.untagged.len()
        );
    }
    for f in &sim.truth.faults {
        let at = match (f.tag, f.node) {
            (Some(t), Some(n)) => format!(", tag {t} (node {n})"),
            _ => String::new(),
        };
        say!(
            "planted: {} on curve {}{at} (the truth's faults)",
            f.kind,
            f.curve
        );
    }
    say!("capture: {}\ntruth:   {}", bin.display(), truth.display());
    exit::OK
}

fn eval(a: EvalArgs) -> i32 {
    // Nothing the user made is written over: an input never, another file only if asked.
    if let Some(out) = &a.out {
        if let Some(input) = [&a.truth, &a.glb].into_iter().find(|i| same_file(out, i)) {
            complain!(
                "sfs: --out {} is an input of this evaluation ({}): give another file",
                out.display(),
                input.display()
            );
            return exit::USAGE;
        }
        if out.exists() && !a.force {
            complain!(
                "sfs: --out {} exists: give another file, or --force to replace it",
                out.display()
            );
            return exit::USAGE;
        }
    }
    let truth = match sfs::simulate::truth::Truth::load(&a.truth) {
        Ok(t) => t,
        Err(e) => {
            complain!("sfs: {e}");
            return exit::INPUT;
        }
    };
    let bytes = match std::fs::read(&a.glb) {
        Ok(b) => b,
        Err(e) => {
            complain!("sfs: cannot read {}: {e}", a.glb.display());
            return exit::INPUT;
        }
    };
    if !bytes.starts_with(b"glTF") {
        complain!(
            "sfs: {}: this is {}, not a glb (a session's network.glb)",
            a.glb.display(),
            sfs::simulate::truth::looks_like(&bytes)
        );
        return exit::INPUT;
    }
    let rec = match sfs::gltf_out::read_glb(&bytes) {
        Ok(r) => r,
        Err(e) => {
            complain!("sfs: {}: {e}", a.glb.display());
            return exit::INPUT;
        }
    };
    let ev = match sfs::eval::evaluate(&truth, &rec) {
        Ok(e) => e,
        Err(e) => {
            complain!("sfs: {}: {e}", a.glb.display());
            return exit::UNUSABLE;
        }
    };
    let json = serde_json::to_string_pretty(&ev).unwrap_or_default();
    match &a.out {
        None => say!("{json}"),
        Some(r) => {
            if let Err(e) = sfs::atomic::write_atomic(r, format!("{json}\n").as_bytes()) {
                complain!("sfs: cannot write {}: {e}", r.display());
                return exit::OUTPUT;
            }
        }
    }
    if !ev.registration.nodes_unknown.is_empty() {
        complain!(
            "sfs: {} has nodes the truth of scene {} does not have ({:?}): is the truth of the scene that was scanned?",
            a.glb.display(),
            ev.scene,
            ev.registration.nodes_unknown
        );
    }
    if ev.registration.residual_rms_pct > sfs::eval::MAX_RESIDUAL_PCT {
        complain!(
            "sfs: no rigid registration fits {} onto the truth of scene {}: {:.1} % of the diagonal left after {} iterations (at most {} % for the same shape): is the truth of the scene that was scanned?",
            a.glb.display(),
            ev.scene,
            ev.registration.residual_rms_pct,
            ev.registration.icp_iterations,
            sfs::eval::MAX_RESIDUAL_PCT
        );
    }
    if !ev.registration.fits {
        return exit::UNUSABLE;
    }
    exit::OK
}

/// Whether `a` and `b` name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// What a replay into `dir` would write over: a session's capture and configuration, and the
/// outputs of a run or a replay (scanning or monitoring), those there.
fn outputs_in(dir: &Path) -> Vec<&'static str> {
    use sfs::monitor::run::{EVENTS_FILE, LATEST_FILE, METRICS_FILE, REFERENCE_FILE};
    use sfs::pipeline::{NETWORK_FILE, REPORT_FILE, SCAN_FILE};
    [
        session::CAPTURE_FILE,
        session::CONFIG_COPY,
        REPORT_FILE,
        SCAN_FILE,
        NETWORK_FILE,
        METRICS_FILE,
        EVENTS_FILE,
        LATEST_FILE,
        REFERENCE_FILE,
    ]
    .into_iter()
    .filter(|f| dir.join(f).exists())
    .collect()
}

/// `1 curve`, `2 curves`.
fn plural(n: usize, word: &str) -> String {
    format!("{n} {word}{}", if n == 1 { "" } else { "s" })
}

fn config_check(file: &Path) -> i32 {
    match config::check(file) {
        Ok(settings) => {
            say!("{}: ok", file.display());
            // A view others can reach and no token: anyone on that network watches the scan.
            if let Some(v) = settings.view {
                if !v.ip().is_loopback() && settings.view_access.token.is_none() {
                    say!(
                        "warning: view.address {v} is reachable from the network and view.token is not set: anyone there can watch this session (set a token, or serve on 127.0.0.1)"
                    );
                }
            }
            // What a monitoring configuration describes, to check it against the structure.
            if let Some(m) = &settings.monitor {
                let rotation = settings.capture_rotation;
                let nodes: std::collections::BTreeSet<u32> = m
                    .layout
                    .curves
                    .iter()
                    .flat_map(|c| c.nodes.iter().copied())
                    .collect();
                let reference = match &m.reference {
                    Some(_) => "a reference file".to_string(),
                    None => format!("the mean of the first {} s", m.reference_s),
                };
                say!(
                    "monitor: {} on {} ({}, node {} at the origin, x at {}° from magnetic north); {} epochs/s; reference: {reference}; {}{}{}{}",
                    plural(m.layout.sensors.len(), "sensor"),
                    plural(m.layout.curves.len(), "curve"),
                    plural(nodes.len(), "node"),
                    m.anchor,
                    m.x_azimuth_deg,
                    m.epoch_hz,
                    plural(m.alarms.len(), "alarm"),
                    if m.surface.is_some() { "; surface" } else { "" },
                    m.http.map(|a| format!("; metrics at http://{a}/metrics")).unwrap_or_default(),
                    rotation
                        .map(|r| format!(
                            "; capture rotated at {} MB, {} kept",
                            r.max_bytes as f64 / 1e6,
                            r.keep
                        ))
                        .unwrap_or_default(),
                );
            }
            exit::OK
        }
        Err(errors) => {
            for e in &errors {
                complain!("sfs: {e}");
            }
            if errors.len() > 1 {
                complain!("sfs: {}: {} errors", file.display(), errors.len());
            }
            exit::USAGE
        }
    }
}

fn run_session(spec: SourceSpec, out: &Path, settings: &Settings, start: session::Start) -> i32 {
    run_session_then(spec, out, settings, start, |_| exit::OK)
}

/// Runs a session, prints its summary, then `verdict` gives the exit code from the outcome;
/// a view still served (a replay with `--view`) is served after that, until interrupted.
fn run_session_then(
    spec: SourceSpec,
    out: &Path,
    settings: &Settings,
    start: session::Start,
    verdict: impl FnOnce(&Outcome) -> i32,
) -> i32 {
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            complain!("sfs: cannot start the runtime: {e}");
            return exit::INTERNAL;
        }
    };
    rt.block_on(async {
        let shutdown = Shutdown::new();
        tokio::spawn(signals(shutdown.clone()));
        match session::run(spec, out, settings, start, shutdown.clone()).await {
            Ok(mut o) => {
                let code = verdict(&o);
                print_summary(&o, code == exit::OK);
                if let Some(serving) = o.serving.take() {
                    serving.until(&shutdown).await;
                }
                code
            }
            Err(e) => {
                complain!("sfs: {e}");
                match e {
                    SessionError::Source(SourceError::Thread(_)) => exit::INTERNAL,
                    SessionError::Source(_) | SessionError::Read { .. } => exit::INPUT,
                    SessionError::Output(_)
                    | SessionError::Capture(_)
                    | SessionError::Serve { .. } => exit::OUTPUT,
                    SessionError::CaptureExists { .. } | SessionError::Resume(_) => exit::USAGE,
                }
            }
        }
    })
}

/// First SIGINT/SIGTERM: orderly shutdown. Second: exit at once (every output file is replaced
/// atomically and the capture is append-only, so nothing is left corrupt).
async fn signals(shutdown: Shutdown) {
    use tokio::signal::unix::{signal, SignalKind};
    let (Ok(mut int), Ok(mut term)) = (
        signal(SignalKind::interrupt()),
        signal(SignalKind::terminate()),
    ) else {
        tracing::warn!("cannot install signal handlers");
        return;
    };
    for n in 0.. {
        tokio::select! {
            _ = int.recv() => {}
            _ = term.recv() => {}
        }
        if n == 0 {
            tracing::info!("signal received: finishing (send again to exit at once)");
            shutdown.trigger();
        } else {
            complain!("sfs: second signal, exiting now");
            std::process::exit(exit::INTERRUPTED);
        }
    }
}

/// The summary lines of a finished session; the outputs' paths when `kept` (a failed replay
/// removes them).
fn print_summary(o: &Outcome, kept: bool) {
    let l = &o.report.link;
    say!(
        "{}: {} bytes, {} packets, {} rejected (crc {}, cobs {}, length {}), {} unknown, {} lost, {} reboots, {} clock wraps ({}, {:.2} s)",
        o.report.source,
        l.bytes,
        l.packets.total(),
        l.rejected.total(),
        l.rejected.crc,
        l.rejected.cobs,
        l.rejected.length,
        l.unknown_types,
        l.lost_packets,
        l.reboots,
        l.clock_wraps,
        o.report.ended,
        o.report.wall_time_s,
    );
    if let Some(m) = &o.report.monitor {
        let last = m.last.map_or("no metrics".to_string(), |x| {
            format!(
                "last: max displacement {:.3} m, mean {:.3} m, curvature change {:.4} rad/m",
                x.max_displacement, x.mean_displacement, x.max_curvature_change
            )
        });
        say!(
            "monitor: {} epochs ({} failed), alarms raised: {}; {last}",
            m.epochs,
            m.failed,
            m.alarms_raised
        );
    }
    let r = &o.report;
    if r.monitor.is_none() {
        say!("{}", network_summary(r));
        say!("{}", warnings_summary(r));
        let q = &r.quality;
        say!("scan: {} ({})", q.verdict.name(), q.verdict_reason);
    } else {
        say!("{}", warnings_summary(r));
    }
    if !kept {
        return;
    }
    if let Some(c) = &o.capture_path {
        say!("capture: {}", c.display());
    }
    say!("report:  {}", o.report_path.display());
    // The other outputs beside the report (scan.json, network.glb; monitoring's files).
    let dir = o.report_path.parent().unwrap_or(Path::new("."));
    let others: Vec<String> = outputs_in(dir)
        .into_iter()
        .filter(|f| {
            ![
                session::CAPTURE_FILE,
                session::CONFIG_COPY,
                sfs::pipeline::REPORT_FILE,
            ]
            .contains(f)
        })
        .map(|f| dir.join(f).display().to_string())
        .collect();
    if !others.is_empty() {
        say!("outputs: {}", others.join(", "));
    }
}

/// `curves: 7 accepted (1 discarded, 0 left out of the network), 12 nodes; surface: 8
/// patches, 3312 triangles` (or why there is none).
fn network_summary(r: &sfs::report::Report) -> String {
    let accepted = r.curves.len() as u64 + r.curves_left_out;
    let left_out = r.network.as_ref().map_or(0, |n| n.curves_left_out);
    let surface = match (&r.network, &r.surface) {
        (_, Some(s)) => format!(
            "{} {}, {} triangles{}",
            s.patches,
            if s.patches == 1 { "patch" } else { "patches" },
            s.triangles,
            if s.holes > 0 {
                format!(", {}", plural(s.holes, "hole"))
            } else {
                String::new()
            }
        ),
        (None, None) => "none (no network)".to_string(),
        (Some(_), None) => match r
            .warnings
            .iter()
            .find(|w| matches!(w, sfs::warning::Warning::NoSurface(_)))
        {
            Some(w) => format!("none ({w})"),
            None => "none".to_string(),
        },
    };
    format!(
        "curves: {} accepted ({} discarded, {} left out of the network), {}; surface: {surface}",
        accepted,
        r.acquisition.curves_discarded,
        left_out,
        plural(r.nodes.len(), "node"),
    )
}

/// `warnings: 3 (keypad_repeat 2, tag_detached 1)`, or `warnings: none`.
fn warnings_summary(r: &sfs::report::Report) -> String {
    let total: u64 = r.warnings_by_code.values().sum();
    if total == 0 {
        return "warnings: none".to_string();
    }
    let by: Vec<String> = r
        .warnings_by_code
        .iter()
        .map(|(code, n)| format!("{code} {n}"))
        .collect();
    format!(
        "warnings: {total} ({}; their texts in the report)",
        by.join(", ")
    )
}
