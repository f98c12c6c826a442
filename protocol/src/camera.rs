//! Camera pose, projection and the adaptive rendering window (DESIGN §3, §4.5).
//!
//! # Conventions
//!
//! * **World.** Right-handed, +Y up. Positions are `f64` so worlds with
//!   coordinates around 1e5..1e7 keep sub-millimetre precision; per-pixel data
//!   is made camera-relative (see [`Camera::to_camera_relative`]) before it is
//!   stored in `f32`.
//! * **Camera.** Looks down its local −Z, local +Y is up and +X is right (glam
//!   conventions). [`Pose::rotation`] maps camera-local axes to world axes.
//! * **Projection.** Perspective with a vertical field of view, the display
//!   aspect (width / height of the *displayed* region), near and far planes.
//!   NDC x and y are in [−1, 1] over the displayed region, +y up; NDC z is in
//!   [0, 1] as in wgpu.
//! * **Window.** The rendered image covers the NDC rectangle
//!   `[u0, u1] × [v0, v1]` of the base projection (GFFE appendix C, eq. 5). The
//!   plain window is `(−1, −1, 1, 1)`; a widened window renders extra content
//!   around the displayed region, which the client crops away.
//! * **Pixels.** Origin at the top-left corner of the rendered image, x right,
//!   y down; pixel `(i, j)` has its centre at `(i + 0.5, j + 0.5)`.
//! * **Depth.** Linear view depth: the positive distance along the camera's
//!   view axis (−Z), in world units. `+inf` means sky / no geometry: such a
//!   pixel is a direction, not a point, and moves only with camera rotation.

use glam::{DMat4, DQuat, DVec2, DVec3, DVec4, Vec3};
use serde::{Deserialize, Serialize};

use crate::ValidationError;

/// How far a pose's rotation quaternion may be from unit length and still be
/// accepted (it is renormalised by [`Pose::normalized`]).
pub const UNIT_QUAT_TOLERANCE: f64 = 1e-3;

/// Largest |coordinate| of a camera position, world units: beyond it a
/// camera-relative `f32` offset loses the precision a frame needs, and
/// products of coordinates overflow towards `inf` (issue 18 §6).
pub const MAX_COORDINATE: f64 = 1e12;

/// Smallest vertical field of view, radians (about 0.06°): narrower, the
/// projection's scale `1 / tan(fov/2)` makes any motion an overflow.
pub const MIN_FOV_Y: f64 = 1e-3;

/// Smallest near plane distance, world units.
pub const MIN_NEAR: f64 = 1e-6;

/// Largest |value| accepted in a window bound: a window 64× wider than the
/// displayed region is already far beyond any useful widening.
pub const MAX_WINDOW_EXTENT: f64 = 64.0;

/// A camera's placement in the world.
///
/// `position` is in world units (`f64`); `rotation` maps camera-local axes to
/// world axes, so the view direction is `rotation * −Z`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Camera centre in world space.
    pub position: DVec3,
    /// Unit quaternion, camera-local → world.
    pub rotation: DQuat,
}

impl Pose {
    /// A pose at `position` with the given rotation.
    pub fn new(position: DVec3, rotation: DQuat) -> Self {
        Self { position, rotation }
    }

