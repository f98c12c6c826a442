//! Input preparation shared by both backends: a rendered [`Frame`] becomes
//! `f32` buffers with every non-finite or out-of-range value replaced and
//! counted, so no pass ever sees NaN or infinity where it does not expect
//! one (DESIGN §11: sanitised, counted, never propagated).
//!
//! * color: NaN / ±inf channels → 0; the rest is clamped to `[0, 65504]`
//!   (linear radiance is non-negative, and 65504 is the largest `f16`);
//! * depth: `+inf` is kept (sky); NaN, `−inf`, zero and negative depths
//!   become 0, which every pass reads as "no surface";
//! * motion: NaN / ±inf components → 0, and vectors are clamped to
//!   ±4 image sizes (beyond that a point left the image anyway).

use protocol::Frame;

/// Largest finite `f16`.
pub const MAX_RADIANCE: f32 = 65504.0;

/// Pixels per block of the colour conversions between `f16` and `f32`
/// (here and in the generator's output): large enough for the vector
/// instructions and the scheduler, small enough for a block on the stack.
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
    /// Linear RGB, alpha 1. [`prepare`] makes it from the frame's `f16`,
    /// zeroed or clamped to 65504, so every value is an `f16` and the wgpu
    /// executor uploads it as one (`passes::common::widen`) without loss;
    /// a value made by hand that an `f16` cannot hold is rounded there.
    pub color: Vec<[f32; 4]>,
    /// Linear depth; 0 = no surface, `+inf` = sky.
    pub depth: Vec<f32>,
    /// Motion to the previous frame, pixels.
    pub motion: Vec<[f32; 2]>,
    /// Pixels with a surface (depth > 0).
    pub valid: u64,
    /// What was replaced.
    pub sanitized: Sanitized,
}

/// Converts and sanitises a frame's buffers.
pub fn prepare(frame: &Frame) -> Prepared {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
    // On all cores, in one pass per buffer: each value is replaced on its
    // own and the (rare) replacements are counted as integers, so the result
    // does not depend on the thread count.
    let [bad_color, bad_depth, bad_motion] = [(); 3].map(|()| AtomicU64::new(0));
    // Colour in blocks: each block converted with the CPU's f16
    // instructions in one call (`half`'s slice conversion, exact), then
    // sanitised in place.
    let mut color = crate::par::filled([0.0f32; 4], frame.color.len());
    color
        .par_chunks_mut(CONVERT_BLOCK)
        .zip(frame.color.par_chunks(CONVERT_BLOCK))
        .for_each(|(out, src)| {
            use half::slice::HalfFloatSliceExt;
            src.as_flattened()
                .convert_to_f32_slice(out.as_flattened_mut());
            // Non-finite values to 0 and counted, the rest clamped.
            let mut bad = 0;
            for c in out.iter_mut() {
                for v in &mut c[..3] {
                    let finite = v.is_finite();
                    bad += u64::from(!finite);
                    *v = if finite {
                        v.clamp(0.0, MAX_RADIANCE)
                    } else {
                        0.0
                    };
                }
                c[3] = 1.0;
            }
            if bad > 0 {
                bad_color.fetch_add(bad, Relaxed);
            }
        });
    let depth: Vec<f32> = frame
        .depth
        .par_iter()
        .map(|&d| {
            if d > 0.0 {
                d
            } else {
                bad_depth.fetch_add(1, Relaxed);
                0.0
            }
        })
        .collect();
    let limit = 4.0 * frame.meta.size.width.max(frame.meta.size.height) as f32;
    let motion = frame
        .motion
        .par_iter()
        .map(|m| {
            // Element by element: `[f32; 2]::map` is not inlined here.
            let clean = |v: f32| {
                if v.is_finite() {
                    v.clamp(-limit, limit)
                } else {
                    bad_motion.fetch_add(1, Relaxed);
                    0.0
                }
            };
            [clean(m[0]), clean(m[1])]
        })
        .collect();
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
