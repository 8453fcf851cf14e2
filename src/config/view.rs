//! `[view]`: the operator's live view (see [`crate::view`]).

use super::{ConfigError, ConfigFile};
use serde::Deserialize;
use std::net::SocketAddr;
use std::path::Path;

/// `[view]`, as written (see the module documentation).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewToml {
    /// Where to serve the view (`"127.0.0.1:8040"`); no view without it.
    pub address: Option<String>,
    /// Host names the view answers besides `localhost` and address literals (a name the
    /// operator's network gives this machine); see [`crate::view::access`].
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// A token every request must carry (`?token=`, `Authorization: Bearer`): for a view
    /// shared on a network.
    pub token: Option<String>,
}

impl ConfigFile {
    /// `allowed_hosts` and `token`, checked.
    pub(super) fn view_access(
        &self,
        file: &Path,
    ) -> Result<crate::settings::ViewAccess, ConfigError> {
        for (i, h) in self.view.allowed_hosts.iter().enumerate() {
            let name = h.rsplit_once(':').map_or(h.as_str(), |(n, _)| n);
            let ok = !name.is_empty()
                && name.len() <= 253
                && name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.');
            if !ok {
                return Err(ConfigError::new(
                    file,
                    format!("view.allowed_hosts[{i}]"),
                    format!("{h:?} is not a host name (letters, digits, '-' and '.', an optional :PORT)"),
                ));
            }
        }
        if let Some(t) = &self.view.token {
            if t.len() < 16 || !t.chars().all(|c| c.is_ascii_graphic()) {
                return Err(ConfigError::new(
                    file,
                    "view.token",
                    "at least 16 printable characters without spaces (e.g. from `openssl rand -hex 16`)",
                ));
            }
        }
        Ok(crate::settings::ViewAccess {
            allowed_hosts: self.view.allowed_hosts.clone(),
            token: self.view.token.clone(),
        })
    }

    /// The view's address (`None`: no view unless `--view` asks for one).
    pub(super) fn view_address(&self, file: &Path) -> Result<Option<SocketAddr>, ConfigError> {
        self.view
            .address
            .as_deref()
            .map(|a| {
                crate::view::parse_address(a).map_err(|e| ConfigError::new(file, "view.address", e))
            })
            .transpose()
    }
}
