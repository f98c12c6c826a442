//! The import check: do a frame's motion vectors agree with its depth and
//! the two cameras?
//!
//! For a static surface point, the motion vector (DESIGN §3: current →
//! previous, pixels) is fully determined by depth and the cameras:
//! `prev.project(cur.unproject(pixel, depth)) − pixel`
//! ([`crate::Camera::static_motion`]). An importer that gets a convention
//! wrong (the sign of the vectors, the direction of the y axis, planar
//! against radial depth) turns that agreement into an error of pixels. The
//! check measures it on static pixels (outside the mask, where the frame has
//! one) or on a grid sample of pixels (otherwise), and also measures how
//! well each wrong convention would have fitted: if one fits better, the
//! importer's assumption is probably the wrong one, and the report says so
//! loudly.

use glam::DVec2;

use crate::camera::size_f;
use crate::frame::{BufferKind, Frame, FrameMeta};

/// Pixels checked per frame at most (a regular grid).
pub const MAX_SAMPLES_PER_FRAME: usize = 4096;

/// Resolution of the error histogram the median comes from, in pixels.
const BIN_PX: f64 = 0.001;
/// Histogram bins; errors beyond `BINS · BIN_PX` (20 px) share the last bin.
const BINS: usize = 20_000;

/// A reading of the motion vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hypothesis {
    /// As the importer converted them.
    AsImported,
    /// Both components negated: previous → current instead of current →
    /// previous.
    SignFlipped,
    /// The y component negated: a y-up source read as y-down, or the reverse.
    YFlipped,
    /// The x component negated.
    XFlipped,
    /// Depth is the distance along the pixel's ray, not planar view depth.
    DepthAlongRay,
}

impl Hypothesis {
    /// Every hypothesis, [`Hypothesis::AsImported`] first.
    pub const ALL: [Hypothesis; 5] = [
        Hypothesis::AsImported,
        Hypothesis::SignFlipped,
        Hypothesis::YFlipped,
        Hypothesis::XFlipped,
        Hypothesis::DepthAlongRay,
    ];

    /// What the hypothesis says, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Hypothesis::AsImported => "the conventions as imported",
            Hypothesis::SignFlipped => "both motion components negated",
            Hypothesis::YFlipped => "the motion's y axis flipped",
            Hypothesis::XFlipped => "the motion's x axis flipped",
            Hypothesis::DepthAlongRay => "depth read as distance along the ray (radial)",
        }
    }
}

/// Mean, median and share below 1 px of one hypothesis' errors.
#[derive(Clone, Debug)]
struct Errors {
    sum: f64,
    count: u64,
    within_1px: u64,
    histogram: Vec<u32>,
}

impl Errors {
    fn new() -> Self {
        Self {
            sum: 0.0,
            count: 0,
            within_1px: 0,
            histogram: vec![0; BINS + 1],
        }
    }

    fn add(&mut self, error: f64) {
        // A non-finite error (an expected position that overflowed) counts
        // as the largest bin, so it raises the statistics instead of
        // vanishing from them.
        let e = if error.is_finite() {
            error
        } else {
            BINS as f64 * BIN_PX
        };
        self.sum += e;
        self.count += 1;
        self.within_1px += u64::from(e <= 1.0);
        let bin = ((e / BIN_PX) as usize).min(BINS);
        self.histogram[bin] += 1;
    }

    fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// The median, to [`BIN_PX`] (the bin's centre).
    fn median(&self) -> f64 {
        let half = self.count.div_ceil(2);
        let mut seen = 0u64;
        for (bin, &n) in self.histogram.iter().enumerate() {
            seen += u64::from(n);
            if seen >= half && n > 0 {
                return (bin as f64 + 0.5) * BIN_PX;
            }
        }
        0.0
    }
}

/// Accumulates the check over the frames of an import.
#[derive(Clone, Debug)]
pub struct ReprojectionCheck {
    frames: u64,
    errors: Vec<Errors>,
}

impl Default for ReprojectionCheck {
    fn default() -> Self {
        Self::new()
    }
}

impl ReprojectionCheck {
    /// An empty check.
    pub fn new() -> Self {
        Self {
            frames: 0,
            errors: Hypothesis::ALL.iter().map(|_| Errors::new()).collect(),
        }
    }

