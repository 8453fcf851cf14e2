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
//! - the client has not drained what was written for [`STALL_TIMEOUT`]: its receive window
//!   has not grown (a client that stopped reading; an event stream would otherwise fill the
//!   kernel's buffers for a minute before a write blocked), or a write has been blocked.

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

/// Whether the peer drains what is written: the receive window it advertises (Linux's
/// `TCP_INFO`, `tcpi_snd_wnd`, kernels from 6.2) shrinks while data waits in its buffer and
/// grows again when its application reads. A window below the largest seen that has not grown
/// for [`STALL_TIMEOUT`] is a client that stopped reading, found long before the kernel's
/// buffers (megabytes on the loopback) are full and writes block.
#[derive(Debug)]
struct Drain {
    checked: Instant,
    largest: u32,
    last: u32,
    grew: Instant,
}

impl Drain {
    fn new(now: Instant) -> Self {
        Drain {
            checked: now,
            largest: 0,
            last: 0,
            grew: now,
        }
    }

    /// Looks at the window (at most once a second); whether the peer has not drained for
    /// [`STALL_TIMEOUT`].
    fn stalled(&mut self, io: &TcpStream, now: Instant) -> bool {
        if now.duration_since(self.checked) < Duration::from_secs(1) {
            return false;
        }
        self.checked = now;
        let Some(w) = peer_window(io) else {
            return false;
        };
        if w > self.last || w >= self.largest {
            self.grew = now;
        }
        self.largest = self.largest.max(w);
        self.last = w;
        now.duration_since(self.grew) > STALL_TIMEOUT
    }
}

/// The receive window the peer advertises, bytes (`None` where the kernel does not say).
fn peer_window(io: &TcpStream) -> Option<u32> {
    use std::os::fd::AsRawFd;
    // SAFETY: tcp_info is plain data; getsockopt writes at most `len` bytes into it.
    let mut info: libc::tcp_info = unsafe { std::mem::zeroed() };
    let mut len = std::mem::size_of::<libc::tcp_info>() as libc::socklen_t;
    let rc = unsafe {
        libc::getsockopt(
            io.as_raw_fd(),
            libc::IPPROTO_TCP,
            libc::TCP_INFO,
            (&mut info as *mut libc::tcp_info).cast(),
            &mut len,
        )
    };
    let end = std::mem::offset_of!(libc::tcp_info, tcpi_snd_wnd) + 4;
    (rc == 0 && len as usize >= end).then_some(info.tcpi_snd_wnd)
}

/// A TCP stream that fails its reads and writes once it breaks one of the rules of the
/// module documentation (the server then closes it), and counts itself out when dropped.
pub struct Guarded {
    io: TcpStream,
    live: Arc<AtomicUsize>,
    drain: Drain,
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
        if self.drain.stalled(&self.io, now) {
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

    #[test]
    fn the_cap_keeps_a_reserve_of_descriptors() {
        assert_eq!(connection_cap(1024), 384);
        assert_eq!(connection_cap(300), 22);
        assert_eq!(connection_cap(100), 8);
        assert_eq!(connection_cap(1 << 20), MAX_CONNECTIONS);
    }
}
