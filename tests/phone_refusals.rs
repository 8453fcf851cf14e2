//! Issue 32, point 4: the phone page is the first route that takes input from another machine.
//! Driven through a TLS client of the test's own (rustls, pinned to the session's certificate)
//! and a WebSocket client (tokio-tungstenite):
//! - without the token, or with a wrong one, the page and the WebSocket get 403, and past five
//!   failures a minute from one address the answers slow down;
//! - one phone at a time: a second WebSocket with the token is refused (409) while one streams;
//! - a message over the size limit closes the connection (1009), and is counted;
//! - plain HTTP on the port gets a 400 that names https;
//! - the bytes the phone sent are in the capture exactly, and the token is in the log only in
//!   the printed address; a new session gets a new token, a resumed one keeps its own;
//! - the live view shows the page's address and its QR code.

mod common;
use common::phone::Daemon;
use common::phone_client::{frames, Client};
use common::*;
use futures_util::{SinkExt, StreamExt};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::Message;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_32_the_phone_port_refuses_what_it_must() {
    let dir = tmpdir("phone-refusals");
    let session = dir.join("session");
    let view_port = common::view::free_port();
    let d = Daemon::start(
        &session,
        false,
        &["--view", &format!("127.0.0.1:{view_port}")],
    );
    let c = Client::of(&d);
    let token = d.token().to_owned();

    // The page: 403 without the token or with a wrong one, the page with it.
    assert_eq!(c.get("/phone").await.0, 403);
    assert_eq!(
        c.get("/phone?token=0123456789abcdef0123456789abcdef")
            .await
            .0,
        403
    );
    let (st, page) = c.get(&format!("/phone?token={token}")).await;
    assert_eq!(st, 200);
    assert!(page.contains("data-action=\"start\"") && page.contains("data-key=\"Enter\""));
    assert!(page
        .to_ascii_lowercase()
        .contains("referrer-policy: no-referrer"));
    // The WebSocket likewise.
    assert_eq!(c.ws("").await.err(), Some(403));
    assert_eq!(c.ws("wrong").await.err(), Some(403));

    // One phone streams; a second is refused while it does.
    let mut phone = c.ws(&token).await.unwrap();
    let sent = frames(30);
    for chunk in sent.chunks(100) {
        phone.send(Message::binary(chunk.to_vec())).await.unwrap();
    }
    assert_eq!(c.ws(&token).await.err(), Some(409));
    // The page is told the link's figures.
    let status = loop {
        match tokio::time::timeout(Duration::from_secs(5), phone.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["packets"].as_u64() == Some(31) {
                    break v;
                }
            }
            Ok(Some(Ok(_))) => {}
            other => panic!("no status with the packets: {other:?}"),
        }
    };
    assert_eq!(status["type"], "status");
    assert_eq!(status["rejected"], 0);

    // A message over the limit closes the connection with 1009.
    phone
        .send(Message::binary(vec![0u8; 100_000]))
        .await
        .unwrap();
    let closed = loop {
        match tokio::time::timeout(Duration::from_secs(5), phone.next()).await {
            Ok(Some(Ok(Message::Close(f)))) => break f,
            Ok(Some(Ok(_))) => {}
            other => panic!("not closed: {other:?}"),
        }
    };
    assert_eq!(u16::from(closed.unwrap().code), 1009);

    // Plain HTTP: a 400 that names https.
    let mut tcp = tokio::net::TcpStream::connect(("127.0.0.1", d.port))
        .await
        .unwrap();
    tcp.write_all(format!("GET /phone?token={token} HTTP/1.1\r\nHost: x\r\n\r\n").as_bytes())
        .await
        .unwrap();
    let mut text = String::new();
    let _ = tcp.read_to_string(&mut text).await;
    assert!(text.starts_with("HTTP/1.1 400"), "{text}");
    assert!(text.contains("https://") && !text.contains(&token));

    // Four failures so far: the fifth is answered at once with 403, the sixth too, and from
    // then on the address is refused a while (250 ms, then 500 ms, …): 429 at once with
    // Retry-After, the token not even looked at, and no answer ever waits.
    let t0 = Instant::now();
    assert_eq!(c.get("/phone?token=x").await.0, 403);
    let (st, text) = c.get("/phone?token=x").await;
    assert_eq!(st, 403);
    assert!(
        text.to_ascii_lowercase().contains("connection: close"),
        "{text}"
    );
    let (st, text) = c.get(&format!("/phone?token={token}")).await;
    assert_eq!(st, 429, "{text}");
    assert!(
        text.to_ascii_lowercase().contains("retry-after: 1"),
        "{text}"
    );
    assert!(
        t0.elapsed() < Duration::from_millis(240),
        "{:?}",
        t0.elapsed()
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(c.get(&format!("/phone?token={token}")).await.0, 200);

    // The view shows the page's address and its QR code.
    let view = format!("http://127.0.0.1:{view_port}");
    let http = reqwest::Client::new();
    let st: serde_json::Value = http
        .get(format!("{view}/status"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(st["phone_url"], d.url.as_str());
    assert_eq!(st["phone"]["page"], d.url.split_once('?').unwrap().0);
    let qr = http
        .get(format!("{view}/phone-qr.svg"))
        .send()
        .await
        .unwrap();
    assert_eq!(qr.status(), 200);
    assert!(qr.text().await.unwrap().contains("<svg"));

    let report = d.stop();
    let refused = &report["phone"]["refused"];
    assert_eq!(refused["token"], 6, "{refused}");
    assert_eq!(refused["slowed"], 1, "{refused}");
    assert_eq!(refused["busy"], 1, "{refused}");
    assert_eq!(refused["plain_http"], 1, "{refused}");
    assert_eq!(refused["oversized"], 1, "{refused}");
    assert_eq!(report["link"]["connects"], 1);
    assert_eq!(report["link"]["disconnects"], 1);
    assert_eq!(report["link"]["packets"]["PHONE_SAMPLE"], 30);
    // Every byte the phone sent, and nothing else, is in the capture.
    assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), sent);
    // The token is in the log once: in the printed address.
    let log = std::fs::read_to_string(session.with_extension("log")).unwrap();
    assert_eq!(log.matches(token.as_str()).count(), 1, "{log}");
    assert!(log.contains(&format!("token={token}")));

    // A resumed session keeps its token; a new one gets another.
    let again = Daemon::start(&session, true, &[]);
    assert_eq!(again.token(), token);
    // It continues the capture: what the phone sent before is decoded again.
    let resumed = again.stop();
    assert_eq!(resumed["link"]["packets"]["PHONE_SAMPLE"], 30);
    assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), sent);
    let other = Daemon::start(&dir.join("other"), false, &[]);
    assert_ne!(other.token(), token);
    assert_eq!(other.token().len(), 32);
    other.stop();
}

