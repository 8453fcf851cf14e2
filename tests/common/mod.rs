//! Helpers shared by the integration tests: a capture with every kind of link fault, built
//! packet by packet so that the expected statistics are known from construction.
#![allow(dead_code)]

use device_protocol::*;
use std::path::PathBuf;

#[allow(dead_code)]
pub mod phone;
#[allow(dead_code)]
pub mod phone_client;
pub mod pty;
pub mod view;
pub mod webdriver;

/// The status code of an HTTP answer's text (`HTTP/1.1 200 OK …`), 0 when there is none.
pub fn http_status(answer: &str) -> u16 {
    answer
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0)
}

/// The `sfs` binary under test.
pub fn sfs() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
}

/// What a correct decoder must count on a [`fault_stream`].
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Expected {
    pub packets: [u64; 7], // in PacketType::ALL order
    pub crc: u64,
    pub cobs: u64,
    pub length: u64,
    pub unknown: u64,
    pub lost: u64,
    pub reboots: u64,
    pub clock_wraps: u64,
    pub partial_start_bytes: u64,
}

pub struct Builder {
    pub bytes: Vec<u8>,
    pub exp: Expected,
    seq: u8,
    pub t: u32,
}

fn type_index(t: PacketType) -> usize {
    PacketType::ALL.iter().position(|&x| x == t).unwrap()
}

pub fn hello() -> Packet {
    Packet::Hello(Hello {
        proto: 1,
        kind: DeviceKind::Morphorider,
        device_id: 7,
        firmware: 1,
        rate_hz: 100,
        acc_scale: 0.0024,
        gyro_scale: 0.0,
        mag_scale: 0.15,
        ticks_per_rev: 1024,
        wheel_circumference_um: 100_000,
        sensors: 1,
    })
}

impl Builder {
    pub fn new() -> Self {
        Builder {
            bytes: Vec::new(),
            exp: Expected::default(),
            seq: 0,
            t: 1_000,
        }
    }

    pub fn packet(&mut self, p: Packet) {
        p.encode(self.seq, &mut self.bytes);
        self.seq = self.seq.wrapping_add(1);
        self.exp.packets[type_index(p.packet_type())] += 1;
    }

    pub fn sample(&mut self, i: i32) {
        self.t = self.t.wrapping_add(10_000);
        self.packet(Packet::RiderSample(RiderSample {
            t_us: self.t,
            acc: [i as i16, 0, 4096],
            mag: [100, -(i as i16), 300],
            wheel: i * 3,
        }));
    }

    pub fn key(&mut self, k: u8) {
        self.packet(Packet::Key(Key {
            t_us: self.t,
            key: k,
        }));
    }

    /// A frame whose CRC is wrong: sent by the device (takes a seq), lost.
    pub fn crc_error(&mut self) {
        let mut raw = vec![PacketType::Key.code(), self.seq, 1, 2, 3, 4, b'E'];
        let crc = crc16(&raw) ^ 0x0101;
        raw.extend_from_slice(&crc.to_le_bytes());
        cobs::encode(&raw, &mut self.bytes);
        self.bytes.push(0);
        self.seq = self.seq.wrapping_add(1);
        self.exp.crc += 1;
        self.exp.lost += 1;
    }

    /// Line noise that is not valid COBS (takes no seq).
    pub fn cobs_error(&mut self) {
        self.bytes.extend_from_slice(&[0x09, 0x41, 0x42, 0x00]);
        self.exp.cobs += 1;
    }

    /// A KEY with a 4-byte payload and a valid CRC (takes a seq).
    pub fn length_error(&mut self) {
        encode_frame(
            PacketType::Key.code(),
            self.seq,
            &[1, 2, 3, 4],
            &mut self.bytes,
        );
        self.seq = self.seq.wrapping_add(1);
        self.exp.length += 1;
    }

    pub fn unknown_type(&mut self) {
        encode_frame(0x7E, self.seq, &[9; 40], &mut self.bytes);
        self.seq = self.seq.wrapping_add(1);
        self.exp.unknown += 1;
    }

    pub fn gap(&mut self, n: u8) {
        self.seq = self.seq.wrapping_add(n);
        self.exp.lost += n as u64;
    }

    pub fn reboot(&mut self) {
        self.seq = 0;
        self.t = 500;
        self.packet(hello());
        self.exp.reboots += 1;
    }

    pub fn approach_clock_wrap(&mut self) {
        self.t = u32::MAX - 25_000;
    }
}

/// A capture with every fault of the wire format: joined mid-packet, CRC, COBS and length
/// errors, unknown types, sequence gaps, a clock wrap and a reboot, around `n` samples.
pub fn fault_stream(n: i32) -> (Vec<u8>, Expected) {
    let mut b = Builder::new();
    // Joined mid-packet: the tail of a frame before the first delimiter.
    let mut tail = Vec::new();
    hello().encode(200, &mut tail);
    let cut = tail.len() - 9;
    b.bytes.extend_from_slice(&tail[cut..]);
    b.exp.partial_start_bytes = (tail.len() - cut - 1) as u64;
    b.packet(hello());
    b.key(b'B');
    for i in 0..n {
        b.sample(i);
        match i % 97 {
            10 => b.crc_error(),
            20 => b.cobs_error(),
            30 => b.length_error(),
            40 => b.unknown_type(),
            50 => b.gap(3),
            _ => {}
        }
        if i == n / 2 {
            b.approach_clock_wrap();
            b.exp.clock_wraps += 1;
        }
        if i == 3 * n / 4 {
            b.key(b'E');
            b.reboot();
            b.key(b'I');
        }
    }
    b.key(b'E');
    b.packet(Packet::Status(Status {
        t_us: b.t,
        battery_mv: 3700,
        flags: Status::MAG_SATURATED,
        dropped: 12,
    }));
    (b.bytes, b.exp)
}

