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
//! multiply-add). Where a run does not fit (winners not in a row, lanes'
//! windows in different rows or out of step by more than a column, the
//! image's border, a pixel off its surface that is not flat, a filter
//! other than Catmull-Rom), it answers `None` and each
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

    /// The red, green and blue planes.
    pub fn rgb(&self) -> [&[f32]; 3] {
        [&self.red, &self.green, &self.blue]
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

/// The four rows of `N` taps of `plane` whose first is at `base`,
/// `stride` apart, or `None` past its end.
#[inline(always)]
fn taps<const N: usize>(plane: &[f32], base: usize, stride: usize) -> Option<[&[f32; N]; 4]> {
    let row = |j: usize| -> Option<&[f32; N]> {
        let first = base + j * stride;
        plane.get(first..first + N)?.try_into().ok()
    };
    Some([row(0)?, row(1)?, row(2)?, row(3)?])
}

/// The rows of `N` taps from `base` of `src`'s depth and of the colour
/// planes (red, green, blue).
type Window<'a, const N: usize> = ([&'a [f32; N]; 4], [[&'a [f32; N]; 4]; 3]);

/// [`taps`] of `src`'s depth and of each colour plane.
#[inline(always)]
fn window<'a, const N: usize>(
    src: Source<'a>,
    planes: &'a Planes,
    base: usize,
    stride: usize,
) -> Option<Window<'a, N>> {
    let depth = taps(src.depth, base, stride)?;
    let red = taps(&planes.red, base, stride)?;
    let green = taps(&planes.green, base, stride)?;
    let blue = taps(&planes.blue, base, stride)?;
    Some((depth, [red, green, blue]))
}

/// Tap column `i` of lane `l` in a row of taps: column `i + l` of `row`,
/// or, in a shifted run (`SHIFTED`), one further where `shift[l]`. Both
/// are loaded and one is selected, so that the lane loops stay vector
/// loads and blends.
#[inline(always)]
fn tap<const N: usize, const SHIFTED: bool>(
    row: &[f32; N],
    i: usize,
    l: usize,
    shift: &[bool; RUN],
) -> f32 {
    match SHIFTED {
        true => {
            let (here, next) = (row[i + l], row[i + l + 1]);
            if shift[l] { next } else { here }
        }
        false => row[i + l],
    }
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
///
/// **Shifted runs.** A position is its winner's centre moved by at most
/// half a pixel (`resample::position`), so its window starts at the
/// winner's column or one before it, by the sign of its offset. Where
/// that sign changes within a run (offsets about 0: a surface that barely
/// moves), some lanes' windows are a column to the right of the rest:
/// rows of [`SPAN`] + 1 taps then hold every lane's, and each lane takes
/// its own columns by a select ([`tap`]). These runs were 4 % of a 720p
/// default-scene warp's and had to be filtered pixel by pixel.
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
    // previous lane's (or two, see above), all in one row, all inside the
    // image (whose columns and rows are then exact as `f32`s).
    let q0 = at[0] - 0.5;
    let (bx, by) = (resample::floor(q0.x), resample::floor(q0.y));
    let exact = |n: i32| n.min(1 << 24);
    if bx < 1 || by < 1 || bx + RUN as i32 + 1 >= exact(w) || by + 2 >= exact(h) {
        return None;
    }
    let (x0, y0) = (bx as f32, by as f32);
    let (mut fx, mut fy) = ([0.0; RUN], [0.0; RUN]);
    let (mut left, mut right) = ([false; RUN], [false; RUN]);
    let mut outside = false;
    for l in 0..RUN {
        let q = at[l] - 0.5;
        // Lane `l`'s inner top-left tap is `(bx + l, by)` where that is the
        // floor of `q`: `x ≤ q.x < x + 1` (and in `y`); or the column
        // before (`left`) or after (`right`) it. In exact comparisons that
        // a NaN fails, without a conversion per lane (the saturating
        // floors cost the warp 5 % of its time at 720p).
        let x = x0 + l as f32;
        let row = (q.y >= y0) & (q.y < y0 + 1.0);
        outside |= !((q.x >= x - 1.0) & (q.x < x + 2.0) & row);
        (left[l], right[l]) = (q.x < x, q.x >= x + 1.0);
        // The column as `resample` floors it (exact, as are `x ± 1`).
        let column = if left[l] {
            x - 1.0
        } else if right[l] {
            x + 1.0
        } else {
            x
        };
        fx[l] = q.x - column;
        fy[l] = q.y - y0;
    }
    let (any_left, any_right) = (left.contains(&true), right.contains(&true));
    if outside || (any_left & any_right) {
        return None;
    }
    let stride = w as usize;
    let own = src.depth.get(first..first + RUN)?.try_into().ok()?;
    // The winners' own colours, as the planes hold them.
    let own_color =
        |plane: &[f32]| -> Option<Lanes> { plane.get(first..first + RUN)?.try_into().ok() };
    let own_colors = [
        own_color(&planes.red)?,
        own_color(&planes.green)?,
        own_color(&planes.blue)?,
    ];
    let lanes = RunLanes {
        own,
        own_colors,
        fx,
        fy,
    };
    if !any_left & !any_right {
        let base = (by - 1) as usize * stride + (bx - 1) as usize;
        let (depth, colour) = window::<SPAN>(src, planes, base, stride)?;
        return lanes.filter::<SPAN, false>(depth, colour, &[false; RUN]);
    }
    // Shifted: the rows start one column before the leftmost lane's
    // window, and a lane a column to the right of it takes the next.
    let (start, shift) = match any_left {
        true => (bx - 1, left.map(|l| !l)),
        false => (bx, right),
    };
    if start < 1 || start + RUN as i32 + 2 >= exact(w) {
        return None;
    }
    let base = (by - 1) as usize * stride + (start - 1) as usize;
    let (depth, colour) = window::<{ SPAN + 1 }>(src, planes, base, stride)?;
    lanes.filter::<{ SPAN + 1 }, true>(depth, colour, &shift)
}

