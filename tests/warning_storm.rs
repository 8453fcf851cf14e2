//! Issue 31, point 5: warnings are bounded in every layer. A storm of random keypad presses
//! between a few samples makes thousands of short curves that acquisition accepts and the
//! reconstruction leaves out: report.json keeps at most `sfs::report::MAX_WARNINGS` warnings
//! (the rest counted by kind, nothing lost silently) and the log is rate-limited for every
//! kind and layer.

mod common;
use common::{hello, tmpdir, Builder};

/// Seeded: xorshift64*.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

/// `keys` random presses of the keypad's keys, each followed by 0–3 samples.
pub fn storm(keys: usize, seed: u64) -> Vec<u8> {
    let mut b = Builder::new();
    b.packet(hello());
    let pad = b"BIKG0123456789\nUCE\n\n1E";
    let mut rng = Rng(seed | 1);
    let mut i = 0;
    for _ in 0..keys {
        b.key(pad[(rng.next() % pad.len() as u64) as usize]);
        for _ in 0..rng.next() % 4 {
            b.sample(i % 9_000);
            i += 1;
        }
    }
    b.bytes
}

#[test]
fn issue_31_a_key_storm_keeps_report_json_and_the_log_bounded() {
    let dir = tmpdir("warning-storm");
    let capture = dir.join("storm.bin");
    // The issue's storm had 4 million keys (SFS_STORM_KEYS=4000000 repeats it: BENCHMARKS.md).
    let keys = std::env::var("SFS_STORM_KEYS")
        .ok()
        .and_then(|k| k.parse().ok())
        .unwrap_or(400_000);
    std::fs::write(&capture, storm(keys, 31)).unwrap();
    let out = common::sfs()
        .args(["--log", "info", "replay"])
        .arg(&capture)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    let lines = log.lines().count();
    let report_bytes = std::fs::metadata(dir.join("out/report.json"))
        .unwrap()
        .len();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/report.json")).unwrap()).unwrap();
    let kept = report["warnings"].as_array().unwrap().len();
    let by_code = report["warnings_by_code"].as_object().unwrap();
    let total: u64 = by_code.values().map(|v| v.as_u64().unwrap()).sum();
    eprintln!(
        "report.json {report_bytes} bytes, {kept} warnings kept of {total}, {lines} log lines; {by_code:?}"
    );
    assert!(out.status.success(), "{log}");
    assert!(kept <= sfs::report::MAX_WARNINGS, "{kept} warnings kept");
    assert!(
        total > kept as u64 * 2,
        "the storm made few warnings: {total}"
    );
    assert_eq!(
        report["warnings_left_out"].as_u64().unwrap(),
        total - kept as u64
    );
    assert!(report_bytes < 2 << 20, "report.json: {report_bytes} bytes");
    assert!(lines < 5000, "{lines} log lines");
    let network_lines = log.lines().filter(|l| l.contains("sfs_geometry")).count();
    assert!(
        network_lines < 200,
        "{network_lines} lines from the geometry"
    );

    // The same storm through the daemon, with live updates after every curve.
    let mut child = common::sfs()
        .args(["--log", "info", "run", "--stdin", "--session"])
        .arg(dir.join("session"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let bytes = std::fs::read(&capture).unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || {
        let _ = std::io::Write::write_all(&mut stdin, &bytes);
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let lines = log.lines().count();
    let report_bytes = std::fs::metadata(dir.join("session/report.json"))
        .unwrap()
        .len();
    eprintln!("live: report.json {report_bytes} bytes, {lines} log lines");
    assert!(
        report_bytes < 2 << 20,
        "live report.json: {report_bytes} bytes"
    );
    assert!(lines < 5000, "live: {lines} log lines");
}
