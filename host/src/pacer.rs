//! Pacing by simulation time (DESIGN §7): frame `k` is sent when
//! `now − start = (t_k − t_0) / speed`, however fast rendering or reading
//! happens to be. When the sender falls behind so that the *next* frame is
//! already due, the current one is skipped rather than queued: a stale frame
//! is worth less than bandwidth for a fresh one. Time going backwards (a
//! looping replay) re-anchors the clock.
//!
//! Sans-IO: the caller passes `now` as a [`Duration`] since any fixed epoch.

use std::time::Duration;

/// What to do with the frame at hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pace {
    /// Sleep until this instant (same epoch as `now`), then ask again.
    WaitUntil(Duration),
    /// Send it now.
    Send,
    /// Skip it: the next frame is already due.
    Skip,
}

/// Maps simulation time to wall time for one stream.
#[derive(Clone, Debug)]
pub struct Pacer {
    speed: f64,
    origin: Option<(Duration, f64)>,
    sent: u64,
    skipped: u64,
}

impl Pacer {
    /// A pacer playing at `speed` × real time (1.0 = real time). Non-finite
    /// or non-positive speeds fall back to 1.0.
    pub fn new(speed: f64) -> Self {
        let speed = if speed.is_finite() && speed > 0.0 {
            speed
        } else {
            1.0
        };
        Self {
            speed,
            origin: None,
            sent: 0,
            skipped: 0,
        }
    }

    /// When a frame with simulation time `time` is due, once anchored.
    pub fn due(&self, time: f64) -> Option<Duration> {
        let (start, t0) = self.origin?;
        let offset = ((time - t0) / self.speed).max(0.0);
        Some(start.saturating_add(Duration::try_from_secs_f64(offset).unwrap_or(Duration::MAX)))
    }

    /// Decides about the frame at simulation time `time`, given the time of
    /// the frame after it, if known. The first frame anchors the clock and
    /// is sent at once.
    pub fn decide(&mut self, now: Duration, time: f64, next_time: Option<f64>) -> Pace {
        let anchored = matches!(self.origin, Some((_, t0)) if time >= t0 && time.is_finite());
        if !anchored {
            self.origin = Some((now, if time.is_finite() { time } else { 0.0 }));
        }
        let due = self.due(time).unwrap_or(now);
        if now < due {
            return Pace::WaitUntil(due);
        }
        if let Some(next_due) = next_time
            .filter(|t| t.is_finite() && *t > time)
            .and_then(|t| self.due(t))
        {
            if now >= next_due {
                self.skipped += 1;
                return Pace::Skip;
            }
        }
        self.sent += 1;
        Pace::Send
    }

    /// Frames decided [`Pace::Send`].
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// Frames decided [`Pace::Skip`].
    pub fn skipped(&self) -> u64 {
        self.skipped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    #[test]
    fn frames_go_out_at_their_simulation_time() {
        let mut p = Pacer::new(1.0);
        let base = MS(1000);
        assert_eq!(p.decide(base, 10.0, Some(10.1)), Pace::Send);
        // Frame at t = 10.1 is due 100 ms later, whatever `now` is.
        assert_eq!(
            p.decide(base + MS(5), 10.1, Some(10.2)),
            Pace::WaitUntil(base + MS(100))
        );
        assert_eq!(p.decide(base + MS(100), 10.1, Some(10.2)), Pace::Send);
        // Double speed halves the spacing.
        let mut fast = Pacer::new(2.0);
        fast.decide(base, 0.0, None);
        assert_eq!(fast.due(1.0), Some(base + MS(500)));
    }

    #[test]
    fn a_sender_that_falls_behind_skips_stale_frames() {
        let mut p = Pacer::new(1.0);
        p.decide(MS(0), 0.0, Some(1.0 / 30.0));
        // 100 ms later frames at 33 ms and 67 ms are both stale.
        let now = MS(100);
        assert_eq!(p.decide(now, 1.0 / 30.0, Some(2.0 / 30.0)), Pace::Skip);
        assert_eq!(p.decide(now, 2.0 / 30.0, Some(3.0 / 30.0)), Pace::Skip);
        assert_eq!(p.decide(now, 3.0 / 30.0, Some(4.0 / 30.0)), Pace::Send);
        assert_eq!((p.sent(), p.skipped()), (2, 2));
        // The last frame of a sequence is never skipped.
        assert_eq!(p.decide(MS(10_000), 4.0 / 30.0, None), Pace::Send);
    }

    #[test]
    fn time_going_backwards_reanchors_and_bad_values_stay_safe() {
        let mut p = Pacer::new(f64::NAN);
        p.decide(MS(0), 5.0, None);
        assert_eq!(p.decide(MS(50), 0.0, Some(0.1)), Pace::Send, "loop restart");
        assert_eq!(p.decide(MS(60), 0.1, None), Pace::WaitUntil(MS(150)));
        assert_eq!(p.decide(MS(70), f64::NAN, None), Pace::Send);
        assert!(p.due(1e300).is_some());
    }
}
