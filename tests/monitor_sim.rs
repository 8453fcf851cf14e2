//! Issue 8, monitoring: the simulator's deforming structures streamed by a sensor array,
//! decoded and averaged per epoch by acquisition, reconstructed epoch by epoch
//! (`sfs::monitor::epoch`), against the simulator's truth.

use nalgebra::{UnitQuaternion, Vector3};
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::monitor::epoch::{EpochParams, EpochReconstructor};
use sfs::monitor::layout::Layout;
use sfs::simulate::structure::{run, StructureKind};
use std::collections::BTreeMap;

mod common;
use common::tmpdir;

/// The epochs of acquisition grouped by window (every sensor's window closes within one
/// sampling period of the others): `(window end, orientation by sensor)`.
fn epochs(scan: &sfs::scan::Scan) -> Vec<(f64, BTreeMap<u16, UnitQuaternion<f64>>)> {
    let mut by: BTreeMap<i64, (f64, BTreeMap<u16, UnitQuaternion<f64>>)> = BTreeMap::new();
    for e in &scan.array {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            e.q[0], e.q[1], e.q[2], e.q[3],
        ));
        let slot = by
            .entry(e.t.round() as i64)
            .or_insert((e.t, BTreeMap::new()));
        slot.1.insert(e.sensor, q);
    }
    by.into_values().collect()
}

/// The truth's tip displacement at time `t`, linearly between its 1 s epochs.
fn truth_tip(truth: &sfs::simulate::structure::StructureTruth, t: f64) -> f64 {
    let k = truth
        .epochs
        .partition_point(|e| e.t <= t)
        .clamp(1, truth.epochs.len() - 1);
    let (a, b) = (&truth.epochs[k - 1], &truth.epochs[k]);
    let u = ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
    a.tip_displacement.unwrap() * (1.0 - u) + b.tip_displacement.unwrap() * u
}

#[test]
fn the_bending_riser_tip_is_within_2_percent_of_its_length() {
    let (bytes, truth) = run(StructureKind::Riser, 1, 120.0, 10.0);
    let layout = Layout {
        sensors: truth.sensors.clone(),
        curves: truth.curves.clone(),
    };
    layout.validate().unwrap();
    let scan = Acquisition::scan_bytes(&bytes, AcquisitionConfig::default());
    let mut rec = EpochReconstructor::new();
    let (mut worst, mut checked, mut swing) = (0.0f64, 0, 0.0f64);
    for (t, q) in epochs(&scan) {
        if q.len() < layout.sensors.len() {
            continue; // a window the stream's start or end cut short
        }
        let shape = rec.run(&layout, &q, &EpochParams::default()).unwrap();
        assert!(shape.missing.is_empty() && shape.left_out.is_empty());
        let d: Vector3<f64> = shape.positions.nodes[&1] - shape.positions.nodes[&0];
        let tip = (d.x * d.x + d.y * d.y).sqrt();
        // A window averages the samples of the second before its end (10 Hz): its middle.
        let expected = truth_tip(&truth, t - 0.55);
        worst = worst.max((tip - expected).abs());
        swing = swing.max(expected);
        checked += 1;
    }
    eprintln!("{checked} epochs, tip swing {swing:.2} m, worst error {worst:.3} m");
    assert!(checked >= 100, "{checked} epochs");
    assert!(swing > 1.5, "the riser barely moved: {swing} m");
    // Issue 8: within 2 % of the riser's length.
    assert!(worst <= 0.02 * truth.size, "worst tip error {worst} m");
}

#[test]
fn missing_sensors_are_interpolated_and_a_curve_without_any_is_left_out() {
    let (bytes, truth) = run(StructureKind::Panel, 2, 5.0, 10.0);
    let layout = Layout {
        sensors: truth.sensors.clone(),
        curves: truth.curves.clone(),
    };
    layout.validate().unwrap();
    let scan = Acquisition::scan_bytes(&bytes, AcquisitionConfig::default());
    let (_, mut q) = epochs(&scan)
        .into_iter()
        .find(|(_, q)| q.len() == layout.sensors.len())
        .unwrap();
    // Two sensors of curve 0 drop out, and every sensor of curve 5.
    let gone: Vec<u16> = layout
        .sensors
        .iter()
        .filter(|s| s.curve == 5 || (s.curve == 0 && (s.sensor == 3 || s.sensor == 4)))
        .map(|s| s.sensor)
        .collect();
    for s in &gone {
        q.remove(s);
    }
    let shape = EpochReconstructor::new()
        .run(&layout, &q, &EpochParams::default())
        .unwrap();
    assert_eq!(shape.missing, gone);
    assert_eq!(shape.left_out.len(), 1, "{:?}", shape.left_out);
    assert!(shape.left_out[0].starts_with("curve 5"));
    assert_eq!(shape.positions.curves.len(), 5);
    assert!(shape
        .positions
        .curves
        .iter()
        .all(|c| c.points.iter().all(|p| p.iter().all(|x| x.is_finite()))));
}

/// The truth's top (sensor at the riser's top) at time `t`, linearly between epochs.
fn truth_top(truth: &sfs::simulate::structure::StructureTruth, t: f64) -> Vector3<f64> {
    let k = truth
        .epochs
        .partition_point(|e| e.t <= t)
        .clamp(1, truth.epochs.len() - 1);
    let (a, b) = (&truth.epochs[k - 1], &truth.epochs[k]);
    let u = ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
    let (pa, pb) = (a.positions.last().unwrap(), b.positions.last().unwrap());
    Vector3::from(*pa) * (1.0 - u) + Vector3::from(*pb) * u
}

/// Issue 8: displacement from the reference shape (the first epoch) follows the truth, and an
/// alarm on it fires when, and only when, the truth crosses the threshold.
#[test]
fn displacement_follows_the_truth_and_the_alarm_fires_when_and_only_when_crossed() {
    use sfs::monitor::alarm::{Alarm, AlarmMetric, Transition};
    use sfs::monitor::metrics::{compare, ReferenceBuilder, Shape};
    let (bytes, truth) = run(StructureKind::Riser, 1, 120.0, 10.0);
    let layout = Layout {
        sensors: truth.sensors.clone(),
        curves: truth.curves.clone(),
    };
    let scan = Acquisition::scan_bytes(&bytes, AcquisitionConfig::default());
    let mut rec = EpochReconstructor::new();
    let mut reference = ReferenceBuilder::new();
    let mut t_ref = None;
    let (threshold, hysteresis, tol) = (1.5, 0.2, 0.2);
    let mut alarm = Alarm::new(AlarmMetric::MaxDisplacement, threshold, hysteresis);
    let (mut raised, mut episodes, mut below) = (0, 0, true);
    let mut worst = 0.0f64;
    for (t, q) in epochs(&scan) {
        if q.len() < layout.sensors.len() {
            continue;
        }
        let shape = rec.run(&layout, &q, &EpochParams::default()).unwrap();
        let now = Shape::anchored(&shape.positions, 0).unwrap();
        let mid = t - 0.55;
        if reference.count() == 0 {
            assert!(reference.add(&now));
            t_ref = Some(mid);
            continue;
        }
        let m = compare(&reference.reference().unwrap(), &now);
        let expected = (truth_top(&truth, mid) - truth_top(&truth, t_ref.unwrap())).norm();
        worst = worst.max((m.max_displacement - expected).abs());
        if alarm.update(m.max_displacement) == Some(Transition::Raised) {
            raised += 1;
        }
        // The truth's episodes above the threshold, counted with the same hysteresis.
        if below && expected > threshold + tol {
            episodes += 1;
            below = false;
        } else if expected < threshold - hysteresis - tol {
            below = true;
        }
        if expected > threshold + tol {
            assert!(
                alarm.is_raised(),
                "t = {t:.1}: truth {expected:.2} m, alarm down"
            );
        }
        if expected < threshold - hysteresis - tol {
            assert!(
                !alarm.is_raised(),
                "t = {t:.1}: truth {expected:.2} m, alarm up"
            );
        }
    }
    eprintln!("displacement worst error {worst:.3} m; {raised} alarms, {episodes} episodes");
    assert!(
        worst <= 0.02 * truth.size,
        "worst displacement error {worst} m"
    );
    assert!(
        episodes >= 2,
        "the riser crossed the threshold {episodes} times"
    );
    assert_eq!(raised, episodes);
}

