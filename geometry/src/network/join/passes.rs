//! The join passes (issue 34, [`run_joined`]): a layer above the reconstructor, which knows
//! nothing of joins. Each pass puts the joins' tags into the scan, has the
//! [`Reconstructor`] reconstruct it with those tags free to slide, and reads back where the
//! loops put each tag and how they fit: which joins are in, where their tags go next, which
//! are refused and why.

use super::parts::{apply_moves, placement};
use super::{
    apply_joins, find_crossings, find_joins_within, Join, JoinReport, JoinSettings, RefusedJoin,
    LIVE_MAX_PASSES, MAX_PASSES, MISFIT_FLOOR_M, REFUSE_RATIO, SETTLED_M, SLIDE_MARGIN_M,
};
use crate::curve::{Curve, ANONYMOUS_NODE_BASE};
use crate::network::closure::LoopFit;
use crate::network::poisson::Positions;
use crate::network::{
    Network, NetworkParams, NetworkWarning, Reconstructor, Slide, Unreconstructed,
};
use std::collections::HashMap;
use std::time::Instant;

/// As [`Reconstructor::run`], with nodes joined after the fact (issue 34, [`super`]): a node
/// tagged on one curve only joins a curve that passes it ([`super::find_joins`]), and with
/// [`JoinSettings::untagged`] two curves that cross with no node there share a fresh one
/// ([`find_crossings`]); the others are proposed.
///
/// The joins settle in passes, one reconstruction each: every joined tag slides along its
/// curve where the Poisson solve puts it
/// ([`crate::network::poisson::PoissonSolver::solve_sliding`], the slides solved together;
/// at most the join distance a pass, halved each time its slide turns back; a tag that closes
/// no loop stays put), until none moves more than [`SETTLED_M`] (at most [`MAX_PASSES`], or
/// [`LIVE_MAX_PASSES`] in a live update); joins found in the moved network join in the next
/// pass. Once settled, the join whose loops misfit worst is refused when beyond
/// [`REFUSE_RATIO`] × the network's other loops, and the passes go on without it. A refused
/// join is never proposed again, so the passes end. Without any join the result is
/// [`Reconstructor::run`]'s, to the bit.
pub fn run_joined(
    r: &mut Reconstructor,
    curves: &[Curve],
    p: &NetworkParams,
    js: &JoinSettings,
) -> Result<Network, Unreconstructed> {
    run_joined_until(r, curves, p, js, &|| false)
}

