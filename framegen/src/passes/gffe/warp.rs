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

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{CRACK, DisplayMap, GpuOutput, Output, Pixel, WARPED};
use crate::passes::common::camera::{Columns, PassCamera, cell};
use crate::passes::common::lanes::{LANES, Lanes3, cells4, project4};
use crate::passes::common::resample::{self, Resample, Source};
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
    candidate_at(p, target).0
}

/// [`candidate`] and the continuous target position it lands at (only
/// meaningful when the candidate has a slot).
#[inline]
pub fn candidate_at(p: [f32; 4], target: &PassCamera) -> (Candidate, Vec2) {
    let Some(r) = target.project(p) else {
        return (Candidate::MISS, Vec2::ZERO);
    };
    let c = cell(r.pixel, target.width(), target.height(), 1.0).map(|slot| Candidate {
        slot,
        key: depth_key(r.depth),
    });
    (c.unwrap_or(Candidate::MISS), r.pixel)
}

/// [`candidate_at`] of four positions, projected in lanes (`lanes.rs`: the
/// same bits).
#[inline]
pub fn candidates_at4(p: &[[f32; 4]; LANES], target: &PassCamera) -> [(Candidate, Vec2); LANES] {
    let (q, w) = Lanes3::from_positions(p);
    let r = project4(target, q, w);
    let cells = cells4(&r, target.width(), target.height(), 1.0);
    std::array::from_fn(|l| match cells[l] {
        Some(slot) => {
            let key = depth_key(r.depth[l]);
            (Candidate { slot, key }, r.pixel(l))
        }
        None => (Candidate::MISS, Vec2::ZERO),
    })
}

/// How `warp_resolve` takes a winner's colour: the filter, and the map
/// from rendered to displayed pixels (motion vectors point through it).
#[derive(Clone, Copy, Debug)]
pub struct Resolve {
    /// Rendered pixels → displayed pixels of the rendered frame.
    pub map: DisplayMap,
    /// The colour filter.
    pub filter: Resample,
    /// Target width and height.
    pub size: (u32, u32),
}

/// CPU reference of `warp_resolve`: the `width × height` output with every
/// won pixel written, the rest holes. A winner's colour is resampled at
/// the sub-pixel position its target pixel's centre maps back to
/// (`resample.rs`); `landing(i)` is where source pixel `i` lands in the
/// target. Its motion points to that position in the rendered frame's
/// displayed region, so colour and motion agree.
pub fn resolve(
    winners: &Winners,
    source: Source<'_>,
    landing: impl Fn(usize) -> Vec2 + Sync + Send,
    how: Resolve,
) -> Output {
    let (width, height) = how.size;
    let (target, image) = (Columns::new(width), Columns::new(source.size.0));
    let per_pixel = Vec2::ONE / how.map.scale;
    Output::from_fn(width, height, |t| {
        let Some(i) = winners.winner(t) else {
            return Pixel::EMPTY;
        };
        let center = target.center(t);
        let own = image.center(i);
        let at = resample::position(own, || landing(i), center, per_pixel, how.filter);
        let c = resample::resample(source, i, at, how.filter);
        Pixel {
            color: [c[0], c[1], c[2], 1.0],
            depth: winners.depth(t).unwrap_or(f32::INFINITY),
            motion: (how.map.apply(at) - center).to_array(),
            mask: WARPED,
        }
    })
}

/// Largest ratio between the depths of a crack's two neighbours: one
/// surface, as the resampling filter takes it.
pub const CRACK_DEPTH_RATIO: f32 = resample::SAME_SURFACE_RATIO;

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
    let fixes: Vec<(usize, [f32; 4], f32, [f32; 2])> = (read.holes().into_par_iter())
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
    /// filter code, source height, 0, 0
    resample: [u32; 4],
}

/// The GPU pass (project + resolve; the splat between them is shared).
#[derive(Debug)]
pub struct GpuWarp {
    project: Kernel,
    resolve: Kernel,
    cracks: Kernel,
}

