//! The phone page's HTTPS server: its own thread and tokio runtime; TLS by rustls; HTTP/1.1
//! by hyper with axum's router; the page, its scripts, and the WebSocket the frames arrive on.
//!
//! Routes: `GET /phone?token=…` (the page; it sets the token as a cookie so that its scripts'
//! requests show it too), `GET /phone.js`, `/wire.js`, `/phone.css` (its code: nothing
//! secret), `GET /phone/ws?token=…&origin=…&now=…` (the WebSocket; `origin` and `now` are the
//! page's clock, checked against the daemon's), `GET /` (where the page is). Refusals:
//! - a `Host` that does not name this server (an address literal, `localhost` or a name in
//!   `[phone] allowed_hosts`): 421;
//! - no token or a wrong one: 403; past [`FREE_FAILURES`] failures within [`FAILURE_WINDOW`]
//!   from one address, the address is refused for a while, doubling from 250 ms up to 8 s:
//!   429 at once with `Retry-After`, its token not looked at. Every refusal closes its
//!   connection; no answer ever waits holding a slot;
//! - a second WebSocket while one streams (data within [`TAKEOVER_SILENCE`], or
//!   [`SAME_ADDRESS_SILENCE`] from the streaming phone's own address): 409; a silent one is
//!   closed and the new one takes over (a phone that roamed, or woke from a screen lock);
//!   takeovers and their refusals are logged with the address and counted;
//! - a message over [`super::MAX_MESSAGE`] bytes, whatever its frame declares: closed with
//!   1009; a text message: closed with 1003 (the page sends binary frames only);
//! - a connection whose first byte is not a TLS handshake: a plain-text 400 saying to use
//!   `https://`, then closed;
//! - connections: [`super::slots`] (who holds a slot, who is let go); a TLS handshake must
//!   finish within [`HANDSHAKE`] of the connection, each request head within [`HEAD`].

use super::slots::{Slot, Slots};
use super::stats::Conn;
use super::{lock, Msg, Phone, MAX_MESSAGE};
use crate::shutdown::Shutdown;
use crate::source::SourceEvent;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode, Uri};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Extension, Router};
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;

/// Failures allowed from one address within [`FAILURE_WINDOW`] before it is refused a while.
pub const FREE_FAILURES: u32 = 5;
pub const FAILURE_WINDOW: Duration = Duration::from_secs(60);
/// The first and the longest while an address is refused past its free failures.
pub const FIRST_PENALTY: Duration = Duration::from_millis(250);
pub const LONGEST_PENALTY: Duration = Duration::from_secs(8);
/// Addresses remembered for the slow-down.
const FAILURE_ADDRESSES: usize = 4096;
/// A streaming WebSocket silent this long is taken over by a new one.
pub const TAKEOVER_SILENCE: Duration = Duration::from_secs(2);
/// ... or this long, when the new one comes from the streaming phone's own address.
pub const SAME_ADDRESS_SILENCE: Duration = Duration::from_millis(500);
/// A WebSocket silent this long is closed (the page streams at its sensor rate).
pub const WATCHDOG: Duration = Duration::from_secs(3);
/// What the page is told, this often.
const FEEDBACK_PERIOD: Duration = Duration::from_millis(250);
/// The TLS handshake must be done within this of the connection.
pub const HANDSHAKE: Duration = Duration::from_secs(3);
/// Each request's head must arrive within this.
pub const HEAD: Duration = Duration::from_secs(3);
/// The cookie the page sets with its token, so that its own requests show it.
const COOKIE: &str = "sfs_phone";

pub(super) struct Context {
    pub token: String,
    pub phone: Arc<Phone>,
    pub tx: tokio::sync::mpsc::Sender<Msg>,
    pub tls: tokio_rustls::TlsAcceptor,
    pub port: u16,
    /// Names besides `localhost` and address literals that `Host` may give.
    pub allowed_hosts: Vec<String>,
}

/// The streaming WebSocket.
struct Live {
    id: u64,
    ip: IpAddr,
    last_data: Instant,
    kick: Arc<tokio::sync::Notify>,
}

/// One address's failures: how many within the window since `since`, and until when it is
/// refused.
#[derive(Debug, Clone, Copy)]
struct Failures {
    n: u32,
    since: Instant,
    until: Option<Instant>,
}

