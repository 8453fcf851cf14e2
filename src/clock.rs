//! The session clock: monotonic session time from the device's timestamps (wraps bridged,
//! reboots continued), and its state where a capture file starts ([`CaptureStart`], kept as
//! the file's sidecar so that a piece of a rotated capture keeps the session's time).

/// The session clock where a capture file starts: its sidecar `NAME.start.json` (absent for
/// the first file of a session, which starts at zero).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CaptureStart {
    /// Session time, µs.
    pub elapsed_us: u64,
    /// The device stamp it was reached at.
    pub last_t_us: Option<u32>,
    /// A device reboot was seen and its first stamp not yet.
    #[serde(default)]
    pub restart: bool,
    /// The last HELLO before the file, as a frame (the device repeats it only every 5 s,
    /// and samples cannot be read without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hello: Option<Vec<u8>>,
}

impl CaptureStart {
    /// The HELLO it carries.
    pub fn hello(&self) -> Option<device_protocol::Hello> {
        let frame = self.hello.as_ref()?;
        device_protocol::Decoder::new()
            .feed(frame)
            .find_map(|e| match e {
                device_protocol::Event::Packet {
                    packet: device_protocol::Packet::Hello(h),
                    ..
                } => Some(h),
                _ => None,
            })
    }
}

/// Monotonic session time from the device clock: increments are `t_us` differences (wraps
/// included); after a reboot ([`Clock::restart`]) the next stamp adds nothing.
#[derive(Debug, Clone, Default)]
pub struct Clock {
    last: Option<u32>,
    elapsed_us: u64,
    restart: bool,
}

impl Clock {
    /// The clock where a capture file starts (see [`CaptureStart`]).
    pub fn at(start: &CaptureStart) -> Clock {
        Clock {
            last: start.last_t_us,
            elapsed_us: start.elapsed_us,
            restart: start.restart,
        }
    }

    /// The state to start another capture file from.
    pub fn state(&self) -> CaptureStart {
        CaptureStart {
            elapsed_us: self.elapsed_us,
            last_t_us: self.last,
            restart: self.restart,
            hello: None,
        }
    }

    /// Session time so far, s.
    pub fn now(&self) -> f64 {
        self.elapsed_us as f64 * 1e-6
    }

    /// The device restarted: its clock starts over.
    pub fn restart(&mut self) {
        self.restart = true;
    }

    /// Session time, s, of a packet stamped `t_us`.
    pub fn advance(&mut self, t_us: u32) -> f64 {
        if let Some(last) = self.last {
            if !self.restart {
                self.elapsed_us += t_us.wrapping_sub(last) as u64;
            }
        }
        self.restart = false;
        self.last = Some(t_us);
        self.elapsed_us as f64 * 1e-6
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_is_monotonic_across_wraps_and_restarts() {
        let mut c = Clock::default();
        assert_eq!(c.advance(u32::MAX - 999), 0.0);
        assert!((c.advance(1000) - 0.002).abs() < 1e-9); // wrapped: +2000 µs
        c.restart();
        assert!((c.advance(5) - 0.002).abs() < 1e-9); // reboot adds nothing
        assert!((c.advance(10_005) - 0.012).abs() < 1e-9);
    }
}
