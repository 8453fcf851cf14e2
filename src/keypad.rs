//! The keypad grammar of the wire format as a state machine.
//!
//! | key | meaning |
//! |---|---|
//! | `B` / `I` | start a curve on the boundary / in the interior |
//! | `K` / `G` | start a crease / a guide curve (interior; [`CurveKind`]) |
//! | `0`–`9` then Enter | tag the node with this index at the position of the Enter press |
//! | `U` | undo the operator's last Enter in the current curve (a tag, or a repeat of one) |
//! | `C` | cancel the current curve |
//! | `E` | end the current curve (it needs at least two tags) |
//! | no curve open: `0`–`9` then `C` | drop the accepted curve with this index (issue 49) |
//! | no curve open: `0`–`9` then `B`/`I`/`K`/`G` | start a curve that replaces the accepted curve with this index once it ends with `E` (issue 49) |
//!
//! A drop or a replacement needs its digits typed within [`DIGIT_TIMEOUT`] of the key that
//! follows them, and names a curve accepted and not dropped yet; a replacing curve that is
//! cancelled or discarded leaves the old one in place. Curve indices never change: a dropped
//! curve's index is not reused.
//!
//! Anything out of grammar yields a [`Warning`] naming the curve, the node and the device
//! time, and is handled without touching the other curves:
//! digits with no curve open that neither `C` nor a start key follows, and Enter with no
//! curve open, are ignored; Enter with no digits is ignored; digits
//! followed by another key are dropped; a repeated tag of the same node is ignored (and a `U`
//! after it undoes that repeat, not the tag before it); `U` with no tag and `C`/`E` with no
//! curve are ignored; `E` with fewer than two tags discards the
//! curve; a start key (`B`, `I`, `K`, `G`) while a curve is open ends it first (kept if it has two tags, else
//! discarded); an unknown key is ignored.
//!
//! The same node tagged twice in a row is a *repeat* (an Enter pressed again at the node) or a
//! *loop* (a closed curve through that one node, `B 1⏎ … 1⏎ E`): the keypad cannot tell them
//! apart by the keys, only by how far the device went between the two Enters. The caller
//! says so before each key with [`Keypad::set_travelled`] (acquisition measures it: the
//! wheel's advance on a Morphorider, the angle the phone turned through); without it a
//! repeated node is a repeat.
//!
//! Packets lost on the link ([`Keypad::link_gap`]) can take keys with them. Digits left
//! without their Enter after a loss are tagged at their last digit (the Enter is presumed
//! lost). An Enter with no digits after a loss means the index was lost but the operator did
//! tag a node there: the curve keeps the tag as an *anonymous* node (an index from
//! [`ANONYMOUS_NODE_BASE`] up, used by no other curve), so its segmentation, and the segment
//! lengths measured for it, stay right.
//!
//! ```
//! use sfs::keypad::{Keypad, KeyEvent};
//! let mut k = Keypad::new();
//! let mut ev = Vec::new();
//! for (t, key) in [(0.0, b'B'), (1.0, b'3'), (1.1, b'\n'), (5.0, b'4'), (5.1, b'\n'), (6.0, b'E')] {
//!     k.key(t, key, &mut ev);
//! }
//! assert!(matches!(ev.last(), Some(KeyEvent::Ended { curve: 0 })));
//! ```

/// Index of a curve in scan order, counting accepted curves (a cancelled curve's index is
/// reused by the next one).
pub type CurveIndex = usize;

/// A grammar violation: the curve open, the node concerned, the time of the key, and what
/// was wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    pub curve: Option<CurveIndex>,
    pub node: Option<u32>,
    /// Session time of the key, seconds.
    pub t: f64,
    pub issue: Issue,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.curve {
            Some(c) => write!(f, "curve {c}")?,
            None => write!(f, "no curve open")?,
        }
        if let Some(n) = self.node {
            write!(f, ", node {n}")?;
        }
        write!(f, ", t = {:.3} s: {}", self.t, self.issue)
    }
}

/// What a key sequence did wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Issue {
    /// Digits typed, then another key than Enter.
    Unconfirmed { digits: String, key: char },
    /// A curve ended (or was ended) with fewer than two node tags.
    TooFewTags { why: &'static str, tags: usize },
    /// Packets were lost after digits and no Enter came: the node is tagged at its last digit.
    EnterPresumedLost,
    /// Digits not confirmed within [`DIGIT_TIMEOUT`].
    TimedOut { digits: String },
    /// Digits with no curve open that no `C` or start key followed in time.
    DigitWithoutCurve { digits: String },
    /// A drop (`N C`) or replacement (`N B`…) names no curve accepted and not dropped.
    NoSuchCurve { curve: u64, key: char },
    /// A seventh digit: the index is not tagged.
    IndexTooLong { digits: String },
    /// An index above the configured maximum: not tagged.
    IndexAboveMax { max: u32 },
    /// Enter with no curve open.
    EnterWithoutCurve,
    /// Enter with no digits after packets were lost: tagged as an anonymous node.
    IndexLost,
    /// Enter with no digits.
    EnterWithoutIndex,
    /// The node just tagged, tagged again.
    Repeat,
    /// B or I while a curve is open: the open one is ended.
    NeverEnded { key: char },
    /// U with nothing to undo.
    UndoNothing,
    /// U with no curve open.
    UndoWithoutCurve,
    /// C with no curve open.
    CancelWithoutCurve,
    /// E with no curve open.
    EndWithoutCurve,
    /// A key the grammar does not know.
    UnknownKey { key: u8 },
}

