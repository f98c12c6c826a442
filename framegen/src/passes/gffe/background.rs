//! Layered background collection, GFFE §4.2 and Fig. 5 (DESIGN §4 step 5).
//!
//! The background buffer has `L` levels of (position, color); level `l + 1`
//! has ¼ the pixels of level `l`, all over the current rendered frame's
//! image. For each rendered frame:
//!
//! 1. the frame's **confirmed static** fragments (see `history.rs`: static
//!    and seen at the same place by the previous frame) fill level 0;
//! 2. for `l = 0..L`, every fragment of the previous buffer's level `l` is
//!    reprojected into the current camera:
//!    * **case 1**: the same level is empty there → candidate for `B_l`;
//!    * **case 2**: the level is occupied by something nearer (by more
//!      than the relative `depth_tolerance`) → candidate for `B_{l+1}`,
//!      "the deeper fragments of the current layer";
//!    * otherwise (the same surface again, or a fragment now in front of
//!      what the camera sees, i.e. something that left) it is dropped;
//!
//!    among candidates for one slot the nearest wins (`splat.rs`). Level
//!    `l`'s step runs before level `l + 1`'s, so case-2 fragments count as
//!    "occupied" for the next level.
//!
//! Choices made here: a fragment keeps its exact position (camera-relative,
//! rebased each frame) instead of being re-derived from its slot's centre,
//! so repeated reprojection does not drift; a slot's "depth" for case 2 is
//! the view depth of the position it holds; sky directions take part like
//! any fragment (they are the deepest layer and move only with rotation).
//! A change of `L` or of the frame size drops the previous buffer.

use glam::Vec3;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::{PassCamera, rebase};
use crate::passes::common::levels::{Grid, Levels};
use crate::passes::common::splat::{self, Candidate, depth_key};
use crate::passes::gffe::history::{is_confirmed, is_dynamic};

/// Most background levels.
pub const MAX_LEVELS: u32 = 4;

/// One background fragment (WGSL `BgTexel`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Texel {
    /// Position (or direction) relative to the current camera centre.
    pub pos: [f32; 4],
    /// Linear RGB; alpha 1 = valid, 0 = empty (so a cleared buffer is empty).
    pub color: [f32; 4],
}

impl Texel {
    /// Whether the slot holds a fragment.
    pub fn is_valid(&self) -> bool {
        self.color[3] > 0.5
    }
}

/// The previous frame's background as the current frame sees it.
#[derive(Clone, Copy, Debug)]
pub struct PrevBackground<'a> {
    /// `C_{t−1}` relative to the current camera centre.
    pub camera: PassCamera,
    /// Its levels.
    pub levels: Levels,
    /// Its texels.
    pub texels: &'a [Texel],
}

/// CPU reference of step 1: level 0 from the confirmed static fragments;
/// the other levels empty. Into `reuse` when it has the right size (every
/// texel is written).
pub fn init(reuse: Vec<Texel>, from: Seeds<'_>, levels: Levels) -> Vec<Texel> {
    use rayon::prelude::*;
    let Seeds { p0, track, color } = from;
    let mut bg = reuse;
    if bg.len() != levels.total() as usize {
        bg = crate::par::filled(Texel::default(), levels.total() as usize);
    }
    if levels.count == 0 {
        return bg;
    }
    let (level0, coarser) = bg.split_at_mut(levels.len(0) as usize);
    level0.par_iter_mut().enumerate().for_each(|(x, slot)| {
        *slot = if seeds(track[x]) {
            let c = color[x];
            Texel {
                pos: p0[x],
                color: [c[0], c[1], c[2], 1.0],
            }
        } else {
            Texel::default()
        };
    });
    coarser
        .par_iter_mut()
        .with_min_len(4096)
        .for_each(|t| *t = Texel::default());
    bg
}

/// Whether a pixel of the rendered frame (its track word) enters level 0
/// of its own slot (step 1): confirmed static. It has a position: the
/// history confirms only pixels with a valid depth (`history.rs`), so its
/// `P_0` is never read to check (a frame-sized plane saved where the CPU
/// executor's background projection asks).
///
/// Such a fragment is exactly the pixel the forward warp moves: eq. 1 keeps
/// a static pixel at `P_0`, so both project to the same target pixel, which
/// the warp has therefore written. Background projection fills only holes,
/// and a level-0 slot is one pixel, so these fragments never fill anything
/// there, and the CPU executor skips them.
pub fn seeds(track: u32) -> bool {
    !is_dynamic(track) && is_confirmed(track)
}

/// The candidate of a previous fragment `t` of level `l` (cases 1 and 2):
/// `here` is level `l` of the current pyramid, `next` level `l + 1` where
/// there is one.
#[inline]
pub fn candidate(
    t: &Texel,
    shift: Vec3,
    camera: &PassCamera,
    bg: &[Texel],
    here: Grid,
    next: Option<Grid>,
    tolerance: f32,
) -> Candidate {
    if !t.is_valid() {
        return Candidate::MISS;
    }
    let Some(r) = camera.project(rebase(t.pos, shift)) else {
        return Candidate::MISS;
    };
    let Some(slot) = here.slot(r.pixel) else {
        return Candidate::MISS;
    };
    let held = bg[slot as usize];
    if !held.is_valid() {
        return Candidate {
            slot,
            key: depth_key(r.depth),
        };
    }
    if let Some(next) = next
        && r.depth > camera.depth_of(held.pos) * (1.0 + tolerance)
        && let Some(slot) = next.slot(r.pixel)
    {
        return Candidate {
            slot,
            key: depth_key(r.depth),
        };
    }
    Candidate::MISS
}

