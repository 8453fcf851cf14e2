//! What the phone link measured: the page's sampling (rate and jitter, from the samples' own
//! timestamps), how the messages arrived, the latency from a sensor event to the daemon, and
//! what was refused (`report.json` `phone`).

use crate::percentiles::Percentiles;
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
    /// Requests from an address that failed too often, answered 429 at once (with
    /// `Retry-After`) without looking at their token.
    pub slowed: u64,
    /// A second phone while one was streaming (409).
    pub busy: u64,
    /// Plain HTTP on the HTTPS port.
    pub plain_http: u64,
    /// Connections closed for a message over the size limit (1009).
    pub oversized: u64,
    /// Connections closed for a text message (1003: the page sends binary frames only).
    pub text: u64,
    /// TLS handshakes that failed or did not finish in time (a client that does not accept
    /// the certificate, or one that holds a connection open without a handshake).
    pub tls: u64,
    /// Requests whose `Host` does not name this server (421).
    pub host: u64,
    /// Connections without the token let go to make room for others (the phone's never for
    /// a guest's).
    pub let_go: u64,
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
    /// A silent phone's stream replaced by a new connection with the token (a phone that
    /// reconnected).
    pub takeovers: u64,
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
    /// clock), ms: only from connections whose clock agrees with the daemon's
    /// (`clock_offset_ms` within ±[`CLOCK_TOLERANCE_MS`]); never negative.
    pub latency_ms: Percentiles,
    /// The daemon's clock minus the page's when the last WebSocket opened, ms (the page's
    /// clock as it sent its address, so a one-way delay is in it): beyond
    /// ±[`CLOCK_TOLERANCE_MS`] the clocks disagree and no latency is measured.
    pub clock_offset_ms: Option<f64>,
    /// The last page's browser (its `User-Agent`, at most [`USER_AGENT_CHARS`] characters,
    /// control characters escaped).
    pub user_agent: Option<String>,
}

/// How far the page's clock may be from the daemon's for its latencies to be measured, ms.
pub const CLOCK_TOLERANCE_MS: f64 = 250.0;
/// The longest user agent kept, characters.
pub const USER_AGENT_CHARS: usize = 200;

/// A browser's `User-Agent` as kept: at most [`USER_AGENT_CHARS`] characters, control and
/// other invisible characters escaped (`\u{1b}`), so that it prints safely in a log, a report
/// or a page.
pub fn user_agent(raw: &str) -> String {
    let invisible =
        |c: char| c.is_control() || matches!(c, '\u{200b}'..='\u{200f}' | '\u{2028}'..='\u{202e}');
    raw.chars()
        .flat_map(|c| {
            let escaped = invisible(c).then(|| c.escape_unicode());
            let plain = (!invisible(c)).then_some(c);
            escaped.into_iter().flatten().chain(plain)
        })
        .take(USER_AGENT_CHARS)
        .collect()
}

/// The running statistics.
#[derive(Debug, Default)]
pub struct Stats {
    pub refused: Refused,
    pub connections: u64,
    messages: u64,
    bytes: u64,
    pub takeovers: u64,
    pub clock_offset_ms: Option<f64>,
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
    /// `performance.timeOrigin` of the page, ms since the Unix epoch (from its WebSocket's
    /// address), when its clock agrees with the daemon's.
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
            if latency.is_finite() && (0.0..60_000.0).contains(&latency) {
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
            takeovers: self.takeovers,
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
            clock_offset_ms: self.clock_offset_ms,
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
    fn user_agents_are_bounded_and_escaped() {
        assert_eq!(user_agent("Mozilla/5.0 (X11)"), "Mozilla/5.0 (X11)");
        assert_eq!(user_agent("a\u{1b}[31mb\nc"), "a\\u{1b}[31mb\\u{a}c");
        assert_eq!(
            user_agent(&"x".repeat(10_000)).chars().count(),
            USER_AGENT_CHARS
        );
        assert!(!user_agent(&"\u{7}".repeat(500))
            .chars()
            .any(char::is_control));
        assert!(user_agent(&"\u{7}".repeat(500)).chars().count() <= USER_AGENT_CHARS);
    }

    #[test]
    fn a_latency_never_goes_negative() {
        let mut s = Stats::default();
        let mut c = Conn::default();
        let now_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64()
            * 1e3;
        // A page whose origin puts its samples 1.5 s in the daemon's future.
        c.time_origin_ms = Some(now_ms - 10_000.0);
        s.message(&mut c, &frames(&[11_500_000]));
        assert_eq!(s.report().latency_ms.n, 0);
        c.time_origin_ms = Some(now_ms - 10_000.0);
        s.message(&mut c, &frames(&[9_990_000]));
        let l = s.report().latency_ms;
        assert_eq!(l.n, 1);
        assert!(l.p50 >= 0.0 && l.p50 < 1000.0, "{}", l.p50);
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
