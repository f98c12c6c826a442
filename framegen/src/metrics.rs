//! Image quality metrics on display-encoded images (DESIGN §9): PSNR and SSIM.
//! ꟻLIP (crate `nv-flip`) joins them with the `eval` report.
//!
//! Both compare [`DisplayImage`]s, i.e. after the fixed display transform, so
//! HDR highlights do not dominate the error.

use crate::display::DisplayImage;

/// Images that cannot be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MetricsError {
    /// The two images differ in size.
    #[error("image sizes differ: {0}x{1} vs {2}x{3}")]
    SizeMismatch(u32, u32, u32, u32),
    /// An image has no pixels.
    #[error("empty image")]
    Empty,
}

fn check(a: &DisplayImage, b: &DisplayImage) -> Result<(), MetricsError> {
    if a.width != b.width || a.height != b.height || a.rgb.len() != b.rgb.len() {
        return Err(MetricsError::SizeMismatch(
            a.width, a.height, b.width, b.height,
        ));
    }
    if a.rgb.is_empty() {
        return Err(MetricsError::Empty);
    }
    Ok(())
}

/// Mean squared error over all pixels and channels.
pub fn mse(a: &DisplayImage, b: &DisplayImage) -> Result<f64, MetricsError> {
    let map = squared_error_map(a, b)?;
    Ok(map.iter().sum::<f64>() / map.len() as f64)
}

/// Peak signal-to-noise ratio in dB with peak 1: `10 log10(1 / MSE)`.
/// Identical images give `+inf`.
pub fn psnr(a: &DisplayImage, b: &DisplayImage) -> Result<f64, MetricsError> {
    let m = mse(a, b)?;
    Ok(if m == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * m.log10()
    })
}

/// Gaussian window of Wang et al. 2004: 11 taps, σ = 1.5, normalised.
fn gaussian_window() -> [f64; 11] {
    let mut w = [0.0; 11];
    for (i, v) in w.iter_mut().enumerate() {
        let x = i as f64 - 5.0;
        *v = (-x * x / (2.0 * 1.5 * 1.5)).exp();
    }
    let sum: f64 = w.iter().sum();
    w.map(|v| v / sum)
}

/// One 1-D pass of the window along x (`horizontal`) or y, clamp-to-edge.
fn blur_pass(
    src: &[f64],
    width: usize,
    height: usize,
    w: &[f64; 11],
    horizontal: bool,
) -> Vec<f64> {
    let (len, step) = if horizontal {
        (width, 1)
    } else {
        (height, width)
    };
    let mut out = vec![0.0; src.len()];
    for y in 0..height {
        for x in 0..width {
            let (pos, base) = if horizontal { (x, y * width) } else { (y, x) };
            out[y * width + x] = (0..11)
                .map(|k| {
                    let s = (pos as isize + k as isize - 5).clamp(0, len as isize - 1) as usize;
                    w[k] * src[base + s * step]
                })
                .sum();
        }
    }
    out
}

/// Separable Gaussian blur with clamp-to-edge borders.
fn blur(src: &[f64], width: usize, height: usize, w: &[f64; 11]) -> Vec<f64> {
    let tmp = blur_pass(src, width, height, w, true);
    blur_pass(&tmp, width, height, w, false)
}

/// Structural similarity (Wang et al. 2004) with the standard constants
/// (11-tap Gaussian, σ = 1.5, K1 = 0.01, K2 = 0.03, dynamic range 1), computed
/// per RGB channel with clamp-to-edge borders and averaged over pixels and
/// channels. 1 means identical.
pub fn ssim(a: &DisplayImage, b: &DisplayImage) -> Result<f64, MetricsError> {
    let map = ssim_map(a, b)?;
    Ok(map.iter().sum::<f64>() / map.len() as f64)
}

/// The SSIM of every pixel (its window's value, averaged over the three
/// channels): [`ssim`] is its mean; the `eval` report pools it over regions
/// (disoccluded, dynamic, static).
pub fn ssim_map(a: &DisplayImage, b: &DisplayImage) -> Result<Vec<f64>, MetricsError> {
    check(a, b)?;
    let (w, h) = (a.width as usize, a.height as usize);
    let win = gaussian_window();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let mut map = vec![0.0; a.rgb.len()];
    for c in 0..3 {
        let x: Vec<f64> = a.rgb.iter().map(|p| f64::from(p[c])).collect();
        let y: Vec<f64> = b.rgb.iter().map(|p| f64::from(p[c])).collect();
        let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
        let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
        let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
        let [mx, my, sxx, syy, sxy] = [&x, &y, &xx, &yy, &xy].map(|v| blur(v, w, h, &win));
        for (i, m) in map.iter_mut().enumerate() {
            let (vx, vy, cov) = (
                sxx[i] - mx[i] * mx[i],
                syy[i] - my[i] * my[i],
                sxy[i] - mx[i] * my[i],
            );
            *m += ((2.0 * mx[i] * my[i] + c1) * (2.0 * cov + c2))
                / ((mx[i] * mx[i] + my[i] * my[i] + c1) * (vx + vy + c2))
                / 3.0;
        }
    }
    Ok(map)
}

