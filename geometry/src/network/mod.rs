//! Curve-network reconstruction: tagged curves → filtered frames → positions.
//!
//! - [`prefilter`](mod@prefilter): per-curve outlier removal, duplicates, uniform Gaussian resampling.
//! - [`mounting`]: the device's mounting offset (a roll and a pitch common to every frame in
//!   its own axes) estimated from the normals at the nodes, and turned back.
//! - [`closure`]: node tags the network's loops refuse (a mistyped or half-lost index) are
//!   detached from their node.
//! - [`regression`]: the frames regressed on SO(3)ᴺ over the whole network.
//! - [`curve_scale`]: a wheel's scale per curve (each pass read a little long or short),
//!   estimated from the loops and applied to the distances.
//! - [`poisson`]: positions of the whole network from its tangents, nodes shared; solved on
//!   the nodes by [`kron`] reduction (each run of samples between tags eliminated exactly).
//! - [`crease`]: the other face of each crease curve, from the curves at its nodes.
//!
//! [`Reconstructor::run`] runs them over a scan, leaving out (with a warning) what cannot be
//! used, and keeps the symbolic factorisations between runs.
//!
//! Above it, and unknown to it: [`join`], nodes tagged on one curve only joined to a curve
//! that passes them (issue 34). [`join::run_joined`] drives a [`Reconstructor`] pass by pass
//! (the joins' tags put into the scan, reconstructed with those tags free to slide,
//! [`Reconstructor::run_sliding`], then moved where the loops put them), so a settle's data
//! flows one way: scan → joins → reconstructor → network.

pub mod closure;
pub mod crease;
pub mod curve_scale;
pub mod join;
pub mod kron;
pub mod marginals;
pub mod mounting;
pub mod poisson;
pub mod prefilter;
pub mod regression;

use crate::curve::Curve;
use nalgebra::UnitQuaternion;
use poisson::{PoissonSolver, Positions};
use prefilter::{prefilter_with_kinks, PrefilterParams, UniformCurve};
use regression::{RegressionParams, RegressionReport, RegressionSolver};
use std::cell::RefCell;
use std::collections::HashMap;
use std::time::Instant;

/// Settings of the reconstruction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NetworkParams {
    pub prefilter: PrefilterParams,
    pub regression: RegressionParams,
    /// Skip the regression (pre-filter only), for comparisons.
    pub no_regression: bool,
    /// Skip the loop-closure test of the tags ([`closure`]), for comparisons.
    pub no_closure_check: bool,
    /// Do not estimate the device's mounting offset from the node normals ([`mounting`]).
    pub no_mounting: bool,
    /// Keep a segment the loops name a slip as measured ([`closure::Slip::lengthen`]).
    pub no_slip_repair: bool,
    /// What the loops must show to name a slip ([`closure::SlipTest`]: the device's).
    pub slips: closure::SlipTest,
    /// Live updates (issue 19): when > 0, a run after the first moves only the frames of the
    /// curves that changed since the last run and those within this many samples of the
    /// nodes they pass through ([`RegressionSolver::run_local`]); the others keep the last
    /// run's. Such a run also keeps the last run's mounting and yaw, and its loop-closure test
    /// tests the tags and segments of those curves only ([`closure::Scope::tested`], issue
    /// 51). The result is then provisional ([`NetworkReport::provisional`]): close to the
    /// whole network's, not equal to it. Default 0: the whole network every run.
    pub local_window: usize,
    /// The device's noise where the loops cannot tell it ([`marginals`]).
    pub noise: marginals::NoisePrior,
    /// The prior spread of each curve's distance scale, a fraction (a wheel's rolling radius
    /// changes from pass to pass): where set, the loops estimate a scale per curve before the
    /// positions are solved ([`curve_scale`]); `None`: the distances as measured.
    pub curve_scale_sigma: Option<f64>,
    /// Keep the distances as measured even where [`curve_scale_sigma`](Self::curve_scale_sigma)
    /// is set (the configuration's `estimate_curve_scales = false`).
    pub no_curve_scales: bool,
    /// Leave the nodes' uncertainty to [`Reconstructor::uncertainty`] (a live update publishes
    /// the curves first, issue 51): the network comes without it.
    pub defer_uncertainty: bool,
}

