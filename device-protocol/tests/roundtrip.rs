//! Property tests of the wire format: encode → decode over arbitrary packets split at
//! arbitrary chunk boundaries, garbage never panics, the decoder recovers at the next delimiter.

use device_protocol::*;
use proptest::prelude::*;

fn finite_f32() -> impl Strategy<Value = f32> {
    prop_oneof![Just(0.0f32), -1.0e6f32..1.0e6f32]
}

fn v3() -> impl Strategy<Value = [i16; 3]> {
    any::<[i16; 3]>()
}

fn packet() -> impl Strategy<Value = Packet> {
    prop_oneof![
        (
            any::<u8>(),
            any::<u8>(),
            any::<u32>(),
            any::<u16>(),
            any::<u16>(),
            (finite_f32(), finite_f32(), finite_f32()),
            (any::<u32>(), any::<u32>(), any::<u16>())
        )
            .prop_map(|(proto, kind, device_id, firmware, rate_hz, s, w)| {
                Packet::Hello(Hello {
                    proto,
                    kind: DeviceKind::from_code(kind),
                    device_id,
                    firmware,
                    rate_hz,
                    acc_scale: s.0,
                    gyro_scale: s.1,
                    mag_scale: s.2,
                    ticks_per_rev: w.0,
                    wheel_circumference_um: w.1,
                    sensors: w.2,
                })
            }),
        (any::<u32>(), v3(), v3(), any::<i32>()).prop_map(|(t_us, acc, mag, wheel)| {
            Packet::RiderSample(RiderSample {
                t_us,
                acc,
                mag,
                wheel,
            })
        }),
        (any::<u32>(), v3(), v3(), v3()).prop_map(|(t_us, acc, gyro, mag)| {
            Packet::PhoneSample(PhoneSample {
                t_us,
                acc,
                gyro,
                mag,
            })
        }),
        (any::<u32>(), any::<u16>(), v3(), v3()).prop_map(|(t_us, sensor, acc, mag)| {
            Packet::ArraySample(ArraySample {
                t_us,
                sensor,
                acc,
                mag,
            })
        }),
        (any::<u32>(), any::<u8>()).prop_map(|(t_us, key)| Packet::Key(Key { t_us, key })),
        (any::<u32>(), any::<u16>(), any::<u32>()).prop_map(|(t_us, segment, length_um)| {
            Packet::SegmentLength(SegmentLength {
                t_us,
                segment,
                length_um,
            })
        }),
        (any::<u32>(), any::<u16>(), any::<u16>(), any::<u32>()).prop_map(
            |(t_us, battery_mv, flags, dropped)| Packet::Status(Status {
                t_us,
                battery_mv,
                flags,
                dropped,
            })
        ),
    ]
}

/// Splits `bytes` at the given cut points (taken modulo the length) and feeds the chunks.
fn feed_chunked(dec: &mut Decoder, bytes: &[u8], cuts: &[usize]) -> Vec<Event> {
    let mut cuts: Vec<usize> = cuts
        .iter()
        .map(|c| c % (bytes.len() + 1))
        .chain([0, bytes.len()])
        .collect();
    cuts.sort_unstable();
    let mut events = Vec::new();
    for w in cuts.windows(2) {
        events.extend(dec.feed(&bytes[w[0]..w[1]]));
    }
    events
}

