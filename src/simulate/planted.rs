//! One operator or field fault planted in a simulated capture (`sfs simulate --fault`, issue
//! 49): a wrong node typed, the wheel slipping over one segment, Enter pressed late, or a
//! magnet under one stretch of a curve. Where it goes and how large it is are drawn from a
//! random stream of its own, so that the capture's other random draws (noise, timing, the
//! profile's own faults) are those of the same seed without it: a wrong node changes the keys
//! of one index, a slip the wheel's counts from one segment on, a magnet the magnetometer's
//! near one stretch; a late Enter changes the number of samples, so the noise after it (and
//! all of the render's) is drawn anew: its twin is the same scan, not the same bytes.
//! The truth says where: `faults[]`, each with `kind`, `curve` (scan order, the program's curve
//! index), `tag` (the position in that curve's tags), `node` and `details`, as
//! the validation set's planted faults do.
//!
//! ```
//! use sfs::simulate::{self, planted::Planted, scene, Profile};
//! let s = scene::builtin("cone").unwrap();
//! let kind = device_protocol::DeviceKind::Morphorider;
//! let sim = simulate::run_planted(&s, kind, Profile::Default, 3, Planted::WrongNode).unwrap();
//! let f = &sim.truth.faults[0];
//! assert_eq!((f.kind.as_str(), f.tag.is_some()), ("wrong-node", true));
//! ```

use super::device::{DeviceParams, Disturbance};
use super::operator::{at_corner, CurveSpec, Mistakes, Script};
use super::rng::Rng;
use super::scene::Scene;
use super::truth::TruthFault;
use device_protocol::DeviceKind;
use nalgebra::Vector3;
use serde_json::json;

/// A fault `sfs simulate --fault` plants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Planted {
    /// At one tag the operator types another existing node's index (as many digits) and goes
    /// on unaware; the device stood at the true node.
    WrongNode,
    /// One segment reads 8–15 % short: the Morphorider's wheel slips over all of it; the
    /// phone's SEGMENT_LENGTH of it is short.
    Slip,
    /// At one tag the index is typed at the node, Enter only once the device has rolled 3–5 cm
    /// on (the phone's segment lengths count from Enter to Enter).
    LateEnter,
    /// A ferromagnetic object under one stretch of a curve (about 15 µT within 4–6 % of the
    /// diagonal).
    Magnet,
}

impl Planted {
    /// Its name on the command line and in the truth.
    pub fn name(self) -> &'static str {
        match self {
            Planted::WrongNode => "wrong-node",
            Planted::Slip => "slip",
            Planted::LateEnter => "late-enter",
            Planted::Magnet => "magnet",
        }
    }
}

/// Why a fault cannot be planted in a scene.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--fault {kind}: {reason}")]
pub struct NoPlace {
    pub kind: &'static str,
    pub reason: &'static str,
}

/// The fault's own random stream: the seed, mixed with a constant no other stream uses and
/// with the kind (so that two kinds planted with one seed land in different places).
fn stream(seed: u64, kind: Planted) -> Rng {
    Rng::new(seed ^ 0xfa17_ed00_5eed_0049 ^ ((kind as u64 + 1) << 56))
}

/// Where the fault goes and how large it is (drawn before the scan is acted out).
#[derive(Debug, Clone)]
pub struct Plan {
    kind: Planted,
    curve: usize,
    /// The scene's tag index on that curve (wrong node, late Enter; a slip's segment start).
    tag: usize,
    typed: u32,
    fraction: f64,
    late_m: f64,
    magnet: Option<(Disturbance, usize)>,
}

/// The tags of curve `c` the operator types (those not left untagged).
fn typed_tags(specs: &[CurveSpec], more: &Mistakes, c: usize) -> Vec<usize> {
    (0..specs[c].tags.len())
        .filter(|&k| !more.untagged.contains(&(c, k)))
        .collect()
}

