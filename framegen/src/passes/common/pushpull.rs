//! Push-pull fill of the holes nothing else covered (DESIGN §4 step 7; the
//! pyramid of GeoMotionGen, seed 003): warp cracks, disocclusions the
//! background never saw, and borders the adaptive window did not cover.
//!
//! * **level 0** is the output itself: every written pixel counts with
//!   weight 1, holes with weight 0. A texel carries color, *inverse* depth
//!   (so sky, `+inf`, is 0 and averages stay finite) and the motion vector.
//! * **pull**: level `k + 1` is the weight-normalised mean of its (up to)
//!   four children, with weight `min(1, Σw)`; level 1 reads the output.
//! * **push**: from the coarsest level down to level 1, a texel of weight
//!   `w < 1` becomes `w·own + (1 − w)·parent`, the parent sampled
//!   bilinearly with each tap weighted by its own weight (empty texels do
//!   not count).
//! * **resolve** is level 0's push: a hole (weight 0) takes its parent's
//!   value outright and is flagged [`FILLED`]; with no parent weight (the
//!   whole frame empty) it becomes black sky.
//!
//! Level 0 is never copied into the pyramid (that would be a frame-sized
//! buffer written once and read twice): the pyramid stores levels 1 and up
//! ([`stored`]), written pixels keep their values, and holes are resolved
//! straight from level 1. This is exactly the full-pyramid scheme: with
//! weight 0 a push yields the parent's value, with weight 1 the pixel stays.
//!
//! The CPU reference makes only the texels that the holes read where that
//! costs little (`fill_near`, within a budget of texel reads; the same
//! operations on the same texels, so the same values) and builds the whole
//! pyramid otherwise, as the kernels do: cracks, slivers along the border
//! and small disocclusions, most frames' only holes, then cost a few
//! thousand texels instead of passes over the frame (issue 15).

use glam::{Vec2, Vec4};

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{EMPTY, FILLED, Output};
use crate::passes::common::levels::Levels;

/// A pyramid texel (WGSL `PpTexel`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Texel {
    /// RGB and weight.
    pub a: [f32; 4],
    /// Inverse depth, motion x, motion y, 0.
    pub b: [f32; 4],
}

/// The pyramid layout for an output of `width × height` and at most
/// `levels` levels (at least 1).
pub fn layout(width: u32, height: u32, levels: u32) -> Levels {
    Levels::new(
        levels.clamp(1, Levels::full_depth(width, height)),
        width,
        height,
    )
}

/// The stored part of the pyramid of `layout`: where level 1 starts in the
/// layout's indexing, and how many texels levels 1 and up hold (level 0 is
/// the output itself).
pub fn stored(layout: Levels) -> (u32, u32) {
    let base = if layout.count > 1 {
        layout.offset(1)
    } else {
        layout.total()
    };
    (base, layout.total() - base)
}

/// Level 0's texel of pixel `t`: the pixel with weight 1 where it was
/// written, empty (weight 0) in a hole.
fn init_texel(out: &Output, t: usize) -> Texel {
    if out.mask[t] == EMPTY {
        Texel::default()
    } else {
        let c = out.color[t];
        let m = out.motion[t];
        Texel {
            a: [c[0], c[1], c[2], 1.0],
            b: [1.0 / out.depth[t], m[0], m[1], 0.0],
        }
    }
}

/// CPU reference of `pp_pull` from level `k` to `k + 1` (`k = 0`: from the
/// output). `pyramid` holds the stored levels ([`stored`]).
pub fn pull(out: &Output, pyramid: &mut [Texel], levels: Levels, k: u32) {
    let (base, _) = stored(levels);
    let d_o = (levels.offset(k + 1) - base) as usize;
    let (below, above) = pyramid.split_at_mut(d_o);
    let dst = &mut above[..levels.len(k + 1) as usize];
    if k == 0 {
        pull_level(dst, levels, k, |t| init_texel(out, t));
    } else {
        let src = &below[(levels.offset(k) - base) as usize..];
        pull_level(dst, levels, k, |i| src[i]);
    }
}

