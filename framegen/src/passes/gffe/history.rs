//! History tracking with the static test: GFFE Algorithm 1 (appendix B),
//! DESIGN §4 step 1.
//!
//! For each pixel `x` of rendered frame t with depth `D_t[x]`:
//!
//! * `p = unproject(x, D_t, C_t)` (camera-relative to `C_t`);
//! * `x̂ = project(p, C_{t−1})`, `x' = x + V_{t→t−1}[x]`;
//! * if `‖x̂ − x'‖ > ε` the pixel is **dynamic**: `P_i = P'_{i−1}[x']` for
//!   `i = 1..k−1` (the previous trajectory shifted by one) and `P_0 = p`;
//! * otherwise it is **static** and every `P_i = p`.
//!
//! Choices the paper leaves open, made here:
//! * `x'` reads the previous history at the pixel containing it (nearest).
//! * The **track word** of a pixel is `dynamic | confirmed << 1 |
//!   chain << 2`, where `chain` counts how many of `P_1..P_{k−1}` are real
//!   history: a static pixel's
//!   entries all hold its (static) position, so its chain is `k − 1`; a
//!   dynamic pixel extends the chain found at `x'` by one; a trajectory
//!   that leaves the previous image, meets an empty pixel, or switches
//!   between a point and a sky direction ends there and the remaining
//!   entries repeat the last real one (zero velocity, never garbage).
//! * **Confirmed** static pixels may enter the background layers
//!   (`background.rs`). The static test only compares screen positions, so
//!   a point moving along its view ray (an object coming straight at the
//!   camera) passes it, and would leave a ghost of the object in the
//!   background. A static pixel is confirmed when its point, seen from the
//!   previous camera (the static test's projection `x̂`), is as deep as the
//!   previous frame's depth `D_{t−1}` in the pixel `x̂` lies in, within the
//!   relative `tolerance` (both are view depths of `C_{t−1}`), or when both
//!   are sky: an object moving along the ray was nearer or farther there.
//!   The rendered depth is read, not the depth of the previous position
//!   there as `C_{t−1}` sees it again: the same value before rounding (that
//!   position was unprojected from it), 4 bytes instead of 16 and no
//!   arithmetic per static pixel (the CPU pass at 720p 5.8 → 5.0 ms).
//!   (First built the other way round, the previous position projected
//!   into the current camera and compared with the depth of the pixel it
//!   lands in: a second projection and a second random read per static
//!   pixel, a fifth of the pass on the CPU at 720p, for the same quality
//!   within ±0.5 % ꟻLIP per scene.) Only the background needs it: a
//!   method that collects no background layers passes no tolerance and
//!   confirms nothing (a random read per static pixel saved).
//! * **Seen again.** Where a confirmed pixel lands in a pixel of the
//!   previous frame that was confirmed static too (a seed of the previous
//!   background's level 0), that seed is the same surface at the same
//!   depth, seen again; where a pixel that is not confirmed lands in one,
//!   it may be what that pixel hides now. The pass flags both
//!   ([`SeenAgain`]), and background collection does not reproject a
//!   seed seen again that nothing unsure landed in (`background.rs`; 97 %
//!   of the previous seeds on the default scene at 720p).
//! * Invalid depth (sanitised NaN / ≤ 0) gives no position at all.
//! * Without a previous frame (first frame, cut, reset) every pixel is
//!   static.
//!
//! Positions are stored relative to the current camera centre; the previous
//! history is rebased by the previous camera's centre (computed in `f64`).

use std::sync::atomic::{AtomicU8, Ordering::Relaxed};

use glam::{Vec2, Vec4};

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::{PassCamera, W_DIRECTION, W_INVALID, W_POINT, cell, rebase};
use crate::passes::common::lanes::{LANES, Lanes3, Projected4, cells, project4};

/// The previous rendered frame's history, as the current frame sees it.
#[derive(Clone, Copy, Debug)]
pub struct PrevHistory<'a> {
    /// `C_{t−1}` relative to the current camera centre, at its image size.
    pub camera: PassCamera,
    /// `k` planes of `width × height` positions (plane `i` is `P'_i`;
    /// planes `1..` read only where a pixel is dynamic, [`History::position`]).
    pub positions: &'a [[f32; 4]],
    /// Track words.
    pub track: &'a [u32],
    /// Its sanitised depth `D_{t−1}`, which the confirmation compares with.
    pub depth: &'a [f32],
}

/// The confirmation of a static pixel (see the module doc): its point or
/// sky direction (`sky`), seen at view depth `seen` from the previous
/// camera, against the previous frame's depth `before` in the pixel it
/// lands in. A point agrees with a surface as deep within the relative
/// `tolerance` (no surface, 0, is never within it, nor NaN), not with sky;
/// a sky with a sky.
#[inline]
fn agrees(sky: bool, seen: f32, before: f32, tolerance: f32) -> bool {
    match sky {
        true => before == f32::INFINITY,
        false => (before < f32::INFINITY) & ((seen - before).abs() <= tolerance * before),
    }
}

