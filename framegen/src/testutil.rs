//! Frames for the unit tests.

use protocol::{Frame, FrameSize};

/// Frame `index` at 60 fps of `size`: black, depth 1, no motion, a camera
/// at the origin ([`Frame::blank`]).
pub fn frame(index: u64, size: FrameSize) -> Frame {
    Frame::blank(index, size)
}
