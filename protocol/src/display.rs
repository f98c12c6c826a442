//! The fixed display transform (DESIGN §3 "Color", §9): linear HDR RGB →
//! exposure 1 → Reinhard `x / (1 + x)` per channel → sRGB OETF → clamp to
//! [0, 1]. Every quality metric and every presenter uses this one transform,
//! so numbers are comparable across methods and runs.
//!
//! Non-finite or negative input (a NaN from a broken pass, `−inf`) maps to 0
//! and `+inf` maps to 1: the output is always finite and in [0, 1].

use half::f16;

/// An image after the display transform: RGB in [0, 1], row-major, top row
/// first.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// One display-encoded RGB triple per pixel.
    pub rgb: Vec<[f32; 3]>,
}

/// Reinhard tone mapping of one linear channel value (exposure 1).
pub fn reinhard(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        0.0
    } else if x.is_infinite() {
        1.0
    } else {
        x / (1.0 + x)
    }
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1) for a value in
/// [0, 1].
pub fn srgb_oetf(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else if v >= 1.0 {
        1.0
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The whole transform for one channel value.
pub fn display_value(x: f32) -> f32 {
    srgb_oetf(reinhard(x)).clamp(0.0, 1.0)
}

/// Applies the display transform to linear RGBA f16 pixels (alpha ignored).
/// `None` if `color` does not hold `width × height` pixels.
pub fn display_encode(width: u32, height: u32, color: &[[f16; 4]]) -> Option<DisplayImage> {
    if color.len() as u64 != u64::from(width) * u64::from(height) {
        return None;
    }
    let rgb = color
        .iter()
        .map(|p| std::array::from_fn(|c| display_value(p[c].to_f32())))
        .collect();
    Some(DisplayImage { width, height, rgb })
}

impl DisplayImage {
    /// 8-bit sRGB bytes (RGB, row-major), e.g. for PNG output or ꟻLIP.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.rgb
            .iter()
            .flat_map(|p| p.map(|v| (v * 255.0 + 0.5) as u8))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform_is_monotonic_and_bounded() {
        let mut last = -1.0;
        for i in 0..2000 {
            let x = i as f32 * 0.01;
            let y = display_value(x);
            assert!((0.0..=1.0).contains(&y));
            assert!(y >= last, "not monotonic at {x}");
            last = y;
        }
        // Known points: 0 → 0, 1 → Reinhard 0.5 → sRGB 0.7354.
        assert_eq!(display_value(0.0), 0.0);
        assert!((display_value(1.0) - 0.735_357).abs() < 1e-5);
        // The sRGB curve is continuous at its knee.
        let knee = 0.003_130_8f32;
        assert!((12.92 * knee - (1.055 * knee.powf(1.0 / 2.4) - 0.055)).abs() < 1e-6);
    }

    #[test]
    fn non_finite_input_stays_finite() {
        for (x, want) in [
            (f32::NAN, 0.0),
            (f32::NEG_INFINITY, 0.0),
            (-3.0, 0.0),
            (f32::INFINITY, 1.0),
        ] {
            assert_eq!(display_value(x), want, "{x}");
        }
        let img = display_encode(2, 1, &[[f16::NAN; 4], [f16::INFINITY; 4]]).unwrap();
        assert_eq!(img.rgb, vec![[0.0; 3], [1.0; 3]]);
        assert_eq!(img.to_rgb8(), vec![0, 0, 0, 255, 255, 255]);
        assert!(display_encode(2, 2, &[[f16::ONE; 4]]).is_none());
    }
}