impl GpuWarp {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = &format!("{}\n{}", resample::WGSL, include_str!("warp.wgsl"));
        Self {
            project: Kernel::new(
                ctx,
                src,
                "warp_project",
                &[Params, Read, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "warp_resolve",
                &[
                    Params, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite, Skip,
                    Read, Read,
                ],
            ),
            cracks: Kernel::new(
                ctx,
                src,
                "warp_cracks",
                &[
                    Params, Skip, Skip, Skip, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// The kernels' uniform: `resample` is the filter code and the source
    /// height (`warp_resolve` only).
    fn params(
        ctx: &Rec<'_>,
        target: &PassCamera,
        sizes: [u32; 4],
        map: DisplayMap,
        resample: [u32; 2],
    ) -> wgpu::Buffer {
        ctx.params(bytemuck::bytes_of(&Params {
            target: *target,
            sizes,
            map: map.to_array(),
            resample: [resample[0], resample[1], 0, 0],
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
        let sizes = [n, target.width(), target.height(), 0];
        let params = Self::params(ctx, target, sizes, DisplayMap::IDENTITY, [0, 0]);
        self.project
            .dispatch(ctx, encoder, &[&params, next, candidates], u64::from(n));
    }

    /// Records `warp_resolve` and `warp_cracks` over the target pixels, with
    /// the map from rendered to displayed pixels and the colour filter.
    /// `source` is the rendered frame's colour and depth with its size,
    /// `next` the positions at α the candidates were projected from.
    pub fn encode_resolve(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (target, map, filter): (&PassCamera, DisplayMap, Resample),
        source: GpuSource<'_>,
        (keys, winners): (&wgpu::Buffer, &wgpu::Buffer),
        out: GpuOutput<'_>,
    ) {
        let (sw, sh) = source.size;
        let sizes = [0, target.width(), target.height(), sw];
        let params = Self::params(ctx, target, sizes, map, [filter.code(), sh]);
        let pixels = u64::from(target.width()) * u64::from(target.height());
        self.resolve.dispatch(
            ctx,
            encoder,
            &[
                &params,
                source.color,
                keys,
                winners,
                out.color,
                out.depth,
                out.motion,
                out.mask,
                source.next,
                source.depth,
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

/// The rendered frame as `warp_resolve` reads it.
#[derive(Debug, Clone, Copy)]
pub struct GpuSource<'a> {
    /// `vec4<f32>` colour.
    pub color: &'a wgpu::Buffer,
    /// `f32` sanitised depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec4<f32>` positions at α (GFFE eq. 1).
    pub next: &'a wgpu::Buffer,
    /// Width and height.
    pub size: (u32, u32),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four positions at a time land where each lands alone: points on and
    /// off the target, behind it, skies, nothing and NaN, seen from a
    /// camera that moved.
    #[test]
    fn four_lanes_land_as_one_by_one() {
        let (eye, size) = ([0.0, 1.0, 3.0], (96, 54));
        let source = crate::testutil::looking(eye, [0.5, 0.0, -4.0], size, eye);
        let target = crate::testutil::looking([0.2, 1.1, 2.9], [0.6, 0.0, -4.0], size, eye);
        let noise = |i: usize| (i as f32 * 0.618_034).fract();
        let p: Vec<[f32; 4]> = (0..4000)
            .map(|i| {
                let pixel = Vec2::new(noise(i) * 120.0 - 12.0, noise(i + 7919) * 68.0 - 7.0);
                let depth = [3.0 + 9.0 * noise(i * 5), f32::INFINITY, -2.0][i % 7 / 5];
                let mut p = source.unproject(pixel, depth);
                match i % 31 {
                    0 => p[3] = -1.0,
                    1 => p[0] = f32::NAN,
                    _ => {}
                }
                p
            })
            .collect();
        let mut landed = 0;
        for four in p.chunks_exact(LANES) {
            let four: &[[f32; 4]; LANES] = four.try_into().unwrap();
            for (l, (c, at)) in candidates_at4(four, &target).into_iter().enumerate() {
                let (one, one_at) = candidate_at(four[l], &target);
                assert_eq!(c, one, "{:?}", four[l]);
                if c.slot != crate::passes::common::splat::NONE {
                    assert_eq!(
                        at.to_array().map(f32::to_bits),
                        one_at.to_array().map(f32::to_bits)
                    );
                    landed += 1;
                }
            }
        }
        assert!(landed > 1000 && landed < 3500, "{landed} of 4000 landed");
    }
}
