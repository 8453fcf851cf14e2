//! The live reconstruction worker: after every finished curve, the network (and its surface)
//! on disk is brought up to date on a thread of its own, so the pipeline that reads the device
//! never waits for it.
//!
//! ```text
//! pipeline ──(curve ended or changed, with the session's counters)──▶ Mailbox
//!                         (one pending update at most; later curves merge into it)
//! worker: take ▶ Reconstructor (cached pre-filter, symbolic factorisations kept) ▶
//!         Surfacer (symbolic factorisation kept) ▶
//!         network.glb and report.json replaced atomically ▶ one status line per curve
//! ```
//!
//! Coalescing: a curve that ends while a reconstruction runs is merged into the pending
//! update, so the worker always works on the latest state and nothing queues up. Closing the
//! mailbox ([`Live::finish`]) lets the worker bring in what is still pending and hands the last
//! reconstruction back to the session for its final outputs. Every update is a pure function
//! of the curves (the caches change the time, not the bits: the regression is not
//! warm-started, which measured no fewer iterations), so the same bytes in give the same
//! files out whatever the timing was.

use crate::link::LinkStats;
use crate::scan::{Counts, Curve, Scan};
use crate::session::{self, Options};
use serde::Serialize;
use sfs_geometry::network::Reconstructor;
use sfs_geometry::surface::fit::Surfacer;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

/// The session's counters at the time of an update (for the live `report.json`).
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    pub link: LinkStats,
    pub counts: Counts,
    /// Acquisition warnings so far.
    pub warnings: Vec<String>,
}

/// What the live updates measured, for `report.json` and `BENCHMARKS.md`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LiveReport {
    /// Reconstructions run (each wrote `network.glb`).
    pub updates: usize,
    /// Curves that ended (or changed) and were sent to the worker.
    pub curves_posted: usize,
    /// Curves merged into an update that was already pending (coalesced).
    pub coalesced: usize,
    /// From the E key packet (the pipeline seeing the curve end) to the `network.glb` that
    /// contains the curve in place, ms.
    pub latency_ms: Percentiles,
    /// Reconstruction (network and surface) time per update, ms.
    pub update_ms: Percentiles,
    /// Resident memory after the last update, and its peak, MB (Linux `/proc/self/status`).
    pub rss_mb: Option<f64>,
    pub peak_rss_mb: Option<f64>,
    /// Every latency, ms (summarised in `latency_ms`).
    #[serde(skip)]
    pub latencies: Vec<f64>,
}

/// What the worker leaves when it is closed.
#[derive(Debug, Default)]
pub struct LiveOutcome {
    pub report: LiveReport,
    /// The last reconstruction (its `network.glb` is in place), of `curves` curves.
    pub products: Option<session::Products>,
    pub curves: usize,
}

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

/// Returns memory the allocator holds but no longer uses to the operating system (glibc keeps
/// freed blocks in per-thread arenas; after a reconstruction of an hour-long scan that is
/// ~40 MB that a long-running daemon would otherwise keep). A no-op elsewhere.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: glibc's malloc_trim only releases free pages of its own arenas; it takes no
        // pointers and is safe to call at any time from any thread.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Resident and peak resident memory of this process, MB (`None` off Linux).
