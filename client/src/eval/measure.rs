//! Scoring one generated frame against the rendered frame it stands for:
//! PSNR, SSIM and ꟻLIP on display-encoded images (DESIGN §9), over the
//! whole frame and split into regions.
//!
//! Regions, per pixel of the generated frame:
//! * **disoccluded**: no warped source covered it (background layers or
//!   push-pull filled it);
//! * **dynamic**: warped, and the ground truth shows an animated object
//!   there (the renderer's dynamic mask);
//! * **static**: everything else.
//!
//! Region values are pooled over every pixel of every frame (a region's
//! PSNR comes from its pooled mean squared error), so a region that is
//! tiny in some frames does not dominate.
//!
//! Across those, the **focus** region (GFFE eq. 3, seed 000 §4.4): where
//! the geometry-aware result (gffe at its defaults, the same pixels for
//! every variant) differs from the truth by SMAPE > 0.5 against each of
//! the truth's 9 pixels around it, and the truth shows no animated object.
//! A pixel shifted by one, or a subtle difference, is not in it; a shadow
//! or highlight left where it was is. [`focus_mask`].

use framegen::{Generated, PixelSource};
use protocol::display::DisplayImage;
use protocol::{BufferKind, Frame};
use serde::Serialize;

/// PSNR of identical images, so that means stay finite.
pub const PSNR_CAP: f64 = 100.0;

/// The regions a frame is split into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// Not covered by a warped source.
    Disoccluded = 0,
    /// On an animated object.
    Dynamic = 1,
    /// The rest.
    Static = 2,
}

impl Region {
    /// All regions, in report order.
    pub const ALL: [Region; 3] = [Region::Disoccluded, Region::Dynamic, Region::Static];
}

/// ꟻLIP's error map of `test` against `reference` (values in [0, 1]) at the
/// default viewing conditions (0.7 m from a 0.7 m wide 4K monitor, 67
/// pixels per degree).
pub fn flip_map(reference: &DisplayImage, test: &DisplayImage) -> nv_flip::FlipImageFloat {
    let r =
        nv_flip::FlipImageRgb8::with_data(reference.width, reference.height, &reference.to_rgb8());
    let t = nv_flip::FlipImageRgb8::with_data(test.width, test.height, &test.to_rgb8());
    nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE)
}

/// Per-pixel region of a generated frame.
pub fn regions(generated: &Generated, truth: &Frame) -> Vec<Region> {
    let dynamic = truth
        .extras
        .iter()
        .find(|e| e.kind == BufferKind::Mask && e.data.len() == generated.mask.len());
    generated
        .mask
        .iter()
        .enumerate()
        .map(|(i, m)| match m {
            PixelSource::Background | PixelSource::Filled => Region::Disoccluded,
            _ if dynamic.is_some_and(|d| d.data[i] > 0) => Region::Dynamic,
            _ => Region::Static,
        })
        .collect()
}

/// GFFE eq. 3's SMAPE threshold of the focus region.
pub const FOCUS_SMAPE: f32 = 0.5;

/// Symmetric mean absolute percentage error of two linear colours, its
/// usual form: the mean over RGB of `|a − b| / ((|a| + |b|) / 2 + 0.01)`,
/// in [0, 2] (the offset keeps black against black at 0). Above 0.5, one
/// is more than 5/3 of the other.
pub fn smape(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3)
        .map(|c| (a[c] - b[c]).abs() / ((a[c].abs() + b[c].abs()) / 2.0 + 0.01))
        .sum::<f32>()
        / 3.0
}

/// GFFE eq. 3: the pixels where `gae` (a geometry-aware generated frame)
/// differs from `truth` by more than [`FOCUS_SMAPE`] against every truth
/// pixel in its 3×3 neighbourhood, and the truth's dynamic mask is clear.
/// Linear HDR colour; non-finite values count as black. `None` when the
/// sizes differ.
pub fn focus_mask(gae: &Frame, truth: &Frame) -> Option<Vec<bool>> {
    let (w, h) = (
        truth.meta.size.width as usize,
        truth.meta.size.height as usize,
    );
    if gae.meta.size != truth.meta.size || gae.color.len() != w * h || truth.color.len() != w * h {
        return None;
    }
    let rgb = |f: &Frame, i: usize| -> [f32; 3] {
        std::array::from_fn(|c| {
            let v = f.color[i][c].to_f32();
            if v.is_finite() { v } else { 0.0 }
        })
    };
    let dynamic = truth
        .extras
        .iter()
        .find(|e| e.kind == BufferKind::Mask && e.data.len() == w * h);
    Some(
        (0..w * h)
            .map(|i| {
                if dynamic.is_some_and(|d| d.data[i] > 0) {
                    return false;
                }
                let (x, y) = (i % w, i / w);
                let g = rgb(gae, i);
                let ys = y.saturating_sub(1)..=(y + 1).min(h - 1);
                ys.flat_map(|ny| {
                    (x.saturating_sub(1)..=(x + 1).min(w - 1)).map(move |nx| ny * w + nx)
                })
                .all(|n| smape(g, rgb(truth, n)) > FOCUS_SMAPE)
            })
            .collect(),
    )
}

