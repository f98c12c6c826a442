//! Per-object animation: pure functions of time that turn the object's
//! placed (local → scene) matrix into the animated one. Animations apply in
//! list order, each on top of the previous result.

use std::f64::consts::TAU;

use glam::{DMat4, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// A position keyframe.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionKey {
    /// Time in seconds.
    pub t: f64,
    /// Offset added to the object's position.
    pub offset: [f64; 3],
}

/// One animation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Animation {
    /// Constant velocity, world units per second.
    Translate {
        /// Velocity.
        velocity: [f64; 3],
    },
    /// Spin about an axis through the object's own position.
    Rotate {
        /// Axis (normalised on use).
        axis: [f64; 3],
        /// Degrees per second.
        deg_per_s: f64,
    },
    /// Circle `center` in the XZ plane (position only; orientation kept).
    Orbit {
        /// Circle centre, scene coordinates.
        center: [f64; 3],
        /// Circle radius.
        radius: f64,
        /// Seconds per turn.
        period_s: f64,
        /// Starting angle in degrees.
        #[serde(default)]
        start_deg: f64,
    },
    /// Bounce up and down: `height · |sin(π t / period)|`.
    Bounce {
        /// Peak height.
        height: f64,
        /// Seconds per bounce.
        period_s: f64,
    },
    /// Back and forth along a vector: `offset · sin(2π t / period)`.
    Oscillate {
        /// Peak offset.
        offset: [f64; 3],
        /// Seconds per cycle.
        period_s: f64,
    },
    /// Linear interpolation of position offsets, clamped at the ends.
    Keyframes(Vec<PositionKey>),
}

impl Animation {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let ok = match self {
            Animation::Translate { velocity } => finite(velocity),
            Animation::Rotate { axis, deg_per_s } => {
                finite(axis) && deg_per_s.is_finite() && DVec3::from(*axis).length_squared() > 1e-12
            }
            Animation::Orbit {
                center,
                radius,
                period_s,
                start_deg,
            } => finite(center) && finite(&[*radius, *period_s, *start_deg]) && *period_s != 0.0,
            Animation::Bounce { height, period_s } => {
                finite(&[*height, *period_s]) && *period_s > 0.0
            }
            Animation::Oscillate { offset, period_s } => {
                finite(offset) && period_s.is_finite() && *period_s > 0.0
            }
            Animation::Keyframes(keys) => {
                !keys.is_empty()
                    && keys.iter().all(|k| k.t.is_finite() && finite(&k.offset))
                    && keys.windows(2).all(|w| w[1].t > w[0].t)
            }
        };
        if ok {
            Ok(())
        } else {
            Err(
                "values must be finite, periods non-zero, axes non-zero, key times increasing"
                    .into(),
            )
        }
    }

    /// Applies this animation at time `t` to the matrix `m`.
    pub fn apply(&self, t: f64, m: DMat4) -> DMat4 {
        let translate = |d: DVec3| DMat4::from_translation(d) * m;
        match self {
            Animation::Translate { velocity } => translate(DVec3::from(*velocity) * t),
            Animation::Rotate { axis, deg_per_s } => {
                let pivot = m.w_axis.truncate();
                let r = DQuat::from_axis_angle(
                    DVec3::from(*axis).normalize(),
                    (deg_per_s * t).to_radians(),
                );
                DMat4::from_translation(pivot)
                    * DMat4::from_quat(r)
                    * DMat4::from_translation(-pivot)
                    * m
            }
            Animation::Orbit {
                center,
                radius,
                period_s,
                start_deg,
            } => {
                let a = start_deg.to_radians() + TAU * t / period_s;
                let target =
                    DVec3::from(*center) + DVec3::new(a.cos() * radius, 0.0, a.sin() * radius);
                let here = m.w_axis.truncate();
                translate(DVec3::new(target.x - here.x, 0.0, target.z - here.z))
            }
            Animation::Bounce { height, period_s } => {
                translate(DVec3::Y * height * (std::f64::consts::PI * t / period_s).sin().abs())
            }
            Animation::Oscillate { offset, period_s } => {
                translate(DVec3::from(*offset) * (TAU * t / period_s).sin())
            }
            Animation::Keyframes(keys) => {
                let last = keys.len() - 1;
                let offset = if t <= keys[0].t {
                    DVec3::from(keys[0].offset)
                } else if t >= keys[last].t {
                    DVec3::from(keys[last].offset)
                } else {
                    let i = keys.windows(2).position(|w| t < w[1].t).unwrap_or(last - 1);
                    let u = (t - keys[i].t) / (keys[i + 1].t - keys[i].t);
                    DVec3::from(keys[i].offset).lerp(DVec3::from(keys[i + 1].offset), u)
                };
                translate(offset)
            }
        }
    }
}

/// Applies every animation in order.
pub fn apply(animations: &[Animation], t: f64, placed: DMat4) -> DMat4 {
    animations.iter().fold(placed, |m, a| a.apply(t, m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn animations_move_as_declared() {
        let at = |a: &Animation, t: f64| {
            a.apply(t, DMat4::from_translation(DVec3::new(1.0, 0.0, 0.0)))
                .w_axis
                .truncate()
        };
        let tr = Animation::Translate {
            velocity: [0.0, 0.0, -2.0],
        };
        assert_eq!(at(&tr, 1.5), DVec3::new(1.0, 0.0, -3.0));
        let orbit = Animation::Orbit {
            center: [0.0; 3],
            radius: 3.0,
            period_s: 4.0,
            start_deg: 0.0,
        };
        assert!((at(&orbit, 1.0) - DVec3::new(0.0, 0.0, 3.0)).length() < 1e-12);
        let bounce = Animation::Bounce {
            height: 2.0,
            period_s: 1.0,
        };
        assert!((at(&bounce, 0.5).y - 2.0).abs() < 1e-12 && at(&bounce, 1.0).y.abs() < 1e-12);
        // Rotation spins in place.
        let spin = Animation::Rotate {
            axis: [0.0, 1.0, 0.0],
            deg_per_s: 90.0,
        };
        assert!((at(&spin, 1.0) - DVec3::X).length() < 1e-12);
        let keys = Animation::Keyframes(vec![
            PositionKey {
                t: 0.0,
                offset: [0.0; 3],
            },
            PositionKey {
                t: 2.0,
                offset: [4.0, 0.0, 0.0],
            },
        ]);
        assert_eq!(at(&keys, 1.0), DVec3::new(3.0, 0.0, 0.0));
        assert_eq!(at(&keys, 9.0), DVec3::new(5.0, 0.0, 0.0));
    }

    #[test]
    fn validation_rejects_degenerate_values() {
        assert!(
            Animation::Rotate {
                axis: [0.0; 3],
                deg_per_s: 1.0
            }
            .validate()
            .is_err()
        );
        assert!(
            Animation::Bounce {
                height: 1.0,
                period_s: 0.0
            }
            .validate()
            .is_err()
        );
        assert!(Animation::Keyframes(vec![]).validate().is_err());
    }
}