/// Draws the fault's place in `scene` (curves as scanned, with the operator's `more` mistakes
/// already chosen).
pub fn plan(kind: Planted, scene: &Scene, seed: u64, more: &Mistakes) -> Result<Plan, NoPlace> {
    let specs = scene.specs();
    let mut rng = stream(seed, kind);
    let pick = |rng: &mut Rng, n: usize| ((rng.uniform() * n as f64) as usize).min(n - 1);
    let no = |reason| NoPlace {
        kind: kind.name(),
        reason,
    };
    // Candidate (curve, tag) places, each kind its own.
    let mut places: Vec<(usize, usize)> = Vec::new();
    for c in 0..specs.len() {
        let tags = typed_tags(&specs, more, c);
        for (j, &k) in tags.iter().enumerate() {
            let ok = match kind {
                Planted::WrongNode => true,
                // A segment from this tag to the next typed one.
                Planted::Slip => j + 1 < tags.len(),
                // Not the last (nowhere to roll on), nor a corner (the operator turns there).
                Planted::LateEnter => j + 1 < tags.len() && !at_corner(&specs[c], k),
                Planted::Magnet => j == 0,
            };
            if ok {
                places.push((c, k));
            }
        }
    }
    if places.is_empty() {
        return Err(no("the scene has no place for it"));
    }
    let (curve, tag) = places[pick(&mut rng, places.len())];
    let mut plan = Plan {
        kind,
        curve,
        tag,
        typed: 0,
        fraction: 0.0,
        late_m: 0.0,
        magnet: None,
    };
    match kind {
        Planted::WrongNode => {
            let node = specs[curve].tags[tag].1;
            let digits = |n: u32| n.to_string().len();
            let on_curve: Vec<u32> = specs[curve].tags.iter().map(|t| t.1).collect();
            let all = 0..scene.nodes.len() as u32;
            let alike: Vec<u32> = all
                .filter(|&n| n != node && digits(n) == digits(node))
                .collect();
            // Rather a node this curve does not pass (else a loop the curve never made).
            let off: Vec<u32> = alike
                .iter()
                .copied()
                .filter(|n| !on_curve.contains(n))
                .collect();
            let from = if off.is_empty() { &alike } else { &off };
            if from.is_empty() {
                return Err(no("no other node has as many digits"));
            }
            plan.typed = from[pick(&mut rng, from.len())];
        }
        Planted::Slip => plan.fraction = rng.range(0.08, 0.15),
        Planted::LateEnter => plan.late_m = rng.range(0.03, 0.05),
        Planted::Magnet => {
            let c = &specs[curve];
            let i = (c.points.len() as f64 * rng.range(0.25, 0.75)) as usize;
            let i = i.min(c.points.len() - 1);
            let radius = scene.bbox_diagonal() * rng.range(0.04, 0.06);
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let field = 15.0 * Vector3::new(phi.cos(), phi.sin(), 0.3).normalize();
            // Under the surface, a third of its radius deep.
            let center = c.points[i] - c.normals[i] * (radius / 3.0);
            plan.magnet = Some((
                Disturbance {
                    center,
                    radius,
                    field_ut: field,
                },
                i,
            ));
        }
    }
    Ok(plan)
}

impl Plan {
    /// The curve the fault is on (scan order).
    pub fn curve(&self) -> usize {
        self.curve
    }

    /// What the operator does differently (before the scan is acted out).
    pub fn act(&self, m: &mut Mistakes) {
        match self.kind {
            Planted::WrongNode => m.typed_instead = Some((self.curve, self.tag, self.typed)),
            Planted::LateEnter => m.late_enter = Some((self.curve, self.tag, self.late_m)),
            Planted::Slip | Planted::Magnet => {}
        }
    }

    /// What the device does differently, once the scan's timeline is known; the truth's entry.
    pub fn realise(
        &self,
        scene: &Scene,
        script: &Script,
        p: &mut DeviceParams,
        more: &Mistakes,
    ) -> TruthFault {
        let specs = scene.specs();
        let tags = typed_tags(&specs, more, self.curve);
        // The position among the tags typed (the program's tag index).
        let j = tags.iter().position(|&k| k == self.tag).unwrap_or(0);
        let truth = &script.curves[self.curve];
        let node = specs[self.curve].tags[self.tag].1;
        let mut f = TruthFault {
            kind: self.kind.name().into(),
            curve: self.curve,
            tag: Some(j),
            node: Some(node),
            details: json!({}),
        };
        match self.kind {
            Planted::WrongNode => {
                let on: Vec<usize> = specs
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| c.tags.iter().any(|t| t.1 == self.typed))
                    .map(|(i, _)| i)
                    .collect();
                f.details = json!({
                    "typed_node": self.typed,
                    "true_node": node,
                    "typed_node_on_curves": on,
                    "note": "the device stood at true_node; the keypad says typed_node (as many digits, so the key timing is the unfaulted case's)",
                });
            }
            Planted::Slip => {
                let (a, b) = (truth.tags[j], truth.tags[j + 1]);
                let true_length = b.1 - a.1;
                let factor = 1.0 - self.fraction;
                match p.kind {
                    DeviceKind::Phone => p.segment_scale.push((self.curve, j, factor)),
                    // From the Enter that starts the segment to the one that ends it.
                    _ => p.skids.push((a.2, b.2 - a.2, factor)),
                }
                f.tag = None;
                f.node = None;
                f.details = json!({
                    "segment": j,
                    "segment_nodes": [a.0, b.0],
                    "true_length_m": true_length,
                    "short_fraction": self.fraction,
                    "note": "this segment reads (1 - short_fraction) x its true length: the wheel slips over all of it (Morphorider), its SEGMENT_LENGTH is short (phone)",
                });
            }
            Planted::LateEnter => {
                let late = truth.enter_s[j] - truth.tags[j].1;
                f.details = json!({
                    "late_m": late,
                    "t_enter_s": truth.tags[j].2,
                    "note": "the index was typed at the node, Enter pressed once the device had rolled late_m on along the next segment",
                });
            }
            Planted::Magnet => {
                let (d, i) = self.magnet.expect("a magnet's plan has its magnet");
                p.disturbances.push(d);
                f.tag = None;
                f.node = None;
                f.details = json!({
                    "center_m": [d.center.x, d.center.y, d.center.z],
                    "radius_m": d.radius,
                    "field_ut": [d.field_ut.x, d.field_ut.y, d.field_ut.z],
                    "near_point": i,
                    "note": "an extra field, constant within radius_m of center_m (a third of the radius under the curve's point near_point), fading over one more radius",
                });
            }
        }
        f
    }
}
