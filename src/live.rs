//! The live reconstruction worker: after every finished curve, the network (and its surface)
//! on disk is brought up to date on a thread of its own, so the pipeline that reads the device
//! never waits for it.
//!
//! ```text
//! pipeline ──(curve ended or changed, with the session's counters)──▶ Mailbox
//!                         (one pending update at most; later curves merge into it)
//! worker: take ▶ Reconstructor (cached pre-filter, symbolic factorisations kept, the frames
//!         regressed near the new curve only: a provisional network) ▶
//!         the view's `curves` event (the network drawn at once, before its surface) ▶
//!         Surfacer (faces kept: a provisional surface) ▶
//!         network.glb and report.json replaced atomically ▶ one status line per curve ▶
//!         while no curve waits: the update settled (exact) ▶ network.glb and report.json again
//! ```
//!
//! Coalescing: a curve that ends while a reconstruction runs is merged into the pending
//! update, so the worker always works on the latest state and nothing queues up. Closing the
//! mailbox ([`Live::finish`]) lets the worker bring in what is still pending and hands the last
//! reconstruction back to the session for its final outputs.
//!
//! Provisional and settled (issue 19): an update regresses only the frames within
//! `[network] local_window` samples of the new curve's nodes (the others kept from the last
//! update, [`sfs_geometry::network::NetworkParams::local_window`]), and its surface keeps the
//! faces of the last one whose rims moved less than `[surface] reuse_tolerance` edges, made in
//! one pass ([`sfs_geometry::surface::fit::SurfaceParams::reuse_tolerance`]): the operator
//! sees it at once; as soon as no curve waits, the worker reconstructs the whole network and
//! surfaces it exactly, and replaces the update (`report.json`: `network.provisional`,
//! `surface.provisional` until then, `live.settled`). A curve that arrives while the settled
//! network is made goes first: the settle asks between the network's long steps (each pass of
//! the loop-closure test, each join pass) and stops there (`Pipeline::settle`; the next update
//! starts from the frames regressed so far). A settled
//! update is a pure function of the curves (the caches change the time, not the bits: the
//! regression is not warm-started, which measured no fewer iterations), and the last update
//! is always settled, so the same bytes in give the same files out whatever the timing was.

use crate::link::LinkStats;
use crate::pipeline::{Pipeline, Products, REPORT_FILE};
use crate::report::{LiveReport, Percentiles};
use crate::scan::{Counts, Curve, Scan};
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
    pub warnings: Vec<crate::warning::Warning>,
    /// The device the HELLO announced (its noise calibrates the uncertainty).
    pub device: Option<device_protocol::DeviceKind>,
}

/// What the worker leaves when it is closed.
#[derive(Debug, Default)]
pub struct LiveOutcome {
    pub report: LiveReport,
    /// The last reconstruction (its `network.glb` is in place), of `curves` curves.
    pub products: Option<Products>,
    pub curves: usize,
}

#[derive(Default)]
struct Mail {
    /// Curves ended or changed since the worker last took the mail, by index.
    curves: BTreeMap<usize, Curve>,
    /// When each of them was posted (the E key packet, or the late change).
    posted: Vec<(usize, Instant)>,
    /// Curves taken out of the network since (issue 49).
    removed: std::collections::BTreeSet<usize>,
    snapshot: Snapshot,
    closed: bool,
}

impl Mail {
    /// Whether an update is due: curves to bring in, or to take out.
    fn pending(&self) -> bool {
        !self.curves.is_empty() || !self.removed.is_empty()
    }
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
    pub network: sfs_geometry::network::NetworkParams,
    /// Nodes joined after the fact (`[network] join_*`).
    pub joins: sfs_geometry::network::join::JoinSettings,
    /// Surfacing settings; `None`: the network only.
    pub surface: Option<sfs_geometry::surface::fit::SurfaceParams>,
    /// Keep a copy of `network.glb` per curve (`snapshots/curve-NNN.glb`).
    pub snapshots: bool,
    pub source: String,
    pub started: Instant,
    /// The live view to tell of every new network.
    pub view: Option<crate::view::View>,
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

