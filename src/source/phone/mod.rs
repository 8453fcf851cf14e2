//! The phone as the device: the daemon serves a page (`/phone?token=…`, HTTPS) that turns a
//! smartphone's browser into the scanner. The page reads the motion sensors, encodes wire
//! format v1 itself (HELLO, PHONE_SAMPLE, KEY: `src/view/assets/wire.js`) and streams whole
//! frames over one WebSocket (`/phone/ws?token=…`, binary messages). To the session this is a
//! byte source like the serial port: every byte goes to the capture before it is decoded.
//!
//! ```text
//! phone browser ──TLS──▶ server thread (its own tokio runtime: accept, TLS, HTTP, WebSocket)
//!                            │ bytes, connects, disconnects (bounded channel)
//!                            ▼
//!                        writer thread (the source thread: capture first, then the session)
//! ```
//!
//! What it keeps in the session directory: `phone.url` (the page's address with its token,
//! one line; a resumed session keeps its token), and, unless `[phone] cert_dir` names another
//! directory, the self-signed certificate `phone-cert.pem` and its key `phone-key.pem` (made
//! with rcgen on the first start, kept so that the phone's accepted exception holds).
//!
//! Security ([`server`], [`slots`]): the token is the right to write into the session. It
//! guards the page and the WebSocket (403 without it; an address that fails too often is
//! refused a while, 429 at once); one phone at a time; messages over [`MAX_MESSAGE`] bytes and
//! text messages close the connection; plain HTTP on the port is refused, and so is a `Host`
//! that does not name this server; connections without the token can never take the slots
//! the phone needs. Nothing the phone sends is more than bytes for the decoder. The token is
//! printed on standard error (with its QR code) and kept in `phone.url` (mode 0600); it is
//! not logged otherwise, and the live view shows it only to a client that may write
//! (on this machine, or with the view's own token).

mod cert;
pub mod qr;
mod server;
pub mod slots;
mod stats;

pub use cert::Certificate;
pub use stats::{PhoneReport, Refused};

use super::{spawn_thread, EndReason, Out, SourceError, SourceEvent};
use crate::shutdown::Shutdown;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Where `--phone` serves when given without an address: every interface (the phone is
/// another machine on the operator's network), port 8443.
pub const DEFAULT_ADDRESS: &str = "0.0.0.0:8443";
/// The largest WebSocket message taken, bytes; a bigger one closes the connection.
pub const MAX_MESSAGE: usize = 64 * 1024;
/// Connections waiting to be accepted on the phone port.
const BACKLOG: libc::c_int = 4096;
/// The page's address with its token, one line, in the session directory.
pub const URL_FILE: &str = "phone.url";

/// The phone source, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct PhoneSpec {
    pub addr: SocketAddr,
    /// Where the certificate is kept (`[phone] cert_dir`); `None`: the session directory.
    pub cert_dir: Option<PathBuf>,
    /// The session directory (set by the session before the source starts).
    pub session_dir: PathBuf,
    /// Names a request's `Host` may give besides `localhost` and address literals
    /// (`[phone] allowed_hosts`).
    pub allowed_hosts: Vec<String>,
}

/// A phone page's address: `IP:PORT`, or a port alone (every interface).
pub fn parse_address(s: &str) -> Result<SocketAddr, String> {
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::from(([0, 0, 0, 0], port)));
    }
    s.parse().map_err(|_| {
        format!("{s:?} is not an address: give IP:PORT (0.0.0.0:8443) or a port (8443)")
    })
}

impl PhoneSpec {
    /// At [`DEFAULT_ADDRESS`], the certificate in the session directory.
    pub fn at_default_address() -> PhoneSpec {
        PhoneSpec::new(parse_address(DEFAULT_ADDRESS).expect("the default address parses"))
    }

    pub fn new(addr: SocketAddr) -> PhoneSpec {
        PhoneSpec {
            addr,
            cert_dir: None,
            session_dir: PathBuf::new(),
            allowed_hosts: Vec::new(),
        }
    }
}

