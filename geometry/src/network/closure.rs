//! Loop closure of the tags: finds node tags that the network's loops refuse.
//!
//! A node index typed wrong, or one whose leading digit was lost on the link ("29" arriving as
//! "9"), ties a curve to a node it never touched. The Poisson reconstruction then has to
//! stretch whole curves to meet it, and the error spreads over the network (a lost digit on
//! one tag of a 9-curve network gave 3.2 % of the diagonal instead of 0.3 %). Such a tag is
//! visible in the misfit of the network's loops, so before the regression every tag is tested
//! and the worst offender, if it is clearly an outlier *and* something else points to a wrong
//! index (packets were lost while it was typed, or the curve passes the same node twice), is
//! *detached*: its curve keeps the tag as an anonymous node (its segmentation and segment
//! lengths are kept) but no longer joins the node. Repeated until no such tag stands out.
//! A refused tag without a second sign is only reported: a heading disturbed along one curve
//! (a magnet) refuses its loops just as much, and detaching a right tag loses a constraint.
//! A curve that would have to be pulled further than [`FAR`] of the network's size to meet
//! its node is such a sign: no drift does that.
//!
//! Where the device stood is another ([`LAND`]): let go of its node, a curve whose index was
//! typed wrong lands on the node it passed, and the tag is put on that node instead of an
//! anonymous one. It also tells which of two tags the loops blame alike is wrong: both ends of
//! a curve of one segment (freeing either frees the segment), the two tags at a node only two
//! curves hold; only the wrong one lands on another node (issue 49). Where both land on one,
//! the only one typed while packets were lost whose landing node's number holds the digits
//! received (`7` for 17: [`digits_lost`]) is the wrong one: the link lost a digit of it.
//!
//! ## The test
//! Each segment `s` of a curve (between two consecutive tags, nodes `a → b`) integrates its
//! tangents to a chord `d_s = Σ_j h_j (T_j + T_{j+1})/2`. Eliminating the samples inside the
//! segments from the Poisson energy (exactly: a chain of edges of weight `1/h_j²` is one edge
//! of weight `c_s = 1/Σ_j h_j²`) leaves a scalar graph Laplacian over the nodes:
//! `E(x) = Σ_s c_s |x_b − x_a − d_s|²`. Detaching the tag at node `v` of a curve adds a free
//! offset `δ` to that curve's end(s) at `v`; the energy then drops by exactly
//! `|g|² / σ` with `g = ∂E/∂δ / 2 = Σ ± c_s e_s` at the optimum and
//! `σ = Σ c_s − uᵀ L⁻¹ u` (the Schur complement of `δ`; `u` couples `δ` to the nodes), one
//! sparse solve per tag with the Laplacian factorised once. A tag is detached when its drop
//! is more than [`SHARE`] of the whole energy *and* more than [`RATIO`] times the energy per
//! degree of freedom left in the other loops (a 3-dof χ² at that ratio is far beyond noise).

use super::prefilter::UniformCurve;
use crate::curve::ANONYMOUS_NODE_BASE;
use crate::selected_inverse::SelectedInverse;
use crate::sparse_llt::{CachedPattern, InverseColumn, SpdFactor, SpdPattern};
use nalgebra::Vector3;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Share of the network's misfit energy a single tag must explain to be detached.
pub const SHARE: f64 = 0.5;
/// Its energy drop against the mean energy per remaining degree of freedom.
pub const RATIO: f64 = 50.0;
/// A refused tag whose curve would have to be pulled further than this share of the
/// network's size (the nodes' bounding-box diagonal) to meet its node is a wrong index: the
/// second sign detaching needs (issue 49). Measured (BENCHMARKS.md "Trust"): refused tags of
/// planted wrong nodes are 24–58 % of the size off; the most a drift pulled a refused tag on
/// any other capture, of the validation set or our simulator's, is 10.5 % (a magnet on the
/// torus).
pub const FAR: f64 = 0.15;

/// A refused tag whose curve, let go of its node, lands this close to another node (a share
/// of how far it had to be pulled) was typed for the node it lands on: where the loops cannot
/// tell which of two tags is wrong (they explain the same), this says; and the tag is put on
/// that node (issue 49). Measured (BENCHMARKS.md "Trust"): planted wrong nodes land within
/// 0.17 of their offset of the node meant; the right tags that explain as much, 0.57 or more
/// from any node.
pub const LAND: f64 = 0.3;
/// Of tags the loops blame alike, the one whose curve lands this many times closer to another
/// node than any other's is the wrong one ([`LAND`]). Measured: the wrong tags 10 times closer
/// or more.
pub const LAND_MARGIN: f64 = 4.0;

/// At most this many tags are detached, or [`MAX_DETACHED_SHARE`] of the tags if more (a
/// network that needs more has a worse problem).
pub const MAX_DETACHED: usize = 4;
/// The share of a network's tags that may be detached: a long session's link loses digits at
/// a rate, so its wrong indices grow with its tags (the 100-curve grid, 9 000 tags: 39 digits
/// lost, each a wrong index).
pub const MAX_DETACHED_SHARE: f64 = 0.02;

/// A refused tag whose misfit another tag explains to this fraction is not located (see
/// [`detach_outlier_tags`]).
pub const LOCATED: f64 = 0.99;

/// Two segments' lengths explain the same misfit when the correlation of their estimates
/// (the loops' Hessian in the two lengths, the nodes eliminated) is at least this: segments
/// in line on one chain, whose stretching moves the network alike. Two that explain as much
/// but less alike (perpendicular segments: two skids of one loop, issue 52's `roof-loop`)
/// are two slips, the larger named first.
pub const ALIKE: f64 = 0.9;

/// A tag is *marked* for the operator (the live view's "rescan here", [`TagMisfit::marked`])
/// when it explains this share of the network's misfit energy…
pub const MARK_SHARE: f64 = 0.25;
/// …and this many times the energy per degree of freedom left in the other loops (milder
/// than the test for detaching: it only points at where to look)…
pub const MARK_RATIO: f64 = 10.0;
/// …and the curve would have to be pulled at least this far at the tag to meet its node, m
/// (below it, nothing a rescan would improve).
pub const MARK_OFFSET_M: f64 = 0.005;

/// A tag detached from its node.
#[derive(Debug, Clone, PartialEq)]
pub struct Detached {
    /// Scan index of the curve.
    pub curve: usize,
    /// Position of the tag in the curve's tag list (0 = first).
    pub tag: usize,
    /// The node it was typed as.
    pub node: u32,
    /// The node the tag now has: a fresh anonymous node that joins no other curve, or
    /// (`retagged`) the node its curve lands on once let go ([`LAND`]).
    pub kept_as: u32,
    /// Whether the tag was put on the node its curve lands on rather than left anonymous.
    pub retagged: bool,
    /// How far the curve's end(s) at the tag had to be pulled to meet the node, m.
    pub offset_m: f64,
    /// Share of the network's misfit energy it explained.
    pub share: f64,
}

impl std::fmt::Display for Detached {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "curve {}, node {} (tag {} of the curve): the network's loops do not close through this tag (the curve would have to be pulled {:.0} mm to meet the node; {:.0} % of the network's misfit); probably a mistyped index or a digit lost on the link",
            self.curve,
            self.node,
            self.tag + 1,
            self.offset_m * 1e3,
            self.share * 100.0,
        )?;
        if self.retagged {
            write!(
                f,
                ": let go, the curve meets node {} there, so the tag is put on node {} (was it meant?)",
                self.kept_as, self.kept_as
            )
        } else {
            write!(
                f,
                ": the tag is kept as anonymous node {} that joins no other curve",
                self.kept_as
            )
        }
    }
}

/// A segment whose loops close if it is longer than measured: a wheel that slipped over it
/// (its distance read short), or a phone's segment length short (issue 49).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Slip {
    /// Scan index of the curve.
    pub curve: usize,
    /// Position of the segment's first tag in the curve's tags (the segment runs to the next).
    pub tag: usize,
    /// Its nodes, first to last.
    pub nodes: (u32, u32),
    /// How much of its true length the measurement missed, by the loops: `κ / (1 + κ)` for
    /// the segment `1 + κ` times as long as measured.
    pub short_fraction: f64,
    /// Its length as measured (the chord of its frames), m.
    pub chord_m: f64,
    /// Share of the network's misfit energy it explains.
    pub share: f64,
    /// The segment was lengthened by the loops' estimate before the regression and Poisson
    /// ([`Slip::lengthen`]).
    pub lengthened: bool,
}

impl Slip {
    /// Lengthens the slipped segment of its curve in `curves` by the loops' estimate (`1 + κ`,
    /// its samples' steps and distances alike; those after it moved on by as much): what the
    /// wheel missed given back. Whether the segment was found.
    pub fn lengthen(&self, curves: &mut [UniformCurve]) -> bool {
        let scale = 1.0 / (1.0 - self.short_fraction);
        if !(scale.is_finite() && scale > 1.0) {
            return false;
        }
        curves
            .iter_mut()
            .find(|c| c.index == self.curve)
            .is_some_and(|c| scale_segment(c, self.tag, scale))
    }
}

/// Scales segment `seg` of `c` (from tag `seg` to the next) by `scale`: its step and its
/// samples' distances, those after it moved on by as much. Whether the segment was found.
fn scale_segment(c: &mut UniformCurve, seg: usize, scale: f64) -> bool {
    let (Some(&(a, _)), Some(&(b, _))) = (c.nodes.get(seg), c.nodes.get(seg + 1)) else {
        return false;
    };
    if b <= a || b >= c.d.len() {
        return false;
    }
    c.h[seg] *= scale;
    let d0 = c.d[a];
    let before = c.d[b];
    for x in &mut c.d[a + 1..=b] {
        *x = d0 + (*x - d0) * scale;
    }
    let moved = c.d[b] - before;
    for x in &mut c.d[b + 1..] {
        *x += moved;
    }
    true
}

impl std::fmt::Display for Slip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "curve {}, segment from node {} to node {} (tags {} to {}): the network's loops close if it is {:.0} % longer than measured ({:.0} mm; {:.0} % of the network's misfit): the wheel probably slipped (a phone: its segment length short); {}rescan the curve",
            self.curve,
            self.nodes.0,
            self.nodes.1,
            self.tag + 1,
            self.tag + 2,
            100.0 * self.short_fraction / (1.0 - self.short_fraction).max(1e-9),
            self.chord_m * self.short_fraction / (1.0 - self.short_fraction).max(1e-9) * 1e3,
            self.share * 100.0,
            if self.lengthened {
                "lengthened by as much meanwhile; "
            } else {
                ""
            }
        )
    }
}

/// A slip is named when lengthening its segment explains at least this share of what freeing
/// the best tag would (a tag frees three directions, a length one: close to it, the simpler
/// explanation wins)…
pub const SLIP_VS_TAG: f64 = 0.8;
/// …and its segment reads between these fractions of its true length short (a wheel slipping
/// over a stretch reads a few % to tens of % short).
pub const SLIP_SHORT: (f64, f64) = (0.03, 0.5);

/// How much of the loops' misfit a segment must explain to be named a slip ([`Slip`]), and
/// how many are looked for (each lengthened before the next is looked for).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlipTest {
    /// Share of the network's misfit energy the segment's length explains…
    pub share: f64,
    /// …and its energy drop against the mean energy per remaining degree of freedom.
    pub ratio: f64,
    /// …and at least this share of what freeing the best tag would ([`SLIP_VS_TAG`]),
    pub vs_tag: f64,
    /// …and its segment reads between these fractions of its true length short
    /// ([`SLIP_SHORT`]).
    pub short: (f64, f64),
    /// At most this many slips are named.
    pub max: usize,
    /// A slip at either end of a tag the loops refuse, whose curve lands on no other node, is
    /// lengthened rather than the tag detached (a wheel: it slips routinely).
    pub before_detach: bool,
    /// A milder showing (`share`, `ratio`, `vs_tag` and the least fraction short, as above)
    /// is named, once no slip of this test is left, but not lengthened: for the operator to
    /// rescan.
    pub named_from: Option<Milder>,
}

/// The milder showing of a slip that [`SlipTest::named_from`] names without lengthening it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Milder {
    pub share: f64,
    pub ratio: f64,
    pub vs_tag: f64,
    pub short_min: f64,
}

impl SlipTest {
    /// As a refused tag ([`SHARE`], [`RATIO`]): a device whose segments read long as often as
    /// short (a phone's lengths, fitted from its stands and accelerometer), where a short one
    /// is no sign of its own.
    pub const STRICT: SlipTest = SlipTest {
        share: SHARE,
        ratio: RATIO,
        vs_tag: SLIP_VS_TAG,
        short: SLIP_SHORT,
        max: 1,
        before_detach: false,
        named_from: None,
    };

