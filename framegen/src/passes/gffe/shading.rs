//! Shading correction (GFFE §4.4, DESIGN §4 step 8), hand-built: the
//! shading a geometry-aware warp leaves behind, moved on.
//!
//! Warping moves surfaces, not the light on them: a shadow or highlight
//! that slides over a static surface stays where frame `t` had it. GFFE
//! closes this with a small network (SCN) fed the geometry-aware result,
//! its depth, frame `t−1` warped to `t+α` and a mask, and blends its output
//! in by a predicted focus mask, `I = I_gae·(1−M) + I'·M` (eq. 4). This
//! stage keeps that contract with an estimator built by hand instead of a
//! learned one:
//!
//! 1. **What changed** (`shading_ratio`, at ingest). Frame `t−1` aligned to
//!    frame `t` by frame `t`'s own motion (the geometry the warp uses, so
//!    what differs is shading, not geometry): per static pixel the log
//!    ratio `r_t = ln((L_t + ε) / (L_{t−1} + ε))` of luminances, where
//!    `L_{t−1}` is the nearest end of the range the aligned position's
//!    bilinear footprint spans in frame `t−1` (its taps of weight ≥
//!    [`FOOTPRINT`] on the pixel's own surface, depths within
//!    `SAME_SURFACE_RATIO`), and `r = 0` inside it: what a sub-pixel shift
//!    of the texture could show is not shading (the spirit of eq. 3's
//!    neighbourhood minimum, at the resampling's own scale); a pixel on a
//!    centre compares with that one pixel exactly. Dynamic (and
//!    disoccluded: the static test fails there) pixels, points without a
//!    surface, positions outside frame `t−1` and footprints off the surface
//!    have `r = 0`. The previous frame's `r_{t−1}`, aligned the
//!    same way, is kept beside it.
//! 2. **How it moves** (`shading_flow`, at ingest). Per block of
//!    [`BLOCK`]² pixels whose change is large enough ([`MIN_ENERGY`]), the
//!    displacement `f` (within ±[`SEARCH`] px: every even one, then the
//!    pixel around the best) that best maps the previous change onto this
//!    one, `r_t(x) ≈ r_{t−1}(x − f)` (least absolute difference; ties to
//!    the shorter `f`): a moving shadow edge leaves a
//!    band of change that moves on by `f` every interval. A block whose
//!    change that does not explain ([`COHERENCE`]) is left alone: noise
//!    does not repeat itself, moving shading does (so the estimate needs
//!    two intervals of history).
//! 3. **Where it goes** (`shading_correct`, per generated frame). The
//!    change continues along `f`: over `α` intervals the pixel `x` gets
//!    `r̂ = Σ_k w_k · r_t(x − k·f)`, `w_k = min(1, α − (k−1))` (for α ≤ 1
//!    `α · r_t(x − f)`: exact at α = 1 for an edge moving at constant speed,
//!    the edge's mean over the interval in between). `f` comes from the
//!    block around `x` with the most change (its 3×3 blocks), so pixels
//!    the band is about to reach take its motion. A uniform change (a
//!    light dimming) has `f = 0` and continues in place.
//! 4. **Focus mask** `M = smoothstep(FOCUS_LOW, FOCUS_HIGH, |r̂|)`, zero on
//!    dynamic pixels: the correction `I' = I·e^{r̂}` is blended in only
//!    where a clear change is predicted, eq. 4; elsewhere the colour is the
//!    geometry-aware one bit for bit.
//!
//! **Departures from the seed.** The estimate runs on frame `t`'s grid
//! before the warp, and the corrected colour is what the warp then moves:
//! frame `t−1` aligned to `t` by `t`'s motion and then warped with `t`'s
//! geometry *is* frame `t−1` warped to `t+α` (GFFE's input), and working
//! before the warp resamples each image once. The estimate (steps 1–2)
//! runs once per rendered frame, shared by its generated frames; only
//! step 3–4 runs per generated frame. No network: no training data, no
//! weights; the estimator is the seed's "non-geometric motion" made
//! explicit as a moving band of luminance change. Colour is scaled by the
//! luminance ratio (hue kept).

use glam::{Vec2, Vec4};

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::cell;
use crate::passes::common::resample::{SAME_SURFACE_RATIO, floor, same_surface};
use crate::passes::gffe::history::is_dynamic;

/// Added to luminances before their ratio, so black against black is no
/// change and the ratio stays finite.
pub const LUMA_FLOOR: f32 = 1e-3;
/// Bilinear weight below which a tap of the aligned footprint does not
/// count: the nearest tap always counts (its weight is at least ¼), a
/// neighbour only where the position is at least as close to it as to
/// the 2×2 average; a position on a pixel centre has one tap. Lighter taps
/// (1/16, as first built) took a shadow edge that moved a pixel under a
/// moving camera for a sub-pixel shift of the texture and left it alone
/// (`eval --sweep methods --backends cpu --only gffe`, 320×180, gffe
/// against gffe without shading correction: `sun_sweep` −2 % → −6 %,
/// `spinning_shadow` −9 % → −13 %, `default` +0.0001 → +0.0003); heavier
/// ones (0.4) admit texture (`default` +0.0007, `huge` +0.0003).
pub const FOOTPRINT: f32 = 0.25;
/// Largest |log ratio| kept (e⁴ ≈ 55×).
pub const MAX_LOG_RATIO: f32 = 4.0;
/// Side of the blocks the shading flow is estimated for, pixels.
pub const BLOCK: u32 = 8;
/// Search radius of the shading flow, pixels per render interval.
pub const SEARCH: i32 = 8;
/// Σ|r| over a block below which it has no change worth tracking (e.g.
/// eight pixels whose luminance changed by a third).
pub const MIN_ENERGY: f32 = 2.0;
/// A block's change is tracked only when the previous change, moved by
/// the best displacement, explains it to within this share of its
/// magnitude (Σ|r_t − r_{t−1}(x − f)| ≤ this · Σ|r_t|).
pub const COHERENCE: f32 = 0.5;
/// The focus mask is 0 below this |predicted log change| (1 %, a few
/// [`QUANTUM`]s: what the coherence test let through is moving shading,
/// so the mask only has to keep quantisation noise out)...
pub const FOCUS_LOW: f32 = 0.01;
/// ...and 1 above this one. At 0.05 and 0.2, as first built, a shadow's
/// soft edge, which changes a pixel by a few percent per interval, was
/// left out: `moving_light` −25 % → −32 % and `sun_sweep` −6 % → −7 %
/// against gffe without shading correction (`eval --all-scenes --sweep
/// methods --backends cpu`, 320×180), every other scene within 0.0001,
/// with every stage run too.
pub const FOCUS_HIGH: f32 = 0.05;
/// Most render intervals a change is continued over (α beyond it is
/// clamped: a shadow is not extrapolated further than the warp's own
/// trajectories are trusted).
pub const MAX_STEPS: f32 = 4.0;

/// Luminance ratio within which a pixel matches its aligned pixel in
/// frame `t−1` (`1 + QUANTUM/4 < e^{QUANTUM/4}`: the log ratio, and with
/// it `r`'s, is under half a [`QUANTUM`] and rounds to 0).
const STILL: f32 = 1.0 + QUANTUM / 4.0;

/// Log ratios are kept in steps of this (0.4 % of luminance): the flow's
/// sums of them are then exact in `f32`, the same on every executor
/// whatever order or `ln` it has.
pub const QUANTUM: f32 = 1.0 / 256.0;

/// `v` rounded to the nearest [`QUANTUM`] (halves up, as WGSL's `floor`
/// gives it), for `|v|` within a few thousand.
#[inline]
pub fn quantize(v: f32) -> f32 {
    floor(v / QUANTUM + 0.5) as f32 * QUANTUM
}

/// Rec. 709 luminance of linear RGB, negatives as 0.
#[inline]
pub fn luminance(c: [f32; 4]) -> f32 {
    (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).max(0.0)
}