/// What [`run`] knows of its lanes before their taps.
struct RunLanes<'a> {
    /// The winners' depths.
    own: &'a Lanes,
    /// The winners' colours (red, green, blue).
    own_colors: [Lanes; 3],
    /// Each position's fraction past its inner top-left tap, in x...
    fx: Lanes,
    /// ...and in y.
    fy: Lanes,
}

impl RunLanes<'_> {
    /// The run's colours from its taps: `depth` and the colour planes'
    /// four rows of `N`, lane `l`'s tap column `i` at [`tap`]`(row, i, l,
    /// shift)`.
    #[inline(always)]
    fn filter<const N: usize, const SHIFTED: bool>(
        &self,
        depth: [&[f32; N]; 4],
        colour: [[&[f32; N]; 4]; 3],
        shift: &[bool; RUN],
    ) -> Option<[Lanes; 3]> {
        let t = |row: &[f32; N], i: usize, l: usize| tap::<N, SHIFTED>(row, i, l, shift);
        // Per lane: the inner 2×2 taps' range per channel (in
        // `Taps::filter`'s order) and whether it is flat; whether all 16
        // depths are on the lane's own surface (`all_on_surface`).
        let mut lo = [[0.0; RUN]; 3];
        let mut hi = [[0.0; RUN]; 3];
        let mut flat = [true; RUN];
        for (k, c) in colour.iter().enumerate() {
            for l in 0..RUN {
                let v = [t(c[1], 1, l), t(c[1], 2, l), t(c[2], 1, l), t(c[2], 2, l)];
                let (a, b) = (
                    min(min(v[0], v[1]), min(v[2], v[3])),
                    max(max(v[0], v[1]), max(v[2], v[3])),
                );
                lo[k][l] = a;
                hi[k][l] = b;
                // Alpha is 1 throughout (`Planes::usable`): flat.
                flat[l] &= b - a <= b * FLAT;
            }
        }
        if flat == [true; RUN] {
            return Some(self.own_colors);
        }
        let own = self.own;
        let mut near = *own;
        let mut far = *own;
        let mut nan = [false; RUN];
        for row in depth {
            for i in 0..4 {
                for l in 0..RUN {
                    let d = t(row, i, l);
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
            // A lane neither flat nor on its surface takes the bilinear
            // taps: the run is left to the pixels one by one.
            taken &= flat[l] | on;
        }
        if !taken {
            return None;
        }

        // Separable Catmull-Rom, each row along x, then the rows along y,
        // in `Taps::filter`'s order; clamped to the inner taps' range.
        let (wx, wy) = (weights(&self.fx), weights(&self.fy));
        let mut out = [[0.0; RUN]; 3];
        for (k, c) in colour.iter().enumerate() {
            let mut sum = [0.0; RUN];
            for j in 0..4 {
                let mut across = [0.0; RUN];
                for i in 0..4 {
                    for l in 0..RUN {
                        across[l] += t(c[j], i, l) * wx[i][l];
                    }
                }
                for l in 0..RUN {
                    sum[l] += across[l] * wy[j][l];
                }
            }
            for l in 0..RUN {
                let clamped = min(max(sum[l], lo[k][l]), hi[k][l]);
                out[k][l] = if flat[l] {
                    self.own_colors[k][l]
                } else {
                    clamped
                };
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::passes::common::camera::Columns;

    /// A `w`×`h` image of textured colour (opaque) on one surface, its
    /// columns from `edge` on a farther one.
    fn textured(w: u32, h: u32, edge: u32) -> (Vec<[f32; 4]>, Vec<f32>) {
        let n = (w * h) as usize;
        let noise = |i: usize| ((i as f32 * 0.618_034).fract() * 7.31).fract();
        let color = (0..n)
            .map(|i| [0.1 + noise(i), noise(i + 1), 2.0 * noise(i + 2), 1.0])
            .collect();
        let depth = (0..n)
            .map(|i| match i as u32 % w >= edge {
                true => 9.0,
                false => 3.0 + 0.01 * noise(i + 3),
            })
            .collect();
        (color, depth)
    }

    /// Each lane of the run `colors` at `first` is its pixel's
    /// [`resample::resample`] at `at`, bit for bit.
    fn assert_pixels(src: Source<'_>, colors: &[Lanes; 3], first: usize, at: &[Vec2; RUN]) {
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

    /// A run gives each pixel's [`resample::resample`], bit for bit, or
    /// declines: lanes moved from their centres by the same or by
    /// different offsets (none, half a pixel either way, an ulp either
    /// side of the centre, a whole pixel, NaN), so that some lanes' taps
    /// shift a column or a row and some do not (runs with lanes a column
    /// apart are taken: shifted runs), over a textured image with
    /// an edge between two surfaces and the image's border.
    #[test]
    fn runs_are_the_pixels_one_by_one_or_decline() {
        let (w, h) = (40u32, 12u32);
        let n = (w * h) as usize;
        let (color, depth) = textured(w, h, 31);
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
        let mut shifted = 0;
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
                // Lanes whose windows are not all one column apart.
                let column = |l: usize| resample::floor(at[l].x - 0.5) - l as i32;
                shifted += usize::from((1..RUN).any(|l| column(l) != column(0)));
                assert_pixels(src, &colors, first, &at);
            }
            let at = std::array::from_fn(|l| image.center(first + l));
            assert!(run(src, &planes, first, &at, Resample::Bilinear).is_none());
        }
        // Both outcomes were met often, and shifted runs were taken.
        assert!(outcomes.iter().all(|&k| k > 1000), "{outcomes:?}");
        assert!(shifted > 100, "{shifted} shifted runs of {outcomes:?}");
    }

    /// A shifted run (lanes whose windows start a column apart: offsets
    /// of both signs) gives each pixel's [`resample::resample`], bit for
    /// bit, at every column of a textured surface up to the image's
    /// borders, where its wider rows must decline rather than read the
    /// next row.
    #[test]
    fn shifted_runs_are_the_pixels_one_by_one() {
        let (w, h) = (24u32, 6u32);
        let n = (w * h) as usize;
        let (color, depth) = textured(w, h, w);
        let src = Source {
            color: &color,
            depth: &depth,
            size: (w, h),
        };
        let mut planes = Planes::default();
        planes.fill(&color);
        let image = Columns::new(w);
        let mut taken = 0;
        for first in (0..n).filter(|&i| image.split(i as u32).0 as usize + RUN <= w as usize) {
            // Lanes before `m` a quarter pixel left of their centres, the
            // rest a quarter right; or the other way round.
            for (m, sign) in (1..RUN).flat_map(|m| [(m, 1.0), (m, -1.0)]) {
                let at: [Vec2; RUN] = std::array::from_fn(|l| {
                    let side = if l < m { -sign } else { sign };
                    image.center(first + l) + Vec2::new(0.25 * side, 0.1)
                });
                let Some(colors) = run(src, &planes, first, &at, Resample::CatmullRom) else {
                    continue;
                };
                taken += 1;
                assert_pixels(src, &colors, first, &at);
            }
        }
        assert!(taken > 100, "{taken} shifted runs taken");
    }
}
