//! The configuration file (`config/*.toml`, serde), resolved once into
//! [`Settings`](crate::settings::Settings): one module per section (`source`, `acquisition`
//! with `[calibration]`, `curves`, `network`, `surface`, `output`, `monitor`), each checking
//! its keys.
//! Every error names the key and the reason ([`ConfigError`]). Command-line flags are kept
//! apart (`cli`) and applied on top by `main`.
//!
//! ```toml
//! [source]
//! kind = "serial"          # "serial" | "replay" | "stdin"
//! path = "/dev/ttyUSB0"    # serial port, or capture file for "replay"
//! baud = 115200
//! watchdog_ms = 3000       # silence that counts as a disconnect
//! pace = "fast"            # replay only: "fast" | "realtime" | "x10" (10× real time)
//! ```
//!
//! A relative `path` of a capture file is relative to the configuration file's directory.
//!
//! ```toml
//! [calibration]                      # of the device; vectors in sensor axes
//! acc_bias = [0.0, 0.0, 0.0]         # m/s², subtracted
//! acc_scale = [1.0, 1.0, 1.0]        # per axis, after the bias
//! mag_hard_iron = [0.0, 0.0, 0.0]    # µT, subtracted
//! mag_soft_iron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
//! gyro_bias = [0.0, 0.0, 0.0]        # rad/s
//! axes = ["x", "y", "z"]             # sensor axes giving T, B, N (default: per device kind)
//! mounting_deg = [0.0, 0.0, 0.0]     # rotation about T, B, N (roll, pitch, yaw), degrees
//!
//! [acquisition]
//! acc_tolerance = 0.6                # m/s²: | |a| - g | above flags motion acceleration
//! mag_norm_tolerance = 0.08          # relative: field norm off the session's median
//! mag_dip_tolerance_deg = 4.0        # field dip off the session's median
//! stationary_window_s = 0.25         # half-width of the standing-still test
//! stationary_distance = 0.002        # Morphorider: still if the wheel moves less (m; (0, 1])
//! stationary_gyro_deg_s = 3.0        # phone: still below this rotation rate
//! stand_margin_s = 1.0               # phone: standing only this close to typing an index
//! heading_bias_tau_s = 0.0           # phone: learn the gyro bias in motion from the heading
//! tilt_bias_tau_s = 0.0              #   and tilt corrections (time constants; 0 = off)
//! smooth = true                      # phone: each finished curve's orientations smoothed
//!                                    #   forward and backward, the gyro bias a state
//! nominal_speed = 0.05               # phone: m/s where no segment length is known
//! array_window_s = 1.0               # sensor arrays: averaging window
//! max_node = 999999                  # largest node index typed; a larger one is not tagged
//! max_curve_samples = 2000000        # a curve is ended (with a warning) at this many samples
//! loop_distance = 0.05               # Morphorider: wheel travel (m) making a node tagged twice
//!                                    #   in a row a loop through it, not a repeated Enter
//! loop_turn_deg = 180.0              # phone: the same, as the angle turned through
//! [acquisition.segment_lengths]      # phone: measured segment lengths (m) per curve index
//! "0" = [0.30, 0.25]
//!
//! [curves]                           # what curves mean, by curve index (else their start key)
//! kinds = { "3" = "crease" }         #   boundary | interior | crease | guide
//!
//! [network]                          # curve-network reconstruction
//! h = 0.01                           # sampling step, m
//! sigma = 0.3                        # pre-filter kernel width, in h
//! alpha = 0.9                        # outlier threshold on |q_i · q_i±1|
//! regression = true                  # false: pre-filter only
//! estimate_mounting = true           # the device's mounting offset (roll, pitch) from the
//!                                    #   normals at the nodes, its yaw from the loops;
//!                                    #   false: frames as measured
//! estimate_curve_scales = true       # Morphorider: each curve's distance scale (its wheel
//!                                    #   reads a pass ~1 % long or short) from the loops;
//!                                    #   false: distances as measured
//! repair_slips = true                # a segment the loops name a slip is lengthened by
//!                                    #   their estimate; false: kept as measured
//! bend_fraction = 0.5                # bending smoothing length ℓ₂ in h (or bend_length in m)
//! stretch_length = 0.0               # stretching smoothing length ℓ₁, m
//! xi = 1e4                           # weight of the node normal consistency
//! local_window = 3                   # live: samples either side of the new curve's nodes
//!                                    # regressed again (0: the whole network every update)
//! join_distance = 0.015              # a node tagged on one curve joins another curve passing
//!                                    #   within this, m (0: no joins, no proposals)
//! join_normal_deg = 15.0             #   with normals agreeing within this, degrees
//! join_untagged = false              # true: crossings nobody tagged are joined too (else proposed)
//! refuse = [[3, 7]]                  # pairs of curves never joined nor proposed
//!
//! [surface]                          # surfacing with normal control
//! enabled = true                     # false: write the network only
//! edge = 0.01                        # target edge inside patches, m (default: the samples'
//!                                    # spacing, at least 1/120 of the network's diagonal)
//! max_vertices = 20000               # the default edge grows to keep about this many vertices
//! reweight = 1                       # passes with cotangent weights from the 3D surface
//! soft = 0.3                         # soft positional constraints of weight ω; 0: hard
//! guide_weight = 0.1                 # the pull of guide curves (G), approximated
//! reuse_tolerance = 0.5              # live: faces kept while their rims moved less than this
//!                                    #   many edges; each update provisional at once, then
//!                                    #   settled exactly when idle (0: every update exact)
//!
//! [monitor]                          # instrumented structures (sensor arrays)
//! epoch_hz = 5.0                     # shapes per second
//! anchor = 0                         # the node at the origin (default: curve 0's first)
//! x_azimuth_deg = 90.0               # the structure's x axis, clockwise from magnetic north
//!                                    #   (default: x east, y north, z up)
//! reference_s = 10.0                 # the mean shape of the first seconds is the reference,
//! # reference_file = "reference.json" #   or a fixed one (a session's reference.json, or a design)
//! smoothing_s = 0.0                  # smooth each sensor across epochs (time constant, s)
//! latest_every = 5                   # latest.glb replaced every this many epochs
//! surface = false                    # true: latest.glb with the surface ([surface] settings)
//! regression = false                 # true: the regression on SO(3) over the network in each
//!                                    #   epoch ([network] settings)
//! metrics_max_mb = 64.0              # metrics.csv rotated past this size …
//! metrics_keep = 4                   # … keeping this many old files
//! http_port = 9464                   # Prometheus metrics at http://127.0.0.1:9464/metrics
//! http_address = "127.0.0.1"         #   (off without http_port; 0.0.0.0 to serve others)
//! [[monitor.alarm]]                  # any number; metric: max_displacement,
//! metric = "max_displacement"        #   mean_displacement or max_curvature_change
//! threshold = 0.5                    # m (rad/m for curvature): raised above it …
//! hysteresis = 0.05                  # … cleared below threshold − hysteresis
//! [[monitor.curve]]                  # curve 0, 1, … in order
//! nodes = [0, 1]                     # nodes along it
//! node_s = [0.0, 20.0]               # their rest arc lengths, m
//! length = 20.0
//! [[monitor.sensor]]
//! sensor = 0                         # the id in ARRAY_SAMPLE packets
//! curve = 0
//! s = 0.0                            # rest arc length on the curve, m
//!
//! [output]                           # what `sfs run` writes into the session directory
//! live = true                        # rebuild network.glb and report.json after every curve
//! snapshots = false                  # also keep snapshots/curve-NNN.glb per curve
//! capture_max_mb = 256.0             # capture.bin rotated past this size (default: never;
//! capture_keep = 8                   #   256 MB and 8 kept when monitoring) … keeping this many
//!
//! [view]                             # the live view (a web page) while the session runs
//! address = "127.0.0.1:8040"         # where to serve it (no view without it, or --view)
//! allowed_hosts = ["scanner.lan"]    # names it answers besides localhost and addresses
//! # token = "…"                      # every request must carry it (≥ 16 characters)
//! ```