/// What a reconstruction did, for `report.json`.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct NetworkReport {
    pub curves_used: usize,
    pub curves_left_out: usize,
    pub samples: usize,
    pub components: usize,
    pub outliers_removed: usize,
    /// Tags detached from their node by the loop-closure test (each also a warning).
    pub tags_detached: usize,
    /// The device's mounting offset estimated from the normals at the nodes, and whether the
    /// frames were turned back by it ([`mounting`]); none where the nodes cannot tell it.
    pub mounting: Option<mounting::MountingEstimate>,
    /// The yaw of that offset about N, estimated from the loops before the closure test, and
    /// its remainder after it where the test moved a tag or lengthened a segment
    /// ([`mounting::estimate_yaw`]); a live update keeps the last full run's.
    pub mounting_yaw: Option<mounting::YawEstimate>,
    /// Largest angle between the normals of two curves at a shared node, degrees.
    pub max_node_normal_angle_deg: f64,
    /// Each curve's distance scale estimated from the loops and applied (`1 + s` times its
    /// measured distances), by scan index ([`curve_scale`]); empty where not estimated.
    pub curve_scales: std::collections::BTreeMap<usize, f64>,
    /// The regression's iterations and energies.
    pub regression: RegressionReport,
    /// The regression moved only the frames near what changed since the last run
    /// ([`NetworkParams::local_window`]), or the join passes stopped at
    /// [`join::LIVE_MAX_PASSES`]: a run with a window of 0 gives the exact network.
    pub provisional: bool,
    /// How each curve closes the network's loops (the loop-closure test's misfit, before the
    /// regression), with the tags that explain most of it marked; empty without loops.
    pub closure: Vec<closure::CurveMisfit>,
    /// The network's closure misfit ([`closure::ClosureReport::misfit_m`]), m.
    pub closure_misfit_m: Option<f64>,
    /// The noise the nodes' uncertainty rests on: the loops' against the device's prior
    /// ([`marginals::Noise`]).
    pub noise: marginals::Noise,
    /// Nodes tagged on one curve joined to another curve that passes them, and crossings
    /// nobody tagged joined under fresh nodes (issue 34; [`join::run_joined`]).
    pub joined: Vec<join::JoinReport>,
    /// Crossings nobody tagged, not joined (`join_untagged` off), for the operator to tag or
    /// refuse.
    pub proposed: Vec<join::Proposal>,
    /// Joins undone, and why.
    pub joins_refused: Vec<join::RefusedJoin>,
    /// Reconstructions the joins took beyond the first (0 when nothing was joined).
    pub join_passes: usize,
    pub timings_ms: Timings,
}

/// Wall time per stage, ms.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Timings {
    pub prefilter: f64,
    /// The loop-closure test of the tags and segments ([`closure`]).
    pub closure: f64,
    /// The regression on SO(3), with the mounting's and curves' scales' estimates around it.
    pub regression: f64,
    pub poisson: f64,
    /// The uncertainty of the nodes and points ([`marginals`]).
    pub uncertainty: f64,
    /// The joins' passes and tests (issue 34), beyond the first reconstruction.
    pub join: f64,
}

/// A problem the reconstruction met, naming the curve and node where it has them; its text
/// is its `Display`, its kind a stable [`code`](NetworkWarning::code).
#[derive(Debug, Clone, PartialEq)]
pub enum NetworkWarning {
    /// A curve that cannot be resampled is left out of the network.
    LeftOut(prefilter::PrefilterError),
    /// No curve could be used: nothing is reconstructed.
    NothingUsable,
    /// A tag the network's loops refuse, detached from its node (a mistyped index).
    TagDetached(closure::Detached),
    /// A tag the network's loops refuse with nothing else suggesting a wrong index: kept.
    TagRefused(closure::Refused),
    /// A segment the network's loops would lengthen: a slip (issue 49).
    SlipSuspected(closure::Slip),
    /// The Poisson system could not be solved.
    PoissonFailed(crate::sparse_llt::SolveError),
    /// The network falls apart into parts with no node in common.
    InParts { components: usize },
    /// A crease curve whose other face is unknown: surfaced as a smooth curve.
    CreaseUnknown(crease::CreaseUnknown),
    /// A join undone: its loops do not close, or the operator refused it.
    JoinRefused(join::RefusedJoin),
    /// The joins still moved after `passes` reconstructions ([`join::MAX_PASSES`], or
    /// [`join::LIVE_MAX_PASSES`] in a live update).
    JoinsUnsettled { moved_m: f64, passes: usize },
}

impl NetworkWarning {
    /// A stable name of the kind of problem (for machines reading `report.json`).
    pub fn code(&self) -> &'static str {
        match self {
            NetworkWarning::LeftOut(_) => "curve_left_out",
            NetworkWarning::NothingUsable => "nothing_reconstructed",
            NetworkWarning::TagDetached(_) => "tag_detached",
            NetworkWarning::TagRefused(_) => "tag_refused",
            NetworkWarning::SlipSuspected(_) => "slip_suspected",
            NetworkWarning::PoissonFailed(_) => "poisson_failed",
            NetworkWarning::InParts { .. } => "network_in_parts",
            NetworkWarning::CreaseUnknown(_) => "crease_other_face_unknown",
            NetworkWarning::JoinRefused(_) => "join_refused",
            NetworkWarning::JoinsUnsettled { .. } => "joins_unsettled",
        }
    }

    /// The curve it names.
    pub fn curve(&self) -> Option<usize> {
        match self {
            NetworkWarning::LeftOut(e) => Some(e.curve()),
            NetworkWarning::TagDetached(d) => Some(d.curve),
            NetworkWarning::TagRefused(r) => Some(r.curve),
            NetworkWarning::SlipSuspected(s) => Some(s.curve),
            NetworkWarning::CreaseUnknown(c) => Some(c.curve()),
            NetworkWarning::JoinRefused(r) => Some(r.curve),
            _ => None,
        }
    }

    /// The node it names.
    pub fn node(&self) -> Option<u32> {
        match self {
            NetworkWarning::TagDetached(d) => Some(d.node),
            NetworkWarning::TagRefused(r) => Some(r.node),
            NetworkWarning::JoinRefused(r) => Some(r.node),
            _ => None,
        }
    }
}

