//! `[phone]`: the phone page (`sfs run --phone`, [`crate::source::phone`]).

use super::{ConfigError, ConfigFile};
use crate::source::phone::PhoneSpec;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// `[phone]`, as written. A configuration with `[phone]` and no `[source]` reads the phone.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhoneToml {
    /// Where to serve the page (default `0.0.0.0:8443`: every interface, since the phone is
    /// another machine on the network).
    pub address: Option<String>,
    /// Where the self-signed certificate is kept (default: the session directory). One
    /// directory for every session keeps one certificate, so the phone's browser accepts it
    /// once. Relative to the configuration file.
    pub cert_dir: Option<PathBuf>,
}

impl ConfigFile {
    /// The phone source `[phone]` describes, if the section is there.
    pub(super) fn phone(&self, file: &Path) -> Result<Option<PhoneSpec>, ConfigError> {
        let Some(p) = &self.phone else {
            return Ok(None);
        };
        let addr = match p.address.as_deref() {
            None => crate::source::phone::DEFAULT_ADDRESS
                .parse()
                .expect("the default address parses"),
            Some(a) => a.parse().map_err(|_| {
                ConfigError::new(
                    file,
                    "phone.address",
                    format!("{a:?} is not an IP address and a port (e.g. \"0.0.0.0:8443\")"),
                )
            })?,
        };
        let base = file.parent().unwrap_or(Path::new(""));
        let cert_dir = match &p.cert_dir {
            Some(d) if d.as_os_str().is_empty() => {
                return Err(ConfigError::new(file, "phone.cert_dir", "an empty path"))
            }
            Some(d) if d.is_relative() => Some(base.join(d)),
            other => other.clone(),
        };
        Ok(Some(PhoneSpec {
            cert_dir,
            ..PhoneSpec::new(addr)
        }))
    }
}
