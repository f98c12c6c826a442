//! The resampling filter of `resample.rs` for a run of [`RUN`] target
//! pixels at once (issue 15: the filter was half of the CPU warp's time,
//! paid one pixel at a time).
//!
//! Under a smooth warp most target pixels of a row are won by consecutive
//! source pixels of one row, shifted by the same whole number of pixels:
//! then tap column `i` of row `j` of the run's [`RUN`] filters is one
//! stretch of [`RUN`] consecutive source pixels, a single load per channel
//! from the source's colour [`Planes`]. The weights, the flat test, the
//! surface test and the clamp are computed lane by lane, on arrays the
//! compiler turns into vector instructions ([`RUN`] = 8: one AVX register
//! where the CPU has it, see `warp.rs`).
//!
//! [`run`] is [`resample::resample`] of each pixel, bit for bit: every lane
//! performs the same IEEE operations in the same order (`min`/`max` as
//! SSE2's `minps`/`maxps`, which glam uses; Rust forms no fused
//! multiply-add). Where a run does not fit (winners not in a row, a
//! shifted window, the image's border, a pixel off its surface that is
//! not flat, a filter other than Catmull-Rom), it answers `None` and each
//! pixel takes [`resample::resample`]; `warp.rs` tests the two against
//! each other.

// Lane loops index by lane on purpose: the iterator and `array::map`
// forms were left as calls in the AVX2 band (`warp.rs`), which made the
// runs slower than the pixels one by one.
#![allow(clippy::needless_range_loop)]

use glam::Vec2;

use crate::passes::common::resample::{self, FLAT, Resample, SAME_SURFACE_RATIO, Source};

/// Target pixels per run.
pub const RUN: usize = 8;

/// Source pixels a row of a run's taps spans.
const SPAN: usize = RUN + 3;

/// One value per pixel of a run.
type Lanes = [f32; RUN];

/// A source image's colour as planes of one channel: a run's tap is one
/// stretch of each. Its buffers are reused from frame to frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Planes {
    red: Vec<f32>,
    green: Vec<f32>,
    blue: Vec<f32>,
    /// Whether every alpha is 1: the filters' flat test reads alpha too
    /// (as one lane of the pixel's `Vec4`), and the planes do not hold it.
    /// Prepared frames are opaque (`input.rs`); where one is not, no run is
    /// taken.
    opaque: bool,
}

impl Planes {
    /// The planes of `color`, written on all cores into the buffers kept.
    pub fn fill(&mut self, color: &[[f32; 4]]) {
        let mut none = vec![(); color.len()];
        self.fill_with(&mut none, 4096, |first, _, r, g, b| {
            Self::transpose(&color[first..first + r.len()], r, g, b)
        });
    }

    /// The planes of `other.len()` pixels made on all cores, block by
    /// block alongside the same block of `other`: `make(first, other, red,
    /// green, blue)` writes the pixels from `first` (those of `other` too,
    /// while they are in the cache) and says whether they are all opaque.
    pub fn fill_with<T: Send>(
        &mut self,
        other: &mut [T],
        block: usize,
        make: impl Fn(usize, &mut [T], &mut [f32], &mut [f32], &mut [f32]) -> bool + Sync + Send,
    ) {
        use rayon::prelude::*;
        let (n, block) = (other.len(), block.max(1));
        for plane in [&mut self.red, &mut self.green, &mut self.blue] {
            plane.resize(n, 0.0);
        }
        let planes = (self.red.par_chunks_mut(block))
            .zip(self.green.par_chunks_mut(block))
            .zip(self.blue.par_chunks_mut(block))
            .zip(other.par_chunks_mut(block))
            .enumerate()
            .with_max_len((64 * 1024 / block).max(1));
        self.opaque = planes
            .map(|(k, (((r, g), b), o))| make(k * block, o, r, g, b))
            .reduce(|| true, |a, b| a & b);
    }

