//! The rendered frame's colour crosses the bus as `f16` (8 bytes a pixel
//! where the passes read 16) and is widened to `f32` on the device, part
//! of the wgpu executor's upload: a rendered frame then crosses in 20 bytes
//! a pixel (colour 8, depth 4, motion 8) instead of 28. The CPU executor's
//! upload widens it on the host ([`widen_into`]).
//!
//! The `f16` is the frame's own, sanitised on its bits
//! ([`crate::input::prepare`]): the host converts nothing on the way to the
//! device, and the kernel gives back the `f32` of each `f16` exactly, bit
//! for bit as the host would (it decodes the bits itself, subnormals
//! included, where WGSL's `unpack2x16float` may flush them). [`widen`] is
//! the CPU reference.

use half::f16;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::input::CONVERT_BLOCK;
use crate::passes::common::resample_run::Planes;

/// CPU reference of `widen`: `f16` colour as `f32`, exact.
pub fn widen(color: &[[f16; 4]]) -> Vec<[f32; 4]> {
    widen_into(color, Vec::new())
}

/// [`widen`] into `reuse` (resized to fit; every element is written), on
/// all cores, in blocks converted with the CPU's `f16` instructions
/// (`half`'s slice conversion).
pub fn widen_into(color: &[[f16; 4]], reuse: Vec<[f32; 4]>) -> Vec<[f32; 4]> {
    use half::slice::HalfFloatSliceExt;
    use rayon::prelude::*;
    let mut out = reuse;
    if out.len() != color.len() {
        out = crate::par::filled([0.0; 4], color.len());
    }
    out.par_chunks_mut(CONVERT_BLOCK)
        .zip(color.par_chunks(CONVERT_BLOCK))
        .with_max_len(16)
        .for_each(|(dst, src)| {
            src.as_flattened()
                .convert_to_f32_slice(dst.as_flattened_mut())
        });
    out
}

/// [`widen_into`], and the widened colour's planes into `planes`
/// ([`Planes::fill`]), each block while it is in the cache: the warp's
/// Catmull-Rom runs read the planes, and making them from the widened frame
/// later read it all again (0.8 ms a generated frame at 720p on two cores).
pub fn widen_planes_into(
    color: &[[f16; 4]],
    reuse: Vec<[f32; 4]>,
    planes: &mut Planes,
) -> Vec<[f32; 4]> {
    let mut out = reuse;
    if out.len() != color.len() {
        out = crate::par::filled([0.0; 4], color.len());
    }
    planes.fill_with(&mut out, CONVERT_BLOCK, |first, dst, r, g, b| {
        let src = &color[first..first + dst.len()];
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
            // SAFETY: the CPU has both, just checked.
            return unsafe { widen_block_f16c(src, dst, [r, g, b]) };
        }
        widen_block(src, dst, [r, g, b])
    });
    out
}

/// One block of [`widen_planes_into`]: `src` widened into `dst` and its
/// channels into the planes `rgb` (all as long as `src`); whether every
/// alpha is 1 ([`Planes::transpose`]).
fn widen_block(src: &[[f16; 4]], dst: &mut [[f32; 4]], rgb: [&mut [f32]; 3]) -> bool {
    use half::slice::HalfFloatSliceExt;
    src.as_flattened()
        .convert_to_f32_slice(dst.as_flattened_mut());
    let [r, g, b] = rgb;
    Planes::transpose(dst, r, g, b)
}