    /// A pose at `eye` looking at `target`, with `up` as the approximate up
    /// vector. Falls back to a different up vector if `up` is parallel to the
    /// view direction.
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3) -> Self {
        let forward = (target - eye).normalize_or(DVec3::NEG_Z);
        let mut right = forward.cross(up);
        if right.length_squared() < 1e-18 {
            right = forward.cross(DVec3::Z);
            if right.length_squared() < 1e-18 {
                right = forward.cross(DVec3::X);
            }
        }
        let right = right.normalize();
        let true_up = right.cross(forward);
        // Columns are the camera's local axes in world space: +X right, +Y up,
        // +Z = −forward.
        let m = glam::DMat3::from_cols(right, true_up, -forward);
        Self::new(eye, DQuat::from_mat3(&m).normalize())
    }

    /// The world-space view direction (local −Z).
    pub fn forward(&self) -> DVec3 {
        self.rotation * DVec3::NEG_Z
    }

    /// The world-space up vector (local +Y).
    pub fn up(&self) -> DVec3 {
        self.rotation * DVec3::Y
    }

    /// The world-space right vector (local +X).
    pub fn right(&self) -> DVec3 {
        self.rotation * DVec3::X
    }

    /// Camera extrapolation, GFFE eq. 2 made exact for a steady camera:
    /// `C̃(t+α)` continues the step `C(t−1) → C(t)` by `α` steps. The
    /// position moves linearly, `p(t) + α (p(t) − p(t−1))`, as in eq. 2;
    /// the rotation turns at constant angular velocity,
    /// `R̃ = (R_t R_{t−1}⁻¹)^α R_t` (the quaternion power along the
    /// shorter arc). Eq. 2 as printed extrapolates the view and up vectors
    /// linearly and re-orthonormalises, which under-rotates: about 3 % at
    /// 10° per step and 12 % at α = 3. A camera that moves at constant
    /// velocity and turns at a constant rate (about any fixed axis, in the
    /// world's frame or its own) is continued exactly for every α.
    ///
    /// `α = 0` gives `cur`, `α = 1` one more step of the same motion, and
    /// `α ∈ [−1, 0]` interpolates (`−1` is `prev`; the rotation is then
    /// the slerp). A half turn between the two poses (the arc's direction
    /// is undefined) turns about the axis the quaternions give. A
    /// non-finite result keeps `cur`'s position or rotation.
    pub fn extrapolate(prev: &Pose, cur: &Pose, alpha: f64) -> Pose {
        let position = cur.position + alpha * (cur.position - prev.position);
        let (r0, r1) = (prev.rotation.normalize(), cur.rotation.normalize());
        let mut step = (r1 * r0.conjugate()).normalize();
        // q and −q are the same rotation; w ≥ 0 is the shorter arc.
        if step.w < 0.0 {
            step = -step;
        }
        let turn = DQuat::from_scaled_axis(step.to_scaled_axis() * alpha);
        let rotation = (turn * r1).normalize();
        Pose::new(
            if position.is_finite() {
                position
            } else {
                cur.position
            },
            if rotation.is_finite() { rotation } else { r1 },
        )
    }

    /// The same pose with its rotation renormalised.
    pub fn normalized(&self) -> Self {
        Self::new(self.position, self.rotation.normalize())
    }

    /// World → view transform (view space: camera at origin looking down −Z).
    pub fn world_to_view(&self) -> DMat4 {
        DMat4::from_rotation_translation(self.rotation.normalize(), self.position).inverse()
    }

    /// Checks that every value is finite, the position within
    /// [`MAX_COORDINATE`] and the rotation a unit quaternion.
    pub fn validate(&self) -> Result<(), ValidationError> {
        if !self.position.is_finite() {
            return Err(ValidationError::NonFinite("camera position"));
        }
        if !self.rotation.is_finite() {
            return Err(ValidationError::NonFinite("camera rotation"));
        }
        if self.position.abs().max_element() > MAX_COORDINATE {
            return Err(ValidationError::OutOfRange("camera position"));
        }
        let len = self.rotation.length();
        if (len - 1.0).abs() > UNIT_QUAT_TOLERANCE {
            return Err(ValidationError::NotUnitQuaternion(len));
        }
        Ok(())
    }
}

/// Perspective projection of the *displayed* region.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Projection {
    /// Vertical field of view in radians, in (0, π).
    pub fov_y: f64,
    /// Width / height of the displayed region.
    pub aspect: f64,
    /// Near plane distance (> 0).
    pub near: f64,
    /// Far plane distance (> near); may be `+inf` for an infinite far plane
    /// (written as the string `"inf"` in JSON, which has no infinity).
    #[serde(with = "far_plane")]
    pub far: f64,
}

impl Projection {
    /// A projection with the given vertical field of view (radians) and aspect.
    pub fn perspective(fov_y: f64, aspect: f64, near: f64, far: f64) -> Self {
        Self {
            fov_y,
            aspect,
            near,
            far,
        }
    }

    /// `tan(fov_y / 2)`: the NDC-y extent of one unit of view depth.
    pub fn tan_half_fov(&self) -> f64 {
        (self.fov_y * 0.5).tan()
    }

    /// Checks ranges (field of view from [`MIN_FOV_Y`] to π, near plane
    /// from [`MIN_NEAR`] to [`MAX_COORDINATE`]); `far` may be `+inf`,
    /// nothing else may be non-finite.
    pub fn validate(&self) -> Result<(), ValidationError> {
        if !self.fov_y.is_finite() || !self.aspect.is_finite() || !self.near.is_finite() {
            return Err(ValidationError::NonFinite("projection"));
        }
        if self.far.is_nan() {
            return Err(ValidationError::NonFinite("projection far plane"));
        }
        if !(self.fov_y >= MIN_FOV_Y && self.fov_y < std::f64::consts::PI - 1e-6) {
            return Err(ValidationError::OutOfRange("fov_y"));
        }
        if !(self.aspect > 1e-4 && self.aspect < 1e4) {
            return Err(ValidationError::OutOfRange("aspect"));
        }
        if !(self.near >= MIN_NEAR && self.near <= MAX_COORDINATE && self.far > self.near) {
            return Err(ValidationError::OutOfRange("near/far"));
        }
        Ok(())
    }
}

