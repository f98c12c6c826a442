//! The deterministic depth test shared by every forward splat (DESIGN §4
//! step 4; GFFE §4.1 "Warping"): the warp, background collection (GFFE §4.2
//! case 1 / case 2) and background projection.
//!
//! A projecting pass first writes one [`Candidate`] per source element: the
//! slot it lands in and a depth key. Two kernels then pick, per slot, the
//! nearest candidate:
//!
//! 1. `splat_key`: `atomicMax(keys[slot], key)` with `key = !bits(depth)`.
//!    Positive `f32` bit patterns order like the values, so the largest key
//!    is the smallest depth, `+inf` (sky) loses to everything finite, and 0
//!    (the value `clear_buffer` leaves) means "empty".
//! 2. `splat_index`: every candidate whose key equals the slot's winning key
//!    does `atomicMax(index[slot], !i)`, so among equal depths the smallest
//!    source index wins.
//!
//! Both steps are order-independent, so the result is the same under any
//! thread schedule, and [`resolve`] (the CPU reference) reproduces it
//! exactly from the same candidates.

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::lanes::LANES;

/// Fewest candidates a band of [`resolve_lanes`]' banded splat takes (50
/// rows of a 1280-pixel frame: a candidate that moves fewer rows than
/// that lands in its own band, or the next).
const MIN_BAND: usize = 64 * 1024;

/// "No slot" / "no winner".
pub const NONE: u32 = u32::MAX;

/// One source element's landing slot and depth key (WGSL `vec2<u32>`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Candidate {
    /// Slot index, or [`NONE`] when the element lands nowhere.
    pub slot: u32,
    /// [`depth_key`] of the element's depth at the slot.
    pub key: u32,
}

impl Candidate {
    /// A candidate that lands nowhere.
    pub const MISS: Candidate = Candidate { slot: NONE, key: 0 };
}

/// The splat key of a positive depth: larger is nearer, never 0.
pub fn depth_key(depth: f32) -> u32 {
    !depth.to_bits()
}

/// The depth a key was made from.
pub fn key_depth(key: u32) -> f32 {
    f32::from_bits(!key)
}

/// The winners of a splat. Per slot, the GPU's two words packed into one:
/// the winning key in the high half and `!index` of the winning candidate in
/// the low half (0 = empty), so that one maximum picks both.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Winners {
    /// The first slot of the range resolved.
    base: usize,
    packed: Vec<u64>,
}

impl Winners {
    /// Index of the candidate that won `slot`, or `None`.
    pub fn winner(&self, slot: usize) -> Option<usize> {
        match self.stored(slot) {
            0 => None,
            s => Some(!s as usize),
        }
    }

    /// Depth of the winner of `slot`, or `None`.
    pub fn depth(&self, slot: usize) -> Option<f32> {
        let key = self.key(slot);
        (key != 0).then(|| key_depth(key))
    }

    /// The winning key of `slot` as the `splat_key` kernel leaves it (0 when
    /// empty).
    pub fn key(&self, slot: usize) -> u32 {
        (self.get(slot) >> 32) as u32
    }

    /// `!index` of the winner of `slot` as the `splat_index` kernel leaves
    /// it (0 when empty).
    pub fn stored(&self, slot: usize) -> u32 {
        self.get(slot) as u32
    }

    /// The packed word of `slot` (0 outside the range resolved).
    fn get(&self, slot: usize) -> u64 {
        slot.checked_sub(self.base)
            .and_then(|i| self.packed.get(i))
            .copied()
            .unwrap_or(0)
    }
}

/// CPU reference of the two splat kernels.
///
/// One maximum per candidate over `key << 32 | !index`: the largest key
/// wins, and among equal keys the largest `!index`, i.e. the smallest
/// index, which is what the kernels' two rounds pick. A maximum does not
/// depend on the order it is taken in, so the winners are the same for any
/// thread count. It is taken atomically, except where a band of candidates
/// owns the slots it lands in ([`resolve_lanes`]); a candidate that cannot
/// beat the slot's current value (most of them, where surfaces overlap)
/// skips the write.
pub fn resolve(candidates: &[Candidate], slots: usize) -> Winners {
    resolve_in(candidates, 0..slots)
}

