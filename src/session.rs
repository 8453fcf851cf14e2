//! One session: a source feeding the decoder, with the capture, statistics and outputs.
//!
//! `bytes → source thread (capture first) → channel → decoder → link statistics → report.json`.
//! Later stages (acquisition, reconstruction) hang off the decoder's packets here.

use crate::acquisition::{Acquisition, AcquisitionConfig, Update};
use crate::atomic::OutputError;
use crate::capture::CaptureWriter;
use crate::link::LinkStats;
use crate::metrics::SessionMetrics;
use crate::monitor::run::{Begin, Monitor};
use crate::pipeline::{Pipeline, REPORT_FILE, SCAN_FILE};
use crate::report::{Progress, Report};
use crate::settings::Settings;
use crate::shutdown::Shutdown;
use crate::source::{self, EndReason, SourceError, SourceEvent, SourceSpec};
use device_protocol::Decoder;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Name of the lossless capture in a session directory.
pub const CAPTURE_FILE: &str = "capture.bin";
/// How often a running session logs its link statistics (when they changed).
const STATS_LOG_INTERVAL: Duration = Duration::from_secs(10);
/// How often the link's state is looked at while nothing happens (a silent link, a port
/// never heard): the view's banner follows within this.
const LINK_TICK: Duration = Duration::from_millis(500);

/// How long the pipeline keeps draining a source after shutdown was asked for.
const SHUTDOWN_GRACE: Duration = Duration::from_millis(300);

/// Name of the copy of the configuration a session started with (used by `--resume`).
pub const CONFIG_COPY: &str = "config.toml";

/// How a session with a live source starts in its directory.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Start {
    /// A new session. Refused when the directory already holds a capture: appending to it
    /// without its curves would lose them from the outputs. `config`, the text of the
    /// configuration file, is kept as `config.toml` for a later `--resume`.
    #[default]
    New,
    NewWithConfig(String),
    /// Continue a session: its capture is decoded first (the curves, tags and counters are
    /// rebuilt exactly as they were), then the source's bytes are appended to it.
    Resume,
}

/// Why a session could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A new session in a directory that already holds a capture.
    #[error("{} already holds a capture ({bytes} bytes): continue it with `sfs run --resume {}`, or choose another directory", path.display(), path.parent().unwrap_or(path).display())]
    CaptureExists { path: PathBuf, bytes: u64 },
    /// `--resume` where there is nothing to resume, or with a source that is not captured.
    #[error("cannot resume: {0}")]
    Resume(String),
    /// The view or the metrics cannot be served (address in use, not this machine's).
    #[error("cannot serve the view and metrics on {addr}: {source}")]
    Serve {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// The output directory or a file in it cannot be written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// Appending to the capture failed (the first write that failed): the source was stopped
    /// so that no byte is read uncaptured; the outputs hold what was captured.
    #[error("{0} (the source was stopped there, so that no byte is read without being captured; the outputs hold what was captured)")]
    Capture(OutputError),
    /// The input (capture file, serial port, stdin) is unavailable.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The input failed while it was read (written after the outputs of what was read).
    #[error("reading {source_name} failed before its end (the error is in the log); the outputs hold what was read")]
    Read { source_name: String },
}

/// What a finished session reports.
#[derive(Debug)]
pub struct Outcome {
    pub report: Report,
    pub report_path: PathBuf,
    pub capture_path: Option<PathBuf>,
    /// The view, still served after the end when the settings ask to keep serving.
    pub serving: Option<Serving>,
}