    /// A phone's: [`STRICT`](Self::STRICT), and a fifth of the misfit at 10× the rest per
    /// degree of freedom, 0.6 of the best tag and 6 % short named but not lengthened
    /// ([`SlipTest::named_from`]): lengthening at that showing gave back most planted slips
    /// but made sound segments of two phone captures 7 and 10 % long (BENCHMARKS.md "Trust",
    /// a phone's slips named on a milder showing).
    pub const PHONE: SlipTest = SlipTest {
        named_from: Some(Milder {
            share: 0.2,
            ratio: 10.0,
            vs_tag: 0.6,
            short_min: 0.06,
        }),
        ..SlipTest::STRICT
    };

    /// A wheel's (the Morphorider): it reads only short (it slips, it never turns on its own),
    /// so a segment the loops would lengthen is a sign in itself, and a scan may hold several.
    /// Named from a tenth of the misfit at 5× the rest per degree of freedom, 0.6 of the best
    /// tag's explanation, and 5 % short (below it lies what the loops' orientation misfit,
    /// taken for a length, reads: 3–7 % where it named a sound segment). Measured
    /// (BENCHMARKS.md "Trust", slips), on the 207 Morphorider captures of the validation set
    /// and of our simulator (planted faults, the field profile's own skids): of the 78
    /// segments named, 74 read truly short by 5–17 % (the loops' estimate within 2 points);
    /// the 4 others are one segment of the relief (field profile, seeds 1–2), lengthened
    /// 6–7 % for 0.1 %. The strict test named 12, all true.
    pub const WHEEL: SlipTest = SlipTest {
        share: 0.1,
        ratio: 5.0,
        vs_tag: 0.6,
        short: (0.05, SLIP_SHORT.1),
        max: 3,
        before_detach: true,
        named_from: None,
    };

    /// The test of its milder showing ([`SlipTest::named_from`]), if any.
    fn milder(&self) -> Option<SlipTest> {
        self.named_from.map(|m| SlipTest {
            share: m.share,
            ratio: m.ratio,
            vs_tag: m.vs_tag,
            short: (m.short_min, self.short.1),
            named_from: None,
            ..*self
        })
    }
}

impl Default for SlipTest {
    fn default() -> Self {
        SlipTest::STRICT
    }
}

struct Segment {
    curve: usize,
    /// Tag positions (in the curve's tag list) at both ends.
    tags: (usize, usize),
    a: usize,
    b: usize,
    c: f64,
    d: Vector3<f64>,
}

/// A tag's energy drop when detached.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    curve: usize,
    tag: usize,
    drop: f64,
    offset: f64,
    /// For a tag that stands out ([`Drops::refuses`]), or that was typed while packets were
    /// lost and stands out of the noise ([`Drops::one_of_many`]): where its curve's end lands
    /// once the tag lets go of its node, the nearest other node there and how far from it, m.
    lands: Option<(u32, f64)>,
}

/// A segment's energy drop when its length is free: `(index into the segments, drop, κ)`.
#[derive(Debug, Clone, Copy)]
struct Stretch {
    seg: usize,
    drop: f64,
    kappa: f64,
    /// The loops' curvature in the length (the Schur complement of `kappa`).
    sigma: f64,
}

/// The network's misfit energy, its loops' degrees of freedom, every tag's drop, and every
/// segment's residual.
struct Drops {
    /// Every segment's drop with its length free ([`Slip`]).
    stretches: Vec<Stretch>,
    /// The segments (indices in `segs`) whose length explains as much as the best stretch's
    /// ([`LOCATED`]) and the same misfit ([`ALIKE`]): which of them slipped, the loops
    /// cannot tell.
    alike_best: Vec<usize>,
    /// The segments the drops are of (the stretches index them).
    segs: Vec<Segment>,
    energy: f64,
    dof: f64,
    /// Mean stiffness of the segments, 1/m² (to read an energy as a length).
    mean_c: f64,
    tags: Vec<Candidate>,
    /// Per segment: its curve (position in the slice), `|e_s|` (m) and `c_s |e_s|²`.
    segments: Vec<(usize, f64, f64)>,
    /// The bounding-box diagonal of the nodes where the loops put them, m.
    size: f64,
}

/// Whether an energy drop `drop` explains `share` of the network's misfit `energy` and
/// `ratio` times the misfit per degree of freedom (`dof`) left without it.
fn explains(drop: f64, energy: f64, dof: f64, share: f64, ratio: f64) -> bool {
    let per_dof = (energy - drop).max(0.0) / dof;
    drop > share * energy && drop > ratio * per_dof
}

impl Drops {
    /// Whether `c` explains `share` of the energy and `ratio` times the energy per degree of
    /// freedom left ([`explains`]).
    fn stands_out(&self, c: &Candidate, share: f64, ratio: f64) -> bool {
        explains(c.drop, self.energy, self.dof, share, ratio)
    }

    /// Whether the curve would have to be pulled further than [`FAR`] of the network's size
    /// to meet the node: no drift of the device does that; a wrong index does.
    fn far(&self, c: &Candidate) -> bool {
        c.offset > FAR * self.size
    }

    /// The slip the loops name, if any ([`Slip`]): the stretch that explains most, when it
    /// stands out as a refused tag would, close to the best tag's explanation
    /// ([`SLIP_VS_TAG`]), no other stretch explaining as much ([`LOCATED`]) of the same misfit
    /// ([`ALIKE`]), and short by a plausible fraction ([`SLIP_SHORT`]).
    fn slip(&self, curves: &[UniformCurve], test: &SlipTest, joined: &[u32]) -> Option<Slip> {
        let best = self
            .stretches
            .iter()
            .max_by(|a, b| a.drop.total_cmp(&b.drop))?;
        let per_dof = (self.energy - best.drop).max(0.0) / self.dof;
        let refuses = explains(best.drop, self.energy, self.dof, test.share, test.ratio);
        let best_tag = self.tags.iter().map(|c| c.drop).fold(0.0, f64::max);
        let located = self.alike_best.is_empty();
        let short = best.kappa / (1.0 + best.kappa);
        tracing::debug!(
            curve = curves[self.segs[best.seg].curve].index,
            tag = self.segs[best.seg].tags.0,
            share = best.drop / self.energy,
            per_dof = best.drop / per_dof.max(f64::MIN_POSITIVE),
            vs_tag = best.drop / best_tag.max(f64::MIN_POSITIVE),
            located,
            short,
            "closure: the segment that explains most"
        );
        if !(refuses
            && located
            && best.drop >= test.vs_tag * best_tag
            && (test.short.0..=test.short.1).contains(&short))
        {
            return None;
        }
        let s = &self.segs[best.seg];
        let (tag, c) = (s.tags.0, &curves[s.curve]);
        let ends = (
            c.nodes[tag].1,
            c.nodes.get(tag + 1).map_or(c.nodes[tag].1, |x| x.1),
        );
        if joined.contains(&ends.0) || joined.contains(&ends.1) {
            // A join's place along its curve is free: the misfit there is the join's to
            // explain (a wrong one misfits), not a length's.
            return None;
        }
        Some(Slip {
            curve: c.index,
            tag,
            nodes: ends,
            short_fraction: short,
            chord_m: s.d.norm(),
            share: best.drop / self.energy,
            lengthened: false,
        })
    }

    /// The tag that explains most of the misfit among those the loops refuse and locate.
    fn worst(&self) -> Option<&Candidate> {
        self.tags
            .iter()
            .filter(|c| self.refuses(c) && self.located(c))
            .max_by(|a, b| a.drop.total_cmp(&b.drop))
    }

    /// Whether `c` passes the test (see the module docs).
    fn refuses(&self, c: &Candidate) -> bool {
        self.stands_out(c, SHARE, RATIO)
    }

    /// Whether `c` is one of several wrong tags: it stands out of the noise ([`RATIO`]) but
    /// shares the misfit with others, so no share says it; its curve, let go, lands on another
    /// node ([`LAND`]). Asked only of tags typed while packets were lost (a digit lost on a
    /// long session's link: `110` typed, `11` received).
    fn one_of_many(&self, c: &Candidate) -> bool {
        self.stands_out(c, 0.0, RATIO) && self.lands(c)
    }

    /// Whether no other tag explains the misfit as well as `c`: on a single loop (a closed
    /// curve alone, early in a live session) every tag does, and the misfit is the loop's
    /// drift, not any one tag's.
    ///
    /// Where other tags explain as much (the two ends of a curve of one segment, the two tags
    /// of a node that only two curves hold), the one whose curve lands on another node once
    /// let go ([`Drops::lands`]) is located, if it lands [`LAND_MARGIN`] times closer than
    /// any of them: the device was there.
    fn located(&self, c: &Candidate) -> bool {
        let mut rivals = self
            .tags
            .iter()
            .filter(|o| !std::ptr::eq(*o, c) && o.drop >= LOCATED * c.drop)
            .peekable();
        rivals.peek().is_none()
            || (self.lands(c) && rivals.all(|o| land_ratio(o) > LAND_MARGIN * land_ratio(c)))
    }

    /// Whether `c`'s curve, let go of its node, lands on another node: within [`LAND`] of
    /// how far it had to be pulled. The index typed was probably that node's.
    fn lands(&self, c: &Candidate) -> bool {
        land_ratio(c) <= LAND
    }
}

/// How close `c`'s curve lands to another node once let go, as a share of how far it had to
/// be pulled (infinite where it was not looked at).
fn land_ratio(c: &Candidate) -> f64 {
    c.lands.map_or(f64::INFINITY, |(_, r)| r / c.offset)
}

/// A live update's loop test finds the columns of the inverse at its curves' nodes up to
/// this many whatever the network's size (a twentieth of its nodes beyond).
const COLUMNS_MIN: usize = 64;

/// Entries of the inverse of a node Laplacian at a few nodes: a live update's loop test at
/// the nodes of its curves (issue 51), where a selected inversion of the whole network's
/// would cost more than the update. Each node's column of `L⁻¹ P` lies on its path up the
/// elimination tree ([`SpdFactor::inverse_column`]), and an entry between two nodes is a
/// sparse dot product of their columns.
#[derive(Default)]
struct Columns {
    paths: std::collections::HashMap<usize, InverseColumn>,
}

impl Columns {
    /// The columns of `nodes` not found yet.
    fn add(&mut self, f: &SpdFactor, nodes: impl Iterator<Item = usize>) {
        for i in nodes {
            if let std::collections::hash_map::Entry::Vacant(e) = self.paths.entry(i) {
                if let Some(c) = f.inverse_column(i) {
                    e.insert(c);
                }
            }
        }
    }

    /// Entry (i, j) of the inverse (NaN where a column was not found, a row out of range:
    /// what it enters is then left out, as a σ that is not a number is).
    fn get(&self, i: usize, j: usize) -> f64 {
        match (self.paths.get(&i), self.paths.get(&j)) {
            (Some(a), Some(b)) => SpdFactor::inverse_entry(a, b),
            _ => f64::NAN,
        }
    }
}

/// Each segment's chord (the frames' tangents integrated between its tags) and resistance
/// (`Σ h²` of its edges, or with `kron` their weights' reciprocals summed: the series
/// resistance of its run in Poisson's node system, to the bit), segment by segment.
fn chords(c: &UniformCurve, kron: bool) -> Vec<(Vector3<f64>, f64)> {
    let steps: Vec<f64> = c.edge_steps().collect();
    c.nodes
        .windows(2)
        .map(|w| {
            let (ia, ib) = (w[0].0, w[1].0);
            let mut d = Vector3::zeros();
            let mut r = 0.0;
            let mut t = c.q[ia] * Vector3::x();
            for (j, &h) in steps.iter().enumerate().take(ib).skip(ia) {
                let next = c.q[j + 1] * Vector3::x();
                d += (t + next) * (0.5 * h);
                t = next;
                r += if kron { (1.0 / (h * h)).recip() } else { h * h };
            }
            (d, r)
        })
        .collect()
}

/// What a live update's loop test shares with Poisson and keeps from one update to the next
/// (issue 51; [`Scope::kept`]).
#[derive(Debug, Default)]
pub struct Kept {
    /// The pattern of Poisson's node system, its last numeric factorisation kept: the test's
    /// node Laplacian is then Poisson's to the bit (its segments' conductances and gauges)
    /// and factorised through it, so that Poisson, on the same curves, does not factorise it
    /// again. The test's figures differ from a run without it in their last bits only.
    pub node_system: CachedPattern,
    /// Each curve's chords ([`chords`], `kron`), by scan index, with the frames, tags and
    /// steps they were found from: a curve found again the same is not integrated again.
    chords: std::collections::HashMap<usize, CurveChords>,
}

#[derive(Debug)]
struct CurveChords {
    q: Vec<nalgebra::UnitQuaternion<f64>>,
    at: Vec<usize>,
    h: Vec<f64>,
    chords: Vec<(Vector3<f64>, f64)>,
}

