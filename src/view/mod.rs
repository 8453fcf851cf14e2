//! The operator's live view: a web page served by the daemon while a session runs
//! (`--view [ADDR]`, `[view] address`; the monitoring metrics share the server).
//!
//! Routes (stable: tests and scripts use them):
//! - `GET /` the page, `GET /assets/…` its scripts (three.js vendored, embedded: [`assets`]);
//! - `GET /network.glb` the latest reconstruction (the bytes of `SESSION/network.glb`);
//! - `GET /status` one JSON object ([`Status`]);
//! - `GET /metrics` Prometheus text ([`crate::metrics`]);
//! - `GET /events` server-sent events: `status` (5 Hz while data flows, 1 Hz otherwise);
//!   `curve` (a curve ended: `{"index"}`); `curves` (an update's network is made, before its
//!   surface: `{"update", "ended", "curves": [{"curve", "kind", "boundary", "nodes",
//!   "points"}], "nodes": {"ID": [x, y, z]}, "closure", "joins"}`, positions in the glb's
//!   frame to 0.01 mm, `closure` and `joins` as in the status; issue 35); `network` (a new `network.glb` is in place:
//!   `{"update", "curves", "ended": [{"curve", "e_unix_ms"}]}`, the curves it brings in and
//!   when their `E` packet was read, wall clock); `warning` (each warning of `report.json` as
//!   it is raised: `{"text", "code", "curve", "node"}`; acquisition's at once, the
//!   reconstruction's when the session ends, since they change with every curve until then:
//!   meanwhile the latest are in the status); `preview` (the curve being scanned, integrated
//!   so far, 10 Hz while it is scanned: `{"curve", "start_node", "points"}`, or `null`).
//!
//! The session and the live worker publish into a [`View`] (a lock and an assignment, never a
//! wait); the server reads it. Nothing the server does can hold them up: events go through a
//! bounded broadcast queue, and a client that falls behind it is dropped (its browser
//! reconnects); the number of event streams and of requests in flight is limited. Who is
//! answered is [`access`]'s (the `Host`, the token); how many connections, and how long one
//! may hold its descriptor without reading, sending or draining, [`conn`]'s.

pub mod access;
pub mod assets;
pub mod conn;
mod server;

pub use server::{bind, serve, DEFAULT_ADDRESS, PREVIEW_PERIOD};

/// The forms `--view` and `[view] address` accept.
pub const ADDRESS_FORMS: &str = "PORT (this machine only: 127.0.0.1:PORT), localhost:PORT, \
     IP:PORT (0.0.0.0:PORT: every interface) or [IPv6]:PORT";

/// Parses where the view is served: a port alone (on the loopback), `localhost:PORT`, or an
/// IP address with its port. An error names the accepted forms.
///
/// ```
/// use sfs::view::parse_address;
/// assert_eq!(parse_address("8933").unwrap().to_string(), "127.0.0.1:8933");
/// assert_eq!(parse_address("localhost:8933").unwrap().to_string(), "127.0.0.1:8933");
/// assert_eq!(parse_address("[::1]:80").unwrap().to_string(), "[::1]:80");
/// assert!(parse_address("localhost").unwrap_err().contains("localhost:PORT"));
/// ```
pub fn parse_address(s: &str) -> Result<std::net::SocketAddr, String> {
    use std::net::{Ipv4Addr, SocketAddr};
    let s = s.trim();
    let port = |p: &str| {
        p.parse::<u16>()
            .map_err(|_| format!("{p:?} is not a port (0 to 65535)"))
    };
    let wrong = |why: String| format!("{s:?}: {why}; give {ADDRESS_FORMS}");
    if s.chars().all(|c| c.is_ascii_digit()) && !s.is_empty() {
        return port(s)
            .map(|p| SocketAddr::from((Ipv4Addr::LOCALHOST, p)))
            .map_err(wrong);
    }
    if let Some(p) = s.strip_prefix("localhost:") {
        return port(p)
            .map(|p| SocketAddr::from((Ipv4Addr::LOCALHOST, p)))
            .map_err(wrong);
    }
    s.parse::<SocketAddr>().map_err(|_| {
        wrong(match s.rsplit_once(':') {
            None => "no port".into(),
            Some(_) => "not an IP address and a port".into(),
        })
    })
}

