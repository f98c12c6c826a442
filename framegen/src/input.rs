//! Input preparation shared by both backends: a rendered [`Frame`] becomes
//! `f32` buffers with every non-finite or out-of-range value replaced and
//! counted, so no pass ever sees NaN or infinity where it does not expect
//! one (DESIGN §11: sanitised, counted, never propagated).
//!
//! * color: NaN / ±inf channels → 0, negative ones → 0 (linear radiance
//!   is non-negative), on the `f16` bits, which stay `f16` (every finite
//!   one is at most 65504);
//! * depth: `+inf` is kept (sky); NaN, `−inf`, zero and negative depths
//!   become 0, which every pass reads as "no surface";
//! * motion: NaN / ±inf components → 0, and vectors are clamped to
//!   ±4 image sizes (beyond that a point left the image anyway).
//!
//! A frame handed over in an [`Arc`] ([`prepare_shared`]) is not copied
//! where none of this changes anything: each such buffer is read where it
//! is ([`Buffer::Shared`]).

use std::sync::Arc;

use half::f16;
use protocol::Frame;

/// Largest finite `f16`.
pub const MAX_RADIANCE: f32 = 65504.0;

/// Pixels per block of the colour conversions between `f16` and `f32`
/// (the executors' widening and the generator's output): large enough for
/// the vector instructions and the scheduler, small enough for a block on
/// the stack.
pub const CONVERT_BLOCK: usize = 1024;

/// How many values of each buffer were replaced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sanitized {
    /// Color channels that were non-finite (or negative / above
    /// [`MAX_RADIANCE`] are clamped silently and not counted).
    pub color: u64,
    /// Depths that were NaN, `−inf`, zero or negative.
    pub depth: u64,
    /// Motion components that were non-finite.
    pub motion: u64,
}

impl Sanitized {
    /// Total replaced values.
    pub fn total(&self) -> u64 {
        self.color + self.depth + self.motion
    }
}

/// Picks one of a frame's buffers.
pub type Pick<T> = fn(&Frame) -> &[T];

/// A buffer of a [`Prepared`] frame: its own, or the rendered frame's
/// where nothing in it had to be replaced ([`prepare_shared`]): a frame
/// handed over in an [`Arc`] is read where it is, not copied.
#[derive(Clone)]
pub enum Buffer<T: 'static> {
    /// Sanitised values of its own.
    Own(Vec<T>),
    /// The frame's buffer that `get` picks, which needed no replacement.
    Shared(Arc<Frame>, Pick<T>),
}

impl<T> std::ops::Deref for Buffer<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match self {
            Buffer::Own(v) => v,
            Buffer::Shared(frame, get) => get(frame),
        }
    }
}

impl<T: PartialEq> PartialEq for Buffer<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl<T: std::fmt::Debug> std::fmt::Debug for Buffer<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = match self {
            Buffer::Own(_) => "Own",
            Buffer::Shared(..) => "Shared",
        };
        write!(f, "{kind}({} elements)", self.len())
    }
}

impl<T> From<Vec<T>> for Buffer<T> {
    fn from(v: Vec<T>) -> Self {
        Buffer::Own(v)
    }
}

impl<T> Buffer<T> {
    /// Whether it is the rendered frame's own buffer (not copied).
    pub fn is_shared(&self) -> bool {
        matches!(self, Buffer::Shared(..))
    }

    /// Its vector, to be written again, where it has one of `n` elements.
    fn reusable(self, n: usize) -> Option<Vec<T>> {
        match self {
            Buffer::Own(v) if v.len() == n => Some(v),
            _ => None,
        }
    }
}

/// A rendered frame's buffers as the passes read them.
#[derive(Clone, Debug, PartialEq)]
pub struct Prepared {
    /// Linear RGB, alpha 1, as `f16`: the frame's own values, non-finite
    /// and negative ones zeroed. Kept as it crosses the wire and the bus:
    /// the wgpu executor uploads these bytes as they are, and each executor
    /// widens them to the `f32` its passes read once per frame
    /// (`passes::common::widen`, exact).
    pub color: Buffer<[f16; 4]>,
    /// Linear depth; 0 = no surface, `+inf` = sky.
    pub depth: Buffer<f32>,
    /// Motion to the previous frame, pixels.
    pub motion: Buffer<[f32; 2]>,
    /// Pixels with a surface (depth > 0).
    pub valid: u64,
    /// What was replaced.
    pub sanitized: Sanitized,
}

