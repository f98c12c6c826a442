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
//!    Level 0's fragments are mostly the previous frame's seeds, and most
//!    of those the current frame sees again: a confirmed pixel of it
//!    landed in the seed's pixel as deep (`history.rs`, [`SeenAgain`]).
//!    Such a seed is not reprojected, unless a pixel of the current frame
//!    that is not confirmed landed in it too. Reprojected, it would land
//!    on the current seed that saw it or next to it, as deep, and be
//!    dropped, or on the pixel that is not confirmed (an object in front
//!    now, a slanted surface whose confirmation failed) and be carried
//!    over there: that case is why the second condition exists. What
//!    still differs from reprojecting every seed is a seed landing a slot
//!    aside onto a nearer seed (case 2 at an edge): under 1 % of the
//!    fragments carried over on `fast_rotation`. On the default scene at
//!    720p 97 % of the seeds are skipped, and the CPU pass takes 4.9 ms
//!    instead of 9.3 (quality and times: README, "Seeds seen again").
//!
//! Choices made here: a fragment keeps its exact position (camera-relative,
//! rebased each frame) instead of being re-derived from its slot's centre,
//! so repeated reprojection does not drift; a slot's "depth" for case 2 is
//! the view depth of the position it holds; sky directions take part like
//! any fragment (they are the deepest layer and move only with rotation).
//! A change of `L` or of the frame size drops the previous buffer.

use glam::{Vec2, Vec3, Vec4};
use half::f16;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::{PassCamera, rebase};
use crate::passes::common::lanes::{LANES, Lanes3, cells4, project4};
use crate::passes::common::levels::{Grid, Levels};
use crate::passes::common::splat::{self, Candidate, depth_key};
use crate::passes::gffe::history::{GpuHistoryBuffers, SeenAgain, is_seed};

/// The GPU collection's scratch: keys, winners and candidates.
type GpuScratch<'a> = (&'a wgpu::Buffer, &'a wgpu::Buffer, &'a wgpu::Buffer);

/// Most background levels.
pub const MAX_LEVELS: u32 = 4;

/// One background fragment (WGSL `BgTexel`), 24 bytes.
///
/// Its colour is the rendered frame's own `f16` (`input::Prepared`), copied
/// bit for bit: the passes' `f32` colour is that `f16` widened, exactly, so
/// nothing is lost, and a texel is 24 bytes instead of 32. Every frame
/// writes a frame's worth of them (level 0) and the next reads them all
/// back (720p: 8 MB less each way).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Texel {
    /// Position (or direction) relative to the current camera centre.
    pub pos: [f32; 4],
    /// Linear RGB; alpha 1 = valid, 0 = empty (so a cleared buffer is empty).
    pub color: [f16; 4],
}

impl Texel {
    /// Whether the slot holds a fragment (WGSL `bg_valid`: its alpha's
    /// bits are not 0).
    pub fn is_valid(&self) -> bool {
        self.color[3].to_bits() != 0
    }