/// [`resolve`] for the slots of `range` only (candidates landing elsewhere
/// are ignored): what the kernels leave in those slots, for a pass whose
/// candidates can only land there (a level of the background layers).
pub fn resolve_in(candidates: &[Candidate], range: std::ops::Range<usize>) -> Winners {
    resolve_with(candidates.len(), range, |i| candidates[i])
}

/// [`resolve_in`] over `count` candidates made on the fly by `candidate`
/// (the CPU executor's fused passes: no frame-sized candidate buffer is
/// written and read back). The same winners as resolving the collected
/// candidates.
pub fn resolve_with(
    count: usize,
    range: std::ops::Range<usize>,
    candidate: impl Fn(usize) -> Candidate + Sync,
) -> Winners {
    resolve_lanes(count, range, |i| {
        std::array::from_fn(|l| match i + l < count {
            true => candidate(i + l),
            false => Candidate::MISS,
        })
    })
}

/// [`resolve_with`] over the candidates of the listed `elements` only,
/// every other element landing nowhere (the same winners): the plain
/// reference of [`Sparse::take_listed`], which background fill takes its
/// carried fragments with.
pub fn resolve_listed(
    elements: &[u32],
    range: std::ops::Range<usize>,
    candidate: impl Fn(usize) -> Candidate + Sync + Send,
) -> Winners {
    use rayon::prelude::*;
    let slots = Slots::new(range);
    elements
        .par_iter()
        .with_min_len(1024)
        .for_each(|&i| slots.take(i as usize, candidate(i as usize)));
    slots.winners()
}

/// Where `slot` is in the `len` slots from `start`, if it is.
#[inline]
fn within(start: usize, len: usize, slot: usize) -> Option<usize> {
    slot.checked_sub(start).filter(|&s| s < len)
}

/// The packed words of a range of slots as the atomic maximum of each
/// builds them ([`resolve_lanes`], [`resolve_listed`]).
struct Slots {
    range: std::ops::Range<usize>,
    packed: Vec<std::sync::atomic::AtomicU64>,
}

impl Slots {
    /// Every slot of `range` empty, cleared on all cores.
    fn new(range: std::ops::Range<usize>) -> Self {
        use rayon::prelude::*;
        let packed = range
            .clone()
            .into_par_iter()
            .with_min_len(4096)
            .map(|_| std::sync::atomic::AtomicU64::new(0))
            .collect();
        Self { range, packed }
    }

    /// Candidate `i`'s word, `key << 32 | !i`: the largest is the nearest,
    /// then the smallest index.
    #[inline]
    fn value(i: usize, c: Candidate) -> u64 {
        (u64::from(c.key) << 32) | u64::from(!(i as u32))
    }

    /// Index of the slot `c` lands in, if it is in the range.
    #[inline]
    fn index(&self, c: Candidate) -> Option<usize> {
        within(self.range.start, self.packed.len(), c.slot as usize)
    }

    /// Candidate `i` taken into its slot with the atomic maximum (no write
    /// where it cannot win, most of them where surfaces overlap).
    #[inline]
    fn take(&self, i: usize, c: Candidate) {
        if let Some(slot) = self.index(c).map(|s| &self.packed[s]) {
            Self::take_word(slot, Self::value(i, c));
        }
    }

    /// `v` into `slot` with the atomic maximum, read first: no write where
    /// it cannot win, most of them where surfaces overlap.
    #[inline]
    fn take_word(slot: &std::sync::atomic::AtomicU64, v: u64) {
        use std::sync::atomic::Ordering::Relaxed;
        if v > slot.load(Relaxed) {
            slot.fetch_max(v, Relaxed);
        }
    }

