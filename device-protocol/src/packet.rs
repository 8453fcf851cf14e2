//! The packets of wire format version 1 as Rust types, and their encoder.
//!
//! ```
//! use device_protocol::{Decoder, Event, Key, Packet};
//! let mut wire = Vec::new();
//! Packet::Key(Key { t_us: 1_000, key: b'B' }).encode(7, &mut wire);
//! let mut dec = Decoder::new();
//! let events: Vec<Event> = dec.feed(&wire).collect();
//! assert_eq!(events, [Event::Packet { seq: 7, packet: Packet::Key(Key { t_us: 1_000, key: b'B' }) }]);
//! ```

use crate::{cobs, crc16};

/// Protocol version announced in HELLO by every device speaking this format.
pub const PROTOCOL_VERSION: u8 = 1;

/// Longest payload of a version-1 packet (HELLO).
pub const MAX_PAYLOAD: usize = 32;

/// Bytes of a frame before COBS besides the payload: type, seq and the two CRC bytes.
pub const FRAME_OVERHEAD: usize = 4;

/// The kind of device, as announced in HELLO.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    /// Mouse-like device rolled on the surface: accelerometer, magnetometer, wheel encoder.
    Morphorider,
    /// Phone app slid on the surface: accelerometer, gyroscope, magnetometer.
    Phone,
    /// Fixed sensors (accelerometer + magnetometer each) on an instrumented structure.
    SensorArray,
    /// A code this version does not define; kept so that nothing is lost.
    Other(u8),
}

impl DeviceKind {
    /// The wire code of the kind.
    pub fn code(self) -> u8 {
        match self {
            DeviceKind::Morphorider => 1,
            DeviceKind::Phone => 2,
            DeviceKind::SensorArray => 3,
            DeviceKind::Other(c) => c,
        }
    }

    /// The kinds this version defines.
    pub const KNOWN: [DeviceKind; 3] = [
        DeviceKind::Morphorider,
        DeviceKind::Phone,
        DeviceKind::SensorArray,
    ];

    /// Its name in reports, truth files and on the command line (`"unknown"` for a code this
    /// version does not define): the one table of the kinds' names.
    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Morphorider => "morphorider",
            DeviceKind::Phone => "phone",
            DeviceKind::SensorArray => "array",
            DeviceKind::Other(_) => "unknown",
        }
    }

    /// The defined kind of that name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::KNOWN.into_iter().find(|k| k.name() == name)
    }

    /// The kind of a wire code.
    pub fn from_code(code: u8) -> Self {
        match code {
            1 => DeviceKind::Morphorider,
            2 => DeviceKind::Phone,
            3 => DeviceKind::SensorArray,
            c => DeviceKind::Other(c),
        }
    }
}

/// The name, with the code of a kind this version does not define: `unknown(9)`.
impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeviceKind::Other(c) => write!(f, "unknown({c})"),
            k => f.write_str(k.name()),
        }
    }
}

/// Packet type codes of version 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum PacketType {
    Hello = 0x01,
    RiderSample = 0x10,
    PhoneSample = 0x11,
    ArraySample = 0x12,
    Key = 0x20,
    SegmentLength = 0x21,
    Status = 0x30,
}

impl PacketType {
    /// All types of version 1, in code order.
    pub const ALL: [PacketType; 7] = [
        PacketType::Hello,
        PacketType::RiderSample,
        PacketType::PhoneSample,
        PacketType::ArraySample,
        PacketType::Key,
        PacketType::SegmentLength,
        PacketType::Status,
    ];

    /// The type of a wire code, or `None` for a code version 1 does not define.
    #[inline]
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0x01 => PacketType::Hello,
            0x10 => PacketType::RiderSample,
            0x11 => PacketType::PhoneSample,
            0x12 => PacketType::ArraySample,
            0x20 => PacketType::Key,
            0x21 => PacketType::SegmentLength,
            0x30 => PacketType::Status,
            _ => return None,
        })
    }

    /// The wire code.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The name used in the wire-format document (`"RIDER_SAMPLE"`, …).
    pub fn name(self) -> &'static str {
        match self {
            PacketType::Hello => "HELLO",
            PacketType::RiderSample => "RIDER_SAMPLE",
            PacketType::PhoneSample => "PHONE_SAMPLE",
            PacketType::ArraySample => "ARRAY_SAMPLE",
            PacketType::Key => "KEY",
            PacketType::SegmentLength => "SEGMENT_LENGTH",
            PacketType::Status => "STATUS",
        }
    }

    /// Exact payload length of this type, in bytes.
    pub fn payload_len(self) -> usize {
        match self {
            PacketType::Hello => 32,
            PacketType::RiderSample => 20,
            PacketType::PhoneSample => 22,
            PacketType::ArraySample => 18,
            PacketType::Key => 5,
            PacketType::SegmentLength => 10,
            PacketType::Status => 12,
        }
    }
}