    /// Its colour as the passes take it: the `f16` widened (exact), alpha 1.
    pub fn rgb1(&self) -> [f32; 4] {
        let [r, g, b, _] = self.color;
        [r.to_f32(), g.to_f32(), b.to_f32(), 1.0]
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
    /// Where `texels` does not hold level 0's seeds (an [`Unseeded`]
    /// buffer): the previous frame's, which are read where they are.
    pub seeds: Option<Seeds<'a>>,
    /// The seeds of its level 0 that the current frame saw again (the
    /// current history's [`SeenAgain`]), which are not reprojected;
    /// `None`: none.
    pub seen: Option<&'a SeenAgain>,
}

/// A background as the CPU executor keeps it: level 0's seeds are not
/// stored. They are the frame's own confirmed static pixels, its `P_0`
/// and colour ([`Seeds`]), which the next frame's collection reads where
/// they are (its [`PrevBackground::seeds`]) and which background fill
/// never needs (see [`seeds`]). Every other texel is empty except those
/// listed in `carried`. A frame's worth of 24-byte texels is not written
/// per rendered frame (720p: 22 MB); the next frame reads the seeds'
/// positions and track words where they are (20 bytes a pixel instead of
/// 24), their colour only for the few that land. [`seeded`] makes the
/// whole buffer where it is asked for.
#[derive(Clone, Debug, Default)]
pub struct Unseeded {
    /// The texels; level 0's seeds left empty.
    pub texels: Vec<Texel>,
    /// The slots that hold a fragment, ascending: every fragment carried
    /// over from the previous background, the only ones background fill
    /// can fill a hole with.
    pub carried: Vec<u32>,
}

/// `texels`, an [`Unseeded`] background's, with level 0's seeds `from`
/// (those it was collected with) written in: the whole buffer, as the GPU
/// keeps it.
pub fn seeded(mut texels: Vec<Texel>, from: Seeds<'_>) -> Vec<Texel> {
    use rayon::prelude::*;
    let n = from.track.len().min(texels.len());
    texels[..n]
        .par_iter_mut()
        .enumerate()
        .with_min_len(16 * 1024)
        .for_each(|(x, t)| {
            if let Some(seed) = from.texel(x) {
                *t = seed;
            }
        });
    texels
}

/// `reuse` emptied for a background of `levels`: only the slots it lists
/// are written where it has the right size (the others are empty
/// already), every slot otherwise.
fn emptied(reuse: Unseeded, levels: Levels) -> Unseeded {
    let Unseeded {
        mut texels,
        mut carried,
    } = reuse;
    let total = levels.total() as usize;
    if texels.len() != total || carried.len() > total / 16 {
        texels = all_empty(texels, total);
    } else {
        for &s in &carried {
            texels[s as usize] = Texel::default();
        }
    }
    carried.clear();
    Unseeded { texels, carried }
}

/// `total` empty texels, into `reuse` where it has that size.
fn all_empty(reuse: Vec<Texel>, total: usize) -> Vec<Texel> {
    use rayon::prelude::*;
    let mut texels = reuse;
    if texels.len() != total {
        return crate::par::filled(Texel::default(), total);
    }
    texels
        .par_iter_mut()
        .with_min_len(16 * 1024)
        .for_each(|t| *t = Texel::default());
    texels
}

/// What a slot of the current buffer holds, as [`judge`] asks it: nothing,
/// or a fragment at a view depth. While the previous level 0's fragments
/// are judged, level 0 holds the seeds, read where they are: 20 bytes a
/// landing (`P_0` and the track word), and no plane of them made first.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Held(f32);

impl Held {
    /// An empty slot: a signalling NaN, which [`Held::at`] never stores
    /// (it stores every NaN depth as the quiet `f32::NAN`; [`judge`] takes
    /// all NaNs alike).
    const EMPTY: u32 = 0x7F80_0001;

    /// Nothing held.
    const NOTHING: Self = Self(f32::from_bits(Self::EMPTY));

    /// A fragment at `pos`, its depth in `camera`.
    #[inline]
    fn at(pos: [f32; 4], camera: &PassCamera) -> Self {
        let depth = camera.depth_of(pos);
        Self(if depth.is_nan() { f32::NAN } else { depth })
    }

    /// What `texel` holds, its depth in `camera`.
    #[inline]
    fn of(texel: &Texel, camera: &PassCamera) -> Self {
        match texel.is_valid() {
            true => Self::at(texel.pos, camera),
            false => Self::NOTHING,
        }
    }

