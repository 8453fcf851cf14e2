//! The phone port's connection slots: how many connections it holds, and whom it lets go when
//! they run out, so that nobody without the token can keep the phone out.
//!
//! Anyone who can reach the port can open connections to it; the phone is one of them, and
//! until a connection has shown the token (a request carrying it, in the address or the page's
//! cookie) nothing tells them apart. So:
//! - A connection that has not shown the token is a *guest*. Guests hold at most
//!   [`GUEST_SLOTS`]; the other [`PHONE_SLOTS`] are kept for connections that showed it.
//! - One address holds at most [`PER_ADDRESS`] guests: a new one from an address at its share
//!   lets that address's own least active guest go.
//! - When the guests' slots are full, a new guest does not wait and is not refused: the guest
//!   that has done least is let go: one that has sent nothing for [`GRACE`] first, then one
//!   from the address that holds most guests (a phone holds one or two: its page's first
//!   request shows the token), else the one whose last step (its connection, a handshake step,
//!   a request) is oldest, passing over any whose bytes wait unread (it is speaking now). A phone speaks within a round trip of
//!   its connection and completes its handshake within a few; connections opened and left
//!   idle, however fast they are reopened, go before it.
//! - An address that showed the token lately (the phone's; the last [`TRUSTED`] of them) is
//!   trusted: its guests (the page reconnecting after a screen lock, its next request) go
//!   only after every other guest, within its share of [`PER_ADDRESS`].
//! - A connection that shows the token becomes the phone's. A guest never takes its slot; the
//!   phone's own are let go only for the phone's (its idlest keep-alive first; the streaming
//!   WebSocket never).
//!
//! Deadlines (the TLS handshake, each request head) are the server's: a slot is held only as
//! long as they allow, and only while nobody needs it more.
//!
//! ```
//! use sfs::source::phone::slots::{Slots, GUEST_SLOTS};
//! use std::net::IpAddr;
//! let slots = Slots::new();
//! let attacker: IpAddr = "127.0.0.2".parse().unwrap();
//! let idle: Vec<_> = (0..GUEST_SLOTS).map(|i| slots.admit(IpAddr::from([127, 0, 1, i as u8]))).collect();
//! let phone = slots.admit("127.0.0.9".parse().unwrap());
//! phone.progress(); // its ClientHello
//! assert_eq!(slots.evicted(), 1); // the oldest silent guest went for it
//! assert!(phone.promote());
//! let more: Vec<_> = (0..200).map(|_| slots.admit(attacker)).collect();
//! assert!(!phone.was_let_go());
//! # drop((idle, more));
//! ```

use std::collections::HashMap;
use std::net::IpAddr;
use std::os::fd::RawFd;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::Notify;

/// Connections at once, guests and the phone's.
pub const MAX_CONNECTIONS: usize = 64;
/// Slots only the token holder's connections take (a browser opens at most 6 connections to a
/// host, plus the WebSocket).
pub const PHONE_SLOTS: usize = 16;
/// Slots guests share.
pub const GUEST_SLOTS: usize = MAX_CONNECTIONS - PHONE_SLOTS;
/// Guests one address holds at once: a dozen addresses are needed to fill the guests' slots
/// (a phone's page and its scripts show the token with their first request).
pub const PER_ADDRESS: usize = 4;
/// Addresses remembered for having shown the token.
pub const TRUSTED: usize = 8;
/// A connection is not counted silent before this: a client's first bytes (a ClientHello)
/// follow its connection within a round trip.
pub const GRACE: Duration = Duration::from_millis(250);

/// How far a connection has come.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Stage {
    /// Accepted, nothing received.
    Silent,
    /// A guest that has sent something (a handshake, a request without the token).
    Talking,
    /// Has shown the token.
    Phone,
    /// The phone's streaming WebSocket.
    Streaming,
}

