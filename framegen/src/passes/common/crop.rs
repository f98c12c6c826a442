//! The adaptive window's crop (GFFE §4.3, DESIGN §4.5 and step 8): a frame
//! rendered with a widened window shows the displayed region
//! `Window::display_rect` of its image; the client crops (and, in
//! `KeepSize` mode, resamples) it to the display size.
//!
//! Generated frames need no crop: the warp projects straight into the
//! displayed region of the generated camera. This pass serves the rendered
//! frames themselves and the `repeat` baseline. It gathers: color is
//! sampled bilinearly (clamped at the edges), depth and motion take the
//! nearest pixel, and motion is rescaled to displayed pixels.

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::input::Prepared;
use crate::output::{COPIED, Output, Pixel, PixelSource};
use crate::passes::common::camera::pixel_center;
use crate::passes::common::pack::Packed;
use crate::passes::common::sample::{bilinear, clamp_index};

/// Where the displayed region lies in the rendered image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crop {
    /// Rendered image width and height.
    pub source: (u32, u32),
    /// Top-left corner of the displayed region, rendered pixels.
    pub origin: Vec2,
    /// Size of the displayed region, rendered pixels.
    pub extent: Vec2,
    /// Output (display) width and height.
    pub output: (u32, u32),
}

impl Crop {
    /// Continuous rendered-image position of output pixel `t`'s centre.
    pub fn source_of(&self, t: usize) -> Vec2 {
        let out = Vec2::new(self.output.0 as f32, self.output.1 as f32);
        self.origin + pixel_center(t, self.output.0) * (self.extent / out)
    }

    /// Whether the displayed region is the whole rendered image at its own
    /// size: every output pixel is the rendered pixel under it.
    pub fn is_identity(&self) -> bool {
        let (w, h) = self.source;
        self.output == self.source
            && self.origin == Vec2::ZERO
            && self.extent == Vec2::new(w as f32, h as f32)
    }

    /// Displayed pixels per rendered pixel.
    pub fn scale(&self) -> Vec2 {
        Vec2::new(self.output.0 as f32, self.output.1 as f32) / self.extent
    }
}

/// CPU reference of `crop`; `still` gives every pixel zero motion (the
/// GPU executor clears the motion buffer after the kernel).
pub fn crop(
    color: &[[f32; 4]],
    depth: &[f32],
    motion: &[[f32; 2]],
    c: &Crop,
    still: bool,
) -> Output {
    let (w, h) = c.source;
    if c.is_identity() {
        return copy(color, depth, motion, (w, h), still);
    }
    gather(color, depth, motion, c, still)
}

/// The identity crop of a still frame, packed for the host: [`crop`]
/// (identity, `still`) and `pack::pack` fused, reading the prepared frame
/// as it is (`repeat` on the CPU). Its colour is already the sanitised
/// `f16` with alpha 1 that packing the widened copy would give back; depth
/// keeps a surface's and sends "no surface" to `+inf`, as packing does;
/// motion is zero and every pixel copied. No `f32` frame is made.
pub fn still_packed(frame: &Prepared, (width, height): (u32, u32)) -> Packed {
    use rayon::prelude::*;
    // Copies and fills (`memcpy`, `memset`), no buffer written twice.
    let n = width as usize * height as usize;
    Packed {
        width,
        height,
        color: frame.color[..n].to_vec(),
        depth: frame.depth[..n]
            .par_iter()
            .map(|&d| if d > 0.0 { d } else { f32::INFINITY })
            .collect(),
        motion: vec![[0.0; 2]; n],
        mask: vec![PixelSource::Copied; n],
    }
}

/// The identity crop: pixel centres map to pixel centres, so the bilinear
/// weights are (1, 0) and the scale 1, and this is [`gather`], exactly.
/// Each buffer is copied whole (colour in blocks, its alpha set to 1 while
/// the block is in cache), not pixel by pixel through four buffers at
/// once.
fn copy(
    color: &[[f32; 4]],
    depth: &[f32],
    motion: &[[f32; 2]],
    (width, height): (u32, u32),
    still: bool,
) -> Output {
    use rayon::prelude::*;
    let n = width as usize * height as usize;
    let (color, depth, motion) = (&color[..n], &depth[..n], &motion[..n]);
    let band = crate::par::band(width as usize, n);
    let mut rgb = crate::par::filled([0.0f32; 4], n);
    rgb.par_chunks_mut(band)
        .zip(color.par_chunks(band))
        .for_each(|(dst, src)| {
            dst.copy_from_slice(src);
            for c in dst {
                c[3] = 1.0;
            }
        });
    Output {
        width,
        height,
        color: rgb,
        depth: depth.to_vec(),
        motion: if still {
            crate::par::filled([0.0; 2], n)
        } else {
            motion.to_vec()
        },
        mask: crate::par::filled(COPIED, n),
    }
}