fn packets_of(events: &[Event]) -> Vec<(u8, Packet)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Packet { seq, packet } => Some((*seq, *packet)),
            _ => None,
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn encode_decode_any_chunking(
        packets in prop::collection::vec(packet(), 0..64),
        seq0 in any::<u8>(),
        cuts in prop::collection::vec(any::<usize>(), 0..40),
    ) {
        let mut wire = Vec::new();
        let mut sent = Vec::new();
        for (i, p) in packets.iter().enumerate() {
            let seq = seq0.wrapping_add(i as u8);
            p.encode(seq, &mut wire);
            sent.push((seq, *p));
        }
        let mut dec = Decoder::new();
        let events = feed_chunked(&mut dec, &wire, &cuts);
        prop_assert_eq!(packets_of(&events), sent);
        for e in &events {
            let link_event_only = matches!(
                e,
                Event::Packet { .. } | Event::ClockWrap | Event::DeviceReboot
            );
            prop_assert!(link_event_only, "unexpected event {:?}", e);
        }
        prop_assert_eq!(dec.buffered(), 0);
    }

    #[test]
    fn each_packet_encodes_to_its_documented_size(p in packet(), seq in any::<u8>()) {
        let mut buf = [0u8; MAX_PAYLOAD];
        prop_assert_eq!(p.write_payload(&mut buf), p.packet_type().payload_len());
        let mut wire = Vec::new();
        p.encode(seq, &mut wire);
        prop_assert_eq!(*wire.last().unwrap(), 0);
        prop_assert!(!wire[..wire.len() - 1].contains(&0));
    }

    #[test]
    fn garbage_never_panics_and_decoder_recovers(
        garbage in prop::collection::vec(any::<u8>(), 0..4096),
        cuts in prop::collection::vec(any::<usize>(), 0..20),
        p in packet(),
    ) {
        let mut dec = Decoder::new();
        let _ = feed_chunked(&mut dec, &garbage, &cuts);
        // A delimiter ends whatever the garbage left open; the next frame decodes.
        let mut wire = vec![0u8];
        p.encode(3, &mut wire);
        let events: Vec<Event> = dec.feed(&wire).collect();
        let got = packets_of(&events);
        prop_assert_eq!(got, vec![(3u8, p)]);
        prop_assert_eq!(dec.buffered(), 0);
    }

    /// Corrupting bytes of a stream loses only the frames the corruption touches.
    #[test]
    fn corruption_loses_only_touched_frames(
        packets in prop::collection::vec(packet(), 1..48),
        hits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        cuts in prop::collection::vec(any::<usize>(), 0..20),
    ) {
        let mut wire = Vec::new();
        let mut spans = Vec::new(); // (start, end inclusive of delimiter)
        for (i, p) in packets.iter().enumerate() {
            let start = wire.len();
            p.encode(i as u8, &mut wire);
            spans.push((start, wire.len()));
        }
        let mut touched = vec![false; wire.len()];
        for (pos, val) in &hits {
            let pos = pos % wire.len();
            if wire[pos] != *val {
                wire[pos] = *val;
                touched[pos] = true;
            }
        }
        let mut dec = Decoder::new();
        let events = feed_chunked(&mut dec, &wire, &cuts);
        let got = packets_of(&events);
        // A frame survives when its bytes, its delimiter and the delimiter before it are intact.
        for (i, &(s, e)) in spans.iter().enumerate() {
            let before_ok = s == 0 || !touched[s - 1];
            if before_ok && !touched[s..e].iter().any(|&t| t) {
                prop_assert!(
                    got.iter().any(|&(seq, q)| seq == i as u8 && q == packets[i]),
                    "intact packet {} lost", i
                );
            }
        }
        // Nothing is invented: every decoded packet was sent (a CRC-16 collision on corrupted
        // bytes is possible in principle; with at most 8 hits it would have to be a real one).
        for (seq, q) in &got {
            prop_assert!(packets.get(*seq as usize) == Some(q), "invented packet {:?}", q);
        }
    }
}

#[test]
fn unknown_type_is_skipped_and_counted() {
    let mut wire = Vec::new();
    encode_frame(0x7E, 0, &[1, 2, 3, 0, 5], &mut wire);
    Packet::Key(Key { t_us: 9, key: b'E' }).encode(1, &mut wire);
    let events: Vec<Event> = Decoder::new().feed(&wire).collect();
    assert_eq!(
        events,
        [
            Event::UnknownType {
                packet_type: 0x7E,
                seq: 0,
                payload_len: 5
            },
            Event::Packet {
                seq: 1,
                packet: Packet::Key(Key { t_us: 9, key: b'E' })
            }
        ]
    );
}

