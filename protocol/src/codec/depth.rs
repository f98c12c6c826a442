//! Quantised depth, [`super::Codec::QuantDepth`] (issue 19 §3, DESIGN §7):
//! depth with a stated error bound instead of 32-bit floats.
//!
//! What matters about a depth error is what it does downstream: generation
//! reprojects each pixel through its depth, and a point at inverse depth
//! `u = 1/d` moves by `f·B·u` pixels when the camera (focal length `f`
//! pixels) translates `B` world units sideways. So an error `δu` in inverse
//! depth moves a reprojected pixel by `f·B·δu`, at any depth; and the depth
//! tests (relative margins of 2 % or more) care about the relative error
//! `δd/d = δu/u`. The quantiser takes inverse depth's step as the smaller of
//! the two needs:
//!
//! * a constant step `c` on `u` near the camera (`u ≥ u₀`), with
//!   `c = 2 · 0.05 px / (f · B)`: reprojection moves a pixel by at most
//!   [`MAX_SHIFT_PX`] for a camera that translates up to `B` = [`REACH`]
//!   times its last step;
//! * a relative step `r` = [`LOG_STEP`] far away (`u < u₀`, log of `u`), so a
//!   far depth is within `r/2` ≈ 6·10⁻⁵ of itself (and the step on `u` is
//!   `r·u < c` there, so the reprojection bound holds too).
//!
//! The two meet at `u₀ = c / r` with equal steps. A first frame or a cut has
//! no camera step: then all of it is on the relative scale. Sky (`+inf`)
//! and NaN keep reserved codes and come back exactly; zero and negative
//! depths (invalid by DESIGN §3) come back as 0. Codes go through
//! [`super::planar`]: inverse depth is affine across a flat surface, which
//! the predictor follows to within a residual constant over the surface.
//!
//! Payload: tag, the three scale parameters (f64), the plane's width (u32),
//! then the packed codes. Every parameter is checked before use.

use crate::FrameMeta;

use super::{CodecError, planar};

/// Relative step of the far scale: depth within `±LOG_STEP/2` of itself.
pub const LOG_STEP: f64 = 1.0 / 8192.0;

/// Largest reprojection shift, pixels, that the near scale's step causes for
/// a camera translating [`REACH`] times its last step.
pub const MAX_SHIFT_PX: f64 = 0.05;

/// How many of the camera's last steps the reprojection bound covers: the
/// generated frames reproject up to `max_alpha` intervals ahead (3 by
/// default), and the camera may speed up.
pub const REACH: f64 = 4.0;

const TAG: u8 = 0xD1;
/// Tag, log step, linear step, pivot, width.
pub(crate) const HEADER: usize = 1 + 8 * 3 + 4;

const INF_CODE: i32 = i32::MAX;
const NAN_CODE: i32 = i32::MAX - 1;
const ZERO_CODE: i32 = i32::MIN;
const MAX_CODE: i32 = i32::MAX - 2;
const MIN_CODE: i32 = i32::MIN + 1;

/// How depth maps to integer codes; sent with every payload.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantizer {
    /// Step of `ln u` on the far scale.
    log_step: f64,
    /// Step of `u` on the near scale; 0 when there is none.
    linear_step: f64,
    /// The `u` where the scales meet (code 0); 1 when there is no near scale.
    pivot: f64,
}

impl Quantizer {
    /// Relative steps only: what a frame without a previous camera gets.
    pub fn relative() -> Self {
        Self {
            log_step: LOG_STEP,
            linear_step: 0.0,
            pivot: 1.0,
        }
    }

    /// The quantiser for `meta`'s depth when the camera was at `previous`
    /// one frame before (none, or a cut: [`Quantizer::relative`]).
    pub fn for_frame(meta: &FrameMeta, previous: Option<&FrameMeta>) -> Self {
        let Some(previous) = previous.filter(|_| !meta.cut) else {
            return Self::relative();
        };
        let step = (meta.camera.pose.position - previous.camera.pose.position).length();
        let camera = &meta.camera;
        let t = camera.projection.tan_half_fov();
        let (w, h) = meta.size.as_f64();
        let focal = (w / (camera.window.width() * t * camera.projection.aspect))
            .max(h / (camera.window.height() * t));
        let linear_step = 2.0 * MAX_SHIFT_PX / (focal * REACH * step);
        if !(linear_step.is_finite() && linear_step > 0.0) {
            return Self::relative();
        }
        Self {
            log_step: LOG_STEP,
            linear_step,
            pivot: linear_step / LOG_STEP,
        }
    }