/// Runs a session from `spec` until its source ends or `shutdown` is triggered, then writes
/// `out_dir/report.json`. A live source is captured to `out_dir/capture.bin` (appended to, so a
/// resumed session continues it).
///
/// Its stages: the directory is prepared ([`prepare`]), the source started, the flow of
/// packets set up ([`Flow::start`]) and, on resume, fed the capture so far
/// ([`Flow::resume`]); then the source is streamed until it ends ([`Flow::stream`]) and the
/// outputs are written ([`Flow::finish`]).
pub async fn run(
    spec: SourceSpec,
    out_dir: &Path,
    settings: &Settings,
    start: Start,
    shutdown: Shutdown,
) -> Result<Outcome, SessionError> {
    // Everything that can refuse the session is done before a byte is captured: the port
    // bound, the directory prepared, the monitor's outputs opened; then the source starts.
    let listeners = bind_all(settings).await?;
    let prepared = prepare(&spec, out_dir, settings, &start)?;
    let description = spec.describe();
    let progress = replay_progress(&spec);
    let begin = match start {
        Start::Resume => Begin::Resume,
        Start::New | Start::NewWithConfig(_) => Begin::Fresh,
    };
    let monitor = match &settings.monitor {
        Some(m) => Some(Monitor::new(m.clone(), out_dir, begin).map_err(OutputError::at(out_dir))?),
        None => None,
    };
    // The view and the metrics: one server, stopped when the session ends (or, to keep a
    // recorded session on screen, when interrupted).
    let server_stop = Shutdown::new();
    let view = (!listeners.is_empty()).then(|| {
        let metrics = SessionMetrics::new(monitor.as_ref().map(|m| &m.metrics));
        crate::view::View::new(&description, metrics)
    });
    let server = view.as_ref().map(|v| {
        let access = &settings.view_access;
        crate::view::serve(
            listeners,
            v.clone(),
            server_stop.clone(),
            (access.allowed_hosts.clone(), access.token.clone()),
        )
    });
    let _stop_server = StopOnDrop(server_stop.clone());
    tracing::info!(source = %description, out = %out_dir.display(), "session started");
    let started = Instant::now();
    let created = prepared.created;
    let mut spec = spec;
    let port = match &spec {
        SourceSpec::Serial(s) => Some(s.path.display().to_string()),
        _ => None,
    };
    if let SourceSpec::Phone(p) = &mut spec {
        p.session_dir = out_dir.to_owned();
    }
    let mut src = match source::spawn(spec, prepared.capture, shutdown.clone()) {
        Ok(s) => s,
        Err(e) => {
            // Nothing was read: what this run made in the directory goes (a port that does
            // not exist leaves no empty session behind).
            created.undo();
            return Err(e.into());
        }
    };
    // Resume: the capture files to decode again, from the newest that starts before what a
    // monitor needs (all of them otherwise).
    let from = monitor.as_ref().and_then(|m| m.replay_from());
    let prior = prepared.prior.map(|files| decoded_again(files, from));
    if let (Some(v), Some(p)) = (&view, &src.phone) {
        v.phone(p.url(), p.fingerprint());
    }
    let clock_start = match &prior {
        Some(files) => files[0].start.clone(),
        None => prepared.replay_start,
    };
    let mut flow = Flow::start(
        settings,
        out_dir,
        &clock_start,
        monitor,
        &description,
        started,
        view.clone(),
    )?;
    flow.phone = src.phone.clone();
    flow.link = crate::link::LinkTracker::new(Instant::now(), port);
    // The service manager is told once the source is open (a resumed capture is decoded
    // after, with the watchdog fed as it goes).
    flow.notifier.ready(&format!("reading {description}"));
    if let Some(files) = prior {
        flow.notifier
            .status("resuming: decoding the capture so far");
        flow.resume(files)?;
        flow.notifier.status(&format!("reading {description}"));
    }
    let end = flow.stream(&mut src, &shutdown, progress.as_ref()).await;
    stop_source(src).await;
    flow.stats.partial_end_bytes = flow.decoder.buffered() as u64;
    if flow.stats.partial_end_bytes > 0 {
        tracing::info!(
            bytes = flow.stats.partial_end_bytes,
            "the stream ended inside a frame"
        );
    }
    if let Some(p) = progress {
        p.finish_and_clear();
    }
    log_stats("session ended", &flow.stats);
    let capture_failure = flow.capture_failure.take();
    let finished = flow.finish(settings, out_dir, end, &description, started);
    if end == EndReason::CaptureFailed {
        // The first write that failed is named (on a full disk the outputs written after it
        // fail too: said in the log).
        if let Err(e) = &finished {
            tracing::error!("{e}");
        }
        let failure = capture_failure.unwrap_or_else(|| {
            OutputError::at(&prepared.capture_path.clone().unwrap_or_default())(
                std::io::Error::other("appending to the capture failed"),
            )
        });
        return Err(SessionError::Capture(failure));
    }
    let (report, report_path) = finished?;
    if end == EndReason::ReadError {
        return Err(SessionError::Read {
            source_name: description,
        });
    }
    let serving = keep_or_stop(server, settings.keep_serving, _stop_server).await;
    Ok(Outcome {
        report,
        report_path,
        capture_path: prepared.capture_path,
        serving,
    })
}