#[test]
fn wrong_length_for_known_type_is_rejected() {
    let mut wire = Vec::new();
    encode_frame(PacketType::Key.code(), 0, &[1, 2, 3, 4], &mut wire);
    Packet::Key(Key { t_us: 9, key: b'E' }).encode(1, &mut wire);
    let events: Vec<Event> = Decoder::new().feed(&wire).collect();
    assert!(matches!(
        events[0],
        Event::PartialStart { .. } // the first frame of a stream is treated as a possible partial
    ));
    let mut wire2 = vec![0u8];
    encode_frame(PacketType::Key.code(), 0, &[1, 2, 3, 4], &mut wire2);
    let frame_len = wire2.len() - 2; // without the leading and trailing delimiters
    let events: Vec<Event> = Decoder::new().feed(&wire2).collect();
    assert_eq!(
        events,
        [Event::Rejected {
            reason: Reject::Length {
                packet_type: PacketType::Key,
                len: 4
            },
            bytes: frame_len
        }]
    );
}

#[test]
fn crc_error_is_reported_with_both_values() {
    let mut wire = vec![0u8];
    Packet::Key(Key { t_us: 9, key: b'E' }).encode(1, &mut wire);
    wire[3] ^= 0x10;
    let events: Vec<Event> = Decoder::new().feed(&wire).collect();
    assert!(
        matches!(events[..], [Event::Rejected { reason: Reject::Crc { computed, received }, .. }] if computed != received),
        "{events:?}"
    );
}

fn rider(t_us: u32) -> Packet {
    Packet::RiderSample(RiderSample {
        t_us,
        acc: [0, 0, 1000],
        mag: [1, 2, 3],
        wheel: 0,
    })
}

fn hello() -> Packet {
    Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::Morphorider,
        device_id: 77,
        firmware: 3,
        rate_hz: 100,
        acc_scale: 0.001,
        gyro_scale: 0.0,
        mag_scale: 0.1,
        ticks_per_rev: 1024,
        wheel_circumference_um: 100_000,
        sensors: 1,
    })
}

fn link_events(stream: &[(u8, Packet)]) -> Vec<Event> {
    let mut wire = Vec::new();
    for (seq, p) in stream {
        p.encode(*seq, &mut wire);
    }
    Decoder::new()
        .feed(&wire)
        .filter(|e| !matches!(e, Event::Packet { .. }))
        .collect()
}

#[test]
fn sequence_gap_counts_lost_packets_across_wrap() {
    let ev = link_events(&[(254, rider(10)), (255, rider(20)), (3, rider(60))]);
    assert_eq!(ev, [Event::SequenceGap { lost: 3 }]);
}

#[test]
fn clock_wrap_is_not_a_reboot() {
    let ev = link_events(&[
        (0, rider(u32::MAX - 15_000)),
        (1, rider(u32::MAX - 5_000)),
        (2, rider(4_704)),
    ]);
    assert_eq!(ev, [Event::ClockWrap]);
}

#[test]
fn periodic_hello_is_not_a_reboot() {
    let ev = link_events(&[
        (0, hello()),
        (1, rider(1_000)),
        (2, hello()),
        (3, rider(11_000)),
    ]);
    assert!(ev.is_empty(), "{ev:?}");
}

#[test]
fn hello_then_clock_back_is_a_reboot_and_the_seq_restart_is_no_loss() {
    let ev = link_events(&[
        (40, rider(9_000_000)),
        (41, rider(9_010_000)),
        (0, hello()),
        (1, rider(2_000)),
    ]);
    assert_eq!(ev, [Event::DeviceReboot]);
}

/// Regression: a packet lost right after the reboot's HELLO flushed the HELLO's sequence
/// restart as 35 lost packets before the clock showed the reboot.
#[test]
fn loss_right_after_a_reboot_hello_does_not_count_the_restart() {
    let ev = link_events(&[
        (219, rider(50_800_000)),
        (220, rider(50_810_000)),
        (0, hello()),
        (2, rider(150_000)), // seq 1 lost
    ]);
    assert_eq!(ev, [Event::SequenceGap { lost: 1 }, Event::DeviceReboot]);
}

