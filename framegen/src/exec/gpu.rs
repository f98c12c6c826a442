//! The wgpu executor: the same passes as [`crate::exec::cpu::CpuBackend`],
//! as compute kernels over storage buffers, in the order the plans of
//! [`crate::pipeline`] give. Per-pass wall times (submit +
//! wait; lavapipe's timestamp queries are unreliable) are recorded when
//! profiling is on; otherwise each ingest and each generation is one
//! submission.

use std::sync::Arc;
use std::time::Instant;

use crate::FramegenError;
use crate::gpu::timestamps::{PassClock, Timestamps};
use crate::gpu::{GpuContext, Pool, Rec};
use crate::input::Prepared;
use crate::output::{GpuOutput, Output};
use crate::passes::common::camera::PassCamera;
use crate::passes::common::crop::{Crop, GpuCrop};
use crate::passes::common::levels::Levels;
use crate::passes::common::pack::{self, GpuPack, GpuPacked, Packed};
use crate::passes::common::pushpull::{self, GpuHoles};
use crate::passes::common::splat::GpuSplat;
use crate::passes::common::widen::GpuWiden;
use crate::passes::gffe::background::{GpuBackground, Texel as BgTexel};
use crate::passes::gffe::bgfill::GpuBgFill;
use crate::passes::gffe::history::{GpuHistory, GpuHistoryBuffers};
use crate::passes::gffe::motion::GpuMotion;
use crate::passes::gffe::shading::{self, GpuCurrent, GpuPrevious, GpuShading};
use crate::passes::gffe::warp::{GpuSource, GpuWarp};
use crate::passes::interp::reproject::GpuReproject;
use crate::passes::interp::resolve::{GpuImage, GpuResolve};
use crate::pipeline::{Backend, Executor, IngestPlan, Job, Pass, PassTime, Snapshot};

/// Bytes of each part of the upload's staging buffer for `n` pixels, in
/// the order they are written: `f16` colour, depth, motion.
fn upload_bytes(n: u64) -> [u64; 3] {
    [n * 8, n * 4, n * 8]
}

/// Every kernel, compiled once.
#[derive(Debug)]
struct Kernels {
    history: GpuHistory,
    motion: GpuMotion,
    warp: GpuWarp,
    splat: GpuSplat,
    background: GpuBackground,
    bgfill: GpuBgFill,
    holes: GpuHoles,
    crop: GpuCrop,
    pack: GpuPack,
    widen: GpuWiden,
    interp: GpuReproject,
    resolve: GpuResolve,
    shading: GpuShading,
}

/// One ingested frame on the GPU.
#[derive(Debug)]
struct FrameBuffers {
    camera: PassCamera,
    n: u32,
    k: u32,
    levels: Levels,
    color: wgpu::Buffer,
    depth: wgpu::Buffer,
    motion: wgpu::Buffer,
    positions: wgpu::Buffer,
    track: wgpu::Buffer,
    background: wgpu::Buffer,
    /// Shading correction's `vec2` per pixel and `vec4` per block.
    ratio: wgpu::Buffer,
    flow: wgpu::Buffer,
    /// Whether `ratio` and `flow` hold this frame's estimate.
    has_ratio: bool,
}

impl FrameBuffers {
    fn new(ctx: &GpuContext, n: u32, k: u32, levels: Levels, camera: PassCamera) -> Self {
        let n64 = u64::from(n);
        // Blocks of any w×h = n frame: ⌈w/8⌉·⌈h/8⌉ ≤ n/8 + 1 (the buffers
        // are reused for any frame of n pixels).
        let blocks = n64 / u64::from(shading::BLOCK) + 1;
        Self {
            camera,
            n,
            k,
            levels,
            color: ctx.storage("color", n64 * 16),
            depth: ctx.storage("depth", n64 * 4),
            motion: ctx.storage("motion", n64 * 8),
            positions: ctx.storage("history", n64 * u64::from(k) * 16),
            track: ctx.storage("track", n64 * 4),
            background: ctx.storage(
                "background",
                u64::from(levels.total()) * std::mem::size_of::<BgTexel>() as u64,
            ),
            ratio: ctx.storage("shading ratio", n64 * 8),
            flow: ctx.storage("shading flow", blocks * 16),
            has_ratio: false,
        }
    }

    /// The buffers shading correction reads and writes.
    fn shading(&self) -> GpuCurrent<'_> {
        GpuCurrent {
            color: &self.color,
            depth: &self.depth,
            motion: &self.motion,
            track: &self.track,
            ratio: &self.ratio,
            flow: &self.flow,
            size: (self.camera.width(), self.camera.height()),
        }
    }
}