/// A configuration reading standard input with `monitor` (the `[monitor]` keys, alarms, and
/// curves; `truth`'s curves when it names none) and every sensor of `truth`'s layout.
fn config_text(monitor: &str, truth: &sfs::simulate::structure::StructureTruth) -> String {
    let mut cfg = format!("[source]\nkind = \"stdin\"\n[monitor]\n{monitor}");
    if !monitor.contains("[[monitor.curve]]") {
        for c in &truth.curves {
            cfg += &format!(
                "[[monitor.curve]]\nnodes = {:?}\nnode_s = {:?}\nlength = {}\n",
                c.nodes, c.node_s, c.length
            );
        }
    }
    for s in &truth.sensors {
        cfg += &format!(
            "[[monitor.sensor]]\nsensor = {}\ncurve = {}\ns = {}\n",
            s.sensor, s.curve, s.s
        );
    }
    cfg
}

/// A monitoring session on standard input given `bytes` to the end, logging at `info`: its
/// log and directory.
fn monitor_logged(
    dir: &std::path::Path,
    monitor: &str,
    truth: &sfs::simulate::structure::StructureTruth,
    bytes: &[u8],
) -> (String, std::path::PathBuf) {
    use std::io::Write;
    let (mut child, session) = start_monitoring_logged(dir, monitor, truth, "sfs=info");
    child.stdin.take().unwrap().write_all(bytes).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (String::from_utf8_lossy(&out.stderr).into_owned(), session)
}

/// `sfs run --stdin` on a monitoring configuration: `monitor` (the `[monitor]` keys, alarms
/// and curves) plus every sensor of `truth`'s layout, in `dir/session`; standard input piped.
fn start_monitoring(
    dir: &std::path::Path,
    monitor: &str,
    truth: &sfs::simulate::structure::StructureTruth,
) -> (std::process::Child, std::path::PathBuf) {
    start_monitoring_logged(dir, monitor, truth, "off")
}

/// As [`start_monitoring`], logging at `log` to a piped standard error; `truth`'s curves are
/// added when `monitor` names none.
fn start_monitoring_logged(
    dir: &std::path::Path,
    monitor: &str,
    truth: &sfs::simulate::structure::StructureTruth,
    log: &str,
) -> (std::process::Child, std::path::PathBuf) {
    let cfg = config_text(monitor, truth);
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("monitor.toml"), cfg).unwrap();
    let session = dir.join("session");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", log, "run", "--stdin", "--config"])
        .arg(dir.join("monitor.toml"))
        .arg("--session")
        .arg(&session)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    (child, session)
}

/// The monitoring daemon end to end: the riser's stream on standard input, `sfs run` with a
/// `[monitor]` layout and an alarm: a metrics line per epoch, the alarm's transitions in
/// events.log, latest.glb, and the metrics files rotated within their retention.
#[test]
fn the_monitoring_daemon_writes_metrics_events_and_the_latest_shape() {
    use std::io::Write;
    let dir = tmpdir("monitor-daemon");
    let (bytes, truth) = run(StructureKind::Riser, 1, 120.0, 10.0);
    let (mut child, session) = start_monitoring(
        &dir,
        "epoch_hz = 5.0\nanchor = 0\nreference_s = 1.0\nmetrics_max_mb = 0.01\nmetrics_keep = 1\n\
         [[monitor.alarm]]\nmetric = \"max_displacement\"\nthreshold = 1.5\nhysteresis = 0.2\n\
         [[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n",
        &truth,
    );
    child.stdin.take().unwrap().write_all(&bytes).unwrap();
    assert!(child.wait().unwrap().success());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(session.join("report.json")).unwrap()).unwrap();
    let m = &report["monitor"];
    // 120 s at 5 epochs per second (the last window closes at the end of input).
    let epochs = m["epochs"].as_u64().unwrap();
    assert!((599..=601).contains(&epochs), "{epochs} epochs");
    assert_eq!(m["failed"], 0);
    assert_eq!(m["alarms_raised"], 4);
    let events = std::fs::read_to_string(session.join("events.log")).unwrap();
    assert_eq!(events.matches("alarm raised").count(), 4, "{events}");
    assert_eq!(events.matches("alarm cleared").count(), 4, "{events}");
    let glb = std::fs::read(session.join("latest.glb")).unwrap();
    let net = sfs::gltf_out::read_glb(&glb).unwrap();
    assert_eq!(net.curves.len(), 1);
    // Retention: 10 kB per file, the current one and one old one; every line complete, and
    // no sensor missing (the windows of all sensors are aligned).
    let mut lines = 0;
    for name in ["metrics.csv", "metrics.1.csv"] {
        let text = std::fs::read_to_string(session.join(name)).unwrap();
        assert!(text.len() <= 10_000, "{name}: {} bytes", text.len());
        for l in text.lines().filter(|l| !l.starts_with("t_s")) {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 8, "{name}: {l}");
            assert_eq!(f[4], "0", "{name}: sensors missing: {l}");
            lines += 1;
        }
    }
    assert!(!session.join("metrics.2.csv").exists());
    assert!(lines > 100 && lines < epochs as usize, "{lines} lines kept");
}

