//! Serial port source: a dedicated thread reads `serialport` with a short timeout, so it can
//! watch for silence and for shutdown, and reconnects with exponential backoff after an
//! unplug, a read error, a run of zero-byte reads or a silence longer than the watchdog.

use super::{spawn_thread, EndReason, Out, SerialSpec, SourceError, SourceEvent, Stop};
use crate::shutdown::Shutdown;
use std::io::{ErrorKind, Read};
use std::time::{Duration, Instant};

/// Read timeout of the port: how often the thread looks at the watchdog and the shutdown flag.
const READ_TIMEOUT: Duration = Duration::from_millis(50);
/// Zero-byte reads in a row that count as end-of-stream (a known failure after an unplug with
/// some drivers: `read` returns `Ok(0)` forever).
const ZERO_READS_LIMIT: u32 = 64;

fn open(spec: &SerialSpec) -> Result<serialport::TTYPort, serialport::Error> {
    serialport::new(spec.path.to_string_lossy(), spec.baud)
        .timeout(READ_TIMEOUT)
        .open_native()
}

pub(super) fn spawn(
    spec: SerialSpec,
    out: Out,
    shutdown: Shutdown,
) -> Result<std::thread::JoinHandle<()>, SourceError> {
    // The first open is done here, so that a wrong path is reported at start-up.
    let port = open(&spec).map_err(|e| SourceError::Serial {
        path: spec.path.clone(),
        message: e.to_string(),
    })?;
    spawn_thread("source-serial", move || run(spec, port, out, shutdown))
}

fn run(spec: SerialSpec, first: serialport::TTYPort, mut out: Out, shutdown: Shutdown) {
    let mut port = Some(first);
    let mut backoff = spec.backoff_min;
    let mut failures = 0u64;
    let reason = loop {
        if shutdown.is_triggered() {
            break EndReason::Shutdown;
        }
        let p = match port.take() {
            Some(p) => p,
            None => match open(&spec) {
                Ok(p) => p,
                Err(e) => {
                    failures += 1;
                    // Log the first failure and then sparingly, not every 100 ms.
                    if failures == 1 || failures.is_power_of_two() {
                        tracing::warn!(path = %spec.path.display(), error = %e, attempts = failures,
                            retry_in_ms = backoff.as_millis() as u64, "serial port not available");
                    }
                    let attempt = SourceEvent::Reconnecting {
                        attempt: failures,
                        error: e.to_string(),
                    };
                    if out.send(attempt).is_err() || shutdown.sleep_blocking(backoff) {
                        break EndReason::Shutdown;
                    }
                    backoff = (backoff * 2).min(spec.backoff_max);
                    continue;
                }
            },
        };
        failures = 0;
        backoff = spec.backoff_min;
        let description = format!("{} @ {} baud", spec.path.display(), spec.baud);
        tracing::info!(port = %description, "serial port connected");
        if out.send(SourceEvent::Connected { description }).is_err() {
            break EndReason::Shutdown;
        }
        match read_until_lost(&spec, p, &mut out, &shutdown) {
            Ok(Lost::Shutdown) => break EndReason::Shutdown,
            Ok(Lost::Disconnected(reason)) => {
                tracing::warn!(path = %spec.path.display(), %reason, "serial link lost; reconnecting");
                if out.send(SourceEvent::Disconnected { reason }).is_err() {
                    break EndReason::Shutdown;
                }
            }
            Err(stop) => break stop.reason(),
        }
    };
    out.end(reason);
}

enum Lost {
    Shutdown,
    Disconnected(String),
}

fn read_until_lost(
    spec: &SerialSpec,
    mut port: serialport::TTYPort,
    out: &mut Out,
    shutdown: &Shutdown,
) -> Result<Lost, Stop> {
    let mut buf = vec![0u8; 4096];
    let mut last_data = Instant::now();
    let mut zero_reads = 0u32;
    loop {
        if shutdown.is_triggered() {
            return Ok(Lost::Shutdown);
        }
        match port.read(&mut buf) {
            Ok(0) => {
                zero_reads += 1;
                if zero_reads >= ZERO_READS_LIMIT {
                    return Ok(Lost::Disconnected(
                        "reads return 0 bytes (end of stream)".into(),
                    ));
                }
                // Do not spin on a port that returns at once.
                std::thread::sleep(READ_TIMEOUT / 5);
            }
            Ok(n) => {
                zero_reads = 0;
                last_data = Instant::now();
                out.bytes(&buf[..n])?;
                continue;
            }
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => return Ok(Lost::Disconnected(format!("read error: {e}"))),
        }
        if last_data.elapsed() > spec.watchdog {
            return Ok(Lost::Disconnected(format!(
                "no byte for {:.1} s (watchdog)",
                spec.watchdog.as_secs_f64()
            )));
        }
    }
}
