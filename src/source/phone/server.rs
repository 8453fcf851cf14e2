//! The phone page's HTTPS server: its own thread and tokio runtime; TLS by rustls; HTTP/1.1
//! by hyper with axum's router; the page, its scripts, and the WebSocket the frames arrive on.
//!
//! Routes: `GET /phone?token=…` (the page), `GET /phone.js`, `/wire.js`, `/phone.css` (its
//! code: nothing secret), `GET /phone/ws?token=…` (the WebSocket). Refusals:
//! - no token or a wrong one: 403; past [`FREE_FAILURES`] failures within [`FAILURE_WINDOW`]
//!   from one address, each further answer waits, doubling from 250 ms up to 8 s;
//! - a second WebSocket while one streams (data within [`TAKEOVER_SILENCE`]): 409; a silent
//!   one is closed and the new one takes over (a phone that roamed to another network);
//! - a message over [`super::MAX_MESSAGE`] bytes: the connection is closed (1009);
//! - a connection whose first byte is not a TLS handshake: a plain-text 400 saying to use
//!   `https://`, then closed.

use super::stats::Conn;
use super::{lock, Msg, Phone, MAX_MESSAGE};
use crate::shutdown::Shutdown;
use crate::source::SourceEvent;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, State};
use axum::http::{header, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;

/// Failures allowed from one address within [`FAILURE_WINDOW`] before answers slow down.
pub const FREE_FAILURES: u32 = 5;
pub const FAILURE_WINDOW: Duration = Duration::from_secs(60);
/// Addresses remembered for the slow-down.
const FAILURE_ADDRESSES: usize = 4096;
/// A streaming WebSocket silent this long is taken over by a new one.
pub const TAKEOVER_SILENCE: Duration = Duration::from_secs(2);
/// A WebSocket silent this long is closed (the page streams at its sensor rate).
pub const WATCHDOG: Duration = Duration::from_secs(3);
/// What the page is told, this often.
const FEEDBACK_PERIOD: Duration = Duration::from_millis(250);
/// TLS handshake, and the head of a request, must arrive within this.
const HANDSHAKE: Duration = Duration::from_secs(10);
/// Connections at once (the page and its scripts, the WebSocket, a few refused).
const MAX_CONNECTIONS: usize = 64;

pub(super) struct Context {
    pub token: String,
    pub phone: Arc<Phone>,
    pub tx: tokio::sync::mpsc::Sender<Msg>,
    pub tls: tokio_rustls::TlsAcceptor,
    pub port: u16,
}

/// The streaming WebSocket.
struct Live {
    id: u64,
    last_data: Instant,
    kick: Arc<tokio::sync::Notify>,
}

struct Shared {
    ctx: Context,
    live: Mutex<Option<Live>>,
    failures: Mutex<HashMap<IpAddr, (u32, Instant)>>,
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
        let app: App = Arc::new(Shared {
            ctx,
            live: Mutex::new(None),
            failures: Mutex::new(HashMap::new()),
            next_id: AtomicU64::new(1),
        });
        let router = router(app.clone());
        let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
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
            let Ok(permit) = slots.clone().try_acquire_owned() else {
                continue; // dropped: too many connections at once
            };
            let (app, router) = (app.clone(), router.clone());
            tokio::spawn(async move {
                connection(app, router, stream, peer).await;
                drop(permit);
            });
        }
    });
    drop(rt);
}

