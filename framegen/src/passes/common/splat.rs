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

use crate::gpu::{Binding, GpuContext, Kernel};

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

/// The winners of a splat, in the GPU's storage form (0 = empty).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Winners {
    /// Per slot: the winning key, 0 when empty.
    pub keys: Vec<u32>,
    /// Per slot: `!index` of the winning candidate, 0 when empty.
    pub stored: Vec<u32>,
}

impl Winners {
    /// Index of the candidate that won `slot`, or `None`.
    pub fn winner(&self, slot: usize) -> Option<usize> {
        match self.stored[slot] {
            0 => None,
            s => Some(!s as usize),
        }
    }

    /// Depth of the winner of `slot`, or `None`.
    pub fn depth(&self, slot: usize) -> Option<f32> {
        (self.keys[slot] != 0).then(|| key_depth(self.keys[slot]))
    }
}

/// CPU reference of the two splat kernels.
///
/// Runs on all cores with atomic maxima, as the kernels do: a maximum does
/// not depend on the order it is taken in, so the winners are the same for
/// any thread count.
pub fn resolve(candidates: &[Candidate], slots: usize) -> Winners {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
    let zeroed = || {
        (0..slots)
            .into_par_iter()
            .map(|_| AtomicU32::new(0))
            .collect::<Vec<_>>()
    };
    let keys = zeroed();
    candidates.par_iter().for_each(|c| {
        if let Some(k) = keys.get(c.slot as usize) {
            k.fetch_max(c.key, Relaxed);
        }
    });
    let keys: Vec<u32> = keys.into_par_iter().map(AtomicU32::into_inner).collect();
    let stored = zeroed();
    candidates.par_iter().enumerate().for_each(|(i, c)| {
        let slot = c.slot as usize;
        if slot < slots && keys[slot] == c.key {
            stored[slot].fetch_max(!(i as u32), Relaxed);
        }
    });
    let stored = stored.into_par_iter().map(AtomicU32::into_inner).collect();
    Winners { keys, stored }
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
    Binding::Uniform,
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

    /// Records the splat of `count` candidates into `slots` slots. `keys`
    /// and `index` are cleared first.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        candidates: &wgpu::Buffer,
        count: u64,
        keys: &wgpu::Buffer,
        index: &wgpu::Buffer,
        slots: u64,
    ) {
        encoder.clear_buffer(keys, 0, Some(slots * 4));
        encoder.clear_buffer(index, 0, Some(slots * 4));
        let params = ctx.uniform(bytemuck::bytes_of(&Params {
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
}