/// The scores of one generated frame, with its per-pixel maps for pooling.
pub struct FrameScore {
    /// PSNR of the frame (dB, capped at [`PSNR_CAP`]).
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// Mean ꟻLIP.
    pub flip: f64,
    /// ꟻLIP's error map, for heat maps.
    pub flip_map: nv_flip::FlipImageFloat,
    /// Per region: pixels, Σ squared error, Σ SSIM, Σ ꟻLIP.
    pub regions: [RegionSums; 3],
    /// The same over the focus region, when one was given.
    pub focus: RegionSums,
}

/// Sums over the pixels of one region.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegionSums {
    /// Pixels.
    pub pixels: u64,
    /// Σ squared error (mean over channels).
    pub squared_error: f64,
    /// Σ SSIM.
    pub ssim: f64,
    /// Σ ꟻLIP.
    pub flip: f64,
}

impl RegionSums {
    fn add(&mut self, o: &RegionSums) {
        self.pixels += o.pixels;
        self.squared_error += o.squared_error;
        self.ssim += o.ssim;
        self.flip += o.flip;
    }
}

/// Scores `test` (display-encoded generated frame) against `truth`, per
/// region and over `focus` (a [`focus_mask`]) where there is one.
pub fn score(
    test: &DisplayImage,
    truth: &DisplayImage,
    regions: &[Region],
    focus: Option<&[bool]>,
) -> Result<FrameScore, framegen::MetricsError> {
    let se = framegen::squared_error_map(test, truth)?;
    let ssim = framegen::ssim_map(test, truth)?;
    let flip = flip_map(truth, test);
    let fl = flip.to_vec();
    let n = se.len() as f64;
    let mut sums = [RegionSums::default(); 3];
    let mut focused = RegionSums::default();
    for (i, r) in regions.iter().enumerate() {
        let pixel = RegionSums {
            pixels: 1,
            squared_error: se[i],
            ssim: ssim[i],
            flip: f64::from(fl[i]),
        };
        sums[*r as usize].add(&pixel);
        if focus.is_some_and(|f| f.get(i) == Some(&true)) {
            focused.add(&pixel);
        }
    }
    Ok(FrameScore {
        psnr: framegen::psnr_of_mse(se.iter().sum::<f64>() / n, PSNR_CAP),
        ssim: ssim.iter().sum::<f64>() / n,
        flip: fl.iter().map(|&v| f64::from(v)).sum::<f64>() / n,
        flip_map: flip,
        regions: sums,
        focus: focused,
    })
}

/// Quality over a whole sequence.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Quality {
    /// Generated frames compared.
    pub frames: usize,
    /// Mean of the per-frame PSNR (dB).
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// Mean ꟻLIP (lower is better).
    pub flip: f64,
    /// Worst frame's PSNR.
    pub psnr_min: f64,
    /// Per region, pooled: disoccluded, dynamic, static.
    pub regions: Vec<RegionQuality>,
    /// The focus region (GFFE eq. 3), pooled; empty where the sweep had
    /// no gffe at its defaults to define it.
    pub focus: RegionQuality,
    /// Mean share of pixels from each source: warped, background, filled,
    /// copied.
    pub sources: Sources,
}

/// Shares of pixels by where they came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Sources {
    /// Forward-warped.
    pub warped: f64,
    /// Background layers.
    pub background: f64,
    /// Push-pull filled.
    pub filled: f64,
    /// Copied (repeat).
    pub copied: f64,
}