    /// The code of one depth.
    pub fn code(&self, depth: f32) -> i32 {
        if depth.is_nan() {
            return NAN_CODE;
        }
        if depth == f32::INFINITY {
            return INF_CODE;
        }
        if depth <= 0.0 {
            return ZERO_CODE;
        }
        let u = 1.0 / f64::from(depth);
        let code = if self.linear_step > 0.0 && u >= self.pivot {
            (u - self.pivot) / self.linear_step
        } else {
            (u / self.pivot).ln() / self.log_step
        };
        // Saturates (an infinite `u` takes the top code).
        super::round_i32(code).clamp(MIN_CODE, MAX_CODE)
    }

    /// The depth a code stands for.
    pub fn depth(&self, code: i32) -> f32 {
        match code {
            INF_CODE => f32::INFINITY,
            NAN_CODE => f32::NAN,
            ZERO_CODE => 0.0,
            _ => {
                let u = if self.linear_step > 0.0 && code >= 0 {
                    self.pivot + f64::from(code) * self.linear_step
                } else {
                    self.pivot * (f64::from(code) * self.log_step).exp()
                };
                (1.0 / u) as f32
            }
        }
    }

    /// The codes of a plane of depths.
    pub fn codes(&self, depth: &[f32]) -> Vec<i32> {
        depth.iter().map(|&d| self.code(d)).collect()
    }

    /// The depths of a plane of codes: what the receiver decodes.
    pub fn depths(&self, codes: &[i32]) -> Vec<f32> {
        // Runs of one code (sky, a wall facing the camera) are common: each
        // value is computed once a run.
        let mut last = None;
        codes
            .iter()
            .map(|&c| match last {
                Some((code, d)) if code == c => d,
                _ => {
                    let d = self.depth(c);
                    last = Some((c, d));
                    d
                }
            })
            .collect()
    }

    /// `depth` as the receiver will decode it.
    pub fn round_trip(&self, depth: &[f32]) -> Vec<f32> {
        self.depths(&self.codes(depth))
    }

    fn check(&self) -> Result<(), CodecError> {
        let ok = self.log_step.is_finite()
            && self.log_step > 0.0
            && self.pivot.is_finite()
            && self.pivot > 0.0
            && self.linear_step.is_finite()
            && self.linear_step >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(CodecError::BadParameters("depth scale"))
        }
    }
}

/// Encodes a plane of `depth` values, `width` wide, at zstd `level`.
pub fn encode(
    quantizer: &Quantizer,
    depth: &[f32],
    width: u32,
    level: i32,
) -> Result<Vec<u8>, CodecError> {
    encode_codes(quantizer, &quantizer.codes(depth), width, level)
}

/// [`encode`] for depths already turned into `codes` by `quantizer`.
pub fn encode_codes(
    quantizer: &Quantizer,
    codes: &[i32],
    width: u32,
    level: i32,
) -> Result<Vec<u8>, CodecError> {
    quantizer.check()?;
    check_width(width, codes.len())?;
    let packed = planar::pack(codes, width as usize, level)?;
    let mut out = Vec::with_capacity(HEADER + packed.len());
    out.push(TAG);
    for v in [quantizer.log_step, quantizer.linear_step, quantizer.pivot] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&width.to_le_bytes());
    out.extend_from_slice(&packed);
    Ok(out)
}

/// Decodes `count` depths; returns them with the plane's width.
pub fn decode(encoded: &[u8], count: usize) -> Result<(Vec<f32>, u32), CodecError> {
    let (head, packed) = encoded
        .split_first_chunk::<HEADER>()
        .ok_or(CodecError::BadParameters("depth header"))?;
    if head[0] != TAG {
        return Err(CodecError::BadParameters("depth tag"));
    }
    let f = |i: usize| f64::from_le_bytes(std::array::from_fn(|k| head[1 + 8 * i + k]));
    let quantizer = Quantizer {
        log_step: f(0),
        linear_step: f(1),
        pivot: f(2),
    };
    quantizer.check()?;
    let width = u32::from_le_bytes([head[25], head[26], head[27], head[28]]);
    check_width(width, count)?;
    let codes = planar::unpack(packed, count, width as usize)?;
    Ok((quantizer.depths(&codes), width))
}