/// The Prometheus endpoint: off unless configured, on 127.0.0.1, serving the latest epoch's
/// gauges and the session's counters while the session runs.
#[test]
fn metrics_are_served_for_a_scraper_while_the_session_runs() {
    use std::io::{Read, Write};
    let dir = tmpdir("monitor-http");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let (bytes, truth) = run(StructureKind::Riser, 1, 30.0, 10.0);
    let (mut child, _session) = start_monitoring(
        &dir,
        &format!(
            "http_port = {port}\nreference_s = 1.0\n\
             [[monitor.alarm]]\nmetric = \"max_displacement\"\nthreshold = 1.0\n\
             [[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n"
        ),
        &truth,
    );
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(&bytes).unwrap();
    stdin.flush().unwrap();
    let get = || -> Option<String> {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
        // A scraper names the host it asks (issue 31: a request without Host gets 421).
        s.write_all(format!("GET /metrics HTTP/1.0\r\nHost: 127.0.0.1:{port}\r\n\r\n").as_bytes())
            .ok()?;
        let mut out = String::new();
        s.read_to_string(&mut out).ok()?;
        Some(out)
    };
    let t0 = std::time::Instant::now();
    // The latency of an epoch is set once its outputs are written, just after its gauges.
    let latency = |page: &str| -> f64 {
        page.lines()
            .find_map(|l| l.strip_prefix("sfs_epoch_latency_seconds "))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0.0)
    };
    let page = loop {
        if let Some(p) = get().filter(|p| p.contains("sfs_epochs_total ") && latency(p) > 0.0) {
            break p;
        }
        assert!(t0.elapsed().as_secs() < 20, "no metrics served");
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    assert!(
        page.starts_with("HTTP/1.0 200 OK") || page.starts_with("HTTP/1.1 200 OK"),
        "{page}"
    );
    assert!(
        page.contains("# TYPE sfs_max_displacement_meters gauge"),
        "{page}"
    );
    assert!(
        page.contains("sfs_alarm{metric=\"max_displacement\",threshold=\"1\"} "),
        "{page}"
    );
    assert!(page.contains("sfs_sensors_missing 0"), "{page}");
    assert!(page.contains("sfs_sensors_unknown 0"), "{page}");
    // Issue 20: the dashboard's epoch latency, the alert's count of epochs with a sensor out.
    assert!(page.contains("sfs_sensors_left_out_epochs 0"), "{page}");
    assert!(latency(&page) < 5.0, "{page}");
    drop(stdin); // end of input: the session finishes and the endpoint closes
    assert!(child.wait().unwrap().success());
    assert!(get().is_none(), "still serving after the session ended");
}

