//! Sub-pixel resampling of a forward-warped pixel's colour (issue 16 §1;
//! GFFE §4.1 keeps the splat's nearest pixel).
//!
//! The forward splat decides *which* source surface a target pixel shows:
//! source pixel `i` won target pixel `t` because its position at α lands at
//! `q_i` inside `t` (depth-tested, deterministic, see `splat.rs`). Copying
//! `i`'s colour puts it at `t`'s centre `c_t` although it belongs at `q_i`,
//! up to half a pixel away: every sub-pixel shift aliases fine texture. The
//! colour that belongs at `c_t` is the source image at `x_i + (c_t − q_i)`,
//! the warp taken as a local translation (exact for pans and moving
//! objects; for a scaling warp the error is the scale change times the
//! offset, a few hundredths of a pixel).
//!
//! The source image is read there with a reconstruction filter restricted
//! to `i`'s own surface: a tap whose depth is not within
//! [`SAME_SURFACE_RATIO`] of `i`'s (another object across a silhouette, or
//! no surface) takes no part, so a foreground edge does not bleed into the
//! background it moved over. The offset is clamped to half a pixel, so `i`
//! itself is always among the taps.
//!
//! * [`Resample::Nearest`]: `i`'s colour (the seed's warp).
//! * [`Resample::Bilinear`]: 2×2 taps on `i`'s surface, renormalised.
//! * [`Resample::CatmullRom`]: 4×4 Catmull-Rom taps when all 16 are on
//!   `i`'s surface, each channel clamped to the range of the inner 2×2
//!   (no ringing around HDR highlights); otherwise the bilinear taps.
//!
//! Where the 2×2 taps around the position are flat to within the `f16`
//! output's rounding ([`FLAT`]), every filter's result is the pixel itself
//! to that precision, and the pixel is taken (most of a flat-shaded
//! surface; the filter's cost is paid at edges and texture).
//!
//! Filtering runs on linear HDR colour, as it arrives.
//! `resample.wgsl` ([`WGSL`]) mirrors [`resample`] operation by operation
//! for the kernels that resample (the warp, interpolation's resolve), but
//! for the Catmull-Rom taps' surface test: the kernel tests them one by
//! one, the CPU by their range ([`all_on_surface`], the same answer).

use glam::{Vec2, Vec4};

/// The WGSL of [`resample`] and [`same_surface`], prefixed to the shaders
/// that resample (each defines where its source image comes from; see the
/// file's head).
pub const WGSL: &str = include_str!("resample.wgsl");

/// How a warped pixel takes its colour from the source frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Resample {
    /// The winning source pixel's colour.
    Nearest = 0,
    /// Bilinear on the winner's surface.
    Bilinear = 1,
    /// Clamped Catmull-Rom on the winner's surface.
    CatmullRom = 2,
}

impl Resample {
    /// Every filter, cheapest first.
    pub const ALL: [Resample; 3] = [Resample::Nearest, Resample::Bilinear, Resample::CatmullRom];

    /// The name on command lines and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Resample::Nearest => "nearest",
            Resample::Bilinear => "bilinear",
            Resample::CatmullRom => "catmull-rom",
        }
    }

    /// The kernels' code for the filter (`warp.wgsl`'s `RESAMPLE_*`).
    pub fn code(self) -> u32 {
        self as u32
    }
}

impl std::fmt::Display for Resample {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Resample {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Resample::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| format!("unknown filter {s:?} (nearest, bilinear, catmull-rom)"))
    }
}

/// Relative spread below which taps count as flat: 2⁻¹², at most the
/// rounding error of the `f16` output (half a step of its 10-bit
/// mantissa), so taking the pixel itself differs from filtering by less
/// than the output's own rounding.
pub const FLAT: f32 = 1.0 / 4096.0;

/// Largest ratio between two depths of one surface (the warp's crack test
/// uses the same).
pub const SAME_SURFACE_RATIO: f32 = 1.1;

/// Whether depths `a` and `b` (sanitised: 0 = no surface, `+inf` = sky)
/// belong to one surface.
/// (The larger within [`SAME_SURFACE_RATIO`] of the smaller, which must be
/// a surface; two skies agree, a sky and a point do not.)
#[inline]
pub fn same_surface(a: f32, b: f32) -> bool {
    // Selects and non-short-circuit `&`, no branches: the bilinear taps
    // and the shading estimate ask this per pixel.
    let (lo, hi) = if a >= b { (b, a) } else { (a, b) };
    (lo > 0.0) & (hi <= lo * SAME_SURFACE_RATIO)
}

