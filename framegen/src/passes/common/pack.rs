//! The generated frame as it leaves the passes for the display, the dump
//! and the wire (GFFE §7.1: colour, depth and motion like a rendered
//! frame): colour sanitised (non-finite and non-positive values to 0, the
//! rest clamped to the largest `f16`) and rounded to the nearest `f16`,
//! depth `+inf` where no surface was written, motion with non-finite
//! components zeroed, and one byte per pixel for its [`PixelSource`].
//!
//! The wgpu executor packs on the device, so a generated frame crosses the
//! bus in 21 bytes a pixel (`f16` colour 8, depth 4, motion 8, source 1)
//! instead of the passes' 32 (`f32` colour, `u32` mask), and the host only
//! copies it into place. [`pack`] is the CPU reference, bit for bit: the
//! kernel rounds to `f16` with integer arithmetic (round to nearest, ties
//! to even, subnormals kept), where WGSL's `pack2x16float` leaves the
//! rounding to the implementation.

use half::f16;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::input::{CONVERT_BLOCK, MAX_RADIANCE};
use crate::output::{Band, Output, PixelSource, Rows};

/// A generated frame's buffers, packed.
#[derive(Clone, Debug, PartialEq)]
pub struct Packed {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, alpha 1.
    pub color: Vec<[f16; 4]>,
    /// Linear view depth, `+inf` where there is no surface.
    pub depth: Vec<f32>,
    /// Motion to the rendered frame it was made from, finite.
    pub motion: Vec<[f32; 2]>,
    /// Where each pixel came from.
    pub mask: Vec<PixelSource>,
}

/// A colour channel as the packed frame keeps it (before the rounding to
/// `f16`): non-finite and non-positive values (`-0` too) become `+0`.
#[inline]
pub fn radiance(v: f32) -> f32 {
    if v.is_finite() && v > 0.0 {
        v.min(MAX_RADIANCE)
    } else {
        0.0
    }
}

/// CPU reference of `pack`, on all cores, band by band into buffers made
/// where they are written ([`pack_band`]).
pub fn pack(out: &Output) -> Packed {
    let b = crate::par::band(out.width as usize, out.mask.len());
    made(out.width, out.height, b, |k, to| {
        let first = k * b;
        pack_band(out.band(first..first + to.mask.len()), to);
    })
}

/// A frame made band by band by `band` ([`Output::from_rows`]) and packed
/// as each band is made, while it is in the cache, instead of in a pass
/// over the finished frame that reads it all back ([`pack`]), with the
/// holes each band was left with. The passes after the warp's resolve
/// write only holes (closing cracks, background fill, push-pull), so
/// packing those pixels again ([`repack`]) gives [`pack`] of the frame they
/// finish.
#[derive(Debug)]
pub struct Resolved {
    /// The frame as `band` made it.
    pub out: Output,
    /// It packed.
    pub packed: Packed,
    /// Its holes ([`crate::output::EMPTY`]), in order.
    pub holes: Vec<usize>,
}

/// [`Resolved`] of the `width`×`height` frame `band` makes.
pub fn resolved(width: u32, height: u32, band: impl Fn(Rows<'_>) + Sync + Send) -> Resolved {
    let n = width as usize * height as usize;
    let b = Output::band_len(width, height);
    let (mut color, mut depth) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut motion, mut mask) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut lists = vec![Vec::new(); Output::bands(width, height)];
    // The packed buffers split into the output's bands, and a list of
    // holes for each.
    let each: Vec<_> = (color.spare_capacity_mut()[..n].chunks_mut(b))
        .zip(depth.spare_capacity_mut()[..n].chunks_mut(b))
        .zip(motion.spare_capacity_mut()[..n].chunks_mut(b))
        .zip(mask.spare_capacity_mut()[..n].chunks_mut(b))
        .zip(lists.iter_mut())
        .collect();
    let bands = each.len();
    let out = Output::from_rows_with(width, height, each, |mut rows, ((((c, d), m), s), list)| {
        use crate::par::init;
        band(rows.reborrow());
        let to = PackedBand {
            color: init(c, [f16::ZERO; 4]),
            depth: init(d, 0.0),
            motion: init(m, [0.0; 2]),
            mask: init(s, PixelSource::Filled),
        };
        let from = rows.band();
        pack_band(from, to);
        list.extend(crate::output::holes_in(from.mask, rows.pixels().start));
    });
    // `from_rows_with` takes one item per band and hands each to a call.
    assert_eq!(bands, Output::bands(width, height));
    // SAFETY: the bands cover the first `n` slots of each buffer (`n` cut
    // in bands of `b`, as the output is), each handed to one call of the
    // band loop, which wrote every slot (`init`) before it returned.
    unsafe {
        color.set_len(n);
        depth.set_len(n);
        motion.set_len(n);
        mask.set_len(n);
    }
    Resolved {
        out,
        packed: Packed::of_planes(width, height, (color, depth, motion, mask)),
        holes: lists.concat(),
    }
}