impl std::fmt::Display for NetworkWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NetworkWarning::LeftOut(e) => write!(f, "{e}; left out of the network"),
            NetworkWarning::NothingUsable => {
                f.write_str("no curve could be used: nothing reconstructed")
            }
            NetworkWarning::TagDetached(d) => d.fmt(f),
            NetworkWarning::TagRefused(r) => r.fmt(f),
            NetworkWarning::SlipSuspected(s) => s.fmt(f),
            NetworkWarning::PoissonFailed(e) => write!(f, "Poisson reconstruction failed: {e}"),
            NetworkWarning::InParts { components } => write!(
                f,
                "the network falls apart into {components} parts with no node in common: each is reconstructed on its own, their relative placement is arbitrary"
            ),
            NetworkWarning::CreaseUnknown(c) => c.fmt(f),
            NetworkWarning::JoinRefused(r) => write!(
                f,
                "node {} not joined to curve {} ({:.1} mm from it): {}",
                r.node,
                r.curve,
                r.distance_m * 1e3,
                r.reason
            ),
            NetworkWarning::JoinsUnsettled { moved_m, passes } => write!(
                f,
                "the joined nodes still moved {:.1} mm along their curves after {} reconstructions: kept where the last one put them",
                moved_m * 1e3,
                passes
            ),
        }
    }
}

/// Why nothing could be reconstructed: the warnings that say so (each curve left out and
/// why, or the failed solve), in order; or that the caller stopped the run
/// ([`Reconstructor::run_until`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Unreconstructed {
    pub warnings: Vec<NetworkWarning>,
    /// Stopped by the caller before the end: nothing is wrong with the scan.
    pub interrupted: bool,
}

impl Unreconstructed {
    /// The run the caller stopped.
    pub(crate) fn interrupted() -> Self {
        Unreconstructed {
            warnings: Vec::new(),
            interrupted: true,
        }
    }
}

impl std::fmt::Display for Unreconstructed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.interrupted {
            return f.write_str("stopped before the end");
        }
        if self.warnings.is_empty() {
            return f.write_str("no curve to reconstruct");
        }
        for (k, w) in self.warnings.iter().enumerate() {
            if k > 0 {
                f.write_str("; ")?;
            }
            w.fmt(f)?;
        }
        Ok(())
    }
}

/// What the Poisson solve and the loop test say of one sliding tag (a join's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Slide {
    /// Where the loops put the node along its curve from the tag, m (one Gauss–Newton step).
    pub(crate) sigma: f64,
    /// How the loops the tag closes fit beside the others.
    pub(crate) fit: Option<closure::LoopFit>,
}

/// The reconstruction of a scan.
#[derive(Debug, Clone)]
pub struct Network {
    pub positions: Positions,
    /// How far each node and point may be from the truth ([`marginals`]).
    pub uncertainty: marginals::Uncertainty,
    pub report: NetworkReport,
    pub warnings: Vec<NetworkWarning>,
}

/// Holds what is reused between reconstructions of a growing scan: the pre-filtered curves
/// (a curve is pre-filtered again only when it changed), the symbolic factorisations, and the
/// last regressed frames (for [`Reconstructor::run_warm`]).
#[derive(Debug, Default)]
pub struct Reconstructor {
    poisson: PoissonSolver,
    marginals: marginals::MarginalsSolver,
    regression: RegressionSolver,
    prefiltered: HashMap<usize, (CurveKey, Result<UniformCurve, prefilter::PrefilterError>)>,
    regressed: HashMap<usize, Vec<UnitQuaternion<f64>>>,
    /// The node ties of each curve the last regression saw (sample, node), after the closure
    /// test: a curve whose ties changed moves whole in a local run.
    regressed_nodes: HashMap<usize, Vec<(usize, u32)>>,
    /// The tags the last closure test moved: where a live update's test starts
    /// ([`closure::check_from`]).
    closure_moved: Vec<closure::Moved>,
    /// The mounting the last run estimated ([`mounting::estimate`]): a live update keeps it.
    mounting: Option<mounting::MountingEstimate>,
    /// The yaw the last run estimated from the loops ([`mounting::estimate_yaw`]): a live
    /// update keeps it, so that the frames it does not regress again stay turned alike.
    yaw: Option<mounting::YawEstimate>,
    /// Each curve's tags in the last loop test of the whole network, by scan index: a live
    /// update, which tests its new curves only, gives the others these.
    closure_tags: HashMap<usize, Vec<closure::TagMisfit>>,
    /// What a live update's loop test keeps between updates (its chords of each curve).
    closure_kept: closure::Kept,
    /// Each curve's distance scale the last full run estimated from the loops
    /// ([`curve_scale`]), by scan index: a live update keeps them.
    curve_scales: HashMap<usize, f64>,
    /// Curves pre-filtered by the last run (not taken from the cache).
    pub prefiltered_last: usize,
    /// The last run's curves as regressed: what its network's uncertainty is computed from
    /// ([`Reconstructor::uncertainty`]).
    last_uniform: Vec<UniformCurve>,
}

