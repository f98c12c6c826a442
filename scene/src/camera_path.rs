//! Camera paths: static, orbit, pan (rotation in place), dolly, smooth
//! keyframes (Catmull-Rom), and shot lists whose boundaries are camera cuts;
//! plus an optional deterministic shake. All pure functions of time.

use std::f64::consts::TAU;

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// The camera: projection and path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Vertical field of view in degrees.
    pub fov_y_deg: f64,
    /// Near plane.
    #[serde(default = "default_near")]
    pub near: f64,
    /// Far plane; absent means infinite.
    #[serde(default)]
    pub far: Option<f64>,
    /// Where the camera is and looks over time.
    pub path: CameraPath,
    /// Optional hand-held shake.
    #[serde(default)]
    pub shake: Option<Shake>,
}

fn default_near() -> f64 {
    0.05
}

/// Deterministic hand-held shake: sums of sines at incommensurate rates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shake {
    /// Offset amplitude in world units.
    pub amplitude: f64,
    /// Base frequency in Hz.
    pub frequency: f64,
}

/// One camera keyframe.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKey {
    /// Time in seconds.
    pub t: f64,
    /// Eye position.
    pub eye: [f64; 3],
    /// Look-at point.
    pub target: [f64; 3],
}

/// One shot of a shot list.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shot {
    /// The shot lasts until this time (the last shot lasts forever).
    pub until: f64,
    /// The path during the shot (its time starts at 0 at the shot start).
    pub path: CameraPath,
}

/// A camera path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum CameraPath {
    /// Fixed.
    Static {
        /// Eye position.
        eye: [f64; 3],
        /// Look-at point.
        target: [f64; 3],
    },
    /// Circles `center` at `radius` and `height`, looking at `center`.
    Orbit {
        /// Orbit centre (also the look-at point).
        center: [f64; 3],
        /// Orbit radius.
        radius: f64,
        /// Eye height above the centre.
        height: f64,
        /// Seconds per turn (negative turns the other way).
        period_s: f64,
        /// Starting angle in degrees.
        #[serde(default)]
        start_deg: f64,
    },
    /// Stands at `eye` and turns about the vertical axis.
    Pan {
        /// Eye position.
        eye: [f64; 3],
        /// Initial heading in degrees (0 looks down −Z).
        yaw_start_deg: f64,
        /// Turn rate in degrees per second.
        deg_per_s: f64,
        /// Pitch in degrees (positive looks up).
        #[serde(default)]
        pitch_deg: f64,
    },
    /// Moves from `from` to `to` and back, smoothly, looking along `look_dir`.
    Dolly {
        /// Start position.
        from: [f64; 3],
        /// End position.
        to: [f64; 3],
        /// Seconds for one way.
        duration_s: f64,
        /// Fixed view direction.
        look_dir: [f64; 3],
    },
    /// Smooth (Catmull-Rom) interpolation of keyframes, clamped at the ends.
    Keyframes(Vec<CameraKey>),
    /// Consecutive shots; each boundary is a camera cut.
    Shots(Vec<Shot>),
}

impl CameraSpec {
    /// Eye, target and shot index at time `t`, relative to the scene origin.
    pub fn eye_target(&self, t: f64) -> (DVec3, DVec3, usize) {
        let (mut eye, mut target, shot) = self.path.eye_target(t);
        if let Some(s) = self.shake {
            let w = TAU * s.frequency * t;
            let jitter = |a: f64, b: f64, c: f64| {
                DVec3::new(
                    (w * a + 0.3).sin() + 0.5 * (w * 2.31 * a + 1.7).sin(),
                    (w * b + 1.1).sin() + 0.5 * (w * 1.93 * b + 0.2).sin(),
                    (w * c + 2.3).sin() + 0.5 * (w * 2.71 * c + 2.9).sin(),
                ) * (s.amplitude / 1.5)
            };
            eye += jitter(1.0, 1.37, 0.71);
            target += jitter(0.83, 1.13, 1.61);
        }
        (eye, target, shot)
    }

