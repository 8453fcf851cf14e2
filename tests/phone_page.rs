//! Issue 32, the phone as the device, in a real browser: Debian's chromium, headless, driven
//! through chromedriver, the phone's sensors emulated through the DevTools protocol
//! (`Emulation.setSensorOverrideReadings` for the accelerometer, the gyroscope and the absolute
//! orientation), the keys pressed by clicking the page's buttons:
//! - the page's encoder (wire.js) writes the shared test vectors byte for byte;
//! - a simulated phone scan played into the page at the sensors' 60 Hz is reconstructed by the
//!   daemon within 2× the error of the same scan's serial capture without its segment lengths
//!   (the page measures none: its distances come from the segment timing), for two scenes; the
//!   session's capture replays to the same outputs;
//! - a dropped connection is a disconnect, and the reconnection continues the session.
//!
//! The refusals (token, second phone, plain HTTP, oversized message) are in
//! `phone_refusals.rs`, through a TLS client of the test's own.

mod common;
use common::phone::{at, data_key, play_of, rest, Daemon, Play, Reading};
use common::webdriver::{available, Browser};
use common::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The sensors the page's events are made of, each overridden.
const SENSORS: [&str; 6] = [
    "accelerometer",
    "gyroscope",
    "linear-acceleration",
    "gravity",
    "absolute-orientation",
    "relative-orientation",
];

/// A browser on the daemon's page, its sensors overridden and at rest, the start button
/// pressed and the page streaming.
async fn open_page(d: &Daemon, profile: &Path) -> Browser {
    let b = Browser::start_with(profile, true).await;
    let origin = format!("https://127.0.0.1:{}", d.port);
    b.cdp(
        "Browser.grantPermissions",
        serde_json::json!({ "permissions": ["sensors"], "origin": origin }),
    )
    .await;
    for t in SENSORS {
        b.cdp(
            "Emulation.setSensorOverrideEnabled",
            serde_json::json!({ "enabled": true, "type": t }),
        )
        .await;
    }
    override_reading(
        &b,
        "linear-acceleration",
        serde_json::json!({ "xyz": { "x": 0, "y": 0, "z": 0 } }),
    )
    .await;
    set(&b, &rest()).await;
    b.goto(&d.url).await;
    let start = b.find("[data-action=start]").await;
    b.click(&start).await;
    wait_page(&b, Duration::from_secs(20), |p| {
        p["state"] == "streaming" && p["acc_sign"] != 0
    })
    .await;
    b
}

/// Sets the three readings of `r`.
async fn set(b: &Browser, r: &Reading) {
    let xyz = |v: [f64; 3]| serde_json::json!({ "xyz": { "x": v[0], "y": v[1], "z": v[2] } });
    let [x, y, z, w] = r.q;
    let orientation = serde_json::json!({ "quaternion": { "x": x, "y": y, "z": z, "w": w } });
    for (sensor, reading) in [
        ("accelerometer", xyz(r.acc)),
        ("gyroscope", xyz(r.gyro)),
        ("absolute-orientation", orientation),
    ] {
        override_reading(b, sensor, reading).await;
    }
}

/// One sensor's reading, through the DevTools protocol.
async fn override_reading(b: &Browser, sensor: &str, reading: serde_json::Value) {
    b.cdp(
        "Emulation.setSensorOverrideReadings",
        serde_json::json!({ "type": sensor, "reading": reading }),
    )
    .await;
}

/// `window.sfsPhone`.
async fn page_state(b: &Browser) -> serde_json::Value {
    let v = b
        .execute(
            "return JSON.stringify(window.sfsPhone || null)",
            serde_json::json!([]),
        )
        .await;
    serde_json::from_str(v.as_str().unwrap_or("null")).unwrap()
}

