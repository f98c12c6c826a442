//! Turning a sequence rendered at the display rate into the frames a
//! renderer at `1/step` of that rate would have sent (DESIGN §9: "feed every
//! (n+1)-th frame").
//!
//! Colors, depths and cameras are simply the kept frames'. Motion vectors
//! are not: a display-rate frame's vectors point one display interval back,
//! but the generator needs them to point to the previous *kept* frame. They
//! are composed along the chain, `V_{t→t−2}(x) = V_{t→t−1}(x) +
//! V_{t−1→t−2}(x + V_{t→t−1}(x))`, reading each older field at the nearest
//! pixel. Where a point was hidden in an intermediate frame the composition
//! follows whatever surface was there, as any motion-vector chain would.

use glam::Vec2;
use protocol::Frame;

/// Composes `newer`'s motion (to the frame before it) with `older`'s motion
/// (from that frame further back): the result points from `newer` to the
/// frame before `older`. Positions outside `older` keep `newer`'s vector
/// extrapolated by `older`'s nearest border pixel.
pub fn compose(newer: &[[f32; 2]], older: &[[f32; 2]], width: u32, height: u32) -> Vec<[f32; 2]> {
    let (w, h) = (width as usize, height as usize);
    newer
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let p = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5) + Vec2::from_array(*m);
            let x = (p.x.max(0.0) as usize).min(w - 1);
            let y = (p.y.max(0.0) as usize).min(h - 1);
            let o = older[y * w + x];
            [m[0] + o[0], m[1] + o[1]]
        })
        .collect()
}

/// `frame` as a renderer at the lower rate would have sent it after the
/// `skipped` frames (oldest first, the previous kept frame excluded): its
/// motion composed back through them, and a cut among them carried over
/// (the chain crosses it; the lower-rate renderer would have flagged it).
/// The chain stops at a frame of another size (no correspondence exists).
///
/// It is numbered as that renderer numbers its frames, `index / step`:
/// kept frames `step` display frames apart count up by one, so the
/// generator takes them as consecutive (an index gap means a frame that
/// never arrived, `FrameGenerator::push`).
pub fn kept(frame: &Frame, skipped: &[&Frame], step: usize) -> Frame {
    let mut f = frame.clone();
    f.meta.index = frame.meta.index / step.max(1) as u64;
    f.meta.cut |= skipped.iter().any(|g| g.meta.cut);
    for older in skipped.iter().rev() {
        if older.meta.size != f.meta.size {
            break;
        }
        f.motion = compose(
            &f.motion,
            &older.motion,
            f.meta.size.width,
            f.meta.size.height,
        );
    }
    f
}

/// Every `step`-th frame of `frames` (starting with the first), each
/// [`kept`] after the frames skipped before it.
pub fn decimate(frames: &[Frame], step: usize) -> Vec<Frame> {
    let step = step.max(1);
    frames
        .iter()
        .enumerate()
        .step_by(step)
        .map(|(k, frame)| {
            let skipped: Vec<&Frame> = frames[k.saturating_sub(step - 1)..k].iter().collect();
            kept(frame, &skipped, step)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cut_in_a_skipped_frame_flags_the_next_kept_one() {
        let size = protocol::FrameSize::new(2, 1);
        let mut frames: Vec<Frame> = (0..5).map(|i| crate::testutil::frame(i, size)).collect();
        frames[3].meta.cut = true;
        let kept = decimate(&frames, 2);
        assert_eq!(
            kept.iter().map(|f| f.meta.cut).collect::<Vec<_>>(),
            [false, false, true]
        );
        // Numbered as the lower-rate renderer numbers them: consecutive.
        assert_eq!(
            kept.iter().map(|f| f.meta.index).collect::<Vec<_>>(),
            [0, 1, 2]
        );
    }

    #[test]
    fn composition_adds_the_vectors_along_the_path() {
        // 4x1 image: newer moves every pixel 1 px right→left (+1), older +2.
        let newer = vec![[1.0, 0.0]; 4];
        let mut older = vec![[2.0, 0.0]; 4];
        older[2] = [5.0, 0.0];
        let c = compose(&newer, &older, 4, 1);
        // Pixel 1 (centre 1.5) lands at 2.5 → older pixel 2.
        assert_eq!(c[1], [6.0, 0.0]);
        assert_eq!(c[0], [3.0, 0.0]);
        // Pixel 3 lands outside: clamped to the border pixel.
        assert_eq!(c[3], [3.0, 0.0]);
    }
}
