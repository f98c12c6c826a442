//! Input preparation shared by both backends: a rendered [`Frame`] becomes
//! `f32` buffers with every non-finite or out-of-range value replaced and
//! counted, so no pass ever sees NaN or infinity where it does not expect
//! one (DESIGN §11: sanitised, counted, never propagated).
//!
//! * color: NaN / ±inf channels → 0, negative ones → 0 (linear radiance
//!   is non-negative), on the `f16` bits, which stay `f16` (every finite
//!   one is at most 65504);
//! * depth: `+inf` is kept (sky); NaN, `−inf`, zero and negative depths
//!   become 0, which every pass reads as "no surface";
//! * motion: NaN / ±inf components → 0, and vectors are clamped to
//!   ±4 image sizes (beyond that a point left the image anyway).

use half::f16;
use protocol::Frame;

/// Largest finite `f16`.
pub const MAX_RADIANCE: f32 = 65504.0;

/// Pixels per block of the colour conversions between `f16` and `f32`
/// (the executors' widening and the generator's output): large enough for
/// the vector instructions and the scheduler, small enough for a block on
/// the stack.
pub const CONVERT_BLOCK: usize = 1024;

/// How many values of each buffer were replaced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sanitized {
    /// Color channels that were non-finite (or negative / above
    /// [`MAX_RADIANCE`] are clamped silently and not counted).
    pub color: u64,
    /// Depths that were NaN, `−inf`, zero or negative.
    pub depth: u64,
    /// Motion components that were non-finite.
    pub motion: u64,
}

impl Sanitized {
    /// Total replaced values.
    pub fn total(&self) -> u64 {
        self.color + self.depth + self.motion
    }
}

/// A rendered frame's buffers as the passes read them.
#[derive(Clone, Debug, PartialEq)]
pub struct Prepared {
    /// Linear RGB, alpha 1, as `f16`: the frame's own values, non-finite
    /// and negative ones zeroed. Kept as it crosses the wire and the bus:
    /// the wgpu executor uploads these bytes as they are, and each executor
    /// widens them to the `f32` its passes read once per frame
    /// (`passes::common::widen`, exact).
    pub color: Vec<[f16; 4]>,
    /// Linear depth; 0 = no surface, `+inf` = sky.
    pub depth: Vec<f32>,
    /// Motion to the previous frame, pixels.
    pub motion: Vec<[f32; 2]>,
    /// Pixels with a surface (depth > 0).
    pub valid: u64,
    /// What was replaced.
    pub sanitized: Sanitized,
}

/// A colour channel as [`prepare`] keeps it, on its `f16` bits: a
/// non-finite value (all exponent bits set) becomes 0 and is reported
/// (`false`), a negative one becomes 0, the rest stays (every finite `f16`
/// is at most [`MAX_RADIANCE`]).
#[inline]
fn sanitize_half(v: f16) -> (f16, bool) {
    let bits = v.to_bits();
    let finite = bits & 0x7c00 != 0x7c00;
    let keep = finite & (bits & 0x8000 == 0);
    (f16::from_bits(if keep { bits } else { 0 }), finite)
}

/// Converts and sanitises a frame's buffers.
pub fn prepare(frame: &Frame) -> Prepared {
    prepare_into(frame, None)
}

