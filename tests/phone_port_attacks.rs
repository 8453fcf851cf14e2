//! Issue 48: the phone port holds against the LAN, and nothing read-only hands out the right to
//! write. The attacks of the issue, scripted on loopback, other loopback addresses standing in
//! for other hosts (127.0.0.1 is the phone and the operator's machine):
//! - point 1: idle connections reopened as fast as they are dropped, ClientHellos begun and
//!   left, and 64 parallel requests with a wrong token, all at once: the phone still gets its
//!   page on at least 29 of 30 tries within 2 s, and its WebSocket back within 3 s;
//! - point 2: the view gives the token (its QR code, the address in `/status`) only to a
//!   client on this machine or one with the view's token, never in its events; `phone.url` is
//!   0600; a takeover needs the token, and is logged with the address and counted;
//! - point 4: a FIFO or a device as the certificate, the key or `phone.url` is an error exit
//!   naming the file within a second; SIGINT stops the daemon at any moment;
//! - point 5: a message over 64 KiB, whatever its frame declares, is closed with 1009, a text
//!   message with 1003, each counted; a page whose clock disagrees gives no latency; the user
//!   agent is stored bounded and escaped; a foreign `Host` gets 421.
//!
//! BENCHMARKS.md "Robustness III" gives the figures these print (`--nocapture`).

mod common;
use common::phone::Daemon;
use common::phone_client::{frames, tcp_from, Client, LOCAL};
use common::*;
use futures_util::SinkExt;
use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::Message;

fn host(a: u8, b: u8) -> IpAddr {
    IpAddr::from([127, 0, a, b])
}

/// Opens a connection from `from`, optionally begins a TLS handshake (one byte of a
/// ClientHello), and holds it until the port closes it; then again, until `stop`.
async fn churn(
    from: IpAddr,
    port: u16,
    begin_hello: bool,
    stop: Arc<AtomicBool>,
    n: Arc<AtomicU64>,
) {
    while !stop.load(Ordering::Relaxed) {
        let Ok(mut tcp) = tcp_from(from, port).await else {
            tokio::time::sleep(Duration::from_millis(5)).await;
            continue;
        };
        n.fetch_add(1, Ordering::Relaxed);
        if begin_hello {
            let _ = tcp.write_all(&[0x16]).await;
        }
        let mut b = [0u8; 64];
        loop {
            tokio::select! {
                r = tcp.read(&mut b) => if matches!(r, Ok(0) | Err(_)) { break },
                _ = tokio::time::sleep(Duration::from_millis(100)) => {
                    if stop.load(Ordering::Relaxed) { return; }
                }
            }
        }
    }
}

