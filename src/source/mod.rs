//! Byte sources behind one interface: a serial port, a capture file replayed fast or in real
//! time, or standard input. Nothing downstream knows which is in use: each runs on its own
//! thread and sends [`SourceEvent`]s into a bounded channel (back-pressure, no unbounded
//! queue), ending with [`SourceEvent::End`].
//!
//! Live sources (serial, stdin) append every byte to the session's capture file on their own
//! thread, before the bytes are sent on for decoding (see [`crate::capture`]).
//!
//! ```no_run
//! # async fn f() -> Result<(), sfs::source::SourceError> {
//! use sfs::source::{self, SourceEvent, SourceSpec, Pace};
//! use sfs::shutdown::Shutdown;
//! let spec = SourceSpec::Replay { path: "replay-logs/cone-morphorider.bin".into(), pace: Pace::Fast };
//! let mut src = source::spawn(spec, None, Shutdown::new())?;
//! while let Some(ev) = src.events.recv().await {
//!     if let SourceEvent::Bytes(b) = ev { println!("{} bytes", b.len()); }
//! }
//! # Ok(()) }
//! ```

pub mod phone;
mod replay;
mod serial;
mod stdin;

use crate::capture::CaptureWriter;
use crate::shutdown::Shutdown;
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc;

pub use replay::Pace;

/// Depth of the channel between a source thread and the pipeline, in chunks.
pub const CHANNEL_CHUNKS: usize = 64;
/// Largest chunk a source sends at once.
pub const CHUNK_BYTES: usize = 64 * 1024;

/// Which source, fully resolved (from configuration and command-line flags).
#[derive(Debug, Clone, PartialEq)]
pub enum SourceSpec {
    /// A serial port through the `serialport` crate.
    Serial(SerialSpec),
    /// A capture file.
    Replay { path: PathBuf, pace: Pace },
    /// Standard input.
    Stdin,
    /// The phone page: a smartphone's browser streaming over HTTPS ([`phone`]).
    Phone(phone::PhoneSpec),
}

/// A serial port and how to watch it.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialSpec {
    pub path: PathBuf,
    pub baud: u32,
    /// Silence longer than this (no byte read) counts as a disconnect: the port is closed
    /// and reopened.
    pub watchdog: Duration,
    /// First reconnection delay; doubles after each failed attempt up to `backoff_max`.
    pub backoff_min: Duration,
    pub backoff_max: Duration,
}

impl SerialSpec {
    /// A port with the default watchdog (3 s) and backoff (100 ms doubling to 5 s).
    pub fn new(path: impl Into<PathBuf>, baud: u32) -> Self {
        SerialSpec {
            path: path.into(),
            baud,
            watchdog: Duration::from_secs(3),
            backoff_min: Duration::from_millis(100),
            backoff_max: Duration::from_secs(5),
        }
    }
}

impl SourceSpec {
    /// Whether the bytes come from a live device (and so must be captured).
    pub fn is_live(&self) -> bool {
        !matches!(self, SourceSpec::Replay { .. })
    }

    /// A short human description ("serial /dev/ttyUSB0 @ 115200", …).
    pub fn describe(&self) -> String {
        match self {
            SourceSpec::Serial(s) => format!("serial {} @ {} baud", s.path.display(), s.baud),
            SourceSpec::Replay { path, pace } => format!("replay {} ({pace})", path.display()),
            SourceSpec::Stdin => "standard input".into(),
            SourceSpec::Phone(p) => format!("phone page on {}", p.addr),
        }
    }
}

/// What a source reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceEvent {
    /// The device is (again) connected.
    Connected { description: String },
    /// Raw bytes, in order, already in the capture file for a live source.
    Bytes(Vec<u8>),
    /// The link was lost (unplug, read error, watchdog); a serial source keeps reconnecting.
    Disconnected { reason: String },
    /// Reopening a lost serial port failed, for the `attempt`-th time since the loss.
    Reconnecting { attempt: u64, error: String },
    /// Appending to the capture failed (a full disk, say): the source stops (then `End`).
    CaptureFailed {
        path: PathBuf,
        kind: std::io::ErrorKind,
        /// The error's text ("No space left on device (os error 28)").
        error: String,
    },
    /// The source is finished (end of file, end of input, shutdown). Always the last event.
    End { reason: EndReason },
}

