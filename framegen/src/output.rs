//! The buffers of a generated frame while passes fill it, shared by the CPU
//! reference and mirrored by the GPU buffers: color, depth, motion and the
//! per-pixel source mask.

use glam::Vec2;

/// Nothing has written the pixel yet (a hole).
pub const EMPTY: u32 = 0;
/// Written by the forward warp (GFFE §4.1).
pub const WARPED: u32 = 1;
/// Filled from the background layers (GFFE §4.2).
pub const BACKGROUND: u32 = 2;
/// Filled by push-pull: no source had it (DESIGN §4 step 7).
pub const FILLED: u32 = 3;
/// Copied from the rendered frame (the `repeat` baseline and window crop).
pub const COPIED: u32 = 4;
/// A one-pixel crack of the forward warp closed from its two warped
/// neighbours (reported as warped).
pub const CRACK: u32 = 5;

/// Where a generated pixel came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PixelSource {
    /// Forward-warped from the rendered frame.
    Warped = 1,
    /// From the background layers.
    Background = 2,
    /// Push-pull filled (no source had it).
    Filled = 3,
    /// Copied from the rendered frame (repeat).
    Copied = 4,
}

impl PixelSource {
    /// The source a pass's mask value reports ([`CRACK`] as warped, an
    /// unknown value as filled).
    pub fn from_mask(m: u32) -> Self {
        match m {
            WARPED | CRACK => PixelSource::Warped,
            BACKGROUND => PixelSource::Background,
            COPIED => PixelSource::Copied,
            _ => PixelSource::Filled,
        }
    }
}

/// Maps a continuous pixel position of the rendered frame to the displayed
/// region's pixels: `(p − offset) · scale`. The identity for a plain window;
/// the crop of the adaptive window (DESIGN §4.5) otherwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplayMap {
    /// Top-left corner of the displayed region in rendered pixels.
    pub offset: Vec2,
    /// Displayed pixels per rendered pixel.
    pub scale: Vec2,
}

impl DisplayMap {
    /// The identity map.
    pub const IDENTITY: DisplayMap = DisplayMap {
        offset: Vec2::ZERO,
        scale: Vec2::ONE,
    };

    /// Applies the map.
    pub fn apply(&self, p: Vec2) -> Vec2 {
        (p - self.offset) * self.scale
    }

    /// As a WGSL `vec4` (offset, scale).
    pub fn to_array(&self) -> [f32; 4] {
        [self.offset.x, self.offset.y, self.scale.x, self.scale.y]
    }
}

/// A band of whole rows of an [`Output`] being made
/// ([`Output::from_rows`]).
#[derive(Debug)]
pub struct Rows<'a> {
    first: usize,
    color: &'a mut [[f32; 4]],
    depth: &'a mut [f32],
    motion: &'a mut [[f32; 2]],
    mask: &'a mut [u32],
}

impl Rows<'_> {
    /// The band as it stands, read only.
    pub fn band(&self) -> Band<'_> {
        Band {
            color: self.color,
            depth: self.depth,
            motion: self.motion,
            mask: self.mask,
        }
    }

    /// The same band, borrowed again (to write it, then read it).
    pub fn reborrow(&mut self) -> Rows<'_> {
        Rows {
            first: self.first,
            color: self.color,
            depth: self.depth,
            motion: self.motion,
            mask: self.mask,
        }
    }

    /// The frame's pixel indices the band holds.
    pub fn pixels(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.mask.len()
    }

    /// Sets the `N` pixels from `t` on (of the frame, in [`Rows::pixels`])
    /// to `color`, `depth`, `motion` and `mask`.
    #[inline]
    pub fn set_run<const N: usize>(
        &mut self,
        t: usize,
        color: &[[f32; 4]; N],
        depth: &[f32; N],
        motion: &[[f32; 2]; N],
        mask: u32,
    ) {
        let k = t - self.first;
        self.color[k..k + N].copy_from_slice(color);
        self.depth[k..k + N].copy_from_slice(depth);
        self.motion[k..k + N].copy_from_slice(motion);
        self.mask[k..k + N].fill(mask);
    }

    /// Sets pixel `t` (of the frame, in [`Rows::pixels`]).
    #[inline]
    pub fn set(&mut self, t: usize, p: Pixel) {
        let k = t - self.first;
        self.color[k] = p.color;
        self.depth[k] = p.depth;
        self.motion[k] = p.motion;
        self.mask[k] = p.mask;
    }
}

/// Consecutive pixels of an [`Output`], read only (`pack`'s bands).
#[derive(Clone, Copy, Debug)]
pub struct Band<'a> {
    /// Linear RGB, alpha 1 where written.
    pub color: &'a [[f32; 4]],
    /// Linear view depth.
    pub depth: &'a [f32],
    /// Motion, displayed pixels.
    pub motion: &'a [[f32; 2]],
    /// Where each came from ([`EMPTY`], [`WARPED`], ...).
    pub mask: &'a [u32],
}