    /// The winners, in place (same layout), without a second frame-sized
    /// allocation.
    fn winners(self) -> Winners {
        let packed = self.packed.into_iter().map(|v| v.into_inner()).collect();
        Winners {
            base: self.range.start,
            packed,
        }
    }
}

/// [`resolve_with`] with the candidates made [`LANES`] at a time:
/// `candidates(i)` gives those of elements `i .. i + LANES` (`i` a multiple
/// of `LANES`), for a pass that projects four at once (`lanes.rs`); those
/// past `count` are ignored. The same winners.
pub fn resolve_lanes(
    count: usize,
    range: std::ops::Range<usize>,
    candidates: impl Fn(usize) -> [Candidate; LANES] + Sync,
) -> Winners {
    use rayon::prelude::*;
    use std::sync::atomic::Ordering::Relaxed;
    let slots = Slots::new(range);
    let packed = &slots.packed;
    if count == packed.len() && count >= 2 * MIN_BAND {
        // One candidate per slot, most landing near their own index (a
        // warp of a frame into a frame of its size): each band of
        // candidates has the band of slots of its own indices to itself
        // first, and takes them with a plain load and store; what lands
        // in another band's slots is taken after every band is done,
        // with the atomic maximum. The same maxima.
        let bands = 4 * rayon::current_num_threads();
        let band = count.div_ceil(bands).max(MIN_BAND).next_multiple_of(LANES);
        let elsewhere: Vec<Vec<(usize, Candidate)>> = (0..count.div_ceil(band))
            .into_par_iter()
            .with_max_len(1)
            .map(|b| {
                let own = b * band..((b + 1) * band).min(count);
                let mut elsewhere = Vec::new();
                for first in own.clone().step_by(LANES) {
                    for (i, c) in (first..count).zip(candidates(first)) {
                        let Some(s) = slots.index(c) else {
                            continue;
                        };
                        let v = Slots::value(i, c);
                        if !own.contains(&s) {
                            elsewhere.push((i, c));
                        } else if v > packed[s].load(Relaxed) {
                            packed[s].store(v, Relaxed);
                        }
                    }
                }
                elsewhere
            })
            .collect();
        elsewhere.par_iter().for_each(|landed| {
            for &(i, c) in landed {
                slots.take(i, c);
            }
        });
    } else {
        let groups = count.div_ceil(LANES);
        (0..groups)
            .into_par_iter()
            .with_min_len(1024)
            .with_max_len(4096)
            .for_each(|g| {
                let first = g * LANES;
                for (i, c) in (first..count).zip(candidates(first)) {
                    slots.take(i, c);
                }
            });
    }
    slots.winners()
}

/// Slots for splats where few candidates land ([`Sparse::resolve`]),
/// kept empty between splats: one clears and reads only the slots its
/// candidates land in, not its whole range. Background collection is
/// such a splat: at 720p (default scene) 8.9 k of 906 k previous level-0
/// fragments land, in 1.15 M slots, which dense slots cleared (9.2 MB)
/// and scanned for winners each frame.
#[derive(Debug, Default)]
pub struct Sparse {
    packed: Vec<std::sync::atomic::AtomicU64>,
    /// Whether a splat stopped before emptying its slots (a panic): the
    /// next one clears them all first.
    dirty: bool,
}

impl Sparse {
    /// Candidates a block of [`Sparse::resolve`] lists at most; past
    /// that, its slots are read and emptied whole, as dense slots are.
    const LISTED: usize = Self::BLOCK / 16;
    /// Candidates per block.
    const BLOCK: usize = 1024 * LANES;