impl Prepared {
    /// A prepared frame of no pixels.
    pub fn empty() -> Self {
        Prepared {
            color: Vec::new().into(),
            depth: Vec::new().into(),
            motion: Vec::new().into(),
            valid: 0,
            sanitized: Sanitized::default(),
        }
    }
}

/// A colour channel as [`prepare`] keeps it, on its `f16` bits: a
/// non-finite value (all exponent bits set) becomes 0 and is reported
/// (`false`), a negative one becomes 0, the rest stays (every finite `f16`
/// is at most [`MAX_RADIANCE`]).
#[inline]
fn sanitize_half(v: f16) -> (f16, bool) {
    let bits = v.to_bits();
    let finite = bits & 0x7c00 != 0x7c00;
    let keep = finite & (bits & 0x8000 == 0);
    (f16::from_bits(if keep { bits } else { 0 }), finite)
}

/// A depth as [`prepare`] keeps it: a surface's (`> 0`, `+inf` = sky)
/// stays, anything else becomes 0 and is counted (`false`).
#[inline]
fn sanitize_depth(d: f32) -> (f32, bool) {
    let surface = d > 0.0;
    (if surface { d } else { 0.0 }, surface)
}

/// A motion component as [`prepare`] keeps it: clamped to `±limit`, a
/// non-finite one 0 and reported (`false`). Compares and selects (`min`/
/// `max` carry NaN rules that keep the loops scalar); NaN fails both and
/// is replaced.
#[inline]
fn sanitize_motion(v: f32, limit: f32) -> (f32, bool) {
    let finite = v.is_finite();
    let c = if v < -limit { -limit } else { v };
    let c = if c > limit { limit } else { c };
    (if finite { c } else { 0.0 }, finite)
}

/// Converts and sanitises a frame's buffers.
pub fn prepare(frame: &Frame) -> Prepared {
    prepare_into(frame, None)
}

/// [`prepare`] into the buffers of `reuse`, a prepared frame no longer
/// needed, where their sizes fit: every element is written, so they are not
/// filled first (a fresh frame-sized buffer is written twice, once to fill
/// it and once with its values).
pub fn prepare_into(frame: &Frame, reuse: Option<Prepared>) -> Prepared {
    prepare_with(frame, None, reuse)
}

/// [`prepare`] of a frame handed over in an [`Arc`]: each buffer that
/// holds nothing to replace (a well-formed frame's, all of them) is read
/// where it is ([`Buffer::Shared`]); only one that does is copied, into
/// `reuse`'s buffer where it fits. The same values and counts as
/// [`prepare`], without writing a frame's worth of bytes (720p: 18 MB
/// read instead of 18 MB read and 18 MB written, per rendered frame).
pub fn prepare_shared(frame: &Arc<Frame>, reuse: Option<Prepared>) -> Prepared {
    prepare_with(frame, Some(frame), reuse)
}

/// One buffer of [`prepare_with`], the one `get` picks of `frame`. Where
/// it may be shared (`share` is the same frame), `scan` tells of
/// each block whether any value changes, and otherwise how many it counts
/// as replaced (a depth of +0 is counted and stays): with no change the
/// frame's buffer is shared. Otherwise it is written by `fix` into
/// `kept`'s vector (where that holds as many elements) or a new one.
fn sanitize_buffer<T: Copy + Default + Send + Sync + 'static>(
    (frame, share): (&Frame, Option<&Arc<Frame>>),
    get: Pick<T>,
    kept: Option<Buffer<T>>,
    scan: impl Fn(&[T]) -> Option<u32> + Sync + Send,
    fix: impl Fn(&[T], &mut [T]) -> u32 + Sync + Send,
) -> (Buffer<T>, u64) {
    use rayon::prelude::*;
    let src = get(frame);
    if let Some(frame) = share {
        let counted = (src.par_chunks(CONVERT_BLOCK))
            .map(|s| scan(s).map(u64::from))
            .try_reduce(|| 0, |a, b| Some(a + b));
        if let Some(bad) = counted {
            return (Buffer::Shared(frame.clone(), get), bad);
        }
    }
    let kept = kept.and_then(|b| b.reusable(src.len()));
    let mut out = kept.unwrap_or_else(|| crate::par::filled(T::default(), src.len()));
    // Each block's replacements summed as integers: the same count for
    // any thread count.
    let bad = (out.par_chunks_mut(CONVERT_BLOCK))
        .zip(src.par_chunks(CONVERT_BLOCK))
        .map(|(o, s)| u64::from(fix(s, o)))
        .sum();
    (Buffer::Own(out), bad)
}

