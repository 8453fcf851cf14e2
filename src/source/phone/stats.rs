//! What the phone link measured: the page's sampling (rate and jitter, from the samples' own
//! timestamps), how the messages arrived, the latency from a sensor event to the daemon, and
//! what was refused (`report.json` `phone`).

use crate::report::Percentiles;
use device_protocol::{Decoder, Event, Packet};
use serde::Serialize;

/// Values kept per distribution; past it every second one is dropped and only every second
/// one after it kept (an even thinning: the percentiles of a long session stay fair).
const KEEP: usize = 1 << 17;

/// A bounded, evenly thinned sample of a distribution.
#[derive(Debug, Clone, Default)]
struct Thinned {
    v: Vec<f64>,
    stride: u64,
    seen: u64,
}

impl Thinned {
    fn push(&mut self, x: f64) {
        let stride = self.stride.max(1);
        if self.seen.is_multiple_of(stride) {
            self.v.push(x);
            if self.v.len() >= KEEP {
                let mut i = 0;
                self.v.retain(|_| {
                    i += 1;
                    i % 2 == 1
                });
                self.stride = stride * 2;
            }
        }
        self.seen += 1;
    }

    fn summary(&self) -> Percentiles {
        Percentiles::of(&self.v)
    }
}

/// What was refused, by reason.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct Refused {
    /// Requests without the token or with a wrong one (403).
    pub token: u64,
    /// Of those, answered late because the address had failed too often.
    pub slowed: u64,
    /// A second phone while one was streaming (409).
    pub busy: u64,
    /// Plain HTTP on the HTTPS port.
    pub plain_http: u64,
    /// Connections closed for a message over the size limit.
    pub oversized: u64,
    /// TLS handshakes that failed (a client that does not accept the certificate).
    pub tls: u64,
}

/// `report.json` `phone`.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct PhoneReport {
    /// Connections of the page's WebSocket accepted (a reconnection counts again).
    pub connections: u64,
    pub refused: Refused,
    /// Binary messages and their bytes.
    pub messages: u64,
    pub bytes: u64,
    /// Text messages that were not the page's hello (ignored).
    pub ignored_text: u64,
    /// PHONE_SAMPLE packets seen.
    pub samples: u64,
    /// The page's sample rate from the samples' timestamps, Hz.
    pub rate_hz: f64,
    /// Between consecutive samples by their timestamps, ms, and the standard deviation of
    /// that interval (the jitter).
    pub interval_ms: Percentiles,
    pub jitter_ms: f64,
    /// Between consecutive messages as the daemon received them, ms.
    pub arrival_interval_ms: Percentiles,
    /// From a sample's sensor event (the page's clock) to its arrival here (the daemon's
    /// clock), ms: meaningful when both clocks agree (the same machine, or both on NTP).
    pub latency_ms: Percentiles,
    /// The last page's browser (`navigator.userAgent`, at most 200 characters).
    pub user_agent: Option<String>,
}

/// The running statistics.
#[derive(Debug, Default)]
pub struct Stats {
    pub refused: Refused,
    pub connections: u64,
    messages: u64,
    bytes: u64,
    pub ignored_text: u64,
    samples: u64,
    span_us: f64,
    intervals: Thinned,
    sum: f64,
    sum2: f64,
    arrivals: Thinned,
    latencies: Thinned,
    pub user_agent: Option<String>,
}

/// One connection's view of its samples: its own decoder (the session decodes the same bytes
/// again; this one only reads timestamps), the last timestamp and arrival, and the page's
/// clock origin.
#[derive(Debug)]
pub struct Conn {
    decoder: Decoder,
    last_t_us: Option<u32>,
    last_arrival: Option<std::time::Instant>,
    /// `performance.timeOrigin` of the page, ms since the Unix epoch (from its hello).
    pub time_origin_ms: Option<f64>,
}

impl Default for Conn {
    fn default() -> Self {
        Conn {
            decoder: Decoder::new(),
            last_t_us: None,
            last_arrival: None,
            time_origin_ms: None,
        }
    }
}