/// The result of Algorithm 1 for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct History {
    /// `k` planes of positions, plane `i` = `P_i`.
    pub positions: Vec<[f32; 4]>,
    /// Per pixel `dynamic | confirmed << 1 | chain << 2`.
    pub track: Vec<u32>,
    /// Number of pixels that failed the static test.
    pub dynamic: u32,
    /// Its flags of the previous frame's pixels, from which background
    /// collection knows the seeds it need not reproject (empty without a
    /// previous frame or a confirmation).
    pub seen: SeenAgain,
}

impl History {
    /// No history (no frame tracked).
    pub fn empty() -> Self {
        Self {
            positions: Vec::new(),
            track: Vec::new(),
            dynamic: 0,
            seen: SeenAgain::default(),
        }
    }

    /// Plane `i` of pixel `x` (`i < k`): `P_i`, which a pixel that is not
    /// dynamic does not store beyond `P_0` ([`Tracker::track_into`]).
    #[inline]
    pub fn position(positions: &[[f32; 4]], track: &[u32], i: usize, x: usize) -> [f32; 4] {
        let plane = if is_dynamic(track[x]) { i } else { 0 };
        positions[plane * track.len() + x]
    }

    /// Every plane written: planes `1..` of each pixel that is not dynamic
    /// hold its `P_0`, as [`track`] and the GPU kernel leave them.
    pub fn expanded(mut self) -> Self {
        use rayon::prelude::*;
        let n = self.track.len();
        if n == 0 {
            return self;
        }
        let (p0, rest) = self.positions.split_at_mut(n);
        let band = 16 * 1024;
        for plane in rest.chunks_mut(n) {
            (plane.par_chunks_mut(band).zip(p0.par_chunks(band)))
                .zip(self.track.par_chunks(band))
                .for_each(|((plane, p0), track)| {
                    for ((p, p0), &word) in plane.iter_mut().zip(p0).zip(track) {
                        if !is_dynamic(word) {
                            *p = *p0;
                        }
                    }
                });
        }
        self
    }
}

/// Whether a track word marks a dynamic pixel (`M_dyn = 1`).
pub fn is_dynamic(track: u32) -> bool {
    track & 1 == 1
}

/// Whether a static pixel was confirmed by the previous frame (may enter
/// the background).
pub fn is_confirmed(track: u32) -> bool {
    track & 2 == 2
}

/// How many of `P_1..` are real history.
pub fn chain(track: u32) -> u32 {
    track >> 2
}

/// Whether a track word is a background seed: a static pixel confirmed by
/// the previous frame (`background::seeds`; WGSL `(track & 3u) == 2u`).
#[inline]
pub fn is_seed(track: u32) -> bool {
    !is_dynamic(track) && is_confirmed(track)
}

/// Two flags per pixel of the previous frame, from which background
/// collection knows the seeds it need not reproject:
///
/// * **seen**: the pixel was a seed of the previous background (confirmed
///   static there) and a confirmed pixel of the current frame lands in it
///   as deep, within the confirmation's tolerance: the surface the current
///   frame's own seed shows again;
/// * **unsure**: a pixel of the current frame that is *not* confirmed
///   (static but not confirmed, or dynamic) lands in it: reprojected, the
///   seed may land on that pixel, which holds no seed, and be carried
///   over there (behind an object that moved in front of it, or where a
///   slanted surface's confirmation failed).
///
/// A seed is skipped where it is seen and not unsure ([`SeenAgain::skips`]).
/// Without the second flag, where the current frame is scaled against the
/// previous one (a turn, a dolly) two current pixels can land in one
/// previous pixel, one confirmed and one not, and the seed was lost from
/// the one not confirmed: `fast_rotation` at 640×360 lost 5–25 % of the
/// fragments carried over in some frames, +0.7 % ꟻLIP.
///
/// Flags are only ever set during the pass (by any band, so atomically:
/// relaxed byte stores, plain `mov`s on x86-64, into two planes, so no
/// read-modify-write), so the result does not depend on the order or the
/// thread count. The GPU keeps one `u32` a pixel, `seen | unsure << 1`
/// (`atomicOr`), as [`SeenAgain::words`] gives them.
#[derive(Debug, Default)]
pub struct SeenAgain {
    seen: Vec<AtomicU8>,
    unsure: Vec<AtomicU8>,
}

impl SeenAgain {
    /// `n` pixels, no flag set, in these planes where they have that
    /// length.
    fn reset(&mut self, n: usize) {
        use rayon::prelude::*;
        for plane in [&mut self.seen, &mut self.unsure] {
            if plane.len() != n {
                *plane = (0..n).map(|_| AtomicU8::new(0)).collect();
                continue;
            }
            (plane.par_iter().with_min_len(64 * 1024)).for_each(|f| f.store(0, Relaxed));
        }
    }

    /// Flags pixel `i` of the previous frame seen.
    #[inline]
    fn set_seen(&self, i: usize) {
        if let Some(f) = self.seen.get(i) {
            f.store(1, Relaxed);
        }
    }

    /// Flags pixel `i` of the previous frame unsure.
    #[inline]
    fn set_unsure(&self, i: usize) {
        if let Some(f) = self.unsure.get(i) {
            f.store(1, Relaxed);
        }
    }

