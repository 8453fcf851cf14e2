//! One session: a source feeding the decoder, with the capture, statistics and outputs.
//!
//! `bytes → source thread (capture first) → channel → decoder → link statistics → report.json`.
//! Later stages (acquisition, reconstruction) hang off the decoder's packets here.

use crate::acquisition::{Acquisition, AcquisitionConfig, Update};
use crate::capture::CaptureWriter;
use crate::link::LinkStats;
use crate::report::{CurveSummary, Report};
use crate::shutdown::Shutdown;
use crate::source::{self, EndReason, SourceError, SourceEvent, SourceSpec};
use device_protocol::Decoder;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Name of the lossless capture in a session directory.
pub const CAPTURE_FILE: &str = "capture.bin";
/// Name of the report in a session (or replay output) directory.
pub const REPORT_FILE: &str = "report.json";
/// Name of the acquired scan (curves of raw samples and tags).
pub const SCAN_FILE: &str = "scan.json";
/// Name of the reconstructed network (glTF binary).
pub const NETWORK_FILE: &str = "network.glb";

/// What a session does with the packets (everything but the source).
#[derive(Debug, Clone)]
pub struct Options {
    pub acquisition: AcquisitionConfig,
    pub network: crate::network::NetworkParams,
    /// Surfacing settings; `None` writes the network only.
    pub surface: Option<crate::surface::fit::SurfaceParams>,
}

/// The soft-constraint weight ω of the surface fit for scans (measured data). On a noisy
/// sphere network (2 cm noise on a unit sphere) it takes the surface's mean distance from
/// 0.0109 (hard) to about 0.004; on simulated scans, whose curve errors are smooth drifts
/// rather than noise, it costs little (lilium 0.065 % hard, 0.067 %; weaker weights cost
/// more there: 0.077 % at 0.01). BENCHMARKS.md, "Soft constraints".
pub const SCAN_SOFTNESS: Option<f64> = Some(0.3);

impl Default for Options {
    /// Documented defaults; the surface is made, with soft constraints ([`SCAN_SOFTNESS`]).
    fn default() -> Self {
        Options {
            acquisition: AcquisitionConfig::default(),
            network: crate::network::NetworkParams::default(),
            surface: Some(crate::surface::fit::SurfaceParams {
                soft: SCAN_SOFTNESS,
                ..Default::default()
            }),
        }
    }
}

/// How often a running session logs its link statistics (when they changed).
const STATS_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// How long the pipeline keeps draining a source after shutdown was asked for.
const SHUTDOWN_GRACE: Duration = Duration::from_millis(300);

/// Why a session could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The input (capture file, serial port, stdin) is unavailable.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The output directory or a file in it cannot be written.
    #[error("cannot write {}: {source}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// What a finished session reports.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub report: Report,
    pub report_path: PathBuf,
    pub capture_path: Option<PathBuf>,
}