/// HELLO (0x01): sent at power-up and every 5 s. Scales convert raw counts to SI-like units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hello {
    /// Protocol version; 1 for this format.
    pub proto: u8,
    pub kind: DeviceKind,
    pub device_id: u32,
    pub firmware: u16,
    /// Nominal sample rate. Never use it as the sample interval: timestamps are measured.
    pub rate_hz: u16,
    /// m/s² per LSB.
    pub acc_scale: f32,
    /// rad/s per LSB; 0 if the device has no gyroscope.
    pub gyro_scale: f32,
    /// µT per LSB.
    pub mag_scale: f32,
    /// Encoder ticks per wheel revolution; 0 if there is no wheel.
    pub ticks_per_rev: u32,
    /// Wheel circumference in micrometres; 0 if there is no wheel.
    pub wheel_circumference_um: u32,
    /// Number of sensors (sensor arrays), else 1 or 0.
    pub sensors: u16,
}

/// RIDER_SAMPLE (0x10): one Morphorider sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RiderSample {
    pub t_us: u32,
    pub acc: [i16; 3],
    pub mag: [i16; 3],
    /// Cumulative signed encoder ticks since power-up.
    pub wheel: i32,
}

/// PHONE_SAMPLE (0x11): one phone sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhoneSample {
    pub t_us: u32,
    pub acc: [i16; 3],
    pub gyro: [i16; 3],
    pub mag: [i16; 3],
}

/// ARRAY_SAMPLE (0x12): one sample of one sensor of an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArraySample {
    pub t_us: u32,
    pub sensor: u16,
    pub acc: [i16; 3],
    pub mag: [i16; 3],
}

/// KEY (0x20): a key press on the keypad, ASCII (`B I 0-9 \n U C E`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Key {
    pub t_us: u32,
    pub key: u8,
}

/// SEGMENT_LENGTH (0x21): measured length of a segment of the current (or last) curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentLength {
    pub t_us: u32,
    /// 0-based, in order of travel.
    pub segment: u16,
    pub length_um: u32,
}

/// STATUS (0x30): device health.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    pub t_us: u32,
    pub battery_mv: u16,
    /// bit 0 accelerometer saturated, bit 1 magnetometer saturated, bit 2 device buffer overflow.
    pub flags: u16,
    /// Samples the device itself dropped since power-up.
    pub dropped: u32,
}

impl Status {
    pub const ACC_SATURATED: u16 = 1 << 0;
    pub const MAG_SATURATED: u16 = 1 << 1;
    pub const BUFFER_OVERFLOW: u16 = 1 << 2;
}

/// Any packet of version 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Packet {
    Hello(Hello),
    RiderSample(RiderSample),
    PhoneSample(PhoneSample),
    ArraySample(ArraySample),
    Key(Key),
    SegmentLength(SegmentLength),
    Status(Status),
}

/// Little-endian reader over a payload of already checked length.
struct Rd<'a>(&'a [u8]);

impl Rd<'_> {
    #[inline]
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let (h, t) = self.0.split_at(N);
        self.0 = t;
        h.try_into().expect("length checked by caller")
    }
    #[inline]
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    #[inline]
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    #[inline]
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    #[inline]
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take())
    }
    #[inline]
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    #[inline]
    fn v3(&mut self) -> [i16; 3] {
        let b: [u8; 6] = self.take();
        [
            i16::from_le_bytes([b[0], b[1]]),
            i16::from_le_bytes([b[2], b[3]]),
            i16::from_le_bytes([b[4], b[5]]),
        ]
    }
}

/// Little-endian writer into a fixed payload buffer.
struct Wr<'a> {
    buf: &'a mut [u8; MAX_PAYLOAD],
    n: usize,
}

impl Wr<'_> {
    fn put(&mut self, b: &[u8]) {
        self.buf[self.n..self.n + b.len()].copy_from_slice(b);
        self.n += b.len();
    }
    fn v3(&mut self, v: [i16; 3]) {
        for x in v {
            self.put(&x.to_le_bytes());
        }
    }
}

impl Packet {
    /// The type of this packet.
    pub fn packet_type(&self) -> PacketType {
        match self {
            Packet::Hello(_) => PacketType::Hello,
            Packet::RiderSample(_) => PacketType::RiderSample,
            Packet::PhoneSample(_) => PacketType::PhoneSample,
            Packet::ArraySample(_) => PacketType::ArraySample,
            Packet::Key(_) => PacketType::Key,
            Packet::SegmentLength(_) => PacketType::SegmentLength,
            Packet::Status(_) => PacketType::Status,
        }
    }

    /// The device timestamp, for every packet but HELLO.
    pub fn t_us(&self) -> Option<u32> {
        match self {
            Packet::Hello(_) => None,
            Packet::RiderSample(p) => Some(p.t_us),
            Packet::PhoneSample(p) => Some(p.t_us),
            Packet::ArraySample(p) => Some(p.t_us),
            Packet::Key(p) => Some(p.t_us),
            Packet::SegmentLength(p) => Some(p.t_us),
            Packet::Status(p) => Some(p.t_us),
        }
    }

