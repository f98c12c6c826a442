//! The adaptive rendering window (GFFE §4.3, appendix C, eq. 5).
//!
//! Before rendering frame t the server predicts the camera of the frames the
//! client will extrapolate from it (eq. 2, [`protocol::Pose::extrapolate`]),
//! intersects both frusta with a virtual plane at distance `d` in front of
//! the current camera, and widens the rendered window to the union of the two
//! footprints, so extrapolated frames have content at their borders
//! (out-of-screen disocclusion).
//!
//! Choices the paper leaves open, made here:
//! * the prediction horizon α is one render interval (the next rendered
//!   frame replaces the extrapolated ones), configurable;
//! * `d` is a setting (default 10 world units);
//! * a corner ray of the predicted camera that does not reach the plane
//!   (turned away by more than the field of view) widens that side to the
//!   cap, and every side is capped (`max_extent`) so fast rotation cannot
//!   blow up the rendered size;
//! * the window is snapped outward to whole pixels of the display density,
//!   so with [`WindowMode::KeepDensity`] the displayed region is an exact
//!   pixel crop of the rendered image;
//! * each widened side is rounded up to a multiple of [`margin_step`]
//!   (about 2.5 % of the side, even), so the rendered size changes only
//!   when a margin crosses a
//!   step: a video encoder restarts with a keyframe at every new size, and
//!   a size that changed with every frame made every frame a keyframe (the
//!   live demo at 320×180 missed twice the vsyncs).

use glam::{DVec2, DVec3};
use protocol::wire::WindowMode;
use protocol::{Camera, FrameSize, Pose, Window};

/// Settings of the adaptive window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowSettings {
    /// Off, keep pixel density (rendered size grows), or keep the size.
    pub mode: WindowMode,
    /// Distance of the virtual plane in front of the camera, world units.
    pub plane_distance: f64,
    /// How far ahead the camera is predicted, in render intervals.
    pub horizon: f64,
    /// Largest |bound| of the window in base NDC (1 = no widening).
    pub max_extent: f64,
}

impl Default for WindowSettings {
    fn default() -> Self {
        Self {
            mode: WindowMode::Off,
            plane_distance: 10.0,
            horizon: 1.0,
            max_extent: 1.5,
        }
    }
}

/// Eq. 5: the window of `cur` covering its own view and the predicted
/// camera's view on the virtual plane. `prev` is the previous frame's pose.
/// Returns [`Window::FULL`] when the mode is off.
pub fn adaptive_window(settings: &WindowSettings, prev: &Pose, cur: &Camera) -> Window {
    if settings.mode == WindowMode::Off {
        return Window::FULL;
    }
    let cap = settings.max_extent.max(1.0);
    let d = settings.plane_distance.max(1e-3);
    let predicted = Pose::extrapolate(prev, &cur.pose, settings.horizon);
    let t = cur.projection.tan_half_fov();
    let a = cur.projection.aspect;
    // The current camera's footprint on the plane z = −d (its own view space):
    // x in ±d·t·a, y in ±d·t.
    let (x_max, y_max) = (d * t * a, d * t);
    // The predicted camera's position and corner rays in the current view.
    let inv = cur.pose.rotation.normalize().conjugate();
    let origin = inv * (predicted.position - cur.pose.position);
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let ray_local = DVec3::new(sx * t * a, sy * t, -1.0);
        let ray = inv * (predicted.rotation.normalize() * ray_local);
        // Reach z = −d from origin along ray.
        let s = if ray.z < -1e-9 {
            (-d - origin.z) / ray.z
        } else {
            -1.0
        };
        if s > 0.0 {
            let p = origin + ray * s;
            lo = lo.min(DVec2::new(p.x, p.y));
            hi = hi.max(DVec2::new(p.x, p.y));
        } else {
            // The corner never meets the plane: widen towards its side.
            if ray.x < 0.0 {
                lo.x = lo.x.min(-x_max * cap);
            } else {
                hi.x = hi.x.max(x_max * cap);
            }
            if ray.y < 0.0 {
                lo.y = lo.y.min(-y_max * cap);
            } else {
                hi.y = hi.y.max(y_max * cap);
            }
        }
    }
    // Rounding noise (1 ± 1e-16 for a still camera) is not a widening.
    let clamp = |v: f64, fallback: f64| {
        if !v.is_finite() {
            fallback
        } else if (v.abs() - 1.0).abs() < 1e-9 {
            v.signum()
        } else {
            v.clamp(-cap, cap)
        }
    };
    Window {
        u0: clamp((lo.x / x_max).min(-1.0), -1.0),
        v0: clamp((lo.y / y_max).min(-1.0), -1.0),
        u1: clamp((hi.x / x_max).max(1.0), 1.0),
        v1: clamp((hi.y / y_max).max(1.0), 1.0),
    }
}

/// The widened sides' margins are multiples of this many display pixels
/// along a side of `pixels`: an even number near 2.5 % of it (8 of 320, 4
/// of 180, 32 of 1280; 2 at least), so the size stays even for 4:2:0 video
/// and few sizes occur.
pub fn margin_step(pixels: u32) -> f64 {
    2.0 * (f64::from(pixels) / 80.0).round().max(1.0)
}