/// Why a source ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    EndOfInput,
    Shutdown,
    /// Writing the capture failed: the source stopped rather than lose bytes.
    CaptureFailed,
    /// A read error that cannot be recovered (file or stdin).
    ReadError,
}

impl EndReason {
    /// Its name in `report.json` (`"ended"`).
    pub fn name(self) -> &'static str {
        match self {
            EndReason::EndOfInput => "end_of_input",
            EndReason::Shutdown => "shutdown",
            EndReason::CaptureFailed => "capture_failed",
            EndReason::ReadError => "read_error",
        }
    }
}

/// A source that could not start.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("cannot open {}: {source}", path.display())]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot open serial port {}: {message} (`sfs ports` lists this machine's serial ports; `sfs ports --probe` says which speak this protocol)", path.display())]
    Serial { path: PathBuf, message: String },
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// The phone page's certificate or token (made or read in `path`).
    #[error("the phone page in {}: {message}", path.display())]
    Phone { path: PathBuf, message: String },
    #[error("cannot start the source thread: {0}")]
    Thread(std::io::Error),
}

/// A running source: its events, and the thread to join.
#[derive(Debug)]
pub struct SourceHandle {
    pub events: mpsc::Receiver<SourceEvent>,
    pub thread: std::thread::JoinHandle<()>,
    /// The phone source's feedback and statistics.
    pub phone: Option<std::sync::Arc<phone::Phone>>,
}

/// Starts `spec` on its own thread. A live source appends to `capture` (if given) before
/// sending. The first open happens here, so a missing file or port is an error now, not later.
pub fn spawn(
    spec: SourceSpec,
    capture: Option<CaptureWriter>,
    shutdown: Shutdown,
) -> Result<SourceHandle, SourceError> {
    let (tx, rx) = mpsc::channel(CHANNEL_CHUNKS);
    let out = Out { tx, capture };
    let mut phone = None;
    let thread = match spec {
        SourceSpec::Serial(s) => serial::spawn(s, out, shutdown)?,
        SourceSpec::Replay { path, pace } => replay::spawn(path, pace, out, shutdown)?,
        SourceSpec::Stdin => stdin::spawn(out, shutdown)?,
        SourceSpec::Phone(p) => {
            let (thread, shared) = phone::spawn(p, out, shutdown)?;
            phone = Some(shared);
            thread
        }
    };
    Ok(SourceHandle {
        events: rx,
        thread,
        phone,
    })
}

/// The sending side shared by the source threads: capture first, then the channel.
struct Out {
    tx: mpsc::Sender<SourceEvent>,
    capture: Option<CaptureWriter>,
}

/// The receiver went away (the pipeline stopped): the source stops too.
struct Closed;

impl Out {
    /// Captures then sends `bytes`. On a capture failure the source must stop.
    fn bytes(&mut self, bytes: &[u8]) -> Result<(), Stop> {
        if let Some(c) = &mut self.capture {
            if let Err(e) = c.append(bytes) {
                tracing::error!(path = %c.path().display(), error = %e,
                    "cannot append to the capture file; stopping the source so no byte is read uncaptured");
                let failed = SourceEvent::CaptureFailed {
                    path: c.path().to_owned(),
                    kind: e.kind(),
                    error: e.to_string(),
                };
                let _ = self.send(failed);
                return Err(Stop::CaptureFailed);
            }
        }
        self.send(SourceEvent::Bytes(bytes.to_vec()))
            .map_err(|Closed| Stop::Closed)
    }

    fn send(&self, ev: SourceEvent) -> Result<(), Closed> {
        self.tx.blocking_send(ev).map_err(|_| Closed)
    }

    fn end(mut self, reason: EndReason) {
        if let Some(c) = &mut self.capture {
            if let Err(e) = c.sync() {
                tracing::error!(error = %e, "final fsync of the capture failed");
            }
        }
        let _ = self.send(SourceEvent::End { reason });
    }
}

enum Stop {
    Closed,
    CaptureFailed,
}

impl Stop {
    fn reason(self) -> EndReason {
        match self {
            Stop::Closed => EndReason::Shutdown,
            Stop::CaptureFailed => EndReason::CaptureFailed,
        }
    }
}

fn spawn_thread(
    name: &str,
    f: impl FnOnce() + Send + 'static,
) -> Result<std::thread::JoinHandle<()>, SourceError> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(f)
        .map_err(SourceError::Thread)
}
