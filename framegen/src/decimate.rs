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

/// Every `step`-th frame of `frames` (starting with the first), each with
/// its motion composed back to the previous kept frame. Frames whose sizes
/// differ from their predecessor keep their own vectors (no chain exists).
pub fn decimate(frames: &[Frame], step: usize) -> Vec<Frame> {
    let step = step.max(1);
    let mut out = Vec::with_capacity(frames.len().div_ceil(step));
    for (k, frame) in frames.iter().enumerate().step_by(step) {
        let mut f = frame.clone();
        if k >= step {
            for j in (k + 1 - step..k).rev() {
                let older = &frames[j];
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
        }
        out.push(f);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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