    /// Whether background collection skips the seed of pixel `i` of the
    /// previous frame: seen and not unsure (never past the end: an empty
    /// set skips nothing).
    #[inline]
    pub fn skips(&self, i: usize) -> bool {
        let flag = |plane: &[AtomicU8]| plane.get(i).is_some_and(|f| f.load(Relaxed) != 0);
        flag(&self.seen) && !flag(&self.unsure)
    }

    /// Whether it skips all four pixels `i ..` (two loads).
    #[inline]
    pub fn skips4(&self, i: usize) -> bool {
        let four = |plane: &[AtomicU8]| {
            let f = plane.get(i..)?.first_chunk::<4>()?;
            Some(f.each_ref().map(|f| f.load(Relaxed)))
        };
        four(&self.seen) == Some([1; 4]) && four(&self.unsure) == Some([0; 4])
    }

    /// Flags as the GPU keeps them, `seen | unsure << 1` a pixel, or read
    /// back from it.
    pub fn from_words(words: &[u32]) -> Self {
        let plane = |bit: u32| {
            words
                .iter()
                .map(move |&w| AtomicU8::new(u8::from(w & bit != 0)))
        };
        Self {
            seen: plane(1).collect(),
            unsure: plane(2).collect(),
        }
    }

    /// The flags as [`SeenAgain::from_words`] takes them.
    pub fn words(&self) -> Vec<u32> {
        (self.seen.iter().zip(&self.unsure))
            .map(|(s, u)| u32::from(s.load(Relaxed)) | u32::from(u.load(Relaxed)) << 1)
            .collect()
    }

    /// How many pixels there are (the previous frame's, or 0).
    pub fn len(&self) -> usize {
        self.seen.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.seen.is_empty()
    }

    /// How many seeds it skips.
    pub fn count(&self) -> usize {
        (0..self.len()).filter(|&i| self.skips(i)).count()
    }
}

impl Clone for SeenAgain {
    fn clone(&self) -> Self {
        Self::from_words(&self.words())
    }
}

impl PartialEq for SeenAgain {
    fn eq(&self, other: &Self) -> bool {
        self.words() == other.words()
    }
}

/// CPU reference of Algorithm 1. `camera` is `C_t` with its centre at the
/// origin; `k ≥ 1`; `epsilon` in pixels; `tolerance` relative depth (the
/// confirmation runs).
///
/// Runs on all cores: pixels are independent, so bands of rows are tracked
/// in parallel and the result is the same for any thread count.
pub fn track(
    camera: &PassCamera,
    depth: &[f32],
    motion: &[[f32; 2]],
    prev: Option<PrevHistory<'_>>,
    k: u32,
    epsilon: f32,
    tolerance: f32,
) -> History {
    let tracker = Tracker {
        camera,
        depth,
        motion,
        prev: prev.as_ref(),
        k,
        epsilon,
        tolerance: Some(tolerance),
    };
    tracker.track_into(History::empty()).expanded()
}

/// A band of rows for one task: its first pixel, its slice of every plane,
/// its track words.
type Band<'a> = (usize, Vec<&'a mut [[f32; 4]]>, &'a mut [u32]);

/// What Algorithm 1 reads for every pixel: [`track`]'s arguments.
#[derive(Clone, Copy, Debug)]
pub struct Tracker<'a> {
    /// `C_t`, centre at the origin.
    pub camera: &'a PassCamera,
    /// The frame's sanitised depth.
    pub depth: &'a [f32],
    /// Its motion to the previous frame.
    pub motion: &'a [[f32; 2]],
    /// The previous frame's history, when it continues.
    pub prev: Option<&'a PrevHistory<'a>>,
    /// History length (clamped to `1..=MAX_HISTORY`).
    pub k: u32,
    /// Static-test threshold, pixels.
    pub epsilon: f32,
    /// Relative depth tolerance of the confirmation; `None` confirms
    /// nothing (no background is collected).
    pub tolerance: Option<f32>,
}

