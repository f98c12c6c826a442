//! The presentation loop (DESIGN §8): frames from a [`Session`] go into a
//! [`FrameGenerator`], the sans-IO [`Scheduler`] decides every vsync what
//! the display shows, and [`Accounting`] records every displayed frame.
//!
//! This is the headless presenter: a virtual vsync clock on the wall clock
//! at the display rate. "Present" is the first vsync at or after the slot's
//! image was finished (submitted); each slot is decided at its vsync and
//! shown at the next one, as a swap chain with one frame of queue would.
//! An image finished after that vsync is shown at the first one after it:
//! the vsync it missed counts as missed, and the slot of the vsync it took
//! is not made (each vsync shows at most one image).
//! Presented frames can be written as display-encoded PNGs and as a dump,
//! on a thread of their own ([`crate::frame_writer`]).
//!
//! Times are from the moment the first frame was pushed (kernels compiled,
//! stream running). Per rendered frame: received (its last byte taken from
//! the connection), ready (decoded), ingested (pushed into the generator:
//! upload, history tracking, background collection) and present; the
//! ingest and any generation on the way to showing it count as added
//! latency (`framegen::accounting`). The loop takes frames at vsyncs; when
//! several arrived within one vsync all are pushed in stream order (each
//! frame's motion points to the one before it) and only the newest is
//! shown; the others are superseded.
//!
//! With late input the viewer's pose is taken as late as a slot allows and
//! an image that missed its vsync is replaced when a fresh one fits before
//! the next ([`crate::latch`]).

use std::borrow::Cow;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use framegen::accounting::{Accounting, InputShown, Percentiles, Record, Summary};
use framegen::schedule::{FrameReady, Policy, ScheduleConfig, Scheduler, Slot, SlotKind};
use framegen::{CameraSource, FrameGenerator, GpuContext, Method, PushOutcome, Settings};
use protocol::wire::{Input, InputEcho};
use protocol::{Frame, FrameMeta, Pose};
use serde::Serialize;

use crate::frame_writer::{DumpSink, FrameSink, FrameWriter, PngSink};
use crate::latch::LateLatch;
use crate::reconnect::{Stream, StreamStats};
use crate::viewer::{InputTrack, LiveViewer, angle_deg};

/// What the presenter does.
#[derive(Clone, Debug)]
pub struct PresentConfig {
    /// Frame generation method.
    pub method: Method,
    /// Generated frames per rendered frame (display = (n+1) × render rate).
    pub n: u32,
    /// How long to present.
    pub duration: Duration,
    /// Largest α extrapolated before holding the last frame.
    pub max_alpha: f64,
    /// Write every presented frame as a PNG here.
    pub png_dir: Option<PathBuf>,
    /// Run the passes on the CPU reference instead of wgpu.
    pub cpu: bool,
    /// Send every presented frame (and the overlay text) to a window.
    pub window: Option<crate::window::Sink>,
    /// Display refresh rate (Hz); `None`: (n + 1) × the render rate.
    pub refresh_hz: Option<f64>,
    /// Write every presented frame into a dump here.
    pub dump_dir: Option<PathBuf>,
    /// Shading correction (gffe; `framegen::Settings::shading`) where the
    /// stream's effects call for it.
    pub shading: bool,
    /// Every stage of the method, whatever the stream's effects (the
    /// welcome's effects are ignored: `framegen::Settings::effects` stays
    /// unknown).
    pub every_stage: bool,
    /// An interactive run's viewer: the client sends its input every
    /// vsync (issue 20).
    pub viewer: Option<ViewerConfig>,
    /// The window's device and display transform, where the generator
    /// runs on that device: generated frames are then handed to the
    /// window there, never read back (unless a dump or PNGs need them).
    pub shared: Option<crate::window::Shared>,
}

/// The viewer of an interactive run (issue 20).
#[derive(Clone, Debug)]
pub struct ViewerConfig {
    /// What moves the viewer's camera (from the first frame's camera).
    pub source: ViewerSource,
    /// Late input: every displayed frame is warped to the newest viewer
    /// pose (generated frames take it instead of eq. 2, rendered ones are
    /// re-projected to it); otherwise the display shows the camera the
    /// server rendered from the input it had (and eq. 2 between).
    pub late: bool,
}

/// What moves the viewer's camera.
#[derive(Clone, Debug)]
pub enum ViewerSource {
    /// A scripted track (headless runs, tests).
    Track(InputTrack),
    /// The window's mouse and keys.
    Live(LiveViewer),
}

impl ViewerSource {
    /// The viewer's camera at `now` (`since` after the presenter's start)
    /// from `start`, and the buttons held.
    fn input(&self, start: &Pose, since: Duration, now: Instant) -> (Pose, u32) {
        match self {
            ViewerSource::Track(track) => (track.pose_at(start, since.as_secs_f64()), 0),
            ViewerSource::Live(live) => (live.pose_at(now).unwrap_or(*start), live.buttons()),
        }
    }
}

impl ViewerConfig {
    /// The mode's name in reports.
    pub fn mode(viewer: Option<&Self>) -> &'static str {
        match viewer {
            None => "scripted server camera",
            Some(v) if v.late => "late input",
            Some(_) => "server camera from input",
        }
    }
}

impl Default for PresentConfig {
    fn default() -> Self {
        Self {
            method: Method::Gffe,
            n: 1,
            duration: Duration::from_secs(5),
            max_alpha: 3.0,
            png_dir: None,
            cpu: false,
            window: None,
            refresh_hz: None,
            dump_dir: None,
            shading: true,
            every_stage: false,
            viewer: None,
            shared: None,
        }
    }
}