/// [`widen_block`] with AVX2 and F16C, eight pixels at a time: each pair
/// widened by `vcvtph2ps` (exact, as `half`'s conversion is on such a
/// CPU) and stored, the four pairs' channels gathered into a register each
/// by shuffles and stored as eight values of a plane, instead of a scalar
/// store per channel and pixel; the last few pixels by [`widen_block`].
///
/// # Safety
///
/// The CPU has AVX2 and F16C.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,f16c")]
unsafe fn widen_block_f16c(src: &[[f16; 4]], dst: &mut [[f32; 4]], rgb: [&mut [f32]; 3]) -> bool {
    use std::arch::x86_64::*;
    let [r, g, b] = rgb;
    let n = src
        .len()
        .min(dst.len())
        .min(r.len())
        .min(g.len())
        .min(b.len());
    let whole = n / 8 * 8;
    let one = _mm256_set1_ps(1.0);
    // After the shuffles a register holds a channel of pixels 0 2 4 6 1 3
    // 5 7: lane i of the channel takes lane `order[i]`.
    let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    let mut opaque = _mm256_cmp_ps::<_CMP_EQ_OQ>(one, one);
    for first in (0..whole).step_by(8) {
        // SAFETY: pixels `first .. first + 8` are inside `src` and `dst`
        // (`first + 8 <= whole <= n`): four unaligned 16-byte loads of two
        // pixels of four `f16`s, four unaligned 32-byte stores of two
        // pixels of four `f32`s.
        let [p01, p23, p45, p67] = std::array::from_fn(|k| unsafe {
            let half = _mm_loadu_si128(src.as_ptr().add(first + 2 * k).cast());
            let wide = _mm256_cvtph_ps(half);
            _mm256_storeu_ps(dst.as_mut_ptr().add(first + 2 * k).cast(), wide);
            wide
        });
        // r0 r2 g0 g2 | r1 r3 g1 g3, b0 b2 a0 a2 | b1 b3 a1 a3, and the
        // same of pixels 4 to 7.
        let (rg0, ba0) = (_mm256_unpacklo_ps(p01, p23), _mm256_unpackhi_ps(p01, p23));
        let (rg4, ba4) = (_mm256_unpacklo_ps(p45, p67), _mm256_unpackhi_ps(p45, p67));
        let channel = |a, b| _mm256_permutevar8x32_ps(a, b);
        let red = channel(_mm256_shuffle_ps::<0x44>(rg0, rg4), order);
        let green = channel(_mm256_shuffle_ps::<0xee>(rg0, rg4), order);
        let blue = channel(_mm256_shuffle_ps::<0x44>(ba0, ba4), order);
        let alpha = _mm256_shuffle_ps::<0xee>(ba0, ba4);
        opaque = _mm256_and_ps(opaque, _mm256_cmp_ps::<_CMP_EQ_OQ>(alpha, one));
        // SAFETY: values `first .. first + 8` of each plane (`<= n`),
        // unaligned 32-byte stores.
        unsafe {
            _mm256_storeu_ps(r.as_mut_ptr().add(first), red);
            _mm256_storeu_ps(g.as_mut_ptr().add(first), green);
            _mm256_storeu_ps(b.as_mut_ptr().add(first), blue);
        }
    }
    let rgb = [&mut r[whole..n], &mut g[whole..n], &mut b[whole..n]];
    let rest = widen_block(&src[whole..n], &mut dst[whole..n], rgb);
    rest & (_mm256_movemask_ps(opaque) == 0xff)
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// pixels, 0, 0, 0
    sizes: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuWiden {
    kernel: Kernel,
}

impl GpuWiden {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("widen.wgsl"),
                "widen",
                &[Params, Read, ReadWrite],
            ),
        }
    }

    /// Records the widening of `n` pixels of `f16` colour (`vec2<u32>`
    /// each) in `half` into `color` (`vec4<f32>` each).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        n: u32,
        half: &wgpu::Buffer,
        color: &wgpu::Buffer,
    ) {
        let params = ctx.params(bytemuck::bytes_of(&Params {
            sizes: [n, 0, 0, 0],
        }));
        self.kernel
            .dispatch(ctx, encoder, &[&params, half, color], u64::from(n));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block widened eight pixels at a time is the block widened pixel
    /// by pixel, bit for bit, planes and opacity included: every length
    /// up to 20 (whole eights and a rest), with one pixel not opaque at
    /// every position (in an eight, in the rest) or none.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_pixels_at_a_time_are_the_pixels_one_by_one() {
        if !(std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c")) {
            return;
        }
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for n in 0..=20usize {
            for translucent in (0..n).map(Some).chain([None]) {
                let src: Vec<[f16; 4]> = (0..n)
                    .map(|i| {
                        let v = |k: usize| {
                            f16::from_bits(
                                ((i * 4 + k) as u16)
                                    .wrapping_mul(0x0a3d)
                                    .wrapping_add(0x0137),
                            )
                        };
                        let alpha = match translucent == Some(i) {
                            true => f16::from_f32(0.5),
                            false => f16::ONE,
                        };
                        [v(0), v(1), v(2), alpha]
                    })
                    .collect();
                let made = |fast: bool| {
                    let (mut dst, mut r, mut g, mut b) =
                        (vec![[9.0; 4]; n], vec![9.0; n], vec![9.0; n], vec![9.0; n]);
                    let opaque = match fast {
                        // SAFETY: the CPU has both, checked above.
                        true => unsafe {
                            widen_block_f16c(&src, &mut dst, [&mut r, &mut g, &mut b])
                        },
                        false => widen_block(&src, &mut dst, [&mut r, &mut g, &mut b]),
                    };
                    (
                        bits(dst.as_flattened()),
                        bits(&r),
                        bits(&g),
                        bits(&b),
                        opaque,
                    )
                };
                let (fast, each) = (made(true), made(false));
                assert_eq!(fast, each, "{n} pixels, {translucent:?} not opaque");
                assert_eq!(each.4, translucent.is_none());
                assert_eq!(
                    each.1,
                    bits(&src.iter().map(|p| p[0].to_f32()).collect::<Vec<_>>())
                );
            }
        }
    }

    /// Every `f16`, in whole blocks and a last partial one, into a reused
    /// buffer of another size: each value its own `f32`, bit for bit, with
    /// or without the colour planes made on the way (`Planes::fill`'s).
    #[test]
    fn widening_is_exact_for_every_half() {
        let all: Vec<[f16; 4]> = (0..=u16::MAX)
            .map(|b| {
                let v = f16::from_bits(b);
                [v, f16::from_bits(!b), f16::MAX, f16::ONE]
            })
            .chain([[f16::from_f32(1.5); 4]])
            .collect();
        let wide = widen_into(&all, vec![[7.0; 4]; 3]);
        assert_eq!(wide.len(), all.len());
        // NaN payloads aside (sanitised colour holds none).
        let bits = |v: f32| if v.is_nan() { u32::MAX } else { v.to_bits() };
        for (w, h) in wide.iter().zip(&all) {
            assert_eq!(w.map(bits), h.map(|v| bits(v.to_f32())));
        }
        // With the planes made on the way: the same bits, and the planes
        // of the widened colour, into planes of another size.
        let mut planes = Planes::default();
        planes.fill(&[[1.0; 4]; 5]);
        let with = widen_planes_into(&all, vec![[7.0; 4]; 3], &mut planes);
        assert_eq!(with.len(), all.len());
        for (w, v) in with.iter().zip(&wide) {
            assert_eq!(w.map(bits), v.map(bits));
        }
        // Alpha 1 but for the NaN payloads' pixels: not opaque.
        let mut expected = Planes::default();
        expected.fill(&wide);
        assert!(!expected.usable(all.len()));
        // NaN != NaN: compare by the widened bits, channel by channel.
        let mut a = Planes::default();
        a.fill(&with);
        assert_eq!(format!("{a:?}"), format!("{planes:?}"));
        let opaque: Vec<[f16; 4]> = all.iter().map(|c| [c[0], c[1], c[2], f16::ONE]).collect();
        let with = widen_planes_into(&opaque, with, &mut planes);
        assert!(planes.usable(all.len()));
        expected.fill(&with);
        assert_eq!(format!("{expected:?}"), format!("{planes:?}"));
    }
}