    /// The winners of [`resolve_lanes`] over the same candidates, as
    /// `(slot, index of the winning candidate)` for each slot of `range`
    /// that one lands in, ascending by slot.
    ///
    /// Every candidate that lands is taken with the atomic maximum (as
    /// [`resolve_lanes`] does) and listed where it is made; the winner of
    /// a slot is the one listed candidate whose word the slot holds at the
    /// end (each word is unique: it holds the candidate's index), and the
    /// listed slots are emptied again. Where many land (a block lists
    /// more than [`Sparse::LISTED`]: after a restart of the history, the
    /// whole previous background lands on an empty level 0), the slots
    /// are scanned and emptied whole instead: the same winners.
    pub fn resolve(
        &mut self,
        count: usize,
        range: std::ops::Range<usize>,
        candidates: impl Fn(usize) -> [Candidate; LANES] + Sync,
    ) -> Vec<(u32, u32)> {
        use rayon::prelude::*;
        use std::sync::atomic::Ordering::Relaxed;
        let len = range.len();
        let packed = self.ready(len);
        let slot = |c: Candidate| within(range.start, len, c.slot as usize);
        // The landed candidates, (slot in the range, word), in the order
        // of their indices whatever the split; `None` for a block that
        // had more.
        let block = Self::BLOCK;
        let landed: Vec<Option<Vec<(u32, u64)>>> = (0..count.div_ceil(block))
            .into_par_iter()
            .with_max_len(1)
            .map(|b| {
                let mut listed = Vec::new();
                let mut all = true;
                for first in (b * block..((b + 1) * block).min(count)).step_by(LANES) {
                    for (i, c) in (first..count).zip(candidates(first)) {
                        if let Some(s) = slot(c) {
                            let v = Slots::value(i, c);
                            Slots::take_word(&packed[s], v);
                            all &= listed.len() < Self::LISTED;
                            if all {
                                listed.push((s as u32, v));
                            }
                        }
                    }
                }
                all.then_some(listed)
            })
            .collect();
        let won = match landed.into_iter().collect::<Option<Vec<_>>>() {
            Some(lists) => {
                let mut won: Vec<(u32, u32)> = (lists.par_iter())
                    .flat_map_iter(|listed| {
                        listed
                            .iter()
                            .filter(|&&(s, v)| packed[s as usize].load(Relaxed) == v)
                            .map(|&(s, v)| ((range.start + s as usize) as u32, !(v as u32)))
                    })
                    .collect();
                lists.par_iter().for_each(|listed| {
                    for &(s, _) in listed.iter() {
                        packed[s as usize].store(0, Relaxed);
                    }
                });
                // Each slot once (one word wins it); mostly ascending
                // already.
                won.par_sort_unstable();
                won
            }
            // Nothing else holds the slots now: each read and emptied with
            // a plain load and store (a swap is a locked instruction).
            None => {
                let slots = self.packed[..len].par_iter_mut().enumerate();
                (slots.with_min_len(4096))
                    .filter_map(|(s, v)| match std::mem::take(v.get_mut()) {
                        0 => None,
                        v => Some(((range.start + s) as u32, !(v as u32))),
                    })
                    .collect()
            }
        };
        self.dirty = false;
        won
    }