pub fn rss_mb() -> (Option<f64>, Option<f64>) {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return (None, None);
    };
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<f64>().ok())
            .map(|kb| kb / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

#[derive(Default)]
struct Mail {
    /// Curves ended or changed since the worker last took the mail, by index.
    curves: BTreeMap<usize, Curve>,
    /// When each of them was posted (the E key packet, or the late change).
    posted: Vec<(usize, Instant)>,
    snapshot: Snapshot,
    closed: bool,
}

struct Shared {
    mail: Mutex<Mail>,
    wake: Condvar,
}

/// The handle the session holds on its worker.
pub struct Live {
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<LiveOutcome>>,
    posted: usize,
    coalesced: usize,
}

/// Where and how the worker writes.
#[derive(Debug, Clone)]
pub struct LiveSettings {
    pub out_dir: PathBuf,
    pub options: Options,
    pub source: String,
    pub started: Instant,
}

impl Live {
    /// Starts the worker thread.
    pub fn spawn(settings: LiveSettings) -> std::io::Result<Live> {
        let shared = Arc::new(Shared {
            mail: Mutex::new(Mail::default()),
            wake: Condvar::new(),
        });
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name("reconstruction".into())
            .spawn(move || worker(s, settings))?;
        Ok(Live {
            shared,
            thread: Some(thread),
            posted: 0,
            coalesced: 0,
        })
    }

    /// Posts a curve that ended (or changed after it ended) at `at` (`None`: not a live event,
    /// e.g. a curve of a resumed capture; no latency is measured), with the session's
    /// counters. Never blocks on the reconstruction: the curve joins the pending update.
    pub fn post(&mut self, curve: &Curve, at: Option<Instant>, snapshot: Snapshot) {
        let mut m = lock(&self.shared.mail);
        if !m.curves.is_empty() {
            self.coalesced += 1;
        }
        m.curves.insert(curve.index, curve.clone());
        if let Some(at) = at {
            m.posted.push((curve.index, at));
        }
        m.snapshot = snapshot;
        self.posted += 1;
        drop(m);
        self.shared.wake.notify_one();
    }

    /// Closes the mailbox: the worker brings in the curves still pending (one more update at
    /// most) and stops; returns its last reconstruction and what the updates measured.
    pub fn finish(mut self) -> LiveOutcome {
        lock(&self.shared.mail).closed = true;
        self.shared.wake.notify_one();
        let mut out = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        out.report.curves_posted = self.posted;
        out.report.coalesced = self.coalesced;
        out
    }
}

fn lock(m: &Mutex<Mail>) -> std::sync::MutexGuard<'_, Mail> {
    // A panic on the other side leaves the mail usable: it holds plain data.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn worker(shared: Arc<Shared>, settings: LiveSettings) -> LiveOutcome {
    let mut scan = Scan::default();
    let mut rec = Reconstructor::new();
    let mut surfacer = Surfacer::new();
    let mut update_ms = Vec::new();
    let mut report = LiveReport::default();
    let mut last = None;
    loop {
        let (curves, posted, snapshot) = {
            let mut m = lock(&shared.mail);
            while m.curves.is_empty() && !m.closed {
                m = shared.wake.wait(m).unwrap_or_else(|p| p.into_inner());
            }
            if m.curves.is_empty() {
                break; // closed, nothing pending
            }
            (
                std::mem::take(&mut m.curves),
                std::mem::take(&mut m.posted),
                m.snapshot.clone(),
            )
        };
        for (index, c) in curves {
            match scan.curves.binary_search_by_key(&index, |c| c.index) {
                Ok(k) => scan.curves[k] = c,
                Err(k) => scan.curves.insert(k, c),
            }
        }
        let t0 = Instant::now();
        let products = session::reconstruct(&scan, &settings.options, &mut rec, &mut surfacer);
        let compute_ms = t0.elapsed().as_secs_f64() * 1e3;
        if let Err(e) = products.write_glb(&settings.out_dir) {
            tracing::error!("live update: {e}");
            last = Some(products);
            continue;
        }
        let done = Instant::now();
        report.updates += 1;
        update_ms.push(compute_ms);
        let lat: Vec<(usize, f64)> = posted
            .iter()
            .map(|(i, at)| (*i, (done - *at).as_secs_f64() * 1e3))
            .collect();
        report.latencies.extend(lat.iter().map(|l| l.1));
        report.latency_ms = Percentiles::of(&report.latencies);
        report.update_ms = Percentiles::of(&update_ms);
        release_free_memory();
        (report.rss_mb, report.peak_rss_mb) = rss_mb();
        if settings.options.snapshots {
            for (i, _) in &lat {
                if let Err(e) = products.write_snapshot(&settings.out_dir, *i) {
                    tracing::warn!("snapshot of curve {i}: {e}");
                }
            }
        }
        let live_report = crate::report::Report {
            sfs_version: env!("CARGO_PKG_VERSION"),
            source: settings.source.clone(),
            ended: "running",
            wall_time_s: settings.started.elapsed().as_secs_f64(),
            link: snapshot.link.clone(),
            curves: scan
                .curves
                .iter()
                .map(crate::report::CurveSummary::from)
                .collect(),
            acquisition: snapshot.counts.clone(),
            warnings: snapshot
                .warnings
                .iter()
                .chain(&products.warnings)
                .cloned()
                .collect(),
            nodes: products.nodes.clone(),
            timings_ms: products
                .network
                .as_ref()
                .map(|n| n.report.timings_ms.clone()),
            network: products.network.as_ref().map(|n| n.report.clone()),
            surface: products.surface.clone(),
            live: Some(report.clone()),
            monitor: None,
        };
        let path = settings.out_dir.join(session::REPORT_FILE);
        if let Err(e) = live_report.write(&path) {
            tracing::error!("live update: cannot write {}: {e}", path.display());
        }
        status_lines(&scan, &products, &lat, compute_ms);
        last = Some(products);
    }
    report.latency_ms = Percentiles::of(&report.latencies);
    report.update_ms = Percentiles::of(&update_ms);
    LiveOutcome {
        report,
        products: last,
        curves: scan.curves.len(),
    }
}

/// One line per curve the update brought in.
fn status_lines(scan: &Scan, p: &session::Products, lat: &[(usize, f64)], compute_ms: f64) {
    let (net_curves, samples, max_angle) = p.network.as_ref().map_or((0, 0, 0.0), |n| {
        (
            n.report.curves_used,
            n.report.samples,
            n.report.max_node_normal_angle_deg,
        )
    });
    for (index, latency) in lat {
        let c = scan.curves.iter().find(|c| c.index == *index);
        tracing::info!(
            curve = index,
            nodes = ?c.map(|c| c.nodes()).unwrap_or_default(),
            samples = c.map_or(0, |c| c.samples.len()),
            network_curves = net_curves,
            network_samples = samples,
            reconstruction_ms = format!("{:.1}", p.network_ms),
            surface_ms = format!("{:.1}", p.surface_ms),
            update_ms = format!("{compute_ms:.1}"),
            latency_ms = format!("{latency:.1}"),
            max_node_normal_deg = format!("{max_angle:.2}"),
            warnings = p.warnings.len(),
            "curve {index} in network.glb"
        );
    }
}