/// One TCP connection: refused if it is not TLS, else served over HTTP/1.1 with upgrades.
async fn connection(app: App, router: Router, stream: tokio::net::TcpStream, peer: SocketAddr) {
    let _ = stream.set_nodelay(true);
    let mut first = [0u8; 1];
    match tokio::time::timeout(HANDSHAKE, stream.peek(&mut first)).await {
        Ok(Ok(1)) => {}
        _ => return,
    }
    // A TLS connection starts with a handshake record (content type 22).
    if first[0] != 0x16 {
        lock(&app.ctx.phone.stats).refused.plain_http += 1;
        refuse_plain_http(stream, app.ctx.port).await;
        return;
    }
    let tls = match tokio::time::timeout(HANDSHAKE, app.ctx.tls.accept(stream)).await {
        Ok(Ok(s)) => s,
        _ => {
            lock(&app.ctx.phone.stats).refused.tls += 1;
            return;
        }
    };
    let svc = hyper::service::service_fn(move |mut req: hyper::Request<hyper::body::Incoming>| {
        req.extensions_mut().insert(ConnectInfo(peer));
        tower::ServiceExt::oneshot(router.clone(), req)
    });
    let served = hyper::server::conn::http1::Builder::new()
        .timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(HANDSHAKE)
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
        .route("/phone", get(page))
        .route("/phone/ws", get(ws))
        .route("/phone.js", get(|| asset("phone.js")))
        .route("/wire.js", get(|| asset("wire.js")))
        .route("/phone.css", get(|| asset("phone.css")))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .with_state(app)
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

/// The token in `uri`'s query, if any.
fn token_in(uri: &Uri) -> Option<&str> {
    uri.query()?
        .split('&')
        .find_map(|kv| kv.strip_prefix("token="))
}

/// Compares in time independent of where the strings differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// `Ok` when `uri` carries the token; else the 403 to answer, after the slow-down the
/// address has earned.
async fn check(app: &App, peer: SocketAddr, uri: &Uri) -> Result<(), Response> {
    if token_in(uri).is_some_and(|t| same(t, &app.ctx.token)) {
        return Ok(());
    }
    let n = {
        let mut f = lock(&app.failures);
        let now = Instant::now();
        if f.len() >= FAILURE_ADDRESSES {
            f.retain(|_, (_, since)| now - *since < FAILURE_WINDOW);
            if f.len() >= FAILURE_ADDRESSES {
                f.clear();
            }
        }
        let e = f.entry(peer.ip()).or_insert((0, now));
        if now - e.1 >= FAILURE_WINDOW {
            *e = (0, now);
        }
        e.0 += 1;
        e.0
    };
    {
        let mut s = lock(&app.ctx.phone.stats);
        s.refused.token += 1;
        if n > FREE_FAILURES {
            s.refused.slowed += 1;
        }
    }
    if n > FREE_FAILURES {
        let k = (n - FREE_FAILURES - 1).min(5);
        tokio::time::sleep(Duration::from_millis(250 << k)).await;
    }
    tracing::debug!(%peer, "phone page: refused a request without the right token");
    Err((
        StatusCode::FORBIDDEN,
        "the phone page needs its token: open the address sfs printed (or its QR code)\n",
    )
        .into_response())
}

async fn page(
    State(app): State<App>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    uri: Uri,
) -> Response {
    if let Err(r) = check(&app, peer, &uri).await {
        return r;
    }
    let (kind, body) = crate::view::assets::PHONE_PAGE;
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-store"),
            // The address holds the token: no page it links to is told it.
            (header::REFERRER_POLICY, "no-referrer"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
        .into_response()
}

async fn ws(
    State(app): State<App>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    uri: Uri,
    upgrade: WebSocketUpgrade,
) -> Response {
    if let Err(r) = check(&app, peer, &uri).await {
        return r;
    }
    let kick = Arc::new(tokio::sync::Notify::new());
    let id = app.next_id.fetch_add(1, Ordering::Relaxed);
    {
        let mut live = lock(&app.live);
        if let Some(l) = &*live {
            if l.last_data.elapsed() < TAKEOVER_SILENCE {
                lock(&app.ctx.phone.stats).refused.busy += 1;
                tracing::info!(%peer, "phone page: refused a second phone while one streams");
                return (
                    StatusCode::CONFLICT,
                    "another phone is streaming to this session\n",
                )
                    .into_response();
            }
            l.kick.notify_one();
        }
        *live = Some(Live {
            id,
            last_data: Instant::now(),
            kick: kick.clone(),
        });
    }
    upgrade
        .max_message_size(4 * MAX_MESSAGE)
        .max_frame_size(4 * MAX_MESSAGE)
        .on_upgrade(move |socket| stream(app, socket, id, kick, peer))
}

/// The page's hello (a text message): its clock's origin and its browser.
#[derive(serde::Deserialize)]
struct Hello {
    time_origin_ms: f64,
    #[serde(default)]
    user_agent: String,
}

/// One streaming WebSocket: its binary messages go to the writer, the feedback comes back.
async fn stream(
    app: App,
    mut socket: WebSocket,
    id: u64,
    kick: Arc<tokio::sync::Notify>,
    peer: SocketAddr,
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
    let mut conn = Conn::default();
    let mut feedback = tokio::time::interval(FEEDBACK_PERIOD);
    let mut last_data = Instant::now();
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
                    if e.to_string().contains("too long") {
                        lock(&app.ctx.phone.stats).refused.oversized += 1;
                    }
                    break format!("{e}");
                }
                Some(Ok(Message::Binary(b))) => {
                    if b.len() > MAX_MESSAGE {
                        lock(&app.ctx.phone.stats).refused.oversized += 1;
                        let _ = socket.send(Message::Close(Some(CloseFrame {
                            code: 1009,
                            reason: format!("a message is at most {MAX_MESSAGE} bytes").into(),
                        }))).await;
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
                    let hello = (t.len() <= 4096)
                        .then(|| serde_json::from_str::<Hello>(t.as_str()).ok())
                        .flatten()
                        .filter(|h| h.time_origin_ms.is_finite());
                    let mut s = lock(&app.ctx.phone.stats);
                    match hello {
                        Some(h) => {
                            conn.time_origin_ms = Some(h.time_origin_ms);
                            s.user_agent = Some(h.user_agent.chars().take(200).collect());
                        }
                        None => s.ignored_text += 1,
                    }
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