/// Snaps `window` outward to whole display pixels and gives the rendered
/// size: with [`WindowMode::KeepDensity`] the size grows with the window, with
/// [`WindowMode::KeepSize`] it stays `display`.
pub fn snap(mode: WindowMode, window: Window, display: FrameSize) -> (Window, FrameSize) {
    if mode == WindowMode::Off || window.is_full() {
        return (Window::FULL, display);
    }
    let px = 2.0 / f64::from(display.width);
    let py = 2.0 / f64::from(display.height);
    let extra = |ndc: f64, step: f64, whole: f64| {
        ((ndc - 1.0).max(0.0) / step / whole - 1e-9).ceil().max(0.0) * whole
    };
    let (sx, sy) = (margin_step(display.width), margin_step(display.height));
    let (l, r) = (extra(-window.u0, px, sx), extra(window.u1, px, sx));
    let (b, t) = (extra(-window.v0, py, sy), extra(window.v1, py, sy));
    let snapped = Window {
        u0: -1.0 - l * px,
        u1: 1.0 + r * px,
        v0: -1.0 - b * py,
        v1: 1.0 + t * py,
    };
    let size = match mode {
        WindowMode::KeepDensity => FrameSize::new(
            display.width + l as u32 + r as u32,
            display.height + b as u32 + t as u32,
        ),
        _ => display,
    };
    (snapped, size)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;
    use protocol::Projection;

    fn cam(pose: Pose) -> Camera {
        Camera::new(
            pose,
            Projection::perspective(60f64.to_radians(), 16.0 / 9.0, 0.1, 100.0),
        )
    }

    fn on() -> WindowSettings {
        WindowSettings {
            mode: WindowMode::KeepDensity,
            ..WindowSettings::default()
        }
    }

    #[test]
    fn a_still_camera_keeps_the_plain_window() {
        let p = Pose::look_at(DVec3::new(1.0, 2.0, 3.0), DVec3::ZERO, DVec3::Y);
        assert_eq!(adaptive_window(&on(), &p, &cam(p)), Window::FULL);
        assert_eq!(
            adaptive_window(&WindowSettings::default(), &p, &cam(p)),
            Window::FULL
        );
    }

    #[test]
    fn turning_left_widens_the_left_side() {
        let prev = Pose::new(DVec3::ZERO, DQuat::IDENTITY);
        let cur = Pose::new(DVec3::ZERO, DQuat::from_rotation_y(3f64.to_radians()));
        let w = adaptive_window(&on(), &prev, &cam(cur));
        assert!(w.u0 < -1.05 && w.u1 == 1.0, "{w:?}");
        // The turned frustum's far-side corners meet the plane further out,
        // so eq. 5 also widens the window vertically, symmetrically.
        assert!(w.v1 > 1.0 && (w.v0 + w.v1).abs() < 1e-12, "{w:?}");
        // Moving right widens the right side (the plane is 10 units away).
        let prev = Pose::new(DVec3::ZERO, DQuat::IDENTITY);
        let cur = Pose::new(DVec3::X * 0.5, DQuat::IDENTITY);
        let w = adaptive_window(&on(), &prev, &cam(cur));
        assert!(w.u1 > 1.04 && w.u0 == -1.0, "{w:?}");
        w.validate().unwrap();
    }

    #[test]
    fn fast_turns_are_capped_and_stay_finite() {
        let prev = Pose::new(DVec3::ZERO, DQuat::IDENTITY);
        for deg in [30.0, 89.0, 120.0, 179.0] {
            let cur = Pose::new(DVec3::ZERO, DQuat::from_rotation_y(f64::to_radians(deg)));
            let w = adaptive_window(&on(), &prev, &cam(cur));
            assert!(w.validate().is_ok(), "{deg}: {w:?}");
            assert!(
                w.u0 >= -1.5 && w.u1 <= 1.5 && w.v0 >= -1.5 && w.v1 <= 1.5,
                "{deg}: {w:?}"
            );
        }
    }

    #[test]
    fn snapping_keeps_density_and_contains_the_window() {
        let display = FrameSize::new(320, 180);
        let w = Window {
            u0: -1.1033,
            v0: -1.0,
            u1: 1.0,
            v1: 1.02,
        };
        let (s, size) = snap(WindowMode::KeepDensity, w, display);
        assert!(s.u0 <= w.u0 && s.v1 >= w.v1 && s.u1 == 1.0 && s.v0 == -1.0);
        // Same pixel density as the display.
        let density = f64::from(size.width) / s.width();
        assert!(
            (density - 160.0).abs() < 1e-9
                && (f64::from(size.height) / s.height() - 90.0).abs() < 1e-9
        );
        let (x0, y0, x1, y1) = s.display_rect(size.as_f64());
        assert!((x0 - x0.round()).abs() < 1e-9 && (y0 - y0.round()).abs() < 1e-9);
        assert!((x1 - x0 - 320.0).abs() < 1e-9 && (y1 - y0 - 180.0).abs() < 1e-9);
        let (_, kept) = snap(WindowMode::KeepSize, w, display);
        assert_eq!(kept, display);
        // Margins in whole steps of 8 and 4 px: 0.1033 of 160 px is
        // 16.5 px, so 24; 0.02 of 90 px is 1.8, so 4.
        assert_eq!((margin_step(320), margin_step(180)), (8.0, 4.0));
        assert_eq!(size, FrameSize::new(320 + 24, 180 + 4));
        // A slightly different widening keeps the size.
        let near = Window { u0: -1.12, ..w };
        assert_eq!(snap(WindowMode::KeepDensity, near, display).1, size);
    }
}