/// Smoothing across epochs (`[monitor] smoothing_s`) takes the epoch-to-epoch jitter of the
/// metrics down (at 5 epochs per second the sensors' noise shows).
#[test]
fn smoothing_across_epochs_lowers_the_jitter() {
    use sfs::monitor::run::Monitor;
    let (bytes, truth) = run(StructureKind::Riser, 3, 60.0, 10.0);
    let cfg = |smoothing_s: f64| sfs::monitor::settings::MonitorConfig {
        layout: Layout {
            sensors: truth.sensors.clone(),
            curves: truth.curves.clone(),
        },
        epoch_hz: 5.0,
        anchor: 0,
        x_azimuth_deg: 90.0,
        reference_s: 1.0,
        reference: None,
        smoothing_s,
        latest_every: 1000,
        surface: None,
        regression: None,
        metrics_max_bytes: u64::MAX,
        metrics_keep: 1,
        alarms: Vec::new(),
        http: None,
    };
    let acq = AcquisitionConfig {
        array_window: 0.2,
        ..Default::default()
    };
    let scan = Acquisition::scan_bytes(&bytes, acq);
    let mut jitter = Vec::new();
    for tau in [0.0, 1.0] {
        let dir = tmpdir(&format!("monitor-smooth-{tau}"));
        let mut m = Monitor::new(cfg(tau), &dir, sfs::monitor::run::Begin::Fresh).unwrap();
        for e in &scan.array {
            m.feed(e);
        }
        m.finish();
        let x: Vec<f64> = std::fs::read_to_string(dir.join("metrics.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(3).unwrap().parse().unwrap())
            .collect();
        assert!(x.len() > 250, "{} epochs", x.len());
        let j = x[10..]
            .windows(3)
            .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
            .sum::<f64>()
            / (x.len() - 12) as f64;
        jitter.push(j);
    }
    eprintln!(
        "curvature-change jitter: raw {:.5}, smoothed {:.5}",
        jitter[0], jitter[1]
    );
    assert!(jitter[1] < 0.5 * jitter[0], "{jitter:?}");
}

/// `bytes` re-encoded with every sensor-array sample passed through `edit` (which drops it
/// by returning false: the array sends nothing for that sensor, no sequence number is lost).
fn edit_samples(
    bytes: &[u8],
    mut edit: impl FnMut(&mut device_protocol::ArraySample) -> bool,
) -> Vec<u8> {
    use device_protocol::{Decoder, Event, Packet};
    let (mut out, mut seq, mut dec) = (Vec::new(), 0u8, Decoder::new());
    for e in dec.feed(bytes) {
        if let Event::Packet { mut packet, .. } = e {
            if let Packet::ArraySample(s) = &mut packet {
                if !edit(s) {
                    continue;
                }
            }
            packet.encode(seq, &mut out);
            seq = seq.wrapping_add(1);
        }
    }
    out
}

/// `bytes` without the samples of `sensors` whose device time is in `t_us` (a dropout).
fn without_sensors(bytes: &[u8], sensors: &[u16], t_us: std::ops::Range<u32>) -> Vec<u8> {
    edit_samples(bytes, |s| {
        !(sensors.contains(&s.sensor) && t_us.contains(&s.t_us))
    })
}

/// Issue 8, point 3: per-sensor health. On the riser, sensor 5's accelerometer saturates from
/// 10 s to 15 s, a magnet near sensors 20 and 21 raises their field by 30 % from 10 s to
/// 20 s, sensor 30 sends nothing from 25 s to 30 s: each is counted in its column of
/// metrics.csv while it lasts (and only then), left out and interpolated across, and the shape
/// stays within 2 % of the truth.
#[test]
fn saturated_disturbed_and_missing_sensors_are_counted_and_left_out() {
    let (bytes, truth) = run(StructureKind::Riser, 9, 40.0, 10.0);
    let during =
        |t_us: u32, a: f64, b: f64| (1e6 + a * 1e6..1e6 + b * 1e6).contains(&(t_us as f64));
    let bytes = edit_samples(&bytes, |s| {
        if s.sensor == 5 && during(s.t_us, 10.0, 15.0) {
            s.acc[0] = i16::MAX;
        }
        if (s.sensor == 20 || s.sensor == 21) && during(s.t_us, 10.0, 20.0) {
            s.mag = s.mag.map(|m| (m as f64 * 1.3) as i16);
        }
        !(s.sensor == 30 && during(s.t_us, 25.0, 30.0))
    });
    let acq = AcquisitionConfig {
        array_window: 0.2,
        ..Default::default()
    };
    let scan = Acquisition::scan_bytes(&bytes, acq);
    let dir = tmpdir("monitor-health");
    let cfg = layout_config(&dir, "anchor = 0\nreference_s = 1.0", &truth);
    let (lines, report) = monitor_lines(cfg, &dir, &scan);
    assert_eq!(report.failed, 0);
    let (mut worst, mut seen) = (0.0f64, [0; 3]);
    for l in &lines[..lines.len() - 1] {
        let f: Vec<f64> = l.split(',').take(7).map(|x| x.parse().unwrap()).collect();
        let (t, max_d) = (f[0], f[1]);
        let [missing, saturated, disturbed] = [f[4], f[5], f[6]];
        let inside = |a: f64, b: f64| t > a + 0.4 && t <= b;
        let outside = |a: f64, b: f64| t <= a || t > b + 0.4;
        for (k, (value, n, a, b)) in [
            (missing, 1.0, 25.0, 30.0),
            (saturated, 1.0, 10.0, 15.0),
            (disturbed, 2.0, 10.0, 20.0),
        ]
        .into_iter()
        .enumerate()
        {
            if inside(a, b) {
                assert_eq!(value, n, "t = {t}: {l}");
                seen[k] += 1;
            } else if outside(a, b) {
                assert_eq!(value, 0.0, "t = {t}: {l}");
            }
        }
        let expected = (truth_top(&truth, t - 0.1) - truth_top(&truth, 0.5)).norm();
        worst = worst.max((max_d - expected).abs());
    }
    assert!(seen.iter().all(|&n| n >= 20), "{seen:?}");
    eprintln!("health: worst displacement error {worst:.3} m");
    // For a scraper, while it lasts: which sensors are left out, and why.
    let live = tmpdir("monitor-health-exposition");
    let cfg = layout_config(&live, "anchor = 0\nreference_s = 1.0", &truth);
    let mut m =
        sfs::monitor::run::Monitor::new(cfg, &live, sfs::monitor::run::Begin::Fresh).unwrap();
    for e in scan.array.iter().filter(|e| e.t < 12.0) {
        m.feed(e);
    }
    let page = sfs::metrics::SessionMetrics::new(Some(&m.metrics)).encode();
    for l in [
        "sfs_sensor_left_out{sensor=\"5\",reason=\"saturated\"} 1",
        "sfs_sensor_left_out{sensor=\"20\",reason=\"disturbed\"} 1",
        "sfs_sensor_left_out{sensor=\"21\",reason=\"disturbed\"} 1",
    ] {
        assert!(page.contains(l), "{page}");
    }
    assert_eq!(page.matches("sfs_sensor_left_out{").count(), 3, "{page}");
    // Per sensor, in events.log: when it was left out and why, and when it came back.
    let events = std::fs::read_to_string(dir.join("events.log")).unwrap();
    let got: Vec<(f64, &str)> = events
        .lines()
        .filter_map(|l| {
            let (t, rest) = l.strip_prefix("t=")?.split_once(' ')?;
            Some((t.parse().ok()?, rest))
        })
        .collect();
    let expected = [
        (10.0, "sensor 5 saturated"),
        (10.0, "sensor 20 disturbed"),
        (10.0, "sensor 21 disturbed"),
        (15.0, "sensor 5 ok"),
        (20.0, "sensor 20 ok"),
        (20.0, "sensor 21 ok"),
        (25.0, "sensor 30 missing"),
        (30.0, "sensor 30 ok"),
    ];
    assert_eq!(got.len(), expected.len(), "{events}");
    for ((t, what), (te, we)) in got.iter().zip(expected) {
        assert_eq!(*what, we, "{events}");
        assert!(*t > te && *t <= te + 0.4, "{what} at {t}: {events}");
    }
    assert!(worst <= 0.02 * truth.size, "worst {worst} m");
}

/// Issue 8, point 6: a monitoring session on a serial device survives sensors dropping out,
/// an unplug and the device rebooting (clock and sequence restarting): every epoch is
/// reconstructed, session time stays monotonic, dropped sensors are counted as missing
/// while they are gone, and the shape after the reboot still follows the truth.
#[test]
fn monitoring_survives_dropouts_an_unplug_and_a_device_reboot() {
    use common::pty::{play, plug, spec};
    use sfs::shutdown::Shutdown;
    use std::time::Duration;
    let dir = tmpdir("monitor-unplug");
    let link = dir.join("ttySFS");
    let session_dir = dir.join("session");
    let (a, truth_a) = run(StructureKind::Riser, 1, 40.0, 10.0);
    let (b, truth_b) = run(StructureKind::Riser, 2, 40.0, 10.0);
    // Sensors 10 and 11 send nothing from 10 s to 20 s of the first run (device clock
    // starts at 1 s).
    let a = without_sensors(&a, &[10, 11], 11_000_000..21_000_000);
    let epoch_hz = 5.0;
    // One averaging window per epoch, as a configuration with this [monitor] resolves.
    let options =
        sfs::settings::Settings::default().with_monitor(sfs::monitor::settings::MonitorConfig {
            layout: Layout {
                sensors: truth_a.sensors.clone(),
                curves: truth_a.curves.clone(),
            },
            epoch_hz,
            anchor: 0,
            x_azimuth_deg: 90.0,
            reference_s: 1.0,
            reference: None,
            smoothing_s: 0.0,
            latest_every: 5,
            surface: None,
            regression: None,
            metrics_max_bytes: u64::MAX,
            metrics_keep: 1,
            alarms: Vec::new(),
            http: None,
        });
    let shutdown = Shutdown::new();
    let mut dev = plug(&link);
    let session = {
        let (spec, dir, shutdown) = (spec(&link), session_dir.clone(), shutdown.clone());
        std::thread::spawn(move || {
            tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap()
                .block_on(sfs::session::run(
                    spec,
                    &dir,
                    &options,
                    sfs::session::Start::New,
                    shutdown,
                ))
        })
    };
    let capture = session_dir.join("capture.bin");
    play(&mut dev, &a);
    common::wait_for("the first run captured", Duration::from_secs(20), || {
        common::file_len(&capture) == a.len() as u64
    });
    drop(dev); // unplug
    std::thread::sleep(Duration::from_millis(300));
    let mut dev = plug(&link); // back, rebooted: a new HELLO, clock and sequence from 0
    play(&mut dev, &b);
    common::wait_for("the second run captured", Duration::from_secs(20), || {
        common::file_len(&capture) == (a.len() + b.len()) as u64
    });
    // Let the session decode the last bytes before stopping it.
    std::thread::sleep(Duration::from_millis(300));
    shutdown.trigger();
    let outcome = session.join().unwrap().expect("session ran");
    drop(dev);

    let report = &outcome.report;
    assert_eq!(report.link.reboots, 1, "{:?}", report.link);
    assert_eq!(report.link.connects, 2, "{:?}", report.link);
    let m = report.monitor.as_ref().expect("monitor report");
    assert_eq!(m.failed, 0);
    // Acquisition closes the windows of sensors that stopped sending on time: none late.
    assert_eq!(m.late, 0);
    // 80 s of stream at 5 epochs per second, each closed once.
    assert!((398..=401).contains(&m.epochs), "{} epochs", m.epochs);
    let text = std::fs::read_to_string(session_dir.join("metrics.csv")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').take(7).map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len() as u64, m.epochs);
    let (mut worst, mut after_reboot) = (0.0f64, 0);
    for (k, r) in rows.iter().enumerate() {
        let (t, max_d, missing) = (r[0], r[1], r[4]);
        if k > 0 {
            assert!(t > rows[k - 1][0], "time went back at line {}: {t}", k + 2);
        }
        if (10.6..=19.8).contains(&t) {
            assert_eq!(missing, 2.0, "t = {t}: sensors 10 and 11 are out");
        } else if !(9.6..=20.6).contains(&t) {
            assert_eq!(missing, 0.0, "t = {t}");
        }
        // After the reboot (session time bridged at 40 s): the second run's truth, against
        // the reference (the mean of the first run's first second).
        if t > 41.0 && t < 79.6 {
            let mid = t - 40.0 - 0.1;
            let expected = (truth_top(&truth_b, mid) - truth_top(&truth_a, 0.5)).norm();
            worst = worst.max((max_d - expected).abs());
            after_reboot += 1;
        }
    }
    eprintln!("after the reboot: {after_reboot} epochs, worst displacement error {worst:.3} m");
    assert!(after_reboot > 180);
    assert!(worst <= 0.02 * truth_a.size, "worst {worst} m");
}

/// The `[monitor]` configuration of `truth`'s layout (5 epochs per second) with `keys`.
fn layout_config(
    dir: &std::path::Path,
    keys: &str,
    truth: &sfs::simulate::structure::StructureTruth,
) -> sfs::monitor::settings::MonitorConfig {
    let text = config_text(&format!("epoch_hz = 5.0\n{keys}\n"), truth);
    let file = dir.join("monitor.toml");
    std::fs::write(&file, &text).unwrap();
    sfs::config::load(&file).unwrap().monitor.unwrap()
}

/// `duration` seconds of the simulated structure (10 Hz, seed `seed`) as acquisition gives them
/// to a monitor at 5 epochs per second, and the truth.
fn epochs_of(
    kind: StructureKind,
    seed: u64,
    duration: f64,
) -> (sfs::scan::Scan, sfs::simulate::structure::StructureTruth) {
    let (bytes, truth) = run(kind, seed, duration, 10.0);
    let acq = AcquisitionConfig {
        array_window: 0.2,
        ..Default::default()
    };
    (Acquisition::scan_bytes(&bytes, acq), truth)
}

/// The riser at rest (straight up, 20 m) as a reference file: a two-point polyline.
const VERTICAL: &str = r#"{"format": "sfs-monitor-reference", "version": 1, "anchor": 0,
    "curves": [{"curve": 0, "points": [[0, 0, 0], [0, 0, 20]]}]}"#;

/// Runs a monitor over `scan` in `dir`; its metrics lines (without the header).
fn monitor_lines(
    cfg: sfs::monitor::settings::MonitorConfig,
    dir: &std::path::Path,
    scan: &sfs::scan::Scan,
) -> (Vec<String>, sfs::monitor::run::MonitorReport) {
    let mut m = sfs::monitor::run::Monitor::new(cfg, dir, sfs::monitor::run::Begin::Fresh).unwrap();
    for e in &scan.array {
        m.feed(e);
    }
    m.finish();
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    (text.lines().skip(1).map(String::from).collect(), m.report)
}

/// Issue 8, point 3: the reference from a file. A session writes the reference it built as
/// reference.json; a later session naming it in `reference_file` measures against exactly
/// that shape from its first epoch.
#[test]
fn a_reference_built_by_one_session_is_kept_by_the_next() {
    let (scan, truth) = epochs_of(StructureKind::Riser, 4, 30.0);
    let first = tmpdir("monitor-ref-first");
    let cfg = layout_config(&first, "reference_s = 2.0", &truth);
    let (built, report) = monitor_lines(cfg, &first, &scan);
    assert_eq!(report.reference_epochs, 10);
    let kept = first.join("reference.json");
    assert!(kept.exists());

    let second = tmpdir("monitor-ref-second");
    let cfg = layout_config(
        &second,
        &format!("reference_file = {:?}", kept.to_str().unwrap()),
        &truth,
    );
    assert!(cfg.reference.is_some());
    let (again, report) = monitor_lines(cfg, &second, &scan);
    assert_eq!(report.reference_epochs, 0);
    assert!(!second.join("reference.json").exists());
    assert_eq!(built.len(), again.len());
    assert!(built.len() > 140, "{} epochs", built.len());
    // While the first session built its reference its metrics differ; after, not a digit.
    assert_ne!(built[..9], again[..9]);
    assert_eq!(built[10..], again[10..]);
    // Afresh in the first directory, measuring from its own kept reference: the file stays.
    let cfg = layout_config(
        &first,
        &format!("reference_file = {:?}", kept.to_str().unwrap()),
        &truth,
    );
    let (third, _) = monitor_lines(cfg, &first, &scan);
    assert!(kept.exists(), "the configured reference was removed");
    assert_eq!(third, again);
}

/// A design shape as the reference: the riser's rest (straight up, 20 m) given as a
/// two-point polyline; the displacement measured against it is the truth's top
/// displacement from the vertical.
#[test]
fn a_design_reference_is_resampled_and_measured_against() {
    let (scan, truth) = epochs_of(StructureKind::Riser, 5, 60.0);
    let dir = tmpdir("monitor-ref-design");
    std::fs::write(dir.join("vertical.json"), VERTICAL).unwrap();
    // Relative to the configuration file's directory.
    let cfg = layout_config(&dir, "reference_file = \"vertical.json\"", &truth);
    let (lines, _) = monitor_lines(cfg, &dir, &scan);
    let (mut worst, mut swing) = (0.0f64, 0.0f64);
    for l in &lines[1..lines.len() - 1] {
        let f: Vec<f64> = l.split(',').take(2).map(|x| x.parse().unwrap()).collect();
        let expected = (truth_top(&truth, f[0] - 0.1) - Vector3::new(0.0, 0.0, 20.0)).norm();
        worst = worst.max((f[1] - expected).abs());
        swing = swing.max(expected);
    }
    eprintln!("against the design: swing {swing:.2} m, worst error {worst:.3} m");
    assert!(swing > 1.5);
    assert!(worst <= 0.02 * truth.size, "worst {worst} m");
}

/// The `[monitor]` keys of the resume tests: a reference of 4 s, an alarm at 1.5 m.
const RESUME_KEYS: &str = "epoch_hz = 5.0\nanchor = 0\nreference_s = 4.0\nlatest_every = 7\n\
     [[monitor.alarm]]\nmetric = \"max_displacement\"\nthreshold = 1.5\nhysteresis = 0.2\n\
     [[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n";

/// A monitoring session on standard input (`monitor`: its keys) given the first 55 % of
/// `bytes`, killed (SIGKILL) once it has measured 300 epochs, then resumed with the rest;
/// its directory.
fn kill_and_resume(
    dir: &std::path::Path,
    monitor: &str,
    bytes: &[u8],
    truth: &sfs::simulate::structure::StructureTruth,
) -> std::path::PathBuf {
    use std::io::Write;
    use std::time::Duration;
    let (first, rest) = bytes.split_at(bytes.len() * 11 / 20);
    let (mut child, session) = start_monitoring(dir, monitor, truth);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(first).unwrap();
    stdin.flush().unwrap();
    let metrics = session.join("metrics.csv");
    common::wait_for(
        "the first part captured and measured",
        Duration::from_secs(20),
        || {
            // Everything captured (the current file ends where `first` does; earlier files
            // may have been rotated away) and measured.
            std::fs::read(session.join("capture.bin")).is_ok_and(|c| first.ends_with(&c))
                && std::fs::read_to_string(&metrics).is_ok_and(|t| t.lines().count() > 300)
        },
    );
    child.kill().unwrap(); // SIGKILL
    let _ = child.wait();
    drop(stdin);
    let events_before = std::fs::read_to_string(session.join("events.log")).unwrap();
    assert!(events_before.contains("alarm raised"), "{events_before}");

    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "run", "--stdin", "--resume"])
        .arg(&session)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(rest).unwrap();
    assert!(child.wait().unwrap().success());
    // No temporary file of the killed session is left behind.
    for e in std::fs::read_dir(&session).unwrap() {
        let name = e.unwrap().file_name();
        assert!(!name.to_string_lossy().starts_with('.'), "{name:?} left");
    }
    session
}

