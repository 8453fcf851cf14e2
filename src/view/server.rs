//! The view's HTTP server (axum): the routes of [`super`], the status ticker, and the limits
//! that keep a browser from holding up the session.

use super::conn::Ends;
use super::{assets, Event, View};
use crate::shutdown::Shutdown;
use axum::error_handling::HandleErrorLayer;
use axum::extract::{ConnectInfo, Path, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::sse::{KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tower::ServiceBuilder;

/// Where `--view` serves when given without an address.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:8040";
/// Event streams open at once; one more takes the slot of a stream whose client has shown no
/// sign of reading for [`UNDRAINED`], else it is answered 503.
pub const MAX_STREAMS: usize = 32;
/// A stream whose client has not drained for this long gives its slot to a new client.
pub const UNDRAINED: Duration = Duration::from_secs(3);
/// Requests being answered at once (event streams aside); one more is answered 503.
pub const MAX_IN_FLIGHT: usize = 64;
/// A request not answered within this is dropped.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);
/// `status` events while data flows.
const STATUS_PERIOD: Duration = Duration::from_millis(200);
/// `preview` events while a curve is scanned (the session integrates it as often).
pub const PREVIEW_PERIOD: Duration = Duration::from_millis(100);
/// `status` events when nothing changes.
const HEARTBEAT: Duration = Duration::from_secs(1);

/// Binds `addr`: done before a session captures a byte, so that a taken port stops it while
/// its directory is untouched (a retry with the same `--session` then works).
pub async fn bind(addr: SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(addr).await
}

#[derive(Clone)]
struct App {
    view: View,
    streams: Arc<Streams>,
    stop: Shutdown,
    /// Whether the view wants its token (then every client answered has shown it).
    token: bool,
}

impl App {
    /// Whether this client may see the phone page's token (the right to write into the
    /// session): one that has shown the view's token, or, without one, a client on this
    /// machine.
    fn may_write(&self, ends: &super::conn::Ends) -> bool {
        self.token || ends.same_machine()
    }
}

/// Serves `view` on every listener (from [`bind`]) until `stop`, with the status ticker,
/// answering the hosts and wanting the token of `(allowed_hosts, token)`
/// ([`super::access`]). The returned task ends when every server has stopped.
pub fn serve(
    listeners: Vec<tokio::net::TcpListener>,
    view: View,
    stop: Shutdown,
    (allowed_hosts, token): (Vec<String>, Option<String>),
) -> tokio::task::JoinHandle<()> {
    let ports = listeners
        .iter()
        .filter_map(|l| l.local_addr().ok())
        .map(|a| a.port())
        .collect();
    let exposed = token.is_none();
    let access = Arc::new(super::access::Access::new(ports, allowed_hosts, token));
    let app = App {
        view: view.clone(),
        streams: Arc::new(Streams::default()),
        stop: stop.clone(),
        token: !exposed,
    };
    let router = Router::new()
        .route("/", get(index))
        .route("/assets/{*path}", get(asset))
        .route("/network.glb", get(glb))
        .route("/monitor.json", get(monitor_json))
        .route("/phone-qr.svg", get(phone_qr))
        .route("/status", get(status))
        .route("/metrics", get(metrics))
        .route("/events", get(events))
        .fallback(not_found)
        .with_state(app)
        .layer(
            ServiceBuilder::new()
                .layer(HandleErrorLayer::new(|_: tower::BoxError| async {
                    (StatusCode::SERVICE_UNAVAILABLE, "busy\n")
                }))
                .load_shed()
                .concurrency_limit(MAX_IN_FLIGHT),
        )
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            REQUEST_TIMEOUT,
        ))
        .layer(axum::middleware::from_fn_with_state(
            access,
            super::access::check,
        ))
        .layer(tower_http::set_header::SetResponseHeaderLayer::overriding(
            header::X_CONTENT_TYPE_OPTIONS,
            HeaderValue::from_static("nosniff"),
        ));
    // One cap for every listener: the connections share the process's descriptors.
    let cap = super::conn::connection_cap(super::conn::raise_file_limit());
    let live = Arc::new(AtomicUsize::new(0));
    let mut servers = Vec::new();
    for listener in listeners {
        if let Ok(addr) = listener.local_addr() {
            tracing::info!("view at http://{addr}/ (metrics at /metrics)");
            if addr.ip().is_unspecified() {
                tracing::warn!(
                    "the view listens on every network interface ({addr}): anyone who can reach this machine can read the scan{}",
                    if exposed { "; set [view] token to require a token" } else { " who has the token" }
                );
            }
        }
        let stop = stop.clone();
        let router = router.clone();
        let listener = super::conn::GuardedListener::new(listener, live.clone(), cap);
        servers.push(tokio::spawn(async move {
            let served = axum::serve(
                listener,
                router.into_make_service_with_connect_info::<super::conn::Ends>(),
            )
            .with_graceful_shutdown(async move { stop.triggered().await })
            .await;
            if let Err(e) = served {
                tracing::warn!("view server: {e}");
            }
        }));
    }
    let ticker = tokio::spawn(tick(view, stop));
    tokio::spawn(async move {
        for s in servers {
            let _ = s.await;
        }
        let _ = ticker.await;
    })
}

