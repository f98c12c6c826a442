//! Background projection (GFFE §4.2, DESIGN §4 step 6): the collected
//! background layers are projected into the generated frame and fill only
//! its holes.
//!
//! Level `l` is splatted at its own resolution (the generated frame's size
//! divided by `2^l`), so one coarse fragment covers a `2^l × 2^l` block and
//! the coarser layers do not leave pinholes. A hole pixel then takes the
//! nearest of the levels' winners at its position (ties go to the finer
//! level). Its motion vector points to where the fragment is in the rendered
//! frame's displayed region, like a warped pixel's.

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{BACKGROUND, DisplayMap, EMPTY, Output};
use crate::passes::common::camera::{PassCamera, pixel_center};
use crate::passes::common::levels::{Grid, Levels};
use crate::passes::common::splat::{Candidate, Winners, depth_key};
use crate::passes::gffe::background::{MAX_LEVELS, Texel};

/// CPU reference of `bgfill_project`: one candidate per background texel.
/// `source` is the background's layout, `target` the generated frame's
/// pyramid (same level count).
pub fn project(
    bg: &[Texel],
    source: Levels,
    camera: &PassCamera,
    target: Levels,
) -> Vec<Candidate> {
    use rayon::prelude::*;
    let layout = Layout::new(source, target);
    bg.par_iter()
        .enumerate()
        .map(|(i, t)| candidate(i, t, camera, &layout))
        .collect()
}

/// Where the texels of each background level land: the ends of the
/// background's levels and the grids of the target pyramid's, computed
/// once per frame instead of per texel.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// One past the last texel of each source level.
    ends: [u32; MAX_LEVELS as usize],
    /// The target pyramid's level of the same number.
    grids: [Grid; MAX_LEVELS as usize],
    /// Levels in use (at most [`MAX_LEVELS`], as the settings allow).
    count: usize,
}

impl Layout {
    /// The layout of a background of `source` levels projected into the
    /// `target` pyramid.
    pub fn new(source: Levels, target: Levels) -> Self {
        let count = source.count.min(MAX_LEVELS);
        let level = |l: u32| l.min(count.saturating_sub(1));
        Self {
            ends: std::array::from_fn(|l| {
                let l = level(l as u32);
                source.offset(l) + source.len(l)
            }),
            grids: std::array::from_fn(|l| target.grid(level(l as u32))),
            count: count as usize,
        }
    }

    /// The level of texel `i` with its target grid; `None` past the last
    /// level.
    #[inline]
    fn level_of(&self, i: u32) -> Option<&Grid> {
        let l = self.ends[..self.count].iter().position(|&end| i < end)?;
        Some(&self.grids[l])
    }
}

/// One element of [`project`]: where texel `i` of the background lands in
/// its level of the target pyramid.
#[inline]
pub fn candidate(i: usize, t: &Texel, camera: &PassCamera, layout: &Layout) -> Candidate {
    if !t.is_valid() {
        return Candidate::MISS;
    }
    let Some(grid) = layout.level_of(i as u32) else {
        return Candidate::MISS;
    };
    camera
        .project(t.pos)
        .and_then(|r| {
            grid.slot(r.pixel).map(|slot| Candidate {
                slot,
                key: depth_key(r.depth),
            })
        })
        .unwrap_or(Candidate::MISS)
}

/// CPU reference of `bgfill_resolve`: fills the holes of `out`. `current`
/// is the rendered frame's camera (for the motion vectors).
pub fn resolve(
    winners: &Winners,
    bg: &[Texel],
    target: Levels,
    current: &PassCamera,
    map: DisplayMap,
    out: &mut Output,
) {
    let won = |slot| winners.depth(slot).zip(winners.winner(slot));
    resolve_won(won, bg, target, current, map, out);
}