/// Rendered frames kept for rendered slots and interpolation pairs.
const KEPT: usize = 6;

/// How long to wait for a session's first frame.
pub const FIRST_FRAME_TIMEOUT: Duration = Duration::from_secs(60);

/// The result of a presentation run.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Method name.
    pub method: String,
    /// Backend that generated frames.
    pub backend: String,
    /// Render and display rates.
    pub render_fps: f64,
    /// Display rate.
    pub display_fps: f64,
    /// Seconds presented.
    pub seconds: f64,
    /// Frames received from the session.
    pub received: u64,
    /// Vsyncs whose slot could not be prepared in time (the loop was
    /// behind), skipped.
    pub missed_vsyncs: u64,
    /// Late input: images finished after their vsync and replaced by a
    /// fresh one for the next (`crate::latch`); each vsync is also counted
    /// in `missed_vsyncs`.
    pub replaced_late: u64,
    /// Generation time per generated frame, ms.
    pub generation_ms: Percentiles,
    /// Push (upload + history + background) time per rendered frame, ms.
    pub ingest_ms: Percentiles,
    /// Decode time per received frame (its codecs, off the async
    /// runtime: last byte received → frame ready), ms.
    pub decode_ms: Percentiles,
    /// Pushes that restarted the generator's history (the first frame,
    /// cuts, size changes; `framegen::PushOutcome::Restarted`).
    pub restarts: u64,
    /// Rendered frames extrapolation left out of the history to keep pace
    /// with the stream (see `Pusher::behind`).
    pub ingest_skipped: u64,
    /// Latency summary.
    pub summary: Summary,
    /// Reconnections and outages.
    pub outages: StreamStats,
    /// Every displayed frame.
    pub records: Vec<Record>,
    /// The passes of the last generated frame whose rendered frame followed
    /// the one before it (no gap; the last generated frame if none did),
    /// that rendered frame's ingest included, in the order they ran, where
    /// the backend times them (the CPU reference always, wgpu when
    /// profiling; otherwise empty).
    pub passes: Vec<String>,
    /// The stages the generator was planned to run, from the method and
    /// the stream's effects (in words in the JSON).
    #[serde(serialize_with = "in_words")]
    pub plan: framegen::pipeline::plan::Plan,
    /// The viewer's camera against what was shown (issue 20).
    pub viewer: ViewerReport,
    /// Generated frames handed to the window on the device that made
    /// them, never read back (issue 15 §2; [`PresentConfig::shared`]).
    pub on_device: u64,
}

impl Report {
    /// A line for a run the stream held back ([`stream_shortfall`]), or
    /// `None` where it kept its rate.
    pub fn stream_shortfall(&self) -> Option<String> {
        stream_shortfall(
            self.received,
            self.render_fps * self.seconds,
            self.summary.repeated + self.summary.beyond_one,
            self.summary.drops.network,
        )
    }
}

/// Share of a run's frames a stream may fail to deliver before the report
/// says so.
pub const SHORTFALL: f64 = 0.1;

/// Says when the stream, not the presenter, set a run's pace: it delivered
/// fewer than `1 − SHORTFALL` of the `expected` frames its rate promised
/// (`received` of them; `never` never arrived: the source fell behind or
/// the link lost them). Vsyncs missed count only slots whose image was
/// late; a slot that held a frame or extrapolated past α = 1 (`stood_in`)
/// was on time, but stands for a frame that did not come. On two cores
/// with the in-process server rendering 640×360 on lavapipe, `repeat`
/// received 154 of 300 frames and interpolation held 452 of 599 slots
/// with no vsync missed (README, "What the end-to-end targets need").
pub fn stream_shortfall(
    received: u64,
    expected: f64,
    stood_in: usize,
    never: u64,
) -> Option<String> {
    if expected.is_nan() || expected < 1.0 || received as f64 >= (1.0 - SHORTFALL) * expected {
        return None;
    }
    let expected = expected.round() as u64;
    Some(format!(
        "the stream delivered {received} of {expected} frames ({:.0} %; {never} never arrived): \
         its source or link set this run's pace, not the generator; {stood_in} slots held a \
         frame or extrapolated past α = 1 in place of frames that did not come",
        100.0 * received as f64 / expected as f64
    ))
}

/// How a run's displayed camera followed the viewer (issue 20).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ViewerReport {
    /// Where the displayed camera came from ([`ViewerConfig::mode`]).
    pub mode: String,
    /// Viewer inputs sent, one a vsync.
    pub inputs: Inputs,
    /// With a scripted viewer: the angle between each displayed frame's
    /// camera and the viewer's at its present time, degrees (record
    /// order).
    pub view_error_deg: Vec<f64>,
    /// How far a scripted viewer turns in one display interval at most,
    /// degrees.
    pub vsync_turn_deg: Option<f64>,
    /// How far the viewer's last input had turned from the first frame's
    /// camera, degrees, and moved from it, metres.
    pub turned_deg: f64,
    /// See [`ViewerReport::turned_deg`].
    pub moved_m: f64,
}

impl ViewerReport {
    /// The share of displayed frames whose camera was within one display
    /// interval's turn of the viewer's at present (none without a viewer).
    pub fn within_vsync_turn(&self) -> Option<f64> {
        let bound = self.vsync_turn_deg? + 1e-6;
        let n = self.view_error_deg.len();
        (n > 0)
            .then(|| self.view_error_deg.iter().filter(|&&e| e <= bound).count() as f64 / n as f64)
    }
}