    /// Checks `cur` against the frame before it, `prev` (metadata only). The
    /// pixels checked are those outside `cur`'s mask (if it has one) and,
    /// when `from_file` is given, marked in it, sampled on a grid of at most
    /// [`MAX_SAMPLES_PER_FRAME`]. Pixels with invalid depth or non-finite
    /// motion are not checked (the import counts them separately).
    pub fn add(&mut self, prev: &FrameMeta, cur: &Frame, from_file: Option<&[bool]>) {
        let size = cur.meta.size;
        let n = size.pixels() as usize;
        if cur.depth.len() != n || cur.motion.len() != n {
            return;
        }
        let mask = cur
            .extras
            .iter()
            .find(|e| e.kind == BufferKind::Mask && e.data.len() == n)
            .map(|e| e.data.as_slice());
        let step = (n as f64 / MAX_SAMPLES_PER_FRAME as f64)
            .sqrt()
            .ceil()
            .max(1.0) as u32;
        let (cam, prev_cam) = (&cur.meta.camera, &prev.camera);
        let (cur_f, prev_f) = (
            size_f(size.width, size.height),
            size_f(prev.size.width, prev.size.height),
        );
        let mut checked = false;
        for y in (step / 2..size.height).step_by(step as usize) {
            for x in (step / 2..size.width).step_by(step as usize) {
                let i = (y * size.width + x) as usize;
                let masked = mask.is_some_and(|m| m[i] != 0);
                let untrusted = from_file.is_some_and(|f| !f.get(i).copied().unwrap_or(false));
                let depth = f64::from(cur.depth[i]);
                let mv = DVec2::new(f64::from(cur.motion[i][0]), f64::from(cur.motion[i][1]));
                if masked || untrusted || depth.is_nan() || depth <= 0.0 || !mv.is_finite() {
                    continue;
                }
                let pixel = DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5);
                let Some(expected) = cam.static_motion(prev_cam, pixel, depth, cur_f, prev_f)
                else {
                    continue;
                };
                let radial = cam.view_ray(pixel, cur_f).length();
                let along_ray = cam
                    .static_motion(prev_cam, pixel, depth / radial, cur_f, prev_f)
                    .unwrap_or(DVec2::splat(f64::INFINITY));
                for (h, errors) in Hypothesis::ALL.iter().zip(&mut self.errors) {
                    let e = match h {
                        Hypothesis::AsImported => mv - expected,
                        Hypothesis::SignFlipped => -mv - expected,
                        Hypothesis::YFlipped => DVec2::new(mv.x, -mv.y) - expected,
                        Hypothesis::XFlipped => DVec2::new(-mv.x, mv.y) - expected,
                        Hypothesis::DepthAlongRay => mv - along_ray,
                    };
                    errors.add(e.length());
                }
                checked = true;
            }
        }
        self.frames += u64::from(checked);
    }

    /// The summary, with its warnings.
    pub fn finish(self) -> ReprojectionReport {
        let own = &self.errors[0];
        let mut report = ReprojectionReport {
            frames: self.frames,
            pixels: own.count,
            mean_px: own.mean(),
            median_px: own.median(),
            within_1px: if own.count == 0 {
                0.0
            } else {
                own.within_1px as f64 / own.count as f64
            },
            alternatives: Hypothesis::ALL[1..]
                .iter()
                .zip(&self.errors[1..])
                .map(|(&hypothesis, e)| Alternative {
                    hypothesis,
                    mean_px: e.mean(),
                    median_px: e.median(),
                })
                .collect(),
            warnings: Vec::new(),
        };
        report.warnings = report.diagnose();
        report
    }
}

/// How well a wrong convention would have fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct Alternative {
    /// The reading.
    pub hypothesis: Hypothesis,
    /// Mean error under it, pixels.
    pub mean_px: f64,
    /// Median error under it, pixels.
    pub median_px: f64,
}

/// The result of a [`ReprojectionCheck`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReprojectionReport {
    /// Frames with at least one checked pixel.
    pub frames: u64,
    /// Pixels checked.
    pub pixels: u64,
    /// Mean reprojection error as imported, pixels.
    pub mean_px: f64,
    /// Median reprojection error as imported, pixels (to 0.001 px).
    pub median_px: f64,
    /// Share of checked pixels within 1 px.
    pub within_1px: f64,
    /// The other readings.
    pub alternatives: Vec<Alternative>,
    /// What looks wrong, in words (empty when all is well).
    pub warnings: Vec<String>,
}

impl ReprojectionReport {
    /// Largest error still taken as agreement, pixels.
    pub const TOLERANCE_PX: f64 = 1.0;

    fn diagnose(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.pixels == 0 {
            return warnings;
        }
        if self.median_px > Self::TOLERANCE_PX {
            warnings.push(format!(
                "motion vectors disagree with depth + camera: median {:.3} px, mean {:.3} px \
                 over {} pixels (agreement is well under 1 px); check the source's conventions",
                self.median_px, self.mean_px, self.pixels
            ));
        } else if self.mean_px > Self::TOLERANCE_PX {
            warnings.push(format!(
                "mean reprojection error {:.3} px is above 1 px (median {:.3} px): moving \
                 objects outside a mask raise it; if the source is static, check its conventions",
                self.mean_px, self.median_px
            ));
        }
        // Both errors tiny: a difference is noise, not evidence.
        let best = self
            .alternatives
            .iter()
            .filter(|_| self.median_px > 0.05)
            .min_by(|a, b| a.median_px.total_cmp(&b.median_px));
        if let Some(alt) =
            best.filter(|a| a.median_px < 0.5 * self.median_px && a.mean_px < self.mean_px)
        {
            warnings.push(format!(
                "the motion fits better with {}: median {:.3} px against {:.3} px as imported; \
                 the source's conventions look different from what the importer assumes",
                alt.hypothesis.describe(),
                alt.median_px,
                self.median_px
            ));
        }
        warnings
    }

