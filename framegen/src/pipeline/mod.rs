//! The contract between the generator and the executors that run the
//! passes, and every method's plan, written once: what ingesting a rendered
//! frame and making one generated frame ask for ([`IngestPlan`], [`Job`]),
//! the passes an executor offers ([`Executor`]), the plans that call them in
//! each method's order ([`ingest`], [`generate`]), the pass names of
//! timings, and the history snapshot the parity tests compare. The generator
//! and each executor depend on this module, never on each other (DESIGN §2).

pub mod plan;

use std::sync::Arc;
use std::time::Duration;

use crate::FramegenError;
use crate::input::Prepared;
use crate::output::{DisplayMap, Output};
use crate::passes::common::camera::PassCamera;
use crate::passes::common::crop::Crop;
use crate::passes::common::levels::Levels;
use crate::passes::common::pack::Packed;
use crate::passes::common::resample::Resample;
use crate::settings::Method;

/// A pass, for timings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Pass {
    /// Sanitising and (GPU) uploading the rendered frame.
    Upload,
    /// History tracking (GFFE Alg. 1).
    History,
    /// Background collection (GFFE §4.2).
    Background,
    /// Position estimation (eq. 1).
    Motion,
    /// Forward warp: project, splat, resolve.
    Warp,
    /// Background projection into holes.
    BgFill,
    /// Push-pull hole fill.
    Holes,
    /// Window crop (repeat).
    Crop,
    /// GeoMotionGen normalize + reproject + merge.
    Reproject,
    /// GeoMotionGen resolve.
    Resolve,
    /// Shading correction's estimate (GFFE §4.4: what changed and how it
    /// moves), at ingest.
    Shading,
    /// Shading correction applied to the colour the warp moves.
    Shade,
    /// (GPU) packing the generated frame for the host
    /// ([`crate::passes::common::pack`]).
    Pack,
    /// (GPU) reading the generated frame back.
    Readback,
}

impl Pass {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Pass::Upload => "upload",
            Pass::History => "history",
            Pass::Background => "background",
            Pass::Motion => "motion",
            Pass::Warp => "warp",
            Pass::BgFill => "bgfill",
            Pass::Holes => "holes",
            Pass::Crop => "crop",
            Pass::Reproject => "reproject",
            Pass::Resolve => "resolve",
            Pass::Shading => "shading",
            Pass::Shade => "shade",
            Pass::Pack => "pack",
            Pass::Readback => "readback",
        }
    }
}

/// Wall time of one pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassTime {
    /// The pass.
    pub pass: Pass,
    /// How long it took (GPU: submit + wait, only when profiling).
    pub time: Duration,
    /// GPU time between timestamps around the pass, when the profiled
    /// backend uses timestamp queries (hardware adapters).
    pub gpu: Option<Duration>,
}

/// What a backend is asked to do with a rendered frame.
#[derive(Clone, Copy, Debug)]
pub struct IngestPlan {
    /// `C_t`, centre at the origin.
    pub camera: PassCamera,
    /// `C_{t−1}` relative to `C_t`'s centre; `None` restarts the history.
    pub prev: Option<PassCamera>,
    /// Whether the frame's motion vectors point to that previous frame.
    /// After a gap (frames that never arrived) they do not: the history
    /// restarts as without a previous frame (every pixel static, no
    /// trajectory), the background layers still carry over (positions and
    /// cameras need no motion), and interpolation has no pair.
    pub follows: bool,
    /// History length (1 = positions of this frame and the static test
    /// only, 0 = no tracking at all: `repeat` needs none).
    pub k: u32,
    /// Static-test threshold.
    pub epsilon: f32,
    /// Background layout (count 0 = none).
    pub levels: Levels,
    /// Case-2 depth margin.
    pub tolerance: f32,
    /// Whether shading correction's estimate runs (gffe with
    /// `Settings::shading`; it needs the history's static test).
    pub shading: bool,
    /// Whether the generated frames take the colour's planes
    /// (`Settings::warps_catmull_rom`).
    pub planes: bool,
}

impl IngestPlan {
    /// The history's confirmation tolerance: only a plan that collects
    /// background layers confirms static pixels.
    pub fn confirm_tolerance(&self) -> Option<f32> {
        (self.levels.count > 0).then_some(self.tolerance)
    }
}