/// Serialises a value as its `Display` text.
fn in_words<S: serde::Serializer>(value: &impl std::fmt::Display, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(value)
}

/// Presents `session` headless for `config.duration`.
pub async fn run_headless(
    session: &mut Stream,
    config: &PresentConfig,
    gpu: Option<Arc<GpuContext>>,
) -> anyhow::Result<Report> {
    let fps = session.welcome.fps;
    let policy = config.method.descriptor().policy;
    let late = config.viewer.as_ref().is_some_and(|v| v.late);
    anyhow::ensure!(
        !late || (policy == Policy::Extrapolate && config.method != Method::Repeat),
        "late input warps every frame to the newest pose: it needs an extrapolating method (gffe or reproject), not {}",
        config.method.name()
    );
    let base = match config.refresh_hz {
        Some(hz) if hz.is_finite() && hz > 0.0 => ScheduleConfig::refresh(policy, fps, hz),
        _ => ScheduleConfig::multiple(policy, fps, config.n),
    };
    let schedule = ScheduleConfig {
        max_alpha: config.max_alpha,
        ..base
    };
    // The display keeps the session's size: a widened window changes the
    // rendered size (keep-density) or the displayed region's (keep-size)
    // from frame to frame, never what is shown.
    let display = session.welcome.size;
    let settings = Settings {
        n: config.n,
        max_alpha: config.max_alpha.max(1.0),
        display_size: Some((display.width, display.height)),
        shading: config.shading,
        effects: if config.every_stage {
            protocol::Effects::UNKNOWN
        } else {
            session.welcome.effects
        },
        ..Settings::for_method(config.method)
    };
    let plan = settings.plan();
    tracing::info!("generation plan: {plan}");
    let mut generator = match (&gpu, config.cpu) {
        (Some(ctx), false) => FrameGenerator::gpu(settings, ctx.clone())?,
        _ => FrameGenerator::cpu(settings)?,
    };
    let display_fps = 1.0 / schedule.display_interval.as_secs_f64();
    let mut sinks: Vec<Box<dyn FrameSink>> = Vec::new();
    if let Some(dir) = &config.dump_dir {
        sinks.push(Box::new(DumpSink(protocol::dump::DumpWriter::create(
            dir,
            protocol::dump::Manifest::new(
                display_fps,
                session.welcome.size,
                format!("client presented frames ({})", config.method),
            )
            .with_effects(session.welcome.effects),
        )?)));
    }
    if let Some(dir) = &config.png_dir {
        sinks.push(Box::new(PngSink::create(dir)?));
    }
    let mut writer = if sinks.is_empty() {
        None
    } else {
        let capacity = FrameWriter::capacity_for(session.welcome.size);
        Some(FrameWriter::start(sinks, capacity, "presentation")?)
    };
    // Generated frames stay on the device where the window shares the
    // generator's and nothing on the host reads them.
    let mut on_device = config
        .shared
        .clone()
        .filter(|s| {
            config.window.is_some()
                && writer.is_none()
                && generator.device().is_some_and(|d| Arc::ptr_eq(d, &s.ctx))
        })
        .map(DeviceFrames::new);
    if on_device.is_some() {
        tracing::info!("generated frames stay on the device the window shows them from");
    }
    let mut scheduler = Scheduler::new(schedule);
    // A slot is prepared after its vsync and shown at the next one at the
    // earliest: a queue of one display interval, for rendered frames shown
    // directly as for the rest.
    let mut accounting = Accounting::new(schedule, Duration::ZERO, schedule.display_interval);
    let di = schedule.display_interval;
    // The clock starts when the first frame is in: waiting for the stream to
    // begin and compiling the GPU kernels (first push and generation) are
    // not presentation.
    let first = tokio::time::timeout(FIRST_FRAME_TIMEOUT, session.frames.recv())
        .await
        .map_err(|_| anyhow::anyhow!("no frame within {FIRST_FRAME_TIMEOUT:?}"))?
        .ok_or_else(|| anyhow::anyhow!("the session ended before its first frame"))?
        .frame;
    let mut first_outcome = PushOutcome::Duplicate;
    tokio::task::block_in_place(|| -> anyhow::Result<()> {
        first_outcome = generator.push_shared(&first)?;
        generator.generate(0.5)?;
        Ok(())
    })?;
    let start = Instant::now();
    let clock = || start.elapsed();
    scheduler.frame_ready(FrameReady {
        id: first.meta.index,
        sim_time: first.meta.time,
        host_processing: first.meta.host_processing,
        received_at: Duration::ZERO,
        ready_at: Duration::ZERO,
    });
    // Rendered frames that may still be shown (the newest few).
    let lazy = policy == Policy::Interpolate;
    let mut pusher = Pusher {
        start,
        last: Some(first.meta.index),
        ingest_ms: Vec::new(),
        ingested: VecDeque::from([(first.meta.index, Duration::ZERO)]),
        restarts: u64::from(matches!(first_outcome, PushOutcome::Restarted { .. })),
        followed: VecDeque::new(),
        keep_pace: (policy == Policy::Extrapolate)
            .then_some(schedule.render_interval.as_secs_f64() * 1e3),
        skipped: 0,
    };
    let start_pose = first.meta.camera.pose;
    if let Some(ViewerSource::Live(live)) = config.viewer.as_ref().map(|v| &v.source) {
        live.begin(start_pose, start);
    }
    let mut kept: VecDeque<Arc<Frame>> = VecDeque::from([first]);
    // The echo of each kept frame's input (interactive streams).
    let mut echoes: VecDeque<(u64, InputEcho)> = VecDeque::new();
    let mut inputs = Inputs::default();
    let mut view_error_deg = Vec::new();
    let mut generation = Vec::new();
    let mut decode_ms = Vec::new();
    // The passes of each generated frame (ingest and generation), and of
    // the last one generated from a frame that followed its predecessor
    // (after a gap the stages that compare with the frame before have
    // nothing to do), or of the last one while there is none such.
    let mut passes = Vec::new();
    let mut shown_passes = Vec::new();
    let (mut received, mut missed) = (1u64, 0u64);
    // Late input: when to take the pose, and late images replaced.
    let mut latch = LateLatch::new(di);
    let mut replaced = 0u64;
    let mut k: u64 = 0;
    let last = (config.duration.as_secs_f64() / di.as_secs_f64()).floor() as u64;
    // Whether the stream may still deliver frames.
    let mut open = true;
    loop {
        if k > last {
            break;
        }
        let vsync = di * k as u32;
        let due = tokio::time::Instant::from_std(start + vsync);
        // Interpolation takes frames in as they arrive, and ingests the
        // one the coming slots go toward at once (or, ready before its
        // predecessor was shown, right after that): the slot between then
        // has only its generation to do.
        while lazy && open {
            tokio::select! {
                biased;
                _ = tokio::time::sleep_until(due) => break,
                a = session.frames.recv() => {
                    let Some(a) = a else {
                        open = false;
                        break;
                    };
                    received += 1;
                    take_in(a, start, &mut scheduler, (&mut kept, &mut echoes), &mut decode_ms);
                    if let Some(next) = scheduler.interpolating_toward() {
                        pusher.push_up_to(&mut generator, &kept, next)?;
                    }
                }
            }
        }
        tokio::time::sleep_until(due).await;
        // Everything that arrived since the last vsync, in stream order;
        // only the newest is generated from (the scheduler counts the
        // others as superseded), but every one is pushed: a frame's motion
        // points to the one before it, and a frame left out is a gap in
        // the generator's history.
        let mut arrived = Vec::new();
        while let Ok(a) = session.frames.try_recv() {
            arrived.push(a);
        }
        received += arrived.len() as u64;
        // Extrapolation generates from the newest frame at once;
        // interpolation pushes up to the pair when a slot between them
        // comes up. A rendered frame that arrived is shown first and
        // ingested after it was handed over (`deferred`): showing it does
        // not need the generator, and its ingest then shares the time to
        // the next vsync with nothing, instead of delaying the frame. Late
        // input re-projects a rendered frame from the generator's current
        // one, so there the ingest comes first, as it does when more frames
        // arrived at once than are kept.
        let deferred = !lazy && !late && arrived.len() <= KEPT;
        if !lazy && !deferred {
            pusher.push(&mut generator, arrived.iter().map(|a| &a.frame))?;
        }
        // The viewer's input, sent at once: taken as late as it can be,
        // after the ingest and just before this slot is generated, so
        // that late input shows the newest pose there is; with late input
        // only as long before the slot's vsync as a slot takes (`latch`).
        let planned = clock();
        let planned = if late {
            let at = latch.input_at(planned, vsync + di);
            tokio::time::sleep_until((start + at).into()).await;
            at
        } else {
            planned
        };
        let newest = config.viewer.as_ref().map(|v| {
            let (now, at) = (Instant::now(), clock());
            let (pose, buttons) = v.source.input(&start_pose, at, now);
            inputs.send(session, (pose, buttons), at)
        });
        for a in arrived {
            take_in(
                a,
                start,
                &mut scheduler,
                (&mut kept, &mut echoes),
                &mut decode_ms,
            );
        }
        // The vsync this slot's image was shown at, if it was shown.
        let mut shown_at = None;
        if let Some(slot) = scheduler.vsync(vsync) {
            if deferred && slot.kind != SlotKind::Rendered {
                // Not one of them is shown now: the slot generates from
                // the newest.
                pusher.push(&mut generator, &kept)?;
            }
            if let (SlotKind::Interpolated, Some(next)) = (slot.kind, slot.next) {
                pusher.push_up_to(&mut generator, &kept, next.id)?;
            }
            // Late input warps what is shown to the newest pose: a rendered
            // frame only while it is the generator's current one.
            let warp = newest.filter(|_| late).filter(|_| {
                slot.kind != SlotKind::Rendered && slot.kind != SlotKind::Repeated
                    || pusher.last == Some(slot.source.id)
            });
            let (mut image, ready_at) = produce(
                &slot,
                (&mut generator, on_device.as_mut()),
                &kept,
                (&mut generation, &mut passes),
                (start, warp.map(|n| n.pose)),
            )?;
            if let Some(n) = warp {
                let finished = clock();
                latch.observe(finished.saturating_sub(planned.min(n.at)));
                if latch.replace(finished, vsync + di) {
                    // Its pose would be more than a vsync old when shown;
                    // the next slot takes a newer one in time.
                    replaced += 1;
                    missed += 1;
                    k += 1;
                    continue;
                }
            }
            let generated = warp.is_some()
                || matches!(slot.kind, SlotKind::Extrapolated | SlotKind::Interpolated);
            if generated && (pusher.followed.contains(&slot.source.id) || shown_passes.is_empty()) {
                shown_passes.clone_from(&passes);
            }
            let shown_input = match warp {
                Some(n) => Some(InputShown {
                    seq: n.seq,
                    at: n.at,
                }),
                None => echoes
                    .iter()
                    .find(|(i, _)| *i == slot.source.id)
                    .map(|(_, e)| InputShown {
                        seq: e.seq,
                        at: Duration::from_micros(e.client_time_us),
                    }),
            };
            if let (Some(sink), Some(shown)) = (&config.window, &mut image) {
                let link = session.stats().session;
                let mut stats = overlay(
                    &accounting,
                    received,
                    clock(),
                    (&generation, &pusher.ingest_ms, &decode_ms),
                    (link.client.rtt_us as f64 / 1000.0, link.color_errors),
                    scheduler.drops(),
                );
                if let Some(v) = &config.viewer {
                    let records = accounting.records();
                    let ip = Percentiles::of(
                        records[records.len().saturating_sub(120)..]
                            .iter()
                            .filter_map(|r| r.input_to_photon_ms)
                            .collect(),
                    );
                    stats += &format!(
                        "\n{}: input to photon p50 {:5.2} ms   p99 {:5.2} ms",
                        ViewerConfig::mode(Some(v)),
                        ip.p50,
                        ip.p99
                    );
                    if matches!(v.source, ViewerSource::Live(_)) {
                        stats.push('\n');
                        stats += crate::viewer::BINDINGS;
                    }
                }
                let event = match shown {
                    Shown::Device(_, image) => crate::window::Event::Encoded {
                        image: image.clone(),
                        stats,
                    },
                    // The colour is read later only by the writer; a
                    // kept frame's is copied.
                    Shown::Host(frame) => crate::window::Event::Frame {
                        width: frame.meta.size.width,
                        height: frame.meta.size.height,
                        color: match frame {
                            Cow::Owned(f) if writer.is_none() => std::mem::take(&mut f.color),
                            f => f.color.clone(),
                        },
                        stats,
                    },
                };
                if sink.send_event(event).is_err() {
                    // The window was closed: the session ends.
                    break;
                }
            }
            let done = clock();
            let present_at = accounting.first_vsync_after(done.max(vsync + di));
            shown_at = Some(present_at);
            let ingested = pusher.ingested_at(slot.source.id);
            accounting.record(
                &slot,
                ready_at.unwrap_or(done),
                ingested,
                present_at,
                shown_input,
            );
            if let (Some(ViewerSource::Track(track)), Some(image)) =
                (config.viewer.as_ref().map(|v| &v.source), &image)
            {
                let at_present = track.pose_at(&start_pose, present_at.as_secs_f64());
                view_error_deg.push(angle_deg(&image.meta().camera.pose, &at_present));
            }
            // Handed over last, when nothing here reads it any more: moved,
            // not copied.
            if let (Some(writer), Some(Shown::Host(shown))) = (writer.as_mut(), image) {
                let mut shown = shown.into_owned();
                // A presented sequence is numbered by display id, uncut.
                shown.meta.index = slot.display_id;
                shown.meta.cut = false;
                writer.write(shown)?;
            }
        }
        if deferred {
            // Every frame that arrived is kept; the pusher takes those it
            // has not taken yet, in order.
            pusher.push(&mut generator, &kept)?;
        }
        if let Some(next) = scheduler.interpolating_toward().filter(|_| lazy) {
            // The frame the next slots go toward was ready before the one
            // shown now: ingested here, after this slot's image.
            pusher.push_up_to(&mut generator, &kept, next)?;
        }
        // Skip vsyncs that passed while this slot was prepared, and the
        // slot of the vsync a late image took (its own vsync passed without
        // a new image: missed; a slot for the next one would be a second
        // image for one vsync).
        let taken = shown_at.map_or(0, |t| (t.as_secs_f64() / di.as_secs_f64()).round() as u64);
        let next = ((clock().as_secs_f64() / di.as_secs_f64()).floor() as u64)
            .max(k + 1)
            .max(taken);
        missed += next.min(last + 1) - k - 1;
        k = next;
    }
    if let Some(writer) = writer {
        writer.finish()?;
    }
    let summary = accounting.summary(scheduler.drops());
    Ok(Report {
        method: config.method.name().into(),
        backend: generator.backend_name(),
        render_fps: fps,
        display_fps: 1.0 / di.as_secs_f64(),
        seconds: config.duration.as_secs_f64(),
        received,
        missed_vsyncs: missed,
        replaced_late: replaced,
        generation_ms: Percentiles::of(generation),
        ingest_ms: Percentiles::of(pusher.ingest_ms),
        decode_ms: Percentiles::of(decode_ms),
        restarts: pusher.restarts,
        ingest_skipped: pusher.skipped,
        summary,
        outages: session.stats(),
        records: accounting.records().to_vec(),
        passes: shown_passes.iter().map(|p| p.name().to_string()).collect(),
        plan,
        on_device: on_device.map_or(0, |d| d.handed),
        viewer: ViewerReport {
            mode: ViewerConfig::mode(config.viewer.as_ref()).into(),
            turned_deg: inputs.last.map_or(0.0, |p| angle_deg(&start_pose, &p)),
            moved_m: inputs
                .last
                .map_or(0.0, |p| (p.position - start_pose.position).length()),
            inputs,
            view_error_deg,
            vsync_turn_deg: match config.viewer.as_ref().map(|v| &v.source) {
                Some(ViewerSource::Track(t)) => Some(t.max_turn_deg_per_s() * di.as_secs_f64()),
                _ => None,
            },
        },
    })
}