mod acquisition;
mod curves;
mod monitor;
mod network;
mod output;
mod phone;
mod source;
mod surface;
mod view;

use crate::settings::{SerialSettings, Settings};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub use crate::settings::{DEFAULT_BAUD, DEFAULT_WATCHDOG_MS};

/// A configuration error: the file, the key, the reason.
#[derive(Debug, thiserror::Error)]
#[error("{}: {}{reason}", file.display(), if key.is_empty() { String::new() } else { format!("{key}: ") })]
pub struct ConfigError {
    pub file: PathBuf,
    /// Dotted key (`source.baud`), or empty when the file itself is at fault.
    pub key: String,
    pub reason: String,
}

impl ConfigError {
    /// `key` of `file` is wrong, for `reason`.
    pub fn new(file: &Path, key: impl Into<String>, reason: impl Into<String>) -> ConfigError {
        ConfigError {
            file: file.to_owned(),
            key: key.into(),
            reason: reason.into(),
        }
    }
}

/// The whole configuration file, as written.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    /// None: the file names no source (`sfs replay` and `sfs run --serial/--stdin` give one).
    source: Option<source::SourceToml>,
    #[serde(default)]
    calibration: acquisition::CalibrationToml,
    #[serde(default)]
    acquisition: acquisition::AcquisitionToml,
    #[serde(default)]
    curves: curves::CurvesToml,
    #[serde(default)]
    network: network::NetworkToml,
    #[serde(default)]
    surface: surface::SurfaceToml,
    #[serde(default)]
    output: output::OutputToml,
    #[serde(default)]
    view: view::ViewToml,
    /// The phone page (`sfs run --phone`).
    phone: Option<phone::PhoneToml>,
    /// Monitoring of an instrumented structure (see the module documentation).
    monitor: Option<monitor::MonitorToml>,
}

