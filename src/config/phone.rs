//! `[phone]`: the phone page (`sfs run --phone`, [`crate::source::phone`]).

use super::{ConfigError, ConfigFile};
use crate::source::phone::PhoneSpec;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// `[phone]`, as written. A configuration with `[phone]` and no `[source]` reads the phone.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhoneToml {
    /// Where to serve the page: `IP:PORT` or a port (default `0.0.0.0:8443`: every interface,
    /// since the phone is another machine on the network).
    pub address: Option<String>,
    /// Where the self-signed certificate is kept (default: the session directory). One
    /// directory for every session keeps one certificate, so the phone's browser accepts it
    /// once. Relative to the configuration file.
    pub cert_dir: Option<PathBuf>,
    /// Names (besides `localhost` and IP addresses) by which the phone may reach the page,
    /// e.g. `["scanner.local"]`: a request whose `Host` names none of them is refused (421).
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
}

impl ConfigFile {
    /// The phone source `[phone]` describes, if the section is there.
    pub(super) fn phone(&self, file: &Path) -> Result<Option<PhoneSpec>, ConfigError> {
        let Some(p) = &self.phone else {
            return Ok(None);
        };
        let mut spec = PhoneSpec::at_default_address();
        if let Some(a) = p.address.as_deref() {
            spec.addr = crate::source::phone::parse_address(a)
                .map_err(|e| ConfigError::new(file, "phone.address", e))?;
        }
        let base = file.parent().unwrap_or(Path::new(""));
        let cert_dir = match &p.cert_dir {
            Some(d) if d.as_os_str().is_empty() => {
                return Err(ConfigError::new(file, "phone.cert_dir", "an empty path"))
            }
            Some(d) if d.is_relative() => Some(base.join(d)),
            other => other.clone(),
        };
        spec.cert_dir = cert_dir;
        for h in &p.allowed_hosts {
            if h.is_empty() || h.len() > 253 || h.contains(['/', ' ', '@']) {
                return Err(ConfigError::new(
                    file,
                    "phone.allowed_hosts",
                    format!("{h:?} is not a host name"),
                ));
            }
        }
        spec.allowed_hosts = p.allowed_hosts.clone();
        Ok(Some(spec))
    }
}