impl Issue {
    /// A stable name of the kind of violation (for machines reading `report.json`).
    pub fn code(&self) -> &'static str {
        match self {
            Issue::Unconfirmed { .. } => "keypad_digits_unconfirmed",
            Issue::TooFewTags { .. } => "keypad_too_few_tags",
            Issue::EnterPresumedLost => "keypad_enter_presumed_lost",
            Issue::TimedOut { .. } => "keypad_digits_timed_out",
            Issue::DigitWithoutCurve { .. } => "keypad_digit_without_curve",
            Issue::NoSuchCurve { .. } => "keypad_no_such_curve",
            Issue::IndexTooLong { .. } => "keypad_index_too_long",
            Issue::IndexAboveMax { .. } => "keypad_index_above_max",
            Issue::EnterWithoutCurve => "keypad_enter_without_curve",
            Issue::IndexLost => "keypad_index_lost",
            Issue::EnterWithoutIndex => "keypad_enter_without_index",
            Issue::Repeat => "keypad_repeat",
            Issue::NeverEnded { .. } => "keypad_curve_never_ended",
            Issue::UndoNothing => "keypad_undo_nothing",
            Issue::UndoWithoutCurve => "keypad_undo_without_curve",
            Issue::CancelWithoutCurve => "keypad_cancel_without_curve",
            Issue::EndWithoutCurve => "keypad_end_without_curve",
            Issue::UnknownKey { .. } => "keypad_unknown_key",
        }
    }
}

impl std::fmt::Display for Issue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Issue::Unconfirmed { digits, key } => write!(
                f,
                "digits {digits:?} were not confirmed with Enter before {key:?}; ignored"
            ),
            Issue::TooFewTags { why, tags } => write!(
                f,
                "{why} with {tags} node tag(s); a curve needs a start and an end node: discarded"
            ),
            Issue::EnterPresumedLost => f.write_str("packets were lost after these digits and no Enter came: Enter presumed lost, node tagged at its last digit"),
            Issue::TimedOut { digits } => write!(
                f,
                "digits {digits:?} not confirmed with Enter within {DIGIT_TIMEOUT} s; ignored"
            ),
            Issue::DigitWithoutCurve { digits } => write!(
                f,
                "digits {digits:?} with no curve open, followed by neither C (drop that curve) nor a start key (rescan it) within {DIGIT_TIMEOUT} s; ignored"
            ),
            Issue::NoSuchCurve { curve, key } => write!(
                f,
                "{curve} {key}: no curve {curve} was accepted, or it is dropped already; {}",
                if *key == 'C' { "nothing dropped" } else { "a new curve is started, replacing none" }
            ),
            Issue::IndexTooLong { digits } => write!(
                f,
                "node index longer than 6 digits ({digits}…); ignored, no node tagged"
            ),
            Issue::IndexAboveMax { max } => write!(
                f,
                "node index above the configured maximum {max}; ignored, no node tagged"
            ),
            Issue::EnterWithoutCurve => f.write_str("Enter with no curve open; ignored"),
            Issue::IndexLost => f.write_str("Enter after packets were lost and with no digits: the node index was lost; tagged as an anonymous node that joins no other curve"),
            Issue::EnterWithoutIndex => f.write_str("Enter with no node index typed; ignored"),
            Issue::Repeat => f.write_str("node tagged twice in a row; the repeat is ignored"),
            Issue::NeverEnded { key } => write!(
                f,
                "curve never ended (no E) before {key:?} started the next one; ending it here"
            ),
            Issue::UndoNothing => f.write_str("U (undo) with no node tag to undo; ignored"),
            Issue::UndoWithoutCurve => f.write_str("U (undo) with no curve open; ignored"),
            Issue::CancelWithoutCurve => f.write_str("C (cancel) with no curve open; ignored"),
            Issue::EndWithoutCurve => f.write_str("E (end) with no curve open; ignored"),
            Issue::UnknownKey { key } => {
                write!(f, "unknown key 0x{key:02X} ({:?}); ignored", *key as char)
            }
        }
    }
}

/// What the keypad did.
#[derive(Debug, Clone, PartialEq)]
pub enum KeyEvent {
    Started {
        curve: CurveIndex,
        kind: CurveKind,
    },
    /// Node `node` tagged at time `t` (the Enter press). `uncertain`: packets were lost
    /// while it was typed, so a digit may be missing.
    Tagged {
        curve: CurveIndex,
        node: u32,
        t: f64,
        uncertain: bool,
    },
    Untagged {
        curve: CurveIndex,
        node: u32,
    },
    /// The curve is dropped (cancel, or not enough tags).
    Discarded {
        curve: CurveIndex,
    },
    /// The curve is complete.
    Ended {
        curve: CurveIndex,
    },
    /// An accepted curve leaves the network: dropped (`N C`), or replaced by curve `by` (`N B
    /// … E`), which has just ended.
    Dropped {
        curve: CurveIndex,
        by: Option<CurveIndex>,
    },
    Warning(Warning),
}

/// Largest node index accepted (six digits).
pub const MAX_NODE: u32 = 999_999;

/// Anonymous nodes (tags whose index was lost on the link) are numbered from
/// [`ANONYMOUS_NODE_BASE`] up, above every index the keypad accepts.
pub use sfs_geometry::curve::{is_anonymous, CurveKind, ANONYMOUS_NODE_BASE};
const _: () = assert!(MAX_NODE < ANONYMOUS_NODE_BASE);

#[derive(Debug, Clone)]
struct Open {
    curve: CurveIndex,
    tags: Vec<u32>,
    /// Repeats of the last tag not undone yet (Enters that re-tagged the node just tagged;
    /// `U` undoes them first, one per press).
    repeats: u64,
    /// The accepted curve this one replaces when it ends.
    replaces: Option<CurveIndex>,
}

