//! Frames for the unit tests.

use half::f16;
use protocol::{Camera, Frame, FrameMeta, FrameSize, Pose, Projection};

/// Frame `index` at 60 fps of `size`: black, depth 1, no motion, a camera
/// at the origin.
pub fn frame(index: u64, size: FrameSize) -> Frame {
    let n = size.pixels() as usize;
    Frame {
        meta: FrameMeta {
            index,
            time: index as f64 / 60.0,
            camera: Camera::new(
                Pose::new(glam::DVec3::ZERO, glam::DQuat::IDENTITY),
                Projection::perspective(1.0, 2.0, 0.1, f64::INFINITY),
            ),
            size,
            host_processing: std::time::Duration::ZERO,
            cut: false,
        },
        color: vec![[f16::ZERO; 4]; n],
        depth: vec![1.0; n],
        motion: vec![[0.0; 2]; n],
        extras: vec![],
    }
}