    /// The depth of the fragment held, or `None` where there is none.
    #[inline]
    fn depth(self) -> Option<f32> {
        (self.0.to_bits() != Self::EMPTY).then_some(self.0)
    }
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
    is_seed(track)
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
    let current = Current::Texels(bg, camera);
    let pos = t.is_valid().then_some(t.pos);
    candidate_in(pos, shift, camera, current, (here, next), tolerance)
}

/// [`candidate`] of a fragment at `pos` (`None`: no fragment) judged
/// against `current`.
#[inline]
fn candidate_in(
    pos: Option<[f32; 4]>,
    shift: Vec3,
    camera: &PassCamera,
    current: Current<'_>,
    (here, next): (Grid, Option<Grid>),
    tolerance: f32,
) -> Candidate {
    let Some(pos) = pos else {
        return Candidate::MISS;
    };
    let Some(r) = camera.project(rebase(pos, shift)) else {
        return Candidate::MISS;
    };
    let Some(slot) = here.slot(r.pixel) else {
        return Candidate::MISS;
    };
    let to = Landing {
        slot,
        pixel: r.pixel,
        depth: r.depth,
    };
    judge(to, current.held(slot), next, tolerance)
}

/// Where a valid fragment's projection lands on its own level.
#[derive(Clone, Copy, Debug)]
struct Landing {
    slot: u32,
    pixel: Vec2,
    depth: f32,
}

/// [`candidate`] after the fragment's projection: case 1, case 2 or none,
/// by what the current buffer holds where it lands (`held`).
#[inline]
fn judge(
    Landing { slot, pixel, depth }: Landing,
    held: Held,
    next: Option<Grid>,
    tolerance: f32,
) -> Candidate {
    let Some(held) = held.depth() else {
        let key = depth_key(depth);
        return Candidate { slot, key };
    };
    if let Some(next) = next
        && depth > held * (1.0 + tolerance)
        && let Some(slot) = next.slot(pixel)
    {
        let key = depth_key(depth);
        return Candidate { slot, key };
    }
    Candidate::MISS
}

/// [`candidate`] of four fragments `t`, their projections made in lanes
/// (`lanes.rs`: the same bits), what they land on judged one by one.
#[inline]
pub fn candidates4(
    t: &[Texel; LANES],
    shift: Vec3,
    camera: &PassCamera,
    bg: &[Texel],
    grids: (Grid, Option<Grid>),
    tolerance: f32,
) -> [Candidate; LANES] {
    let held = Current::Texels(bg, camera);
    let pos = t.map(|t| t.is_valid().then_some(t.pos));
    candidates4_in(pos, shift, camera, held, grids, tolerance)
}

/// The current buffer as one level's fragments are judged against it.
#[derive(Clone, Copy, Debug)]
enum Current<'a> {
    /// Its texels, seen by a camera.
    Texels(&'a [Texel], &'a PassCamera),
    /// Level 0 while its previous fragments are judged: the seeds (step
    /// 1), read where they are, seen by a camera.
    Seeds(Seeds<'a>, &'a PassCamera),
}

impl Current<'_> {
    /// What slot `slot` holds.
    #[inline]
    fn held(self, slot: u32) -> Held {
        match self {
            Current::Texels(bg, camera) => Held::of(&bg[slot as usize], camera),
            Current::Seeds(seeds, camera) => match seeds.position(slot as usize) {
                Some(pos) => Held::at(pos, camera),
                None => Held::NOTHING,
            },
        }
    }
}

/// [`candidates4`] of fragments at `pos` (`None`: no fragment) judged
/// against `current`.
#[inline]
fn candidates4_in(
    pos: [Option<[f32; 4]>; LANES],
    shift: Vec3,
    camera: &PassCamera,
    current: Current<'_>,
    (here, next): (Grid, Option<Grid>),
    tolerance: f32,
) -> [Candidate; LANES] {
    if pos.iter().all(Option::is_none) {
        return [Candidate::MISS; LANES];
    }
    // A lane without a fragment projects the origin, and is not judged.
    let (p, w) = Lanes3::from_positions(&pos.map(Option::unwrap_or_default));
    // `rebase`: a point moves with the origin.
    let point = w.cmpgt(Vec4::splat(0.5));
    let shifted = p + Lanes3::splat([shift.x, shift.y, shift.z, 0.0]);
    let r = project4(camera, Lanes3::select(point, shifted, p), w);
    let cells = cells4(&r, here.width, here.height, here.scale);
    std::array::from_fn(|l| match cells[l] {
        Some(cell) if pos[l].is_some() => {
            let to = Landing {
                slot: here.offset + cell,
                pixel: r.pixel(l),
                depth: r.depth[l],
            };
            judge(to, current.held(to.slot), next, tolerance)
        }
        _ => Candidate::MISS,
    })
}

/// What [`collect`] writes besides the texels, and where it splats.
#[derive(Debug)]
pub struct Work<'a> {
    /// The slots of the fragments carried over (see [`collect`]).
    pub carried: &'a mut Vec<u32>,
    /// The splat's slots, kept from frame to frame.
    pub slots: &'a mut splat::Sparse,
}

