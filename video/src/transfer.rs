//! What the codec carries for HDR colour (issue 19 §1): the display-referred
//! signal, at 10 bits.
//!
//! Every quality metric and every presenter sees colour through one fixed
//! display transform (`protocol::display`: Reinhard `x / (1 + x)`, then the
//! sRGB OETF). That transform is invertible on `[0, 1)`, so the codec carries
//! its output, `v = display_value(x)` per channel, as full-range BT.709
//! Y′CbCr at 10 bits, and the receiver inverts it
//! (`x = y / (1 − y)`, `y = sRGB⁻¹(v)`). The codec's error therefore lands
//! evenly in the space where frames are judged, not where linear light has
//! few visible steps (a PQ or log curve would spend bits on highlights the
//! display compresses away).
//!
//! What the generator receives: linear HDR RGB whose display transform equals
//! the sent one up to the codec's error (and the 10-bit quantisation:
//! [`tests`]), never above the frame's peak. Near the top of the display
//! range a code step is a large step of linear light (the inverse of
//! `x / (1 + x)` has no bound), so a codec error of a code or two on a
//! highlight could come back as any linear value up to `f16::MAX`, which the
//! generator's linear-light filters would then spread (measured: single
//! pixels at 65 504 from a 200 highlight). The sender therefore states the
//! frame's peak, its largest finite channel value, and the receiver clamps
//! to it ([`peak`], [`from_planes`]). Negative and NaN input comes back as 0
//! (their display is 0), `+inf` as the peak; alpha is not carried and comes
//! back as 1.

use half::f16;

/// Bits of every coded sample.
pub const BITS: u32 = 10;
/// Largest code.
const MAX_CODE: f32 = ((1 << BITS) - 1) as f32;
/// BT.709 luma weights (any fixed weights round-trip; these decorrelate
/// natural RGB well).
const KR: f32 = 0.2126;
const KB: f32 = 0.0722;
const KG: f32 = 1.0 - KR - KB;

/// How chroma is sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Chroma {
    /// Half resolution both ways (what streaming services send).
    Yuv420,
    /// Full resolution (H.264 High 4:4:4 Predictive).
    Yuv444,
}

impl Chroma {
    /// Divisors of the chroma planes' width and height.
    pub fn subsampling(self) -> (usize, usize) {
        match self {
            Chroma::Yuv420 => (2, 2),
            Chroma::Yuv444 => (1, 1),
        }
    }
}

/// A picture as the codec codes it: three 10-bit planes at the coded size
/// (the frame's size rounded up to the chroma subsampling, edges
/// replicated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Planes {
    /// Coded width.
    pub width: usize,
    /// Coded height.
    pub height: usize,
    /// Luma, `width × height`.
    pub y: Vec<u16>,
    /// Blue-difference chroma.
    pub cb: Vec<u16>,
    /// Red-difference chroma.
    pub cr: Vec<u16>,
    /// Chroma plane width.
    pub chroma_width: usize,
}

/// The size a frame is coded at: subsampled planes need whole blocks.
pub fn coded_size(width: u32, height: u32, chroma: Chroma) -> (usize, usize) {
    let (sx, sy) = chroma.subsampling();
    (
        (width as usize).div_ceil(sx) * sx,
        (height as usize).div_ceil(sy) * sy,
    )
}

/// The display transform of every `f16` bit pattern, so that the forward
/// transform costs a table lookup per channel.
fn forward_table() -> &'static [f32] {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=u16::MAX)
            .map(|bits| protocol::display::display_value(f16::from_bits(bits).to_f32()))
            .collect()
    })
}

/// Steps of the inverse table over display values `[0, 1]`.
const INVERSE_STEPS: usize = 1 << 16;

/// The inverse display transform at `INVERSE_STEPS + 1` display values.
fn inverse_table() -> &'static [f16] {
    static TABLE: std::sync::OnceLock<Vec<f16>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=INVERSE_STEPS)
            .map(|i| f16::from_f32(inverse_display(i as f32 / INVERSE_STEPS as f32)))
            .collect()
    })
}

/// Linear light whose display transform is `v` ∈ [0, 1]: the sRGB EOTF,
/// then Reinhard's inverse. Saturated display (`v ≥ 1`) gives the largest
/// finite `f16`.
pub fn inverse_display(v: f32) -> f32 {
    if v.is_nan() {
        return 0.0;
    }
    let v = v.clamp(0.0, 1.0);
    let y = if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    };
    let x = y / (1.0 - y);
    if x.is_finite() {
        x.min(f16::MAX.to_f32())
    } else {
        f16::MAX.to_f32()
    }
}

