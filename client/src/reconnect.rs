//! A stream that outlives its sessions (issue 18 §9): when the server goes
//! away, [`Stream`] reconnects with a bounded backoff while the presenter
//! keeps presenting from what it has (extrapolating, then holding), and the
//! frames of the new session continue the old ones: indices and times keep
//! increasing, and the first frame after an outage is flagged as a cut, so
//! the generator restarts its history instead of blending across the gap.
//!
//! What ends the stream instead: the server ending it (a finished replay),
//! refusing the client (a wrong token, a full server), breaking the
//! protocol, coming back with a different stream (size, rate or buffers),
//! or staying away longer than [`ReconnectPolicy::give_up_after`].
//!
//! [`Backoff`] is the sans-IO schedule (it takes `now`); [`Stream`] runs it.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use protocol::wire::Welcome;
use serde::Serialize;
use tokio::sync::mpsc;

use crate::connect::{Arrived, ConnectConfig, ConnectError, Session, SessionStats};

/// How to reconnect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconnectPolicy {
    /// Wait before the first attempt after a session is lost.
    pub first_delay: Duration,
    /// Longest wait between attempts (the wait doubles up to it). It bounds
    /// how long after the server is back the stream resumes: this plus one
    /// handshake.
    pub max_delay: Duration,
    /// An outage this long ends the stream.
    pub give_up_after: Duration,
    /// Longest a reconnection attempt's handshake may take.
    pub attempt_timeout: Duration,
}

impl Default for ReconnectPolicy {
    /// 100 ms, doubling to 1 s, for up to 30 s; 1 s per handshake.
    fn default() -> Self {
        Self {
            first_delay: Duration::from_millis(100),
            max_delay: Duration::from_secs(1),
            give_up_after: Duration::from_secs(30),
            attempt_timeout: Duration::from_secs(1),
        }
    }
}

impl ReconnectPolicy {
    /// Never reconnect: the stream ends with its first session.
    pub const NEVER: Self = Self {
        first_delay: Duration::ZERO,
        max_delay: Duration::ZERO,
        give_up_after: Duration::ZERO,
        attempt_timeout: Duration::ZERO,
    };
}

/// The reconnection schedule of one outage (sans-IO).
#[derive(Clone, Debug)]
pub struct Backoff {
    policy: ReconnectPolicy,
    lost_at: Duration,
    attempts: u32,
}

impl Backoff {
    /// An outage that began at `now`.
    pub fn new(policy: ReconnectPolicy, now: Duration) -> Self {
        Self {
            policy,
            lost_at: now,
            attempts: 0,
        }
    }

    /// When to attempt next, counting from `now` (the start of the attempt
    /// before, or the loss), or `None`: give up.
    pub fn next_attempt(&mut self, now: Duration) -> Option<Duration> {
        let wait = self
            .policy
            .first_delay
            .saturating_mul(1u32 << self.attempts.min(20))
            .min(self.policy.max_delay);
        let at = now + wait;
        if at.saturating_sub(self.lost_at) >= self.policy.give_up_after {
            return None;
        }
        self.attempts += 1;
        Some(at)
    }

    /// Attempts made.
    pub fn attempts(&self) -> u32 {
        self.attempts
    }

    /// When the outage began.
    pub fn lost_at(&self) -> Duration {
        self.lost_at
    }
}

/// Counters of a stream across its sessions.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StreamStats {
    /// Sessions lost and connected again.
    pub reconnects: u64,
    /// Connection attempts that failed during outages.
    pub failed_attempts: u64,
    /// Time without frames across outages, all together, ms: from the last
    /// frame before each lost session to the first frame of the next.
    pub outage_ms: f64,
    /// The longest outage, ms.
    pub longest_outage_ms: f64,
    /// Whether the stream is in an outage now (no session, or a new one
    /// whose first frame has not arrived).
    pub in_outage: bool,
    /// The current (or last) session's statistics.
    #[serde(skip)]
    pub session: SessionStats,
}

#[derive(Default)]
struct Shared {
    stats: StreamStats,
    /// Why the stream ended, once it has.
    ended: Option<String>,
    /// The current session's connection (input goes out on it).
    conn: Option<quinn::Connection>,
}