/// A plane `width` wide must hold whole rows of `count` values.
pub(crate) fn check_width(width: u32, count: usize) -> Result<(), CodecError> {
    if width == 0 || count % width as usize != 0 {
        return Err(CodecError::BadParameters("plane width"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec3};

    use super::*;
    use crate::{Camera, FrameSize, Pose, Projection};

    fn meta(x: f64, cut: bool) -> FrameMeta {
        FrameMeta {
            index: 1,
            time: 0.0,
            camera: Camera::new(
                Pose::new(DVec3::new(x, 1.0, 5.0), DQuat::IDENTITY),
                Projection::perspective(60f64.to_radians(), 16.0 / 9.0, 0.1, 1000.0),
            ),
            size: FrameSize::new(640, 360),
            host_processing: std::time::Duration::ZERO,
            cut,
        }
    }

    #[test]
    fn error_stays_within_both_bounds() {
        let (prev, cur) = (meta(0.0, false), meta(0.1, false));
        let q = Quantizer::for_frame(&cur, Some(&prev));
        assert!(q.linear_step > 0.0);
        // Focal length in pixels of a 60° vertical field over 360 rows.
        let focal = 180.0 / (30f64.to_radians()).tan();
        let baseline = REACH * 0.1;
        let mut d = 0.1f32;
        while d < 1e6 {
            let back = q.depth(q.code(d));
            let rel = (f64::from(back) / f64::from(d) - 1.0).abs();
            assert!(rel <= LOG_STEP / 2.0 + 1e-6, "d {d}: relative {rel}");
            let shift = focal * baseline * (1.0 / f64::from(back) - 1.0 / f64::from(d)).abs();
            assert!(shift <= MAX_SHIFT_PX * 1.001, "d {d}: shift {shift}");
            d *= 1.013;
        }
    }

    #[test]
    fn special_values_keep_their_meaning() {
        for q in [
            Quantizer::relative(),
            Quantizer::for_frame(&meta(0.2, false), Some(&meta(0.0, false))),
        ] {
            assert_eq!(q.depth(q.code(f32::INFINITY)), f32::INFINITY);
            assert!(q.depth(q.code(f32::NAN)).is_nan());
            assert_eq!(q.depth(q.code(0.0)), 0.0);
            assert_eq!(q.depth(q.code(-3.0)), 0.0);
            assert_eq!(q.depth(q.code(f32::NEG_INFINITY)), 0.0);
            for d in [f32::MIN_POSITIVE, 1e-30, f32::MAX, 1e30] {
                let back = q.depth(q.code(d));
                assert!(back.is_finite() || back == f32::INFINITY, "{d} → {back}");
                assert!(back > 0.0, "{d} → {back}");
            }
        }
        // A cut has no baseline: relative steps only.
        let q = Quantizer::for_frame(&meta(0.2, true), Some(&meta(0.0, false)));
        assert_eq!(q, Quantizer::relative());
    }

    #[test]
    fn a_slanted_floor_with_sky_round_trips_small() {
        let (w, h) = (320u32, 180u32);
        let depth: Vec<f32> = (0..w * h)
            .map(|i| {
                let y = (i / w) as f32;
                if y < 60.0 {
                    f32::INFINITY
                } else {
                    // A ground plane: depth ∝ 1 / (rows below the horizon).
                    200.0 / (y - 59.5)
                }
            })
            .collect();
        let q = Quantizer::relative();
        let enc = encode(&q, &depth, w, 1).unwrap();
        let (back, width) = decode(&enc, depth.len()).unwrap();
        assert_eq!(width, w);
        assert_eq!(back, q.round_trip(&depth));
        // Four bytes a pixel raw; the plane costs a small fraction of that.
        assert!(enc.len() * 20 < depth.len() * 4, "{} bytes", enc.len());
    }

    #[test]
    fn bad_headers_are_typed_errors() {
        let q = Quantizer::relative();
        let enc = encode(&q, &[1.0; 12], 4, 1).unwrap();
        assert!(decode(&enc[..10], 12).is_err());
        let mut bad = enc.clone();
        bad[0] ^= 1;
        assert!(decode(&bad, 12).is_err());
        let mut bad = enc.clone();
        bad[1..9].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(decode(&bad, 12).is_err());
        // A width that does not divide the count.
        assert!(decode(&enc, 10).is_err());
        let mut bad = enc;
        bad[25..29].copy_from_slice(&0u32.to_le_bytes());
        assert!(decode(&bad, 12).is_err());
    }
}
