//! Lossless capture: every byte read from a live source is appended to the session's capture
//! file before anything interprets it.
//!
//! Bytes are written to the file with one `write` per chunk, straight from the reading thread
//! (no user-space buffer: a chunk is in the kernel before it is sent on for decoding, so the
//! 250 ms flush bound holds with margin and a SIGKILL of the daemon loses nothing already read).
//! A background thread `fsync`s the file at most one second after any write, which bounds what
//! a power cut can lose.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Longest time a written byte waits for its `fsync`.
pub const FSYNC_INTERVAL: Duration = Duration::from_millis(1000);

/// Appends raw bytes to a capture file. Cloning is not offered: one writer per file.
#[derive(Debug)]
pub struct CaptureWriter {
    path: PathBuf,
    file: File,
    shared: Arc<Shared>,
    syncer: Option<std::thread::JoinHandle<()>>,
}

#[derive(Debug, Default)]
struct Shared {
    dirty: AtomicBool,
    stop: AtomicBool,
    bytes: AtomicU64,
    syncs: AtomicU64,
}

impl CaptureWriter {
    /// Opens `path` for appending (creating it), so that a resumed session continues the file.
    pub fn open_append(path: &Path) -> io::Result<Self> {
        let file = OpenOptions::new().create(true).append(true).open(path)?;
        let shared = Arc::new(Shared::default());
        let sync_file = file.try_clone()?;
        let s = shared.clone();
        let syncer = std::thread::Builder::new()
            .name("capture-fsync".into())
            .spawn(move || syncer(sync_file, s))?;
        Ok(CaptureWriter {
            path: path.to_owned(),
            file,
            shared,
            syncer: Some(syncer),
        })
    }

    /// The capture file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends `bytes`. Returns once they are in the kernel's page cache.
    pub fn append(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.file.write_all(bytes)?;
        self.shared
            .bytes
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        self.shared.dirty.store(true, Ordering::Release);
        Ok(())
    }

    /// Bytes appended through this writer.
    pub fn bytes_written(&self) -> u64 {
        self.shared.bytes.load(Ordering::Relaxed)
    }

    /// `fsync`s now (also done on drop).
    pub fn sync(&mut self) -> io::Result<()> {
        self.shared.dirty.store(false, Ordering::Release);
        self.file.sync_data()
    }
}

fn syncer(file: File, s: Arc<Shared>) {
    // A write lands at most one tick before the check that sees it dirty, and that check
    // syncs: no byte waits longer than two ticks = FSYNC_INTERVAL.
    let tick = FSYNC_INTERVAL / 2;
    while !s.stop.load(Ordering::Acquire) {
        std::thread::park_timeout(tick);
        if s.dirty.swap(false, Ordering::AcqRel) {
            if let Err(e) = file.sync_data() {
                tracing::error!(error = %e, "fsync of the capture file failed");
            }
            s.syncs.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl Drop for CaptureWriter {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Err(e) = self.file.sync_data() {
            tracing::error!(path = %self.path.display(), error = %e, "final fsync of the capture failed");
        }
        if let Some(h) = self.syncer.take() {
            h.thread().unpark();
            let _ = h.join();
        }
    }
}