/// The state machine. Feed it every KEY packet in order.
#[derive(Debug, Clone, Default)]
pub struct Keypad {
    open: Option<Open>,
    digits: String,
    accepted: CurveIndex,
    /// Time of the last digit typed, and whether packets were lost since.
    last_digit: f64,
    gap_since_digit: bool,
    /// Packets were lost since the last key, and when (session time of the last packet
    /// before the loss, as told by [`link_gap`](Self::link_gap)).
    gap_since_key: bool,
    gap_time: f64,
    /// Packets were lost while the pending digits were typed (or just before the first).
    digits_uncertain: bool,
    /// Anonymous nodes handed out so far.
    anonymous: u32,
    /// The index being typed passed six digits: it is not tagged (said once).
    overlong: bool,
    /// Largest node index accepted (`None`: [`MAX_NODE`]).
    max_node: Option<u32>,
    /// Digits typed with no curve open (a curve's index, if `C` or a start key follows), and
    /// the time of the last.
    pending: String,
    pending_t: f64,
    /// Accepted curves dropped or replaced.
    dropped: std::collections::BTreeSet<CurveIndex>,
    /// The Enter being processed was said with the digits before it.
    enter_said: bool,
    /// The device travelled far since the open curve's last tag (see
    /// [`set_travelled`](Keypad::set_travelled)).
    travelled: bool,
}

/// Digits not confirmed within this many seconds are stale (the operator moved on).
pub const DIGIT_TIMEOUT: f64 = 2.0;

impl Keypad {
    pub fn new() -> Self {
        Self::default()
    }

    /// A keypad that refuses node indices above `max` (at most [`MAX_NODE`]).
    pub fn with_max_node(max: u32) -> Self {
        Keypad {
            max_node: Some(max.min(MAX_NODE)),
            ..Self::default()
        }
    }

    /// Tells the keypad whether the device has travelled, since the open curve's last tag, far
    /// enough that tagging the same node again closes a loop through it (a closed curve with
    /// one node) rather than repeating the tag. Holds until changed; `false` by default (a
    /// caller that measures no travel gets repeats).
    pub fn set_travelled(&mut self, travelled: bool) {
        self.travelled = travelled;
    }

    /// Whether tagging `node` now would repeat the open curve's last tag (the same node, and
    /// the device has not travelled a loop since).
    fn is_repeat(&self, node: u32) -> bool {
        let open = self.open.as_ref().expect("checked by the caller");
        open.tags.last() == Some(&node) && !self.travelled
    }

    /// Adds a tag to the open curve (a new tag ends the repeats of the one before).
    fn push_tag(&mut self, node: u32) -> CurveIndex {
        let open = self.open.as_mut().expect("checked by the caller");
        open.tags.push(node);
        open.repeats = 0;
        open.curve
    }

    /// Index the next started curve will get.
    pub fn next_curve(&self) -> CurveIndex {
        self.accepted
    }

    /// The open curve, if any.
    pub fn open_curve(&self) -> Option<CurveIndex> {
        self.open.as_ref().map(|o| o.curve)
    }

    /// Tags of the open curve.
    pub fn open_tags(&self) -> &[u32] {
        self.open.as_ref().map_or(&[], |o| &o.tags)
    }

    fn warn(&self, out: &mut Vec<KeyEvent>, t: f64, node: Option<u32>, issue: Issue) {
        let w = Warning {
            curve: self.open_curve(),
            node,
            t,
            issue,
        };
        out.push(KeyEvent::Warning(w));
    }

    fn drop_digits(&mut self, t: f64, key: u8, out: &mut Vec<KeyEvent>) {
        if std::mem::take(&mut self.overlong) {
            self.digits.clear(); // said when the index became too long
        }
        if !self.digits.is_empty() {
            let d = std::mem::take(&mut self.digits);
            self.warn(
                out,
                t,
                d.parse().ok(),
                Issue::Unconfirmed {
                    digits: d,
                    key: key as char,
                },
            );
        }
    }

    /// Ends the open curve: kept with two tags or more, else discarded.
    fn finish(&mut self, t: f64, why: &'static str, out: &mut Vec<KeyEvent>) {
        let Some(open) = &self.open else { return };
        let curve = open.curve;
        if open.tags.len() >= 2 {
            let replaces = open.replaces;
            self.accepted += 1;
            self.open = None;
            out.push(KeyEvent::Ended { curve });
            if let Some(old) = replaces.filter(|&o| self.dropped.insert(o)) {
                out.push(KeyEvent::Dropped {
                    curve: old,
                    by: Some(curve),
                });
            }
        } else {
            let n = open.tags.len();
            let node = open.tags.first().copied();
            self.warn(out, t, node, Issue::TooFewTags { why, tags: n });
            self.open = None;
            out.push(KeyEvent::Discarded { curve });
        }
    }

    /// Ends the open curve as `E` would, for a reason of the caller's (`why`, in the warning
    /// if the curve has fewer than two tags): acquisition ends a curve that reached its
    /// largest size. Digits not confirmed are dropped. Nothing happens with no curve open.
    pub fn end_curve(&mut self, t: f64, why: &'static str, out: &mut Vec<KeyEvent>) {
        if self.open.is_some() {
            self.drop_digits(t, b'E', out);
            self.finish(t, why, out);
        }
    }