/// What identifies a curve's content for the pre-filter cache: a curve that gained samples,
/// tags or segment lengths (a late SEGMENT_LENGTH) is pre-filtered again.
#[derive(Debug, Clone, PartialEq)]
struct CurveKey {
    samples: usize,
    last: Option<(u64, u64)>,
    tags: Vec<(u32, u64, bool)>,
    segment_lengths: Vec<Option<u64>>,
    params: PrefilterParams,
    /// Its nodes a crease passes through (where it may kink).
    kink_nodes: Vec<u32>,
}

impl CurveKey {
    fn of(c: &Curve, p: &PrefilterParams, kink_nodes: Vec<u32>) -> Self {
        CurveKey {
            samples: c.samples.len(),
            last: c
                .samples
                .t
                .last()
                .zip(c.samples.d.last())
                .map(|(t, d)| (t.to_bits(), d.to_bits())),
            tags: c
                .tags
                .iter()
                .map(|t| (t.node, t.d.to_bits(), t.uncertain))
                .collect(),
            segment_lengths: c
                .segment_lengths
                .iter()
                .map(|l| l.map(f64::to_bits))
                .collect(),
            params: *p,
            kink_nodes,
        }
    }
}

impl Reconstructor {
    pub fn new() -> Self {
        Self::default()
    }

    /// Reconstructs the network of `curves` (a scan's accepted curves); when nothing can be
    /// reconstructed, the warnings that say why. The result depends only on `curves` and `p` (the caches change the time it takes, not the
    /// bits).
    pub fn run(&mut self, curves: &[Curve], p: &NetworkParams) -> Result<Network, Unreconstructed> {
        self.run_until(curves, p, &|| false)
    }

    /// As [`run`](Self::run), asking `stop` before each pass of the loop-closure test (a
    /// long session's from scratch puts back its lost digits one pass each): once it says
    /// yes, the run ends with nothing reconstructed ([`Unreconstructed`], `interrupted`). The
    /// caches keep what was done (the pre-filtered curves).
    pub fn run_until(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        stop: &dyn Fn() -> bool,
    ) -> Result<Network, Unreconstructed> {
        let mut net = self.run_bare_until(curves, p, stop)?;
        self.uncertainty_unless_deferred(&mut net, p);
        Ok(net)
    }

    /// As [`run_until`](Self::run_until), without the nodes' uncertainty: what the join passes
    /// run, the uncertainty left to the network they end with.
    pub(crate) fn run_bare_until(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        stop: &dyn Fn() -> bool,
    ) -> Result<Network, Unreconstructed> {
        self.run_inner(curves, p, false, &[], false, stop)
            .map(|(n, _)| n)
    }

    /// The uncertainty of the nodes and points of `net`, the network of this reconstructor's
    /// last run ([`marginals`]): into `net.uncertainty`, its points' `sigma_m` and
    /// `net.report.noise`. A network from another reconstructor, or made before its last run,
    /// is left without.
    pub fn uncertainty(&mut self, net: &mut Network, p: &NetworkParams) {
        let t0 = Instant::now();
        let same = self.last_uniform.len() == net.positions.curves.len()
            && self
                .last_uniform
                .iter()
                .zip(&net.positions.curves)
                .all(|(u, c)| u.index == c.index && u.q.len() == c.points.len());
        if !same {
            tracing::debug!("no uncertainty: the network is not the last run's");
            return;
        }
        net.uncertainty = match self
            .marginals
            .run(&self.last_uniform, &mut net.positions, &p.noise)
        {
            Ok(u) => u,
            Err(e) => {
                // The node Laplacian is the Poisson one's Schur complement: it factors when
                // that one did. Should it not, the positions stand without their σ.
                tracing::warn!("the uncertainty of the network could not be computed: {e}");
                marginals::Uncertainty::default()
            }
        };
        net.report.noise = net.uncertainty.noise;
        net.report.timings_ms.uncertainty = t0.elapsed().as_secs_f64() * 1e3;
    }

    /// [`uncertainty`](Self::uncertainty), unless `p` defers it to the caller
    /// ([`NetworkParams::defer_uncertainty`]).
    pub(crate) fn uncertainty_unless_deferred(&mut self, net: &mut Network, p: &NetworkParams) {
        if !p.defer_uncertainty {
            self.uncertainty(net, p);
        }
    }

    /// As [`run`](Self::run), with the regression warm-started from the previous run's
    /// frames (curves unchanged since): the optimum is the same, but not to the last bit.
    /// Measured on a growing scan it starts lower but takes as many iterations (Gauss–Newton
    /// needs about three either way), so the live worker uses [`run`](Self::run), whose
    /// result depends on the curves alone.
    pub fn run_warm(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
    ) -> Result<Network, Unreconstructed> {
        let (mut net, _) = self.run_inner(curves, p, true, &[], false, &|| false)?;
        self.uncertainty_unless_deferred(&mut net, p);
        Ok(net)
    }

