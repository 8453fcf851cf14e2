//! Link statistics: what the decoder saw, per packet type and per kind of fault.
//!
//! Serialised as the `"link"` object of `report.json`:
//! ```json
//! { "bytes": 1234, "packets": { "RIDER_SAMPLE": 12000, "KEY": 40, ... },
//!   "rejected": { "crc": 1, "cobs": 0, "length": 0 }, "unknown_types": 0,
//!   "lost_packets": 3, "reboots": 0, "clock_wraps": 0, "partial_start_bytes": 0,
//!   "partial_end_bytes": 0,
//!   "connects": 1, "disconnects": 0, "hello": { ... }, "status": { ... } }
//! ```

use device_protocol::{Event, Hello, Packet, PacketType, Reject, Status};
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};

/// Counters of one session's link. All counts are since the session started.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LinkStats {
    /// Bytes received (live) or read (replay).
    pub bytes: u64,
    /// Valid packets per wire-format name.
    pub packets: PacketCounts,
    /// Frames dropped, by reason.
    pub rejected: Rejected,
    /// Frames with a valid CRC and a type version 1 does not define (skipped).
    pub unknown_types: u64,
    /// Packets the device sent that never arrived, from sequence gaps (includes rejected ones).
    pub lost_packets: u64,
    /// Device restarts seen in the stream.
    pub reboots: u64,
    /// Wraps of the device's 32-bit microsecond clock.
    pub clock_wraps: u64,
    /// Bytes before the first delimiter that did not form a frame (joined mid-packet).
    pub partial_start_bytes: u64,
    /// Bytes after the last delimiter when the stream ended inside a frame (a capture cut
    /// mid-packet): set when the session ends.
    pub partial_end_bytes: u64,
    /// Times the source (re)connected, and lost the device.
    pub connects: u64,
    pub disconnects: u64,
    /// The last HELLO.
    pub hello: Option<HelloInfo>,
    /// The device's last STATUS.
    pub status: Option<StatusInfo>,
}

/// Per-type packet counts, indexed by [`PacketType::ALL`]; serialised as a map by name.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PacketCounts(pub [u64; PacketType::ALL.len()]);

impl PacketCounts {
    #[inline]
    fn index(t: PacketType) -> usize {
        match t {
            PacketType::Hello => 0,
            PacketType::RiderSample => 1,
            PacketType::PhoneSample => 2,
            PacketType::ArraySample => 3,
            PacketType::Key => 4,
            PacketType::SegmentLength => 5,
            PacketType::Status => 6,
        }
    }

    /// Count of packets of type `t`.
    pub fn get(&self, t: PacketType) -> u64 {
        self.0[Self::index(t)]
    }

    /// All valid packets.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }

    /// `(wire-format name, count)` of every type, in [`PacketType::ALL`] order.
    pub fn by_name(&self) -> Vec<(&'static str, u64)> {
        PacketType::ALL
            .iter()
            .map(|&t| (t.name(), self.get(t)))
            .collect()
    }
}

impl Serialize for PacketCounts {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(PacketType::ALL.len()))?;
        for t in PacketType::ALL {
            m.serialize_entry(t.name(), &self.get(t))?;
        }
        m.end()
    }
}

/// Rejected frames by the buckets of the report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Rejected {
    pub crc: u64,
    pub cobs: u64,
    /// Wrong payload length for the type, shorter than a header, or longer than any frame.
    pub length: u64,
}

impl Rejected {
    pub fn total(&self) -> u64 {
        self.crc + self.cobs + self.length
    }

    /// `(reason, count)` of every reason.
    pub fn by_reason(&self) -> [(&'static str, u64); 3] {
        [
            ("crc", self.crc),
            ("cobs", self.cobs),
            ("length", self.length),
        ]
    }
}

/// The HELLO fields a reader of the report wants.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HelloInfo {
    pub proto: u8,
    pub kind: &'static str,
    pub kind_code: u8,
    pub device_id: u32,
    pub firmware: u16,
    pub rate_hz: u16,
    pub acc_scale: f32,
    pub gyro_scale: f32,
    pub mag_scale: f32,
    pub ticks_per_rev: u32,
    pub wheel_circumference_um: u32,
    pub sensors: u16,
}

impl From<&Hello> for HelloInfo {
    fn from(h: &Hello) -> Self {
        HelloInfo {
            proto: h.proto,
            kind: h.kind.name(),
            kind_code: h.kind.code(),
            device_id: h.device_id,
            firmware: h.firmware,
            rate_hz: h.rate_hz,
            acc_scale: h.acc_scale,
            gyro_scale: h.gyro_scale,
            mag_scale: h.mag_scale,
            ticks_per_rev: h.ticks_per_rev,
            wheel_circumference_um: h.wheel_circumference_um,
            sensors: h.sensors,
        }
    }
}