#[derive(Debug)]
struct Entry {
    ip: IpAddr,
    /// The connection's socket, to look for bytes waiting in it (`None` in unit tests).
    fd: Option<RawFd>,
    stage: Stage,
    last: Instant,
    kick: Arc<Notify>,
    let_go: bool,
}

/// The registry of the port's connections (see the module documentation).
#[derive(Debug, Default)]
pub struct Slots {
    inner: Mutex<Inner>,
    evicted: AtomicU64,
}

#[derive(Debug, Default)]
struct Inner {
    next: u64,
    conns: HashMap<u64, Entry>,
    /// The addresses that showed the token lately (at most [`TRUSTED`], the latest last).
    trusted: Vec<IpAddr>,
}

impl Inner {
    /// Lets go, among the connections `among` admits, the one that has done least: one that
    /// has sent nothing for [`GRACE`] first, then one from the address holding most guests,
    /// then the one whose last step (its connection, a handshake step, a request) is oldest.
    /// A candidate whose bytes wait unread in its socket (its task has not run since they came)
    /// is speaking now: it is passed over, unless its address holds over half its share.
    fn let_go(&mut self, among: impl Fn(&Entry) -> bool) -> bool {
        let now = Instant::now();
        let trusted = std::mem::take(&mut self.trusted);
        let mut speaking = Vec::new();
        let mut per_ip: HashMap<IpAddr, usize> = HashMap::new();
        for e in self.conns.values() {
            if !e.let_go && e.stage < Stage::Phone {
                *per_ip.entry(e.ip).or_default() += 1;
            }
        }
        loop {
            let victim = self
                .conns
                .iter()
                .filter(|(id, e)| !e.let_go && among(e) && !speaking.contains(*id))
                .min_by_key(|(id, e)| {
                    let rank = match e.stage {
                        Stage::Silent | Stage::Talking if trusted.contains(&e.ip) => 2,
                        Stage::Silent if now.duration_since(e.last) >= GRACE => 0,
                        Stage::Silent | Stage::Talking => 1,
                        Stage::Phone => 3,
                        Stage::Streaming => 4,
                    };
                    let crowd = per_ip.get(&e.ip).copied().unwrap_or(0);
                    (rank, std::cmp::Reverse(crowd), e.last, **id)
                })
                .map(|(id, _)| *id);
            let Some(id) = victim else {
                self.trusted = trusted;
                return false;
            };
            let e = self.conns.get_mut(&id).expect("a connection just found");
            let crowded = per_ip.get(&e.ip).is_some_and(|&n| n > PER_ADDRESS / 2);
            if !crowded && e.fd.is_some_and(bytes_waiting) {
                e.stage = e.stage.max(Stage::Talking);
                e.last = now;
                speaking.push(id);
                continue;
            }
            // Out of the count at once; the connection's task drops its slot soon after.
            e.let_go = true;
            e.kick.notify_one();
            self.trusted = trusted;
            return true;
        }
    }

    fn live(&self, guest: bool) -> usize {
        self.conns
            .values()
            .filter(|e| !e.let_go && (e.stage < Stage::Phone) == guest)
            .count()
    }
}

impl Slots {
    pub fn new() -> Arc<Slots> {
        Arc::new(Slots::default())
    }

    /// A slot for a connection just accepted from `ip`, as a guest; guests let go to make room
    /// are told through their [`Slot::let_go`].
    pub fn admit(self: &Arc<Self>, ip: IpAddr) -> Slot {
        self.admit_socket(ip, None)
    }