/// Blocks of a `w`×`h` frame: columns, rows.
pub fn blocks(w: u32, h: u32) -> (u32, u32) {
    (w.div_ceil(BLOCK), h.div_ceil(BLOCK))
}

/// Frame `t` as the estimate reads it.
#[derive(Clone, Copy, Debug)]
pub struct Current<'a> {
    /// Linear RGB.
    pub color: &'a [[f32; 4]],
    /// Sanitised depth (0 = no surface).
    pub depth: &'a [f32],
    /// Motion to frame `t−1`, pixels.
    pub motion: &'a [[f32; 2]],
    /// History track words (`is_dynamic`).
    pub track: &'a [u32],
    /// Width, height.
    pub size: (u32, u32),
    /// `color`'s red, green and blue, as planes of one channel where the
    /// executor keeps them (`resample_run::Planes`, the CPU executor's):
    /// the runs of [`ratio_into`] read the luminances from these (the same
    /// values; 5–9 % of its time at 720p, paired).
    pub planes: Option<[&'a [f32]; 3]>,
}

/// Frame `t−1` as the estimate reads it (same size).
#[derive(Clone, Copy, Debug)]
pub struct Previous<'a> {
    /// Linear RGB.
    pub color: &'a [[f32; 4]],
    /// Sanitised depth.
    pub depth: &'a [f32],
    /// Its own `(r, aligned r)` per pixel, or empty (no estimate then).
    pub ratio: &'a [[f32; 2]],
    /// Its luminances plus [`LUMA_FLOOR`] per pixel, as its own estimate
    /// wrote them, or empty (then computed from `color`).
    pub luma: &'a [f32],
}

/// Step 1 for pixel `(px, py)` whose luminance plus [`LUMA_FLOOR`] is
/// `lt`: `(r_t, r_{t−1} aligned)`.
#[inline]
pub fn ratio_at(px: u32, py: u32, lt: f32, cur: &Current<'_>, prev: &Previous<'_>) -> [f32; 2] {
    let (w, h) = cur.size;
    let x = (py * w + px) as usize;
    let d = cur.depth[x];
    if is_dynamic(cur.track[x]) || d.is_nan() || d <= 0.0 {
        return [0.0; 2];
    }
    let m = cur.motion[x];
    let p = Vec2::new(px as f32 + 0.5 + m[0], py as f32 + 0.5 + m[1]);
    // A position outside (or not a number) has no aligned pixel.
    let Some(near) = cell(p, w, h, 1.0) else {
        return [0.0; 2];
    };
    let near = near as usize;
    let aligned = prev.ratio.get(near).map_or(0.0, |r| r[0]);
    let luma_at = |s: usize| match prev.luma.get(s) {
        Some(&l) => l,
        None => luminance(prev.color[s]) + LUMA_FLOOR,
    };
    // The pixel the position falls in is always in the footprint (its
    // bilinear weight is at least ¼): when it is on the surface and within
    // [`STILL`] of `lt`, so is the range's nearest end, and `r` rounds to
    // 0 whatever the other taps hold. Most pixels of most frames, at a
    // quarter of the work.
    let l = luma_at(near);
    if same_surface(prev.depth[near], d) && lt <= l * STILL && l <= lt * STILL {
        return [0.0, aligned];
    }
    [footprint(p, d, lt, cur.size, prev), aligned]
}

/// [`ratio_at`]'s `r_t` where the pixel the aligned position `p` falls in
/// does not settle it: the nearest end of the range of the position's
/// bilinear footprint (on the surface of depth `d`) against `lt`. Out of
/// line: the common case above stays a short loop.
#[inline(never)]
fn footprint(p: Vec2, d: f32, lt: f32, size: (u32, u32), prev: &Previous<'_>) -> f32 {
    let luma_at = |s: usize| match prev.luma.get(s) {
        Some(&l) => l,
        None => luminance(prev.color[s]) + LUMA_FLOOR,
    };
    let (lo, hi) = footprint_range(p, d, size, prev.depth, luma_at);
    against_range(lt, lo, hi)
}

/// [`footprint`] where the previous frame's luminances are kept (`luma`,
/// beside its `depth`): a footprint inside the frame is taken in one
/// vector of its four taps, the same operations lane by lane (and the
/// range of luminances, which are never NaN, is the same in any order).
#[inline(never)]
fn footprint_kept(p: Vec2, d: f32, lt: f32, size: (u32, u32), depth: &[f32], luma: &[f32]) -> f32 {
    let (w, h) = (size.0 as i32, size.1 as i32);
    let (bx, by) = (floor(p.x - 0.5), floor(p.y - 0.5));
    let inside = bx >= 0 && by >= 0 && bx + 1 < w && by + 1 < h;
    let taps = |v: &[f32]| -> Option<Vec4> {
        let s = by as usize * w as usize + bx as usize;
        let (top, bottom) = (v.get(s..s + 2)?, v.get(s + w as usize..s + w as usize + 2)?);
        Some(Vec4::new(top[0], top[1], bottom[0], bottom[1]))
    };
    let found = if inside {
        taps(depth).zip(taps(luma))
    } else {
        None
    };
    let Some((depths, lumas)) = found else {
        let (lo, hi) = footprint_range(p, d, size, depth, |s| luma[s]);
        return against_range(lt, lo, hi);
    };
    let (tx, ty) = (p.x - 0.5 - bx as f32, p.y - 0.5 - by as f32);
    let weight = Vec4::new(
        (1.0 - tx) * (1.0 - ty),
        tx * (1.0 - ty),
        (1.0 - tx) * ty,
        tx * ty,
    );
    // `same_surface(depth, d)` lane by lane.
    let d = Vec4::splat(d);
    let nearer = depths.cmpge(d);
    let (near, far) = (
        Vec4::select(nearer, d, depths),
        Vec4::select(nearer, depths, d),
    );
    let surface = near.cmpgt(Vec4::ZERO) & far.cmple(near * SAME_SURFACE_RATIO);
    let keep = weight.cmpge(Vec4::splat(FOOTPRINT)) & surface;
    let lo = Vec4::select(keep, lumas, Vec4::INFINITY).min_element();
    let hi = Vec4::select(keep, lumas, Vec4::ZERO).max_element();
    against_range(lt, lo, hi)
}

/// The range of luminances (`luma_at`) of the taps of `p`'s bilinear
/// footprint that weigh at least [`FOOTPRINT`] and lie on the surface of
/// depth `d`: what a sub-pixel shift of the surface's texture could show
/// there. Empty (`lo > hi`) where none does.
#[inline(always)]
fn footprint_range(
    p: Vec2,
    d: f32,
    (w, h): (u32, u32),
    depth: &[f32],
    luma_at: impl Fn(usize) -> f32,
) -> (f32, f32) {
    let (bx, by) = (floor(p.x - 0.5), floor(p.y - 0.5));
    let (tx, ty) = (p.x - 0.5 - bx as f32, p.y - 0.5 - by as f32);
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for (dx, dy, weight) in [
        (0, 0, (1.0 - tx) * (1.0 - ty)),
        (1, 0, tx * (1.0 - ty)),
        (0, 1, (1.0 - tx) * ty),
        (1, 1, tx * ty),
    ] {
        let sx = (bx + dx).clamp(0, w as i32 - 1) as usize;
        let sy = (by + dy).clamp(0, h as i32 - 1) as usize;
        let s = sy * w as usize + sx;
        // Only taps of the pixel's own surface (not across a silhouette);
        // selects rather than branches (luminances are never NaN).
        let keep = (weight >= FOOTPRINT) & same_surface(depth[s], d);
        let l = luma_at(s);
        lo = if keep && l < lo { l } else { lo };
        hi = if keep && l > hi { l } else { hi };
    }
    (lo, hi)
}

/// The quantised log ratio of `lt` to the nearest end of the range `lo ..=
/// hi`: 0 inside it, or where it is empty (nothing to compare with).
#[inline(always)]
fn against_range(lt: f32, lo: f32, hi: f32) -> f32 {
    let best = if lo > hi {
        0.0
    } else if lt < lo {
        (lt / lo).ln()
    } else if lt > hi {
        (lt / hi).ln()
    } else {
        0.0
    };
    quantize(best.clamp(-MAX_LOG_RATIO, MAX_LOG_RATIO))
}