/// The newest viewer input: its sequence number, when it was taken and
/// its pose.
#[derive(Clone, Copy, Debug)]
struct Newest {
    seq: u64,
    at: Duration,
    pose: Pose,
}

/// The viewer inputs a run sent, and those it could not (no session).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Inputs {
    /// Sent.
    pub sent: u64,
    /// Not sent.
    pub unsent: u64,
    /// The last input's pose.
    #[serde(skip)]
    last: Option<Pose>,
}

impl Inputs {
    /// Sends the viewer's `pose` and `buttons`, taken at `now` (presenter
    /// clock), on `session`.
    fn send(&mut self, session: &Stream, (pose, buttons): (Pose, u32), now: Duration) -> Newest {
        let newest = Newest {
            seq: self.sent + self.unsent + 1,
            at: now,
            pose,
        };
        self.last = Some(pose);
        let input = Input {
            seq: newest.seq,
            client_time_us: u64::try_from(now.as_micros()).unwrap_or(u64::MAX),
            camera: Some(newest.pose),
            buttons,
            axes: [0.0; 4],
        };
        if session.send_input(&input) {
            self.sent += 1;
        } else {
            self.unsent += 1;
        }
        newest
    }
}

/// Pushes rendered frames into the generator in stream order.
struct Pusher {
    /// The presenter's clock origin.
    start: Instant,
    /// The index of the last frame pushed.
    last: Option<u64>,
    /// Each push's time, ms.
    ingest_ms: Vec<f64>,
    /// When the newest few frames were ingested (since `start`).
    ingested: VecDeque<(u64, Duration)>,
    /// Pushes that restarted the history.
    restarts: u64,
    /// The newest few frames pushed right after their predecessor (no
    /// gap: every ingest stage had the frame before to work with).
    followed: VecDeque<u64>,
    /// Extrapolation's render interval, ms: where ingesting a frame takes
    /// longer than that, a backlog is taken in from its newest frame.
    keep_pace: Option<f64>,
    /// Frames left out to keep pace.
    skipped: u64,
}

