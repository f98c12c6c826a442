//! The viewer's camera on the client (issue 20): a scripted input track,
//! as a headless run or a test drives it, turned into poses the client
//! sends to an interactive server and warps its frames to.
//!
//! In a window, [`LiveViewer`] does the same from the mouse and keys (the
//! usual game bindings: drag with the left button to look, W/A/S/D to move,
//! Space and C up and down, Shift to run).
//!
//! A track moves a game camera from where the stream starts (the first
//! frame's camera): it turns about the world's vertical (yaw), tilts about
//! its own right axis (pitch, kept within ±89° of the start's) and moves along the start
//! camera's axes, each at a constant rate per segment. Poses are exact at
//! any time (no integration steps): yaw and pitch are piecewise linear, the
//! position too.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::{DQuat, DVec3};
use protocol::Pose;
use serde::{Deserialize, Serialize};

/// One stretch of a track, at constant rates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackSegment {
    /// How long it lasts, seconds.
    pub seconds: f64,
    /// Turn rate about the vertical, degrees a second (positive: left).
    #[serde(default)]
    pub yaw_deg_per_s: f64,
    /// Tilt rate, degrees a second (positive: up).
    #[serde(default)]
    pub pitch_deg_per_s: f64,
    /// Velocity along the start camera's right, up and backward axes, m/s.
    #[serde(default)]
    pub velocity: [f64; 3],
}

/// A scripted viewer: its segments one after the other, then still.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputTrack {
    /// The segments, in order.
    pub segments: Vec<TrackSegment>,
}

/// Why a track was refused.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    /// The file could not be read.
    #[error("reading the input track {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a track.
    #[error("the input track {path} is not valid JSON for a track: {source}")]
    Parse {
        /// The file.
        path: String,
        /// Why.
        source: serde_json::Error,
    },
    /// No built-in track has the name.
    #[error("no built-in input track {0:?} (built in: turn, look-around, walk)")]
    Unknown(String),
    /// A value is out of range.
    #[error("input track segment {segment}: {what}")]
    Invalid {
        /// Which segment.
        segment: usize,
        /// What is wrong.
        what: &'static str,
    },
}

/// Most segments a track may have.
pub const MAX_SEGMENTS: usize = 10_000;
/// Fastest turn or tilt, degrees a second (two turns a second).
pub const MAX_RATE_DEG: f64 = 720.0;
/// Fastest movement, m/s.
pub const MAX_SPEED: f64 = 100.0;
/// Pitch is kept this far from straight up or down, degrees.
const PITCH_LIMIT_DEG: f64 = 89.0;

impl InputTrack {
    /// A built-in track: `turn` (90°/s to the left, for ever),
    /// `look-around` (left, right, up and down over 8 s, then still) or
    /// `walk` (forward at 1.5 m/s while turning 20°/s).
    pub fn builtin(name: &str) -> Result<Self, TrackError> {
        let seg = |seconds, yaw, pitch, velocity| TrackSegment {
            seconds,
            yaw_deg_per_s: yaw,
            pitch_deg_per_s: pitch,
            velocity,
        };
        let segments = match name {
            "turn" => vec![seg(1e6, 90.0, 0.0, [0.0; 3])],
            "look-around" => vec![
                seg(2.0, 60.0, 0.0, [0.0; 3]),
                seg(2.0, -60.0, 0.0, [0.0; 3]),
                seg(2.0, 0.0, 15.0, [0.0; 3]),
                seg(2.0, 0.0, -15.0, [0.0; 3]),
            ],
            "walk" => vec![seg(1e6, 20.0, 0.0, [0.0, 0.0, -1.5])],
            other => return Err(TrackError::Unknown(other.into())),
        };
        Ok(Self { segments })
    }

    /// `builtin:NAME` or a JSON file (`{"segments": [{"seconds": 2,
    /// "yaw_deg_per_s": 90}, ...]}`), validated.
    pub fn load(spec: &str) -> Result<Self, TrackError> {
        let track = match spec.strip_prefix("builtin:") {
            Some(name) => Self::builtin(name)?,
            None => {
                let path = Path::new(spec);
                let text = std::fs::read_to_string(path).map_err(|source| TrackError::Io {
                    path: spec.into(),
                    source,
                })?;
                serde_json::from_str(&text).map_err(|source| TrackError::Parse {
                    path: spec.into(),
                    source,
                })?
            }
        };
        track.validate()?;
        Ok(track)
    }