    /// Tells the keypad that packets were lost on the link (a sequence gap) after session
    /// time `t`: a key may be missing.
    pub fn link_gap(&mut self, t: f64) {
        self.gap_since_key = true;
        self.gap_time = t;
        if !self.digits.is_empty() {
            self.gap_since_digit = true;
        }
    }

    /// Digits still waiting for their Enter when a key arrives that cannot continue them: a
    /// digit more than [`DIGIT_TIMEOUT`] later, or any other key but Enter. If packets were lost
    /// since the digits, the Enter is presumed lost and the node tagged at the time of its last
    /// digit (the operator stood there typing); otherwise a late digit drops them (other keys
    /// drop them in [`key`](Self::key)).
    fn stale_digits(&mut self, t: f64, key: u8, out: &mut Vec<KeyEvent>) {
        if self.digits.is_empty() || key == b'\n' || key == b'\r' {
            return;
        }
        let late_digit = key.is_ascii_digit() && t - self.last_digit > DIGIT_TIMEOUT;
        let other_key = !key.is_ascii_digit();
        if !(late_digit || (other_key && self.gap_since_digit)) {
            return;
        }
        if std::mem::take(&mut self.overlong) {
            // An index too long is never tagged (said when it became too long).
            self.digits.clear();
            self.gap_since_digit = false;
            return;
        }
        let digits = std::mem::take(&mut self.digits);
        let node: u32 = digits.parse().expect("only digits, at most 6");
        let t_tag = self.last_digit;
        if self.gap_since_digit {
            self.gap_since_digit = false;
            if !self.is_repeat(node) {
                let curve = self.push_tag(node);
                self.warn(out, t_tag, Some(node), Issue::EnterPresumedLost);
                out.push(KeyEvent::Tagged {
                    curve,
                    node,
                    t: t_tag,
                    uncertain: true,
                });
            }
        } else {
            self.warn(
                out,
                t_tag,
                Some(node),
                Issue::TimedOut {
                    digits: digits.clone(),
                },
            );
        }
    }

    /// The curve index typed with no curve open, if `key` at `t` acts on it (`C` or a start
    /// key, within [`DIGIT_TIMEOUT`] of the last digit). Other keys, and late ones, leave the
    /// digits ignored (said); a digit in time continues them.
    fn curve_command(&mut self, t: f64, key: u8, out: &mut Vec<KeyEvent>) -> Option<u64> {
        if self.pending.is_empty() {
            return None;
        }
        let fresh = t - self.pending_t <= DIGIT_TIMEOUT;
        if key.is_ascii_digit() && fresh {
            return None;
        }
        let digits = std::mem::take(&mut self.pending);
        if fresh && matches!(key, b'C' | b'B' | b'I' | b'K' | b'G') {
            return digits.parse().ok();
        }
        // An Enter after them is said with them (once), at its own time.
        let at = if key == b'\n' || key == b'\r' {
            self.enter_said = true;
            t
        } else {
            self.pending_t
        };
        self.warn(out, at, None, Issue::DigitWithoutCurve { digits });
        None
    }

    /// At the end of the input: digits typed with no curve open and never acted on are said.
    pub fn flush(&mut self, out: &mut Vec<KeyEvent>) {
        if !self.pending.is_empty() {
            let digits = std::mem::take(&mut self.pending);
            self.warn(
                out,
                self.pending_t,
                None,
                Issue::DigitWithoutCurve { digits },
            );
        }
    }

    /// Whether `n` names a curve that can be dropped or replaced (accepted, not dropped).
    fn droppable(&self, n: u64) -> Option<CurveIndex> {
        let n = usize::try_from(n).ok()?;
        (n < self.accepted && !self.dropped.contains(&n)).then_some(n)
    }

