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
//!
//! **The shading oracle** ([`shade`], issue 17) bounds shading correction
//! (GFFE §4.4) instead: a frame generated without it keeps the shading of
//! the frame it was made from; [`shade`] gives it the exact change of
//! shading since, measured by the renderer as the truth over the truth
//! rendered with the earlier lights and shadow casters. What error is left
//! is the warp's, which no shading correction is meant to remove.

use glam::Vec2;
use half::f16;
use protocol::{Frame, FrameSize};

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
    let size = rendered.meta.size;
    same_size(size, truth.meta.size)?;
    let (src, dst) = (prepare(rendered), prepare(truth));
    let (w, h) = (size.width, size.height);
    let color = crate::passes::common::widen::widen(&src.color);
    let source = Source {
        color: &color,
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
    pushpull::fill(&mut out, pushpull_levels, &mut pushpull::Scratch::default());
    // The true geometry wherever the fill left its own.
    out.depth.copy_from_slice(&dst.depth);
    out.motion.copy_from_slice(&dst.motion);
    let mut meta = truth.meta;
    meta.cut = false;
    finish(meta, alpha, out)
}

/// Below this value of a channel without the change (`unshaded`) the
/// change is taken as a difference, not a ratio (a ratio over black, or
/// over the `f16` rounding near it, is meaningless).
pub const SHADE_FLOOR: f32 = 1.0 / 1024.0;

/// Gives `generated` (made without shading correction from a frame
/// rendered at some earlier time) the exact change of shading since: each
/// channel times `truth / unshaded`, where `unshaded` is the displayed
/// frame `truth` rendered with the earlier time's lights and shadows
/// (`scene::render::Renderer::render_shaded_at`). Light multiplies what a
/// surface reflects, so the ratio carries the change onto the generated
/// pixel's own texture even where the warp took it from a neighbour;
/// where `unshaded` is black (below [`SHADE_FLOOR`]) the difference is
/// added instead. Colour stays finite, non-negative and within `f16`;
/// a channel with a non-finite input keeps its generated value.
pub fn shade(generated: &mut Frame, truth: &Frame, unshaded: &Frame) -> Result<(), FramegenError> {
    let limits = protocol::Limits::default();
    for frame in [&*generated, truth, unshaded] {
        frame.validate(&limits)?;
        same_size(generated.meta.size, frame.meta.size)?;
    }
    for ((g, t), u) in generated
        .color
        .iter_mut()
        .zip(&truth.color)
        .zip(&unshaded.color)
    {
        for c in 0..3 {
            let (gv, tv, uv) = (g[c].to_f32(), t[c].to_f32(), u[c].to_f32());
            let v = if uv >= SHADE_FLOOR {
                gv * (tv / uv)
            } else {
                gv + (tv - uv)
            };
            if v.is_finite() {
                g[c] = f16::from_f32(v.clamp(0.0, f16::MAX.to_f32()));
            }
        }
    }
    Ok(())
}

/// `Ok` when `other` is `size`.
fn same_size(size: FrameSize, other: FrameSize) -> Result<(), FramegenError> {
    if other == size {
        Ok(())
    } else {
        Err(FramegenError::Sizes(
            size.width,
            size.height,
            other.width,
            other.height,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use half::f16;
    use protocol::FrameMeta;

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
                    let output = g.output.as_ref().expect("the oracle runs on the CPU");
                    let mask = output.mask[t];
                    assert_eq!(mask == WARPED, !hidden, "{filter} ({x}, {y})");
                    if !hidden {
                        assert_eq!(g.frame.color[t], truth.color[t], "{filter} ({x}, {y})");
                    }
                    assert!(output.color[t].iter().all(|v| v.is_finite()));
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

    #[test]
    fn the_shading_oracle_applies_the_exact_change_and_stays_finite() {
        let truth = frame(1);
        // Unshaded: the truth at half the light.
        let mut unshaded = truth.clone();
        for c in &mut unshaded.color {
            c[0] = f16::from_f32(c[0].to_f32() * 0.5);
        }
        // Generated from the earlier shading: exactly the unshaded image
        // comes back as the truth.
        let mut g = unshaded.clone();
        shade(&mut g, &truth, &unshaded).unwrap();
        assert_eq!(g.color, truth.color);
        // No change: the generated frame is kept as it is.
        let mut g = frame(0);
        g.color[3][1] = f16::from_f32(0.25);
        let kept = g.color.clone();
        shade(&mut g, &truth, &truth).unwrap();
        assert_eq!(g.color, kept);
        // Black without the change: the difference is added; extremes and
        // non-finite inputs stay finite and within f16.
        let mut dark = truth.clone();
        dark.color[0] = [f16::ZERO, f16::from_f32(1e-6), f16::NAN, f16::ONE];
        dark.color[1] = [f16::from_f32(1e-3), f16::INFINITY, f16::ONE, f16::ONE];
        let mut bright = truth.clone();
        bright.color[0][0] = f16::from_f32(2.0);
        bright.color[1][0] = f16::MAX;
        let mut g = frame(0);
        g.color[1][0] = f16::MAX;
        let before = g.color[0];
        shade(&mut g, &bright, &dark).unwrap();
        assert_eq!(g.color[0][0].to_f32(), before[0].to_f32() + 2.0);
        assert_eq!(
            g.color[0][2], before[2],
            "a NaN input keeps the generated value"
        );
        assert_eq!(g.color[1][0], f16::MAX, "clamped within f16");
        assert!(
            g.color
                .iter()
                .all(|c| c.iter().all(|v| v.is_finite() && v.to_f32() >= 0.0))
        );
        let small = Frame {
            meta: FrameMeta {
                size: FrameSize::new(8, 16),
                ..truth.meta
            },
            ..truth.clone()
        };
        assert!(matches!(
            shade(&mut frame(0), &small, &truth),
            Err(FramegenError::Sizes(16, 8, 8, 16))
        ));
    }
}