/// Packs pixels `at` of `out` again into `packed`, [`pack`] of `out`
/// everywhere else (see [`Resolved`]): afterwards it is [`pack`] of `out`.
/// `at` is ascending (the holes as [`resolved`] lists them); indices
/// outside the frame are skipped.
///
/// On all cores, band by band of the packed frame, each band with the
/// stretch of `at` inside it: the listed pixels are scattered, and one by
/// one they wait on the cache (about 80 ns each, 0.9 ms for the 10 000
/// holes of a 720p default-scene frame on one core).
pub fn repack(out: &Output, packed: &mut Packed, at: &[usize]) {
    use rayon::prelude::*;
    debug_assert!(at.is_sorted(), "pixels listed in order");
    let b = Output::band_len(packed.width, packed.height);
    let Packed {
        color,
        depth,
        motion,
        mask,
        ..
    } = packed;
    let bands = (color.par_chunks_mut(b))
        .zip(depth.par_chunks_mut(b))
        .zip(motion.par_chunks_mut(b))
        .zip(mask.par_chunks_mut(b))
        .enumerate();
    bands.for_each(|(k, (((color, depth), motion), mask))| {
        let band = PackedBand {
            color,
            depth,
            motion,
            mask,
        };
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
            // SAFETY: the CPU has both, just checked.
            return unsafe { repack_band_f16c(out, band, k * b, at) };
        }
        repack_band(out, band, k * b, at, packed_color);
    });
}

/// [`repack`] of the band from pixel `first`, its colour packed by
/// `packed_color`.
#[inline(always)]
fn repack_band(
    out: &Output,
    band: PackedBand<'_>,
    first: usize,
    at: &[usize],
    packed_color: impl Fn([f32; 4]) -> [f16; 4],
) {
    let PackedBand {
        color,
        depth,
        motion,
        mask,
    } = band;
    let from = |t: usize| at.partition_point(|&i| i < t);
    for &t in &at[from(first)..from(first + color.len())] {
        let (Some(&c), Some(&d), Some(&m), Some(&s)) = (
            out.color.get(t),
            out.depth.get(t),
            out.motion.get(t),
            out.mask.get(t),
        ) else {
            continue;
        };
        let i = t - first;
        if let (Some(pc), Some(pd), Some(pm), Some(ps)) = (
            color.get_mut(i),
            depth.get_mut(i),
            motion.get_mut(i),
            mask.get_mut(i),
        ) {
            *pc = packed_color(c);
            *pd = packed_depth(d);
            *pm = m.map(packed_motion);
            *ps = PixelSource::from_mask(s);
        }
    }
}

