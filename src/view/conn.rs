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
//!   [`STALL_TIMEOUT`] with no read seen meanwhile.

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
/// A connection whose peer has held its stream up this long without reading is closed (with
/// the once-a-second check and a large buffer's first seconds, a client that does not read is
/// gone within 15 s whatever its receive buffer: see [`Drain`]).
pub const DRAIN_TIMEOUT: Duration = Duration::from_secs(6);
/// A peer that has never read, found neither reading nor owing this long, is asked to show
/// whether it reads: its stream is sent padding that fills the window it offers, twice over (see
/// [`Drain`]).
pub const PROBE_AFTER: Duration = Duration::from_secs(1);
/// The most padding asked for at once, bytes.
pub const PROBE_MAX: u32 = 8 << 20;
/// The most padding a connection is sent in all, bytes: enough to fill a 4 MiB receive buffer
/// (which Linux doubles), and a bound on what a reader whose window keeps growing costs (a
/// continuous reader on loopback, its buffer tuned up to 32 MiB by the padding itself, was sent
/// 37 MB before its window stopped growing).
pub const PROBE_BUDGET: u64 = 16 << 20;
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
/// (Linux's `TCP_INFO` and `SIOCOUTQ`), checked at most once a second, after a write.
///
/// The *right edge* of the peer's receive window, the bytes it has acknowledged plus the
/// window it still offers (`tcpi_bytes_acked + tcpi_snd_wnd`), moves on only when its
/// application reads, or when the receiver offers more of its buffer than before. Each check
/// is one of:
/// - **read**: the edge passed its furthest by at least half of what was acknowledged since
///   the last check, with a window no larger than ever before (a receiver offers more of its
///   buffer as data comes, reading or not: a window larger than ever is no evidence), or
///   reopening a window that was shut;
/// - **owing**: bytes wait here that the window cannot take (`SIOCOUTQ` over the window), and
///   the window is not growing: the peer holds the stream up;
/// - **neither**: nothing waits, or the window grows. A reader can stay here for minutes
///   without a read in sight: a receiver keeps its edge where it was while it offers less of
///   its buffer, as when a burst of large segments gives way to a lull of small ones (Linux
///   weighs free space by the segments' overhead), which an older rule read as a stall and cut
///   a reader after 148 s of a 600 s soak.
///
/// A peer owing for [`DRAIN_TIMEOUT`] with no read in between has stopped reading.
///
/// A sleeper with a large buffer would stay *neither* until the stream's own events filled its
/// buffer (a 4 MiB receive buffer took 24–30 s of the demo capture's events). So a peer that
/// has never read, *neither* for [`PROBE_AFTER`], is asked for a *probe*: padding twice as
/// large as the window it offers (a receiver that does not read offers about half its free
/// space at first: 4.26 MB of a 4 MiB buffer that took 7.16 MB), which the event stream sends
/// as a comment (ignored by every client).
/// A sleeper's buffer fills, its window closes and it owes; a reader reads it. That costs a
/// reader about its window of padding while its window grows, before it has been seen to
/// read, at most [`PROBE_BUDGET`]; once it has, it is never probed again.
#[derive(Debug)]
struct Drain {
    checked: Instant,
    acked: u64,
    largest: u32,
    edge: u64,
    /// Whether the window was shut (zero, bytes waiting) at the last check.
    shut: bool,
    /// Checks that found the peer reading (see [`Drain::proven`]).
    reads: u32,
    /// The last check that found it in good standing: a read, or (once it has read) a check
    /// that found it owing nothing.
    drained: Instant,
    /// Since when it has owed, with no read since.
    owing_since: Option<Instant>,
    /// Since when a peer that never read has neither read nor owed.
    neither_since: Option<Instant>,
    /// The padding the latest check asked for, bytes (0: none).
    probe: u32,
    /// The padding asked for in all, bytes.
    probed: u64,
}

impl Drain {
    fn new(now: Instant) -> Self {
        Drain {
            checked: now,
            acked: 0,
            largest: 0,
            edge: 0,
            shut: false,
            reads: 0,
            drained: now,
            owing_since: None,
            neither_since: None,
            probe: 0,
            probed: 0,
        }
    }