    /// Checks every value is finite and within the limits above.
    pub fn validate(&self) -> Result<(), TrackError> {
        if self.segments.len() > MAX_SEGMENTS {
            return Err(TrackError::Invalid {
                segment: MAX_SEGMENTS,
                what: "too many segments",
            });
        }
        for (segment, s) in self.segments.iter().enumerate() {
            let bad = |what| Err(TrackError::Invalid { segment, what });
            if !(s.seconds.is_finite() && s.seconds > 0.0 && s.seconds <= 1e6) {
                return bad("seconds must be in (0, 1e6]");
            }
            let rates = [s.yaw_deg_per_s, s.pitch_deg_per_s];
            if !rates
                .iter()
                .all(|r| r.is_finite() && r.abs() <= MAX_RATE_DEG)
            {
                return bad("turn rates must be finite and at most 720°/s");
            }
            let v = DVec3::from(s.velocity);
            if !(v.is_finite() && v.length() <= MAX_SPEED) {
                return bad("velocity must be finite and at most 100 m/s");
            }
        }
        Ok(())
    }

    /// Yaw and pitch (degrees) and displacement (start camera axes) `t`
    /// seconds in; pitch is clamped, and time beyond the last segment
    /// holds still.
    fn state_at(&self, t: f64) -> (f64, f64, DVec3) {
        let (mut yaw, mut pitch, mut moved) = (0.0, 0.0, DVec3::ZERO);
        let mut left = t.max(0.0);
        for s in &self.segments {
            let dt = left.min(s.seconds);
            yaw += s.yaw_deg_per_s * dt;
            pitch = (pitch + s.pitch_deg_per_s * dt).clamp(-PITCH_LIMIT_DEG, PITCH_LIMIT_DEG);
            moved += DVec3::from(s.velocity) * dt;
            left -= dt;
            if left <= 0.0 {
                break;
            }
        }
        (yaw, pitch, moved)
    }

    /// The viewer's camera `t` seconds after `start`.
    pub fn pose_at(&self, start: &Pose, t: f64) -> Pose {
        let (yaw, pitch, moved) = self.state_at(t);
        Pose::new(
            start.position + start.rotation * moved,
            turned(start, yaw, pitch),
        )
    }

    /// The fastest the view turns anywhere on the track, degrees a second
    /// (a bound for how far one display interval moves it).
    pub fn max_turn_deg_per_s(&self) -> f64 {
        self.segments
            .iter()
            .map(|s| s.yaw_deg_per_s.hypot(s.pitch_deg_per_s))
            .fold(0.0, f64::max)
    }
}

/// `start`'s orientation turned by `yaw` about the vertical and tilted by
/// `pitch` about its own right axis (degrees).
fn turned(start: &Pose, yaw: f64, pitch: f64) -> DQuat {
    (DQuat::from_rotation_y(yaw.to_radians())
        * start.rotation
        * DQuat::from_rotation_x(pitch.to_radians()))
    .normalize()
}

/// A movement key of the window's viewer; held, it sets bit
/// `1 << key as u32` of the input's `buttons`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MoveKey {
    /// W.
    Forward,
    /// S.
    Back,
    /// A.
    Left,
    /// D.
    Right,
    /// Space.
    Up,
    /// C.
    Down,
    /// Shift: three times as fast.
    Run,
}

/// The window's bindings, as its overlay shows them.
pub const BINDINGS: &str = "drag: look   W/A/S/D: move   Space/C: up/down   Shift: run";

/// Walking speed of the window's viewer, m/s (a game's default).
pub const WALK_SPEED: f64 = 3.0;
/// Degrees of turn per pixel the mouse is dragged.
pub const LOOK_DEG_PER_PIXEL: f64 = 0.15;

/// The window's viewer: the window feeds it mouse drags and keys, the
/// presenter takes its pose every vsync. Movement follows the current
/// heading; held keys move it at [`WALK_SPEED`] until released.
#[derive(Clone, Debug, Default)]
pub struct LiveViewer(Arc<Mutex<LiveState>>);

#[derive(Debug, Default)]
struct LiveState {
    /// The stream's first camera, once there is one.
    start: Option<Pose>,
    yaw: f64,
    pitch: f64,
    /// Displacement in world space from the start.
    moved: DVec3,
    held: Vec<MoveKey>,
    /// When `moved` was last brought up to date.
    since: Option<Instant>,
}

