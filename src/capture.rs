//! Lossless capture: every byte read from a live source is appended to the session's capture
//! file before anything interprets it.
//!
//! Bytes are written to the file with one `write` per chunk, straight from the reading thread
//! (no user-space buffer: a chunk is in the kernel before it is sent on for decoding, so the
//! 250 ms flush bound holds with margin and a SIGKILL of the daemon loses nothing already read).
//! A background thread `fsync`s the file at most one second after any write, which bounds what
//! a power cut can lose.
//!
//! With a [`Rotation`] (unattended monitoring, where a month of stream would fill the disk),
//! a file past its size limit is closed at the next frame delimiter and renamed
//! `capture.1.bin` (older ones shift to `capture.2.bin`, …, the oldest beyond `keep` is
//! deleted); the new `capture.bin` gets a sidecar `capture.start.json` ([`CaptureStart`]):
//! the session clock where it starts, so that decoding it alone (`--resume`, `sfs replay`)
//! continues the session's time. The writer follows the clock with its own decoder.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Longest time a written byte waits for its `fsync`.
pub const FSYNC_INTERVAL: Duration = Duration::from_millis(1000);

/// Size limit and retention of a rotated capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rotation {
    /// A file is rotated at the first frame delimiter past this many bytes.
    pub max_bytes: u64,
    /// Rotated files kept (`capture.1.bin` … `capture.KEEP.bin`); 0: none.
    pub keep: usize,
}

pub use crate::clock::CaptureStart;

/// The sidecar of capture file `path` (`capture.bin` → `capture.start.json`).
pub fn start_path(path: &Path) -> PathBuf {
    path.with_extension("start.json")
}

/// Where the session clock stands at the start of capture file `path`: its sidecar, or zero.
pub fn read_start(path: &Path) -> io::Result<CaptureStart> {
    match std::fs::read(start_path(path)) {
        Ok(b) => serde_json::from_slice(&b).map_err(io::Error::other),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(CaptureStart::default()),
        Err(e) => Err(e),
    }
}

/// The session clock followed through the bytes written (for the sidecar of the next file).
#[derive(Debug, Default)]
struct ClockTracker {
    decoder: device_protocol::Decoder,
    clock: crate::clock::Clock,
    hello: Option<Vec<u8>>,
}

impl ClockTracker {
    fn feed(&mut self, bytes: &[u8]) {
        use device_protocol::Event;
        for e in self.decoder.feed(bytes) {
            match e {
                Event::Packet { packet, seq } => {
                    if let Some(t) = packet.t_us() {
                        self.clock.advance(t);
                    }
                    if let device_protocol::Packet::Hello(_) = packet {
                        let mut frame = Vec::new();
                        packet.encode(seq, &mut frame);
                        self.hello = Some(frame);
                    }
                }
                Event::DeviceReboot => self.clock.restart(),
                _ => {}
            }
        }
    }
}