/// Recent ingests [`Pusher::behind`] looks at, and how many of them must
/// have taken longer than a render interval (one slow ingest is not a
/// pace).
const PACE_WINDOW: usize = 4;
const PACE_SLOW: usize = 3;

impl Pusher {
    /// Pushes the kept frames up to frame `id` that come after the last
    /// pushed one (interpolation: up to the frame the slots go toward).
    fn push_up_to(
        &mut self,
        generator: &mut FrameGenerator,
        kept: &VecDeque<Arc<Frame>>,
        id: u64,
    ) -> anyhow::Result<()> {
        self.push(generator, kept.iter().filter(|f| f.meta.index <= id))
    }

    /// Pushes the frames of `due` that come after the last pushed one, in
    /// stream order; one that arrived after a newer one was pushed can no
    /// longer join the history and is left out.
    fn push<'a>(
        &mut self,
        generator: &mut FrameGenerator,
        due: impl IntoIterator<Item = &'a Arc<Frame>>,
    ) -> anyhow::Result<()> {
        let mut due: Vec<&Arc<Frame>> = due
            .into_iter()
            .filter(|f| self.last.is_none_or(|p| f.meta.index > p))
            .collect();
        due.sort_by_key(|f| f.meta.index);
        if due.len() > 1 && self.behind() {
            let skip = due.len() - 1;
            tracing::debug!(
                skip,
                "ingest slower than the stream: taking in its newest frame"
            );
            self.skipped += skip as u64;
            due.drain(..skip);
        }
        for f in due {
            let t = Instant::now();
            let outcome = tokio::task::block_in_place(|| generator.push_shared(f))?;
            self.ingest_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if self.last.is_some_and(|p| p + 1 == f.meta.index) {
                self.followed.push_back(f.meta.index);
                if self.followed.len() > 2 * KEPT {
                    self.followed.pop_front();
                }
            }
            self.last = Some(f.meta.index);
            self.ingested
                .push_back((f.meta.index, self.start.elapsed()));
            if self.ingested.len() > 2 * KEPT {
                self.ingested.pop_front();
            }
            if let PushOutcome::Restarted { reason } = outcome {
                tracing::debug!(frame = f.meta.index, reason, "history restarted");
                self.restarts += 1;
            }
        }
        Ok(())
    }

    /// Whether extrapolation's ingest falls behind the stream: most recent
    /// ingests took longer than a render interval, so taking in every
    /// frame of a backlog only grows it (at 640×360 on lavapipe, an
    /// 80 ms ingest of each of 30 frames a second showed one rendered
    /// frame in 40 vsyncs and generated none). Then the newest frame alone
    /// is taken in: the ones before it are a gap in the history, as a
    /// frame lost on the network is (the generator restarts its
    /// trajectories from the newest), and the display stays as fresh as
    /// the ingest allows. Interpolation needs every frame of its pairs and
    /// never skips.
    fn behind(&self) -> bool {
        let Some(interval) = self.keep_pace else {
            return false;
        };
        let recent = &self.ingest_ms[self.ingest_ms.len().saturating_sub(PACE_WINDOW)..];
        recent.len() == PACE_WINDOW
            && recent.iter().filter(|&&ms| ms > interval).count() >= PACE_SLOW
    }

    /// When frame `id` was ingested, if it was (recently).
    fn ingested_at(&self, id: u64) -> Option<Duration> {
        self.ingested
            .iter()
            .find(|(i, _)| *i == id)
            .map(|(_, t)| *t)
    }
}