/// A monitoring session killed (SIGKILL) and resumed (`sfs run --resume`) writes the same
/// metrics, events, reference and latest shape as the session would have uninterrupted
/// (`sfs replay` of the whole capture): the resumed session feeds the capture again, quietly
/// up to the last metrics line, so that the reference, the alarms' states and the epoch
/// count carry over.
#[test]
fn a_killed_monitoring_session_resumes_where_it_stopped() {
    let dir = tmpdir("monitor-resume");
    let (bytes, truth) = run(StructureKind::Riser, 1, 120.0, 10.0);
    let session = kill_and_resume(&dir, RESUME_KEYS, &bytes, &truth);
    assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), bytes);

    let whole = dir.join("whole");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "replay"])
        .arg(session.join("capture.bin"))
        .arg("--config")
        .arg(dir.join("monitor.toml"))
        .arg("--out")
        .arg(&whole)
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    for name in ["metrics.csv", "events.log", "reference.json", "latest.glb"] {
        let (a, b) = (
            std::fs::read(session.join(name)).unwrap(),
            std::fs::read(whole.join(name)).unwrap(),
        );
        assert!(a == b, "{name} differs from the uninterrupted session's");
    }
    let lines = std::fs::read_to_string(session.join("metrics.csv"))
        .unwrap()
        .lines()
        .count();
    assert!((599..=602).contains(&lines), "{lines} lines");
    let report = |d: &std::path::Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap()
    };
    let (r, w) = (report(&session), report(&whole));
    for key in ["epochs", "alarms_raised", "reference_epochs"] {
        assert_eq!(r["monitor"][key], w["monitor"][key], "{key}");
    }
    assert_eq!(w["monitor"]["alarms_raised"], 4);
}