/// Scratch buffers, grown on demand.
#[derive(Debug, Default)]
struct Scratch {
    next: Option<wgpu::Buffer>,
    candidates: Option<wgpu::Buffer>,
    keys: Option<wgpu::Buffer>,
    winners: Option<wgpu::Buffer>,
    color: Option<wgpu::Buffer>,
    depth: Option<wgpu::Buffer>,
    motion: Option<wgpu::Buffer>,
    mask: Option<wgpu::Buffer>,
    pyramid: Option<wgpu::Buffer>,
    dynamic: Option<wgpu::Buffer>,
    seen: Option<wgpu::Buffer>,
    shaded: Option<wgpu::Buffer>,
    /// The packed colour and source bytes of a generated frame.
    packed_color: Option<wgpu::Buffer>,
    packed_mask: Option<wgpu::Buffer>,
    /// Where a rendered frame is written for the GPU to copy, and its
    /// colour as f16 on the device.
    upload: Option<wgpu::Buffer>,
    uploaded: Option<wgpu::Buffer>,
    /// Where a generated frame is copied for the CPU to read.
    staging: Option<wgpu::Buffer>,
    /// Where an ingest's dynamic-pixel count is copied for the CPU to read.
    count: Option<wgpu::Buffer>,
}

/// The scratch buffer in `slot`, replaced by a larger one when it is
/// smaller than `bytes` (and then the pool's bind groups, which would keep
/// the old one alive, are dropped).
fn ensure<'a>(
    ctx: &GpuContext,
    pool: &Pool,
    slot: &'a mut Option<wgpu::Buffer>,
    label: &str,
    bytes: u64,
) -> &'a wgpu::Buffer {
    let bytes = bytes.max(16);
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = Some(ctx.storage(label, bytes));
        pool.clear_groups();
    }
    slot.as_ref().expect("just allocated")
}

/// Records passes into one submission, or one per pass (waited for and
/// timed) when profiling.
#[derive(Debug, Default)]
struct Recorder {
    profile: bool,
    /// Timestamp queries for profiled passes (hardware adapters).
    timestamps: Option<Timestamps>,
    /// Passes recorded and not yet submitted.
    encoder: Option<wgpu::CommandEncoder>,
    timings: Vec<PassTime>,
    /// Parameter slots and bind groups, reused from frame to frame.
    pool: Pool,
}

impl Recorder {
    fn pass(
        &mut self,
        ctx: &GpuContext,
        pass: Pass,
        f: impl FnOnce(&Rec<'_>, &mut wgpu::CommandEncoder),
    ) -> Result<(), FramegenError> {
        let start = Instant::now();
        let encoder = self
            .encoder
            .get_or_insert_with(|| ctx.device.create_command_encoder(&Default::default()));
        let timestamps = self.timestamps.as_ref().filter(|_| self.profile);
        if let Some(ts) = timestamps {
            ts.begin(encoder);
        }
        f(&Rec::new(ctx, &self.pool), encoder);
        if let Some(ts) = timestamps {
            ts.end(encoder);
        }
        if self.profile {
            self.flush(ctx)?;
            let time = start.elapsed();
            let timestamps = self.timestamps.as_ref();
            let gpu = timestamps.map(|ts| ts.read(ctx)).transpose()?;
            self.timings.push(PassTime { pass, time, gpu });
        }
        Ok(())
    }

    /// Submits what was recorded and waits for it.
    fn flush(&mut self, ctx: &GpuContext) -> Result<(), FramegenError> {
        if let Some(encoder) = self.encoder.take() {
            let index = ctx.queue.submit([encoder.finish()]);
            self.pool.restart();
            ctx.wait_for(index)?;
        }
        Ok(())
    }
}

/// A rendered frame being ingested (between `upload` and `ingested`).
#[derive(Debug)]
struct Ingest {
    buffers: FrameBuffers,
    /// The previous frame with its camera, when the history continues.
    prev: Option<(PassCamera, FrameBuffers)>,
    /// Whether the plan continues the history and tracks (the dynamic
    /// count is read back only then).
    counted: bool,
    /// Whether the frame's motion points to `prev` (no gap between them).
    follows: bool,
    /// The frame's colour as uploaded, `f16` (background collection copies
    /// it into its texels as it is).
    uploaded: wgpu::Buffer,
    keys: wgpu::Buffer,
    winners: wgpu::Buffer,
    candidates: wgpu::Buffer,
    dynamic: wgpu::Buffer,
    /// The history's `SeenAgain` flags (a `u32` per previous pixel), which
    /// background collection reads.
    seen: wgpu::Buffer,
}

/// The wgpu backend.
#[derive(Debug)]
pub struct GpuBackend {
    ctx: Arc<GpuContext>,
    kernels: Kernels,
    current: Option<FrameBuffers>,
    /// The frame before `current` (interpolation's α = 0 when `paired`),
    /// or buffers to reuse.
    spare: Option<FrameBuffers>,
    /// Whether `current`'s motion points to `spare` (no frame between
    /// them went missing).
    paired: bool,
    scratch: Scratch,
    rec: Recorder,
    /// The rendered frame being ingested.
    ingest: Option<Ingest>,
    /// The buffers of the generated frame being made.
    generation: Option<Generation>,
}

/// The buffers one generated frame uses (handles into [`Scratch`]).
#[derive(Debug)]
struct Generation {
    /// Output pixels and size.
    tn: u32,
    size: (u32, u32),
    color: wgpu::Buffer,
    depth: wgpu::Buffer,
    motion: wgpu::Buffer,
    mask: wgpu::Buffer,
    keys: wgpu::Buffer,
    winners: wgpu::Buffer,
    candidates: wgpu::Buffer,
    next: wgpu::Buffer,
    pyramid: wgpu::Buffer,
    layout: Levels,
    /// The shading-corrected colour the warp moves, once `shade` made it.
    shaded: Option<wgpu::Buffer>,
}

impl FrameBuffers {
    /// Positions and track words, as the history pass reads and writes them.
    fn history(&self) -> GpuHistoryBuffers<'_> {
        GpuHistoryBuffers {
            positions: &self.positions,
            track: &self.track,
        }
    }