/// The code of a luma value in [0, 1].
fn code(v: f32) -> u16 {
    (v * MAX_CODE + 0.5).clamp(0.0, MAX_CODE) as u16
}

/// The code of chroma zero: grey, black and white are coded exactly.
const CHROMA_ZERO: f32 = (1 << (BITS - 1)) as f32;

/// The code of a chroma value in [−½, ½].
fn chroma_code(c: f32) -> u16 {
    (c * MAX_CODE + CHROMA_ZERO + 0.5).clamp(0.0, MAX_CODE) as u16
}

/// Linear RGBA `color` (`width × height`, row-major) as coded planes, into
/// `out` (reused from frame to frame), a row of chroma blocks at a time
/// (the chroma block of a pixel a shift, not a division).
///
/// # Panics
/// If `color` does not hold `width × height` pixels (the caller validates).
pub fn to_planes(width: u32, height: u32, color: &[[f16; 4]], chroma: Chroma, out: &mut Planes) {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(color.len(), w * h, "colour of {w}×{h} pixels");
    let (cw, ch) = coded_size(width, height, chroma);
    let (sx, sy) = chroma.subsampling();
    out.width = cw;
    out.height = ch;
    out.chroma_width = cw / sx;
    out.y.resize(cw * ch, 0);
    let chroma_len = (cw / sx) * (ch / sy);
    out.cb.resize(chroma_len, 0);
    out.cr.resize(chroma_len, 0);
    if chroma_len == 0 {
        return;
    }
    let chroma_width = out.chroma_width;
    let mut sums = vec![[0.0f32; 2]; chroma_width];
    let blocks = (out.y.chunks_mut(cw * sy))
        .zip(out.cb.chunks_mut(chroma_width))
        .zip(out.cr.chunks_mut(chroma_width));
    for (by, ((luma, cb), cr)) in blocks.enumerate() {
        let rows = (by * sy..by * sy + sy).map(|yy| &color[yy.min(h - 1) * w..][..w]);
        match chroma {
            Chroma::Yuv420 => code_blocks::<2>(rows, luma, (cb, cr), &mut sums),
            Chroma::Yuv444 => code_blocks::<1>(rows, luma, (cb, cr), &mut sums),
        }
    }
}

/// One row of chroma blocks `S` pixels a side: the `S` rows of colour
/// `rows` into the luma rows `luma` (the coded width each, edges
/// replicated) and the chroma rows `cb` and `cr`. Chroma sums over each
/// block in display space, in the pixels' row-major order (`sums`: one
/// per block, scratch).
#[inline]
fn code_blocks<'a, const S: usize>(
    rows: impl Iterator<Item = &'a [[f16; 4]]>,
    luma: &mut [u16],
    (cb, cr): (&mut [u16], &mut [u16]),
    sums: &mut [[f32; 2]],
) {
    let table = forward_table();
    let cw = luma.len() / S;
    sums.fill([0.0; 2]);
    for (src, row) in rows.zip(luma.chunks_exact_mut(cw)) {
        let w = src.len();
        for (x, luma) in row.iter_mut().enumerate() {
            let p = &src[x.min(w - 1)];
            let [r, g, b] = [0, 1, 2].map(|c| table[usize::from(p[c].to_bits())]);
            let l = KR * r + KG * g + KB * b;
            *luma = code(l);
            let s = &mut sums[x / S];
            s[0] += (b - l) / (2.0 * (1.0 - KB));
            s[1] += (r - l) / (2.0 * (1.0 - KR));
        }
    }
    let n = (S * S) as f32;
    for ((s, cb), cr) in sums.iter().zip(cb.iter_mut()).zip(cr.iter_mut()) {
        *cb = chroma_code(s[0] / n);
        *cr = chroma_code(s[1] / n);
    }
}

/// PSNR (dB) of `b` against `a` in display space, where the carriage spends
/// its bits (capped at 100 dB for equal images).
pub fn display_psnr(a: &[[f16; 4]], b: &[[f16; 4]]) -> f64 {
    let table = forward_table();
    let mut se = 0.0f64;
    for (p, q) in a.iter().zip(b) {
        for c in 0..3 {
            let d = table[usize::from(p[c].to_bits())] - table[usize::from(q[c].to_bits())];
            se += f64::from(d * d);
        }
    }
    let mse = se / (a.len().max(1) * 3) as f64;
    if mse > 0.0 {
        (10.0 * (1.0 / mse).log10()).min(100.0)
    } else {
        100.0
    }
}