/// Issue 8, point 5 with point 6: the capture of a monitoring session is rotated
/// (`[output] capture_max_mb`, `capture_keep`), so a month-long run cannot fill the disk; a
/// session killed and resumed from its last capture file alone (its session time from the
/// file's sidecar, the reference from reference.json, the alarm states from the last metrics
/// line) writes the metrics and events of a session that was never interrupted.
#[test]
fn a_monitoring_session_with_a_rotated_capture_resumes_too() {
    use std::io::Write;
    let dir = tmpdir("monitor-rotated");
    let (bytes, truth) = run(StructureKind::Riser, 1, 120.0, 10.0);
    // 1.3 MB of stream in files of 60 kB, 4 old ones kept.
    let keys = format!("{RESUME_KEYS}[output]\ncapture_max_mb = 0.06\ncapture_keep = 4\n");
    let session = kill_and_resume(&dir.join("a"), &keys, &bytes, &truth);
    let whole_dir = dir.join("b");
    std::fs::create_dir_all(&whole_dir).unwrap();
    let (mut child, whole) = start_monitoring(&whole_dir, &keys, &truth);
    child.stdin.take().unwrap().write_all(&bytes).unwrap();
    assert!(child.wait().unwrap().success());

    for d in [&session, &whole] {
        let mut kept = Vec::new();
        for n in [
            "capture.4.bin",
            "capture.3.bin",
            "capture.2.bin",
            "capture.1.bin",
            "capture.bin",
        ] {
            let b = std::fs::read(d.join(n)).unwrap();
            assert!(b.len() <= 70_000, "{n}: {} bytes", b.len());
            kept.extend_from_slice(&b);
        }
        assert!(!d.join("capture.5.bin").exists());
        assert!(
            bytes.ends_with(&kept),
            "the kept files are not the stream's end"
        );
    }
    for name in ["metrics.csv", "events.log", "reference.json"] {
        let (a, b) = (
            std::fs::read_to_string(session.join(name)).unwrap(),
            std::fs::read_to_string(whole.join(name)).unwrap(),
        );
        assert!(a == b, "{name} differs from the uninterrupted session's");
    }
    let events = std::fs::read_to_string(whole.join("events.log")).unwrap();
    assert_eq!(events.matches("alarm raised").count(), 4, "{events}");
}

