//! GeoMotionGen pass 7, resolve (seed 003), two-sided and occlusion-aware
//! (issue 16 §4).
//!
//! The seed fetches each pixel from one frame: a written pixel from the
//! current frame back along its motion, `y − (1 − α)·m`; an unwritten one
//! (disoccluded in the current frame) reverses the inpainted motion and
//! fetches the previous frame at `y + α·m`. Here a written pixel also
//! looks where its surface was in the previous frame, `y + α·m`: if that
//! point is inside the previous frame and on the same surface
//! ([`same_surface`] of the two depths: not covered by something nearer,
//! not a background the object left), the pixel is visible in both frames
//! and takes both, weighted `(1 − α)` previous and `α` current, so shading
//! that changes between the frames (moving lights, shadows, view-dependent
//! highlights) is interpolated instead of jumping at α's midpoint.
//! Otherwise (occluded in the previous frame, or entering the view) it
//! takes the current frame alone.
//!
//! Every fetch uses the warp's sharp reconstruction ([`resample`]) on the
//! surface of the pixel it falls in, edges clamped; depth is the fetched
//! pixel's (both sides blended with the colour's weights); the output
//! motion points to the previous frame (`α·m`, in pixels).

use glam::{Vec2, Vec4};

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{Output, WARPED};
use crate::passes::common::camera::Columns;
use crate::passes::common::resample::{self, Resample, Source, same_surface};
use crate::passes::common::sample::{clamp_index, inside};

/// Where a pixel's colour comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fetch {
    /// Visible in both frames: previous at `.0`, current at `.1`.
    Both(Vec2, Vec2),
    /// The current frame only, at the position.
    Current(Vec2),
    /// The previous frame only, at the position.
    Previous(Vec2),
}

/// What pixel centre `center` fetches, with motion `m` (pixels, current →
/// previous) and `written` saying the current frame's splat reached it.
pub fn fetch(
    center: Vec2,
    m: Vec2,
    written: bool,
    alpha: f32,
    current: Source<'_>,
    previous: Source<'_>,
) -> Fetch {
    let before = center + m * alpha;
    if !written {
        return Fetch::Previous(before);
    }
    let now = center - m * (1.0 - alpha);
    if inside(before, previous.size) {
        let (w, h) = current.size;
        let d_now = current.depth[clamp_index(now, w, h)];
        let (pw, ph) = previous.size;
        let d_before = previous.depth[clamp_index(before, pw, ph)];
        if same_surface(d_before, d_now) {
            return Fetch::Both(before, now);
        }
    }
    Fetch::Current(now)
}

/// `a` and `b` weighted `1 − α` and `α` (exactly `a` at α = 0 and `b` at
/// α = 1); equal values (two skies) stay as they are.
#[inline]
fn mix(a: f32, b: f32, alpha: f32) -> f32 {
    if a == b {
        a
    } else {
        a * (1.0 - alpha) + b * alpha
    }
}

/// One side's colour and depth at `at` on the surface of the pixel it
/// falls in.
#[inline]
fn take(src: Source<'_>, at: Vec2, filter: Resample) -> (Vec4, f32) {
    let own = clamp_index(at, src.size.0, src.size.1);
    let c = resample::resample(src, own, at, filter);
    (Vec4::new(c[0], c[1], c[2], 1.0), src.depth[own])
}

/// CPU reference: turns `out` (uv motion + written mask after push-pull)
/// into the interpolated frame.
pub fn resolve(
    out: &mut Output,
    (current, previous): (Source<'_>, Source<'_>),
    alpha: f32,
    filter: Resample,
) {
    use rayon::prelude::*;
    let (w, h) = (out.width, out.height);
    let size = Vec2::new(w as f32, h as f32);
    let columns = Columns::new(w);
    out.par_pixels_mut().for_each(|(t, px)| {
        let center = columns.center(t);
        let m = Vec2::from_array(*px.motion) * size;
        let (color, depth) = match fetch(center, m, *px.mask == WARPED, alpha, current, previous) {
            Fetch::Both(before, now) => {
                let (cb, db) = take(previous, before, filter);
                let (cn, dn) = take(current, now, filter);
                (cb * (1.0 - alpha) + cn * alpha, mix(db, dn, alpha))
            }
            Fetch::Current(now) => take(current, now, filter),
            Fetch::Previous(before) => take(previous, before, filter),
        };
        *px.color = color.to_array();
        *px.depth = depth;
        *px.motion = (m * alpha).to_array();
    });
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// width, height, filter code, 0
    size: [u32; 4],
    alpha: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuResolve {
    kernel: Kernel,
}

/// Color and depth buffers of one frame on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GpuImage<'a> {
    /// `vec4<f32>` color.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
}