impl Tracker<'_> {
    /// Algorithm 1 for every pixel, into the buffers of `reuse`, a history
    /// that is no longer needed (the CPU executor's frame before the
    /// previous one), where their sizes fit: every element read later is
    /// written, so they are not cleared first and no frame-sized
    /// allocation is made again each frame.
    ///
    /// A pixel that is not dynamic stores only `P_0`: its planes after it
    /// would repeat it, and are left as they were (every reader takes
    /// `P_0` for them, [`History::position`]; [`History::expanded`] writes
    /// them). Most pixels are static, so at `k = 2` a frame of 16-byte
    /// positions is not written (720p: 15 MB).
    pub fn track_into(&self, reuse: History) -> History {
        use rayon::prelude::*;
        let (n, k) = (self.depth.len(), self.k());
        let invalid = [0.0, 0.0, 0.0, W_INVALID];
        let mut positions = reuse.positions;
        if positions.len() != k * n {
            positions = crate::par::filled(invalid, k * n);
        }
        let mut track_words = reuse.track;
        if track_words.len() != n {
            track_words = crate::par::filled(0, n);
        }
        // Only a confirmation sees anything again.
        let mut seen = reuse.seen;
        let confirming = self.tolerance.is_some();
        seen.reset(
            self.prev
                .filter(|_| confirming)
                .map_or(0, |p| p.track.len()),
        );
        // Bands of rows; each band gets its slice of every plane.
        let band = crate::par::band(self.camera.width() as usize, n);
        let mut planes: Vec<_> = positions
            .chunks_mut(n.max(1))
            .map(|p| p.chunks_mut(band))
            .collect();
        let bands: Vec<Band<'_>> = track_words
            .chunks_mut(band)
            .enumerate()
            .map(|(b, words)| {
                let slices = planes.iter_mut().filter_map(Iterator::next).collect();
                (b * band, slices, words)
            })
            .collect();
        let width = (self.camera.width() as usize).max(1);
        let dynamic = bands
            .into_par_iter()
            .with_max_len(1)
            .map(|(start, mut planes, words)| {
                let mut dynamic = 0;
                let mut entries = [invalid; MAX_HISTORY];
                // Whole rows: the pixel centre is counted, not divided out.
                for (r, row) in words.chunks_mut(width).enumerate() {
                    let first = r * width;
                    let y = ((start + first) / width) as f32 + 0.5;
                    // Four pixels at a time where they take the common
                    // case (`track4`), one by one otherwise.
                    for (g, group) in row.chunks_mut(LANES).enumerate() {
                        let c0 = g * LANES;
                        let x = start + first + c0;
                        if group.len() == LANES
                            && let Some((words, p)) = self.track4(x, c0, y, &seen)
                        {
                            // Static: `P_0` only (the planes after it
                            // would repeat it).
                            for (l, (word, w)) in group.iter_mut().zip(words).enumerate() {
                                planes[0][first + c0 + l] = p[l];
                                *word = w;
                            }
                            continue;
                        }
                        for (l, word) in group.iter_mut().enumerate() {
                            let c = c0 + l;
                            let center = Vec2::new(c as f32 + 0.5, y);
                            // Every element is written, valid or not.
                            let w = self.track(start + first + c, center, &mut entries, &seen);
                            let stored = if is_dynamic(w) { planes.len() } else { 1 };
                            for (plane, e) in planes.iter_mut().zip(&entries).take(stored) {
                                plane[first + c] = *e;
                            }
                            *word = w;
                            dynamic += u32::from(is_dynamic(w));
                        }
                    }
                }
                dynamic
            })
            .sum();
        History {
            positions,
            track: track_words,
            dynamic,
            seen,
        }
    }

    /// [`Tracker::track`] of the four pixels `x .. x + 4` of one row (columns
    /// `c0 ..`, row centre `y`) at once, as the lanes of `Vec4`s (SSE2 on
    /// x86-64): the same operations in the same order, each correctly
    /// rounded, so the same bits. Only the common case is taken, most of a
    /// frame: a previous frame, four surfaces or skies, each reprojected
    /// into it and static. Anything else (no surface, a dynamic pixel, a
    /// projection off the image, a row's last pixels) gives `None`, and the
    /// caller tracks the four one by one.
    ///
    /// Returns the track words and each pixel's position `p`, which every
    /// entry of a static pixel holds; flags in `seen` the previous pixels
    /// they land in.
    #[inline]
    fn track4(
        &self,
        x: usize,
        c0: usize,
        y: f32,
        seen: &SeenAgain,
    ) -> Option<([u32; LANES], [[f32; 4]; LANES])> {
        let prev = self.prev?;
        let depth: &[f32; LANES] = self.depth.get(x..)?.first_chunk()?;
        let motion: &[[f32; 2]; LANES] = self.motion.get(x..)?.first_chunk()?;
        let d = Vec4::from_array(*depth);
        // NaN fails too.
        if !d.cmpgt(Vec4::ZERO).all() {
            return None;
        }
        let sky = d.cmpeq(Vec4::INFINITY);
        let cam = self.camera;
        let c = c0 as f32;
        let cx = Vec4::new(c, c + 1.0, c + 2.0, c + 3.0) + 0.5;
        // `unproject`: the ray through each centre, then the point.
        let ray = Lanes3 {
            x: Vec4::splat(cam.ray[0]) + cx * cam.ray[1],
            y: Vec4::splat(cam.ray[2] + y * cam.ray[3]),
            z: Vec4::splat(-1.0),
        };
        let world = Lanes3::splat(cam.col0) * ray.x
            + Lanes3::splat(cam.col1) * ray.y
            + Lanes3::splat(cam.col2) * ray.z;
        let point = Lanes3::splat(cam.eye) + world * d;
        // A sky's direction (`normalize`) only where there is one: a
        // division and a square root saved in most groups.
        let p = match sky.any() {
            true => {
                let direction = world * (Vec4::ONE / world.dot(world).map(f32::sqrt));
                Lanes3::select(sky, direction, point)
            }
            false => point,
        };
        // The static test: `p` reprojected into the previous camera lands
        // within ε of where the motion points.
        let w = Vec4::select(sky, Vec4::splat(W_DIRECTION), Vec4::splat(W_POINT));
        let r = project4(&prev.camera, p, w);
        let target = (
            cx + Vec4::from_array(motion.map(|m| m[0])),
            Vec4::splat(y) + Vec4::from_array(motion.map(|m| m[1])),
        );
        let e = (r.x - target.0, r.y - target.1);
        let eps = Vec4::splat(self.epsilon * self.epsilon);
        if !(r.valid & (e.0 * e.0 + e.1 * e.1).cmple(eps)).all() {
            return None;
        }
        let mut words = [((self.k() - 1) as u32) << 2; LANES];
        let p = p.positions(w);
        if let Some(tolerance) = self.tolerance {
            let confirmed = self.confirm4(prev, w, &r, tolerance, seen);
            for (word, c) in words.iter_mut().zip(confirmed) {
                *word |= u32::from(c) << 1;
            }
        }
        Some((words, p))
    }

    /// [`agrees`] of four static positions with `w`s `kind` (see
    /// [`Tracker::track`]), seen from the previous camera as `seen` (the
    /// static test's projection), against the previous depth in the pixel
    /// each lands in; flags those pixels in `again` (seen where one
    /// agrees with a seed, unsure where it does not agree).
    #[inline]
    fn confirm4(
        &self,
        prev: &PrevHistory<'_>,
        kind: Vec4,
        seen: &Projected4,
        tolerance: f32,
        again: &SeenAgain,
    ) -> [bool; LANES] {
        let (pw, ph) = (prev.camera.width(), prev.camera.height());
        let found = cells(seen.x, seen.y, seen.valid, pw, ph);
        // The previous depth in the pixel each lands in (NaN, which
        // agrees with nothing, where it lands off the previous image).
        let before =
            Vec4::from_array(found.map(|j| j.map_or(f32::NAN, |j| prev.depth[j as usize])));
        // `agrees`, lane by lane.
        let sky = kind.cmpeq(Vec4::splat(W_DIRECTION));
        let was_sky = before.cmpeq(Vec4::INFINITY);
        let surface = before.cmplt(Vec4::INFINITY);
        let near = (seen.depth - before).abs().cmple(before * tolerance);
        let agrees = (sky & was_sky) | (!sky & surface & near);
        let agrees = agrees.bitmask();
        for (l, j) in found.into_iter().enumerate() {
            if let Some(j) = j {
                flag(prev, j as usize, agrees & 1 << l != 0, again);
            }
        }
        std::array::from_fn(|l| agrees & 1 << l != 0)
    }

    /// The history length in use.
    fn k(&self) -> usize {
        (self.k as usize).clamp(1, MAX_HISTORY)
    }

    /// Pixel `x` (centre `center`): its positions `P_0..P_{k−1}` into
    /// `entries[..k]` and its track word; all invalid (word 0) for an
    /// invalid depth (no position at all).
    /// Flags in `seen` the previous pixel it lands in, where it has one.
    #[allow(clippy::needless_range_loop)] // mirrors the shader's indexing
    #[inline]
    fn track(
        &self,
        x: usize,
        center: Vec2,
        entries: &mut [[f32; 4]; MAX_HISTORY],
        seen: &SeenAgain,
    ) -> u32 {
        let Self {
            camera,
            depth,
            motion,
            epsilon,
            tolerance,
            ..
        } = *self;
        let k = self.k();
        let d = depth[x];
        if d.is_nan() || d <= 0.0 {
            // Only the `k` entries in use are written (and stored).
            entries[..k].fill([0.0, 0.0, 0.0, W_INVALID]);
            return 0;
        }
        let p = camera.unproject(center, d);
        entries[..k].fill(p);
        let mut word = ((k - 1) as u32) << 2;
        if let Some(prev) = self.prev {
            let target = center + Vec2::from_array(motion[x]);
            let reprojected = prev.camera.project(p);
            let is_static = reprojected.is_some_and(|r| {
                let e = r.pixel - target;
                e.x * e.x + e.y * e.y <= epsilon * epsilon
            });
            let found =
                cell(target, prev.camera.width(), prev.camera.height(), 1.0).map(|j| j as usize);
            // Confirmed where the point lands in the previous frame; that
            // pixel flagged either way.
            if let Some(tolerance) = tolerance
                && let Some(r) = reprojected
                && let Some(j) = cell(r.pixel, prev.camera.width(), prev.camera.height(), 1.0)
            {
                let before = prev.depth[j as usize];
                let confirmed =
                    is_static && agrees(p[3] == W_DIRECTION, r.depth, before, tolerance);
                if confirmed {
                    word |= 2;
                }
                flag(prev, j as usize, confirmed, seen);
            }
            if !is_static {
                let mut len = 0usize;
                if let Some(j) = found {
                    let prev_word = prev.track[j];
                    let available = if is_dynamic(prev_word) {
                        chain(prev_word) as usize + 1
                    } else {
                        k - 1
                    };
                    let limit = available.min(k - 1);
                    for i in 1..=limit {
                        let q = History::position(prev.positions, prev.track, i - 1, j);
                        let q = rebase(q, shift(prev));
                        if q[3] != p[3] {
                            break;
                        }
                        entries[i] = q;
                        len = i;
                    }
                }
                for i in len + 1..k {
                    entries[i] = entries[i - 1];
                }
                word = 1 | (len as u32) << 2;
            }
        }
        word
    }
}

