//! The view server's connections: how many (a cap well under the file limit, so that no
//! client, however many, can make a session's output write fail for want of a descriptor),
//! and how long one may hold its descriptor without doing its part.
//!
//! Each accepted connection is wrapped in a [`Guarded`] stream that fails (and so closes the
//! connection) when:
//! - bytes of a request have been read but nothing answered for [`HEAD_TIMEOUT`] (a request
//!   head sent a byte a second never completes);
//! - nothing has been read or written for [`IDLE_TIMEOUT`] (an idle keep-alive connection; an
//!   event stream writes at least every second, so it is never idle);
//! - the client has not drained what was written for [`DRAIN_TIMEOUT`] (a client that stopped
//!   reading, whatever its receive buffer: see [`Drain`]; an event stream would otherwise fill
//!   the kernel's buffers for minutes before a write blocked), or a write has been blocked for
//!   [`STALL_TIMEOUT`].

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::{Instant, Sleep};

/// A request whose head has not been answered within this is closed.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// A connection with no byte either way for this long is closed.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(30);
/// A connection whose writes have been blocked this long is closed.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// A connection whose peer has not drained what it was sent for this long is closed (with the
/// once-a-second check and a buffer's first seconds, a client that does not read is gone within
/// 15 s whatever its receive buffer).
pub const DRAIN_TIMEOUT: Duration = Duration::from_secs(6);
/// Descriptors kept for the session (capture, outputs, the serial port, the runtime).
pub const RESERVED_FDS: u64 = 256;
/// The most connections served at once, whatever the file limit.
pub const MAX_CONNECTIONS: usize = 1024;

/// Raises the soft limit on open files to the hard one (once, at start) and returns the
/// soft limit in force.
pub fn raise_file_limit() -> u64 {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit and setrlimit only read and write the struct given.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return 1024;
        }
        if lim.rlim_cur < lim.rlim_max {
            let raised = libc::rlimit {
                rlim_cur: lim.rlim_max,
                rlim_max: lim.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) == 0 {
                lim.rlim_cur = lim.rlim_max;
            }
        }
    }
    lim.rlim_cur
}

/// The connection cap for a soft file limit: half of what the reserve leaves, at most
/// [`MAX_CONNECTIONS`], at least 8.
pub fn connection_cap(file_limit: u64) -> usize {
    ((file_limit.saturating_sub(RESERVED_FDS) / 2) as usize).clamp(8, MAX_CONNECTIONS)
}

/// A listener that serves at most `cap` connections at once (one more is closed as soon as
/// it is accepted) and wraps each in a [`Guarded`] stream.
pub struct GuardedListener {
    inner: TcpListener,
    live: Arc<AtomicUsize>,
    cap: usize,
}

impl GuardedListener {
    pub fn new(inner: TcpListener, live: Arc<AtomicUsize>, cap: usize) -> Self {
        GuardedListener { inner, live, cap }
    }
}