    /// [`resolve_listed`] into these slots, which stay taken until the
    /// answer is dropped: it gives each slot's winner (as [`Winners`]
    /// does) from them, for a pass that looks its slots up pixel by pixel
    /// (background fill: a few thousand candidates, 1.15 M slots at 720p,
    /// which dense slots cleared and converted each frame, 0.5 ms).
    ///
    /// `candidates(ids)` gives the candidates of the elements `ids`,
    /// [`LANES`] listed ones at a time, for a pass that projects four at
    /// once (`lanes.rs`); the last `ids` repeat the last element where
    /// fewer are left (the same word twice takes its slot once).
    pub fn take_listed(
        &mut self,
        elements: &[u32],
        range: std::ops::Range<usize>,
        candidates: impl Fn([usize; LANES]) -> [Candidate; LANES] + Sync + Send,
    ) -> Taken<'_> {
        use rayon::prelude::*;
        let len = range.len();
        let packed = self.ready(len);
        let take = |ids: &[u32], landed: &mut dyn FnMut(u32)| {
            let ids = std::array::from_fn(|k| ids[k.min(ids.len() - 1)] as usize);
            for (i, c) in ids.into_iter().zip(candidates(ids)) {
                if let Some(s) = within(range.start, len, c.slot as usize) {
                    Slots::take_word(&packed[s], Slots::value(i, c));
                    landed(s as u32);
                }
            }
        };
        let groups = elements.par_chunks(LANES).with_min_len(256);
        // Where many are listed (after a restart of the history, the
        // whole previous background), the slots are emptied whole, as
        // dense slots are made, rather than one by one.
        let landed: Option<Vec<Vec<u32>>> = match elements.len() <= len / 8 {
            true => Some(
                groups
                    .fold(Vec::new, |mut listed, ids| {
                        take(ids, &mut |s| listed.push(s));
                        listed
                    })
                    .collect(),
            ),
            false => {
                groups.for_each(|ids| take(ids, &mut |_| ()));
                None
            }
        };
        Taken {
            sparse: self,
            start: range.start,
            len,
            landed,
        }
    }

    /// The first `len` slots, every one empty; marked taken until a splat
    /// empties them again.
    fn ready(&mut self, len: usize) -> &[std::sync::atomic::AtomicU64] {
        use rayon::prelude::*;
        if self.dirty || self.packed.len() < len {
            let kept = self.packed.len().max(len);
            self.packed = (0..kept)
                .into_par_iter()
                .with_min_len(4096)
                .map(|_| std::sync::atomic::AtomicU64::new(0))
                .collect();
        }
        self.dirty = true;
        &self.packed[..len]
    }
}

/// The winners of [`Sparse::take_listed`], in its slots; dropping it
/// empties them.
#[derive(Debug)]
pub struct Taken<'a> {
    sparse: &'a mut Sparse,
    start: usize,
    len: usize,
    /// The slots (in the range) candidates landed in; `None`: any of
    /// the range.
    landed: Option<Vec<Vec<u32>>>,
}

impl Taken<'_> {
    /// The winner of `slot`, `(depth, index)`, as [`Winners::depth`] and
    /// [`Winners::winner`] give it; `None` for an empty slot or one outside
    /// the range.
    #[inline]
    pub fn get(&self, slot: usize) -> Option<(f32, usize)> {
        use std::sync::atomic::Ordering::Relaxed;
        let s = within(self.start, self.len, slot)?;
        match self.sparse.packed[s].load(Relaxed) {
            0 => None,
            v => Some((key_depth((v >> 32) as u32), !(v as u32) as usize)),
        }
    }
}

impl Drop for Taken<'_> {
    fn drop(&mut self) {
        use rayon::prelude::*;
        use std::sync::atomic::Ordering::Relaxed;
        let packed = &self.sparse.packed[..self.len];
        match &self.landed {
            Some(landed) => landed.par_iter().for_each(|listed| {
                for &s in listed {
                    packed[s as usize].store(0, Relaxed);
                }
            }),
            None => (packed.par_iter().with_min_len(4096)).for_each(|v| v.store(0, Relaxed)),
        }
        self.sparse.dirty = false;
    }
}

/// Parameters of the splat kernels.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    count: u32,
    slots: u32,
    _pad: [u32; 2],
}

/// The GPU splat: two kernels over a candidate buffer.
#[derive(Debug)]
pub struct GpuSplat {
    key: Kernel,
    index: Kernel,
}

const BINDINGS: &[Binding] = &[
    Binding::Params,
    Binding::Read,
    Binding::ReadWrite,
    Binding::ReadWrite,
];