/// Sends `status` (at [`STATUS_PERIOD`] while it changes, every [`HEARTBEAT`] otherwise) and
/// `preview` (at [`PREVIEW_PERIOD`] while it changes), and keeps the packet rate.
async fn tick(view: View, stop: Shutdown) {
    let mut interval = tokio::time::interval(PREVIEW_PERIOD);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let (mut seen, mut preview_seen) = (u64::MAX, 0);
    let mut last_sent = Instant::now();
    let mut rate_from = (Instant::now(), 0u64);
    loop {
        tokio::select! {
            _ = interval.tick() => {}
            _ = stop.triggered() => return,
        }
        let g = view.status_generation();
        let since = last_sent.elapsed();
        // (Half a tick of slack: ticks jitter, and a status every third tick would be 3 Hz.)
        if (g != seen && since + PREVIEW_PERIOD / 2 >= STATUS_PERIOD) || since >= HEARTBEAT {
            seen = g;
            last_sent = Instant::now();
            let status = {
                let mut s = super::lock(&view.shared.status);
                let dt = rate_from.0.elapsed().as_secs_f64();
                if dt > 0.0 {
                    s.link.packets_per_s = s.link.packets.saturating_sub(rate_from.1) as f64 / dt;
                }
                rate_from = (Instant::now(), s.link.packets);
                s.clone()
            };
            view.send("status", serde_json::to_string(&status).unwrap_or_default());
        }
        if let Some(p) = view.take_preview(&mut preview_seen) {
            let data = p.map_or_else(|| "null".to_string(), |p| p.to_string());
            view.send("preview", data);
        }
    }
}

async fn index() -> Response {
    let (kind, body) = assets::INDEX;
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}

async fn asset(Path(path): Path<String>) -> Response {
    match assets::get(&path) {
        Some((kind, body)) => (
            [
                (header::CONTENT_TYPE, kind),
                (header::CACHE_CONTROL, "max-age=3600"),
            ],
            body,
        )
            .into_response(),
        None => not_found().await,
    }
}