    /// `color`'s channels into `r`, `g` and `b` (as long): whether every
    /// alpha is 1.
    #[inline]
    pub fn transpose(color: &[[f32; 4]], r: &mut [f32], g: &mut [f32], b: &mut [f32]) -> bool {
        let mut opaque = true;
        for (k, p) in color.iter().enumerate() {
            (r[k], g[k], b[k]) = (p[0], p[1], p[2]);
            opaque &= p[3] == 1.0;
        }
        opaque
    }

    /// Pixel `i`'s colour replaced by `c` (shading correction's changes
    /// and their undoing), as [`Planes::fill`] of the changed image would
    /// hold it; a `c` that is not opaque leaves no runs taken until the
    /// next fill (they give the pixels' own bits either way).
    pub fn set(&mut self, i: usize, c: [f32; 4]) {
        if let (Some(r), Some(g), Some(b)) = (
            self.red.get_mut(i),
            self.green.get_mut(i),
            self.blue.get_mut(i),
        ) {
            (*r, *g, *b) = (c[0], c[1], c[2]);
        }
        self.opaque &= c[3] == 1.0;
    }

    /// Whether these are the planes of an image of `n` pixels that runs
    /// can be taken from.
    pub fn usable(&self, n: usize) -> bool {
        self.opaque && self.red.len() == n
    }
}

/// `resample::catmull_rom` of every lane's fraction, tap by tap.
#[inline(always)]
fn weights(f: &Lanes) -> [Lanes; 4] {
    let mut w = [[0.0; RUN]; 4];
    for l in 0..RUN {
        let c = resample::catmull_rom(f[l]);
        for i in 0..4 {
            w[i][l] = c[i];
        }
    }
    w
}

/// SSE2's `minps` of one lane (glam's `Vec4::min`, and its `Vec2::min`
/// component by component): `b` unless `a < b`.
#[inline(always)]
pub fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// SSE2's `maxps` of one lane (glam's `Vec4::max`, and its `Vec2::max`
/// component by component): `b` unless `a > b`.
#[inline(always)]
pub fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The four rows of [`SPAN`] taps of `plane` whose first is at `base`,
/// `stride` apart, or `None` past its end.
#[inline(always)]
fn taps(plane: &[f32], base: usize, stride: usize) -> Option<[&[f32; SPAN]; 4]> {
    let row = |j: usize| -> Option<&[f32; SPAN]> {
        let first = base + j * stride;
        plane.get(first..first + SPAN)?.try_into().ok()
    };
    Some([row(0)?, row(1)?, row(2)?, row(3)?])
}