/// Serde for the far plane: binary formats store the `f64` as is; human-
/// readable ones (JSON) write `+inf` as `"inf"` because JSON has no infinity.
mod far_plane {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Readable {
        Number(f64),
        Text(String),
    }

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() && v.is_infinite() && *v > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_f64(*v)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        if !d.is_human_readable() {
            return f64::deserialize(d);
        }
        match Readable::deserialize(d)? {
            Readable::Number(v) => Ok(v),
            Readable::Text(t) if t == "inf" => Ok(f64::INFINITY),
            Readable::Text(t) => Err(serde::de::Error::custom(format!(
                "far plane must be a number or \"inf\", got {t:?}"
            ))),
        }
    }
}

/// The adaptive rendering window (GFFE appendix C, eq. 5): the rectangle of
/// base-projection NDC that the rendered image covers. `v` is NDC y (up), so
/// `v1` is the top edge of the image and `v0` the bottom edge.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// Left edge, NDC x.
    pub u0: f64,
    /// Bottom edge, NDC y.
    pub v0: f64,
    /// Right edge, NDC x.
    pub u1: f64,
    /// Top edge, NDC y.
    pub v1: f64,
}

impl Window {
    /// The plain window: the rendered image is exactly the displayed region.
    pub const FULL: Window = Window {
        u0: -1.0,
        v0: -1.0,
        u1: 1.0,
        v1: 1.0,
    };

    /// Width of the window in NDC units (2 for [`Window::FULL`]).
    pub fn width(&self) -> f64 {
        self.u1 - self.u0
    }

    /// Height of the window in NDC units (2 for [`Window::FULL`]).
    pub fn height(&self) -> f64 {
        self.v1 - self.v0
    }

    /// True for the plain `(−1, −1, 1, 1)` window.
    pub fn is_full(&self) -> bool {
        *self == Self::FULL
    }

    /// The pixel rectangle `(x0, y0, x1, y1)` (continuous pixel coordinates of
    /// the rendered image) that shows the displayed region `[−1, 1]²`: the
    /// client crops to it.
    pub fn display_rect(&self, size: FrameSizeF) -> (f64, f64, f64, f64) {
        let x0 = (-1.0 - self.u0) / self.width() * size.0;
        let x1 = (1.0 - self.u0) / self.width() * size.0;
        let y0 = (self.v1 - 1.0) / self.height() * size.1;
        let y1 = (self.v1 + 1.0) / self.height() * size.1;
        (x0, y0, x1, y1)
    }

    /// Checks finiteness, ordering and extent.
    pub fn validate(&self) -> Result<(), ValidationError> {
        let all = [self.u0, self.v0, self.u1, self.v1];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(ValidationError::NonFinite("window"));
        }
        if all.iter().any(|v| v.abs() > MAX_WINDOW_EXTENT) {
            return Err(ValidationError::OutOfRange("window extent"));
        }
        // Eq. 5 only ever widens: the window contains the displayed region,
        // so the crop rectangle always lies inside the image.
        if !(self.u0 <= -1.0 && self.v0 <= -1.0 && self.u1 >= 1.0 && self.v1 >= 1.0) {
            return Err(ValidationError::OutOfRange(
                "window must contain (-1, -1, 1, 1)",
            ));
        }
        Ok(())
    }
}

impl Default for Window {
    fn default() -> Self {
        Self::FULL
    }
}

/// Image size in pixels as floats, `(width, height)`.
pub type FrameSizeF = (f64, f64);

/// A point to project: a finite world position or, for `+inf` depth, a
/// direction (a point at infinity, which only camera rotation moves).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WorldPoint {
    /// A finite position in world space.
    Finite(DVec3),
    /// A unit direction in world space (sky).
    AtInfinity(DVec3),
}

/// The image of a [`WorldPoint`] in a camera: continuous pixel coordinates and
/// linear view depth (`+inf` for [`WorldPoint::AtInfinity`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    /// Continuous pixel position (pixel centres at `i + 0.5`).
    pub pixel: DVec2,
    /// Linear view depth, > 0.
    pub depth: f64,
}

/// Everything needed to map between pixels and the world for one frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Where the camera is and where it looks.
    pub pose: Pose,
    /// The projection of the displayed region.
    pub projection: Projection,
    /// The region of base NDC the rendered image covers.
    pub window: Window,
}

impl Camera {
    /// A camera with the plain window.
    pub fn new(pose: Pose, projection: Projection) -> Self {
        Self {
            pose,
            projection,
            window: Window::FULL,
        }
    }