impl axum::serve::Listener for GuardedListener {
    type Io = Guarded;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Guarded, std::net::SocketAddr) {
        loop {
            match self.inner.accept().await {
                Ok((io, addr)) => {
                    if self.live.load(Ordering::Acquire) >= self.cap {
                        tracing::debug!(%addr, cap = self.cap, "view: connection refused (at the cap)");
                        drop(io);
                        continue;
                    }
                    self.live.fetch_add(1, Ordering::AcqRel);
                    return (Guarded::new(io, self.live.clone()), addr);
                }
                // Out of descriptors or another transient error: wait, never spin.
                Err(e) => {
                    tracing::debug!("view: accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> io::Result<std::net::SocketAddr> {
        self.inner.local_addr()
    }
}

/// Whether the peer drains what is written, from what the kernel knows of the connection
/// (Linux's `TCP_INFO` and `SIOCOUTQ`): the *right edge* of the peer's receive window, the
/// bytes it has acknowledged plus the window it still offers (`tcpi_bytes_acked +
/// tcpi_snd_wnd`), moves on only when its application reads. A client that reads moves it by
/// about what it was sent; one that does not read keeps it where it was, whatever its receive
/// buffer: a small buffer fills, its window goes to zero and nothing more is acknowledged while
/// bytes wait here; a large one acknowledges everything and offers ever less window.
///
/// Checked at most once a second, after a write. A check is evidence of draining when bytes
/// were acknowledged and the edge moved by at least half of them; of a stall when bytes were
/// acknowledged and the edge did not follow, or when bytes wait unacknowledged and none were;
/// when nothing was sent, the peer owes nothing; a window larger than ever before is no
/// evidence either way (a receiver offers more of its buffer as data comes, reading or not:
/// with a large buffer, for its first seconds, TCP does not tell a sleeper from a reader). A peer with no evidence of draining for
/// [`DRAIN_TIMEOUT`] and a stall at its latest check has stopped reading. (Window sizes alone
/// do not tell: a reading client's window wobbles by a scaling step, and a non-reading one's
/// can grow for its first seconds.)
#[derive(Debug)]
struct Drain {
    checked: Instant,
    acked: u64,
    largest: u32,
    edge: u64,
    drained: Instant,
}

impl Drain {
    fn new(now: Instant) -> Self {
        Drain {
            checked: now,
            acked: 0,
            largest: 0,
            edge: 0,
            drained: now,
        }
    }

    /// Looks at the connection (at most once a second); whether the peer has not drained for
    /// [`DRAIN_TIMEOUT`].
    fn stalled(&mut self, io: &TcpStream, now: Instant) -> bool {
        if now.duration_since(self.checked) < Duration::from_secs(1) {
            return false;
        }
        self.checked = now;
        let Some(p) = peer_state(io) else {
            return false;
        };
        self.judge(p, now)
    }

    /// [`Drain::stalled`] on a state read.
    fn judge(&mut self, p: PeerState, now: Instant) -> bool {
        let edge = p.acked + u64::from(p.window);
        let acked = p.acked.saturating_sub(self.acked);
        let moved = edge.saturating_sub(self.edge);
        let stall = if acked > 0 {
            2 * moved < acked
        } else {
            p.waiting > 0
        };
        // A window larger than ever before says nothing of reading: a receiver offers more of
        // its buffer as data comes, whether its application reads or not. (A window reopening
        // to a size it had is a read.)
        let growing = acked > 0 && p.window > self.largest;
        self.acked = p.acked;
        self.largest = self.largest.max(p.window);
        self.edge = self.edge.max(edge);
        if !stall && !growing {
            self.drained = now;
            return false;
        }
        // (Not "no evidence for long enough" alone: a reader whose window keeps growing, its
        // buffer tuned up by bursts of large events, gave none for over 12 s in a 600 s soak.)
        stall && now.duration_since(self.drained) > DRAIN_TIMEOUT
    }
}

/// What the kernel says of a connection's sending side.
#[derive(Debug, Clone, Copy)]
struct PeerState {
    /// Bytes the peer has acknowledged, in all (`tcpi_bytes_acked`).
    acked: u64,
    /// The receive window it offers now, bytes (`tcpi_snd_wnd`).
    window: u32,
    /// Bytes written here and not yet acknowledged, sent or not (`SIOCOUTQ`).
    waiting: u32,
}

/// The connection's [`PeerState`] (`None` where the kernel does not say: before 6.2 it gives
/// no `tcpi_snd_wnd`).
fn peer_state(io: &TcpStream) -> Option<PeerState> {
    use std::os::fd::AsRawFd;
    let fd = io.as_raw_fd();
    // SAFETY: tcp_info is plain data; getsockopt writes at most `len` bytes into it.
    let mut info: libc::tcp_info = unsafe { std::mem::zeroed() };
    let mut len = std::mem::size_of::<libc::tcp_info>() as libc::socklen_t;
    let rc = unsafe {
        libc::getsockopt(
            fd,
            libc::IPPROTO_TCP,
            libc::TCP_INFO,
            (&mut info as *mut libc::tcp_info).cast(),
            &mut len,
        )
    };
    let end = std::mem::offset_of!(libc::tcp_info, tcpi_snd_wnd) + 4;
    if rc != 0 || (len as usize) < end {
        return None;
    }
    let mut waiting: libc::c_int = 0;
    // SAFETY: SIOCOUTQ (TIOCOUTQ) writes one int.
    if unsafe { libc::ioctl(fd, libc::TIOCOUTQ, &mut waiting) } != 0 {
        return None;
    }
    Some(PeerState {
        acked: info.tcpi_bytes_acked,
        window: info.tcpi_snd_wnd,
        waiting: waiting.max(0) as u32,
    })
}

/// A TCP stream that fails its reads and writes once it breaks one of the rules of the
/// module documentation (the server then closes it), and counts itself out when dropped.
pub struct Guarded {
    io: TcpStream,
    live: Arc<AtomicUsize>,
    drain: Drain,
    health: Arc<Health>,
    last_activity: Instant,
    /// When a request's first byte was read with nothing written since.
    head_since: Option<Instant>,
    /// When a write started to block.
    blocked_since: Option<Instant>,
    timer: Pin<Box<Sleep>>,
}

impl Guarded {
    fn new(io: TcpStream, live: Arc<AtomicUsize>) -> Self {
        let now = Instant::now();
        Guarded {
            io,
            live,
            drain: Drain::new(now),
            health: Arc::new(Health::new(now)),
            last_activity: now,
            head_since: None,
            blocked_since: None,
            timer: Box::pin(tokio::time::sleep_until(now + IDLE_TIMEOUT)),
        }
    }

    /// The earliest deadline in force.
    fn deadline(&self) -> Instant {
        let mut d = self.last_activity + IDLE_TIMEOUT;
        if let Some(h) = self.head_since {
            d = d.min(h + HEAD_TIMEOUT);
        }
        if let Some(b) = self.blocked_since {
            d = d.min(b + STALL_TIMEOUT);
        }
        d
    }

    /// After a write of `n` bytes: an error when the peer has stopped draining.
    fn wrote(&mut self, n: usize) -> io::Result<usize> {
        let now = Instant::now();
        if n > 0 {
            self.last_activity = now;
            self.head_since = None;
        }
        self.blocked_since = None;
        let stalled = self.drain.stalled(&self.io, now);
        self.health.drained(self.drain.drained);
        if stalled {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "view connection closed: the client stopped reading",
            ));
        }
        Ok(n)
    }

    /// After the inner stream said Pending: an error once the deadline has passed, else
    /// Pending with the timer armed to wake this task then.
    fn pending_or_expired<T>(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        let d = self.deadline();
        if self.timer.deadline() != d {
            self.timer.as_mut().reset(d);
        }
        match self.timer.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "view connection closed: idle, slow or stalled",
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

/// What a handler may know of its connection's draining ([`Drain`]): when its peer last
/// showed that it reads. Shared by the connection and its requests.
#[derive(Debug)]
pub struct Health {
    epoch: Instant,
    /// [`Drain`]'s last evidence of draining, ms after `epoch`.
    drained_ms: std::sync::atomic::AtomicU64,
}

impl Health {
    fn new(now: Instant) -> Health {
        Health {
            epoch: now,
            drained_ms: std::sync::atomic::AtomicU64::new(0),
        }
    }

    fn drained(&self, at: Instant) {
        let ms = at.saturating_duration_since(self.epoch).as_millis() as u64;
        self.drained_ms.store(ms, Ordering::Relaxed);
    }

    /// How long the peer has shown no sign of reading what it was sent (since the connection
    /// was made, when never).
    pub fn undrained_for(&self) -> Duration {
        let at = self.epoch + Duration::from_millis(self.drained_ms.load(Ordering::Relaxed));
        Instant::now().saturating_duration_since(at)
    }
}

/// Both ends of a view connection (axum's connect info): whether the client is this machine,
/// and how its peer drains.
#[derive(Debug, Clone)]
pub struct Ends {
    pub peer: std::net::SocketAddr,
    /// This server's end (`None` where the socket does not say).
    pub local: Option<std::net::SocketAddr>,
    pub health: Arc<Health>,
}

impl Ends {
    /// Whether the client runs on this machine: a connection from this host to one of its own
    /// addresses leaves from that same address (127.0.0.1 to 127.0.0.1, the LAN address to
    /// itself). Another host, or another loopback address standing in for one, does not.
    pub fn same_machine(&self) -> bool {
        self.local.is_some_and(|l| l.ip() == self.peer.ip())
    }
}

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, GuardedListener>>
    for Ends
{
    fn connect_info(stream: axum::serve::IncomingStream<'_, GuardedListener>) -> Ends {
        Ends {
            peer: *stream.remote_addr(),
            local: stream.io().io.local_addr().ok(),
            health: stream.io().health.clone(),
        }
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        self.live.fetch_sub(1, Ordering::AcqRel);
    }
}

impl AsyncRead for Guarded {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.io).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if buf.filled().len() > before {
                    let now = Instant::now();
                    self.last_activity = now;
                    self.head_since.get_or_insert(now);
                }
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.pending_or_expired(cx),
        }
    }
}