impl GpuSplat {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("splat.wgsl");
        Self {
            key: Kernel::new(ctx, src, "splat_key", BINDINGS),
            index: Kernel::new(ctx, src, "splat_index", BINDINGS),
        }
    }

    /// Records the splat of `count` candidates into `slots` slots (their
    /// `keys` and `index`, cleared first).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (candidates, count): (&wgpu::Buffer, u64),
        (keys, index, slots): (&wgpu::Buffer, &wgpu::Buffer, u64),
    ) {
        encoder.clear_buffer(keys, 0, Some(slots * 4));
        encoder.clear_buffer(index, 0, Some(slots * 4));
        let params = ctx.params(bytemuck::bytes_of(&Params {
            count: count as u32,
            slots: slots as u32,
            _pad: [0; 2],
        }));
        let buffers = [&params, candidates, keys, index];
        self.key.dispatch(ctx, encoder, &buffers, count);
        self.index.dispatch(ctx, encoder, &buffers, count);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_wins_and_ties_go_to_the_smallest_index() {
        let c = |slot, d: f32| Candidate {
            slot,
            key: depth_key(d),
        };
        let cands = [
            c(0, 5.0),
            c(0, 2.0),
            c(0, 2.0),
            c(1, f32::INFINITY),
            c(1, 1e30),
            Candidate::MISS,
            c(2, f32::INFINITY),
        ];
        let w = resolve(&cands, 4);
        assert_eq!(w.winner(0), Some(1));
        assert_eq!(w.depth(0), Some(2.0));
        assert_eq!(w.winner(1), Some(4));
        assert_eq!(w.winner(2), Some(6));
        assert_eq!(w.depth(2), Some(f32::INFINITY));
        assert_eq!(w.winner(3), None);
    }

    #[test]
    fn keys_order_like_depths() {
        let depths = [1e-30f32, 1e-6, 0.5, 1.0, 1e7, f32::MAX, f32::INFINITY];
        for pair in depths.windows(2) {
            assert!(depth_key(pair[0]) > depth_key(pair[1]));
            assert_ne!(depth_key(pair[1]), 0);
            assert_eq!(key_depth(depth_key(pair[0])), pair[0]);
        }
    }

    /// One candidate per slot, as many as the banded splat takes: the
    /// same winners as the atomic maximum of each slot one by one, for
    /// candidates that land in their own band, in others, far away,
    /// nowhere and outside the range, with ties between bands.
    #[test]
    fn the_banded_splat_finds_every_slot_s_nearest() {
        let n = 3 * MIN_BAND + 123;
        let noise = |i: usize| (i as f32 * 0.618_034).fract();
        let candidate = |i: usize| -> Candidate {
            let slot = match i % 11 {
                0 => NONE,
                1 => (n + i) as u32,
                2 => ((i * 7919) % n) as u32,
                3..=5 => (i as i64 + (noise(i) * 4000.0) as i64 - 2000).rem_euclid(n as i64) as u32,
                _ => i as u32,
            };
            let depth = [1.0, 2.0, 1.0 + noise(i * 3)][i % 3];
            Candidate {
                slot,
                key: depth_key(depth),
            }
        };
        let banded = resolve_with(n, 0..n, candidate);
        let mut expected = vec![0u64; n];
        for i in 0..n {
            let c = candidate(i);
            if let Some(e) = expected.get_mut(c.slot as usize) {
                *e = (*e).max(u64::from(c.key) << 32 | u64::from(!(i as u32)));
            }
        }
        for (s, &e) in expected.iter().enumerate() {
            assert_eq!(banded.get(s), e, "slot {s}");
        }
        assert!(expected.iter().filter(|&&e| e != 0).count() > n / 2);
    }

    /// The listed splat finds what the dense one finds over the same
    /// elements, and so do sparse slots taken from the list (in turn on
    /// the same slots: dropping the answer empties them): over listed
    /// candidates that miss, land outside the range, tie, and land in the
    /// same slots from far apart.
    #[test]
    fn the_listed_splat_finds_what_the_dense_one_finds() {
        let n = 50_000;
        let candidate = |i: usize| match i % 29 {
            0 => Candidate {
                slot: (i % 97) as u32 + 100,
                key: depth_key([1.0, 2.0][i % 2]),
            },
            1 => Candidate {
                slot: 10_000,
                key: depth_key(3.0),
            },
            2 => Candidate {
                slot: (i % 50) as u32,
                key: depth_key(1.0),
            },
            _ => Candidate::MISS,
        };
        // Most of those that land, and some that miss; not the others.
        let listed = |i: usize| (i % 29 < 3 && i % 7 != 0) || i % 31 == 0;
        let elements: Vec<u32> = (0..n as u32).filter(|&i| listed(i as usize)).collect();
        let range = 90..260;
        let only = |i: usize| match listed(i) {
            true => candidate(i),
            false => Candidate::MISS,
        };
        let dense = resolve_with(n, range.clone(), only);
        assert_eq!(resolve_listed(&elements, range.clone(), candidate), dense);
        let mut sparse = Sparse::default();
        // Few for 60 k slots (listed), then so many for 20 slots that they
        // are emptied whole, then listed again.
        for range in [0..60_000, 100..120, 90..60_000] {
            let dense = resolve_with(n, range.clone(), only);
            let four = |ids: [usize; LANES]| ids.map(candidate);
            let taken = sparse.take_listed(&elements, range.clone(), four);
            for s in 0..60_100 {
                let expected = dense.depth(s).zip(dense.winner(s));
                assert_eq!(taken.get(s), expected, "slot {s}");
            }
        }
        let empty =
            |v: &std::sync::atomic::AtomicU64| v.load(std::sync::atomic::Ordering::Relaxed) == 0;
        assert!(sparse.packed.iter().all(empty) && !sparse.dirty);
        let won = |w: &Winners| range.clone().filter(|&s| w.winner(s).is_some()).count();
        assert!(won(&dense) > 90);
        // The unlisted ones would have won some of the slots.
        assert_ne!(resolve_with(n, range.clone(), candidate), dense);
    }

    /// The sparse splat gives the dense one's winners, each slot once,
    /// ascending, and leaves its slots empty: splats in turn on one set of
    /// slots (one after a splat that stopped half-way), where few land
    /// (listed) or many (more than a block lists), over candidates that
    /// miss, land outside the range, tie, crowd into few slots or spread
    /// over many, and counts that are not whole lanes.
    #[test]
    fn the_sparse_splat_finds_what_the_dense_one_finds() {
        let noise = |i: usize| (i as f32 * 0.618_034).fract();
        let mut slots = Sparse::default();
        // (candidates, slots spread over, one in `every` lands at most)
        let rounds = [
            (40_003, 50, 1),
            (100_001, 90_000, 29),
            (50_001, 500, 40),
            (7_777, 3_000, 1),
        ];
        for (round, (count, spread, every)) in rounds.into_iter().enumerate() {
            let range = 1_000..1_000 + 60_000;
            let candidate = |i: usize| -> Candidate {
                let slot = match (i + round) % 7 {
                    _ if (i * 7919) % every != 0 => NONE,
                    0 => NONE,
                    1 => 500 + (i % 700) as u32,
                    _ => 1_000 + ((noise(i * 3) * spread as f32) as u32 * 13) % 61_000,
                };
                let depth = [1.0, 2.0, 1.0 + noise(i)][i % 3];
                Candidate {
                    slot,
                    key: depth_key(depth),
                }
            };
            let lanes = |first: usize| {
                std::array::from_fn(|l| match first + l < count {
                    true => candidate(first + l),
                    false => Candidate::MISS,
                })
            };
            if round == 3 {
                // A splat that stopped half-way leaves words behind.
                slots.dirty = true;
                slots.packed[5].store(u64::MAX, std::sync::atomic::Ordering::Relaxed);
            }
            let won = slots.resolve(count, range.clone(), lanes);
            let dense = resolve_with(count, range.clone(), candidate);
            let expected: Vec<(u32, u32)> = range
                .clone()
                .filter_map(|s| Some((s as u32, dense.winner(s)? as u32)))
                .collect();
            assert!(expected.len() > 40, "round {round}: {}", expected.len());
            assert_eq!(won, expected, "round {round}");
            assert!(
                slots
                    .packed
                    .iter()
                    .all(|v| v.load(std::sync::atomic::Ordering::Relaxed) == 0)
            );
            assert!(!slots.dirty);
        }
    }
}
