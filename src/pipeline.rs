//! The pipeline's products: one place that turns a scan's curves into the network, its
//! surface, the `network.glb` bytes and the warnings, for the live updates and the session's
//! final outputs alike; monitoring surfaces and encodes its shapes through the same steps.
//!
//! ```text
//! curves ─▶ Reconstructor (pre-filter, closure test, regression, Poisson) ─▶ positions
//!        ─▶ surface (segments ─▶ Surfacer) ─▶ glb (curves, nodes, surface) ─▶ Products
//! ```
//!
//! Two phases (issue 35): [`Pipeline::reconstruct`] makes the network alone, which the live
//! worker publishes at once (the view's `curves` event); [`Pipeline::surface_into`] then
//! surfaces it and encodes `network.glb`. [`Pipeline::run`] is both.

use crate::atomic::OutputError;
use crate::scan::Curve;
use crate::warning::Warning;
use sfs_geometry::network::join::JoinSettings;
use sfs_geometry::network::poisson::Positions;
use sfs_geometry::network::{Network, NetworkParams, Reconstructor};
use sfs_geometry::surface::cycles::NetworkSegments;
use sfs_geometry::surface::fit::{SurfaceError, SurfaceParams, SurfaceReport, Surfaced, Surfacer};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// Name of the report in a session (or replay output) directory.
pub const REPORT_FILE: &str = "report.json";
/// Name of the acquired scan (curves of raw samples and tags).
pub const SCAN_FILE: &str = "scan.json";
/// Name of the reconstructed network (glTF binary).
pub const NETWORK_FILE: &str = "network.glb";
/// Name of the folder of per-curve snapshots in a session directory.
pub const SNAPSHOT_DIR: &str = "snapshots";

/// The soft-constraint weight ω of the surface fit for scans (measured data). On a noisy
/// sphere network (2 cm noise on a unit sphere) it takes the surface's mean distance from
/// 0.0109 (hard) to about 0.004; on simulated scans, whose curve errors are smooth drifts
/// rather than noise, it costs little (lilium 0.065 % hard, 0.067 %; weaker weights cost
/// more there: 0.077 % at 0.01). BENCHMARKS.md, "Soft constraints".
pub const SCAN_SOFTNESS: Option<f64> = Some(0.3);

/// Default `[surface] reuse_tolerance` (target edges): a live update keeps the faces whose
/// rims moved less than half an edge since they were built and is provisional until the
/// worker settles it (`sfs_geometry::surface::fit::SurfaceParams::reuse_tolerance`; BENCHMARKS.md,
/// issue 19). Replays surface once, from scratch, whatever it is.
pub const LIVE_REUSE_TOLERANCE: f64 = 0.5;

/// Default `[network] local_window` (samples): a live update regresses the frames of the new
/// curve and those within this many samples of its nodes, the rest kept from the last update,
/// and is provisional until the worker settles it (`NetworkParams::local_window`;
/// BENCHMARKS.md, issue 19: on five scenes in both profiles, windows of 5 to 30 samples all
/// put every point within 1e-6 of the diagonal of the whole network's regression; issue 51:
/// 3 samples as close as 10 on the same scenes, where 2 are not: a correction at a node decays
/// by about 0.3 a sample, and on a grid of 100 curves the new curve's windows are most of the
/// update's frames).
pub const LIVE_LOCAL_WINDOW: usize = 3;

/// What one reconstruction of a scan produced (network, surface, the glb bytes), before it is
/// written: shared by the live updates and the session's final outputs.
#[derive(Debug, Default)]
pub struct Products {
    pub network: Option<Network>,
    pub surface: Option<SurfaceReport>,
    /// Node positions in the glb's frame (y up), by node index.
    pub nodes: BTreeMap<String, [f32; 3]>,
    /// The reconstruction's and the surfacer's warnings (naming curves and nodes).
    pub warnings: Vec<Warning>,
    /// `network.glb`, when there is a network and it could be encoded.
    pub glb: Option<Vec<u8>>,
    pub network_ms: f64,
    pub surface_ms: f64,
}

