//! Incremental streaming decoder: feed byte chunks of any size, get packets and link events.
//!
//! ```
//! use device_protocol::{Decoder, Event, Key, Packet, Reject};
//! let mut wire = Vec::new();
//! Packet::Key(Key { t_us: 5, key: b'E' }).encode(0, &mut wire);
//! wire.extend_from_slice(&[0x07, 0x99, 0x00]); // garbage, then a delimiter
//! Packet::Key(Key { t_us: 6, key: b'B' }).encode(1, &mut wire);
//!
//! let mut dec = Decoder::new();
//! let mut events = Vec::new();
//! for chunk in wire.chunks(3) {
//!     events.extend(dec.feed(chunk)); // a partial frame yields nothing yet
//! }
//! assert!(matches!(events[0], Event::Packet { seq: 0, .. }));
//! assert!(matches!(events[1], Event::Rejected { reason: Reject::Cobs, .. }));
//! assert!(matches!(events[2], Event::Packet { seq: 1, .. }));
//! ```
//!
//! The decoder allocates nothing after construction: a frame that lies wholly inside the chunk
//! is decoded in place, a frame split across chunks is gathered in a fixed buffer.

use crate::cobs;
use crate::crc::crc16;
use crate::packet::{Packet, PacketType, FRAME_OVERHEAD};

/// Longest decoded frame accepted (type, seq, payload, crc). Version 1 needs 36 bytes; the
/// margin lets a later version's longer packets be skipped as unknown types rather than
/// counted as errors.
pub const MAX_FRAME: usize = 512;
/// Longest encoded frame accepted (without the delimiter).
pub const MAX_ENCODED_FRAME: usize = cobs::max_encoded_len(MAX_FRAME);

/// A clock jump from near the top of the `u32` microsecond range to near zero is taken as a
/// wrap of the device clock when the forward difference is at most this (60 s). A backwards
/// jump that is not such a wrap is a device restart.
pub const WRAP_WINDOW_US: u32 = 60_000_000;

/// Why a frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    /// The COBS encoding is malformed.
    Cobs,
    /// The CRC does not match.
    Crc { computed: u16, received: u16 },
    /// The frame is shorter than type + seq + crc (4 bytes).
    TooShort,
    /// The frame is longer than [`MAX_ENCODED_FRAME`]; its bytes were discarded up to the
    /// next delimiter.
    TooLong,
    /// The payload length does not match the (known) type.
    Length { packet_type: PacketType, len: usize },
}

impl Reject {
    /// The statistics bucket of this reason: `"crc"`, `"cobs"` or `"length"`.
    pub fn bucket(&self) -> &'static str {
        match self {
            Reject::Cobs => "cobs",
            Reject::Crc { .. } => "crc",
            Reject::TooShort | Reject::TooLong | Reject::Length { .. } => "length",
        }
    }
}

/// What the decoder reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A valid packet.
    Packet { seq: u8, packet: Packet },
    /// A frame was dropped; `bytes` is its encoded length (without delimiter).
    Rejected { reason: Reject, bytes: usize },
    /// A frame with a valid CRC but a type this version does not define: skipped.
    UnknownType {
        packet_type: u8,
        seq: u8,
        payload_len: usize,
    },
    /// `lost` packets are missing before the packet that follows this event (sequence gap).
    SequenceGap { lost: u8 },
    /// The device restarted: its clock went back (after a HELLO, or with the HELLO lost).
    /// Reported before the first timestamped packet of the new run.
    DeviceReboot,
    /// The device's 32-bit microsecond clock wrapped. Reported before the first packet after
    /// the wrap.
    ClockWrap,
    /// Bytes before the first delimiter that did not form a valid frame: the stream was joined
    /// in the middle of a packet. Not an error.
    PartialStart { bytes: usize },
}

/// Small fixed queue of pending events (a frame yields at most three).
#[derive(Debug, Clone, Copy)]
struct Queue {
    ev: [Option<Event>; 4],
    head: usize,
    len: usize,
}