/// Requests the page with a wrong token from `from`, over and over, until `stop`.
async fn wrong_tokens(client: Arc<Client>, from: IpAddr, stop: Arc<AtomicBool>, n: Arc<AtomicU64>) {
    while !stop.load(Ordering::Relaxed) {
        let r = tokio::time::timeout(
            Duration::from_secs(5),
            client.get_from(from, "/phone?token=00000000000000000000000000000000"),
        )
        .await;
        if matches!(r, Ok(Ok(_))) {
            n.fetch_add(1, Ordering::Relaxed);
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_48_the_phone_gets_in_while_the_lan_floods_its_port() {
    let dir = tmpdir("phone-flood");
    let d = Daemon::start(&dir.join("session"), false, &[]);
    let client = Arc::new(Client::of(&d));
    let token = d.token().to_owned();
    let stop = Arc::new(AtomicBool::new(false));
    let (opened, refused) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let mut attackers = Vec::new();
    // Sustained churn: 192 idle connections reopened as they are dropped, a third of them
    // with a ClientHello begun and left, from 8 hosts (`SFS_FLOOD_HOSTS` for more: 192 is
    // the most, one connection each).
    let hosts: usize = std::env::var("SFS_FLOOD_HOSTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8)
        .clamp(1, 192);
    for h in 0..hosts {
        for k in 0..192 / hosts {
            attackers.push(tokio::spawn(churn(
                host(1 + (h / 200) as u8, (h % 200) as u8),
                d.port,
                k % 3 == 0,
                stop.clone(),
                opened.clone(),
            )));
        }
    }
    // 64 requests with a wrong token in parallel, from 8 more hosts, over and over.
    for k in 0..64u8 {
        attackers.push(tokio::spawn(wrong_tokens(
            client.clone(),
            host(3, k % 8),
            stop.clone(),
            refused.clone(),
        )));
    }
    tokio::time::sleep(Duration::from_secs(2)).await;

    // The phone: its page, 30 tries, each within 2 s.
    let mut took = Vec::new();
    let mut ok = 0;
    for _ in 0..30 {
        let t0 = Instant::now();
        let r = tokio::time::timeout(
            Duration::from_secs(2),
            client.get_from(LOCAL, &format!("/phone?token={token}")),
        )
        .await;
        match r {
            Ok(Ok((200, _))) => {
                ok += 1;
                took.push(t0.elapsed().as_secs_f64() * 1e3);
            }
            other => println!(
                "issue 48 point 1: a try failed after {:?}: {:?}",
                t0.elapsed(),
                other.map(|r| r.map(|(st, text)| (st, text.chars().take(80).collect::<String>())))
            ),
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    took.sort_by(f64::total_cmp);
    let p95 = took.get((took.len() * 95 / 100).min(took.len().saturating_sub(1)));
    println!(
        "issue 48 point 1: the page on {ok} of 30 tries under attack from {hosts} + 8 hosts, max {:.0} ms, p95 {:.0} ms; attackers opened {} idle connections, made {} wrong-token requests",
        took.last().copied().unwrap_or(f64::NAN),
        p95.copied().unwrap_or(f64::NAN),
        opened.load(Ordering::Relaxed),
        refused.load(Ordering::Relaxed),
    );
    assert!(ok >= 29, "the page on {ok} of 30 tries");

    // The WebSocket: streaming, dropped (a network change), back within 3 s, retrying as the
    // page does (500 ms, doubling).
    let mut ws = client
        .ws_from(LOCAL, &format!("token={token}"), None)
        .await
        .expect("the phone's WebSocket under attack");
    ws.send(Message::binary(frames(10))).await.unwrap();
    ws.close(None).await.unwrap();
    drop(ws);
    let t0 = Instant::now();
    let mut wait = Duration::from_millis(500);
    let back = loop {
        match tokio::time::timeout(
            Duration::from_secs(2),
            client.ws_from(LOCAL, &format!("token={token}"), None),
        )
        .await
        {
            Ok(Ok(ws)) => break (t0.elapsed(), ws),
            _ if t0.elapsed() > Duration::from_secs(10) => panic!("no reconnection in 10 s"),
            _ => {
                tokio::time::sleep(wait).await;
                wait *= 2;
            }
        }
    };
    println!(
        "issue 48 point 1: the WebSocket back {:.0} ms after it dropped",
        back.0.as_secs_f64() * 1e3
    );
    assert!(back.0 < Duration::from_secs(3), "{:?}", back.0);
    // A screen lock: the old stream stays open and silent; the page, from the same address,
    // gets back in.
    let mut silent = back.1;
    silent.send(Message::binary(frames(3))).await.unwrap();
    tokio::time::sleep(Duration::from_millis(700)).await;
    let t0 = Instant::now();
    let again = client.ws_from(LOCAL, &format!("token={token}"), None).await;
    assert!(again.is_ok(), "{:?}", again.err());
    assert!(t0.elapsed() < Duration::from_secs(3));
    stop.store(true, Ordering::Relaxed);
    for a in attackers {
        let _ = a.await;
    }
    drop((silent, again));
    let report = d.stop();
    let refused = &report["phone"]["refused"];
    assert!(refused["let_go"].as_u64().unwrap() > 0, "{refused}");
    // (With many churning hosts the wrong-token requests hardly get through: none slowed.)
    if hosts <= 8 {
        assert!(refused["slowed"].as_u64().unwrap() > 0, "{refused}");
    }
    assert!(report["phone"]["takeovers"].as_u64().unwrap() >= 1);
}

/// `GET path` on the view at `port` from `from`: the status and the body.
async fn view_get(from: IpAddr, port: u16, path: &str) -> (u16, String) {
    let mut tcp = tcp_from(from, port).await.unwrap();
    tcp.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n")
            .as_bytes(),
    )
    .await
    .unwrap();
    let mut text = String::new();
    let _ = tokio::time::timeout(Duration::from_secs(3), tcp.read_to_string(&mut text)).await;
    (http_status(&text), text)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_48_the_token_stays_with_the_phone() {
    let dir = tmpdir("phone-token-stays");
    let session = dir.join("session");
    let view_port = common::view::free_port();
    let d = Daemon::start(
        &session,
        false,
        &["--view", &format!("127.0.0.1:{view_port}")],
    );
    let token = d.token().to_owned();
    let client = Client::of(&d);
    // phone.url is the owner's alone.
    let mode = std::os::unix::fs::PermissionsExt::mode(
        &std::fs::metadata(session.join("phone.url"))
            .unwrap()
            .permissions(),
    );
    assert_eq!(mode & 0o777, 0o600, "{mode:o}");

    // Another host reads the view: no token anywhere.
    let other = host(3, 1);
    let body = status_once_the_phone_is_up(other, view_port, "/status").await;
    assert!(!body.contains(&token), "{body}");
    assert!(body.contains("\"phone\":{\"page\":\"https://"), "{body}");
    let (st, body) = view_get(other, view_port, "/phone-qr.svg").await;
    assert_eq!(st, 403, "{body}");
    assert!(!body.contains(&token));
    // Its event stream, for a few status events.
    let mut tcp = tcp_from(other, view_port).await.unwrap();
    tcp.write_all(
        format!("GET /events HTTP/1.1\r\nHost: 127.0.0.1:{view_port}\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut events = Vec::new();
    let _ = tokio::time::timeout(Duration::from_millis(2500), async {
        let mut b = [0u8; 8192];
        while let Ok(n) = tcp.read(&mut b).await {
            if n == 0 {
                break;
            }
            events.extend_from_slice(&b[..n]);
        }
    })
    .await;
    let events = String::from_utf8_lossy(&events);
    assert!(
        events.contains("event: status") && events.contains("\"phone\""),
        "{events}"
    );
    assert!(!events.contains(&token));
    // The operator's browser on this machine gets the QR code and the address.
    let (st, body) = view_get(LOCAL, view_port, "/status").await;
    assert_eq!(st, 200);
    assert!(
        body.contains(&format!("\"phone_url\":\"{}\"", d.url)),
        "{body}"
    );
    assert_eq!(view_get(LOCAL, view_port, "/phone-qr.svg").await.0, 200);

    // A takeover needs the token: the phone streams, then falls silent (a screen lock).
    let mut phone = client.ws(&token).await.unwrap();
    phone.send(Message::binary(frames(10))).await.unwrap();
    tokio::time::sleep(Duration::from_millis(2300)).await;
    let intruder = host(3, 2);
    assert_eq!(
        client.ws_from(intruder, "token=", None).await.err(),
        Some(403)
    );
    assert_eq!(
        client
            .ws_from(intruder, "token=0123456789abcdef0123456789abcdef", None)
            .await
            .err(),
        Some(403)
    );
    // The phone itself (another address after a roam) takes its stream back with the token.
    let roamed = client
        .ws_from(host(3, 3), &format!("token={token}"), None)
        .await
        .expect("a takeover with the token");
    drop((phone, roamed));
    let report = d.stop();
    assert_eq!(report["phone"]["takeovers"], 1, "{}", report["phone"]);
    assert_eq!(report["phone"]["refused"]["token"], 2);
    let log = std::fs::read_to_string(session.with_extension("log")).unwrap();
    assert!(
        log.contains("took over") && log.contains("127.0.3.3"),
        "the takeover is logged with the address: {log}"
    );
    assert_eq!(log.matches(token.as_str()).count(), 1, "{log}");
}

/// `sfs run --phone 127.0.0.1:0 --session SESSION`, its standard error to `stderr` (for the
/// tests that watch it start or fail, not [`Daemon`], which waits until it serves).
fn phone_daemon(session: &std::path::Path, stderr: std::process::Stdio) -> std::process::Child {
    phone_daemon_command(session, stderr).spawn().unwrap()
}

/// The command of [`phone_daemon`], not started.
fn phone_daemon_command(
    session: &std::path::Path,
    stderr: std::process::Stdio,
) -> std::process::Command {
    let mut command = sfs();
    command
        .args([
            "--log",
            "warn",
            "run",
            "--phone",
            "127.0.0.1:0",
            "--session",
        ])
        .arg(session)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(stderr);
    command
}

/// The daemon on a session directory whose `name` is `target` (a FIFO or a device): an error
/// exit within a second that names the file.
fn refused_within_a_second(name: &str, target: Option<&str>) {
    let dir = tmpdir(&format!("phone-bad-{}", name.replace('.', "-")));
    let session = dir.join("session");
    std::fs::create_dir_all(&session).unwrap();
    let path = session.join(name);
    match target {
        Some(t) => std::os::unix::fs::symlink(t, &path).unwrap(),
        None => {
            let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
            // SAFETY: mkfifo reads a C string.
            assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        }
    }
    if name != "phone.url" {
        // The other of the pair, a real (empty) file: the bad one is read first or second.
        let other = if name == "phone-cert.pem" {
            "phone-key.pem"
        } else {
            "phone-cert.pem"
        };
        std::fs::write(session.join(other), "").unwrap();
    }
    let t0 = Instant::now();
    let mut child = phone_daemon(&session, std::process::Stdio::piped());
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if t0.elapsed() > Duration::from_secs(5) {
            let _ = child.kill();
            panic!("{name} -> {target:?}: still running after 5 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let took = t0.elapsed();
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(!status.success(), "{name}: {err}");
    assert!(
        took < Duration::from_secs(1),
        "{name} -> {target:?}: {took:?}"
    );
    assert!(err.contains(name), "{name} -> {target:?}: {err}");
    assert!(!err.contains("memory allocation"), "{err}");
}

#[test]
fn issue_48_certificate_key_and_address_files_are_read_bounded() {
    for name in ["phone-cert.pem", "phone-key.pem", "phone.url"] {
        refused_within_a_second(name, None);
        refused_within_a_second(name, Some("/dev/zero"));
        refused_within_a_second(name, Some("/dev/urandom"));
    }
}

/// A WebSocket upgrade by hand over TLS (for frames no client library sends): the stream after
/// the 101.
async fn raw_upgrade(client: &Client, token: &str) -> common::phone_client::Tls {
    let mut s = client.connect().await;
    let req = format!(
        "GET /phone/ws?token={token} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
        client.port
    );
    s.write_all(req.as_bytes()).await.unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b).await.unwrap();
        head.push(b[0]);
    }
    assert!(
        head.starts_with(b"HTTP/1.1 101"),
        "{}",
        String::from_utf8_lossy(&head)
    );
    s
}

/// The close code of the first close frame the server sends on `s` (skipping its status
/// messages).
async fn close_code(s: &mut common::phone_client::Tls) -> Option<u16> {
    let read = async {
        loop {
            let mut h = [0u8; 2];
            s.read_exact(&mut h).await.ok()?;
            let mut len = u64::from(h[1] & 0x7f);
            if len == 126 {
                let mut l = [0u8; 2];
                s.read_exact(&mut l).await.ok()?;
                len = u64::from(u16::from_be_bytes(l));
            } else if len == 127 {
                let mut l = [0u8; 8];
                s.read_exact(&mut l).await.ok()?;
                len = u64::from_be_bytes(l);
            }
            let mut payload = vec![0u8; len as usize];
            s.read_exact(&mut payload).await.ok()?;
            if h[0] & 0x0f == 0x8 {
                return Some(u16::from_be_bytes([payload[0], payload[1]]));
            }
        }
    };
    tokio::time::timeout(Duration::from_secs(5), read)
        .await
        .ok()
        .flatten()
}

/// A masked client frame header: `opcode`, declared `len`.
fn frame_head(opcode: u8, len: u64) -> Vec<u8> {
    let mut h = vec![0x80 | opcode];
    if len < 126 {
        h.push(0x80 | len as u8);
    } else if len < 65_536 {
        h.push(0x80 | 126);
        h.extend_from_slice(&(len as u16).to_be_bytes());
    } else {
        h.push(0x80 | 127);
        h.extend_from_slice(&len.to_be_bytes());
    }
    h.extend_from_slice(&[0, 0, 0, 0]); // the mask: zero, so the payload goes as it is
    h
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_48_limits_as_documented() {
    let dir = tmpdir("phone-limits");
    let d = Daemon::start(&dir.join("session"), false, &[]);
    let client = Client::of(&d);
    let token = d.token().to_owned();
    const MAX: u64 = 64 * 1024;

    // Over 64 KiB, whatever the frame declares: 1009.
    for (opcode, declared, sent) in [
        (0x2, MAX + 1, MAX + 1),
        (0x2, 1 << 62, 16),
        (0x1, MAX + 1, 1000),
        (0x1, 300 * 1024, 300 * 1024),
    ] {
        let mut s = raw_upgrade(&client, &token).await;
        s.write_all(&frame_head(opcode, declared)).await.unwrap();
        let _ = s.write_all(&vec![b'a'; sent as usize]).await;
        assert_eq!(
            close_code(&mut s).await,
            Some(1009),
            "opcode {opcode}, {declared} bytes declared"
        );
        tokio::time::sleep(Duration::from_millis(600)).await;
    }
    // Two fragments that add up to more than 64 KiB.
    let mut s = raw_upgrade(&client, &token).await;
    let mut first = frame_head(0x2, 40_000);
    first[0] &= 0x7f; // not the last fragment
    s.write_all(&first).await.unwrap();
    s.write_all(&vec![0u8; 40_000]).await.unwrap();
    s.write_all(&frame_head(0x0, 40_000)).await.unwrap();
    let _ = s.write_all(&vec![0u8; 40_000]).await;
    assert_eq!(close_code(&mut s).await, Some(1009), "fragments");
    tokio::time::sleep(Duration::from_millis(600)).await;
    // A text message, small: 1003.
    let mut s = raw_upgrade(&client, &token).await;
    s.write_all(&frame_head(0x1, 5)).await.unwrap();
    s.write_all(b"hello").await.unwrap();
    assert_eq!(close_code(&mut s).await, Some(1003));
    tokio::time::sleep(Duration::from_millis(600)).await;

    // A page whose clock is 5 s ahead: no latency measured, the offset reported.
    let now_ms = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64()
            * 1e3
    };
    let ahead = now_ms() + 5000.0;
    let mut ws = client
        .ws_from(
            LOCAL,
            &format!("token={token}&origin={}&now={ahead}", ahead - 1000.0),
            Some("Ahead"),
        )
        .await
        .unwrap();
    ws.send(Message::binary(frames(30))).await.unwrap();
    ws.close(None).await.unwrap();
    drop(ws);
    tokio::time::sleep(Duration::from_millis(300)).await;
    // One that agrees, with a user agent 10 000 characters long with escapes in it.
    let now = now_ms();
    // (A header value holds no escape character; a tab is the control character it may.)
    let agent = format!("Mozilla/5.0 \t{}", "x".repeat(10_000));
    let mut ws = client
        .ws_from(
            LOCAL,
            &format!("token={token}&origin={}&now={now}", now - 20.0),
            Some(&agent),
        )
        .await
        .unwrap();
    // The samples' timestamps: the page's event times since its origin (as the page sends).
    let mut b = Vec::new();
    for i in 0..30u32 {
        device_protocol::Packet::PhoneSample(device_protocol::PhoneSample {
            t_us: 15_000 + i * 100,
            acc: [0, 0, 4096],
            gyro: [0; 3],
            mag: [0, 140, -287],
        })
        .encode(i as u8, &mut b);
    }
    ws.send(Message::binary(b)).await.unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    ws.close(None).await.unwrap();
    drop(ws);

    // Host: a name that is not this server's gets 421; an address literal and localhost pass.
    let mut s = client.connect().await;
    s.write_all(
        format!("GET /phone?token={token} HTTP/1.1\r\nHost: evil.example.com:{}\r\nConnection: close\r\n\r\n", d.port)
            .as_bytes(),
    )
    .await
    .unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text).await;
    assert!(text.starts_with("HTTP/1.1 421"), "{text}");
    let mut s = client.connect().await;
    s.write_all(
        format!(
            "GET /phone?token={token} HTTP/1.1\r\nHost: localhost:{}\r\nConnection: close\r\n\r\n",
            d.port
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text).await;
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    // `/` says where the page is.
    let (st, text) = client.get("/").await;
    assert_eq!(st, 200);
    assert!(text.contains("/phone?token="), "{text}");

    let report = d.stop();
    let p = &report["phone"];
    assert_eq!(p["refused"]["oversized"], 5, "{p}");
    assert_eq!(p["refused"]["text"], 1, "{p}");
    assert_eq!(p["refused"]["host"], 1, "{p}");
    let latency = &p["latency_ms"];
    // One message measured: the agreeing page's (the one 5 s ahead gave none).
    assert_eq!(latency["n"], 1, "{p}");
    assert!(latency["p50"].as_f64().unwrap() >= 0.0, "{p}");
    let offset = p["clock_offset_ms"].as_f64().unwrap();
    assert!(offset.abs() < 250.0, "{p}");
    let ua = p["user_agent"].as_str().unwrap();
    assert!(ua.chars().count() <= 200, "{ua}");
    assert!(!ua.chars().any(char::is_control), "{ua}");
    assert!(ua.starts_with("Mozilla/5.0 \\u{"), "{ua}");
}

/// Point 4: SIGINT stops the daemon at any moment before it serves (and after): sent 0 to
/// 300 ms after the start, the daemon is gone within 2 s.
#[test]
fn issue_48_sigint_stops_the_phone_daemon_at_any_moment() {
    let dir = tmpdir("phone-sigint");
    for (k, after_ms) in [0u64, 5, 20, 50, 100, 300].into_iter().enumerate() {
        let session = dir.join(format!("s{k}"));
        // Started as a terminal or systemd starts it. A shell's background job (this suite run
        // with `&`) inherits SIGINT ignored: the daemon takes it back first thing in `main`
        // (`shutdown::default_signals`), but a signal before `main` would be lost.
        let mut command = phone_daemon_command(&session, std::process::Stdio::null());
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            std::os::unix::process::CommandExt::pre_exec(&mut command, || {
                libc::signal(libc::SIGINT, libc::SIG_DFL);
                Ok(())
            });
        }
        let mut child = command.spawn().unwrap();
        std::thread::sleep(Duration::from_millis(after_ms));
        // SAFETY: kill sends a signal to a child of ours.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
        let t0 = Instant::now();
        loop {
            if child.try_wait().unwrap().is_some() {
                break;
            }
            if t0.elapsed() > Duration::from_secs(2) {
                let _ = child.kill();
                panic!("SIGINT {after_ms} ms after the start: still running 2 s later");
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// `/status` (at `path`) from `from` once it carries the phone page: the view serves from the
/// start, and is told the page's address a moment after `phone.url` is written (which
/// `Daemon::start` waits for).
async fn status_once_the_phone_is_up(from: std::net::IpAddr, port: u16, path: &str) -> String {
    let t0 = Instant::now();
    loop {
        let (st, body) = view_get(from, port, path).await;
        assert_eq!(st, 200, "{body}");
        if body.contains("\"phone\":") || t0.elapsed() > Duration::from_secs(10) {
            return body;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Point 2, the other way to the QR code: with `[view] token`, a client on another host that
/// gives the view's token may write, and gets the phone's address; one without it gets 403 for
/// every route.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_48_the_views_token_shows_the_phone_address_to_another_host() {
    let dir = tmpdir("phone-view-token");
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("view.toml");
    let view_token = "0123456789abcdef0123";
    std::fs::write(&cfg, format!("[view]\ntoken = \"{view_token}\"\n")).unwrap();
    let view_port = common::view::free_port();
    let d = Daemon::start(
        &dir.join("session"),
        false,
        &[
            "--config",
            cfg.to_str().unwrap(),
            "--view",
            &format!("127.0.0.1:{view_port}"),
        ],
    );
    let other = host(4, 1);
    let (st, _) = view_get(other, view_port, "/status").await;
    assert_eq!(st, 403);
    let body =
        status_once_the_phone_is_up(other, view_port, &format!("/status?token={view_token}")).await;
    assert!(
        body.contains(&format!("\"phone_url\":\"{}\"", d.url)),
        "{body}"
    );
    let (st, _) = view_get(
        other,
        view_port,
        &format!("/phone-qr.svg?token={view_token}"),
    )
    .await;
    assert_eq!(st, 200);
    d.stop();
}