/// As [`run_joined`], asking `stop` before each pass of the loop-closure test and each join
/// pass ([`Reconstructor::run_until`]): once it says yes, nothing is reconstructed
/// ([`Unreconstructed`], `interrupted`). What the live worker settles with: a curve that comes
/// in meanwhile goes first.
pub fn run_joined_until(
    r: &mut Reconstructor,
    curves: &[Curve],
    p: &NetworkParams,
    js: &JoinSettings,
    stop: &dyn Fn() -> bool,
) -> Result<Network, Unreconstructed> {
    // Every run without the nodes' uncertainty: it is computed once, for the network the
    // passes end with (unless `p` defers it to the caller).
    let mut net = r.run_bare_until(curves, p, stop)?;
    if !js.enabled() {
        r.uncertainty_unless_deferred(&mut net, p);
        return Ok(net);
    }
    let t0 = Instant::now();
    // The reach of the joins: at least the set distance, and beyond the network's noise.
    let lonely_reach = js
        .params
        .distance_m
        .max(js.params.noise_factor * net.report.closure_misfit_m.unwrap_or(0.0));
    let mut state = Passes::new(curves, js, lonely_reach);
    let max_passes = if p.local_window > 0 {
        LIVE_MAX_PASSES
    } else {
        MAX_PASSES
    };
    let mut moved = 0.0_f64;
    loop {
        let fresh = state.fresh(&net.positions);
        let mut refusing = false;
        if fresh.is_empty() && moved <= SETTLED_M {
            // Settled: the join whose loops misfit worst, if beyond the others' noise.
            if !state.refuse_worst() {
                break;
            }
            refusing = true;
        } else if state.passes >= max_passes {
            net.warnings.push(NetworkWarning::JoinsUnsettled {
                moved_m: moved,
                passes: state.passes,
            });
            // Cut short in a live update: provisional, whatever the regression did, so that
            // the worker settles it.
            if max_passes < MAX_PASSES {
                net.report.provisional = true;
            }
            break;
        }
        state.joins.extend(fresh);
        state.passes += 1;
        if stop() {
            return Err(Unreconstructed::interrupted());
        }
        if state.joins.is_empty() {
            net = r.run_bare_until(curves, p, stop)?;
            break;
        }
        let (work, slides) = state.joined_scan(curves);
        match r.run_slides(&work, p, &slides, stop) {
            Ok((n, slid)) => {
                net = n;
                moved = state.slide(&work, &slid);
                tracing::debug!(
                    pass = state.passes,
                    joins = state.joins.len(),
                    moved_mm = moved * 1e3,
                    placement_ms = state.placement_ms,
                    "join pass"
                );
                if refusing {
                    moved = moved.max(1.0);
                }
            }
            Err(e) if e.interrupted => return Err(e),
            // The joined network cannot be reconstructed: keep the last that could.
            Err(e) => {
                state.drop_all(&format!(
                    "the joined network could not be reconstructed: {e}"
                ));
                break;
            }
        }
    }
    let (joined, refused) = state.finish(curves);
    net.report.joined = joined;
    net.report.proposed = find_crossings(&net.positions, &js.params)
        .into_iter()
        .filter(|pr| !js.refuses(pr.curves[0], pr.curves[1]))
        .collect();
    net.warnings
        .extend(refused.iter().cloned().map(NetworkWarning::JoinRefused));
    net.report.joins_refused = refused;
    net.report.join_passes = state.passes;
    net.report.timings_ms.join = t0.elapsed().as_secs_f64() * 1e3;
    r.uncertainty_unless_deferred(&mut net, p);
    Ok(net)
}

/// A join in the passes.
#[derive(Debug, Clone)]
pub(crate) struct Pending {
    join: Join,
    /// A crossing nobody tagged, under a fresh node.
    untagged: bool,
    /// How its loops fit in the last reconstruction.
    fit: Option<LoopFit>,
    /// The distance its tag had in the last reconstruction, m.
    used_d: f64,
    /// The most its tag moves in a pass, m: the join distance, halved each time its slide
    /// turns back.
    step_max: f64,
    /// Its tag's last move, m.
    last_step: f64,
}

impl Pending {
    fn new(join: Join, untagged: bool, step_max: f64) -> Self {
        Pending {
            used_d: join.d,
            join,
            untagged,
            fit: None,
            step_max,
            last_step: 0.0,
        }
    }
}

/// The state of the passes over one scan.
pub(crate) struct Passes<'a> {
    js: &'a JoinSettings,
    /// How far a node one curve tags reaches, m.
    lonely_reach: f64,
    /// The next fresh node (above every tagged one).
    fresh_node: u32,
    pub(crate) joins: Vec<Pending>,
    refused: Vec<RefusedJoin>,
    /// (node, curve) refused, and pairs of curves whose untagged crossing was refused.
    refused_at: Vec<(u32, usize)>,
    refused_pairs: Vec<(usize, usize)>,
    /// Reconstructions made with joins.
    pub(crate) passes: usize,
    /// The parts' placement found on the first network in parts, and its partition: the
    /// passes after it move the same parts the same way while the partition stands.
    placement: Option<(Vec<Vec<usize>>, Vec<super::parts::Move>)>,
    /// The time the placements took so far, ms.
    placement_ms: f64,
}

impl<'a> Passes<'a> {
    pub(crate) fn new(curves: &[Curve], js: &'a JoinSettings, lonely_reach: f64) -> Self {
        let fresh_node = curves
            .iter()
            .flat_map(|c| c.tags.iter().map(|t| t.node))
            .filter(|&n| n < ANONYMOUS_NODE_BASE)
            .max()
            .map_or(0, |n| n + 1);
        Passes {
            js,
            lonely_reach,
            fresh_node,
            joins: Vec::new(),
            refused: Vec::new(),
            refused_at: Vec::new(),
            refused_pairs: Vec::new(),
            passes: 0,
            placement: None,
            placement_ms: 0.0,
        }
    }

