//! Capture-file source: replayed as fast as the pipeline takes it, or paced in real time from
//! the device timestamps in the packets (`t_us`), which reproduces the timing of the session.

use super::{spawn_thread, EndReason, Out, SourceError, CHUNK_BYTES};
use crate::shutdown::Shutdown;
use device_protocol::{Decoder, Event};
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How a capture file is replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pace {
    /// As fast as the pipeline consumes it.
    #[default]
    Fast,
    /// At the speed the device sent it, from its timestamps.
    Realtime,
    /// Paced like `Realtime`, N times faster (`"x10"`): a session's timing, compressed.
    Times(u16),
}

impl Pace {
    /// How many times faster than the device's clock; `None` for [`Pace::Fast`].
    fn speed(self) -> Option<u64> {
        match self {
            Pace::Fast => None,
            Pace::Realtime => Some(1),
            Pace::Times(n) => Some(n.max(1) as u64),
        }
    }
}

impl std::fmt::Display for Pace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Pace::Fast => f.write_str("fast"),
            Pace::Realtime => f.write_str("realtime"),
            Pace::Times(n) => write!(f, "x{n}"),
        }
    }
}

/// A pace that is not `fast`, `realtime` or `xN` (N from 1 to 1000).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown pace {0:?}: expected \"fast\", \"realtime\" or \"xN\" (N times real time, 1 to 1000)"
)]
pub struct PaceError(pub String);

impl std::str::FromStr for Pace {
    type Err = PaceError;
    fn from_str(s: &str) -> Result<Self, PaceError> {
        match s {
            "fast" => Ok(Pace::Fast),
            "realtime" => Ok(Pace::Realtime),
            _ => match s.strip_prefix('x').map(str::parse::<u16>) {
                Some(Ok(n)) if (1..=1000).contains(&n) => Ok(Pace::Times(n)),
                _ => Err(PaceError(s.to_owned())),
            },
        }
    }
}

/// A jump of the device clock larger than this (a reboot, a clock going back, a device that
/// was off) is replayed as no wait at all.
const MAX_PACED_GAP_US: u32 = 5_000_000;

pub(super) fn spawn(
    path: PathBuf,
    pace: Pace,
    out: Out,
    shutdown: Shutdown,
) -> Result<std::thread::JoinHandle<()>, SourceError> {
    let file = File::open(&path).map_err(|source| SourceError::Open {
        path: path.clone(),
        source,
    })?;
    let meta = file.metadata().map_err(|source| SourceError::Open {
        path: path.clone(),
        source,
    })?;
    if meta.is_dir() {
        return Err(SourceError::Open {
            path,
            source: std::io::Error::new(ErrorKind::InvalidInput, "is a directory"),
        });
    }
    spawn_thread("source-replay", move || {
        run(path, file, pace, out, shutdown)
    })
}

fn run(path: PathBuf, mut file: File, pace: Pace, mut out: Out, shutdown: Shutdown) {
    let mut buf = vec![0u8; CHUNK_BYTES];
    let mut pacer = Pacer::new();
    let reason = loop {
        if shutdown.is_triggered() {
            break EndReason::Shutdown;
        }
        let n = match file.read(&mut buf) {
            Ok(0) => break EndReason::EndOfInput,
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => {
                tracing::error!(path = %path.display(), error = %e, "reading the capture failed");
                break EndReason::ReadError;
            }
        };
        let sent = match pace.speed() {
            None => out.bytes(&buf[..n]).map_err(|s| s.reason()),
            Some(speed) => pacer.send_paced(&buf[..n], speed, &mut out, &shutdown),
        };
        if let Err(reason) = sent {
            break reason;
        }
    };
    out.end(reason);
}

/// Sends bytes frame by frame, sleeping so that each timestamped packet leaves when the
/// device clock says it was sent.
struct Pacer {
    decoder: Decoder,
    start: Option<Instant>,
    device_elapsed_us: u64,
    last_t: Option<u32>,
}

impl Pacer {
    fn new() -> Self {
        Pacer {
            decoder: Decoder::new(),
            start: None,
            device_elapsed_us: 0,
            last_t: None,
        }
    }

    /// The instant at which the frame holding a packet stamped `t` is due, replaying `speed`
    /// times faster than the device's clock.
    fn due(&mut self, t: u32, speed: u64) -> Instant {
        let start = *self.start.get_or_insert_with(Instant::now);
        if let Some(last) = self.last_t {
            let d = t.wrapping_sub(last);
            if d <= MAX_PACED_GAP_US {
                self.device_elapsed_us += d as u64;
            }
        }
        self.last_t = Some(t);
        start + Duration::from_micros(self.device_elapsed_us / speed)
    }

    fn send_paced(
        &mut self,
        chunk: &[u8],
        speed: u64,
        out: &mut Out,
        shutdown: &Shutdown,
    ) -> Result<(), EndReason> {
        let mut pending = 0; // bytes of `chunk` not yet sent
        let mut pos = 0;
        while let Some(z) = chunk[pos..].iter().position(|&b| b == 0) {
            let end = pos + z + 1;
            let mut stamp = None;
            for ev in self.decoder.feed(&chunk[pos..end]) {
                if let Event::Packet { packet, .. } = ev {
                    stamp = packet.t_us().or(stamp);
                }
            }
            if let Some(due) = stamp.map(|t| self.due(t, speed)) {
                let now = Instant::now();
                if due > now {
                    if pending < pos {
                        out.bytes(&chunk[pending..pos]).map_err(|s| s.reason())?;
                        pending = pos;
                    }
                    if shutdown.sleep_blocking(due - now) {
                        return Err(EndReason::Shutdown);
                    }
                }
            }
            pos = end;
        }
        // The rest, including a frame that continues in the next chunk (its bytes are fed to
        // the pacing decoder with the next chunk's first frame).
        self.decoder.feed(&chunk[pos..]).for_each(drop);
        if pending < chunk.len() {
            out.bytes(&chunk[pending..]).map_err(|s| s.reason())?;
        }
        Ok(())
    }
}
