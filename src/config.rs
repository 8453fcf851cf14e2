//! Resolved configuration, read from `config/*.toml` (serde). Every error names the key and the
//! reason. Command-line flags are kept apart (`cli`) and applied on top by `main`.
//!
//! ```toml
//! [source]
//! kind = "serial"          # "serial" | "replay" | "stdin"
//! path = "/dev/ttyUSB0"    # serial port, or capture file for "replay"
//! baud = 115200
//! watchdog_ms = 3000       # silence that counts as a disconnect
//! pace = "fast"            # replay only: "fast" | "realtime"
//! ```
//!
//! A relative `path` of a capture file is relative to the configuration file's directory.

use crate::source::{Pace, SerialSpec, SourceSpec};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Default serial speed (the wire format's default; a phone's Bluetooth serial ignores it).
pub const DEFAULT_BAUD: u32 = 115_200;
/// Default serial silence watchdog.
pub const DEFAULT_WATCHDOG_MS: u64 = 3_000;

/// A configuration error: the file, the key, the reason.
#[derive(Debug, thiserror::Error)]
#[error("{}: {key}: {reason}", file.display())]
pub struct ConfigError {
    pub file: PathBuf,
    /// Dotted key (`source.baud`), or `-` when the file itself is at fault.
    pub key: String,
    pub reason: String,
}

/// The whole configuration file.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub source: SourceConfig,
}

/// `[source]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    #[serde(default = "default_kind")]
    pub kind: String,
    pub path: Option<PathBuf>,
    #[serde(default = "default_baud")]
    pub baud: u32,
    #[serde(default = "default_watchdog_ms")]
    pub watchdog_ms: u64,
    #[serde(default = "default_pace")]
    pub pace: String,
}

impl Default for SourceConfig {
    fn default() -> Self {
        SourceConfig {
            kind: default_kind(),
            path: None,
            baud: DEFAULT_BAUD,
            watchdog_ms: DEFAULT_WATCHDOG_MS,
            pace: default_pace(),
        }
    }
}

fn default_kind() -> String {
    "serial".into()
}
fn default_baud() -> u32 {
    DEFAULT_BAUD
}
fn default_watchdog_ms() -> u64 {
    DEFAULT_WATCHDOG_MS
}
fn default_pace() -> String {
    "fast".into()
}

impl Config {
    /// Reads and validates `path`. Relative paths inside it are taken relative to the
    /// directory of the file, so a shipped configuration works from any working directory.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: path.to_owned(),
            key: "-".into(),
            reason: format!("cannot read: {e}"),
        })?;
        let mut cfg = Self::parse(&text, path)?;
        let base = path.parent().unwrap_or(Path::new(""));
        if let Some(p) = &mut cfg.source.path {
            if p.is_relative() && cfg.source.kind != "serial" {
                *p = base.join(&*p);
            }
        }
        Ok(cfg)
    }

    /// Parses and validates `text` (read from `file`, for messages).
    pub fn parse(text: &str, file: &Path) -> Result<Config, ConfigError> {
        let cfg: Config = toml::from_str(text).map_err(|e| ConfigError {
            file: file.to_owned(),
            key: e
                .span()
                .map(|s| key_at(text, s.start))
                .unwrap_or_else(|| "-".into()),
            reason: e.message().trim().to_owned(),
        })?;
        cfg.source_spec(file)?;
        Ok(cfg)
    }

    /// The source this configuration describes.
    pub fn source_spec(&self, file: &Path) -> Result<SourceSpec, ConfigError> {
        let s = &self.source;
        let err = |key: &str, reason: String| ConfigError {
            file: file.to_owned(),
            key: format!("source.{key}"),
            reason,
        };
        let need_path = || {
            s.path
                .clone()
                .filter(|p| !p.as_os_str().is_empty())
                .ok_or_else(|| err("path", format!("required when source.kind = {:?}", s.kind)))
        };
        let pace: Pace = s.pace.parse().map_err(|e| err("pace", e))?;
        if s.baud == 0 {
            return Err(err(
                "baud",
                "must be a positive number of bits per second".into(),
            ));
        }
        if s.watchdog_ms < 100 {
            return Err(err(
                "watchdog_ms",
                format!(
                    "{} ms is too short to tell silence from a slow device (minimum 100)",
                    s.watchdog_ms
                ),
            ));
        }
        match s.kind.as_str() {
            "serial" => {
                let mut spec = SerialSpec::new(need_path()?, s.baud);
                spec.watchdog = Duration::from_millis(s.watchdog_ms);
                Ok(SourceSpec::Serial(spec))
            }
            "replay" => Ok(SourceSpec::Replay {
                path: need_path()?,
                pace,
            }),
            "stdin" => Ok(SourceSpec::Stdin),
            other => Err(err(
                "kind",
                format!(
                    "unknown source kind {other:?}: expected \"serial\", \"replay\" or \"stdin\""
                ),
            )),
        }
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
        (true, true) => "-".into(),
        (true, false) => key,
        (false, true) => table,
        (false, false) => format!("{table}.{key}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(t: &str) -> Result<Config, ConfigError> {
        Config::parse(t, Path::new("x.toml"))
    }

    #[test]
    fn serial_with_defaults() {
        let c = parse("[source]\nkind = \"serial\"\npath = \"/dev/ttyUSB0\"\n").unwrap();
        match c.source_spec(Path::new("x")).unwrap() {
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
}