impl Stats {
    /// A binary message of `conn` arrived now.
    pub fn message(&mut self, conn: &mut Conn, bytes: &[u8]) {
        let now = std::time::Instant::now();
        let wall_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64() * 1e3);
        self.messages += 1;
        self.bytes += bytes.len() as u64;
        if let Some(prev) = conn.last_arrival.replace(now) {
            self.arrivals.push((now - prev).as_secs_f64() * 1e3);
        }
        let mut newest = None;
        for e in conn.decoder.feed(bytes) {
            let Event::Packet {
                packet: Packet::PhoneSample(s),
                ..
            } = e
            else {
                continue;
            };
            self.samples += 1;
            if let Some(prev) = conn.last_t_us.replace(s.t_us) {
                let dt = s.t_us.wrapping_sub(prev) as f64;
                // A page reloaded (its clock restarted) or a gap of seconds is no interval.
                if dt > 0.0 && dt < 1e6 {
                    self.span_us += dt;
                    let ms = dt * 1e-3;
                    self.intervals.push(ms);
                    self.sum += ms;
                    self.sum2 += ms * ms;
                }
            }
            newest = Some(s.t_us);
        }
        if let (Some(t_us), Some(origin)) = (newest, conn.time_origin_ms) {
            // The page's t_us is its event time since its origin, modulo 2³² µs.
            let wrap = 4_294_967.296;
            let since = wall_ms - origin;
            let mut event = t_us as f64 * 1e-3;
            event += ((since - event) / wrap).round() * wrap;
            let latency = since - event;
            if latency.is_finite() && (-60_000.0..60_000.0).contains(&latency) {
                self.latencies.push(latency);
            }
        }
    }

    pub fn report(&self) -> PhoneReport {
        let n = self.intervals.seen as f64;
        let jitter = if n > 1.0 {
            let mean = self.sum / n;
            (self.sum2 / n - mean * mean).max(0.0).sqrt()
        } else {
            0.0
        };
        PhoneReport {
            connections: self.connections,
            refused: self.refused.clone(),
            messages: self.messages,
            bytes: self.bytes,
            ignored_text: self.ignored_text,
            samples: self.samples,
            rate_hz: if self.span_us > 0.0 {
                self.intervals.seen as f64 / (self.span_us * 1e-6)
            } else {
                0.0
            },
            interval_ms: self.intervals.summary(),
            jitter_ms: jitter,
            arrival_interval_ms: self.arrivals.summary(),
            latency_ms: self.latencies.summary(),
            user_agent: self.user_agent.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use device_protocol::PhoneSample;

    fn frames(ts: &[u32]) -> Vec<u8> {
        let mut out = Vec::new();
        for (i, &t_us) in ts.iter().enumerate() {
            Packet::PhoneSample(PhoneSample {
                t_us,
                acc: [0; 3],
                gyro: [0; 3],
                mag: [0; 3],
            })
            .encode(i as u8, &mut out);
        }
        out
    }

    #[test]
    fn rate_and_jitter_come_from_the_samples_timestamps() {
        let mut s = Stats::default();
        let mut c = Conn::default();
        // 16 ms and 18 ms alternating: 17 ms mean, 1 ms standard deviation.
        let ts: Vec<u32> = (0..101u32)
            .map(|i| 1000 + i * 17_000 + (i % 2) * 1000)
            .collect();
        let b = frames(&ts);
        s.message(&mut c, &b[..b.len() / 2]);
        s.message(&mut c, &b[b.len() / 2..]);
        let r = s.report();
        assert_eq!(r.samples, 101);
        assert!((r.rate_hz - 1000.0 / 17.0).abs() < 0.5, "{}", r.rate_hz);
        assert!((r.jitter_ms - 1.0).abs() < 0.05, "{}", r.jitter_ms);
        assert_eq!(r.interval_ms.n, 100);
        assert_eq!(r.arrival_interval_ms.n, 1);
    }

    #[test]
    fn thinning_keeps_an_even_sample() {
        let mut t = Thinned::default();
        for i in 0..(KEEP as u64 * 4) {
            t.push(i as f64);
        }
        assert!(t.v.len() <= KEEP);
        let p = t.summary();
        let mid = KEEP as f64 * 2.0;
        assert!((p.p50 - mid).abs() / mid < 0.01, "{}", p.p50);
    }
}