/// Pixels [`holes_in`] tests together.
const HOLE_RUN: usize = 64;

/// The holes ([`EMPTY`]) of `mask`, the mask of the pixels from `first` on,
/// in order: runs of pixels are tested together first (a loop the
/// compiler vectorizes), since after the warp holes are few.
pub fn holes_in(mask: &[u32], first: usize) -> impl Iterator<Item = usize> + '_ {
    mask.chunks(HOLE_RUN).enumerate().flat_map(move |(r, run)| {
        let any = run.iter().fold(false, |any, &m| any | (m == EMPTY));
        let at = move |(i, &m): (usize, &u32)| (m == EMPTY).then_some(first + r * HOLE_RUN + i);
        let holes = any.then(|| run.iter().enumerate().filter_map(at));
        holes.into_iter().flatten()
    })
}

/// A generated frame in the making (CPU reference).
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, alpha 1 where written.
    pub color: Vec<[f32; 4]>,
    /// Linear view depth in the generated frame's camera (`+inf` sky).
    pub depth: Vec<f32>,
    /// Motion to the rendered frame it was made from, in displayed pixels.
    pub motion: Vec<[f32; 2]>,
    /// Per pixel: [`EMPTY`], [`WARPED`], [`BACKGROUND`], [`FILLED`] or
    /// [`COPIED`].
    pub mask: Vec<u32>,
}

impl Output {
    /// An all-empty frame.
    pub fn empty(width: u32, height: u32) -> Self {
        Self::from_fn(width, height, |_| Pixel::EMPTY)
    }

    /// A frame whose pixel `t` is `pixel(t)`, made on all cores with every
    /// buffer written once (a pass that writes every pixel builds its
    /// output this way instead of clearing one and writing it again).
    pub fn from_fn(width: u32, height: u32, pixel: impl Fn(usize) -> Pixel + Sync + Send) -> Self {
        use rayon::prelude::*;
        let n = width as usize * height as usize;
        let (color, (depth, (motion, mask))) = (0..n)
            .into_par_iter()
            .map(|t| {
                let p = pixel(t);
                (p.color, (p.depth, (p.motion, p.mask)))
            })
            .unzip();
        Self {
            width,
            height,
            color,
            depth,
            motion,
            mask,
        }
    }