    /// The reconstruction with the tags `slides` (`(scan index of the curve, node)`) free to
    /// slide along their curve: for each, the slide the Poisson solve gives it (m, one
    /// Gauss–Newton step towards where the loops put the node), `None` for a tag not found.
    pub fn run_sliding(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        slides: &[(usize, u32)],
    ) -> Result<(Network, Vec<Option<f64>>), Unreconstructed> {
        let (mut net, s) = self.run_inner(curves, p, false, slides, false, &|| false)?;
        self.uncertainty_unless_deferred(&mut net, p);
        Ok((net, s.iter().map(|x| x.map(|x| x.sigma)).collect()))
    }

    /// As [`run_sliding`](Self::run_sliding), with each tag's [`Slide`]: where the loops put
    /// it and how its loops fit (what the join passes above, [`join::run_joined`], iterate).
    /// The loop-closure test starts from the tags it moved in the last run (the pass
    /// before, or the run the passes started from: [`closure::check_from`]), so that a long
    /// session's lost digits are not put back one at a time again in every pass. Without the
    /// nodes' uncertainty ([`uncertainty`](Self::uncertainty)).
    pub(crate) fn run_slides(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        slides: &[(usize, u32)],
        stop: &dyn Fn() -> bool,
    ) -> Result<(Network, Vec<Option<Slide>>), Unreconstructed> {
        self.run_inner(curves, p, false, slides, true, stop)
    }

