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
