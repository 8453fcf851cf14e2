//! Issue 15 point 11: soak. A one-hour simulated Morphorider session and a one-hour phone
//! session (`config/scenes/torus-hour.toml`) streamed through `sfs run --stdin` at full speed:
//! the outputs are those `sfs replay` gives from the capture, and the resident size grows from
//! ten minutes in to the end by the samples the session holds and nothing more. (The issue
//! asked for the end within 10 % of ten minutes in: not possible while the scan is held in
//! memory, which grows with every curve; see BENCHMARKS.md.)

mod common;
use common::*;
use device_protocol::{Decoder, DeviceKind, Event, Packet};
use sfs::simulate::{self, scene, Profile};
use std::io::Write;
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

fn report(dir: &Path) -> Option<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).ok()?).ok()
}

/// The byte offset of the first whole packet at or after session time `t` (s).
fn offset_at(bytes: &[u8], t: f64) -> usize {
    let mut dec = Decoder::new();
    let (mut now, mut last) = (0.0, None::<u32>);
    for (k, chunk) in bytes.chunks(64).enumerate() {
        for e in dec.feed(chunk) {
            let Event::Packet { packet, .. } = e else {
                continue;
            };
            let t_us = match packet {
                Packet::RiderSample(s) => s.t_us,
                Packet::PhoneSample(s) => s.t_us,
                _ => continue,
            };
            if let Some(l) = last {
                now += t_us.wrapping_sub(l) as f64 * 1e-6;
            }
            last = Some(t_us);
            if now >= t {
                return k * 64;
            }
        }
    }
    bytes.len()
}

/// Resident size of process `pid`, MB (`VmRSS` in `/proc/PID/status`).
fn rss_mb(pid: u32) -> f64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    let kb: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    kb / 1024.0
}

/// The resident size of the daemon `pid` once it has captured `bytes` and the live worker
/// has taken in `curves` curves (and is idle), MB.
fn rss_once_idle(pid: u32, session: &Path, bytes: u64, curves: usize) -> f64 {
    wait_for("the capture", Duration::from_secs(120), || {
        file_len(&session.join("capture.bin")) == bytes
    });
    if curves > 0 {
        wait_for("the live update", Duration::from_secs(120), || {
            report(session)
                .is_some_and(|r| r["curves"].as_array().is_some_and(|c| c.len() == curves))
        });
    }
    // Settled: the same size twice, 200 ms apart.
    let mut last = rss_mb(pid);
    loop {
        std::thread::sleep(Duration::from_millis(200));
        let now = rss_mb(pid);
        if (now - last).abs() < 0.5 {
            return now;
        }
        last = now;
    }
}

#[test]
fn issue_15_an_hour_at_full_speed_holds_its_memory_and_matches_replay() {
    let s = scene::builtin("torus-hour").unwrap();
    for device in [DeviceKind::Morphorider, DeviceKind::Phone] {
        let dir = tmpdir(&format!("soak-{device}"));
        let bytes = simulate::run(&s, device, Profile::Default, 1).bytes;
        let cut = offset_at(&bytes, 600.0);
        let early =
            sfs::acquisition::Acquisition::scan_bytes(&bytes[..cut], Default::default()).curves;
        let session = dir.join("s");
        let mut child = sfs()
            .args(["--log", "warn", "run", "--stdin", "--session"])
            .arg(&session)
            .stdin(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(&bytes[..cut]).unwrap();
        let ten_minutes = rss_once_idle(child.id(), &session, cut as u64, early.len());
        stdin.write_all(&bytes[cut..]).unwrap();
        drop(stdin);
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let end = report(&session).unwrap();
        assert_eq!(end["ended"], "end_of_input");
        let at_end = end["live"]["rss_mb"].as_f64().unwrap();
        let held = |curves: &[serde_json::Value]| -> f64 {
            curves.iter().map(|c| c["samples"].as_f64().unwrap()).sum()
        };
        let early_samples: f64 = early.iter().map(|c| c.samples.len() as f64).sum();
        let grown = held(end["curves"].as_array().unwrap()) - early_samples;
        let per_sample = (at_end - ten_minutes).max(0.0) * 1048576.0 / grown;
        eprintln!(
            "{device}: RSS {ten_minutes:.1} MB after 10 min ({} curves), {at_end:.1} MB at the end ({} curves, {grown} samples more: {per_sample:.0} bytes a sample; peak {} MB)",
            early.len(),
            end["curves"].as_array().unwrap().len(),
            end["live"]["peak_rss_mb"]
        );
        // The scan is held whole (the reconstruction re-runs over every curve), so the memory
        // grows with the samples of the curves scanned: by their size (57 bytes, held by
        // acquisition and by the live worker) and the caches, and by nothing else: no growth
        // per update, packet or warning. Measured 73-147 bytes a sample (the end varies by
        // ±10 MB from run to run with the allocator's arenas); a surface leaked per update
        // would add over 600.
        assert!(
            per_sample <= 250.0,
            "{device}: RSS {ten_minutes:.1} MB after ten minutes, {at_end:.1} MB at the end: {per_sample:.0} bytes a sample scanned"
        );
        // The outputs are those of a replay of the capture.
        assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), bytes);
        let replayed = dir.join("replay");
        replay_to(&session.join("capture.bin"), &replayed);
        assert_same_files(
            &session,
            &replayed,
            &["scan.json", "network.glb"],
            &format!("{device}: live vs replay"),
        );
    }
}