/// Whether every depth of the rows of taps `rows` is on the surface of
/// depth `d0` (`same_surface(d, d0)` for each), as one test of their
/// range: the nearest and the farthest, `d0` among them, within the ratio
/// of `d0` and positive. The same answer as the tests one by one
/// (rounding of `d · ratio` is monotonic), four taps at a time, without
/// early exits or a branch per tap: the Catmull-Rom filter asks it of 16
/// taps per pixel, most of them inside a surface. A NaN tap fails, as
/// `same_surface` says of it.
#[inline]
fn all_on_surface(rows: impl IntoIterator<Item = Vec4>, d0: f32) -> bool {
    let (mut near, mut far, mut nan) = (Vec4::splat(d0), Vec4::splat(d0), false);
    for row in rows {
        // Exact where no lane is NaN; a NaN fails below whatever they hold.
        near = near.min(row);
        far = far.max(row);
        nan |= row.is_nan();
    }
    let (near, far) = (near.min_element(), far.max_element());
    !nan & (near > 0.0) & (far <= d0 * SAME_SURFACE_RATIO) & (d0 <= near * SAME_SURFACE_RATIO)
}

/// The source image a warp resamples.
#[derive(Clone, Copy, Debug)]
pub struct Source<'a> {
    /// Linear RGB (alpha ignored).
    pub color: &'a [[f32; 4]],
    /// Sanitised depth.
    pub depth: &'a [f32],
    /// Width and height.
    pub size: (u32, u32),
}

/// Where the colour of target pixel centre `center` lies in the source
/// image: the winner `i`'s centre `source` moved by the offset between the
/// centre and `landing()` (where `i` lands in the target), converted to
/// source pixels by `per_pixel` (source pixels per target pixel, the
/// reciprocal of the display map's scale, taken once per frame: a division
/// per pixel cost the CPU warp 4 % of its time) and clamped to half a
/// pixel. Nearest keeps `source` (and never asks where it landed).
#[inline]
pub fn position(
    source: Vec2,
    landing: impl FnOnce() -> Vec2,
    center: Vec2,
    per_pixel: Vec2,
    mode: Resample,
) -> Vec2 {
    if mode == Resample::Nearest {
        return source;
    }
    let offset = ((center - landing()) * per_pixel).clamp(Vec2::splat(-0.5), Vec2::splat(0.5));
    source + offset
}

/// Catmull-Rom weights of the four taps around a fraction `f ∈ [0, 1)`.
#[inline]
pub(crate) fn catmull_rom(f: f32) -> [f32; 4] {
    let f2 = f * f;
    let f3 = f2 * f;
    [
        -0.5 * f3 + f2 - 0.5 * f,
        1.5 * f3 - 2.5 * f2 + 1.0,
        -1.5 * f3 + 2.0 * f2 + 0.5 * f,
        0.5 * f3 - 0.5 * f2,
    ]
}

/// `⌊v⌋` as `v.floor() as i32` gives it (saturating, NaN 0) without a
/// library call (baseline x86-64 has no rounding instruction): the
/// truncation, one less for negative non-integers. Below −2³¹ the
/// truncation is already `i32::MIN`, where one less would overflow (a
/// panic in debug builds, `i32::MAX` in release): the subtraction
/// saturates. Shading correction's per-pixel floors use it too (`floorf`
/// is a call on this target and cost a tenth of the shading estimate).
#[inline]
pub(crate) fn floor(v: f32) -> i32 {
    let t = v as i32;
    t.saturating_sub(i32::from(v < t as f32))
}

/// The colour of `src` at continuous position `at` with filter `mode`,
/// restricted to the surface of pixel `own` (see the module doc).
///
/// Always inlined into the pixel loops that call it (the warp's resolve,
/// interpolation's): called, it spilled what it had to the stack and took
/// 3–6 % more of the CPU warp's time at 1280×720.
#[inline(always)]
pub fn resample(src: Source<'_>, own: usize, at: Vec2, mode: Resample) -> [f32; 3] {
    let fallback = src.color[own];
    if mode == Resample::Nearest {
        return [fallback[0], fallback[1], fallback[2]];
    }
    let q = at - 0.5;
    let (bx, by) = (floor(q.x), floor(q.y));
    let taps = Taps {
        f: q - Vec2::new(bx as f32, by as f32),
        d0: src.depth[own],
        fallback,
        mode,
    };
    // Tap columns bx − 1 ..= bx + 2 and rows by − 1 ..= by + 2. Inside the
    // image the taps lie in one span of its pixels, taken with one bounds
    // check (a struct of a row reference per tap row cost a tenth more of
    // the warp's resolve); at its border they are clamped into it, one by
    // one.
    if let Some(window) = Window::inside(src, bx, by) {
        return taps.filter(|i, j| window.color(i, j), |j| window.depths(j));
    }
    let (w, h) = (src.size.0 as i32, src.size.1 as i32);
    let column = |i: i32| (bx + i - 1).clamp(0, w - 1) as usize;
    let row = |j: i32| (by + j - 1).clamp(0, h - 1) as usize * w as usize;
    let xs = [column(0), column(1), column(2), column(3)];
    let ys = [row(0), row(1), row(2), row(3)];
    taps.filter(
        |i, j| Vec4::from_array(src.color[ys[j] + xs[i]]),
        |j| {
            let d = |i: usize| src.depth[ys[j] + xs[i]];
            Vec4::new(d(0), d(1), d(2), d(3))
        },
    )
}