async fn glb(State(app): State<App>) -> Response {
    match app.view.glb() {
        Some(bytes) => (
            [
                (header::CONTENT_TYPE, "model/gltf-binary"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            bytes,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no network yet\n").into_response(),
    }
}

async fn monitor_json(State(app): State<App>) -> Response {
    match app.view.monitor_json() {
        Some(json) => (
            [
                (header::CONTENT_TYPE, "application/json"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            json.to_string(),
        )
            .into_response(),
        None => (
            StatusCode::NOT_FOUND,
            "no shape yet (a monitoring session shows its first after its first epochs)\n",
        )
            .into_response(),
    }
}

/// The phone page's address as a QR code (`sfs run --phone`), for the operator to scan from
/// the view's screen: only to a client that may write ([`App::may_write`]).
async fn phone_qr(State(app): State<App>, ConnectInfo(ends): ConnectInfo<Ends>) -> Response {
    let Some(url) = app.view.phone_url() else {
        return (StatusCode::NOT_FOUND, "no phone page in this session\n").into_response();
    };
    if !app.may_write(&ends) {
        return phone_withheld();
    }
    match crate::source::phone::qr::svg(&url) {
        Some(svg) => (
            [
                (header::CONTENT_TYPE, "image/svg+xml"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            svg,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no phone page in this session\n").into_response(),
    }
}

/// 403 for the phone page's address asked by a client that may not write.
fn phone_withheld() -> Response {
    (
        StatusCode::FORBIDDEN,
        [(header::CACHE_CONTROL, "no-store")],
        "the phone page's address carries the right to write into the session: it is shown on the machine that runs sfs (its terminal, SESSION/phone.url, or this view opened there), or with the view's token ([view] token)\n",
    )
        .into_response()
}

async fn status(State(app): State<App>, ConnectInfo(ends): ConnectInfo<Ends>) -> Response {
    let mut status = app.view.status();
    if app.may_write(&ends) {
        status.phone_url = app.view.phone_url();
    }
    ([(header::CACHE_CONTROL, "no-store")], axum::Json(status)).into_response()
}

async fn metrics(State(app): State<App>) -> Response {
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        app.view.metrics().encode(),
    )
        .into_response()
}

async fn not_found() -> Response {
    (StatusCode::NOT_FOUND, "not found\n").into_response()
}

/// An open event stream: its connection's health, and the signal that ends it.
type OpenStream = (Arc<super::conn::Health>, Arc<tokio::sync::Notify>);

/// The open event streams.
#[derive(Default)]
struct Streams {
    open: std::sync::Mutex<std::collections::HashMap<u64, OpenStream>>,
    next: std::sync::atomic::AtomicU64,
}

/// An open event stream's place in [`Streams`], given up when dropped.
struct StreamSlot(Arc<Streams>, u64);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        super::lock(&self.0.open).remove(&self.1);
    }
}

impl Streams {
    /// A slot for a new stream on a connection of `health`; when all are taken, the one whose
    /// client has shown no sign of reading longest gives its place (after [`UNDRAINED`]).
    fn take(
        self: &Arc<Self>,
        health: Arc<super::conn::Health>,
    ) -> Option<(StreamSlot, Arc<tokio::sync::Notify>)> {
        let mut open = super::lock(&self.open);
        if open.len() >= MAX_STREAMS {
            let (id, undrained) = open
                .iter()
                .map(|(id, (h, _))| (*id, h.undrained_for()))
                .max_by_key(|(_, u)| *u)?;
            if undrained < UNDRAINED {
                return None;
            }
            if let Some((_, end)) = open.remove(&id) {
                tracing::debug!(
                    ?undrained,
                    "view: an event stream not read gave its slot to a new client"
                );
                end.notify_one();
            }
        }
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let end = Arc::new(tokio::sync::Notify::new());
        open.insert(id, (health, end.clone()));
        Some((StreamSlot(self.clone(), id), end))
    }
}

/// An event as the SSE stream sends it.
fn sse_event(ev: &Event) -> axum::response::sse::Event {
    axum::response::sse::Event::default()
        .event(ev.name)
        .data(&*ev.data)
}

async fn events(State(app): State<App>, ConnectInfo(ends): ConnectInfo<Ends>) -> Response {
    let Some((slot, end)) = app.streams.take(ends.health.clone()) else {
        return (StatusCode::SERVICE_UNAVAILABLE, "too many event streams\n").into_response();
    };
    let rx = app.view.subscribe();
    // The first event is the status now, so that a page shows something at once.
    let first = Event {
        name: "status",
        data: serde_json::to_string(&app.view.status())
            .unwrap_or_default()
            .into(),
    };
    // Once a second, whether the connection's drain check asks for padding (see `conn::Drain`).
    let mut probe_tick = tokio::time::interval(Duration::from_secs(1));
    probe_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let health = ends.health.clone();
    let state = (Some(first), rx, (slot, end), app.stop.clone(), probe_tick);
    let stream =
        futures_util::stream::unfold(state, move |(first, mut rx, slot, stop, mut tick)| {
            let health = health.clone();
            async move {
                let sse = match first {
                    Some(ev) => sse_event(&ev),
                    None => loop {
                        tokio::select! {
                            r = rx.recv() => match r {
                                Ok(ev) => break sse_event(&ev),
                                // Too far behind: ended; a browser reconnects and loads the
                                // network again.
                                Err(e) => {
                                    tracing::debug!("view: an event stream ended: {e}");
                                    return None;
                                }
                            },
                            _ = stop.triggered() => return None,
                            // Its slot given to a new client (not read for a while).
                            _ = slot.1.notified() => return None,
                            _ = tick.tick() => {
                                let n = health.take_probe();
                                if n > 0 {
                                    break axum::response::sse::Event::default()
                                        .comment(" ".repeat(n as usize));
                                }
                            }
                        }
                    },
                };
                Some((
                    Ok::<_, std::convert::Infallible>(sse),
                    (None, rx, slot, stop, tick),
                ))
            }
        });
    let mut r = Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response();
    // Its connection ends with it (a browser opens a new one to reconnect): a stream ended
    // for a client that does not read leaves nothing held.
    r.headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    r
}