/// The device's last STATUS, with its flags spelled out.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StatusInfo {
    pub t_us: u32,
    pub battery_mv: u16,
    pub flags: u16,
    pub flag_names: Vec<&'static str>,
    pub dropped: u32,
}

impl From<&Status> for StatusInfo {
    fn from(s: &Status) -> Self {
        let names = [
            (Status::ACC_SATURATED, "accelerometer_saturated"),
            (Status::MAG_SATURATED, "magnetometer_saturated"),
            (Status::BUFFER_OVERFLOW, "buffer_overflow"),
        ];
        StatusInfo {
            t_us: s.t_us,
            battery_mv: s.battery_mv,
            flags: s.flags,
            flag_names: names
                .iter()
                .filter(|(bit, _)| s.flags & bit != 0)
                .map(|(_, n)| *n)
                .collect(),
            dropped: s.dropped,
        }
    }
}

impl LinkStats {
    /// Accounts for one decoder event, and logs the ones an operator should see.
    #[inline]
    pub fn observe(&mut self, ev: &Event) {
        match ev {
            Event::Packet { packet, .. } => {
                self.packets.0[PacketCounts::index(packet.packet_type())] += 1;
                match packet {
                    Packet::Hello(h) => {
                        let first = self.hello.is_none();
                        let info = HelloInfo::from(h);
                        if first || self.hello.as_ref() != Some(&info) {
                            tracing::info!(
                                kind = info.kind,
                                device_id = h.device_id,
                                firmware = h.firmware,
                                rate_hz = h.rate_hz,
                                proto = h.proto,
                                "device HELLO"
                            );
                            if h.proto != device_protocol::PROTOCOL_VERSION {
                                tracing::warn!(
                                    proto = h.proto,
                                    "device announces a protocol version other than 1"
                                );
                            }
                        }
                        self.hello = Some(info);
                    }
                    Packet::Status(s) => {
                        let info = StatusInfo::from(s);
                        if info.flags != self.status.as_ref().map_or(0, |p| p.flags) {
                            tracing::warn!(flags = ?info.flag_names, battery_mv = s.battery_mv,
                                dropped = s.dropped, "device STATUS flags changed");
                        }
                        self.status = Some(info);
                    }
                    _ => {}
                }
            }
            Event::Rejected { reason, bytes } => {
                match reason {
                    Reject::Crc { .. } => self.rejected.crc += 1,
                    Reject::Cobs => self.rejected.cobs += 1,
                    Reject::TooShort | Reject::TooLong | Reject::Length { .. } => {
                        self.rejected.length += 1
                    }
                }
                tracing::debug!(?reason, bytes, "frame rejected");
            }
            Event::UnknownType {
                packet_type,
                payload_len,
                ..
            } => {
                self.unknown_types += 1;
                tracing::debug!(packet_type, payload_len, "unknown packet type skipped");
            }
            Event::SequenceGap { lost } => {
                self.lost_packets += *lost as u64;
                tracing::debug!(lost, "sequence gap");
            }
            Event::DeviceReboot => {
                self.reboots += 1;
                tracing::warn!("device rebooted");
            }
            Event::ClockWrap => {
                self.clock_wraps += 1;
                tracing::info!("device clock wrapped");
            }
            Event::PartialStart { bytes } => {
                self.partial_start_bytes += *bytes as u64;
                tracing::debug!(bytes, "stream joined mid-packet");
            }
        }
    }
}

/// How long a connected link may stay without a byte before it is `silent` (at least; five
/// sample periods of the device's HELLO rate when that is longer).
pub const SILENT_AFTER: std::time::Duration = std::time::Duration::from_secs(1);
/// How long a serial port may be connected without one valid frame before it is named as no
/// sfs device ([`LinkState::problem`]).
pub const UNHEARD_AFTER: std::time::Duration = std::time::Duration::from_secs(10);

