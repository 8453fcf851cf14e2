//! A daemon serving the live view (`sfs replay … --view`), for the view's tests and its
//! latency benchmark.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A free loopback port (the listener is closed again at once).
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

/// A daemon that serves until interrupted; killed if the test fails first.
pub struct Served(pub Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `sfs replay CAPTURE --out OUT --pace PACE --view 127.0.0.1:PORT` (`pace` `None`: as fast
/// as it goes), with `extra` arguments. Its log is dropped; with `SFS_VIEW_TEST_LOG=FILE` (to
/// look into a failure), its debug log goes to FILE.
pub fn serve_replay(
    capture: &Path,
    out: &Path,
    pace: Option<&str>,
    port: u16,
    extra: &[&str],
) -> Served {
    let log = std::env::var_os("SFS_VIEW_TEST_LOG");
    let mut c = Command::new(env!("CARGO_BIN_EXE_sfs"));
    c.args([
        "--log",
        if log.is_some() {
            "debug,sfs::view::conn=trace"
        } else {
            "warn"
        },
        "replay",
    ])
    .arg(capture)
    .arg("--out")
    .arg(out)
    .args(["--view", &format!("127.0.0.1:{port}")])
    .args(extra);
    if let Some(p) = pace {
        c.args(["--pace", p]);
    }
    let stderr = match log.and_then(|f| std::fs::File::create(f).ok()) {
        Some(f) => Stdio::from(f),
        None => Stdio::null(),
    };
    Served(c.stdout(Stdio::null()).stderr(stderr).spawn().unwrap())
}

/// [`serve_replay`] on a free port, and the port: tried again on another port when the daemon
/// exits at once (the port [`free_port`] chose was taken meanwhile, e.g. by a browser's
/// debugging port, and the daemon could not bind it).
pub fn serve_replay_on_a_free_port(
    capture: &Path,
    out: &Path,
    pace: Option<&str>,
    extra: &[&str],
) -> (u16, Served) {
    for _ in 0..5 {
        let port = free_port();
        let mut served = serve_replay(capture, out, pace, port, extra);
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(20) {
            if served.0.try_wait().ok().flatten().is_some() {
                break;
            }
            if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                std::thread::sleep(Duration::from_millis(200));
                if served.0.try_wait().ok().flatten().is_none() {
                    return (port, served);
                }
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = std::fs::remove_dir_all(out);
    }
    panic!("the daemon could not serve on any of 5 free ports");
}

/// SIGINT: the replay that keeps serving stops, with success.
pub fn interrupt(served: &mut Served) {
    let child = &mut served.0;
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            assert!(st.success(), "{st}");
            return;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "did not stop");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `OUT/report.json` once the replay has ended (waits up to `limit`).
pub fn ended_report(out: &Path, limit: Duration) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let r = std::fs::read(out.join("report.json"))
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
        if let Some(r) = r.filter(|r| r["ended"] == "end_of_input") {
            return r;
        }
        assert!(t0.elapsed() < limit, "the replay did not end in {limit:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `bytes` written to `DIR/NAME.bin`, replayed and served on a free port until the replay
/// has ended: the port, the daemon and its `report.json`.
#[allow(dead_code)]
pub fn serve_ended(dir: &Path, name: &str, bytes: &[u8]) -> (u16, Served, serde_json::Value) {
    let capture = dir.join(format!("{name}.bin"));
    std::fs::write(&capture, bytes).unwrap();
    let out = dir.join("out");
    let (port, served) = serve_replay_on_a_free_port(&capture, &out, None, &[]);
    let report = ended_report(&out, Duration::from_secs(60));
    (port, served, report)
}

/// `sfs run --serial LINK --view 127.0.0.1:PORT`, its standard error into `log`.
pub fn serve_serial(link: &Path, session: &Path, port: u16, log: &Path) -> Served {
    let err = std::fs::File::create(log).unwrap();
    Served(
        Command::new(env!("CARGO_BIN_EXE_sfs"))
            .args(["--log", "warn", "run", "--serial"])
            .arg(link)
            .arg("--session")
            .arg(session)
            .args(["--view", &format!("127.0.0.1:{port}")])
            .stdout(Stdio::null())
            .stderr(err)
            .spawn()
            .unwrap(),
    )
}