/// Binds the view's address and the monitor's metrics address (one server when they are the
/// same).
async fn bind_all(settings: &Settings) -> Result<Vec<tokio::net::TcpListener>, SessionError> {
    let mut addrs: Vec<std::net::SocketAddr> = settings.view.into_iter().collect();
    if let Some(a) = settings.monitor.as_ref().and_then(|m| m.http) {
        if !addrs.contains(&a) {
            addrs.push(a);
        }
    }
    let mut listeners = Vec::new();
    for addr in addrs {
        listeners.push(
            crate::view::bind(addr)
                .await
                .map_err(|source| SessionError::Serve { addr, source })?,
        );
    }
    Ok(listeners)
}

/// Of a resumed session's capture files, those to decode again: from the newest that starts
/// at or before `from` (s of session time, what a monitor needs), all of them otherwise.
fn decoded_again(mut files: Vec<PriorFile>, from: Option<f64>) -> Vec<PriorFile> {
    let k = from.map_or(0, |t| {
        files
            .iter()
            .rposition(|f| f.start.elapsed_us as f64 * 1e-6 <= t)
            .unwrap_or(0)
    });
    files.split_off(k)
}

/// The view's server after the session: kept serving (`keep`) until the [`Serving`] is told
/// to stop, or stopped now (waiting up to 2 s for it).
async fn keep_or_stop(
    server: Option<tokio::task::JoinHandle<()>>,
    keep: bool,
    stop: StopOnDrop,
) -> Option<Serving> {
    match (server, keep) {
        (Some(task), true) => Some(Serving { task, _stop: stop }),
        (Some(task), false) => {
            stop.0.trigger();
            let _ = tokio::time::timeout(std::time::Duration::from_secs(2), task).await;
            None
        }
        (None, _) => None,
    }
}

/// The view of a finished session, still served (`keep_serving`: a replay watched with
/// `--view`) until [`Serving::until`] is told to stop; dropped, it stops at once.
#[derive(Debug)]
pub struct Serving {
    task: tokio::task::JoinHandle<()>,
    _stop: StopOnDrop,
}

impl Serving {
    /// Serves until `shutdown` is triggered (the operator's interrupt), then stops the
    /// server, giving it 2 s to close its connections.
    pub async fn until(self, shutdown: &Shutdown) {
        if !shutdown.is_triggered() {
            tracing::info!("the session is over; the view is still served until interrupted");
            shutdown.triggered().await;
        }
        let Serving { task, _stop } = self;
        drop(_stop);
        let _ = tokio::time::timeout(std::time::Duration::from_secs(2), task).await;
    }
}

/// A session directory made ready before the source starts.
struct Prepared {
    /// Where a live source's bytes are captured (`None`: a replayed file).
    capture_path: Option<PathBuf>,
    /// A resumed session's capture files, opened before the source appends to them.
    prior: Option<Vec<PriorFile>>,
    capture: Option<CaptureWriter>,
    /// Where the session clock starts for a replayed file (a piece of a rotated capture
    /// continues the time of the files before it: its sidecar).
    replay_start: crate::capture::CaptureStart,
    /// What preparing made, removed again when the source cannot start.
    created: Created,
}

/// The files and directory a session's preparation made (none of them existed before).
#[derive(Debug, Default)]
struct Created {
    dir: Option<PathBuf>,
    files: Vec<PathBuf>,
}

impl Created {
    /// Removes them: the directory with what it holds when this run made it (a monitor's
    /// outputs, opened empty, included), else the files; a capture only while it is empty.
    fn undo(self) {
        if let Some(d) = self.dir {
            let _ = std::fs::remove_dir_all(d);
            return;
        }
        for f in self.files {
            if std::fs::metadata(&f).is_ok_and(|m| m.len() == 0)
                || f.file_name().is_some_and(|n| n == CONFIG_COPY)
            {
                let _ = std::fs::remove_file(f);
            }
        }
    }
}