/// Issue 8, point 2: the optional surface. The panel bulging by up to 5 cm, surfaced in
/// latest.glb (`surface = true`): a valid mesh over the network's closed cells, lying on the
/// truth's bulge.
#[test]
fn the_panel_is_surfaced_in_the_latest_shape() {
    let (scan, truth) = epochs_of(StructureKind::Panel, 6, 25.0);
    let dir = tmpdir("monitor-panel-surface");
    let cfg = layout_config(
        &dir,
        "reference_s = 1.0\nsurface = true\nlatest_every = 10",
        &truth,
    );
    let (lines, report) = monitor_lines(cfg, &dir, &scan);
    assert_eq!(report.failed, 0);
    assert_eq!(report.surfaces_failed, 0);
    assert_eq!(report.surfaces, lines.len() as u64 / 10);
    // Issue 19, point 5: the same faces at every epoch, and from the second surface on the
    // same weights: two factorisations in all, every later surface back-substitutions.
    assert!(report.surfaces > 3);
    assert_eq!(report.surface_factorisations, 2);
    // The epoch of the last latest.glb, and the truth then: the bulge at the centre (sensor 5
    // of curve 1, the middle line along x), the anchor (curve 0's first sensor).
    let k = lines.len() / 10 * 10 - 1;
    let t: f64 = lines[k].split(',').next().unwrap().parse().unwrap();
    let at = |sensor: usize| -> Vector3<f64> {
        let e = truth
            .epochs
            .partition_point(|e| e.t <= t - 0.1)
            .clamp(1, truth.epochs.len() - 1);
        let (a, b) = (&truth.epochs[e - 1], &truth.epochs[e]);
        let u = ((t - 0.1 - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
        Vector3::from(a.positions[sensor]) * (1.0 - u) + Vector3::from(b.positions[sensor]) * u
    };
    let bulge = at(16).z;
    let size = bulge.abs();
    let anchor = at(0);
    assert!(size > 0.03, "the panel barely bulged: {bulge} m");
    let net = sfs::gltf_out::read_glb(&std::fs::read(dir.join("latest.glb")).unwrap()).unwrap();
    let mesh = net.surface.expect("a surface in latest.glb");
    assert!(
        mesh.triangles.len() > 100,
        "{} triangles",
        mesh.triangles.len()
    );
    let v = &mesh.positions;
    for tri in &mesh.triangles {
        let [a, b, c] = tri.map(|i| v[i as usize]);
        assert!((b - a).cross(&(c - a)).norm() > 0.0, "degenerate {tri:?}");
    }
    let pi = std::f64::consts::PI;
    let (mut worst, mut sum) = (0.0f64, 0.0);
    for p in v {
        assert!(p.iter().all(|x| x.is_finite()));
        let w = p + anchor;
        let dz = (w.z - bulge * (pi * w.x).sin() * (pi * w.y).sin()).abs();
        worst = worst.max(dz);
        sum += dz;
    }
    let mean = sum / v.len() as f64;
    eprintln!(
        "panel surface: {} vertices, bulge {:.1} mm, height error mean {:.2} mm, max {:.2} mm, {:.1} ms",
        v.len(),
        bulge * 1e3,
        mean * 1e3,
        worst * 1e3,
        report.surface_ms.unwrap()
    );
    assert!(
        mean < 0.03 * size && worst < 0.06 * size,
        "mean {mean}, max {worst}"
    );

    // The metrics: the largest displacement from the reference (the mean of the first
    // second, its middle at 0.5 s) is the bulge's change at the centre. Errors are mostly
    // below 1.5 mm; the worst (~7 mm) come where the bulge passes its reference value and the
    // largest displacement is the largest noise over the 600 points (two samples per sensor
    // per epoch; the magnetometers' heading noise moves the far edges). Within 1 % of the
    // panel's size.
    let a = |t: f64| 0.05 * (std::f64::consts::TAU * t / 30.0).sin();
    let mut worst = 0.0f64;
    for l in &lines[5..] {
        let f: Vec<f64> = l.split(',').take(2).map(|x| x.parse().unwrap()).collect();
        worst = worst.max((f[1] - (a(f[0] - 0.1) - a(0.5)).abs()).abs());
    }
    eprintln!("panel displacement: worst error {:.2} mm", worst * 1e3);
    assert!(worst < 0.01 * truth.size, "{worst} m");
}

/// The kept configuration of a session (`SESSION/config.toml`, used by `--resume` without
/// `--config`) resolves its relative paths where it was copied from: a `reference_file`
/// next to the original configuration is found again.
#[test]
fn a_resumed_session_finds_the_relative_paths_of_its_configuration() {
    use std::io::Write;
    let dir = tmpdir("monitor-kept-config");
    let (bytes, truth) = run(StructureKind::Riser, 7, 20.0, 10.0);
    let cfg_dir = dir.join("etc");
    std::fs::create_dir_all(&cfg_dir).unwrap();
    std::fs::write(cfg_dir.join("vertical.json"), VERTICAL).unwrap();
    let (mut child, session) = start_monitoring(
        &cfg_dir,
        "reference_file = \"vertical.json\"\n\
         [[monitor.curve]]\nnodes = [0, 1]\nnode_s = [0.0, 20.0]\nlength = 20.0\n",
        &truth,
    );
    let (first, rest) = bytes.split_at(bytes.len() / 2);
    child.stdin.take().unwrap().write_all(first).unwrap();
    assert!(child.wait().unwrap().success());
    let kept = std::fs::read_to_string(session.join("config.toml")).unwrap();
    assert!(kept.starts_with("# sfs: copied from /"), "{kept}");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "run", "--stdin", "--resume"])
        .arg(&session)
        .current_dir(&dir)
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(rest).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(session.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        report["monitor"]["reference_epochs"], 0,
        "the file is the reference"
    );
    let lines = std::fs::read_to_string(session.join("metrics.csv"))
        .unwrap()
        .lines()
        .count();
    assert!((99..=102).contains(&lines), "{lines} lines");
}

/// Issue 8, point 1: the reference frame. The riser bends towards magnetic east; with the
/// structure's x axis pointing north (`x_azimuth_deg = 0`) its top moves along −y in
/// `latest.glb` (z stays up), and the metrics, which do not depend on the frame, are the same
/// digits as in the sensors' own frame.
#[test]
fn the_shape_is_given_in_the_configured_frame() {
    let (scan, truth) = epochs_of(StructureKind::Riser, 8, 20.0);
    let mut metrics = Vec::new();
    for azimuth in [90.0, 0.0] {
        let dir = tmpdir(&format!("monitor-frame-{azimuth}"));
        let cfg = layout_config(
            &dir,
            &format!("anchor = 0\nreference_s = 1.0\nlatest_every = 1\nx_azimuth_deg = {azimuth}"),
            &truth,
        );
        let (lines, _) = monitor_lines(cfg, &dir, &scan);
        let t: f64 = lines
            .last()
            .unwrap()
            .split(',')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let top = sfs::gltf_out::read_glb(&std::fs::read(dir.join("latest.glb")).unwrap())
            .unwrap()
            .nodes[&1];
        // East, north, up → the structure's frame.
        let w = truth_top(&truth, t - 0.1);
        let expected = if azimuth == 90.0 {
            w
        } else {
            Vector3::new(w.y, -w.x, w.z)
        };
        eprintln!("x azimuth {azimuth}: top {top:?}, expected {expected:?}");
        assert!(w.x > 1.0, "the riser barely bent: {w:?}");
        assert!(
            (top - expected).norm() < 0.1,
            "top {top:?}, expected {expected:?}"
        );
        metrics.push(lines);
    }
    assert_eq!(metrics[0], metrics[1]);
}

/// An epoch of a window the monitor has closed already (out of time order) is ignored and
/// counted, never written out of order.
#[test]
fn an_epoch_of_a_closed_window_is_late() {
    let (scan, truth) = epochs_of(StructureKind::Riser, 1, 3.0);
    let dir = tmpdir("monitor-late");
    let cfg = layout_config(&dir, "anchor = 0\nreference_s = 0.2", &truth);
    let mut m =
        sfs::monitor::run::Monitor::new(cfg, &dir, sfs::monitor::run::Begin::Fresh).unwrap();
    let first = scan.array[0].t;
    let second: Vec<_> = scan
        .array
        .iter()
        .filter(|e| e.t > first + 0.1)
        .take(50)
        .collect();
    for e in scan.array.iter().filter(|e| e.t == first) {
        m.feed(e);
    }
    for e in &second {
        m.feed(e); // closes the first window
    }
    let mut stale = scan.array[0].clone();
    stale.sensor = 7;
    m.feed(&stale);
    m.finish();
    assert_eq!(m.report.late, 1);
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    let t: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(t.len() >= 2 && t.windows(2).all(|w| w[1] > w[0]), "{t:?}");
}

/// A sensor that streams but is not in the layout (here the riser's top one, left out of
/// it) is ignored and named once, in the report and the log; the shape is made without it.
#[test]
fn a_sensor_the_layout_does_not_place_is_named_and_ignored() {
    let (scan, mut truth) = epochs_of(StructureKind::Riser, 1, 3.0);
    truth.sensors.retain(|s| s.sensor != 40);
    let dir = tmpdir("monitor-unknown");
    let cfg = layout_config(&dir, "anchor = 0\nreference_s = 0.2", &truth);
    let (lines, report) = monitor_lines(cfg, &dir, &scan);
    assert_eq!(report.unknown_sensors, vec![40]);
    assert_eq!(report.failed, 0);
    assert!(lines.len() >= 10);
    assert!(
        lines.iter().all(|l| l.split(',').nth(4) == Some("0")),
        "{lines:?}"
    );
}