    /// Colour and depth, as interpolation's resolve reads them.
    fn image(&self) -> GpuImage<'_> {
        GpuImage {
            color: &self.color,
            depth: &self.depth,
        }
    }
}

impl Generation {
    /// The depth-tested splat of `sources` candidates into `slots` slots,
    /// over this frame's candidate, key and winner buffers.
    fn splat(&self, p: &PassInputs<'_>, enc: &mut wgpu::CommandEncoder, sources: u64, slots: u64) {
        let (candidates, keys, winners) = (&self.candidates, &self.keys, &self.winners);
        p.kernels
            .splat
            .encode(p.ctx, enc, (candidates, sources), (keys, winners, slots));
    }

    fn out(&self) -> GpuOutput<'_> {
        GpuOutput {
            color: &self.color,
            depth: &self.depth,
            motion: &self.motion,
            mask: &self.mask,
        }
    }
}

/// What a generation pass records with.
struct PassInputs<'a> {
    ctx: &'a Rec<'a>,
    kernels: &'a Kernels,
    cur: &'a FrameBuffers,
    /// The frame before `cur` at its size (interpolation).
    prev: Option<&'a FrameBuffers>,
    g: &'a Generation,
}

impl GpuBackend {
    /// Compiles every kernel on `ctx`.
    pub fn new(ctx: Arc<GpuContext>) -> Self {
        let c = &ctx;
        let kernels = Kernels {
            history: GpuHistory::new(c),
            motion: GpuMotion::new(c),
            warp: GpuWarp::new(c),
            splat: GpuSplat::new(c),
            background: GpuBackground::new(c),
            bgfill: GpuBgFill::new(c),
            holes: GpuHoles::new(c),
            crop: GpuCrop::new(c),
            pack: GpuPack::new(c),
            widen: GpuWiden::new(c),
            interp: GpuReproject::new(c),
            resolve: GpuResolve::new(c),
            shading: GpuShading::new(c),
        };
        Self {
            ctx,
            kernels,
            current: None,
            spare: None,
            paired: false,
            scratch: Scratch::default(),
            rec: Recorder::default(),
            ingest: None,
            generation: None,
        }
    }

    /// A backend that submits and waits after every pass and records its
    /// wall time, and its GPU time from timestamp queries where the adapter
    /// is real hardware with the features ([`PassClock::preferred`]).
    pub fn profiled(ctx: Arc<GpuContext>) -> Self {
        let clock = PassClock::preferred(&ctx);
        Self::profiled_with(ctx, clock).unwrap_or_else(|(b, _)| b)
    }

    /// A profiled backend on the given clock. Asking for timestamps on a
    /// device without the features returns the wall-time backend with the
    /// reason.
    #[allow(clippy::result_large_err)] // the backend is handed back, not lost
    pub fn profiled_with(
        ctx: Arc<GpuContext>,
        clock: PassClock,
    ) -> Result<Self, (Self, FramegenError)> {
        let mut b = Self::new(ctx);
        b.rec.profile = true;
        if clock == PassClock::Timestamps {
            match Timestamps::new(&b.ctx) {
                Some(ts) => b.rec.timestamps = Some(ts),
                None => {
                    let why = FramegenError::Device(format!(
                        "{} lacks {:?}",
                        b.ctx.adapter_info.name,
                        crate::gpu::timestamps::FEATURES
                    ));
                    return Err((b, why));
                }
            }
        }
        Ok(b)
    }

    /// Runs `f` (a generation) inside an error scope, after checking the
    /// device can hold the generated frame.
    fn generating<T>(
        &mut self,
        job: &Job,
        f: impl FnOnce(&mut Self) -> Result<T, FramegenError>,
    ) -> Result<T, FramegenError> {
        let tn = u64::from(job.target.width()) * u64::from(job.target.height());
        self.ctx
            .require_buffer("the generated frame's colour", tn * 16, true)?;
        let packed = pack::packed_bytes(tn).iter().sum();
        self.ctx
            .require_buffer("the generated frame's read-back", packed, false)?;
        self.scoped("generating a frame", f)
    }

    /// Runs `f` inside an error scope named `what`. After an error the
    /// scratch buffers and the work in flight (the frame being ingested or
    /// generated) are dropped: a buffer the failed work created may be
    /// invalid, and kept for the next frame it would fail that one too.
    /// The frames ingested before stay.
    fn scoped<T>(
        &mut self,
        what: &str,
        f: impl FnOnce(&mut Self) -> Result<T, FramegenError>,
    ) -> Result<T, FramegenError> {
        let scope = self.ctx.scope(what);
        let out = f(self);
        let out = scope.finish().map_err(FramegenError::from).and(out);
        if out.is_err() {
            self.scratch = Scratch::default();
            self.rec.pool.clear_groups();
            self.rec.encoder = None;
            self.ingest = None;
            self.generation = None;
        }
        out
    }