/// Prepares `out_dir`: created, the temporary files of a killed session removed, a new
/// session refused where a capture exists, the capture files of a resumed one opened, the
/// configuration kept (`config.toml`) and the capture opened for appending (rotated if
/// configured).
fn prepare(
    spec: &SourceSpec,
    out_dir: &Path,
    settings: &Settings,
    start: &Start,
) -> Result<Prepared, SessionError> {
    let output_err = OutputError::at;
    let mut created = Created {
        dir: (!out_dir.exists()).then(|| out_dir.to_owned()),
        files: Vec::new(),
    };
    std::fs::create_dir_all(out_dir).map_err(output_err(out_dir))?;
    match crate::atomic::remove_stale(out_dir) {
        Ok(0) => {}
        Ok(n) => tracing::info!("removed {n} temporary files a killed session left"),
        Err(e) => tracing::warn!("cannot clean {}: {e}", out_dir.display()),
    }
    let capture_path = spec.is_live().then(|| out_dir.join(CAPTURE_FILE));
    let prior = match (&capture_path, start) {
        (Some(p), Start::New | Start::NewWithConfig(_)) => match std::fs::metadata(p) {
            Ok(m) if m.len() > 0 => {
                return Err(SessionError::CaptureExists {
                    path: p.clone(),
                    bytes: m.len(),
                })
            }
            _ => None,
        },
        (Some(p), Start::Resume) => match prior_files(p) {
            Ok(f) => Some(f),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(SessionError::Resume(format!(
                    "{} has no {CAPTURE_FILE}",
                    out_dir.display()
                )))
            }
            Err(source) => return Err(output_err(p)(source).into()),
        },
        (None, Start::Resume) => {
            return Err(SessionError::Resume(
                "only a live source (serial port, standard input) has a capture to continue".into(),
            ))
        }
        (None, _) => None,
    };
    if let (Some(_), Start::NewWithConfig(text)) = (&capture_path, start) {
        let p = out_dir.join(CONFIG_COPY);
        if !p.exists() {
            created.files.push(p.clone());
        }
        crate::atomic::write_atomic(&p, text.as_bytes()).map_err(output_err(&p))?;
    }
    if let Some(p) = capture_path.as_ref().filter(|p| !p.exists()) {
        created.files.push(p.clone());
    }
    let capture = match (&capture_path, settings.capture_rotation) {
        (Some(p), None) => Some(CaptureWriter::open_append(p).map_err(output_err(p))?),
        (Some(p), Some(r)) => Some(CaptureWriter::open_rotating(p, r).map_err(output_err(p))?),
        (None, _) => None,
    };
    let replay_start = match spec {
        SourceSpec::Replay { path, .. } => crate::capture::read_start(path)
            .map_err(output_err(&crate::capture::start_path(path)))?,
        _ => Default::default(),
    };
    Ok(Prepared {
        capture_path,
        prior,
        capture,
        replay_start,
        created,
    })
}

/// What a session holds while it streams: the decoder and its statistics, acquisition, and
/// the monitor and live worker it feeds.
struct Flow {
    decoder: Decoder,
    stats: LinkStats,
    /// What the link is doing now (`/status` `link.state`, `sfs_link_up`).
    link: crate::link::LinkTracker,
    acq: Acquisition,
    monitor: Option<Monitor>,
    live: Option<crate::live::Live>,
    /// The first failed append to the capture (the source stopped there).
    capture_failure: Option<OutputError>,
    /// The live view, and the scan's warnings it has been given.
    view: Option<crate::view::View>,
    warnings_shown: usize,
    /// When the view was last given the preview, and whether it shows one.
    preview_at: Option<Instant>,
    preview_shown: bool,
    /// systemd: readiness, status, the watchdog fed by this loop.
    notifier: crate::service::Notifier,
    /// The watchdog test's fault injection ([`crate::service::stall_after_bytes`]).
    stall_after: Option<u64>,
    /// The phone page, told the open curve and the latest warning.
    phone: Option<std::sync::Arc<source::phone::Phone>>,
    /// The monitor's state the view was last given.
    monitor_shown: Option<crate::monitor::run::MonitorStatus>,
}

