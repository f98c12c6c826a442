//! Frames for the unit tests.

use protocol::{Frame, FrameSize};

/// Frame `index` at 60 fps of `size`: black, depth 1, no motion, a camera
/// at the origin ([`Frame::blank`]).
pub fn frame(index: u64, size: FrameSize) -> Frame {
    Frame::blank(index, size)
}

/// The pass camera of a `width × height` image seen from `eye` looking at
/// `target` (y up, a 1-radian 16:9 view), relative to `origin`.
pub fn looking(
    eye: [f64; 3],
    target: [f64; 3],
    (width, height): (u32, u32),
    origin: [f64; 3],
) -> crate::passes::common::camera::PassCamera {
    use glam::DVec3;
    use protocol::{Camera, Pose, Projection};
    let pose = Pose::look_at(DVec3::from(eye), DVec3::from(target), DVec3::Y);
    let camera = Camera::new(pose, Projection::perspective(1.0, 16.0 / 9.0, 0.1, 1e4));
    let size = FrameSize { width, height };
    crate::passes::common::camera::PassCamera::new(&camera, size, DVec3::from(origin))
}