/// Step 1 for every pixel, on all cores, into `out`; frame `t`'s
/// luminances (plus [`LUMA_FLOOR`]) into `luma`, for the next frame's
/// estimate to read as its [`Previous::luma`].
///
/// [`ratio_at`]'s answers, bit for bit, in three sweeps over a short run
/// of a row ([`ratio_run`]) where the previous frame's luminances are
/// kept (every frame but the first after a restart): most of
/// `ratio_at`'s time was its branches, taken per pixel one way or the
/// other by data (a pixel without an aligned pixel; one whose footprint
/// has to be measured: 15 % of a 720p default-scene frame).
pub fn ratio_into(
    cur: &Current<'_>,
    prev: &Previous<'_>,
    out: &mut Vec<[f32; 2]>,
    luma: &mut Vec<f32>,
) {
    use rayon::prelude::*;
    let w = cur.size.0 as usize;
    let n = cur.track.len();
    out.resize(n, [0.0; 2]);
    luma.resize(n, 0.0);
    // The runs' cells are taken in 32-bit signed lanes (see `ratio_run`):
    // frames up to 2²⁴ a side (far beyond `protocol`'s default limits),
    // larger ones pixel by pixel.
    let small = cur.size.0 <= 1 << 24 && cur.size.1 <= 1 << 24;
    let runs = prev.luma.len() == n && prev.depth.len() == n && small;
    // By rows: no division per pixel for its coordinates.
    out.par_chunks_mut(w)
        .zip(luma.par_chunks_mut(w))
        .enumerate()
        .with_max_len(8)
        .for_each(|(py, (row, luma))| {
            if runs {
                for (k, (row, luma)) in row.chunks_mut(RUN).zip(luma.chunks_mut(RUN)).enumerate() {
                    ratio_run(((k * RUN) as u32, py as u32), row, luma, cur, prev);
                }
                return;
            }
            let colors = &cur.color[py * w..][..row.len()];
            for (px, ((r, l), c)) in row.iter_mut().zip(luma).zip(colors).enumerate() {
                *l = luminance(*c) + LUMA_FLOOR;
                *r = ratio_at(px as u32, py as u32, *l, cur, prev);
            }
        });
}

/// Pixels [`ratio_run`] takes at a time.
const RUN: usize = 64;

/// [`ratio_at`] for the run of pixels from `(x0, y)` (`row.len()` of
/// them, at most [`RUN`]), where `prev.luma` and `prev.depth` cover the
/// frame and the frame is at most 2²⁴ pixels a side. First, without
/// branches, each pixel's luminance and the pixel its aligned position
/// falls in (or none: dynamic, no surface, outside); then that pixel's
/// test, the pixels that fail it listed without branches; last, the
/// listed pixels' footprints. Each value is made by the same operations
/// as in `ratio_at`.
fn ratio_run(
    (x0, y): (u32, u32),
    row: &mut [[f32; 2]],
    luma: &mut [f32],
    cur: &Current<'_>,
    prev: &Previous<'_>,
) {
    const NONE: u32 = u32::MAX;
    let (w, h) = cur.size;
    let first = (y * w + x0) as usize;
    let len = row.len();
    let color = &cur.color[first..][..len];
    // The luminances from the colour planes where there are some: three
    // runs of one channel each, which the loop below takes in vectors.
    let planes = cur.planes.map(|p| p.map(|c| &c[first..][..len]));
    let depth = &cur.depth[first..][..len];
    let motion = &cur.motion[first..][..len];
    let track = &cur.track[first..][..len];
    let (wf, hf) = (w as f32, h as f32);
    let mut near = [NONE; RUN];
    for i in 0..len {
        luma[i] = match planes {
            Some([r, g, b]) => luminance([r[i], g[i], b[i], 1.0]),
            None => luminance(color[i]),
        } + LUMA_FLOOR;
        let (d, m) = (depth[i], motion[i]);
        let p = Vec2::new((x0 + i as u32) as f32 + 0.5 + m[0], y as f32 + 0.5 + m[1]);
        // `cell`'s test (at scale 1), `ratio_at`'s early return, as masks.
        let inside = (p.x >= 0.0) & (p.y >= 0.0) & (p.x < wf) & (p.y < hf);
        let keep = !is_dynamic(track[i]) & (d > 0.0) & inside;
        let q = if keep { p } else { Vec2::ZERO };
        // `cell_inside`'s index through `i32`s, which SSE2 converts four at
        // a time (to a `u32` it converts one by one: 5–8 % of this
        // function's time at 720p, paired). SAFETY: `q` is on the grid, a
        // position inside or the origin, and the grid is at most 2²⁴ a
        // side (`ratio_into`): its coordinates are numbers in `0 .. 2²⁴`.
        let (cx, cy) = unsafe { (q.x.to_int_unchecked::<i32>(), q.y.to_int_unchecked::<i32>()) };
        let s = cy as u32 * w + cx as u32;
        near[i] = if keep { s } else { NONE };
    }
    let mut listed = [0u8; RUN];
    let mut count = 0;
    for i in 0..len {
        let Some(s) = (near[i] != NONE).then_some(near[i] as usize) else {
            row[i] = [0.0; 2];
            continue;
        };
        let aligned = prev.ratio.get(s).map_or(0.0, |r| r[0]);
        let (l, lt) = (prev.luma[s], luma[i]);
        let still = same_surface(prev.depth[s], depth[i]) & (lt <= l * STILL) & (l <= lt * STILL);
        row[i] = [0.0, aligned];
        listed[count] = i as u8;
        count += usize::from(!still);
    }
    for &i in &listed[..count] {
        let i = i as usize;
        let m = motion[i];
        let p = Vec2::new((x0 + i as u32) as f32 + 0.5 + m[0], y as f32 + 0.5 + m[1]);
        row[i][0] = footprint_kept(p, depth[i], luma[i], cur.size, prev.depth, prev.luma);
    }
}

/// A ratio in [`QUANTUM`]s. Ratios are whole multiples of it within
/// ±[`MAX_LOG_RATIO`], so this is exact (the WGSL kernel's `fl_quanta`
/// does the same), and the integer search below finds what the kernel
/// finds, bit for bit.
#[inline]
fn quanta(v: f32) -> i32 {
    // By the cast `floor`, not `round` (a call on this target): the same
    // for whole multiples.
    floor(v / QUANTUM + 0.5)
}

/// Farthest a displacement reaches: the even search, then the pixel
/// around its best.
const REACH: i32 = SEARCH + 1;
/// Side of the window of `r_{t−1}` a block's search reads.
const SPAN: usize = (BLOCK as i32 + 2 * REACH) as usize;

/// The search's even displacements, shortest first and, among equally
/// long ones, in the kernel's row order (`dy`, then `dx`, ascending).
fn even_displacements() -> &'static [(i32, i32)] {
    static ORDER: std::sync::OnceLock<Vec<(i32, i32)>> = std::sync::OnceLock::new();
    ORDER.get_or_init(|| {
        let mut order: Vec<(i32, i32)> = (-SEARCH..=SEARCH)
            .step_by(2)
            .flat_map(|dy| (-SEARCH..=SEARCH).step_by(2).map(move |dx| (dx, dy)))
            .collect();
        // Stable: equals keep the row order.
        order.sort_by_key(|&(dx, dy)| dx * dx + dy * dy);
        order
    })
}