/// Level `k + 1` (`dst`) from level `k`, whose texel `i` is `child(i)`.
fn pull_level(dst: &mut [Texel], levels: Levels, k: u32, child: impl Fn(usize) -> Texel + Sync) {
    use rayon::prelude::*;
    let ((dw, _), size) = (levels.size(k + 1), levels.size(k));
    dst.par_chunks_mut(dw as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in (0u32..).zip(row.iter_mut()) {
                *texel = pull_texel(size, (x, y as u32), &child);
            }
        });
}

/// Texel `(x, y)` of the level above one of `size` whose texel `i` is
/// `child(i)`: the weight-normalised mean of its (up to) four children.
#[inline]
fn pull_texel(size: (u32, u32), (x, y): (u32, u32), child: impl Fn(usize) -> Texel) -> Texel {
    let mut sum_w = 0.0f32;
    let mut sa = Vec4::ZERO;
    let mut sb = Vec4::ZERO;
    for c in children(size, (x, y)).into_iter().flatten() {
        let c = child(c);
        let w = c.a[3];
        sum_w += w;
        sa += Vec4::from_array(c.a) * w;
        sb += Vec4::from_array(c.b) * w;
    }
    if sum_w > 0.0 {
        let a = sa / sum_w;
        Texel {
            a: [a.x, a.y, a.z, sum_w.min(1.0)],
            b: (sb / sum_w).to_array(),
        }
    } else {
        Texel::default()
    }
}

/// The children of texel `(x, y)` in the level below, of `(w, h)`, row by
/// row (`None` past its edge).
#[inline]
fn children((w, h): (u32, u32), (x, y): (u32, u32)) -> [Option<usize>; 4] {
    let child = |dx: u32, dy: u32| {
        let (cx, cy) = (2 * x + dx, 2 * y + dy);
        (cx < w && cy < h).then_some((cy * w + cx) as usize)
    };
    [child(0, 0), child(1, 0), child(0, 1), child(1, 1)]
}

/// Weighted bilinear sample of one level (its texel `i` is `level(i)`, its
/// size) at the level's continuous position `p`: each tap counts with its
/// bilinear weight times its own weight, so empty texels do not drag the
/// value toward zero; the returned weight is the bilinear blend of the
/// taps' weights.
#[inline]
fn sample(level: impl Fn(usize) -> Texel, size: (u32, u32), p: Vec2) -> (Vec4, Vec4) {
    let (index, f) = sample_taps(size, p);
    let at = |j: usize| {
        let t = level(index[j]);
        (Vec4::from_array(t.a), Vec4::from_array(t.b))
    };
    let taps = [
        ((1.0 - f.x) * (1.0 - f.y), at(0)),
        (f.x * (1.0 - f.y), at(1)),
        ((1.0 - f.x) * f.y, at(2)),
        (f.x * f.y, at(3)),
    ];
    let (mut sw, mut sa, mut sb) = (0.0f32, Vec4::ZERO, Vec4::ZERO);
    for (bw, (a, b)) in taps {
        let wt = bw * a.w;
        sw += wt;
        sa += a * wt;
        sb += b * wt;
    }
    if sw > 0.0 {
        let a = sa / sw;
        (Vec4::new(a.x, a.y, a.z, sw), sb / sw)
    } else {
        (Vec4::ZERO, Vec4::ZERO)
    }
}

/// The texels [`sample`] reads at `p` of a level of `(w, h)`: its 2×2
/// taps (clamped into the level; top-left, top-right, bottom-left,
/// bottom-right), and `p`'s fraction past the first.
#[inline]
fn sample_taps((w, h): (u32, u32), p: Vec2) -> ([usize; 4], Vec2) {
    let q = p - 0.5;
    let base = q.floor();
    let at = |x: f32, y: f32| {
        let xi = (x.max(0.0) as u32).min(w - 1);
        let yi = (y.max(0.0) as u32).min(h - 1);
        (yi * w + xi) as usize
    };
    let index = [
        at(base.x, base.y),
        at(base.x + 1.0, base.y),
        at(base.x, base.y + 1.0),
        at(base.x + 1.0, base.y + 1.0),
    ];
    (index, q - base)
}