impl LiveState {
    /// Moves on to `now` with the keys held since the last update.
    fn advance(&mut self, now: Instant) {
        let Some(start) = self.start else {
            return;
        };
        let dt = self
            .since
            .map_or(0.0, |s| now.saturating_duration_since(s).as_secs_f64());
        self.since = Some(now);
        let axis = |k, v: DVec3| {
            if self.held.contains(&k) {
                v
            } else {
                DVec3::ZERO
            }
        };
        let local = axis(MoveKey::Forward, DVec3::NEG_Z)
            + axis(MoveKey::Back, DVec3::Z)
            + axis(MoveKey::Left, DVec3::NEG_X)
            + axis(MoveKey::Right, DVec3::X);
        let vertical = axis(MoveKey::Up, DVec3::Y) + axis(MoveKey::Down, DVec3::NEG_Y);
        let speed = WALK_SPEED
            * if self.held.contains(&MoveKey::Run) {
                3.0
            } else {
                1.0
            };
        let heading = turned(&start, self.yaw, self.pitch);
        let velocity = (heading * local.normalize_or_zero() + vertical) * speed;
        self.moved += velocity * dt;
    }
}

impl LiveViewer {
    fn state(&self) -> std::sync::MutexGuard<'_, LiveState> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The mouse was dragged by `dx`, `dy` pixels (right, down).
    pub fn look(&self, dx: f64, dy: f64) {
        let mut s = self.state();
        s.yaw -= dx * LOOK_DEG_PER_PIXEL;
        s.pitch = (s.pitch - dy * LOOK_DEG_PER_PIXEL).clamp(-PITCH_LIMIT_DEG, PITCH_LIMIT_DEG);
    }

    /// The viewer starts from `start` (the stream's first camera), and
    /// moves from `now` on.
    pub fn begin(&self, start: Pose, now: Instant) {
        let mut s = self.state();
        s.start = Some(start);
        s.since = Some(now);
    }

    /// `key` went down or up at `now`.
    pub fn key(&self, key: MoveKey, down: bool, now: Instant) {
        let mut s = self.state();
        s.advance(now);
        s.held.retain(|&k| k != key);
        if down {
            s.held.push(key);
        }
    }

    /// The movement keys held, as the input's button bits.
    pub fn buttons(&self) -> u32 {
        self.state()
            .held
            .iter()
            .fold(0, |bits, &k| bits | 1 << k as u32)
    }

    /// The viewer's camera at `now`, once it has begun.
    pub fn pose_at(&self, now: Instant) -> Option<Pose> {
        let mut s = self.state();
        s.advance(now);
        let start = s.start?;
        Some(Pose::new(
            start.position + s.moved,
            turned(&start, s.yaw, s.pitch),
        ))
    }
}