/// [`repack_band`] with AVX2 and F16C: a pixel's colour sanitised and
/// rounded to `f16` in one register (`vcvtps2ph`, to nearest even:
/// [`packed_color`]'s bits), as [`pack_band_f16c`] packs two.
///
/// # Safety
///
/// The CPU has AVX2 and F16C.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,f16c")]
unsafe fn repack_band_f16c(out: &Output, band: PackedBand<'_>, first: usize, at: &[usize]) {
    use std::arch::x86_64::*;
    let (zero, max) = (_mm_setzero_ps(), _mm_set1_ps(MAX_RADIANCE));
    let (inf, one) = (_mm_set1_ps(f32::INFINITY), _mm_set1_ps(1.0));
    repack_band(out, band, first, at, |c| {
        // SAFETY: four `f32`s, 16 bytes, unaligned load.
        let v = unsafe { _mm_loadu_ps(c.as_ptr()) };
        let keep = _mm_and_ps(_mm_cmpgt_ps(v, zero), _mm_cmplt_ps(v, inf));
        let clean = _mm_and_ps(keep, _mm_min_ps(v, max));
        let opaque = _mm_blend_ps::<0b1000>(clean, one);
        let half = _mm_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(opaque);
        let bits = (_mm_cvtsi128_si64(half) as u64).to_le_bytes();
        std::array::from_fn(|k| f16::from_le_bytes([bits[2 * k], bits[2 * k + 1]]))
    });
}

/// A packed frame's colour of one pixel: [`radiance`], alpha 1, to the
/// nearest `f16`.
#[inline]
fn packed_color(c: [f32; 4]) -> [f16; 4] {
    let c = c.map(radiance);
    [c[0], c[1], c[2], 1.0].map(f16::from_f32)
}

/// A packed frame's depth: `+inf` where no surface was written.
#[inline]
fn packed_depth(d: f32) -> f32 {
    if d > 0.0 { d } else { f32::INFINITY }
}

/// A packed frame's motion component: 0 where not finite.
#[inline]
fn packed_motion(v: f32) -> f32 {
    if v.is_finite() { v } else { 0.0 }
}

/// Packs `from` into `to` (as long): with AVX2 and F16C where the CPU
/// has them ([`pack_band_f16c`]), else colour in blocks, sanitised on the
/// stack and converted with `half`'s slice conversion (rounding to
/// nearest, like `f16::from_f32`).
fn pack_band(from: Band<'_>, to: PackedBand<'_>) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
        // SAFETY: the CPU has both, just checked.
        return unsafe { pack_band_f16c(from, to) };
    }
    pack_band_blocks(from, to);
}

/// [`pack_band`] on any CPU.
fn pack_band_blocks(from: Band<'_>, to: PackedBand<'_>) {
    use half::slice::HalfFloatSliceExt;
    let blocks = (to.color.chunks_mut(CONVERT_BLOCK)).zip(from.color.chunks(CONVERT_BLOCK));
    // Cleared once for the band, not per block (16 KB each time).
    let mut clean = [[0.0f32; 4]; CONVERT_BLOCK];
    for (dst, src) in blocks {
        // Lane by lane, then alpha: loops the compiler vectorises.
        let lanes = clean.as_flattened_mut().iter_mut();
        for (c, &s) in lanes.zip(src.as_flattened()) {
            *c = radiance(s);
        }
        for c in &mut clean {
            c[3] = 1.0;
        }
        dst.as_flattened_mut()
            .convert_from_f32_slice(clean[..src.len()].as_flattened());
    }
    pack_rest(from, to);
}

/// [`pack_band`] with AVX2 and F16C: two pixels' colour a register,
/// sanitised, given alpha 1 and rounded to `f16` (`vcvtps2ph`, to nearest
/// even: `f16::from_f32`'s bits) without a buffer between; the rest
/// compiled for eight lanes. A 720p frame's packing 2.2 → 1.4 ms, paired.
///
/// # Safety
///
/// The CPU has AVX2 and F16C.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,f16c")]
unsafe fn pack_band_f16c(from: Band<'_>, to: PackedBand<'_>) {
    use std::arch::x86_64::*;
    let (zero, max) = (_mm256_setzero_ps(), _mm256_set1_ps(MAX_RADIANCE));
    let (inf, one) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(1.0));
    let pairs = to.color.chunks_exact_mut(2).zip(from.color.chunks_exact(2));
    for (dst, src) in pairs {
        // SAFETY: two pixels of four `f32`s, 32 bytes, unaligned load.
        let v = unsafe { _mm256_loadu_ps(src.as_ptr().cast()) };
        // `radiance`: `0 < v < ∞` (NaN fails), then at most the largest.
        let keep = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(v, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(v, inf),
        );
        let clean = _mm256_and_ps(keep, _mm256_min_ps(v, max));
        let opaque = _mm256_blend_ps::<0b1000_1000>(clean, one);
        let half = _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(opaque);
        // SAFETY: two pixels of four `f16`s, 16 bytes, unaligned store.
        unsafe { _mm_storeu_si128(dst.as_mut_ptr().cast(), half) };
    }
    let odd = from.color.len() / 2 * 2;
    for (dst, src) in to.color[odd..].iter_mut().zip(&from.color[odd..]) {
        *dst = packed_color(*src);
    }
    pack_rest(from, to);
}