    /// Validates pose, projection and window.
    pub fn validate(&self) -> Result<(), ValidationError> {
        self.pose.validate()?;
        self.projection.validate()?;
        self.window.validate()
    }

    /// View-space direction through a continuous pixel position, scaled so its
    /// z component is −1 (so `ray * depth` is the view-space point at that
    /// linear depth).
    pub fn view_ray(&self, pixel: DVec2, size: FrameSizeF) -> DVec3 {
        let w = &self.window;
        let ndc_x = w.u0 + pixel.x / size.0 * w.width();
        let ndc_y = w.v1 - pixel.y / size.1 * w.height();
        let t = self.projection.tan_half_fov();
        DVec3::new(ndc_x * t * self.projection.aspect, ndc_y * t, -1.0)
    }

    /// World → continuous pixel position and linear depth. Returns `None` for
    /// points at or behind the camera plane. Points outside the image are
    /// still projected (callers test bounds).
    pub fn project(&self, point: WorldPoint, size: FrameSizeF) -> Option<Projected> {
        // Validation admits |q| within 1e-3 of 1: normalise so depth and
        // positions are not scaled by |q|².
        let inv = self.pose.rotation.normalize().conjugate();
        let (view, depth) = match point {
            WorldPoint::Finite(p) => {
                let v = inv * (p - self.pose.position);
                (v, -v.z)
            }
            WorldPoint::AtInfinity(d) => (inv * d, f64::INFINITY),
        };
        let depth_along_ray = -view.z;
        if depth_along_ray.is_nan() || depth_along_ray <= 0.0 || !view.is_finite() {
            return None;
        }
        let t = self.projection.tan_half_fov();
        let ndc_x = view.x / (depth_along_ray * t * self.projection.aspect);
        let ndc_y = view.y / (depth_along_ray * t);
        let w = &self.window;
        let pixel = DVec2::new(
            (ndc_x - w.u0) / w.width() * size.0,
            (w.v1 - ndc_y) / w.height() * size.1,
        );
        pixel.is_finite().then_some(Projected { pixel, depth })
    }

    /// Continuous pixel position + linear depth → world point. `+inf` depth
    /// gives a direction ([`WorldPoint::AtInfinity`]). NaN, zero, negative or
    /// `−inf` depth gives `None`.
    pub fn unproject(&self, pixel: DVec2, depth: f64, size: FrameSizeF) -> Option<WorldPoint> {
        if depth.is_nan() || depth <= 0.0 {
            return None;
        }
        let ray = self.view_ray(pixel, size);
        let rotation = self.pose.rotation.normalize();
        if depth == f64::INFINITY {
            Some(WorldPoint::AtInfinity((rotation * ray).normalize()))
        } else {
            Some(WorldPoint::Finite(
                self.pose.position + rotation * (ray * depth),
            ))
        }
    }

    /// The motion vector (DESIGN §3: current → previous, in pixels) that a
    /// *static* surface point seen at `pixel` with linear `depth` in this
    /// camera gets when the previous frame was seen by `prev`:
    /// `prev.project(self.unproject(pixel)) − pixel`. `None` if the point is
    /// invalid or was behind the previous camera.
    pub fn static_motion(
        &self,
        prev: &Camera,
        pixel: DVec2,
        depth: f64,
        size: FrameSizeF,
        prev_size: FrameSizeF,
    ) -> Option<DVec2> {
        let p = self.unproject(pixel, depth, size)?;
        Some(prev.project(p, prev_size)?.pixel - pixel)
    }

    /// A world position relative to the camera centre, in world axes, in
    /// `f32`: the representation per-pixel positions use (DESIGN §3,
    /// precision). The subtraction happens in `f64`, so huge coordinates keep
    /// their precision near the camera.
    pub fn to_camera_relative(&self, p: DVec3) -> Vec3 {
        (p - self.pose.position).as_vec3()
    }

    /// wgpu-style projection matrix (view → clip, NDC z in [0, 1]) for the
    /// *rendered* image, i.e. with the window's off-centre frustum applied.
    pub fn clip_from_view(&self) -> DMat4 {
        let t = self.projection.tan_half_fov();
        let (n, f) = (self.projection.near, self.projection.far);
        let w = &self.window;
        // Off-centre frustum at the near plane, from the window's NDC bounds.
        let left = w.u0 * t * self.projection.aspect * n;
        let right = w.u1 * t * self.projection.aspect * n;
        let bottom = w.v0 * t * n;
        let top = w.v1 * t * n;
        let (a, b) = if f.is_finite() {
            (f / (n - f), n * f / (n - f))
        } else {
            (-1.0, -n)
        };
        DMat4::from_cols(
            DVec4::new(2.0 * n / (right - left), 0.0, 0.0, 0.0),
            DVec4::new(0.0, 2.0 * n / (top - bottom), 0.0, 0.0),
            DVec4::new(
                (right + left) / (right - left),
                (top + bottom) / (top - bottom),
                a,
                -1.0,
            ),
            DVec4::new(0.0, 0.0, b, 0.0),
        )
    }
}