/// Issue 50 point 4: with `--log-format json` standard error holds nothing but JSON lines: the
/// phone page's banner (the address as text and QR code) is an event with the url and the
/// certificate's fingerprint as fields.
#[test]
fn issue_50_a_json_log_takes_no_banner() {
    let dir = tmpdir("phone-json-log");
    let session = dir.join("s");
    let d = Daemon::start(&session, false, &["--log-format", "json"]);
    let url = d.url.clone();
    d.stop();
    let log = std::fs::read_to_string(session.with_extension("log")).unwrap();
    let mut served = false;
    for line in log.lines().filter(|l| !l.trim().is_empty()) {
        let v: serde_json::Value =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line:?}"));
        served |= v["fields"]["url"].as_str() == Some(url.as_str())
            && v["fields"]["fingerprint"]
                .as_str()
                .is_some_and(|f| !f.is_empty());
    }
    assert!(served, "no event with the url {url}:\n{log}");
}

/// Issue 50 point 4: a phone page on a loopback address is warned about, with this machine's
/// LAN addresses named; `/` on the phone port says where the page is.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn issue_50_a_loopback_page_is_warned_about_and_the_root_explains() {
    let dir = tmpdir("phone-loopback");
    let session = dir.join("s");
    let d = Daemon::start(&session, false, &[]);
    let (status, body) = Client::of(&d).get("/").await;
    assert_eq!(status, 200, "{body}");
    assert!(
        body.contains("/phone?token=") && body.contains("phone.url"),
        "{body}"
    );
    d.stop();
    let log = std::fs::read_to_string(session.with_extension("log")).unwrap();
    let warning = log
        .lines()
        .find(|l| l.contains("a loopback address: no phone can reach it"))
        .unwrap_or_else(|| panic!("no loopback warning:\n{log}"));
    for ip in sfs::source::phone::lan_addresses() {
        assert!(
            warning.contains(&ip.to_string()),
            "{ip} not named: {warning}"
        );
    }
}