/// [`resolve`] with each slot's winner given by `won`, `(depth, index)`
/// (the CPU executor's splat leaves them in slots of its own:
/// `splat::Sparse::take_listed`).
pub fn resolve_won(
    won: impl Fn(usize) -> Option<(f32, usize)> + Sync,
    bg: &[Texel],
    target: Levels,
    current: &PassCamera,
    map: DisplayMap,
    out: &mut Output,
) {
    use rayon::prelude::*;
    let width = out.width;
    let grids: Vec<Grid> = (0..target.count).map(|l| target.grid(l)).collect();
    out.par_pixels_mut().for_each(|(t, px)| {
        if *px.mask != EMPTY {
            return;
        }
        let center = pixel_center(t, width);
        let mut best: Option<(f32, usize)> = None;
        for grid in &grids {
            let Some(slot) = grid.slot(center) else {
                continue;
            };
            let slot = slot as usize;
            if let Some((d, i)) = won(slot)
                && best.is_none_or(|(bd, _)| d < bd)
            {
                best = Some((d, i));
            }
        }
        let Some((d, i)) = best else {
            return;
        };
        let texel = bg[i];
        let motion = current
            .project(texel.pos)
            .map(|r| map.apply(r.pixel) - center)
            .unwrap_or(Vec2::ZERO);
        *px.color = texel.rgb1();
        *px.depth = d;
        *px.motion = motion.to_array();
        *px.mask = BACKGROUND;
    });
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    target: PassCamera,
    current: PassCamera,
    map: [f32; 4],
    /// L, texel count, target width, target height
    config: [u32; 4],
    /// Start of each source level (unused levels: the total).
    source_offsets: [u32; 4],
    target_offsets: [u32; 4],
    target_widths: [u32; 4],
    target_heights: [u32; 4],
    /// Pixels whose level-0 fragments are skipped (0: none), 0, 0, 0.
    seed: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuBgFill {
    project: Kernel,
    resolve: Kernel,
}

impl GpuBgFill {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("bgfill.wgsl");
        Self {
            project: Kernel::new(
                ctx,
                src,
                "bgfill_project",
                &[
                    Params, Read, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite, Read, Read,
                ],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "bgfill_resolve",
                &[
                    Params, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// The uniform both kernels read; `seeded` pixels of the rendered
    /// frame have level-0 fragments the projection skips (its pixel count
    /// when the warp ran from the same history, else 0).
    pub fn params(
        ctx: &Rec<'_>,
        target: &PassCamera,
        current: &PassCamera,
        map: DisplayMap,
        (source, target_levels): (Levels, Levels),
        seeded: u32,
    ) -> wgpu::Buffer {
        let mut p = Params {
            target: *target,
            current: *current,
            map: map.to_array(),
            config: [
                source.count,
                source.total(),
                target.width(),
                target.height(),
            ],
            source_offsets: [source.total(); 4],
            target_offsets: [0; 4],
            target_widths: [0; 4],
            target_heights: [0; 4],
            seed: [seeded, 0, 0, 0],
        };
        for l in 0..source.count.min(MAX_LEVELS) as usize {
            p.source_offsets[l] = source.offset(l as u32);
            p.target_offsets[l] = target_levels.offset(l as u32);
            let (w, h) = target_levels.size(l as u32);
            p.target_widths[l] = w;
            p.target_heights[l] = h;
        }
        ctx.params(bytemuck::bytes_of(&p))
    }

    /// Records the projection of every texel of the background `bg` (its
    /// texel count beside it) into `candidates`; `seeds` are the rendered
    /// frame's track words and `P_0` plane (read for the seeded pixels of
    /// [`GpuBgFill::params`]).
    pub fn encode_project(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        params: &wgpu::Buffer,
        (bg, texels): (&wgpu::Buffer, u32),
        candidates: &wgpu::Buffer,
        (track, p0): (&wgpu::Buffer, &wgpu::Buffer),
    ) {
        self.project.dispatch(
            ctx,
            encoder,
            &[params, bg, candidates, track, p0],
            u64::from(texels),
        );
    }

    /// Records the hole fill.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_resolve(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        params: &wgpu::Buffer,
        bg: &wgpu::Buffer,
        keys: &wgpu::Buffer,
        winners: &wgpu::Buffer,
        out: crate::output::GpuOutput<'_>,
        pixels: u32,
    ) {
        self.resolve.dispatch(
            ctx,
            encoder,
            &[
                params, bg, keys, winners, out.color, out.depth, out.motion, out.mask,
            ],
            u64::from(pixels),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The per-frame layout puts every texel in the level `Levels` says,
    /// with that level's target grid, for every level count the settings
    /// allow and odd sizes; nothing past the last level.
    #[test]
    fn the_layout_finds_each_texels_level() {
        for count in 0..=MAX_LEVELS {
            let source = Levels::new(count, 13, 7);
            let target = Levels::new(count, 11, 9);
            let layout = Layout::new(source, target);
            for i in 0..source.total() {
                let l = source.level_of(i);
                assert_eq!(
                    layout.level_of(i),
                    Some(&target.grid(l)),
                    "count {count}, texel {i}"
                );
            }
            assert_eq!(layout.level_of(source.total()), None, "count {count}");
        }
    }
}