/// What the session tells the page while it streams (pushed to the phone every 250 ms).
#[derive(Debug, Clone, Default, serde::Serialize, PartialEq)]
pub struct Feedback {
    /// The curve being scanned: its index, kind and the nodes tagged so far.
    pub curve: Option<FeedbackCurve>,
    /// Curves accepted so far.
    pub curves: usize,
    /// The latest warning of the scan (acquisition's: a keypad sequence, a curve discarded).
    pub warning: Option<String>,
    /// Packets decoded, rejected and lost so far.
    pub packets: u64,
    pub rejected: u64,
    pub lost: u64,
}

/// The open curve as the page shows it.
#[derive(Debug, Clone, Default, serde::Serialize, PartialEq)]
pub struct FeedbackCurve {
    pub index: usize,
    pub kind: &'static str,
    pub nodes: Vec<u32>,
}

/// The running phone source's shared state: the feedback the session sets, the statistics
/// the server keeps.
#[derive(Debug, Default)]
pub struct Phone {
    feedback: Mutex<Feedback>,
    stats: Mutex<stats::Stats>,
    /// The page's address (with the token) and the certificate's fingerprint.
    url: String,
    fingerprint: String,
}

impl Phone {
    /// Replaces what the page is told.
    pub fn tell(&self, f: Feedback) {
        *lock(&self.feedback) = f;
    }

    fn feedback(&self) -> Feedback {
        lock(&self.feedback).clone()
    }

    /// The link figures so far (for `report.json` `phone`).
    pub fn report(&self) -> PhoneReport {
        lock(&self.stats).report()
    }