/// The colours [`resample::resample`] gives the [`RUN`] target pixels
/// whose winners are the source pixels `first .. first + RUN` (consecutive
/// in one row of `src`), at positions `at` (`resample::position`), with
/// filter `mode`, as planes (red, green, blue; lane `l` is pixel `l`);
/// `None` where the run cannot be taken at once (see the module doc).
/// `planes` are `src`'s colour, [`Planes::usable`].
///
/// Planes, not a colour per pixel: the lanes' last steps (the clamp, the
/// flat pixels' own colour) are then selects in registers. Written pixel
/// by pixel, they were a branch per lane, taken by data (0.4–0.55 ms of
/// the CPU warp's 15 at 720p, paired).
#[inline(always)]
pub fn run(
    src: Source<'_>,
    planes: &Planes,
    first: usize,
    at: &[Vec2; RUN],
    mode: Resample,
) -> Option<[Lanes; 3]> {
    if mode != Resample::CatmullRom {
        return None;
    }
    let (w, h) = (src.size.0 as i32, src.size.1 as i32);
    // Each lane's window: its inner top-left tap one column past the
    // previous lane's, all in one row, all inside the image (whose columns
    // and rows are then exact as `f32`s).
    let q0 = at[0] - 0.5;
    let (bx, by) = (resample::floor(q0.x), resample::floor(q0.y));
    let exact = |n: i32| n.min(1 << 24);
    if bx < 1 || by < 1 || bx + RUN as i32 + 1 >= exact(w) || by + 2 >= exact(h) {
        return None;
    }
    let (x0, y0) = (bx as f32, by as f32);
    let (mut fx, mut fy) = ([0.0; RUN], [0.0; RUN]);
    let mut shifted = false;
    for l in 0..RUN {
        let q = at[l] - 0.5;
        // Lane `l`'s inner top-left tap is `(bx + l, by)` where that is the
        // floor of `q`: `x ≤ q.x < x + 1` (and in `y`), in exact
        // comparisons that a NaN fails, without a conversion per lane (the
        // saturating floors cost the warp 5 % of its time at 720p).
        let x = x0 + l as f32;
        let inside = (q.x >= x) & (q.x < x + 1.0) & (q.y >= y0) & (q.y < y0 + 1.0);
        shifted |= !inside;
        fx[l] = q.x - x;
        fy[l] = q.y - y0;
    }
    if shifted {
        return None;
    }
    let stride = w as usize;
    let base = (by - 1) as usize * stride + (bx - 1) as usize;
    let depth = taps(src.depth, base, stride)?;
    let red = taps(&planes.red, base, stride)?;
    let green = taps(&planes.green, base, stride)?;
    let blue = taps(&planes.blue, base, stride)?;
    let own = src.depth.get(first..first + RUN)?;

    // Per lane: the inner 2×2 taps' range per channel (in `Taps::filter`'s
    // order) and whether it is flat; whether all 16 depths are on the
    // lane's own surface (`all_on_surface`).
    let mut lo = [[0.0; RUN]; 3];
    let mut hi = [[0.0; RUN]; 3];
    let mut flat = [true; RUN];
    for (k, c) in [red, green, blue].iter().enumerate() {
        for l in 0..RUN {
            let t = [c[1][l + 1], c[1][l + 2], c[2][l + 1], c[2][l + 2]];
            let (a, b) = (
                min(min(t[0], t[1]), min(t[2], t[3])),
                max(max(t[0], t[1]), max(t[2], t[3])),
            );
            lo[k][l] = a;
            hi[k][l] = b;
            // Alpha is 1 throughout (`Planes::usable`): flat.
            flat[l] &= b - a <= b * FLAT;
        }
    }
    // The winners' own colours, as the planes hold them.
    let own_color =
        |plane: &[f32]| -> Option<Lanes> { plane.get(first..first + RUN)?.try_into().ok() };
    let own_colors = [
        own_color(&planes.red)?,
        own_color(&planes.green)?,
        own_color(&planes.blue)?,
    ];
    if flat == [true; RUN] {
        return Some(own_colors);
    }
    let mut near = [0.0; RUN];
    let mut far = [0.0; RUN];
    let mut nan = [false; RUN];
    near.copy_from_slice(own);
    far.copy_from_slice(own);
    for row in depth {
        for i in 0..4 {
            for l in 0..RUN {
                let d = row[i + l];
                near[l] = min(near[l], d);
                far[l] = max(far[l], d);
                nan[l] |= d.is_nan();
            }
        }
    }
    let mut taken = true;
    for l in 0..RUN {
        let d0 = own[l];
        let on = !nan[l]
            & (near[l] > 0.0)
            & (far[l] <= d0 * SAME_SURFACE_RATIO)
            & (d0 <= near[l] * SAME_SURFACE_RATIO);
        // A lane neither flat nor on its surface takes the bilinear taps:
        // the run is left to the pixels one by one.
        taken &= flat[l] | on;
    }
    if !taken {
        return None;
    }

    // Separable Catmull-Rom, each row along x, then the rows along y, in
    // `Taps::filter`'s order; clamped to the inner taps' range.
    let (wx, wy) = (weights(&fx), weights(&fy));
    let mut out = [[0.0; RUN]; 3];
    for (k, c) in [red, green, blue].iter().enumerate() {
        let mut sum = [0.0; RUN];
        for j in 0..4 {
            let mut across = [0.0; RUN];
            for i in 0..4 {
                for l in 0..RUN {
                    across[l] += c[j][i + l] * wx[i][l];
                }
            }
            for l in 0..RUN {
                sum[l] += across[l] * wy[j][l];
            }
        }
        for l in 0..RUN {
            let clamped = min(max(sum[l], lo[k][l]), hi[k][l]);
            out[k][l] = if flat[l] { own_colors[k][l] } else { clamped };
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::passes::common::camera::Columns;

    /// A run gives each pixel's [`resample::resample`], bit for bit, or
    /// declines: lanes moved from their centres by the same or by
    /// different offsets (none, half a pixel either way, an ulp either
    /// side of the centre, a whole pixel, NaN), so that some lanes' taps
    /// shift a column or a row and some do not, over a textured image with
    /// an edge between two surfaces and the image's border.
    #[test]
    fn runs_are_the_pixels_one_by_one_or_decline() {
        let (w, h) = (40u32, 12u32);
        let n = (w * h) as usize;
        let noise = |i: usize| ((i as f32 * 0.618_034).fract() * 7.31).fract();
        let color: Vec<[f32; 4]> = (0..n)
            .map(|i| [0.1 + noise(i), noise(i + 1), 2.0 * noise(i + 2), 1.0])
            .collect();
        let depth: Vec<f32> = (0..n)
            .map(|i| match i % w as usize {
                31.. => 9.0,
                _ => 3.0 + 0.01 * noise(i + 3),
            })
            .collect();
        let src = Source {
            color: &color,
            depth: &depth,
            size: (w, h),
        };
        let mut planes = Planes::default();
        planes.fill(&color);
        assert!(planes.usable(n));
        let image = Columns::new(w);
        let offsets = [0.0, 0.5, -0.5, 0.25, -0.3, 1.0, -1.0, f32::NAN];
        let ulp = |v: f32, k: i32| f32::from_bits((v.to_bits() as i32 + k) as u32);
        let mut outcomes = [0usize; 2];
        for first in (0..n).filter(|&i| image.split(i as u32).0 as usize + RUN <= w as usize) {
            for k in 0..48 {
                let at: [Vec2; RUN] = std::array::from_fn(|l| {
                    // Every lane with the run's offset; or every fifth
                    // lane with its own; or each nudged by an ulp.
                    let own = k % 3 == 1 && (k + l) % 5 == 0;
                    let pick = |j: usize| match own {
                        true => offsets[(k / 3 + l + j) % offsets.len()],
                        false => offsets[(k / 3 + j) % offsets.len()],
                    };
                    let nudge = [0, 0, [0, 1, -1][(k / 3 + l) % 3]][k % 3];
                    let c = image.center(first + l);
                    Vec2::new(ulp(c.x + pick(0), nudge), ulp(c.y + pick(1), -nudge))
                });
                let Some(colors) = run(src, &planes, first, &at, Resample::CatmullRom) else {
                    outcomes[0] += 1;
                    continue;
                };
                outcomes[1] += 1;
                for l in 0..RUN {
                    let one = resample::resample(src, first + l, at[l], Resample::CatmullRom);
                    assert_eq!(
                        colors.map(|c| c[l].to_bits()),
                        one.map(f32::to_bits),
                        "run at {first}, lane {l}: {:?}",
                        at[l]
                    );
                }
            }
            let at = std::array::from_fn(|l| image.center(first + l));
            assert!(run(src, &planes, first, &at, Resample::Bilinear).is_none());
        }
        // Both outcomes were met often.
        assert!(outcomes.iter().all(|&k| k > 1000), "{outcomes:?}");
    }
}
