//! The depth-tested forward warp (GFFE §4.1 "Warping", DESIGN §4 step 4):
//! every pixel's next position is projected into the generated frame's
//! camera and splatted; where several land in one pixel the nearest wins
//! (see `splat.rs` for the deterministic atomics).
//!
//! A warped pixel takes the source pixel's color, the projected depth, and a
//! motion vector pointing to where the source pixel is in the rendered
//! frame's displayed region (DESIGN §4: generated motion points from the
//! generated frame to the frame it was made from).
//!
//! **Cracks.** Splatting one pixel per source leaves one-pixel gaps where a
//! surface is magnified. Left alone, the background layers would fill such
//! a gap inside a foreground object with what lies *behind* it. A hole
//! whose two opposite neighbours (left/right, up/down, or either diagonal
//! pair) were both warped at depths within [`CRACK_DEPTH_RATIO`] of each
//! other is a crack, not a disocclusion: `warp_cracks` closes it with the
//! mean of the first such pair. It reads only pixels the splat wrote
//! ([`WARPED`]) and writes only holes ([`CRACK`]), so it is
//! order-independent.

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{CRACK, DisplayMap, EMPTY, Output, Pixel, WARPED};
use crate::passes::common::camera::{PassCamera, cell, pixel_center};
use crate::passes::common::splat::{Candidate, Winners, depth_key};

/// CPU reference of `warp_project`: one candidate per source pixel.
/// `next` and `target` are relative to the same origin.
pub fn project(next: &[[f32; 4]], target: &PassCamera) -> Vec<Candidate> {
    use rayon::prelude::*;
    next.par_iter().map(|&p| candidate(p, target)).collect()
}

/// One element of [`project`]: where the position `p` lands in `target`,
/// and its depth key.
#[inline]
pub fn candidate(p: [f32; 4], target: &PassCamera) -> Candidate {
    target
        .project(p)
        .and_then(|r| {
            cell(r.pixel, target.width(), target.height(), 1.0).map(|slot| Candidate {
                slot,
                key: depth_key(r.depth),
            })
        })
        .unwrap_or(Candidate::MISS)
}

/// CPU reference of `warp_resolve`: the `width × height` output with every
/// won pixel written, the rest holes.
pub fn resolve(
    winners: &Winners,
    color: &[[f32; 4]],
    source_width: u32,
    map: DisplayMap,
    (width, height): (u32, u32),
) -> Output {
    Output::from_fn(width, height, |t| {
        let Some(i) = winners.winner(t) else {
            return Pixel::EMPTY;
        };
        let center = pixel_center(t, width);
        let source = map.apply(pixel_center(i, source_width));
        let c = color[i];
        Pixel {
            color: [c[0], c[1], c[2], 1.0],
            depth: winners.depth(t).unwrap_or(f32::INFINITY),
            motion: (source - center).to_array(),
            mask: WARPED,
        }
    })
}

/// Largest ratio between the depths of a crack's two neighbours.
pub const CRACK_DEPTH_RATIO: f32 = 1.1;

/// The neighbour pairs a crack is closed from, in the order they are tried.
const PAIRS: [[(i32, i32); 2]; 4] = [
    [(-1, 0), (1, 0)],
    [(0, -1), (0, 1)],
    [(-1, -1), (1, 1)],
    [(1, -1), (-1, 1)],
];