/// CPU reference of `pp_push` from level `k + 1` into level `k ≥ 1`.
pub fn push(pyramid: &mut [Texel], levels: Levels, k: u32) {
    use rayon::prelude::*;
    let (base, _) = stored(levels);
    let (w, _) = levels.size(k);
    let o = (levels.offset(k) - base) as usize;
    let (below, above) = pyramid.split_at_mut((levels.offset(k + 1) - base) as usize);
    let coarse = &above[..levels.len(k + 1) as usize];
    let coarse_size = levels.size(k + 1);
    below[o..o + levels.len(k) as usize]
        .par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                if texel.a[3] >= 1.0 {
                    continue;
                }
                *texel = push_texel(*texel, parent(|i| coarse[i], coarse_size, x, y));
            }
        });
}

/// Texel `own` (weight below 1) pushed: blended with its parent value
/// `(pa, pb)` by its own weight.
#[inline]
fn push_texel(own: Texel, (pa, pb): (Vec4, Vec4)) -> Texel {
    let wgt = own.a[3];
    let oa = Vec4::from_array(own.a);
    let ob = Vec4::from_array(own.b);
    let a = oa * wgt + pa * (1.0 - wgt);
    let b = ob * wgt + pb * (1.0 - wgt);
    Texel {
        a: [a.x, a.y, a.z, wgt + (1.0 - wgt) * pa.w],
        b: b.to_array(),
    }
}

/// The parent value of texel `(x, y)` of a level: the next coarser level
/// (texel `i` is `coarse(i)`, of `size`) sampled at the texel's centre.
#[inline]
fn parent(coarse: impl Fn(usize) -> Texel, size: (u32, u32), x: usize, y: usize) -> (Vec4, Vec4) {
    sample(coarse, size, parent_at(x, y))
}

/// Where texel `(x, y)`'s parent value is sampled: the texel's centre, in
/// the next coarser level.
#[inline]
fn parent_at(x: usize, y: usize) -> Vec2 {
    Vec2::new(x as f32 + 0.5, y as f32 + 0.5) * 0.5
}

/// CPU reference of `pp_resolve`, level 0's push: every hole of `out` takes
/// its parent's value from level 1 (black sky without one).
pub fn resolve(pyramid: &[Texel], levels: Levels, out: &mut Output) {
    use rayon::prelude::*;
    let width = out.width as usize;
    let level1 = (levels.count > 1).then(|| (&pyramid[..levels.len(1) as usize], levels.size(1)));
    out.par_pixels_mut().for_each(|(t, px)| {
        if *px.mask != EMPTY {
            return;
        }
        (*px.color, *px.depth, *px.motion) = hole_value(match level1 {
            Some((coarse, size)) => parent(|i| coarse[i], size, t % width, t / width),
            None => (Vec4::ZERO, Vec4::ZERO),
        });
        *px.mask = FILLED;
    });
}

/// What a hole becomes from its parent value `(pa, pb)` (level 1 sampled
/// at it): colour, depth and motion, black sky without parent weight.
#[inline]
fn hole_value((pa, pb): (Vec4, Vec4)) -> ([f32; 4], f32, [f32; 2]) {
    let (color, inv_depth, motion) = if pa.w > 0.0 {
        (pa, pb.x, [pb.y, pb.z])
    } else {
        (Vec4::ZERO, 0.0, [0.0; 2])
    };
    let depth = if inv_depth > 0.0 {
        1.0 / inv_depth
    } else {
        f32::INFINITY
    };
    ([color.x, color.y, color.z, 1.0], depth, motion)
}

/// [`fill_near`] may read at most one texel (a pixel, or a texel it
/// made) for this many pixels of the frame: past that, the whole pyramid,
/// whose loops read each texel about once, is cheaper or near enough.
const NEAR_BUDGET: usize = 16;