impl Queue {
    const fn new() -> Self {
        Queue {
            ev: [None; 4],
            head: 0,
            len: 0,
        }
    }
    #[inline]
    fn push(&mut self, e: Event) {
        debug_assert!(self.len < self.ev.len());
        self.ev[(self.head + self.len) % 4] = Some(e);
        self.len += 1;
    }
    #[inline]
    fn pop(&mut self) -> Option<Event> {
        if self.len == 0 {
            return None;
        }
        let e = self.ev[self.head].take();
        self.head = (self.head + 1) % 4;
        self.len -= 1;
        e
    }
}

/// Sequence and clock tracking, and the queue of events of the frame being processed.
#[derive(Debug, Clone)]
struct Link {
    queue: Queue,
    at_start: bool,
    last_seq: Option<u8>,
    /// A HELLO arrived with a sequence gap: held until the next timestamp says whether the
    /// device restarted (then the gap is not a loss).
    pending_gap: Option<u8>,
    last_t: Option<u32>,
    hello_since_t: bool,
}

/// The streaming decoder. See the module documentation.
#[derive(Debug, Clone)]
pub struct Decoder {
    /// Encoded bytes of a frame split across chunks.
    partial: Box<[u8; MAX_ENCODED_FRAME]>,
    partial_len: usize,
    /// The current frame overflowed: discard until the next delimiter.
    overflow: bool,
    /// Decoded frame.
    raw: Box<[u8; MAX_ENCODED_FRAME]>,
    link: Link,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Decoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        Decoder {
            partial: Box::new([0; MAX_ENCODED_FRAME]),
            partial_len: 0,
            overflow: false,
            raw: Box::new([0; MAX_ENCODED_FRAME]),
            link: Link {
                queue: Queue::new(),
                at_start: true,
                last_seq: None,
                pending_gap: None,
                last_t: None,
                hello_since_t: false,
            },
        }
    }

    /// Returns an iterator over the events completed by `bytes`. Bytes not consumed when the
    /// iterator is dropped early stay unread, so drain it.
    pub fn feed<'a>(&'a mut self, bytes: &'a [u8]) -> Feed<'a> {
        Feed { dec: self, bytes }
    }

    /// Decodes from the front of `input`, advancing it, until one event is ready; `None` when
    /// `input` is exhausted (a partial frame stays buffered: that is not an error).
    pub fn next_event(&mut self, input: &mut &[u8]) -> Option<Event> {
        loop {
            if let Some(e) = self.link.queue.pop() {
                return Some(e);
            }
            if input.is_empty() {
                return None;
            }
            match memchr0(input) {
                Some(pos) => {
                    let frame = &input[..pos];
                    *input = &input[pos + 1..];
                    if self.partial_len == 0 && !self.overflow {
                        self.link.frame(frame, &mut self.raw);
                    } else {
                        self.append(frame);
                        let n = std::mem::replace(&mut self.partial_len, 0);
                        if std::mem::replace(&mut self.overflow, false) {
                            self.link.reject(Reject::TooLong, n);
                        } else {
                            self.link.frame(&self.partial[..n], &mut self.raw);
                        }
                    }
                    self.link.at_start = false;
                }
                None => {
                    self.append(input);
                    *input = &[];
                }
            }
        }
    }

    /// Bytes of an unfinished frame held since the last delimiter.
    pub fn buffered(&self) -> usize {
        self.partial_len
    }

    fn append(&mut self, bytes: &[u8]) {
        let end = self.partial_len.saturating_add(bytes.len());
        if !self.overflow && end > MAX_ENCODED_FRAME {
            self.overflow = true;
        }
        if !self.overflow {
            self.partial[self.partial_len..end].copy_from_slice(bytes);
        }
        self.partial_len = end;
    }
}

impl Link {
    fn reject(&mut self, reason: Reject, bytes: usize) {
        if self.at_start {
            self.queue.push(Event::PartialStart { bytes });
        } else {
            self.queue.push(Event::Rejected { reason, bytes });
        }
    }

