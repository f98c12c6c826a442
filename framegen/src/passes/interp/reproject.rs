//! GeoMotionGen passes 2–4 (seed 003): normalize, reproject, merge. See the
//! module docs of [`crate::passes::interp`] for the conventions chosen.

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{Output, Pixel, WARPED};
use crate::passes::common::camera::{cell, pixel_center};
use crate::passes::common::splat::{Candidate, Winners, depth_key};

/// Pass 2: motion in pixels → motion in uv (pixels / size, y down).
pub fn normalize(motion: &[[f32; 2]], width: u32, height: u32) -> Vec<[f32; 2]> {
    use rayon::prelude::*;
    motion.par_iter().map(|m| uv(*m, width, height)).collect()
}

/// One element of [`normalize`].
#[inline]
pub fn uv(m: [f32; 2], width: u32, height: u32) -> [f32; 2] {
    [m[0] / width as f32, m[1] / height as f32]
}

/// Pass 3: where each current pixel is at α (0 = previous frame, 1 =
/// current): `x + (1 − α)·m`, with its depth key. Pixels without a surface
/// (depth 0) land nowhere.
pub fn project(
    uv_motion: &[[f32; 2]],
    depth: &[f32],
    width: u32,
    height: u32,
    alpha: f32,
) -> Vec<Candidate> {
    use rayon::prelude::*;
    uv_motion
        .par_iter()
        .zip(depth)
        .enumerate()
        .map(|(i, (m, &d))| candidate(i, *m, d, (width, height), alpha))
        .collect()
}

/// One element of [`project`]: pixel `i` with uv motion `m` and depth `d`.
#[inline]
pub fn candidate(
    i: usize,
    m: [f32; 2],
    d: f32,
    (width, height): (u32, u32),
    alpha: f32,
) -> Candidate {
    if d.is_nan() || d <= 0.0 {
        return Candidate::MISS;
    }
    let size = Vec2::new(width as f32, height as f32);
    let at = pixel_center(i, width) + Vec2::from_array(m) * size * (1.0 - alpha);
    cell(at, width, height, 1.0)
        .map(|slot| Candidate {
            slot,
            key: depth_key(d),
        })
        .unwrap_or(Candidate::MISS)
}

/// Pass 4: the `width × height` output whose written pixels take their
/// winner's uv motion (`uv_of(i)`) and depth and are flagged written
/// ([`WARPED`]); the rest stay empty.
pub fn merge(
    winners: &Winners,
    uv_of: impl Fn(usize) -> [f32; 2] + Sync + Send,
    depth: &[f32],
    (width, height): (u32, u32),
) -> Output {
    Output::from_fn(width, height, |t| match winners.winner(t) {
        Some(i) => Pixel {
            color: [0.0, 0.0, 0.0, 1.0],
            depth: depth[i],
            motion: uv_of(i),
            mask: WARPED,
        },
        None => Pixel::EMPTY,
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// width, height, 0, 0
    size: [u32; 4],
    /// alpha, 0, 0, 0
    alpha: [f32; 4],
}

/// The GPU passes 2–4 (the splat between 3 and 4 is `splat.rs`).
#[derive(Debug)]
pub struct GpuReproject {
    normalize: Kernel,
    project: Kernel,
    merge: Kernel,
}

impl GpuReproject {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("reproject.wgsl");
        Self {
            normalize: Kernel::new(
                ctx,
                src,
                "interp_normalize",
                &[Params, Read, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite],
            ),
            project: Kernel::new(
                ctx,
                src,
                "interp_project",
                &[
                    Params, Skip, Read, Skip, Skip, Skip, Skip, Skip, ReadWrite, ReadWrite,
                ],
            ),
            merge: Kernel::new(
                ctx,
                src,
                "interp_merge",
                &[
                    Params, Skip, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    fn params(ctx: &Rec<'_>, width: u32, height: u32, alpha: f32) -> wgpu::Buffer {
        ctx.params(bytemuck::bytes_of(&Params {
            size: [width, height, 0, 0],
            alpha: [alpha, 0.0, 0.0, 0.0],
        }))
    }

    /// Records normalize + project of a `width`×`height` frame's `motion`
    /// (pixels) and `depth` at `alpha`: `motion` → `uv` → `candidates`.
    pub fn encode_project(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        ((width, height), alpha): ((u32, u32), f32),
        (motion, depth): (&wgpu::Buffer, &wgpu::Buffer),
        (uv, candidates): (&wgpu::Buffer, &wgpu::Buffer),
    ) {
        let p = Self::params(ctx, width, height, alpha);
        let n = u64::from(width) * u64::from(height);
        self.normalize.dispatch(ctx, encoder, &[&p, motion, uv], n);
        self.project
            .dispatch(ctx, encoder, &[&p, depth, uv, candidates], n);
    }

    /// Records merge of the splat `winners` (of the `uv` positions) of a
    /// `width`×`height` frame of `depth` into `out`.
    pub fn encode_merge(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        ((width, height), depth): ((u32, u32), &wgpu::Buffer),
        (winners, uv): (&wgpu::Buffer, &wgpu::Buffer),
        out: crate::output::GpuOutput<'_>,
    ) {
        let p = Self::params(ctx, width, height, 0.0);
        let n = u64::from(width) * u64::from(height);
        self.merge.dispatch(
            ctx,
            encoder,
            &[
                &p, depth, winners, out.color, out.depth, out.motion, out.mask, uv,
            ],
            n,
        );
    }
}
