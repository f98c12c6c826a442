//! Viewer input of a session (issue 20), sans-IO: which [`Input`] datagrams
//! a session takes, and the camera an interactive producer renders from.
//!
//! Datagrams come from the network, unordered, unreliable and possibly
//! hostile. The wire already refuses what does not decode or validate (NaN,
//! a quaternion off unit length by more than the tolerance, coordinates
//! beyond `protocol::camera::MAX_COORDINATE`); the [`InputGate`] then
//!
//! * drops a flood: a token bucket of [`InputLimits::rate_hz`] (a few times
//!   any display rate) with a burst of [`InputLimits::burst`], checked
//!   first, so a flood costs one comparison a datagram;
//! * drops replayed and out-of-order inputs: only a sequence number above
//!   the newest taken is newer (the datagram that overtook it already
//!   carries a later pose);
//! * normalises the rotation and clamps the position into a ball around
//!   the scene's origin, so a viewer who walks off (or lies) renders a
//!   scene that is still there rather than float noise;
//!
//! and counts every decision ([`InputCounts`]). One session's gate knows
//! nothing of another's: a bad client disturbs only its own camera.

use std::time::Instant;

use glam::DVec3;
use protocol::Pose;
use protocol::wire::{Input, InputEcho};

/// The newest admitted input of a session: its pose and what the frame
/// rendered from it echoes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewerInput {
    /// Sequence number and client time, echoed in the frame header.
    pub echo: InputEcho,
    /// The viewer's camera, normalised and clamped.
    pub pose: Pose,
}

/// What a session's gate admits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputLimits {
    /// Sustained inputs per second (a token bucket).
    pub rate_hz: f64,
    /// Inputs that may arrive at once.
    pub burst: f64,
    /// Centre of the ball positions are clamped into (the scene's origin).
    pub origin: DVec3,
    /// Radius of that ball, metres.
    pub max_distance: f64,
}

impl Default for InputLimits {
    /// 480 inputs a second (twice a 240 Hz display), bursts of 32, within
    /// 10 km of the origin.
    fn default() -> Self {
        Self {
            rate_hz: 480.0,
            burst: 32.0,
            origin: DVec3::ZERO,
            max_distance: 10_000.0,
        }
    }
}

/// What a session's gate did with the input datagrams it saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InputCounts {
    /// Taken: the session's camera follows them.
    pub accepted: u64,
    /// Did not decode or validate (also counted by the caller: see
    /// [`InputGate::invalid`]).
    pub invalid: u64,
    /// A sequence number not above the newest taken (replayed, duplicated
    /// or overtaken).
    pub stale: u64,
    /// Over the rate.
    pub flood: u64,
    /// In sequence but with no camera (buttons and axes only).
    pub without_camera: u64,
    /// Taken with the position pulled into the allowed ball.
    pub clamped: u64,
}

/// One session's input filter; see the module doc.
#[derive(Clone, Debug)]
pub struct InputGate {
    limits: InputLimits,
    newest: Option<u64>,
    tokens: f64,
    refilled: Option<Instant>,
    counts: InputCounts,
}

impl InputGate {
    /// A gate with a full bucket.
    pub fn new(limits: InputLimits) -> Self {
        Self {
            tokens: limits.burst,
            limits,
            newest: None,
            refilled: None,
            counts: InputCounts::default(),
        }
    }

    /// What it did so far.
    pub fn counts(&self) -> InputCounts {
        self.counts
    }

    /// Counts a datagram that did not decode or validate as an input.
    pub fn invalid(&mut self) {
        self.counts.invalid += 1;
    }