/// What the CPU's push-pull keeps from frame to frame: for each level
/// from 1, the map of which texels [`fill_near`] made, all zero between
/// calls (each use zeroes what it set), so a few holes neither allocate
/// nor touch new pages.
#[derive(Debug, Default)]
pub struct Scratch {
    slots: Vec<Vec<u32>>,
}

impl Scratch {
    /// The maps of levels 1 and up of `layout`, grown where they are short.
    fn maps(&mut self, layout: Levels) -> impl Iterator<Item = &mut [u32]> {
        let count = layout.count.saturating_sub(1) as usize;
        if self.slots.len() < count {
            self.slots.resize_with(count, Vec::new);
        }
        (1..).zip(&mut self.slots).map(move |(k, map)| {
            let len = layout.len(k) as usize;
            if map.len() < len {
                map.resize(len, 0);
            }
            &mut map[..len]
        })
    }
}

/// The texels [`fill_near`] makes of one level: which, where each is in
/// that list (`slot[i]` is one more than texel `i`'s place, 0 where it is
/// not made; zeroed again when it is dropped) and the values made so far,
/// in the list's order.
struct Made<'a> {
    texels: Vec<usize>,
    slot: &'a mut [u32],
    values: Vec<Texel>,
}

impl<'a> Made<'a> {
    /// None made of a level whose map is `slot` (all zero).
    fn new(slot: &'a mut [u32]) -> Self {
        Self {
            texels: Vec::new(),
            slot,
            values: Vec::new(),
        }
    }

    /// Adds texel `i` to the list unless it is there: whether it was not.
    fn add(&mut self, i: usize) -> bool {
        let new = self.slot[i] == 0;
        if new {
            self.texels.push(i);
            self.slot[i] = self.texels.len() as u32;
        }
        new
    }

    /// Texel `i` of the level (default where it is not made: never read,
    /// as the plan makes every texel read first).
    fn get(&self, i: usize) -> Texel {
        self.place(i).map_or(Texel::default(), |p| self.values[p])
    }

    /// Texel `i`, made, becomes `t`.
    fn set(&mut self, i: usize, t: Texel) {
        if let Some(p) = self.place(i) {
            self.values[p] = t;
        }
    }

    /// Where texel `i` is in the list, if it is made.
    fn place(&self, i: usize) -> Option<usize> {
        (self.slot[i] as usize).checked_sub(1)
    }
}

impl Drop for Made<'_> {
    fn drop(&mut self) {
        for &i in &self.texels {
            self.slot[i] = 0;
        }
    }
}

/// What [`fill_near`] did, and how many texel reads it spent of its
/// budget (four for each texel it made).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Near {
    /// Every hole filled.
    Filled(usize),
    /// The texels of the next level would have taken it past the budget
    /// (or there is no level 1): nothing written, the whole pyramid
    /// serves.
    GaveUp(usize),
}