/// Takes an arrived frame in: its decode time, the scheduler hears it is
/// ready (times since `start`), and it joins the kept frames (with its
/// input echo, if any).
fn take_in(
    a: crate::Arrived,
    start: Instant,
    scheduler: &mut Scheduler,
    (kept, echoes): (&mut VecDeque<Arc<Frame>>, &mut VecDeque<(u64, InputEcho)>),
    decode_ms: &mut Vec<f64>,
) {
    let since = |t: Instant| t.saturating_duration_since(start);
    decode_ms.push(
        a.decoded
            .saturating_duration_since(a.received)
            .as_secs_f64()
            * 1e3,
    );
    let frame = a.frame;
    if let Some(echo) = a.input {
        echoes.push_back((frame.meta.index, echo));
        if echoes.len() > KEPT {
            echoes.pop_front();
        }
    }
    scheduler.frame_ready(FrameReady {
        id: frame.meta.index,
        sim_time: frame.meta.time,
        host_processing: frame.meta.host_processing,
        received_at: since(a.received),
        ready_at: since(a.decoded),
    });
    kept.push_back(frame);
    if kept.len() > KEPT {
        kept.pop_front();
    }
}

/// The image of a slot and when it was ready (the source frame's ready
/// time, or the end of generation). A generated slot adds its time to
/// `generation` and leaves its passes in `passes`. With `warp` (late
/// input), every slot is generated with that camera: a rendered or held
/// frame at α = 0 (re-projected, holes filled as for generated frames).
fn produce<'a>(
    slot: &Slot,
    (generator, on_device): (&mut FrameGenerator, Option<&mut DeviceFrames>),
    kept: &'a VecDeque<Arc<Frame>>,
    (generation, passes): (&mut Vec<f64>, &mut Vec<framegen::pipeline::Pass>),
    (start, warp): (Instant, Option<Pose>),
) -> anyhow::Result<(Option<Shown<'a>>, Option<Duration>)> {
    let generated = matches!(slot.kind, SlotKind::Extrapolated | SlotKind::Interpolated);
    if !generated && warp.is_none() {
        // Its displayed region (a no-op without a widened window).
        let frame = kept.iter().find(|f| f.meta.index == slot.source.id);
        let shown = match frame {
            Some(f) => Some(Shown::Host(tokio::task::block_in_place(|| {
                generator.displayed(f)
            })?)),
            None => None,
        };
        return Ok((shown, Some(slot.source.ready_at)));
    }
    // A rendered or held frame warped to the viewer is generated at α = 0.
    let (alpha, camera) = match warp {
        Some(pose) => (
            if generated { slot.alpha } else { 0.0 },
            CameraSource::Given(pose),
        ),
        None => (slot.alpha, CameraSource::Extrapolated),
    };
    let t = Instant::now();
    let shown = tokio::task::block_in_place(|| match on_device {
        Some(d) => d
            .generate(generator, alpha, camera)
            .map(|(meta, image)| Shown::Device(meta, image)),
        None => Ok(Shown::Host(Cow::Owned(
            generator.generate_with(alpha, camera)?.frame,
        ))),
    })?;
    generation.push(t.elapsed().as_secs_f64() * 1e3);
    passes.clear();
    passes.extend(generator.timings().iter().map(|p| p.pass));
    Ok((Some(shown), Some(start.elapsed())))
}

