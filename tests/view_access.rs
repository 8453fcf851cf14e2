//! Issue 31, point 3: the view answers only requests whose `Host` names it (DNS rebinding),
//! wants `[view] token` on every route when one is set, and warns when it listens on every
//! interface. Through the real binary and raw HTTP (to send any `Host`, or none).

mod common;
use common::tmpdir;
use common::view::serve_replay_on_a_free_port;
use std::io::{BufRead, Read, Write};
use std::path::PathBuf;
use std::process::Stdio;
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The status code of `GET path` sent with these header lines (raw, so any `Host` or none).
fn status_of(port: u16, path: &str, headers: &[String]) -> (u16, String) {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut req = format!("GET {path} HTTP/1.1\r\nConnection: close\r\n");
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut resp = Vec::new();
    let _ = s.read_to_end(&mut resp);
    let text = String::from_utf8_lossy(&resp).into_owned();
    (common::http_status(&text), text)
}

fn host(h: &str) -> Vec<String> {
    vec![format!("Host: {h}")]
}

#[test]
fn issue_31_the_view_answers_only_the_hosts_that_name_it() {
    let dir = tmpdir("view-hosts");
    let cfg = dir.join("view.toml");
    std::fs::write(&cfg, "[view]\nallowed_hosts = [\"scanner.lan\"]\n").unwrap();
    let cfg = cfg.display().to_string();
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/cone-morphorider.bin"),
        &dir.join("out"),
        None,
        &["--config", &cfg],
    );
    for ok in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
        format!("scanner.lan:{port}"),
    ] {
        for path in ["/status", "/metrics", "/"] {
            let (code, text) = status_of(port, path, &host(&ok));
            assert_eq!(code, 200, "{ok} {path}: {text}");
        }
    }
    let long = "a".repeat(5000);
    for bad in [
        Some(format!("evil.example.com:{port}")),
        Some("evil.example.com".to_string()),
        Some(String::new()),
        Some(long),
        Some(format!("localhost:{}", port.wrapping_add(1))),
        None,
    ] {
        for path in ["/status", "/network.glb", "/metrics", "/events"] {
            let headers = bad.as_deref().map(host).unwrap_or_default();
            let (code, text) = status_of(port, path, &headers);
            assert!(
                code == 421 || code == 400,
                "Host {:?} {path}: {code}: {}",
                bad.as_deref().map(|h| &h[..h.len().min(40)]),
                &text[..text.len().min(200)]
            );
            assert!(!text.contains("\"link\""), "the status leaked: {text}");
        }
    }
}

#[test]
fn issue_31_a_token_is_wanted_on_every_route() {
    let dir = tmpdir("view-token");
    let cfg = dir.join("view.toml");
    let token = "0123456789abcdef0123";
    std::fs::write(&cfg, format!("[view]\ntoken = \"{token}\"\n")).unwrap();
    let cfg = cfg.display().to_string();
    let (port, _served) = serve_replay_on_a_free_port(
        &root().join("replay-logs/cone-morphorider.bin"),
        &dir.join("out"),
        None,
        &["--config", &cfg],
    );
    let h = host(&format!("127.0.0.1:{port}"));
    for path in [
        "/",
        "/status",
        "/metrics",
        "/network.glb",
        "/assets/view.js",
    ] {
        let (code, _) = status_of(port, path, &h);
        assert_eq!(code, 403, "{path} without the token");
        let (code, _) = status_of(port, &format!("{path}?token=wrong"), &h);
        assert_eq!(code, 403, "{path} with a wrong token");
        let (code, text) = status_of(port, &format!("{path}?token={token}"), &h);
        assert!(code == 200 || code == 404, "{path}?token: {text}");
        let mut with_bearer = h.clone();
        with_bearer.push(format!("Authorization: Bearer {token}"));
        let (code2, _) = status_of(port, path, &with_bearer);
        assert_eq!(code2, code, "{path} with the bearer header");
    }
    // The page opened with the token gives the browser a cookie its own requests carry.
    let (code, text) = status_of(port, &format!("/?token={token}"), &h);
    assert_eq!(code, 200);
    let cookie = text
        .lines()
        .find_map(|l| {
            l.strip_prefix("set-cookie: ")
                .or_else(|| l.strip_prefix("Set-Cookie: "))
        })
        .expect("a cookie")
        .split(';')
        .next()
        .unwrap()
        .to_string();
    assert!(cookie.contains("HttpOnly") || text.contains("HttpOnly"));
    let mut with_cookie = h.clone();
    with_cookie.push(format!("Cookie: {cookie}"));
    let (code, _) = status_of(port, "/status", &with_cookie);
    assert_eq!(code, 200);
    // A foreign Host is refused even with the token.
    let (code, _) = status_of(
        port,
        &format!("/status?token={token}"),
        &host("evil.example.com"),
    );
    assert_eq!(code, 421);
}

#[test]
fn issue_31_a_view_on_every_interface_warns_of_the_exposure() {
    let dir = tmpdir("view-exposed");
    let mut child = common::sfs()
        .args(["--log", "warn", "replay"])
        .arg(root().join("replay-logs/cone-morphorider.bin"))
        .arg("--out")
        .arg(dir.join("out"))
        .args(["--view", "0.0.0.0:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in std::io::BufReader::new(stderr).lines() {
            if tx.send(l.unwrap_or_default()).is_err() {
                break;
            }
        }
    });
    let t0 = Instant::now();
    let mut seen = Vec::new();
    let found = loop {
        match rx.recv_timeout(Duration::from_secs(30).saturating_sub(t0.elapsed())) {
            Ok(l) if l.contains("every network interface") => break Some(l),
            Ok(l) => seen.push(l),
            Err(_) => break None,
        }
    };
    let _ = child.kill();
    let _ = child.wait();
    let line = found.unwrap_or_else(|| panic!("no warning: {seen:?}"));
    assert!(line.contains("WARN") && line.contains("token"), "{line}");
}