impl Products {
    /// Replaces `dir/network.glb` atomically; when there is no network, removes the one an
    /// earlier update left, so that network.glb never describes another update than
    /// report.json (which says why there is none).
    pub fn write_glb(&self, dir: &Path) -> Result<(), OutputError> {
        let path = dir.join(NETWORK_FILE);
        match &self.glb {
            Some(bytes) => {
                crate::atomic::write_atomic(&path, bytes).map_err(OutputError::at(&path))
            }
            None => match std::fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    Err(OutputError::at(&path)(e))
                }
                _ => Ok(()),
            },
        }
    }

    /// Writes `dir/snapshots/curve-NNN.glb`.
    pub fn write_snapshot(&self, dir: &Path, curve: usize) -> Result<(), OutputError> {
        let Some(bytes) = &self.glb else {
            return Ok(());
        };
        let folder = dir.join(SNAPSHOT_DIR);
        let path = folder.join(format!("curve-{curve:03}.glb"));
        std::fs::create_dir_all(&folder)
            .and_then(|_| crate::atomic::write_atomic(&path, bytes))
            .map_err(OutputError::at(&path))
    }
}

/// Logs the warnings of a session's final reconstruction when it came from the live worker
/// (whose updates logged them as provisional), with the usual rate limit.
pub fn log_final(p: &Products) {
    let mut log = crate::warning::LogLimiter::default();
    p.warnings.iter().for_each(|w| log.log(w));
}

/// The reconstruction caches kept between runs over a growing scan: the pre-filtered curves
/// and the symbolic factorisations (they change the time a run takes, not its result).
#[derive(Debug, Default)]
pub struct Pipeline {
    reconstructor: Reconstructor,
    /// Nodes joined after the fact ([`sfs_geometry::network::join::run_joined`]).
    joins: JoinSettings,
    surfacer: Surfacer,
    /// The log's rate limit for the warnings of every run (the geometry logs none itself).
    log: crate::warning::LogLimiter,
}

impl Pipeline {
    /// With the default joins ([`JoinSettings::default`]).
    pub fn new() -> Self {
        Self::default()
    }

    /// With the joins of `joins` (`[network] join_*`).
    pub fn with_joins(joins: JoinSettings) -> Self {
        Pipeline {
            joins,
            ..Self::default()
        }
    }

    /// For the live updates of a scan still going on: what a run cannot do yet (no cycle, a
    /// face along one curve both ways) is logged at info, not as a warning; the session's
    /// final outputs say what is left ([`log_final`]).
    pub fn live(self) -> Self {
        Pipeline {
            log: crate::warning::LogLimiter::provisional(),
            ..self
        }
    }

    /// Reconstructs the network of `curves`, and its surface when `surface` is given.
    pub fn run(
        &mut self,
        curves: &[Curve],
        network: &NetworkParams,
        surface: Option<&SurfaceParams>,
    ) -> Products {
        let mut out = self.reconstruct(curves, network);
        self.surface_into(&mut out, surface);
        out
    }

    /// The network of `curves` alone (no surface, no glb yet): the first phase of
    /// [`run`](Self::run), what the live view draws before the surface comes.
    pub fn reconstruct(&mut self, curves: &[Curve], network: &NetworkParams) -> Products {
        self.reconstruct_until(curves, network, &|| false)
            .unwrap_or_default()
    }