/// A slot's image: a frame on the host (a kept rendered frame borrowed as
/// it is), or a generated frame left on the device the window shares,
/// display-encoded there.
enum Shown<'a> {
    Host(Cow<'a, Frame>),
    Device(FrameMeta, Arc<crate::display::Image>),
}

impl Shown<'_> {
    fn meta(&self) -> &FrameMeta {
        match self {
            Shown::Host(f) => &f.meta,
            Shown::Device(meta, _) => meta,
        }
    }
}

/// Images a generator on the window's device writes its frames into
/// ([`FrameGenerator::generate_to`]) and display-encodes there (issue 15
/// §2): nothing crosses to the host. A few in turn, so the window can
/// still be showing one while the next is made.
struct DeviceFrames {
    shared: crate::window::Shared,
    ring: Vec<Arc<crate::display::Image>>,
    next: usize,
    /// Frames handed over.
    handed: u64,
}

/// Images in [`DeviceFrames`]' ring.
pub(crate) const RING: usize = 3;

impl DeviceFrames {
    fn new(shared: crate::window::Shared) -> Self {
        Self {
            shared,
            ring: Vec::with_capacity(RING),
            next: 0,
            handed: 0,
        }
    }

    /// Generates at `alpha` from `camera` into the next image and records
    /// its display transform; the frame's header and the image.
    fn generate(
        &mut self,
        generator: &mut FrameGenerator,
        alpha: f64,
        camera: CameraSource,
    ) -> anyhow::Result<(FrameMeta, Arc<crate::display::Image>)> {
        let size = generator
            .generated_size()
            .ok_or(framegen::FramegenError::NoFrame)?;
        let (ctx, display) = (&self.shared.ctx, &self.shared.display);
        ctx.require_texture("a generated frame", size.width, size.height)?;
        let slot = self.next % RING;
        self.next += 1;
        let fits = |i: &crate::display::Image| (i.width, i.height) == (size.width, size.height);
        let image = match self.ring.get(slot) {
            Some(i) if fits(i) => i.clone(),
            _ => {
                let i = Arc::new(display.image(&ctx.device, size.width, size.height));
                if slot < self.ring.len() {
                    self.ring[slot] = i.clone();
                } else {
                    self.ring.push(i.clone());
                }
                i
            }
        };
        let meta = generator.generate_to(alpha, camera, image.source())?;
        // In a scope of its own: the window's errors on the shared device
        // stay the window's to report.
        ctx.checked("display-encoding a generated frame", || {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            display.encode(&mut encoder, &image);
            ctx.queue.submit([encoder.finish()]);
        })?;
        self.handed += 1;
        Ok((meta, image))
    }
}