    /// [`Slots::admit`] for the accepted socket `fd`: while it is counted silent, the bytes
    /// waiting in it say it is not. (Looked at only while the slot lives; were the descriptor closed
    /// and reused meanwhile, a connection would only be ranked wrong.)
    pub fn admit_socket(self: &Arc<Self>, ip: IpAddr, fd: Option<RawFd>) -> Slot {
        let mut inner = lock(&self.inner);
        let mut evicted = 0;
        let from_ip = inner
            .conns
            .values()
            .filter(|e| !e.let_go && e.ip == ip && e.stage < Stage::Phone)
            .count();
        if from_ip >= PER_ADDRESS && inner.let_go(|e| e.ip == ip && e.stage < Stage::Phone) {
            evicted += 1;
        }
        while inner.live(true) >= GUEST_SLOTS && inner.let_go(|e| e.stage < Stage::Phone) {
            evicted += 1;
        }
        let id = inner.next;
        inner.next += 1;
        let kick = Arc::new(Notify::new());
        inner.conns.insert(
            id,
            Entry {
                ip,
                fd,
                stage: Stage::Silent,
                last: Instant::now(),
                kick: kick.clone(),
                let_go: false,
            },
        );
        drop(inner);
        self.evicted.fetch_add(evicted, Ordering::Relaxed);
        Slot {
            slots: self.clone(),
            id,
            kick,
        }
    }

    /// Connections let go so far to make room.
    pub fn evicted(&self) -> u64 {
        self.evicted.load(Ordering::Relaxed)
    }

    /// Connections held now: guests and the phone's (those let go but not yet closed aside).
    pub fn held(&self) -> (usize, usize) {
        let inner = lock(&self.inner);
        (inner.live(true), inner.live(false))
    }
}

/// One connection's slot, freed when dropped (shared by the connection and, after an upgrade,
/// its WebSocket).
#[derive(Debug)]
pub struct Slot {
    slots: Arc<Slots>,
    id: u64,
    kick: Arc<Notify>,
}

impl Slot {
    fn with<R>(&self, f: impl FnOnce(&mut Inner, u64) -> R) -> R {
        f(&mut lock(&self.slots.inner), self.id)
    }

    /// The connection did its next step (a byte, the handshake, a request).
    pub fn progress(&self) {
        self.with(|inner, id| {
            if let Some(e) = inner.conns.get_mut(&id).filter(|e| !e.let_go) {
                e.last = Instant::now();
                e.stage = e.stage.max(Stage::Talking);
            }
        });
    }

    /// The connection showed the token: the phone's from now on. False when it had already
    /// been let go.
    pub fn promote(&self) -> bool {
        let (ok, evicted) = self.with(|inner, id| {
            match inner.conns.get_mut(&id) {
                Some(e) if !e.let_go => {
                    e.last = Instant::now();
                    if e.stage >= Stage::Phone {
                        return (true, 0);
                    }
                    e.stage = Stage::Phone;
                }
                _ => return (false, 0),
            }
            let ip = inner.conns[&id].ip;
            inner.trusted.retain(|&t| t != ip);
            if inner.trusted.len() >= TRUSTED {
                inner.trusted.remove(0);
            }
            inner.trusted.push(ip);
            let mut evicted = 0;
            while inner.live(false) > PHONE_SLOTS && inner.let_go(|e| e.stage == Stage::Phone) {
                evicted += 1;
            }
            (true, evicted)
        });
        self.slots.evicted.fetch_add(evicted, Ordering::Relaxed);
        ok && !self.was_let_go()
    }

    /// The phone's WebSocket streams on this connection: never let go.
    pub fn streaming(&self) {
        self.with(|inner, id| {
            if let Some(e) = inner.conns.get_mut(&id).filter(|e| !e.let_go) {
                e.stage = Stage::Streaming;
            }
        });
    }

    /// Whether this connection was let go to make room.
    pub fn was_let_go(&self) -> bool {
        self.with(|inner, id| inner.conns.get(&id).is_none_or(|e| e.let_go))
    }

    /// Completes when the connection is let go to make room.
    pub async fn let_go(&self) {
        self.kick.notified().await;
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let id = self.id;
        lock(&self.slots.inner).conns.remove(&id);
    }
}