/// [`prepare_into`], sharing the buffers of `share` (the same frame) that
/// need no replacement.
fn prepare_with(frame: &Frame, share: Option<&Arc<Frame>>, reuse: Option<Prepared>) -> Prepared {
    let kept = match reuse {
        Some(p) => (Some(p.color), Some(p.depth), Some(p.motion)),
        None => (None, None, None),
    };
    // Colour on its `f16` bits (no conversion needed to see a non-finite
    // or negative value), every lane alike (alpha too, then set to 1 and
    // its count taken back out): uniform lanes vectorise, a 3-of-4 pattern
    // does not. Counts per block fit a `u32`.
    let color_fix = |src: &[[f16; 4]], out: &mut [[f16; 4]]| {
        let mut bad = 0u32;
        for (d, &v) in out.as_flattened_mut().iter_mut().zip(src.as_flattened()) {
            let (h, finite) = sanitize_half(v);
            bad += u32::from(!finite);
            *d = h;
        }
        for (c, s) in out.iter_mut().zip(src) {
            bad -= u32::from(!sanitize_half(s[3]).1);
            c[3] = f16::ONE;
        }
        bad
    };
    // A channel changes where its bits are at least those of +inf (a sign
    // bit, or all exponent bits: NaN, ±inf, anything negative), alpha
    // where it is not 1; nothing is counted where nothing changes.
    let color_scan = |src: &[[f16; 4]]| {
        let highest = (src.as_flattened().iter()).fold(0u16, |m, v| m.max(v.to_bits()));
        let alpha = (src.iter()).fold(0u16, |a, c| a | (c[3].to_bits() ^ f16::ONE.to_bits()));
        (highest < f16::INFINITY.to_bits() && alpha == 0).then_some(0)
    };
    // In blocks with a count per block, as motion: a loop the compiler
    // vectorises (a count per value, an atomic add, kept it scalar).
    let depth_fix = |src: &[f32], out: &mut [f32]| {
        let mut bad = 0u32;
        for (o, &d) in out.iter_mut().zip(src) {
            let (v, surface) = sanitize_depth(d);
            bad += u32::from(!surface);
            *o = v;
        }
        bad
    };
    // A depth changes where it is not a surface and not +0 (its bits are
    // not 0): NaN, −0, anything negative.
    let depth_scan = |src: &[f32]| {
        let (mut bad, mut changed) = (0u32, false);
        for &d in src {
            let surface = d > 0.0;
            bad += u32::from(!surface);
            changed |= !surface & (d.to_bits() != 0);
        }
        (!changed).then_some(bad)
    };
    let limit = 4.0 * frame.meta.size.width.max(frame.meta.size.height) as f32;
    // Component by component in blocks, with a count per block: a loop the
    // compiler vectorises (a closure per component was not inlined).
    let motion_fix = |src: &[[f32; 2]], out: &mut [[f32; 2]]| {
        let mut bad = 0u32;
        for (o, &v) in out.as_flattened_mut().iter_mut().zip(src.as_flattened()) {
            let (c, finite) = sanitize_motion(v, limit);
            bad += u32::from(!finite);
            *o = c;
        }
        bad
    };
    // A component changes where it is not within ±limit (NaN is not).
    let motion_scan = |src: &[[f32; 2]]| {
        let inside = (src.as_flattened().iter()).fold(true, |a, v| a & (v.abs() <= limit));
        inside.then_some(0)
    };
    let on = (frame, share);
    let (color, bad_color) = sanitize_buffer(on, |f| &f.color, kept.0, color_scan, color_fix);
    let (depth, bad_depth) = sanitize_buffer(on, |f| &f.depth, kept.1, depth_scan, depth_fix);
    let (motion, bad_motion) = sanitize_buffer(on, |f| &f.motion, kept.2, motion_scan, motion_fix);
    let s = Sanitized {
        color: bad_color,
        depth: bad_depth,
        motion: bad_motion,
    };
    let valid = depth.len() as u64 - s.depth;
    Prepared {
        color,
        depth,
        motion,
        valid,
        sanitized: s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sanitising on the bits is the documented one on the values, for
    /// every `f16`: non-finite → 0 and reported, the rest clamped to
    /// `[0, 65504]`.
    #[test]
    fn every_half_is_sanitised_as_its_value_says() {
        for bits in 0..=u16::MAX {
            let v = f16::from_bits(bits);
            let (h, finite) = sanitize_half(v);
            let x = v.to_f32();
            let expected = if x.is_finite() {
                x.clamp(0.0, MAX_RADIANCE)
            } else {
                0.0
            };
            assert_eq!(finite, x.is_finite(), "{bits:#06x}");
            assert_eq!(h.to_f32(), expected, "{bits:#06x}");
            assert!(h.is_sign_positive(), "{bits:#06x}");
        }
    }

    /// A frame with values to replace in every buffer.
    fn dirty(index: u64, size: protocol::FrameSize) -> Frame {
        let mut f = crate::testutil::frame(index, size);
        for (i, c) in f.color.iter_mut().enumerate() {
            let v = f16::from_f32(i as f32 * 0.37 - 20.0);
            *c = [v, f16::NAN, f16::from_f32(i as f32), f16::INFINITY];
        }
        for (i, d) in f.depth.iter_mut().enumerate() {
            *d = [f32::NAN, -1.0, 0.0, 2.5, f32::INFINITY][i % 5];
        }
        for (i, m) in f.motion.iter_mut().enumerate() {
            *m = [[f32::NAN, 1e9][i % 2], i as f32 - 3.0];
        }
        f
    }

    /// Preparing into the buffers of an earlier prepared frame gives what a
    /// fresh preparation gives (buffers, counts), whatever those buffers
    /// held, and buffers of another size are not reused.
    #[test]
    fn prepared_into_reused_buffers_is_prepared_afresh() {
        let size = protocol::FrameSize::new(37, 5);
        let frame = dirty(1, size);
        let fresh = prepare(&frame);
        assert!(fresh.sanitized.total() > 0 && fresh.valid > 0);
        let earlier = prepare(&crate::testutil::frame(0, size));
        let color_at = earlier.color.as_ptr();
        let reused = prepare_into(&frame, Some(earlier));
        assert_eq!(reused, fresh);
        assert_eq!(reused.color.as_ptr(), color_at, "the buffer was reused");
        let small = prepare(&crate::testutil::frame(0, protocol::FrameSize::new(3, 2)));
        assert_eq!(prepare_into(&frame, Some(small)), fresh);
    }

    /// A frame handed over in an `Arc` is prepared as a copied one is
    /// (values and counts), and only the buffers with nothing to replace
    /// are shared: a clean frame's all three, a frame with one value to
    /// replace in one buffer (each kind of value in turn) that buffer
    /// copied and the others shared.
    #[test]
    fn a_shared_frame_is_prepared_as_a_copied_one_and_copies_only_what_changes() {
        let size = protocol::FrameSize::new(37, 5);
        let mut clean = crate::testutil::frame(3, size);
        for (i, (c, (d, m))) in (clean.color.iter_mut())
            .zip(clean.depth.iter_mut().zip(clean.motion.iter_mut()))
            .enumerate()
        {
            let v = i as f32;
            *c = [0.1 * v, 65504.0, 0.0, 1.0].map(f16::from_f32);
            *d = [0.0, 2.5, f32::INFINITY][i % 3];
            *m = [v - 90.0, 4.0 * 37.0];
        }
        let shared = |f: &Frame| {
            let p = prepare_shared(&Arc::new(f.clone()), None);
            assert_eq!(p, prepare(f));
            [
                p.color.is_shared(),
                p.depth.is_shared(),
                p.motion.is_shared(),
            ]
        };
        assert_eq!(shared(&clean), [true; 3]);
        // (the buffer it makes copied, the edit)
        type Edit = (usize, fn(&mut Frame));
        let edits: [Edit; 11] = [
            (0, |f| f.color[7][1] = f16::NAN),
            (0, |f| f.color[7][0] = f16::NEG_ZERO),
            (0, |f| f.color[7][2] = f16::from_f32(-1.0)),
            (0, |f| f.color[7][3] = f16::from_f32(0.5)),
            (0, |f| f.color[7][3] = f16::INFINITY),
            (1, |f| f.depth[7] = f32::NAN),
            (1, |f| f.depth[7] = -0.0),
            (1, |f| f.depth[7] = f32::NEG_INFINITY),
            (2, |f| f.motion[7][0] = f32::INFINITY),
            (2, |f| f.motion[7][1] = 4.0 * 37.0 + 1.0),
            (2, |f| f.motion[7][0] = -1e9),
        ];
        for (k, (copied, edit)) in edits.into_iter().enumerate() {
            let mut f = clean.clone();
            edit(&mut f);
            let mut expected = [true; 3];
            expected[copied] = false;
            assert_eq!(shared(&f), expected, "edit {k}");
        }
        assert_eq!(shared(&dirty(4, size)), [false; 3]);
    }
}