/// The angle between two cameras' orientations, degrees.
pub fn angle_deg(a: &Pose, b: &Pose) -> f64 {
    let d = a.rotation.normalize().dot(b.rotation.normalize()).abs();
    (2.0 * d.min(1.0).acos()).to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start() -> Pose {
        Pose::look_at(DVec3::new(0.0, 1.7, 5.0), DVec3::ZERO, DVec3::Y)
    }

    #[test]
    fn a_steady_turn_turns_at_its_rate() {
        let track = InputTrack::builtin("turn").unwrap();
        let s = start();
        for t in [0.0, 0.1, 0.5, 1.0, 1.9] {
            let p = track.pose_at(&s, t);
            assert!((angle_deg(&s, &p) - (90.0 * t).min(360.0 - 90.0 * t)).abs() < 1e-6);
            assert_eq!(p.position, s.position);
        }
        // One 60 Hz interval apart: 1.5°.
        let (a, b) = (track.pose_at(&s, 0.3), track.pose_at(&s, 0.3 + 1.0 / 60.0));
        assert!((angle_deg(&a, &b) - 1.5).abs() < 1e-9);
        assert_eq!(track.max_turn_deg_per_s(), 90.0);
    }

    #[test]
    fn segments_follow_each_other_then_hold() {
        let track = InputTrack {
            segments: vec![
                TrackSegment {
                    seconds: 1.0,
                    yaw_deg_per_s: 0.0,
                    pitch_deg_per_s: 0.0,
                    velocity: [0.0, 0.0, -2.0],
                },
                TrackSegment {
                    seconds: 1.0,
                    yaw_deg_per_s: 0.0,
                    pitch_deg_per_s: 120.0,
                    velocity: [1.0, 0.0, 0.0],
                },
            ],
        };
        track.validate().unwrap();
        let s = start();
        // Forward 2 m along the start camera's view, then 1 m right.
        let forward = s.rotation * DVec3::NEG_Z;
        let right = s.rotation * DVec3::X;
        let p = track.pose_at(&s, 1.0);
        assert!((p.position - (s.position + 2.0 * forward)).length() < 1e-12);
        let end = track.pose_at(&s, 5.0);
        assert!((end.position - (s.position + 2.0 * forward + right)).length() < 1e-12);
        // Pitch stops at 89°.
        assert!((angle_deg(&s, &end) - 89.0).abs() < 1e-6);
        assert_eq!(end, track.pose_at(&s, 50.0));
    }

    #[test]
    fn the_live_viewer_looks_and_walks_along_its_heading() {
        let viewer = LiveViewer::default();
        // Level, so that pitch is elevation.
        let s = Pose::look_at(
            DVec3::new(0.0, 1.7, 5.0),
            DVec3::new(0.0, 1.7, 0.0),
            DVec3::Y,
        );
        let t0 = Instant::now();
        let at = |ms| t0 + std::time::Duration::from_millis(ms);
        assert_eq!(viewer.pose_at(t0), None);
        // Keys before the stream starts move nothing.
        viewer.key(MoveKey::Forward, true, t0);
        viewer.begin(s, at(1000));
        viewer.key(MoveKey::Forward, false, at(1000));
        assert_eq!(
            viewer.pose_at(at(1000)),
            Some(Pose::new(s.position, s.rotation.normalize()))
        );
        // Dragged 600 px to the right: 90° to the right.
        viewer.look(600.0, 0.0);
        let p = viewer.pose_at(at(1000)).unwrap();
        assert!((angle_deg(&s, &p) - 90.0).abs() < 1e-9);
        // W held for half a second: 1.5 m along the new heading.
        viewer.key(MoveKey::Forward, true, at(1000));
        viewer.key(MoveKey::Run, true, at(1000));
        viewer.key(MoveKey::Run, false, at(1000));
        assert_eq!(viewer.buttons(), 1 << MoveKey::Forward as u32);
        viewer.key(MoveKey::Forward, false, at(1500));
        assert_eq!(viewer.buttons(), 0);
        let p = viewer.pose_at(at(3000)).unwrap();
        let heading = p.rotation * DVec3::NEG_Z;
        assert!((p.position - (s.position + 1.5 * heading)).length() < 1e-9);
        // Dragging far up stops at the pitch limit.
        viewer.look(0.0, -1e5);
        let up = viewer.pose_at(at(3000)).unwrap().rotation * DVec3::NEG_Z;
        assert!((up.y.asin().to_degrees() - 89.0).abs() < 1.0, "{up}");
    }

    #[test]
    fn bad_tracks_are_typed_errors() {
        let bad = |seconds, yaw, v: f64| InputTrack {
            segments: vec![TrackSegment {
                seconds,
                yaw_deg_per_s: yaw,
                pitch_deg_per_s: 0.0,
                velocity: [v, 0.0, 0.0],
            }],
        };
        for t in [
            bad(f64::NAN, 0.0, 0.0),
            bad(-1.0, 0.0, 0.0),
            bad(1.0, 1e4, 0.0),
            bad(1.0, 0.0, f64::INFINITY),
            bad(1.0, 0.0, 1e3),
        ] {
            assert!(
                matches!(t.validate(), Err(TrackError::Invalid { .. })),
                "{t:?}"
            );
        }
        assert!(matches!(
            InputTrack::load("builtin:nope"),
            Err(TrackError::Unknown(_))
        ));
        assert!(matches!(
            InputTrack::load("/nonexistent/track.json"),
            Err(TrackError::Io { .. })
        ));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.json");
        std::fs::write(&path, r#"{"segments": [{"seconds": 2, "yaw": 3}]}"#).unwrap();
        assert!(matches!(
            InputTrack::load(path.to_str().unwrap()),
            Err(TrackError::Parse { .. })
        ));
        std::fs::write(
            &path,
            r#"{"segments": [{"seconds": 2, "yaw_deg_per_s": 30}]}"#,
        )
        .unwrap();
        let t = InputTrack::load(path.to_str().unwrap()).unwrap();
        assert_eq!(t.segments[0].yaw_deg_per_s, 30.0);
    }
}
