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
use crate::passes::common::lanes::{LANES, Lanes3, cells4, project4};
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
        Some(&self.grids[self.level(i)?])
    }

    /// The level of texel `i`; `None` past the last level.
    #[inline]
    fn level(&self, i: u32) -> Option<usize> {
        self.ends[..self.count].iter().position(|&end| i < end)
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

/// [`candidate`] of texels `ids`, projected in lanes (`lanes.rs`: the same
/// bits) where all four are of one level, as the texels a pass lists
/// mostly are (background fill: the carried ones, ascending); one by one
/// otherwise.
#[inline]
pub fn candidates4(
    ids: [usize; LANES],
    bg: &[Texel],
    camera: &PassCamera,
    layout: &Layout,
) -> [Candidate; LANES] {
    let level = layout.level(ids[0] as u32);
    let one_level = ids[1..].iter().all(|&i| layout.level(i as u32) == level);
    let Some(grid) = level.filter(|_| one_level).map(|l| layout.grids[l]) else {
        return ids.map(|i| candidate(i, &bg[i], camera, layout));
    };
    let t = ids.map(|i| bg[i]);
    let (p, w) = Lanes3::from_positions(&t.map(|t| t.pos));
    let r = project4(camera, p, w);
    let cells = cells4(&r, grid.width, grid.height, grid.scale);
    std::array::from_fn(|l| match cells[l] {
        Some(cell) if t[l].is_valid() => Candidate {
            slot: grid.offset + cell,
            key: depth_key(r.depth[l]),
        },
        _ => Candidate::MISS,
    })
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
    resolve_won(won, bg, target, current, map, out, None);
}

/// [`resolve`] with each slot's winner given by `won`, `(depth, index)`
/// (the CPU executor's splat leaves them in slots of its own:
/// `splat::Sparse::take_listed`). With `holes`, a list of pixels that
/// holds every hole of `out` (the warp's resolve lists them), only those
/// are visited (at 720p about 1 % of the frame), instead of every pixel;
/// the frame filled is the same.
pub fn resolve_won(
    won: impl Fn(usize) -> Option<(f32, usize)> + Sync,
    bg: &[Texel],
    target: Levels,
    current: &PassCamera,
    map: DisplayMap,
    out: &mut Output,
    holes: Option<&[usize]>,
) {
    use rayon::prelude::*;
    let width = out.width;
    let grids: Vec<Grid> = (0..target.count).map(|l| target.grid(l)).collect();
    // The fragment that fills hole `t`, with its depth and motion.
    let fill = |t: usize| {
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
        let (d, i) = best?;
        let texel = bg[i];
        let motion = current
            .project(texel.pos)
            .map(|r| map.apply(r.pixel) - center)
            .unwrap_or(Vec2::ZERO);
        Some((texel.rgb1(), d, motion.to_array()))
    };
    let Some(holes) = holes else {
        out.par_pixels_mut().for_each(|(t, px)| {
            if *px.mask == EMPTY
                && let Some((color, depth, motion)) = fill(t)
            {
                (*px.color, *px.depth, *px.motion) = (color, depth, motion);
                *px.mask = BACKGROUND;
            }
        });
        return;
    };
    // Found on all cores, written after (few).
    let mask = &out.mask;
    let filled: Vec<_> = (holes.par_iter())
        .filter(|&&t| mask.get(t) == Some(&EMPTY))
        .filter_map(|&t| fill(t).map(|f| (t, f)))
        .collect();
    for (t, (color, depth, motion)) in filled {
        (out.color[t], out.depth[t], out.motion[t]) = (color, depth, motion);
        out.mask[t] = BACKGROUND;
    }
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

    /// Records the hole fill of the `pixels` of `out` from the texels
    /// `bg`, by the splat's `keys` and `winners`.
    pub fn encode_resolve(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (params, bg): (&wgpu::Buffer, &wgpu::Buffer),
        (keys, winners): (&wgpu::Buffer, &wgpu::Buffer),
        (out, pixels): (crate::output::GpuOutput<'_>, u32),
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
    use half::f16;

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

    /// SplitMix64's mixing: an independent value in [0, 1) for each
    /// `(i, k)`.
    fn noise(i: usize, k: usize) -> f32 {
        let mut x = (i as u64 * 4 + k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((x ^ (x >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A background of `levels`: points 2 to 10 in front of a camera at
    /// the origin looking down −z (most in its view), one in 11 a
    /// direction, one in 7 an empty slot.
    fn texels(levels: Levels) -> Vec<Texel> {
        (0..levels.total() as usize)
            .map(|i| {
                let z = 2.0 + 8.0 * noise(i, 0);
                let (x, y) = (noise(i, 1) - 0.5, noise(i, 2) - 0.5);
                let point = [2.0 * x * z, 1.2 * y * z, -z, 1.0];
                let direction = [x, y, -1.0, 0.0];
                let alpha = f16::from_f32(if i % 7 == 3 { 0.0 } else { 1.0 });
                Texel {
                    pos: if i % 11 == 5 { direction } else { point },
                    color: [f16::from_f32(noise(i, 3)), f16::ONE, f16::ZERO, alpha],
                }
            })
            .collect()
    }

    /// The candidates made in lanes are those made one by one: four of one
    /// level (every run of four) and of two levels (the scattered sets),
    /// with empty slots and directions among them, at every level count.
    #[test]
    fn candidates_in_lanes_are_the_candidates() {
        use crate::testutil::looking;
        let (w, h) = (37u32, 23u32);
        let camera = looking([0.4, 0.1, 0.0], [0.3, 0.0, -1.0], (w, h), [0.0; 3]);
        for count in 1..=MAX_LEVELS {
            let levels = Levels::new(count, w, h);
            let bg = texels(levels);
            let layout = Layout::new(levels, levels);
            let n = bg.len();
            let mut landed = 0;
            for first in 0..n {
                let runs = [
                    std::array::from_fn(|k| (first + k) % n),
                    [first, (first + 5) % n, (first * 7) % n, (first + 300) % n],
                ];
                for ids in runs {
                    let one = ids.map(|i| candidate(i, &bg[i], &camera, &layout));
                    assert_eq!(candidates4(ids, &bg, &camera, &layout), one, "{ids:?}");
                    landed += one
                        .iter()
                        .filter(|c| c.slot != Candidate::MISS.slot)
                        .count();
                }
            }
            assert!(landed > n, "count {count}");
        }
    }

    /// Visiting only the listed holes fills the frame that visiting every
    /// pixel fills; listed pixels that are not holes are left alone.
    #[test]
    fn filling_the_listed_holes_is_filling_the_frame() {
        use crate::output::WARPED;
        use crate::testutil::looking;
        let (w, h) = (37u32, 23u32);
        let camera = looking([0.4, 0.1, 0.0], [0.3, 0.0, -1.0], (w, h), [0.0; 3]);
        let levels = Levels::new(3, w, h);
        let bg = texels(levels);
        // Every other slot won by a texel in front of the camera.
        let won = |slot: usize| (slot % 2 == 0).then(|| (1.0 + (slot % 5) as f32, slot % bg.len()));
        let map = DisplayMap::IDENTITY;
        let mut every = Output::empty(w, h);
        for t in 0..every.mask.len() {
            if t % 3 != 0 {
                every.mask[t] = WARPED;
            }
        }
        let mut listed = every.clone();
        resolve_won(won, &bg, levels, &camera, map, &mut every, None);
        // Listed too, a pixel that is not a hole but would be filled if it
        // were one.
        let mut all = Output::empty(w, h);
        resolve_won(won, &bg, levels, &camera, map, &mut all, None);
        let extra = (0..every.mask.len())
            .find(|&t| every.mask[t] == WARPED && all.mask[t] == BACKGROUND)
            .expect("a warped pixel background fill reaches");
        let holes: Vec<usize> = listed.holes().into_iter().chain([extra]).collect();
        resolve_won(won, &bg, levels, &camera, map, &mut listed, Some(&holes));
        assert_eq!(listed, every);
        assert_eq!(listed.mask[extra], WARPED);
        let filled = every.count(BACKGROUND);
        assert!(filled > 0 && every.count(EMPTY) > 0, "{filled}");
    }
}