impl Flow {
    /// The flow of a session whose clock starts at `clock_start`, with its live worker when
    /// the settings ask for live updates.
    fn start(
        settings: &Settings,
        out_dir: &Path,
        clock_start: &crate::capture::CaptureStart,
        monitor: Option<Monitor>,
        description: &str,
        started: Instant,
        view: Option<crate::view::View>,
    ) -> Result<Flow, SessionError> {
        let mut monitor = monitor;
        if let (Some(m), Some(_)) = (&mut monitor, &view) {
            m.show();
        }
        let live = if settings.live {
            Some(
                crate::live::Live::spawn(crate::live::LiveSettings {
                    out_dir: out_dir.to_owned(),
                    network: settings.network,
                    joins: settings.joins.clone(),
                    surface: settings.surface,
                    snapshots: settings.snapshots,
                    source: description.to_owned(),
                    started,
                    view: view.clone(),
                })
                .map_err(|e| SessionError::Source(SourceError::Thread(e)))?,
            )
        } else {
            None
        };
        Ok(Flow {
            decoder: Decoder::new(),
            stats: LinkStats::default(),
            link: crate::link::LinkTracker::new(Instant::now(), None),
            acq: Acquisition::starting_at(
                AcquisitionConfig {
                    preview: view.is_some(),
                    ..settings.acquisition.clone()
                },
                clock_start,
            ),
            monitor,
            live,
            capture_failure: None,
            view,
            warnings_shown: 0,
            preview_at: None,
            preview_shown: false,
            notifier: crate::service::Notifier::from_env(),
            stall_after: crate::service::stall_after_bytes(),
            phone: None,
            monitor_shown: None,
        })
    }

    /// Decodes `bytes`; with `post`, hands every curve that ends (or changes) to the live
    /// worker as it happens.
    fn feed(&mut self, bytes: &[u8], post: bool) {
        for e in self.decoder.feed(bytes) {
            self.stats.observe(&e);
            for update in self.acq.event(&e) {
                if let (true, Update::CurveDropped(i) | Update::CurveReplaced { dropped: i, .. }) =
                    (post, update)
                {
                    if let Some(live) = &mut self.live {
                        live.remove(i, snapshot(&self.acq, &self.stats));
                    }
                }
                let update = match update {
                    Update::CurveReplaced { ended, .. } => Update::CurveEnded(ended),
                    u => u,
                };
                if let (true, Update::CurveEnded(i) | Update::CurveUpdated(i)) = (post, update) {
                    post_curve(&mut self.live, &self.acq, i, &self.stats);
                }
                if let (Some(v), Update::CurveEnded(i)) = (&self.view, update) {
                    v.curve_ended(i);
                }
                if let (true, Update::CurveEnded(i)) = (post, update) {
                    let curves = self.acq.scan().curves.len();
                    self.notifier
                        .status(&format!("curve {i} ended; {curves} curves in the scan"));
                }
            }
        }
        feed_monitor(&mut self.monitor, &mut self.acq);
        self.show();
    }

    /// Tells the view the link's state and counters (and the metrics).
    fn show_link(&self) {
        let Some(v) = &self.view else { return };
        let unix_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let state = self.link.state(Instant::now(), unix_ms);
        v.link(&self.stats, state, self.acq.session_time());
    }

    /// Gives the view the scan's warnings it has not shown yet.
    fn show_warnings(&mut self) {
        let Some(v) = &self.view else { return };
        let warnings = &self.acq.scan().warnings;
        if warnings.len() > self.warnings_shown {
            v.warnings(&warnings[self.warnings_shown..]);
            self.warnings_shown = warnings.len();
        }
    }

    /// Tells the view the link's counters, the curve being scanned and the new warnings.
    fn show(&mut self) {
        self.tell_phone();
        self.show_link();
        let Some(v) = self.view.clone() else { return };
        if let Some(m) = &mut self.monitor {
            // A structure monitored: its shape, alarms and sensors; nothing of a scan.
            if let Some(latest) = m.take_latest() {
                v.monitor_shape(latest);
            }
            let status = m.status();
            if self.monitor_shown.as_ref() != Some(&status) {
                self.monitor_shown = Some(status.clone());
                v.monitor(status);
            }
            self.show_warnings();
            return;
        }
        let curve = self.acq.open_curve().map(|c| crate::view::CurrentCurve {
            index: c.index,
            kind: c.kind.name(),
            nodes: c.nodes,
            samples: c.samples,
            distance_m: c.distance_m,
        });
        let orientation = self
            .acq
            .orientation()
            .map(|q| crate::view::Orientation::of(&q));
        v.update(|s| {
            s.curve = curve;
            s.curves_accepted = self.acq.scan().curves.len();
            s.orientation = orientation;
        });
        self.show_warnings();
        // The curve being scanned, every `view::PREVIEW_PERIOD` at most; cleared once when it ends.
        let due = self
            .preview_at
            .is_none_or(|t| t.elapsed() >= crate::view::PREVIEW_PERIOD);
        let preview = match (self.acq.curve_open(), self.preview_shown) {
            (true, _) if due => self.acq.preview(),
            (false, true) => None,
            _ => return,
        };
        if preview.is_some() || self.preview_shown {
            self.preview_shown = preview.is_some();
            self.preview_at = Some(Instant::now());
            v.preview(preview);
        }
    }