impl Kept {
    /// The chords of `c` ([`chords`] with `kron`): kept, or found and kept.
    fn chords(&mut self, c: &UniformCurve) -> &[(Vector3<f64>, f64)] {
        let same = |k: &CurveChords| {
            k.q == c.q && k.h == c.h && k.at.iter().copied().eq(c.nodes.iter().map(|n| n.0))
        };
        if !self.chords.get(&c.index).is_some_and(same) {
            self.chords.insert(
                c.index,
                CurveChords {
                    q: c.q.clone(),
                    at: c.nodes.iter().map(|n| n.0).collect(),
                    h: c.h.clone(),
                    chords: chords(c, true),
                },
            );
        }
        &self.chords[&c.index].chords
    }

    /// Forgets the chords of curves not in `curves` (undone).
    fn keep_only(&mut self, curves: &[UniformCurve]) {
        let present: std::collections::HashSet<usize> = curves.iter().map(|c| c.index).collect();
        self.chords.retain(|index, _| present.contains(index));
    }
}

/// The segments at each tag of the curves (`(segment, the tag is its end b?)`, at most two:
/// the segments before and after it), flat by curve position then tag.
struct AtTags {
    /// Each curve's first slot.
    start: Vec<usize>,
    slots: Vec<([(usize, bool); 2], u8)>,
}

impl AtTags {
    fn of(curves: &[UniformCurve], segs: &[Segment]) -> AtTags {
        let mut start = Vec::with_capacity(curves.len() + 1);
        start.push(0);
        for c in curves {
            start.push(start.last().copied().unwrap_or(0) + c.nodes.len());
        }
        let mut slots = vec![([(0, false); 2], 0u8); start[curves.len()]];
        for (si, s) in segs.iter().enumerate() {
            for (tag, is_b) in [(s.tags.0, false), (s.tags.1, true)] {
                let (list, len) = &mut slots[start[s.curve] + tag];
                list[usize::from(*len)] = (si, is_b);
                *len += 1;
            }
        }
        AtTags { start, slots }
    }

    fn get(&self, ci: usize, tag: usize) -> &[(usize, bool)] {
        match (self.start.get(ci), self.start.get(ci + 1)) {
            (Some(&first), Some(&end)) if first + tag < end => {
                let (list, len) = &self.slots[first + tag];
                &list[..usize::from(*len)]
            }
            _ => &[],
        }
    }

    /// `(curve position, tag, its segments)` of every tag with a segment, in order.
    fn iter(&self) -> impl Iterator<Item = (usize, usize, &[(usize, bool)])> + '_ {
        self.start.windows(2).enumerate().flat_map(move |(ci, w)| {
            (0..w[1] - w[0]).filter_map(move |tag| {
                let (list, len) = &self.slots[w[0] + tag];
                (*len > 0).then(|| (ci, tag, &list[..usize::from(*len)]))
            })
        })
    }
}

/// What a restricted loop test tests ([`drops`]): the tags and segments of some curves (by
/// position in the slice), and some tags by themselves (`(curve position, tag)`).
#[derive(Debug, Clone, Copy)]
struct Subset<'a> {
    curves: &'a [bool],
    tags: &'a [(usize, usize)],
}

impl Subset<'_> {
    fn has_tag(&self, ci: usize, tag: usize) -> bool {
        self.curves[ci] || self.tags.contains(&(ci, tag))
    }
}

/// The loop test of every tag and segment of `curves` (`tested`: only of those it says, and
/// of the tags that share a node with one of theirs that stands out; see [`Scope::tested`]).
fn drops(
    curves: &[UniformCurve],
    uncertain: &dyn Fn(usize, usize) -> bool,
    tested: Option<Subset>,
    kept: Option<&RefCell<Kept>>,
) -> Option<Drops> {
    let mut var: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    let mut ids = Vec::new();
    for c in curves {
        for &(_, n) in &c.nodes {
            let k = var.len();
            var.entry(n).or_insert_with(|| {
                ids.push(n);
                k
            });
        }
    }
    let n = var.len();
    let mut segs = Vec::new();
    // A live update keeps the chords of the curves it saw the same, and its resistances are
    // Poisson's (`Kept::node_system`).
    let mut kept_state = kept.map(|k| k.borrow_mut());
    if let Some(k) = kept_state.as_deref_mut() {
        k.keep_only(curves);
    }
    for (ci, c) in curves.iter().enumerate() {
        let found;
        let of_curve: &[(Vector3<f64>, f64)] = match kept_state.as_deref_mut() {
            Some(k) => k.chords(c),
            None => {
                found = chords(c, false);
                &found
            }
        };
        for (k, &(d, r)) in of_curve.iter().enumerate() {
            let (na, nb) = (c.nodes[k].1, c.nodes[k + 1].1);
            if r > 0.0 && r.is_finite() && d.iter().all(|x| x.is_finite()) {
                segs.push(Segment {
                    curve: ci,
                    tags: (k, k + 1),
                    a: var[&na],
                    b: var[&nb],
                    c: 1.0 / r,
                    d,
                });
            }
        }
    }
    if n < 2 || segs.is_empty() {
        return None;
    }
    // Components and gauges.
    let mut sets = crate::union_find::UnionFind::new(n);
    let links = segs.iter().filter(|s| sets.union(s.a, s.b)).count();
    // Independent loops: E − V + C, with C = V − links.
    let loops = segs.len() - links;
    if loops == 0 {
        return None; // a tree of segments: nothing to check against
    }
    let mean_c = segs.iter().map(|s| s.c).sum::<f64>() / segs.len() as f64;
    let mut entries: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
    let mut vals = vec![0.0; n];
    let mut rhs = vec![[0.0; 3]; n];
    for s in &segs {
        if s.a == s.b {
            continue;
        }
        vals[s.a] += s.c;
        vals[s.b] += s.c;
        entries.push((s.a.max(s.b), s.a.min(s.b)));
        vals.push(-s.c);
        for (d, v) in s.d.iter().enumerate() {
            rhs[s.b][d] += s.c * v;
            rhs[s.a][d] -= s.c * v;
        }
    }
    // Each component's gauge (any weight fixes the same solution): a live update's is
    // Poisson's, so that the matrix is its node system's.
    let gauge = if kept.is_some() {
        super::poisson::gauge_weight(curves)
    } else {
        mean_c
    };
    for root in sets.roots() {
        vals[root] += gauge;
    }
    let at = AtTags::of(curves, &segs);
    // The columns of the curves tested cost a path up the elimination tree per node they
    // pass: where that is more than a twentieth of the network's nodes (a curve undone, whose
    // neighbours are all tested), the selected inversion of the whole is the cheaper, and
    // every tag is tested.
    let tested = tested.filter(|t| {
        let mut at_nodes: Vec<usize> = segs
            .iter()
            .filter(|s| t.curves[s.curve])
            .flat_map(|s| [s.a, s.b])
            .collect();
        for &(ci, tag) in t.tags {
            let list = at.get(ci, tag);
            at_nodes.extend(list.iter().flat_map(|&(si, _)| [segs[si].a, segs[si].b]));
        }
        at_nodes.sort_unstable();
        at_nodes.dedup();
        at_nodes.len() <= COLUMNS_MIN.max(n / 20)
    });
    // A live update factorises through the node system's pattern that Poisson uses next,
    // its numeric factorisation kept: the same matrix there is not factorised again.
    let f: Arc<SpdFactor> = match kept_state.as_deref_mut() {
        Some(k) => k
            .node_system
            .factor_kept(n, entries.clone(), &vals, true)
            .ok()?,
        None => Arc::new(SpdPattern::new(n, &entries).ok()?.factor(&vals).ok()?),
    };
    f.solve(&mut rhs);
    let x: Vec<Vector3<f64>> = rhs.iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect();
    let resid = |s: &Segment| x[s.b] - x[s.a] - s.d;
    let energy: f64 = segs.iter().map(|s| s.c * resid(s).norm_squared()).sum();
    if energy.is_nan() || energy <= 0.0 || energy.is_infinite() {
        return None;
    }
    let dof = (3 * loops).saturating_sub(3).max(1) as f64;
    // Each tag's coupling: δ moves the curve's end(s) at the tag: e_s gains +δ where the tag
    // is the end b, −δ where it is the end a.
    struct AtTag {
        ci: usize,
        tag: usize,
        g: Vector3<f64>,
        hdd: f64,
        u: BTreeMap<usize, f64>,
    }
    let prepare = |(ci, tag, list): (usize, usize, &[(usize, bool)])| {
        let mut g = Vector3::zeros();
        let mut hdd = 0.0;
        let mut u: BTreeMap<usize, f64> = BTreeMap::new();
        for &(si, is_b) in list {
            let s = &segs[si];
            let sign = if is_b { 1.0 } else { -1.0 };
            g += resid(s) * (sign * s.c);
            hdd += s.c;
            // Coupling of δ with the nodes in e_s = x_b − x_a − d: ∂e/∂δ = sign.
            *u.entry(s.b).or_default() += sign * s.c;
            *u.entry(s.a).or_default() -= sign * s.c;
        }
        AtTag { ci, tag, g, hdd, u }
    };
    // One tag's candidate from the inverse's entries `zij` between the nodes its coupling
    // touches.
    let candidate = |t: &AtTag, zij: &dyn Fn(usize, usize) -> f64| -> Option<Candidate> {
        let (ci, tag, g, hdd) = (t.ci, t.tag, t.g, t.hdd);
        let uy: f64 =
            t.u.iter()
                .map(|(&i, &ui)| t.u.iter().map(|(&j, &uj)| ui * uj * zij(i, j)).sum::<f64>())
                .sum();
        let sigma = hdd - uy;
        if sigma.is_nan() || sigma <= 1e-9 * hdd {
            return None; // detaching the tag frees nothing (the node holds only this curve)
        }
        let drop = g.norm_squared() / sigma;
        // Let go, the tag's end moves by δ = −g/σ off its node, and the nodes by −y δ
        // (y = L⁻¹u): it lands at x_v + (1 − y_v) δ. Only for the tags that stand out (a
        // solve and a pass over the nodes each).
        let lands = if explains(drop, energy, dof, SHARE, RATIO)
            || (uncertain(curves[ci].index, tag) && explains(drop, energy, dof, 0.0, RATIO))
        {
            let mut y = vec![[0.0]; n];
            for (&i, &ui) in &t.u {
                y[i][0] = ui;
            }
            f.solve(&mut y);
            // Not on a node of its own curve: one close along it is no other place. But a
            // curve's end tag may land on the node of its other end: a closed curve whose
            // closing index lost a digit (`1` received for 14, the curve's first node).
            let nodes = &curves[ci].nodes;
            let other_end = match tag {
                0 => nodes.last().map(|m| m.1),
                t if t + 1 == nodes.len() => nodes.first().map(|m| m.1),
                _ => None,
            };
            let own: Vec<usize> = nodes
                .iter()
                .filter(|m| Some(m.1) != other_end)
                .map(|m| var[&m.1])
                .collect();
            let v = var[&curves[ci].nodes[tag].1];
            let shift = g / sigma;
            let landing = x[v] - shift * (1.0 - y[v][0]);
            (0..n)
                .filter(|j| !own.contains(j))
                .map(|j| (ids[j], (x[j] + shift * y[j][0] - landing).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
        } else {
            None
        };
        Some(Candidate {
            curve: ci,
            tag,
            drop,
            offset: g.norm() / sigma,
            lands,
        })
    };
    // Each segment with its length free: e_s(κ) = x_b − x_a − (1 + κ) d_s; the drop is
    // (c d·e)² / σ, σ = c |d|² − uᵀ L⁻¹ u with u = ± c d at its nodes (the Schur complement
    // of κ), κ = c d·e / σ: uᵀ L⁻¹ u = c² |d|² r_ab, r_ab the resistance across the segment.
    let stretch = |si: usize, zij: &dyn Fn(usize, usize) -> f64| -> Option<Stretch> {
        let s = &segs[si];
        let dd = s.d.norm_squared();
        if s.a == s.b || dd <= 0.0 {
            return None;
        }
        let r_ab = zij(s.a, s.a) + zij(s.b, s.b) - 2.0 * zij(s.a, s.b);
        let sigma = s.c * dd - s.c * s.c * dd * r_ab;
        if sigma.is_nan() || sigma <= 1e-9 * s.c * dd {
            return None; // its length is not checked by any loop
        }
        let g = s.c * s.d.dot(&resid(s));
        Some(Stretch {
            seg: si,
            drop: g * g / sigma,
            kappa: g / sigma,
            sigma,
        })
    };
    let (tags, stretches) = match tested {
        None => {
            // The inverse's entries the tests need (σ of a tag: between the nodes its
            // coupling touches; of a stretch: across its segment), on the factor's pattern
            // with the pairs of a tag's nodes added as explicit zeros: one selected
            // inversion, not a solve per tag and per segment.
            let prepared: Vec<AtTag> = at.iter().map(prepare).collect();
            for t in &prepared {
                let nodes: Vec<usize> = t.u.keys().copied().collect();
                for (k, &i) in nodes.iter().enumerate() {
                    for &j in &nodes[..k] {
                        entries.push((i, j));
                        vals.push(0.0);
                    }
                }
            }
            let z = SelectedInverse::new(n, &entries, &vals).ok()?;
            let zij =
                |i: usize, j: usize| z.get(i, j).expect("on the pattern: an entry of the matrix");
            let tags: Vec<Candidate> = prepared.iter().filter_map(|t| candidate(t, &zij)).collect();
            let stretches: Vec<Stretch> =
                (0..segs.len()).filter_map(|si| stretch(si, &zij)).collect();
            (tags, stretches)
        }
        Some(tested) => {
            // A live update's test (issue 51): the tags and segments of the curves tested,
            // from the columns of the inverse at their nodes (a path each); then
            // the tags that share a node with one of theirs that is marked, refused or one of
            // many: the rivals [`Drops::located`] weighs it against (the tags of a node only
            // two curves hold explain alike).
            let mut columns = Columns::default();
            let chosen: Vec<AtTag> = at
                .iter()
                .filter(|&(ci, tag, _)| tested.has_tag(ci, tag))
                .map(prepare)
                .collect();
            let seg_list: Vec<usize> = (0..segs.len())
                .filter(|&si| tested.curves[segs[si].curve])
                .collect();
            columns.add(
                &f,
                chosen
                    .iter()
                    .flat_map(|t| t.u.keys().copied())
                    .chain(seg_list.iter().flat_map(|&si| [segs[si].a, segs[si].b])),
            );
            let mut tags: Vec<Candidate> = chosen
                .iter()
                .filter_map(|t| candidate(t, &|i, j| columns.get(i, j)))
                .collect();
            // Rivals are weighed only for a tag marked, refused or one of many.
            let loud: std::collections::BTreeSet<usize> = tags
                .iter()
                .filter(|c| {
                    explains(
                        c.drop,
                        energy,
                        dof,
                        MARK_SHARE.min(SHARE),
                        MARK_RATIO.min(RATIO),
                    ) || (uncertain(curves[c.curve].index, c.tag)
                        && explains(c.drop, energy, dof, 0.0, RATIO))
                })
                .map(|c| var[&curves[c.curve].nodes[c.tag].1])
                .collect();
            let mates: Vec<AtTag> = at
                .iter()
                .filter(|&(ci, tag, _)| {
                    !tested.has_tag(ci, tag) && loud.contains(&var[&curves[ci].nodes[tag].1])
                })
                .map(prepare)
                .collect();
            columns.add(&f, mates.iter().flat_map(|t| t.u.keys().copied()));
            tags.extend(
                mates
                    .iter()
                    .filter_map(|t| candidate(t, &|i, j| columns.get(i, j))),
            );
            tags.sort_by_key(|c| (c.curve, c.tag));
            let stretches = seg_list
                .into_iter()
                .filter_map(|si| stretch(si, &|i, j| columns.get(i, j)))
                .collect();
            (tags, stretches)
        }
    };
    // The best stretch's rivals, and how alike their lengths' effects are: the Hessian's
    // cross term `−u_sᵀ L⁻¹ u_t = −c_s c_t (d_s·d_t) w_sᵀ L⁻¹ w_t` (`w = e_a − e_b`), against
    // its diagonal `σ` (one solve, where a rival explains as much).
    let alike_best = match stretches.iter().max_by(|a, b| a.drop.total_cmp(&b.drop)) {
        Some(best) => {
            let rivals: Vec<&Stretch> = stretches
                .iter()
                .filter(|o| o.seg != best.seg && o.drop >= LOCATED * best.drop)
                .collect();
            if rivals.is_empty() {
                Vec::new()
            } else {
                let sb = &segs[best.seg];
                let mut y = vec![[0.0]; n];
                y[sb.a][0] += 1.0;
                y[sb.b][0] -= 1.0;
                f.solve(&mut y);
                rivals
                    .into_iter()
                    .filter(|o| {
                        let so = &segs[o.seg];
                        let cross = sb.c * so.c * sb.d.dot(&so.d) * (y[so.a][0] - y[so.b][0]);
                        let rho = cross / (best.sigma * o.sigma).sqrt();
                        // (Not a number: alike, the cautious reading.)
                        rho.is_nan() || rho.abs() >= ALIKE
                    })
                    .map(|o| o.seg)
                    .collect()
            }
        }
        None => Vec::new(),
    };
    let segments = segs
        .iter()
        .map(|s| {
            let e = resid(s).norm();
            (s.curve, e, s.c * e * e)
        })
        .collect();
    Some(Drops {
        stretches,
        alike_best,
        segs,
        size: crate::bbox_diagonal(&x),
        energy,
        mean_c,
        dof,
        tags,
        segments,
    })
}

/// How the loops a tag closes fit beside the network's other loops (issue 34's test of a
/// join): see [`loop_test`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopFit {
    /// The network's misfit without the tag: the root mean square, per degree of freedom of
    /// its other loops, of what a segment of the network's mean stiffness misses by, m;
    /// `None` when no other loop is left to compare with.
    pub others_m: Option<f64>,
    /// The same measure for the loops the tag closes alone (the energy it adds, over its 3
    /// degrees of freedom), m.
    pub own_m: f64,
}

/// For each of `tags` (`(curve position in curves, tag position in its nodes)`), how the
/// loops it closes fit beside the others ([`LoopFit`]); `None` for a tag that frees nothing
/// (its node held by its curve alone) or where the network has no loop. With `alone`, only
/// those tags are tested, by solves (a live update's join passes, issue 51), not every tag of
/// the network by a selected inversion: the same figures but for their last bits.
pub fn loop_test(
    curves: &[UniformCurve],
    tags: &[(usize, usize)],
    alone: bool,
) -> Vec<Option<LoopFit>> {
    let none = vec![false; curves.len()];
    let subset = alone.then_some(Subset {
        curves: &none,
        tags,
    });
    let Some(d) = drops(curves, &|_, _| false, subset, None) else {
        return vec![None; tags.len()];
    };
    let length = |energy_per_dof: f64| (energy_per_dof.max(0.0) / d.mean_c).sqrt();
    tags.iter()
        .map(|&(ci, tag)| {
            let c = d.tags.iter().find(|c| c.curve == ci && c.tag == tag)?;
            // `d.dof` counts the loops but one: those left when the tag is let go.
            let dof = d.dof;
            Some(LoopFit {
                others_m: (dof >= 3.0).then(|| length((d.energy - c.drop) / dof)),
                own_m: length(c.drop / 3.0),
            })
        })
        .collect()
}

/// Whether tag `tag` of `c` repeats a node the curve passes elsewhere (not the closing pair
/// of a closed curve): a curve that meets itself is rare, a misread index is not.
fn repeats_in_curve(c: &UniformCurve, tag: usize) -> bool {
    let n = c.nodes[tag].1;
    let last = c.nodes.len() - 1;
    c.nodes
        .iter()
        .enumerate()
        .any(|(k, &(_, m))| k != tag && m == n && !(k.min(tag) == 0 && k.max(tag) == last))
}

/// What the loop-closure test found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClosureReport {
    /// Tags detached, in order.
    pub detached: Vec<Detached>,
    /// Tags the loops refuse but with no other sign of a wrong index (kept: the misfit may
    /// be the data's, e.g. a heading disturbed along the whole curve).
    pub refused: Vec<Refused>,
    /// A segment the loops would lengthen ([`Slip`]), once the tags are detached.
    pub slips: Vec<Slip>,
    /// How each curve closes the network's loops once the tags are detached (empty when the
    /// network has no loop), in the order of the curves.
    pub curves: Vec<CurveMisfit>,
    /// The network's closure misfit: the root mean square, per degree of freedom of its
    /// loops, of what a segment of the network's mean stiffness misses by, m (the measure of
    /// [`LoopFit`]); `None` without loops.
    pub misfit_m: Option<f64>,
    /// The tags whose node the test changed, as [`check_from`] finds them again.
    pub moved: Vec<Moved>,
    /// Stopped by the caller ([`check_from`]'s `stop`) before the test ended.
    pub interrupted: bool,
}

