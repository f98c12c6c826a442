//! History tracking with the static test: GFFE Algorithm 1 (appendix B),
//! DESIGN §4 step 1.
//!
//! For each pixel `x` of rendered frame t with depth `D_t[x]`:
//!
//! * `p = unproject(x, D_t, C_t)` (camera-relative to `C_t`);
//! * `x̂ = project(p, C_{t−1})`, `x' = x + V_{t→t−1}[x]`;
//! * if `‖x̂ − x'‖ > ε` the pixel is **dynamic**: `P_i = P'_{i−1}[x']` for
//!   `i = 1..k−1` (the previous trajectory shifted by one) and `P_0 = p`;
//! * otherwise it is **static** and every `P_i = p`.
//!
//! Choices the paper leaves open, made here:
//! * `x'` reads the previous history at the pixel containing it (nearest).
//! * The **track word** of a pixel is `dynamic | confirmed << 1 |
//!   chain << 2`, where `chain` counts how many of `P_1..P_{k−1}` are real
//!   history: a static pixel's
//!   entries all hold its (static) position, so its chain is `k − 1`; a
//!   dynamic pixel extends the chain found at `x'` by one; a trajectory
//!   that leaves the previous image, meets an empty pixel, or switches
//!   between a point and a sky direction ends there and the remaining
//!   entries repeat the last real one (zero velocity, never garbage).
//! * **Confirmed** static pixels may enter the background layers
//!   (`background.rs`). The static test only compares screen positions, so
//!   a point moving along its view ray (an object coming straight at the
//!   camera) passes it, and would leave a ghost of the object in the
//!   background. A static pixel is confirmed when the previous frame's
//!   position at `x'`, seen from the current camera, lands in a pixel whose
//!   depth agrees with it within the relative `tolerance`. Only the
//!   background needs it: a method that collects no background layers
//!   passes no tolerance and confirms nothing (a second projection and a
//!   random read per static pixel saved).
//! * Invalid depth (sanitised NaN / ≤ 0) gives no position at all.
//! * Without a previous frame (first frame, cut, reset) every pixel is
//!   static.
//!
//! Positions are stored relative to the current camera centre; the previous
//! history is rebased by the previous camera's centre (computed in `f64`).

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::passes::common::camera::{PassCamera, W_DIRECTION, W_INVALID, cell, rebase};

/// The previous rendered frame's history, as the current frame sees it.
#[derive(Clone, Copy, Debug)]
pub struct PrevHistory<'a> {
    /// `C_{t−1}` relative to the current camera centre, at its image size.
    pub camera: PassCamera,
    /// `k` planes of `width × height` positions (plane `i` is `P'_i`).
    pub positions: &'a [[f32; 4]],
    /// Track words.
    pub track: &'a [u32],
}

/// The result of Algorithm 1 for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct History {
    /// `k` planes of positions, plane `i` = `P_i`.
    pub positions: Vec<[f32; 4]>,
    /// Per pixel `dynamic | confirmed << 1 | chain << 2`.
    pub track: Vec<u32>,
    /// Number of pixels that failed the static test.
    pub dynamic: u32,
}

impl History {
    /// No history (no frame tracked).
    pub fn empty() -> Self {
        Self {
            positions: Vec::new(),
            track: Vec::new(),
            dynamic: 0,
        }
    }
}

/// Whether a track word marks a dynamic pixel (`M_dyn = 1`).
pub fn is_dynamic(track: u32) -> bool {
    track & 1 == 1
}

/// Whether a static pixel was confirmed by the previous frame (may enter
/// the background).
pub fn is_confirmed(track: u32) -> bool {
    track & 2 == 2
}

/// How many of `P_1..` are real history.
pub fn chain(track: u32) -> u32 {
    track >> 2
}

/// CPU reference of Algorithm 1. `camera` is `C_t` with its centre at the
/// origin; `k ≥ 1`; `epsilon` in pixels; `tolerance` relative depth (the
/// confirmation runs).
///
/// Runs on all cores: pixels are independent, so bands of rows are tracked
/// in parallel and the result is the same for any thread count.
pub fn track(
    camera: &PassCamera,
    depth: &[f32],
    motion: &[[f32; 2]],
    prev: Option<PrevHistory<'_>>,
    k: u32,
    epsilon: f32,
    tolerance: f32,
) -> History {
    let tracker = Tracker {
        camera,
        depth,
        motion,
        prev: prev.as_ref(),
        k,
        epsilon,
        tolerance: Some(tolerance),
    };
    tracker.track_into(History::empty())
}