/// Pooled quality of one region.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RegionQuality {
    /// `disoccluded`, `dynamic`, `static` or `focus`.
    pub region: &'static str,
    /// Share of all compared pixels in it.
    pub share: f64,
    /// PSNR of the pooled mean squared error (`None` when empty).
    pub psnr: Option<f64>,
    /// Mean SSIM.
    pub ssim: Option<f64>,
    /// Mean ꟻLIP.
    pub flip: Option<f64>,
}

/// Accumulates [`FrameScore`]s into a [`Quality`].
#[derive(Default)]
pub struct Accumulator {
    frames: usize,
    psnr: f64,
    psnr_min: f64,
    ssim: f64,
    flip: f64,
    regions: [RegionSums; 3],
    focus: RegionSums,
    sources: [f64; 4],
}

impl Accumulator {
    /// Adds one frame.
    pub fn add(&mut self, score: &FrameScore, generated: &Generated) {
        self.psnr_min = if self.frames == 0 {
            score.psnr
        } else {
            self.psnr_min.min(score.psnr)
        };
        self.frames += 1;
        self.psnr += score.psnr;
        self.ssim += score.ssim;
        self.flip += score.flip;
        for (a, b) in self.regions.iter_mut().zip(&score.regions) {
            a.add(b);
        }
        self.focus.add(&score.focus);
        let n = generated.mask.len().max(1) as f64;
        for (k, source) in [
            PixelSource::Warped,
            PixelSource::Background,
            PixelSource::Filled,
            PixelSource::Copied,
        ]
        .into_iter()
        .enumerate()
        {
            self.sources[k] += generated.count(source) as f64 / n;
        }
    }