struct Shared {
    ctx: Context,
    /// `[phone] allowed_hosts`, lower case, without port.
    names: Vec<String>,
    live: Mutex<Option<Live>>,
    failures: Mutex<HashMap<IpAddr, Failures>>,
    slots: Arc<Slots>,
    next_id: AtomicU64,
}

type App = Arc<Shared>;

/// Serves until `stop` or `gone` (the writer thread ended); the runtime, its connections and
/// their senders are dropped on return, so the writer sees the end.
pub(super) fn run(listener: std::net::TcpListener, ctx: Context, stop: Shutdown, gone: Shutdown) {
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            tracing::error!("phone page: cannot start its runtime: {e}");
            return;
        }
    };
    rt.block_on(async move {
        let listener = match tokio::net::TcpListener::from_std(listener) {
            Ok(l) => l,
            Err(e) => {
                tracing::error!("phone page: {e}");
                return;
            }
        };
        let names = ctx
            .allowed_hosts
            .iter()
            .map(|h| crate::host::split_port(h).0.to_ascii_lowercase())
            .collect();
        let app: App = Arc::new(Shared {
            ctx,
            names,
            live: Mutex::new(None),
            failures: Mutex::new(HashMap::new()),
            slots: Slots::new(),
            next_id: AtomicU64::new(1),
        });
        let router = router(app.clone());
        loop {
            let (stream, peer) = tokio::select! {
                _ = stop.triggered() => break,
                _ = gone.triggered() => break,
                r = listener.accept() => match r {
                    Ok(a) => a,
                    Err(e) => {
                        tracing::debug!("phone page: accept: {e}");
                        tokio::time::sleep(Duration::from_millis(50)).await;
                        continue;
                    }
                },
            };
            let fd = std::os::fd::AsRawFd::as_raw_fd(&stream);
            let slot = Arc::new(app.slots.admit_socket(peer.ip(), Some(fd)));
            lock(&app.ctx.phone.stats).refused.let_go = app.slots.evicted();
            let (app, router) = (app.clone(), router.clone());
            tokio::spawn(async move {
                tokio::select! {
                    _ = slot.let_go() => {}
                    _ = connection(app, router, stream, peer, slot.clone()) => {}
                }
            });
        }
    });
    drop(rt);
}

/// One TCP connection: refused if it is not TLS, else served over HTTP/1.1 with upgrades.
async fn connection(
    app: App,
    router: Router,
    stream: tokio::net::TcpStream,
    peer: SocketAddr,
    slot: Arc<Slot>,
) {
    let _ = stream.set_nodelay(true);
    let deadline = tokio::time::Instant::now() + HANDSHAKE;
    let mut first = [0u8; 1];
    match tokio::time::timeout_at(deadline, stream.peek(&mut first)).await {
        Ok(Ok(1)) => {}
        Ok(_) => return,
        Err(_) => {
            lock(&app.ctx.phone.stats).refused.tls += 1;
            return;
        }
    }
    slot.progress();
    // A TLS connection starts with a handshake record (content type 22).
    if first[0] != 0x16 {
        lock(&app.ctx.phone.stats).refused.plain_http += 1;
        refuse_plain_http(stream, app.ctx.port).await;
        return;
    }
    let tls = match tokio::time::timeout_at(deadline, app.ctx.tls.accept(stream)).await {
        Ok(Ok(s)) => s,
        _ => {
            lock(&app.ctx.phone.stats).refused.tls += 1;
            return;
        }
    };
    slot.progress();
    let svc = hyper::service::service_fn(move |mut req: hyper::Request<hyper::body::Incoming>| {
        slot.progress();
        req.extensions_mut().insert(ConnectInfo(peer));
        req.extensions_mut().insert(slot.clone());
        tower::ServiceExt::oneshot(router.clone(), req)
    });
    let served = hyper::server::conn::http1::Builder::new()
        .timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(HEAD)
        .serve_connection(hyper_util::rt::TokioIo::new(tls), svc)
        .with_upgrades()
        .await;
    if let Err(e) = served {
        tracing::debug!("phone page: connection from {peer}: {e}");
    }
}

