//! Running under systemd as a `Type=notify` service (`deploy/sfs@.service`): readiness,
//! status, the watchdog and stopping, through the `sd-notify` crate. Outside systemd
//! (`NOTIFY_SOCKET` unset) every call does nothing.
//!
//! - `READY=1` once the source is open (the serial port, standard input, the capture file)
//!   and the session directory prepared: a unit ordered after this one can rely on it.
//! - `WATCHDOG=1` from the pipeline itself (the loop that decodes the source's bytes, and the
//!   decoding of a resumed capture), at least every half of `WatchdogSec=` while it runs,
//!   also while the device is silent: a pipeline that stalls stops the pings and systemd
//!   restarts the service (which continues the session, `sfs run --continue`).
//! - `STOPPING=1` when a signal asks the session to finish, `STATUS=` lines along the way
//!   (`systemctl status` shows the last one).
//!
//! ```no_run
//! let notifier = sfs::service::Notifier::from_env();
//! notifier.ready("reading /dev/sfs-morphorider-A10K3G7Q");
//! loop {
//!     // … decode what arrived …
//!     notifier.alive();
//! #   break;
//! }
//! ```

use sd_notify::NotifyState;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The service manager's end of the notification socket, with the watchdog's period.
#[derive(Debug)]
pub struct Notifier {
    enabled: bool,
    /// `WatchdogSec=` (from `WATCHDOG_USEC`, when meant for this process).
    watchdog: Option<Duration>,
    last_ping: Mutex<Option<Instant>>,
}

impl Notifier {
    /// From the environment systemd gives a service (`NOTIFY_SOCKET`, `WATCHDOG_USEC`,
    /// `WATCHDOG_PID`).
    pub fn from_env() -> Notifier {
        Notifier {
            enabled: std::env::var_os("NOTIFY_SOCKET").is_some(),
            watchdog: sd_notify::watchdog_enabled().filter(|d| !d.is_zero()),
            last_ping: Mutex::new(None),
        }
    }

    /// How often the pipeline must show it is alive (half the watchdog's period), if the
    /// watchdog is on.
    pub fn ping_period(&self) -> Option<Duration> {
        self.watchdog.map(|d| d / 2)
    }

    /// The source is open: the service is up.
    pub fn ready(&self, status: &str) {
        self.send(&[NotifyState::Ready, NotifyState::Status(status)]);
        self.ping();
    }

    /// A line for `systemctl status`.
    pub fn status(&self, status: &str) {
        self.send(&[NotifyState::Status(status)]);
    }

    /// The session was asked to finish.
    pub fn stopping(&self) {
        self.send(&[NotifyState::Stopping, NotifyState::Status("finishing")]);
    }

    /// The pipeline made progress: a watchdog ping, when a quarter of the period has passed
    /// since the last one (so a fast stream does not flood the socket).
    pub fn alive(&self) {
        let Some(period) = self.watchdog.filter(|_| self.enabled) else {
            return;
        };
        let due = {
            let last = self.last_ping.lock().unwrap_or_else(|p| p.into_inner());
            last.is_none_or(|t| t.elapsed() >= period / 4)
        };
        if due {
            self.ping();
        }
    }

    fn ping(&self) {
        if self.watchdog.is_some() && self.enabled {
            self.send(&[NotifyState::Watchdog]);
            *self.last_ping.lock().unwrap_or_else(|p| p.into_inner()) = Some(Instant::now());
        }
    }

    fn send(&self, states: &[NotifyState]) {
        if !self.enabled {
            return;
        }
        if let Err(e) = sd_notify::notify(states) {
            tracing::warn!("cannot notify the service manager: {e}");
        }
    }
}

/// Fault injection for the watchdog's test, never for production: with
/// `SFS_TEST_STALL_AFTER_BYTES=N` the pipeline stops for good once it has decoded N bytes of
/// the source (the process stays up; the watchdog pings stop).
pub(crate) fn stall_after_bytes() -> Option<u64> {
    std::env::var("SFS_TEST_STALL_AFTER_BYTES")
        .ok()
        .and_then(|v| v.parse().ok())
}

/// Stops the calling thread for good (see [`stall_after_bytes`]).
pub(crate) fn stall() -> ! {
    tracing::error!("SFS_TEST_STALL_AFTER_BYTES: the pipeline stalls on purpose");
    loop {
        std::thread::sleep(Duration::from_secs(3600));
    }
}
