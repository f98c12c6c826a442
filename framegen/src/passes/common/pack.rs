//! The generated frame as it leaves the passes for the display, the dump
//! and the wire (GFFE §7.1: colour, depth and motion like a rendered
//! frame): colour sanitised (non-finite and non-positive values to 0, the
//! rest clamped to the largest `f16`) and rounded to the nearest `f16`,
//! depth `+inf` where no surface was written, motion with non-finite
//! components zeroed, and one byte per pixel for its [`PixelSource`].
//!
//! The wgpu executor packs on the device, so a generated frame crosses the
//! bus in 21 bytes a pixel (`f16` colour 8, depth 4, motion 8, source 1)
//! instead of the passes' 32 (`f32` colour, `u32` mask), and the host only
//! copies it into place. [`pack`] is the CPU reference, bit for bit: the
//! kernel rounds to `f16` with integer arithmetic (round to nearest, ties
//! to even, subnormals kept), where WGSL's `pack2x16float` leaves the
//! rounding to the implementation.

use half::f16;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::input::{CONVERT_BLOCK, MAX_RADIANCE};
use crate::output::{Output, PixelSource};

/// A generated frame's buffers, packed.
#[derive(Clone, Debug, PartialEq)]
pub struct Packed {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, alpha 1.
    pub color: Vec<[f16; 4]>,
    /// Linear view depth, `+inf` where there is no surface.
    pub depth: Vec<f32>,
    /// Motion to the rendered frame it was made from, finite.
    pub motion: Vec<[f32; 2]>,
    /// Where each pixel came from.
    pub mask: Vec<PixelSource>,
}

/// A colour channel as the packed frame keeps it (before the rounding to
/// `f16`): non-finite and non-positive values (`-0` too) become `+0`.
#[inline]
pub fn radiance(v: f32) -> f32 {
    if v.is_finite() && v > 0.0 {
        v.min(MAX_RADIANCE)
    } else {
        0.0
    }
}

/// CPU reference of `pack`, on all cores, each buffer made where it is
/// written (`par::blocks`). Colour in blocks: sanitised on
/// the stack, then converted with the CPU's `f16` instructions in one call
/// (`half`'s slice conversion, rounding to nearest like `f16::from_f32`).
pub fn pack(out: &Output) -> Packed {
    use half::slice::HalfFloatSliceExt;
    use rayon::prelude::*;
    let color = crate::par::blocks([f16::ZERO; 4], out.color.len(), CONVERT_BLOCK, |k, dst| {
        let src = &out.color[k * CONVERT_BLOCK..][..dst.len()];
        // Lane by lane, then alpha: loops the compiler vectorises.
        let mut clean = [[0.0f32; 4]; CONVERT_BLOCK];
        let lanes = clean.as_flattened_mut().iter_mut();
        for (c, &s) in lanes.zip(src.as_flattened()) {
            *c = radiance(s);
        }
        for c in &mut clean {
            c[3] = 1.0;
        }
        dst.as_flattened_mut()
            .convert_from_f32_slice(clean[..src.len()].as_flattened());
    });
    Packed {
        width: out.width,
        height: out.height,
        color,
        depth: out
            .depth
            .par_iter()
            .map(|&d| if d > 0.0 { d } else { f32::INFINITY })
            .collect(),
        // In blocks, component by component (a closure per component was
        // not inlined).
        motion: crate::par::blocks([0.0f32; 2], out.motion.len(), CONVERT_BLOCK, |k, dst| {
            let src = &out.motion[k * CONVERT_BLOCK..][..dst.len()];
            let lanes = dst.as_flattened_mut().iter_mut();
            for (d, &v) in lanes.zip(src.as_flattened()) {
                *d = if v.is_finite() { v } else { 0.0 };
            }
        }),
        mask: out
            .mask
            .par_iter()
            .map(|&m| PixelSource::from_mask(m))
            .collect(),
    }
}

/// Bytes of each packed buffer for `n` pixels, in the order the executor
/// reads them back: colour, depth, motion, source (4 a word, the last word
/// padded).
pub fn packed_bytes(n: u64) -> [u64; 4] {
    [n * 8, n * 4, n * 8, n.div_ceil(4) * 4]
}

