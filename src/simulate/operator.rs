//! The operator: turns curves on a surface into a timeline of true device states and key
//! presses, as a person scanning them would: start key, stand at the node while typing its
//! index, Enter, roll to the next node with slowly varying speed, …, `E`, then carry the
//! device to the next curve.

use super::rng::Rng;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
pub use sfs_geometry::curve::CurveKind;

/// A curve to scan: a dense polyline on the surface with outward normals, and its node tags.
#[derive(Debug, Clone)]
pub struct CurveSpec {
    /// Points along the curve in order of travel, m.
    pub points: Vec<Vector3<f64>>,
    /// Outward unit surface normals at the points.
    pub normals: Vec<Vector3<f64>>,
    /// `(point index, node index)` in order of travel; the first at point 0, the last at the
    /// last point.
    pub tags: Vec<(usize, u32)>,
    /// What the curve means; the operator starts it with its key (`B`, `I`, `K`, `G`).
    pub kind: CurveKind,
}

/// How the operator moves (documented defaults).
#[derive(Debug, Clone, PartialEq)]
pub struct OperatorParams {
    /// Mean rolling speed, m/s. Default 0.05.
    pub speed: f64,
    /// Relative amplitude of the slow speed changes. Default 0.3.
    pub speed_variation: f64,
    /// Standing at a node before typing its index, s. Default 0.6.
    pub pause_before_typing: f64,
    /// Between key presses, s. Default 0.25.
    pub key_interval: f64,
    /// Standing after Enter before rolling on, s. Default 0.4.
    pub pause_after_enter: f64,
    /// Carrying the device from one curve's end to the next curve's start, s. Default 3.
    pub carry_time: f64,
    /// Amplitude of the hand's back-and-forth along the curve while standing, m. Default 0.3 mm.
    pub stand_wobble: f64,
    /// The hand tilts the standing device by about this much while typing an index, degrees
    /// (±25 %, about a random axis in the surface's tangent plane, in and out smoothly).
    /// Default 0.
    pub typing_tilt_deg: f64,
    /// The device is put down at each curve's start node turned about the surface normal by
    /// about this much (±50 %, either way), the index typed, and then turned in place to the
    /// curve's direction over `turn_time` before it moves, degrees. Default 0.
    pub turn_in_place_deg: f64,
    /// Duration of that turn, s. Default 0.8.
    pub turn_time: f64,
    /// The hand slows the device to rest over about this long before each node and speeds
    /// it up as gently after leaving one (a constant deceleration from the mean speed), s.
    /// Default 0: it stops and starts at once.
    pub stop_ramp: f64,
    /// Operator mistakes to act out (none by default).
    pub mistakes: Mistakes,
}

/// Mistakes a real operator makes, acted out so that acquisition must recover from them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mistakes {
    /// `(curve, tag)`: type a wrong index there, Enter, notice, `U`, then the right one.
    pub wrong_index: Option<(usize, usize)>,
    /// Start this curve, tag its first node, roll 40 % of its first segment, press `C`, carry
    /// the device back and scan the curve again.
    pub cancel_and_rescan: Option<usize>,
    /// `(curve, tag)`: after the right index and Enter there, type it again and Enter (a
    /// repeated tag), notice, `U` (which must undo the repeat, not the tag: issue 15).
    pub repeated_index: Option<(usize, usize)>,
    /// `(curve, tag)`: roll through this node without standing or typing (a crossing left
    /// untagged on this curve, issue 34). Not done at a curve's first or last tag, nor at a
    /// corner (where the operator stands to turn); [`Script::untagged`] says where it was.
    pub untagged: Vec<(usize, usize)>,
    /// `(curve, tag, node)`: type this node's index there instead of the right one, and go on
    /// unaware (a wrong node, issue 49; the same number of digits keeps the key timing).
    pub typed_instead: Option<(usize, usize, u32)>,
    /// `(curve, tag, m)`: type the index at the node, but press Enter only after rolling this
    /// far on along the next segment (a late Enter, issue 49; never at a curve's last tag).
    pub late_enter: Option<(usize, usize, f64)>,
    /// After the last curve (and its last sample), type this curve's index and `C`: it is
    /// dropped (issue 49).
    pub drop_after: Option<usize>,
    /// After the last curve, carry the device to this curve's start, type its index and its
    /// start key, and scan it again, making no mistake: it replaces the first scan (issue 49).
    pub rescan: Option<usize>,
}