/// Frames from one server across reconnections. Frames arrive on
/// [`Stream::frames`]; the channel closes when the stream ends.
pub struct Stream {
    /// The first session's welcome (every later one matches it).
    pub welcome: Welcome,
    /// Complete, decoded frames, in order, renumbered across sessions.
    pub frames: mpsc::Receiver<Arrived>,
    shared: Arc<Mutex<Shared>>,
    task: tokio::task::JoinHandle<()>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Stream {
    /// Connects (the first session must succeed: its errors are returned)
    /// and keeps reconnecting as `policy` says.
    pub async fn connect(
        config: ConnectConfig,
        policy: ReconnectPolicy,
    ) -> Result<Self, ConnectError> {
        let session = crate::connect(config.clone()).await?;
        let welcome = session.welcome.clone();
        let (tx, frames) = mpsc::channel(config.queue.max(1));
        let shared = Arc::new(Mutex::new(Shared {
            conn: Some(session.connection().clone()),
            ..Shared::default()
        }));
        let (stop, stopped) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(supervise(
            session,
            config,
            policy,
            tx,
            shared.clone(),
            stopped,
        ));
        Ok(Self {
            welcome,
            frames,
            shared,
            task,
            stop: Some(stop),
        })
    }

    /// Counters across sessions.
    pub fn stats(&self) -> StreamStats {
        self.shared.lock().map(|s| s.stats).unwrap_or_default()
    }

    /// Sends the viewer's input on the current session; false while there
    /// is none (an outage) or the datagram could not be sent. Input is
    /// unreliable by design: the next one supersedes it.
    pub fn send_input(&self, input: &protocol::wire::Input) -> bool {
        let conn = self.shared.lock().ok().and_then(|s| s.conn.clone());
        conn.is_some_and(|c| crate::connect::send_input(&c, input).is_ok())
    }

    /// Why the stream ended, once it has.
    pub fn ended(&self) -> Option<String> {
        self.shared.lock().ok().and_then(|s| s.ended.clone())
    }

    /// Ends the stream and its session politely.
    pub async fn close(mut self) {
        // Frames no one will take no longer hold the supervisor up.
        self.frames.close();
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        let _ = (&mut self.task).await;
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Keeps indices and times increasing across sessions.
#[derive(Debug, Default)]
struct Renumber {
    /// The last frame forwarded: its new index and time, and when.
    last: Option<(u64, f64, Instant)>,
    /// This session's first frame: its own index and time, and the new ones.
    base: Option<(u64, f64, u64, f64)>,
}

impl Renumber {
    /// A new session starts: its first frame follows the last one forwarded,
    /// as far on in time as the outage lasted, and is a cut.
    fn new_session(&mut self) {
        self.base = None;
    }

    fn apply(&mut self, arrived: &mut Arrived) {
        // Not shared yet: renumbered in place.
        let meta = &mut std::sync::Arc::make_mut(&mut arrived.frame).meta;
        let base = match (self.base, self.last) {
            (Some(b), _) => b,
            (None, None) => {
                // The first session keeps its own numbers.
                let b = (meta.index, meta.time, meta.index, meta.time);
                self.base = Some(b);
                b
            }
            (None, Some((index, time, at))) => {
                let gap = arrived.received.saturating_duration_since(at).as_secs_f64();
                let b = (meta.index, meta.time, index + 1, time + gap);
                self.base = Some(b);
                meta.cut = true;
                b
            }
        };
        let (own_index, own_time, index, time) = base;
        meta.index = index + meta.index.saturating_sub(own_index);
        meta.time = time + (meta.time - own_time);
        self.last = Some((meta.index, meta.time, arrived.received));
    }
}

/// Why a session ended, and whether to reconnect after it.
fn after_session(session: &Session) -> Result<String, String> {
    if let Some(failure) = session.failure() {
        return Err(format!("the server broke the protocol: {failure}"));
    }
    match session.close_reason() {
        Some(quinn::ConnectionError::ApplicationClosed(close)) => {
            let code = u32::try_from(close.error_code.into_inner()).unwrap_or(u32::MAX);
            let reason = String::from_utf8_lossy(&close.reason).into_owned();
            match code {
                host::serve::close_code::SHUTDOWN => Ok(format!("the server shut down ({reason})")),
                host::serve::close_code::DONE => {
                    Err(format!("the server ended the stream ({reason})"))
                }
                _ => Err(format!(
                    "the server closed the connection: code {code} ({reason})"
                )),
            }
        }
        Some(quinn::ConnectionError::LocallyClosed) => Err("closed".into()),
        Some(e) => Ok(e.to_string()),
        None => Ok("the session ended".into()),
    }
}

/// Whether a new session streams what the first one did.
fn same_stream(a: &Welcome, b: &Welcome) -> bool {
    a.size == b.size
        && a.fps == b.fps
        && a.buffers == b.buffers
        && a.window_mode == b.window_mode
        && a.max_frame == b.max_frame
        // The generator was planned for the first session's effects.
        && a.effects == b.effects
}

async fn supervise(
    mut session: Session,
    config: ConnectConfig,
    policy: ReconnectPolicy,
    tx: mpsc::Sender<Arrived>,
    shared: Arc<Mutex<Shared>>,
    mut stopped: tokio::sync::oneshot::Receiver<()>,
) {
    let origin = Instant::now();
    let now = || origin.elapsed();
    let welcome = session.welcome.clone();
    let mut renumber = Renumber::default();
    // When the last frame arrived, while an outage is not over yet.
    let mut outage_since: Option<Instant> = None;
    let mut last_frame = Instant::now();
    let update = |f: &mut dyn FnMut(&mut Shared)| {
        if let Ok(mut s) = shared.lock() {
            f(&mut s);
        }
    };
    let end = |why: String| {
        tracing::warn!("stream ended: {why}");
        update(&mut |s| s.ended = Some(why.clone()));
    };
    loop {
        // Forward this session's frames until it ends.
        loop {
            let next = tokio::select! {
                a = session.frames.recv() => a,
                _ = &mut stopped => {
                    session.close().await;
                    return;
                }
            };
            let Some(mut arrived) = next else { break };
            renumber.apply(&mut arrived);
            let stats = session.stats();
            let outage = outage_since.take().map(|since| {
                arrived
                    .received
                    .saturating_duration_since(since)
                    .as_secs_f64()
                    * 1e3
            });
            last_frame = arrived.received;
            update(&mut |s| {
                s.stats.session = stats;
                if let Some(ms) = outage {
                    tracing::info!("frames again after {ms:.0} ms");
                    s.stats.outage_ms += ms;
                    s.stats.longest_outage_ms = s.stats.longest_outage_ms.max(ms);
                    s.stats.in_outage = false;
                }
            });
            let sent = tokio::select! {
                sent = tx.send(arrived) => sent.is_ok(),
                _ = &mut stopped => false,
            };
            if !sent {
                session.close().await;
                return;
            }
        }
        let why = match after_session(&session) {
            Ok(why) => why,
            Err(why) => return end(why),
        };
        session.close().await;
        tracing::warn!("session lost: {why}; reconnecting");
        let mut backoff = Backoff::new(policy, now());
        update(&mut |s| s.stats.in_outage = true);
        // Waits count from the start of the attempt before, so attempts
        // begin at most `max_delay` apart however long each one takes.
        let mut last_start = now();
        session = loop {
            let Some(at) = backoff.next_attempt(last_start) else {
                return end(format!(
                    "no session for {:?} after {} attempts: {why}",
                    policy.give_up_after,
                    backoff.attempts()
                ));
            };
            tokio::select! {
                () = tokio::time::sleep(at.saturating_sub(now())) => {}
                _ = &mut stopped => return,
            }
            last_start = now();
            // A handshake with no server behind the address would wait for
            // the idle timeout; a new attempt soon after reaches a server
            // that has just come back sooner.
            let attempt =
                tokio::time::timeout(policy.attempt_timeout, crate::connect(config.clone()));
            let attempt = match attempt.await {
                Ok(result) => result,
                Err(_) => Err(ConnectError::Timeout("the handshake")),
            };
            match attempt {
                Ok(s) if same_stream(&welcome, &s.welcome) => break s,
                Ok(s) => {
                    s.close().await;
                    return end("the server came back with a different stream".into());
                }
                Err(ConnectError::Rejected(r)) => {
                    return end(format!(
                        "refused on reconnecting ({:?}): {}",
                        r.reason, r.message
                    ));
                }
                Err(e) => {
                    tracing::info!(attempt = backoff.attempts(), "reconnect failed: {e}");
                    update(&mut |s| s.stats.failed_attempts += 1);
                }
            }
        };
        let lost_for = (now() - backoff.lost_at()).as_secs_f64() * 1e3;
        tracing::info!("reconnected {lost_for:.0} ms after the session was lost");
        update(&mut |s| {
            s.stats.reconnects += 1;
            s.conn = Some(session.connection().clone());
        });
        outage_since = Some(last_frame);
        renumber.new_session();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_backoff_doubles_to_its_bound_and_gives_up() {
        let policy = ReconnectPolicy::default();
        let mut b = Backoff::new(policy, 1000 * MS);
        let mut now = 1000 * MS;
        let mut waits = vec![];
        while let Some(at) = b.next_attempt(now) {
            waits.push((at - now).as_millis());
            now = at + 5 * MS; // each attempt takes 5 ms to fail
        }
        assert_eq!(&waits[..5], &[100, 200, 400, 800, 1000]);
        assert!(waits[5..].iter().all(|&w| w == 1000));
        // Given up within the bound, never past it.
        assert!(now - 1000 * MS <= policy.give_up_after + 5 * MS, "{now:?}");
        assert!(
            now - 1000 * MS >= policy.give_up_after - 1005 * MS,
            "{now:?}"
        );
        assert_eq!(b.attempts() as usize, waits.len());
        // Never: no attempt at all.
        assert!(
            Backoff::new(ReconnectPolicy::NEVER, now)
                .next_attempt(now)
                .is_none()
        );
    }

    fn arrived(index: u64, time: f64, received: Instant) -> Arrived {
        let size = protocol::FrameSize::new(1, 1);
        Arrived {
            frame: std::sync::Arc::new(protocol::Frame {
                meta: protocol::FrameMeta {
                    index,
                    time,
                    camera: protocol::Camera::new(
                        protocol::Pose::new(glam::DVec3::ZERO, glam::DQuat::IDENTITY),
                        protocol::Projection::perspective(1.0, 1.0, 0.1, 10.0),
                    ),
                    size,
                    host_processing: Duration::ZERO,
                    cut: false,
                },
                color: vec![[half::f16::ZERO; 4]],
                depth: vec![1.0],
                motion: vec![[0.0; 2]],
                extras: vec![],
            }),
            received,
            decoded: received,
            input: None,
        }
    }

    /// A new session's frames continue the old ones: indices one on, time
    /// on by the outage, the first one a cut.
    #[test]
    fn frames_of_a_new_session_continue_the_old_ones() {
        let t0 = Instant::now();
        let mut r = Renumber::default();
        let mut got = vec![];
        for (k, i) in [5u64, 6, 8].into_iter().enumerate() {
            let mut a = arrived(i, i as f64 / 30.0, t0 + k as u32 * 33 * MS);
            r.apply(&mut a);
            got.push(a.frame.meta);
        }
        assert_eq!(got.iter().map(|m| m.index).collect::<Vec<_>>(), [5, 6, 8]);
        assert!(got.iter().all(|m| !m.cut));
        let last = got[2];
        // The server restarted: its frames start again at 0, 1.5 s later.
        r.new_session();
        let back = t0 + 66 * MS + 1500 * MS;
        let mut after = vec![];
        for i in [0u64, 1, 3] {
            let mut a = arrived(i, i as f64 / 30.0, back + i as u32 * 33 * MS);
            r.apply(&mut a);
            after.push(a.frame.meta);
        }
        assert_eq!(
            after.iter().map(|m| m.index).collect::<Vec<_>>(),
            [9, 10, 12]
        );
        assert_eq!(
            after.iter().map(|m| m.cut).collect::<Vec<_>>(),
            [true, false, false]
        );
        assert!(
            (after[0].time - (last.time + 1.5)).abs() < 1e-9,
            "{}",
            after[0].time
        );
        assert!((after[2].time - after[0].time - 0.1).abs() < 1e-9);
    }
}