    /// Looks at the connection (at most once a second); whether the peer has owed for
    /// [`DRAIN_TIMEOUT`] without reading.
    fn stalled(&mut self, io: &TcpStream, now: Instant) -> bool {
        if now.duration_since(self.checked) < Duration::from_secs(1) {
            return false;
        }
        self.checked = now;
        let Some(p) = peer_state(io) else {
            return false;
        };
        let stalled = self.judge(p, now);
        tracing::trace!(peer = ?io.peer_addr().ok(), ?p, owing = ?self.owing_since.map(|o| now.duration_since(o)), proven = self.proven(), probe = self.probe, stalled, "view: drain check");
        stalled
    }

    /// Whether the peer has been seen to read, twice: once can be a receiver whose window
    /// stopped growing, its edge jumping to where its free space ends.
    fn proven(&self) -> bool {
        self.reads >= 2
    }

    /// [`Drain::stalled`] on a state read.
    fn judge(&mut self, p: PeerState, now: Instant) -> bool {
        let edge = p.acked + u64::from(p.window);
        let acked = p.acked.saturating_sub(self.acked);
        let moved = edge.saturating_sub(self.edge);
        let growing = acked > 0 && p.window > self.largest;
        // A window that was shut with bytes waiting reopens only when the application reads
        // (a receiver shuts it when its buffer is about full), larger than ever or not.
        let read = (!growing || self.shut) && moved > 0 && 2 * moved >= acked;
        let owing = !growing && p.waiting > p.window;
        self.shut = p.window == 0 && p.waiting > 0;
        self.acked = p.acked;
        self.largest = self.largest.max(p.window);
        self.edge = self.edge.max(edge);
        self.probe = 0;
        if read {
            self.reads += 1;
            self.drained = now;
            self.owing_since = None;
        } else if owing {
            self.neither_since = None;
            let since = *self.owing_since.get_or_insert(now);
            return now.duration_since(since) > DRAIN_TIMEOUT;
        }
        if self.proven() {
            self.drained = now;
            self.neither_since = None;
        } else {
            let since = *self.neither_since.get_or_insert(now);
            if now.duration_since(since) >= PROBE_AFTER {
                let left = PROBE_BUDGET.saturating_sub(self.probed);
                self.probe = p
                    .window
                    .saturating_mul(2)
                    .saturating_sub(p.waiting)
                    .min(PROBE_MAX)
                    .min(left as u32);
                self.probed += u64::from(self.probe);
            }
        }
        false
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
        self.check(now).map(|()| n)
    }

    /// While a write is blocked: the drain check goes on (a peer whose window is shut blocks
    /// the writes that would otherwise run it), an error when the peer has stopped draining.
    fn blocked(&mut self) -> io::Result<()> {
        let now = Instant::now();
        self.blocked_since.get_or_insert(now);
        self.check(now)
    }

    /// The drain check (at most once a second): an error when the peer has stopped draining.
    /// A read seen restarts the blocked write's clock: a client that reads, if more slowly
    /// than the stream comes, is not cut for it (it falls behind, and its stream ends once it
    /// is [`super::EVENT_QUEUE`] events behind).
    fn check(&mut self, now: Instant) -> io::Result<()> {
        let reads = self.drain.reads;
        let stalled = self.drain.stalled(&self.io, now);
        if self.drain.reads > reads && self.blocked_since.is_some() {
            self.blocked_since = Some(now);
        }
        self.health.checked(&mut self.drain);
        if stalled {
            tracing::debug!(peer = ?self.io.peer_addr().ok(), drain = ?self.drain, "view: a connection closed: its client stopped reading");
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "view connection closed: the client stopped reading",
            ));
        }
        Ok(())
    }

    /// After the inner stream said Pending: an error once the deadline has passed, else
    /// Pending with the timer armed to wake this task then (or, while a write is blocked, at
    /// the next drain check: the task is woken to poll its write again, which runs it).
    fn pending_or_expired<T>(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        let d = self.deadline();
        let wake = match self.blocked_since {
            Some(_) => d.min(self.drain.checked + Duration::from_secs(1)),
            None => d,
        };
        if self.timer.deadline() != wake {
            self.timer.as_mut().reset(wake);
        }
        match self.timer.as_mut().poll(cx) {
            Poll::Ready(()) if Instant::now() < d => {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
            Poll::Ready(()) => {
                tracing::debug!(
                    idle = ?self.last_activity.elapsed(),
                    head = ?self.head_since.map(|h| h.elapsed()),
                    blocked = ?self.blocked_since.map(|b| b.elapsed()),
                    "view: a connection closed: idle, slow or stalled"
                );
                Poll::Ready(Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "view connection closed: idle, slow or stalled",
                )))
            }
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
    /// The padding [`Drain`] asks the connection's event stream to send, bytes (0: none).
    probe: std::sync::atomic::AtomicU32,
}