/// Largest file a configuration may name (a reference shape), bytes: a larger one (or one
/// that never ends, like `/dev/zero`) is refused instead of read until memory runs out.
pub const MAX_NAMED_FILE: u64 = 64 << 20;

/// Reads a file a configuration names (a reference shape): regular, at most `limit` bytes.
fn read_limited(path: &Path, limit: u64) -> std::io::Result<String> {
    crate::named_file::read_text(path, limit, "a reference shape")
}

/// Largest configuration file, bytes.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Reads a configuration file: a regular file (never a FIFO or a device, which could block or
/// never end) of at most [`MAX_CONFIG_BYTES`]; the error says why not.
pub fn read_config_file(path: &Path) -> Result<String, String> {
    crate::named_file::read_text(path, MAX_CONFIG_BYTES, "a configuration")
        .map_err(|e| format!("cannot read: {e}"))
}

/// Reads `path` and resolves it into the settings it describes (every key checked, each
/// section once). Relative paths inside it are taken relative to the directory of the file,
/// so a shipped configuration works from any working directory.
pub fn load(path: &Path) -> Result<Settings, ConfigError> {
    let text = read_config_file(path).map_err(|reason| ConfigError::new(path, "", reason))?;
    from_text(&text, path).and_then(|s| files_named(s, path))
}

/// The files a configuration names, checked where the configuration is loaded (so that
/// `sfs run` refuses what `sfs config check` refuses): a replayed capture must be a regular
/// file (a device such as `/dev/zero` would be read for ever, a FIFO block).
fn files_named(settings: Settings, file: &Path) -> Result<Settings, ConfigError> {
    if let Some(crate::source::SourceSpec::Replay { path, .. }) = &settings.source {
        if !path.is_file() {
            return Err(ConfigError::new(
                file,
                "source.path",
                format!(
                    "{} is not a regular file{}",
                    path.display(),
                    if path.exists() {
                        ""
                    } else {
                        " (it does not exist)"
                    }
                ),
            ));
        }
    }
    Ok(settings)
}

/// As [`load`], for the text of a file at `path`.
pub fn from_text(text: &str, path: &Path) -> Result<Settings, ConfigError> {
    let mut cfg: ConfigFile = toml::from_str(text).map_err(|e| de_error(path, text, &e, ""))?;
    resolve_paths(&mut cfg, path);
    cfg.settings(path)
}

/// A replayed capture's relative path is relative to the configuration's directory.
fn resolve_paths(cfg: &mut ConfigFile, path: &Path) {
    let base = path.parent().unwrap_or(Path::new(""));
    if let Some(src) = &mut cfg.source {
        if let Some(p) = &mut src.path {
            if p.is_relative() && src.kind != "serial" {
                *p = base.join(&*p);
            }
        }
    }
}

/// Loads a session's kept configuration (`SESSION/config.toml`, see [`kept_config`]): its
/// relative paths are resolved where it was copied from, and its errors name that file.
pub fn load_kept(path: &Path) -> Result<Settings, ConfigError> {
    let text = read_config_file(path).map_err(|reason| ConfigError::new(path, "", reason))?;
    match kept_origin(&text) {
        (Some(origin), body) => from_text(body, &origin),
        (None, _) => from_text(&text, path),
    }
    .and_then(|s| files_named(s, path))
}