async fn refuse_plain_http(mut stream: tokio::net::TcpStream, port: u16) {
    let body = format!(
        "This port serves the phone page over HTTPS only: open https://…:{port}/phone?token=… (the address sfs printed, or its QR code).\n"
    );
    let head = format!(
        "HTTP/1.1 400 Bad Request\r\ncontent-type: text/plain; charset=utf-8\r\ncontent-length: {}\r\nconnection: close\r\n\r\n",
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(2), async {
        let _ = stream.write_all(head.as_bytes()).await;
        let _ = stream.write_all(body.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
}

fn router(app: App) -> Router {
    Router::new()
        .route("/", get(root))
        .route("/phone", get(page))
        .route("/phone/ws", get(ws))
        .route("/phone.js", get(|| asset("phone.js")))
        .route("/wire.js", get(|| asset("wire.js")))
        .route("/phone.css", get(|| asset("phone.css")))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .layer(axum::middleware::from_fn_with_state(app.clone(), admit))
        .with_state(app)
}

/// Every request: its `Host` must name this server (421), and one that shows the token makes
/// its connection the phone's ([`super::slots`]).
async fn admit(
    State(app): State<App>,
    Extension(slot): Extension<Arc<Slot>>,
    req: Request,
    next: Next,
) -> Response {
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok());
    if !crate::host::names_this_server(host, &[app.ctx.port], &app.names) {
        lock(&app.ctx.phone.stats).refused.host += 1;
        return closing(
            StatusCode::MISDIRECTED_REQUEST,
            "this Host is not the phone page's: open the address sfs printed, or add the name to [phone] allowed_hosts\n",
        );
    }
    if shows_token(&app, req.uri(), req.headers()) {
        slot.promote();
    }
    next.run(req).await
}

/// A plain-text refusal that closes its connection (a refused client holds no slot).
fn closing(status: StatusCode, text: &'static str) -> Response {
    (status, [(header::CONNECTION, "close")], text).into_response()
}

async fn root() -> Response {
    (
        [(header::CACHE_CONTROL, "no-cache")],
        "This is sfs's phone port. The phone page is at /phone?token=…: open the address sfs printed when it started (or scan its QR code), or read it in the session directory's phone.url.\n",
    )
        .into_response()
}

async fn asset(name: &'static str) -> Response {
    match crate::view::assets::phone(name) {
        Some((kind, body)) => (
            [
                (header::CONTENT_TYPE, kind),
                (header::CACHE_CONTROL, "no-cache"),
                (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
            ],
            body,
        )
            .into_response(),
        None => StatusCode::NOT_FOUND.into_response(),
    }
}

/// The value of `key` in `uri`'s query, if any.
fn query<'a>(uri: &'a Uri, key: &str) -> Option<&'a str> {
    uri.query()?
        .split('&')
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
}

/// Whether the request carries the token: in the query, or in the page's cookie.
fn shows_token(app: &App, uri: &Uri, headers: &HeaderMap) -> bool {
    let want = app.ctx.token.as_str();
    let in_query = query(uri, "token").is_some_and(|t| same(t, want));
    in_query
        || headers
            .get_all(header::COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|c| c.trim().strip_prefix(COOKIE)?.strip_prefix('='))
            .any(|t| same(t, want))
}

/// Compares in time independent of where the strings differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// `None` when the request shows the token; else the refusal to answer at once: 429 with
/// `Retry-After` while the address is refused for its failures (the token not looked at),
/// else 403, counted toward the address's failures.
fn check(app: &App, peer: SocketAddr, uri: &Uri, headers: &HeaderMap) -> Option<Response> {
    let now = Instant::now();
    let refused_until = lock(&app.failures)
        .get(&peer.ip())
        .and_then(|f| f.until)
        .filter(|&until| until > now);
    if let Some(until) = refused_until {
        lock(&app.ctx.phone.stats).refused.slowed += 1;
        let wait = (until - now).as_secs_f64().ceil().max(1.0) as u64;
        tracing::debug!(%peer, "phone page: an address that failed too often refused a while");
        let mut r = closing(
            StatusCode::TOO_MANY_REQUESTS,
            "too many requests without the token from this address: wait, then open the address sfs printed\n",
        );
        r.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(wait));
        return Some(r);
    }
    if shows_token(app, uri, headers) {
        return None;
    }
    {
        let mut f = lock(&app.failures);
        if f.len() >= FAILURE_ADDRESSES {
            f.retain(|_, e| now - e.since < FAILURE_WINDOW);
            if f.len() >= FAILURE_ADDRESSES {
                f.clear();
            }
        }
        let e = f.entry(peer.ip()).or_insert(Failures {
            n: 0,
            since: now,
            until: None,
        });
        if now - e.since >= FAILURE_WINDOW {
            *e = Failures {
                n: 0,
                since: now,
                until: None,
            };
        }
        e.n += 1;
        if e.n > FREE_FAILURES {
            let k = (e.n - FREE_FAILURES - 1).min(5);
            e.until = Some(now + (FIRST_PENALTY * (1 << k)).min(LONGEST_PENALTY));
        }
    }
    lock(&app.ctx.phone.stats).refused.token += 1;
    tracing::debug!(%peer, "phone page: refused a request without the right token");
    Some(closing(
        StatusCode::FORBIDDEN,
        "the phone page needs its token: open the address sfs printed (or its QR code)\n",
    ))
}