/// Fills the holes of `out` from the texels they read, each made once
/// with the pyramid's own operations (so the same values), instead of
/// pulling the whole frame for a few thousand holes.
///
/// A texel's weight is 0 or 1 at every level (level 0's are, and a pull
/// caps the sum of its children's at 1), so a push changes only empty
/// texels, and only those read the next level: cracks and slivers read a
/// level or a few, a texel or a few each. Level by level, the parents of
/// the holes (then of the level's empty texels) are made, with the
/// children they are pulled from that are not made yet, down to level 1.
///
/// It gives up, `out` untouched, before that would take it past `budget`
/// texel reads (large holes read deep texels, each pulled from many;
/// many holes, many texels), or where there is no level 1. Giving up
/// costs at most the budget and its planning (a read per texel planned).
/// `holes` are every hole of `out`, in order.
fn fill_near(
    out: &mut Output,
    holes: Vec<usize>,
    layout: Levels,
    budget: usize,
    scratch: &mut Scratch,
) -> Near {
    use rayon::prelude::*;
    if layout.count < 2 {
        return Near::GaveUp(0);
    }
    // made[k − 1]: what is made of level k; empty[k]: the texels of level
    // k that read level k + 1 (the holes, then empty texels made).
    let mut made: Vec<Made> = Vec::new();
    let mut empty = vec![holes];
    let mut spent = 0usize;
    for (k, map) in (1..layout.count).zip(scratch.maps(layout)) {
        made.push(Made::new(map));
        let Some(planned) = plan(&mut made, layout, &empty[k as usize - 1], budget - spent) else {
            return Near::GaveUp(spent);
        };
        spent += planned;
        make(&mut made, layout, out);
        // The taps just made that are empty read level k + 1 (the last
        // level is not pushed).
        let taps = &made[k as usize - 1];
        let next: Vec<usize> = (taps.texels.iter().copied())
            .filter(|&i| taps.get(i).a[3] < 1.0)
            .collect();
        if next.is_empty() || k + 1 == layout.count {
            break;
        }
        empty.push(next);
    }
    // The pushes, coarsest first, of the empty texels that are read: each
    // blended with its parent value from the level above, pushed before.
    for k in (1..empty.len()).rev() {
        let (below, above) = made.split_at_mut(k);
        let (level, parents) = (&mut below[k - 1], &above[0]);
        let (size, width) = (layout.size(k as u32 + 1), layout.size(k as u32).0 as usize);
        let parent = |i: usize| parent(|j| parents.get(j), size, i % width, i / width);
        let pushed: Vec<Texel> = empty[k]
            .par_iter()
            .map(|&i| push_texel(level.get(i), parent(i)))
            .collect();
        for (&i, t) in empty[k].iter().zip(pushed) {
            level.set(i, t);
        }
    }
    // The holes from level 1: read first, then written, as the pyramid is
    // built before the resolve.
    let (level1, holes) = (&made[0], &empty[0]);
    let (size, width) = (layout.size(1), out.width as usize);
    let fills: Vec<_> = holes
        .par_iter()
        .map(|&t| hole_value(parent(|j| level1.get(j), size, t % width, t / width)))
        .collect();
    for (&t, (color, depth, motion)) in holes.iter().zip(fills) {
        out.color[t] = color;
        out.depth[t] = depth;
        out.motion[t] = motion;
        out.mask[t] = FILLED;
    }
    Near::Filled(spent)
}

/// Plans level `k` = `made.len()` for [`fill_near`], top down: the parents
/// of level `k − 1`'s texels `empty`, then the children not made yet of
/// each level's new texels, down to level 1. Each new texel is charged its
/// four reads as it is planned: the reads planned, or `None` past `left`.
fn plan(made: &mut [Made], layout: Levels, empty: &[usize], left: usize) -> Option<usize> {
    let k = made.len() as u32;
    let mut planned = 0usize;
    let mut charge = |new: bool| {
        planned += 4 * usize::from(new);
        planned <= left
    };
    let (size, width) = (layout.size(k), layout.size(k - 1).0 as usize);
    for &t in empty {
        for i in sample_taps(size, parent_at(t % width, t / width)).0 {
            charge(made[k as usize - 1].add(i)).then_some(())?;
        }
    }
    for j in (2..=k as usize).rev() {
        let (below, above) = made.split_at_mut(j - 1);
        let (lower, upper) = (&mut below[j - 2], &above[0]);
        let ((w, _), lower_size) = (layout.size(j as u32), layout.size(j as u32 - 1));
        for &i in &upper.texels[upper.values.len()..] {
            let at = (i as u32 % w, i as u32 / w);
            for c in children(lower_size, at).into_iter().flatten() {
                charge(lower.add(c)).then_some(())?;
            }
        }
    }
    Some(planned)
}