/// How one curve closes the network's loops: what the operator needs to know to decide what
/// to rescan.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CurveMisfit {
    /// Scan index of the curve.
    pub curve: usize,
    /// The most by which one of its segments (between two consecutive tags), integrated from
    /// its frames, misses its two nodes where the network's loops put them, m.
    pub misfit_m: f64,
    /// Share of the network's misfit energy in its segments.
    pub share: f64,
    /// Its tags, in order (a tag on a node no other curve holds frees nothing and is left
    /// out; a detached tag is listed with the node it was typed as).
    pub tags: Vec<TagMisfit>,
}

/// One tag's part in the network's misfit.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct TagMisfit {
    /// Position in the curve's tag list (0 = first).
    pub tag: usize,
    pub node: u32,
    /// How far the curve would have to be pulled at this tag to meet the node, m.
    pub offset_m: f64,
    /// Share of the network's misfit energy that letting go of the tag removes.
    pub share: f64,
    /// One of the network's worst tags: it explains [`MARK_SHARE`] of the misfit and
    /// [`MARK_RATIO`] times the noise of the other loops, pulls its curve at least
    /// [`MARK_OFFSET_M`], and no other tag does as well; or the test detached it.
    pub marked: bool,
    /// The test detached it from its node.
    pub detached: bool,
}

/// The marked tags of `misfits` (a network's [`ClosureReport::curves`]), as (curve, tag).
pub fn marked(misfits: &[CurveMisfit]) -> Vec<(usize, &TagMisfit)> {
    misfits
        .iter()
        .flat_map(|c| {
            c.tags
                .iter()
                .filter(|t| t.marked)
                .map(move |t| (c.curve, t))
        })
        .collect()
}

/// The misfit of each curve in `curves` under `d`, with the detached tags added.
fn curve_misfits(curves: &[UniformCurve], d: &Drops, detached: &[Detached]) -> Vec<CurveMisfit> {
    let mut out: Vec<CurveMisfit> = curves
        .iter()
        .map(|c| CurveMisfit {
            curve: c.index,
            misfit_m: 0.0,
            share: 0.0,
            tags: Vec::new(),
        })
        .collect();
    for &(ci, e, energy) in &d.segments {
        out[ci].misfit_m = out[ci].misfit_m.max(e);
        out[ci].share += energy / d.energy;
    }
    for t in &d.tags {
        out[t.curve].tags.push(TagMisfit {
            tag: t.tag,
            node: curves[t.curve].nodes[t.tag].1,
            offset_m: t.offset,
            share: t.drop / d.energy,
            marked: d.stands_out(t, MARK_SHARE, MARK_RATIO)
                && t.offset >= MARK_OFFSET_M
                && d.located(t),
            detached: false,
        });
    }
    for x in detached {
        if let Some(m) = out.iter_mut().find(|m| m.curve == x.curve) {
            m.tags.push(TagMisfit {
                tag: x.tag,
                node: x.node,
                offset_m: x.offset_m,
                share: x.share,
                marked: true,
                detached: true,
            });
        }
    }
    for m in &mut out {
        m.tags.sort_by_key(|t| t.tag);
    }
    out
}

/// A tag the network's loops refuse, kept on its node: nothing else suggests a wrong index.
#[derive(Debug, Clone, PartialEq)]
pub struct Refused {
    /// Scan index of the curve.
    pub curve: usize,
    /// The node it tags.
    pub node: u32,
    /// Position of the tag in the curve's tag list (0 = first).
    pub tag: usize,
    /// Share of the network's misfit energy it explains, %.
    pub misfit_pct: f64,
    /// How far the curve would have to be pulled to meet the node, m.
    pub offset_m: f64,
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "curve {}, node {} (tag {} of the curve): the network's loops do not close through this tag ({:.0} % of the network's misfit; the curve would have to be pulled {:.0} mm to meet the node); nothing else suggests a wrong index, so it is kept: check the index, or the data of this curve",
            self.curve,
            self.node,
            self.tag + 1,
            self.misfit_pct,
            self.offset_m * 1e3
        )
    }
}

/// Detaches the tags the network's loops refuse (see the module docs) when there is a second
/// sign of a wrong index: packets were lost while it was typed (`uncertain(curve index, tag)`),
/// or the curve passes the same node elsewhere. Each detached tag is renamed to a fresh
/// anonymous node in `curves`. A refused tag without such a sign is kept, with a warning.
pub fn detach_outlier_tags(
    curves: &mut [UniformCurve],
    uncertain: impl Fn(usize, usize) -> bool,
) -> ClosureReport {
    check(curves, uncertain, &SlipTest::STRICT, false, &[])
}