/// A band of rows for one task: its first pixel, its slice of every plane,
/// its track words.
type Band<'a> = (usize, Vec<&'a mut [[f32; 4]]>, &'a mut [u32]);

/// What Algorithm 1 reads for every pixel: [`track`]'s arguments.
#[derive(Clone, Copy, Debug)]
pub struct Tracker<'a> {
    /// `C_t`, centre at the origin.
    pub camera: &'a PassCamera,
    /// The frame's sanitised depth.
    pub depth: &'a [f32],
    /// Its motion to the previous frame.
    pub motion: &'a [[f32; 2]],
    /// The previous frame's history, when it continues.
    pub prev: Option<&'a PrevHistory<'a>>,
    /// History length (clamped to `1..=MAX_HISTORY`).
    pub k: u32,
    /// Static-test threshold, pixels.
    pub epsilon: f32,
    /// Relative depth tolerance of the confirmation; `None` confirms
    /// nothing (no background is collected).
    pub tolerance: Option<f32>,
}

impl Tracker<'_> {
    /// Algorithm 1 for every pixel, into the buffers of `reuse`, a history
    /// that is no longer needed (the CPU executor's frame before the
    /// previous one), where their sizes fit: every element is written, so
    /// they are not cleared first and no frame-sized allocation is made
    /// again each frame.
    pub fn track_into(&self, reuse: History) -> History {
        use rayon::prelude::*;
        let (n, k) = (self.depth.len(), self.k());
        let invalid = [0.0, 0.0, 0.0, W_INVALID];
        let mut positions = reuse.positions;
        if positions.len() != k * n {
            positions = crate::par::filled(invalid, k * n);
        }
        let mut track_words = reuse.track;
        if track_words.len() != n {
            track_words = crate::par::filled(0, n);
        }
        // Bands of rows; each band gets its slice of every plane.
        let band = crate::par::band(self.camera.width() as usize, n);
        let mut planes: Vec<_> = positions
            .chunks_mut(n.max(1))
            .map(|p| p.chunks_mut(band))
            .collect();
        let bands: Vec<Band<'_>> = track_words
            .chunks_mut(band)
            .enumerate()
            .map(|(b, words)| {
                let slices = planes.iter_mut().filter_map(Iterator::next).collect();
                (b * band, slices, words)
            })
            .collect();
        let width = (self.camera.width() as usize).max(1);
        let dynamic = bands
            .into_par_iter()
            .map(|(start, mut planes, words)| {
                let mut dynamic = 0;
                let mut entries = [invalid; MAX_HISTORY];
                // Whole rows: the pixel centre is counted, not divided out.
                for (r, row) in words.chunks_mut(width).enumerate() {
                    let first = r * width;
                    let y = ((start + first) / width) as f32 + 0.5;
                    for (c, word) in row.iter_mut().enumerate() {
                        let center = Vec2::new(c as f32 + 0.5, y);
                        // Every element is written, valid or not.
                        let w = self.track(start + first + c, center, &mut entries);
                        for (plane, e) in planes.iter_mut().zip(&entries) {
                            plane[first + c] = *e;
                        }
                        *word = w;
                        dynamic += u32::from(is_dynamic(w));
                    }
                }
                dynamic
            })
            .sum();
        History {
            positions,
            track: track_words,
            dynamic,
        }
    }

    /// The history length in use.
    fn k(&self) -> usize {
        (self.k as usize).clamp(1, MAX_HISTORY)
    }

    /// Pixel `x` (centre `center`): its positions `P_0..P_{k−1}` into
    /// `entries[..k]` and its track word; all invalid (word 0) for an
    /// invalid depth (no position at all).
    #[allow(clippy::needless_range_loop)] // mirrors the shader's indexing
    #[inline]
    fn track(&self, x: usize, center: Vec2, entries: &mut [[f32; 4]; MAX_HISTORY]) -> u32 {
        let Self {
            camera,
            depth,
            motion,
            epsilon,
            tolerance,
            ..
        } = *self;
        let k = self.k();
        let width = camera.width();
        let d = depth[x];
        if d.is_nan() || d <= 0.0 {
            // Only the `k` entries in use are written (and stored).
            entries[..k].fill([0.0, 0.0, 0.0, W_INVALID]);
            return 0;
        }
        let p = camera.unproject(center, d);
        entries[..k].fill(p);
        let mut word = ((k - 1) as u32) << 2;
        if let Some(prev) = self.prev {
            let target = center + Vec2::from_array(motion[x]);
            let reprojected = prev.camera.project(p);
            let is_static = reprojected.is_some_and(|r| {
                let e = r.pixel - target;
                e.x * e.x + e.y * e.y <= epsilon * epsilon
            });
            let found =
                cell(target, prev.camera.width(), prev.camera.height(), 1.0).map(|j| j as usize);
            if is_static
                && let Some(j) = found
                && let Some(tolerance) = tolerance
            {
                let q = rebase(prev.positions[j], shift(prev));
                let agrees = q[3] == p[3]
                    && (q[3] == W_DIRECTION
                        || camera.project(q).is_some_and(|r| {
                            cell(r.pixel, width, camera.height(), 1.0).is_some_and(|y| {
                                let dy = depth[y as usize];
                                (r.depth - dy).abs() <= tolerance * dy
                            })
                        }));
                if agrees {
                    word |= 2;
                }
            }
            if !is_static {
                let prev_n = prev.track.len();
                let mut len = 0usize;
                if let Some(j) = found {
                    let prev_word = prev.track[j];
                    let available = if is_dynamic(prev_word) {
                        chain(prev_word) as usize + 1
                    } else {
                        k - 1
                    };
                    let limit = available.min(k - 1);
                    for i in 1..=limit {
                        let q = rebase(prev.positions[(i - 1) * prev_n + j], shift(prev));
                        if q[3] != p[3] {
                            break;
                        }
                        entries[i] = q;
                        len = i;
                    }
                }
                for i in len + 1..k {
                    entries[i] = entries[i - 1];
                }
                word = 1 | (len as u32) << 2;
            }
        }
        word
    }
}