/// Flags pixel `j` of the previous frame, which a pixel of the current
/// frame lands in: seen where it was a seed and that pixel is
/// `confirmed` by it, unsure where that pixel is not confirmed.
#[inline]
fn flag(prev: &PrevHistory<'_>, j: usize, confirmed: bool, seen: &SeenAgain) {
    match confirmed {
        true if is_seed(prev.track[j]) => seen.set_seen(j),
        true => {}
        false => seen.set_unsure(j),
    }
}

/// The largest history length `k`.
pub const MAX_HISTORY: usize = 8;

fn shift(prev: &PrevHistory<'_>) -> glam::Vec3 {
    glam::Vec3::new(prev.camera.eye[0], prev.camera.eye[1], prev.camera.eye[2])
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    cur: PassCamera,
    prev: PassCamera,
    /// width, height, prev width, prev height
    sizes: [u32; 4],
    /// k, has_prev, 0, 0
    config: [u32; 4],
    /// epsilon, tolerance (negative: no confirmation), 0, 0
    epsilon: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuHistory {
    kernel: Kernel,
}

/// Buffers of one frame's history on the GPU.
#[derive(Debug)]
pub struct GpuHistoryBuffers<'a> {
    /// `k` planes of `vec4<f32>`.
    pub positions: &'a wgpu::Buffer,
    /// Track words.
    pub track: &'a wgpu::Buffer,
}