    /// Takes curve `index` out of the network (dropped or replaced from the keypad): the next
    /// update is made without it.
    pub fn remove(&mut self, index: usize, snapshot: Snapshot) {
        let mut m = lock(&self.shared.mail);
        m.curves.remove(&index);
        m.posted.retain(|p| p.0 != index);
        m.removed.insert(index);
        m.snapshot = snapshot;
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

/// A duration, ms.
fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn lock(m: &Mutex<Mail>) -> std::sync::MutexGuard<'_, Mail> {
    // A panic on the other side leaves the mail usable: it holds plain data.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn worker(shared: Arc<Shared>, settings: LiveSettings) -> LiveOutcome {
    let mut scan = Scan::default();
    let mut pipeline = Pipeline::with_joins(settings.joins.clone()).live();
    let mut update_ms = Vec::new();
    let mut settle_ms = Vec::new();
    let mut report = LiveReport::default();
    let mut last = None;
    let mut status_log = StatusLog::default();
    loop {
        let (curves, posted, snapshot) = {
            let mut m = lock(&shared.mail);
            while !m.pending() && !m.closed {
                m = shared.wake.wait(m).unwrap_or_else(|p| p.into_inner());
            }
            if !m.pending() {
                break; // closed, nothing pending
            }
            let removed = std::mem::take(&mut m.removed);
            scan.curves.retain(|c| !removed.contains(&c.index));
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
        let network = crate::pipeline::for_device(&settings.network, snapshot.device);
        // Phase one: the network, published at once (the operator sees the curve in place);
        // phase two: the nodes' uncertainty (issue 51), the surface and network.glb (issue 35).
        let first = sfs_geometry::network::NetworkParams {
            defer_uncertainty: true,
            ..network
        };
        let mut products = pipeline.reconstruct(&scan.curves, &first);
        if let Some(v) = &settings.view {
            v.curves(&products, report.updates + 1, &posted);
        }
        let published = Instant::now();
        report
            .curves_latencies
            .extend(posted.iter().map(|(_, at)| ms(published - *at)));
        report.curves_latency_ms = Percentiles::of(&report.curves_latencies);
        pipeline.uncertainty_into(&mut products, &network);
        pipeline.surface_into(&mut products, settings.surface.as_ref());
        let compute_ms = ms(t0.elapsed());
        if let Err(e) = products.write_glb(&settings.out_dir) {
            tracing::error!("live update: {e}");
            last = Some(products);
            continue;
        }
        let done = Instant::now();
        report.updates += 1;
        update_ms.push(compute_ms);
        let lat: Vec<(usize, f64)> = posted.iter().map(|(i, at)| (*i, ms(done - *at))).collect();
        report.latencies.extend(lat.iter().map(|l| l.1));
        report.latency_ms = Percentiles::of(&report.latencies);
        report.update_ms = Percentiles::of(&update_ms);
        let update = Update {
            settings: &settings,
            scan: &scan,
            snapshot: &snapshot,
            lat: &lat,
        };
        update.publish(&products, &mut report, &posted);
        status_log.lines(&scan, &products, &lat, compute_ms);
        // A provisional update is settled at once while no curve waits (the operator sees the
        // quick one meanwhile), so the last update is always exact.
        let waiting = || lock(&shared.mail).pending();
        let t0 = Instant::now();
        if !waiting()
            && pipeline.settle(
                &scan.curves,
                &mut products,
                &network,
                settings.surface.as_ref(),
                waiting,
            )
        {
            let took = ms(t0.elapsed());
            if let Err(e) = products.write_glb(&settings.out_dir) {
                tracing::error!("live update: {e}");
            } else {
                report.settled += 1;
                settle_ms.push(took);
                report.settle_ms = Percentiles::of(&settle_ms);
                update.publish(&products, &mut report, &[]);
                tracing::debug!("update settled in {took:.1} ms");
            }
        }
        last = Some(products);
    }
    report.latency_ms = Percentiles::of(&report.latencies);
    report.curves_latency_ms = Percentiles::of(&report.curves_latencies);
    report.update_ms = Percentiles::of(&update_ms);
    LiveOutcome {
        report,
        products: last,
        curves: scan.curves.len(),
    }
}

/// What an update's outputs are written with: where, the curves, the session's counters,
/// and the latencies of the curves it brought in.
struct Update<'a> {
    settings: &'a LiveSettings,
    scan: &'a Scan,
    snapshot: &'a Snapshot,
    lat: &'a [(usize, f64)],
}

impl Update<'_> {
    /// Tells the view (`posted`: the curves the products brought in, none for a settled
    /// surface), writes the snapshots of the update's curves and the live `report.json`.
    fn publish(&self, products: &Products, report: &mut LiveReport, posted: &[(usize, Instant)]) {
        let settings = self.settings;
        // The view first: a page fetches the new network while the rest is written.
        if let Some(v) = &settings.view {
            v.network(products, report, self.scan.curves.len(), posted);
            v.reconstruction_warnings(&products.warnings);
        }
        crate::memory::release_free_memory();
        (report.rss_mb, report.peak_rss_mb) = crate::memory::rss_mb();
        if settings.snapshots {
            for (i, _) in self.lat {
                if let Err(e) = products.write_snapshot(&settings.out_dir, *i) {
                    tracing::warn!("snapshot of curve {i}: {e}");
                }
            }
        }
        let mut live_report = crate::report::Report::assemble(
            crate::report::Progress {
                source: &settings.source,
                ended: "running",
                started: settings.started,
                link: &self.snapshot.link,
                curves: &self.scan.curves,
                counts: &self.snapshot.counts,
                warnings: &self.snapshot.warnings,
            },
            products,
        );
        live_report.live = Some(report.clone());
        if let Some(v) = &settings.view {
            v.quality(&live_report.quality);
        }
        let path = settings.out_dir.join(REPORT_FILE);
        if let Err(e) = live_report.write(&path) {
            tracing::error!("live update: cannot write {}: {e}", path.display());
        }
    }
}