    /// Checks ranges; returns the field and the message.
    pub fn validate(&self) -> Result<(), (String, String)> {
        if !(self.fov_y_deg > 1.0 && self.fov_y_deg < 179.0) {
            return Err(("fov_y_deg".into(), "must be in (1, 179)".into()));
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return Err(("near".into(), "must be finite and > 0".into()));
        }
        if let Some(far) = self.far {
            if !(far.is_finite() && far > self.near) {
                return Err((
                    "far".into(),
                    "must be finite and > near (omit it for infinity)".into(),
                ));
            }
        }
        if let Some(s) = self.shake {
            if !(s.amplitude.is_finite()
                && s.amplitude >= 0.0
                && s.frequency.is_finite()
                && s.frequency >= 0.0)
            {
                return Err((
                    "shake".into(),
                    "amplitude and frequency must be finite and ≥ 0".into(),
                ));
            }
        }
        self.path
            .validate()
            .map_err(|(f, m)| (format!("path{f}"), m))
    }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl CameraPath {
    /// Eye, target and shot index at time `t`.
    pub fn eye_target(&self, t: f64) -> (DVec3, DVec3, usize) {
        match self {
            CameraPath::Static { eye, target } => (DVec3::from(*eye), DVec3::from(*target), 0),
            CameraPath::Orbit {
                center,
                radius,
                height,
                period_s,
                start_deg,
            } => {
                let a = start_deg.to_radians() + TAU * t / period_s;
                let c = DVec3::from(*center);
                (
                    c + DVec3::new(a.cos() * radius, *height, a.sin() * radius),
                    c,
                    0,
                )
            }
            CameraPath::Pan {
                eye,
                yaw_start_deg,
                deg_per_s,
                pitch_deg,
            } => {
                let yaw = (yaw_start_deg + deg_per_s * t).to_radians();
                let pitch = pitch_deg.to_radians();
                let dir = DVec3::new(
                    -yaw.sin() * pitch.cos(),
                    pitch.sin(),
                    -yaw.cos() * pitch.cos(),
                );
                let eye = DVec3::from(*eye);
                (eye, eye + dir, 0)
            }
            CameraPath::Dolly {
                from,
                to,
                duration_s,
                look_dir,
            } => {
                // Triangle wave 0 → 1 → 0 with smoothstep easing.
                let phase = (t / duration_s).rem_euclid(2.0);
                let u = if phase <= 1.0 { phase } else { 2.0 - phase };
                let s = u * u * (3.0 - 2.0 * u);
                let eye = DVec3::from(*from).lerp(DVec3::from(*to), s);
                (eye, eye + DVec3::from(*look_dir), 0)
            }
            CameraPath::Keyframes(keys) => {
                let eye = catmull_rom(keys, t, |k| DVec3::from(k.eye));
                let target = catmull_rom(keys, t, |k| DVec3::from(k.target));
                (eye, target, 0)
            }
            CameraPath::Shots(shots) => {
                let mut start = 0.0;
                for (i, shot) in shots.iter().enumerate() {
                    if t < shot.until || i + 1 == shots.len() {
                        let (eye, target, _) = shot.path.eye_target(t - start);
                        return (eye, target, i);
                    }
                    start = shot.until;
                }
                (DVec3::ZERO, DVec3::NEG_Z, 0)
            }
        }
    }

    /// Checks ranges; returns a field suffix and the message.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, m: &str| Err((f.to_owned(), m.to_owned()));
        match self {
            CameraPath::Static { eye, target } => {
                if !finite(eye) || !finite(target) || eye == target {
                    return bad(".Static", "eye and target must be finite and distinct");
                }
            }
            CameraPath::Orbit {
                center,
                radius,
                height,
                period_s,
                start_deg,
            } => {
                if !finite(center)
                    || !finite(&[*radius, *height, *period_s, *start_deg])
                    || *period_s == 0.0
                {
                    return bad(".Orbit", "values must be finite and period_s non-zero");
                }
                if *radius == 0.0 && *height == 0.0 {
                    return bad(".Orbit", "radius or height must be non-zero");
                }
            }
            CameraPath::Pan {
                eye,
                yaw_start_deg,
                deg_per_s,
                pitch_deg,
            } => {
                if !finite(eye)
                    || !finite(&[*yaw_start_deg, *deg_per_s, *pitch_deg])
                    || pitch_deg.abs() >= 89.0
                {
                    return bad(".Pan", "values must be finite and |pitch_deg| < 89");
                }
            }
            CameraPath::Dolly {
                from,
                to,
                duration_s,
                look_dir,
            } => {
                if !finite(from)
                    || !finite(to)
                    || !finite(look_dir)
                    || duration_s.is_nan()
                    || *duration_s <= 0.0
                {
                    return bad(".Dolly", "values must be finite and duration_s > 0");
                }
                if DVec3::from(*look_dir).length_squared() < 1e-12 {
                    return bad(".Dolly.look_dir", "must be non-zero");
                }
            }
            CameraPath::Keyframes(keys) => {
                if keys.len() < 2 {
                    return bad(".Keyframes", "needs at least 2 keys");
                }
                for (i, k) in keys.iter().enumerate() {
                    if !finite(&[k.t]) || !finite(&k.eye) || !finite(&k.target) || k.eye == k.target
                    {
                        return Err((
                            format!(".Keyframes[{i}]"),
                            "must be finite, eye ≠ target".into(),
                        ));
                    }
                    if i > 0 && k.t <= keys[i - 1].t {
                        return Err((format!(".Keyframes[{i}].t"), "times must increase".into()));
                    }
                }
            }
            CameraPath::Shots(shots) => {
                if shots.is_empty() {
                    return bad(".Shots", "needs at least one shot");
                }
                for (i, s) in shots.iter().enumerate() {
                    if !(s.until.is_finite() && s.until > 0.0)
                        || (i > 0 && s.until <= shots[i - 1].until)
                    {
                        return Err((
                            format!(".Shots[{i}].until"),
                            "must be finite, > 0 and increasing".into(),
                        ));
                    }
                    s.path
                        .validate()
                        .map_err(|(f, m)| (format!(".Shots[{i}].path{f}"), m))?;
                }
            }
        }
        Ok(())
    }
}