/// Converts a frame size in pixels to floats.
pub fn size_f(width: u32, height: u32) -> FrameSizeF {
    (f64::from(width), f64::from(height))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: FrameSizeF = (320.0, 180.0);

    fn cam(pos: DVec3, target: DVec3) -> Camera {
        Camera::new(
            Pose::look_at(pos, target, DVec3::Y),
            Projection::perspective(60f64.to_radians(), 16.0 / 9.0, 0.1, 1000.0),
        )
    }

    #[test]
    fn camera_looks_down_negative_z_with_y_up() {
        let c = Camera::new(
            Pose::new(DVec3::ZERO, DQuat::IDENTITY),
            Projection::perspective(1.0, 1.0, 0.1, 10.0),
        );
        let p = c
            .project(
                WorldPoint::Finite(DVec3::new(0.0, 0.0, -5.0)),
                (100.0, 100.0),
            )
            .unwrap();
        // Centre of the image, depth is the positive distance along −Z.
        assert!((p.pixel - DVec2::new(50.0, 50.0)).length() < 1e-9);
        assert!((p.depth - 5.0).abs() < 1e-12);
        // World +Y is up, which is towards pixel row 0 (y down).
        let up = c
            .project(
                WorldPoint::Finite(DVec3::new(0.0, 1.0, -5.0)),
                (100.0, 100.0),
            )
            .unwrap();
        assert!(up.pixel.y < 50.0);
        // World +X is right, towards larger pixel x.
        let right = c
            .project(
                WorldPoint::Finite(DVec3::new(1.0, 0.0, -5.0)),
                (100.0, 100.0),
            )
            .unwrap();
        assert!(right.pixel.x > 50.0);
        // Behind the camera: no projection.
        assert!(
            c.project(
                WorldPoint::Finite(DVec3::new(0.0, 0.0, 5.0)),
                (100.0, 100.0)
            )
            .is_none()
        );
    }

    #[test]
    fn look_at_centres_the_target_with_up_towards_row_zero() {
        let c = cam(DVec3::new(4.0, 3.0, -2.0), DVec3::new(-1.0, 0.5, 6.0));
        let t = c
            .project(WorldPoint::Finite(DVec3::new(-1.0, 0.5, 6.0)), SIZE)
            .unwrap();
        assert!((t.pixel - DVec2::new(SIZE.0 / 2.0, SIZE.1 / 2.0)).length() < 1e-9);
        let above = c
            .project(WorldPoint::Finite(DVec3::new(-1.0, 1.5, 6.0)), SIZE)
            .unwrap();
        assert!(above.pixel.y < t.pixel.y);
        // The basis is right-handed and orthonormal.
        let p = c.pose;
        assert!((p.right().cross(p.up()) - (-p.forward())).length() < 1e-12);
        // Looking straight down still works (up parallel to the view axis).
        let down = Pose::look_at(DVec3::Y, DVec3::ZERO, DVec3::Y);
        assert!((down.forward() - DVec3::NEG_Y).length() < 1e-12);
        assert!(down.rotation.is_normalized());
    }

    #[test]
    fn clip_matrix_maps_near_to_zero_and_far_to_one() {
        let mut c = cam(DVec3::ZERO, DVec3::NEG_Z);
        for far in [1000.0, f64::INFINITY] {
            c.projection.far = far;
            let m = c.clip_from_view();
            let ndc_z = |d: f64| {
                let v = m * DVec4::new(0.0, 0.0, -d, 1.0);
                v.z / v.w
            };
            assert!(ndc_z(0.1).abs() < 1e-12, "near plane → 0");
            if far.is_finite() {
                assert!((ndc_z(far) - 1.0).abs() < 1e-12, "far plane → 1");
            } else {
                assert!(
                    ndc_z(1e12) < 1.0 && ndc_z(1e12) > 1.0 - 1e-9,
                    "infinity → 1"
                );
            }
            assert!(ndc_z(10.0) > ndc_z(1.0), "farther is larger");
        }
    }

    #[test]
    fn camera_extrapolation_continues_linear_motion() {
        let a = Pose::look_at(DVec3::ZERO, DVec3::NEG_Z, DVec3::Y);
        let b = Pose::look_at(DVec3::X, DVec3::X + DVec3::NEG_Z, DVec3::Y);
        let c = Pose::extrapolate(&a, &b, 1.0);
        assert!((c.position - DVec3::new(2.0, 0.0, 0.0)).length() < 1e-12);
        assert!((c.forward() - DVec3::NEG_Z).length() < 1e-12);
        assert_eq!(Pose::extrapolate(&a, &b, 0.0).position, b.position);
        // A small yaw step continues exactly (eq. 2 as printed, linear in
        // the direction vectors, undershoots the angle).
        let r = |deg: f64| Pose::new(DVec3::ZERO, DQuat::from_rotation_y(deg.to_radians()));
        let next = Pose::extrapolate(&r(0.0), &r(5.0), 1.0);
        let yaw = next.forward().x.atan2(-next.forward().z).to_degrees();
        assert!((yaw + 10.0).abs() < 1e-9, "{yaw}");
        assert!(next.rotation.is_normalized());
        // A half turn between the frames: still a valid rotation.
        let flip = Pose::extrapolate(&r(180.0), &r(0.0), 0.5);
        assert!(flip.rotation.is_finite() && flip.rotation.is_normalized());
        // Non-finite input keeps the current pose's parts.
        let bad = Pose::new(DVec3::splat(f64::NAN), DQuat::IDENTITY);
        assert_eq!(Pose::extrapolate(&bad, &b, 1.0).position, b.position);
    }

    /// A camera moving at constant velocity and turning at a constant rate
    /// is continued exactly, out to the generator's largest α, whether it
    /// turns about a fixed world axis or about a fixed axis of its own;
    /// α ∈ [−1, 0] lands on the same path between the two poses.
    #[test]
    fn a_steady_turn_is_extrapolated_exactly() {
        let r0 = DQuat::from_euler(glam::EulerRot::YXZ, 0.4, -0.3, 0.2);
        let axis = DVec3::new(0.3, 1.0, -0.2).normalize();
        let (p0, v) = (DVec3::new(1e5, 2.0, -3e4), DVec3::new(0.7, -0.1, 0.25));
        for deg in [0.01f64, 1.0, 10.0, 45.0, 170.0] {
            let w = deg.to_radians();
            let world = |t: f64| Pose::new(p0 + v * t, DQuat::from_axis_angle(axis, w * t) * r0);
            let own = |t: f64| Pose::new(p0 + v * t, r0 * DQuat::from_axis_angle(axis, w * t));
            for path in [&world as &dyn Fn(f64) -> Pose, &own] {
                let (a, b) = (path(3.0), path(4.0));
                for alpha in [-1.0, -0.5, 0.0, 0.5, 1.0, 3.0, 8.0, 16.0] {
                    let got = Pose::extrapolate(&a, &b, alpha);
                    let want = path(4.0 + alpha);
                    // Half the angle between them, to first order (acos
                    // near 1 would hide anything below ~1e-8).
                    let (g, h) = (DVec4::from(got.rotation), DVec4::from(want.rotation));
                    let angle = (g - h * g.dot(h).signum()).length();
                    // The position is ~1e5 from the origin: f64 rounding.
                    let off = (got.position - want.position).length();
                    assert!(angle < 1e-9, "{deg}°/step α={alpha}: {angle} rad off");
                    assert!(off < 1e-9, "{deg}°/step α={alpha}: {off} off");
                }
            }
        }
    }

    #[test]
    fn pixel_centres_are_at_half_integers() {
        let c = Camera::new(
            Pose::new(DVec3::ZERO, DQuat::IDENTITY),
            Projection::perspective(1.0, 2.0, 0.1, 10.0),
        );
        // Pixel (0,0)'s centre is half a pixel inside the top-left corner; the
        // corner itself (0,0) is NDC (−1, +1).
        let corner = c.view_ray(DVec2::ZERO, (4.0, 2.0));
        let t = 0.5f64.tan();
        assert!((corner.x + t * 2.0).abs() < 1e-12 && (corner.y - t).abs() < 1e-12);
        let centre = c.view_ray(DVec2::new(0.5, 0.5), (4.0, 2.0));
        assert!((centre.x + 0.75 * t * 2.0).abs() < 1e-12);
        assert!((centre.y - 0.5 * t).abs() < 1e-12);
    }

    #[test]
    fn unproject_then_project_round_trips_depth_and_pixel() {
        let c = cam(DVec3::new(3.0, 2.0, 10.0), DVec3::new(0.0, 1.0, 0.0));
        for &(x, y, d) in &[(0.5, 0.5, 1.0), (160.5, 90.5, 37.25), (319.5, 179.5, 999.0)] {
            let px = DVec2::new(x, y);
            let p = c.unproject(px, d, SIZE).unwrap();
            let back = c.project(p, SIZE).unwrap();
            assert!((back.pixel - px).length() < 1e-9, "{back:?}");
            assert!((back.depth - d).abs() < 1e-9 * d);
        }
    }

    #[test]
    fn static_point_motion_points_from_current_to_previous() {
        // The camera moves right between the previous and the current frame:
        // a static point appears further right in the previous frame, so its
        // motion vector (current → previous) points right.
        let prev = cam(DVec3::new(0.0, 0.0, 10.0), DVec3::new(0.0, 0.0, 0.0));
        let cur = cam(DVec3::new(1.0, 0.0, 10.0), DVec3::new(1.0, 0.0, 0.0));
        let px = DVec2::new(160.5, 90.5);
        let d = 10.0;
        let mv = cur.static_motion(&prev, px, d, SIZE, SIZE).unwrap();
        assert!(mv.x > 0.0 && mv.y.abs() < 1e-9, "{mv:?}");
        // prev = cur + mv lands on the same world point.
        let world = cur.unproject(px, d, SIZE).unwrap();
        let in_prev = prev.project(world, SIZE).unwrap();
        assert!((in_prev.pixel - (px + mv)).length() < 1e-9);
        // Magnitude: 1 world unit at depth 10 with a 60° vertical fov.
        let expect = 1.0 / (10.0 * (30f64.to_radians()).tan() * 16.0 / 9.0) * 0.5 * SIZE.0;
        assert!((mv.x - expect).abs() < 1e-9, "{} vs {expect}", mv.x);
    }

    #[test]
    fn infinite_depth_moves_only_with_rotation() {
        let a = cam(DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.0, 0.0, -1.0));
        // Pure translation: sky does not move.
        let b = cam(DVec3::new(500.0, -3.0, 20.0), DVec3::new(500.0, -3.0, 19.0));
        let px = DVec2::new(10.5, 20.5);
        let mv = b.static_motion(&a, px, f64::INFINITY, SIZE, SIZE).unwrap();
        assert!(mv.length() < 1e-9, "{mv:?}");
        // Rotation: sky moves, and stays finite.
        let c = Camera::new(
            Pose::new(DVec3::ZERO, DQuat::from_rotation_y(5f64.to_radians())),
            a.projection,
        );
        let mv = c.static_motion(&a, px, f64::INFINITY, SIZE, SIZE).unwrap();
        assert!(mv.is_finite() && mv.x.abs() > 1.0);
        let p = c.unproject(px, f64::INFINITY, SIZE).unwrap();
        assert!(matches!(p, WorldPoint::AtInfinity(d) if (d.length() - 1.0).abs() < 1e-12));
        assert_eq!(c.project(p, SIZE).unwrap().depth, f64::INFINITY);
    }

    #[test]
    fn invalid_depth_is_rejected_not_nan() {
        let c = cam(DVec3::ZERO, DVec3::NEG_Z);
        for d in [f64::NAN, 0.0, -1.0, f64::NEG_INFINITY] {
            assert!(c.unproject(DVec2::new(1.5, 1.5), d, SIZE).is_none(), "{d}");
        }
        // Tiny depth is valid and finite.
        let p = c.unproject(DVec2::new(1.5, 1.5), 1e-6, SIZE).unwrap();
        assert!(matches!(p, WorldPoint::Finite(v) if v.is_finite()));
    }

    #[test]
    fn huge_coordinates_keep_subpixel_motion_precision() {
        for base in [1e5, 1e7] {
            let o = DVec3::new(base, base * 0.5, -base);
            let prev = cam(o, o + DVec3::new(0.0, 0.0, -1.0));
            let cur = cam(
                o + DVec3::new(0.01, 0.0, 0.0),
                o + DVec3::new(0.01, 0.0, -1.0),
            );
            let px = DVec2::new(100.5, 50.5);
            let mv = cur.static_motion(&prev, px, 2.0, SIZE, SIZE).unwrap();
            let expect = 0.01 / (2.0 * (30f64.to_radians()).tan() * 16.0 / 9.0) * 0.5 * SIZE.0;
            assert!(
                (mv.x - expect).abs() < 1e-4,
                "base {base}: {mv:?} vs {expect}"
            );
            // Camera-relative f32 keeps the offset exact enough.
            let w = match cur.unproject(px, 2.0, SIZE).unwrap() {
                WorldPoint::Finite(w) => w,
                WorldPoint::AtInfinity(_) => unreachable!(),
            };
            let rel = cur.to_camera_relative(w);
            assert!((f64::from(rel.length()) - (w - cur.pose.position).length()).abs() < 1e-5);
        }
    }

    #[test]
    fn window_widens_the_frustum_and_crop_recovers_the_display() {
        let mut c = cam(DVec3::new(0.0, 1.0, 5.0), DVec3::ZERO);
        let plain = c;
        c.window = Window {
            u0: -1.5,
            v0: -1.0,
            u1: 1.0,
            v1: 1.25,
        };
        // Same pixel density: size grows with the window.
        let wide = (SIZE.0 * 2.5 / 2.0, SIZE.1 * 2.25 / 2.0);
        let (x0, y0, x1, y1) = c.window.display_rect(wide);
        assert!((x1 - x0 - SIZE.0).abs() < 1e-9 && (y1 - y0 - SIZE.1).abs() < 1e-9);
        // A world point lands at the same place inside the crop as it does in
        // the plain image.
        let world = WorldPoint::Finite(DVec3::new(0.3, 0.2, 0.1));
        let a = plain.project(world, SIZE).unwrap();
        let b = c.project(world, wide).unwrap();
        assert!((b.pixel - DVec2::new(x0, y0) - a.pixel).length() < 1e-9);
        // The window's clip matrix agrees with `project`.
        let v = c
            .pose
            .world_to_view()
            .transform_point3(DVec3::new(0.3, 0.2, 0.1));
        let clip = c.clip_from_view() * v.extend(1.0);
        let ndc = clip.truncate() / clip.w;
        let px = DVec2::new((ndc.x + 1.0) * 0.5 * wide.0, (1.0 - ndc.y) * 0.5 * wide.1);
        assert!((px - b.pixel).length() < 1e-6, "{px:?} vs {:?}", b.pixel);
        assert!(ndc.z > 0.0 && ndc.z < 1.0);
    }

    /// Finite but absurd cameras (issue 18 §6) are out of range, with
    /// the limits themselves accepted: a 1e-300 field of view, a position
    /// at 1e13, a near plane at 1e-9 used to pass and end in NaN paths.
    #[test]
    fn validation_bounds_finite_extremes() {
        let good = cam(DVec3::ZERO, DVec3::NEG_Z);
        let range = |c: Camera| matches!(c.validate(), Err(ValidationError::OutOfRange(_)));
        let mut c = good;
        c.projection.fov_y = 1e-300;
        assert!(range(c));
        c.projection.fov_y = MIN_FOV_Y;
        assert!(c.validate().is_ok());
        let mut c = good;
        c.pose.position = DVec3::new(0.0, -1e13, 0.0);
        assert!(range(c));
        c.pose.position = DVec3::splat(-MAX_COORDINATE);
        assert!(c.validate().is_ok());
        let mut c = good;
        c.projection.near = 1e-9;
        assert!(range(c));
        c.projection.near = MIN_NEAR;
        assert!(c.validate().is_ok());
        c.projection.near = 1e13;
        c.projection.far = f64::INFINITY;
        assert!(range(c));
    }

    #[test]
    fn validation_rejects_non_finite_and_bad_ranges() {
        let good = cam(DVec3::ZERO, DVec3::NEG_Z);
        assert!(good.validate().is_ok());
        let mut c = good;
        c.pose.position.x = f64::NAN;
        assert!(matches!(c.validate(), Err(ValidationError::NonFinite(_))));
        let mut c = good;
        c.pose.rotation = DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0);
        assert!(matches!(
            c.validate(),
            Err(ValidationError::NotUnitQuaternion(_))
        ));
        let mut c = good;
        c.projection.fov_y = f64::INFINITY;
        assert!(c.validate().is_err());
        let mut c = good;
        c.projection.far = f64::INFINITY;
        assert!(c.validate().is_ok(), "infinite far plane is allowed");
        let mut c = good;
        c.window.u1 = c.window.u0;
        assert!(c.validate().is_err());
        let mut c = good;
        c.window = Window {
            u0: 0.0,
            v0: 0.0,
            u1: 0.5,
            v1: 0.5,
        };
        assert!(
            c.validate().is_err(),
            "a window that does not contain the display"
        );
        // A rotation slightly off unit length is accepted and does not scale
        // depth.
        let mut c = good;
        c.pose.rotation *= 1.0009;
        assert!(c.validate().is_ok());
        let p = c.unproject(DVec2::new(3.5, 4.5), 7.0, SIZE).unwrap();
        assert!((c.project(p, SIZE).unwrap().depth - 7.0).abs() < 1e-9);
        let (WorldPoint::Finite(a), Some(WorldPoint::Finite(b))) =
            (p, good.unproject(DVec2::new(3.5, 4.5), 7.0, SIZE))
        else {
            panic!("finite depth gives finite points");
        };
        assert!((a - b).length() < 1e-9);
    }
}