/// [`detach_outlier_tags`], then the slips `slips` names (see [`SlipTest`]): with `lengthen`,
/// each is lengthened in `curves` ([`Slip::lengthen`]) before the next is looked for, and the
/// curves' misfits are those of the loops after them. No slip is named on a segment that ends
/// at one of the nodes `joined` (where a join holds or is tried: its loops judge the join).
pub fn check(
    curves: &mut [UniformCurve],
    uncertain: impl Fn(usize, usize) -> bool,
    slips: &SlipTest,
    lengthen: bool,
    joined: &[u32],
) -> ClosureReport {
    check_from(
        curves,
        uncertain,
        slips,
        lengthen,
        joined,
        Scope::default(),
        &|| false,
    )
}

/// Where a run of the test starts and what it tests ([`check_from`]): a run from scratch
/// ([`Scope::default`]) tests every tag and segment from the tags as typed.
#[derive(Debug, Clone, Copy, Default)]
pub struct Scope<'a> {
    /// Tags an earlier run moved ([`ClosureReport::moved`]), put where it left them first.
    pub prior: &'a [Moved],
    /// Only the tags and segments of these curves (scan indices) are tested, and the tags
    /// that share a node with one of theirs that stands out (marked, refused or one of many:
    /// its rivals); `None`: every one.
    /// A live update tests its new curves so (issue 51): a whole network's test is a
    /// selected inversion of its node Laplacian, 30–60 ms at 2 500 nodes, where the new
    /// curve's are a path up the elimination tree per node it passes. The misfit of the
    /// loops, their energy and
    /// degrees of freedom are the whole network's either way; the other curves' tags are
    /// not in [`ClosureReport::curves`] (the settle tests them).
    pub tested: Option<&'a std::collections::BTreeSet<usize>>,
    /// What a live update shares with Poisson and keeps between updates ([`Kept`]).
    pub kept: Option<&'a RefCell<Kept>>,
}

/// A tag an earlier run of the closure test detached, found again by its curve, the node it
/// was typed as, which of that curve's tags of the node it is, and where on the curve it lies
/// (a join's tag put in before it shifts its place in the tag list, not these).
#[derive(Debug, Clone, PartialEq)]
pub struct Moved {
    /// Its curve's scan index.
    pub curve: usize,
    /// The node it was typed as.
    pub node: u32,
    /// Which of its curve's tags of `node` it is (0 = the first).
    pub occurrence: usize,
    /// Its arc length on the curve, m.
    pub d: f64,
    /// What the earlier run did with it (`kept_as` the node it ended on).
    pub detached: Detached,
}

/// A prior tag is found again only this close along its curve, m.
const MOVED_TOLERANCE_M: f64 = 0.01;

/// [`check`], starting from the tags an earlier run detached (`prior`, its
/// [`ClosureReport::moved`]): each found again is first put where that run left it (a retag
/// on the same node, a detached tag on a fresh anonymous node), then the test goes on as
/// [`check`] does, one tag at a time. A live update of a long session uses it: the grid of 100
/// curves puts back some 45 lost digits, each a pass of the loop test, and would do so again
/// at every update. The result is what the test accepts from that start, not to the bit what
/// [`check`] finds from scratch (a tag put back that the new loops refuse is moved again);
/// the settle runs [`check`]. `scope.tested` restricts what is tested to some curves
/// ([`Scope::tested`]). `stop` is asked before each pass of the loop test: once it says
/// yes, the test ends there ([`ClosureReport::interrupted`]; the curves as they were left).
pub fn check_from(
    curves: &mut [UniformCurve],
    uncertain: impl Fn(usize, usize) -> bool,
    slips: &SlipTest,
    lengthen: bool,
    joined: &[u32],
    scope: Scope,
    stop: &dyn Fn() -> bool,
) -> ClosureReport {
    let prior = scope.prior;
    let tested_curves: Option<Vec<bool>> = scope
        .tested
        .map(|t| curves.iter().map(|c| t.contains(&c.index)).collect());
    let tested = tested_curves
        .as_deref()
        .map(|curves| Subset { curves, tags: &[] });
    let mut out = ClosureReport::default();
    let tags: usize = curves.iter().map(|c| c.nodes.len()).sum();
    let most = MAX_DETACHED.max((MAX_DETACHED_SHARE * tags as f64) as usize);
    let typed: Vec<Vec<u32>> = curves
        .iter()
        .map(|c| c.nodes.iter().map(|n| n.1).collect())
        .collect();
    for m in prior.iter().take(most) {
        let Some(ci) = curves.iter().position(|c| c.index == m.curve) else {
            continue;
        };
        let Some(tag) = typed[ci]
            .iter()
            .enumerate()
            .filter(|(_, &n)| n == m.node)
            .nth(m.occurrence)
            .map(|(k, _)| k)
        else {
            continue;
        };
        let cu = &curves[ci];
        let found =
            cu.d.get(cu.nodes[tag].0)
                .is_some_and(|d| (d - m.d).abs() <= MOVED_TOLERANCE_M);
        if !found || cu.nodes[tag].1 != m.node {
            continue;
        }
        let kept_as = if m.detached.retagged {
            m.detached.kept_as
        } else {
            next_anonymous(curves)
        };
        curves[ci].nodes[tag].1 = kept_as;
        out.detached.push(Detached {
            tag,
            kept_as,
            ..m.detached.clone()
        });
    }
    let mut judge_refused = false;
    let mut last = loop {
        if stop() {
            out.interrupted = true;
            return out;
        }
        let Some(d) = drops(curves, &uncertain, tested, scope.kept) else {
            break None;
        };
        if out.detached.len() == most {
            break Some(d);
        }
        let worst = d.worst();
        // A tag typed while packets were lost whose curve lands on a node whose number is the
        // index received with digits missing (`7` received, 17 landed on): the link lost a
        // digit of it. Of tags the loops blame alike (the two tags of a node only two curves
        // hold), the only one with that sign is the wrong one.
        let digit_lost = |c: &Candidate| {
            let typed = curves[c.curve].nodes[c.tag].1;
            d.lands(c)
                && uncertain(curves[c.curve].index, c.tag)
                && c.lands
                    .is_some_and(|(n, _)| !crate::curve::is_anonymous(n) && digits_lost(typed, n))
        };
        let located = |c: &Candidate| {
            d.located(c)
                || (digit_lost(c)
                    && !d.tags.iter().any(|o| {
                        !std::ptr::eq(o, c) && o.drop >= LOCATED * c.drop && digit_lost(o)
                    }))
        };
        let evidenced = d
            .tags
            .iter()
            .filter(|c| {
                uncertain(curves[c.curve].index, c.tag)
                    || repeats_in_curve(&curves[c.curve], c.tag)
                    || d.far(c)
                    || d.lands(c)
            })
            .filter(|c| d.refuses(c) && located(c))
            .max_by(|a, b| a.drop.total_cmp(&b.drop))
            .or_else(|| {
                d.tags
                    .iter()
                    .filter(|c| uncertain(curves[c.curve].index, c.tag))
                    .filter(|c| d.one_of_many(c) && located(c))
                    .max_by(|a, b| a.drop.total_cmp(&b.drop))
            });
        for c in d.tags.iter().filter(|c| c.lands.is_some()) {
            tracing::debug!(
                curve = curves[c.curve].index,
                tag = c.tag,
                offset_m = c.offset,
                share = c.drop / d.energy,
                lands = ?c.lands,
                located = d.located(c),
                "closure: a tag stands out"
            );
        }
        if let Some(w) = worst {
            tracing::debug!(
                "closure: worst tag curve {} tag {}: {:.0} % of the misfit, offset {:.1} mm",
                curves[w.curve].index,
                w.tag,
                100.0 * w.drop / d.energy,
                w.offset * 1e3
            );
        }
        let Some(c) = evidenced.copied() else {
            // A tag the loops refuse with nothing else against it is named, once the slips
            // below are lengthened (what a slip explains is no tag's).
            judge_refused = worst.is_some();
            break Some(d);
        };
        let next = next_anonymous(curves);
        let lands_on = c.lands.filter(|_| d.lands(&c)).map(|l| l.0);
        // A wheel that slipped over a segment puts the tags at its ends out of their loops as
        // a wrong tag would; a tag whose curve lands on no other node is no sign of a wrong
        // index, and a wheel slips routinely: the segment is lengthened instead, and the
        // loops asked again.
        if lands_on.is_none() && slips.before_detach && lengthen && out.slips.len() < slips.max {
            let index = curves[c.curve].index;
            let at_its_end = |s: &Slip| s.curve == index && (s.tag == c.tag || s.tag + 1 == c.tag);
            if let Some(mut slip) = d.slip(curves, slips, joined).filter(at_its_end) {
                slip.lengthened = slip.lengthen(curves);
                if slip.lengthened {
                    out.slips.push(slip);
                    continue;
                }
            }
        }
        let cu = &mut curves[c.curve];
        let node = cu.nodes[c.tag].1;
        cu.nodes[c.tag].1 = lands_on.unwrap_or(next);
        out.detached.push(Detached {
            curve: cu.index,
            tag: c.tag,
            node,
            kept_as: cu.nodes[c.tag].1,
            retagged: lands_on.is_some(),
            offset_m: c.offset,
            share: c.drop / d.energy,
        });
    };
    while let Some(d) = &last {
        if out.slips.len() == slips.max {
            break;
        }
        let Some(mut slip) = d.slip(curves, slips, joined) else {
            break;
        };
        if !lengthen {
            out.slips.push(slip);
            break;
        }
        slip.lengthened = slip.lengthen(curves);
        let again = slip.lengthened;
        out.slips.push(slip);
        if !again {
            break;
        }
        // The loops with the segment lengthened: what they say now (`None`: nothing left to
        // check, the last figures stand).
        match drops(curves, &uncertain, tested, scope.kept) {
            Some(next) => last = Some(next),
            None => break,
        }
    }
    // A milder showing, named for the operator to rescan, the segment kept as measured.
    let room = out.slips.len() < slips.max;
    if let (Some(test), Some(d)) = (slips.milder().filter(|_| room), &last) {
        out.slips.extend(d.slip(curves, &test, joined));
    }
    if let Some(d) = last.as_ref().filter(|_| judge_refused) {
        if let Some(w) = d.worst() {
            let cu = &curves[w.curve];
            out.refused.push(Refused {
                curve: cu.index,
                node: cu.nodes[w.tag].1,
                tag: w.tag,
                misfit_pct: 100.0 * w.drop / d.energy,
                offset_m: w.offset,
            });
        }
    }
    if let Some(d) = last {
        out.curves = curve_misfits(curves, &d, &out.detached);
        out.misfit_m = Some((d.energy / d.dof / d.mean_c).max(0.0).sqrt());
    }
    out.moved = moved(curves, &typed, &out.detached);
    out
}

/// Whether the index `received` is `meant` with one or more digits lost on the link (its
/// decimal digits a shorter subsequence of `meant`'s: `7` for 17, `3` for 31, `12` for 102).
pub fn digits_lost(received: u32, meant: u32) -> bool {
    let (r, m) = (received.to_string(), meant.to_string());
    let mut want = r.bytes().peekable();
    for b in m.bytes() {
        if want.peek() == Some(&b) {
            want.next();
        }
    }
    r.len() < m.len() && want.peek().is_none()
}

/// A node number no tag of `curves` has, among the anonymous ones.
fn next_anonymous(curves: &[UniformCurve]) -> u32 {
    curves
        .iter()
        .flat_map(|c| c.nodes.iter().map(|n| n.1))
        .max()
        .map_or(ANONYMOUS_NODE_BASE, |m| m.saturating_add(1))
        .max(ANONYMOUS_NODE_BASE)
}