/// [`prepare`] into the buffers of `reuse`, a prepared frame no longer
/// needed, where their sizes fit: every element is written, so they are not
/// filled first (a fresh frame-sized buffer is written twice, once to fill
/// it and once with its values).
pub fn prepare_into(frame: &Frame, reuse: Option<Prepared>) -> Prepared {
    use rayon::prelude::*;
    // A buffer of `reuse` where it holds `n` elements, else a new one.
    fn buffer<T: Copy + Send + Sync>(kept: Option<Vec<T>>, zero: T, n: usize) -> Vec<T> {
        kept.filter(|b| b.len() == n)
            .unwrap_or_else(|| crate::par::filled(zero, n))
    }
    let (kept_color, kept_depth, kept_motion) = match reuse {
        Some(p) => (Some(p.color), Some(p.depth), Some(p.motion)),
        None => (None, None, None),
    };
    use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
    // On all cores, in one pass per buffer: each value is replaced on its
    // own and the (rare) replacements are counted as integers, so the result
    // does not depend on the thread count.
    let [bad_color, bad_depth, bad_motion] = [(); 3].map(|()| AtomicU64::new(0));
    // Colour on its `f16` bits (no conversion needed to see a non-finite
    // or negative value), every lane alike (alpha too, then set to 1 and
    // its count taken back out): uniform lanes vectorise, a 3-of-4 pattern
    // does not. Counts per block fit a `u32`.
    let mut color = buffer(kept_color, [f16::ZERO; 4], frame.color.len());
    color
        .par_chunks_mut(CONVERT_BLOCK)
        .zip(frame.color.par_chunks(CONVERT_BLOCK))
        .for_each(|(out, src)| {
            let mut bad = 0u32;
            let lanes = out.as_flattened_mut().iter_mut();
            for (d, &v) in lanes.zip(src.as_flattened()) {
                let (h, finite) = sanitize_half(v);
                bad += u32::from(!finite);
                *d = h;
            }
            for (c, s) in out.iter_mut().zip(src) {
                bad -= u32::from(!sanitize_half(s[3]).1);
                c[3] = f16::ONE;
            }
            if bad > 0 {
                bad_color.fetch_add(u64::from(bad), Relaxed);
            }
        });
    // In blocks with a count per block, as motion: a loop the compiler
    // vectorises (a count per value, an atomic add, kept it scalar).
    let mut depth = buffer(kept_depth, 0.0f32, frame.depth.len());
    depth
        .par_chunks_mut(CONVERT_BLOCK)
        .zip(frame.depth.par_chunks(CONVERT_BLOCK))
        .for_each(|(out, src)| {
            let mut bad = 0u32;
            for (o, &d) in out.iter_mut().zip(src) {
                let surface = d > 0.0;
                bad += u32::from(!surface);
                *o = if surface { d } else { 0.0 };
            }
            if bad > 0 {
                bad_depth.fetch_add(u64::from(bad), Relaxed);
            }
        });
    let limit = 4.0 * frame.meta.size.width.max(frame.meta.size.height) as f32;
    // Component by component in blocks, with a count per block: a loop the
    // compiler vectorises (a closure per component was not inlined).
    let mut motion = buffer(kept_motion, [0.0f32; 2], frame.motion.len());
    motion
        .par_chunks_mut(CONVERT_BLOCK)
        .zip(frame.motion.par_chunks(CONVERT_BLOCK))
        .for_each(|(out, src)| {
            let mut bad = 0u32;
            for (o, &v) in out.as_flattened_mut().iter_mut().zip(src.as_flattened()) {
                let finite = v.is_finite();
                bad += u32::from(!finite);
                // Compares and selects (`min`/`max` carry NaN rules that
                // keep the loop scalar); NaN fails both and is replaced.
                let c = if v < -limit { -limit } else { v };
                let c = if c > limit { limit } else { c };
                *o = if finite { c } else { 0.0 };
            }
            if bad > 0 {
                bad_motion.fetch_add(u64::from(bad), Relaxed);
            }
        });
    let s = Sanitized {
        color: bad_color.into_inner(),
        depth: bad_depth.into_inner(),
        motion: bad_motion.into_inner(),
    };
    let valid = depth.len() as u64 - s.depth;
    Prepared {
        color,
        depth,
        motion,
        valid,
        sanitized: s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sanitising on the bits is the documented one on the values, for
    /// every `f16`: non-finite → 0 and reported, the rest clamped to
    /// `[0, 65504]`.
    #[test]
    fn every_half_is_sanitised_as_its_value_says() {
        for bits in 0..=u16::MAX {
            let v = f16::from_bits(bits);
            let (h, finite) = sanitize_half(v);
            let x = v.to_f32();
            let expected = if x.is_finite() {
                x.clamp(0.0, MAX_RADIANCE)
            } else {
                0.0
            };
            assert_eq!(finite, x.is_finite(), "{bits:#06x}");
            assert_eq!(h.to_f32(), expected, "{bits:#06x}");
            assert!(h.is_sign_positive(), "{bits:#06x}");
        }
    }

    /// A frame with values to replace in every buffer.
    fn dirty(index: u64, size: protocol::FrameSize) -> Frame {
        let mut f = crate::testutil::frame(index, size);
        for (i, c) in f.color.iter_mut().enumerate() {
            let v = f16::from_f32(i as f32 * 0.37 - 20.0);
            *c = [v, f16::NAN, f16::from_f32(i as f32), f16::INFINITY];
        }
        for (i, d) in f.depth.iter_mut().enumerate() {
            *d = [f32::NAN, -1.0, 0.0, 2.5, f32::INFINITY][i % 5];
        }
        for (i, m) in f.motion.iter_mut().enumerate() {
            *m = [[f32::NAN, 1e9][i % 2], i as f32 - 3.0];
        }
        f
    }

    /// Preparing into the buffers of an earlier prepared frame gives what a
    /// fresh preparation gives (buffers, counts), whatever those buffers
    /// held, and buffers of another size are not reused.
    #[test]
    fn prepared_into_reused_buffers_is_prepared_afresh() {
        let size = protocol::FrameSize::new(37, 5);
        let frame = dirty(1, size);
        let fresh = prepare(&frame);
        assert!(fresh.sanitized.total() > 0 && fresh.valid > 0);
        let earlier = prepare(&crate::testutil::frame(0, size));
        let color_at = earlier.color.as_ptr();
        let reused = prepare_into(&frame, Some(earlier));
        assert_eq!(reused, fresh);
        assert_eq!(reused.color.as_ptr(), color_at, "the buffer was reused");
        let small = prepare(&crate::testutil::frame(0, protocol::FrameSize::new(3, 2)));
        assert_eq!(prepare_into(&frame, Some(small)), fresh);
    }
}
