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
    let (sw, sh) = levels.size(k);
    let (dw, _) = levels.size(k + 1);
    dst.par_chunks_mut(dw as usize)
        .enumerate()
        .for_each(|(y, row)| {
            let y = y as u32;
            for (x, texel) in (0u32..).zip(row.iter_mut()) {
                let mut sum_w = 0.0f32;
                let mut sa = Vec4::ZERO;
                let mut sb = Vec4::ZERO;
                for dy in 0..2 {
                    for dx in 0..2 {
                        let (cx, cy) = (2 * x + dx, 2 * y + dy);
                        if cx < sw && cy < sh {
                            let c = child((cy * sw + cx) as usize);
                            let w = c.a[3];
                            sum_w += w;
                            sa += Vec4::from_array(c.a) * w;
                            sb += Vec4::from_array(c.b) * w;
                        }
                    }
                }
                *texel = if sum_w > 0.0 {
                    let a = sa / sum_w;
                    Texel {
                        a: [a.x, a.y, a.z, sum_w.min(1.0)],
                        b: (sb / sum_w).to_array(),
                    }
                } else {
                    Texel::default()
                };
            }
        });
}

/// Weighted bilinear sample of one level (its texels and size) at the
/// level's continuous position `p`: each tap counts with its bilinear weight times its own weight, so
/// empty texels do not drag the value toward zero; the returned weight is
/// the bilinear blend of the taps' weights.
fn sample(level: &[Texel], (w, h): (u32, u32), p: Vec2) -> (Vec4, Vec4) {
    let q = p - 0.5;
    let base = q.floor();
    let f = q - base;
    let at = |x: f32, y: f32| {
        let xi = (x.max(0.0) as u32).min(w - 1);
        let yi = (y.max(0.0) as u32).min(h - 1);
        let t = level[(yi * w + xi) as usize];
        (Vec4::from_array(t.a), Vec4::from_array(t.b))
    };
    let taps = [
        ((1.0 - f.x) * (1.0 - f.y), at(base.x, base.y)),
        (f.x * (1.0 - f.y), at(base.x + 1.0, base.y)),
        ((1.0 - f.x) * f.y, at(base.x, base.y + 1.0)),
        (f.x * f.y, at(base.x + 1.0, base.y + 1.0)),
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
                let own = *texel;
                let wgt = own.a[3];
                if wgt >= 1.0 {
                    continue;
                }
                let (pa, pb) = parent(coarse, coarse_size, x, y);
                let oa = Vec4::from_array(own.a);
                let ob = Vec4::from_array(own.b);
                let a = oa * wgt + pa * (1.0 - wgt);
                let b = ob * wgt + pb * (1.0 - wgt);
                *texel = Texel {
                    a: [a.x, a.y, a.z, wgt + (1.0 - wgt) * pa.w],
                    b: b.to_array(),
                };
            }
        });
}

/// The parent value of texel `(x, y)` of a level: the next coarser level
/// (`coarse`, of `size`) sampled at the texel's centre.
fn parent(coarse: &[Texel], size: (u32, u32), x: usize, y: usize) -> (Vec4, Vec4) {
    let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) * 0.5;
    sample(coarse, size, p)
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
        let (pa, pb) = match level1 {
            Some((coarse, size)) => parent(coarse, size, t % width, t / width),
            None => (Vec4::ZERO, Vec4::ZERO),
        };
        let (color, inv_depth, motion) = if pa.w > 0.0 {
            (pa, pb.x, [pb.y, pb.z])
        } else {
            (Vec4::ZERO, 0.0, [0.0; 2])
        };
        *px.color = [color.x, color.y, color.z, 1.0];
        *px.depth = if inv_depth > 0.0 {
            1.0 / inv_depth
        } else {
            f32::INFINITY
        };
        *px.motion = motion;
        *px.mask = FILLED;
    });
}

/// The whole CPU reference: fills every hole of `out`. A frame without
/// holes is left as it is, without building the pyramid (the resolve
/// writes only holes).
pub fn fill(out: &mut Output, levels: u32) {
    use rayon::prelude::*;
    if !out.mask.par_iter().any(|&m| m == EMPTY) {
        return;
    }
    let layout = layout(out.width, out.height, levels);
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
            Uniform, ReadWrite, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
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
            let params = ctx.uniform(bytemuck::bytes_of(&Params {
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