    /// The joins found in `net` that are not in, nor refused (a pair of curves the operator
    /// refused is reported so, once).
    pub(crate) fn fresh(&mut self, net: &Positions) -> Vec<Pending> {
        let js = self.js;
        // A network in parts: each part moved to where its lonely nodes fit first, as far as
        // they reach. The search is the costly part of a pass (every part against the placed
        // ones), and a pass changes the parts' shapes by its slides only: it is made once per
        // partition.
        let placed;
        let seen = if net.components > 1 {
            let mut moved = net.clone();
            let partition = super::parts::partition(net);
            match &self.placement {
                Some((known, moves)) if *known == partition => apply_moves(&mut moved, moves),
                _ => {
                    let reach = super::JoinParams {
                        distance_m: self.lonely_reach,
                        ..js.params
                    };
                    let t0 = Instant::now();
                    let moves = placement(&mut moved, &reach);
                    self.placement_ms += t0.elapsed().as_secs_f64() * 1e3;
                    self.placement = Some((partition, moves));
                }
            }
            placed = moved;
            &placed
        } else {
            net
        };
        let mut fresh = Vec::new();
        for j in find_joins_within(seen, &js.params, self.lonely_reach) {
            if self
                .joins
                .iter()
                .any(|x| x.join.node == j.node && x.join.curve == j.curve)
                || self.refused_at.contains(&(j.node, j.curve))
            {
                continue;
            }
            if js.refuses(j.home, j.curve) {
                self.refused_at.push((j.node, j.curve));
                self.refused.push(RefusedJoin::configured(&j));
                continue;
            }
            fresh.push(Pending::new(j, false, js.params.distance_m));
        }
        if js.untagged {
            for pr in find_crossings(seen, &js.params) {
                let [a, b] = pr.curves;
                if js.refuses(a, b) || self.refused_pairs.contains(&(a, b)) {
                    continue;
                }
                for (k, (curve, home)) in [(a, b), (b, a)].into_iter().enumerate() {
                    let j = Join {
                        node: self.fresh_node,
                        curve,
                        home,
                        d: pr.d[k],
                        arc_length_m: 0.0,
                        distance_m: pr.distance_m,
                        normal_deg: pr.normal_deg,
                    };
                    fresh.push(Pending::new(j, true, js.params.distance_m));
                }
                self.fresh_node += 1;
            }
        }
        fresh
    }

