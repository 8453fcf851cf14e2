//! Shutdown signalling shared by the async pipeline and the blocking source threads.
//!
//! One [`Shutdown`] is created per session and cloned into everything that must stop:
//! the source threads poll [`Shutdown::is_triggered`] between reads (their reads time out
//! periodically), async tasks `await` [`Shutdown::triggered`].

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use tokio::sync::Notify;

/// A cloneable, one-way "stop now" flag.
#[derive(Debug, Clone, Default)]
pub struct Shutdown {
    inner: Arc<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    flag: AtomicBool,
    notify: Notify,
}

impl Shutdown {
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks everything holding a clone to stop. Idempotent.
    pub fn trigger(&self) {
        self.inner.flag.store(true, Ordering::SeqCst);
        self.inner.notify.notify_waiters();
    }

    /// Whether [`trigger`](Self::trigger) was called.
    pub fn is_triggered(&self) -> bool {
        self.inner.flag.load(Ordering::SeqCst)
    }

    /// Completes once [`trigger`](Self::trigger) has been called.
    pub async fn triggered(&self) {
        loop {
            let notified = self.inner.notify.notified();
            if self.is_triggered() {
                return;
            }
            notified.await;
        }
    }

    /// Sleeps for `d` on a blocking thread, waking early (returning `true`) on shutdown.
    pub fn sleep_blocking(&self, d: std::time::Duration) -> bool {
        let end = std::time::Instant::now() + d;
        loop {
            if self.is_triggered() {
                return true;
            }
            let now = std::time::Instant::now();
            if now >= end {
                return false;
            }
            std::thread::sleep((end - now).min(std::time::Duration::from_millis(20)));
        }
    }
}

/// SIGINT and SIGTERM back to their default (the process ends) until the daemon's own
/// handlers take them: a shell that starts a command in the background leaves SIGINT ignored
/// (POSIX), and a signal before the handlers are in place would then be lost. Called first
/// thing in `main`, before any thread starts; nothing is written yet, so ending is safe.
pub fn default_signals() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: sets a disposition to the default; no thread runs yet and no handler of ours
        // is replaced.
        unsafe {
            libc::signal(sig, libc::SIG_DFL);
        }
    }
}