/// Runs a session from `spec` until its source ends or `shutdown` is triggered, then writes
/// `out_dir/report.json`. A live source is captured to `out_dir/capture.bin` (appended to, so a
/// resumed session continues it).
pub async fn run(
    spec: SourceSpec,
    out_dir: &Path,
    options: &Options,
    shutdown: Shutdown,
) -> Result<Outcome, SessionError> {
    let output_err = |path: &Path| {
        let path = path.to_owned();
        move |source| SessionError::Output { path, source }
    };
    std::fs::create_dir_all(out_dir).map_err(output_err(out_dir))?;
    let capture_path = spec.is_live().then(|| out_dir.join(CAPTURE_FILE));
    let capture = match &capture_path {
        Some(p) => Some(CaptureWriter::open_append(p).map_err(output_err(p))?),
        None => None,
    };
    let description = spec.describe();
    tracing::info!(source = %description, out = %out_dir.display(), "session started");
    let started = Instant::now();
    let mut src = source::spawn(spec, capture, shutdown.clone())?;

    let mut decoder = Decoder::new();
    let mut stats = LinkStats::default();
    let mut acq = Acquisition::new(options.acquisition.clone());
    let mut end = EndReason::Shutdown;
    let mut deadline: Option<tokio::time::Instant> = None;
    let mut tick = tokio::time::interval_at(
        tokio::time::Instant::now() + STATS_LOG_INTERVAL,
        STATS_LOG_INTERVAL,
    );
    let mut logged = LinkStats::default();
    loop {
        let ev = tokio::select! {
            ev = src.events.recv() => ev,
            _ = tick.tick() => {
                if stats != logged {
                    log_stats("link", &stats);
                    logged = stats.clone();
                }
                continue;
            }
            _ = shutdown.triggered(), if deadline.is_none() => {
                tracing::info!("shutdown requested: draining the source");
                deadline = Some(tokio::time::Instant::now() + SHUTDOWN_GRACE);
                continue;
            }
            _ = sleep_until(deadline), if deadline.is_some() => {
                tracing::warn!("source did not stop in time; finishing without it");
                break;
            }
        };
        match ev {
            Some(SourceEvent::Bytes(bytes)) => {
                stats.bytes += bytes.len() as u64;
                for e in decoder.feed(&bytes) {
                    stats.observe(&e);
                    match acq.event(&e) {
                        Some(Update::CurveEnded(_)) | Some(Update::CurveUpdated(_)) | None => {}
                    }
                }
            }
            Some(SourceEvent::Connected { .. }) => stats.connects += 1,
            Some(SourceEvent::Disconnected { .. }) => stats.disconnects += 1,
            Some(SourceEvent::End { reason }) => {
                end = reason;
                break;
            }
            None => break,
        }
    }
    drop(src.events); // a source still blocked on send sees the channel closed and stops
                      // Let the source thread finish its final fsync; a thread blocked reading stdin is left.
    let join_deadline = Instant::now() + Duration::from_secs(1);
    while !src.thread.is_finished() && Instant::now() < join_deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    if src.thread.is_finished() {
        let _ = src.thread.join();
    }
    if decoder.buffered() > 0 {
        tracing::debug!(bytes = decoder.buffered(), "stream ended inside a frame");
    }
    log_stats("session ended", &stats);
    let mut scan = acq.finish();
    let scan_path = out_dir.join(SCAN_FILE);
    crate::atomic::write_json(&scan_path, &scan, false).map_err(output_err(&scan_path))?;
    let mut reconstructor = crate::network::Reconstructor::new();
    let network = reconstructor.run(&scan, &options.network);
    let mut nodes = std::collections::BTreeMap::new();
    let mut surface_report = None;
    if let Some(net) = &network {
        scan.warnings.extend(net.warnings.iter().cloned());
        let surfaced = options.surface.as_ref().and_then(|sp| {
            let t0 = Instant::now();
            let segs = crate::surface::cycles::NetworkSegments::from_positions(&net.positions);
            match crate::surface::fit::surface(&segs, sp) {
                Ok(s) => {
                    let r = s.report(t0.elapsed().as_secs_f64() * 1e3);
                    scan.warnings
                        .extend(s.problems.iter().map(|p| format!("surface: {p}")));
                    surface_report = Some(r);
                    Some(s)
                }
                Err(e) => {
                    tracing::warn!("no surface: {e}");
                    scan.warnings.push(format!("no surface: {e}"));
                    None
                }
            }
        });
        let glb_path = out_dir.join(NETWORK_FILE);
        match network_glb(net, surfaced.as_ref()) {
            Ok(bytes) => {
                crate::atomic::write_atomic(&glb_path, &bytes).map_err(output_err(&glb_path))?
            }
            Err(e) => {
                tracing::error!("network.glb not written: {e}");
                scan.warnings.push(format!("network.glb not written: {e}"));
            }
        }
        for (k, p) in &net.positions.nodes {
            nodes.insert(k.to_string(), crate::gltf_out::to_gltf(p));
        }
    }
    let report = Report {
        sfs_version: env!("CARGO_PKG_VERSION"),
        source: description,
        ended: match end {
            EndReason::EndOfInput => "end_of_input",
            EndReason::Shutdown => "shutdown",
            EndReason::CaptureFailed => "capture_failed",
            EndReason::ReadError => "read_error",
        },
        wall_time_s: started.elapsed().as_secs_f64(),
        link: stats,
        curves: scan.curves.iter().map(CurveSummary::from).collect(),
        acquisition: scan.counts.clone(),
        warnings: scan.warnings.clone(),
        nodes,
        timings_ms: network.as_ref().map(|n| n.report.timings_ms.clone()),
        network: network.map(|n| n.report),
        surface: surface_report,
    };
    let report_path = out_dir.join(REPORT_FILE);
    report
        .write(&report_path)
        .map_err(output_err(&report_path))?;
    if end == EndReason::CaptureFailed {
        return Err(SessionError::Output {
            path: capture_path.clone().unwrap_or_default(),
            source: std::io::Error::other("appending to the capture failed"),
        });
    }
    Ok(Outcome {
        report,
        report_path,
        capture_path,
    })
}

/// The glb of a reconstruction.
fn network_glb(
    net: &crate::network::Network,
    surface: Option<&crate::surface::fit::Surfaced>,
) -> Result<Vec<u8>, crate::gltf_out::GltfError> {
    let mesh = surface.map(|s| s.mesh());
    crate::gltf_out::network_glb(
        &net.positions.network_curves(),
        &net.positions.nodes,
        mesh.as_ref(),
    )
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
