//! `[source]`: where the bytes come from.

use super::ConfigError;
use crate::settings::{DEFAULT_BAUD, DEFAULT_WATCHDOG_MS};
use crate::source::{Pace, SerialSpec, SourceSpec};
use serde::Deserialize;
use std::path::Path;
use std::path::PathBuf;
use std::time::Duration;

/// `[source]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceToml {
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

impl Default for SourceToml {
    fn default() -> Self {
        SourceToml {
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

impl SourceToml {
    /// The source this `[source]` describes.
    pub(super) fn spec(&self, file: &Path) -> Result<SourceSpec, ConfigError> {
        let s = self;
        let err =
            |key: &str, reason: String| ConfigError::new(file, format!("source.{key}"), reason);
        let need_path = || {
            s.path
                .clone()
                .filter(|p| !p.as_os_str().is_empty())
                .ok_or_else(|| err("path", format!("required when source.kind = {:?}", s.kind)))
        };
        let pace = s
            .pace
            .parse::<Pace>()
            .map_err(|e| err("pace", e.to_string()))?;
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