    /// Parses a payload whose length the caller has checked against `ty.payload_len()`.
    #[inline]
    pub(crate) fn parse(ty: PacketType, payload: &[u8]) -> Packet {
        debug_assert_eq!(payload.len(), ty.payload_len());
        let mut r = Rd(payload);
        match ty {
            PacketType::Hello => Packet::Hello(Hello {
                proto: r.u8(),
                kind: DeviceKind::from_code(r.u8()),
                device_id: r.u32(),
                firmware: r.u16(),
                rate_hz: r.u16(),
                acc_scale: r.f32(),
                gyro_scale: r.f32(),
                mag_scale: r.f32(),
                ticks_per_rev: r.u32(),
                wheel_circumference_um: r.u32(),
                sensors: r.u16(),
            }),
            PacketType::RiderSample => Packet::RiderSample(RiderSample {
                t_us: r.u32(),
                acc: r.v3(),
                mag: r.v3(),
                wheel: r.i32(),
            }),
            PacketType::PhoneSample => Packet::PhoneSample(PhoneSample {
                t_us: r.u32(),
                acc: r.v3(),
                gyro: r.v3(),
                mag: r.v3(),
            }),
            PacketType::ArraySample => Packet::ArraySample(ArraySample {
                t_us: r.u32(),
                sensor: r.u16(),
                acc: r.v3(),
                mag: r.v3(),
            }),
            PacketType::Key => Packet::Key(Key {
                t_us: r.u32(),
                key: r.u8(),
            }),
            PacketType::SegmentLength => Packet::SegmentLength(SegmentLength {
                t_us: r.u32(),
                segment: r.u16(),
                length_um: r.u32(),
            }),
            PacketType::Status => Packet::Status(Status {
                t_us: r.u32(),
                battery_mv: r.u16(),
                flags: r.u16(),
                dropped: r.u32(),
            }),
        }
    }

    /// Writes the payload (after type and seq) into `buf` and returns its length.
    pub fn write_payload(&self, buf: &mut [u8; MAX_PAYLOAD]) -> usize {
        let mut w = Wr { buf, n: 0 };
        match *self {
            Packet::Hello(h) => {
                w.put(&[h.proto, h.kind.code()]);
                w.put(&h.device_id.to_le_bytes());
                w.put(&h.firmware.to_le_bytes());
                w.put(&h.rate_hz.to_le_bytes());
                w.put(&h.acc_scale.to_le_bytes());
                w.put(&h.gyro_scale.to_le_bytes());
                w.put(&h.mag_scale.to_le_bytes());
                w.put(&h.ticks_per_rev.to_le_bytes());
                w.put(&h.wheel_circumference_um.to_le_bytes());
                w.put(&h.sensors.to_le_bytes());
            }
            Packet::RiderSample(s) => {
                w.put(&s.t_us.to_le_bytes());
                w.v3(s.acc);
                w.v3(s.mag);
                w.put(&s.wheel.to_le_bytes());
            }
            Packet::PhoneSample(s) => {
                w.put(&s.t_us.to_le_bytes());
                w.v3(s.acc);
                w.v3(s.gyro);
                w.v3(s.mag);
            }
            Packet::ArraySample(s) => {
                w.put(&s.t_us.to_le_bytes());
                w.put(&s.sensor.to_le_bytes());
                w.v3(s.acc);
                w.v3(s.mag);
            }
            Packet::Key(k) => {
                w.put(&k.t_us.to_le_bytes());
                w.put(&[k.key]);
            }
            Packet::SegmentLength(s) => {
                w.put(&s.t_us.to_le_bytes());
                w.put(&s.segment.to_le_bytes());
                w.put(&s.length_um.to_le_bytes());
            }
            Packet::Status(s) => {
                w.put(&s.t_us.to_le_bytes());
                w.put(&s.battery_mv.to_le_bytes());
                w.put(&s.flags.to_le_bytes());
                w.put(&s.dropped.to_le_bytes());
            }
        }
        debug_assert_eq!(w.n, self.packet_type().payload_len());
        w.n
    }

    /// Appends the complete wire frame of this packet with sequence number `seq` to `out`:
    /// COBS of `type, seq, payload, crc` followed by the `0x00` delimiter.
    pub fn encode(&self, seq: u8, out: &mut Vec<u8>) {
        let mut payload = [0u8; MAX_PAYLOAD];
        let n = self.write_payload(&mut payload);
        encode_frame(self.packet_type().code(), seq, &payload[..n], out);
    }
}

/// Appends a wire frame of any type code and payload to `out` (COBS, then `0x00`). Used for
/// [`Packet::encode`], and by tests and simulators to produce types this version does not know.
pub fn encode_frame(packet_type: u8, seq: u8, payload: &[u8], out: &mut Vec<u8>) {
    let mut raw = Vec::with_capacity(payload.len() + FRAME_OVERHEAD);
    raw.push(packet_type);
    raw.push(seq);
    raw.extend_from_slice(payload);
    let crc = crc16(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    cobs::encode(&raw, out);
    out.push(0);
}
