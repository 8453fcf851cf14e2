//! The serial source through a real pseudo-terminal pair: a writer thread plays a capture into
//! the master end, the session reads the slave by path (through a symlink, as udev's
//! /dev/serial/by-id links), captures and decodes it. Closing the master is an unplug; a new
//! pair behind the same link is the device coming back.

mod common;
use common::pty::*;
use common::*;
use sfs::session;
use sfs::shutdown::Shutdown;
use sfs::source::{SerialSpec, SourceSpec};
use std::path::PathBuf;
use std::time::Duration;

fn start_session(
    spec: SourceSpec,
    dir: PathBuf,
    shutdown: Shutdown,
) -> std::thread::JoinHandle<Result<session::Outcome, session::SessionError>> {
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(session::run(
                spec,
                &dir,
                &sfs::settings::Settings::default(),
                session::Start::New,
                shutdown,
            ))
    })
}

#[test]
fn serial_session_decodes_captures_and_reconnects() {
    let dir = tmpdir("serial-pty");
    let link = dir.join("ttySFS");
    let session_dir = dir.join("session");
    let capture = session_dir.join("capture.bin");
    let (bytes, exp) = fault_stream(3000);
    let half = bytes.len() / 2;
    // Split at a delimiter so that the unplug does not cut a frame (that would be a legitimate
    // loss the expected counts do not model).
    let split = bytes[..half].iter().rposition(|&b| b == 0).unwrap() + 1;

    let mut master = plug(&link);
    let shutdown = Shutdown::new();
    let session = start_session(spec(&link), session_dir.clone(), shutdown.clone());

    play(&mut master, &bytes[..split]);
    wait_for("first half captured", Duration::from_secs(10), || {
        file_len(&capture) == split as u64
    });
    drop(master); // unplug
    std::thread::sleep(Duration::from_millis(300)); // the session sees the loss, retries
    let mut master = plug(&link); // the device comes back on a new pty behind the same link
    play(&mut master, &bytes[split..]);
    wait_for("second half captured", Duration::from_secs(10), || {
        file_len(&capture) == bytes.len() as u64
    });
    shutdown.trigger();
    let outcome = session.join().unwrap().expect("session ran");
    drop(master);

    // Lossless capture: exactly the bytes the device sent, in order.
    assert_eq!(std::fs::read(&capture).unwrap(), bytes);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&outcome.report_path).unwrap()).unwrap();
    let link_stats = &report["link"];
    assert_link(link_stats, bytes.len(), &exp);
    assert_eq!(link_stats["connects"], 2);
    assert!(link_stats["disconnects"].as_u64().unwrap() >= 1);
    assert_eq!(report["ended"], "shutdown");
}

#[test]
fn watchdog_counts_silence_as_disconnect() {
    let dir = tmpdir("serial-watchdog");
    let link = dir.join("ttySFS");
    let mut master = plug(&link);
    let mut s = SerialSpec::new(&link, 115_200);
    s.watchdog = Duration::from_millis(200);
    s.backoff_min = Duration::from_millis(20);
    let shutdown = Shutdown::new();
    let session = start_session(SourceSpec::Serial(s), dir.join("session"), shutdown.clone());
    let mut b = Builder::new();
    b.packet(hello());
    play(&mut master, &b.bytes);
    std::thread::sleep(Duration::from_millis(700)); // silence: more than one watchdog period
    shutdown.trigger();
    let outcome = session.join().unwrap().unwrap();
    let l = &outcome.report.link;
    assert!(l.disconnects >= 1, "silence not detected: {l:?}");
    assert!(l.connects >= 2, "no reconnection after the watchdog: {l:?}");
    assert_eq!(l.packets.total(), 1);
    drop(master);
}

#[test]
fn missing_serial_port_is_an_input_error_naming_the_path() {
    let dir = tmpdir("serial-missing");
    let path = dir.join("ttyNONE");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "run", "--serial"])
        .arg(&path)
        .arg("--session")
        .arg(dir.join("s"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(sfs::exit::INPUT));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("ttyNONE"), "{err}");
}