/// Every error of a configuration file, each naming its key (see [`ConfigError`]): what
/// `sfs config check` reports. [`load`] stops at the first.
pub fn check(path: &Path) -> Result<Settings, Vec<ConfigError>> {
    let text = read_config_file(path).map_err(|reason| vec![ConfigError::new(path, "", reason)])?;
    // A syntax error stops the reading: where it is, by line and column.
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e.span().map_or(String::new(), |s| {
            let (line, col) = line_col(&text, s.start);
            format!("line {line}, column {col}: ")
        });
        vec![ConfigError::new(
            path,
            "",
            format!("{at}{}", e.message().trim()),
        )]
    })?;
    // Each section on its own, so that one's error does not hide another's; the sections
    // that read are then resolved, and their errors added.
    let mut errors = Vec::new();
    let mut good = toml::Table::new();
    for (k, v) in &table {
        let mut one = toml::Table::new();
        one.insert(k.clone(), v.clone());
        let piece = toml::to_string(&one).unwrap_or_default();
        match toml::from_str::<ConfigFile>(&piece) {
            Ok(_) => {
                good.insert(k.clone(), v.clone());
            }
            Err(e) => errors.push(de_error(path, &piece, &e, k)),
        }
    }
    let mut cfg: ConfigFile = match toml::Value::Table(good).try_into() {
        Ok(c) => c,
        Err(e) => {
            errors.push(ConfigError::new(path, "", e.message().trim()));
            return Err(errors);
        }
    };
    resolve_paths(&mut cfg, path);
    match cfg.settings_all(path) {
        Ok(s) if errors.is_empty() => files_named(s, path).map_err(|e| vec![e]),
        Ok(_) => Err(errors),
        Err(more) => {
            errors.extend(more);
            Err(errors)
        }
    }
}

/// A configuration `text` of `path` that does not read as the file's sections: the key where
/// it went wrong (`key` when the error says no place), and why.
fn de_error(path: &Path, text: &str, e: &toml::de::Error, key: &str) -> ConfigError {
    let key = e
        .span()
        .map_or_else(|| key.to_owned(), |s| key_at(text, s.start));
    ConfigError::new(path, key, e.message().trim())
}

