//! The phone page's tests: a daemon reading the phone (`sfs run --phone`), and a simulated
//! phone scan turned into what a browser's sensors would read, to be played into the page.

use device_protocol::{Decoder, DeviceKind, Event, Packet};
use nalgebra::{Rotation3, UnitQuaternion};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// `sfs run --phone 127.0.0.1:PORT --session DIR`, logging at info level to `DIR.log`;
/// killed if the test fails first.
pub struct Daemon {
    pub child: Child,
    pub dir: PathBuf,
    pub port: u16,
    /// `DIR/phone.url`: the page's address with its token.
    pub url: String,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Daemon {
    /// Starts a daemon on a free port (tried again on another if it exits at once) with
    /// `extra` arguments (`--resume DIR` replaces `--session DIR` when `resume`).
    pub fn start(dir: &Path, resume: bool, extra: &[&str]) -> Daemon {
        for _ in 0..5 {
            let port = super::view::free_port();
            // A resumed session's phone.url is there before the daemon replaces it (with a
            // new file: another inode).
            let inode =
                |p: &Path| std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(p).ok()?).into();
            let old: Option<u64> = inode(&dir.join("phone.url"));
            let log = std::fs::File::create(dir.with_extension("log")).unwrap();
            let mut child = super::sfs()
                .args(["--log", "info", "run", "--phone"])
                .arg(format!("127.0.0.1:{port}"))
                .arg(if resume { "--resume" } else { "--session" })
                .arg(dir)
                .args(extra)
                .stdout(Stdio::null())
                .stderr(log)
                .spawn()
                .unwrap();
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(20) {
                if child.try_wait().ok().flatten().is_some() {
                    break;
                }
                let path = dir.join("phone.url");
                let now = inode(&path);
                let fresh = now.is_some() && now != old;
                let url = std::fs::read_to_string(&path).unwrap_or_default();
                if fresh
                    && url.ends_with('\n')
                    && std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
                {
                    return Daemon {
                        child,
                        dir: dir.to_owned(),
                        port,
                        url: url.trim().to_owned(),
                    };
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        panic!("the daemon could not serve the phone page on any of 5 free ports");
    }

    /// The page's token.
    pub fn token(&self) -> &str {
        self.url.rsplit_once("token=").unwrap().1
    }

    /// SIGINT, then its report once it has exited (with success).
    pub fn stop(mut self) -> serde_json::Value {
        let _ = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status();
        let t0 = Instant::now();
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                assert!(st.success(), "sfs run --phone: {st}");
                break;
            }
            assert!(t0.elapsed() < Duration::from_secs(30), "did not stop");
            std::thread::sleep(Duration::from_millis(20));
        }
        serde_json::from_slice(&std::fs::read(self.dir.join("report.json")).unwrap()).unwrap()
    }
}

/// One moment of a phone scan as the browser's sensors read it.
#[derive(Debug, Clone, Copy)]
pub struct Reading {
    /// The scan's time, s.
    pub t: f64,
    /// Accelerometer (specific force), phone axes, m/s².
    pub acc: [f64; 3],
    /// Gyroscope, phone axes, rad/s.
    pub gyro: [f64; 3],
    /// The simulated magnetometer, phone axes, µT (not played into the page: browsers give
    /// none).
    pub mag: [f64; 3],
    /// Absolute orientation, phone → Earth (x east, y north, z up): `[x, y, z, w]`.
    pub q: [f64; 4],
}

/// What is played into the page: the readings and the keys pressed, `(t, key)`.
pub struct Play {
    pub readings: Vec<Reading>,
    pub keys: Vec<(f64, u8)>,
    /// The simulated device's clock at scan time 0, µs.
    pub clock_offset_us: i64,
}

/// A simulated phone scan as readings: the accelerometer and gyroscope the simulated phone
/// measured (its noise included, from its PHONE_SAMPLE packets), and the true orientation of
/// each sample as the browser's absolute orientation; its KEY packets as key presses.
pub fn play_of(sim: &sfs::simulate::Simulation) -> Play {
    let frame_from_sensor = sfs::sensor::Calibration::default_for(DeviceKind::Phone)
        .axes
        .m;
    let to_frame =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(frame_from_sensor));
    let truth = &sim.samples;
    let mut decoder = Decoder::new();
    let (mut acc_lsb, mut gyro_lsb, mut mag_lsb) = (0.0, 0.0, 0.0);
    let mut offset: Option<i64> = None;
    let by_us: std::collections::HashMap<i64, usize> = truth
        .t
        .iter()
        .enumerate()
        .map(|(j, t)| ((t * 1e6).round() as i64, j))
        .collect();
    let mut play = Play {
        readings: Vec::new(),
        keys: Vec::new(),
        clock_offset_us: 0,
    };
    for e in decoder.feed(&sim.bytes) {
        let Event::Packet { packet, .. } = e else {
            continue;
        };
        match packet {
            Packet::Hello(h) => {
                (acc_lsb, gyro_lsb, mag_lsb) =
                    (h.acc_scale as f64, h.gyro_scale as f64, h.mag_scale as f64)
            }
            Packet::PhoneSample(s) if acc_lsb > 0.0 => {
                let off = *offset.get_or_insert(s.t_us as i64 - (truth.t[0] * 1e6).round() as i64);
                let Some(&j) = by_us.get(&(s.t_us as i64 - off)) else {
                    continue;
                };
                let q = truth.q[j] * to_frame;
                let v = |c: [i16; 3], lsb: f64| [0, 1, 2].map(|i| c[i] as f64 * lsb);
                play.readings.push(Reading {
                    t: truth.t[j],
                    acc: v(s.acc, acc_lsb),
                    gyro: v(s.gyro, gyro_lsb),
                    mag: v(s.mag, mag_lsb),
                    q: [q.i, q.j, q.k, q.w],
                });
            }
            Packet::Key(k) => {
                if let Some(off) = offset {
                    play.keys.push(((k.t_us as i64 - off) as f64 * 1e-6, k.key));
                }
            }
            _ => {}
        }
    }
    assert!(
        play.readings.len() as f64 >= 0.99 * truth.t.len() as f64,
        "{} of {} samples matched",
        play.readings.len(),
        truth.t.len()
    );
    play.clock_offset_us = offset.unwrap_or(0);
    play
}

/// The reading at scan time `t` (the latest before it).
pub fn at(readings: &[Reading], t: f64) -> &Reading {
    let i = readings.partition_point(|r| r.t <= t);
    &readings[i.saturating_sub(1).min(readings.len() - 1)]
}

/// The page's `data-key` of a key byte.
pub fn data_key(k: u8) -> String {
    match k {
        b'\n' => "Enter".into(),
        k => (k as char).to_string(),
    }
}

/// Rest readings: flat, facing north, still.
pub fn rest() -> Reading {
    let q = UnitQuaternion::<f64>::identity();
    Reading {
        t: 0.0,
        acc: [0.0, 0.0, 9.81],
        gyro: [0.0; 3],
        mag: [0.0, 21.04, -43.14],
        q: [q.i, q.j, q.k, q.w],
    }
}