    /// As [`reconstruct`](Self::reconstruct), asking `stop` between its long steps (each pass
    /// of the loop-closure test, each join pass): `None` once it said yes.
    fn reconstruct_until(
        &mut self,
        curves: &[Curve],
        network: &NetworkParams,
        stop: &dyn Fn() -> bool,
    ) -> Option<Products> {
        let t0 = Instant::now();
        let net = sfs_geometry::network::join::run_joined_until(
            &mut self.reconstructor,
            curves,
            network,
            &self.joins,
            stop,
        );
        let mut out = Products {
            network_ms: t0.elapsed().as_secs_f64() * 1e3,
            ..Default::default()
        };
        let net = match net {
            Ok(net) => net,
            Err(why) if why.interrupted => return None,
            Err(why) => {
                // Nothing reconstructed: the report says why (each curve left out, or the
                // failed solve).
                out.warnings
                    .extend(why.warnings.into_iter().map(Warning::Network));
                out.warnings.iter().for_each(|w| self.log.log(w));
                return Some(out);
            }
        };
        out.warnings
            .extend(net.warnings.iter().cloned().map(Warning::Network));
        out.warnings.iter().for_each(|w| self.log.log(w));
        for (k, p) in &net.positions.nodes {
            out.nodes.insert(k.to_string(), crate::gltf_out::to_gltf(p));
        }
        out.network = Some(net);
        Some(out)
    }

    /// The nodes' uncertainty of the network in `out`, reconstructed by
    /// [`reconstruct`](Self::reconstruct) with `network`'s `defer_uncertainty` (the live
    /// worker's first phase, whose curves are published before it): the second phase's first
    /// step.
    pub fn uncertainty_into(&mut self, out: &mut Products, network: &NetworkParams) {
        if let Some(net) = out.network.as_mut() {
            self.reconstructor.uncertainty(net, network);
        }
    }

    /// Makes provisional products exact: a network regressed locally
    /// ([`NetworkParams::local_window`]) is reconstructed again over the whole network and
    /// surfaced exactly; a provisional surface (a live update that kept faces,
    /// [`SurfaceParams::reuse_tolerance`]) is surfaced again with no tolerance: what a run
    /// from scratch on `curves` gives. Whether `out` was settled: not when there was nothing
    /// to settle, nor when `waiting` says a curve waits: it is asked between the network's
    /// long steps (each pass of the loop-closure test, each join pass) and once the network is
    /// made, and the settle stops there (the next update comes first; its local regression
    /// starts from the frames regressed so far).
    pub fn settle(
        &mut self,
        curves: &[Curve],
        out: &mut Products,
        network: &NetworkParams,
        surface: Option<&SurfaceParams>,
        waiting: impl Fn() -> bool,
    ) -> bool {
        let surface = surface.map(exact);
        if out.network.as_ref().is_some_and(|n| n.report.provisional) {
            let Some(mut settled) =
                self.reconstruct_until(curves, &exact_network(network), &waiting)
            else {
                return false;
            };
            if waiting() {
                return false;
            }
            self.surface_into(&mut settled, surface.as_ref());
            *out = settled;
            return true;
        }
        if !out.surface.as_ref().is_some_and(|s| s.provisional) {
            return false;
        }
        out.warnings.retain(|w| {
            !matches!(
                w,
                Warning::Surface(_)
                    | Warning::NoSurface(_)
                    | Warning::SurfaceNotWritten(_)
                    | Warning::GlbNotWritten(_)
            )
        });
        self.surface_into(out, surface.as_ref());
        true
    }

