//! A network impairment relay for tests and demos (issue 18 §7): loopback
//! never loses, delays or reorders anything, so the paths that handle a real
//! network's do not run there. [`Relay`] is a UDP relay on 127.0.0.1 between
//! one client and a server; every datagram, both ways, goes through a
//! [`Link`] that drops, delays, jitters, reorders and rate-limits it, seeded
//! so that a run can be repeated.
//!
//! The parameters follow Linux `netem`'s (`tc-netem(8)`), with one
//! difference: `loss` is the chance a datagram is dropped; each other
//! datagram is delayed by `delay` ± up to `jitter` (uniform) but never
//! leaves before one sent ahead of it. A path's jitter is queueing delay
//! that varies, and a queue keeps order; netem's jitter instead reorders
//! datagrams closer than the jitter, which at a video stream's thousands of
//! datagrams a second is a reordering hundreds deep that no real path shows
//! (and that QUIC's loss detection takes for loss). Reordering is its own
//! knob: `reorder` is the chance a datagram skips the delay and leaves at
//! once, ahead of those delayed (netem's). `rate` serialises datagrams onto
//! a link of that many bits per second before the delay; `limit` bounds the
//! datagrams held (more are dropped, as a full router queue drops them).
//!
//! [`Link`] is sans-IO (it takes `now`, as quinn-proto does) and tested on
//! a fake clock; [`Relay`] moves the bytes.

use std::collections::BinaryHeap;
use std::net::SocketAddr;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use bytes::Bytes;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use tokio::net::UdpSocket;
use tokio::time::Instant;

/// What a [`Link`] does to the datagrams through it (`--impair`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Impairment {
    /// Chance a datagram is dropped, 0..=1.
    pub loss: f64,
    /// Base one-way delay.
    pub delay: Duration,
    /// Each datagram's delay varies uniformly within ± this, in order.
    pub jitter: Duration,
    /// Chance a datagram skips the delay, 0..=1.
    pub reorder: f64,
    /// Link rate in bits per second (`None`: unlimited).
    pub rate_bps: Option<u64>,
    /// Most datagrams held at once; more are dropped.
    pub limit: usize,
    /// Seed of the random choices.
    pub seed: u64,
}

/// The longest delay or jitter a [`Link`] applies (a larger one is cut to
/// this).
pub const MAX_DELAY: Duration = Duration::from_secs(3600);

impl Impairment {
    /// The same impairment with every field inside what a link can apply:
    /// chances clamped to 0..=1 (NaN: 0), delay and jitter to
    /// [`MAX_DELAY`], a rate of at least 1 bit/s. The command line refuses
    /// values outside these; a library caller gets them clamped, never a
    /// panic in the link.
    pub fn bounded(self) -> Self {
        let chance = |p: f64| if p.is_nan() { 0.0 } else { p.clamp(0.0, 1.0) };
        Self {
            loss: chance(self.loss),
            reorder: chance(self.reorder),
            delay: self.delay.min(MAX_DELAY),
            jitter: self.jitter.min(MAX_DELAY),
            rate_bps: self.rate_bps.map(|r| r.max(1)),
            ..self
        }
    }
}

impl Default for Impairment {
    /// A perfect link: nothing dropped or delayed (netem's queue limit).
    fn default() -> Self {
        Self {
            loss: 0.0,
            delay: Duration::ZERO,
            jitter: Duration::ZERO,
            reorder: 0.0,
            rate_bps: None,
            limit: 1000,
            seed: 1,
        }
    }
}

/// An `--impair` value that cannot be used.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ImpairParseError {
    /// Not `key=value`.
    #[error("`{0}` is not key=value")]
    NotKeyValue(String),
    /// A key this relay does not know.
    #[error("unknown impairment `{0}` (loss, delay, jitter, reorder, rate, limit, seed)")]
    UnknownKey(String),
    /// A value that does not parse or is out of range.
    #[error("{key}: `{value}` {why}")]
    BadValue {
        /// The key.
        key: String,
        /// The value given.
        value: String,
        /// What is expected.
        why: &'static str,
    },
}