impl Default for OperatorParams {
    fn default() -> Self {
        OperatorParams {
            speed: 0.05,
            speed_variation: 0.3,
            pause_before_typing: 0.6,
            key_interval: 0.25,
            pause_after_enter: 0.4,
            carry_time: 3.0,
            stand_wobble: 0.0003,
            typing_tilt_deg: 0.0,
            turn_in_place_deg: 0.0,
            turn_time: 0.8,
            stop_ramp: 0.0,
            mistakes: Mistakes::default(),
        }
    }
}

/// The true state of the device at one sample.
#[derive(Debug, Clone)]
pub struct State {
    /// Session time, s.
    pub t: f64,
    /// Frame `[T B N]` → world.
    pub q: UnitQuaternion<f64>,
    pub pos: Vector3<f64>,
    /// Kinematic acceleration, world, m/s² (from the positions).
    pub acc: Vector3<f64>,
    /// Angular velocity in frame axes, rad/s (from the orientations).
    pub omega: Vector3<f64>,
    /// Signed distance the wheel has rolled since the session started, m.
    pub wheel: f64,
    /// The curve being scanned (between its start key and its `E`).
    pub curve: Option<usize>,
    /// True distance along that curve, m.
    pub s: f64,
    /// Whether the operator is standing (at a node).
    pub standing: bool,
}

/// The truth of one scanned curve.
#[derive(Debug, Clone)]
pub struct CurveTruth {
    pub kind: CurveKind,
    /// `(node, true distance s, time of Enter, wheel reading then)`.
    pub tags: Vec<(u32, f64, f64, f64)>,
    /// The true distance at each tag's Enter (its `s`, but for a late Enter).
    pub enter_s: Vec<f64>,
    pub length: f64,
}

/// The timeline.
#[derive(Debug, Clone, Default)]
pub struct Script {
    pub states: Vec<State>,
    /// `(time, key)` in time order.
    pub keys: Vec<(f64, u8)>,
    pub curves: Vec<CurveTruth>,
    /// `(curve, node)` rolled through untagged ([`Mistakes::untagged`]), in scan order.
    pub untagged: Vec<(usize, u32)>,
}

/// Arc-length parametrised curve with smooth frames, but at corners.
struct Param<'a> {
    spec: &'a CurveSpec,
    cum: Vec<f64>,
    t: Vec<Vector3<f64>>,
    n: Vec<Vector3<f64>>,
    /// At a tagged point where the curve turns about the surface normal by more than
    /// [`CORNER_DEG`] (a box's corner): the tangents arriving and leaving. The operator stops
    /// there and turns the device in place.
    corner: Vec<Option<(Vector3<f64>, Vector3<f64>)>>,
}

/// A turn about the normal sharper than this at a node is a corner, degrees.
pub const CORNER_DEG: f64 = 30.0;

/// Whether tag `k` of `spec` is at a corner ([`CORNER_DEG`]), where the operator stands to
/// turn (and so always types the node).
pub fn at_corner(spec: &CurveSpec, k: usize) -> bool {
    spec.tags
        .get(k)
        .is_some_and(|&(i, _)| Param::new(spec).corner.get(i).is_some_and(|c| c.is_some()))
}

impl<'a> Param<'a> {
    fn new(spec: &'a CurveSpec) -> Self {
        let p = &spec.points;
        let m = p.len();
        let mut cum = vec![0.0; m];
        for i in 1..m {
            cum[i] = cum[i - 1] + (p[i] - p[i - 1]).norm();
        }
        let t: Vec<Vector3<f64>> = (0..m)
            .map(|i| {
                let a = p[i.saturating_sub(1)];
                let b = p[(i + 1).min(m - 1)];
                (b - a).normalize()
            })
            .collect();
        let n = (0..m)
            .map(|i| {
                let n = spec.normals[i];
                (n - t[i] * n.dot(&t[i])).normalize()
            })
            .collect();
        let mut corner = vec![None; m];
        for &(i, _) in &spec.tags {
            if i == 0 || i + 1 >= m {
                continue;
            }
            let nn = spec.normals[i];
            let flat = |d: Vector3<f64>| d - nn * nn.dot(&d);
            let (din, dout) = (p[i] - p[i - 1], p[i + 1] - p[i]);
            if flat(din).angle(&flat(dout)) > CORNER_DEG.to_radians() {
                corner[i] = Some((din.normalize(), dout.normalize()));
            }
        }
        Param {
            spec,
            cum,
            t,
            n,
            corner,
        }
    }