/// A whole block's cost at displacement `(dx, dy)` (see [`flow_block`]),
/// or `None` past `limit`: the differences summed column by column, in one
/// vector of lanes, and their total tested once. (Giving up after the row
/// that passes the limit, as the partial block does, cost more in tests
/// and horizontal sums than it saved: 720p flow 1.64 ms against 2.0.)
#[inline]
fn whole_cost(
    now: &[[i32; BLOCK as usize]; BLOCK as usize],
    before: &[[i32; SPAN]; SPAN],
    (dx, dy): (i32, i32),
    limit: i32,
) -> Option<i32> {
    let mut columns = [0i32; BLOCK as usize];
    for (y, row) in now.iter().enumerate() {
        let from = &before[(y as i32 + REACH - dy) as usize][(REACH - dx) as usize..];
        for ((sum, a), b) in columns.iter_mut().zip(row).zip(&from[..BLOCK as usize]) {
            *sum += (a - b).abs();
        }
    }
    let cost = columns.iter().sum();
    (cost <= limit).then_some(cost)
}

/// Step 2 for block `b`: `[f.x, f.y, energy, 0]` (energy 0: nothing to
/// track).
///
/// The block's `r_t` and the window of aligned `r_{t−1}` around it are
/// gathered once, in quanta (0 outside the frame); each displacement's
/// cost is then a sum over two small arrays ([`whole_cost`]; a block cut by
/// the frame's edge gives up as soon as its sum exceeds the best so far,
/// as it could only lose).
pub fn flow_block(b: usize, ratio: &[[f32; 2]], size: (u32, u32)) -> [f32; 4] {
    let (w, h) = size;
    let (bw, _) = blocks(w, h);
    let (x0, y0) = ((b as u32 % bw) * BLOCK, (b as u32 / bw) * BLOCK);
    let (cols, rows) = ((x0 + BLOCK).min(w) - x0, (y0 + BLOCK).min(h) - y0);
    let (cols, rows) = (cols as usize, rows as usize);
    // Most blocks have next to no change (at 720p, 92 % of the default
    // scene's). Rounding to quanta makes each |r| at most half a quantum
    // larger, so the energy is at most Σ|r| + 64 · ½ quantum; where that
    // (with 1 % to spare for the sum's own rounding) stays under
    // [`MIN_ENERGY`], the block is ruled out before any conversion: the
    // same answer for any values (NaN and overflow fail the test and take
    // the exact path). Column sums, kept in one register.
    let mut sums = [0.0f32; BLOCK as usize];
    for y in 0..rows {
        let at = (y0 as usize + y) * w as usize + x0 as usize;
        for (sum, r) in sums.iter_mut().zip(&ratio[at..at + cols]) {
            *sum += r[0].abs();
        }
    }
    let rounding = (BLOCK * BLOCK) as f32 * QUANTUM / 2.0;
    if sums.iter().sum::<f32>() + rounding < MIN_ENERGY * 0.99 {
        return [0.0; 4];
    }
    let mut now = [[0i32; BLOCK as usize]; BLOCK as usize];
    let mut energy = 0i32;
    for (y, row) in now.iter_mut().enumerate().take(rows) {
        let at = (y0 as usize + y) * w as usize + x0 as usize;
        for (v, r) in row.iter_mut().zip(&ratio[at..at + cols]) {
            *v = quanta(r[0]);
            energy += v.abs();
        }
    }
    let energy = energy as f32 * QUANTUM;
    if energy < MIN_ENERGY {
        return [0.0; 4];
    }
    let mut before = [[0i32; SPAN]; SPAN];
    // The window's columns inside the frame, the same in every row: one
    // slice of each row, without a test per element.
    let left = x0 as i32 - REACH;
    let (from, to) = (left.max(0), (left + SPAN as i32).min(w as i32));
    let columns = (from - left) as usize..(to - left) as usize;
    for (y, row) in before.iter_mut().enumerate() {
        let sy = y0 as i32 - REACH + y as i32;
        if sy < 0 || sy >= h as i32 {
            continue;
        }
        let line = (sy as u32 * w) as usize;
        let source = &ratio[line + from as usize..line + to as usize];
        for (v, r) in row[columns.clone()].iter_mut().zip(source) {
            *v = quanta(r[1]);
        }
    }
    // Σ|r_t(x) − r_{t−1}(x − d)| in quanta, or `None` once past `limit`.
    // A whole block's rows are slices of a constant length, which the
    // compiler sums in vector registers; a block at the frame's edge sums
    // only its own columns.
    let sad = |a: &[i32], b: &[i32]| a.iter().zip(b).map(|(a, b)| (a - b).abs()).sum::<i32>();
    let whole = cols == BLOCK as usize && rows == BLOCK as usize;
    let cost = |dx: i32, dy: i32, limit: i32| {
        if whole {
            return whole_cost(&now, &before, (dx, dy), limit);
        }
        let mut cost = 0i32;
        for (y, row) in now.iter().enumerate().take(rows) {
            let from = &before[(y as i32 + REACH - dy) as usize][(REACH - dx) as usize..];
            cost += sad(&row[..cols], &from[..cols]);
            if cost > limit {
                return None;
            }
        }
        Some(cost)
    };
    // (cost, |f|², f): the least cost, then the shortest displacement,
    // then the kernel's order; over every even displacement, then the
    // pixel around the best. The even ones go shortest first (so a good
    // bound comes early), and one only replaces the best when it costs
    // strictly less: what wins is what the kernel's row order finds.
    let mut best = (i32::MAX, i32::MAX, 0i32, 0i32);
    for &(dx, dy) in even_displacements() {
        if let Some(c) = cost(dx, dy, best.0.saturating_sub(1)) {
            best = (c, dx * dx + dy * dy, dx, dy);
        }
    }
    let consider = |best: &mut (i32, i32, i32, i32), dx: i32, dy: i32| {
        let len = dx * dx + dy * dy;
        if let Some(c) = cost(dx, dy, best.0) {
            if c < best.0 || (c == best.0 && len < best.1) {
                *best = (c, len, dx, dy);
            }
        }
    };
    let (cx, cy) = (best.2, best.3);
    for dy in -1..=1 {
        for dx in -1..=1 {
            if dx != 0 || dy != 0 {
                consider(&mut best, cx + dx, cy + dy);
            }
        }
    }
    // A change the previous one does not explain, moved, is no shading
    // moving on (resampling noise, a first interval): left alone.
    if best.0 as f32 * QUANTUM > COHERENCE * energy {
        return [0.0; 4];
    }
    [best.2 as f32, best.3 as f32, energy, 0.0]
}

/// Step 2 for every block, on all cores, into `out`.
pub fn flow_into(ratio: &[[f32; 2]], size: (u32, u32), out: &mut Vec<[f32; 4]>) {
    use rayon::prelude::*;
    let (bw, bh) = blocks(size.0, size.1);
    out.clear();
    out.par_extend(
        (0..(bw * bh) as usize)
            .into_par_iter()
            .with_max_len(64)
            .map(|b| flow_block(b, ratio, size)),
    );
}

/// The estimate of one rendered frame, as the correction reads it.
#[derive(Clone, Copy, Debug)]
pub struct Estimate<'a> {
    /// Linear RGB of frame `t`.
    pub color: &'a [[f32; 4]],
    /// Track words.
    pub track: &'a [u32],
    /// `(r_t, aligned r_{t−1})` per pixel.
    pub ratio: &'a [[f32; 2]],
    /// Per block `[f.x, f.y, energy, 0]`.
    pub flow: &'a [[f32; 4]],
    /// Width, height.
    pub size: (u32, u32),
}

/// `smoothstep(lo, hi, v)`, as WGSL defines it.
#[inline]
fn smoothstep(lo: f32, hi: f32, v: f32) -> f32 {
    let t = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The motion pixels of block `(bx, by)` continue the change along: the
/// block's own when it has change of its own, else that of its neighbour
/// (3×3) with the most change, so the pixels a band is about to reach
/// move with it. `None`: nothing to continue there.
pub fn lender(flow: &[[f32; 4]], size: (u32, u32), bx: i32, by: i32) -> Option<[f32; 4]> {
    let (bw, bh) = blocks(size.0, size.1);
    let mut lender = flow[(by as u32 * bw + bx as u32) as usize];
    if lender[2] <= 0.0 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (nx, ny) = (bx + dx, by + dy);
                if nx < 0 || ny < 0 || nx >= bw as i32 || ny >= bh as i32 {
                    continue;
                }
                let f = flow[(ny as u32 * bw + nx as u32) as usize];
                if f[2] > lender[2] {
                    lender = f;
                }
            }
        }
    }
    (lender[2] > 0.0).then_some(lender)
}