/// CPU reference of `warp_cracks`.
pub fn close_cracks(out: &mut Output) {
    use rayon::prelude::*;
    let (w, h) = (out.width as i32, out.height as i32);
    let read = &*out;
    // Cracks are few: find them in parallel (reading only pixels that
    // were warped before, never one being written), then write them.
    let fixes: Vec<(usize, [f32; 4], f32, [f32; 2])> = (0..read.mask.len())
        .into_par_iter()
        .filter(|&t| read.mask[t] == EMPTY)
        .filter_map(|t| {
            let (x, y) = ((t as i32) % w, (t as i32) / w);
            PAIRS.iter().find_map(|pair| {
                let [a, b] = pair.map(|(dx, dy)| {
                    let (nx, ny) = (x + dx, y + dy);
                    (nx >= 0 && ny >= 0 && nx < w && ny < h).then(|| (ny * w + nx) as usize)
                });
                let (a, b) = (a?, b?);
                if read.mask[a] != WARPED || read.mask[b] != WARPED {
                    return None;
                }
                let (da, db) = (read.depth[a], read.depth[b]);
                if da.max(db) > da.min(db) * CRACK_DEPTH_RATIO {
                    return None;
                }
                let (ca, cb) = (read.color[a], read.color[b]);
                let (ma, mb) = (read.motion[a], read.motion[b]);
                let color = [
                    (ca[0] + cb[0]) * 0.5,
                    (ca[1] + cb[1]) * 0.5,
                    (ca[2] + cb[2]) * 0.5,
                    1.0,
                ];
                let motion = [(ma[0] + mb[0]) * 0.5, (ma[1] + mb[1]) * 0.5];
                Some((t, color, (da + db) * 0.5, motion))
            })
        })
        .collect();
    for (t, color, depth, motion) in fixes {
        out.color[t] = color;
        out.depth[t] = depth;
        out.motion[t] = motion;
        out.mask[t] = CRACK;
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    target: PassCamera,
    /// source count, target width, target height, source width
    sizes: [u32; 4],
    map: [f32; 4],
}

/// The GPU pass (project + resolve; the splat between them is shared).
#[derive(Debug)]
pub struct GpuWarp {
    project: Kernel,
    resolve: Kernel,
    cracks: Kernel,
}

/// The generated frame's buffers on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GpuOutput<'a> {
    /// `vec4<f32>` color.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec2<f32>` motion.
    pub motion: &'a wgpu::Buffer,
    /// `u32` mask.
    pub mask: &'a wgpu::Buffer,
}

impl GpuWarp {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("warp.wgsl");
        Self {
            project: Kernel::new(
                ctx,
                src,
                "warp_project",
                &[Uniform, Read, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "warp_resolve",
                &[
                    Uniform, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
            cracks: Kernel::new(
                ctx,
                src,
                "warp_cracks",
                &[
                    Uniform, Skip, Skip, Skip, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    fn params(
        ctx: &Rec<'_>,
        target: &PassCamera,
        n: u32,
        sw: u32,
        map: DisplayMap,
    ) -> wgpu::Buffer {
        ctx.uniform(bytemuck::bytes_of(&Params {
            target: *target,
            sizes: [n, target.width(), target.height(), sw],
            map: map.to_array(),
        }))
    }

    /// Records `warp_project`: `next` (n positions) → `candidates`.
    pub fn encode_project(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        target: &PassCamera,
        next: &wgpu::Buffer,
        n: u32,
        candidates: &wgpu::Buffer,
    ) {
        let params = Self::params(ctx, target, n, 0, DisplayMap::IDENTITY);
        self.project
            .dispatch(ctx, encoder, &[&params, next, candidates], u64::from(n));
    }

    /// Records `warp_resolve` and `warp_cracks` over the target pixels.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_resolve(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        target: &PassCamera,
        color: &wgpu::Buffer,
        source_width: u32,
        map: DisplayMap,
        keys: &wgpu::Buffer,
        winners: &wgpu::Buffer,
        out: GpuOutput<'_>,
    ) {
        let params = Self::params(ctx, target, 0, source_width, map);
        let pixels = u64::from(target.width()) * u64::from(target.height());
        self.resolve.dispatch(
            ctx,
            encoder,
            &[
                &params, color, keys, winners, out.color, out.depth, out.motion, out.mask,
            ],
            pixels,
        );
        self.cracks.dispatch(
            ctx,
            encoder,
            &[&params, out.color, out.depth, out.motion, out.mask],
            pixels,
        );
    }
}
