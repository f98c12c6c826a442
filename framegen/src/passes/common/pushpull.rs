//! Push-pull fill of the holes nothing else covered (DESIGN §4 step 7; the
//! pyramid of GeoMotionGen, seed 003): warp cracks, disocclusions the
//! background never saw, and borders the adaptive window did not cover.
//!
//! * **init**: every written pixel enters level 0 with weight 1, holes with
//!   weight 0. A texel carries color, *inverse* depth (so sky, `+inf`, is 0
//!   and averages stay finite) and the motion vector.
//! * **pull**: level `k + 1` is the weight-normalised mean of its (up to)
//!   four children, with weight `min(1, Σw)`.
//! * **push**: from the coarsest level down, a texel of weight `w < 1`
//!   becomes `w·own + (1 − w)·parent`, the parent sampled bilinearly with
//!   each tap weighted by its own weight (empty texels do not count).
//! * **resolve**: holes take level 0's value and are flagged
//!   [`FILLED`]; if the whole frame was empty they become black sky.

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

/// CPU reference of `pp_init`.
pub fn init(out: &Output, pyramid: &mut [Texel]) {
    use rayon::prelude::*;
    let n = out.mask.len();
    pyramid[..n]
        .par_iter_mut()
        .enumerate()
        .for_each(|(t, texel)| *texel = init_texel(out, t));
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

/// CPU reference of `pp_pull` from level `k` to `k + 1`.
pub fn pull(pyramid: &mut [Texel], levels: Levels, k: u32) {
    use rayon::prelude::*;
    let (sw, sh) = levels.size(k);
    let (dw, dh) = levels.size(k + 1);
    let (so, d_o) = (levels.offset(k) as usize, levels.offset(k + 1) as usize);
    let (below, above) = pyramid.split_at_mut(d_o);
    let src = &below[so..];
    above[..(dw * dh) as usize]
        .par_chunks_mut(dw as usize)
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
                            let c = src[(cy * sw + cx) as usize];
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

/// CPU reference of `pp_push` from level `k + 1` into level `k`.
pub fn push(pyramid: &mut [Texel], levels: Levels, k: u32) {
    use rayon::prelude::*;
    let (w, h) = levels.size(k);
    let o = levels.offset(k) as usize;
    let (below, above) = pyramid.split_at_mut(levels.offset(k + 1) as usize);
    let coarse = &above[..levels.len(k + 1) as usize];
    let coarse_size = levels.size(k + 1);
    below[o..o + (w * h) as usize]
        .par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                let own = *texel;
                let wgt = own.a[3];
                if wgt >= 1.0 {
                    continue;
                }
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) * 0.5;
                let (pa, pb) = sample(coarse, coarse_size, p);
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

/// CPU reference of `pp_resolve`.
pub fn resolve(pyramid: &[Texel], out: &mut Output) {
    use rayon::prelude::*;
    out.par_pixels_mut().for_each(|(t, px)| {
        if *px.mask != EMPTY {
            return;
        }
        let p = pyramid[t];
        let (color, inv_depth, motion) = if p.a[3] > 0.0 {
            (p.a, p.b[0], [p.b[1], p.b[2]])
        } else {
            ([0.0; 4], 0.0, [0.0; 2])
        };
        *px.color = [color[0], color[1], color[2], 1.0];
        *px.depth = if inv_depth > 0.0 {
            1.0 / inv_depth
        } else {
            f32::INFINITY
        };
        *px.motion = motion;
        *px.mask = FILLED;
    });
}

/// The whole CPU reference: fills every hole of `out`.
pub fn fill(out: &mut Output, levels: u32) {
    use rayon::prelude::*;
    let layout = layout(out.width, out.height, levels);
    // Level 0 built in parallel (what `init` writes), the coarser levels
    // after it (every texel of them is written by `pull`).
    let mut pyramid: Vec<Texel> = (0..out.mask.len())
        .into_par_iter()
        .map(|t| init_texel(out, t))
        .collect();
    pyramid.resize(layout.total() as usize, Texel::default());
    for k in 0..layout.count - 1 {
        pull(&mut pyramid, layout, k);
    }
    for k in (0..layout.count - 1).rev() {
        push(&mut pyramid, layout, k);
    }
    resolve(&pyramid, out);
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
    init: Kernel,
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
            init: Kernel::new(ctx, src, "pp_init", b),
            pull: Kernel::new(ctx, src, "pp_pull", b),
            push: Kernel::new(ctx, src, "pp_push", b),
            resolve: Kernel::new(ctx, src, "pp_resolve", b),
        }
    }

    /// Records the whole push-pull over `out` with `layout` (see
    /// [`layout`]); `pyramid` holds at least `layout.total()` texels.
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        out: crate::passes::gffe::warp::GpuOutput<'_>,
        pyramid: &wgpu::Buffer,
        layout: Levels,
    ) {
        let level = |k: u32| {
            let (w, h) = layout.size(k);
            [layout.offset(k), w, h, 0]
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
        run(&self.init, encoder, 0, 0);
        for k in 0..layout.count - 1 {
            run(&self.pull, encoder, k + 1, k);
        }
        for k in (0..layout.count - 1).rev() {
            run(&self.push, encoder, k, k + 1);
        }
        run(&self.resolve, encoder, 0, 0);
    }
}