    /// The means.
    pub fn finish(&self) -> Quality {
        let f = self.frames.max(1) as f64;
        let total: u64 = self.regions.iter().map(|r| r.pixels).sum();
        let pooled = |region: &'static str, s: &RegionSums| {
            let p = s.pixels as f64;
            let some = |v: f64| (s.pixels > 0).then_some(v);
            RegionQuality {
                region,
                share: p / total.max(1) as f64,
                psnr: some(framegen::psnr_of_mse(s.squared_error / p, PSNR_CAP)),
                ssim: some(s.ssim / p),
                flip: some(s.flip / p),
            }
        };
        let regions = Region::ALL
            .iter()
            .map(|&r| {
                let name = match r {
                    Region::Disoccluded => "disoccluded",
                    Region::Dynamic => "dynamic",
                    Region::Static => "static",
                };
                pooled(name, &self.regions[r as usize])
            })
            .collect();
        let [warped, background, filled, copied] = self.sources.map(|v| v / f);
        Quality {
            frames: self.frames,
            psnr: self.psnr / f,
            ssim: self.ssim / f,
            flip: self.flip / f,
            psnr_min: self.psnr_min,
            regions,
            focus: pooled("focus", &self.focus),
            sources: Sources {
                warped,
                background,
                filled,
                copied,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> DisplayImage {
        DisplayImage {
            width: w,
            height: h,
            rgb: (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| [f(x, y); 3])
                .collect(),
        }
    }

    #[test]
    fn identical_images_score_perfectly_and_errors_land_in_their_region() {
        let a = image(32, 16, |x, y| ((x / 4 + y / 4) % 2) as f32 * 0.8 + 0.1);
        let regions: Vec<Region> = (0..32 * 16)
            .map(|i| {
                if i % 32 < 8 {
                    Region::Disoccluded
                } else {
                    Region::Static
                }
            })
            .collect();
        let same = score(&a, &a, &regions, None).unwrap();
        assert_eq!(same.focus, RegionSums::default());
        assert_eq!(same.psnr, PSNR_CAP);
        assert!((same.ssim - 1.0).abs() < 1e-9);
        assert!(same.flip < 1e-6, "{}", same.flip);

        // Damage only the left quarter (the disoccluded region).
        let b = image(32, 16, |x, y| {
            if x < 8 {
                1.0 - a.rgb[(y * 32 + x) as usize][0]
            } else {
                a.rgb[(y * 32 + x) as usize][0]
            }
        });
        // The focus region: the first two columns, inside the damage.
        let focus: Vec<bool> = (0..32 * 16).map(|i| i % 32 < 2).collect();
        let s = score(&b, &a, &regions, Some(&focus)).unwrap();
        assert_eq!(s.focus.pixels, 2 * 16);
        assert!(s.focus.squared_error > 0.1 * s.focus.pixels as f64);
        let [dis, _, stat] = s.regions;
        assert_eq!(dis.pixels + stat.pixels, 32 * 16);
        assert!(dis.squared_error > 0.1 * dis.pixels as f64);
        assert_eq!(stat.squared_error, 0.0);
        assert!(dis.flip / dis.pixels as f64 > 10.0 * stat.flip / stat.pixels as f64);
        assert!(s.psnr < 20.0 && s.flip > 0.05);
    }

    /// What the stream report says of ꟻLIP (`transport::StreamCost::
    /// color_codes_changed`): it weighs one-code changes of the 8-bit
    /// display values it compares, so a codec's floor is set by how many
    /// codes it changes, not by how far.
    #[test]
    fn flip_weighs_one_code_changes() {
        let (w, h) = (160, 90);
        let code = |v: u32| (v % 256) as f32 / 255.0;
        let base = image(w, h, |x, y| code(x * 7 + y * 3));
        let up = |every: u32| {
            image(w, h, |x, y| {
                let v = x * 7 + y * 3;
                // One code up (staying below white) in one pixel of `every`.
                if (x + y * w) % every == 0 && v % 256 < 255 {
                    code(v + 1)
                } else {
                    code(v)
                }
            })
        };
        let mean = |t: &DisplayImage| {
            let v = flip_map(&base, t).to_vec();
            v.iter().map(|&e| f64::from(e)).sum::<f64>() / v.len() as f64
        };
        let (all, tenth) = (mean(&up(1)), mean(&up(10)));
        assert!((0.02..0.08).contains(&all), "one code up everywhere: {all}");
        assert!((0.003..0.02).contains(&tenth), "in a tenth: {tenth}");
        assert!(mean(&base) == 0.0);
    }

    /// A `w`×`h` frame of grey `value(x, y)` (linear), with a dynamic mask
    /// where `dynamic(x, y)`.
    fn frame(
        w: u32,
        h: u32,
        value: impl Fn(u32, u32) -> f32,
        dynamic: impl Fn(u32, u32) -> bool,
    ) -> Frame {
        let size = protocol::FrameSize::new(w, h);
        let pixels = (0..h).flat_map(|y| (0..w).map(move |x| (x, y)));
        let mut f = Frame::blank(0, size);
        f.color = pixels
            .clone()
            .map(|(x, y)| {
                let v = half::f16::from_f32(value(x, y));
                [v, v, v, half::f16::ONE]
            })
            .collect();
        f.extras.push(protocol::frame::ExtraBuffer {
            kind: BufferKind::Mask,
            data: pixels.map(|(x, y)| u8::from(dynamic(x, y))).collect(),
        });
        f
    }

    #[test]
    fn the_focus_region_is_a_shading_change_not_a_shift_nor_a_dynamic_pixel() {
        // The truth has a shadow over columns 4..; the geometry-aware
        // frame left it out (lit everywhere).
        let (w, h) = (10, 6);
        let truth = frame(w, h, |x, _| if x >= 4 { 0.05 } else { 1.0 }, |_, _| false);
        let lit = frame(w, h, |_, _| 1.0, |_, _| false);
        let mask = focus_mask(&lit, &truth).unwrap();
        // Inside by a pixel: every truth neighbour is in shadow.
        for (i, &m) in mask.iter().enumerate() {
            assert_eq!(m, i as u32 % w >= 5, "pixel {i}");
        }
        // The shadow one pixel off: the 3×3 minimum forgives it.
        let shifted = frame(w, h, |x, _| if x >= 5 { 0.05 } else { 1.0 }, |_, _| false);
        assert!(focus_mask(&shifted, &truth).unwrap().iter().all(|&m| !m));
        // Where the truth shows an animated object, nothing is focus.
        let moving = frame(w, h, |x, _| if x >= 4 { 0.05 } else { 1.0 }, |x, _| x >= 7);
        let mask = focus_mask(&lit, &moving).unwrap();
        assert_eq!(mask.iter().filter(|&&m| m).count(), 2 * h as usize);
        // Sizes that differ give no mask; black against black is no error.
        assert!(focus_mask(&frame(4, 4, |_, _| 1.0, |_, _| false), &truth).is_none());
        assert_eq!(smape([0.0; 3], [0.0; 3]), 0.0);
        assert!(smape([1.0; 3], [0.05; 3]) > FOCUS_SMAPE);
    }
}