    /// Tells the phone page the open curve, the curves so far, the latest warning and the
    /// link's counters.
    fn tell_phone(&self) {
        let Some(p) = &self.phone else { return };
        let scan = self.acq.scan();
        p.tell(source::phone::Feedback {
            curve: self.acq.open_curve().map(|c| source::phone::FeedbackCurve {
                index: c.index,
                kind: c.kind.name(),
                nodes: c.nodes,
            }),
            curves: scan.curves.len(),
            warning: scan.warnings.last().map(|w| w.to_string()),
            packets: self.stats.packets.total(),
            rejected: self.stats.rejected.total(),
            lost: self.stats.lost_packets,
        });
    }

    /// Resume: the same decoder and acquisition state as if the session had not stopped.
    /// Read in pieces, up to the length each file had before the source appended to it, so
    /// that a monitor takes the epochs as they come; then every curve goes to the live worker.
    fn resume(&mut self, files: Vec<PriorFile>) -> Result<(), SessionError> {
        let mut chunk = vec![0u8; 1 << 16];
        let mut total = 0;
        for f in files {
            self.stats.bytes += f.len;
            total += f.len;
            let mut file = std::io::Read::take(f.file, f.len);
            loop {
                let n =
                    std::io::Read::read(&mut file, &mut chunk).map_err(OutputError::at(&f.path))?;
                if n == 0 {
                    break;
                }
                self.feed(&chunk[..n], false);
                self.notifier.alive();
            }
        }
        tracing::info!(
            bytes = total,
            curves = self.acq.scan().curves.len(),
            "resumed: the capture so far is decoded"
        );
        if let Some(l) = &mut self.live {
            for c in &self.acq.scan().curves {
                l.post(c, None, snapshot(&self.acq, &self.stats));
            }
        }
        Ok(())
    }