/// Makes what [`plan`] added to `made`, bottom up: each level's new
/// texels pulled from the level below (the output itself below level 1).
fn make(made: &mut [Made], layout: Levels, out: &Output) {
    use rayon::prelude::*;
    for j in 1..=made.len() {
        let (below, above) = made.split_at_mut(j - 1);
        let level = &mut above[0];
        let ((w, _), lower_size) = (layout.size(j as u32), layout.size(j as u32 - 1));
        let pull = |i: usize| {
            let at = (i as u32 % w, i as u32 / w);
            match below.last() {
                None => pull_texel(lower_size, at, |c| init_texel(out, c)),
                Some(lower) => pull_texel(lower_size, at, |c| lower.get(c)),
            }
        };
        let new = &level.texels[level.values.len()..];
        let values: Vec<Texel> = new.par_iter().map(|&i| pull(i)).collect();
        level.values.extend(values);
    }
}

/// The whole CPU reference: fills every hole of `out`. A frame without
/// holes is left as it is, without building the pyramid (the resolve
/// writes only holes); one with few, small holes makes only the texels
/// they read (`fill_near`), with `scratch` kept from frame to frame.
pub fn fill(out: &mut Output, levels: u32, scratch: &mut Scratch) {
    fill_listed(out, levels, scratch, None);
}

/// [`fill`] where `holes`, if given, lists every hole of `out` in order
/// (the executor kept them from the warp's resolve), instead of a scan
/// for them.
pub fn fill_listed(
    out: &mut Output,
    levels: u32,
    scratch: &mut Scratch,
    holes: Option<Vec<usize>>,
) {
    let count = match &holes {
        Some(list) => list.len(),
        None => out.count(EMPTY),
    };
    if count == 0 {
        return;
    }
    let layout = layout(out.width, out.height, levels);
    let budget = out.mask.len() / NEAR_BUDGET;
    // Holes cost the near fill a read each at least (a texel of level 1 is
    // read by at most 16 holes, and reads four pixels): more than a
    // quarter of its budget go to the pyramid at once, without a list.
    let few = count <= budget / 4;
    let near = |out: &mut Output| {
        let holes = holes.unwrap_or_else(|| out.holes());
        fill_near(out, holes, layout, budget, scratch)
    };
    if !(few && matches!(near(out), Near::Filled(_))) {
        pyramid(out, layout);
    }
}

/// [`fill`] through the whole pyramid of `levels`, as the kernels fill
/// (the same result: what `fill` is measured against).
pub fn fill_pyramid(out: &mut Output, levels: u32) {
    pyramid(out, layout(out.width, out.height, levels));
}