/// Line and column (from 1, in characters) of byte `at` of `text`.
fn line_col(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// A section's value, or the error kept in `errors`.
fn take<T>(r: Result<T, ConfigError>, errors: &mut Vec<ConfigError>) -> Option<T> {
    r.map_err(|e| errors.push(e)).ok()
}

impl ConfigFile {
    /// Every section resolved, once; the first error.
    fn settings(&self, file: &Path) -> Result<Settings, ConfigError> {
        self.settings_all(file).map_err(|mut e| e.swap_remove(0))
    }

    /// Every section resolved, once; every section's error.
    fn settings_all(&self, file: &Path) -> Result<Settings, Vec<ConfigError>> {
        let mut errors = Vec::new();
        let e = &mut errors;
        let source = take(self.source.as_ref().map(|s| s.spec(file)).transpose(), e);
        let raw = self.source.clone().unwrap_or_default();
        let acquisition = take(self.acquisition_config(file), e);
        let kinds = take(self.curve_kinds(file), e);
        let network = take(self.network_params(file), e);
        let joins = take(self.join_settings(file), e);
        let surface = take(self.surface_params(file), e);
        // The monitor's reconstruction builds on the network's and the surface's settings.
        let monitor = match (&network, surface) {
            (Some(n), Some(s)) => take(self.monitor_config(file, s, n), e),
            _ => None,
        };
        let capture_rotation = take(self.capture_rotation(file), e);
        let view = take(self.view_address(file), e);
        let view_access = take(self.view_access(file), e);
        let phone = take(self.phone(file), e);
        let (
            Some(source),
            Some(mut acquisition),
            Some(kinds),
            Some(network),
            Some(joins),
            Some(surface),
            Some(monitor),
            Some(capture_rotation),
            Some(view),
            Some(view_access),
            Some(phone),
        ) = (
            source,
            acquisition,
            kinds,
            network,
            joins,
            surface,
            monitor,
            capture_rotation,
            view,
            view_access,
            phone,
        )
        else {
            return Err(errors);
        };
        acquisition.kinds = kinds;
        let settings = Settings {
            source,
            serial: SerialSettings {
                baud: raw.baud,
                watchdog: Duration::from_millis(raw.watchdog_ms),
            },
            acquisition,
            network,
            joins,
            surface,
            live: self.output.live.unwrap_or(true) && self.monitor.is_none(),
            snapshots: self.output.snapshots.unwrap_or(false),
            monitor: None,
            capture_rotation,
            view,
            keep_serving: false,
            view_access,
            phone,
        };
        Ok(match monitor {
            Some(m) => settings.with_monitor(m),
            None => settings,
        })
    }
}

/// The first line of a kept configuration: where it was copied from. Its relative paths (a
/// replayed capture, a reference file) are relative to that file's directory, not to the
/// session's.
const CONFIG_ORIGIN: &str = "# sfs: copied from ";

/// The text to keep as `config.toml` for the configuration `text` read from `origin`.
pub fn kept_config(text: &str, origin: &Path) -> String {
    let origin = std::path::absolute(origin).unwrap_or_else(|_| origin.to_owned());
    format!("{CONFIG_ORIGIN}{}\n{text}", origin.display())
}

/// A kept configuration's origin (see [`kept_config`]) and its text as it was.
pub fn kept_origin(kept: &str) -> (Option<PathBuf>, &str) {
    match kept
        .strip_prefix(CONFIG_ORIGIN)
        .and_then(|r| r.split_once('\n'))
    {
        Some((origin, text)) => (Some(PathBuf::from(origin)), text),
        None => (None, kept),
    }
}

/// The dotted key whose line contains byte offset `at` (best effort, for error messages).
fn key_at(text: &str, at: usize) -> String {
    let mut table = String::new();
    let mut key = String::new();
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        let t = line.trim();
        if t.starts_with('[') {
            table = t.trim_matches(|c| c == '[' || c == ']').trim().to_owned();
            key.clear();
        } else if let Some((k, _)) = t.split_once('=') {
            key = k.trim().to_owned();
        }
        if at < pos + line.len() {
            break;
        }
        pos += line.len();
    }
    match (table.is_empty(), key.is_empty()) {
        (true, true) => String::new(),
        (true, false) => key,
        (false, true) => table,
        (false, false) => format!("{table}.{key}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::source::SourceSpec;

    fn parse(t: &str) -> Result<Settings, ConfigError> {
        from_text(t, Path::new("x.toml"))
    }

    /// A configuration that sets nothing but its source runs with the documented defaults,
    /// as a session without a configuration file does.
    #[test]
    fn an_empty_configuration_resolves_to_the_defaults() {
        let s = parse("[source]\nkind = \"stdin\"\n").unwrap();
        assert!(matches!(s.source, Some(SourceSpec::Stdin)));
        let s = Settings { source: None, ..s };
        assert_eq!(format!("{s:?}"), format!("{:?}", Settings::default()));
        // Without a [source] (replay, --serial or --stdin give one): no source, the defaults.
        let s = parse("").unwrap();
        assert!(s.source.is_none());
        assert_eq!(format!("{s:?}"), format!("{:?}", Settings::default()));
    }

    #[test]
    fn serial_with_defaults() {
        let c = parse("[source]\nkind = \"serial\"\npath = \"/dev/ttyUSB0\"\n").unwrap();
        match c.source.unwrap() {
            SourceSpec::Serial(s) => {
                assert_eq!(s.baud, DEFAULT_BAUD);
                assert_eq!(s.watchdog, Duration::from_millis(DEFAULT_WATCHDOG_MS));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn errors_name_the_key() {
        let e =
            parse("[source]\nkind = \"serial\"\npath = \"/dev/x\"\nbaud = \"fast\"\n").unwrap_err();
        assert_eq!(e.key, "source.baud", "{e}");
        let e = parse("[source]\nkind = \"serial\"\n").unwrap_err();
        assert_eq!(e.key, "source.path", "{e}");
        let e = parse("[source]\nkind = \"usb\"\npath = \"/dev/x\"\n").unwrap_err();
        assert_eq!(e.key, "source.kind", "{e}");
        let e =
            parse("[source]\nkind = \"serial\"\npath = \"/dev/x\"\nbaudrate = 9600\n").unwrap_err();
        assert_eq!(e.key, "source.baudrate", "{e}");
        assert!(e.reason.contains("unknown field"), "{e}");
        let e =
            parse("[source]\nkind = \"replay\"\npath = \"a.bin\"\npace = \"slow\"\n").unwrap_err();
        assert_eq!(e.key, "source.pace", "{e}");
    }

    #[test]
    fn monitor_layout_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let curve = "[[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n";
        let sensor = |id: u16, c: usize, s: f64| {
            format!("[[monitor.sensor]]\nsensor = {id}\ncurve = {c}\ns = {s}\n")
        };
        let ok = parse(&format!(
            "{base}[monitor]\nepoch_hz = 2.0\n{curve}{}{}",
            sensor(0, 0, 0.0),
            sensor(1, 0, 20.0)
        ))
        .unwrap();
        let m = ok.monitor.unwrap();
        assert_eq!((m.layout.sensors.len(), m.epoch_hz, m.anchor), (2, 2.0, 0));
        assert_eq!(m.http, None, "no endpoint unless asked for");
        assert_eq!(
            (m.regression, m.surface.is_some()),
            (None, false),
            "off by default"
        );
        let on = parse(&format!(
            "{base}[network]\nxi = 2.0\n[monitor]\nregression = true\nsurface = true\n{curve}"
        ))
        .unwrap()
        .monitor
        .unwrap();
        assert_eq!(
            on.regression.map(|r| r.xi),
            Some(2.0),
            "with the [network] settings"
        );
        assert!(on.surface.is_some());
        let cases = [
            (format!("[monitor]\n{curve}{}", sensor(0, 1, 0.0)), "monitor.sensor[0]", "curve 1"),
            (
                format!("[monitor]\n{curve}{}{}", sensor(0, 0, 0.0), sensor(0, 0, 1.0)),
                "monitor.sensor[0]",
                "twice",
            ),
            (format!("[monitor]\n{curve}{}", sensor(3, 0, 25.0)), "monitor.sensor[0]", "outside"),
            (
                "[monitor]\n[[monitor.curve]]\nnodes = [0, 1]\nnode_s = [5.0, 1.0]\nlength = 20.0\n"
                    .to_string(),
                "monitor.curve[0]",
                "increase",
            ),
            (format!("[monitor]\nepoch_hz = 0.0\n{curve}"), "monitor.epoch_hz", "out of range"),
            (format!("[monitor]\nanchor = 7\n{curve}"), "monitor.anchor", "node 7"),
            ("[monitor]\nepoch_hz = 1.0\n".to_string(), "monitor.curve", "at least one"),
            (format!("[monitor]\nhttp_port = 0\n{curve}"), "monitor.http_port", "not a port"),
            (
                format!("[surface]\nenabled = false\n[monitor]\nsurface = true\n{curve}"),
                "monitor.surface",
                "enabled = false",
            ),
            (
                format!("[monitor]\nhttp_port = 9464\nhttp_address = \"localhost\"\n{curve}"),
                "monitor.http_address",
                "not an IP",
            ),
            (
                format!("[monitor]\n{curve}[[monitor.alarm]]\nmetric = \"tip\"\nthreshold = 1.0\n"),
                "monitor.alarm[0].metric",
                "not one of",
            ),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
    }

    #[test]
    fn monitor_reference_file_errors_name_the_key_and_the_file() {
        let dir = std::env::temp_dir().join(format!("sfs-config-ref-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("monitor.toml");
        let reference = |anchor: u32, curve: usize| {
            format!(
                r#"{{"format": "sfs-monitor-reference", "version": 1, "anchor": {anchor},
                    "curves": [{{"curve": {curve}, "points": [[0, 0, 0], [0, 0, 20]]}}]}}"#
            )
        };
        std::fs::write(dir.join("good.json"), reference(0, 0)).unwrap();
        std::fs::write(dir.join("anchor.json"), reference(1, 0)).unwrap();
        std::fs::write(dir.join("curve.json"), reference(0, 3)).unwrap();
        std::fs::write(
            dir.join("format.json"),
            r#"{"format": "x", "version": 1, "anchor": 0, "curves": []}"#,
        )
        .unwrap();
        let text = |keys: &str| {
            format!(
                "[source]\nkind = \"stdin\"\n[monitor]\n{keys}\n[[monitor.curve]]\nnodes = [0, 1]\n\
                 node_s = [0.0, 20.0]\nlength = 20.0\n"
            )
        };
        let m = from_text(&text("reference_file = \"good.json\""), &file)
            .unwrap()
            .monitor
            .unwrap();
        // Relative to the configuration's directory; sampled every 5 cm.
        assert_eq!(m.reference.unwrap().curves[0].1.len(), 401);
        let cases = [
            ("reference_file = \"none.json\"", "none.json"),
            // Issue 15 point 7: read with a size limit, not until memory runs out; issue 31
            // point 4: a device is not even opened.
            ("reference_file = \"/dev/zero\"", "not a regular file"),
            ("reference_file = \"anchor.json\"", "anchored at node 1"),
            (
                "reference_file = \"curve.json\"",
                "curve 3 is not in the layout",
            ),
            (
                "reference_file = \"format.json\"",
                "is not \"sfs-monitor-reference\"",
            ),
            (
                "reference_file = \"good.json\"\nreference_s = 3.0",
                "not both",
            ),
        ];
        for (keys, reason) in cases {
            let e = from_text(&text(keys), &file).unwrap_err();
            assert_eq!(e.key, "monitor.reference_file", "{keys}: {e}");
            assert!(e.reason.contains(reason), "{keys}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn surface_and_output_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let cases = [
            ("[surface]\nedge = 0.0\n", "surface.edge", "out of range"),
            (
                "[surface]\nmax_vertices = 10\n",
                "surface.max_vertices",
                "out of range",
            ),
            (
                "[surface]\nreweight = 11\n",
                "surface.reweight",
                "more than 10",
            ),
            ("[surface]\nsoft = -1.0\n", "surface.soft", "out of range"),
            (
                "[surface]\nguide_weight = -1.0\n",
                "surface.guide_weight",
                "out of range",
            ),
            (
                "[surface]\nreuse_tolerance = -0.5\n",
                "surface.reuse_tolerance",
                "not a tolerance",
            ),
            (
                "[network]\nlocal_window = 1000000\n",
                "network.local_window",
                "more than 100000",
            ),
            (
                "[network]\nlocal_window = -1\n",
                "network.local_window",
                "invalid value",
            ),
            (
                "[output]\nsnapshot = true\n",
                "output.snapshot",
                "unknown field",
            ),
            ("[output]\nlive = \"yes\"\n", "output.live", "bool"),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
        let ok = parse(&format!(
            "{base}[surface]\nmax_vertices = 5000\nsoft = 0\n[output]\nsnapshots = true\n"
        ))
        .unwrap();
        let s = ok.surface.unwrap();
        assert_eq!((s.max_vertices, s.soft), (5000, None));
        assert_eq!(s.reuse_tolerance, crate::pipeline::LIVE_REUSE_TOLERANCE);
        assert_eq!(ok.network.local_window, crate::pipeline::LIVE_LOCAL_WINDOW);
        let whole = parse(&format!("{base}[network]\nlocal_window = 0\n")).unwrap();
        assert_eq!(whole.network.local_window, 0);
        let inf = parse(&format!("{base}[surface]\nreuse_tolerance = inf\n")).unwrap();
        assert_eq!(inf.surface.unwrap().reuse_tolerance, f64::INFINITY);
        assert!(ok.snapshots);
    }

    #[test]
    fn calibration_and_acquisition_errors_name_the_key() {
        let base = "[source]\nkind = \"stdin\"\n";
        let cases = [
            ("[calibration]\naxes = [\"y\", \"x\", \"z\"]\n", "calibration.axes", "reflection"),
            ("[calibration]\nacc_scale = [1.0, 0.0, 1.0]\n", "calibration.acc_scale", "positive"),
            (
                "[calibration]\nmag_soft_iron = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]\n",
                "calibration.mag_soft_iron",
                "singular",
            ),
            ("[calibration]\nmounting_deg = [0.0, 90.0, 0.0]\n", "calibration.mounting_deg", "45"),
            ("[calibration]\nacc_bias = [0.0, 0.0]\n", "calibration.acc_bias", ""),
            ("[acquisition]\nnominal_speed = -1.0\n", "acquisition.nominal_speed", "out of range"),
            ("[acquisition]\nmax_node = 0\n", "acquisition.max_node", "out of range"),
            ("[acquisition]\nstationary_distance = nan\n", "acquisition.stationary_distance", "out of range"),
            ("[acquisition]\nstationary_distance = -0.1\n", "acquisition.stationary_distance", "out of range"),
            ("[acquisition]\nstationary_distance = 0.0\n", "acquisition.stationary_distance", "out of range"),
            ("[acquisition]\nmax_node = 1000000\n", "acquisition.max_node", "out of range"),
            ("[acquisition]\nmax_curve_samples = 1\n", "acquisition.max_curve_samples", "out of range"),
            ("[acquisition]\nloop_distance = 0\n", "acquisition.loop_distance", "out of range"),
            ("[acquisition]\nloop_turn_deg = 400\n", "acquisition.loop_turn_deg", "out of range"),
            ("[view]\naddress = \"localhost\"\n", "view.address", "no port"),
            ("[view]\nport = 8040\n", "view.port", "unknown field"),
            ("[view]\ntoken = \"short\"\n", "view.token", "at least 16"),
            ("[view]\nallowed_hosts = [\"evil host\"]\n", "view.allowed_hosts[0]", "not a host name"),
            (
                "[acquisition.segment_lengths]\nfirst = [0.3]\n",
                "acquisition.segment_lengths.first",
                "curve index",
            ),
            ("[acquisition]\nspeed = 1.0\n", "acquisition.speed", "unknown field"),
            (
                "[curves]\nkinds = { \"three\" = \"crease\" }\n",
                "curves.kinds.three",
                "curve index",
            ),
            (
                "[curves]\nkinds = { \"3\" = \"sharp\" }\n",
                "curves.kinds.3",
                "one of boundary, interior, crease, guide",
            ),
            ("[curves]\ncrease = [3]\n", "curves.crease", "unknown field"),
        ];
        for (text, key, reason) in cases {
            let e = parse(&format!("{base}{text}")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
            assert!(e.reason.contains(reason), "{text}: {e}");
        }
        let ok = parse(&format!(
            "{base}[calibration]\naxes = [\"y\", \"-x\", \"z\"]\nmounting_deg = [0.0, 0.0, 2.0]\n\
             [acquisition.segment_lengths]\n\"0\" = [0.3, 0.2]\n"
        ))
        .unwrap();
        let a = ok.acquisition;
        assert_eq!(a.max_node, crate::keypad::MAX_NODE);
        let limited = parse(&format!("{base}[acquisition]\nmax_node = 50\n")).unwrap();
        assert_eq!(limited.acquisition.max_node, 50);
        let still = parse(&format!(
            "{base}[acquisition]\nstationary_distance = 0.004\n"
        ))
        .unwrap();
        assert_eq!(still.acquisition.stationary_distance, 0.004);
        let e = parse(&format!("{base}[network]\nh = -1.0\n")).unwrap_err();
        assert_eq!(e.key, "network.h", "{e}");
        let e = parse(&format!("{base}[network]\nsmoothing = 1.0\n")).unwrap_err();
        assert_eq!(e.key, "network.smoothing", "{e}");
        let n = parse(&format!("{base}[network]\nh = 0.005\nregression = false\n"))
            .unwrap()
            .network;
        assert!(n.no_regression && (n.prefilter.h - 0.005).abs() < 1e-15);
        // Issue 34: the joins' keys, and a bad one named.
        let j = parse(&format!(
            "{base}[network]\njoin_distance = 0.02\njoin_normal_deg = 10.0\njoin_untagged = true\nrefuse = [[3, 7]]\n"
        ))
        .unwrap()
        .joins;
        assert_eq!((j.params.distance_m, j.params.normal_deg), (0.02, 10.0));
        assert_eq!(
            j.params.noise_factor, 0.0,
            "a set distance is the operator's"
        );
        assert!(j.untagged && j.refuses(7, 3) && !j.refuses(3, 4));
        let d = parse(base).unwrap().joins;
        assert_eq!(d, sfs_geometry::network::join::JoinSettings::default());
        for (text, key) in [
            ("join_distance = 2.0", "network.join_distance"),
            ("join_normal_deg = -1.0", "network.join_normal_deg"),
            ("refuse = [[3, 3]]", "network.refuse"),
            ("refuse = [[3]]", "network.refuse"),
        ] {
            let e = parse(&format!("{base}[network]\n{text}\n")).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
        }
        assert_eq!(a.segment_lengths[&0], vec![0.3, 0.2]);
        assert!((a.calibration.mounting.angle() - 2f64.to_radians()).abs() < 1e-12);
        // Issue 18: curve kinds by index.
        let k = parse(&format!(
            "{base}[curves]\nkinds = {{ \"3\" = \"crease\", \"0\" = \"guide\" }}\n"
        ))
        .unwrap()
        .acquisition
        .kinds;
        use sfs_geometry::curve::CurveKind;
        assert_eq!(
            k.into_iter().collect::<Vec<_>>(),
            [(0, CurveKind::Guide), (3, CurveKind::Crease)]
        );
    }
}