impl GpuResolve {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = format!("{}\n{}", resample::WGSL, include_str!("resolve.wgsl"));
        Self {
            kernel: Kernel::new(
                ctx,
                &src,
                "interp_resolve",
                &[
                    Params, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the resolve over `out` (`size` is both frames' and the
    /// output's).
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        ((width, height), alpha, filter): ((u32, u32), f32, Resample),
        (current, previous): (GpuImage<'_>, GpuImage<'_>),
        out: crate::output::GpuOutput<'_>,
    ) {
        let p = ctx.params(bytemuck::bytes_of(&Params {
            size: [width, height, filter.code(), 0],
            alpha: [alpha, 0.0, 0.0, 0.0],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &p,
                current.color,
                current.depth,
                previous.color,
                previous.depth,
                out.color,
                out.depth,
                out.motion,
                out.mask,
            ],
            u64::from(width) * u64::from(height),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two uniform frames of one size: colour value and depth of each.
    struct Pair {
        size: (u32, u32),
        color: [Vec<[f32; 4]>; 2],
        depth: [Vec<f32>; 2],
    }

    impl Pair {
        fn new((w, h): (u32, u32), current: (f32, f32), previous: (f32, f32)) -> Self {
            let n = (w * h) as usize;
            let color = |v: f32| vec![[v, v, v, 1.0]; n];
            Self {
                size: (w, h),
                color: [color(current.0), color(previous.0)],
                depth: [vec![current.1; n], vec![previous.1; n]],
            }
        }

        /// Current and previous.
        fn sources(&self) -> (Source<'_>, Source<'_>) {
            let side = |k: usize| Source {
                color: &self.color[k],
                depth: &self.depth[k],
                size: self.size,
            };
            (side(0), side(1))
        }

        fn output(&self, uv: [f32; 2], mask: u32) -> Output {
            let mut o = Output::empty(self.size.0, self.size.1);
            o.motion.fill(uv);
            o.mask.fill(mask);
            o
        }
    }

    #[test]
    fn a_surface_seen_in_both_frames_blends_them_by_alpha() {
        let p = Pair::new((8, 8), (4.0, 5.0), (2.0, 5.2));
        for alpha in [0.0, 0.25, 0.5, 1.0] {
            let mut o = p.output([0.0, 0.0], WARPED);
            resolve(&mut o, p.sources(), alpha, Resample::CatmullRom);
            let want = 2.0 + 2.0 * alpha;
            assert!(
                o.color.iter().all(|c| (c[0] - want).abs() < 1e-6),
                "{alpha}"
            );
            let d = 5.2 + (5.0 - 5.2) * alpha;
            assert!(o.depth.iter().all(|x| (x - d).abs() < 1e-6), "{alpha}");
        }
    }

    #[test]
    fn an_occluded_or_entering_surface_takes_the_current_frame() {
        // Something nearer covered the surface in the previous frame.
        let p = Pair::new((8, 8), (4.0, 5.0), (2.0, 1.0));
        let mut o = p.output([0.0, 0.0], WARPED);
        resolve(&mut o, p.sources(), 0.5, Resample::Bilinear);
        assert!(o.color.iter().all(|c| c[0] == 4.0));
        assert!(o.depth.iter().all(|&d| d == 5.0));
        // The same surface, but it was outside the previous frame (3 px
        // right of the right edge at α = 1 for the last column).
        let p = Pair::new((8, 8), (4.0, 5.0), (2.0, 5.0));
        let (cur, prev) = p.sources();
        let m = Vec2::new(3.0, 0.0);
        let c = fetch(Vec2::new(7.5, 2.5), m, true, 1.0, cur, prev);
        assert_eq!(c, Fetch::Current(Vec2::new(7.5, 2.5)));
        let c = fetch(Vec2::new(2.5, 2.5), m, true, 1.0, cur, prev);
        assert_eq!(c, Fetch::Both(Vec2::new(5.5, 2.5), Vec2::new(2.5, 2.5)));
        // Unwritten: disoccluded in the current frame, the previous only.
        let c = fetch(Vec2::new(2.5, 2.5), m, false, 0.5, cur, prev);
        assert_eq!(c, Fetch::Previous(Vec2::new(4.0, 2.5)));
    }

    #[test]
    fn skies_blend_to_sky() {
        let inf = f32::INFINITY;
        let p = Pair::new((4, 4), (1.0, inf), (3.0, inf));
        for alpha in [0.0, 0.5, 1.0] {
            let mut o = p.output([0.1, -0.1], WARPED);
            resolve(&mut o, p.sources(), alpha, Resample::CatmullRom);
            assert!(o.depth.iter().all(|&d| d == inf), "{alpha}");
            assert!(o.color.iter().all(|c| c[0].is_finite()), "{alpha}");
        }
    }
}