/// The link's state as it happens: `/status` `link.state` and the fields beside it, and the
/// `sfs_link_up` gauge.
///
/// `connecting` (nothing yet), `connected`, `silent` (connected, no byte for
/// [`SILENT_AFTER`]), `disconnected` (lost; a serial port is reopened), `reconnecting`
/// (reopening failed `attempt` times), `ended` (the source finished).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LinkState {
    pub state: &'static str,
    /// When the state began (for `silent`: the last byte; for `reconnecting`: the loss), Unix
    /// time in ms.
    pub since_unix_ms: Option<u64>,
    /// For how long, s.
    pub for_s: Option<f64>,
    /// Failed attempts to reopen the port, while `reconnecting`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub attempt: Option<u64>,
    /// Why the link was lost, or why reopening fails.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// What is wrong with the port itself: nothing heard on it, or bytes but no valid frame,
    /// for [`UNHEARD_AFTER`] (with `sfs ports --probe` suggested).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub problem: Option<String>,
}

impl LinkState {
    /// Whether the device is connected (`sfs_link_up`): `connected` or `silent`.
    pub fn up(&self) -> bool {
        matches!(self.state, "connected" | "silent")
    }
}

/// Follows the source's events and the bytes to say what the link is doing now
/// ([`LinkState`]). Time is given, so that it is tested without waiting.
#[derive(Debug, Clone)]
pub struct LinkTracker {
    state: &'static str,
    since: std::time::Instant,
    last_byte: Option<std::time::Instant>,
    attempt: Option<u64>,
    reason: Option<String>,
    /// The port's name when the source is a serial port (the only source whose bytes may come
    /// from something other than an sfs device).
    port: Option<String>,
    first_connected: Option<std::time::Instant>,
    problem: Option<String>,
}

impl LinkTracker {
    /// A link not connected yet; `port` names a serial port (checked for a device that is no
    /// sfs device).
    pub fn new(now: std::time::Instant, port: Option<String>) -> LinkTracker {
        LinkTracker {
            state: "connecting",
            since: now,
            last_byte: None,
            attempt: None,
            reason: None,
            port,
            first_connected: None,
            problem: None,
        }
    }

    pub fn connected(&mut self, now: std::time::Instant) {
        self.set("connected", now);
        self.first_connected.get_or_insert(now);
        self.last_byte = None;
    }

    pub fn disconnected(&mut self, now: std::time::Instant, reason: &str) {
        self.set("disconnected", now);
        self.reason = Some(reason.to_owned());
    }

    /// Reopening failed for the `attempt`-th time since the loss.
    pub fn reconnecting(&mut self, now: std::time::Instant, attempt: u64, error: &str) {
        if self.state != "reconnecting" && self.state != "disconnected" {
            self.since = now;
        }
        self.state = "reconnecting";
        self.attempt = Some(attempt);
        self.reason = Some(error.to_owned());
    }

    /// Bytes arrived (a source that never says `Connected`, a replay or standard input, is
    /// connected by its first bytes).
    pub fn bytes(&mut self, now: std::time::Instant) {
        if self.state == "connecting" {
            self.connected(now);
        }
        if self.state == "silent" {
            self.state = "connected";
            self.since = now;
        }
        self.last_byte = Some(now);
    }

    pub fn ended(&mut self, now: std::time::Instant) {
        self.set("ended", now);
    }

    fn set(&mut self, state: &'static str, now: std::time::Instant) {
        self.state = state;
        self.since = now;
        self.attempt = None;
        self.reason = None;
    }

    /// Moves time on to `now`: a connected link without bytes turns `silent`; a serial port
    /// connected for [`UNHEARD_AFTER`] without a valid frame is named. Returns the problem when
    /// it is new (for the log), and logs when it is gone.
    pub fn tick(&mut self, now: std::time::Instant, stats: &LinkStats) -> Option<String> {
        let silent_after = stats
            .hello
            .as_ref()
            .filter(|h| h.rate_hz > 0)
            .map_or(SILENT_AFTER, |h| {
                SILENT_AFTER.max(std::time::Duration::from_secs_f64(5.0 / h.rate_hz as f64))
            });
        if self.state == "connected" {
            let last = self.last_byte.unwrap_or(self.since);
            if now.saturating_duration_since(last) >= silent_after {
                self.state = "silent";
                self.since = last;
            }
        }
        if stats.packets.total() > 0 {
            if self.problem.take().is_some() {
                tracing::info!(
                    port = self.port.as_deref(),
                    "valid frames now come from the port"
                );
            }
            return None;
        }
        let (Some(port), Some(first)) = (&self.port, self.first_connected) else {
            return None;
        };
        if self.problem.is_some() || now.saturating_duration_since(first) < UNHEARD_AFTER {
            return None;
        }
        let secs = UNHEARD_AFTER.as_secs();
        let problem = if stats.bytes == 0 {
            format!("no byte from {port} in {secs} s: no sfs device was heard there (is it the device's port, and is the device on? `sfs ports --probe` says which ports speak this protocol)")
        } else {
            format!("{} bytes from {port} in {secs} s but no valid frame: not an sfs device, or a wrong baud rate (`sfs ports --probe` says which ports speak this protocol)", stats.bytes)
        };
        self.problem = Some(problem.clone());
        Some(problem)
    }