/// Appends raw bytes to a capture file. Cloning is not offered: one writer per file.
#[derive(Debug)]
pub struct CaptureWriter {
    path: PathBuf,
    file: File,
    shared: Arc<Shared>,
    syncer: Option<std::thread::JoinHandle<()>>,
    rotation: Option<(Rotation, ClockTracker)>,
    /// Length of the current file.
    len: u64,
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
        let len = file.metadata()?.len();
        let shared = Arc::new(Shared::default());
        let syncer = spawn_syncer(&file, &shared)?;
        Ok(CaptureWriter {
            path: path.to_owned(),
            file,
            shared,
            syncer: Some(syncer),
            rotation: None,
            len,
        })
    }

    /// As [`open_append`](Self::open_append), rotated by `rotation` (the clock is followed
    /// from the file's sidecar through what it already holds).
    pub fn open_rotating(path: &Path, rotation: Rotation) -> io::Result<Self> {
        let mut w = Self::open_append(path)?;
        let start = read_start(path)?;
        let mut tracker = ClockTracker {
            clock: crate::clock::Clock::at(&start),
            hello: start.hello,
            ..Default::default()
        };
        let mut f = File::open(path)?;
        let mut buf = vec![0u8; 1 << 16];
        loop {
            let n = io::Read::read(&mut f, &mut buf)?;
            if n == 0 {
                break;
            }
            tracker.feed(&buf[..n]);
        }
        w.rotation = Some((rotation, tracker));
        Ok(w)
    }

    /// Stops the syncer thread after a final `fsync`.
    fn stop_syncer(&mut self) -> io::Result<()> {
        self.shared.stop.store(true, Ordering::Release);
        let synced = self.file.sync_data();
        if let Some(h) = self.syncer.take() {
            h.thread().unpark();
            let _ = h.join();
        }
        synced
    }

    /// Closes the current file and starts the next (see the module documentation).
    fn rotate(&mut self) -> io::Result<()> {
        let Some((r, tracker)) = &self.rotation else {
            return Ok(());
        };
        let (keep, mut start) = (r.keep, tracker.clock.state());
        start.hello = tracker.hello.clone();
        self.stop_syncer()?;
        let name = |k: usize| match k {
            0 => self.path.clone(),
            k => {
                let stem = self.path.file_stem().unwrap_or_default().to_string_lossy();
                self.path.with_file_name(format!("{stem}.{k}.bin"))
            }
        };
        crate::atomic::shift_generations(name, keep)?;
        crate::atomic::shift_generations(|k| start_path(&name(k)), keep)?;
        crate::atomic::write_json(&start_path(&self.path), &start, false)?;
        self.file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)?;
        self.len = 0;
        self.shared = Arc::new(Shared {
            bytes: AtomicU64::new(self.shared.bytes.load(Ordering::Relaxed)),
            syncs: AtomicU64::new(self.shared.syncs.load(Ordering::Relaxed)),
            ..Default::default()
        });
        self.syncer = Some(spawn_syncer(&self.file, &self.shared)?);
        tracing::info!(
            path = %self.path.display(),
            session_s = start.elapsed_us as f64 * 1e-6,
            "capture rotated"
        );
        Ok(())
    }

    fn write(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.file.write_all(bytes)?;
        self.len += bytes.len() as u64;
        if let Some((_, t)) = &mut self.rotation {
            t.feed(bytes);
        }
        self.shared
            .bytes
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        self.shared.dirty.store(true, Ordering::Release);
        Ok(())
    }

    /// The capture file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends `bytes`. Returns once they are in the kernel's page cache.
    pub fn append(&mut self, bytes: &[u8]) -> io::Result<()> {
        let limit = self.rotation.as_ref().map(|(r, _)| r.max_bytes);
        if limit.is_some_and(|m| self.len + bytes.len() as u64 > m) {
            // Past the limit: rotate after the last delimiter of this chunk (the next file
            // starts on a frame), or wait for a chunk that has one.
            if let Some(k) = bytes.iter().rposition(|&b| b == 0) {
                let (head, tail) = bytes.split_at(k + 1);
                self.write(head)?;
                self.rotate()?;
                return self.write(tail);
            }
        }
        self.write(bytes)
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

fn spawn_syncer(file: &File, shared: &Arc<Shared>) -> io::Result<std::thread::JoinHandle<()>> {
    let (f, s) = (file.try_clone()?, shared.clone());
    std::thread::Builder::new()
        .name("capture-fsync".into())
        .spawn(move || syncer(f, s))
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
        if let Err(e) = self.stop_syncer() {
            tracing::error!(path = %self.path.display(), error = %e, "final fsync of the capture failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquisition::{Acquisition, AcquisitionConfig};
    use crate::simulate::structure::{run, StructureKind};

    /// The sensor-array epochs of `bytes`: `(time, sensor, orientation)`.
    fn epochs(bytes: &[u8], start: &CaptureStart) -> Vec<(f64, u16, [f64; 4])> {
        let cfg = AcquisitionConfig {
            array_window: 0.5,
            ..Default::default()
        };
        let mut acq = Acquisition::starting_at(cfg, start);
        let mut dec = device_protocol::Decoder::new();
        for e in dec.feed(bytes) {
            acq.event(&e);
        }
        acq.finish()
            .array
            .iter()
            .map(|e| (e.t, e.sensor, e.q))
            .collect()
    }

    #[test]
    fn a_rotated_capture_keeps_its_newest_files_whole_and_their_session_time() {
        let dir = std::env::temp_dir().join(format!("sfs-capture-rot-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let (stream, _) = run(StructureKind::Riser, 1, 30.0, 10.0);
        let path = dir.join("capture.bin");
        let rotation = Rotation {
            max_bytes: 40_000,
            keep: 3,
        };
        // Written in pieces of 1 to 600 bytes, as a serial port delivers them; reopened
        // half-way, as a resumed session does.
        let (mut at, mut x) = (0usize, 12345u64);
        let mut w = CaptureWriter::open_rotating(&path, rotation).unwrap();
        while at < stream.len() {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let n = ((x >> 33) % 600 + 1) as usize;
            let end = (at + n).min(stream.len());
            w.append(&stream[at..end]).unwrap();
            at = end;
            if at > stream.len() / 2 && w.rotation.is_some() && x % 97 == 0 {
                drop(w);
                w = CaptureWriter::open_rotating(&path, rotation).unwrap();
            }
        }
        drop(w);
        assert!(!dir.join("capture.4.bin").exists());
        let names = [
            "capture.3.bin",
            "capture.2.bin",
            "capture.1.bin",
            "capture.bin",
        ];
        let mut kept = Vec::new();
        for n in names {
            let b = std::fs::read(dir.join(n)).unwrap();
            if n != "capture.bin" {
                assert_eq!(b.last(), Some(&0), "{n} ends inside a frame");
                assert!(
                    b.len() as u64 <= rotation.max_bytes + 600,
                    "{n}: {}",
                    b.len()
                );
            }
            kept.extend_from_slice(&b);
        }
        // The newest files, whole: a suffix of the stream.
        assert!(stream.ends_with(&kept));
        assert!(kept.len() as u64 > 3 * rotation.max_bytes - 3 * 600);
        // Each file decoded alone from its sidecar gives the epochs the whole stream gives, at
        // the same session times (but a sensor's first window in a file, cut by the rotation).
        let whole = epochs(&stream, &CaptureStart::default());
        for n in names {
            let p = dir.join(n);
            let start = read_start(&p).unwrap();
            assert!(
                start.elapsed_us > 0 && start.hello.is_some(),
                "{n}: no sidecar"
            );
            let piece = epochs(&std::fs::read(&p).unwrap(), &start);
            let mut seen = std::collections::BTreeSet::new();
            let mut compared = 0;
            for (t, sensor, q) in &piece {
                if seen.insert(*sensor) {
                    continue;
                }
                let w = whole
                    .iter()
                    .find(|w| (w.0 - t).abs() < 1e-9 && w.1 == *sensor);
                assert_eq!(w.map(|w| w.2), Some(*q), "{n}: sensor {sensor} at t = {t}");
                compared += 1;
            }
            assert!(compared >= 41, "{n}: {compared} epochs compared");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
