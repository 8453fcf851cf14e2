//! A serial device on a pseudo-terminal pair: the session reads the slave by path (through a
//! symlink, as udev's /dev/serial/by-id links); closing the master is an unplug, a new pair
//! behind the same link is the device coming back.

use super::wait_for;
use serialport::{SerialPort, TTYPort};
use sfs::source::{SerialSpec, SourceSpec};
use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// A plugged-in device: the pty master it writes to, and the slave kept open so that the line
/// stays up while the session (re)opens it by path.
pub struct Device {
    pub master: TTYPort,
    pub _slave: TTYPort,
    pub pts: String,
}

/// A pty pair whose slave is reachable as `link`.
pub fn plug(link: &Path) -> Device {
    let (master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
    let pts = slave.name().expect("slave name");
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(&pts, link).unwrap();
    Device {
        master,
        _slave: slave,
        pts,
    }
}

/// Open descriptors of this process on `pts` (ours, plus the session's once it has opened it).
pub fn opened(pts: &str) -> usize {
    std::fs::read_dir("/proc/self/fd")
        .unwrap()
        .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
        .filter(|t| t == Path::new(pts))
        .count()
}

/// Waits until the session has the device open, then writes `bytes` in small pieces, as a
/// device at a few kB/s would.
pub fn play(dev: &mut Device, bytes: &[u8]) {
    wait_for(
        "the session to open the port",
        Duration::from_secs(10),
        || opened(&dev.pts) >= 2,
    );
    write(dev, bytes);
}

/// Writes `bytes` in small pieces, as a device at a few kB/s would (the port must be open on
/// the other side: a pty not yet in raw mode would echo and edit them).
pub fn write(dev: &mut Device, bytes: &[u8]) {
    for c in bytes.chunks(257) {
        dev.master.write_all(c).unwrap();
        std::thread::sleep(Duration::from_micros(300));
    }
}

pub fn spec(link: &Path) -> SourceSpec {
    let mut s = SerialSpec::new(link, 115_200);
    s.backoff_min = Duration::from_millis(20);
    s.backoff_max = Duration::from_millis(200);
    s.watchdog = Duration::from_secs(5);
    SourceSpec::Serial(s)
}