/// The largest history length `k`.
pub const MAX_HISTORY: usize = 8;

fn shift(prev: &PrevHistory<'_>) -> glam::Vec3 {
    glam::Vec3::new(prev.camera.eye[0], prev.camera.eye[1], prev.camera.eye[2])
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    cur: PassCamera,
    prev: PassCamera,
    /// width, height, prev width, prev height
    sizes: [u32; 4],
    /// k, has_prev, 0, 0
    config: [u32; 4],
    /// epsilon, tolerance (negative: no confirmation), 0, 0
    epsilon: [f32; 4],
}

/// The GPU pass.
#[derive(Debug)]
pub struct GpuHistory {
    kernel: Kernel,
}

/// Buffers of one frame's history on the GPU.
#[derive(Debug)]
pub struct GpuHistoryBuffers<'a> {
    /// `k` planes of `vec4<f32>`.
    pub positions: &'a wgpu::Buffer,
    /// Track words.
    pub track: &'a wgpu::Buffer,
}

impl GpuHistory {
    /// Compiles the kernel.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        Self {
            kernel: Kernel::new(
                ctx,
                include_str!("history.wgsl"),
                "history",
                &[
                    Uniform, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// Records Algorithm 1. `prev` is `None` after a reset (its buffers are
    /// then not read; `out` is bound in their place). `dynamic` receives the
    /// count of dynamic pixels (atomic add; clear it first).
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        camera: &PassCamera,
        depth: &wgpu::Buffer,
        motion: &wgpu::Buffer,
        prev: Option<(&PassCamera, GpuHistoryBuffers<'_>)>,
        out: GpuHistoryBuffers<'_>,
        dynamic: &wgpu::Buffer,
        k: u32,
        epsilon: f32,
        tolerance: Option<f32>,
    ) {
        let (w, h) = (camera.width(), camera.height());
        let (prev_cam, pw, ph) = match &prev {
            Some((c, _)) => (**c, c.width(), c.height()),
            None => (*camera, 0, 0),
        };
        let params = ctx.uniform(bytemuck::bytes_of(&Params {
            cur: *camera,
            prev: prev_cam,
            sizes: [w, h, pw, ph],
            config: [k.max(1), u32::from(prev.is_some()), 0, 0],
            epsilon: [epsilon, tolerance.unwrap_or(-1.0), 0.0, 0.0],
        }));
        // Unused previous buffers are bound to the executor's placeholder
        // (read-only bindings cannot alias the written ones).
        let placeholder = ctx.placeholder();
        let (pp, pt) = match &prev {
            Some((_, b)) => (b.positions, b.track),
            None => (&placeholder, &placeholder),
        };
        self.kernel.dispatch(
            ctx,
            encoder,
            &[
                &params,
                depth,
                motion,
                pp,
                pt,
                out.positions,
                out.track,
                dynamic,
            ],
            u64::from(w) * u64::from(h),
        );
    }
}