    /// The frame `band` makes, band by band on all cores: each call gets a
    /// band of whole rows ([`Rows`]), all holes, and sets the pixels it
    /// makes. For a pass that makes several pixels at once
    /// (`warp::resolve_runs`); [`Output::from_fn`] is one at a time.
    pub fn from_rows(width: u32, height: u32, band: impl Fn(Rows<'_>) + Sync + Send) -> Self {
        let each = vec![(); Self::bands(width, height)];
        Self::from_rows_with(width, height, each, |rows, ()| band(rows))
    }

    /// How many bands [`Output::from_rows`] makes a `width`×`height`
    /// frame in, and how many pixels each holds (the last one fewer).
    pub fn bands(width: u32, height: u32) -> usize {
        let n = width as usize * height as usize;
        n.div_ceil(Self::band_len(width, height))
    }

    /// Pixels of each band of [`Output::from_rows`].
    pub fn band_len(width: u32, height: u32) -> usize {
        crate::par::band(width as usize, width as usize * height as usize)
    }

    /// [`Output::from_rows`] with something of its own for each band:
    /// `each[k]` ([`Output::bands`] of them) goes to the `k`-th band's
    /// call, for what it makes alongside (`pack::resolved`).
    pub fn from_rows_with<P: Send>(
        width: u32,
        height: u32,
        each: Vec<P>,
        band: impl Fn(Rows<'_>, P) + Sync + Send,
    ) -> Self {
        let n = width as usize * height as usize;
        let e = Pixel::EMPTY;
        // Each band is filled with holes where it is made, while it is in
        // the cache (`par::bands4`), not in a pass over the whole frame
        // first (about 0.9 ms of a 720p warp on two cores).
        let b = Self::band_len(width, height);
        let fill = (e.color, e.depth, e.motion, e.mask);
        let make = |k, p, color: &mut _, depth: &mut _, motion: &mut _, mask: &mut _| {
            let first = k * b;
            let rows = Rows {
                first,
                color,
                depth,
                motion,
                mask,
            };
            band(rows, p)
        };
        let planes = crate::par::bands4_with(n, b, fill, each, make);
        Self {
            width,
            height,
            color: planes.0,
            depth: planes.1,
            motion: planes.2,
            mask: planes.3,
        }
    }

    /// Pixels `range` of the frame, read only.
    pub fn band(&self, range: std::ops::Range<usize>) -> Band<'_> {
        Band {
            color: &self.color[range.clone()],
            depth: &self.depth[range.clone()],
            motion: &self.motion[range.clone()],
            mask: &self.mask[range],
        }
    }

    /// Number of pixels with the given mask value, counted on all cores (a
    /// loop the compiler vectorizes).
    pub fn count(&self, mask: u32) -> usize {
        use rayon::prelude::*;
        let runs = self.mask.par_chunks(4096);
        runs.map(|run| run.iter().map(|&m| usize::from(m == mask)).sum::<usize>())
            .sum()
    }

    /// Where the holes ([`EMPTY`]) are, in order, found on all cores
    /// ([`holes_in`] of each run of pixels).
    pub fn holes(&self) -> Vec<usize> {
        use rayon::prelude::*;
        (self.mask.par_chunks(HOLE_RUN).enumerate())
            .flat_map_iter(|(r, run)| holes_in(run, r * HOLE_RUN))
            .collect()
    }

    /// Every pixel with its index, for a CPU pass that writes each pixel
    /// from its own task on all cores (rayon; the result does not depend on
    /// the thread count).
    pub fn par_pixels_mut(
        &mut self,
    ) -> impl rayon::iter::IndexedParallelIterator<Item = (usize, PixelMut<'_>)> {
        use rayon::prelude::*;
        (
            &mut self.color,
            &mut self.depth,
            &mut self.motion,
            &mut self.mask,
        )
            .into_par_iter()
            .map(|(color, depth, motion, mask)| PixelMut {
                color,
                depth,
                motion,
                mask,
            })
            .enumerate()
    }
}

/// A generated frame in the making on the GPU: the buffers of an
/// [`Output`], which every pass that writes the frame binds (the warp,
/// background fill, push-pull, crop, packing, interpolation's passes).
#[derive(Debug, Clone, Copy)]
pub struct GpuOutput<'a> {
    /// `vec4<f32>` color.
    pub color: &'a wgpu::Buffer,
    /// `f32` depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec2<f32>` motion.
    pub motion: &'a wgpu::Buffer,
    /// `u32` mask.
    pub mask: &'a wgpu::Buffer,
}

/// One pixel of an [`Output`], by value ([`Output::from_fn`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pixel {
    /// Linear RGB, alpha.
    pub color: [f32; 4],
    /// Linear view depth.
    pub depth: f32,
    /// Motion to the rendered frame, displayed pixels.
    pub motion: [f32; 2],
    /// Where it came from.
    pub mask: u32,
}

impl Pixel {
    /// A hole: nothing written.
    pub const EMPTY: Pixel = Pixel {
        color: [0.0; 4],
        depth: 0.0,
        motion: [0.0; 2],
        mask: EMPTY,
    };
}

/// One pixel of an [`Output`], writable ([`Output::par_pixels_mut`]).
#[derive(Debug)]
pub struct PixelMut<'a> {
    /// Linear RGB, alpha.
    pub color: &'a mut [f32; 4],
    /// Linear view depth.
    pub depth: &'a mut f32,
    /// Motion to the rendered frame, displayed pixels.
    pub motion: &'a mut [f32; 2],
    /// Where it came from.
    pub mask: &'a mut u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The holes found run by run are every hole, in order, and counted
    /// alike (each mask value is): frames whose size is no multiple of the run, with no hole,
    /// every pixel a hole, holes at both ends, and scattered ones.
    #[test]
    fn holes_are_every_empty_pixel_in_order() {
        for (w, h) in [(1, 1), (37, 23), (64, 2), (130, 65)] {
            let n = (w * h) as usize;
            let patterns: [&dyn Fn(usize) -> bool; 4] =
                [&|_| false, &|_| true, &|t| t == 0 || t + 1 == n, &|t| {
                    (t * 7919) % 23 < 2
                }];
            for (p, hole) in patterns.iter().enumerate() {
                let mut out = Output::empty(w, h);
                for (t, m) in out.mask.iter_mut().enumerate() {
                    if !hole(t) {
                        *m = WARPED + (t % 3) as u32;
                    }
                }
                let expected: Vec<usize> = (0..n).filter(|&t| out.mask[t] == EMPTY).collect();
                assert_eq!(out.holes(), expected, "{w}×{h} pattern {p}");
                for m in [EMPTY, WARPED, BACKGROUND, FILLED] {
                    let plain = out.mask.iter().filter(|&&v| v == m).count();
                    assert_eq!(out.count(m), plain, "{w}×{h} pattern {p} mask {m}");
                }
                assert_eq!(out.count(EMPTY), expected.len());
            }
        }
    }
}