/// What the rendered frame seeds level 0 with (step 1).
#[derive(Clone, Copy, Debug)]
pub struct Seeds<'a> {
    /// The frame's `P_0` plane.
    pub p0: &'a [[f32; 4]],
    /// Its track words.
    pub track: &'a [u32],
    /// Its colour, as the frame's own `f16` (`input::Prepared`).
    pub color: &'a [[f16; 4]],
}

impl Seeds<'_> {
    /// The position of slot `x`'s seed, if it has one.
    #[inline]
    fn position(&self, x: usize) -> Option<[f32; 4]> {
        let track = *self.track.get(x)?;
        seeds(track).then(|| self.p0.get(x).copied()).flatten()
    }

    /// Slot `x`'s seed, if it has one: its `P_0` and its colour, alpha 1.
    #[inline]
    fn texel(&self, x: usize) -> Option<Texel> {
        let pos = self.position(x)?;
        let [r, g, b, _] = *self.color.get(x)?;
        Some(Texel {
            pos,
            color: [r, g, b, f16::ONE],
        })
    }
}

/// One level of the previous background, as its fragments are read.
#[derive(Clone, Copy, Debug)]
struct Fragments<'a> {
    texels: &'a [Texel],
    /// Level 0's seeds where `texels` does not hold them.
    seeds: Option<Seeds<'a>>,
    /// Level 0's seeds seen again, which are not reprojected.
    seen: Option<&'a SeenAgain>,
}

impl Fragments<'_> {
    /// Fragment `i`.
    #[inline]
    fn get(&self, i: usize) -> Texel {
        match self.seeds.and_then(|s| s.texel(i)) {
            Some(seed) => seed,
            None => self.texels[i],
        }
    }

    /// Whether fragment `i` is a seed seen again (not reprojected).
    #[inline]
    fn seen_again(&self, i: usize) -> bool {
        self.seen.is_some_and(|s| s.skips(i))
    }

    /// Where fragment `i` is, if there is one to reproject (its colour not
    /// read).
    #[inline]
    fn position(&self, i: usize) -> Option<[f32; 4]> {
        if self.seen_again(i) {
            return None;
        }
        if let Some(pos) = self.seeds.and_then(|s| s.position(i)) {
            return Some(pos);
        }
        self.stored(i)
    }

    /// Where the fragment stored in texel `i` is, if there is one.
    #[inline]
    fn stored(&self, i: usize) -> Option<[f32; 4]> {
        let t = self.texels.get(i)?;
        t.is_valid().then_some(t.pos)
    }

    /// [`Fragments::position`] of fragments `i .. i + LANES` (`None` past
    /// the end), read as runs: seeds' positions and track words where the
    /// previous frame's seeds stand in for texels (most of level 0),
    /// texels elsewhere. Most of level 0 is four seeds seen again: one
    /// load.
    #[inline]
    fn positions4(&self, i: usize) -> [Option<[f32; 4]>; LANES] {
        if self.seen.is_some_and(|s| s.skips4(i)) {
            return [None; LANES];
        }
        let Some(s) = self.seeds else {
            return std::array::from_fn(|k| self.position(i + k));
        };
        let track = s.track.get(i..).and_then(|t| t.first_chunk::<LANES>());
        match (track, s.p0.get(i..).and_then(|p| p.first_chunk::<LANES>())) {
            (Some(track), Some(p0)) => std::array::from_fn(|k| match seeds(track[k]) {
                _ if self.seen_again(i + k) => None,
                true => Some(p0[k]),
                false => self.stored(i + k),
            }),
            _ => std::array::from_fn(|k| self.position(i + k)),
        }
    }
}