/// [`pack_band`]'s depth, motion and source.
#[inline(always)]
fn pack_rest(from: Band<'_>, to: PackedBand<'_>) {
    for (d, &v) in to.depth.iter_mut().zip(from.depth) {
        *d = packed_depth(v);
    }
    // Component by component (a closure per component was not inlined).
    let lanes = to.motion.as_flattened_mut().iter_mut();
    for (d, &v) in lanes.zip(from.motion.as_flattened()) {
        *d = packed_motion(v);
    }
    for (d, &m) in to.mask.iter_mut().zip(from.mask) {
        *d = PixelSource::from_mask(m);
    }
}

/// One band of a [`Packed`] being made.
struct PackedBand<'a> {
    color: &'a mut [[f16; 4]],
    depth: &'a mut [f32],
    motion: &'a mut [[f32; 2]],
    mask: &'a mut [PixelSource],
}

/// A `width`×`height` [`Packed`] made band by band on all cores: `make(k,
/// band)` writes band `k` of `b` pixels (the last one shorter), which is
/// filled first where it is handed out (`par::bands4`: in the cache).
fn made(
    width: u32,
    height: u32,
    b: usize,
    make: impl Fn(usize, PackedBand<'_>) + Sync + Send,
) -> Packed {
    let n = width as usize * height as usize;
    let fill = ([f16::ZERO; 4], 0.0, [0.0; 2], PixelSource::Filled);
    let planes = crate::par::bands4(n, b, fill, |k, color, depth, motion, mask| {
        make(
            k,
            PackedBand {
                color,
                depth,
                motion,
                mask,
            },
        )
    });
    Packed::of_planes(width, height, planes)
}

/// A packed frame's buffers, colour, depth, motion and source.
type Planes = (Vec<[f16; 4]>, Vec<f32>, Vec<[f32; 2]>, Vec<PixelSource>);

impl Packed {
    /// The `width`×`height` frame of `planes`.
    fn of_planes(width: u32, height: u32, planes: Planes) -> Self {
        let (color, depth, motion, mask) = planes;
        Self {
            color,
            depth,
            motion,
            mask,
            width,
            height,
        }
    }
}

/// Bytes of each packed buffer for `n` pixels, in the order the executor
/// reads them back: colour, depth, motion, source (4 a word, the last word
/// padded).
pub fn packed_bytes(n: u64) -> [u64; 4] {
    [n * 8, n * 4, n * 8, n.div_ceil(4) * 4]
}

/// Unpacks the bytes the executor read back (laid out as
/// [`packed_bytes`]) into a [`Packed`], copying on all cores. A source
/// byte the kernel cannot write reads as [`PixelSource::Filled`].
pub fn unpack(bytes: &[u8], width: u32, height: u32) -> Packed {
    let n = width as usize * height as usize;
    let [c, d, m, _] = packed_bytes(n as u64).map(|b| b as usize);
    let (color, rest) = bytes.split_at(c);
    let (depth, rest) = rest.split_at(d);
    let (motion, mask) = rest.split_at(m);
    Packed {
        width,
        height,
        color: par_copy(color, [f16::ZERO; 4], n),
        depth: par_copy(depth, 0.0f32, n),
        motion: par_copy(motion, [0.0f32; 2], n),
        mask: {
            use rayon::prelude::*;
            mask[..n]
                .par_iter()
                .map(|&b| PixelSource::from_mask(u32::from(b)))
                .collect()
        },
    }
}

/// `n` values of `T` from the front of `bytes`, copied block by block on
/// all cores into a buffer made where it is written (`par::blocks`; one
/// core alone moves a frame at a fraction of the memory bandwidth).
fn par_copy<T: bytemuck::Pod + Send + Sync>(bytes: &[u8], zero: T, n: usize) -> Vec<T> {
    const BLOCK: usize = 1 << 16;
    let per = (BLOCK / std::mem::size_of::<T>().max(1)).max(1);
    let bytes = &bytes[..n * std::mem::size_of::<T>()];
    crate::par::blocks(zero, n, per, |k, dst| {
        let dst: &mut [u8] = bytemuck::cast_slice_mut(dst);
        let at = k * per * std::mem::size_of::<T>();
        dst.copy_from_slice(&bytes[at..at + dst.len()]);
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    /// pixels, 0, 0, 0
    sizes: [u32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuPack {
    kernel: Kernel,
}

/// The packed buffers on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GpuPacked<'a> {
    /// `vec2<u32>` per pixel: four `f16`.
    pub color: &'a wgpu::Buffer,
    /// A byte per pixel, four a word.
    pub mask: &'a wgpu::Buffer,
}

impl GpuPack {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("pack.wgsl"),
                "pack",
                &[
                    Params, Read, ReadWrite, ReadWrite, Read, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records the packing of the `n`-pixel output `out`: colour and mask
    /// into `packed`, depth and motion in place.
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        n: u32,
        out: crate::output::GpuOutput<'_>,
        packed: GpuPacked<'_>,
    ) {
        let params = ctx.params(bytemuck::bytes_of(&Params {
            sizes: [n, 0, 0, 0],
        }));
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &params,
                out.color,
                out.depth,
                out.motion,
                out.mask,
                packed.color,
                packed.mask,
            ],
            u64::from(n),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_is_sanitised_before_rounding() {
        assert_eq!(radiance(f32::NAN), 0.0);
        assert_eq!(radiance(f32::INFINITY), 0.0);
        assert_eq!(radiance(-1.0), 0.0);
        assert!(radiance(-0.0).is_sign_positive());
        assert_eq!(radiance(1e9), MAX_RADIANCE);
        assert_eq!(radiance(0.25), 0.25);
    }

    #[test]
    fn unpacking_what_was_packed_gives_it_back() {
        let (w, h) = (7u32, 3u32);
        let mut out = Output::empty(w, h);
        for t in 0..out.mask.len() {
            out.color[t] = [t as f32, 0.5, f32::NAN, 1.0];
            out.depth[t] = if t % 2 == 0 { t as f32 } else { 0.0 };
            out.motion[t] = [t as f32, f32::INFINITY];
            out.mask[t] = (t % 6) as u32;
        }
        let p = pack(&out);
        let n = out.mask.len();
        let mut bytes = Vec::new();
        bytes.extend_from_slice(bytemuck::cast_slice(&p.color));
        bytes.extend_from_slice(bytemuck::cast_slice(&p.depth));
        bytes.extend_from_slice(bytemuck::cast_slice(&p.motion));
        bytes.extend(p.mask.iter().map(|&m| m as u8));
        bytes.resize(packed_bytes(n as u64).iter().sum::<u64>() as usize, 0);
        assert_eq!(unpack(&bytes, w, h), p);
        assert_eq!(p.depth[1], f32::INFINITY);
        assert_eq!(p.motion[2], [2.0, 0.0]);
        assert_eq!(p.mask[5], PixelSource::Warped);
        assert_eq!(p.color[3][2], f16::ZERO);
    }

    /// Values that sanitising and rounding treat apart (NaN, infinities,
    /// negatives, −0, subnormal and tie halves, beyond the largest `f16`).
    const SPECIAL: [f32; 16] = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        -0.0,
        0.0,
        1e-7,
        6.0e-8,
        2.9802322e-8,
        1.0 + 1.0 / 2048.0,
        1.0 + 3.0 / 2048.0,
        65504.0,
        65520.0,
        1e9,
        MAX_RADIANCE,
        0.333,
    ];

    /// Every way of packing gives the same bits: the bands with and
    /// without F16C, each pixel alone, over [`SPECIAL`] values, an odd
    /// number of pixels over several blocks.
    #[test]
    fn every_packing_gives_the_same_bits() {
        let special = SPECIAL;
        let (w, h) = (1031u32, 3u32);
        let mut out = Output::empty(w, h);
        for t in 0..out.mask.len() {
            let v =
                |k: usize| special[(t * 7 + k * 3) % special.len()] * (1.0 + (t % 5) as f32 * 0.1);
            out.color[t] = [v(0), v(1), v(2), v(3)];
            out.depth[t] = v(4);
            out.motion[t] = [v(5), v(6)];
            out.mask[t] = (t % 6) as u32;
        }
        let n = out.mask.len();
        let packed = |f: &(dyn Fn(Band<'_>, PackedBand<'_>) + Sync)| {
            made(w, h, n, |_, band| f(out.band(0..n), band))
        };
        let blocks = packed(&|from, to| pack_band_blocks(from, to));
        assert_eq!(blocks, pack(&out));
        for (t, c) in out.color.iter().enumerate() {
            assert_eq!(
                blocks.color[t].map(f16::to_bits),
                packed_color(*c).map(f16::to_bits)
            );
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
            // SAFETY: the CPU has both, just checked.
            let f16c = packed(&|from, to| unsafe { pack_band_f16c(from, to) });
            let bits = |p: &Packed| {
                p.color
                    .iter()
                    .flatten()
                    .map(|c| c.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&f16c), bits(&blocks));
            assert_eq!(f16c, blocks);
        }
    }

    /// Packing each band as it is made, then the holes again once they are
    /// filled (with [`SPECIAL`] colours), gives what packing the finished
    /// frame gives, each hole's colour as [`packed_color`] packs it; the
    /// holes listed are the frame's, across bands.
    #[test]
    fn packing_as_resolved_then_the_holes_again_is_packing() {
        use crate::output::{CRACK, EMPTY, FILLED, Pixel, WARPED};
        // Several bands, the last one short.
        let (w, h) = (300u32, 130u32);
        assert!(Output::bands(w, h) >= 3);
        let pixel = |t: usize, mask| Pixel {
            color: [t as f32 * 0.01, 0.5, -1.0, 1.0],
            depth: 1.0 + t as f32,
            motion: [t as f32 * 0.25, -0.5],
            mask,
        };
        let r = resolved(w, h, |mut rows| {
            for t in rows.pixels() {
                // Holes scattered, and whole runs of them.
                if t % 7 != 3 && !(5000..5200).contains(&t) {
                    rows.set(t, pixel(t, WARPED));
                }
            }
        });
        assert_eq!(r.packed, pack(&r.out));
        assert_eq!(r.holes, r.out.holes());
        assert!(r.holes.contains(&3) && r.holes.contains(&5100));
        let (mut out, mut packed) = (r.out, r.packed);
        // The passes after the resolve fill some holes (not all).
        for &t in r.holes.iter().filter(|&&t| t % 2 == 0) {
            let p = pixel(t * 3, if t % 4 == 0 { CRACK } else { FILLED });
            // Colours that sanitising and rounding treat apart.
            let v = |k: usize| SPECIAL[(t / 2 + k * 5) % SPECIAL.len()];
            (out.color[t], out.depth[t], out.motion[t], out.mask[t]) =
                ([v(0), v(1), v(2), v(3)], p.depth, p.motion, p.mask);
        }
        assert_ne!(packed, pack(&out));
        repack(&out, &mut packed, &r.holes);
        assert_eq!(packed, pack(&out));
        for &t in &r.holes {
            assert_eq!(
                packed.color[t].map(f16::to_bits),
                packed_color(out.color[t]).map(f16::to_bits),
                "pixel {t}"
            );
        }
        assert!(out.mask.contains(&EMPTY));
    }
}