impl Health {
    fn new(now: Instant) -> Health {
        Health {
            epoch: now,
            drained_ms: std::sync::atomic::AtomicU64::new(0),
            probe: std::sync::atomic::AtomicU32::new(0),
        }
    }

    /// After a check: its last evidence of draining, and the padding it asked for (taken).
    fn checked(&self, drain: &mut Drain) {
        let ms = drain
            .drained
            .saturating_duration_since(self.epoch)
            .as_millis() as u64;
        self.drained_ms.store(ms, Ordering::Relaxed);
        let probe = std::mem::take(&mut drain.probe);
        if probe > 0 {
            self.probe.store(probe, Ordering::Relaxed);
        }
    }

    /// The padding asked for since the last call, bytes (0: none): an event stream sends it
    /// as a comment, so that its client shows whether it reads (see [`Drain`]).
    pub fn take_probe(&self) -> u32 {
        self.probe.swap(0, Ordering::Relaxed)
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
            Poll::Pending => match self.blocked() {
                Ok(()) => self.pending_or_expired(cx),
                Err(e) => Poll::Ready(Err(e)),
            },
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
            Poll::Pending => match self.blocked() {
                Ok(()) => self.pending_or_expired(cx),
                Err(e) => Poll::Ready(Err(e)),
            },
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

    /// A receiver as the kernel shows it to the sender, one check a second: its buffer of
    /// `buffer` bytes takes what is sent while it has room; `reads(t)` says whether its
    /// application empties the buffer at second `t` (after taking what came); it offers its
    /// free space up to `offer(t, received)` (the window's growth as data comes, or its fall
    /// in a lull). The stream
    /// sends `events(t)` bytes a second plus the probes the checks ask for. The second at which
    /// the connection is found stalled, if within `seconds`.
    fn stalled_at(
        buffer: u64,
        reads: impl Fn(u64) -> bool,
        offer: impl Fn(u64, u64) -> u64,
        events: impl Fn(u64) -> u64,
        seconds: u64,
    ) -> Option<u64> {
        let t0 = Instant::now();
        let mut d = Drain::new(t0);
        let (mut sent, mut acked, mut unread, mut probe) = (0u64, 0u64, 0u64, 0u64);
        for t in 1..=seconds {
            sent += events(t) + probe;
            let take = (sent - acked).min(buffer - unread);
            acked += take;
            unread += take;
            if reads(t) {
                unread = 0;
                // What waited comes in, and is read too.
                let take = (sent - acked).min(buffer);
                acked += take;
            }
            let window = (buffer - unread).min(offer(t, acked));
            let stalled = d.judge(
                PeerState {
                    acked,
                    window: window as u32,
                    waiting: (sent - acked) as u32,
                },
                t0 + Duration::from_secs(t),
            );
            if stalled {
                return Some(t);
            }
            probe = u64::from(std::mem::take(&mut d.probe));
        }
        None
    }

    /// Readers, continuous or every few seconds, through bursts and lulls, a window growing
    /// for their first seconds or falling in a lull, are never found stalled; clients that do
    /// not read are, within 14 s whatever their buffer (the probe fills a large one).
    #[test]
    fn a_reader_drains_and_a_sleeper_does_not_whatever_its_buffer() {
        let bursts = |t: u64| {
            if (t / 20).is_multiple_of(2) {
                300_000
            } else {
                1_500
            }
        };
        // Linux raises the window by two segments for each segment that comes in.
        let growing = |cap: u64| move |_, received: u64| (65_536 + 2 * received).min(cap);
        // Continuous readers, a window growing to 8 MB, or falling in a lull.
        assert_eq!(
            stalled_at(8 << 20, |_| true, growing(8 << 20), bursts, 300),
            None
        );
        let falls = |t: u64, _| {
            if (t / 20).is_multiple_of(2) {
                4 << 20
            } else {
                1 << 20
            }
        };
        assert_eq!(stalled_at(8 << 20, |_| true, falls, bursts, 300), None);
        // Readers every 2 and 4 s, small and large buffers.
        for every in [2, 4] {
            for buffer in [4096, 64 << 10, 8 << 20] {
                let at = stalled_at(
                    buffer,
                    |t| t.is_multiple_of(every),
                    growing(buffer),
                    bursts,
                    300,
                );
                assert_eq!(at, None, "a reader every {every} s, buffer {buffer}");
            }
        }
        // Sleepers: a small buffer's window closes, a large one is filled by the probe.
        for buffer in [1024, 4096, 64 << 10, 1 << 20, 8 << 20] {
            for events in [bursts, |_| 1_500] {
                let at = stalled_at(buffer, |_| false, growing(buffer), events, 60);
                let at = at.unwrap_or_else(|| panic!("a sleeper with {buffer} B is found"));
                assert!(at <= 14, "a sleeper with {buffer} B: found after {at} s");
            }
        }
        // Nothing sent (a connection that is not an event stream takes no probe): nothing
        // owed.
        let t0 = Instant::now();
        let mut d = Drain::new(t0);
        let idle = PeerState {
            acked: 5_000,
            window: 65_536,
            waiting: 0,
        };
        assert!((1..60).all(|t| !d.judge(idle, t0 + Duration::from_secs(t))));
    }

    /// A window that grows with no read seen asks for padding twice as large (less what waits),
    /// after [`PROBE_AFTER`]; once the peer has read twice, no more.
    #[test]
    fn a_peer_that_never_read_is_probed() {
        let t0 = Instant::now();
        let mut d = Drain::new(t0);
        let mut asked = vec![];
        for i in 0..8u64 {
            let acked = 10_000 * (i + 1);
            let window = if i < 5 {
                100_000 * (i as u32 + 1)
            } else {
                500_000
            };
            let now = t0 + Duration::from_secs(i + 1);
            let stalled = d.judge(
                PeerState {
                    acked,
                    window,
                    waiting: 1_000,
                },
                now,
            );
            assert!(!stalled, "{i}");
            asked.push(std::mem::take(&mut d.probe));
        }
        assert_eq!(
            asked,
            [0, 399_000, 599_000, 799_000, 999_000, 999_000, 0, 0]
        );
        // Never more than PROBE_MAX at once, nor PROBE_BUDGET in all: a window of 16 MiB that
        // keeps growing.
        let mut d = Drain::new(t0);
        let asked: Vec<u32> = (0..10u32)
            .map(|i| {
                let p = PeerState {
                    acked: 1 + u64::from(i),
                    window: (1 << 24) + i,
                    waiting: 0,
                };
                d.judge(p, t0 + Duration::from_secs(u64::from(i) + 1));
                d.probe
            })
            .collect();
        assert_eq!(asked[..4], [0, PROBE_MAX, PROBE_MAX, 0]);
        assert_eq!((d.probed, d.probe), (PROBE_BUDGET, 0));
    }

    /// Measured (loopback, a reader every 4 s with a 64 KiB buffer, cut at 12 s by a rule that
    /// took every window larger than ever for growth): a shut window that reopens larger than
    /// ever is a read.
    #[test]
    fn a_shut_window_that_reopens_larger_than_ever_is_a_read() {
        let t0 = Instant::now();
        let mut d = Drain::new(t0);
        let states = [
            (3_474, 62_026, 0),
            (6_288, 59_212, 0),
            (69_620, 58_152, 1_434),
            (141_219, 67_150, 2_303),
            (208_673, 0, 20_940),
            (208_673, 0, 52_118),
            (208_673, 0, 85_898),
            (330_927, 111_226, 4_041),
            (373_986, 69_008, 4_747),
            (443_196, 0, 60_549),
            (443_196, 0, 120_729),
            (443_196, 0, 150_000),
            (560_000, 120_000, 3_000),
        ];
        for (i, &(acked, window, waiting)) in states.iter().enumerate() {
            let now = t0 + Duration::from_secs(i as u64 + 1);
            let p = PeerState {
                acked,
                window,
                waiting,
            };
            assert!(!d.judge(p, now), "found stalled at {}", i + 1);
        }
        assert!(d.proven());
    }

    #[test]
    fn the_cap_keeps_a_reserve_of_descriptors() {
        assert_eq!(connection_cap(1024), 384);
        assert_eq!(connection_cap(300), 22);
        assert_eq!(connection_cap(100), 8);
        assert_eq!(connection_cap(1 << 20), MAX_CONNECTIONS);
    }
}