    /// The viewer input `input` gives at `now`, if it is taken.
    pub fn admit(&mut self, input: &Input, now: Instant) -> Option<ViewerInput> {
        if let Some(at) = self.refilled {
            let earned = now.saturating_duration_since(at).as_secs_f64() * self.limits.rate_hz;
            self.tokens = (self.tokens + earned).min(self.limits.burst);
        }
        self.refilled = Some(now);
        if self.tokens < 1.0 {
            self.counts.flood += 1;
            return None;
        }
        self.tokens -= 1.0;
        if self.newest.is_some_and(|n| input.seq <= n) {
            self.counts.stale += 1;
            return None;
        }
        self.newest = Some(input.seq);
        let Some(pose) = input.camera else {
            self.counts.without_camera += 1;
            return None;
        };
        // The wire validated it; the gate does not count on that.
        if pose.validate().is_err() {
            self.counts.invalid += 1;
            return None;
        }
        let mut pose = pose.normalized();
        let offset = pose.position - self.limits.origin;
        let distance = offset.length();
        if distance > self.limits.max_distance {
            pose.position = self.limits.origin + offset * (self.limits.max_distance / distance);
            self.counts.clamped += 1;
        }
        self.counts.accepted += 1;
        Some(ViewerInput {
            echo: InputEcho {
                seq: input.seq,
                client_time_us: input.client_time_us,
            },
            pose,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use glam::DQuat;

    use super::*;

    fn input(seq: u64, position: DVec3, rotation: DQuat) -> Input {
        Input {
            seq,
            client_time_us: seq * 1000,
            camera: Some(Pose::new(position, rotation)),
            buttons: 0,
            axes: [0.0; 4],
        }
    }

    #[test]
    fn newer_inputs_are_taken_and_old_ones_dropped() {
        let mut gate = InputGate::new(InputLimits::default());
        let t0 = Instant::now();
        let at = |ms| t0 + Duration::from_millis(ms);
        let p = |x| input(x as u64, DVec3::new(x, 0.0, 0.0), DQuat::IDENTITY);
        assert_eq!(gate.admit(&p(5.0), at(0)).map(|v| v.echo.seq), Some(5));
        // Replayed, and overtaken.
        assert!(gate.admit(&p(5.0), at(10)).is_none());
        assert!(gate.admit(&p(3.0), at(20)).is_none());
        let taken = gate.admit(&p(9.0), at(30)).unwrap();
        assert_eq!(taken.pose.position.x, 9.0);
        assert_eq!(taken.echo.client_time_us, 9000);
        // Buttons only: in sequence, no camera.
        let mut buttons = p(10.0);
        buttons.camera = None;
        assert!(gate.admit(&buttons, at(40)).is_none());
        assert!(gate.admit(&p(10.0), at(50)).is_none(), "10 was seen");
        assert_eq!(
            gate.counts(),
            InputCounts {
                accepted: 2,
                stale: 3,
                without_camera: 1,
                ..InputCounts::default()
            }
        );
    }

    #[test]
    fn poses_are_normalised_and_clamped_and_bad_ones_refused() {
        let limits = InputLimits {
            origin: DVec3::new(100.0, 0.0, 0.0),
            max_distance: 50.0,
            ..InputLimits::default()
        };
        let mut gate = InputGate::new(limits);
        let now = Instant::now();
        // Slightly off unit length (within the wire's tolerance).
        let q = DQuat::from_rotation_y(0.3) * (1.0 + 1e-7);
        let v = gate
            .admit(&input(1, DVec3::new(1e9, 0.0, 0.0), q), now)
            .unwrap();
        assert!((v.pose.rotation.length() - 1.0).abs() < 1e-12);
        assert!((v.pose.position - DVec3::new(150.0, 0.0, 0.0)).length() < 1e-9);
        // Off unit length by far, and NaN: refused, counted.
        let far = input(2, DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 3.0));
        assert!(gate.admit(&far, now).is_none());
        let nan = input(3, DVec3::new(f64::NAN, 0.0, 0.0), DQuat::IDENTITY);
        assert!(gate.admit(&nan, now).is_none());
        let c = gate.counts();
        assert_eq!((c.accepted, c.clamped, c.invalid), (1, 1, 2));
    }

    #[test]
    fn a_flood_is_cut_to_the_rate() {
        let limits = InputLimits::default();
        let mut gate = InputGate::new(limits);
        let t0 = Instant::now();
        // 10 000 inputs in one second of arrival times.
        let n = 10_000u64;
        let taken = (1..=n)
            .filter(|&s| {
                let at = t0 + Duration::from_secs_f64(s as f64 / n as f64);
                gate.admit(&input(s, DVec3::ZERO, DQuat::IDENTITY), at)
                    .is_some()
            })
            .count() as f64;
        let most = limits.rate_hz + limits.burst;
        assert!(taken <= most + 1.0, "{taken} taken");
        assert!(taken >= limits.rate_hz * 0.95, "{taken} taken");
        assert_eq!(gate.counts().flood, n - taken as u64);
        // A display-rate client is never cut.
        let mut gate = InputGate::new(limits);
        let all = (1..=600u64).all(|s| {
            let at = t0 + Duration::from_secs_f64(s as f64 / 240.0);
            gate.admit(&input(s, DVec3::ZERO, DQuat::IDENTITY), at)
                .is_some()
        });
        assert!(all);
    }
}