use crate::link::{LinkState, LinkStats};
use crate::metrics::SessionMetrics;
use crate::report::{LiveReport, Percentiles};
use crate::warning::Warning;
use serde::Serialize;
use std::collections::HashSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// Warnings kept in [`Status::warnings`] (the latest).
pub const STATUS_WARNINGS: usize = 20;
/// Events queued for the event streams; a client further behind is dropped.
pub const EVENT_QUEUE: usize = 1024;

/// What `GET /status` returns.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    /// `starting`, `running`, `ended`.
    pub state: &'static str,
    pub source: String,
    /// Session time of the latest packet, s.
    pub session_time_s: f64,
    /// The curve being scanned.
    pub curve: Option<CurrentCurve>,
    pub curves_accepted: usize,
    pub link: LinkStatus,
    /// The device's HELLO and last STATUS.
    pub device: Option<DeviceStatus>,
    /// The device's orientation now: its direction of travel `t` and outward normal `n`, in
    /// the glb's frame.
    pub orientation: Option<Orientation>,
    /// The latest warnings (at most [`STATUS_WARNINGS`]), oldest first.
    pub warnings: Vec<WarningEvent>,
    pub warnings_total: u64,
    /// Live reconstruction figures.
    pub live: Option<LiveStatus>,
    /// What the latest reconstruction could not do (replaced at every update: a network
    /// still being scanned has open faces; the final ones are `warning` events).
    pub reconstruction: Vec<WarningEvent>,
    /// How each curve of the latest network closes its loops, with the tags to rescan
    /// (`report.json` `network.closure` in brief); empty until the network has a loop.
    pub closure: Vec<ClosureStatus>,
    /// Nodes of the latest network joined to a curve that passes them untagged, crossings
    /// nobody tagged proposed, and joins refused (`report.json` `network.joined`,
    /// `proposed`, `joins_refused` in brief; issue 34).
    pub joins: JoinsStatus,
    /// The phone page (`sfs run --phone`): its address without the token, and its
    /// certificate's fingerprint. The token never goes to every client.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phone: Option<PhoneStatus>,
    /// The phone page's address with its token, in `GET /status` only, and only to a client
    /// that may write into the session (on this machine, or with the view's token); its QR
    /// code is at `/phone-qr.svg` for the same clients. Never in the `status` events.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phone_url: Option<String>,
    /// The latest reconstruction's verdict, expected error and suspects (`report.json`
    /// `quality`; issue 49).
    pub quality: Option<crate::report::Quality>,
    /// A monitoring session (`[monitor]`): the latest epoch, the reference, the alarms and
    /// each sensor's health. The page then shows the structure, not the scanning interface.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub monitor: Option<crate::monitor::run::MonitorStatus>,
}

/// The phone page as every client of the view sees it.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct PhoneStatus {
    /// `https://HOST:PORT/phone`, without the token.
    pub page: String,
    /// SHA-256 of its certificate, `AB:CD:…`.
    pub fingerprint: String,
}

/// The joins of the latest network as the view shows them.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct JoinsStatus {
    pub joined: Vec<JoinedNode>,
    pub proposed: Vec<ProposedCrossing>,
    pub refused: Vec<RefusedJoinStatus>,
}

/// A node joined to a curve that passes it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct JoinedNode {
    pub node: u32,
    pub curve: usize,
    /// Where the curve passed the node before it was joined, mm.
    pub distance_mm: f64,
    /// A crossing nobody tagged, joined under a fresh node (`join_untagged`).
    pub untagged: bool,
}

/// Two curves that cross with no node there.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ProposedCrossing {
    pub curves: [usize; 2],
    /// Where, in the glb's frame.
    pub point: [f32; 3],
    pub distance_mm: f64,
}

/// A join undone, and why.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RefusedJoinStatus {
    pub node: u32,
    pub curve: usize,
    pub reason: String,
}

impl From<&sfs_geometry::network::NetworkReport> for JoinsStatus {
    fn from(r: &sfs_geometry::network::NetworkReport) -> Self {
        let mm = |m: f64| (m * 1e4).round() / 10.0;
        JoinsStatus {
            joined: r
                .joined
                .iter()
                .map(|j| JoinedNode {
                    node: j.node,
                    curve: j.curve,
                    distance_mm: mm(j.distance_m),
                    untagged: j.untagged,
                })
                .collect(),
            proposed: r
                .proposed
                .iter()
                .map(|p| ProposedCrossing {
                    curves: p.curves,
                    point: crate::gltf_out::to_gltf(&nalgebra::Vector3::from(p.point)),
                    distance_mm: mm(p.distance_m),
                })
                .collect(),
            refused: r
                .joins_refused
                .iter()
                .map(|x| RefusedJoinStatus {
                    node: x.node,
                    curve: x.curve,
                    reason: x.reason.clone(),
                })
                .collect(),
        }
    }
}