/// Status lines logged per update: a session brings in one curve an update, a key storm
/// thousands (the rest are said in one line).
const STATUS_LINES_PER_UPDATE: usize = 5;

/// Updates whose lines are all logged; after them, at most one update's lines a second.
const UPDATES_LOGGED: u64 = 100;

/// The log's rate limit for the status lines: every update's for the first
/// [`UPDATES_LOGGED`] (a session has tens of curves), then at most one update's a second, the
/// curves of the updates in between counted in the next lines.
#[derive(Debug, Default)]
struct StatusLog {
    updates: u64,
    last: Option<Instant>,
    held: usize,
}

impl StatusLog {
    fn lines(&mut self, scan: &Scan, p: &Products, lat: &[(usize, f64)], compute_ms: f64) {
        self.updates += 1;
        let recent = self
            .last
            .is_some_and(|t| t.elapsed() < std::time::Duration::from_secs(1));
        if self.updates > UPDATES_LOGGED && recent {
            self.held += lat.len();
            return;
        }
        if self.held > 0 {
            tracing::info!(
                curves = self.held,
                "{} more curves came into network.glb meanwhile (their lines left out of the log)",
                self.held
            );
            self.held = 0;
        }
        self.last = Some(Instant::now());
        status_lines(scan, p, lat, compute_ms);
    }
}

/// One line per curve the update brought in (at most [`STATUS_LINES_PER_UPDATE`]).
fn status_lines(scan: &Scan, p: &Products, lat: &[(usize, f64)], compute_ms: f64) {
    let (net_curves, samples, max_angle) = p.network.as_ref().map_or((0, 0, 0.0), |n| {
        (
            n.report.curves_used,
            n.report.samples,
            n.report.max_node_normal_angle_deg,
        )
    });
    if lat.len() > STATUS_LINES_PER_UPDATE {
        tracing::info!(
            curves = lat.len(),
            "{} curves in network.glb in this update: the first {STATUS_LINES_PER_UPDATE} are logged below, the other {} only counted here (every curve is in report.json)",
            lat.len(),
            lat.len() - STATUS_LINES_PER_UPDATE
        );
    }
    for (index, latency) in lat.iter().take(STATUS_LINES_PER_UPDATE) {
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