    /// The turn about the frame's normal that takes the frame leaving corner point `i` to the
    /// one arriving there, radians (`None` where the curve has no corner).
    fn corner_turn(&self, i: usize) -> Option<f64> {
        let (tin, _) = self.corner[i]?;
        let local = self.frame(self.cum[i]).inverse() * tin;
        Some(local.y.atan2(local.x))
    }

    fn length(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    fn locate(&self, s: f64) -> (usize, f64) {
        let s = s.clamp(0.0, self.length());
        let i = self
            .cum
            .partition_point(|&c| c <= s)
            .clamp(1, self.cum.len() - 1);
        let (a, b) = (self.cum[i - 1], self.cum[i]);
        let u = if b > a { (s - a) / (b - a) } else { 0.0 };
        (i, u)
    }

    fn pos(&self, s: f64) -> Vector3<f64> {
        let (i, u) = self.locate(s);
        let p = &self.spec.points;
        p[i - 1] * (1.0 - u) + p[i] * u
    }

    /// The frame at `s`; at a corner, the one leaving it.
    fn frame(&self, s: f64) -> UnitQuaternion<f64> {
        let (i, u) = self.locate(s);
        self.frame_in_segment(i, u)
    }

    /// The frame at `s`; at a corner, the one arriving there.
    fn frame_in(&self, s: f64) -> UnitQuaternion<f64> {
        let s = s.clamp(0.0, self.length());
        let i = self
            .cum
            .partition_point(|&c| c < s)
            .clamp(1, self.cum.len() - 1);
        let (a, b) = (self.cum[i - 1], self.cum[i]);
        let u = if b > a { (s - a) / (b - a) } else { 0.0 };
        self.frame_in_segment(i, u)
    }

    /// The frame at `u` of the way from point `i − 1` to point `i`.
    fn frame_in_segment(&self, i: usize, u: f64) -> UnitQuaternion<f64> {
        let ta = self.corner[i - 1].map_or(self.t[i - 1], |c| c.1);
        let tb = self.corner[i].map_or(self.t[i], |c| c.0);
        let t = (ta * (1.0 - u) + tb * u).normalize();
        let n = self.n[i - 1] * (1.0 - u) + self.n[i] * u;
        let n = (n - t * n.dot(&t)).normalize();
        let b = n.cross(&t);
        let m = Matrix3::from_columns(&[t, b, n]);
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
    }
}

struct Timeline<'r> {
    script: Script,
    t: f64,
    dt: f64,
    jitter: f64,
    wheel: f64,
    rng: &'r mut Rng,
    /// The hand's tilt while an index is typed.
    tilt: Option<Tilt>,
    /// The device turned about the normal at a curve's start, until turned in place.
    turn: Option<Turn>,
    /// The interval to the next sample, once drawn.
    pending_dt: Option<f64>,
}

/// A turn about the normal (frame z) of a standing device: `angle` until `start`, then eased
/// to zero over `duration`.
struct Turn {
    angle: f64,
    start: f64,
    duration: f64,
}

impl Turn {
    fn at(&self, t: f64) -> UnitQuaternion<f64> {
        let u = ((t - self.start) / self.duration).clamp(0.0, 1.0);
        let ease = u * u * (3.0 - 2.0 * u);
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.angle * (1.0 - ease))
    }
}

/// A tilt of the standing device: `amp · sin²(π (t − start) / duration)` radians about `axis`
/// (frame axes).
struct Tilt {
    start: f64,
    duration: f64,
    axis: nalgebra::Unit<Vector3<f64>>,
    amp: f64,
}

impl Tilt {
    fn at(&self, t: f64) -> UnitQuaternion<f64> {
        let u = ((t - self.start) / self.duration).clamp(0.0, 1.0);
        UnitQuaternion::from_axis_angle(
            &self.axis,
            self.amp * (std::f64::consts::PI * u).sin().powi(2),
        )
    }
}