    /// Streams the source's events until it ends, the channel closes, or a shutdown's grace
    /// period runs out; logs the link statistics every [`STATS_LOG_INTERVAL`] they changed.
    async fn stream(
        &mut self,
        src: &mut source::SourceHandle,
        shutdown: &Shutdown,
        progress: Option<&indicatif::ProgressBar>,
    ) -> EndReason {
        let mut deadline: Option<tokio::time::Instant> = None;
        let mut tick = tokio::time::interval_at(
            tokio::time::Instant::now() + STATS_LOG_INTERVAL,
            STATS_LOG_INTERVAL,
        );
        let mut logged = LinkStats::default();
        // The watchdog is fed by this loop, also while the source is silent.
        let ping_period = self.notifier.ping_period();
        let mut watchdog =
            tokio::time::interval(ping_period.unwrap_or(std::time::Duration::from_secs(3600)));
        // The link's state moves with time too (silent, a port never heard).
        let mut link_tick = tokio::time::interval(LINK_TICK);
        link_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            self.notifier.alive();
            let ev = tokio::select! {
                ev = src.events.recv() => ev,
                _ = watchdog.tick(), if ping_period.is_some() => continue,
                _ = link_tick.tick() => {
                    if let Some(problem) = self.link.tick(Instant::now(), &self.stats) {
                        tracing::warn!("{problem}");
                    }
                    self.show_link();
                    continue;
                }
                _ = tick.tick() => {
                    if self.stats != logged {
                        log_stats("link", &self.stats);
                        logged = self.stats.clone();
                    }
                    continue;
                }
                _ = shutdown.triggered(), if deadline.is_none() => {
                    tracing::info!("shutdown requested: draining the source");
                    self.notifier.stopping();
                    deadline = Some(tokio::time::Instant::now() + SHUTDOWN_GRACE);
                    continue;
                }
                _ = sleep_until(deadline), if deadline.is_some() => {
                    tracing::warn!("source did not stop in time; finishing without it");
                    return EndReason::Shutdown;
                }
            };
            match ev {
                Some(SourceEvent::Bytes(bytes)) => {
                    self.stats.bytes += bytes.len() as u64;
                    self.link.bytes(Instant::now());
                    if self.stall_after.is_some_and(|n| self.stats.bytes >= n) {
                        crate::service::stall();
                    }
                    if let Some(p) = progress {
                        p.inc(bytes.len() as u64);
                    }
                    self.feed(&bytes, true);
                }
                Some(SourceEvent::Connected { .. }) => {
                    self.stats.connects += 1;
                    self.link.connected(Instant::now());
                    self.show_link();
                }
                Some(SourceEvent::Disconnected { reason }) => {
                    self.stats.disconnects += 1;
                    self.link.disconnected(Instant::now(), &reason);
                    self.show_link();
                }
                Some(SourceEvent::Reconnecting { attempt, error }) => {
                    self.link.reconnecting(Instant::now(), attempt, &error);
                    self.show_link();
                }
                Some(SourceEvent::CaptureFailed { path, kind, error }) => {
                    self.capture_failure.get_or_insert(OutputError {
                        path,
                        source: std::io::Error::new(kind, error),
                    });
                }
                Some(SourceEvent::End { reason }) => {
                    self.link.ended(Instant::now());
                    self.show_link();
                    return reason;
                }
                None => return EndReason::Shutdown,
            }
        }
    }

    /// The final outputs: the monitor and the live worker finish (its last reconstruction is
    /// the final one, the same bits a fresh one would give, when it saw every curve),
    /// `scan.json`, `network.glb` and `report.json` are written.
    fn finish(
        self,
        settings: &Settings,
        out_dir: &Path,
        end: EndReason,
        description: &str,
        started: Instant,
    ) -> Result<(Report, PathBuf), SessionError> {
        // The last windows of a sensor array, when complete, are epochs too.
        let (mut acq, mut monitor) = (self.acq, self.monitor);
        acq.close_array();
        feed_monitor(&mut monitor, &mut acq);
        let mut warnings = None;
        let view = self.view.clone();
        let monitor_report = monitor.map(|mut m| {
            m.finish();
            // The view shows the last epochs too (`/network.glb` is `latest.glb`).
            if let Some(v) = &view {
                if let Some(latest) = m.take_latest() {
                    v.monitor_shape(latest);
                }
                v.monitor(m.status());
            }
            if let Some(w) = m.unknown_sensors() {
                tracing::warn!("{w}");
                warnings = Some(w);
            }
            m.report
        });
        let live = self.live.map(|l| l.finish());
        let device = acq.device();
        let scan = acq.finish();
        let scan_path = out_dir.join(SCAN_FILE);
        crate::atomic::write_json(&scan_path, &scan, false).map_err(OutputError::at(&scan_path))?;
        let (products, mut live_report, fresh) = match live {
            Some(crate::live::LiveOutcome {
                report,
                products: Some(p),
                curves,
            }) if curves == scan.curves.len() => (p, Some(report), false),
            other => (
                Pipeline::with_joins(settings.joins.clone()).run(
                    &scan.curves,
                    &crate::pipeline::exact_network(&crate::pipeline::for_device(
                        &settings.network,
                        device,
                    )),
                    settings
                        .surface
                        .as_ref()
                        .map(crate::pipeline::exact)
                        .as_ref(),
                ),
                other.map(|o| o.report),
                true,
            ),
        };
        if !fresh {
            // The live updates logged theirs as provisional: the final ones are warnings.
            crate::pipeline::log_final(&products);
        }
        products.write_glb(out_dir)?;
        if let Some(l) = &mut live_report {
            crate::memory::release_free_memory();
            (l.rss_mb, l.peak_rss_mb) = crate::memory::rss_mb();
        }
        // The monitor's warning (its sensors the layout does not place) with the products'.
        let mut products = products;
        products.warnings.extend(warnings);
        let mut report = Report::assemble(
            Progress {
                source: description,
                ended: end.name(),
                started,
                link: &self.stats,
                curves: &scan.curves,
                counts: &scan.counts,
                warnings: &scan.warnings,
            },
            &products,
        );
        report.monitor = monitor_report;
        report.phone = self.phone.as_ref().map(|p| p.report());
        let report_path = out_dir.join(REPORT_FILE);
        report.live = live_report;
        report
            .write(&report_path)
            .map_err(OutputError::at(&report_path))?;
        // The view says `ended` once every output is in place.
        if let Some(v) = &self.view {
            v.warnings(scan.warnings.iter().chain(&products.warnings));
            v.reconstruction_warnings(&[]);
            v.quality(&report.quality);
            if fresh {
                let live = report.live.clone().unwrap_or_default();
                v.network(&products, &live, scan.curves.len(), &[]);
            }
            v.preview(None);
            v.ended();
        }
        Ok((report, report_path))
    }
}

