//! Standard input source: reads until end of input. Captured like any live source.

use super::{spawn_thread, EndReason, Out, SourceError, CHUNK_BYTES};
use crate::shutdown::Shutdown;
use std::io::{ErrorKind, Read};

pub(super) fn spawn(
    out: Out,
    shutdown: Shutdown,
) -> Result<std::thread::JoinHandle<()>, SourceError> {
    spawn_thread("source-stdin", move || run(out, shutdown))
}

fn run(mut out: Out, shutdown: Shutdown) {
    let stdin = std::io::stdin();
    let mut lock = stdin.lock();
    let mut buf = vec![0u8; CHUNK_BYTES];
    let reason = loop {
        // A blocking read on stdin cannot be interrupted; the flag is seen at the next chunk
        // or at end of input. The pipeline does not wait for this thread on shutdown.
        if shutdown.is_triggered() {
            break EndReason::Shutdown;
        }
        match lock.read(&mut buf) {
            Ok(0) => break EndReason::EndOfInput,
            Ok(n) => {
                if let Err(stop) = out.bytes(&buf[..n]) {
                    break stop.reason();
                }
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => {
                tracing::error!(error = %e, "reading standard input failed");
                break EndReason::ReadError;
            }
        }
    };
    out.end(reason);
}