/// Uniform Catmull-Rom through the keys' values, parameterised by each
/// segment's time; clamped before the first and after the last key.
fn catmull_rom(keys: &[CameraKey], t: f64, value: impl Fn(&CameraKey) -> DVec3) -> DVec3 {
    let last = keys.len() - 1;
    if t <= keys[0].t {
        return value(&keys[0]);
    }
    if t >= keys[last].t {
        return value(&keys[last]);
    }
    let i = keys.windows(2).position(|w| t < w[1].t).unwrap_or(last - 1);
    let u = (t - keys[i].t) / (keys[i + 1].t - keys[i].t);
    let p0 = value(&keys[i.saturating_sub(1)]);
    let p1 = value(&keys[i]);
    let p2 = value(&keys[i + 1]);
    let p3 = value(&keys[(i + 2).min(last)]);
    0.5 * (2.0 * p1
        + (p2 - p0) * u
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u * u
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * u * u * u)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(t: f64, x: f64) -> CameraKey {
        CameraKey {
            t,
            eye: [x, 1.0, 0.0],
            target: [x, 0.0, -1.0],
        }
    }

    #[test]
    fn keyframes_pass_through_keys_and_are_continuous() {
        let p = CameraPath::Keyframes(vec![
            key(0.0, 0.0),
            key(1.0, 2.0),
            key(2.0, 3.0),
            key(4.0, 0.0),
        ]);
        for k in [0.0, 1.0, 2.0, 4.0] {
            let (eye, _, _) = p.eye_target(k);
            let want = match k as u32 {
                0 => 0.0,
                1 => 2.0,
                2 => 3.0,
                _ => 0.0,
            };
            assert!((eye.x - want).abs() < 1e-12, "t={k}: {eye}");
        }
        // No jumps: small steps give small moves.
        let mut last = p.eye_target(0.0).0;
        for i in 1..=400 {
            let e = p.eye_target(i as f64 * 0.01).0;
            assert!((e - last).length() < 0.05);
            last = e;
        }
        assert_eq!(p.eye_target(-5.0).0, p.eye_target(0.0).0);
        assert_eq!(p.eye_target(50.0).0, p.eye_target(4.0).0);
    }

    #[test]
    fn shots_cut_and_restart_their_clock() {
        let p = CameraPath::Shots(vec![
            Shot {
                until: 1.0,
                path: CameraPath::Static {
                    eye: [0.0, 1.0, 5.0],
                    target: [0.0; 3],
                },
            },
            Shot {
                until: 2.0,
                path: CameraPath::Pan {
                    eye: [10.0, 1.0, 0.0],
                    yaw_start_deg: 0.0,
                    deg_per_s: 90.0,
                    pitch_deg: 0.0,
                },
            },
        ]);
        assert_eq!(p.eye_target(0.99).2, 0);
        let (eye, target, shot) = p.eye_target(1.0);
        assert_eq!(shot, 1);
        assert_eq!(eye, DVec3::new(10.0, 1.0, 0.0));
        assert!(
            (target - eye - DVec3::NEG_Z).length() < 1e-12,
            "pan clock restarts at the cut"
        );
        assert_eq!(p.eye_target(7.0).2, 1, "the last shot lasts");
    }

    #[test]
    fn pan_orbit_dolly_are_periodic_or_bounded() {
        let pan = CameraPath::Pan {
            eye: [0.0; 3],
            yaw_start_deg: 0.0,
            deg_per_s: 90.0,
            pitch_deg: 0.0,
        };
        let (e, t, _) = pan.eye_target(1.0);
        assert!(
            (t - e - DVec3::NEG_X).length() < 1e-12,
            "90° left of −Z is −X"
        );
        let orbit = CameraPath::Orbit {
            center: [0.0; 3],
            radius: 2.0,
            height: 1.0,
            period_s: 4.0,
            start_deg: 0.0,
        };
        assert!((orbit.eye_target(0.0).0 - orbit.eye_target(4.0).0).length() < 1e-12);
        let dolly = CameraPath::Dolly {
            from: [0.0; 3],
            to: [0.0, 0.0, -10.0],
            duration_s: 2.0,
            look_dir: [0.0, 0.0, -1.0],
        };
        assert!((dolly.eye_target(2.0).0.z + 10.0).abs() < 1e-12);
        assert!(dolly.eye_target(4.0).0.length() < 1e-12);
    }

    #[test]
    fn shake_is_deterministic_and_bounded() {
        let spec = CameraSpec {
            fov_y_deg: 60.0,
            near: 0.1,
            far: None,
            path: CameraPath::Static {
                eye: [0.0, 1.0, 0.0],
                target: [0.0, 1.0, -1.0],
            },
            shake: Some(Shake {
                amplitude: 0.1,
                frequency: 3.0,
            }),
        };
        for i in 0..100 {
            let t = i as f64 * 0.037;
            assert_eq!(spec.eye_target(t), spec.eye_target(t));
            assert!((spec.eye_target(t).0 - DVec3::Y).length() <= 0.1 * 3f64.sqrt() + 1e-12);
        }
    }
}