impl FromStr for Impairment {
    type Err = ImpairParseError;

    /// Parses `loss=10%,delay=30ms,jitter=20ms,reorder=1%,rate=50mbit,limit=1000,seed=7`
    /// (any subset, any order).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut imp = Impairment::default();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| ImpairParseError::NotKeyValue(part.into()))?;
            let bad = |why| ImpairParseError::BadValue {
                key: key.into(),
                value: value.into(),
                why,
            };
            match key {
                "loss" => imp.loss = parse_fraction(value).ok_or_else(|| bad("is not 0..100%"))?,
                "reorder" => {
                    imp.reorder = parse_fraction(value).ok_or_else(|| bad("is not 0..100%"))?
                }
                "delay" => imp.delay = parse_duration(value).ok_or_else(|| bad(DURATION))?,
                "jitter" => imp.jitter = parse_duration(value).ok_or_else(|| bad(DURATION))?,
                "rate" => {
                    imp.rate_bps = Some(parse_rate(value).ok_or_else(|| {
                        bad("is not a rate above 0 (e.g. 800kbit, 50mbit, 1gbit)")
                    })?)
                }
                "limit" => {
                    imp.limit = value
                        .parse()
                        .ok()
                        .filter(|&n| n > 0)
                        .ok_or_else(|| bad("is not a count above 0"))?
                }
                "seed" => imp.seed = value.parse().map_err(|_| bad("is not an integer"))?,
                _ => return Err(ImpairParseError::UnknownKey(key.into())),
            }
        }
        Ok(imp)
    }
}

const DURATION: &str = "is not a duration up to an hour (e.g. 30ms, 1.5s, 500us)";

/// `10%`, or a fraction `0.1`, within 0..=1.
fn parse_fraction(s: &str) -> Option<f64> {
    let v = match s.strip_suffix('%') {
        Some(p) => p.trim().parse::<f64>().ok()? / 100.0,
        None => s.parse::<f64>().ok()?,
    };
    (0.0..=1.0).contains(&v).then_some(v)
}

/// `30ms`, `1.5s`, `500us`, up to an hour.
fn parse_duration(s: &str) -> Option<Duration> {
    let (number, unit) = split_unit(s);
    let scale = match unit {
        "us" => 1e-6,
        "ms" => 1e-3,
        "s" => 1.0,
        _ => return None,
    };
    let secs = number.parse::<f64>().ok()? * scale;
    (0.0..=3600.0)
        .contains(&secs)
        .then(|| Duration::from_secs_f64(secs))
}

/// `800kbit`, `50mbit`, `1gbit`, `9600bit`: bits per second, above 0.
fn parse_rate(s: &str) -> Option<u64> {
    let (number, unit) = split_unit(s);
    let scale = match unit.to_ascii_lowercase().as_str() {
        "bit" => 1.0,
        "kbit" => 1e3,
        "mbit" => 1e6,
        "gbit" => 1e9,
        _ => return None,
    };
    let bps = number.parse::<f64>().ok()? * scale;
    (1.0..=1e12).contains(&bps).then_some(bps as u64)
}

/// Splits `12.5ms` into `("12.5", "ms")`.
fn split_unit(s: &str) -> (&str, &str) {
    let at = s
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(s.len());
    (&s[..at], s[at..].trim())
}

/// Counters of one direction of a link.
#[derive(Debug, Default)]
pub struct LinkStats {
    /// Datagrams delivered.
    pub delivered: AtomicU64,
    /// Datagrams dropped by `loss`.
    pub lost: AtomicU64,
    /// Datagrams dropped because `limit` were held.
    pub overflowed: AtomicU64,
}

impl LinkStats {
    /// (delivered, lost, overflowed).
    pub fn snapshot(&self) -> (u64, u64, u64) {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        (get(&self.delivered), get(&self.lost), get(&self.overflowed))
    }
}