/// CPU reference of the whole collection for one rendered frame, into
/// `reuse` where its size fits (a background no longer needed; every texel
/// is written). `camera` is `C_t` (centre at the origin).
///
/// Also lists in `work.carried` (cleared first) the slots of the
/// fragments it carried over from the previous background, ascending:
/// every valid texel that is not a seed of this frame, the only ones
/// background fill can fill a hole with (`background::seeds`). At 720p a
/// few thousand of 1.2 M slots, which the CPU executor's background fill
/// then projects instead of reading every texel. Its splats take
/// `work.slots` ([`splat::Sparse`]: few of the previous fragments land).
///
/// [`collect_unseeded`] with every texel emptied first and the seeds
/// written in after ([`seeded`]).
pub fn collect(
    reuse: Vec<Texel>,
    camera: &PassCamera,
    from: Seeds<'_>,
    levels: Levels,
    prev: Option<PrevBackground<'_>>,
    tolerance: f32,
    work: Work<'_>,
) -> Vec<Texel> {
    let Work { carried, slots } = work;
    carried.clear();
    let empty = Unseeded {
        texels: all_empty(reuse, levels.total() as usize),
        carried: std::mem::take(carried),
    };
    let bg = collect_unseeded(empty, camera, from, levels, prev, tolerance, slots);
    *carried = bg.carried;
    seeded(bg.texels, from)
}

