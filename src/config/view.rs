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
}

impl ConfigFile {
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