impl AsyncWrite for Guarded {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.io).poll_write(cx, data) {
            Poll::Ready(Ok(n)) => Poll::Ready(self.wrote(n)),
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => {
                self.blocked_since.get_or_insert_with(Instant::now);
                self.pending_or_expired(cx)
            }
        }
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.io).poll_write_vectored(cx, bufs) {
            Poll::Ready(Ok(n)) => Poll::Ready(self.wrote(n)),
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => {
                self.blocked_since.get_or_insert_with(Instant::now);
                self.pending_or_expired(cx)
            }
        }
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel's figures each second for a client that reads, one that does not with a
    /// large buffer, and one with a small buffer (as measured on loopback, Linux 6.18: the
    /// large buffer's window first grew, then fell by what it was sent).
    #[test]
    fn a_reader_drains_and_a_sleeper_does_not_whatever_its_buffer() {
        let t0 = Instant::now();
        let run = |states: &[(u64, u32, u32)]| {
            let mut d = Drain::new(t0);
            states
                .iter()
                .enumerate()
                .map(|(i, &(acked, window, waiting))| {
                    let now = t0 + Duration::from_secs(i as u64 + 1);
                    d.judge(
                        PeerState {
                            acked,
                            window,
                            waiting,
                        },
                        now,
                    )
                })
                .position(|s| s)
        };
        // Reads: the window wobbles by a scaling step below its largest, bursts and lulls.
        let mut sent = 0;
        let reader: Vec<_> = (0..120u64)
            .map(|i| {
                sent += if (i / 10) % 2 == 0 { 30_000 } else { 800 };
                (sent, if i % 3 == 0 { 101_376 } else { 100_352 }, 0)
            })
            .collect();
        assert_eq!(run(&reader), None);
        // Does not read, 4 MB: the window grows for two seconds, then falls by what it gets.
        let big: Vec<_> = (0..30u64)
            .map(|i| {
                let acked = 800 * (i + 1);
                let w = if i < 2 {
                    4_300_000 + 1_000_000 * i
                } else {
                    5_300_000 - acked + 32 * i
                };
                (acked, w as u32, 0)
            })
            .collect();
        let at = run(&big).expect("a sleeper with a large buffer is found");
        assert!(at <= 11, "{at}");
        // Does not read, 2 KiB: a zero window, the bytes wait here.
        let small: Vec<_> = (0..30u64)
            .map(|i| (2048, 0, 2000 + 800 * i as u32))
            .collect();
        let at = run(&small).expect("a sleeper with a small buffer is found");
        assert!(at <= 9, "{at}");
        // Nothing sent: nothing owed.
        let idle: Vec<_> = (0..60).map(|_| (5000, 65_536, 0)).collect();
        assert_eq!(run(&idle), None);
    }

    #[test]
    fn the_cap_keeps_a_reserve_of_descriptors() {
        assert_eq!(connection_cap(1024), 384);
        assert_eq!(connection_cap(300), 22);
        assert_eq!(connection_cap(100), 8);
        assert_eq!(connection_cap(1 << 20), MAX_CONNECTIONS);
    }
}