#[test]
fn gap_before_a_periodic_hello_is_counted() {
    let ev = link_events(&[(0, rider(1_000)), (5, hello()), (6, rider(2_000))]);
    assert_eq!(ev, [Event::SequenceGap { lost: 4 }]);
}

#[test]
fn oversized_frame_is_dropped_and_the_next_decodes() {
    let mut wire = vec![0u8];
    wire.extend(std::iter::repeat_n(0x55u8, 5000));
    wire.push(0);
    Packet::Key(Key { t_us: 1, key: b'I' }).encode(0, &mut wire);
    let mut dec = Decoder::new();
    let mut events = Vec::new();
    for c in wire.chunks(7) {
        events.extend(dec.feed(c));
    }
    assert_eq!(
        events[0],
        Event::Rejected {
            reason: Reject::TooLong,
            bytes: 5000
        }
    );
    assert!(matches!(events[1], Event::Packet { seq: 0, .. }));
}

#[test]
fn capture_joined_mid_packet_reports_partial_start() {
    let mut wire = Vec::new();
    Packet::Key(Key { t_us: 1, key: b'I' }).encode(0, &mut wire);
    Packet::Key(Key { t_us: 2, key: b'1' }).encode(1, &mut wire);
    let cut = 3;
    let events: Vec<Event> = Decoder::new().feed(&wire[cut..]).collect();
    assert_eq!(events.len(), 2);
    assert!(matches!(events[0], Event::PartialStart { .. }));
    assert!(matches!(events[1], Event::Packet { seq: 1, .. }));
}

/// The long fuzzing run of the decoder: `FUZZ_CASES` (default 2 000) random streams mixing
/// valid frames, corrupted frames and raw garbage, fed in random chunks. Run by `.ci/run`
/// with a large count. In two halves, which cargo runs at once on two cores (the filter
/// `fuzz_decoder_mixed_streams` runs both).
#[test]
fn fuzz_decoder_mixed_streams_first_half() {
    fuzz_decoder_mixed_streams(fuzz_cases().div_ceil(2));
}

/// The other half of `FUZZ_CASES` ([`fuzz_decoder_mixed_streams_first_half`]).
#[test]
fn fuzz_decoder_mixed_streams_second_half() {
    fuzz_decoder_mixed_streams(fuzz_cases() / 2);
}

fn fuzz_cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2_000)
}

fn fuzz_decoder_mixed_streams(cases: u32) {
    use proptest::test_runner::{Config, TestRunner};
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    let piece = prop_oneof![
        packet().prop_map(|p| {
            let mut w = Vec::new();
            p.encode(0, &mut w);
            w
        }),
        prop::collection::vec(any::<u8>(), 0..64),
        (packet(), any::<usize>(), any::<u8>()).prop_map(|(p, i, b)| {
            let mut w = Vec::new();
            p.encode(1, &mut w);
            let i = i % w.len();
            w[i] = b;
            w
        }),
        (any::<u8>(), prop::collection::vec(any::<u8>(), 0..700)).prop_map(|(t, pl)| {
            let mut w = Vec::new();
            encode_frame(t, 2, &pl, &mut w);
            w
        }),
    ];
    let strategy = (
        prop::collection::vec(piece, 0..32),
        prop::collection::vec(any::<usize>(), 0..16),
    );
    runner
        .run(&strategy, |(pieces, cuts)| {
            let stream: Vec<u8> = pieces.concat();
            let mut dec = Decoder::new();
            let events = feed_chunked(&mut dec, &stream, &cuts);
            // Every byte is accounted for by some frame or is still buffered.
            prop_assert!(dec.buffered() <= stream.len());
            prop_assert!(events.len() <= stream.len() * 4 + 1);
            Ok(())
        })
        .unwrap();
}