    /// The page's address, with its token.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// SHA-256 of the certificate (DER), as browsers show it: `AB:CD:…`.
    pub fn fingerprint(&self) -> &str {
        &self.fingerprint
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// What the server thread hands the writer thread.
enum Msg {
    Bytes(Vec<u8>),
    Event(SourceEvent),
}

/// Binds `spec.addr`, loads or makes the certificate and the token, writes `phone.url`,
/// prints the address (text and QR code) and the fingerprint on standard error, and starts
/// the server and writer threads.
pub(super) fn spawn(
    spec: PhoneSpec,
    out: Out,
    shutdown: Shutdown,
) -> Result<(std::thread::JoinHandle<()>, Arc<Phone>), SourceError> {
    let listener = std::net::TcpListener::bind(spec.addr)
        .and_then(|l| l.set_nonblocking(true).map(|()| l))
        .map_err(|source| SourceError::Bind {
            addr: spec.addr,
            source,
        })?;
    // A deeper queue of connections not yet accepted than the standard library's 128, so that
    // a flood of connections (which the server lets go: [`slots`]) does not make the phone's
    // wait for a retransmitted SYN. Listening again on a listening socket sets its backlog
    // (the kernel caps it at net.core.somaxconn).
    // SAFETY: listen on a descriptor the listener owns.
    unsafe {
        libc::listen(std::os::fd::AsRawFd::as_raw_fd(&listener), BACKLOG);
    }
    let bound = listener.local_addr().map_err(|source| SourceError::Bind {
        addr: spec.addr,
        source,
    })?;
    let cert_dir = spec.cert_dir.clone().unwrap_or(spec.session_dir.clone());
    let certificate = Certificate::load_or_make(&cert_dir).map_err(|e| SourceError::Phone {
        path: cert_dir.clone(),
        message: e,
    })?;
    let url_path = spec.session_dir.join(URL_FILE);
    let kept = token_of(&url_path).map_err(|source| SourceError::Open {
        path: url_path.clone(),
        source,
    })?;
    let token = kept
        .map_or_else(new_token, Ok)
        .map_err(|e| SourceError::Phone {
            path: spec.session_dir.clone(),
            message: format!("cannot make the page's token: {e}"),
        })?;
    let url = format!("https://{}/phone?token={token}", public_host(bound));
    // The token is the right to write into the session: its file is the owner's alone.
    crate::atomic::write_atomic_private(&url_path, format!("{url}\n").as_bytes()).map_err(
        |source| SourceError::Open {
            path: url_path.clone(),
            source,
        },
    )?;
    announce(&url, &certificate.fingerprint, bound);
    let phone = Arc::new(Phone {
        url,
        fingerprint: certificate.fingerprint.clone(),
        ..Phone::default()
    });
    let (tx, rx) = tokio::sync::mpsc::channel::<Msg>(super::CHANNEL_CHUNKS);
    // The writer stops the server when the session's side is gone (or the capture failed).
    let writer_gone = Shutdown::new();
    let config = certificate
        .server_config()
        .map_err(|e| SourceError::Phone {
            path: cert_dir,
            message: e,
        })?;
    let ctx = server::Context {
        token,
        phone: phone.clone(),
        tx,
        tls: tokio_rustls::TlsAcceptor::from(config),
        port: bound.port(),
        allowed_hosts: spec.allowed_hosts.clone(),
    };
    let stop = shutdown.clone();
    let gone = writer_gone.clone();
    spawn_thread("source-phone-server", move || {
        server::run(listener, ctx, stop, gone)
    })?;
    let writer = spawn_thread("source-phone", move || write(out, rx, writer_gone))?;
    Ok((writer, phone))
}

/// The writer thread: captures and forwards what the server received, in order.
fn write(mut out: Out, mut rx: tokio::sync::mpsc::Receiver<Msg>, gone: Shutdown) {
    let reason = loop {
        match rx.blocking_recv() {
            None => break EndReason::Shutdown,
            Some(Msg::Bytes(b)) => {
                if let Err(stop) = out.bytes(&b) {
                    break stop.reason();
                }
            }
            Some(Msg::Event(ev)) => {
                if out.send(ev).is_err() {
                    break EndReason::Shutdown;
                }
            }
        }
    };
    gone.trigger();
    out.end(reason);
}

/// The token in a session's `phone.url` (a resumed session keeps it): `None` when there is
/// no such file or it holds no token; an error when the path is not a regular file of at most
/// 4 KiB (a FIFO, a device), found before it is opened.
fn token_of(url_path: &Path) -> std::io::Result<Option<String>> {
    let text = match crate::named_file::read_text(url_path, 4096, "the phone page's address") {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    let token = text.trim().rsplit_once("token=").map(|(_, t)| t);
    Ok(token
        .filter(|t| t.len() == 32 && t.bytes().all(|b| b.is_ascii_hexdigit()))
        .map(str::to_owned))
}

/// 128 random bits, as 32 hexadecimal digits.
fn new_token() -> std::io::Result<String> {
    use ring::rand::SecureRandom;
    let mut b = [0u8; 16];
    ring::rand::SystemRandom::new()
        .fill(&mut b)
        .map_err(|_| std::io::Error::other("no system randomness"))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// The address a phone on the network reaches: the bound one, or, when bound to every
/// interface, the address of the interface that routes outward (127.0.0.1 without one).
fn public_host(bound: SocketAddr) -> SocketAddr {
    if !bound.ip().is_unspecified() {
        return bound;
    }
    // A UDP socket "connected" to a documentation address sends nothing; its local address
    // is the interface the system would route through.
    let ip = std::net::UdpSocket::bind("0.0.0.0:0")
        .and_then(|s| s.connect("192.0.2.1:9").map(|()| s))
        .and_then(|s| s.local_addr())
        .map(|a| a.ip())
        .ok()
        .filter(|ip| !ip.is_unspecified())
        .unwrap_or(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST));
    SocketAddr::new(ip, bound.port())
}

/// This machine's IPv4 addresses on interfaces that are up, loopback left out: where a phone
/// on the LAN may reach it.
pub fn lan_addresses() -> Vec<std::net::IpAddr> {
    let mut out = Vec::new();
    let mut list: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs fills `list` with a linked list we only read, then free once.
    if unsafe { libc::getifaddrs(&mut list) } != 0 {
        return out;
    }
    let mut at = list;
    while !at.is_null() {
        // SAFETY: `at` is a node of the list getifaddrs returned, not yet freed.
        let ifa = unsafe { &*at };
        at = ifa.ifa_next;
        let up = ifa.ifa_flags & (libc::IFF_UP as libc::c_uint) != 0;
        let lo = ifa.ifa_flags & (libc::IFF_LOOPBACK as libc::c_uint) != 0;
        if ifa.ifa_addr.is_null() || !up || lo {
            continue;
        }
        // SAFETY: a non-null ifa_addr points to a sockaddr whose family says its type.
        if unsafe { (*ifa.ifa_addr).sa_family } as libc::c_int == libc::AF_INET {
            let sin = unsafe { &*(ifa.ifa_addr as *const libc::sockaddr_in) };
            let ip = std::net::Ipv4Addr::from(u32::from_be(sin.sin_addr.s_addr));
            if !out.contains(&ip.into()) {
                out.push(ip.into());
            }
        }
    }
    // SAFETY: `list` came from getifaddrs and is freed once.
    unsafe { libc::freeifaddrs(list) };
    out
}

/// The warning for a phone page on a loopback address: no phone reaches it. Names this
/// machine's LAN addresses and how to serve on them.
pub fn loopback_warning(bound: SocketAddr, lan: &[std::net::IpAddr]) -> Option<String> {
    if !bound.ip().is_loopback() {
        return None;
    }
    let port = bound.port();
    let how = match lan {
        [] => format!("this machine has no LAN address up: connect it to the phone's network, then serve with `--phone {port}` (every interface)"),
        [one] => format!("serve with `--phone {port}` (every interface) or `--phone {one}:{port}`: this machine's LAN address is {one}"),
        more => format!(
            "serve with `--phone {port}` (every interface) or `--phone IP:{port}` with one of this machine's LAN addresses: {}",
            more.iter().map(|a| a.to_string()).collect::<Vec<_>>().join(", ")
        ),
    };
    Some(format!("the phone page is served on {bound}, a loopback address: no phone can reach it (the QR code works only in a browser on this machine); {how}"))
}

/// Tells the operator where to point the phone: the address as text and as a QR code, and the
/// certificate's fingerprint (standard error, so that a redirected standard output keeps only
/// the summary).
fn announce(url: &str, fingerprint: &str, bound: SocketAddr) {
    use std::io::Write;
    if let Some(w) = loopback_warning(bound, &lan_addresses()) {
        tracing::warn!("{w}");
    }
    // A JSON log takes nothing but JSON: the address and fingerprint as an event's fields.
    if crate::logging::json() {
        tracing::info!(%url, %bound, %fingerprint, "phone page served: open the url on the phone, accept the certificate of this fingerprint");
        return;
    }
    let mut text = String::new();
    text.push_str(&format!(
        "\nScan with your phone: open this address on the phone (or scan the QR code):\n\n  {url}\n\n"
    ));
    if let Some(code) = qr::terminal(url) {
        text.push_str(&code);
    }
    text.push_str(&format!(
        "\nThe browser warns about the certificate (self-signed, made for this daemon): accept it\nif its SHA-256 fingerprint is\n  {fingerprint}\nListening on {bound}.\n\n"
    ));
    let _ = std::io::stderr().write_all(text.as_bytes());
    tracing::info!(%bound, %fingerprint, "phone page served");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loopback_page_names_the_lan_addresses() {
        let lo: SocketAddr = "127.0.0.1:8443".parse().unwrap();
        let lan: Vec<std::net::IpAddr> =
            vec!["192.168.1.20".parse().unwrap(), "10.0.0.5".parse().unwrap()];
        let w = loopback_warning(lo, &lan).unwrap();
        assert!(
            w.contains("no phone can reach it") && w.contains("192.168.1.20, 10.0.0.5"),
            "{w}"
        );
        assert!(w.contains("--phone 8443"), "{w}");
        let w = loopback_warning(lo, &lan[..1]).unwrap();
        assert!(w.contains("--phone 192.168.1.20:8443"), "{w}");
        assert!(loopback_warning(lo, &[])
            .unwrap()
            .contains("no LAN address"));
        assert_eq!(
            loopback_warning("0.0.0.0:8443".parse().unwrap(), &lan),
            None
        );
        assert_eq!(
            loopback_warning("192.168.1.20:8443".parse().unwrap(), &lan),
            None
        );
        // This machine's addresses are never loopback ones.
        assert!(lan_addresses().iter().all(|a| !a.is_loopback()));
    }
}