/// A datagram held until it is due.
#[derive(Debug, PartialEq, Eq)]
struct Held {
    due: Duration,
    /// Arrival order: equal due times leave in it.
    seq: u64,
    bytes: Bytes,
}

impl Ord for Held {
    /// Reversed, for a min-heap on (due, seq).
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.due, other.seq).cmp(&(self.due, self.seq))
    }
}

impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// One direction of an impaired link (sans-IO): datagrams go in with
/// [`Link::send`] and come out of [`Link::poll`] when due. Times are
/// durations since any fixed origin.
#[derive(Debug)]
pub struct Link {
    imp: Impairment,
    rng: StdRng,
    held: BinaryHeap<Held>,
    seq: u64,
    /// When the rate-limited link is free to serialise the next datagram.
    free_at: Duration,
    /// When the last delayed datagram is due: a later one is not due
    /// before it (jitter keeps order).
    last_due: Duration,
    stats: Arc<LinkStats>,
}

impl Link {
    /// A link applying `imp`, its random choices seeded by `imp.seed` and
    /// `stream` (so two directions differ).
    pub fn new(imp: Impairment, stream: u64) -> Self {
        let imp = imp.bounded();
        Self {
            imp,
            rng: StdRng::seed_from_u64(imp.seed ^ stream.wrapping_mul(0x9e37_79b9_7f4a_7c15)),
            held: BinaryHeap::new(),
            seq: 0,
            free_at: Duration::ZERO,
            last_due: Duration::ZERO,
            stats: Arc::default(),
        }
    }

    /// Its counters.
    pub fn stats(&self) -> Arc<LinkStats> {
        self.stats.clone()
    }

    /// A datagram enters the link at `now`.
    pub fn send(&mut self, now: Duration, bytes: Bytes) {
        if self.held.len() >= self.imp.limit {
            self.stats.overflowed.fetch_add(1, Ordering::Relaxed);
            return;
        }
        if self.imp.loss > 0.0 && self.rng.random_bool(self.imp.loss) {
            self.stats.lost.fetch_add(1, Ordering::Relaxed);
            return;
        }
        // Serialised onto the link at its rate, then delayed.
        let sent = match self.imp.rate_bps {
            Some(bps) => {
                let on_wire = Duration::from_secs_f64(bytes.len() as f64 * 8.0 / bps as f64);
                self.free_at = self.free_at.max(now) + on_wire;
                self.free_at
            }
            None => now,
        };
        let immediate = self.imp.reorder > 0.0 && self.rng.random_bool(self.imp.reorder);
        let due = if immediate {
            sent
        } else {
            let delay = if self.imp.jitter.is_zero() {
                self.imp.delay
            } else {
                let j = self.imp.jitter.as_secs_f64();
                let d = self.imp.delay.as_secs_f64() + self.rng.random_range(-j..=j);
                Duration::from_secs_f64(d.max(0.0))
            };
            self.last_due = self.last_due.max(sent + delay);
            self.last_due
        };
        self.seq += 1;
        self.held.push(Held {
            due,
            seq: self.seq,
            bytes,
        });
    }

    /// When the next held datagram is due.
    pub fn next_due(&self) -> Option<Duration> {
        self.held.peek().map(|h| h.due)
    }

    /// The next datagram due at or before `now`.
    pub fn poll(&mut self, now: Duration) -> Option<Bytes> {
        if self.held.peek()?.due > now {
            return None;
        }
        self.stats.delivered.fetch_add(1, Ordering::Relaxed);
        self.held.pop().map(|h| h.bytes)
    }

    /// Datagrams held.
    pub fn held(&self) -> usize {
        self.held.len()
    }
}

/// A running impairment relay between one client and `upstream`: the
/// client sends to [`Relay::local_addr`] instead of the server. Stops when
/// dropped.
pub struct Relay {
    local: SocketAddr,
    /// Client → server counters.
    pub upstream: Arc<LinkStats>,
    /// Server → client counters.
    pub downstream: Arc<LinkStats>,
    task: tokio::task::JoinHandle<()>,
}