    /// The generated frame being made, at its end.
    fn take_generation(&mut self) -> Result<Generation, FramegenError> {
        self.generation
            .take()
            .ok_or(FramegenError::PassOrder("finish() before begin()"))
    }

    /// Ends the frame packed ([`pack`]): the kernel joins the generation's
    /// submission, and 21 bytes a pixel are read back instead of 32.
    fn finish_packed(&mut self) -> Result<Packed, FramegenError> {
        let g = self.take_generation()?;
        let n = u64::from(g.tn);
        let [color_bytes, depth_bytes, motion_bytes, mask_bytes] = pack::packed_bytes(n);
        let (color, mask) = self.pack(&g)?;
        let parts = [
            (&color, color_bytes),
            (&g.depth, depth_bytes),
            (&g.motion, motion_bytes),
            (&mask, mask_bytes),
        ];
        let (w, h) = g.size;
        self.read_back(&parts, |bytes| pack::unpack(bytes, w, h))
    }

    /// Ends the frame with its packed colour copied into `target` on this
    /// device, in the generation's own submission; nothing is read back.
    fn finish_to(&mut self, target: &wgpu::Texture) -> Result<(), FramegenError> {
        let g = self.take_generation()?;
        let (w, h) = g.size;
        let (tw, th, format) = (target.width(), target.height(), target.format());
        if (tw, th, format) != (w, h, wgpu::TextureFormat::Rgba16Float)
            || !target.usage().contains(wgpu::TextureUsages::COPY_DST)
        {
            return Err(FramegenError::Target(w, h, (tw, th, format)));
        }
        let (color, _) = self.pack(&g)?;
        let ctx = &*self.ctx;
        let encoder = self
            .rec
            .encoder
            .get_or_insert_with(|| ctx.device.create_command_encoder(&Default::default()));
        // A buffer-to-texture copy takes rows 256-byte aligned: the packed
        // rows (8 bytes a pixel, tight) in one copy where they are, one
        // copy a row where not.
        let row = u64::from(w) * 8;
        let rows: Vec<(u32, u32)> = if row % u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) == 0 {
            vec![(0, h)]
        } else {
            (0..h).map(|y| (y, 1)).collect()
        };
        for (y, count) in rows {
            encoder.copy_buffer_to_texture(
                wgpu::TexelCopyBufferInfo {
                    buffer: &color,
                    // One row needs (and may have) no stride.
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: u64::from(y) * row,
                        bytes_per_row: (count > 1).then_some(row as u32),
                        rows_per_image: (count > 1).then_some(count),
                    },
                },
                wgpu::TexelCopyTextureInfo {
                    texture: target,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y, z: 0 },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width: w,
                    height: count,
                    depth_or_array_layers: 1,
                },
            );
        }
        self.rec.flush(ctx)
    }

    /// Records the pack kernel over `g`'s output; its packed colour and
    /// mask buffers (depth and motion are packed in place).
    fn pack(&mut self, g: &Generation) -> Result<(wgpu::Buffer, wgpu::Buffer), FramegenError> {
        let n = u64::from(g.tn);
        let [color_bytes, _, _, mask_bytes] = pack::packed_bytes(n);
        let (ctx, pool) = (&*self.ctx, &self.rec.pool);
        let s = &mut self.scratch;
        let color = ensure(ctx, pool, &mut s.packed_color, "packed color", color_bytes).clone();
        let mask = ensure(ctx, pool, &mut s.packed_mask, "packed mask", mask_bytes).clone();
        let packed = GpuPacked {
            color: &color,
            mask: &mask,
        };
        let kernels = &self.kernels;
        self.rec.pass(ctx, Pass::Pack, |gpu, enc| {
            kernels.pack.encode(gpu, enc, g.tn, g.out(), packed);
        })?;
        Ok((color, mask))
    }

    /// Copies the first bytes of each buffer, one after the other, into
    /// one persistent staging buffer as part of the generation's own
    /// submission (one submit and one wait per generated frame), and hands
    /// the mapped bytes to `read`.
    fn read_back<T>(
        &mut self,
        parts: &[(&wgpu::Buffer, u64)],
        read: impl FnOnce(&[u8]) -> T,
    ) -> Result<T, FramegenError> {
        let total = parts.iter().map(|(_, len)| len).sum::<u64>();
        let ctx = &*self.ctx;
        let s = &mut self.scratch.staging;
        if s.as_ref().is_none_or(|b| b.size() < total) {
            *s = Some(ctx.staging("generated frame read-back", total));
        }
        let staging = s.as_ref().expect("just allocated");
        let start = Instant::now();
        let encoder = self
            .rec
            .encoder
            .get_or_insert_with(|| ctx.device.create_command_encoder(&Default::default()));
        let mut offset = 0;
        for &(buffer, len) in parts {
            encoder.copy_buffer_to_buffer(buffer, 0, staging, offset, len);
            offset += len;
        }
        self.rec.flush(ctx)?;
        let out = ctx.map_read(staging, total, read)?;
        if self.rec.profile {
            self.rec.timings.push(PassTime {
                pass: Pass::Readback,
                time: start.elapsed(),
                gpu: None,
            });
        }
        Ok(out)
    }

    /// Records one generation pass (submitting and timing it when
    /// profiling).
    fn record(
        &mut self,
        pass: Pass,
        f: impl FnOnce(&PassInputs<'_>, &mut wgpu::CommandEncoder),
    ) -> Result<(), FramegenError> {
        let Self {
            ctx,
            kernels,
            current,
            spare,
            generation,
            rec,
            ..
        } = self;
        let cur = current.as_ref().ok_or(FramegenError::NoFrame)?;
        let g = generation
            .as_ref()
            .ok_or(FramegenError::PassOrder("a pass ran before begin()"))?;
        rec.pass(ctx, pass, |gpu, enc| {
            let inputs = PassInputs {
                ctx: gpu,
                kernels,
                cur,
                prev: spare.as_ref().filter(|p| p.n == cur.n),
                g,
            };
            f(&inputs, enc)
        })
    }

    /// Records one ingest pass over the frame being ingested.
    fn record_ingest(
        &mut self,
        pass: Pass,
        f: impl FnOnce(&Rec<'_>, &Kernels, &Ingest, &mut wgpu::CommandEncoder),
    ) -> Result<(), FramegenError> {
        let Self {
            ctx,
            kernels,
            ingest,
            rec,
            ..
        } = self;
        let i = ingest.as_ref().ok_or(FramegenError::PassOrder(
            "an ingest pass ran before upload()",
        ))?;
        rec.pass(ctx, pass, |gpu, enc| f(gpu, kernels, i, enc))
    }
}

impl Backend for GpuBackend {
    fn ingest(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<u32, FramegenError> {
        let n = frame.depth.len() as u64;
        // The largest buffers a frame of this size needs: the k history
        // positions and the colour (vec4<f32> per pixel).
        let what = format!("a {}-pixel frame's history (k = {})", n, plan.k);
        self.ctx
            .require_buffer(&what, n * u64::from(plan.k.max(1)) * 16, true)?;
        self.ctx.require_buffer(
            "the rendered frame's upload",
            upload_bytes(n).iter().sum(),
            false,
        )?;
        self.scoped("ingesting a frame", |b| {
            crate::pipeline::ingest(b, frame, plan)
        })
    }

    fn generate(&mut self, job: &Job) -> Result<Output, FramegenError> {
        self.generating(job, |b| crate::pipeline::generate(b, job))
    }

    fn generate_packed(&mut self, job: &Job) -> Result<(Packed, Option<Output>), FramegenError> {
        self.generating(job, |b| {
            crate::pipeline::passes(b, job)?;
            Ok((b.finish_packed()?, None))
        })
    }

    fn device(&self) -> Option<&Arc<GpuContext>> {
        Some(&self.ctx)
    }

    fn generate_to(&mut self, job: &Job, target: &wgpu::Texture) -> Result<(), FramegenError> {
        self.generating(job, |b| {
            crate::pipeline::passes(b, job)?;
            b.finish_to(target)
        })
    }

    fn reset(&mut self) {
        if let Some(b) = self.current.take() {
            self.spare = Some(b);
        }
    }

    fn timings(&self) -> Vec<PassTime> {
        self.rec.timings.clone()
    }

    fn snapshot(&self) -> Result<Option<Snapshot>, FramegenError> {
        let Some(c) = &self.current else {
            return Ok(None);
        };
        let n = c.n as usize;
        Ok(Some(Snapshot {
            positions: bytemuck::cast_slice::<f32, [f32; 4]>(
                &self
                    .ctx
                    .read_pod::<f32>(&c.positions, n * c.k as usize * 4)?,
            )
            .to_vec(),
            track: if c.k == 0 {
                Vec::new()
            } else {
                self.ctx.read_pod(&c.track, n)?
            },
            background: self
                .ctx
                .read_pod(&c.background, c.levels.total() as usize)?,
            seen: match (&self.scratch.seen, c.k) {
                (Some(seen), 1..) => self.ctx.read_pod(seen, n)?,
                _ => Vec::new(),
            },
        }))
    }

    fn set_profiling(&mut self, on: bool) {
        self.rec.profile = on;
    }

    fn profiling(&self) -> bool {
        self.rec.profile
    }

    fn name(&self) -> String {
        format!(
            "wgpu {} ({:?})",
            self.ctx.adapter_info.name, self.ctx.adapter_info.backend
        )
    }
}

impl Executor for GpuBackend {
    fn upload(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<(), FramegenError> {
        self.rec.timings.clear();
        self.rec.encoder = None;
        let ctx = &*self.ctx;
        let n = frame.depth.len() as u32;
        let start = Instant::now();
        let mut buffers = match self.spare.take() {
            Some(b) if b.n == n && b.k == plan.k && b.levels == plan.levels => b,
            // k = 0 (repeat) tracks nothing; the buffers keep a valid size.
            _ => {
                // The groups of the buffers replaced would keep them alive.
                self.rec.pool.clear_groups();
                FrameBuffers::new(ctx, n, plan.k, plan.levels, plan.camera)
            }
        };
        buffers.camera = plan.camera;
        buffers.has_ratio = false;
        // Colour crosses as the f16 it arrived in and is widened on the
        // device (`widen`).
        // The three buffers are written on all cores into one staging
        // buffer kept from frame to frame, and copied from there.
        let n64 = u64::from(n);
        let [color_bytes, depth_bytes, motion_bytes] = upload_bytes(n64);
        let total = color_bytes + depth_bytes + motion_bytes;
        let s = &mut self.scratch;
        if s.upload.as_ref().is_none_or(|b| b.size() < total) {
            s.upload = Some(ctx.upload_staging("rendered frame upload", total));
        }
        let staging = s.upload.as_ref().expect("just allocated");
        ctx.map_write(staging, total, |view| {
            let (color, rest) = view.split_at(color_bytes as usize);
            let (depth, motion) = rest.split_at(depth_bytes as usize);
            crate::gpu::par_write(bytemuck::cast_slice(&frame.color), color);
            crate::gpu::par_write(bytemuck::cast_slice(&frame.depth), depth);
            crate::gpu::par_write(bytemuck::cast_slice(&frame.motion), motion);
        })?;
        let uploaded = ensure(
            ctx,
            &self.rec.pool,
            &mut s.uploaded,
            "uploaded color",
            color_bytes,
        )
        .clone();
        let encoder = self
            .rec
            .encoder
            .get_or_insert_with(|| ctx.device.create_command_encoder(&Default::default()));
        let staging = s.upload.as_ref().expect("allocated above");
        encoder.copy_buffer_to_buffer(staging, 0, &uploaded, 0, color_bytes);
        encoder.copy_buffer_to_buffer(staging, color_bytes, &buffers.depth, 0, depth_bytes);
        let offset = color_bytes + depth_bytes;
        encoder.copy_buffer_to_buffer(staging, offset, &buffers.motion, 0, motion_bytes);
        let rec = Rec::new(ctx, &self.rec.pool);
        self.kernels
            .widen
            .encode(&rec, encoder, n, &uploaded, &buffers.color);
        if self.rec.profile {
            self.rec.flush(ctx)?;
            self.rec.timings.push(PassTime {
                pass: Pass::Upload,
                time: start.elapsed(),
                gpu: None,
            });
        }
        let prev = match plan.prev {
            Some(camera) => self.current.take().map(|b| (camera, b)),
            None => None,
        };
        let (s, pool) = (&mut self.scratch, &self.rec.pool);
        let slots = u64::from(plan.levels.total().max(n)) * 4;
        let level0 = u64::from(prev.as_ref().map_or(0, |(_, p)| p.levels.len(0)).max(n));
        let sources = level0 * 8;
        self.ingest = Some(Ingest {
            buffers,
            prev,
            counted: plan.prev.is_some() && plan.follows && plan.k > 0,
            follows: plan.follows,
            uploaded,
            keys: ensure(ctx, pool, &mut s.keys, "keys", slots).clone(),
            winners: ensure(ctx, pool, &mut s.winners, "winners", slots).clone(),
            candidates: ensure(ctx, pool, &mut s.candidates, "candidates", sources).clone(),
            dynamic: ensure(ctx, pool, &mut s.dynamic, "dynamic count", 16).clone(),
            seen: ensure(ctx, pool, &mut s.seen, "seen again", level0.max(1) * 4).clone(),
        });
        Ok(())
    }

    fn history(&mut self, plan: &IngestPlan) -> Result<(), FramegenError> {
        let plan = *plan;
        self.record_ingest(Pass::History, |ctx, k, i, enc| {
            enc.clear_buffer(&i.dynamic, 0, None);
            // After a gap the motion does not reach the previous frame: the
            // history restarts.
            let prev = i.prev.as_ref().filter(|(_, p)| p.k == plan.k && i.follows);
            let b = &i.buffers;
            k.history.encode(
                ctx,
                enc,
                (&plan.camera, &b.depth, &b.motion),
                prev.map(|(cam, p)| (cam, p.history(), &p.depth)),
                (b.history(), &i.dynamic, &i.seen),
                (plan.k, plan.epsilon, plan.confirm_tolerance()),
            );
        })
    }

    fn background(&mut self, plan: &IngestPlan) -> Result<(), FramegenError> {
        let plan = *plan;
        self.record_ingest(Pass::Background, |ctx, k, i, enc| {
            let b = &i.buffers;
            let scratch = (&i.keys, &i.winners, &i.candidates);
            k.background.encode(
                ctx,
                enc,
                (&plan.camera, b.history(), &i.uploaded),
                (plan.levels, plan.tolerance),
                i.prev
                    .as_ref()
                    .map(|(cam, p)| (cam, p.levels, &p.background, &i.seen)),
                (&b.background, &k.splat, scratch),
            );
        })
    }

    fn shading(&mut self, _plan: &IngestPlan) -> Result<(), FramegenError> {
        self.record_ingest(Pass::Shading, |ctx, k, i, enc| {
            let b = &i.buffers;
            // Only a frame whose motion reaches the previous one, at its
            // size, has a change to measure; otherwise the planes clear.
            let prev = i
                .prev
                .as_ref()
                .filter(|(_, p)| i.follows && p.n == b.n)
                .map(|(_, p)| GpuPrevious {
                    color: &p.color,
                    depth: &p.depth,
                    ratio: &p.ratio,
                    has_ratio: p.has_ratio,
                });
            k.shading.encode_estimate(ctx, enc, b.shading(), prev);
        })?;
        if let Some(i) = self.ingest.as_mut() {
            let n = i.buffers.n;
            i.buffers.has_ratio = i.follows && i.prev.as_ref().is_some_and(|(_, p)| p.n == n);
        }
        Ok(())
    }

    fn ingested(&mut self) -> Result<u32, FramegenError> {
        let i = self
            .ingest
            .take()
            .ok_or(FramegenError::PassOrder("ingested() before upload()"))?;
        let ctx = &*self.ctx;
        // The count's copy joins the ingest's submission.
        let staging = i.counted.then(|| {
            let s = self
                .scratch
                .count
                .get_or_insert_with(|| ctx.staging("dynamic count", 4));
            let encoder = self
                .rec
                .encoder
                .get_or_insert_with(|| ctx.device.create_command_encoder(&Default::default()));
            encoder.copy_buffer_to_buffer(&i.dynamic, 0, s, 0, 4);
            s.clone()
        });
        self.rec.flush(ctx)?;
        let count = match staging {
            Some(s) => ctx.map_read(&s, 4, |b| u32::from_ne_bytes([b[0], b[1], b[2], b[3]]))?,
            None => 0,
        };
        self.spare = i.prev.map(|(_, b)| b);
        self.paired = i.follows;
        self.current = Some(i.buffers);
        Ok(count)
    }

    fn begin(&mut self, job: &Job) -> Result<(), FramegenError> {
        let ctx = &*self.ctx;
        self.rec.timings.retain(|p| {
            matches!(
                p.pass,
                Pass::Upload | Pass::History | Pass::Background | Pass::Shading
            )
        });
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        let (tw, th) = (job.target.width(), job.target.height());
        let tn = tw * th;
        let (s, pool) = (&mut self.scratch, &self.rec.pool);
        let slots = tn.max(job.bg_target.total());
        let layout = pushpull::layout(tw, th, job.pushpull);
        let pyramid_bytes = GpuHoles::pyramid_bytes(layout);
        let sources = u64::from(cur.n.max(cur.levels.total()));
        self.generation = Some(Generation {
            tn,
            size: (tw, th),
            color: ensure(ctx, pool, &mut s.color, "out color", u64::from(tn) * 16).clone(),
            depth: ensure(ctx, pool, &mut s.depth, "out depth", u64::from(tn) * 4).clone(),
            motion: ensure(ctx, pool, &mut s.motion, "out motion", u64::from(tn) * 8).clone(),
            mask: ensure(ctx, pool, &mut s.mask, "out mask", u64::from(tn) * 4).clone(),
            keys: ensure(ctx, pool, &mut s.keys, "keys", u64::from(slots) * 4).clone(),
            winners: ensure(ctx, pool, &mut s.winners, "winners", u64::from(slots) * 4).clone(),
            candidates: ensure(ctx, pool, &mut s.candidates, "candidates", sources * 8).clone(),
            next: ensure(
                ctx,
                pool,
                &mut s.next,
                "next positions",
                u64::from(cur.n) * 16,
            )
            .clone(),
            pyramid: ensure(ctx, pool, &mut s.pyramid, "pyramid", pyramid_bytes).clone(),
            layout,
            shaded: None,
        });
        self.rec.encoder = None;
        Ok(())
    }

    fn has_previous(&self) -> bool {
        self.paired && matches!((&self.current, &self.spare), (Some(c), Some(p)) if c.n == p.n)
    }

    fn crop(&mut self, crop: &Crop, still: bool) -> Result<(), FramegenError> {
        let crop = *crop;
        self.record(Pass::Crop, |p, enc| {
            let c = p.cur;
            let out = p.g.out();
            p.kernels
                .crop
                .encode(p.ctx, enc, &crop, (&c.color, &c.depth, &c.motion), out);
            if still {
                enc.clear_buffer(&p.g.motion, 0, Some(u64::from(p.g.tn) * 8));
            }
        })
    }

    fn shade(&mut self, job: &Job) -> Result<(), FramegenError> {
        let n = match &self.current {
            // No estimate (first frame, gap): the rendered colour as it is.
            Some(c) if !c.has_ratio => return Ok(()),
            Some(c) => c.n,
            None => return Err(FramegenError::NoFrame),
        };
        let ctx = &*self.ctx;
        let (s, pool) = (&mut self.scratch, &self.rec.pool);
        let shaded = ensure(ctx, pool, &mut s.shaded, "shaded color", u64::from(n) * 16).clone();
        let g = self
            .generation
            .as_mut()
            .ok_or(FramegenError::PassOrder("a pass ran before begin()"))?;
        g.shaded = Some(shaded.clone());
        let alpha = job.alpha;
        self.record(Pass::Shade, |p, enc| {
            p.kernels
                .shading
                .encode_correct(p.ctx, enc, p.cur.shading(), alpha, &shaded);
        })
    }

    fn motion(&mut self, job: &Job) -> Result<(), FramegenError> {
        let alpha = job.alpha;
        self.record(Pass::Motion, |p, enc| {
            let c = p.cur;
            (p.kernels.motion).encode(p.ctx, enc, c.history(), &p.g.next, (c.n, c.k, alpha));
        })
    }

    fn warp(&mut self, job: &Job) -> Result<(), FramegenError> {
        let job = *job;
        self.record(Pass::Warp, |p, enc| {
            let (c, g, k) = (p.cur, p.g, p.kernels);
            enc.clear_buffer(&g.mask, 0, Some(u64::from(g.tn) * 4));
            k.warp
                .encode_project(p.ctx, enc, &job.target, &g.next, c.n, &g.candidates);
            g.splat(p, enc, u64::from(c.n), u64::from(g.tn));
            let source = GpuSource {
                color: g.shaded.as_ref().unwrap_or(&c.color),
                depth: &c.depth,
                next: &g.next,
                size: (c.camera.width(), c.camera.height()),
            };
            k.warp.encode_resolve(
                p.ctx,
                enc,
                (&job.target, job.map, job.resample),
                source,
                (&g.keys, &g.winners),
                g.out(),
            );
        })
    }

    fn bgfill(&mut self, job: &Job) -> Result<(), FramegenError> {
        let job = *job;
        self.record(Pass::BgFill, |p, enc| {
            let (c, g, k) = (p.cur, p.g, p.kernels);
            // The warp ran from this frame's history, so the level-0
            // fragments its static pixels seeded are skipped
            // (`background::seeds`).
            let levels = (c.levels, job.bg_target);
            let params = GpuBgFill::params(p.ctx, &job.target, &c.camera, job.map, levels, c.n);
            let texels = c.levels.total();
            k.bgfill.encode_project(
                p.ctx,
                enc,
                &params,
                (&c.background, texels),
                &g.candidates,
                (&c.track, &c.positions),
            );
            g.splat(p, enc, u64::from(texels), u64::from(job.bg_target.total()));
            k.bgfill.encode_resolve(
                p.ctx,
                enc,
                (&params, &c.background),
                (&g.keys, &g.winners),
                (g.out(), g.tn),
            );
        })
    }

    fn pushpull(&mut self, _job: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Holes, |p, enc| {
            let g = p.g;
            p.kernels
                .holes
                .encode(p.ctx, enc, g.out(), &g.pyramid, g.layout);
        })
    }

    fn reproject(&mut self, job: &Job) -> Result<(), FramegenError> {
        let alpha = job.alpha;
        self.record(Pass::Reproject, |p, enc| {
            let (c, g, k) = (p.cur, p.g, p.kernels);
            let size = (c.camera.width(), c.camera.height());
            k.interp.encode_project(
                p.ctx,
                enc,
                (size, alpha),
                (&c.motion, &c.depth),
                (&g.next, &g.candidates),
            );
            g.splat(p, enc, u64::from(c.n), u64::from(c.n));
            let image = (size, &c.depth);
            k.interp
                .encode_merge(p.ctx, enc, image, (&g.winners, &g.next), g.out());
        })
    }

    fn resolve(&mut self, job: &Job) -> Result<(), FramegenError> {
        if !self.has_previous() {
            return Err(FramegenError::PassOrder(
                "interpolation without a previous frame",
            ));
        }
        let (alpha, filter) = (job.alpha, job.resample);
        self.record(Pass::Resolve, |p, enc| {
            let c = p.cur;
            let Some(prev) = p.prev else { return };
            let size = (c.camera.width(), c.camera.height());
            p.kernels.resolve.encode(
                p.ctx,
                enc,
                (size, alpha, filter),
                (c.image(), prev.image()),
                p.g.out(),
            );
        })
    }

    fn finish(&mut self) -> Result<Output, FramegenError> {
        let g = self.take_generation()?;
        let n = u64::from(g.tn);
        let parts = [
            (&g.color, n * 16),
            (&g.depth, n * 4),
            (&g.motion, n * 8),
            (&g.mask, n * 4),
        ];
        let (n, (w, h)) = (g.tn as usize, g.size);
        self.read_back(&parts, |bytes| {
            let (color, rest) = bytes.split_at(n * 16);
            let (depth, rest) = rest.split_at(n * 4);
            let (motion, mask) = rest.split_at(n * 8);
            Output {
                width: w,
                height: h,
                color: bytemuck::pod_collect_to_vec(color),
                depth: bytemuck::pod_collect_to_vec(depth),
                motion: bytemuck::pod_collect_to_vec(motion),
                mask: bytemuck::pod_collect_to_vec(&mask[..n * 4]),
            }
        })
    }
}