/// The general crop: bilinear colour, nearest depth and motion.
fn gather(color: &[[f32; 4]], depth: &[f32], motion: &[[f32; 2]], c: &Crop, still: bool) -> Output {
    let (w, h) = c.source;
    let scale = c.scale();
    Output::from_fn(c.output.0, c.output.1, |t| {
        let s = c.source_of(t);
        let rgb = bilinear(color, w, h, s);
        let nearest = clamp_index(s, w, h);
        let motion = if still {
            [0.0; 2]
        } else {
            (Vec2::from_array(motion[nearest]) * scale).to_array()
        };
        Pixel {
            color: [rgb.x, rgb.y, rgb.z, 1.0],
            depth: depth[nearest],
            motion,
            mask: COPIED,
        }
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// source width, height, output width, height
    sizes: [u32; 4],
    /// origin, extent
    rect: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuCrop {
    kernel: Kernel,
}

impl GpuCrop {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("crop.wgsl"),
                "crop",
                &[
                    Params, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the crop of the rendered buffers (colour, depth, motion)
    /// into `out`.
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        c: &Crop,
        (color, depth, motion): (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer),
        out: crate::output::GpuOutput<'_>,
    ) {
        let params = ctx.params(bytemuck::bytes_of(&Params {
            sizes: [c.source.0, c.source.1, c.output.0, c.output.1],
            rect: [c.origin.x, c.origin.y, c.extent.x, c.extent.y],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &params, color, depth, motion, out.color, out.depth, out.motion, out.mask,
            ],
            u64::from(c.output.0) * u64::from(c.output.1),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fused crop and pack of `repeat` is the crop of the widened
    /// colour, packed, bit for bit, on a frame with every special value the
    /// input sanitising meets (NaN, ±inf, negatives, −0, subnormals, the
    /// largest `f16`; no surface, sky, NaN depth; non-finite motion).
    #[test]
    fn the_packed_still_copy_is_the_crop_packed() {
        use crate::passes::common::{pack, widen};
        use half::f16;
        let size = protocol::FrameSize::new(29, 11);
        let (w, h) = (size.width, size.height);
        let mut frame = crate::testutil::frame(3, size);
        let specials = [
            f16::NAN,
            f16::INFINITY,
            f16::NEG_INFINITY,
            f16::from_f32(-2.5),
            f16::NEG_ZERO,
            f16::from_bits(1),
            f16::MAX,
            f16::from_f32(0.75),
        ];
        for (i, c) in frame.color.iter_mut().enumerate() {
            *c = [0, 3, 5, 7].map(|k| specials[(i + k) % specials.len()]);
        }
        let depths = [0.0, f32::INFINITY, f32::NAN, -1.0, 2.5, f32::NEG_INFINITY];
        for (i, d) in frame.depth.iter_mut().enumerate() {
            *d = depths[i % depths.len()];
        }
        for (i, m) in frame.motion.iter_mut().enumerate() {
            *m = [f32::NAN, i as f32 - 9.5];
        }
        let p = crate::input::prepare(&frame);
        let c = Crop {
            source: (w, h),
            origin: Vec2::ZERO,
            extent: Vec2::new(w as f32, h as f32),
            output: (w, h),
        };
        let color = widen::widen(&p.color);
        let reference = pack::pack(&crop(&color, &p.depth, &p.motion, &c, true));
        let fused = still_packed(&p, (w, h));
        let bits = |q: &Packed| {
            let color: Vec<u16> = q.color.iter().flatten().map(|v| v.to_bits()).collect();
            let depth: Vec<u32> = q.depth.iter().map(|v| v.to_bits()).collect();
            let motion: Vec<u32> = q.motion.iter().flatten().map(|v| v.to_bits()).collect();
            (color, depth, motion, q.mask.clone(), (q.width, q.height))
        };
        assert_eq!(bits(&fused), bits(&reference));
    }

    #[test]
    fn the_identity_crop_is_the_gather_exactly() {
        let (w, h) = (37u32, 23u32);
        let n = (w * h) as usize;
        // Finite, non-negative colour (what input sanitising leaves), with
        // values far apart so any blend with a neighbour would show.
        let color: Vec<[f32; 4]> = (0..n)
            .map(|i| {
                let v = (i * 7919 % 1013) as f32 * 0.37;
                [v, v * 3.1 + 1.0, 65504.0 - v, 1.0]
            })
            .collect();
        let depth: Vec<f32> = (0..n).map(|i| 1.0 + i as f32 * 0.01).collect();
        let motion: Vec<[f32; 2]> = (0..n).map(|i| [i as f32 * 0.3 - 40.0, -2.5]).collect();
        let c = Crop {
            source: (w, h),
            origin: Vec2::ZERO,
            extent: Vec2::new(w as f32, h as f32),
            output: (w, h),
        };
        assert!(c.is_identity());
        for still in [false, true] {
            let fast = crop(&color, &depth, &motion, &c, still);
            assert_eq!(fast, gather(&color, &depth, &motion, &c, still));
        }
        let shifted = Crop {
            origin: Vec2::new(1.0, 0.0),
            ..c
        };
        assert!(!shifted.is_identity());
    }
}