impl GpuHistory {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("history.wgsl"),
                "history",
                &[
                    Params, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, Read,
                    ReadWrite,
                ],
            ),
        }
    }

    /// Records Algorithm 1 for the current frame (its camera, depth and
    /// motion) into `out`, with the settings `k`, `ε` and the confirmation
    /// tolerance ([`Tracker`]'s). `prev` is the previous frame's camera,
    /// history and depth, or `None` after a reset (its buffers are then
    /// not read; the placeholder is bound in their place). `dynamic`
    /// receives the count of dynamic pixels (atomic add; clear it first),
    /// `seen` the [`SeenAgain`] flags, one `u32` per previous pixel (at
    /// least one element; cleared here).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (camera, depth, motion): (&PassCamera, &wgpu::Buffer, &wgpu::Buffer),
        prev: Option<(&PassCamera, GpuHistoryBuffers<'_>, &wgpu::Buffer)>,
        (out, dynamic, seen): (GpuHistoryBuffers<'_>, &wgpu::Buffer, &wgpu::Buffer),
        (k, epsilon, tolerance): (u32, f32, Option<f32>),
    ) {
        encoder.clear_buffer(seen, 0, None);
        let (w, h) = (camera.width(), camera.height());
        let (prev_cam, pw, ph) = match &prev {
            Some((c, ..)) => (**c, c.width(), c.height()),
            None => (*camera, 0, 0),
        };
        let params = ctx.params(bytemuck::bytes_of(&Params {
            cur: *camera,
            prev: prev_cam,
            sizes: [w, h, pw, ph],
            config: [k.max(1), u32::from(prev.is_some()), 0, 0],
            epsilon: [epsilon, tolerance.unwrap_or(-1.0), 0.0, 0.0],
        }));
        // Unused previous buffers are bound to the executor's placeholder
        // (read-only bindings cannot alias the written ones).
        let placeholder = ctx.placeholder();
        let (pp, pt, pd) = match &prev {
            Some((_, b, depth)) => (b.positions, b.track, *depth),
            None => (&placeholder, &placeholder, &placeholder),
        };
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &params,
                depth,
                motion,
                pp,
                pt,
                out.positions,
                out.track,
                dynamic,
                pd,
                seen,
            ],
            u64::from(w) * u64::from(h),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};
    use protocol::{Camera, FrameSize, Pose, Projection};

    /// Every pixel through [`Tracker::track`], one by one.
    fn one_by_one(t: &Tracker<'_>) -> History {
        let (n, k, w) = (t.depth.len(), t.k(), t.camera.width() as usize);
        let mut positions = vec![[0.0; 4]; k * n];
        let mut track = vec![0; n];
        let mut entries = [[0.0; 4]; MAX_HISTORY];
        let mut dynamic = 0;
        let mut seen = SeenAgain::default();
        let confirming = t.tolerance.is_some();
        seen.reset(t.prev.filter(|_| confirming).map_or(0, |p| p.track.len()));
        for x in 0..n {
            let center = Vec2::new((x % w) as f32 + 0.5, (x / w) as f32 + 0.5);
            track[x] = t.track(x, center, &mut entries, &seen);
            for (i, e) in entries[..k].iter().enumerate() {
                positions[i * n + x] = *e;
            }
            dynamic += u32::from(is_dynamic(track[x]));
        }
        History {
            positions,
            track,
            dynamic,
            seen,
        }
    }

    fn bits(h: &History) -> (Vec<[u32; 4]>, &[u32], u32, &SeenAgain) {
        let p = h.positions.iter().map(|p| p.map(f32::to_bits)).collect();
        (p, &h.track, h.dynamic, &h.seen)
    }

    /// A deterministic scramble of `i` into `0..1`.
    fn noise(i: usize, salt: u64) -> f32 {
        let mut v = (i as u64 ^ salt.rotate_left(17)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        v ^= v >> 29;
        v = v.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        ((v >> 40) as f32) / (1u64 << 24) as f32
    }

    /// The four-lane path gives the one-by-one path's bits, on frames that
    /// mix its common case with everything that leaves it: skies, no
    /// surface, NaN, dynamic pixels, targets off the previous image,
    /// previous positions that are directions, invalid or far off, and a
    /// width that leaves a partial group at each row's end.
    #[test]
    fn four_lanes_are_the_pixels_one_by_one() {
        let size = FrameSize {
            width: 67,
            height: 29,
        };
        let n = (size.width * size.height) as usize;
        let projection = Projection::perspective(1.0, 67.0 / 29.0, 0.1, f64::INFINITY);
        let origin = DVec3::new(1e4, -3.0, 20.0);
        let at = |eye: DVec3, yaw: f64| {
            let rotation = DQuat::from_rotation_y(yaw) * DQuat::from_rotation_x(-0.1);
            Camera::new(Pose::new(eye, rotation), projection)
        };
        let cur = at(origin, 0.02);
        let before = at(origin + DVec3::new(-0.15, 0.02, 0.1), 0.0);
        let camera = PassCamera::new(&cur, size, origin);
        let prev_own = PassCamera::new(&before, size, before.pose.position);
        let prev_camera = PassCamera::new(&before, size, origin);
        // A sky above, and specials scattered.
        let depth_at = |x: usize, salt: u64| match (noise(x, salt) * 40.0) as u32 {
            _ if x < 6 * 67 => f32::INFINITY,
            0 => 0.0,
            1 => f32::INFINITY,
            2 if salt == 1 => f32::NAN,
            // A smooth surface, so that a confirmation mostly agrees.
            _ => 3.0 + 2.0 * (x % 67) as f32 / 67.0 + (x / 67) as f32 / 29.0,
        };
        // The previous frame, tracked alone: every pixel static.
        let prev_depth: Vec<f32> = (0..n).map(|x| depth_at(x, 2)).collect();
        let still = vec![[0.0; 2]; n];
        for k in [1, 2, 4] {
            let mut prev = track(&prev_own, &prev_depth, &still, None, k, 0.5, 0.02);
            // Some previous positions a trajectory cannot use, or finds
            // elsewhere.
            for (x, p) in prev.positions.iter_mut().enumerate() {
                match (noise(x, 5) * 30.0) as u32 {
                    0 => p[3] = W_DIRECTION,
                    1 => p[3] = W_INVALID,
                    2 => p[2] += 3.0,
                    3 => p[0] = f32::NAN,
                    _ => {}
                }
            }
            // Most previous pixels seeds (confirmed static), as if tracked
            // after a frame of their own: a pixel that lands in one and
            // agrees sees it again, one that lands in another does not.
            for (x, word) in prev.track.iter_mut().enumerate() {
                if noise(x, 7) < 0.7 {
                    *word |= 2;
                }
            }
            // Some previous depths a confirmation cannot agree with: sky,
            // no surface, far off, NaN.
            let before: Vec<f32> = (prev_depth.iter().enumerate())
                .map(|(x, &d)| match (noise(x, 6) * 30.0) as u32 {
                    0 => f32::INFINITY,
                    1 => 0.0,
                    2 => d + 3.0,
                    3 => f32::NAN,
                    _ => d,
                })
                .collect();
            let depth: Vec<f32> = (0..n).map(|x| depth_at(x, 1)).collect();
            // Motion that is the camera's (static) for most pixels, off by
            // less or more than ε for some, far off the image for a few.
            let motion: Vec<[f32; 2]> = (0..n)
                .map(|x| {
                    let w = size.width as usize;
                    let c = Vec2::new((x % w) as f32 + 0.5, (x / w) as f32 + 0.5);
                    let p = camera.unproject(c, depth[x]);
                    let to = prev_camera.project(p).map_or(c, |r| r.pixel);
                    let off = match (noise(x, 3) * 20.0) as u32 {
                        0 => Vec2::new(2.0, -1.0),
                        1 => Vec2::new(0.3, 0.3),
                        2 => Vec2::new(-500.0, 0.0),
                        _ => Vec2::ZERO,
                    };
                    (to - c + off).to_array()
                })
                .collect();
            let prev = PrevHistory {
                camera: prev_camera,
                positions: &prev.positions,
                track: &prev.track,
                depth: &before,
            };
            for tolerance in [Some(0.02), None] {
                let t = Tracker {
                    camera: &camera,
                    depth: &depth,
                    motion: &motion,
                    prev: Some(&prev),
                    k,
                    epsilon: 0.5,
                    tolerance,
                };
                let fast = t.track_into(History::empty());
                let slow = one_by_one(&t);
                let whole = fast.clone().expanded();
                assert_eq!(bits(&whole), bits(&slow), "k = {k}, {tolerance:?}");
                // Both paths were taken, and both confirmation outcomes.
                let w = size.width as usize;
                let groups = (0..n)
                    .filter(|x| x % w % LANES == 0)
                    .filter(|&x| {
                        let seen = SeenAgain::default();
                        t.track4(x, x % w, (x / w) as f32 + 0.5, &seen).is_some()
                    })
                    .count();
                let all = size.height as usize * w.div_ceil(LANES);
                assert!(groups * 4 > all && groups < all, "{groups} of {all} groups");
                let confirmed = fast.track.iter().filter(|&&w| is_confirmed(w)).count();
                let seen = fast.seen.count();
                if tolerance.is_some() {
                    assert!(confirmed > n / 4 && confirmed < n * 3 / 4, "{confirmed}");
                    // Seeds both seen again and not.
                    assert!(seen > n / 8 && seen < confirmed, "{seen} of {confirmed}");
                } else {
                    assert!(fast.seen.is_empty());
                }
                assert!(fast.dynamic > 0);
            }
        }
    }

    /// `h`, the history of a frame of `depth` seen by `camera`, as the next
    /// frame continues it.
    fn seen_by<'a>(camera: PassCamera, h: &'a History, depth: &'a [f32]) -> PrevHistory<'a> {
        PrevHistory {
            camera,
            positions: &h.positions,
            track: &h.track,
            depth,
        }
    }

    /// Confirmation: a static point whose depth the previous frame had
    /// too (within the tolerance) is confirmed, as is sky; an object that
    /// came straight at the camera (the same screen position, no motion,
    /// nearer than before) passes the static test but is not confirmed.
    #[test]
    fn an_object_moving_along_its_rays_is_static_but_not_confirmed() {
        let size = FrameSize {
            width: 40,
            height: 24,
        };
        let (w, n) = (40usize, 40 * 24);
        let projection = Projection::perspective(1.0, 40.0 / 24.0, 0.1, f64::INFINITY);
        let origin = DVec3::new(2.0, 1.0, -3.0);
        let camera = Camera::new(Pose::new(origin, DQuat::from_rotation_y(0.3)), projection);
        let cam = PassCamera::new(&camera, size, origin);
        // The object: columns 8..20 of rows 6..18; sky: the first 2 rows;
        // a wall behind at 6, 1 % deeper now in columns 30.. (within the
        // 2 % tolerance).
        let object = |x: usize| (6..18).contains(&(x / w)) && (8..20).contains(&(x % w));
        let sky = |x: usize| x < 2 * w;
        let before: Vec<f32> = (0..n)
            .map(|x| {
                if sky(x) {
                    f32::INFINITY
                } else if object(x) {
                    4.0
                } else {
                    6.0
                }
            })
            .collect();
        let now: Vec<f32> = (0..n)
            .map(|x| match x {
                _ if sky(x) => f32::INFINITY,
                _ if object(x) => 3.0,
                _ if x % w >= 30 => 6.06,
                _ => 6.0,
            })
            .collect();
        let still = vec![[0.0; 2]; n];
        let first = track(&cam, &before, &still, None, 2, 0.5, 0.02);
        let h = track(
            &cam,
            &now,
            &still,
            Some(seen_by(cam, &first, &before)),
            2,
            0.5,
            0.02,
        );
        assert_eq!(h.dynamic, 0, "the object keeps its screen position");
        for (x, &word) in h.track.iter().enumerate() {
            assert_eq!(is_confirmed(word), !object(x), "pixel {x}");
        }
        // The previous frame had no seeds: nothing is seen again.
        assert_eq!((h.seen.len(), h.seen.count()), (n, 0));
        // The next frame: the object stays where it is now, and a new one
        // appears in front of the wall (columns 32..36 of rows 3..10).
        // The camera stays, so each pixel lands in itself: every seed of
        // `h` is skipped except where the new object hides it (its pixels
        // are not confirmed), and the object's pixels, confirmed now,
        // were no seeds.
        let new = |x: usize| (3..10).contains(&(x / w)) && (32..36).contains(&(x % w));
        let later: Vec<f32> = (0..n).map(|x| if new(x) { 2.0 } else { now[x] }).collect();
        let prev = seen_by(cam, &h, &now);
        let again = track(&cam, &later, &still, Some(prev), 2, 0.5, 0.02);
        assert_eq!(again.seen.len(), n);
        // The new object's pixels, not confirmed, leave theirs unsure.
        for (x, word) in again.seen.words().into_iter().enumerate() {
            let seed = is_seed(h.track[x]);
            assert_eq!(word & 2 != 0, new(x), "pixel {x}");
            assert_eq!(again.seen.skips(x), seed && !new(x), "pixel {x}");
            assert_eq!(is_confirmed(again.track[x]), !new(x), "pixel {x}");
        }
    }
}