impl Timeline<'_> {
    /// The interval to the next sample instant (drawn once, then kept until it is taken).
    fn peek_dt(&mut self) -> f64 {
        if let Some(h) = self.pending_dt {
            return h;
        }
        // Sample instants are regular up to a small jitter, which the timestamps record.
        let h = self.dt * (1.0 + self.jitter * (self.rng.uniform() - 0.5));
        self.pending_dt = Some(h);
        h
    }

    fn next_t(&mut self) -> f64 {
        self.t += self.peek_dt();
        self.pending_dt = None;
        self.t
    }

    fn push(
        &mut self,
        q: UnitQuaternion<f64>,
        pos: Vector3<f64>,
        curve: Option<usize>,
        s: f64,
        standing: bool,
    ) {
        let t = self.next_t();
        self.script.states.push(State {
            t,
            q,
            pos,
            acc: Vector3::zeros(),
            omega: Vector3::zeros(),
            wheel: self.wheel,
            curve,
            s,
            standing,
        });
    }

    /// Stands at distance `s` of curve `c` for `d` seconds, with a small back-and-forth (one
    /// smooth oscillation that starts and ends at rest).
    fn stand(&mut self, p: &Param, c: Option<usize>, s: f64, d: f64, wobble: f64) {
        let start = self.t;
        let end = self.t + d;
        let base_wheel = self.wheel;
        let sign = if self.rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        while self.t + self.dt <= end {
            let u = (self.t - start) / d;
            let w = sign
                * wobble
                * (std::f64::consts::TAU * u).sin()
                * (std::f64::consts::PI * u).sin();
            let sw = (s + w).clamp(0.0, p.length());
            self.wheel = base_wheel + (sw - s);
            let next = self.t + self.dt;
            let tilt = self
                .tilt
                .as_ref()
                .map_or_else(UnitQuaternion::identity, |k| k.at(next));
            let turn = self
                .turn
                .as_ref()
                .map_or_else(UnitQuaternion::identity, |k| k.at(next));
            self.push(p.frame(sw) * tilt * turn, p.pos(sw), c, sw, true);
        }
        self.wheel = base_wheel;
    }

    /// If the device was put down turned, turns it in place to the curve's direction (standing
    /// at `s` of curve `c`) before it moves off.
    fn turn_in_place(&mut self, p: &Param, c: usize, s: f64, op: &OperatorParams) {
        if let Some(turn) = &mut self.turn {
            turn.start = self.t;
            self.stand(p, Some(c), s, op.turn_time + 0.1, op.stand_wobble);
        }
    }

    fn key(&mut self, k: u8) {
        self.script.keys.push((self.t, k));
    }

    /// Rolls along curve `c` from `s` to `target` with slowly varying speed; returns the new s.
    #[allow(clippy::too_many_arguments)]
    fn roll(
        &mut self,
        p: &Param,
        c: usize,
        mut s: f64,
        target: f64,
        op: &OperatorParams,
        period: f64,
        phase: f64,
    ) -> f64 {
        let from = s;
        while s < target {
            let v = op.speed
                * (1.0
                    + op.speed_variation * (std::f64::consts::TAU * self.t / period + phase).sin());
            let v = v.max(0.2 * op.speed);
            // Easing in and out of the nodes: no faster than a constant deceleration from the
            // mean speed over `stop_ramp` allows this close to either end (1 mm/s at least,
            // so that the node is reached).
            let v = if op.stop_ramp > 0.0 {
                let a = op.speed / op.stop_ramp;
                let ease = (2.0 * a * (s - from).min(target - s)).sqrt();
                v.min(ease.max(0.001))
            } else {
                v
            };
            // Over the sample's own interval: a step of the nominal interval at a jittered
            // instant would be a speed jittering by ±5 % from sample to sample (accelerations
            // of ±0.5 m/s² that no hand makes).
            let step = v * self.peek_dt();
            let ns = (s + step).min(target);
            self.wheel += ns - s;
            s = ns;
            self.push(p.frame_in(s), p.pos(s), Some(c), s, false);
        }
        s
    }

    /// Stands at the node, types its index and Enter, stands a moment (the hand tilting the
    /// device meanwhile, if `op` says so).
    fn type_index(&mut self, p: &Param, c: Option<usize>, s: f64, node: u32, op: &OperatorParams) {
        self.type_digits(p, c, s, node, op);
        self.key(b'\n');
        self.stand(p, c, s, op.pause_after_enter, op.stand_wobble);
        self.tilt = None;
    }

    /// [`Timeline::type_index`] up to its Enter.
    fn type_digits(&mut self, p: &Param, c: Option<usize>, s: f64, node: u32, op: &OperatorParams) {
        let digits = node.to_string().len() as f64;
        if op.typing_tilt_deg > 0.0 {
            let phi = self.rng.range(0.0, std::f64::consts::TAU);
            self.tilt = Some(Tilt {
                start: self.t,
                duration: op.pause_before_typing + digits * op.key_interval + op.pause_after_enter,
                axis: nalgebra::Unit::new_normalize(Vector3::new(phi.cos(), phi.sin(), 0.0)),
                amp: op.typing_tilt_deg.to_radians() * self.rng.range(0.75, 1.25),
            });
        }
        self.stand(p, c, s, op.pause_before_typing, op.stand_wobble);
        for d in node.to_string().bytes() {
            self.key(d);
            self.stand(p, c, s, op.key_interval, op.stand_wobble);
        }
    }
}