/// The largest finite, non-negative channel value of `color` (0 for none):
/// what the receiver clamps decoded linear light to.
pub fn peak(color: &[[f16; 4]]) -> f16 {
    color
        .iter()
        .flat_map(|p| &p[..3])
        .filter(|v| v.is_finite())
        .fold(f16::ZERO, |m, &v| if v > m { v } else { m })
}

/// Coded planes back to linear RGBA `width × height` (the frame's size, at
/// most the coded size), each channel at most `peak`, into `out`, a row at
/// a time (the chroma of a pixel a shift away, not a division).
///
/// # Panics
/// If the planes are smaller than the frame or than their stated size (the
/// caller validates the decoder's output).
pub fn from_planes(
    planes: &Planes,
    width: u32,
    height: u32,
    chroma: Chroma,
    peak: f16,
    out: &mut Vec<[f16; 4]>,
) {
    let (w, h) = (width as usize, height as usize);
    let (_, sy) = chroma.subsampling();
    assert!(
        w <= planes.width && h <= planes.height,
        "frame within the picture"
    );
    let peak = if peak.is_finite() && peak > f16::ZERO {
        peak
    } else {
        f16::ZERO
    };
    out.clear();
    out.resize(w * h, [f16::ZERO; 4]);
    if w == 0 {
        return;
    }
    for (y, row) in out.chunks_mut(w).enumerate() {
        let luma = &planes.y[y * planes.width..][..w];
        let at = (y / sy) * planes.chroma_width;
        let span = at..at + planes.chroma_width;
        let (cb, cr) = (&planes.cb[span.clone()], &planes.cr[span]);
        match chroma {
            Chroma::Yuv420 => linear_row::<2>(luma, (cb, cr), peak, row),
            Chroma::Yuv444 => linear_row::<1>(luma, (cb, cr), peak, row),
        }
    }
}

/// One row of [`from_planes`]: the luma codes `luma` and the chroma codes
/// of their row (`cb`, `cr`, a code per `S` pixels) into linear light at
/// most `peak` (finite, not negative).
#[inline]
fn linear_row<const S: usize>(
    luma: &[u16],
    (cb, cr): (&[u16], &[u16]),
    peak: f16,
    out: &mut [[f16; 4]],
) {
    let inverse = inverse_table();
    // The table holds finite values that are not negative, as `peak` is:
    // their order is that of their bits.
    let peak = peak.to_bits();
    let lin = |v: f32| {
        let x = inverse[(v.clamp(0.0, 1.0) * INVERSE_STEPS as f32 + 0.5) as usize];
        if x.to_bits() > peak {
            f16::from_bits(peak)
        } else {
            x
        }
    };
    let one = f16::ONE;
    for (x, (o, &l)) in out.iter_mut().zip(luma).enumerate() {
        let l = f32::from(l) / MAX_CODE;
        let cb = (f32::from(cb[x / S]) - CHROMA_ZERO) / MAX_CODE;
        let cr = (f32::from(cr[x / S]) - CHROMA_ZERO) / MAX_CODE;
        let r = l + 2.0 * (1.0 - KR) * cr;
        let b = l + 2.0 * (1.0 - KB) * cb;
        let g = (l - KR * r - KB * b) / KG;
        *o = [lin(r), lin(g), lin(b), one];
    }
}

#[cfg(test)]
mod tests {
    use protocol::display::display_value;

    use super::*;