async fn wait_page(
    b: &Browser,
    limit: Duration,
    mut done: impl FnMut(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let s = page_state(b).await;
        if done(&s) {
            return s;
        }
        assert!(t0.elapsed() < limit, "the page: {s}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Plays `play` into the page in real time: the readings of the scan's clock every 1/60 s,
/// each key clicked when its time comes. Returns the ticks that ran late (over 1/60 s).
///
/// The scan's clock stops while a key is clicked. A WebDriver click takes 20–400 ms on a
/// loaded machine, and no reading can be set meanwhile: had the clock run on, the page would
/// have held the standing readings through the operator's set-off and then jumped to cruising
/// speed with no acceleration between, with the Enter after it (issue 32's test failing in CI
/// at 1.20 % through the page against 0.52 %). Stopped, the click is an operator who types a
/// little slower at the node, where the scan stands anyway.
async fn perform(b: &Browser, play: &Play) -> usize {
    let mut keys: Vec<String> = play.keys.iter().map(|&(_, k)| data_key(k)).collect();
    keys.sort();
    keys.dedup();
    let mut buttons = HashMap::new();
    for key in keys {
        let id = b.find(&format!("[data-key=\"{key}\"]")).await;
        buttons.insert(key, id);
    }
    let t_first = play.readings[0].t;
    let t_end = play.readings.last().unwrap().t;
    let mut tick = tokio::time::interval(Duration::from_micros(16_667));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let (mut k, mut late) = (0, 0);
    let start = Instant::now();
    let mut last = start;
    // Time spent clicking keys: the scan's clock stands still meanwhile.
    let mut typing = Duration::ZERO;
    loop {
        tick.tick().await;
        if last.elapsed() > Duration::from_millis(20) {
            late += 1;
        }
        last = Instant::now();
        let t = t_first + (start.elapsed() - typing).as_secs_f64();
        while k < play.keys.len() && play.keys[k].0 <= t {
            let key = data_key(play.keys[k].1);
            let clicked = Instant::now();
            b.click(&buttons[&key]).await;
            if key == "C" {
                // The page sends C on a second tap (issue 50).
                b.click(&buttons[&key]).await;
            }
            typing += clicked.elapsed();
            k += 1;
        }
        if t > t_end && k == play.keys.len() {
            return late;
        }
        set(b, at(&play.readings, t)).await;
    }
}

/// `bytes` without their SEGMENT_LENGTH frames: what a phone sends that has no way to measure
/// its segments (the page has none: its distances come from the segment timing). The decoder
/// counts the frames cut out as lost packets.
fn without_segment_lengths(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    for frame in bytes.split_inclusive(|&b| b == 0) {
        let mut d = device_protocol::Decoder::new();
        let is_length = d.feed(frame).into_iter().any(|e| {
            matches!(
                e,
                device_protocol::Event::Packet {
                    packet: device_protocol::Packet::SegmentLength(_),
                    ..
                }
            )
        });
        if !is_length {
            out.extend_from_slice(frame);
        }
    }
    out
}

/// CPU seconds a process has used (user and system, from /proc/PID/stat).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or(vec![], |(_, r)| r.split_whitespace().collect());
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
    (ticks(11) + ticks(12)) / 100.0
}

/// The curve error of a scene scanned three ways, % of the diagonal.
struct Errors {
    /// Played into the page, reconstructed by the daemon.
    page: f64,
    /// The simulated serial capture of the same scan, as `sfs simulate` writes it (its phone
    /// app also sends each segment's measured length).
    serial: f64,
    /// The same capture without the segment lengths: the information the page has.
    serial_timing: f64,
}

/// The scene scanned with the phone in the page, and through its simulated serial capture;
/// and the session directory.
async fn scan_through_the_page(scene: &str, seed: u64) -> (Errors, PathBuf) {
    let dir = tmpdir(&format!("phone-{scene}"));
    let s = sfs::simulate::scene::builtin(scene).unwrap();
    let sim = sfs::simulate::run(
        &s,
        device_protocol::DeviceKind::Phone,
        sfs::simulate::Profile::Default,
        seed,
    );
    let truth = dir.join("truth.json");
    std::fs::write(&truth, serde_json::to_vec(&sim.truth).unwrap()).unwrap();
    let serial = dir.join("serial.bin");
    std::fs::write(&serial, &sim.bytes).unwrap();
    replay_to(&serial, &dir.join("serial"));
    let serial_err = eval(&truth, &dir.join("serial/network.glb"))["curves"]["mean_pct"]
        .as_f64()
        .unwrap();
    let timing = dir.join("serial-timing.bin");
    std::fs::write(&timing, without_segment_lengths(&sim.bytes)).unwrap();
    replay_to(&timing, &dir.join("serial-timing"));
    let timing_err = eval(&truth, &dir.join("serial-timing/network.glb"))["curves"]["mean_pct"]
        .as_f64()
        .unwrap();

    let play = play_of(&sim);
    let session = dir.join("session");
    let d = Daemon::start(&session, false, &[]);
    let b = open_page(&d, &dir.join("profile")).await;
    let late = perform(&b, &play).await;
    let curves = sim.truth.curves.len() as u64;
    let page = wait_page(&b, Duration::from_secs(10), |p| {
        p["feedback"]["curves"] == curves
    })
    .await;
    b.close().await;
    let cpu = cpu_seconds(d.child.id());
    let report = d.stop();
    eprintln!(
        "{scene}: {} readings played, {late} ticks late; page {page}; phone link {}; daemon CPU {cpu:.2} s in {:.1} s ({:.1} %)",
        play.readings.len(),
        report["phone"],
        report["wall_time_s"].as_f64().unwrap(),
        100.0 * cpu / report["wall_time_s"].as_f64().unwrap(),
    );
    assert_eq!(report["curves"].as_array().unwrap().len() as u64, curves);
    assert_eq!(report["link"]["rejected"]["crc"], 0);
    assert_eq!(report["link"]["lost_packets"], 0);
    let rate = report["phone"]["rate_hz"].as_f64().unwrap();
    assert!((50.0..70.0).contains(&rate), "{rate} Hz");
    let page_err = eval(&truth, &session.join("network.glb"))["curves"]["mean_pct"]
        .as_f64()
        .unwrap();
    let errors = Errors {
        page: page_err,
        serial: serial_err,
        serial_timing: timing_err,
    };
    (errors, session)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_32_the_pages_encoder_writes_the_shared_vectors() {
    available();
    let dir = tmpdir("phone-vectors");
    let d = Daemon::start(&dir.join("session"), false, &[]);
    let b = Browser::start_with(&dir.join("profile"), true).await;
    b.goto(&d.url).await;
    let vectors: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("device-protocol/tests/vectors/phone.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let script = r#"
        const [vectors, done] = arguments;
        import('/wire.js').then((w) => done(vectors.map((v) => {
            let f;
            if (v.type === 'KEY') f = w.key(v.seq, { tUs: v.t_us, key: v.key });
            else if (v.type === 'PHONE_SAMPLE') f = w.phoneSample(v.seq, { tUs: v.t_us, acc: v.acc, gyro: v.gyro, mag: v.mag });
            else f = w.hello(v.seq, { deviceId: v.device_id, firmware: v.firmware, rateHz: v.rate_hz,
                accScale: v.acc_scale, gyroScale: v.gyro_scale, magScale: v.mag_scale });
            return Array.from(f, (x) => x.toString(16).padStart(2, '0')).join('');
        })), (e) => done(String(e)));
    "#;
    let got = b
        .execute_async(script, serde_json::json!([vectors["vectors"]]))
        .await;
    let got = got.as_array().unwrap_or_else(|| panic!("{got}"));
    let vs = vectors["vectors"].as_array().unwrap();
    assert_eq!(got.len(), vs.len());
    for (g, v) in got.iter().zip(vs) {
        assert_eq!(g, &v["hex"], "{}", v["name"]);
    }
    b.close().await;
    d.stop();
}

/// A scene played into the page reconstructs within 2× the error of its serial capture without
/// segment lengths, and the session's capture replays to the same outputs.
async fn played_into_the_page_like_its_serial_capture(scene: &str, seed: u64) {
    available();
    let (e, session) = scan_through_the_page(scene, seed).await;
    eprintln!(
        "{scene}: curve error {:.3} % through the page; serial capture {:.3} % with the segment lengths, {:.3} % without",
        e.page, e.serial, e.serial_timing
    );
    // The page has what a phone without a length measurement has: held to 2× the serial
    // capture of the same information (BENCHMARKS.md gives the figures with lengths too).
    assert!(
        e.page <= 2.0 * e.serial_timing,
        "{scene}: {:.3} % through the page, {:.3} % through the serial capture without segment lengths",
        e.page,
        e.serial_timing
    );
    let again = session.with_file_name(format!("{scene}-replayed"));
    replay_to(&session.join("capture.bin"), &again);
    assert_same_files(
        &session,
        &again,
        &["network.glb", "scan.json"],
        "the phone session and its replay",
    );
}

// Two scenes, two tests: they play at once (each in real time: 54 s and 125 s).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_32_torus_loops_played_into_the_page_reconstructs_like_its_serial_capture() {
    played_into_the_page_like_its_serial_capture("torus-loops", 1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_32_bumpy_played_into_the_page_reconstructs_like_its_serial_capture() {
    played_into_the_page_like_its_serial_capture("bumpy", 1).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_32_a_reconnection_continues_the_session() {
    available();
    let dir = tmpdir("phone-reconnect");
    let session = dir.join("session");
    let d = Daemon::start(&session, false, &[]);
    let b = open_page(&d, &dir.join("profile")).await;
    let click = |k: &'static str| {
        let b = &b;
        async move {
            let id = b.find(&format!("[data-key=\"{k}\"]")).await;
            b.click(&id).await;
        }
    };
    // A curve from node 0 to node 1, its connection dropped halfway (as when the phone's
    // Wi-Fi roams): the page keeps what it measured meanwhile and sends it on reconnecting.
    let mut r = rest();
    let step = |r: &mut Reading, moving: bool| {
        r.acc = [0.0, if moving { 0.05 } else { 0.0 }, 9.81];
    };
    for k in ["B", "0", "Enter"] {
        click(k).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    step(&mut r, true);
    set(&b, &r).await;
    tokio::time::sleep(Duration::from_millis(800)).await;
    let before = page_state(&b).await;
    b.execute("window.sfsPhone.drop()", serde_json::json!([]))
        .await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let after = wait_page(&b, Duration::from_secs(15), |p| p["connections"] == 2).await;
    step(&mut r, false);
    set(&b, &r).await;
    tokio::time::sleep(Duration::from_millis(800)).await;
    for k in ["1", "Enter", "E"] {
        click(k).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    wait_page(&b, Duration::from_secs(10), |p| {
        p["feedback"]["curves"] == 1
    })
    .await;
    // Streaming stopped, what the page sent is final (and all of it on its way).
    b.execute("window.sfsPhone.stop()", serde_json::json!([]))
        .await;
    let sent = wait_page(&b, Duration::from_secs(5), |p| p["state"] == "stopped").await
        ["sent_packets"]
        .as_u64()
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    b.close().await;
    let report = d.stop();
    eprintln!("before {before}\nafter {after}\nreport {}", report["link"]);
    assert_eq!(report["link"]["connects"], 2, "{}", report["link"]);
    assert!(report["link"]["disconnects"].as_u64().unwrap() >= 1);
    assert_eq!(report["phone"]["connections"], 2);
    // Nothing lost across the drop: every packet the page sent was decoded, in sequence.
    assert_eq!(report["link"]["lost_packets"], 0, "{}", report["link"]);
    assert_eq!(report["link"]["packets"]["KEY"], 6);
    let decoded: u64 = report["link"]["packets"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(decoded, sent);
    let curves = report["curves"].as_array().unwrap();
    assert_eq!(curves.len(), 1, "{}", report["warnings"]);
    assert_eq!(curves[0]["nodes"], serde_json::json!([0, 1]));
}

/// Issue 50 point 4: a browser that sends no motion (no sensor overridden: headless chromium
/// has none) is told so 3 s after Start, with the likely causes, and never connects (the
/// daemon logs no disconnect every 3 s); keys pressed before Start are refused with a hint and
/// never reach the daemon; the letter keys have a legend.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_50_a_browser_without_motion_is_told_why() {
    available();
    let dir = tmpdir("phone-no-motion");
    let d = Daemon::start(&dir.join("session"), false, &[]);
    let b = Browser::start_with(&dir.join("profile"), true).await;
    b.goto(&d.url).await;
    let legend = b
        .execute(
            "return [...document.querySelectorAll('#legend dt')].map((e) => e.textContent)",
            serde_json::json!([]),
        )
        .await;
    for k in ["B", "I", "K", "G", "C", "E", "U", "Enter"] {
        assert!(
            legend.as_array().unwrap().iter().any(|d| d == k),
            "{k} not in {legend}"
        );
    }
    // A key before Start: refused, with a hint.
    let key_b = b.find("[data-key=\"B\"]").await;
    b.click(&key_b).await;
    let p = page_state(&b).await;
    assert_eq!(p["refused_keys"], 1, "{p}");
    assert!(
        p["hint"].as_str().unwrap().contains("Press Start first"),
        "{p}"
    );
    // Start: no motion comes.
    let start = b.find("[data-action=start]").await;
    b.click(&start).await;
    let t0 = Instant::now();
    let p = wait_page(&b, Duration::from_secs(6), |p| p["state"] == "no-motion").await;
    assert!(
        t0.elapsed() >= Duration::from_millis(2900),
        "{:?}",
        t0.elapsed()
    );
    let shown = b
        .execute(
            "const h = document.getElementById('hint'); return [h.hidden, h.textContent, document.getElementById('state').textContent]",
            serde_json::json!([]),
        )
        .await;
    assert_eq!(shown[0], false, "{shown}");
    let text = shown[1].as_str().unwrap();
    assert!(
        text.contains("No motion data") && text.contains("desktop") && text.contains("refused"),
        "{text}"
    );
    assert_eq!(shown[2], "no motion data");
    assert_eq!(p["connections"], 0, "{p}");
    // Keys now: refused too.
    b.click(&key_b).await;
    assert_eq!(page_state(&b).await["refused_keys"], 2);
    tokio::time::sleep(Duration::from_secs(4)).await;
    b.close().await;
    let report = d.stop();
    assert_eq!(report["link"]["connects"], 0, "{}", report["link"]);
    assert_eq!(report["link"]["disconnects"], 0, "{}", report["link"]);
    assert_eq!(report["link"]["packets"]["KEY"], 0);
}

/// Issue 50 point 4: C cancels the whole curve only when tapped twice within 2 s; a single
/// tap (or two taps further apart) sends nothing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(sfs_chromium),
    ignore = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
)]
async fn issue_50_c_cancels_only_when_confirmed() {
    available();
    let dir = tmpdir("phone-confirm-c");
    let d = Daemon::start(&dir.join("session"), false, &[]);
    let b = open_page(&d, &dir.join("profile")).await;
    let mut buttons = HashMap::new();
    for k in ["B", "0", "Enter", "C"] {
        buttons.insert(k, b.find(&format!("[data-key=\"{k}\"]")).await);
    }
    for k in ["B", "0", "Enter"] {
        b.click(&buttons[k]).await;
    }
    wait_page(&b, Duration::from_secs(5), |p| {
        p["feedback"]["curve"]["nodes"] == serde_json::json!([0])
    })
    .await;
    let keys = page_state(&b).await["keys"].as_u64().unwrap();
    b.click(&buttons["C"]).await;
    let p = page_state(&b).await;
    assert_eq!(p["keys"].as_u64().unwrap(), keys, "one tap sent C: {p}");
    assert!(p["hint"].as_str().unwrap().contains("Tap C again"), "{p}");
    // The confirmation lapses.
    tokio::time::sleep(Duration::from_millis(2300)).await;
    b.click(&buttons["C"]).await;
    assert_eq!(page_state(&b).await["keys"].as_u64().unwrap(), keys);
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(page_state(&b).await["feedback"]["curve"].is_object());
    // Confirmed.
    b.click(&buttons["C"]).await;
    let p = wait_page(&b, Duration::from_secs(5), |p| {
        p["feedback"]["curve"].is_null()
    })
    .await;
    assert_eq!(p["keys"].as_u64().unwrap(), keys + 1, "{p}");
    b.close().await;
    let report = d.stop();
    assert_eq!(report["link"]["packets"]["KEY"], keys + 1);
    assert_eq!(report["curves"].as_array().unwrap().len(), 0);
}