    /// The reconstruction, with the tags `slides` (`(scan index of the curve, node)`, issue
    /// 34's joins) free to slide along their curve in the Poisson solve: for each, where the
    /// loops put it and how its loops fit ([`Slide`]). The loop-closure test starts from the
    /// tags the last run moved in a live update ([`NetworkParams::local_window`]) and with
    /// `closure_from_last`, from the tags as typed otherwise.
    fn run_inner(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        warm: bool,
        slides: &[(usize, u32)],
        closure_from_last: bool,
        stop: &dyn Fn() -> bool,
    ) -> Result<(Network, Vec<Option<Slide>>), Unreconstructed> {
        let mut warnings = Vec::new();
        let t0 = Instant::now();
        let mut uniform = self.prefilter_all(curves, p, &mut warnings);
        let t1 = Instant::now();
        if uniform.is_empty() {
            if !curves.is_empty() {
                warnings.push(NetworkWarning::NothingUsable);
            }
            return Err(Unreconstructed {
                warnings,
                interrupted: false,
            });
        }
        // A live update (a local regression) keeps the last run's mounting, as its yaw below:
        // the frames it does not regress again were regressed under it (and its estimate
        // pairs every two frames at a node: a grid's poles, 2 450 pairs at 100 curves).
        let local = self.local(p);
        let mounting = if p.no_mounting {
            None
        } else if local {
            self.mounting
        } else {
            mounting::estimate(&uniform)
        };
        self.mounting = mounting;
        if let Some(est) = mounting.filter(|e| e.applied) {
            mounting::apply(&mut uniform, &est);
        }
        // The yaw about N, from the loops' misfit with the tags as typed, so that the closure
        // test sees the misfit the yaw leaves; a live update (a local regression) keeps the
        // last run's, so that the frames it does not regress again stay turned alike.
        if p.no_mounting {
            self.yaw = None;
        } else if !local {
            self.yaw = self.estimate_yaw(&uniform);
        }
        if let Some(est) = self.yaw.filter(|e| e.applied) {
            mounting::apply_yaw(&mut uniform, &est);
        }
        let joined: Vec<u32> = slides.iter().map(|x| x.1).collect();
        // A live update starts the closure test from the tags the last one moved, and so does
        // a join pass (from the pass before); a run that starts the passes (and so the settle
        // and a replay), from the tags as typed.
        let prior: &[closure::Moved] = if p.local_window > 0 || closure_from_last {
            &self.closure_moved
        } else {
            &[]
        };
        let from_prior = !prior.is_empty();
        // A live update tests the tags and segments of the curves it regresses whole (new, or
        // with their ties changed) and of those at the nodes of curves undone (issue 51).
        let tested = local.then(|| self.tested_in_update(&uniform, prior));
        // It keeps the chords of the curves it saw the same, and factorises its node Laplacian
        // as Poisson's, through Poisson's pattern: Poisson finds it kept when the curves'
        // lengths are the same after the regression.
        let kept = local.then(|| {
            let mut kept = std::mem::take(&mut self.closure_kept);
            kept.node_system = std::mem::take(self.poisson.node_pattern());
            RefCell::new(kept)
        });
        let scope = closure::Scope {
            prior,
            tested: tested.as_ref(),
            kept: kept.as_ref(),
        };
        let tc = Instant::now();
        let mut closure =
            closure_check(curves, &mut uniform, p, &joined, scope, stop, &mut warnings);
        let closure_ms = tc.elapsed().as_secs_f64() * 1e3;
        if let Some(kept) = kept {
            self.closure_kept = kept.into_inner();
            *self.poisson.node_pattern() = std::mem::take(&mut self.closure_kept.node_system);
        }
        if closure.interrupted {
            return Err(Unreconstructed::interrupted());
        }
        self.closure_moved = std::mem::take(&mut closure.moved);
        if let Some(tested) = &tested {
            // The other curves' tags as the last whole test found them (the view's marks).
            for m in closure
                .curves
                .iter_mut()
                .filter(|m| !tested.contains(&m.curve))
            {
                if let Some(tags) = self.closure_tags.get(&m.curve) {
                    m.tags.clone_from(tags);
                }
            }
        } else {
            self.closure_tags = closure
                .curves
                .iter()
                .map(|m| (m.curve, m.tags.clone()))
                .collect();
        }
        // Tags the closure test moved, or segments it lengthened, misfit the loops no more:
        // what they say of the yaw then is added.
        let changed = !closure.detached.is_empty() || closure.slips.iter().any(|s| s.lengthened);
        if !p.no_mounting && !local && changed {
            if let Some(more) = self.estimate_yaw(&uniform).filter(|e| e.applied) {
                mounting::apply_yaw(&mut uniform, &more);
                self.yaw = Some(mounting::YawEstimate {
                    yaw_deg: self.yaw.filter(|e| e.applied).map_or(0.0, |e| e.yaw_deg)
                        + more.yaw_deg,
                    ..more
                });
            }
        }
        let regression = self.regress(&mut uniform, p, warm);
        let t2 = Instant::now();
        let curve_scales = self.curve_scales(&mut uniform, p);
        // Each slide's curve (position) and the tag's position in its nodes.
        let at: Vec<Option<(usize, usize)>> = slides
            .iter()
            .map(|&(curve, node)| {
                let ci = uniform.iter().position(|u| u.index == curve)?;
                let tag = uniform[ci].nodes.iter().position(|x| x.1 == node)?;
                Some((ci, tag))
            })
            .collect();
        let found: Vec<(usize, usize)> = at.iter().flatten().copied().collect();
        let fits = if found.is_empty() {
            Vec::new()
        } else {
            closure::loop_test(&uniform, &found, local)
        };
        let samples: Vec<(usize, usize)> = found
            .iter()
            .map(|&(ci, tag)| (ci, uniform[ci].nodes[tag].0))
            .collect();
        let (mut positions, sigma) = match self.poisson.solve_sliding(&uniform, &samples) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!("Poisson reconstruction failed: {e}");
                warnings.push(NetworkWarning::PoissonFailed(e));
                return Err(Unreconstructed {
                    warnings,
                    interrupted: false,
                });
            }
        };
        warnings.extend(
            crease::other_faces(&mut positions)
                .into_iter()
                .map(NetworkWarning::CreaseUnknown),
        );
        let t3 = Instant::now();
        if positions.components > 1 {
            warnings.push(NetworkWarning::InParts {
                components: positions.components,
            });
        }
        let report = NetworkReport {
            curves_used: uniform.len(),
            curves_left_out: curves.len() - uniform.len(),
            samples: uniform.iter().map(|u| u.q.len()).sum(),
            components: positions.components,
            outliers_removed: uniform.iter().map(|u| u.outliers).sum(),
            tags_detached: closure.detached.len(),
            mounting,
            mounting_yaw: self.yaw,
            max_node_normal_angle_deg: max_node_normal_angle(&positions),
            // A live update's closure test, started from the last update's moves, may differ
            // from the one of a run from scratch: the settle runs that.
            provisional: regression.frames_moved < regression.frames
                || (p.local_window > 0 && from_prior),
            regression,
            closure_misfit_m: closure.misfit_m,
            curve_scales,
            closure: closure.curves,
            timings_ms: Timings {
                prefilter: (t1 - t0).as_secs_f64() * 1e3,
                closure: closure_ms,
                regression: (t2 - t1).as_secs_f64() * 1e3 - closure_ms,
                poisson: (t3 - t2).as_secs_f64() * 1e3,
                ..Default::default()
            },
            // The joins are the join passes' (join::run_joined).
            ..Default::default()
        };
        // The slides found, in order, back to the slides asked for.
        let mut solved = sigma
            .into_iter()
            .zip(fits)
            .map(|(sigma, fit)| Slide { sigma, fit });
        let slid = at.iter().map(|a| a.and_then(|_| solved.next())).collect();
        // Kept for the uncertainty of this network ([`Reconstructor::uncertainty`]).
        self.last_uniform = uniform;
        Ok((
            Network {
                positions,
                uncertainty: marginals::Uncertainty::default(),
                report,
                warnings,
            },
            slid,
        ))
    }

    /// The curves (scan indices) a live update's loop test tests ([`closure::Scope::tested`]):
    /// those whose tags are not the last run's (new curves; ties changed, once the tags the
    /// last test moved, `prior`, are put back as it left them), and those that pass a node of
    /// a curve the last run had and this one has not (undone: their loops changed).
    fn tested_in_update(
        &self,
        uniform: &[UniformCurve],
        prior: &[closure::Moved],
    ) -> std::collections::BTreeSet<usize> {
        let gone = self.nodes_of_curves_gone(uniform);
        let moved_to = |curve: usize, typed: u32, now: u32| {
            prior
                .iter()
                .any(|m| m.curve == curve && m.node == typed && m.detached.kept_as == now)
        };
        uniform
            .iter()
            .filter(|u| {
                let same = self.regressed_nodes.get(&u.index).is_some_and(|last| {
                    last.len() == u.nodes.len()
                        && last
                            .iter()
                            .zip(&u.nodes)
                            .all(|(l, n)| l.0 == n.0 && (l.1 == n.1 || moved_to(u.index, n.1, l.1)))
                });
                !same || u.nodes.iter().any(|n| gone.binary_search(&n.1).is_ok())
            })
            .map(|u| u.index)
            .collect()
    }

    /// The nodes of the curves the last run regressed that `uniform` has not (undone, or now
    /// left out): their ties went with them. Sorted, each once.
    fn nodes_of_curves_gone(&self, uniform: &[UniformCurve]) -> Vec<u32> {
        let in_use: std::collections::HashSet<usize> = uniform.iter().map(|u| u.index).collect();
        let mut gone: Vec<u32> = self
            .regressed_nodes
            .iter()
            .filter(|(k, _)| !in_use.contains(k))
            .flat_map(|(_, nodes)| nodes.iter().map(|x| x.1))
            .collect();
        gone.sort_unstable();
        gone.dedup();
        gone
    }

    /// Whether a run with `p` is a live update: a local regression
    /// ([`NetworkParams::local_window`]) after a first run. It keeps the last run's mounting
    /// and yaw, and tests only its new curves' tags.
    fn local(&self, p: &NetworkParams) -> bool {
        p.local_window > 0 && !self.regressed_nodes.is_empty()
    }

    /// Each curve's distance scale from the loops ([`curve_scale`]), where
    /// [`NetworkParams::curve_scale_sigma`] asks for it, applied to `uniform`: estimated by a
    /// full run, kept by a live update (a curve the last full run did not have keeps its
    /// distances). The scales applied, by scan index (none where not estimated).
    fn curve_scales(
        &mut self,
        uniform: &mut [UniformCurve],
        p: &NetworkParams,
    ) -> std::collections::BTreeMap<usize, f64> {
        let Some(sigma) = p.curve_scale_sigma.filter(|_| !p.no_curve_scales) else {
            self.curve_scales.clear();
            return Default::default();
        };
        if !self.local(p) {
            self.curve_scales.clear();
            match self.poisson.scale_form(uniform) {
                Ok(form) => {
                    let lengths: Vec<f64> = uniform.iter().map(|u| u.length()).collect();
                    if let Some(s) = curve_scale::estimate(&form, sigma, &lengths) {
                        self.curve_scales
                            .extend(uniform.iter().map(|u| u.index).zip(s.iter().copied()));
                    }
                }
                Err(e) => tracing::debug!("no curve scales: {e}"),
            }
        }
        let applied: std::collections::BTreeMap<usize, f64> = uniform
            .iter()
            .filter_map(|u| Some((u.index, *self.curve_scales.get(&u.index)?)))
            .collect();
        let scales: Vec<f64> = uniform
            .iter()
            .map(|u| applied.get(&u.index).copied().unwrap_or(0.0))
            .collect();
        curve_scale::apply(uniform, &scales);
        applied
    }

    /// The yaw about N of `uniform`'s frames, from the loops ([`mounting::estimate_yaw`]).
    fn estimate_yaw(&mut self, uniform: &[UniformCurve]) -> Option<mounting::YawEstimate> {
        match self.poisson.yaw_form(uniform) {
            Ok(form) => mounting::estimate_yaw(&form),
            Err(e) => {
                tracing::debug!("no yaw estimate: {e}");
                None
            }
        }
    }

    /// Every curve resampled ([`prefilter_with_kinks`]: curves may kink at the nodes a crease
    /// passes through, and where the device turned in place), from the cache where the curve
    /// and its kinks are unchanged; a curve that cannot be is left out (a warning). Forgets
    /// the curves no longer in `curves`.
    fn prefilter_all(
        &mut self,
        curves: &[Curve],
        p: &NetworkParams,
        warnings: &mut Vec<NetworkWarning>,
    ) -> Vec<UniformCurve> {
        let mut uniform: Vec<UniformCurve> = Vec::new();
        let live: std::collections::HashSet<usize> = curves.iter().map(|c| c.index).collect();
        self.prefiltered.retain(|k, _| live.contains(k));
        self.regressed.retain(|k, _| live.contains(k));
        self.prefiltered_last = 0;
        let crease_nodes: std::collections::BTreeSet<u32> = curves
            .iter()
            .filter(|c| c.kind == crate::curve::CurveKind::Crease)
            .flat_map(|c| c.tags.iter().map(|t| t.node))
            .collect();
        for c in curves {
            let mut kink_nodes: Vec<u32> = c
                .tags
                .iter()
                .map(|t| t.node)
                .filter(|n| crease_nodes.contains(n))
                .collect();
            kink_nodes.sort_unstable();
            kink_nodes.dedup();
            let key = CurveKey::of(c, &p.prefilter, kink_nodes);
            let fresh = !matches!(self.prefiltered.get(&c.index), Some((k, _)) if *k == key);
            if fresh {
                self.prefiltered_last += 1;
                self.regressed.remove(&c.index);
                let u = prefilter_with_kinks(c, &p.prefilter, &key.kink_nodes);
                self.prefiltered.insert(c.index, (key, u));
            }
            match &self.prefiltered[&c.index].1 {
                Ok(u) => uniform.push(u.clone()),
                Err(e) => warnings.push(NetworkWarning::LeftOut(e.clone())),
            }
        }
        uniform
    }

    /// The regression on SO(3) of the resampled curves: local around the changed ties when a
    /// regressed network is kept ([`NetworkParams::local_window`]), warm-started from the
    /// kept frames (`warm`), or from scratch; the frames kept for the next run.
    fn regress(
        &mut self,
        uniform: &mut [UniformCurve],
        p: &NetworkParams,
        warm: bool,
    ) -> RegressionReport {
        let changed_nodes = self.nodes_of_curves_gone(uniform);
        let local = self.local(p);
        let regression = if p.no_regression {
            RegressionReport::default()
        } else if local {
            let previous: Vec<Option<&[UnitQuaternion<f64>]>> = uniform
                .iter()
                .map(|u| {
                    let same_ties = self.regressed_nodes.get(&u.index) == Some(&u.nodes);
                    self.regressed
                        .get(&u.index)
                        .filter(|_| same_ties)
                        .map(|q| q.as_slice())
                })
                .collect();
            self.regression.run_local(
                uniform,
                &p.regression,
                &previous,
                p.local_window,
                &changed_nodes,
            )
        } else if warm {
            let init: Vec<Vec<UnitQuaternion<f64>>> = uniform
                .iter()
                .map(|u| self.regressed.get(&u.index).cloned().unwrap_or_default())
                .collect();
            let init: Vec<Option<&[UnitQuaternion<f64>]>> =
                init.iter().map(|v| Some(v.as_slice())).collect();
            self.regression.run_from(uniform, &p.regression, &init)
        } else {
            self.regression.run(uniform, &p.regression)
        };
        self.regressed_nodes.clear();
        if !p.no_regression {
            for u in uniform.iter() {
                self.regressed.insert(u.index, u.q.clone());
                self.regressed_nodes.insert(u.index, u.nodes.clone());
            }
        }
        regression
    }
}