/// The 4×4 taps of a position whose taps all lie inside the image: four
/// rows of four neighbours, `stride` apart in the image's rows.
struct Window<'a> {
    color: &'a [[f32; 4]],
    depth: &'a [f32],
    stride: usize,
}

impl<'a> Window<'a> {
    /// The taps of columns `bx − 1 ..= bx + 2` and rows `by − 1 ..= by + 2`,
    /// or `None` where some lie outside the image.
    #[inline]
    fn inside(src: Source<'a>, bx: i32, by: i32) -> Option<Self> {
        let (w, h) = (src.size.0 as i32, src.size.1 as i32);
        if bx < 1 || by < 1 || bx + 2 >= w || by + 2 >= h {
            return None;
        }
        let stride = w as usize;
        let first = (by - 1) as usize * stride + (bx - 1) as usize;
        let taps = first..first + 3 * stride + 4;
        Some(Self {
            color: src.color.get(taps.clone())?,
            depth: src.depth.get(taps)?,
            stride,
        })
    }

    /// Tap column `i`, row `j`.
    #[inline(always)]
    fn color(&self, i: usize, j: usize) -> Vec4 {
        Vec4::from_array(self.color[j * self.stride + i])
    }

    /// Row `j`'s four depths.
    #[inline(always)]
    fn depths(&self, j: usize) -> Vec4 {
        let o = j * self.stride;
        Vec4::from_slice(&self.depth[o..o + 4])
    }
}

/// What [`resample`] filters with, besides the taps themselves.
struct Taps {
    /// The position's fraction past the inner top-left tap's centre.
    f: Vec2,
    /// The depth of `own`, whose surface the taps must be on.
    d0: f32,
    /// `own`'s colour.
    fallback: [f32; 4],
    mode: Resample,
}