/// Monitoring a stream that is not a sensor array's (here the shipped Morphorider capture
/// with the riser's configuration) says so, rather than writing nothing silently.
#[test]
fn monitoring_a_stream_without_an_array_says_so() {
    let dir = tmpdir("monitor-no-array");
    let root = env!("CARGO_MANIFEST_DIR");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "warn", "replay"])
        .arg(format!("{root}/replay-logs/cone-morphorider.bin"))
        .arg("--config")
        .arg(format!("{root}/config/riser.toml"))
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success());
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        stdout.contains("monitor: 0 epochs (0 failed), alarms raised: 0"),
        "{stdout}"
    );
    assert!(stderr.contains("no sensor-array samples"), "{stderr}");
}

/// Epochs that cannot be reconstructed (here a magnet disturbs every sensor for 5 s) are
/// counted, warned about once while it lasts, and the recovery is said: an unattended log
/// does not grow by a line per epoch.
#[test]
fn failing_epochs_are_warned_about_once_while_it_lasts() {
    let (bytes, truth) = run(StructureKind::Riser, 10, 25.0, 10.0);
    let during = |t_us: u32| (11e6..16e6).contains(&(t_us as f64));
    let bytes = edit_samples(&bytes, |s| {
        if during(s.t_us) {
            s.mag = s.mag.map(|m| (m as f64 * 1.3) as i16);
        }
        true
    });
    let dir = tmpdir("monitor-failing");
    let (log, session) = monitor_logged(&dir, "anchor = 0\nreference_s = 1.0\n", &truth, &bytes);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(session.join("report.json")).unwrap()).unwrap();
    let failed = report["monitor"]["failed"].as_u64().unwrap();
    assert!((20..=26).contains(&failed), "{failed} failed");
    assert_eq!(log.matches("said once while it lasts").count(), 1, "{log}");
    assert_eq!(log.matches("reconstructed again").count(), 1, "{log}");
}

/// A flapping sensor (present one epoch, gone the next, for 20 s): every change is in
/// events.log, but the log says at most four a minute for it.
#[test]
fn a_flapping_sensor_does_not_flood_the_log() {
    let (bytes, truth) = run(StructureKind::Riser, 11, 30.0, 10.0);
    let bytes = edit_samples(&bytes, |s| {
        let t = s.t_us as f64 * 1e-6 - 1.0;
        !(s.sensor == 7 && (5.0..25.0).contains(&t) && (t / 0.2).floor() as i64 % 2 == 0)
    });
    let dir = tmpdir("monitor-flapping");
    let (log, session) = monitor_logged(&dir, "anchor = 0\nreference_s = 1.0\n", &truth, &bytes);
    let events = std::fs::read_to_string(session.join("events.log")).unwrap();
    let in_events = events.matches("sensor 7 ").count();
    let in_log = log.matches("sensor 7 ").count();
    eprintln!("sensor 7: {in_events} changes in events.log, {in_log} in the log");
    assert!(in_events >= 90, "{events}");
    assert!((1..=4).contains(&in_log), "{log}");
}

/// An output that cannot be written (here latest.glb, a directory in the way) is an error in
/// the log once while it lasts, not at every epoch, and the session goes on.
#[test]
fn an_output_that_cannot_be_written_is_said_once() {
    let (bytes, truth) = run(StructureKind::Riser, 12, 10.0, 10.0);
    let dir = tmpdir("monitor-unwritable");
    std::fs::create_dir_all(dir.join("session/latest.glb/in-the-way")).unwrap();
    let (log, session) = monitor_logged(
        &dir,
        "anchor = 0\nreference_s = 1.0\nlatest_every = 1\n",
        &truth,
        &bytes,
    );
    assert_eq!(log.matches("latest.glb").count(), 1, "{log}");
    assert!(log.contains("said once while it lasts"), "{log}");
    let lines = std::fs::read_to_string(session.join("metrics.csv"))
        .unwrap()
        .lines()
        .count();
    assert!(lines > 45, "{lines} lines");
}

/// An epoch's metrics come as soon as it ends: once a sample of the next window has been
/// decoded, every earlier window has its line in metrics.csv (the session closes the windows
/// acquisition has completed instead of waiting for the next window's epochs).
#[test]
fn an_epoch_is_written_as_soon_as_it_ends() {
    use device_protocol::{Decoder, Event, Packet};
    let (bytes, truth) = run(StructureKind::Riser, 13, 6.0, 10.0);
    let dir = tmpdir("monitor-prompt");
    let cfg = layout_config(&dir, "anchor = 0\nreference_s = 0.4", &truth);
    let mut m =
        sfs::monitor::run::Monitor::new(cfg, &dir, sfs::monitor::run::Begin::Fresh).unwrap();
    let mut acq = Acquisition::new(AcquisitionConfig {
        array_window: 0.2,
        ..Default::default()
    });
    let (mut first, mut windows_seen, mut checked) = (None, 0i64, 0);
    for e in Decoder::new().feed(&bytes) {
        acq.event(&e);
        for x in acq.take_array() {
            m.feed(&x);
        }
        if let Some(t) = acq.array_complete_until() {
            m.close_until(t);
        }
        if let Event::Packet {
            packet: Packet::ArraySample(s),
            ..
        } = e
        {
            let t0 = *first.get_or_insert(s.t_us);
            let t = (s.t_us - t0) as f64 * 1e-6;
            // As acquisition places it (a sample on a boundary may fall either side).
            let complete = (t / 0.2).floor() as i64;
            if complete > windows_seen {
                windows_seen = complete;
                let lines = std::fs::read_to_string(dir.join("metrics.csv"))
                    .unwrap()
                    .lines()
                    .count()
                    - 1;
                assert_eq!(lines as i64, complete, "t = {t}: {complete} windows ended");
                checked += 1;
            }
        }
    }
    assert!(checked >= 25, "{checked}");
}

/// Issue 50 point 3, its last bullet: a capture whose sensors the layout does not place (a
/// panel replayed with the riser's layout) is one warning in the log at the first such sensor
/// and one at the end, one in `report.json` (`unknown_sensors`) and in the summary; not a
/// line per sensor.
#[test]
fn issue_50_sensors_the_layout_does_not_place_are_one_warning() {
    let dir = common::tmpdir("monitor-wrong-layout");
    let panel = dir.join("panel");
    let sim = common::sfs()
        .args([
            "--log",
            "off",
            "simulate",
            "--structure",
            "panel",
            "--duration",
            "5",
            "--seed",
            "1",
            "--out",
        ])
        .arg(&panel)
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let riser = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/riser.toml");
    let out = dir.join("out");
    let o = common::sfs()
        .args(["--log", "warn", "replay"])
        .arg(panel.with_extension("bin"))
        .arg("--config")
        .arg(&riser)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let log = String::from_utf8(o.stderr).unwrap();
    let lines: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("layout does not place"))
        .collect();
    assert_eq!(lines.len(), 2, "{log}");
    let report = common::read_report(&out);
    assert_eq!(
        report["warnings_by_code"]["unknown_sensors"], 1,
        "{}",
        report["warnings_by_code"]
    );
    let unknown = report["monitor"]["unknown_sensors"].as_array().unwrap();
    assert!(unknown.len() > 1);
    let text = report["warnings"][0].as_str().unwrap();
    assert!(
        text.contains(&format!("{} sensor(s)", unknown.len())),
        "{text}"
    );
    let summary = String::from_utf8(o.stdout).unwrap();
    assert!(summary.contains("unknown_sensors 1"), "{summary}");
}