/// One curve's closure misfit as the view shows it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ClosureStatus {
    pub curve: usize,
    /// The most by which one of its segments misses its nodes, mm.
    pub misfit_mm: f64,
    /// Its marked tags ([`sfs_geometry::network::closure::TagMisfit::marked`]).
    pub marked: Vec<MarkedTag>,
}

/// A tag the operator should check or rescan.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MarkedTag {
    /// Position in the curve's tag list (0 = first).
    pub tag: usize,
    pub node: u32,
    /// How far the curve would have to be pulled at the tag to meet the node, mm.
    pub offset_mm: f64,
    /// The reconstruction let go of it (a wrong index, probably).
    pub detached: bool,
}

impl From<&sfs_geometry::network::closure::CurveMisfit> for ClosureStatus {
    fn from(m: &sfs_geometry::network::closure::CurveMisfit) -> Self {
        let mm = |m: f64| (m * 1e4).round() / 10.0;
        ClosureStatus {
            curve: m.curve,
            misfit_mm: mm(m.misfit_m),
            marked: m
                .tags
                .iter()
                .filter(|t| t.marked)
                .map(|t| MarkedTag {
                    tag: t.tag,
                    node: t.node,
                    offset_mm: mm(t.offset_m),
                    detached: t.detached,
                })
                .collect(),
        }
    }
}

/// The curve being scanned.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct CurrentCurve {
    pub index: usize,
    /// `boundary`, `interior`, `crease` or `guide` (as started).
    pub kind: &'static str,
    /// Nodes tagged so far.
    pub nodes: Vec<u32>,
    pub samples: usize,
    /// Distance rolled since its first tag (Morphorider), m.
    pub distance_m: Option<f64>,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct LinkStatus {
    /// What the link is doing now: `state` (connecting, connected, silent, disconnected,
    /// reconnecting, ended), since when, the attempt and reason, a port's problem.
    #[serde(flatten)]
    pub state: LinkState,
    pub bytes: u64,
    pub packets: u64,
    /// Over the last status period.
    pub packets_per_s: f64,
    pub rejected: u64,
    pub lost: u64,
    pub reboots: u64,
    pub disconnects: u64,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct DeviceStatus {
    pub kind: &'static str,
    pub id: u32,
    pub rate_hz: u16,
    pub battery_mv: Option<u16>,
    pub status_flags: Vec<&'static str>,
    /// Samples the device itself dropped since power-up.
    pub dropped: Option<u32>,
}

#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Orientation {
    pub t: [f32; 3],
    pub n: [f32; 3],
}

impl Orientation {
    /// Of a frame `[T B N]` → world rotation.
    pub fn of(q: &nalgebra::UnitQuaternion<f64>) -> Orientation {
        use nalgebra::Vector3;
        Orientation {
            t: crate::gltf_out::to_gltf(&(q * Vector3::x())),
            n: crate::gltf_out::to_gltf(&(q * Vector3::z())),
        }
    }
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct LiveStatus {
    pub updates: usize,
    pub latency_ms: Percentiles,
    /// From `E` to the curves published (the `curves` event), ms.
    pub curves_latency_ms: Percentiles,
    pub update_ms: Percentiles,
}

/// A warning as the view shows it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct WarningEvent {
    pub text: String,
    pub code: &'static str,
    pub curve: Option<usize>,
    pub node: Option<u32>,
}

impl From<&Warning> for WarningEvent {
    fn from(w: &Warning) -> Self {
        WarningEvent {
            text: w.to_string(),
            code: w.code(),
            curve: w.curve(),
            node: w.node(),
        }
    }
}

/// The closure marks and the joins of a reconstruction, as the status and the events give them.
fn marks(products: &crate::pipeline::Products) -> (Vec<ClosureStatus>, JoinsStatus) {
    let closure = products
        .network
        .iter()
        .flat_map(|n| &n.report.closure)
        .map(Into::into)
        .collect();
    let joins = products
        .network
        .as_ref()
        .map(|n| (&n.report).into())
        .unwrap_or_default();
    (closure, joins)
}