/// [`fill_pyramid`] of `layout`.
fn pyramid(out: &mut Output, layout: Levels) {
    // Every stored texel is written by `pull` before anything reads it.
    let mut pyramid = crate::par::filled(Texel::default(), stored(layout).1 as usize);
    for k in 0..layout.count - 1 {
        pull(out, &mut pyramid, layout, k);
    }
    for k in (1..layout.count - 1).rev() {
        push(&mut pyramid, layout, k);
    }
    resolve(&pyramid, layout, out);
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// Level the kernel writes: offset, width, height, 0.
    dst: [u32; 4],
    /// Level it reads: offset, width, height, 0.
    src: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuHoles {
    pull: Kernel,
    push: Kernel,
    resolve: Kernel,
}

impl GpuHoles {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("pushpull.wgsl");
        let b = &[
            Params, ReadWrite, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
        ];
        Self {
            pull: Kernel::new(ctx, src, "pp_pull", b),
            push: Kernel::new(ctx, src, "pp_push", b),
            resolve: Kernel::new(ctx, src, "pp_resolve", b),
        }
    }

    /// Bytes of the pyramid buffer for `layout`: its stored levels
    /// ([`stored`]), at least one texel (wgpu binds no empty buffer).
    pub fn pyramid_bytes(layout: Levels) -> u64 {
        u64::from(stored(layout).1.max(1)) * std::mem::size_of::<Texel>() as u64
    }

    /// Records the whole push-pull over `out` with `layout` (see
    /// [`layout`]); `pyramid` holds at least [`GpuHoles::pyramid_bytes`].
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        out: crate::output::GpuOutput<'_>,
        pyramid: &wgpu::Buffer,
        layout: Levels,
    ) {
        let (base, _) = stored(layout);
        // Offset in the pyramid buffer, width, height, and 1 for level 0
        // (the output itself); a missing level is all zeros.
        let level = |k: u32| {
            if k == 0 {
                let (w, h) = layout.size(0);
                [0, w, h, 1]
            } else if k < layout.count {
                let (w, h) = layout.size(k);
                [layout.offset(k) - base, w, h, 0]
            } else {
                [0; 4]
            }
        };
        let run = |kernel: &Kernel, encoder: &mut wgpu::CommandEncoder, dst: u32, src: u32| {
            let params = ctx.params(bytemuck::bytes_of(&Params {
                dst: level(dst),
                src: level(src),
            }));
            kernel.dispatch(
                ctx,
                encoder,
                &[&params, out.color, out.depth, out.motion, out.mask, pyramid],
                u64::from(layout.len(dst)),
            );
        };
        for k in 0..layout.count - 1 {
            run(&self.pull, encoder, k + 1, k);
        }
        for k in (1..layout.count - 1).rev() {
            run(&self.push, encoder, k, k + 1);
        }
        run(&self.resolve, encoder, 0, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::WARPED;

    /// A written frame of `w × h` (colour, depth and motion varying per
    /// pixel, some sky) with holes where `hole(x, y)`.
    fn frame(w: u32, h: u32, hole: impl Fn(u32, u32) -> bool) -> Output {
        let mut out = Output::empty(w, h);
        for t in 0..(w * h) as usize {
            let (x, y) = (t as u32 % w, t as u32 / w);
            if !hole(x, y) {
                let v = (t as f32 * 0.618_034).fract();
                out.color[t] = [v, 1.0 - v, v * 3.0, 1.0];
                out.depth[t] = if t % 11 == 0 {
                    f32::INFINITY
                } else {
                    1.0 + 9.0 * v
                };
                out.motion[t] = [x as f32 * 0.1 - v, y as f32 * -0.2];
                out.mask[t] = WARPED;
            }
        }
        out
    }

    /// Every bit of the frame: colour, depth, motion, mask.
    fn bits(o: &Output) -> Vec<u32> {
        let color = o.color.iter().flatten().map(|v| v.to_bits());
        let depth = o.depth.iter().map(|v| v.to_bits());
        let motion = o.motion.iter().flatten().map(|v| v.to_bits());
        color
            .chain(depth)
            .chain(motion)
            .chain(o.mask.iter().copied())
            .collect()
    }

    /// Holes filled from the texels they read become what the whole
    /// pyramid makes of them, bit for bit, on frames of odd and even sizes:
    /// scattered pixels, one-pixel cracks across and down, holes on every
    /// edge and corner (level 1 alone), strips two and three pixels wide
    /// along an edge and across part of the frame, a block of 6×6 (empty
    /// level-1 texels, so level 2 too), and one of 24×24 (levels 3 to 5).
    /// `fill`, which makes them near within its budget or builds the
    /// pyramid, too.
    #[test]
    fn holes_filled_where_they_read_are_the_whole_pyramids() {
        // One scratch for every case, near or given up, as from frame to
        // frame.
        let mut scratch = Scratch::default();
        let mut taken = [0; 7];
        for (w, h) in [(37, 23), (64, 36), (9, 6), (160, 120)] {
            let scattered = |x: u32, y: u32| (x * 7 + y * 13) % 20 == 0;
            let cracks = |x: u32, y: u32| x == w / 2 || (y == h / 3 && x % 5 != 0);
            let edges = |x: u32, y: u32| {
                (x == 0 && y % 2 == 0) || (y + 1 == h && x % 2 == 1) || (x + 1 == w && y % 3 == 0)
            };
            let border = |x: u32, _: u32| x < 2;
            let band = |x: u32, y: u32| (3..6).contains(&y) && x > 0 && x < w / 3;
            let block = |x: u32, y: u32| (w / 4..w / 4 + 6).contains(&x) && (1..7).contains(&y);
            let large = |x: u32, y: u32| (w / 5..w / 5 + 24).contains(&x) && (5..29).contains(&y);
            let patterns: [&dyn Fn(u32, u32) -> bool; 7] =
                [&scattered, &cracks, &edges, &border, &band, &block, &large];
            for (p, hole) in patterns.into_iter().enumerate() {
                let out = frame(w, h, hole);
                let holes = out.count(EMPTY);
                assert!(holes > 0, "{w}×{h} pattern {p}");
                for levels in [1, 2, 3, 7] {
                    let layout = layout(w, h, levels);
                    let mut slow = out.clone();
                    fill_pyramid(&mut slow, levels);
                    let case = format!("{w}×{h} pattern {p} levels {levels}");
                    assert_eq!(slow.count(EMPTY), 0, "{case}");
                    assert_eq!(slow.count(FILLED), holes, "{case}");
                    let mut fast = out.clone();
                    fill(&mut fast, levels, &mut scratch);
                    assert_eq!(bits(&fast), bits(&slow), "{case}");
                    // With the holes listed by the caller: the same.
                    let mut listed = out.clone();
                    fill_listed(&mut listed, levels, &mut scratch, Some(out.holes()));
                    assert_eq!(bits(&listed), bits(&slow), "{case}");
                    // Near without a budget: wherever there is a level 1.
                    let mut near = out.clone();
                    let holes = near.holes();
                    let filled = fill_near(&mut near, holes, layout, usize::MAX, &mut scratch);
                    let went = matches!(filled, Near::Filled(_));
                    assert_eq!(went, levels > 1, "{case}");
                    let expected = if went { &slow } else { &out };
                    assert_eq!(bits(&near), bits(expected), "{case}");
                    taken[p] += usize::from(went);
                }
            }
        }
        assert_eq!(taken, [12; 7]);
        // Every map was zeroed again after use.
        assert!(scratch.slots.iter().flatten().all(|&s| s == 0));
    }

    /// The budget bounds what making texels near can cost before it gives
    /// up: at 720p, 800 blocks of 8×8 holes 32 pixels apart (51 200 holes,
    /// under the share) would read about 2 000 pixels each through levels
    /// 1 to 4, the whole frame's worth; it gives up within one pixel read
    /// in [`NEAR_BUDGET`], `out` untouched. A sliver along the left edge
    /// and a few cracks, the holes of a typical frame, are filled near,
    /// within it, as the whole pyramid fills them.
    #[test]
    fn the_budget_bounds_the_near_fill() {
        let (w, h) = (1280, 720);
        let budget = (w * h) as usize / NEAR_BUDGET;
        let layout = layout(w, h, 7);
        let mut scratch = Scratch::default();
        let blocks = |x: u32, y: u32| x % 32 < 8 && y % 32 < 8 && y < 32 * 5;
        let out = frame(w, h, blocks);
        assert_eq!(out.count(EMPTY), 200 * 64);
        let mut near = out.clone();
        match fill_near(&mut near, out.holes(), layout, budget, &mut scratch) {
            Near::GaveUp(spent) => assert!(spent <= budget, "{spent} > {budget}"),
            filled => panic!("{filled:?}"),
        }
        assert_eq!(bits(&near), bits(&out));
        // Without a budget it would have read four times as much.
        match fill_near(
            &mut near.clone(),
            out.holes(),
            layout,
            usize::MAX,
            &mut scratch,
        ) {
            Near::Filled(spent) => assert!(spent > 4 * budget, "{spent}"),
            gave_up => panic!("{gave_up:?}"),
        }

        let sliver = |x: u32, y: u32| x < 4 || (x == 600 && y % 7 != 0) || (y == 300 && x % 3 == 0);
        let out = frame(w, h, sliver);
        let (mut near, mut slow) = (out.clone(), out.clone());
        match fill_near(&mut near, out.holes(), layout, budget, &mut scratch) {
            Near::Filled(spent) => assert!(spent <= budget / 2, "{spent} of {budget}"),
            gave_up => panic!("{gave_up:?}"),
        }
        fill_pyramid(&mut slow, 7);
        assert_eq!(bits(&near), bits(&slow));
    }
}