/// Polls `cond` every 10 ms until it holds; panics naming `what` after `timeout`.
pub fn wait_for(what: &str, timeout: std::time::Duration, mut cond: impl FnMut() -> bool) {
    let t0 = std::time::Instant::now();
    while !cond() {
        assert!(t0.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// The length of a file, 0 while it does not exist.
pub fn file_len(p: &std::path::Path) -> u64 {
    std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
}

/// A fresh directory under the target's temporary folder.
pub fn tmpdir(name: &str) -> PathBuf {
    let d =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `DIR/report.json`, parsed.
pub fn read_report(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap()
}

/// A JSON array of strings (a report's `warnings`, `warning_codes`) as `&str`s.
pub fn strings(v: &serde_json::Value) -> Vec<&str> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect()
}

/// Asserts the `"link"` object of a report against the construction.
pub fn assert_link(link: &serde_json::Value, bytes: usize, exp: &Expected) {
    assert_eq!(link["bytes"], bytes as u64, "bytes");
    for (i, t) in PacketType::ALL.iter().enumerate() {
        assert_eq!(
            link["packets"][t.name()],
            exp.packets[i],
            "packets.{}",
            t.name()
        );
    }
    assert_eq!(link["rejected"]["crc"], exp.crc, "rejected.crc");
    assert_eq!(link["rejected"]["cobs"], exp.cobs, "rejected.cobs");
    assert_eq!(link["rejected"]["length"], exp.length, "rejected.length");
    assert_eq!(link["unknown_types"], exp.unknown, "unknown_types");
    assert_eq!(link["lost_packets"], exp.lost, "lost_packets");
    assert_eq!(link["reboots"], exp.reboots, "reboots");
    assert_eq!(link["clock_wraps"], exp.clock_wraps, "clock_wraps");
    assert_eq!(
        link["partial_start_bytes"], exp.partial_start_bytes,
        "partial_start_bytes"
    );
}

/// `sfs eval --truth TRUTH --glb GLB`, which must succeed: its JSON.
pub fn eval(truth: &std::path::Path, glb: &std::path::Path) -> serde_json::Value {
    let out = sfs()
        .args(["--log", "off", "eval", "--truth"])
        .arg(truth)
        .arg("--glb")
        .arg(glb)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "sfs eval: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `sfs --log off replay CAPTURE --out OUT`, which must succeed.
pub fn replay_to(capture: &std::path::Path, out: &std::path::Path) {
    let st = sfs()
        .args(["--log", "off", "replay"])
        .arg(capture)
        .arg("--out")
        .arg(out)
        .status()
        .unwrap();
    assert!(st.success(), "sfs replay {}: {st}", capture.display());
}

/// Asserts that each of `files` is the same bytes in directories `a` and `b`.
pub fn assert_same_files(a: &std::path::Path, b: &std::path::Path, files: &[&str], what: &str) {
    for f in files {
        assert!(
            std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
            "{what}: {f} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

/// `sfs run --stdin ARGS SESSION` (`--session` or `--resume`), logs off, its standard input
/// piped.
pub fn run_stdin(args: &[&str], session: &std::path::Path) -> std::process::Child {
    sfs()
        .args(["--log", "off", "run", "--stdin"])
        .args(args)
        .arg(session)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

/// `sfs run --stdin --session SESSION` fed `first`, killed (SIGKILL) once it has captured
/// it and synced (past the capture's 1 s fsync interval), then `--resume` fed `rest`, which
/// must end with success.
pub fn killed_then_resumed(session: &std::path::Path, first: &[u8], rest: &[u8]) {
    use std::io::Write;
    let mut child = run_stdin(&["--session"], session);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(first).unwrap();
    stdin.flush().unwrap();
    wait_for(
        "the first part captured",
        std::time::Duration::from_secs(20),
        || file_len(&session.join("capture.bin")) == first.len() as u64,
    );
    std::thread::sleep(std::time::Duration::from_millis(1200));
    let _ = child.kill();
    let _ = child.wait();
    drop(stdin);
    let mut child = run_stdin(&["--resume"], session);
    child.stdin.take().unwrap().write_all(rest).unwrap();
    assert!(child.wait().unwrap().success());
}

/// Mean curve error of a field-profile capture of a shipped scene, % of the diagonal: simulated
/// without the faults `without`, acquired and reconstructed with the defaults, scored with
/// the paper's metric against the simulator's truth.
pub fn field_error(
    name: &str,
    device: DeviceKind,
    seed: u64,
    without: &[sfs::simulate::Fault],
) -> f64 {
    use sfs::acquisition::{Acquisition, AcquisitionConfig};
    use sfs_geometry::network::{NetworkParams, Reconstructor};
    let s = sfs::simulate::scene::builtin(name).expect("shipped scene");
    let sim = sfs::simulate::run_without(
        &s,
        device,
        sfs::simulate::Profile::Field,
        seed,
        &sfs::simulate::Mistakes::default(),
        without,
    );
    let scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    let net = Reconstructor::new()
        .run(&scan.curves, &NetworkParams::default())
        .expect("the field capture reconstructs");
    let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
        .expect("evaluates");
    e.curves.mean_pct
}
