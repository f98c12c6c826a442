//! GeoMotionGen pass 7, resolve (seed 003): a written pixel fetches the
//! current frame back along its motion, `y − (1 − α)·m`; an unwritten one
//! (disoccluded in the current frame) reverses the inpainted motion and
//! fetches the previous frame at `y + α·m`. Fetches are bilinear and
//! clamped to the image; depth is the fetched frame's nearest pixel; the
//! output motion points to the previous frame (`α·m`, in pixels).

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{Output, WARPED};
use crate::passes::common::camera::pixel_center;
use crate::passes::common::sample::{bilinear, clamp_index};

/// One rendered frame's color and depth.
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    /// Linear RGB.
    pub color: &'a [[f32; 4]],
    /// Linear depth.
    pub depth: &'a [f32],
}

/// CPU reference: turns `out` (uv motion + written mask after push-pull)
/// into the interpolated frame.
pub fn resolve(out: &mut Output, current: Image<'_>, previous: Image<'_>, alpha: f32) {
    use rayon::prelude::*;
    let (w, h) = (out.width, out.height);
    let size = Vec2::new(w as f32, h as f32);
    out.par_pixels_mut().for_each(|(t, px)| {
        let center = pixel_center(t, w);
        let m = Vec2::from_array(*px.motion) * size;
        let (image, at) = if *px.mask == WARPED {
            (current, center - m * (1.0 - alpha))
        } else {
            (previous, center + m * alpha)
        };
        let c = bilinear(image.color, w, h, at);
        *px.color = [c.x, c.y, c.z, 1.0];
        *px.depth = image.depth[clamp_index(at, w, h)];
        *px.motion = (m * alpha).to_array();
    });
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    size: [u32; 4],
    alpha: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuResolve {
    kernel: Kernel,
}

/// Color and depth buffers of one frame on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GpuImage<'a> {
    /// `vec4<f32>` color.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
}

impl GpuResolve {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("resolve.wgsl"),
                "interp_resolve",
                &[
                    Uniform, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the resolve over `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (width, height): (u32, u32),
        alpha: f32,
        current: GpuImage<'_>,
        previous: GpuImage<'_>,
        out: crate::passes::gffe::warp::GpuOutput<'_>,
    ) {
        let p = ctx.uniform(bytemuck::bytes_of(&Params {
            size: [width, height, 0, 0],
            alpha: [alpha, 0.0, 0.0, 0.0],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &p,
                current.color,
                current.depth,
                previous.color,
                previous.depth,
                out.color,
                out.depth,
                out.motion,
                out.mask,
            ],
            u64::from(width) * u64::from(height),
        );
    }
}