    /// Processes one encoded frame (delimiter stripped).
    #[inline]
    fn frame(&mut self, enc: &[u8], raw: &mut [u8; MAX_ENCODED_FRAME]) {
        if enc.is_empty() {
            return; // consecutive delimiters: idle line or an explicit resync
        }
        if enc.len() > MAX_ENCODED_FRAME {
            return self.reject(Reject::TooLong, enc.len());
        }
        let n = match cobs::decode(enc, &mut raw[..]) {
            Ok(n) => n,
            Err(_) => return self.reject(Reject::Cobs, enc.len()),
        };
        if n < FRAME_OVERHEAD {
            return self.reject(Reject::TooShort, enc.len());
        }
        let (body, crc) = raw[..n].split_at(n - 2);
        let received = u16::from_le_bytes([crc[0], crc[1]]);
        let computed = crc16(body);
        if computed != received {
            return self.reject(Reject::Crc { computed, received }, enc.len());
        }
        let (code, seq, payload) = (body[0], body[1], &body[2..]);
        let Some(ty) = PacketType::from_code(code) else {
            self.sequence(seq, false);
            self.queue.push(Event::UnknownType {
                packet_type: code,
                seq,
                payload_len: payload.len(),
            });
            return;
        };
        if payload.len() != ty.payload_len() {
            // The CRC is valid, so the sender did send this frame and it took a seq number.
            self.reject(
                Reject::Length {
                    packet_type: ty,
                    len: payload.len(),
                },
                enc.len(),
            );
            self.sequence(seq, false);
            return;
        }
        let packet = Packet::parse(ty, payload);
        let hello = ty == PacketType::Hello;
        self.sequence(seq, hello);
        if hello {
            self.hello_since_t = true;
        } else if let Some(t) = packet.t_us() {
            self.clock(t);
        }
        self.queue.push(Event::Packet { seq, packet });
    }

    #[inline]
    fn sequence(&mut self, seq: u8, hello: bool) {
        if let Some(last) = self.last_seq {
            let lost = seq.wrapping_sub(last).wrapping_sub(1);
            if lost != 0 {
                if hello {
                    // An earlier HELLO's gap still unresolved is taken as a loss.
                    self.flush_gap();
                    self.pending_gap = Some(lost);
                } else {
                    // A pending HELLO gap stays pending: the clock of this packet decides it.
                    self.queue.push(Event::SequenceGap { lost });
                }
            }
        }
        self.last_seq = Some(seq);
    }

    fn flush_gap(&mut self) {
        if let Some(lost) = self.pending_gap.take() {
            self.queue.push(Event::SequenceGap { lost });
        }
    }

    #[inline]
    fn clock(&mut self, t: u32) {
        if let Some(last) = self.last_t {
            if t < last {
                let forward = t.wrapping_sub(last);
                let wrap = forward <= WRAP_WINDOW_US && last > u32::MAX - WRAP_WINDOW_US;
                if wrap && !self.hello_since_t {
                    self.flush_gap();
                    self.queue.push(Event::ClockWrap);
                } else {
                    // The device restarted: its sequence restarted too, so a gap held at the
                    // HELLO is not a loss.
                    self.pending_gap = None;
                    self.queue.push(Event::DeviceReboot);
                }
            }
        }
        self.flush_gap();
        self.last_t = Some(t);
        self.hello_since_t = false;
    }
}

/// Iterator returned by [`Decoder::feed`].
pub struct Feed<'a> {
    dec: &'a mut Decoder,
    bytes: &'a [u8],
}

impl Iterator for Feed<'_> {
    type Item = Event;
    #[inline]
    fn next(&mut self) -> Option<Event> {
        self.dec.next_event(&mut self.bytes)
    }
}

#[inline]
fn memchr0(s: &[u8]) -> Option<usize> {
    s.iter().position(|&b| b == 0)
}