impl Taps {
    /// The filtered colour from `color(i, j)`, tap column `i` and row `j`
    /// of the 4×4 (the inner 2×2 are 1 and 2), and `depths(j)`, row `j`'s
    /// four depths.
    #[inline(always)]
    fn filter(
        &self,
        color: impl Fn(usize, usize) -> Vec4,
        depths: impl Fn(usize) -> Vec4,
    ) -> [f32; 3] {
        let Self {
            f,
            d0,
            fallback,
            mode,
        } = *self;
        // The inner 2×2 taps (`own` is one of them) bound every result
        // below, channel by channel: the clamped Catmull-Rom, the bilinear
        // over any of them, `own`. Where they are flat to within the
        // rounding of the `f16` output, no filter changes the stored
        // colour: take `own`.
        let c = [color(1, 1), color(2, 1), color(1, 2), color(2, 2)];
        let lo = c[0].min(c[1]).min(c[2].min(c[3]));
        let hi = c[0].max(c[1]).max(c[2].max(c[3]));
        if (hi - lo).cmple(hi * FLAT).all() {
            return [fallback[0], fallback[1], fallback[2]];
        }
        if mode == Resample::CatmullRom && all_on_surface((0..4).map(&depths), d0) {
            // Separable: each row along x, then the rows along y.
            let (wx, wy) = (catmull_rom(f.x), catmull_rom(f.y));
            let mut sum = Vec4::ZERO;
            for (j, wyj) in wy.into_iter().enumerate() {
                let mut across = Vec4::ZERO;
                for (i, wxi) in wx.into_iter().enumerate() {
                    across += color(i, j) * wxi;
                }
                sum += across * wyj;
            }
            let c = sum.clamp(lo, hi);
            return [c.x, c.y, c.z];
        }
        // The inner two rows' depths, each read once for its two taps.
        let inner = [depths(1), depths(2)];
        let mut sum = Vec4::ZERO;
        let mut weight = 0.0;
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            if same_surface(inner[dy][dx + 1], d0) {
                let wx = if dx == 0 { 1.0 - f.x } else { f.x };
                let wy = if dy == 0 { 1.0 - f.y } else { f.y };
                sum += color(dx + 1, dy + 1) * (wx * wy);
                weight += wx * wy;
            }
        }
        if weight > 1e-6 {
            let c = sum / weight;
            return [c.x, c.y, c.z];
        }
        [fallback[0], fallback[1], fallback[2]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_range_test_of_a_surface_is_the_tests_one_by_one() {
        use proptest::prelude::*;
        // Uniform in `lo..hi` from a whole number: proptest's own `f32`
        // ranges trip a debug assertion of its sampler now and then (about
        // one draw in ten million of `0.95..1.08`, which this test draws
        // some 300 000 times: one run in thirty failed).
        let uniform = |lo: f32, hi: f32| {
            (0u32..1 << 24).prop_map(move |k| lo + (hi - lo) * (k as f32 / (1u32 << 24) as f32))
        };
        // The own depth: ordinary, tiny, huge (log-uniform), and the
        // sanitised specials (no surface, sky) and NaN.
        let own = prop_oneof![
            6 => uniform(0.5, 2.0),
            1 => uniform(-30.0, 30.0).prop_map(|e| 10f32.powf(e)),
            1 => Just(0.0f32),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NAN),
        ];
        // Taps as multiples of it: mostly one surface (so that all 16 are
        // on it in about a fifth of the cases), some just beyond the ratio
        // or exactly at it, and the specials.
        let factor = prop_oneof![
            60 => uniform(0.95, 1.08),
            1 => uniform(0.85, 0.95),
            1 => uniform(1.08, 1.15),
            1 => (-1i32..=1).prop_map(|k| SAME_SURFACE_RATIO.powi(k)),
            1 => Just(0.0f32),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NAN),
        ];
        let cases = (proptest::collection::vec(factor, 16), own);
        let on = std::cell::Cell::new(0usize);
        proptest!(ProptestConfig::with_cases(20_000), |((factors, d0) in cases)| {
            let taps: Vec<f32> = factors.iter().map(|f| f * d0).collect();
            let one_by_one = taps.iter().all(|&d| same_surface(d, d0));
            let rows = taps.chunks(4).map(Vec4::from_slice);
            prop_assert_eq!(all_on_surface(rows, d0), one_by_one);
            on.set(on.get() + usize::from(one_by_one));
        });
        let on = on.get();
        assert!(on > 1000, "only {on} cases of taps all on the surface");
    }

    /// A horizontal ramp: every linear filter reproduces it exactly, so a
    /// resampled value is the ramp at the sampled position.
    fn ramp(w: u32, h: u32) -> (Vec<[f32; 4]>, Vec<f32>) {
        let color = (0..w * h)
            .map(|i| {
                let x = (i % w) as f32 + 0.5;
                [x, 2.0 * x, 1.0, 1.0]
            })
            .collect();
        (color, vec![5.0; (w * h) as usize])
    }

    #[test]
    fn filters_reproduce_a_ramp_at_the_sub_pixel_position() {
        let (color, depth) = ramp(8, 8);
        let src = Source {
            color: &color,
            depth: &depth,
            size: (8, 8),
        };
        let own = 3 * 8 + 4;
        let at = Vec2::new(4.5 + 0.3, 3.5 - 0.2);
        for mode in [Resample::Bilinear, Resample::CatmullRom] {
            let c = resample(src, own, at, mode);
            assert!((c[0] - 4.8).abs() < 1e-5, "{mode}: {c:?}");
            assert!((c[1] - 9.6).abs() < 1e-5, "{mode}: {c:?}");
        }
        assert_eq!(resample(src, own, at, Resample::Nearest), [4.5, 9.0, 1.0]);
    }

    #[test]
    fn taps_off_the_surface_take_no_part() {
        let (mut color, mut depth) = ramp(8, 8);
        // Column 5 is another surface (nearer), bright.
        for y in 0..8 {
            depth[y * 8 + 5] = 1.0;
            color[y * 8 + 5] = [1000.0; 4];
        }
        let src = Source {
            color: &color,
            depth: &depth,
            size: (8, 8),
        };
        let own = 3 * 8 + 4;
        for mode in [Resample::Bilinear, Resample::CatmullRom] {
            let c = resample(src, own, Vec2::new(4.9, 3.5), mode);
            assert!((c[0] - 4.5).abs() < 1e-5, "{mode}: {c:?}");
        }
        // No surface at all around: the pixel's own colour.
        let none = vec![0.0; 64];
        let src = Source {
            depth: &none,
            ..src
        };
        assert_eq!(
            resample(src, own, Vec2::new(4.9, 3.5), Resample::CatmullRom),
            [4.5, 9.0, 1.0]
        );
    }

    #[test]
    fn catmull_rom_does_not_ring_around_a_highlight() {
        let mut color = vec![[1.0f32; 4]; 64];
        color[3 * 8 + 3] = [60000.0; 4];
        let depth = vec![5.0; 64];
        let src = Source {
            color: &color,
            depth: &depth,
            size: (8, 8),
        };
        for x in 0..8 {
            for y in 0..8 {
                let own = y * 8 + x;
                let at = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + Vec2::new(0.37, -0.41);
                let c = resample(src, own, at, Resample::CatmullRom);
                assert!(
                    c.iter()
                        .all(|v| v.is_finite() && (1.0..=60000.0).contains(v)),
                    "{c:?}"
                );
            }
        }
    }

    #[test]
    fn the_offset_is_clamped_and_nearest_keeps_the_source() {
        let s = Vec2::new(10.5, 4.5);
        let p = position(
            s,
            || Vec2::new(3.2, 3.9),
            Vec2::new(3.5, 3.5),
            Vec2::ONE,
            Resample::Bilinear,
        );
        assert!((p - Vec2::new(10.8, 4.1)).length() < 1e-5);
        let far = position(
            s,
            || Vec2::ZERO,
            Vec2::splat(9.0),
            Vec2::ONE,
            Resample::CatmullRom,
        );
        assert_eq!(far, s + 0.5);
        let unasked = || unreachable!("nearest asked where it landed");
        let near = position(s, unasked, Vec2::ONE, Vec2::ONE, Resample::Nearest);
        assert_eq!(near, s);
    }

    #[test]
    fn flat_taps_give_the_pixel_itself() {
        let mut color = vec![[2.0f32, 3.0, 4.0, 1.0]; 64];
        // Within the f16 output's rounding of its neighbours.
        color[3 * 8 + 4] = [2.0 * (1.0 + 1.0 / 8192.0), 3.0, 4.0, 1.0];
        let depth = vec![5.0; 64];
        let src = Source {
            color: &color,
            depth: &depth,
            size: (8, 8),
        };
        let own = 3 * 8 + 3;
        for mode in Resample::ALL {
            assert_eq!(
                resample(src, own, Vec2::new(3.9, 3.7), mode),
                [2.0, 3.0, 4.0]
            );
        }
        // A real edge is filtered.
        color[3 * 8 + 4] = [3.0, 3.0, 4.0, 1.0];
        let src = Source {
            color: &color,
            depth: &depth,
            size: (8, 8),
        };
        let c = resample(src, own, Vec2::new(3.9, 3.7), Resample::Bilinear);
        assert!(c[0] > 2.1 && c[0] < 3.0, "{c:?}");
    }

    #[test]
    fn surfaces() {
        let inf = f32::INFINITY;
        assert!(same_surface(5.0, 5.4) && same_surface(5.4, 5.0));
        assert!(!same_surface(5.0, 5.6) && !same_surface(5.6, 5.0));
        assert!(same_surface(inf, inf));
        assert!(!same_surface(inf, 5.0) && !same_surface(5.0, inf));
        assert!(!same_surface(0.0, 0.0) && !same_surface(0.0, 5.0) && !same_surface(5.0, 0.0));
    }

    #[test]
    fn floor_is_the_floor() {
        for v in [
            -2.5f32,
            -1.0,
            -0.5,
            -1e-7,
            0.0,
            1e-7,
            0.5,
            1.0,
            3.999_999_8,
            1e6 + 0.5,
            // Where the truncation saturates, and beyond.
            -2_147_483_648.0,
            -2_147_483_904.0,
            -3e9,
            f32::MIN,
            f32::NEG_INFINITY,
            2_147_483_520.0,
            2_147_483_648.0,
            3e9,
            f32::MAX,
            f32::INFINITY,
            f32::NAN,
        ] {
            assert_eq!(floor(v), v.floor() as i32, "{v}");
        }
    }

    #[test]
    fn names_round_trip() {
        for r in Resample::ALL {
            assert_eq!(r.name().parse::<Resample>().unwrap(), r);
        }
        assert!("cubic".parse::<Resample>().is_err());
    }
}