/// `r_t` at pixel `(sx, sy)` (given as the floor of a position), 0
/// outside the frame.
#[inline]
fn ratio_nearest(ratio: &[[f32; 2]], size: (u32, u32), sx: f32, sy: f32) -> f32 {
    let (w, h) = size;
    cell(Vec2::new(sx, sy), w, h, 1.0).map_or(0.0, |s| ratio[s as usize][0])
}

/// `r_t` bilinearly at the continuous position `(x, y)` (pixel centres at
/// `+0.5`), taps outside the frame 0.
#[inline]
fn ratio_bilinear(ratio: &[[f32; 2]], size: (u32, u32), x: f32, y: f32) -> f32 {
    let (bx, by) = (floor(x - 0.5) as f32, floor(y - 0.5) as f32);
    let (tx, ty) = (x - 0.5 - bx, y - 0.5 - by);
    let tap = |dx: f32, dy: f32| ratio_nearest(ratio, size, bx + dx, by + dy);
    let top = tap(0.0, 0.0) * (1.0 - tx) + tap(1.0, 0.0) * tx;
    let bottom = tap(0.0, 1.0) * (1.0 - tx) + tap(1.0, 1.0) * tx;
    top * (1.0 - ty) + bottom * ty
}

/// Step 3 for pixel `(px, py)`: the log change predicted over `alpha`
/// intervals along `f`.
///
/// With `g` the log shading at `t` and the band model `r_t(y) = g(y) −
/// g(y + f)` (the shading moves on by `f` per interval), the change over
/// `α` intervals is `g(x − α·f) − g(x)`. Each whole interval `k` adds
/// `r_t(x − k·f)`. A last fraction `φ` of an interval, from `y = x −
/// (k−1)·f`, needs `g(y − φ·f) − g(y)`: `r_t(y − φ·f)` (bilinearly) spans
/// it and `(1−φ)` of an interval ahead of `y` more, whose change is taken
/// as that fraction of `r_t(y)`. That is exact for a hard edge (nothing
/// changes ahead of it) and for a smooth ramp (then `φ·r`, as for a light
/// dimming in place, `f = 0`). It is kept between 0 and the whole
/// interval's `r_t(y − f)`: a fraction of an interval changes a pixel
/// less than all of it does, and a pixel the band has already passed not
/// at all.
#[inline]
pub fn predict(
    ratio: &[[f32; 2]],
    size: (u32, u32),
    px: u32,
    py: u32,
    f: [f32; 2],
    alpha: f32,
) -> f32 {
    let (cx, cy) = (px as f32 + 0.5, py as f32 + 0.5);
    let mut predicted = 0.0f32;
    let mut left = alpha.clamp(0.0, MAX_STEPS);
    let mut k = 1.0f32;
    while left > 0.0 {
        let whole = interval_back(ratio, size, (cx, cy), k, f);
        predicted += if left >= 1.0 {
            whole
        } else if whole == 0.0 {
            // Kept between 0 and 0 below, whatever the fraction's change:
            // its three reads and four bilinear taps are not needed (most
            // pixels the correction visits).
            0.0
        } else {
            let (yx, yy) = (cx - (k - 1.0) * f[0], cy - (k - 1.0) * f[1]);
            let part = ratio_bilinear(ratio, size, yx - left * f[0], yy - left * f[1]);
            let ahead = ratio_nearest(ratio, size, floor(yx) as f32, floor(yy) as f32);
            let change = part - (1.0 - left) * ahead;
            change.max(whole.min(0.0)).min(whole.max(0.0))
        };
        left -= 1.0;
        k += 1.0;
    }
    predicted
}

/// `r_t` `k` whole intervals back along `f` from the pixel centre `(cx,
/// cy)`: what [`predict`] adds for interval `k`.
#[inline]
fn interval_back(
    ratio: &[[f32; 2]],
    size: (u32, u32),
    (cx, cy): (f32, f32),
    k: f32,
    f: [f32; 2],
) -> f32 {
    let (x, y) = (floor(cx - k * f[0]), floor(cy - k * f[1]));
    ratio_nearest(ratio, size, x as f32, y as f32)
}

/// Step 4 for colour `c` with predicted log change `predicted`: the focus
/// mask blends the corrected colour in.
#[inline]
fn apply(c: [f32; 4], predicted: f32) -> [f32; 4] {
    let m = smoothstep(FOCUS_LOW, FOCUS_HIGH, predicted.abs());
    if m <= 0.0 {
        return c;
    }
    let gain = predicted.clamp(-MAX_LOG_RATIO, MAX_LOG_RATIO).exp();
    let blend = |v: f32| v + m * (v * gain - v);
    [blend(c[0]), blend(c[1]), blend(c[2]), c[3]]
}

/// Steps 3–4 for every pixel, on all cores, into `out`. Returns false
/// (and leaves `out` as it was) when no block has a change to continue:
/// the colour is then the rendered one as it is.
pub fn correct_into(e: &Estimate<'_>, alpha: f32, out: &mut Vec<[f32; 4]>) -> bool {
    let Some(changes) = changes(e, alpha) else {
        return false;
    };
    out.clear();
    out.extend_from_slice(e.color);
    for (i, c) in changes {
        out[i as usize] = c;
    }
    true
}

/// Steps 3–4 as the pixels they change: each with its corrected colour,
/// in no particular order; `None` when no block has a change to continue.
/// Only the pixels of blocks with a lender are visited (a tenth of a 720p
/// frame of the default scene, of which a tenth change): the CPU executor
/// writes these into the frame's colour for the warp and takes them back
/// after it, instead of copying the whole frame ([`correct_into`]).
pub fn changes(e: &Estimate<'_>, alpha: f32) -> Option<Vec<(u32, [f32; 4])>> {
    use rayon::prelude::*;
    let (w, h) = e.size;
    let (bw, bh) = blocks(w, h);
    let lenders: Vec<(u32, [f32; 4])> = (0..bw * bh)
        .into_par_iter()
        .filter_map(|b| lender(e.flow, e.size, (b % bw) as i32, (b / bw) as i32).map(|f| (b, f)))
        .collect();
    if lenders.is_empty() {
        return None;
    }
    // With less than one interval to continue (α < 1: every frame
    // generated between two rendered ones), a pixel whose change one
    // interval back along `f` is 0 is predicted none (`predict`) and keeps
    // its colour bit for bit (`apply`): it is passed over on that one
    // read, before its track word and colour are read. Most of the pixels
    // visited are (720p, default scene: 9 k of the 99 k visited change),
    // and reading theirs was most of this pass's time (a block's rows lie
    // a frame's row apart in memory).
    let fraction = alpha.clamp(0.0, MAX_STEPS) < 1.0;
    // Block by block, in plain loops.
    let lists: Vec<Vec<(u32, [f32; 4])>> = lenders
        .par_iter()
        .fold(Vec::new, |mut changed, &(b, f)| {
            let (x0, y0) = ((b % bw) * BLOCK, (b / bw) * BLOCK);
            let (x1, y1) = ((x0 + BLOCK).min(w), (y0 + BLOCK).min(h));
            let f = [f[0], f[1]];
            for py in y0..y1 {
                let row = (py * w) as usize;
                for px in x0..x1 {
                    let i = row + px as usize;
                    let center = (px as f32 + 0.5, py as f32 + 0.5);
                    if fraction && interval_back(e.ratio, e.size, center, 1.0, f) == 0.0 {
                        continue;
                    }
                    if is_dynamic(e.track[i]) {
                        continue;
                    }
                    let c = e.color[i];
                    let o = apply(c, predict(e.ratio, e.size, px, py, f, alpha));
                    if o.map(f32::to_bits) != c.map(f32::to_bits) {
                        changed.push((i as u32, o));
                    }
                }
            }
            changed
        })
        .collect();
    let changed: Vec<(u32, [f32; 4])> = lists.concat();
    Some(changed)
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// width, height, blocks per row, blocks per column
    size: [u32; 4],
    /// whether frame t−1 has a ratio plane, 0, 0, 0
    flags: [u32; 4],
    /// alpha, 0, 0, 0
    alpha: [f32; 4],
}