    /// Refuses the join whose loops misfit most beyond [`REFUSE_RATIO`] × the network's
    /// other loops, if there is one.
    pub(crate) fn refuse_worst(&mut self) -> bool {
        let worst = self
            .joins
            .iter()
            .enumerate()
            .filter_map(|(k, x)| {
                let f = x.fit?;
                let limit = REFUSE_RATIO * f.others_m?.max(MISFIT_FLOOR_M);
                (f.own_m > limit).then_some((k, f.own_m / limit))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|x| x.0);
        let Some(k) = worst else { return false };
        let out = self.joins[k].clone();
        let f = out.fit.expect("judged by its fit");
        self.refused.push(RefusedJoin {
            node: out.join.node,
            curve: out.join.curve,
            distance_m: out.join.distance_m,
            misfit_before_m: f.others_m,
            misfit_after_m: Some(f.own_m),
            reason: format!(
                "the loops it closes miss by {:.1} mm, more than {} times the network's other loops ({:.1} mm): the curves pass there without crossing",
                f.own_m * 1e3,
                REFUSE_RATIO,
                f.others_m.unwrap_or(0.0) * 1e3
            ),
        });
        self.refused_at.push((out.join.node, out.join.curve));
        if out.untagged {
            let (a, b) = (
                out.join.curve.min(out.join.home),
                out.join.curve.max(out.join.home),
            );
            self.refused_pairs.push((a, b));
        }
        // An untagged crossing's fresh node goes with both its tags.
        self.joins.retain(|x| {
            x.join.node != out.join.node || (!out.untagged && x.join.curve != out.join.curve)
        });
        true
    }

    /// The scan with the joins' tags put in, and the slides of those tags.
    pub(crate) fn joined_scan(&self, curves: &[Curve]) -> (Vec<Curve>, Vec<(usize, u32)>) {
        let mut work = curves.to_vec();
        let now: Vec<Join> = self.joins.iter().map(|x| x.join.clone()).collect();
        apply_joins(&mut work, &now);
        let slides = now.iter().map(|j| (j.curve, j.node)).collect();
        (work, slides)
    }

    /// Each join's tag moved where its slide puts it (within its segment, at most the join
    /// distance a pass), a join whose tag the reconstruction lost refused; the most a tag
    /// moved, m.
    pub(crate) fn slide(&mut self, work: &[Curve], slid: &[Option<Slide>]) -> f64 {
        let mut moved = 0.0_f64;
        let mut lost = Vec::new();
        for (k, s) in slid.iter().enumerate() {
            let x = &mut self.joins[k];
            x.used_d = x.join.d;
            let Some(s) = s else {
                lost.push(k);
                continue;
            };
            x.fit = s.fit;
            // A tag that closes no loop is where nothing tells it to move (its part hangs
            // from it, free to slide with it): it stays where it was found.
            if s.fit.is_none() {
                continue;
            }
            let (lo, hi) = segment_around(work, &x.join);
            let margin = SLIDE_MARGIN_M.min(0.25 * (hi - lo));
            // A slide that turns back halves the tag's steps from then on: two joins of one
            // loop overshoot each other by the most a pass allows, back and forth, where the
            // solve's step is larger than the distance left.
            if s.sigma * x.last_step < 0.0 {
                x.step_max *= 0.5;
            }
            let step = s.sigma.clamp(-x.step_max, x.step_max);
            let d = (x.join.d + step).clamp(lo + margin, (hi - margin).max(lo + margin));
            moved = moved.max((d - x.join.d).abs());
            x.last_step = d - x.join.d;
            x.join.d = d;
        }
        for &k in lost.iter().rev() {
            let x = self.joins.remove(k);
            self.refused_at.push((x.join.node, x.join.curve));
            self.refused.push(RefusedJoin {
                reason: "the loop-closure test detached the joined tag".into(),
                ..RefusedJoin::configured(&x.join)
            });
            moved = moved.max(1.0);
        }
        moved
    }

    /// Every join refused with `reason`.
    pub(crate) fn drop_all(&mut self, reason: &str) {
        for x in self.joins.drain(..) {
            self.refused.push(RefusedJoin {
                reason: reason.to_owned(),
                ..RefusedJoin::configured(&x.join)
            });
        }
    }

    /// The joins kept (as the last reconstruction saw them) and those refused.
    pub(crate) fn finish(&mut self, curves: &[Curve]) -> (Vec<JoinReport>, Vec<RefusedJoin>) {
        let at_d0: HashMap<usize, f64> = curves
            .iter()
            .filter_map(|c| Some((c.index, c.tags.first()?.d)))
            .collect();
        let joined = self
            .joins
            .iter()
            .map(|x| JoinReport {
                node: x.join.node,
                curve: x.join.curve,
                arc_length_m: x.used_d - at_d0.get(&x.join.curve).copied().unwrap_or(0.0),
                distance_m: x.join.distance_m,
                normal_deg: x.join.normal_deg,
                misfit_before_m: x.fit.and_then(|f| f.others_m),
                misfit_after_m: x.fit.map(|f| f.own_m),
                untagged: x.untagged,
            })
            .collect();
        (joined, std::mem::take(&mut self.refused))
    }
}

/// The distances of the tags either side of `j`'s tag on its curve in `work`.
fn segment_around(work: &[Curve], j: &Join) -> (f64, f64) {
    work.iter()
        .find(|c| c.index == j.curve)
        .and_then(|c| {
            let t = c.tags.iter().position(|t| t.node == j.node)?;
            Some((c.tags.get(t.checked_sub(1)?)?.d, c.tags.get(t + 1)?.d))
        })
        .unwrap_or((j.d, j.d))
}