/// Performs the scan of `curves` in order; `rate_hz` is the device's sample rate, `jitter` the
/// relative jitter of its sample instants.
pub fn perform(
    curves: &[CurveSpec],
    op: &OperatorParams,
    rate_hz: f64,
    jitter: f64,
    rng: &mut Rng,
) -> Script {
    let mut tl = Timeline {
        script: Script::default(),
        t: 0.5,
        dt: 1.0 / rate_hz,
        jitter,
        wheel: 0.0,
        rng,
        tilt: None,
        turn: None,
        pending_dt: None,
    };
    let mut prev_end: Option<UnitQuaternion<f64>> = None;
    // The curves in scan order, then the rescan (its index typed first, no mistake made).
    let clean = OperatorParams {
        mistakes: Mistakes::default(),
        ..op.clone()
    };
    let rescan = op.mistakes.rescan.filter(|&c| c < curves.len());
    let order = (0..curves.len())
        .map(|c| (c, false))
        .chain(rescan.map(|c| (c, true)));
    for (ci, again) in order {
        let spec = &curves[ci];
        let op = if again { &clean } else { op };
        let p = Param::new(spec);
        // Put down turned about the normal (if the operator does so), turned in place later.
        let turn = if op.turn_in_place_deg > 0.0 {
            let sign = if tl.rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            let angle = sign * op.turn_in_place_deg.to_radians() * tl.rng.range(0.5, 1.5);
            Some(Turn {
                angle,
                start: f64::INFINITY,
                duration: op.turn_time,
            })
        } else {
            None
        };
        let start_q = p.frame(0.0)
            * turn
                .as_ref()
                .map_or_else(UnitQuaternion::identity, |k| k.at(0.0));
        tl.turn = turn;
        // Carry the device to the start (orientation slerps; the wheel does not turn).
        if let Some(q0) = prev_end {
            let n = (op.carry_time / tl.dt) as usize;
            for k in 1..=n {
                let u = k as f64 / n as f64;
                let u = u * u * (3.0 - 2.0 * u);
                let q = q0.slerp(&start_q, u);
                tl.push(q, p.pos(0.0), None, 0.0, false);
            }
        } else {
            tl.stand(&p, None, 0.0, 1.0, 0.0);
        }
        let phase = tl.rng.range(0.0, std::f64::consts::TAU);
        let period = tl.rng.range(3.0, 6.0);
        let start_key = spec.kind.key();
        if op.mistakes.cancel_and_rescan == Some(ci) && spec.tags.len() >= 2 {
            // A false start: first node, 40 % of the way, C, back to the start.
            tl.key(start_key);
            let node = spec.tags[0].1;
            tl.type_index(&p, Some(ci), 0.0, node, op);
            tl.turn_in_place(&p, ci, 0.0, op);
            let target = 0.4 * p.cum[spec.tags[1].0];
            let s = tl.roll(&p, ci, 0.0, target, op, period, phase);
            tl.stand(&p, Some(ci), s, 0.5, op.stand_wobble);
            tl.key(b'C');
            tl.stand(&p, None, s, 0.3, 0.0);
            let (q0, q1) = (p.frame(s), start_q);
            let n = (op.carry_time / tl.dt) as usize;
            for k in 1..=n {
                let u = k as f64 / n as f64;
                tl.push(
                    q0.slerp(&q1, u * u * (3.0 - 2.0 * u)),
                    p.pos(0.0),
                    None,
                    0.0,
                    false,
                );
            }
            if let Some(turn) = &mut tl.turn {
                turn.start = f64::INFINITY; // put down turned again
            }
        }
        if again {
            for d in ci.to_string().bytes() {
                tl.key(d);
                tl.stand(&p, None, 0.0, op.key_interval, 0.0);
            }
        }
        tl.key(start_key);
        let mut truth = CurveTruth {
            kind: spec.kind,
            tags: Vec::new(),
            enter_s: Vec::new(),
            length: p.length(),
        };
        let mut s = 0.0;
        for (k, &(pi, node)) in spec.tags.iter().enumerate() {
            s = tl.roll(&p, ci, s, p.cum[pi], op, period, phase);
            // At a corner: stand still, type, turn in place to the way on.
            let corner = p.corner_turn(pi);
            if op.mistakes.untagged.contains(&(ci, k))
                && k > 0
                && k + 1 < spec.tags.len()
                && corner.is_none()
            {
                tl.script.untagged.push((ci, node));
                continue;
            }
            let still = OperatorParams {
                stand_wobble: 0.0,
                ..op.clone()
            };
            let op = if let Some(angle) = corner {
                tl.turn = Some(Turn {
                    angle,
                    start: f64::INFINITY,
                    duration: op.turn_time,
                });
                &still
            } else {
                op
            };
            if op.mistakes.wrong_index == Some((ci, k)) {
                // A wrong index confirmed, noticed, undone.
                tl.type_index(&p, Some(ci), s, node + 1, op);
                tl.key(b'U');
                tl.stand(&p, Some(ci), s, op.key_interval, op.stand_wobble);
            }
            let typed = match op.mistakes.typed_instead {
                Some((c, t, other)) if (c, t) == (ci, k) => other,
                _ => node,
            };
            let late = match op.mistakes.late_enter {
                Some((c, t, m)) if (c, t) == (ci, k) && k + 1 < spec.tags.len() => {
                    Some(m.min(0.5 * (p.cum[spec.tags[k + 1].0] - s)))
                }
                _ => None,
            };
            let at = s;
            let mut enter_s = s;
            match late {
                None => tl.type_index(&p, Some(ci), s, typed, op),
                Some(m) => {
                    // The digits typed at the node, Enter once rolled `m` on.
                    tl.type_digits(&p, Some(ci), s, typed, op);
                    tl.tilt = None;
                    if k == 0 {
                        tl.turn_in_place(&p, ci, s, op);
                        tl.turn = None;
                    }
                    s = tl.roll(&p, ci, s, s + m, op, period, phase);
                    tl.key(b'\n');
                    enter_s = s;
                }
            }
            if late.is_none() && (k == 0 || corner.is_some()) {
                tl.turn_in_place(&p, ci, s, op);
                tl.turn = None;
            }
            truth.tags.push((
                node,
                at,
                tl.script.keys.last().map_or(tl.t, |k| k.0),
                tl.wheel,
            ));
            truth.enter_s.push(enter_s);
            if op.mistakes.repeated_index == Some((ci, k)) {
                tl.type_index(&p, Some(ci), s, node, op);
                tl.key(b'U');
                tl.stand(&p, Some(ci), s, op.key_interval, op.stand_wobble);
            }
            if k + 1 == spec.tags.len() {
                tl.key(b'E');
                tl.stand(&p, None, s, 0.3, 0.0);
            }
        }
        prev_end = Some(p.frame(p.length()));
        tl.script.curves.push(truth);
    }
    if let Some(c) = op.mistakes.drop_after {
        // Typed after the last sample: no sample and no random draw more, so the capture is
        // the one without the drop but for these keys at its end.
        let keys = c.to_string().into_bytes().into_iter().chain([b'C']);
        for (k, key) in keys.enumerate() {
            let t = tl.t + op.pause_before_typing + k as f64 * op.key_interval;
            tl.script.keys.push((t, key));
        }
    }
    let mut script = tl.script;
    differentiate(&mut script.states);
    script
}

/// Fills accelerations and angular velocities by finite differences (uneven spacing).
fn differentiate(st: &mut [State]) {
    let n = st.len();
    for i in 1..n.saturating_sub(1) {
        let (h1, h2) = (st[i].t - st[i - 1].t, st[i + 1].t - st[i].t);
        let (p0, p1, p2) = (st[i - 1].pos, st[i].pos, st[i + 1].pos);
        st[i].acc = 2.0 * (h1 * (p2 - p1) - h2 * (p1 - p0)) / (h1 * h2 * (h1 + h2));
    }
    for i in 0..n.saturating_sub(1) {
        let h = st[i + 1].t - st[i].t;
        let d = st[i].q.inverse() * st[i + 1].q;
        st[i].omega = d.scaled_axis() / h;
    }
}