/// Stops the source: the channel is closed (a source still blocked on send sees it and
/// stops) and its thread is given a second to finish its final fsync; a thread blocked
/// reading stdin is left.
async fn stop_source(src: source::SourceHandle) {
    let source::SourceHandle { events, thread, .. } = src;
    drop(events);
    let join_deadline = Instant::now() + Duration::from_secs(1);
    while !thread.is_finished() && Instant::now() < join_deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    if thread.is_finished() {
        let _ = thread.join();
    }
}

/// Hands acquisition's sensor-array epochs to the monitor (if any), and closes the epochs
/// acquisition has completed.
fn feed_monitor(monitor: &mut Option<Monitor>, acq: &mut Acquisition) {
    if let Some(m) = monitor {
        for e in acq.take_array() {
            m.feed(&e);
        }
        if let Some(t) = acq.array_complete_until() {
            m.close_until(t);
        }
    }
}

/// A capture file of a session being resumed, opened before the source appends to it.
struct PriorFile {
    path: PathBuf,
    file: std::fs::File,
    /// Its length then.
    len: u64,
    /// The session clock where it starts ([`crate::capture::CaptureStart`]).
    start: crate::capture::CaptureStart,
}

/// The capture files of a session, oldest first: the rotated ones still kept
/// (`capture.K.bin` … `capture.1.bin`), then `capture` itself.
fn prior_files(capture: &Path) -> std::io::Result<Vec<PriorFile>> {
    let open = |path: PathBuf| -> std::io::Result<PriorFile> {
        let file = std::fs::File::open(&path)?;
        let len = file.metadata()?.len();
        let start = crate::capture::read_start(&path)?;
        Ok(PriorFile {
            path,
            file,
            len,
            start,
        })
    };
    let mut files = vec![open(capture.to_owned())?];
    let stem = capture.file_stem().unwrap_or_default().to_string_lossy();
    for k in 1.. {
        match open(capture.with_file_name(format!("{stem}.{k}.bin"))) {
            Ok(f) => files.push(f),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => break,
            Err(e) => return Err(e),
        }
    }
    files.reverse();
    Ok(files)
}

/// A progress bar on standard error for a replayed capture, when standard error is a terminal
/// (never in logs piped to a file).
fn replay_progress(spec: &SourceSpec) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    let SourceSpec::Replay { path, .. } = spec else {
        return None;
    };
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let len = std::fs::metadata(path).ok()?.len();
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(len),
        indicatif::ProgressDrawTarget::stderr_with_hz(4),
    );
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{bar:40} {bytes}/{total_bytes} ({eta} left)")
    {
        bar.set_style(style);
    }
    Some(bar)
}

/// Sends curve `index` (just ended or changed) to the live worker.
fn post_curve(
    live: &mut Option<crate::live::Live>,
    acq: &Acquisition,
    index: usize,
    stats: &LinkStats,
) {
    let Some(live) = live else { return };
    if let Some(c) = acq.scan().curves.iter().find(|c| c.index == index) {
        live.post(c, Some(Instant::now()), snapshot(acq, stats));
    }
}

/// The session's counters for a live update.
fn snapshot(acq: &Acquisition, stats: &LinkStats) -> crate::live::Snapshot {
    let scan = acq.scan();
    crate::live::Snapshot {
        link: stats.clone(),
        counts: scan.counts.clone(),
        warnings: scan.warnings.clone(),
        device: acq.device(),
    }
}

fn log_stats(msg: &str, s: &LinkStats) {
    tracing::info!(
        bytes = s.bytes,
        packets = s.packets.total(),
        rejected_crc = s.rejected.crc,
        rejected_cobs = s.rejected.cobs,
        rejected_length = s.rejected.length,
        unknown_types = s.unknown_types,
        lost_packets = s.lost_packets,
        reboots = s.reboots,
        clock_wraps = s.clock_wraps,
        disconnects = s.disconnects,
        "{msg}"
    );
}

async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}

/// Triggers a [`Shutdown`] when dropped (the view's server stops with the session, however
/// it ends).
#[derive(Debug)]
struct StopOnDrop(Shutdown);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.trigger();
    }
}