/// What the rendered frame seeds level 0 with (step 1).
#[derive(Clone, Copy, Debug)]
pub struct Seeds<'a> {
    /// The frame's `P_0` plane.
    pub p0: &'a [[f32; 4]],
    /// Its track words.
    pub track: &'a [u32],
    /// Its colour.
    pub color: &'a [[f32; 4]],
}

/// CPU reference of the whole collection for one rendered frame, into
/// `reuse` where its size fits (a background no longer needed; every texel
/// is written). `camera` is `C_t` (centre at the origin).
pub fn collect(
    reuse: Vec<Texel>,
    camera: &PassCamera,
    from: Seeds<'_>,
    levels: Levels,
    prev: Option<PrevBackground<'_>>,
    tolerance: f32,
) -> Vec<Texel> {
    let mut bg = init(reuse, from, levels);
    let Some(prev) = prev.filter(|p| p.levels.count == levels.count) else {
        return bg;
    };
    use rayon::prelude::*;
    let shift = Vec3::from_slice(&prev.camera.eye[..3]);
    for l in 0..levels.count {
        let start = prev.levels.offset(l) as usize;
        let source = &prev.texels[start..start + prev.levels.len(l) as usize];
        // Level l's candidates land in level l or l + 1.
        let (begin, end) = (levels.offset(l), levels.offset((l + 2).min(levels.count)));
        let (here, next) = (
            levels.grid(l),
            (l + 1 < levels.count).then(|| levels.grid(l + 1)),
        );
        let winners = splat::resolve_with(source.len(), begin as usize..end as usize, |i| {
            candidate(&source[i], shift, camera, &bg, here, next, tolerance)
        });
        bg[begin as usize..end as usize]
            .par_iter_mut()
            .zip(begin..end)
            .for_each(|(texel, s)| {
                if let Some(i) = winners.winner(s as usize) {
                    let t = source[i];
                    *texel = Texel {
                        pos: rebase(t.pos, shift),
                        color: t.color,
                    };
                }
            });
    }
    bg
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    camera: PassCamera,
    /// previous camera centre (xyz), tolerance
    shift: [f32; 4],
    /// n (init), level l, L, 0
    config: [u32; 4],
    /// offset, width, height of level l; end of the resolve range
    level: [u32; 4],
    /// offset, width, height of level l+1; 1 if it exists
    next: [u32; 4],
    /// previous offset and length of level l
    prev: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuBackground {
    init: Kernel,
    project: Kernel,
    resolve: Kernel,
}

impl GpuBackground {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("background.wgsl");
        Self {
            init: Kernel::new(
                ctx,
                src,
                "bg_init",
                &[Uniform, Read, Read, Read, Skip, ReadWrite],
            ),
            project: Kernel::new(
                ctx,
                src,
                "bg_project",
                &[
                    Uniform, Skip, Skip, Skip, Read, ReadWrite, Skip, Skip, ReadWrite,
                ],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "bg_resolve",
                &[Uniform, Skip, Skip, Skip, Read, ReadWrite, Read, Read],
            ),
        }
    }

    /// Records the collection. `bg` receives the new buffer (`levels`);
    /// `keys`, `winners` and `candidates` are scratch of at least
    /// `levels.total()` / previous level-0 length elements.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        splat: &splat::GpuSplat,
        camera: &PassCamera,
        positions: &wgpu::Buffer,
        track: &wgpu::Buffer,
        color: &wgpu::Buffer,
        levels: Levels,
        prev: Option<(&PassCamera, Levels, &wgpu::Buffer)>,
        bg: &wgpu::Buffer,
        scratch: (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer),
        tolerance: f32,
    ) {
        let total = u64::from(levels.total());
        encoder.clear_buffer(bg, 0, Some(total * std::mem::size_of::<Texel>() as u64));
        if levels.count == 0 {
            return;
        }
        let n = levels.len(0);
        let params = |l: u32, shift: [f32; 3], prev_levels: Option<Levels>| {
            let (w, h) = levels.size(l);
            let (w1, h1) = levels.size(l + 1);
            let end = levels.offset((l + 2).min(levels.count));
            ctx.uniform(bytemuck::bytes_of(&Params {
                camera: *camera,
                shift: [shift[0], shift[1], shift[2], tolerance],
                config: [n, l, levels.count, 0],
                level: [levels.offset(l), w, h, end],
                next: [
                    levels.offset(l + 1),
                    w1,
                    h1,
                    u32::from(l + 1 < levels.count),
                ],
                prev: prev_levels
                    .map(|p| [p.offset(l), p.len(l), 0, 0])
                    .unwrap_or_default(),
            }))
        };
        let p = params(0, [0.0; 3], None);
        self.init.dispatch(
            ctx,
            encoder,
            &[&p, positions, track, color, bg],
            u64::from(n),
        );
        let Some((prev_cam, prev_levels, prev_bg)) = prev.filter(|p| p.1.count == levels.count)
        else {
            return;
        };
        let (keys, winners, candidates) = scratch;
        let shift = [prev_cam.eye[0], prev_cam.eye[1], prev_cam.eye[2]];
        for l in 0..levels.count {
            let p = params(l, shift, Some(prev_levels));
            let count = u64::from(prev_levels.len(l));
            self.project
                .dispatch(ctx, encoder, &[&p, prev_bg, bg, candidates], count);
            splat.encode(ctx, encoder, candidates, count, keys, winners, total);
            let start = levels.offset(l);
            let end = levels.offset((l + 2).min(levels.count));
            self.resolve.dispatch(
                ctx,
                encoder,
                &[&p, prev_bg, bg, keys, winners],
                u64::from(end - start),
            );
        }
    }
}
