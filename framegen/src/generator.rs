//! The frame generator: one API over every method and both backends.
//!
//! Fed rendered frames with [`FrameGenerator::push`], asked for generated
//! frames with [`FrameGenerator::generate`] at any α ≥ 0 (α = 1 is one
//! render interval after the last rendered frame). The generator owns what
//! is the same for every backend: input sanitising, cut and duplicate
//! detection, the camera of the generated frame (GFFE eq. 2 or a pose the
//! caller knows), the displayed region of a widened window, and turning the
//! passes' output into a [`Frame`] plus a per-pixel [`PixelSource`] mask.
//! The passes themselves run on a [`Backend`]: the CPU reference
//! ([`crate::exec::cpu::CpuBackend`]) or wgpu ([`crate::exec::gpu::GpuBackend`]).
//!
//! Which passes run is the settings' [`Plan`](crate::pipeline::plan::Plan):
//! the method, and the stages the stream's effects call for (shading
//! correction where shading moves, trajectories where objects move).

use std::borrow::Cow;
use std::sync::Arc;
use std::time::Duration;

use glam::Vec2;
use protocol::{Camera, Frame, FrameMeta, FrameSize, Limits, Pose, Window};

use crate::FramegenError;
use crate::gpu::GpuContext;
use crate::input::{Prepared, Sanitized, prepare, prepare_into, prepare_shared};
use crate::output::{DisplayMap, Output, PixelSource};
use crate::passes::common::camera::PassCamera;
use crate::passes::common::crop::Crop;
use crate::passes::common::levels::Levels;
use crate::passes::common::pack::Packed;
use crate::pipeline::{Backend, IngestPlan, Job, PassTime, Snapshot};
use crate::settings::Settings;

/// Where the camera of a generated frame comes from (DESIGN §4 step 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraSource {
    /// GFFE eq. 2 from the last two rendered cameras.
    Extrapolated,
    /// A pose the caller knows (e.g. the viewer's own input).
    Given(Pose),
}

/// A generated frame.
#[derive(Clone, Debug)]
pub struct Generated {
    /// Color, depth and motion like a rendered frame (GFFE §7.1). The
    /// meta carries the source frame's index, time `t + α·Δ`, the
    /// generated camera (plain window) and the displayed size. Motion
    /// points to the source rendered frame's displayed region.
    pub frame: Frame,
    /// The α it was generated at.
    pub alpha: f64,
    /// Per pixel, where it came from.
    pub mask: Vec<PixelSource>,
    /// The same buffers in `f32`, as the passes left them, where the
    /// backend has them on the host (the CPU reference; the wgpu backend
    /// packs on the device and reads back only the packed frame).
    pub output: Option<Output>,
}

impl Generated {
    /// Number of pixels from `source`.
    pub fn count(&self, source: PixelSource) -> usize {
        self.mask.iter().filter(|&&m| m == source).count()
    }
}

/// What [`FrameGenerator::push`] did with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PushOutcome {
    /// Taken, continuing the history.
    Continued {
        /// Pixels that failed the static test.
        dynamic: u32,
    },
    /// Taken after a reset (first frame, cut flag, size or projection
    /// change, time going backwards, or a detected cut).
    Restarted {
        /// Why.
        reason: &'static str,
    },
    /// The same frame again (same time and camera): ignored.
    Duplicate,
}

/// What the generator remembers of the last rendered frame.
#[derive(Clone, Debug)]
struct Current {
    meta: FrameMeta,
    /// The rendered frame before it, when the history continues.
    prev: Option<Previous>,
    display: (u32, u32),
    crop: Crop,
}

/// What eq. 2 needs of the rendered frame before the current one.
#[derive(Clone, Copy, Debug)]
struct Previous {
    pose: Pose,
    time: f64,
    /// Stream frames between it and the current one: 1, or more after a
    /// gap (frames that never arrived).
    steps: u64,
}

impl Previous {
    /// The render interval the stream ran at: the time between the two
    /// frames per stream frame (0 if time stood still).
    fn interval(&self, now: f64) -> f64 {
        if now > self.time {
            (now - self.time) / self.steps as f64
        } else {
            0.0
        }
    }
}

/// The frame generator.
pub struct FrameGenerator {
    settings: Settings,
    backend: Box<dyn Backend>,
    current: Option<Current>,
    sanitized: Sanitized,
    limits: Limits,
    /// The last few prepared frames, whose buffers the next push reuses
    /// once no executor holds them.
    recent: std::collections::VecDeque<Arc<Prepared>>,
}