/// The largest UDP datagram.
const MAX_DATAGRAM: usize = 65_535;

impl Relay {
    /// Starts relaying between a new socket on 127.0.0.1 and `upstream`,
    /// impaired by `imp` both ways. Needs a tokio runtime.
    pub async fn start(upstream: SocketAddr, imp: Impairment) -> std::io::Result<Self> {
        let front = UdpSocket::bind(SocketAddr::from(([127, 0, 0, 1], 0))).await?;
        let back_bind: SocketAddr = if upstream.is_ipv6() {
            "[::]:0".parse().map_err(std::io::Error::other)?
        } else {
            SocketAddr::from(([0, 0, 0, 0], 0))
        };
        let back = UdpSocket::bind(back_bind).await?;
        back.connect(upstream).await?;
        let local = front.local_addr()?;
        let (up, down) = (Link::new(imp, 0), Link::new(imp, 1));
        tracing::info!(%local, %upstream, ?imp, "impairment relay started");
        let (up_stats, down_stats) = (up.stats(), down.stats());
        let task = tokio::spawn(relay(front, back, up, down));
        Ok(Self {
            local,
            upstream: up_stats,
            downstream: down_stats,
            task,
        })
    }

    /// Where the client sends.
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Moves datagrams: client → `up` → server, server → `down` → the client
/// last heard from.
async fn relay(front: UdpSocket, back: UdpSocket, mut up: Link, mut down: Link) {
    let origin = Instant::now();
    let now = || origin.elapsed();
    let mut client: Option<SocketAddr> = None;
    let (mut from_client, mut from_server) = (vec![0u8; MAX_DATAGRAM], vec![0u8; MAX_DATAGRAM]);
    loop {
        // Everything due leaves first.
        let t = now();
        while let Some(d) = up.poll(t) {
            let _ = back.send(&d).await;
        }
        while let Some(d) = down.poll(t) {
            if let Some(c) = client {
                let _ = front.send_to(&d, c).await;
            }
        }
        let next = [up.next_due(), down.next_due()].into_iter().flatten().min();
        let wake = async {
            match next {
                Some(due) => tokio::time::sleep_until(origin + due).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            r = front.recv_from(&mut from_client) => match r {
                Ok((n, addr)) => {
                    client = Some(addr);
                    up.send(now(), Bytes::copy_from_slice(&from_client[..n]));
                }
                Err(e) => tracing::debug!("relay: from the client: {e}"),
            },
            r = back.recv(&mut from_server) => match r {
                Ok(n) => down.send(now(), Bytes::copy_from_slice(&from_server[..n])),
                // An ICMP "port unreachable" while the server is down.
                Err(e) => tracing::debug!("relay: from the server: {e}"),
            },
            () = wake => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    /// Datagram `i` as 8 bytes (its number) padded to `len`.
    fn datagram(i: u64, len: usize) -> Bytes {
        let mut b = i.to_le_bytes().to_vec();
        b.resize(len.max(8), 0);
        b.into()
    }

    fn number(b: &Bytes) -> u64 {
        u64::from_le_bytes(b[..8].try_into().unwrap())
    }

    /// Sends `n` datagrams one every `spacing` and drains the link on a
    /// fake clock in 0.1 ms steps: (number, sent, delivered) per datagram out.
    fn run(
        imp: Impairment,
        n: u64,
        spacing: Duration,
        len: usize,
    ) -> Vec<(u64, Duration, Duration)> {
        let mut link = Link::new(imp, 0);
        let step = Duration::from_micros(100);
        let mut out = vec![];
        let mut t = Duration::ZERO;
        let mut next = 0u64;
        while next < n || link.held() > 0 {
            while next < n && spacing * next as u32 <= t {
                link.send(t, datagram(next, len));
                next += 1;
            }
            while let Some(d) = link.poll(t) {
                let i = number(&d);
                out.push((i, spacing * i as u32, t));
            }
            t += step;
        }
        out
    }

    #[test]
    fn impairments_parse_with_units_and_refuse_nonsense() {
        let imp: Impairment =
            "loss=10%,delay=30ms,jitter=20ms,reorder=0.5%,rate=50mbit,limit=64,seed=7"
                .parse()
                .unwrap();
        assert_eq!(
            imp,
            Impairment {
                loss: 0.1,
                delay: 30 * MS,
                jitter: 20 * MS,
                reorder: 0.005,
                rate_bps: Some(50_000_000),
                limit: 64,
                seed: 7,
            }
        );
        assert_eq!("".parse::<Impairment>().unwrap(), Impairment::default());
        assert_eq!(
            "delay=1.5s".parse::<Impairment>().unwrap().delay,
            Duration::from_millis(1500)
        );
        assert!(matches!(
            "lose=1%".parse::<Impairment>(),
            Err(ImpairParseError::UnknownKey(_))
        ));
        assert!(matches!(
            "loss".parse::<Impairment>(),
            Err(ImpairParseError::NotKeyValue(_))
        ));
        for bad in [
            "loss=150%",
            "loss=-1%",
            "delay=30",
            "delay=2h",
            "jitter=xms",
            "rate=0mbit",
            "rate=5mb",
            "limit=0",
            "seed=-1",
        ] {
            let e = bad.parse::<Impairment>().unwrap_err();
            assert!(matches!(e, ImpairParseError::BadValue { .. }), "{bad}: {e}");
        }
    }

    #[test]
    fn out_of_range_impairments_are_clamped_not_a_panic() {
        for (loss, reorder) in [(f64::NAN, 2.0), (-1.0, f64::NAN), (7.0, -3.0)] {
            let imp = Impairment {
                loss,
                reorder,
                delay: Duration::MAX,
                jitter: Duration::MAX,
                rate_bps: Some(0),
                ..Impairment::default()
            };
            let b = imp.bounded();
            assert!((0.0..=1.0).contains(&b.loss) && (0.0..=1.0).contains(&b.reorder));
            assert_eq!(
                (b.delay, b.jitter, b.rate_bps),
                (MAX_DELAY, MAX_DELAY, Some(1))
            );
            // Datagrams go through the link without a panic, and none is
            // due before its 160 bits are on the wire at 1 bit/s.
            let mut link = Link::new(imp, 0);
            for i in 0..20 {
                link.send(MS * i, datagram(i.into(), 20));
            }
            assert!(link.poll(Duration::from_secs(60)).is_none());
            let on_wire = Duration::from_secs(160);
            assert!(link.next_due().is_none_or(|due| due >= on_wire));
        }
    }

    #[test]
    fn a_perfect_link_delivers_everything_at_once_in_order() {
        let out = run(Impairment::default(), 100, MS, 100);
        assert_eq!(out.len(), 100);
        for (k, &(i, sent, got)) in out.iter().enumerate() {
            assert_eq!(i, k as u64);
            assert!(got - sent < MS, "{i}: {got:?} after {sent:?}");
        }
    }

    #[test]
    fn loss_is_the_chance_given_and_repeats_with_the_seed() {
        let imp = Impairment {
            loss: 0.1,
            ..Impairment::default()
        };
        let out = run(imp, 20_000, Duration::from_micros(100), 16);
        let lost = 20_000 - out.len();
        assert!((1_800..=2_200).contains(&lost), "{lost} of 20000 lost");
        let again = run(imp, 20_000, Duration::from_micros(100), 16);
        assert_eq!(out, again, "the same seed, the same losses");
        let other = run(
            Impairment { seed: 2, ..imp },
            20_000,
            Duration::from_micros(100),
            16,
        );
        assert_ne!(out, other);
    }

    #[test]
    fn delay_and_jitter_bound_each_datagram_and_keep_order() {
        let imp = Impairment {
            delay: 30 * MS,
            jitter: 20 * MS,
            ..Impairment::default()
        };
        // Datagrams 5 ms apart: wider than the jitter's reach once it has
        // held one back, so delays spread over the whole range.
        let out = run(imp, 1000, 5 * MS, 100);
        assert_eq!(out.len(), 1000);
        let step = Duration::from_micros(100);
        for &(i, sent, got) in &out {
            let d = got - sent;
            assert!(d >= 10 * MS && d <= 50 * MS + step, "{i}: {d:?}");
        }
        assert!(out.windows(2).all(|w| w[1].0 > w[0].0), "in order");
        let delays: Vec<Duration> = out.iter().map(|&(_, s, g)| g - s).collect();
        assert!(delays.iter().any(|&d| d < 15 * MS) && delays.iter().any(|&d| d > 45 * MS));
        // Datagrams closer than the jitter queue behind a delayed one: still
        // in order, never more than delay + jitter late.
        let dense = run(imp, 5000, Duration::from_micros(100), 100);
        assert!(dense.windows(2).all(|w| w[1].0 > w[0].0));
        assert!(dense.iter().all(|&(_, s, g)| g - s <= 50 * MS + step));
        // Without jitter every datagram takes the delay.
        let plain = Impairment {
            jitter: Duration::ZERO,
            ..imp
        };
        let plain = run(plain, 1000, MS, 100);
        assert!(
            plain
                .iter()
                .all(|&(_, s, g)| g - s >= 30 * MS && g - s <= 30 * MS + step)
        );
    }

    #[test]
    fn reorder_sends_that_share_at_once_ahead_of_the_delayed() {
        let imp = Impairment {
            delay: 10 * MS,
            reorder: 0.25,
            ..Impairment::default()
        };
        let out = run(imp, 4000, MS, 100);
        let immediate = out.iter().filter(|&&(_, s, g)| g - s < MS).count();
        assert!((800..=1200).contains(&immediate), "{immediate} of 4000");
        assert!(out.windows(2).any(|w| w[1].0 < w[0].0));
    }

    #[test]
    fn rate_serialises_datagrams_and_limit_drops_the_excess() {
        // 100 datagrams of 1250 bytes (10 kbit) at 1 Mbit/s, all at once:
        // the last leaves after 1 s.
        let imp = Impairment {
            rate_bps: Some(1_000_000),
            ..Impairment::default()
        };
        let out = run(imp, 100, Duration::ZERO, 1250);
        assert_eq!(out.len(), 100);
        let last = out.last().unwrap().2;
        assert!(
            last >= Duration::from_millis(1000) && last <= Duration::from_millis(1001),
            "{last:?}"
        );
        assert!(
            out.windows(2)
                .all(|w| w[1].2 - w[0].2 >= Duration::from_micros(9_900))
        );
        // A queue of 10: the other 90 are dropped.
        let mut link = Link::new(Impairment { limit: 10, ..imp }, 0);
        for i in 0..100 {
            link.send(Duration::ZERO, datagram(i, 1250));
        }
        assert_eq!(link.held(), 10);
        assert_eq!(link.stats().snapshot(), (0, 0, 90));
    }

    /// The relay carries datagrams both ways between a client socket and a
    /// server socket, delayed as configured.
    #[tokio::test]
    async fn the_relay_carries_datagrams_both_ways() {
        let server = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let imp = Impairment {
            delay: 20 * MS,
            ..Impairment::default()
        };
        let relay = Relay::start(server.local_addr().unwrap(), imp)
            .await
            .unwrap();
        let client = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let t = std::time::Instant::now();
        client.send_to(b"ping", relay.local_addr()).await.unwrap();
        let mut buf = [0u8; 16];
        let (n, from) = server.recv_from(&mut buf).await.unwrap();
        assert_eq!(&buf[..n], b"ping");
        server.send_to(b"pong", from).await.unwrap();
        let (n, from) = client.recv_from(&mut buf).await.unwrap();
        assert_eq!((&buf[..n], from), (&b"pong"[..], relay.local_addr()));
        assert!(t.elapsed() >= 40 * MS, "{:?}", t.elapsed());
        assert_eq!(relay.upstream.snapshot().0, 1);
        assert_eq!(relay.downstream.snapshot().0, 1);
    }
}