/// The collection as the CPU executor runs it, into a background whose
/// level 0's seeds are not stored ([`Unseeded`]): [`collect`]'s buffer
/// without them, and its list of fragments carried over. `reuse` is a
/// background no longer needed, [`Unseeded`] too: only the texels it
/// lists are emptied.
pub fn collect_unseeded(
    reuse: Unseeded,
    camera: &PassCamera,
    from: Seeds<'_>,
    levels: Levels,
    prev: Option<PrevBackground<'_>>,
    tolerance: f32,
    slots: &mut splat::Sparse,
) -> Unseeded {
    let Unseeded {
        texels: mut bg,
        mut carried,
    } = emptied(reuse, levels);
    let prev = prev.filter(|p| p.levels.count == levels.count);
    let Some(prev) = prev.filter(|_| levels.count > 0) else {
        return Unseeded {
            texels: bg,
            carried,
        };
    };
    // Step 1 stores nothing: level 0 holds the seeds where they are
    // (`Current::Seeds`).
    use rayon::prelude::*;
    let shift = Vec3::from_slice(&prev.camera.eye[..3]);
    for l in 0..levels.count {
        let start = prev.levels.offset(l) as usize;
        let source = Fragments {
            texels: &prev.texels[start..start + prev.levels.len(l) as usize],
            seeds: prev.seeds.filter(|_| l == 0),
            seen: prev.seen.filter(|_| l == 0),
        };
        // Level l's candidates land in level l or l + 1.
        let (begin, end) = (levels.offset(l), levels.offset((l + 2).min(levels.count)));
        let (here, next) = (
            levels.grid(l),
            (l + 1 < levels.count).then(|| levels.grid(l + 1)),
        );
        let current = match l {
            0 => Current::Seeds(from, camera),
            _ => Current::Texels(&bg, camera),
        };
        let grids = (here, next);
        // Few land (most previous fragments meet the same surface again):
        // the sparse splat.
        let range = begin as usize..end as usize;
        let won = slots.resolve(source.texels.len(), range.clone(), |i| {
            candidates4_in(
                source.positions4(i),
                shift,
                camera,
                current,
                grids,
                tolerance,
            )
        });
        // Each won slot from its fragment, by blocks of slots (`won` is
        // ascending).
        const BLOCK: usize = 16 * 1024;
        (bg[range].par_chunks_mut(BLOCK).enumerate()).for_each(|(b, block)| {
            let first = begin as usize + b * BLOCK;
            let from = |s: usize| won.partition_point(|&(w, _)| (w as usize) < s);
            for &(s, i) in &won[from(first)..from(first + block.len())] {
                let t = source.get(i as usize);
                block[s as usize - first] = Texel {
                    pos: rebase(t.pos, shift),
                    color: t.color,
                };
            }
        });
        carried.extend(won.iter().map(|&(s, _)| s));
    }
    // A slot of level l + 1 written again by level l + 1's own step is
    // listed twice.
    carried.sort_unstable();
    carried.dedup();
    Unseeded {
        texels: bg,
        carried,
    }
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
                &[Params, Read, Read, Read, Skip, ReadWrite],
            ),
            project: Kernel::new(
                ctx,
                src,
                "bg_project",
                &[
                    Params, Skip, Skip, Skip, Read, ReadWrite, Skip, Skip, ReadWrite, Read,
                ],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "bg_resolve",
                &[Params, Skip, Skip, Skip, Read, ReadWrite, Read, Read],
            ),
        }
    }

    /// Records the collection for the current frame: its camera, its
    /// history (the seeds' positions and track words) and its colour as
    /// uploaded (four `f16` a pixel), with `levels` and the depth
    /// `tolerance`. `bg` receives the new buffer, splatted with `splat`
    /// over `scratch` (`keys`, `winners` and `candidates`, of at least
    /// `levels.total()` / previous level-0 length elements). `prev` is the
    /// previous background's camera, levels and texels, with the history's
    /// [`SeenAgain`] flags of its level 0 (`u32`s, written by
    /// `GpuHistory::encode`).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (camera, seeds, color): (&PassCamera, GpuHistoryBuffers<'_>, &wgpu::Buffer),
        (levels, tolerance): (Levels, f32),
        prev: Option<(&PassCamera, Levels, &wgpu::Buffer, &wgpu::Buffer)>,
        (bg, splat, scratch): (&wgpu::Buffer, &splat::GpuSplat, GpuScratch<'_>),
    ) {
        let (positions, track) = (seeds.positions, seeds.track);
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
            ctx.params(bytemuck::bytes_of(&Params {
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
        let Some((prev_cam, prev_levels, prev_bg, seen)) =
            prev.filter(|p| p.1.count == levels.count)
        else {
            return;
        };
        let (keys, winners, candidates) = scratch;
        let shift = [prev_cam.eye[0], prev_cam.eye[1], prev_cam.eye[2]];
        for l in 0..levels.count {
            let p = params(l, shift, Some(prev_levels));
            let count = u64::from(prev_levels.len(l));
            self.project
                .dispatch(ctx, encoder, &[&p, prev_bg, bg, candidates, seen], count);
            splat.encode(ctx, encoder, (candidates, count), (keys, winners, total));
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Four fragments at a time are judged as one by one, and against
    /// level 0's seeds (read where they are) as against its texels: over
    /// fragments that are points, skies, nothing or NaN, landing on and
    /// off the image, on empty slots, on the same surface, behind it, and
    /// on slots whose fragment has no depth (NaN).
    #[test]
    fn four_lanes_are_the_fragments_one_by_one() {
        let eye = [0.0, 1.0, 3.0];
        let camera = crate::testutil::looking(eye, [0.5, 0.0, -4.0], (64, 36), eye);
        let levels = Levels::new(2, 64, 36);
        let noise = |i: usize| (i as f32 * 0.618_034).fract();
        // The current buffer: level 0 mostly held, at depths 4 to 6.
        let bg: Vec<Texel> = (0..levels.total() as usize)
            .map(|s| {
                let pixel = Vec2::new((s % 64) as f32 + 0.5, (s / 64 % 36) as f32 + 0.5);
                let held = noise(s * 3) < 0.7;
                let mut pos = camera.unproject(pixel, 4.0 + 2.0 * noise(s * 5));
                match s % 17 {
                    0 => pos[3] = -1.0,
                    1 => pos[2] = f32::NAN,
                    _ => {}
                }
                Texel {
                    pos,
                    color: [
                        f16::ONE,
                        f16::ONE,
                        f16::ONE,
                        if held { f16::ONE } else { f16::ZERO },
                    ],
                }
            })
            .collect();
        // Level 0 as seeds: a fragment's position and a seed's track word
        // where it holds one (`history::is_confirmed`, static).
        let n = levels.len(0) as usize;
        let p0: Vec<[f32; 4]> = bg[..n].iter().map(|t| t.pos).collect();
        let track: Vec<u32> = bg[..n]
            .iter()
            .map(|t| 2 * u32::from(t.is_valid()))
            .collect();
        let color = vec![[f16::ONE; 4]; n];
        let level0 = Seeds {
            p0: &p0,
            track: &track,
            color: &color,
        };
        let shift = Vec3::new(0.02, -0.01, 0.03);
        let source: Vec<Texel> = (0..4000)
            .map(|i| {
                let pixel = Vec2::new(noise(i) * 80.0 - 8.0, noise(i + 7919) * 44.0 - 4.0);
                let depth = match i % 9 {
                    0 => f32::INFINITY,
                    1 => -1.0,
                    _ => 3.0 + 5.0 * noise(i * 11),
                };
                let mut pos = camera.unproject(pixel, depth);
                pos = [pos[0] - shift.x, pos[1] - shift.y, pos[2] - shift.z, pos[3]];
                match i % 23 {
                    0 => pos[3] = -1.0,
                    1 => pos[1] = f32::NAN,
                    _ => {}
                }
                let valid = i % 13 != 0;
                Texel {
                    pos,
                    color: [f16::from_f32(0.5); 4].map(|c| if valid { c } else { f16::ZERO }),
                }
            })
            .collect();
        let (here, next) = (levels.grid(0), Some(levels.grid(1)));
        let mut outcomes = [0usize; 3];
        for four in source.chunks_exact(LANES) {
            let four: &[Texel; LANES] = four.try_into().unwrap();
            let lanes = candidates4(four, shift, &camera, &bg, (here, next), 0.02);
            let held = Current::Seeds(level0, &camera);
            let pos = four.map(|t| t.is_valid().then_some(t.pos));
            let planes = candidates4_in(pos, shift, &camera, held, (here, next), 0.02);
            for ((t, c), p) in four.iter().zip(lanes).zip(planes) {
                assert_eq!(c, candidate(t, shift, &camera, &bg, here, next, 0.02));
                assert_eq!(p, c);
                let kind = match c.slot {
                    splat::NONE => 0,
                    s if s < levels.offset(1) => 1,
                    _ => 2,
                };
                outcomes[kind] += 1;
            }
        }
        // Misses, case 1 and case 2 were all met often.
        assert!(outcomes.iter().all(|&n| n > 200), "{outcomes:?}");
    }

    /// What level 0 holds, read from the seeds, is what its texels hold
    /// once seeded, as the current camera sees them: none where a slot is empty (a NaN position
    /// included), a NaN where a held fragment has no depth, never read as
    /// empty. Its seeds' colours are the frame's, exactly, alpha 1.
    #[test]
    fn held_depths_are_what_level_0_holds() {
        let eye = [0.0, 1.0, 3.0];
        let camera = crate::testutil::looking(eye, [0.5, 0.0, -4.0], (16, 9), eye);
        let levels = Levels::new(2, 16, 9);
        let n = 16 * 9;
        let p0: Vec<[f32; 4]> = (0..n)
            .map(|i| match i % 5 {
                0 => [f32::NAN, 0.0, -2.0, 1.0],
                1 => [0.0, 0.0, -1.0, 0.0],
                2 => [0.0, 0.0, -2.0, -1.0],
                _ => [0.1 * i as f32, 0.0, -3.0, 1.0],
            })
            .collect();
        // Seeded (static and confirmed) or not, by turns of three.
        let track: Vec<u32> = (0..n as u32)
            .map(|i| match i % 3 {
                0 => 0,
                _ => 2, // static, confirmed (`history::is_confirmed`)
            })
            .collect();
        // Colours as prepared frames hold them: subnormal, largest,
        // zero, ordinary; alpha anything (a seed's is 1).
        let color: Vec<[f16; 4]> = (0..n)
            .map(|i| {
                let c = [0.5, 0.25, 1.0, 0.0].map(f16::from_f32);
                match i % 4 {
                    0 => [
                        f16::from_bits(1),
                        f16::MIN_POSITIVE_SUBNORMAL,
                        f16::MAX,
                        c[3],
                    ],
                    1 => [f16::ZERO, f16::from_bits(0x03ff), c[1], f16::ONE],
                    _ => c,
                }
            })
            .collect();
        let widened = crate::passes::common::widen::widen(&color);
        let from = Seeds {
            p0: &p0,
            track: &track,
            color: &color,
        };
        let bg = seeded(emptied(Unseeded::default(), levels).texels, from);
        let held = Current::Seeds(from, &camera);
        let mut kinds = [0usize; 3];
        for (x, t) in bg[..n].iter().enumerate() {
            let h = held.held(x as u32);
            assert_eq!(t.is_valid(), seeds(track[x]));
            // A seed's colour, as the passes take it, is the frame's.
            if t.is_valid() {
                let [r, g, b, _] = widened[x];
                assert_eq!(t.rgb1().map(f32::to_bits), [r, g, b, 1.0].map(f32::to_bits));
            }
            let kind = match h.depth() {
                None => 0,
                Some(d) if d.is_nan() => 1,
                Some(d) => {
                    assert_eq!(d.to_bits(), camera.depth_of(t.pos).to_bits());
                    2
                }
            };
            assert_eq!(kind == 0, !t.is_valid(), "slot {x}");
            kinds[kind] += 1;
        }
        assert!(kinds.iter().all(|&k| k > 10), "{kinds:?}");
    }

    /// A previous seed the current frame saw again is not reprojected:
    /// collecting with the history's flags is collecting as if those
    /// seeds were not there, whether the previous level 0 is read from
    /// its seeds or from its texels, and the flags change what is carried
    /// over.
    #[test]
    fn seeds_seen_again_are_not_reprojected() {
        let (size, target) = ((64, 36), [0.5, 0.0, -4.0]);
        let (eye, before) = ([0.0, 1.0, 3.0], [0.1, 1.0, 3.05]);
        let camera = crate::testutil::looking(eye, target, size, eye);
        let levels = Levels::new(2, size.0, size.1);
        let n = levels.len(0) as usize;
        // The previous frame, relative to its own centre: a surface at
        // depths 4 to 6, seeds except every 13th pixel.
        let own = crate::testutil::looking(before, target, size, before);
        let p0: Vec<[f32; 4]> = (0..n)
            .map(|x| {
                let pixel = Vec2::new((x % 64) as f32 + 0.5, (x / 64) as f32 + 0.5);
                own.unproject(pixel, 4.0 + 2.0 * (x * 7 % 11) as f32 / 11.0)
            })
            .collect();
        let track: Vec<u32> = (0..n).map(|x| if x % 13 == 0 { 0 } else { 2 }).collect();
        let color = vec![[f16::ONE; 4]; n];
        // Every third seed seen again, and every one of the first rows
        // (whole groups of four); every seventh pixel unsure (so not
        // skipped, seen or not).
        let seen = |x: usize| (x % 3 == 0 || x < 64 * 12) && seeds(track[x]);
        let unsure = |x: usize| x % 7 == 0;
        let words: Vec<u32> = (0..n)
            .map(|x| u32::from(seen(x)) | u32::from(unsure(x)) << 1)
            .collect();
        let flags = SeenAgain::from_words(&words);
        let skipped = |x: usize| seen(x) && !unsure(x);
        assert_eq!((0..n).filter(|&x| flags.skips(x)).count(), flags.count());
        assert!((0..n).all(|x| flags.skips(x) == skipped(x)));
        let gone: Vec<u32> = (0..n)
            .map(|x| if skipped(x) { 0 } else { track[x] })
            .collect();
        // The current frame holds no seeds: every previous seed that lands
        // on the image is a candidate.
        let (none, no_color) = (vec![0u32; n], vec![[f16::ZERO; 4]; n]);
        let current = Seeds {
            p0: &p0,
            track: &none,
            color: &no_color,
        };
        let collect_with = |track: &[u32], seen: Option<&SeenAgain>, unseeded: bool| {
            let from = Seeds {
                p0: &p0,
                track,
                color: &color,
            };
            let empty = emptied(Unseeded::default(), levels).texels;
            let whole = seeded(empty.clone(), from);
            let prev = PrevBackground {
                camera: crate::testutil::looking(before, target, size, eye),
                levels,
                texels: if unseeded { &empty } else { &whole },
                seeds: unseeded.then_some(from),
                seen,
            };
            let mut slots = splat::Sparse::default();
            let reuse = Unseeded::default();
            let bg = collect_unseeded(
                reuse,
                &camera,
                current,
                levels,
                Some(prev),
                0.02,
                &mut slots,
            );
            (seeded(bg.texels, current), bg.carried)
        };
        let plain = collect_with(&track, None, true);
        for unseeded in [true, false] {
            let with = collect_with(&track, Some(&flags), unseeded);
            assert!(with == collect_with(&gone, None, unseeded), "{unseeded}");
            assert!(
                with.1.len() < plain.1.len() * 9 / 10,
                "{} of {}",
                with.1.len(),
                plain.1.len()
            );
        }
    }
}