/// One generated frame to make.
#[derive(Clone, Copy, Debug)]
pub struct Job {
    /// The method.
    pub method: Method,
    /// The generated frame's camera relative to `C_t`'s centre, at the
    /// displayed size.
    pub target: PassCamera,
    /// `C_t` (for background motion vectors).
    pub current: PassCamera,
    /// α.
    pub alpha: f32,
    /// History length in use.
    pub k: u32,
    /// Rendered pixels → displayed pixels of `C_t`.
    pub map: DisplayMap,
    /// The background splat layout over the generated frame.
    pub bg_target: Levels,
    /// The rendered frame's background layout.
    pub bg_source: Levels,
    /// Push-pull levels.
    pub pushpull: u32,
    /// The displayed region of the rendered frame (repeat).
    pub crop: Crop,
    /// How the warp takes a winner's colour.
    pub resample: Resample,
    /// Whether the warp moves the shading-corrected colour (GFFE §4.4).
    pub shading: bool,
}

/// The generation passes, one method per pass, as an executor runs them on
/// the last ingested frame. [`generate`] calls them in each method's order;
/// a new pass is one method here, one implementation per executor, and one
/// line in the plans that use it.
pub trait Executor {
    /// Takes a sanitised rendered frame (the GPU executor uploads it), with
    /// the frame before it when `plan.prev` continues the history.
    fn upload(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<(), FramegenError>;
    /// GFFE Alg. 1: positions, static test, trajectories (`k = 1`: this
    /// frame's positions and the static test only).
    fn history(&mut self, plan: &IngestPlan) -> Result<(), FramegenError>;
    /// GFFE §4.2: the background layers.
    fn background(&mut self, plan: &IngestPlan) -> Result<(), FramegenError>;
    /// GFFE §4.4, estimate: how the shading changed from the previous
    /// frame and how that change moves (none after a gap or restart).
    fn shading(&mut self, plan: &IngestPlan) -> Result<(), FramegenError>;
    /// Ends the ingest: the frame becomes the one generation starts from.
    /// Returns the number of pixels that failed the static test (0 without
    /// a previous frame or tracking).
    fn ingested(&mut self) -> Result<u32, FramegenError>;
    /// Starts a generated frame for `job` (the GPU executor sizes its
    /// buffers).
    fn begin(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// Whether the frame before the last ingested one is kept, at its size
    /// (interpolation's α = 0).
    fn has_previous(&self) -> bool;
    /// The rendered frame's region `crop`, resampled into the output;
    /// `still` zeroes the motion (repeat shows a still frame).
    fn crop(&mut self, crop: &Crop, still: bool) -> Result<(), FramegenError>;
    /// GFFE §4.4, correction: the colour the following warp moves, with
    /// the estimated shading change continued to α.
    fn shade(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// GFFE eq. 1: every pixel's position at α.
    fn motion(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// Forward warp of those positions into the output (project, splat,
    /// resolve, crack closing).
    fn warp(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// The background layers projected into the output's holes.
    fn bgfill(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// Push-pull fill of the output's remaining holes.
    fn pushpull(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// GeoMotionGen normalize + reproject + merge into the output.
    fn reproject(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// GeoMotionGen resolve: colour from the current or previous frame.
    fn resolve(&mut self, job: &Job) -> Result<(), FramegenError>;
    /// Ends the frame and hands the output over (the GPU executor submits,
    /// waits and reads back).
    fn finish(&mut self) -> Result<Output, FramegenError>;
}

/// Every method's ingest plan, written once for both executors: a method
/// that tracks (all but repeat) runs the history and background passes
/// (the background pass collects nothing at `L = 0`).
pub fn ingest<E: Executor + ?Sized>(
    e: &mut E,
    frame: &Arc<Prepared>,
    plan: &IngestPlan,
) -> Result<u32, FramegenError> {
    e.upload(frame, plan)?;
    if plan.k > 0 {
        e.history(plan)?;
        e.background(plan)?;
        if plan.shading {
            e.shading(plan)?;
        }
    }
    e.ingested()
}

/// Every method's generation plan, written once for both executors.
pub fn generate<E: Executor + ?Sized>(e: &mut E, job: &Job) -> Result<Output, FramegenError> {
    passes(e, job)?;
    e.finish()
}

/// The generation plan's passes, up to (not including) the hand-over of
/// the output: [`generate`] then calls [`Executor::finish`], an executor
/// that packs the frame where it made it its own ending.
pub fn passes<E: Executor + ?Sized>(e: &mut E, job: &Job) -> Result<(), FramegenError> {
    e.begin(job)?;
    match job.method {
        Method::Repeat => e.crop(&job.crop, true)?,
        // Without the frame before (first frame, restart, size change)
        // interpolation shows the current frame as it is.
        Method::Interp if !e.has_previous() => {
            let (w, h) = (job.current.width(), job.current.height());
            let whole = Crop {
                source: (w, h),
                origin: glam::Vec2::ZERO,
                extent: glam::Vec2::new(w as f32, h as f32),
                output: (w, h),
            };
            e.crop(&whole, false)?;
        }
        Method::Interp => {
            e.reproject(job)?;
            e.pushpull(job)?;
            e.resolve(job)?;
        }
        Method::Reproject | Method::Gffe => {
            if job.shading {
                e.shade(job)?;
            }
            e.motion(job)?;
            e.warp(job)?;
            if job.bg_source.count > 0 && job.bg_target.count == job.bg_source.count {
                e.bgfill(job)?;
            }
            e.pushpull(job)?;
        }
    }
    Ok(())
}

/// Runs the passes.
pub trait Backend: Send {
    /// Takes a sanitised rendered frame: history tracking and background
    /// collection. Returns the number of dynamic pixels. The frame is
    /// shared, so a backend that keeps it (the CPU reference) copies
    /// nothing.
    fn ingest(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<u32, FramegenError>;
    /// Runs the generation passes for `job` on the last ingested frame.
    fn generate(&mut self, job: &Job) -> Result<Output, FramegenError>;
    /// [`Backend::generate`], packed for the host
    /// ([`crate::passes::common::pack`]), with the `f32` output where the
    /// backend has it on the host anyway. The default packs on the CPU; the
    /// wgpu backend packs on the device and reads back only the packed
    /// frame.
    fn generate_packed(&mut self, job: &Job) -> Result<(Packed, Option<Output>), FramegenError> {
        let out = self.generate(job)?;
        Ok((crate::passes::common::pack::pack(&out), Some(out)))
    }
    /// Makes a generated frame and writes its colour, as
    /// [`Backend::generate_packed`] packs it (linear RGBA `f16`), into
    /// `target` (`Rgba16Float`, the frame's size) on the backend's own
    /// device, where a presenter on that device shows it: nothing is read
    /// back. A backend without a device refuses.
    fn generate_to(&mut self, _job: &Job, _target: &wgpu::Texture) -> Result<(), FramegenError> {
        Err(FramegenError::NotOnDevice(self.name()))
    }
    /// The device the backend runs on (none for the CPU reference).
    fn device(&self) -> Option<&Arc<crate::gpu::GpuContext>> {
        None
    }
    /// Drops all history.
    fn reset(&mut self);
    /// Wall times of the passes of the last `ingest` + `generate`.
    fn timings(&self) -> Vec<PassTime>;
    /// A name for reports ("cpu", or the GPU adapter).
    fn name(&self) -> String;
    /// The state the last ingest left (for parity tests and debugging).
    fn snapshot(&self) -> Result<Option<Snapshot>, FramegenError>;
    /// Whether the following pushes and generations time each pass, where
    /// that costs something (the wgpu backend then submits and waits per
    /// pass); a backend whose per-pass times are free ignores it.
    fn set_profiling(&mut self, _on: bool) {}
    /// Whether [`Backend::timings`] holds per-pass times.
    fn profiling(&self) -> bool {
        true
    }
}

/// What ingesting a rendered frame produced.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// `k` planes of history positions.
    pub positions: Vec<[f32; 4]>,
    /// Track words.
    pub track: Vec<u32>,
    /// Background texels.
    pub background: Vec<crate::passes::gffe::background::Texel>,
    /// The history's `SeenAgain` flags of the previous frame's pixels, 1
    /// where set, as many as the frame has pixels (all 0 without a
    /// previous frame).
    pub seen: Vec<u32>,
}
