//! Keyframe recovery for one session, sans-IO (issue 19 §1): a client
//! decodes video-coded colour only from a keyframe on, through every frame
//! after it. When it joins, when the server drops a frame for it, or when
//! it says it lost one ([`protocol::wire::KeyframeRequest`]), the session
//! sends it nothing until the next keyframe (predicted frames would be
//! undecodable, wasted bandwidth) and asks the producer for one: at once,
//! then again every [`KEYFRAME_RETRY`] while it waits. That bound is also
//! all one client can make the shared producer spend on keyframes.
//!
//! The producer is shared by every session, so it bounds its keyframes
//! itself too ([`KeyframeBudget`]): however many sessions ask, it forces
//! one at most every [`KEYFRAME_RETRY`] after the last keyframe it made,
//! so all its sessions together cost it no more than one lossy session
//! can (issue 18: one client never disturbs another).
//!
//! Without video-coded colour every frame is a keyframe and nothing is
//! ever held back.

use std::time::{Duration, Instant};

/// How long a session waits for a keyframe before asking again, and the
/// least time between two of its requests: about four frames at 30 fps,
/// room for the producer's next frame and its trip. Every frame between a
/// loss and the keyframe is held back, so this bounds a lossy client's
/// freezes as well as what it can make the producer spend (at most one
/// keyframe request per this time, and requests between two frames make
/// one keyframe). At 500 ms a loss soon after a keyframe froze the stream
/// for up to half a second: `client run --window off --seconds 10 --size
/// 320x180 --impair loss=10%,jitter=20ms,seed=S --congestion bbr`, six
/// seeds, held slots of 600 were 116–279 (mean 203) at 500 ms against
/// 57–148 (mean 88) at 150 ms, frames received 123–206 (mean 159) against
/// 185–220 (mean 208).
pub const KEYFRAME_RETRY: Duration = Duration::from_millis(150);

/// What to do with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Send it.
    Send,
    /// Hold it back: the client cannot decode it.
    Skip,
}

/// Whether a session's client can decode the next frame.
#[derive(Debug)]
pub struct Recovery {
    waiting: bool,
    asked: Option<Instant>,
}

impl Default for Recovery {
    fn default() -> Self {
        Self::new()
    }
}

impl Recovery {
    /// A new session: its client starts from a keyframe.
    pub fn new() -> Self {
        Self {
            waiting: true,
            asked: None,
        }
    }

    /// Whether the client waits for a keyframe.
    pub fn waiting(&self) -> bool {
        self.waiting
    }

    /// The client lost a frame (the server dropped it, or the client said
    /// so): from now on it waits for a keyframe.
    pub fn lost(&mut self) {
        self.waiting = true;
    }

    /// Whether to ask the producer for a keyframe `now`: while waiting, at
    /// most once every [`KEYFRAME_RETRY`].
    pub fn ask(&mut self, now: Instant) -> bool {
        let due = self.waiting
            && self
                .asked
                .is_none_or(|at| now.saturating_duration_since(at) >= KEYFRAME_RETRY);
        if due {
            self.asked = Some(now);
        }
        due
    }

    /// A frame to send, `keyframe` or not.
    pub fn on_frame(&mut self, keyframe: bool) -> Decision {
        if keyframe {
            self.waiting = false;
        }
        if self.waiting {
            Decision::Skip
        } else {
            Decision::Send
        }
    }
}

/// The producer's side: when a pending keyframe request may be granted.
/// Sans-IO; the producer says when it made a keyframe (forced or the
/// encoder's periodic one) and asks before each frame.
#[derive(Debug, Default)]
pub struct KeyframeBudget {
    last: Option<Instant>,
}

impl KeyframeBudget {
    /// Whether a request may force the frame encoded `now` to be a
    /// keyframe: the last keyframe is at least [`KEYFRAME_RETRY`] old (a
    /// request not granted stays pending until then).
    pub fn allows(&self, now: Instant) -> bool {
        self.last
            .is_none_or(|at| now.saturating_duration_since(at) >= KEYFRAME_RETRY)
    }

    /// A keyframe was made `now`.
    pub fn made(&mut self, now: Instant) {
        self.last = Some(now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Requests before every frame from any number of sessions: keyframes
    /// come no closer than the retry time, and a periodic one counts.
    #[test]
    fn the_producer_forces_a_keyframe_at_most_once_a_retry_period() {
        let t0 = Instant::now();
        let frame = Duration::from_millis(33);
        let mut budget = KeyframeBudget::default();
        let mut made = vec![];
        for k in 0..90u32 {
            let now = t0 + frame * k;
            // The encoder makes a periodic keyframe at frame 42.
            if budget.allows(now) || k == 42 {
                budget.made(now);
                made.push(k);
            }
        }
        assert_eq!(made[0], 0, "the first request is granted at once");
        assert!(made.contains(&42));
        for w in made.windows(2) {
            assert!(
                frame * (w[1] - w[0]) >= KEYFRAME_RETRY || w[1] == 42,
                "{made:?}"
            );
        }
        // 150 ms is five frames of 33 ms: every fifth frame, the periodic
        // one shifting the rest (0, 5, ..., 40, 42, 47, ..., 87).
        assert_eq!(made.len(), 19, "{made:?}");
    }

    #[test]
    fn a_session_waits_for_a_keyframe_and_asks_at_a_bounded_rate() {
        let t0 = Instant::now();
        // Times in retry periods.
        let at = |periods: f64| t0 + KEYFRAME_RETRY.mul_f64(periods);
        let mut r = Recovery::new();
        // Joining: ask at once, hold predicted frames back.
        assert!(r.waiting() && r.ask(t0));
        assert_eq!(r.on_frame(false), Decision::Skip);
        assert!(!r.ask(at(0.2)), "asked again within the retry time");
        assert!(r.ask(at(1.0)), "no keyframe came: ask again");
        assert_eq!(r.on_frame(true), Decision::Send);
        assert_eq!(r.on_frame(false), Decision::Send);
        assert!(!r.ask(at(1.2)), "nothing to ask for");
        // A loss soon after: the request waits out the retry time, and a
        // client that keeps saying so gets no more than one request in it.
        r.lost();
        assert!(!r.ask(at(1.4)));
        assert_eq!(r.on_frame(false), Decision::Skip);
        r.lost();
        assert!(!r.ask(at(1.8)));
        assert!(r.ask(at(2.0)));
        assert_eq!(r.on_frame(true), Decision::Send);
        // Without video every frame is a keyframe: nothing is held back.
        let mut plain = Recovery::new();
        plain.lost();
        assert_eq!(plain.on_frame(true), Decision::Send);
    }
}