/// The loop-closure test of the tags and slips ([`closure::check`]; tags the operator marked
/// uncertain go first; no slip at the nodes `joined`), unless
/// [`NetworkParams::no_closure_check`]; its detached and refused tags and its slips are
/// warnings.
fn closure_check(
    curves: &[Curve],
    uniform: &mut [UniformCurve],
    p: &NetworkParams,
    joined: &[u32],
    scope: closure::Scope,
    stop: &dyn Fn() -> bool,
    warnings: &mut Vec<NetworkWarning>,
) -> closure::ClosureReport {
    let closure = if p.no_closure_check {
        closure::ClosureReport::default()
    } else {
        let uncertain: std::collections::BTreeSet<(usize, usize)> = curves
            .iter()
            .flat_map(|c| {
                c.tags
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| t.uncertain)
                    .map(|(k, _)| (c.index, k))
            })
            .collect();
        closure::check_from(
            uniform,
            |c, k| uncertain.contains(&(c, k)),
            &p.slips,
            !p.no_slip_repair,
            joined,
            scope,
            stop,
        )
    };
    warnings.extend(
        closure
            .detached
            .iter()
            .cloned()
            .map(NetworkWarning::TagDetached),
    );
    warnings.extend(
        closure
            .refused
            .iter()
            .cloned()
            .map(NetworkWarning::TagRefused),
    );
    warnings.extend(
        closure
            .slips
            .iter()
            .cloned()
            .map(NetworkWarning::SlipSuspected),
    );
    closure
}

/// Largest angle between normals of different curves at a shared node, degrees. At a node a
/// crease passes through, the frames on its two faces are not compared: only pairs within
/// [`regression::CREASE_PAIR_DEG`] count there (those the regression ties).
pub fn max_node_normal_angle(p: &Positions) -> f64 {
    // Every tag's (node, on a crease, normal), grouped by node (a sort, not a map of lists:
    // this runs at every live update over every tag).
    let mut at: Vec<(u32, bool, nalgebra::Vector3<f64>)> = p
        .curves
        .iter()
        .flat_map(|c| {
            let crease = c.kind == crate::curve::CurveKind::Crease;
            c.nodes.iter().map(move |&(i, n)| (n, crease, c.normals[i]))
        })
        .collect();
    at.sort_by_key(|e| e.0);
    let mut worst: f64 = 0.0;
    for group in at.chunk_by(|a, b| a.0 == b.0) {
        let crease = group.iter().any(|e| e.1);
        for a in 0..group.len() {
            for b in a + 1..group.len() {
                let angle = group[a].2.angle(&group[b].2).to_degrees();
                if !crease || angle < regression::CREASE_PAIR_DEG {
                    worst = worst.max(angle);
                }
            }
        }
    }
    worst
}