    fn image(width: u32, height: u32) -> Vec<[f16; 4]> {
        (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f32, (i / width) as f32);
                let v = |s: f32| f16::from_f32((s * 0.37).sin().abs() * 4.0 * s / (s + 3.0));
                [v(x + 1.0), v(y + 2.0), v(x + y + 3.0), f16::ONE]
            })
            .collect()
    }

    /// In 4:4:4, the round trip moves every channel's display value by at
    /// most the 10-bit quantisation of the coded samples (luma and chroma
    /// each off by ≤ half a code; blue gathers the most through the inverse
    /// matrix, `½(1 + 2(1 − Kb))` codes), plus the inverse table's step and
    /// the rounding of linear light to `f16` (≤ 2⁻¹² in display space).
    /// [`to_planes`] by the formulas alone, a coded sample at a time: each
    /// luma code from its pixel (edges replicated), each chroma code from
    /// the sum over its block, taken in row-major order.
    fn to_planes_sample_by_sample(w: u32, h: u32, color: &[[f16; 4]], chroma: Chroma) -> Planes {
        let (cw, ch) = coded_size(w, h, chroma);
        let (sx, sy) = chroma.subsampling();
        let display = |x: usize, y: usize| {
            let p = color[y.min(h as usize - 1) * w as usize + x.min(w as usize - 1)];
            [0, 1, 2].map(|c| forward_table()[usize::from(p[c].to_bits())])
        };
        let luma = |[r, g, b]: [f32; 3]| KR * r + KG * g + KB * b;
        let mut planes = Planes {
            width: cw,
            height: ch,
            chroma_width: cw / sx,
            y: (0..cw * ch)
                .map(|i| code(luma(display(i % cw, i / cw))))
                .collect(),
            ..Planes::default()
        };
        for i in 0..(cw / sx) * (ch / sy) {
            let (bx, by) = (i % (cw / sx), i / (cw / sx));
            let mut sum = [0.0f32; 2];
            for (dx, dy) in (0..sy).flat_map(|dy| (0..sx).map(move |dx| (dx, dy))) {
                let [r, g, b] = display(bx * sx + dx, by * sy + dy);
                let l = luma([r, g, b]);
                sum[0] += (b - l) / (2.0 * (1.0 - KB));
                sum[1] += (r - l) / (2.0 * (1.0 - KR));
            }
            let n = (sx * sy) as f32;
            planes.cb.push(chroma_code(sum[0] / n));
            planes.cr.push(chroma_code(sum[1] / n));
        }
        planes
    }

    /// Pixel `(x, y)` of [`from_planes`], by the formulas alone: its codes
    /// read where they are (the chroma's by division), the inverse table,
    /// the peak (sanitised as `from_planes` does) as an `f16` comparison.
    fn linear_pixel(
        planes: &Planes,
        (x, y): (usize, usize),
        chroma: Chroma,
        peak: f16,
    ) -> [f16; 4] {
        let (sx, sy) = chroma.subsampling();
        let peak = if peak.is_finite() && peak > f16::ZERO {
            peak
        } else {
            f16::ZERO
        };
        let lin = |v: f32| {
            let x = inverse_table()[(v.clamp(0.0, 1.0) * INVERSE_STEPS as f32 + 0.5) as usize];
            if x > peak { peak } else { x }
        };
        let at = (y / sy) * planes.chroma_width + x / sx;
        let l = f32::from(planes.y[y * planes.width + x]) / MAX_CODE;
        let cb = (f32::from(planes.cb[at]) - CHROMA_ZERO) / MAX_CODE;
        let cr = (f32::from(planes.cr[at]) - CHROMA_ZERO) / MAX_CODE;
        let r = l + 2.0 * (1.0 - KR) * cr;
        let b = l + 2.0 * (1.0 - KB) * cb;
        let g = (l - KR * r - KB * b) / KG;
        [lin(r), lin(g), lin(b), f16::ONE]
    }

    /// The coding and decoding row by row give the bits of the
    /// formulas sample by sample above: both chroma modes, odd and even
    /// sizes, special values, a peak below some of the light.
    #[test]
    fn rows_are_the_formulas_sample_by_sample() {
        for (w, h) in [(1, 1), (2, 2), (37, 21), (64, 9), (33, 48)] {
            let mut color = image(w, h);
            let specials = [
                f16::NAN,
                f16::INFINITY,
                f16::NEG_INFINITY,
                -f16::ONE,
                f16::MAX,
            ];
            for (i, c) in color.iter_mut().enumerate().step_by(7) {
                c[i % 3] = specials[i % specials.len()];
            }
            for chroma in [Chroma::Yuv420, Chroma::Yuv444] {
                let mut rows = Planes::default();
                to_planes(w, h, &color, chroma, &mut rows);
                let samples = to_planes_sample_by_sample(w, h, &color, chroma);
                assert_eq!(rows, samples, "{w}×{h} {chroma:?}");
                for peak in [f16::ZERO, f16::from_f32(0.7), f16::MAX, f16::NAN] {
                    let mut a = vec![[f16::ONE; 4]; 3];
                    from_planes(&rows, w, h, chroma, peak, &mut a);
                    let b: Vec<_> = (0..(w * h) as usize)
                        .map(|i| (i % w as usize, i / w as usize))
                        .map(|at| linear_pixel(&rows, at, chroma, peak))
                        .collect();
                    let bits = |v: &[[f16; 4]]| {
                        v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>()
                    };
                    assert_eq!(bits(&a), bits(&b), "{w}×{h} {chroma:?} peak {peak}");
                }
            }
        }
    }

    #[test]
    fn the_round_trip_is_within_the_quantisation_in_display_space() {
        let (w, h) = (37, 21);
        let color = image(w, h);
        let mut planes = Planes::default();
        to_planes(w, h, &color, Chroma::Yuv444, &mut planes);
        let mut back = Vec::new();
        from_planes(&planes, w, h, Chroma::Yuv444, peak(&color), &mut back);
        assert_eq!(back.len(), color.len());
        let bound =
            0.5 * (1.0 + 2.0 * (1.0 - KB)) / MAX_CODE + 0.5 / INVERSE_STEPS as f32 + 1.0 / 4096.0;
        let mut worst = 0.0f32;
        for (a, b) in color.iter().zip(&back) {
            for c in 0..3 {
                let d = (display_value(a[c].to_f32()) - display_value(b[c].to_f32())).abs();
                worst = worst.max(d);
            }
            assert_eq!(b[3], f16::ONE);
        }
        assert!(worst <= bound, "display error {worst} > {bound}");
        assert!(worst > 0.0, "10 bits cannot be exact");
    }

    /// 4:2:0 of a flat-coloured picture is as exact as 4:4:4; odd sizes are
    /// padded to whole blocks and cropped back.
    #[test]
    fn odd_sizes_are_padded_and_cropped() {
        let (w, h) = (5, 3);
        assert_eq!(coded_size(w, h, Chroma::Yuv420), (6, 4));
        assert_eq!(coded_size(w, h, Chroma::Yuv444), (5, 3));
        let flat = vec![[0.8, 0.3, 0.05, 1.0].map(f16::from_f32); 15];
        let mut planes = Planes::default();
        to_planes(w, h, &flat, Chroma::Yuv420, &mut planes);
        assert_eq!((planes.y.len(), planes.cb.len()), (24, 6));
        let mut back = Vec::new();
        from_planes(&planes, w, h, Chroma::Yuv420, peak(&flat), &mut back);
        assert_eq!(back.len(), 15);
        assert!(back.windows(2).all(|p| p[0] == p[1]));
        for c in 0..3 {
            let d = display_value(back[0][c].to_f32()) - display_value(flat[0][c].to_f32());
            assert!(d.abs() < 2.0 / MAX_CODE, "channel {c}: {d}");
        }
    }

    /// Non-finite and negative input maps where the display maps it; the
    /// output is always finite and non-negative.
    #[test]
    fn special_values_stay_finite() {
        let special = [
            f16::NAN,
            f16::INFINITY,
            f16::NEG_INFINITY,
            f16::from_f32(-3.0),
        ];
        let color: Vec<[f16; 4]> = special.iter().map(|&v| [v, v, v, v]).collect();
        let mut planes = Planes::default();
        to_planes(2, 2, &color, Chroma::Yuv444, &mut planes);
        let mut back = Vec::new();
        assert_eq!(peak(&color), f16::ZERO, "no finite positive value");
        from_planes(&planes, 2, 2, Chroma::Yuv444, f16::MAX, &mut back);
        for (p, v) in back.iter().zip(special) {
            for c in &p[..3] {
                assert!(c.is_finite() && c.to_f32() >= 0.0, "{v} → {c}");
            }
        }
        assert_eq!(back[1][0], f16::MAX, "+inf saturates the display");
        assert_eq!(back[0][0].to_f32(), 0.0, "NaN displays as 0");
        assert_eq!(back[3][0].to_f32(), 0.0, "negative displays as 0");
    }

    /// A highlight whose code a codec error pushes to the top comes back at
    /// the peak, not at `f16::MAX`.
    #[test]
    fn decoded_light_stops_at_the_peak() {
        let color = vec![[200.0, 0.5, 0.1, 1.0].map(f16::from_f32); 4];
        let mut planes = Planes::default();
        to_planes(2, 2, &color, Chroma::Yuv444, &mut planes);
        planes.y.iter_mut().for_each(|y| *y += 3);
        let mut back = Vec::new();
        from_planes(&planes, 2, 2, Chroma::Yuv444, peak(&color), &mut back);
        assert!(back.iter().all(|p| p[0].to_f32() <= 200.0), "{back:?}");
        from_planes(&planes, 2, 2, Chroma::Yuv444, f16::MAX, &mut back);
        assert!(back[0][0].to_f32() > 1000.0, "the clamp is what holds it");
    }

    #[test]
    fn the_inverse_inverts_the_display() {
        for i in 0..=1000 {
            let v = i as f32 / 1000.0;
            let x = inverse_display(v);
            assert!(x.is_finite() && x >= 0.0);
            if v < 0.999 {
                assert!((display_value(x) - v).abs() < 1e-5, "{v} → {x}");
            }
        }
        assert_eq!(inverse_display(1.0), f16::MAX.to_f32());
        assert_eq!(inverse_display(f32::NAN), 0.0);
    }
}