/// Each tag of `curves` whose node is no longer the one typed (`typed`, each curve's nodes
/// before the test), as a later [`check_from`] finds it again.
fn moved(curves: &[UniformCurve], typed: &[Vec<u32>], detached: &[Detached]) -> Vec<Moved> {
    let mut out = Vec::new();
    for (c, typed) in curves.iter().zip(typed) {
        for (tag, (&(sample, now), &node)) in c.nodes.iter().zip(typed).enumerate() {
            if now == node {
                continue;
            }
            // The test's last record of it (every node it changed has one).
            let Some(last) = detached
                .iter()
                .rev()
                .find(|x| x.curve == c.index && x.tag == tag)
            else {
                continue;
            };
            out.push(Moved {
                curve: c.index,
                node,
                occurrence: typed[..tag].iter().filter(|&&n| n == node).count(),
                d: c.d.get(sample).copied().unwrap_or(f64::NAN),
                // From the node typed to where it is now.
                detached: Detached {
                    node,
                    kept_as: now,
                    retagged: !crate::curve::is_anonymous(now),
                    ..last.clone()
                },
            });
        }
    }
    out
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use nalgebra::UnitQuaternion;

    /// A frame of heading `yaw` in the plane (normal +z) turned by a random rotation of up to
    /// `noise_deg`.
    fn frame(rng: &mut Rng, yaw: f64, noise_deg: f64) -> UnitQuaternion<f64> {
        let axis = Vector3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let noise = UnitQuaternion::from_scaled_axis(
            axis.normalize() * rng.range(0.0, noise_deg.to_radians()),
        );
        noise * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
    }

    /// A planar grid of `k` curves along x and `k` along y (spacing 1 m, step 1 cm) through
    /// nodes `i + k·j`, frames with normal +z, each sample's frame turned by a random rotation
    /// of up to `noise_deg` (independently per sample, as the pre-filter leaves it).
    fn grid(k: usize, noise_deg: f64, seed: u64) -> Vec<UniformCurve> {
        let mut rng = Rng::new(seed);
        let steps = 100;
        let h = 1.0 / steps as f64;
        let mut curves = Vec::new();
        for dir in 0..2 {
            for j in 0..k {
                let n = (k - 1) * steps;
                let yaw = if dir == 0 {
                    0.0
                } else {
                    std::f64::consts::FRAC_PI_2
                };
                let q = (0..=n).map(|_| frame(&mut rng, yaw, noise_deg)).collect();
                let nodes = (0..k)
                    .map(|i| {
                        let node = if dir == 0 { i + k * j } else { j + k * i };
                        (i * steps, node as u32)
                    })
                    .collect();
                curves.push(UniformCurve {
                    index: curves.len(),
                    kind: crate::curve::CurveKind::Interior,
                    d: (0..=n).map(|s| s as f64 * h).collect(),
                    q,
                    nodes,
                    h: vec![h; k - 1],
                    w: vec![1.0; n + 1],
                    outliers: 0,
                    kinks: Vec::new(),
                });
            }
        }
        curves
    }

    /// A closed curve alone (the first curve of a live session) has one loop: its drift shows
    /// as a misfit that every tag on it explains, so none is blamed.
    #[test]
    fn a_single_loop_blames_no_tag() {
        let n = 300;
        let h = 0.01;
        // A circle (radius 0.48 m) whose heading turns 2% too far: it misses its start by ~6 cm.
        let q: Vec<UnitQuaternion<f64>> = (0..=n)
            .map(|j| {
                let yaw = 1.02 * std::f64::consts::TAU * j as f64 / n as f64;
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            })
            .collect();
        let mut curves = vec![UniformCurve {
            index: 0,
            kind: crate::curve::CurveKind::Boundary,
            d: (0..=n).map(|s| s as f64 * h).collect(),
            q,
            nodes: vec![(0, 0), (100, 1), (200, 2), (300, 0)],
            h: vec![h; 3],
            w: vec![1.0; n + 1],
            outliers: 0,
            kinks: Vec::new(),
        }];
        let r = detach_outlier_tags(&mut curves, |_, _| true);
        assert!(r.detached.is_empty() && r.refused.is_empty(), "{r:?}");
        assert_eq!(curves[0].nodes[3].1, 0);
        // The curve carries the whole misfit, its ~12 cm gap shared by its three segments,
        // and no tag is marked.
        assert_eq!(r.curves.len(), 1);
        let m = &r.curves[0];
        assert!((m.share - 1.0).abs() < 1e-9, "{m:?}");
        let gap = m.tags[0].offset_m;
        assert!(gap > 0.05 && gap < 0.07, "{m:?}");
        assert!((3.0 * m.misfit_m - gap).abs() < 0.05 * gap, "{m:?}");
        assert!(m.tags.iter().all(|t| !t.marked), "{m:?}");
    }

    #[test]
    fn a_consistent_network_keeps_every_tag() {
        for seed in 1..=5 {
            for noise in [0.0, 1.0, 3.0] {
                let mut g = grid(4, noise, seed);
                let before: Vec<_> = g.iter().map(|c| c.nodes.clone()).collect();
                let r = detach_outlier_tags(&mut g, |_, _| true);
                assert!(
                    r.detached.is_empty() && r.refused.is_empty(),
                    "seed {seed}, {noise}°: {r:?}"
                );
                // Noise marks no tag for rescanning; every curve has its misfit.
                assert_eq!(r.curves.len(), g.len());
                assert!(marked(&r.curves).is_empty(), "seed {seed}, {noise}°: {r:?}");
                let shares: f64 = r.curves.iter().map(|c| c.share).sum();
                assert!(noise == 0.0 || (shares - 1.0).abs() < 1e-9, "{shares}");
                let after: Vec<_> = g.iter().map(|c| c.nodes.clone()).collect();
                assert_eq!(before, after);
            }
        }
    }

    /// Issue 51: a live update's test of its new curve alone ([`Scope::tested`]) finds what
    /// the whole network's test finds on that curve: the same tags' drops (from columns of the
    /// inverse instead of the selected inversion, to 1e-9), the same misfits (to 1e-9: its
    /// own factorisation), and a wrong index on it put back on
    /// the node meant; a wrong index on a curve it does not test is left to the settle.
    #[test]
    fn issue_51_a_live_updates_test_of_its_new_curve_finds_what_the_whole_test_does() {
        let quiet = |_: usize, _: usize| false;
        for seed in 1..=3 {
            // A live update's test of the curve `curve` alone.
            let live_test = |g: &mut [UniformCurve], curve: usize| {
                let tested: std::collections::BTreeSet<usize> = [curve].into();
                // As a live update runs it: through a node system's pattern.
                let kept = RefCell::new(Kept::default());
                let scope = Scope {
                    prior: &[],
                    tested: Some(&tested),
                    kept: Some(&kept),
                };
                check_from(g, quiet, &SlipTest::STRICT, false, &[], scope, &|| false)
            };
            let clean = grid(8, 1.0, seed);
            let full = check(&mut clean.clone(), quiet, &SlipTest::STRICT, false, &[]);
            let part = live_test(&mut clean.clone(), 5);
            // The live test factorises the same Laplacian in another order: the same
            // figures but for their last bits.
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs();
            let (pm, fm) = (part.misfit_m.unwrap(), full.misfit_m.unwrap());
            assert!(close(pm, fm), "{pm} vs {fm}");
            assert_eq!(part.curves.len(), full.curves.len());
            for (p, f) in part.curves.iter().zip(&full.curves) {
                assert_eq!(p.curve, f.curve);
                assert!(
                    close(p.misfit_m, f.misfit_m) && close(p.share, f.share),
                    "{p:?} vs {f:?}"
                );
                if p.curve != 5 {
                    assert!(p.tags.is_empty(), "{p:?}");
                    continue;
                }
                assert_eq!(p.tags.len(), f.tags.len());
                assert!(!p.tags.is_empty());
                for (a, b) in p.tags.iter().zip(&f.tags) {
                    assert_eq!((a.tag, a.node, a.marked), (b.tag, b.node, b.marked));
                    assert!((a.share - b.share).abs() <= 1e-9 * b.share, "{a:?} {b:?}");
                    assert!((a.offset_m - b.offset_m).abs() <= 1e-9 * b.offset_m);
                }
            }
            // Curve 2's third node (18) typed as 9: tested, it is put back on 18 as the whole
            // test puts it; untested (a live update of curve 5), it is not looked at.
            let mut wrong = clean.clone();
            wrong[2].nodes[2].1 = 9;
            let mut whole = wrong.clone();
            let w = check(&mut whole, quiet, &SlipTest::STRICT, false, &[]);
            let mut live = wrong.clone();
            let l = live_test(&mut live, 2);
            let key = |r: &ClosureReport| -> Vec<_> {
                r.detached
                    .iter()
                    .map(|d| (d.curve, d.tag, d.node, d.kept_as, d.retagged))
                    .collect()
            };
            assert_eq!(key(&l), key(&w), "seed {seed}");
            assert!((l.detached[0].share - w.detached[0].share).abs() < 1e-9);
            assert_eq!(live[2].nodes, whole[2].nodes);
            assert_eq!(live[2].nodes[2].1, 18);
            let mut other = wrong.clone();
            let o = live_test(&mut other, 5);
            assert!(o.detached.is_empty(), "{o:?}");
            assert_eq!(other[2].nodes[2].1, 9);
        }
    }

    /// Issue 51: the entries of the inverse a live test reads are the inverse's, from paths
    /// on a simplicial factor (a grid) and on a supernodal one (a dense matrix, as faer
    /// factorises the larger networks: the 200-curve grid's 10 002 nodes).
    #[test]
    fn the_inverse_columns_are_found_by_paths_simplicial_or_supernodal() {
        let (grid_n, grid_entries, mut grid_values) = crate::sparse_llt::grid_laplacian(9, 5);
        grid_values[0] += 1.0;
        let dense_n = 200;
        let mut dense_entries = Vec::new();
        let mut dense_values = Vec::new();
        let mut rng = Rng::new(9);
        for i in 0..dense_n {
            for j in 0..=i {
                dense_entries.push((i, j));
                dense_values.push(if i == j {
                    dense_n as f64
                } else {
                    rng.uniform() - 0.5
                });
            }
        }
        for (n, entries, values, supernodal) in [
            (grid_n, grid_entries, grid_values, false),
            (dense_n, dense_entries, dense_values, true),
        ] {
            let f = SpdPattern::new(n, &entries)
                .unwrap()
                .factor(&values)
                .unwrap();
            assert_eq!(f.supernodal(), supernodal);
            let nodes: Vec<usize> = (0..n).step_by(11).collect();
            let mut columns = Columns::default();
            columns.add(&f, nodes.iter().copied());
            for &j in &nodes {
                let mut col = vec![[0.0]; n];
                col[j][0] = 1.0;
                f.solve(&mut col);
                for &i in &nodes {
                    let got = columns.get(i, j);
                    assert!(
                        (got - col[i][0]).abs() <= 1e-12,
                        "({i}, {j}): {got} vs {:?}",
                        col[i]
                    );
                }
            }
            assert!(columns.get(0, n).is_nan(), "a row out of range");
        }
    }

    /// Issue 51: a live update's test factorises its node Laplacian through Poisson's node
    /// system's pattern, to the bit Poisson's matrix: Poisson, on the same curves, finds the
    /// factorisation kept and does not factorise again. The test's own chords of a curve
    /// seen the same are kept too.
    #[test]
    fn issue_51_the_live_tests_node_laplacian_is_poissons_node_system() {
        let quiet = |_: usize, _: usize| false;
        let mut g = grid(8, 1.0, 1);
        // Uneven steps: the conductance's arithmetic is Poisson's, not only its value.
        for c in &mut g {
            let i = c.index as f64;
            for (k, h) in c.h.iter_mut().enumerate() {
                *h *= 1.0 + 0.0137 * k as f64 + 0.0071 * i;
            }
        }
        let kept = RefCell::new(Kept::default());
        let tested: std::collections::BTreeSet<usize> = [5].into();
        let scope = Scope {
            prior: &[],
            tested: Some(&tested),
            kept: Some(&kept),
        };
        check_from(&mut g, quiet, &SlipTest::STRICT, false, &[], scope, &|| {
            false
        });
        assert_eq!(kept.borrow().chords.len(), g.len());
        let mut poisson = super::super::poisson::PoissonSolver::new();
        *poisson.node_pattern() = std::mem::take(&mut kept.borrow_mut().node_system);
        let before = poisson.numeric_count();
        assert!(before >= 1, "the test factorised through the node system");
        poisson.solve(&g).expect("positions");
        assert_eq!(poisson.numeric_count(), before, "Poisson found it kept");
        // Without the test's factorisation, Poisson factorises.
        let mut alone = super::super::poisson::PoissonSolver::new();
        alone.solve(&g).expect("positions");
        assert_eq!(alone.numeric_count(), 1);
    }

    #[test]
    fn issue_51_the_loop_test_of_a_few_tags_alone_is_the_whole_tests() {
        for seed in 1..=3 {
            let g = grid(8, 1.0, seed);
            let tags = [(2, 3), (10, 4), (15, 0)];
            let whole = loop_test(&g, &tags, false);
            let alone = loop_test(&g, &tags, true);
            assert_eq!(whole.len(), 3);
            for (w, a) in whole.iter().zip(&alone) {
                let (w, a) = (w.expect("a loop"), a.expect("a loop"));
                assert!((w.own_m - a.own_m).abs() <= 1e-9 * w.own_m, "{w:?} {a:?}");
                let (wo, ao) = (w.others_m.unwrap(), a.others_m.unwrap());
                assert!((wo - ao).abs() <= 1e-9 * wo, "{w:?} {a:?}");
            }
        }
    }

    #[test]
    fn a_wrong_index_is_detached_with_its_curve_and_tag_named() {
        for seed in 1..=5 {
            // An 8 × 8 grid (9.9 m across): a wrong index 1.4 m away is not [`FAR`] off.
            let mut g = grid(8, 1.0, seed);
            // Curve 2 (along x at y = 2) has its third node (x = 2, node 18) typed as node 9
            // (x = 1, y = 1), a node it never passes.
            assert_eq!(g[2].nodes[2].1, 18);
            g[2].nodes[2].1 = 9;
            // Let go, the curve lands on node 18, which the curve along y at x = 2 tags: the
            // tag is put there, with no other sign needed (issue 49), and the loops close.
            let mut retagged = g.clone();
            let r = detach_outlier_tags(&mut retagged, |_, _| false);
            assert_eq!(r.detached.len(), 1, "seed {seed}: {r:?}");
            let d = &r.detached[0];
            assert_eq!((d.curve, d.tag, d.node, d.kept_as), (2, 2, 9, 18), "{d:?}");
            assert!(d.retagged && r.refused.is_empty(), "{r:?}");
            assert_eq!(retagged[2].nodes[2].1, 18);
            assert!(d.to_string().contains("put on node 18"), "{d}");
            // Without that crossing tagged (curve 10, along y at x = 2, not tagged at node 18),
            // the curve lands on no node.
            assert_eq!(g[10].nodes[2].1, 18);
            g[10].nodes.remove(2);
            g[10].h.pop();
            // With no second sign of a wrong index the tag is kept, with a warning.
            let kept = detach_outlier_tags(&mut g.clone(), |_, _| false);
            assert!(kept.detached.is_empty());
            assert_eq!(kept.refused.len(), 1, "{kept:?}");
            // The view marks that tag, and only it; its curve misses its nodes the most.
            let shown: Vec<(usize, usize, u32)> = marked(&kept.curves)
                .iter()
                .map(|(c, t)| (*c, t.tag, t.node))
                .collect();
            assert_eq!(shown, vec![(2, 2, 9)], "seed {seed}");
            let worst = kept
                .curves
                .iter()
                .max_by(|a, b| a.misfit_m.total_cmp(&b.misfit_m))
                .unwrap();
            assert_eq!(worst.curve, 2, "seed {seed}: {:?}", kept.curves);
            assert_eq!(
                (
                    kept.refused[0].curve,
                    kept.refused[0].node,
                    kept.refused[0].tag
                ),
                (2, 9, 2)
            );
            // Packets lost while it was typed: detached.
            let r = detach_outlier_tags(&mut g, |c, k| (c, k) == (2, 2));
            let d = r.detached;
            assert_eq!(d.len(), 1, "seed {seed}: {d:?}");
            // Once detached the loops close: the tag is still marked (with the node it was
            // typed as), and no other.
            let shown: Vec<(usize, usize, u32, bool)> = marked(&r.curves)
                .iter()
                .map(|(c, t)| (*c, t.tag, t.node, t.detached))
                .collect();
            assert_eq!(shown, vec![(2, 2, 9, true)], "seed {seed}");
            assert_eq!((d[0].curve, d[0].tag, d[0].node), (2, 2, 9));
            assert!(crate::curve::is_anonymous(d[0].kept_as) && !d[0].retagged);
            assert_eq!(g[2].nodes[2].1, d[0].kept_as);
            // The curve had to reach 1 m sideways (spread over its segments and the others).
            assert!(d[0].offset_m > 0.5 && d[0].share > 0.9, "{}", d[0]);
            let msg = d[0].to_string();
            assert!(msg.contains("curve 2, node 9 (tag 3"), "{msg}");
        }
    }

    /// Issue 49: a curve the loops would pull a third of the network's size to meet its
    /// node has a wrong index, whatever else is known: detached with no other sign.
    #[test]
    fn issue_49_a_wrong_index_far_off_needs_no_other_sign() {
        for seed in 1..=5 {
            let mut g = grid(4, 1.0, seed);
            // Curve 2's third node (x = 2, y = 2, node 10) typed as node 5 (x = 1, y = 1):
            // 1.4 m away in a network 4.2 m across.
            g[2].nodes[2].1 = 5;
            let r = detach_outlier_tags(&mut g, |_, _| false);
            assert_eq!(r.detached.len(), 1, "seed {seed}: {r:?}");
            assert_eq!(
                (r.detached[0].curve, r.detached[0].tag, r.detached[0].node),
                (2, 2, 5)
            );
            assert!(r.refused.is_empty(), "seed {seed}: {r:?}");
        }
    }

    /// Issue 49: a segment measured 12 % short (a wheel slipping over it) is named as a slip,
    /// with its curve, its first tag and the fraction missed; the same grid without it names
    /// none.
    #[test]
    fn issue_49_a_segment_measured_short_is_named_a_slip() {
        for seed in 1..=5 {
            let mut g = grid(4, 0.5, seed);
            assert!(detach_outlier_tags(&mut g.clone(), |_, _| false)
                .slips
                .is_empty());
            // Curve 5 (along y at x = 1): its second segment (tags 1 → 2) read 12 % short.
            let c = &mut g[5];
            let (i0, i1) = (c.nodes[1].0, c.nodes[2].0);
            let h = c.h[1] * 0.88;
            c.h[1] = h;
            let base = c.d[i0];
            for j in i0..=i1 {
                c.d[j] = base + (j - i0) as f64 * h;
            }
            let shift = c.d[i1] - (base + (i1 - i0) as f64 * c.h[1] / 0.88);
            for j in i1 + 1..c.d.len() {
                c.d[j] += shift;
            }
            let r = detach_outlier_tags(&mut g, |_, _| false);
            assert_eq!(r.slips.len(), 1, "seed {seed}: {r:?}");
            let s = &r.slips[0];
            assert_eq!(
                (s.curve, s.tag, s.nodes),
                (5, 1, (5, 9)),
                "seed {seed}: {s:?}"
            );
            assert!((s.short_fraction - 0.12).abs() < 0.02, "seed {seed}: {s:?}");
            assert!(r.detached.is_empty(), "seed {seed}: {r:?}");
            assert!(
                s.to_string()
                    .contains("curve 5, segment from node 5 to node 9"),
                "{s}"
            );
        }
    }

    /// Segment `seg` of `c` read `f` short (its step and the distances from it on).
    fn shorten(c: &mut UniformCurve, seg: usize, f: f64) {
        assert!(scale_segment(c, seg, 1.0 - f));
    }

    /// A test that names up to three slips on the grids and lengthens them.
    const LENGTHENS: SlipTest = SlipTest {
        share: 0.2,
        ratio: 10.0,
        vs_tag: SLIP_VS_TAG,
        short: SLIP_SHORT,
        max: 3,
        before_detach: false,
        named_from: None,
    };

    /// The `(curve, segment)` of each slip the test named, in order.
    fn named_slips(r: &ClosureReport) -> Vec<(usize, usize)> {
        let mut named: Vec<(usize, usize)> = r.slips.iter().map(|s| (s.curve, s.tag)).collect();
        named.sort_unstable();
        named
    }

    /// Each `(curve, segment)` of `named` has its step of `exact` back within 1.5 %.
    fn given_back(g: &[UniformCurve], exact: &[Vec<f64>], named: &[(usize, usize)], seed: u64) {
        for &(c, k) in named {
            let back = g[c].h[k] / exact[c][k];
            assert!(
                (back - 1.0).abs() < 0.015,
                "seed {seed}: curve {c} segment {k}: {back}"
            );
        }
    }

    /// Issue 49: two segments read short on two curves: each named in turn, lengthened by the
    /// loops' estimate before the next is looked for, their steps given back within 1.5 %;
    /// the strict test of [`detach_outlier_tags`] names one and lengthens nothing.
    #[test]
    fn issue_49_slips_are_named_and_lengthened_one_after_another() {
        let test = LENGTHENS;
        for seed in 1..=5 {
            let mut g = grid(4, 0.5, seed);
            let exact: Vec<Vec<f64>> = g.iter().map(|c| c.h.clone()).collect();
            assert!(check(&mut g.clone(), |_, _| false, &test, true, &[])
                .slips
                .is_empty());
            shorten(&mut g[5], 1, 0.12);
            shorten(&mut g[2], 0, 0.10);
            let mut strict = g.clone();
            let r = detach_outlier_tags(&mut strict, |_, _| false);
            assert!(
                r.slips.len() <= 1 && r.slips.iter().all(|s| !s.lengthened),
                "{r:?}"
            );
            assert!(strict.iter().zip(&g).all(|(a, b)| a.h == b.h));
            let r = check(&mut g, |_, _| false, &test, true, &[]);
            let named = named_slips(&r);
            assert_eq!(named, vec![(2, 0), (5, 1)], "seed {seed}: {r:?}");
            assert!(r.slips.iter().all(|s| s.lengthened), "{r:?}");
            given_back(&g, &exact, &named, seed);
            assert!(r.detached.is_empty(), "seed {seed}: {r:?}");
        }
    }

    /// Issue 52 (`roof-loop`'s field captures): two perpendicular segments of one loop read
    /// short by as much (a wheel skidding twice), so that each alone explains the same share
    /// of the misfit. They are not alike (the correlation of their lengths' estimates is
    /// small, [`ALIKE`]): both are named and lengthened in turn. Before, the tie was taken for
    /// one slip that the loops could not locate, and neither was. Two segments in line on one
    /// chain, which the loops cannot tell apart, still name none.
    #[test]
    fn issue_52_two_slips_of_one_loop_explaining_as_much_are_both_named() {
        let test = LENGTHENS;
        for seed in 1..=5 {
            let mut g = grid(4, 0.5, seed);
            let exact: Vec<Vec<f64>> = g.iter().map(|c| c.h.clone()).collect();
            // Curve 5 (along y at x = 1) from node 5 to node 9, curve 2 (along x at y = 2)
            // from node 9 to node 10: both 10 % short, meeting at node 9.
            shorten(&mut g[5], 1, 0.10);
            shorten(&mut g[2], 1, 0.10);
            let r = check(&mut g, |_, _| false, &test, true, &[]);
            let named = named_slips(&r);
            assert_eq!(named, vec![(2, 1), (5, 1)], "seed {seed}: {r:?}");
            given_back(&g, &exact, &named, seed);
            // A node of curve 5 alone halfway from node 5 to node 9: its two halves are in
            // line, and either one 12 % short explains the loops alike. Named neither.
            let mut g = grid(4, 0.5, seed);
            let c = &mut g[5];
            let mid = (c.nodes[1].0 + c.nodes[2].0) / 2;
            c.nodes.insert(2, (mid, 99));
            c.h.insert(2, c.h[1]);
            shorten(&mut g[5], 1, 0.12);
            let r = check(&mut g, |_, _| false, &test, true, &[]);
            assert!(r.slips.is_empty(), "seed {seed}: {:?}", r.slips);
        }
    }

    /// Issue 49: a phone's segment read 8 % short, beside a curve turned 3° (a misfit no
    /// length explains, so that the segment explains less than half of it): the strict test
    /// names nothing; a phone's ([`SlipTest::PHONE`]) names it on its milder showing and keeps
    /// its length (lengthening at that showing made sound segments of two phone captures 7
    /// and 10 % long).
    #[test]
    fn issue_49_a_phone_names_a_milder_slip_and_keeps_its_length() {
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3f64.to_radians());
        for seed in 1..=5 {
            let mut g = grid(4, 0.5, seed);
            for q in g[1].q.iter_mut() {
                *q = turn * *q;
            }
            shorten(&mut g[5], 1, 0.08);
            let measured: Vec<Vec<f64>> = g.iter().map(|c| c.h.clone()).collect();
            let r = check(&mut g.clone(), |_, _| false, &SlipTest::STRICT, true, &[]);
            assert!(r.slips.is_empty(), "seed {seed}: {r:?}");
            let r = check(&mut g, |_, _| false, &SlipTest::PHONE, true, &[]);
            let named: Vec<(usize, usize, bool)> = r
                .slips
                .iter()
                .map(|s| (s.curve, s.tag, s.lengthened))
                .collect();
            assert_eq!(named, [(5, 1, false)], "seed {seed}: {r:?}");
            assert!((r.slips[0].short_fraction - 0.08).abs() < 0.01, "{r:?}");
            assert!(
                g.iter().zip(&measured).all(|(c, h)| &c.h == h),
                "seed {seed}: a length changed"
            );
        }
    }

    /// Issue 49: a wheel that slipped over a curve's last segment puts the curve's end tag out
    /// of its loops as a wrong tag would (let go, the end floats and the loops close). Typed
    /// while packets were lost, the tag was detached as an anonymous node and the slip left;
    /// not so typed, it was named a refused tag beside the slip. A wheel's test lengthens the
    /// segment and names no tag; a test that does not prefer the slip still detaches it. (The
    /// curve is scanned twice, so that its end node is held by three curves and the loops can
    /// tell which tag is out.)
    #[test]
    fn issue_49_a_wheel_slip_is_lengthened_before_the_tag_at_its_end_is_blamed() {
        for seed in 1..=5 {
            let mut g = grid(4, 0.5, seed);
            let mut again = g[5].clone();
            again.index = g.len();
            g.push(again);
            shorten(&mut g[5], 2, 0.12);
            for typed_while_lost in [true, false] {
                let uncertain = |c: usize, k: usize| typed_while_lost && c == 5 && k == 3;
                let r = check(&mut g.clone(), uncertain, &SlipTest::WHEEL, true, &[]);
                let named: Vec<(usize, usize, bool)> = r
                    .slips
                    .iter()
                    .map(|s| (s.curve, s.tag, s.lengthened))
                    .collect();
                assert_eq!(named, [(5, 2, true)], "seed {seed}: {r:?}");
                assert!(r.detached.is_empty(), "seed {seed}: {r:?}");
                assert!(r.refused.is_empty(), "seed {seed}: {r:?}");
            }
            let blind = SlipTest {
                before_detach: false,
                ..SlipTest::WHEEL
            };
            let r = check(&mut g.clone(), |c, k| c == 5 && k == 3, &blind, true, &[]);
            let detached: Vec<(usize, usize)> =
                r.detached.iter().map(|d| (d.curve, d.tag)).collect();
            assert_eq!(detached, [(5, 3)], "seed {seed}: {r:?}");
        }
    }

    #[test]
    fn a_node_repeated_inside_a_curve_is_a_second_sign() {
        let mut g = grid(4, 1.0, 7);
        // Curve 1 (y = 1, nodes 4 5 6 7) with its third node typed as its first.
        g[1].nodes[2].1 = 4;
        let r = detach_outlier_tags(&mut g, |_, _| false);
        assert_eq!(r.detached.len(), 1, "{r:?}");
        assert_eq!((r.detached[0].curve, r.detached[0].tag), (1, 2));
        assert!(r.refused.is_empty());
    }

    /// A long session's link loses digits at a rate (`110` typed, `11` received): several wrong
    /// indices at once, each typed while packets were lost. None explains half the misfit, so
    /// the one-outlier test refuses none; each stands out of the noise and its curve, let go,
    /// lands on the node meant: all are put back, more than [`MAX_DETACHED`] of them.
    #[test]
    fn several_digits_lost_on_a_long_session_are_each_put_back() {
        let k = 13; // 26 curves, 338 tags: up to 6 detached
        for seed in 1..=3 {
            let mut g = grid(k, 0.5, seed);
            let mut wrong = Vec::new();
            for (c, t) in [(1, 3), (4, 8), (7, 1), (15, 5), (19, 10), (23, 6)] {
                let meant = g[c].nodes[t].1;
                let typed = (meant + 5 * k as u32) % (k * k) as u32;
                g[c].nodes[t].1 = typed;
                wrong.push((c, t, meant));
            }
            let lost = |c: usize, t: usize| wrong.iter().any(|w| (w.0, w.1) == (c, t));
            let before = detach_outlier_tags(&mut g.clone(), |_, _| false);
            assert!(before.detached.is_empty(), "seed {seed}: {before:?}");
            let r = detach_outlier_tags(&mut g, lost);
            let mut put: Vec<(usize, usize, u32)> = r
                .detached
                .iter()
                .filter(|d| d.retagged)
                .map(|d| (d.curve, d.tag, d.kept_as))
                .collect();
            put.sort_unstable();
            assert_eq!(put, wrong, "seed {seed}: {r:?}");
            assert_eq!(r.detached.len(), wrong.len(), "seed {seed}: {r:?}");
        }
    }

    /// A live update starts the test from the tags the last one moved: on the same curves it
    /// ends where that test ended, and a tag the last test moved wrongly (a prior the new loops
    /// refute) is moved back, not kept.
    #[test]
    fn issue_51_a_live_update_starts_from_the_tags_the_last_test_moved() {
        let k = 13;
        let mut g = grid(k, 0.5, 1);
        let mut wrong = Vec::new();
        for (c, t) in [(1, 3), (4, 8), (7, 1), (15, 5), (19, 10), (23, 6)] {
            let meant = g[c].nodes[t].1;
            g[c].nodes[t].1 = (meant + 5 * k as u32) % (k * k) as u32;
            wrong.push((c, t, meant));
        }
        let lost = |c: usize, t: usize| wrong.iter().any(|w| (w.0, w.1) == (c, t));
        let test = |g: &mut [UniformCurve], prior: &[Moved]| {
            let scope = Scope {
                prior,
                ..Scope::default()
            };
            check_from(g, lost, &SlipTest::STRICT, false, &[], scope, &|| false)
        };
        let nodes = |g: &[UniformCurve]| -> Vec<Vec<u32>> {
            g.iter()
                .map(|c| c.nodes.iter().map(|n| n.1).collect())
                .collect()
        };
        let mut scratch = g.clone();
        let first = test(&mut scratch, &[]);
        assert_eq!(first.moved.len(), wrong.len(), "{first:?}");
        let mut warm = g.clone();
        let again = test(&mut warm, &first.moved);
        assert_eq!(nodes(&warm), nodes(&scratch));
        assert_eq!(again.moved, first.moved);
        let key = |r: &ClosureReport| {
            let mut v: Vec<_> = r
                .detached
                .iter()
                .map(|d| (d.curve, d.tag, d.node, d.kept_as))
                .collect();
            v.sort_unstable();
            v
        };
        assert_eq!(key(&again), key(&first));
        // The start is the prior's: with no tag marked uncertain, the test from scratch puts
        // none back; started from the prior, the loops accept all six where they are.
        let unmarked = |g: &mut [UniformCurve], prior: &[Moved]| {
            let scope = Scope {
                prior,
                ..Scope::default()
            };
            check_from(
                g,
                |_, _| false,
                &SlipTest::STRICT,
                false,
                &[],
                scope,
                &|| false,
            )
        };
        assert!(unmarked(&mut g.clone(), &[]).moved.is_empty());
        let mut warm = g.clone();
        assert_eq!(unmarked(&mut warm, &first.moved).moved, first.moved);
        assert_eq!(nodes(&warm), nodes(&scratch));
        // A prior that moved a right tag (curve 10, tag 4) onto another node: the loops refuse
        // it, its curve lands on the node typed, and it goes back.
        let right = g[10].nodes[4];
        let mut stale = first.moved.clone();
        stale.push(Moved {
            curve: 10,
            node: right.1,
            occurrence: 0,
            d: g[10].d[right.0],
            detached: Detached {
                curve: 10,
                tag: 4,
                node: right.1,
                kept_as: (right.1 + 3) % (k * k) as u32,
                retagged: true,
                offset_m: 0.0,
                share: 0.0,
            },
        });
        let mut warm = g.clone();
        let r = test(&mut warm, &stale);
        assert_eq!(nodes(&warm), nodes(&scratch), "{r:?}");
        assert_eq!(r.moved, first.moved);
    }

    #[test]
    fn digits_lost_is_the_index_received_with_digits_missing() {
        for (received, meant) in [(2, 12), (1, 11), (3, 31), (12, 102), (5, 125), (0, 10)] {
            assert!(digits_lost(received, meant), "{received} from {meant}");
        }
        for (received, meant) in [(12, 12), (13, 12), (21, 12), (4, 12), (12, 2), (11, 10)] {
            assert!(!digits_lost(received, meant), "{received} from {meant}");
        }
    }

    /// The two tags of a node only two curves hold explain the misfit alike, so neither is
    /// located by the loops. A node's third curve lost its index on the link (an anonymous
    /// node), and a digit of another tag was lost (`7` received for 17, packets lost while it
    /// was typed): that tag, whose curve lands on 17, is the wrong one and is put back there
    /// (the phone on the dense ellipsoid, field profile, seed 4: 3.58 % → 0.18 %).
    #[test]
    fn issue_52_of_a_node_held_by_two_curves_the_tag_with_a_digit_lost_is_put_back() {
        let k = 13;
        for seed in 1..=3 {
            let mut g = grid(k, 0.5, seed);
            // Node 7 (i = 7, j = 0): curve 0 tag 7 and curve 20 tag 0. Node 17: curve 1 tag
            // 4 and curve 17 tag 1.
            assert_eq!((g[0].nodes[7].1, g[20].nodes[0].1), (7, 7));
            assert_eq!((g[1].nodes[4].1, g[17].nodes[1].1), (17, 17));
            g[0].nodes[7].1 = ANONYMOUS_NODE_BASE;
            g[17].nodes[1].1 = 7;
            let put_back = |r: &ClosureReport| {
                r.detached
                    .iter()
                    .any(|d| (d.curve, d.tag, d.node, d.kept_as) == (17, 1, 7, 17))
            };
            let lost = |c: usize, t: usize| (c, t) == (17, 1);
            let r = check(&mut g.clone(), lost, &SlipTest::STRICT, false, &[]);
            assert!(put_back(&r), "seed {seed}: {r:?}");
            assert_eq!(r.detached.len(), 1, "seed {seed}: {r:?}");
            // No packet lost while it was typed: nothing says which of the two it is.
            let r = check(&mut g.clone(), |_, _| false, &SlipTest::STRICT, false, &[]);
            assert!(!put_back(&r) && r.detached.is_empty(), "seed {seed}: {r:?}");
        }
    }

    /// A closed curve whose closing index lost a digit (`1` received for 14, its first node):
    /// let go, its end lands on its own first node, which is the node meant; the tag is put
    /// back there, not left anonymous (our phone on the dense ellipsoid, default profile,
    /// seed 2, the last unfaulted capture judged `suspect`).
    #[test]
    fn issue_52_a_closed_curve_whose_closing_index_lost_a_digit_is_closed_again() {
        let k = 13;
        let (lo, hi, steps) = (1usize, 11usize, 100usize);
        for seed in 1..=3 {
            let mut g = grid(k, 0.5, seed);
            // A square through rows and columns 1 and 11, from node 14 round to node 14.
            let mut rng = Rng::new(100 + seed);
            let corners = [(lo, lo), (hi, lo), (hi, hi), (lo, hi), (lo, lo)];
            let (mut q, mut nodes) = (Vec::new(), Vec::new());
            for (side, w) in corners.windows(2).enumerate() {
                let yaw = side as f64 * std::f64::consts::FRAC_PI_2;
                let cells = (hi - lo) * steps;
                for s in 0..cells + usize::from(side == 3) {
                    if s % steps == 0 {
                        let t = s / steps;
                        let (x, y) = match side {
                            0 => (w[0].0 + t, lo),
                            1 => (hi, w[0].1 + t),
                            2 => (w[0].0 - t, hi),
                            _ => (lo, w[0].1 - t),
                        };
                        nodes.push((q.len(), (x + k * y) as u32));
                    }
                    q.push(frame(&mut rng, yaw, 0.5));
                }
            }
            let n = q.len() - 1;
            let h = 1.0 / steps as f64;
            assert_eq!((nodes[0].1, nodes.last().unwrap().1), (14, 14));
            let last = nodes.len() - 1;
            let ring = g.len();
            g.push(UniformCurve {
                index: ring,
                kind: crate::curve::CurveKind::Interior,
                d: (0..=n).map(|s| s as f64 * h).collect(),
                q,
                h: vec![h; nodes.len() - 1],
                nodes,
                w: vec![1.0; n + 1],
                outliers: 0,
                kinks: Vec::new(),
            });
            assert!(
                check(&mut g.clone(), |_, _| true, &SlipTest::STRICT, false, &[])
                    .detached
                    .is_empty()
            );
            g[ring].nodes[last].1 = 1;
            let lost = |c: usize, t: usize| (c, t) == (ring, last);
            let r = check(&mut g.clone(), lost, &SlipTest::STRICT, false, &[]);
            let closed = r
                .detached
                .iter()
                .any(|d| (d.curve, d.tag, d.node, d.kept_as) == (ring, last, 1, 14));
            assert!(closed && r.detached.len() == 1, "seed {seed}: {r:?}");
        }
    }

    #[test]
    fn a_tree_of_curves_has_nothing_to_check() {
        let mut g = grid(2, 0.0, 1);
        g.truncate(3); // three sides of a square: no loop
        g[2].nodes[1].1 = 17;
        assert_eq!(
            detach_outlier_tags(&mut g, |_, _| true),
            ClosureReport::default()
        );
    }
}