/// Unpacks the bytes the executor read back (laid out as
/// [`packed_bytes`]) into a [`Packed`], copying on all cores. A source
/// byte the kernel cannot write reads as [`PixelSource::Filled`].
pub fn unpack(bytes: &[u8], width: u32, height: u32) -> Packed {
    let n = width as usize * height as usize;
    let [c, d, m, _] = packed_bytes(n as u64).map(|b| b as usize);
    let (color, rest) = bytes.split_at(c);
    let (depth, rest) = rest.split_at(d);
    let (motion, mask) = rest.split_at(m);
    Packed {
        width,
        height,
        color: par_copy(color, [f16::ZERO; 4], n),
        depth: par_copy(depth, 0.0f32, n),
        motion: par_copy(motion, [0.0f32; 2], n),
        mask: {
            use rayon::prelude::*;
            mask[..n]
                .par_iter()
                .map(|&b| PixelSource::from_mask(u32::from(b)))
                .collect()
        },
    }
}

/// `n` values of `T` from the front of `bytes`, copied block by block on
/// all cores into a buffer made where it is written (`par::blocks`; one
/// core alone moves a frame at a fraction of the memory bandwidth).
fn par_copy<T: bytemuck::Pod + Send + Sync>(bytes: &[u8], zero: T, n: usize) -> Vec<T> {
    const BLOCK: usize = 1 << 16;
    let per = (BLOCK / std::mem::size_of::<T>().max(1)).max(1);
    let bytes = &bytes[..n * std::mem::size_of::<T>()];
    crate::par::blocks(zero, n, per, |k, dst| {
        let dst: &mut [u8] = bytemuck::cast_slice_mut(dst);
        let at = k * per * std::mem::size_of::<T>();
        dst.copy_from_slice(&bytes[at..at + dst.len()]);
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// pixels, 0, 0, 0
    sizes: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuPack {
    kernel: Kernel,
}

/// The packed buffers on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GpuPacked<'a> {
    /// `vec2<u32>` per pixel: four `f16`.
    pub color: &'a wgpu::Buffer,
    /// A byte per pixel, four a word.
    pub mask: &'a wgpu::Buffer,
}

impl GpuPack {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("pack.wgsl"),
                "pack",
                &[
                    Params, Read, ReadWrite, ReadWrite, Read, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the packing of the `n`-pixel output `out`: colour and mask
    /// into `packed`, depth and motion in place.
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        n: u32,
        out: crate::output::GpuOutput<'_>,
        packed: GpuPacked<'_>,
    ) {
        let params = ctx.params(bytemuck::bytes_of(&Params {
            sizes: [n, 0, 0, 0],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &params,
                out.color,
                out.depth,
                out.motion,
                out.mask,
                packed.color,
                packed.mask,
            ],
            u64::from(n),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_is_sanitised_before_rounding() {
        assert_eq!(radiance(f32::NAN), 0.0);
        assert_eq!(radiance(f32::INFINITY), 0.0);
        assert_eq!(radiance(-1.0), 0.0);
        assert!(radiance(-0.0).is_sign_positive());
        assert_eq!(radiance(1e9), MAX_RADIANCE);
        assert_eq!(radiance(0.25), 0.25);
    }

    #[test]
    fn unpacking_what_was_packed_gives_it_back() {
        let (w, h) = (7u32, 3u32);
        let mut out = Output::empty(w, h);
        for t in 0..out.mask.len() {
            out.color[t] = [t as f32, 0.5, f32::NAN, 1.0];
            out.depth[t] = if t % 2 == 0 { t as f32 } else { 0.0 };
            out.motion[t] = [t as f32, f32::INFINITY];
            out.mask[t] = (t % 6) as u32;
        }
        let p = pack(&out);
        let n = out.mask.len();
        let mut bytes = Vec::new();
        bytes.extend_from_slice(bytemuck::cast_slice(&p.color));
        bytes.extend_from_slice(bytemuck::cast_slice(&p.depth));
        bytes.extend_from_slice(bytemuck::cast_slice(&p.motion));
        bytes.extend(p.mask.iter().map(|&m| m as u8));
        bytes.resize(packed_bytes(n as u64).iter().sum::<u64>() as usize, 0);
        assert_eq!(unpack(&bytes, w, h), p);
        assert_eq!(p.depth[1], f32::INFINITY);
        assert_eq!(p.motion[2], [2.0, 0.0]);
        assert_eq!(p.mask[5], PixelSource::Warped);
        assert_eq!(p.color[3][2], f16::ZERO);
    }
}
