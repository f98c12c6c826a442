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
use crate::output::{COPIED, Output};
use crate::passes::common::camera::pixel_center;
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

    /// Displayed pixels per rendered pixel.
    pub fn scale(&self) -> Vec2 {
        Vec2::new(self.output.0 as f32, self.output.1 as f32) / self.extent
    }
}

/// CPU reference of `crop`.
pub fn crop(color: &[[f32; 4]], depth: &[f32], motion: &[[f32; 2]], c: &Crop) -> Output {
    let (w, h) = c.source;
    let mut out = Output::empty(c.output.0, c.output.1);
    let scale = c.scale();
    use rayon::prelude::*;
    out.par_pixels_mut().for_each(|(t, px)| {
        let s = c.source_of(t);
        let rgb = bilinear(color, w, h, s);
        let nearest = clamp_index(s, w, h);
        *px.color = [rgb.x, rgb.y, rgb.z, 1.0];
        *px.depth = depth[nearest];
        *px.motion = (Vec2::from_array(motion[nearest]) * scale).to_array();
        *px.mask = COPIED;
    });
    out
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
                    Uniform, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the crop of the rendered buffers into `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        c: &Crop,
        color: &wgpu::Buffer,
        depth: &wgpu::Buffer,
        motion: &wgpu::Buffer,
        out: crate::passes::gffe::warp::GpuOutput<'_>,
    ) {
        let params = ctx.uniform(bytemuck::bytes_of(&Params {
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