/// The curves an update brings in, each with its `E` packet on the wall clock
/// (`{"curve", "e_unix_ms"}`), for a page on this machine to measure the time to its own
/// screen.
fn ended_on_the_wall_clock(posted: &[(usize, std::time::Instant)]) -> Vec<serde_json::Value> {
    let (now, wall) = (std::time::Instant::now(), std::time::SystemTime::now());
    posted
        .iter()
        .map(|(curve, at)| {
            let unix = wall
                .checked_sub(now.saturating_duration_since(*at))
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0.0, |d| d.as_secs_f64() * 1e3);
            serde_json::json!({ "curve": curve, "e_unix_ms": unix })
        })
        .collect()
}

/// One server-sent event: its name and JSON data.
#[derive(Debug, Clone)]
pub struct Event {
    pub name: &'static str,
    pub data: Arc<str>,
}

/// The live state the view serves; cheap to clone, shared by the session, the live worker
/// and the server.
#[derive(Debug, Clone)]
pub struct View {
    shared: Arc<Shared>,
}

#[derive(Debug)]
struct Shared {
    metrics: SessionMetrics,
    status: Mutex<Status>,
    /// Bumped at every status change (the server sends `status` when it moved).
    status_generation: AtomicU64,
    glb: Mutex<Option<axum::body::Bytes>>,
    events: tokio::sync::broadcast::Sender<Event>,
    /// Texts of the warnings already sent.
    warned: Mutex<HashSet<String>>,
    /// Suspects already counted (curve, tag, kind).
    suspected: Mutex<HashSet<(usize, Option<usize>, &'static str)>>,
    preview: Mutex<Option<Arc<str>>>,
    preview_generation: AtomicU64,
    /// A monitoring session's latest shape and reference ([`View::monitor_json`]).
    monitor_json: Mutex<Option<Arc<str>>>,
    /// Node positions of the latest network, world frame (where a preview starts).
    nodes: Mutex<std::collections::BTreeMap<u32, nalgebra::Vector3<f64>>>,
    /// The phone page's address with its token (kept out of [`Status`]: see
    /// [`Status::phone_url`]).
    phone_url: Mutex<Option<String>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl View {
    pub fn new(source: &str, metrics: SessionMetrics) -> View {
        let (events, _) = tokio::sync::broadcast::channel(EVENT_QUEUE);
        View {
            shared: Arc::new(Shared {
                metrics,
                status: Mutex::new(Status {
                    state: "starting",
                    source: source.to_owned(),
                    ..Default::default()
                }),
                status_generation: AtomicU64::new(0),
                glb: Mutex::new(None),
                events,
                warned: Mutex::new(HashSet::new()),
                suspected: Mutex::new(HashSet::new()),
                preview: Mutex::new(None),
                preview_generation: AtomicU64::new(0),
                monitor_json: Mutex::new(None),
                nodes: Mutex::new(Default::default()),
                phone_url: Mutex::new(None),
            }),
        }
    }

    pub fn metrics(&self) -> &SessionMetrics {
        &self.shared.metrics
    }

    /// Changes the status (and marks it changed).
    pub fn update(&self, f: impl FnOnce(&mut Status)) {
        f(&mut lock(&self.shared.status));
        self.shared
            .status_generation
            .fetch_add(1, Ordering::Release);
    }

    /// The status now.
    /// The phone page served in this session: `url` with its token (given only to clients
    /// that may write) and its certificate's `fingerprint`.
    pub fn phone(&self, url: &str, fingerprint: &str) {
        *lock(&self.shared.phone_url) = Some(url.to_owned());
        let page = url.split_once('?').map_or(url, |(p, _)| p).to_owned();
        let fingerprint = fingerprint.to_owned();
        self.update(|s| s.phone = Some(PhoneStatus { page, fingerprint }));
    }

    /// The phone page's address with its token, for a client that may write.
    pub fn phone_url(&self) -> Option<String> {
        lock(&self.shared.phone_url).clone()
    }

    pub fn status(&self) -> Status {
        lock(&self.shared.status).clone()
    }

    fn status_generation(&self) -> u64 {
        self.shared.status_generation.load(Ordering::Acquire)
    }

    /// The link's counters (status and metrics).
    pub fn link(&self, stats: &LinkStats, state: LinkState, session_time_s: f64) {
        self.shared.metrics.link(stats);
        self.shared.metrics.link_up.set(state.up() as i64);
        self.update(|s| {
            s.state = "running";
            s.session_time_s = session_time_s;
            s.link = LinkStatus {
                state,
                bytes: stats.bytes,
                packets: stats.packets.total(),
                packets_per_s: s.link.packets_per_s,
                rejected: stats.rejected.total(),
                lost: stats.lost_packets,
                reboots: stats.reboots,
                disconnects: stats.disconnects,
            };
            s.device = stats.hello.as_ref().map(|h| DeviceStatus {
                kind: h.kind,
                id: h.device_id,
                rate_hz: h.rate_hz,
                battery_mv: stats.status.as_ref().map(|st| st.battery_mv),
                status_flags: stats
                    .status
                    .as_ref()
                    .map(|st| st.flag_names.clone())
                    .unwrap_or_default(),
                dropped: stats.status.as_ref().map(|st| st.dropped),
            });
        });
    }

    fn send(&self, name: &'static str, data: String) {
        // No receiver is not an error: nobody is looking.
        let _ = self.shared.events.send(Event {
            name,
            data: data.into(),
        });
    }

    /// A curve was accepted (the status counts it with the rest of the session's state).
    pub fn curve_ended(&self, index: usize) {
        self.shared.metrics.curves_accepted.inc();
        self.send("curve", serde_json::json!({ "index": index }).to_string());
    }

    /// Warnings raised so far (those not sent yet are sent, in order).
    pub fn warnings<'a>(&self, all: impl IntoIterator<Item = &'a Warning>) {
        let mut new = Vec::new();
        {
            let mut warned = lock(&self.shared.warned);
            for w in all {
                let e = WarningEvent::from(w);
                if warned.insert(e.text.clone()) {
                    new.push(e);
                }
            }
        }
        if new.is_empty() {
            return;
        }
        self.shared.metrics.warnings.inc_by(new.len() as u64);
        for e in &new {
            self.send("warning", serde_json::to_string(e).unwrap_or_default());
        }
        self.update(|s| {
            s.warnings_total += new.len() as u64;
            s.warnings.extend(new);
            let excess = s.warnings.len().saturating_sub(STATUS_WARNINGS);
            s.warnings.drain(..excess);
        });
    }

    /// What the latest live reconstruction reported (in the status, not as `warning` events:
    /// they change with every curve until the network is complete).
    pub fn reconstruction_warnings(&self, ws: &[Warning]) {
        let list: Vec<WarningEvent> = ws.iter().take(STATUS_WARNINGS).map(Into::into).collect();
        self.update(|s| s.reconstruction = list);
    }

    /// The network of live update `update` is made (its surface is not yet): its curves, nodes,
    /// closure marks and joins, sent as the `curves` event for the page to draw at once, with
    /// the curves it brings in (`posted`: index, when its `E` packet was read) (issue 35).
    pub fn curves(
        &self,
        products: &crate::pipeline::Products,
        update: usize,
        posted: &[(usize, std::time::Instant)],
    ) {
        let Some(n) = &products.network else {
            return; // nothing reconstructed: the network event says why (report.json)
        };
        *lock(&self.shared.nodes) = n.positions.nodes.clone();
        let (closure, joins) = marks(products);
        let curves: Vec<serde_json::Value> = n
            .positions
            .curves
            .iter()
            .map(|c| {
                let points: Vec<[f32; 3]> = c
                    .points
                    .iter()
                    .map(|p| crate::gltf_out::to_gltf(p).map(|x| (x * 1e5).round() / 1e5))
                    .collect();
                // Each point's uncertainty, mm to the hundredth (issue 49); empty in a live
                // update, whose second phase computes it (issue 51): the glb then has it.
                let sigma_mm: Vec<f64> = c
                    .sigma_m
                    .iter()
                    .map(|s| (s * 1e5).round() / 100.0)
                    .collect();
                serde_json::json!({
                    "curve": c.index,
                    "kind": c.kind.name(),
                    "boundary": c.kind == sfs_geometry::curve::CurveKind::Boundary,
                    "nodes": c.nodes.iter().map(|n| n.1).collect::<Vec<_>>(),
                    "points": points,
                    "sigma_mm": sigma_mm,
                })
            })
            .collect();
        let nodes: std::collections::BTreeMap<String, [f32; 3]> = products.nodes.clone();
        let data = serde_json::json!({
            "update": update,
            "ended": ended_on_the_wall_clock(posted),
            "curves": curves,
            "nodes": nodes,
            "closure": &closure,
            "joins": &joins,
        });
        self.update(|s| {
            s.closure = closure;
            s.joins = joins;
        });
        self.send("curves", data.to_string());
    }

    /// A new `network.glb` is in place (`products`: its bytes and node positions), after
    /// live update `live.updates` over `curves` curves, bringing in the curves `posted` (index,
    /// when its `E` packet was read).
    pub fn network(
        &self,
        products: &crate::pipeline::Products,
        live: &LiveReport,
        curves: usize,
        posted: &[(usize, std::time::Instant)],
    ) {
        if let Some(b) = &products.glb {
            *lock(&self.shared.glb) = Some(axum::body::Bytes::copy_from_slice(b));
        }
        if let Some(n) = &products.network {
            *lock(&self.shared.nodes) = n.positions.nodes.clone();
        }
        let (closure, joins) = marks(products);
        let m = &self.shared.metrics;
        crate::metrics::count_to(&m.updates, live.updates as u64);
        m.latency_p50.set(live.latency_ms.p50 * 1e-3);
        m.latency_p95.set(live.latency_ms.p95 * 1e-3);
        self.update(|s| {
            s.closure = closure;
            s.joins = joins;
            s.live = Some(LiveStatus {
                updates: live.updates,
                latency_ms: live.latency_ms.clone(),
                curves_latency_ms: live.curves_latency_ms.clone(),
                update_ms: live.update_ms.clone(),
            })
        });
        let ended = ended_on_the_wall_clock(posted);
        self.send(
            "network",
            serde_json::json!({ "update": live.updates, "curves": curves, "ended": ended })
                .to_string(),
        );
    }

    /// A monitoring session's state now.
    pub fn monitor(&self, status: crate::monitor::run::MonitorStatus) {
        self.update(|s| s.monitor = Some(status));
    }

    /// A monitoring session wrote `latest.glb`: its bytes are `/network.glb`, the shape and its
    /// reference `/monitor.json`; a `network` event says so.
    pub fn monitor_shape(&self, latest: crate::monitor::run::LatestShape) {
        *lock(&self.shared.glb) = Some(axum::body::Bytes::from(latest.glb));
        *lock(&self.shared.monitor_json) = Some(latest.json.into());
        self.send(
            "network",
            serde_json::json!({ "monitor_t_s": latest.t_s }).to_string(),
        );
    }

    /// The latest shape of a monitoring session and its reference, JSON.
    pub fn monitor_json(&self) -> Option<Arc<str>> {
        lock(&self.shared.monitor_json).clone()
    }

    /// The latest `network.glb` bytes.
    pub fn glb(&self) -> Option<axum::body::Bytes> {
        lock(&self.shared.glb).clone()
    }

    /// The preview of the curve being scanned: curve `index`, integrated from node `start`
    /// (`points` in the world frame relative to it), placed where the network has the node
    /// (at the origin before it has one), in the glb's frame; `None`: no curve open.
    pub fn preview(&self, curve: Option<(usize, u32, Vec<nalgebra::Vector3<f64>>)>) {
        let json = curve.map(|(index, start, points)| {
            let origin = lock(&self.shared.nodes)
                .get(&start)
                .copied()
                .unwrap_or_else(nalgebra::Vector3::zeros);
            let pts: Vec<[f32; 3]> = points
                .iter()
                .map(|p| crate::gltf_out::to_gltf(&(origin + p)))
                .collect();
            serde_json::json!({ "curve": index, "start_node": start, "points": pts }).to_string()
        });
        *lock(&self.shared.preview) = json.map(Into::into);
        self.shared
            .preview_generation
            .fetch_add(1, Ordering::Release);
    }

    fn take_preview(&self, seen: &mut u64) -> Option<Option<Arc<str>>> {
        let g = self.shared.preview_generation.load(Ordering::Acquire);
        if g == *seen {
            return None;
        }
        *seen = g;
        Some(lock(&self.shared.preview).clone())
    }

    /// The session ended.
    /// The latest reconstruction's quality: in the status, the verdict's gauge, and each
    /// suspect named for the first time counted.
    pub fn quality(&self, q: &crate::report::Quality) {
        let m = &self.shared.metrics;
        m.scan_verdict.set(q.verdict.level());
        let fresh = {
            let mut seen = lock(&self.shared.suspected);
            q.suspects
                .iter()
                .filter(|s| seen.insert((s.curve, s.tag, s.kind)))
                .count()
        };
        m.suspects.inc_by(fresh as u64);
        self.update(|s| s.quality = Some(q.clone()));
    }

    pub fn ended(&self) {
        self.update(|s| {
            s.state = "ended";
            s.curve = None;
        });
    }

    fn subscribe(&self) -> tokio::sync::broadcast::Receiver<Event> {
        self.shared.events.subscribe()
    }
}
