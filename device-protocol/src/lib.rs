//! Wire format version 1 of the sfs acquisition devices (Morphorider, phone, sensor array).
//!
//! - [`packet`]: every packet as a Rust type, and the encoder ([`Packet::encode`]).
//! - [`decoder`]: the incremental streaming decoder ([`Decoder`]) and its [`Event`]s.
//! - [`cobs`], [`crc`]: the framing (COBS, `0x00` delimiter) and the CRC-16/CCITT-FALSE.
//!
//! The format itself is restated in this crate's README.
//!
//! ```
//! use device_protocol::{Decoder, Event, Packet, Status};
//! let status = Packet::Status(Status { t_us: 42, battery_mv: 3900, flags: 0, dropped: 0 });
//! let mut wire = Vec::new();
//! status.encode(200, &mut wire);
//! let mut dec = Decoder::new();
//! let got: Vec<_> = dec.feed(&wire).collect();
//! assert_eq!(got, [Event::Packet { seq: 200, packet: status }]);
//! ```

pub mod cobs;
pub mod crc;
pub mod decoder;
pub mod packet;

pub use crc::crc16;
pub use decoder::{Decoder, Event, Feed, Reject};
pub use packet::{
    encode_frame, ArraySample, DeviceKind, Hello, Key, Packet, PacketType, PhoneSample,
    RiderSample, SegmentLength, Status, MAX_PAYLOAD, PROTOCOL_VERSION,
};