/// The overlay text (in the spirit of Moonlight's statistics overlay).
fn overlay(
    accounting: &Accounting,
    received: u64,
    now: Duration,
    (generation, ingest, decode): (&[f64], &[f64], &[f64]),
    (rtt_ms, color_errors): (f64, u64),
    drops: framegen::schedule::Drops,
) -> String {
    let secs = now.as_secs_f64().max(1e-3);
    let records = accounting.records();
    let recent = &records[records.len().saturating_sub(120)..];
    let generated = records
        .iter()
        .filter(|r| matches!(r.kind, SlotKind::Extrapolated | SlotKind::Interpolated))
        .count();
    let last = |v: &[f64]| Percentiles::of(v[v.len().saturating_sub(120)..].to_vec());
    let latency = Percentiles::of(recent.iter().map(|r| r.latency_ms).collect());
    let host = Percentiles::of(recent.iter().map(|r| r.host_processing_ms).collect());
    format!(
        "incoming {:5.1} fps   generated {:5.1} fps   presented {:5.1} fps\n\
         host {:5.2} ms   network rtt {:5.2} ms   decode {:5.2} ms\n\
         ingest {:5.2} ms   generation {:5.2} ms\n\
         latency p50 {:5.2} ms   p99 {:5.2} ms\n\
         drops: network {}  late {}  scheduler {}  colour errors {}",
        received as f64 / secs,
        generated as f64 / secs,
        records.len() as f64 / secs,
        host.p50,
        rtt_ms,
        last(decode).p50,
        last(ingest).p50,
        last(generation).p50,
        latency.p50,
        latency.p99,
        drops.network,
        drops.late,
        drops.scheduler,
        color_errors,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run told apart from one the stream held back: under nine tenths
    /// of the promised frames it names the counts, at or above it (or with
    /// no frames promised, or a rate that is not a number) it says nothing.
    #[test]
    fn a_stream_that_fell_short_is_named() {
        let line = stream_shortfall(146, 300.0, 452, 155).expect("half the frames");
        for part in [
            "146 of 300 frames",
            "49 %",
            "155 never arrived",
            "452 slots",
        ] {
            assert!(line.contains(part), "{part:?} missing from {line:?}");
        }
        assert!(stream_shortfall(269, 300.0, 0, 31).is_some());
        assert_eq!(stream_shortfall(270, 300.0, 0, 30), None);
        assert_eq!(stream_shortfall(301, 300.0, 0, 0), None);
        assert_eq!(stream_shortfall(0, 0.0, 0, 0), None);
        assert_eq!(stream_shortfall(0, f64::NAN, 0, 0), None);
    }

    /// A pusher that has taken in frame 0, with `ingest_ms` for its recent
    /// ingests and `keep_pace` as the presenter sets it.
    fn pusher(keep_pace: Option<f64>, ingest_ms: &[f64]) -> Pusher {
        Pusher {
            start: Instant::now(),
            last: Some(0),
            ingest_ms: ingest_ms.to_vec(),
            ingested: VecDeque::new(),
            restarts: 0,
            followed: VecDeque::new(),
            keep_pace,
            skipped: 0,
        }
    }

    /// Extrapolation whose ingests mostly take longer than a render
    /// interval takes a backlog in from its newest frame (the rest are a
    /// gap); one that keeps pace, interpolation, a lone frame and too few
    /// ingests to tell take every frame, in order.
    #[test]
    fn a_slow_ingest_takes_a_backlog_in_from_its_newest_frame() {
        let size = protocol::FrameSize::new(16, 9);
        let frames: Vec<Arc<Frame>> = (0..5).map(|i| Arc::new(Frame::blank(i, size))).collect();
        let interval = 1000.0 / 30.0;
        let slow = [50.0, 50.0, 10.0, 50.0];
        // (keep pace, recent ingests, frames due, frames taken in)
        type Case<'a> = (Option<f64>, &'a [f64], std::ops::Range<usize>, &'a [u64]);
        let cases: [Case; 6] = [
            (Some(interval), &slow, 1..5, &[4]),
            (
                Some(interval),
                &[50.0, 10.0, 10.0, 50.0],
                1..5,
                &[1, 2, 3, 4],
            ),
            (None, &slow, 1..5, &[1, 2, 3, 4]),
            (Some(interval), &slow, 1..2, &[1]),
            (Some(interval), &[50.0, 50.0, 50.0], 1..5, &[1, 2, 3, 4]),
            // Frames already taken in are not taken again.
            (Some(interval), &slow, 0..3, &[2]),
        ];
        for (keep_pace, recent, due, taken) in cases {
            let mut generator = FrameGenerator::cpu(Settings::for_method(Method::Gffe)).unwrap();
            generator.push(&frames[0]).unwrap();
            let mut p = pusher(keep_pace, recent);
            p.push(&mut generator, frames[due.clone()].iter().rev())
                .unwrap();
            let ids: Vec<u64> = p.ingested.iter().map(|(id, _)| *id).collect();
            let case = format!("{keep_pace:?} {recent:?} {due:?}");
            assert_eq!(ids, taken, "{case}");
            assert_eq!(p.last, taken.last().copied(), "{case}");
            // Every new frame due was taken in or counted as left out.
            let fresh = due.filter(|&i| i > 0).count();
            assert_eq!(p.skipped as usize, fresh - taken.len(), "{case}");
        }
    }
}
