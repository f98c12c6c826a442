//! The rendered frame's colour crosses the bus as `f16` (8 bytes a pixel
//! where the passes read 16) and is widened to `f32` on the device, part
//! of the wgpu executor's upload: a rendered frame then crosses in 20 bytes
//! a pixel (colour 8, depth 4, motion 8) instead of 28.
//!
//! Nothing is lost: the sanitised colour ([`crate::input::prepare`]) came
//! from the frame's own `f16` and was only zeroed or clamped to 0 and
//! 65504, both `f16` values, so [`narrow`] is exact on it and the kernel
//! gives back the same `f32`, bit for bit (it decodes the bits itself,
//! subnormals included, where WGSL's `unpack2x16float` may flush them).
//! [`widen`] is the CPU reference.

use half::f16;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::input::CONVERT_BLOCK;

/// `f32` colour as `f16` bytes (8 a pixel) into `out`, on all cores, in
/// blocks converted with the CPU's `f16` instructions (rounding to nearest;
/// exact on sanitised colour).
pub fn narrow_into(color: &[[f32; 4]], out: wgpu::WriteOnly<'_, [u8]>) {
    use rayon::prelude::*;
    const BYTES: usize = CONVERT_BLOCK * 8;
    let (pieces, rest) = crate::gpu::write_pieces::<BYTES>(out);
    let whole = pieces.len() * CONVERT_BLOCK;
    pieces
        .into_par_iter()
        .zip(color[..whole].par_chunks_exact(CONVERT_BLOCK))
        .for_each(|(dst, src)| convert(src, dst.into()));
    convert(&color[whole..], rest);
}

/// One block of [`narrow_into`].
fn convert(src: &[[f32; 4]], mut dst: wgpu::WriteOnly<'_, [u8]>) {
    use half::slice::HalfFloatSliceExt;
    let mut block = [[f16::ZERO; 4]; CONVERT_BLOCK];
    let block = &mut block[..src.len()];
    block
        .as_flattened_mut()
        .convert_from_f32_slice(src.as_flattened());
    dst.copy_from_slice(bytemuck::cast_slice(block));
}

/// CPU reference of `widen`: `f16` colour as `f32`.
pub fn widen(color: &[[f16; 4]]) -> Vec<[f32; 4]> {
    color.iter().map(|c| c.map(f16::to_f32)).collect()
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
                &[Uniform, Read, ReadWrite],
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
        let params = ctx.uniform(bytemuck::bytes_of(&Params {
            sizes: [n, 0, 0, 0],
        }));
        self.kernel
            .dispatch(ctx, encoder, &[&params, half, color], u64::from(n));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`narrow_into`] a vector.
    fn narrow(color: &[[f32; 4]]) -> Vec<[f16; 4]> {
        let mut out = vec![[f16::ZERO; 4]; color.len()];
        narrow_into(
            color,
            bytemuck::cast_slice_mut::<_, u8>(&mut out[..]).into(),
        );
        out
    }

    #[test]
    fn narrowing_sanitised_colour_is_exact() {
        // Every finite, non-negative f16 (what sanitising leaves), as f32.
        let all: Vec<[f32; 4]> = (0..0x7c00u16)
            .map(|b| {
                let v = f16::from_bits(b).to_f32();
                [v, 0.0, 65504.0, 1.0]
            })
            // A last, partial block.
            .chain([[1.5, 2.0, 3.0, 1.0]])
            .collect();
        let half = narrow(&all);
        assert_eq!(widen(&half), all);
        assert_eq!(half[0x3c00][0], f16::ONE);
    }
}
