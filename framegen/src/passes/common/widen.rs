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
    use half::slice::HalfFloatSliceExt;
    let mut out = reuse;
    if out.len() != color.len() {
        out = crate::par::filled([0.0; 4], color.len());
    }
    planes.fill_with(&mut out, CONVERT_BLOCK, |first, dst, r, g, b| {
        let src = &color[first..first + dst.len()];
        src.as_flattened()
            .convert_to_f32_slice(dst.as_flattened_mut());
        Planes::transpose(dst, r, g, b)
    });
    out
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