async fn page(
    State(app): State<App>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    uri: Uri,
    headers: HeaderMap,
) -> Response {
    if let Some(r) = check(&app, peer, &uri, &headers) {
        return r;
    }
    let (kind, body) = crate::view::assets::PHONE_PAGE;
    let cookie = format!(
        "{COOKIE}={}; Path=/; Secure; HttpOnly; SameSite=Strict",
        app.ctx.token
    );
    let mut r = (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-store"),
            // The address holds the token: no page it links to is told it.
            (header::REFERRER_POLICY, "no-referrer"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
        .into_response();
    if let Ok(v) = HeaderValue::from_str(&cookie) {
        r.headers_mut().insert(header::SET_COOKIE, v);
    }
    r
}

/// The page's clock, from its WebSocket's address: `origin` (`performance.timeOrigin`) and
/// `now` (its wall clock as it connected), ms since the Unix epoch. The origin is kept when the
/// clocks agree within [`super::stats::CLOCK_TOLERANCE_MS`]; the offset is kept either way.
fn page_clock(uri: &Uri) -> (Option<f64>, Option<f64>) {
    let num = |k| {
        query(uri, k)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
    };
    let (Some(origin), Some(page_now)) = (num("origin"), num("now")) else {
        return (None, None);
    };
    let daemon_now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1e3);
    let offset = daemon_now - page_now;
    let agree = offset.abs() <= super::stats::CLOCK_TOLERANCE_MS && origin <= page_now;
    (agree.then_some(origin), Some(offset))
}

async fn ws(
    State(app): State<App>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    Extension(slot): Extension<Arc<Slot>>,
    uri: Uri,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    if let Some(r) = check(&app, peer, &uri, &headers) {
        return r;
    }
    let kick = Arc::new(tokio::sync::Notify::new());
    let id = app.next_id.fetch_add(1, Ordering::Relaxed);
    {
        let mut live = lock(&app.live);
        if let Some(l) = &*live {
            let silent = l.last_data.elapsed();
            let enough = if l.ip == peer.ip() {
                SAME_ADDRESS_SILENCE
            } else {
                TAKEOVER_SILENCE
            };
            if silent < enough {
                lock(&app.ctx.phone.stats).refused.busy += 1;
                tracing::info!(
                    %peer,
                    streaming = %l.ip,
                    "phone page: refused a second phone while one streams"
                );
                return closing(
                    StatusCode::CONFLICT,
                    "another phone is streaming to this session\n",
                );
            }
            lock(&app.ctx.phone.stats).takeovers += 1;
            tracing::info!(
                %peer,
                silent_ms = silent.as_millis() as u64,
                was = %l.ip,
                "phone page: a new connection with the token took over a silent stream"
            );
            l.kick.notify_one();
        }
        *live = Some(Live {
            id,
            ip: peer.ip(),
            last_data: Instant::now(),
            kick: kick.clone(),
        });
    }
    slot.streaming();
    let (origin, offset) = page_clock(&uri);
    let agent = headers
        .get(header::USER_AGENT)
        .map(|v| super::stats::user_agent(&String::from_utf8_lossy(v.as_bytes())));
    {
        let mut s = lock(&app.ctx.phone.stats);
        s.clock_offset_ms = offset;
        if agent.is_some() {
            s.user_agent = agent;
        }
    }
    let mut conn = Conn::default();
    conn.time_origin_ms = origin;
    upgrade
        .max_message_size(MAX_MESSAGE)
        .max_frame_size(MAX_MESSAGE)
        .on_upgrade(move |socket| stream(app, socket, id, kick, peer, conn, slot))
}

/// Closes `socket` with `code` and `reason` (best effort: the peer may be gone).
async fn close(socket: &mut WebSocket, code: u16, reason: String) {
    let frame = CloseFrame {
        code,
        reason: reason.into(),
    };
    let _ = tokio::time::timeout(
        Duration::from_secs(1),
        socket.send(Message::Close(Some(frame))),
    )
    .await;
}

/// One streaming WebSocket: its binary messages go to the writer, the feedback comes back.
/// It holds its connection's slot until it ends.
async fn stream(
    app: App,
    mut socket: WebSocket,
    id: u64,
    kick: Arc<tokio::sync::Notify>,
    peer: SocketAddr,
    mut conn: Conn,
    _slot: Arc<Slot>,
) {
    let tx = app.ctx.tx.clone();
    let description = format!("phone at {}", peer.ip());
    tracing::info!("{description} connected");
    lock(&app.ctx.phone.stats).connections += 1;
    if tx
        .send(Msg::Event(SourceEvent::Connected {
            description: description.clone(),
        }))
        .await
        .is_err()
    {
        return;
    }
    let mut feedback = tokio::time::interval(FEEDBACK_PERIOD);
    let mut last_data = Instant::now();
    let too_long = format!("a message is at most {MAX_MESSAGE} bytes");
    let reason = loop {
        let deadline = tokio::time::Instant::from_std(last_data + WATCHDOG);
        tokio::select! {
            _ = tokio::time::sleep_until(deadline) => break format!("no data for {} s", WATCHDOG.as_secs()),
            _ = kick.notified() => break "a new connection took over".to_owned(),
            _ = feedback.tick() => {
                let mut v = serde_json::to_value(app.ctx.phone.feedback()).unwrap_or_default();
                v["type"] = "status".into();
                if socket.send(Message::Text(v.to_string().into())).await.is_err() {
                    break "the page went away".to_owned();
                }
            }
            m = socket.recv() => match m {
                None => break "the page closed the connection".to_owned(),
                Some(Err(e)) => {
                    // A frame or message declared or grown over the limit: the WebSocket
                    // layer stops reading it at its header.
                    let text = e.to_string();
                    if text.contains("too long") || text.contains("Space limit") {
                        lock(&app.ctx.phone.stats).refused.oversized += 1;
                        close(&mut socket, 1009, too_long.clone()).await;
                        break format!("a message over {MAX_MESSAGE} bytes: {text}");
                    }
                    break text;
                }
                Some(Ok(Message::Binary(b))) => {
                    if b.len() > MAX_MESSAGE {
                        lock(&app.ctx.phone.stats).refused.oversized += 1;
                        close(&mut socket, 1009, too_long.clone()).await;
                        break format!("a message of {} bytes (at most {MAX_MESSAGE})", b.len());
                    }
                    last_data = Instant::now();
                    if let Some(l) = lock(&app.live).as_mut().filter(|l| l.id == id) {
                        l.last_data = last_data;
                    }
                    lock(&app.ctx.phone.stats).message(&mut conn, &b);
                    if tx.send(Msg::Bytes(b.to_vec())).await.is_err() {
                        break "the session ended".to_owned();
                    }
                }
                Some(Ok(Message::Text(t))) => {
                    lock(&app.ctx.phone.stats).refused.text += 1;
                    close(&mut socket, 1003, "the page sends binary frames only".to_owned()).await;
                    break format!("a text message of {} bytes (binary frames only)", t.len());
                }
                Some(Ok(Message::Close(_))) => break "the page closed the connection".to_owned(),
                Some(Ok(_)) => {}
            },
        }
    };
    {
        let mut live = lock(&app.live);
        if live.as_ref().is_some_and(|l| l.id == id) {
            *live = None;
        }
    }
    tracing::info!("{description} disconnected: {reason}");
    let _ = tx
        .send(Msg::Event(SourceEvent::Disconnected { reason }))
        .await;
}