    /// Logs every warning at `warn` level.
    pub fn warn(&self) {
        for w in &self.warnings {
            tracing::warn!("{w}");
        }
    }

    /// The alternative for `hypothesis`, if it was measured.
    pub fn alternative(&self, hypothesis: Hypothesis) -> Option<&Alternative> {
        self.alternatives
            .iter()
            .find(|a| a.hypothesis == hypothesis)
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::camera::{Camera, Pose, Projection};
    use crate::frame::FrameSize;

    const SIZE: FrameSize = FrameSize::new(64, 36);

    /// A wall 5 units away seen by a camera that moved 0.3 right and 0.2 up
    /// since the previous frame; `convert` maps the true motion to what an importer
    /// produced.
    fn pair(convert: impl Fn([f32; 2]) -> [f32; 2]) -> (FrameMeta, Frame) {
        let projection = Projection::perspective(1.0, 64.0 / 36.0, 0.1, 100.0);
        let at = |x: f64, y: f64| {
            Camera::new(
                Pose::look_at(DVec3::new(x, y, 5.0), DVec3::new(x, y, 0.0), DVec3::Y),
                projection,
            )
        };
        let (prev, cur) = (at(-0.3, -0.2), at(0.0, 0.0));
        let meta = |camera, index| FrameMeta {
            index,
            time: index as f64 / 30.0,
            camera,
            size: SIZE,
            host_processing: std::time::Duration::ZERO,
            cut: false,
        };
        let mut frame = Frame::empty(meta(cur, 1));
        let n = SIZE.pixels() as usize;
        frame.depth = vec![5.0; n];
        frame.motion = (0..n)
            .map(|i| convert(super::super::camera_motion(&cur, Some(&prev), SIZE, i, 5.0)))
            .collect();
        (meta(prev, 0), frame)
    }

    fn check(convert: impl Fn([f32; 2]) -> [f32; 2]) -> ReprojectionReport {
        let (prev, cur) = pair(convert);
        let mut c = ReprojectionCheck::new();
        c.add(&prev, &cur, None);
        c.finish()
    }

    #[test]
    fn right_conventions_agree_silently() {
        let r = check(|m| m);
        assert_eq!((r.frames, r.pixels), (1, SIZE.pixels()));
        assert!(r.mean_px < 1e-4 && r.within_1px == 1.0, "{r:?}");
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    }

    #[test]
    fn a_flipped_sign_is_named_loudly() {
        let r = check(|[x, y]| [-x, -y]);
        assert!(r.median_px > 1.0, "{r:?}");
        assert_eq!(r.warnings.len(), 2, "{:?}", r.warnings);
        assert!(r.warnings[0].contains("disagree"));
        assert!(r.warnings[1].contains("both motion components negated"));
        let flipped = r.alternative(Hypothesis::SignFlipped).unwrap();
        assert!(flipped.mean_px < 1e-4);
    }

    #[test]
    fn masked_and_untrusted_pixels_are_not_checked() {
        let (prev, mut cur) = pair(|[x, y]| [-x, -y]);
        let n = SIZE.pixels() as usize;
        // Everything masked but the first row.
        let mask = (0..n).map(|i| u8::from(i >= 64) * 255).collect();
        cur.extras.push(crate::frame::ExtraBuffer {
            kind: BufferKind::Mask,
            data: mask,
        });
        let mut c = ReprojectionCheck::new();
        c.add(&prev, &cur, None);
        assert!(c.clone().finish().pixels <= 64);
        let nothing = vec![false; n];
        let mut d = ReprojectionCheck::new();
        d.add(&prev, &cur, Some(&nothing));
        let r = d.finish();
        assert_eq!((r.frames, r.pixels), (0, 0));
        assert!(r.warnings.is_empty());
    }

    #[test]
    fn the_median_comes_from_the_histogram() {
        let mut e = Errors::new();
        for v in [0.1, 0.2, 0.3, 5.0, f64::NAN] {
            e.add(v);
        }
        assert!((e.median() - 0.3005).abs() < 1e-9);
        assert_eq!(e.within_1px, 3);
        assert!(e.mean().is_finite());
    }
}
