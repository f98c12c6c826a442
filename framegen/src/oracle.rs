//! The oracle-motion reference (issue 16 §11): what the extrapolators
//! would make if they knew the skipped frame's true depth and motion, the
//! G-buffers of the future frame that ExtraSS-style extrapolation assumes
//! (seed 002; GFFE Table 3's ExSS-E row). It is not realisable (those
//! buffers are what the renderer has not made yet); `eval` reports it
//! beside gffe to show how much of gffe's error is its geometry estimate
//! (eq. 1, the splat, the background layers) and how much is what no
//! geometry can show.
//!
//! Every pixel `y` of the skipped frame fetches the rendered frame at
//! `y + m(y)` (its true motion, composed back to the rendered frame) with
//! the warp's resampling ([`resample`]). Where the rendered frame shows
//! another surface there (the depths disagree by more than
//! [`same_surface`] allows: the point was hidden), the pixel is a hole and
//! is filled by the same push-pull as gffe's remaining holes. Depth and
//! motion are the true ones.

use glam::Vec2;
use protocol::Frame;

use crate::FramegenError;
use crate::generator::{Generated, finish};
use crate::input::prepare;
use crate::output::{Output, Pixel, WARPED};
use crate::passes::common::camera::pixel_center;
use crate::passes::common::pushpull;
use crate::passes::common::resample::{Resample, Source, resample, same_surface};
use crate::passes::common::sample::{clamp_index, inside};

/// The skipped frame `truth` (its motion pointing to `rendered`) made from
/// `rendered` with true geometry; `alpha` is recorded as given.
pub fn backward_warp(
    rendered: &Frame,
    truth: &Frame,
    alpha: f64,
    (filter, pushpull_levels): (Resample, u32),
) -> Result<Generated, FramegenError> {
    let limits = protocol::Limits::default();
    rendered.validate(&limits)?;
    truth.validate(&limits)?;
    let (size, other) = (rendered.meta.size, truth.meta.size);
    if other != size {
        return Err(FramegenError::Sizes(
            size.width,
            size.height,
            other.width,
            other.height,
        ));
    }
    let (src, dst) = (prepare(rendered), prepare(truth));
    let (w, h) = (size.width, size.height);
    let source = Source {
        color: &src.color,
        depth: &src.depth,
        size: (w, h),
    };
    let mut out = Output::from_fn(w, h, |t| {
        let d = dst.depth[t];
        let m = Vec2::from_array(dst.motion[t]);
        let at = pixel_center(t, w) + m;
        let own = clamp_index(at, w, h);
        if !inside(at, (w, h)) || !same_surface(src.depth[own], d) {
            return Pixel::EMPTY;
        }
        let c = resample(source, own, at, filter);
        Pixel {
            color: [c[0], c[1], c[2], 1.0],
            depth: d,
            motion: m.to_array(),
            mask: WARPED,
        }
    });
    pushpull::fill(&mut out, pushpull_levels);
    // The true geometry wherever the fill left its own.
    out.depth.copy_from_slice(&dst.depth);
    out.motion.copy_from_slice(&dst.motion);
    let mut meta = truth.meta;
    meta.cut = false;
    Ok(finish(meta, alpha, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use half::f16;
    use protocol::{FrameMeta, FrameSize};

    /// A 16×8 frame whose red channel is `1 + x + 16y` and depth 5.
    fn frame(index: u64) -> Frame {
        let mut f = crate::testutil::frame(index, FrameSize::new(16, 8));
        for (i, c) in f.color.iter_mut().enumerate() {
            *c = [f16::from_f32(i as f32 + 1.0), f16::ONE, f16::ONE, f16::ONE];
        }
        f.depth.fill(5.0);
        f
    }

    #[test]
    fn true_motion_fetches_the_true_pixels_and_fills_what_was_hidden() {
        let rendered = frame(0);
        // The skipped frame: the image moved 2 px left, so each pixel was
        // 2 px to the right in the rendered frame.
        let mut truth = frame(1);
        truth.motion.fill([2.0, 0.0]);
        for (i, c) in truth.color.iter_mut().enumerate() {
            *c = rendered.color[(i + 2).min(127)];
        }
        // Row 3, column 5 was hidden behind something nearer.
        let mut occluded = rendered.clone();
        occluded.depth[3 * 16 + 7] = 1.0;
        for filter in Resample::ALL {
            let g = backward_warp(&occluded, &truth, 0.5, (filter, 8)).unwrap();
            for y in 0..8 {
                for x in 0..16 {
                    let t = y * 16 + x;
                    let hidden = (y, x) == (3, 5) || x >= 14;
                    let mask = g.output.mask[t];
                    assert_eq!(mask == WARPED, !hidden, "{filter} ({x}, {y})");
                    if !hidden {
                        assert_eq!(g.frame.color[t], truth.color[t], "{filter} ({x}, {y})");
                    }
                    assert!(g.output.color[t].iter().all(|v| v.is_finite()));
                    assert_eq!(g.frame.motion[t], [2.0, 0.0]);
                }
            }
        }
        let small = Frame {
            meta: FrameMeta {
                size: FrameSize::new(8, 16),
                ..truth.meta
            },
            ..truth
        };
        assert!(matches!(
            backward_warp(&rendered, &small, 0.5, (Resample::Nearest, 8)),
            Err(FramegenError::Sizes(16, 8, 8, 16))
        ));
    }
}
