//! Nearest-rank percentiles of a sample of figures (latencies, intervals): what the reports
//! and the live view summarise a distribution by.
//!
//! ```
//! let p = sfs::percentiles::Percentiles::of(&[3.0, 1.0, 2.0, 4.0]);
//! assert_eq!((p.n, p.p50, p.p95, p.max), (4, 2.0, 4.0, 4.0));
//! ```

use serde::Serialize;

/// A distribution summarised.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Percentiles {
    pub n: usize,
    pub p50: f64,
    pub p95: f64,
    pub max: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of `v`.
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Percentiles::default();
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let rank = |p: f64| s[((p * s.len() as f64).ceil() as usize).clamp(1, s.len()) - 1];
        Percentiles {
            n: s.len(),
            p50: rank(0.5),
            p95: rank(0.95),
            max: *s.last().expect("not empty"),
        }
    }
}