    /// Processes one key pressed at session time `t`, appending what happened to `out`.
    pub fn key(&mut self, t: f64, key: u8, out: &mut Vec<KeyEvent>) {
        let gap_before = std::mem::take(&mut self.gap_since_key);
        let command = self.curve_command(t, key, out);
        self.stale_digits(t, key, out);
        if key.is_ascii_digit() && self.open.is_some() {
            if self.digits.is_empty() {
                self.gap_since_digit = false;
                // A loss shortly before the first digit may have taken a leading digit.
                self.digits_uncertain = gap_before && t - self.gap_time <= DIGIT_TIMEOUT;
            } else if gap_before {
                self.digits_uncertain = true; // a middle digit may be gone
            }
            self.last_digit = t;
        }
        match key {
            b'0'..=b'9' => {
                if self.open.is_none() {
                    // A curve's index, if C or a start key follows.
                    if self.pending.len() < 6 {
                        self.pending.push(key as char);
                    }
                    self.pending_t = t;
                } else if self.overlong {
                    // Said once for the index.
                } else if self.digits.len() >= 6 {
                    self.overlong = true;
                    self.warn(
                        out,
                        t,
                        None,
                        Issue::IndexTooLong {
                            digits: self.digits.clone(),
                        },
                    );
                } else {
                    self.digits.push(key as char);
                }
            }
            b'\n' | b'\r' => {
                self.gap_since_digit = false;
                let digits = std::mem::take(&mut self.digits);
                if self.open.is_none() {
                    if !std::mem::take(&mut self.enter_said) {
                        self.warn(out, t, digits.parse().ok(), Issue::EnterWithoutCurve);
                    }
                    return;
                }
                if std::mem::take(&mut self.overlong) {
                    return; // not tagged: said when the index became too long
                }
                if digits.is_empty() {
                    if gap_before {
                        let node = ANONYMOUS_NODE_BASE + self.anonymous;
                        self.anonymous += 1;
                        self.warn(out, t, Some(node), Issue::IndexLost);
                        let curve = self.push_tag(node);
                        out.push(KeyEvent::Tagged {
                            curve,
                            node,
                            t,
                            uncertain: false, // anonymous: joins nothing
                        });
                        return;
                    }
                    self.warn(out, t, None, Issue::EnterWithoutIndex);
                    return;
                }
                let node: u32 = digits.parse().expect("only digits, at most 6");
                let max = self.max_node.unwrap_or(MAX_NODE);
                if node > max {
                    self.warn(out, t, Some(node), Issue::IndexAboveMax { max });
                    return;
                }
                // A loss between the last digit and the Enter may have taken a digit too.
                let uncertain = std::mem::take(&mut self.digits_uncertain) || gap_before;
                if self.is_repeat(node) {
                    self.warn(out, t, Some(node), Issue::Repeat);
                    self.open.as_mut().expect("checked").repeats += 1;
                    return;
                }
                let curve = self.push_tag(node);
                out.push(KeyEvent::Tagged {
                    curve,
                    node,
                    t,
                    uncertain,
                });
            }
            b'B' | b'I' | b'K' | b'G' => {
                self.drop_digits(t, key, out);
                if self.open.is_some() {
                    self.warn(
                        out,
                        t,
                        self.open_tags().last().copied(),
                        Issue::NeverEnded { key: key as char },
                    );
                    self.finish(t, "ended implicitly", out);
                }
                let replaces = command.and_then(|n| {
                    let c = self.droppable(n);
                    if c.is_none() {
                        let issue = Issue::NoSuchCurve {
                            curve: n,
                            key: key as char,
                        };
                        self.warn(out, t, None, issue);
                    }
                    c
                });
                let curve = self.accepted;
                self.open = Some(Open {
                    curve,
                    tags: Vec::new(),
                    repeats: 0,
                    replaces,
                });
                out.push(KeyEvent::Started {
                    curve,
                    kind: CurveKind::of_key(key).unwrap_or_default(),
                });
            }
            b'U' => {
                self.drop_digits(t, key, out);
                match self.open.as_mut() {
                    // The last Enter repeated the tag before it: undo the repeat (already
                    // ignored), keep the tag.
                    Some(o) if o.repeats > 0 => o.repeats -= 1,
                    Some(o) => match o.tags.pop() {
                        Some(node) => out.push(KeyEvent::Untagged {
                            curve: o.curve,
                            node,
                        }),
                        None => self.warn(out, t, None, Issue::UndoNothing),
                    },
                    None => self.warn(out, t, None, Issue::UndoWithoutCurve),
                }
            }
            b'C' => {
                self.drop_digits(t, key, out);
                match (self.open.take(), command) {
                    (Some(o), _) => out.push(KeyEvent::Discarded { curve: o.curve }),
                    (None, Some(n)) => match self.droppable(n) {
                        Some(curve) => {
                            self.dropped.insert(curve);
                            out.push(KeyEvent::Dropped { curve, by: None });
                        }
                        None => {
                            let issue = Issue::NoSuchCurve { curve: n, key: 'C' };
                            self.warn(out, t, None, issue);
                        }
                    },
                    (None, None) => self.warn(out, t, None, Issue::CancelWithoutCurve),
                }
            }
            b'E' => {
                self.drop_digits(t, key, out);
                if self.open.is_none() {
                    self.warn(out, t, None, Issue::EndWithoutCurve);
                } else {
                    self.finish(t, "E pressed", out);
                }
            }
            other => {
                self.warn(out, t, None, Issue::UnknownKey { key: other });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(keys: &str) -> Vec<KeyEvent> {
        let mut k = Keypad::new();
        let mut out = Vec::new();
        for (i, c) in keys.bytes().enumerate() {
            k.key(i as f64, c, &mut out);
        }
        out
    }

    fn warnings(ev: &[KeyEvent]) -> Vec<&Warning> {
        ev.iter()
            .filter_map(|e| match e {
                KeyEvent::Warning(w) => Some(w),
                _ => None,
            })
            .collect()
    }

    fn ended(ev: &[KeyEvent]) -> Vec<CurveIndex> {
        ev.iter()
            .filter_map(|e| match e {
                KeyEvent::Ended { curve } => Some(*curve),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn well_formed_session() {
        let ev = run("B1\n2\n3\n1\nEI12\n0\n7\nE");
        assert!(warnings(&ev).is_empty(), "{ev:?}");
        assert_eq!(ended(&ev), [0, 1]);
        let tags: Vec<u32> = ev
            .iter()
            .filter_map(|e| match e {
                KeyEvent::Tagged { node, .. } => Some(*node),
                _ => None,
            })
            .collect();
        assert_eq!(tags, [1, 2, 3, 1, 12, 0, 7]);
        assert!(matches!(
            ev[0],
            KeyEvent::Started {
                curve: 0,
                kind: CurveKind::Boundary
            }
        ));
    }

    /// Issue 18: `K` starts a crease and `G` a guide curve; like `B`/`I`, a start key with a
    /// curve open ends it first (with the usual warning); the receiver before them reported
    /// them as unknown keys.
    #[test]
    fn issue_18_k_and_g_start_creases_and_guide_curves() {
        let ev = run("K1\n2\nEG2\n3\nI3\n1\nE");
        let started: Vec<(CurveIndex, CurveKind)> = ev
            .iter()
            .filter_map(|e| match e {
                KeyEvent::Started { curve, kind } => Some((*curve, *kind)),
                _ => None,
            })
            .collect();
        assert_eq!(
            started,
            [
                (0, CurveKind::Crease),
                (1, CurveKind::Guide),
                (2, CurveKind::Interior)
            ]
        );
        assert_eq!(ended(&ev), [0, 1, 2]);
        let w = warnings(&ev);
        assert_eq!(w.len(), 1, "{ev:?}");
        assert_eq!(w[0].curve, Some(1), "the guide curve never ended: {}", w[0]);
        assert!(!w
            .iter()
            .any(|w| matches!(w.issue, Issue::UnknownKey { .. })));
    }

    #[test]
    fn undo_and_cancel() {
        let ev = run("I1\n5\nU2\nEI3\nCI3\n4\nE");
        assert!(warnings(&ev).is_empty(), "{ev:?}");
        assert!(ev.contains(&KeyEvent::Untagged { curve: 0, node: 5 }));
        assert!(ev.contains(&KeyEvent::Discarded { curve: 1 }));
        // The cancelled curve's index is reused by the rescan.
        assert_eq!(ended(&ev), [0, 1]);
    }

    #[test]
    fn every_violation_warns_with_curve_node_and_time() {
        let cases: &[(&str, Option<usize>, &str)] = &[
            ("5\n", None, "with no curve open"),
            ("\n", None, "Enter with no curve open"),
            ("B\n", Some(0), "no node index"),
            ("B1\nE", Some(0), "needs a start and an end"),
            ("B1\n2\nI", Some(0), "never ended"),
            ("B1\n1\n", Some(0), "twice in a row"),
            ("BU", Some(0), "no node tag to undo"),
            ("U", None, "no curve open"),
            ("C", None, "no curve open"),
            ("E", None, "no curve open"),
            ("B1\n2\n12E", Some(0), "not confirmed with Enter"),
            ("BX", Some(0), "unknown key"),
        ];
        for (keys, curve, needle) in cases {
            let ev = run(keys);
            let w = warnings(&ev);
            assert_eq!(w.len(), 1, "{keys:?}: {ev:?}");
            assert_eq!(w[0].curve, *curve, "{keys:?}");
            assert!(w[0].to_string().contains(needle), "{keys:?}: {}", w[0]);
            assert_eq!(
                w[0].t,
                (keys.len() - 1) as f64,
                "{keys:?}: time of the offending key"
            );
        }
    }

    #[test]
    fn lost_enter_is_presumed_after_a_gap_and_stale_digits_dropped() {
        let mut k = Keypad::new();
        let mut out = Vec::new();
        for (t, c) in [
            (0.0, b'B'),
            (1.0, b'1'),
            (1.2, b'\n'),
            (5.0, b'1'),
            (5.2, b'6'),
        ] {
            k.key(t, c, &mut out);
        }
        k.link_gap(0.0); // the Enter after "16" was lost
        for (t, c) in [(9.0, b'8'), (9.2, b'\n'), (9.5, b'E')] {
            k.key(t, c, &mut out);
        }
        let tags: Vec<(u32, f64)> = out
            .iter()
            .filter_map(|e| match e {
                KeyEvent::Tagged { node, t, .. } => Some((*node, *t)),
                _ => None,
            })
            .collect();
        assert_eq!(tags, [(1, 1.2), (16, 5.2), (8, 9.2)]);
        assert_eq!(warnings(&out)[0].issue, Issue::EnterPresumedLost);
        // Without a gap, digits left for more than the timeout are dropped with a warning.
        let mut k = Keypad::new();
        let mut out = Vec::new();
        for (t, c) in [
            (0.0, b'B'),
            (1.0, b'1'),
            (1.1, b'\n'),
            (2.0, b'7'),
            (6.0, b'2'),
            (6.1, b'\n'),
            (7.0, b'E'),
        ] {
            k.key(t, c, &mut out);
        }
        let w = warnings(&out);
        assert_eq!(w.len(), 1, "{out:?}");
        assert!(matches!(w[0].issue, Issue::TimedOut { .. }) && w[0].node == Some(7));
        assert!(out.contains(&KeyEvent::Tagged {
            curve: 0,
            node: 2,
            t: 6.1,
            uncertain: false
        }));
        // A loss between two digits of one index (a sample packet) does not split the index.
        let mut k = Keypad::new();
        let mut out = Vec::new();
        for (t, c) in [(0.0, b'I'), (1.0, b'2')] {
            k.key(t, c, &mut out);
        }
        k.link_gap(0.0);
        for (t, c) in [(1.25, b'9'), (1.5, b'\n')] {
            k.key(t, c, &mut out);
        }
        assert!(
            out.contains(&KeyEvent::Tagged {
                curve: 0,
                node: 29,
                t: 1.5,
                uncertain: true
            }),
            "{out:?}"
        );
        assert!(warnings(&out).is_empty());
    }

    #[test]
    fn enter_after_a_loss_with_no_digits_tags_an_anonymous_node() {
        let mut k = Keypad::new();
        let mut out = Vec::new();
        for (t, c) in [(0.0, b'I'), (1.0, b'3'), (1.1, b'\n')] {
            k.key(t, c, &mut out);
        }
        k.link_gap(0.0); // the digit "4" was lost
        for (t, c) in [(5.1, b'\n'), (8.0, b'5'), (8.1, b'\n')] {
            k.key(t, c, &mut out);
        }
        k.link_gap(0.0); // a second lost index in the same curve gets its own node
        for (t, c) in [(9.1, b'\n'), (9.5, b'E')] {
            k.key(t, c, &mut out);
        }
        let tags: Vec<u32> = out
            .iter()
            .filter_map(|e| match e {
                KeyEvent::Tagged { node, .. } => Some(*node),
                _ => None,
            })
            .collect();
        assert_eq!(
            tags,
            [3, ANONYMOUS_NODE_BASE, 5, ANONYMOUS_NODE_BASE + 1],
            "{out:?}"
        );
        assert!(tags.iter().filter(|&&n| is_anonymous(n)).count() == 2);
        let w = warnings(&out);
        assert_eq!(w.len(), 2, "{out:?}");
        assert!(w[0].issue == Issue::IndexLost && w[0].curve == Some(0));
        assert_eq!(ended(&out), [0]);
        // Without a loss, an Enter with no digits is still ignored.
        let ev = run("I1\n\n2\nE");
        assert_eq!(warnings(&ev).len(), 1);
        assert!(!ev
            .iter()
            .any(|e| matches!(e, KeyEvent::Tagged { node, .. } if is_anonymous(*node))));
    }

    #[test]
    fn a_loss_while_an_index_is_typed_marks_the_tag_uncertain() {
        let tag = |gap: Option<f64>| {
            let mut k = Keypad::new();
            let mut out = Vec::new();
            for (t, c) in [(0.0, b'I'), (1.0, b'1'), (1.1, b'\n')] {
                k.key(t, c, &mut out);
            }
            if let Some(g) = gap {
                k.link_gap(g);
            }
            for (t, c) in [(5.0, b'9'), (5.1, b'\n')] {
                k.key(t, c, &mut out);
            }
            out.iter()
                .filter_map(|e| match e {
                    KeyEvent::Tagged {
                        node, uncertain, ..
                    } => Some((*node, *uncertain)),
                    _ => None,
                })
                .collect::<Vec<_>>()
        };
        // "29" lost its "2" just before the "9" arrived.
        assert_eq!(tag(Some(4.9)), [(1, false), (9, true)]);
        // A loss long before the typing started says nothing about the index.
        assert_eq!(tag(Some(1.5)), [(1, false), (9, false)]);
        assert_eq!(tag(None), [(1, false), (9, false)]);
    }

    #[test]
    fn implicit_end_keeps_a_complete_curve_and_violations_cost_no_other_curve() {
        let ev = run("B1\n2\nI2\n3\nE5B4\nEI4\n1\nE");
        assert_eq!(ended(&ev), [0, 1, 2]);
        assert!(ev.contains(&KeyEvent::Discarded { curve: 2 }));
        assert_eq!(warnings(&ev).len(), 3, "{ev:?}"); // no E, stray digit, E with one tag
    }

    fn tagged(ev: &[KeyEvent]) -> Vec<u32> {
        ev.iter()
            .filter_map(|e| match e {
                KeyEvent::Tagged { node, .. } => Some(*node),
                _ => None,
            })
            .collect()
    }

    /// Issue 15 point 2: an index longer than six digits is refused with one warning (a
    /// stuck key too) and no node is tagged (`1000000⏎` tagged node 100000).
    #[test]
    fn issue_15_an_index_longer_than_six_digits_tags_nothing() {
        for long in ["1000000".to_string(), "7".repeat(1000)] {
            let ev = run(&format!("B1\n{long}\n2\nE"));
            assert_eq!(tagged(&ev), [1, 2], "{}", &long[..7]);
            let w = warnings(&ev);
            assert_eq!(w.len(), 1, "{w:?}");
            assert!(matches!(w[0].issue, Issue::IndexTooLong { .. }), "{}", w[0]);
        }
        // Left unconfirmed, it goes stale quietly and the next index is whole again.
        let mut k = Keypad::new();
        let mut ev = Vec::new();
        let keys = [(0.0, b'B'), (1.0, b'1'), (2.0, b'\n')]
            .into_iter()
            .chain((0..8).map(|i| (3.0 + i as f64, b'1' + i as u8)))
            .chain([
                (13.0, b'3'),
                (14.0, b'\n'),
                (15.0, b'2'),
                (16.0, b'\n'),
                (17.0, b'E'),
            ]);
        for (t, c) in keys {
            k.key(t, c, &mut ev);
        }
        assert_eq!(tagged(&ev), [1, 3, 2]);
        assert_eq!(warnings(&ev).len(), 1, "{:?}", warnings(&ev));
    }

    /// Issue 15 point 2: an index above the configured maximum is refused, naming it.
    #[test]
    fn issue_15_an_index_above_the_configured_maximum_tags_nothing() {
        let mut k = Keypad::with_max_node(50);
        let mut ev = Vec::new();
        for (i, c) in "B1\n51\n50\nE".bytes().enumerate() {
            k.key(i as f64, c, &mut ev);
        }
        assert_eq!(tagged(&ev), [1, 50]);
        let w = warnings(&ev);
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].issue, Issue::IndexAboveMax { max: 50 });
        assert_eq!(w[0].node, Some(51));
    }

    /// Issue 15 point 1: `U` after an Enter that repeated the node before it undoes that
    /// repeat, not the tag (an operator typing the previous index again by mistake lost a
    /// correct node); each further `U` undoes the Enter before.
    #[test]
    fn issue_15_undo_after_a_repeated_tag_undoes_the_repeat() {
        let ev = run("B1\n2\n2\nU3\nE");
        assert_eq!(tagged(&ev), [1, 2, 3]);
        assert!(
            !ev.iter().any(|e| matches!(e, KeyEvent::Untagged { .. })),
            "{ev:?}"
        );
        let w = warnings(&ev);
        assert!(
            w.len() == 1 && w[0].issue == Issue::Repeat && w[0].node == Some(2),
            "{w:?}"
        );
        assert_eq!(ended(&ev), [0]);
        // Two repeats, three undos: both repeats, then the tag of node 2.
        let mut k = Keypad::new();
        let mut ev = Vec::new();
        for (i, c) in "B1\n2\n2\n2\nUUU".bytes().enumerate() {
            k.key(i as f64, c, &mut ev);
        }
        assert_eq!(k.open_tags(), [1]);
        assert_eq!(
            ev.iter()
                .filter(|e| matches!(e, KeyEvent::Untagged { node: 2, .. }))
                .count(),
            1
        );
        // A tag after a repeat ends it: U then undoes the new tag.
        let ev = run("B1\n2\n2\n3\nU4\nE");
        assert_eq!(tagged(&ev), [1, 2, 3, 4]);
        assert!(ev.contains(&KeyEvent::Untagged { curve: 0, node: 3 }));
    }

    /// Issue 15 point 1: a closed curve through a single node (`B 1⏎ … 1⏎ E`) is a curve, not
    /// a repeat, when the device travelled the loop between the two Enters.
    #[test]
    fn issue_15_a_loop_through_one_node_is_a_closed_curve() {
        let keys = |travelled: bool| {
            let mut k = Keypad::new();
            let mut ev = Vec::new();
            for (i, c) in "B1\n".bytes().enumerate() {
                k.key(i as f64, c, &mut ev);
            }
            k.set_travelled(travelled);
            for (i, c) in "1\nE".bytes().enumerate() {
                k.key(10.0 + i as f64, c, &mut ev);
            }
            ev
        };
        let ev = keys(true);
        assert_eq!(tagged(&ev), [1, 1]);
        assert!(warnings(&ev).is_empty(), "{ev:?}");
        assert_eq!(ended(&ev), [0]);
        // Standing at the node, the same keys are a repeat and the curve has one tag.
        let ev = keys(false);
        assert_eq!(tagged(&ev), [1]);
        assert!(ev.contains(&KeyEvent::Discarded { curve: 0 }));
    }

    fn dropped(ev: &[KeyEvent]) -> Vec<(CurveIndex, Option<CurveIndex>)> {
        ev.iter()
            .filter_map(|e| match e {
                KeyEvent::Dropped { curve, by } => Some((*curve, *by)),
                _ => None,
            })
            .collect()
    }

    fn codes(ev: &[KeyEvent]) -> Vec<&'static str> {
        warnings(ev).iter().map(|w| w.issue.code()).collect()
    }

    /// Issue 49 point 4: with no curve open, a curve's number then `C` drops it; then a start
    /// key starts the curve that replaces it, which takes the old one out when it ends. Indices
    /// are never reused.
    #[test]
    fn issue_49_a_curve_dropped_or_rescanned_from_the_keypad() {
        // Drop curve 0.
        let ev = run("B1\n2\nEI2\n3\nE0C");
        assert_eq!(ended(&ev), [0, 1]);
        assert_eq!(dropped(&ev), [(0, None)]);
        assert!(warnings(&ev).is_empty(), "{ev:?}");
        // Rescan curve 1: it leaves when the new one (curve 2) ends, not before.
        let ev = run("B1\n2\nEI2\n3\nE1I2\n3\nE");
        assert_eq!(ended(&ev), [0, 1, 2]);
        assert_eq!(dropped(&ev), [(1, Some(2))]);
        let at = |e: &KeyEvent| ev.iter().position(|x| x == e).unwrap();
        assert!(
            at(&KeyEvent::Ended { curve: 2 })
                < at(&KeyEvent::Dropped {
                    curve: 1,
                    by: Some(2)
                })
        );
        assert!(warnings(&ev).is_empty(), "{ev:?}");
        // Two-digit indices.
        let keys: String = (0..11).map(|_| "B1\n2\nE").collect::<String>() + "10C";
        assert_eq!(dropped(&run(&keys)), [(10, None)]);
        // A rescan cancelled, or discarded, leaves the old curve in.
        let ev = run("B1\n2\nE0B1\nC0B1\nE");
        assert_eq!(dropped(&ev), []);
        assert_eq!(ended(&ev), [0]);
        // No such curve: not accepted yet, or dropped already; the start key still starts.
        let ev = run("B1\n2\nE3C0C0C0B1\n2\nE");
        assert_eq!(dropped(&ev), [(0, None)]);
        assert_eq!(
            codes(&ev),
            [
                "keypad_no_such_curve",
                "keypad_no_such_curve",
                "keypad_no_such_curve"
            ]
        );
        assert_eq!(ended(&ev), [0, 1]);
    }

    /// Digits with no curve open that no `C` or start key follows in time are ignored, said
    /// once with the digits; a drop needs its digits within the timeout.
    #[test]
    fn issue_49_digits_with_no_curve_open_act_only_in_time() {
        let mut k = Keypad::new();
        let mut ev = Vec::new();
        for (t, key) in [
            (0.0, b'B'),
            (1.0, b'1'),
            (1.1, b'\n'),
            (2.0, b'2'),
            (2.1, b'\n'),
        ] {
            k.key(t, key, &mut ev);
        }
        for (t, key) in [
            (3.0, b'E'),
            (4.0, b'0'),
            (9.0, b'C'),
            (10.0, b'4'),
            (10.5, b'\n'),
        ] {
            k.key(t, key, &mut ev);
        }
        assert_eq!(dropped(&ev), []);
        assert_eq!(
            codes(&ev),
            [
                "keypad_digit_without_curve",
                "keypad_cancel_without_curve",
                "keypad_digit_without_curve",
            ]
        );
        let w = warnings(&ev);
        assert_eq!(w[0].t, 4.0);
        assert!(w[0].to_string().contains("\"0\""), "{}", w[0]);
    }
}