/// Whether bytes wait unread in the socket `fd` (`FIONREAD`).
fn bytes_waiting(fd: RawFd) -> bool {
    let mut n: libc::c_int = 0;
    // SAFETY: FIONREAD writes one int; a descriptor no longer open gives an error.
    unsafe { libc::ioctl(fd, libc::FIONREAD, &mut n) == 0 && n > 0 }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(a: u8, b: u8) -> IpAddr {
        IpAddr::from([10, 0, a, b])
    }

    /// Makes every connection held now `by` older.
    fn age(slots: &Slots, by: Duration) {
        for e in lock(&slots.inner).conns.values_mut() {
            e.last -= by;
        }
    }

    #[test]
    fn silent_guests_go_first_and_one_speaking_is_passed_over() {
        let slots = Slots::new();
        // The guests' slots full of connections silent past the grace, but one that spoke.
        let silent: Vec<_> = (0..GUEST_SLOTS - 1)
            .map(|i| slots.admit(ip(1, i as u8)))
            .collect();
        let spoke = slots.admit(ip(9, 9));
        spoke.progress();
        age(&slots, GRACE * 2);
        // New connections let the silent ones go, oldest first, not the one that spoke.
        let young: Vec<_> = (0..GUEST_SLOTS - 1)
            .map(|i| slots.admit(ip(2, i as u8)))
            .collect();
        assert!(silent.iter().all(Slot::was_let_go));
        assert!(!spoke.was_let_go() && young.iter().all(|s| !s.was_let_go()));
        assert_eq!(slots.evicted(), (GUEST_SLOTS - 1) as u64);
        // Bytes waiting in a connection's socket: it is speaking, whatever its task has seen.
        let (mut a, b) = std::os::unix::net::UnixStream::pair().unwrap();
        std::io::Write::write_all(&mut a, &[0x16]).unwrap();
        let hello = slots.admit_socket(ip(9, 8), Some(std::os::fd::AsRawFd::as_raw_fd(&b)));
        age(&slots, GRACE * 2);
        let flood: Vec<_> = (0..1000u32)
            .map(|i| slots.admit(ip(3 + (i / 250) as u8, i as u8)))
            .collect();
        assert!(!hello.was_let_go());
        assert_eq!(slots.held().0, GUEST_SLOTS);
        drop((flood, young, spoke));
    }

    #[test]
    fn the_phone_never_goes_for_a_guest() {
        let slots = Slots::new();
        let phone = slots.admit(ip(9, 9));
        assert!(phone.promote());
        let mut flood = Vec::new();
        for i in 0..2000u32 {
            let s = slots.admit(ip((i % 250) as u8, (i / 250) as u8));
            if i % 2 == 0 {
                s.progress();
            }
            flood.push(s);
        }
        assert!(!phone.was_let_go());
        assert_eq!(slots.held(), (GUEST_SLOTS, 1));
    }

    #[test]
    fn one_address_holds_its_share_of_guests() {
        let slots = Slots::new();
        let a = ip(1, 1);
        let first: Vec<_> = (0..PER_ADDRESS).map(|_| slots.admit(a)).collect();
        let other = slots.admit(ip(1, 2));
        let again = slots.admit(a);
        assert!(first[0].was_let_go() && !other.was_let_go() && !again.was_let_go());
        assert_eq!(slots.held().0, PER_ADDRESS + 1);
    }

    #[test]
    fn the_phones_own_make_room_for_the_phone_but_never_its_stream() {
        let slots = Slots::new();
        let ws = slots.admit(ip(9, 9));
        assert!(ws.promote());
        ws.streaming();
        let mut keep = Vec::new();
        for _ in 0..PHONE_SLOTS * 3 {
            let s = slots.admit(ip(9, 9));
            assert!(s.promote());
            keep.push(s);
        }
        assert!(!ws.was_let_go());
        assert_eq!(slots.held().1, PHONE_SLOTS);
        // A slot let go is freed when its connection drops it.
        keep.clear();
        assert_eq!(slots.held(), (0, 1));
        drop(ws);
        assert_eq!(slots.held(), (0, 0));
    }
}
