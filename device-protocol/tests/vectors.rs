//! The phone page's test vectors (`tests/vectors/phone.json`): the frames of HELLO,
//! PHONE_SAMPLE and KEY as bytes on the wire. The encoder writes them, the decoder reads them
//! back to the same fields; the page's JavaScript encoder is held to the same bytes by
//! `tests/phone_page.rs` at the top of the repository. `SFS_BLESS=1` writes the hex of the
//! encoder into the file (for a new vector; check it by hand before committing).

use device_protocol::{Decoder, DeviceKind, Event, Hello, Key, Packet, PhoneSample};
use serde_json::Value;

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/phone.json");

fn array3(v: &Value) -> [i16; 3] {
    let a = v.as_array().expect("three numbers");
    [0, 1, 2].map(|i| a[i].as_i64().expect("a number") as i16)
}

/// The packet a vector describes.
fn packet(v: &Value) -> Packet {
    let u = |k: &str| v[k].as_u64().unwrap_or_else(|| panic!("{k} in {v}"));
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}")) as f32;
    match v["type"].as_str().unwrap() {
        "KEY" => Packet::Key(Key {
            t_us: u("t_us") as u32,
            key: u("key") as u8,
        }),
        "PHONE_SAMPLE" => Packet::PhoneSample(PhoneSample {
            t_us: u("t_us") as u32,
            acc: array3(&v["acc"]),
            gyro: array3(&v["gyro"]),
            mag: array3(&v["mag"]),
        }),
        "HELLO" => Packet::Hello(Hello {
            proto: 1,
            kind: DeviceKind::Phone,
            device_id: u("device_id") as u32,
            firmware: u("firmware") as u16,
            rate_hz: u("rate_hz") as u16,
            acc_scale: f("acc_scale"),
            gyro_scale: f("gyro_scale"),
            mag_scale: f("mag_scale"),
            ticks_per_rev: 0,
            wheel_circumference_um: 0,
            sensors: 1,
        }),
        t => panic!("no packet type {t}"),
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

#[test]
fn the_phone_vectors_encode_and_decode_exactly() {
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(FILE).unwrap()).unwrap();
    let bless = std::env::var_os("SFS_BLESS").is_some();
    let vectors = doc["vectors"].as_array_mut().unwrap();
    assert!(vectors.len() >= 6);
    for v in vectors.iter_mut() {
        let p = packet(v);
        let seq = v["seq"].as_u64().unwrap() as u8;
        let mut bytes = Vec::new();
        p.encode(seq, &mut bytes);
        if bless {
            v["hex"] = hex(&bytes).into();
            continue;
        }
        assert_eq!(hex(&bytes), v["hex"].as_str().unwrap(), "{}", v["name"]);
        // Framing: one delimiter, at the end.
        assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1);
        assert_eq!(bytes.last(), Some(&0));
        let wire = unhex(v["hex"].as_str().unwrap());
        let mut decoder = Decoder::new();
        let decoded: Vec<_> = decoder
            .feed(&wire)
            .filter_map(|e| match e {
                Event::Packet { seq: s, packet } => Some((s, packet)),
                _ => None,
            })
            .collect();
        assert_eq!(decoded, vec![(seq, p)], "{}", v["name"]);
    }
    if bless {
        std::fs::write(FILE, serde_json::to_string_pretty(&doc).unwrap() + "\n").unwrap();
    }
}
