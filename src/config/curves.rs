//! `[curves]`: what each curve means for the surface, set after the fact by curve index (for
//! sessions captured before the keypad had `K` and `G`, or typed with the wrong start key).
//!
//! ```toml
//! [curves]
//! kinds = { "3" = "crease", "7" = "guide" }   # boundary | interior | crease | guide
//! ```

use super::{ConfigError, ConfigFile};
use serde::Deserialize;
use sfs_geometry::curve::CurveKind;
use std::collections::BTreeMap;
use std::path::Path;

/// `[curves]`, as written.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CurvesToml {
    /// Curve index (as text, a TOML key) → kind name.
    #[serde(default)]
    pub kinds: BTreeMap<String, String>,
}

impl ConfigFile {
    /// The kinds set by curve index, each key and name checked.
    pub(super) fn curve_kinds(
        &self,
        file: &Path,
    ) -> Result<BTreeMap<usize, CurveKind>, ConfigError> {
        let mut out = BTreeMap::new();
        for (k, v) in &self.curves.kinds {
            let key = format!("curves.kinds.{k}");
            let index: usize = k.parse().map_err(|_| {
                ConfigError::new(
                    file,
                    &key,
                    format!("{k:?} is not a curve index (0, 1, 2, …)"),
                )
            })?;
            let kind = CurveKind::of_name(v).ok_or_else(|| {
                let names: Vec<&str> = CurveKind::ALL.iter().map(|k| k.name()).collect();
                ConfigError::new(
                    file,
                    &key,
                    format!("{v:?} is not a curve kind: one of {}", names.join(", ")),
                )
            })?;
            out.insert(index, kind);
        }
        Ok(out)
    }
}