    /// The surface of the network in `out` (when `surface` is given) and the glb of both: the
    /// second phase of [`run`](Self::run).
    pub fn surface_into(&mut self, out: &mut Products, surface: Option<&SurfaceParams>) {
        let Some(net) = &out.network else {
            return;
        };
        out.surface = None;
        let surfaced = surface.and_then(|sp| {
            let (result, ms) = surface_of(&net.positions, sp, &mut self.surfacer);
            out.surface_ms = ms;
            match result {
                Ok(s) => {
                    out.warnings
                        .extend(s.problems.iter().cloned().map(Warning::Surface));
                    out.surface = Some(s.report(ms));
                    Some(s)
                }
                Err(e) => {
                    let w = Warning::NoSurface(e);
                    self.log.log(&w);
                    out.warnings.push(w);
                    None
                }
            }
        });
        out.glb = None;
        // A surface that cannot be written never costs the network: network.glb then holds
        // the curves and no surface node, and the report says why.
        let encoded = match glb(&net.positions, surfaced.as_ref()) {
            Err(e) if surfaced.is_some() => glb(&net.positions, None).map(|b| (b, Some(e))),
            r => r.map(|b| (b, None)),
        };
        match encoded {
            Ok((bytes, surface_error)) => {
                if let Some(e) = surface_error {
                    let w = Warning::SurfaceNotWritten(e);
                    self.log.log(&w);
                    out.warnings.push(w);
                    out.surface = None;
                }
                out.glb = Some(bytes);
            }
            Err(e) => {
                tracing::error!("network.glb not written: {e}");
                out.warnings.push(Warning::GlbNotWritten(e));
            }
        }
    }
}

/// The surfacing settings with no faces reused: the surface a run from scratch gives (the
/// final outputs of a session, a replay, the live worker's settled updates).
pub fn exact(surface: &SurfaceParams) -> SurfaceParams {
    SurfaceParams {
        reuse_tolerance: 0.0,
        ..*surface
    }
}

/// The reconstruction settings with the whole network regressed: the network a run from
/// scratch gives (the final outputs of a session, the live worker's settled updates).
/// `network` with the noise of `device` (the Morphorider's when unknown), what the nodes'
/// uncertainty is calibrated with (`sfs_geometry::network::marginals::NoisePrior`), and the
/// test its slips are named by (`SlipTest`: a wheel's milder; a phone's strict, its milder
/// showings named and kept), and for a wheel the spread of its curves' scales, which the loops
/// then estimate (`curve_scale`).
pub fn for_device(
    network: &NetworkParams,
    device: Option<device_protocol::DeviceKind>,
) -> NetworkParams {
    use sfs_geometry::network::closure::SlipTest;
    use sfs_geometry::network::marginals::NoisePrior;
    NetworkParams {
        noise: match device {
            Some(device_protocol::DeviceKind::Phone) => NoisePrior::PHONE,
            _ => NoisePrior::MORPHORIDER,
        }
        .overridden(),
        slips: match device {
            Some(device_protocol::DeviceKind::Phone) => SlipTest::PHONE,
            _ => SlipTest::WHEEL,
        },
        // A wheel reads each curve a little long or short; a phone's lengths are measured
        // per segment or come from its speed (no scale common to a curve).
        curve_scale_sigma: match device {
            Some(device_protocol::DeviceKind::Phone) => None,
            _ => Some(sfs_geometry::network::curve_scale::WHEEL_SIGMA),
        },
        ..*network
    }
}

pub fn exact_network(network: &NetworkParams) -> NetworkParams {
    NetworkParams {
        local_window: 0,
        defer_uncertainty: false,
        ..*network
    }
}

/// The surface of a reconstructed network (its segments through the surfacer, whose caches
/// are kept in `surfacer`), and the time it took, ms.
pub fn surface_of(
    positions: &Positions,
    params: &SurfaceParams,
    surfacer: &mut Surfacer,
) -> (Result<Surfaced, SurfaceError>, f64) {
    let t0 = Instant::now();
    let segments = NetworkSegments::from_positions(positions);
    let result = surfacer.run(&segments, params);
    (result, t0.elapsed().as_secs_f64() * 1e3)
}

/// The glb of a network and its surface.
pub fn glb(
    positions: &Positions,
    surface: Option<&Surfaced>,
) -> Result<Vec<u8>, crate::gltf_out::GltfError> {
    let mesh = surface.map(|s| s.mesh());
    crate::gltf_out::network_glb(
        &crate::gltf_out::network_curves(positions),
        &positions.nodes,
        mesh.as_ref(),
    )
}