/// The GPU passes (`shading.wgsl`).
#[derive(Debug)]
pub struct GpuShading {
    ratio: Kernel,
    flow: Kernel,
    correct: Kernel,
}

/// Frame `t`'s buffers as the GPU estimate reads them.
#[derive(Debug, Clone, Copy)]
pub struct GpuCurrent<'a> {
    /// `vec4<f32>` colour.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec2<f32>` motion.
    pub motion: &'a wgpu::Buffer,
    /// `u32` track words.
    pub track: &'a wgpu::Buffer,
    /// `vec2<f32>` ratios (written by the estimate).
    pub ratio: &'a wgpu::Buffer,
    /// `vec4<f32>` per block (written by the estimate).
    pub flow: &'a wgpu::Buffer,
    /// Width, height.
    pub size: (u32, u32),
}

/// Frame `t−1`'s buffers as the GPU estimate reads them.
#[derive(Debug, Clone, Copy)]
pub struct GpuPrevious<'a> {
    /// `vec4<f32>` colour.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec2<f32>` ratios...
    pub ratio: &'a wgpu::Buffer,
    /// ...holding an estimate, or not (then unread).
    pub has_ratio: bool,
}

impl GpuShading {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = include_str!("shading.wgsl");
        // params, color, depth, motion, track, prev color, prev ratio,
        // ratio, flow, out, prev depth
        let k = |entry, b: &[Binding]| Kernel::new(ctx, src, entry, b);
        Self {
            ratio: k(
                "shading_ratio",
                &[
                    Params, Read, Read, Read, Read, Read, Read, ReadWrite, Skip, Skip, Read,
                ],
            ),
            // The ratio and flow planes are written by one entry point and
            // read by the next; the shader declares them read-write.
            flow: k(
                "shading_flow",
                &[
                    Params, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite, ReadWrite, Skip, Skip,
                ],
            ),
            correct: k(
                "shading_correct",
                &[
                    Params, Read, Skip, Skip, Read, Skip, Skip, ReadWrite, ReadWrite, ReadWrite,
                    Skip,
                ],
            ),
        }
    }

    fn params(ctx: &Rec<'_>, size: (u32, u32), has_prev: bool, alpha: f32) -> wgpu::Buffer {
        let (bw, bh) = blocks(size.0, size.1);
        ctx.params(bytemuck::bytes_of(&Params {
            size: [size.0, size.1, bw, bh],
            flags: [u32::from(has_prev), 0, 0, 0],
            alpha: [alpha, 0.0, 0.0, 0.0],
        }))
    }

    /// Records steps 1–2 for frame `cur` against `prev`. Without a
    /// previous frame the ratio and flow are cleared (no correction).
    pub fn encode_estimate(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        cur: GpuCurrent<'_>,
        prev: Option<GpuPrevious<'_>>,
    ) {
        let Some(prev) = prev else {
            encoder.clear_buffer(cur.ratio, 0, None);
            encoder.clear_buffer(cur.flow, 0, None);
            return;
        };
        let params = Self::params(ctx, cur.size, prev.has_ratio, 0.0);
        let n = u64::from(cur.size.0) * u64::from(cur.size.1);
        self.ratio.dispatch(
            ctx,
            encoder,
            &[
                &params, cur.color, cur.depth, cur.motion, cur.track, prev.color, prev.ratio,
                cur.ratio, prev.depth,
            ],
            n,
        );
        self.encode_flow(ctx, encoder, cur.ratio, cur.flow, cur.size);
    }

    /// Records step 2 alone: the flow of each block of the `size` ratio
    /// plane `ratio` into `flow` (`vec4<f32>` per block), one workgroup
    /// per block.
    pub fn encode_flow(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        ratio: &wgpu::Buffer,
        flow: &wgpu::Buffer,
        size: (u32, u32),
    ) {
        let params = Self::params(ctx, size, false, 0.0);
        let (bw, bh) = blocks(size.0, size.1);
        self.flow
            .dispatch_groups(ctx, encoder, &[&params, ratio, flow], bw * bh);
    }

    /// Records steps 3–4 at `alpha` into `out` (`vec4<f32>` per pixel).
    pub fn encode_correct(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        cur: GpuCurrent<'_>,
        alpha: f32,
        out: &wgpu::Buffer,
    ) {
        let params = Self::params(ctx, cur.size, false, alpha);
        let n = u64::from(cur.size.0) * u64::from(cur.size.1);
        self.correct.dispatch(
            ctx,
            encoder,
            &[&params, cur.color, cur.track, cur.ratio, cur.flow, out],
            n,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::passes::common::resample_run::Planes;

    /// Step 1 for every pixel, into a new plane.
    fn ratio(cur: &Current<'_>, prev: &Previous<'_>) -> Vec<[f32; 2]> {
        let mut out = Vec::new();
        ratio_into(cur, prev, &mut out, &mut Vec::new());
        out
    }

    /// Step 2 for every block, into a new plane.
    fn flow(ratio: &[[f32; 2]], size: (u32, u32)) -> Vec<[f32; 4]> {
        let mut out = Vec::new();
        flow_into(ratio, size, &mut out);
        out
    }

    /// Steps 3–4 for every pixel, into a new image (the colour as it is
    /// where nothing is continued).
    fn correct(e: &Estimate<'_>, alpha: f32) -> Vec<[f32; 4]> {
        let mut out = Vec::new();
        if !correct_into(e, alpha, &mut out) {
            out = e.color.to_vec();
        }
        out
    }

    const W: u32 = 48;
    const H: u32 = 16;

    /// A lit grey surface with a shadow over `x < edge` (luminance 1 and
    /// 0.1), plus a fine texture that does not move.
    fn shadowed(edge: f32) -> Vec<[f32; 4]> {
        (0..W * H)
            .map(|i| {
                let x = i % W;
                let texture = if x % 2 == 0 { 1.0 } else { 0.9 };
                let v = if (x as f32) < edge { 0.1 } else { 1.0 } * texture;
                [v, v, v, 1.0]
            })
            .collect()
    }

    fn current<'a>(color: &'a [[f32; 4]], track: &'a [u32]) -> Current<'a> {
        Current {
            color,
            depth: &[1.0; (W * H) as usize],
            motion: &[[0.0; 2]; (W * H) as usize],
            track,
            size: (W, H),
            planes: None,
        }
    }

    #[test]
    fn a_moving_shadow_edge_is_continued() {
        // The shadow's edge moves right by 3 px per interval: 12 → 15 → 18.
        let track = vec![0u32; (W * H) as usize];
        let (c0, c1, c2) = (shadowed(12.0), shadowed(15.0), shadowed(18.0));
        let depth = vec![1.0f32; (W * H) as usize];
        let none = Previous {
            color: &c0,
            depth: &depth,
            ratio: &[],
            luma: &[],
        };
        let r1 = ratio(&current(&c1, &track), &none);
        let r2 = ratio(
            &current(&c2, &track),
            &Previous {
                color: &c1,
                depth: &depth,
                ratio: &r1,
                luma: &[],
            },
        );
        // The new band (columns 15–17) changed by the shadow's ratio; the
        // old shadow and the lit side did not, texture and all (no motion:
        // each pixel compares with itself).
        let at = |r: &[[f32; 2]], x: u32| r[(4 * W + x) as usize];
        assert!(at(&r2, 16)[0] < -2.0, "{:?}", at(&r2, 16));
        for (i, r) in r2.iter().enumerate() {
            let changed = matches!(i as u32 % W, 15..=17);
            assert_eq!(r[0] != 0.0, changed, "pixel {i}: {r:?}");
        }
        let f = flow(&r2, (W, H));
        let moving: Vec<_> = f.iter().filter(|b| b[2] > 0.0).collect();
        assert!(!moving.is_empty());
        for b in moving {
            assert_eq!((b[0], b[1]), (3.0, 0.0), "{b:?}");
        }
        // One interval on, the band reaches column 19 (18..21 becomes
        // shadow): corrected to the truth's shadow there, the lit side
        // beyond and the old shadow left alone.
        let e = Estimate {
            color: &c2,
            track: &track,
            ratio: &r2,
            flow: &f,
            size: (W, H),
        };
        let out = correct(&e, 1.0);
        let truth = shadowed(21.0);
        let px = |img: &[[f32; 4]], x: u32| img[(4 * W + x) as usize][0];
        assert!(
            (px(&out, 19) - px(&truth, 19)).abs() < 0.02,
            "{}",
            px(&out, 19)
        );
        assert_eq!(px(&out, 24), px(&c2, 24));
        assert_eq!(px(&out, 5), px(&c2, 5));
        // Half an interval: the edge is half-way on, at 19.5. Column 18
        // has all of the change, column 19 (half covered) half of it in
        // log space, column 20 none.
        let half = correct(&e, 0.5);
        let full = px(&c2, 18) * at(&r2, 15)[0].exp();
        assert!((px(&half, 18) - full).abs() < 1e-5, "{}", px(&half, 18));
        let expect = px(&c2, 19) * (0.5 * at(&r2, 16)[0]).exp();
        assert!((px(&half, 19) - expect).abs() < 1e-5, "{}", px(&half, 19));
        assert_eq!(px(&half, 20), px(&c2, 20));
        // Nothing at α = 0.
        assert_eq!(correct(&e, 0.0), c2);
    }

    #[test]
    fn a_smooth_ramp_and_a_change_in_place_continue_in_proportion() {
        // A log-linear ramp of shading moving on by 3 px per interval
        // changes every pixel by the same r each interval: α of an
        // interval is α·r, as is a light dimming in place (f = 0).
        let ratio = vec![[-0.6f32, -0.6]; (W * H) as usize];
        for f in [[3.0, 0.0], [0.0, 0.0], [-2.0, 1.0]] {
            for (alpha, expect) in [(0.25, -0.15), (0.5, -0.3), (1.0, -0.6), (2.5, -1.5)] {
                let got = predict(&ratio, (W, H), 24, 8, f, alpha);
                assert!((got - expect).abs() < 1e-5, "f {f:?} α {alpha}: {got}");
            }
        }
    }

    /// Where the whole interval back along `f` has no change, a fraction
    /// of an interval has none either, whatever lies around it (the
    /// fraction is kept between 0 and that change), and the reads for the
    /// fraction are skipped; an interval and a half reaches the change
    /// beyond it.
    #[test]
    fn no_change_an_interval_back_is_none_for_a_fraction_of_one() {
        let mut ratio = vec![[0.5f32, 0.5]; (W * H) as usize];
        ratio[(8 * W + 21) as usize] = [0.0; 2];
        for alpha in [0.25, 0.5, 0.9] {
            let got = predict(&ratio, (W, H), 24, 8, [3.0, 0.0], alpha);
            assert_eq!(got.to_bits(), 0.0f32.to_bits(), "α {alpha}");
        }
        let further = predict(&ratio, (W, H), 24, 8, [3.0, 0.0], 1.5);
        assert!((further - 0.5).abs() < 1e-6, "{further}");
    }

    /// The search as first written: every displacement's cost in full,
    /// in `f32`, over the frame (what the first kernel did).
    fn exhaustive(b: usize, ratio: &[[f32; 2]], size: (u32, u32)) -> [f32; 4] {
        let (w, h) = size;
        let (bw, _) = blocks(w, h);
        let (x0, y0) = ((b as u32 % bw) * BLOCK, (b as u32 / bw) * BLOCK);
        let (x1, y1) = ((x0 + BLOCK).min(w), (y0 + BLOCK).min(h));
        let pixels = || (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y)));
        let energy: f32 = pixels()
            .map(|(x, y)| ratio[(y * w + x) as usize][0].abs())
            .sum();
        if energy < MIN_ENERGY {
            return [0.0; 4];
        }
        let cost = |dx: i32, dy: i32| -> f32 {
            pixels()
                .map(|(x, y)| {
                    let (sx, sy) = (x as i32 - dx, y as i32 - dy);
                    let inside = sx >= 0 && sx < w as i32 && sy >= 0 && sy < h as i32;
                    let before = if inside {
                        ratio[(sy as u32 * w + sx as u32) as usize][1]
                    } else {
                        0.0
                    };
                    (ratio[(y * w + x) as usize][0] - before).abs()
                })
                .sum()
        };
        let mut best = (f32::INFINITY, i32::MAX, 0, 0);
        let consider = |dx: i32, dy: i32, best: &mut (f32, i32, i32, i32)| {
            let (c, len) = (cost(dx, dy), dx * dx + dy * dy);
            if c < best.0 || (c == best.0 && len < best.1) {
                *best = (c, len, dx, dy);
            }
        };
        for dy in (-SEARCH..=SEARCH).step_by(2) {
            for dx in (-SEARCH..=SEARCH).step_by(2) {
                consider(dx, dy, &mut best);
            }
        }
        let (cx, cy) = (best.2, best.3);
        for (dx, dy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))) {
            if dx != 0 || dy != 0 {
                consider(cx + dx, cy + dy, &mut best);
            }
        }
        if best.0 > COHERENCE * energy {
            return [0.0; 4];
        }
        [best.2 as f32, best.3 as f32, energy, 0.0]
    }

    /// The plain sum that rules blocks out before their conversion to
    /// quanta never rules out one the quanta let through: a block at the
    /// threshold is searched, one a quantum under it is not, and one of
    /// values just over half a quantum under the quanta they round to
    /// (its plain sum 1.88, under the threshold) is searched.
    #[test]
    fn blocks_at_the_energy_threshold_are_searched() {
        let (w, h) = (24u32, 8u32);
        let q = QUANTUM;
        let ratio: Vec<[f32; 2]> = (0..w * h)
            .map(|i| {
                let v = match (i % w / 8, i) {
                    (1, 8) => 7.0 * q,
                    (0 | 1, _) => 8.0 * q,
                    _ => 7.51 * q,
                };
                [v, v]
            })
            .collect();
        let energy: Vec<f32> = (0..3).map(|b| flow_block(b, &ratio, (w, h))[2]).collect();
        assert_eq!(energy, [MIN_ENERGY, 0.0, MIN_ENERGY]);
    }

    #[test]
    fn the_pruned_integer_search_finds_what_the_exhaustive_one_finds() {
        // Bands of change moving by a few pixels, over noise, on a frame
        // whose size is no multiple of the block (partial blocks at the
        // edges), with ties between equal displacements.
        let (w, h) = (45u32, 21u32);
        let (bw, bh) = blocks(w, h);
        let agree = |ratio: &[[f32; 2]], case: i32| {
            for b in 0..(bw * bh) as usize {
                assert_eq!(
                    flow_block(b, ratio, (w, h)),
                    exhaustive(b, ratio, (w, h)),
                    "case {case}, block {b}"
                );
            }
        };
        let mut seed = 12345u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        for case in 0..20 {
            let shift = case % 7 - 3;
            let ratio: Vec<[f32; 2]> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as i32, (i / w) as i32);
                    let band = |x: i32| ((x + y / 3) % 11) < 3;
                    let now = if band(x) { -1.5 } else { 0.0 } + 0.3 * (noise() - 0.5);
                    let before = if band(x + shift) { -1.5 } else { 0.0 };
                    let before = if case % 3 == 0 {
                        before
                    } else {
                        before + 0.2 * noise()
                    };
                    [quantize(now), quantize(before)]
                })
                .collect();
            agree(&ratio, case);
            assert!(
                flow(&ratio, (w, h)).iter().any(|f| f[2] > 0.0),
                "case {case}"
            );
        }
        // Stripes of period 4: moved by 2 px either way they match exactly,
        // a tie the kernel's row order settles (−2 comes first).
        let stripes = |x: u32| if x % 4 < 2 { -1.0 } else { 0.0 };
        let ratio: Vec<[f32; 2]> = (0..w * h)
            .map(|i| [stripes(i % w), stripes(i % w + 2)])
            .collect();
        agree(&ratio, 20);
        assert_eq!(
            flow_block(bw as usize + 1, &ratio, (w, h))[..2],
            [-2.0, 0.0]
        );
    }

    #[test]
    fn a_texture_moved_by_half_a_pixel_is_no_change() {
        // The surface moved right by half a pixel: each pixel now shows the
        // mean of the two texels it straddled, and its motion points half
        // a pixel left.
        let n = (W * H) as usize;
        let prev = shadowed(0.0);
        let cur: Vec<[f32; 4]> = (0..n)
            .map(|i| {
                let left = if i % W as usize == 0 { i } else { i - 1 };
                std::array::from_fn(|c| (prev[i][c] + prev[left][c]) / 2.0)
            })
            .collect();
        let track = vec![0u32; n];
        let motion = vec![[-0.5f32, 0.0]; n];
        let depth = vec![1.0f32; n];
        let c = Current {
            motion: &motion,
            ..current(&cur, &track)
        };
        let r = ratio(
            &c,
            &Previous {
                color: &prev,
                depth: &depth,
                ratio: &[],
                luma: &[],
            },
        );
        assert!(r.iter().all(|v| v[0] == 0.0));
        // Against a frame whose surface lies elsewhere in depth (another
        // object), there is nothing to compare with.
        let far = vec![3.0f32; n];
        let lit = shadowed(0.0);
        let dark = shadowed(W as f32);
        let r = ratio(
            &current(&dark, &track),
            &Previous {
                color: &lit,
                depth: &far,
                ratio: &[],
                luma: &[],
            },
        );
        assert!(r.iter().all(|v| v[0] == 0.0));
    }

    #[test]
    fn dynamic_pixels_and_bad_values_stay_out() {
        let n = (W * H) as usize;
        let (c0, mut c1) = (shadowed(12.0), shadowed(30.0));
        c1[5] = [f32::NAN, f32::INFINITY, -1.0, 1.0];
        let mut track = vec![0u32; n];
        track[(4 * W + 20) as usize] = 1;
        let mut motion = vec![[0.0f32; 2]; n];
        motion[7] = [f32::NAN, 0.0];
        motion[8] = [-1e9, 0.0];
        let mut depth = vec![1.0f32; n];
        depth[9] = 0.0;
        let cur = Current {
            color: &c1,
            depth: &depth,
            motion: &motion,
            track: &track,
            size: (W, H),
            planes: None,
        };
        let r = ratio(
            &cur,
            &Previous {
                color: &c0,
                depth: &depth,
                ratio: &[],
                luma: &[],
            },
        );
        for i in [(4 * W + 20) as usize, 7, 8, 9] {
            assert_eq!(r[i], [0.0; 2], "pixel {i}");
        }
        assert!(r.iter().all(|v| v[0].abs() <= MAX_LOG_RATIO && v[1] == 0.0));
        let f = flow(&r, (W, H));
        let e = Estimate {
            color: &c1,
            track: &track,
            ratio: &r,
            flow: &f,
            size: (W, H),
        };
        for alpha in [0.5, 1.0, 3.0, 1e9, f32::NAN] {
            let out = correct(&e, alpha);
            assert_eq!(out[(4 * W + 20) as usize], c1[(4 * W + 20) as usize]);
            for (i, (o, c)) in out.iter().zip(&c1).enumerate() {
                if c.iter().all(|v| v.is_finite()) {
                    assert!(o.iter().all(|v| v.is_finite()), "pixel {i} at {alpha}");
                    assert!(o[0] <= c[0] * MAX_LOG_RATIO.exp() + 1e-6);
                }
            }
        }
    }

    #[test]
    fn the_runs_give_what_ratio_at_gives() {
        // A row that is not a whole number of runs, and every case of
        // `ratio_at`: dynamic pixels, no surface (0, negative, NaN), sky,
        // positions outside (or NaN), taps off the surface, still pixels,
        // footprints to measure, with and without the previous ratio.
        let (w, h) = (150u32, 7u32);
        let n = (w * h) as usize;
        let hash = |i: usize, salt: u32| {
            let mut v = (i as u32).wrapping_mul(0x9E37_79B9) ^ salt.wrapping_mul(0x85EB_CA6B);
            v ^= v >> 15;
            v = v.wrapping_mul(0x2C1B_3C6D);
            v ^= v >> 12;
            v
        };
        let unit = |i: usize, salt: u32| hash(i, salt) as f32 / u32::MAX as f32;
        let depth_of = |i: usize, salt: u32| match hash(i, salt) % 16 {
            0 => 0.0,
            1 => -1.0,
            2 => f32::NAN,
            3 => 5.0,
            4 => f32::INFINITY,
            _ => 1.0 + 0.02 * unit(i, salt + 1),
        };
        let color = |i: usize, salt: u32| {
            let v = if hash(i, salt) % 3 == 0 {
                unit(i, salt + 2)
            } else {
                0.5
            };
            [v, v * 0.9, v * 1.1, 1.0]
        };
        let cur_color: Vec<[f32; 4]> = (0..n).map(|i| color(i, 1)).collect();
        let prev_color: Vec<[f32; 4]> = (0..n).map(|i| color(i, 2)).collect();
        let depth: Vec<f32> = (0..n).map(|i| depth_of(i, 3)).collect();
        let prev_depth: Vec<f32> = (0..n).map(|i| depth_of(i, 4)).collect();
        let track: Vec<u32> = (0..n).map(|i| u32::from(hash(i, 5) % 11 == 0)).collect();
        let motion: Vec<[f32; 2]> = (0..n)
            .map(|i| match hash(i, 6) % 20 {
                0 => [f32::NAN, 0.0],
                1 => [1e9, -1e9],
                2 => [-0.5, 0.0],
                3 | 4 => [-0.5, 0.5],
                _ => [8.0 * unit(i, 7) - 4.0, 6.0 * unit(i, 8) - 3.0],
            })
            .collect();
        let prev_luma: Vec<f32> = prev_color
            .iter()
            .map(|c| luminance(*c) + LUMA_FLOOR)
            .collect();
        let prev_ratio: Vec<[f32; 2]> = (0..n).map(|i| [quantize(unit(i, 9) - 0.5), 0.0]).collect();
        let mut planes = Planes::default();
        planes.fill(&cur_color);
        let plain = Current {
            color: &cur_color,
            depth: &depth,
            motion: &motion,
            track: &track,
            size: (w, h),
            planes: None,
        };
        // With the colour's planes too (the luminances read from them).
        let with_planes = Current {
            planes: Some(planes.rgb()),
            ..plain
        };
        let cases = [&prev_ratio[..], &[]].map(|r| [(plain, r), (with_planes, r)]);
        for (cur, ratio) in cases.into_iter().flatten() {
            let prev = Previous {
                color: &prev_color,
                depth: &prev_depth,
                ratio,
                luma: &prev_luma,
            };
            let (mut out, mut luma) = (Vec::new(), Vec::new());
            ratio_into(&cur, &prev, &mut out, &mut luma);
            let mut measured = 0;
            for i in 0..n {
                let (px, py) = (i as u32 % w, i as u32 / w);
                let lt = luminance(cur_color[i]) + LUMA_FLOOR;
                assert_eq!(luma[i].to_bits(), lt.to_bits(), "pixel {i}");
                let want = ratio_at(px, py, lt, &cur, &prev);
                let got = out[i];
                assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
                measured += usize::from(want[0] != 0.0);
            }
            // The footprints were measured, not only the still pixels.
            assert!(measured > n / 10, "{measured} of {n}");
        }
    }
}