    /// The state now; `now_unix_ms` is the wall clock at `now`.
    pub fn state(&self, now: std::time::Instant, now_unix_ms: u64) -> LinkState {
        let age = now.saturating_duration_since(self.since);
        LinkState {
            state: self.state,
            since_unix_ms: Some(now_unix_ms.saturating_sub(age.as_millis() as u64)),
            for_s: Some((age.as_secs_f64() * 10.0).round() / 10.0),
            attempt: self.attempt,
            reason: self.reason.clone(),
            problem: self.problem.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn frames(n: u64) -> LinkStats {
        let mut s = LinkStats::default();
        s.packets.0[1] = n;
        s.bytes = 30 * n;
        s
    }

    #[test]
    fn a_link_goes_silent_then_lost_then_reconnecting_then_back() {
        let t0 = Instant::now();
        let mut l = LinkTracker::new(t0, Some("/dev/ttyUSB0".into()));
        assert_eq!(l.state(t0, 0).state, "connecting");
        assert!(!l.state(t0, 0).up());
        l.connected(t0);
        l.bytes(t0 + Duration::from_millis(100));
        assert_eq!(l.tick(t0 + Duration::from_millis(500), &frames(10)), None);
        assert_eq!(l.state(t0, 0).state, "connected");
        // No byte for a second: silent since the last byte, still up.
        l.tick(t0 + Duration::from_millis(1200), &frames(10));
        let s = l.state(t0 + Duration::from_millis(1200), 10_000);
        assert_eq!((s.state, s.up()), ("silent", true));
        assert_eq!(s.since_unix_ms, Some(10_000 - 1100));
        assert_eq!(s.for_s, Some(1.1));
        let lost = t0 + Duration::from_secs(3);
        l.disconnected(lost, "read error");
        assert!(!l.state(lost, 0).up());
        l.reconnecting(lost + Duration::from_millis(100), 1, "No such file");
        l.reconnecting(lost + Duration::from_millis(300), 2, "No such file");
        let s = l.state(lost + Duration::from_secs(1), 50_000);
        assert_eq!((s.state, s.attempt), ("reconnecting", Some(2)));
        // Since the loss, not since the last attempt.
        assert_eq!(s.since_unix_ms, Some(49_000));
        l.connected(lost + Duration::from_secs(2));
        l.bytes(lost + Duration::from_secs(2));
        let s = l.state(lost + Duration::from_secs(2), 0);
        assert_eq!((s.state, s.attempt, s.reason), ("connected", None, None));
    }

    #[test]
    fn a_port_that_never_sends_a_frame_is_named_once() {
        let t0 = Instant::now();
        let mut l = LinkTracker::new(t0, Some("/dev/ttyS0".into()));
        l.connected(t0);
        assert_eq!(
            l.tick(t0 + Duration::from_secs(9), &LinkStats::default()),
            None
        );
        let p = l
            .tick(t0 + Duration::from_secs(10), &LinkStats::default())
            .unwrap();
        assert!(
            p.contains("no byte from /dev/ttyS0") && p.contains("sfs ports --probe"),
            "{p}"
        );
        assert_eq!(
            l.tick(t0 + Duration::from_secs(11), &LinkStats::default()),
            None
        );
        assert_eq!(l.state(t0, 0).problem, Some(p));
        // Bytes that are no frame.
        let mut l = LinkTracker::new(t0, Some("/dev/ttyS0".into()));
        l.connected(t0);
        let noise = LinkStats {
            bytes: 512,
            ..LinkStats::default()
        };
        let p = l.tick(t0 + Duration::from_secs(10), &noise).unwrap();
        assert!(
            p.contains("512 bytes") && p.contains("no valid frame"),
            "{p}"
        );
        // A frame clears it.
        assert_eq!(l.tick(t0 + Duration::from_secs(12), &frames(1)), None);
        assert_eq!(l.state(t0, 0).problem, None);
        // Not a serial port: never named.
        let mut l = LinkTracker::new(t0, None);
        l.connected(t0);
        assert_eq!(
            l.tick(t0 + Duration::from_secs(60), &LinkStats::default()),
            None
        );
    }
}
