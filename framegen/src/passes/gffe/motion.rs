//! Position estimation, GFFE eq. 1 (DESIGN §4 step 2):
//! `NP_{t→t+α}[x] = P_0[x] + α (P_0[x] − P_1[x])`.
//!
//! With a history longer than two (`k > 2`) the velocity is the mean over the
//! pixel's real chain, `(P_0 − P_m) / m` with `m` = the chain length of the
//! track word (see `history.rs`); for `k = 2` this is exactly eq. 1, and a
//! broken chain falls back to the longest real part. Static pixels, sky
//! directions and pixels without history keep `P_0`.
//!
//! Positions stay relative to the current camera centre; the warp projects
//! them with the target camera given relative to the same centre.

use glam::Vec3;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::W_POINT;
use crate::passes::gffe::history::{GpuHistoryBuffers, MAX_HISTORY, chain, is_dynamic};

/// Eq. 1 for one pixel. `planes` are `P_0..P_{k−1}` of the pixel.
pub fn estimate_pixel(planes: &[[f32; 4]], track: u32, alpha: f32) -> [f32; 4] {
    let p0 = planes[0];
    match moving_chain(p0, track, planes.len()) {
        Some(m) => extrapolate(p0, planes[m], m, alpha),
        None => p0,
    }
}

/// CPU reference: next positions of every pixel. `positions` holds `k`
/// planes of `n` pixels.
pub fn estimate(positions: &[[f32; 4]], track: &[u32], k: u32, alpha: f32) -> Vec<[f32; 4]> {
    use rayon::prelude::*;
    (0..track.len())
        .into_par_iter()
        .map(|x| estimate_at(positions, track, k, x, alpha))
        .collect()
}

/// Eq. 1 for pixel `x` of `k` planes of `track.len()` positions: one
/// element of [`estimate`], for a pass that uses the position at α at once
/// (the CPU executor's warp) instead of storing it. Reads `P_0` and, for a
/// dynamic pixel only, `P_m` (a static pixel's planes would repeat `P_0`,
/// and the CPU executor's history does not store them): the
/// same result as [`estimate_pixel`] over all `k` planes, at half the
/// bytes read per pixel for `k = 2`.
#[inline]
pub fn estimate_at(
    positions: &[[f32; 4]],
    track: &[u32],
    k: u32,
    x: usize,
    alpha: f32,
) -> [f32; 4] {
    let n = track.len();
    let k = (k.max(1) as usize).min(MAX_HISTORY);
    let p0 = positions[x];
    match moving_chain(p0, track[x], k) {
        Some(m) => extrapolate(p0, positions[m * n + x], m, alpha),
        None => p0,
    }
}

/// The chain length `m` that eq. 1 reads `P_m` at, or `None` where the pixel
/// keeps `P_0`: static, no chain, a chain past the `k` planes held, or a
/// `P_0` that is not a point (a sky direction or no depth).
#[inline]
fn moving_chain(p0: [f32; 4], track: u32, k: usize) -> Option<usize> {
    let m = chain(track) as usize;
    (is_dynamic(track) && m != 0 && m < k && p0[3] == W_POINT).then_some(m)
}

/// Eq. 1 from `P_0` (a point) and `P_m`, `m` intervals apart; keeps `P_0`
/// where `P_m` is not a point.
#[inline]
fn extrapolate(p0: [f32; 4], pm: [f32; 4], m: usize, alpha: f32) -> [f32; 4] {
    if pm[3] != W_POINT {
        return p0;
    }
    let a = Vec3::new(p0[0], p0[1], p0[2]);
    let b = Vec3::new(pm[0], pm[1], pm[2]);
    let velocity = (a - b) / m as f32;
    let np = a + velocity * alpha;
    [np.x, np.y, np.z, W_POINT]
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// n, k, 0, 0
    config: [u32; 4],
    /// alpha, 0, 0, 0
    motion: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuMotion {
    kernel: Kernel,
}

impl GpuMotion {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("motion.wgsl"),
                "estimate",
                &[Params, Read, Read, ReadWrite],
            ),
        }
    }

    /// Records eq. 1 for the `n` pixels of `history` (`k` planes) at
    /// `alpha` into `next` (`vec4<f32>` per pixel).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        history: GpuHistoryBuffers<'_>,
        next: &wgpu::Buffer,
        (n, k, alpha): (u32, u32, f32),
    ) {
        let (positions, track) = (history.positions, history.track);
        let params = ctx.params(bytemuck::bytes_of(&Params {
            config: [n, k.max(1), 0, 0],
            motion: [alpha, 0.0, 0.0, 0.0],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[&params, positions, track, next],
            u64::from(n),
        );
    }
}