/// The squared error of every pixel, averaged over its three channels:
/// [`mse`] is its mean; pooled over a region it gives that region's PSNR.
pub fn squared_error_map(a: &DisplayImage, b: &DisplayImage) -> Result<Vec<f64>, MetricsError> {
    check(a, b)?;
    Ok(a.rgb
        .iter()
        .zip(&b.rgb)
        .map(|(p, q)| (0..3).map(|c| f64::from(p[c] - q[c]).powi(2)).sum::<f64>() / 3.0)
        .collect())
}

/// PSNR in dB (peak 1) of a mean squared error, capped at `cap` so that
/// identical images average to a finite number.
pub fn psnr_of_mse(mse: f64, cap: f64) -> f64 {
    if mse <= 0.0 {
        cap
    } else {
        (-10.0 * mse.log10()).min(cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> DisplayImage {
        let rgb = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| [f(x, y); 3])
            .collect();
        DisplayImage {
            width: w,
            height: h,
            rgb,
        }
    }

    #[test]
    fn identical_images_are_perfect() {
        let a = image(20, 13, |x, y| ((x * 7 + y * 3) % 11) as f32 / 10.0);
        assert_eq!(psnr(&a, &a).unwrap(), f64::INFINITY);
        assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn psnr_matches_a_known_error() {
        // Every value off by 0.1: MSE 0.01 → 20 dB.
        let a = image(8, 8, |_, _| 0.5);
        let b = image(8, 8, |_, _| 0.6);
        assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-5);
    }

    #[test]
    fn ssim_ranks_structure_loss_below_a_brightness_shift() {
        let a = image(
            32,
            32,
            |x, y| if (x / 4 + y / 4) % 2 == 0 { 0.8 } else { 0.2 },
        );
        let shifted = image(
            32,
            32,
            |x, y| if (x / 4 + y / 4) % 2 == 0 { 0.85 } else { 0.25 },
        );
        let flat = image(32, 32, |_, _| 0.5);
        let s_shift = ssim(&a, &shifted).unwrap();
        let s_flat = ssim(&a, &flat).unwrap();
        assert!(s_shift > 0.9 && s_flat < 0.1, "{s_shift} {s_flat}");
    }

    #[test]
    fn mismatched_sizes_are_errors() {
        let a = image(4, 4, |_, _| 0.0);
        let b = image(4, 5, |_, _| 0.0);
        assert!(matches!(psnr(&a, &b), Err(MetricsError::SizeMismatch(..))));
        assert!(matches!(ssim(&a, &b), Err(MetricsError::SizeMismatch(..))));
        let e = DisplayImage {
            width: 0,
            height: 0,
            rgb: vec![],
        };
        assert_eq!(psnr(&e, &e), Err(MetricsError::Empty));
    }

    #[test]
    fn maps_pool_to_the_global_metrics() {
        let a = image(17, 9, |x, y| ((x * 5 + y * 3) % 7) as f32 / 6.0);
        let b = image(17, 9, |x, y| ((x * 3 + y * 5) % 7) as f32 / 6.0);
        let se = squared_error_map(&a, &b).unwrap();
        let mean = se.iter().sum::<f64>() / se.len() as f64;
        assert!((mean - mse(&a, &b).unwrap()).abs() < 1e-12);
        assert!((psnr_of_mse(mean, 100.0) - psnr(&a, &b).unwrap()).abs() < 1e-9);
        assert_eq!(psnr_of_mse(0.0, 100.0), 100.0);
        let map = ssim_map(&a, &b).unwrap();
        let pooled = map.iter().sum::<f64>() / map.len() as f64;
        assert!((pooled - ssim(&a, &b).unwrap()).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn metrics_are_symmetric_and_bounded(
            va in prop::collection::vec(0.0f32..=1.0, 36),
            vb in prop::collection::vec(0.0f32..=1.0, 36),
        ) {
            let a = image(6, 6, |x, y| va[(y * 6 + x) as usize]);
            let b = image(6, 6, |x, y| vb[(y * 6 + x) as usize]);
            let (p, q) = (psnr(&a, &b).unwrap(), psnr(&b, &a).unwrap());
            prop_assert!(p == q && p >= 0.0);
            let (s, t) = (ssim(&a, &b).unwrap(), ssim(&b, &a).unwrap());
            prop_assert!((s - t).abs() < 1e-12 && (-1.0..=1.0 + 1e-12).contains(&s));
        }
    }
}