/// Prepared frames kept in [`FrameGenerator`]'s `recent`: one more than an
/// executor holds (the current frame and the one before).
const RECENT: usize = 3;

impl std::fmt::Debug for FrameGenerator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameGenerator")
            .field("settings", &self.settings)
            .field("backend", &self.backend.name())
            .finish()
    }
}

impl FrameGenerator {
    /// A generator on the CPU reference.
    pub fn cpu(settings: Settings) -> Result<Self, FramegenError> {
        Self::with_backend(settings, Box::new(crate::exec::cpu::CpuBackend::default()))
    }

    /// A generator on wgpu. A kernel the device cannot build (e.g. a
    /// limit of wgpu's OpenGL backend) is a typed error.
    pub fn gpu(settings: Settings, ctx: Arc<GpuContext>) -> Result<Self, FramegenError> {
        let backend = ctx.checked("compiling the generator's kernels", || {
            crate::exec::gpu::GpuBackend::new(ctx.clone())
        })?;
        Self::with_backend(settings, Box::new(backend))
    }

    /// A generator on any backend.
    pub fn with_backend(
        settings: Settings,
        backend: Box<dyn Backend>,
    ) -> Result<Self, FramegenError> {
        settings.validate()?;
        Ok(Self {
            settings,
            backend,
            current: None,
            sanitized: Sanitized::default(),
            limits: Limits::default(),
            recent: Default::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// `frame` as the display shows it: its displayed region (the plain
    /// view of a frame rendered with a widened window, DESIGN §4.5) at the
    /// display size, with the plain view's camera and motion in displayed
    /// pixels; a frame already at the display size with a full window as
    /// it is, borrowed (nothing is copied on the presenter's path for a
    /// plain window). Rendered frames go to the display through this,
    /// generated ones are made in the displayed view.
    pub fn displayed<'a>(&self, frame: &'a Frame) -> Result<Cow<'a, Frame>, FramegenError> {
        frame.validate(&self.limits)?;
        let (_, crop) = displayed_region(&frame.meta, self.settings.display_size);
        if crop.is_identity() {
            return Ok(Cow::Borrowed(frame));
        }
        let p = prepare(frame);
        let color = crate::passes::common::widen::widen(&p.color);
        let out = crate::passes::common::crop::crop(&color, &p.depth, &p.motion, &crop, false);
        let (width, height) = crop.output;
        let meta = FrameMeta {
            camera: Camera {
                window: Window::FULL,
                ..frame.meta.camera
            },
            size: FrameSize { width, height },
            ..frame.meta
        };
        Ok(Cow::Owned(finish(meta, 0.0, out)?.frame))
    }

    /// The backend's name.
    pub fn backend_name(&self) -> String {
        self.backend.name()
    }

    /// Values replaced by input sanitising so far.
    pub fn sanitized(&self) -> Sanitized {
        self.sanitized
    }

    /// The stages this generator runs.
    pub fn plan(&self) -> crate::pipeline::plan::Plan {
        self.settings.plan()
    }

    /// Pass timings of the last push + generate.
    pub fn timings(&self) -> Vec<PassTime> {
        self.backend.timings()
    }

    /// Whether the following pushes and generations time each pass (see
    /// [`Backend::set_profiling`]): per-pass times on wgpu cost a
    /// submission and a wait per pass, so true totals are measured with it
    /// off.
    pub fn set_profiling(&mut self, on: bool) {
        self.backend.set_profiling(on);
    }

    /// Whether [`FrameGenerator::timings`] holds per-pass times.
    pub fn profiling(&self) -> bool {
        self.backend.profiling()
    }

    /// The history and background the last push left (parity tests,
    /// debugging).
    pub fn snapshot(&self) -> Result<Option<Snapshot>, FramegenError> {
        self.backend.snapshot()
    }

    /// Drops all history (the caller signals a cut).
    pub fn reset(&mut self) {
        self.current = None;
        self.backend.reset();
    }

    /// Takes a rendered frame, copying its buffers (sanitised on the way).
    pub fn push(&mut self, frame: &Frame) -> Result<PushOutcome, FramegenError> {
        self.push_with(frame, |reuse| prepare_into(frame, reuse))
    }

    /// [`FrameGenerator::push`] of a frame handed over in an [`Arc`]: its
    /// buffers are read where they are, not copied, where nothing in them
    /// needs sanitising ([`crate::input::prepare_shared`]); the frame is
    /// held until the passes are done with it.
    pub fn push_shared(&mut self, frame: &Arc<Frame>) -> Result<PushOutcome, FramegenError> {
        self.push_with(frame, |reuse| prepare_shared(frame, reuse))
    }

    /// [`FrameGenerator::push`], the frame prepared by `prepare` (given the
    /// buffers of a prepared frame no longer needed).
    fn push_with(
        &mut self,
        frame: &Frame,
        prepare: impl FnOnce(Option<Prepared>) -> Prepared,
    ) -> Result<PushOutcome, FramegenError> {
        frame.validate(&self.limits)?;
        let meta = &frame.meta;
        let (display, crop) = displayed_region(meta, self.settings.display_size);
        let restart = match &self.current {
            None => Some("first frame"),
            Some(_) if meta.cut => Some("cut flagged by the source"),
            // A widened window may change the rendered size every frame
            // (KeepDensity); the passes map between the two grids. Only the
            // displayed size must stay.
            Some(c) if c.display != display => Some("display size changed"),
            Some(c) if c.meta.camera.projection != meta.camera.projection => {
                Some("projection changed")
            }
            Some(c) if meta.time < c.meta.time => Some("time went backwards"),
            Some(c) if meta.time == c.meta.time && meta.camera.pose == c.meta.camera.pose => {
                return Ok(PushOutcome::Duplicate);
            }
            Some(c) if meta.index <= c.meta.index => Some("index did not increase"),
            Some(_) => None,
        };
        // The oldest prepared frame nothing else holds any more (the
        // executors keep the last one or two) lends its buffers.
        let free = self.recent.iter().position(|p| Arc::strong_count(p) == 1);
        let reuse = free
            .and_then(|i| self.recent.remove(i))
            .and_then(|p| Arc::try_unwrap(p).ok());
        let prepared = Arc::new(prepare(reuse));
        self.recent.push_back(prepared.clone());
        if self.recent.len() > RECENT {
            self.recent.pop_front();
        }
        self.sanitized.color += prepared.sanitized.color;
        self.sanitized.depth += prepared.sanitized.depth;
        self.sanitized.motion += prepared.sanitized.motion;
        if prepared.sanitized.total() > 0 {
            tracing::debug!(frame = meta.index, sanitized = ?prepared.sanitized, "replaced non-finite input values");
        }
        let origin = meta.camera.pose.position;
        let camera = PassCamera::new(&meta.camera, meta.size, origin);
        let levels = Levels::new(
            self.settings.effective_levels(),
            meta.size.width,
            meta.size.height,
        );
        let mut plan = IngestPlan {
            camera,
            prev: None,
            follows: false,
            k: self.settings.effective_history(),
            epsilon: self.settings.static_epsilon,
            levels,
            tolerance: self.settings.depth_tolerance,
            shading: self.settings.effective_shading(),
            planes: self.settings.warps_catmull_rom(),
        };
        let mut prev = match (&self.current, restart) {
            (Some(c), None) => {
                plan.prev = Some(PassCamera::new(&c.meta.camera, c.meta.size, origin));
                let steps = meta.index - c.meta.index;
                // After a gap the motion vectors point to a frame that never
                // arrived: the history restarts (every pixel static, no
                // trajectory) while the background, held as positions,
                // carries over through the cameras alone.
                plan.follows = steps == 1;
                if !plan.follows {
                    tracing::debug!(frame = meta.index, missing = steps - 1, "frame gap");
                }
                Some(Previous {
                    pose: c.meta.camera.pose,
                    time: c.meta.time,
                    steps,
                })
            }
            _ => {
                self.backend.reset();
                None
            }
        };
        let mut outcome = match restart {
            Some(reason) => PushOutcome::Restarted { reason },
            None => PushOutcome::Continued { dynamic: 0 },
        };
        let dynamic = self.backend.ingest(&prepared, &plan)?;
        if plan.prev.is_some() {
            let fraction = dynamic as f32 / prepared.valid.max(1) as f32;
            // Every method that tracks (all but repeat) detects cuts: an
            // undetected cut would extrapolate the camera across the jump
            // (reproject, gffe) or blend two shots (interp).
            if plan.k > 0 && fraction > self.settings.cut_dynamic_fraction {
                tracing::debug!(
                    frame = meta.index,
                    fraction,
                    "detected a cut: restarting history"
                );
                self.backend.reset();
                plan.prev = None;
                self.backend.ingest(&prepared, &plan)?;
                outcome = PushOutcome::Restarted {
                    reason: "detected cut (most pixels failed the static test)",
                };
                prev = None;
            } else {
                outcome = PushOutcome::Continued { dynamic };
            }
        }
        self.current = Some(Current {
            meta: *meta,
            prev,
            display,
            crop,
        });
        Ok(outcome)
    }

    /// A generated frame at `alpha` with the extrapolated camera.
    pub fn generate(&mut self, alpha: f64) -> Result<Generated, FramegenError> {
        self.generate_with(alpha, CameraSource::Extrapolated)
    }

    /// The `n` generated frames of the last rendered frame, α = j/(n+1).
    pub fn generate_all(&mut self) -> Result<Vec<Generated>, FramegenError> {
        let n = self.settings.n;
        (1..=n)
            .map(|j| self.generate(f64::from(j) / f64::from(n + 1)))
            .collect()
    }

    /// A generated frame at `alpha` with the camera from `source`.
    pub fn generate_with(
        &mut self,
        alpha: f64,
        source: CameraSource,
    ) -> Result<Generated, FramegenError> {
        let (job, meta) = self.job(alpha, source)?;
        let (packed, output) = self.backend.generate_packed(&job)?;
        assemble(meta, alpha, packed, output)
    }

    /// The device the generator runs on, if it runs on one.
    pub fn device(&self) -> Option<&Arc<GpuContext>> {
        self.backend.device()
    }

    /// A generated frame at `alpha` with the camera from `source`, left on
    /// the generator's device: its colour (linear RGBA `f16`, bit for bit
    /// the colour [`FrameGenerator::generate_with`] returns) is written
    /// into `target`, an `Rgba16Float` texture of the frame's size on
    /// [`FrameGenerator::device`] with `COPY_DST` usage, and nothing is
    /// read back (issue 15 §2: a presenter on that device shows it from
    /// there). Returns the frame's header; a generator on the CPU refuses.
    pub fn generate_to(
        &mut self,
        alpha: f64,
        source: CameraSource,
        target: &wgpu::Texture,
    ) -> Result<FrameMeta, FramegenError> {
        let (job, meta) = self.job(alpha, source)?;
        self.backend.generate_to(&job, target)?;
        Ok(meta)
    }

    /// The size of the frames generated from the last rendered frame: the
    /// displayed size, or the rendered grid for a method that works on it
    /// (interpolation); none before the first frame.
    pub fn generated_size(&self) -> Option<FrameSize> {
        let cur = self.current.as_ref()?;
        let (width, height) = if self.settings.method.descriptor().rendered_grid {
            (cur.meta.size.width, cur.meta.size.height)
        } else {
            cur.display
        };
        Some(FrameSize { width, height })
    }

    /// The job of a generated frame at `alpha` with the camera from
    /// `source`, and the frame's header.
    fn job(&self, alpha: f64, source: CameraSource) -> Result<(Job, FrameMeta), FramegenError> {
        let method = self.settings.method.descriptor();
        let max_alpha = method.max_alpha(self.settings.max_alpha);
        if !(alpha.is_finite() && alpha >= 0.0 && alpha <= max_alpha) {
            return Err(FramegenError::Alpha(alpha, max_alpha));
        }
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        // Interpolation runs between the previous frame (α = 0) and the
        // current one (α = 1): eq. 2 with α − 1 interpolates (the position
        // linearly, the rotation by slerp).
        let along = method.along(alpha);
        let pose = match source {
            // α counts render intervals; after a gap the last step spans
            // several.
            CameraSource::Extrapolated => match &cur.prev {
                Some(prev) => {
                    Pose::extrapolate(&prev.pose, &cur.meta.camera.pose, along / prev.steps as f64)
                }
                None => cur.meta.camera.pose,
            },
            CameraSource::Given(pose) => {
                pose.validate().map_err(FramegenError::Camera)?;
                pose.normalized()
            }
        };
        // Interpolation works on the rendered grid (its window included).
        let camera = Camera {
            pose,
            projection: cur.meta.camera.projection,
            window: if method.rendered_grid {
                cur.meta.camera.window
            } else {
                Window::FULL
            },
        };
        let size = self.generated_size().ok_or(FramegenError::NoFrame)?;
        let (dw, dh) = (size.width, size.height);
        let origin = cur.meta.camera.pose.position;
        let crop = cur.crop;
        let job = Job {
            method: self.settings.method,
            target: PassCamera::new(&camera, size, origin),
            current: PassCamera::new(&cur.meta.camera, cur.meta.size, origin),
            alpha: alpha as f32,
            k: self.settings.effective_history(),
            map: DisplayMap {
                offset: crop.origin,
                scale: crop.scale(),
            },
            bg_target: Levels::new(self.settings.effective_levels(), dw, dh),
            bg_source: Levels::new(
                self.settings.effective_levels(),
                cur.meta.size.width,
                cur.meta.size.height,
            ),
            pushpull: self.settings.pushpull_levels,
            crop,
            resample: self.settings.resample,
            shading: self.settings.effective_shading(),
        };
        let interval = cur.prev.map_or(0.0, |p| p.interval(cur.meta.time));
        let meta = FrameMeta {
            index: cur.meta.index,
            time: cur.meta.time + along * interval,
            camera,
            size,
            host_processing: Duration::ZERO,
            cut: false,
        };
        Ok((job, meta))
    }
}

/// The displayed size and crop of a frame (DESIGN §4.5).
fn displayed_region(meta: &FrameMeta, display_size: Option<(u32, u32)>) -> ((u32, u32), Crop) {
    let (w, h) = (meta.size.width, meta.size.height);
    let (x0, y0, x1, y1) = meta.camera.window.display_rect(meta.size.as_f64());
    let extent = Vec2::new((x1 - x0) as f32, (y1 - y0) as f32);
    let display = display_size.unwrap_or_else(|| {
        if meta.camera.window.is_full() {
            (w, h)
        } else {
            (
                (extent.x.round() as u32).max(1),
                (extent.y.round() as u32).max(1),
            )
        }
    });
    let crop = Crop {
        source: (w, h),
        origin: Vec2::new(x0 as f32, y0 as f32),
        extent,
        output: display,
    };
    (display, crop)
}

/// Turns the passes' output into a [`Generated`] (the CPU reference's
/// packing; the f32 output is kept).
pub(crate) fn finish(meta: FrameMeta, alpha: f64, out: Output) -> Result<Generated, FramegenError> {
    let packed = crate::passes::common::pack::pack(&out);
    assemble(meta, alpha, packed, Some(out))
}

/// A [`Generated`] of packed buffers, which must be of the size `meta`
/// says (an executor that made another size is refused, not passed on as
/// a frame whose buffers contradict its header).
pub(crate) fn assemble(
    meta: FrameMeta,
    alpha: f64,
    packed: Packed,
    output: Option<Output>,
) -> Result<Generated, FramegenError> {
    let size = meta.size;
    if (packed.width, packed.height) != (size.width, size.height) {
        return Err(FramegenError::Sizes(
            packed.width,
            packed.height,
            size.width,
            size.height,
        ));
    }
    let frame = Frame {
        meta,
        color: packed.color,
        depth: packed.depth,
        motion: packed.motion,
        extras: Vec::new(),
    };
    Ok(Generated {
        frame,
        alpha,
        mask: packed.mask,
        output,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::Pixel;

    #[test]
    fn a_generated_frame_of_another_size_is_refused() {
        let meta = crate::testutil::frame(0, FrameSize::new(4, 2)).meta;
        let fits = Output::from_fn(4, 2, |_| Pixel::EMPTY);
        let g = finish(meta, 0.5, fits).expect("the size of its header");
        assert_eq!(g.frame.color.len(), 8);
        let other = Output::from_fn(2, 4, |_| Pixel::EMPTY);
        assert!(matches!(
            finish(meta, 0.5, other),
            Err(FramegenError::Sizes(2, 4, 4, 2))
        ));
    }

    /// A frame of the display's size with a plain window is shown as it
    /// is, borrowed; one rendered with a widened window is cropped to the
    /// display, a frame of its own.
    #[test]
    fn a_plain_frame_is_displayed_without_a_copy() {
        let settings = crate::Settings {
            display_size: Some((16, 8)),
            ..crate::Settings::for_method(crate::Method::Gffe)
        };
        let g = FrameGenerator::cpu(settings).expect("a CPU generator");
        let plain = crate::testutil::frame(3, FrameSize::new(16, 8));
        match g.displayed(&plain).expect("a valid frame") {
            Cow::Borrowed(f) => assert!(std::ptr::eq(f, &plain)),
            Cow::Owned(_) => panic!("a plain frame was copied"),
        }
        let mut widened = crate::testutil::frame(4, FrameSize::new(20, 10));
        widened.meta.camera.window = Window {
            u0: -1.25,
            v0: -1.25,
            u1: 1.25,
            v1: 1.25,
        };
        let shown = g.displayed(&widened).expect("a valid frame");
        assert!(matches!(shown, Cow::Owned(_)));
        assert_eq!((shown.meta.size.width, shown.meta.size.height), (16, 8));
        assert!(shown.meta.camera.window.is_full());
        assert_eq!(shown.color.len(), 16 * 8);
    }
}
