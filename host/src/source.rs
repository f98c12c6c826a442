//! Where streamed frames come from: the renderer or a dump, on a thread of
//! its own, paced by simulation time ([`crate::pacer`]), encoded once and
//! shared by every client through a broadcast channel. A client that lags
//! loses the oldest frames (counted as drops) and never slows the producer.
//!
//! A live scene is rendered once and shared by all sessions ([`Feed::Live`]);
//! a dump replay can instead start afresh for every session, from its first
//! frame ([`Feed::PerSession`]). An interactive scene (issue 20) is rendered
//! for every session from that session's viewer camera
//! ([`Feed::Interactive`]): the newest input its [`crate::input::InputGate`]
//! took, else the scene's own path; each frame echoes the input it was
//! rendered with.
//!
//! Video-coded colour (issue 19 §1) is encoded once too, by the producer:
//! a session whose client joins or loses a frame asks the producer for a
//! keyframe through the channel's [`KeyframeRequests`], and sends its
//! client nothing until one comes ([`crate::recovery`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use protocol::Pose;
use protocol::assemble::encode_frame_with;
use protocol::codec::stream::ColorStreamEncoder;
use protocol::import::AnyDump;
use protocol::wire::InputEcho;
use protocol::wire::StreamBuffer;
use protocol::{BufferKind, Codec, Frame, FrameSize};
use tokio::sync::{broadcast, watch};
use video::{ColorCodec, ColorEncoder};

use crate::input::{InputLimits, ViewerInput};
use crate::pacer::{Pace, Pacer};
use crate::recovery::KeyframeBudget;
use scene::Scene;
use scene::render::{Renderer, ViewerPoses, WindowSettings};

/// Where a session's gate puts the newest viewer input, and an interactive
/// producer reads it.
pub type ViewerSender = watch::Sender<Option<ViewerInput>>;

/// One frame, encoded as the bytes of its per-frame stream.
#[derive(Debug)]
pub struct StreamFrame {
    /// The frame's index.
    pub index: u64,
    /// Header message then payload messages.
    pub bytes: Vec<u8>,
    /// Encoded payload size per buffer, for reports.
    pub buffer_bytes: Vec<(protocol::BufferKind, u64)>,
    /// Whether a receiver can start decoding here: always, unless colour
    /// is video-coded and this frame's is predicted from the one before.
    pub keyframe: bool,
}

/// How a source encodes its frames: the buffers it sends, and the
/// setting of a video-coded colour buffer.
#[derive(Clone, Debug)]
pub struct Encoding {
    /// Buffers every frame carries.
    pub buffers: Vec<StreamBuffer>,
    /// The colour codec; its setting is used when the colour buffer's
    /// codec is [`Codec::H264`].
    pub color: ColorCodec,
}

impl Encoding {
    /// `geometry`'s depth and motion, and colour by `color`.
    pub fn new(geometry: protocol::wire::BufferSet, color: ColorCodec) -> Self {
        Self {
            buffers: geometry.buffers(color.codec()).to_vec(),
            color,
        }
    }

    /// The colour encoder for a stream of `size` at `fps`, if colour is
    /// video-coded; fails if libavcodec lacks the encoder.
    fn color_encoder(&self, size: FrameSize, fps: f64) -> anyhow::Result<Option<ColorEncoder>> {
        let video = self
            .buffers
            .iter()
            .any(|b| b.kind == BufferKind::Color && b.codec == Codec::H264);
        let settings = match self.color.settings(size, fps) {
            Some(s) if video => s,
            None if video => ColorCodec::DEFAULT_LIVE
                .settings(size, fps)
                .ok_or_else(|| anyhow::anyhow!("no default video setting"))?,
            _ => return Ok(None),
        };
        Ok(Some(ColorEncoder::new(settings, fps)?))
    }
}

/// Buffers alone: a video-coded colour buffer gets the automatic rate.
impl From<Vec<StreamBuffer>> for Encoding {
    fn from(buffers: Vec<StreamBuffer>) -> Self {
        let color = match buffers.iter().find(|b| b.kind == BufferKind::Color) {
            Some(b) if b.codec == Codec::H264 => ColorCodec::DEFAULT_LIVE,
            Some(b) if b.codec == Codec::Zstd => ColorCodec::Zstd,
            _ => ColorCodec::Raw,
        };
        Self { buffers, color }
    }
}

/// A stream's frames and the way back to their producer: sessions
/// subscribe to the frames, and ask the producer for a keyframe when their
/// client needs one.
#[derive(Clone, Debug)]
pub struct Channel {
    frames: broadcast::Sender<Arc<StreamFrame>>,
    keyframe: KeyframeRequests,
}

/// The way back from sessions to a producer: requests for a keyframe
/// (requests between two frames make one keyframe). Holding it does not
/// keep the frames' channel open.
#[derive(Clone, Debug, Default)]
pub struct KeyframeRequests(Arc<AtomicBool>);

impl KeyframeRequests {
    /// Asks the producer to make its next frame a keyframe.
    pub fn request(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Takes a pending request.
    fn take(&self) -> bool {
        self.0.swap(false, Ordering::Relaxed)
    }
}

impl Channel {
    /// A receiver of every frame sent from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<StreamFrame>> {
        self.frames.subscribe()
    }

    /// Sends a frame to every subscriber (no subscriber is fine: clients
    /// join a live stream); returns how many got it.
    pub fn send(&self, frame: Arc<StreamFrame>) -> usize {
        self.frames.send(frame).unwrap_or(0)
    }

    /// Where sessions ask its producer for keyframes.
    pub fn keyframes(&self) -> KeyframeRequests {
        self.keyframe.clone()
    }
}

/// What to stream.
#[derive(Clone, Debug)]
pub enum SourceSpec {
    /// Render a scene live.
    Scene {
        /// `builtin:NAME` or a RON path.
        spec: String,
        /// Displayed size.
        size: FrameSize,
        /// Render rate.
        fps: f64,
        /// Adaptive window.
        window: WindowSettings,
        /// Directory for relative glTF paths.
        base: PathBuf,
    },
    /// Replay a dump at its own rate: a native dump, a Blender render or an
    /// Unreal capture ([`protocol::import::AnyDump`]).
    Dump {
        /// The dump directory.
        dir: PathBuf,
        /// Start again after the last frame.
        looped: bool,
    },
}

impl SourceSpec {
    /// What the stream's content does (sent in the welcome, issue 17): a
    /// scene's from its file, a dump's from its manifest or sidecar
    /// ([`AnyDump::effects`]). Reads only the scene file or the dump's
    /// metadata.
    pub fn effects(&self) -> anyhow::Result<protocol::Effects> {
        Ok(match self {
            SourceSpec::Scene { spec, .. } => Scene::load(spec)?.stream_effects(),
            SourceSpec::Dump { dir, .. } => AnyDump::open(dir)?.effects(),
        })
    }
}

/// Counters of the producer.
#[derive(Debug, Default)]
pub struct SourceStats {
    /// Frames produced and broadcast.
    pub produced: AtomicU64,
    /// Frames skipped by the pacer because production fell behind.
    pub skipped: AtomicU64,
    /// Dump frames that could not be read and were left out (the next
    /// frame sent is flagged as a cut).
    pub unreadable: AtomicU64,
}

/// A running producer thread.
pub struct Source {
    /// Counters.
    pub stats: Arc<SourceStats>,
    stop: Arc<AtomicBool>,
    /// Releases a paused producer ([`Source::start_paused`]).
    go: Option<std::sync::mpsc::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Where a session's frames come from.
#[derive(Clone, Debug)]
pub enum Feed {
    /// One shared live stream: sessions join it where it is.
    Live(Channel),
    /// A fresh source per session (dump replays): every client gets the
    /// whole sequence, and its session ends after the last frame.
    PerSession {
        /// What to replay.
        spec: SourceSpec,
        /// How to encode it.
        encoding: Encoding,
    },
    /// A scene rendered for each session from its viewer's camera (issue
    /// 20): every session costs a render.
    Interactive {
        /// The scene ([`SourceSpec::Scene`]).
        spec: SourceSpec,
        /// How to encode it.
        encoding: Encoding,
        /// What each session's gate takes (positions around the scene's
        /// origin).
        input: InputLimits,
        /// Where each session's source is opened (see [`Opener`]); `None`:
        /// on the session's blocking task.
        opener: Option<Opener>,
    },
}

/// Runs the opening of a session's own source ([`Source::open`], which
/// starts its renderer's and producer's threads) where the process that
/// embeds the server wants it, and returns when it is done: it calls the
/// function it is given once. The in-process demo opens them on a thread
/// of lower priority, which the threads they start inherit, so that a
/// session's rendering does not take the presenter's time on the same
/// machine (a standalone server has no use for it).
pub type Opener = fn(&mut (dyn FnMut() + Send));

impl Feed {
    /// An interactive feed of the scene `spec` ([`Feed::Interactive`]),
    /// its input bounded around the scene's origin, each session's source
    /// opened by `opener` where one is given.
    pub fn interactive(
        spec: SourceSpec,
        encoding: Encoding,
        opener: Option<Opener>,
    ) -> anyhow::Result<Self> {
        let SourceSpec::Scene { spec: scene, .. } = &spec else {
            anyhow::bail!("only a scene can be interactive (a dump has no viewer camera)");
        };
        let origin = glam::DVec3::from(Scene::load(scene)?.origin);
        Ok(Feed::Interactive {
            spec,
            encoding,
            input: InputLimits {
                origin,
                ..InputLimits::default()
            },
            opener,
        })
    }

    /// What a session's input gate takes.
    pub fn input_limits(&self) -> InputLimits {
        match self {
            Feed::Interactive { input, .. } => *input,
            _ => InputLimits::default(),
        }
    }

    /// A receiver for one session, and the source it owns (per-session
    /// feeds: opened, paused until [`Source::resume`], so that its pacing
    /// starts when the session does), which stops when dropped; and the
    /// channel to ask for keyframes on.
    pub fn subscribe(&self) -> anyhow::Result<Subscription> {
        match self {
            Feed::Live(channel) => Ok(Subscription {
                frames: channel.subscribe(),
                keyframes: channel.keyframes(),
                source: None,
                viewer: None,
            }),
            Feed::PerSession { spec, encoding } | Feed::Interactive { spec, encoding, .. } => {
                // The producer thread holds the only sender: when the
                // replay ends, the session sees the channel close.
                let channel = Source::channel();
                let frames = channel.subscribe();
                let keyframes = channel.keyframes();
                let (viewer, input, opener) = match self {
                    Feed::Interactive { opener, .. } => {
                        let (tx, rx) = watch::channel(None);
                        (Some(tx), Some(rx), *opener)
                    }
                    _ => (None, None, None),
                };
                let open = || Source::open(spec.clone(), encoding.clone(), channel, input);
                let source = match opener {
                    None => open()?,
                    Some(run) => {
                        let (mut open, mut opened) = (Some(open), None);
                        run(&mut || {
                            if let Some(open) = open.take() {
                                opened = Some(open());
                            }
                        });
                        opened.ok_or_else(|| {
                            anyhow::anyhow!("the session's source was never opened")
                        })??
                    }
                };
                Ok(Subscription {
                    frames,
                    keyframes,
                    source: Some(source),
                    viewer,
                })
            }
        }
    }
}

/// One session's view of a [`Feed`].
pub struct Subscription {
    /// The frames.
    pub frames: broadcast::Receiver<Arc<StreamFrame>>,
    /// Where to ask for keyframes.
    pub keyframes: KeyframeRequests,
    /// The session's own source (per-session feeds).
    pub source: Option<Source>,
    /// Where the session puts its viewer's input (interactive feeds).
    pub viewer: Option<ViewerSender>,
}

/// How many frames a lagging client may be behind before it loses the
/// oldest: a couple of frames is all a real-time stream can use.
pub const BROADCAST_DEPTH: usize = 4;

impl Source {
    /// A channel for [`Source::start`] with [`BROADCAST_DEPTH`].
    pub fn channel() -> Channel {
        Channel {
            frames: broadcast::channel(BROADCAST_DEPTH).0,
            keyframe: KeyframeRequests::default(),
        }
    }

    /// Starts producing `spec` with `encoding` into `frames`. Fails early
    /// if the scene or dump cannot be opened, or the colour encoder is
    /// missing.
    pub fn start(
        spec: SourceSpec,
        encoding: impl Into<Encoding>,
        frames: Channel,
    ) -> anyhow::Result<Self> {
        let mut source = Self::start_paused(spec, encoding, frames)?;
        source.resume();
        Ok(source)
    }

    /// [`Source::start`], with the producer opened (the scene or dump, so
    /// that errors come now) but waiting for [`Source::resume`] before its
    /// first frame and the start of its pacing.
    pub fn start_paused(
        spec: SourceSpec,
        encoding: impl Into<Encoding>,
        frames: Channel,
    ) -> anyhow::Result<Self> {
        Self::open(spec, encoding.into(), frames, None)
    }

    /// [`Source::start_paused`]; with `viewer`, a scene is rendered from
    /// the newest viewer input there (its path until there is one).
    fn open(
        spec: SourceSpec,
        encoding: Encoding,
        frames: Channel,
        viewer: Option<watch::Receiver<Option<ViewerInput>>>,
    ) -> anyhow::Result<Self> {
        let stats = Arc::new(SourceStats::default());
        let stop = Arc::new(AtomicBool::new(false));
        let mut producer = Producer::open(&spec, viewer)?;
        let (size, fps) = producer.size_and_fps();
        let mut color = encoding.color_encoder(size, fps)?;
        let (go, released) = std::sync::mpsc::channel::<()>();
        let thread = {
            // The thread owns its sender: when a finite source ends and the
            // caller holds no other, subscribers see the channel close.
            let (stats, stop) = (stats.clone(), stop.clone());
            std::thread::Builder::new()
                .name("frame source".into())
                .spawn(move || {
                    // Released, or the source dropped (then `stop` is set).
                    let _ = released.recv();
                    if stop.load(Ordering::Relaxed) {
                        return;
                    }
                    let coders = Coders {
                        buffers: &encoding.buffers,
                        color: color.as_mut(),
                    };
                    if let Err(e) = producer.run(&frames, coders, &stats, &stop) {
                        tracing::error!("frame source stopped: {e:#}");
                    }
                })?
        };
        Ok(Self {
            stats,
            stop,
            go: Some(go),
            thread: Some(thread),
        })
    }

    /// Lets a paused producer start (nothing once it runs).
    pub fn resume(&mut self) {
        if let Some(go) = self.go.take() {
            let _ = go.send(());
        }
    }

    /// Stops the producer and waits for it (as dropping does).
    pub fn stop(self) {}
}

impl Drop for Source {
    /// Stops the producer and waits for it: it finishes the frame it is on
    /// (one render or read, at most a frame interval of pacing). A producer
    /// left running could still be inside the GPU driver when the process
    /// exits, and Mesa's lavapipe then crashes during teardown (seen as a
    /// SIGSEGV after every test of a binary had passed).
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // A paused producer wakes up to the closed channel and returns.
        self.go = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Unreadable dump frames in a row, and whether the next frame sent must
/// be flagged as a cut.
#[derive(Default)]
struct Gap {
    run: u64,
    cut_next: bool,
}

enum Producer {
    Scene {
        renderer: Box<Renderer>,
        fps: f64,
        viewer: Option<ViewerCamera>,
    },
    Dump {
        reader: Box<AnyDump>,
        looped: bool,
    },
}

/// The camera of an interactive producer (issue 20): the newest viewer
/// input's pose, else the scene's path, and the two poses before it (the
/// motion vectors lead to the previous one; the window looks at both).
struct ViewerCamera {
    input: watch::Receiver<Option<ViewerInput>>,
    prev: Option<Pose>,
    before: Option<Pose>,
}

impl ViewerCamera {
    /// The poses of the next frame (`path`: the scene's own camera at its
    /// time) and the input they come from. The history moves on for a
    /// skipped frame too: the next frame's motion leads to its time, so to
    /// the pose it would have had.
    fn advance(&mut self, path: Pose) -> (ViewerPoses, Option<InputEcho>) {
        let newest = *self.input.borrow();
        let now = newest.map_or(path, |v| v.pose);
        let prev = self.prev.unwrap_or(now);
        let before = self.before.unwrap_or(prev);
        self.before = Some(prev);
        self.prev = Some(now);
        (ViewerPoses { now, prev, before }, newest.map(|v| v.echo))
    }
}

/// What the producer encodes with.
struct Coders<'a> {
    buffers: &'a [StreamBuffer],
    color: Option<&'a mut ColorEncoder>,
}

impl Producer {
    /// The stream's displayed size and rate.
    fn size_and_fps(&self) -> (FrameSize, f64) {
        match self {
            Producer::Scene { renderer, fps, .. } => (renderer.size(), *fps),
            Producer::Dump { reader, .. } => (reader.size(), reader.fps()),
        }
    }

    fn open(
        spec: &SourceSpec,
        viewer: Option<watch::Receiver<Option<ViewerInput>>>,
    ) -> anyhow::Result<Self> {
        Ok(match spec {
            SourceSpec::Scene {
                spec,
                size,
                fps,
                window,
                base,
            } => {
                anyhow::ensure!(fps.is_finite() && *fps > 0.0, "fps must be > 0");
                let mut renderer = Renderer::new(Scene::load(spec)?, *size, base)?;
                renderer.set_window(*window);
                Producer::Scene {
                    renderer: Box::new(renderer),
                    fps: *fps,
                    viewer: viewer.map(|input| ViewerCamera {
                        input,
                        prev: None,
                        before: None,
                    }),
                }
            }
            SourceSpec::Dump { dir, looped } => {
                anyhow::ensure!(viewer.is_none(), "a dump has no viewer camera");
                // A native dump, a Blender render or an Unreal capture.
                let reader = Box::new(AnyDump::open(dir)?);
                anyhow::ensure!(!reader.is_empty(), "the dump has no frames");
                Producer::Dump {
                    reader,
                    looped: *looped,
                }
            }
        })
    }

    /// Simulation time of frame `k` and the next one.
    fn times(&self, k: u64) -> anyhow::Result<(f64, Option<f64>)> {
        Ok(match self {
            Producer::Scene { fps, .. } => (k as f64 / fps, Some((k + 1) as f64 / fps)),
            Producer::Dump { reader, looped } => {
                let n = reader.len();
                let offset = Self::loop_offset(reader, *looped, k)?;
                let t = reader.read_meta(k % n)?.time + offset;
                // An unreadable next frame costs only the pacer's look-ahead;
                // it is left out when its own turn comes.
                let next = if k % n + 1 < n {
                    reader.read_meta(k % n + 1).ok().map(|m| m.time + offset)
                } else if *looped {
                    let first = reader.read_meta(0).ok();
                    let offset = Self::loop_offset(reader, true, k + 1).ok();
                    first.zip(offset).map(|(m, offset)| m.time + offset)
                } else {
                    None
                };
                (t, next)
            }
        })
    }

    /// The viewer camera of a skipped frame `k` moves on.
    fn skip(&mut self, k: u64) {
        if let Producer::Scene {
            renderer,
            fps,
            viewer: Some(viewer),
        } = self
        {
            viewer.advance(Self::path_pose(renderer, k as f64 / *fps));
        }
    }

    /// The scene's own camera at time `t`.
    fn path_pose(renderer: &Renderer, t: f64) -> Pose {
        renderer.camera(&renderer.scene().evaluate(t)).pose
    }

    /// Frame `k`, and the viewer input it was rendered from.
    fn frame(&mut self, k: u64) -> anyhow::Result<(Frame, Option<InputEcho>)> {
        Ok(match self {
            Producer::Scene {
                renderer,
                fps,
                viewer: Some(viewer),
            } => {
                let time = |k: u64| k as f64 / *fps;
                let (poses, echo) = viewer.advance(Self::path_pose(renderer, time(k)));
                let frame = renderer.render_posed(k, time(k), time(k.saturating_sub(1)), &poses)?;
                (frame, echo)
            }
            Producer::Scene {
                renderer,
                fps,
                viewer: None,
            } => (renderer.render(k, *fps)?, None),
            Producer::Dump { reader, looped } => {
                let n = reader.len();
                let mut f = reader.read_frame(k % n)?;
                if *looped {
                    // Indices and times keep increasing across loops, so
                    // clients do not take the second loop for late frames
                    // and the pacer keeps the dump's rate; the jump back to
                    // the first frame is a cut.
                    f.meta.index = k;
                    f.meta.time += Self::loop_offset(reader, true, k)?;
                    f.meta.cut |= k >= n && k % n == 0;
                }
                (f, None)
            }
        })
    }

    /// How far in time loop number `k / len` of a looped dump is shifted:
    /// whole loops of (first → last frame + one frame interval).
    fn loop_offset(reader: &AnyDump, looped: bool, k: u64) -> anyhow::Result<f64> {
        let n = reader.len();
        if !looped || k < n {
            return Ok(0.0);
        }
        let span = reader.read_meta(n - 1)?.time - reader.read_meta(0)?.time;
        Ok((k / n) as f64 * (span + 1.0 / reader.fps()))
    }

    /// Frames in one pass of the source (a scene never ends).
    fn len(&self) -> u64 {
        match self {
            Producer::Scene { .. } => u64::MAX,
            Producer::Dump { reader, .. } => reader.len(),
        }
    }

    fn finished(&self, k: u64) -> bool {
        match self {
            Producer::Scene { .. } => false,
            Producer::Dump { reader, looped } => !looped && k >= reader.len(),
        }
    }

    /// What producing frame `k` gave: `Some` value, or `None` for a dump
    /// frame that could not be read (counted and logged; the next frame sent
    /// becomes a cut). A scene's render failing is fatal (the device is
    /// gone), and so is a dump none of whose frames could be read in a row.
    fn readable<T>(
        &self,
        result: anyhow::Result<T>,
        k: u64,
        stats: &SourceStats,
        gap: &mut Gap,
    ) -> anyhow::Result<Option<T>> {
        let error = match (result, self) {
            (Ok(value), _) => return Ok(Some(value)),
            (Err(e), Producer::Scene { .. }) => return Err(e.context(format!("frame {k}"))),
            (Err(e), Producer::Dump { .. }) => e,
        };
        let n = self.len();
        stats.unreadable.fetch_add(1, Ordering::Relaxed);
        gap.run += 1;
        gap.cut_next = true;
        tracing::warn!("dump frame {} left out: {error:#}", k % n);
        anyhow::ensure!(gap.run < n, "no frame of the dump could be read: {error:#}");
        Ok(None)
    }

    fn run(
        &mut self,
        frames: &Channel,
        coders: Coders<'_>,
        stats: &SourceStats,
        stop: &AtomicBool,
    ) -> anyhow::Result<()> {
        let Coders { buffers, mut color } = coders;
        let epoch = Instant::now();
        let mut pacer = Pacer::new(1.0);
        let mut k = 0u64;
        // A dump frame that cannot be read is left out, and the frame sent
        // after it is a cut (as `import` does): the client must not blend
        // across the gap. A dump whose every frame fails in a row stops.
        let mut gap = Gap::default();
        // The last frame sent: the quantised codecs code motion against the
        // camera's motion since then (a skipped frame only makes that
        // prediction, never the result, less exact).
        let mut previous: Option<protocol::FrameMeta> = None;
        // Sessions' keyframe requests, granted at a bounded rate.
        let mut keyframes = KeyframeBudget::default();
        while !stop.load(Ordering::Relaxed) && !self.finished(k) {
            let times = self.times(k);
            let Some((t, next)) = self.readable(times, k, stats, &mut gap)? else {
                k += 1;
                continue;
            };
            match pacer.decide(epoch.elapsed(), t, next) {
                Pace::WaitUntil(at) => {
                    let wait = at
                        .saturating_sub(epoch.elapsed())
                        .min(Duration::from_millis(50));
                    std::thread::sleep(wait);
                    continue;
                }
                Pace::Skip => {
                    stats.skipped.fetch_add(1, Ordering::Relaxed);
                    self.skip(k);
                    k += 1;
                    continue;
                }
                Pace::Send => {}
            }
            let started = Instant::now();
            let frame = self.frame(k);
            let Some((mut frame, input)) = self.readable(frame, k, stats, &mut gap)? else {
                k += 1;
                continue;
            };
            gap.run = 0;
            frame.meta.cut |= std::mem::take(&mut gap.cut_next);
            if keyframes.allows(started) && frames.keyframe.take() {
                if let Some(c) = color.as_deref_mut() {
                    c.request_keyframe();
                }
            }
            let encoded = encode_frame_with(
                &frame,
                previous.as_ref(),
                buffers,
                protocol::codec::DEFAULT_ZSTD_LEVEL,
                color
                    .as_deref_mut()
                    .map(|c| c as &mut dyn ColorStreamEncoder),
            )?;
            previous = Some(frame.meta);
            // Host processing = render (or read) + encode, as a duration.
            frame.meta.host_processing =
                frame.meta.host_processing.saturating_add(started.elapsed());
            let mut encoded = encoded;
            encoded.header.meta.host_processing = frame.meta.host_processing;
            encoded.header.input = input;
            let bytes = encoded.to_stream_bytes()?;
            let buffer_bytes = encoded
                .header
                .buffers
                .iter()
                .map(|b| (b.kind, b.payload_len))
                .collect();
            let keyframe = encoded
                .header
                .buffers
                .iter()
                .zip(&encoded.payloads)
                .all(|(b, p)| b.codec != Codec::H264 || video::is_keyframe(&p.data));
            if keyframe {
                keyframes.made(started);
            }
            frames.send(Arc::new(StreamFrame {
                index: frame.meta.index,
                bytes,
                buffer_bytes,
                keyframe,
            }));
            stats.produced.fetch_add(1, Ordering::Relaxed);
            k += 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    /// A looped replay keeps time and indices increasing at the dump's rate
    /// across the jump back, and flags the jump as a cut. The dump is the
    /// Blender fixture (10 frames, 30 fps), read through the importer.
    #[test]
    fn a_looped_dump_keeps_time_running_and_cuts_at_the_seam() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/blender");
        let spec = SourceSpec::Dump { dir, looped: true };
        let mut producer = Producer::open(&spec, None).unwrap();
        let mut last: Option<f64> = None;
        for k in 0..25 {
            let (t, next) = producer.times(k).unwrap();
            let next = next.expect("a looped dump never ends");
            assert!(
                (next - t - 1.0 / 30.0).abs() < 1e-9,
                "frame {k}: {t} → {next}"
            );
            if let Some(prev) = last {
                assert!((t - prev - 1.0 / 30.0).abs() < 1e-9, "frame {k}");
            }
            last = Some(t);
            let (f, input) = producer.frame(k).unwrap();
            assert_eq!(input, None);
            assert_eq!(f.meta.index, k);
            assert!((f.meta.time - t).abs() < 1e-9);
            assert_eq!(f.meta.cut, k == 10 || k == 20, "frame {k}");
        }
        assert!(!producer.finished(1000));
    }

    /// Runs `spec` to its end and returns the frames' indices and cuts.
    fn replay(spec: &SourceSpec) -> (Vec<(u64, bool)>, SourceStats, anyhow::Result<()>) {
        let mut producer = Producer::open(spec, None).unwrap();
        let tx = Channel {
            frames: broadcast::channel(64).0,
            keyframe: KeyframeRequests::default(),
        };
        let mut rx = tx.subscribe();
        let stats = SourceStats::default();
        let buffers = StreamBuffer::default_set(protocol::Codec::Raw);
        let coders = Coders {
            buffers: &buffers,
            color: None,
        };
        let result = producer.run(&tx, coders, &stats, &AtomicBool::new(false));
        let mut sent = vec![];
        while let Ok(f) = rx.try_recv() {
            let mut decoder = protocol::wire::Decoder::new(protocol::Limits::default());
            decoder.feed(&f.bytes);
            let Ok(Some(protocol::wire::Message::FrameHeader(h))) = decoder.next_message() else {
                panic!("frame {} does not start with its header", f.index);
            };
            sent.push((h.meta.index, h.meta.cut));
        }
        (sent, stats, result)
    }

    /// A frame of a replayed dump that cannot be read is left out and
    /// counted, the stream goes on, and the next frame is a cut (issue 18
    /// §4); a dump none of whose frames can be read stops with an error.
    #[test]
    fn an_unreadable_dump_frame_is_left_out_and_the_next_is_a_cut() {
        let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/blender");
        let dir = tempfile::tempdir().unwrap();
        for entry in std::fs::read_dir(&fixture).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, dir.path().join(path.file_name().unwrap())).unwrap();
        }
        // Frame 3 (0004.exr) truncated to half, frame 6 replaced by text.
        let bytes = std::fs::read(dir.path().join("0004.exr")).unwrap();
        std::fs::write(dir.path().join("0004.exr"), &bytes[..bytes.len() / 2]).unwrap();
        std::fs::write(dir.path().join("0007.exr"), b"not an EXR").unwrap();
        let spec = SourceSpec::Dump {
            dir: dir.path().into(),
            looped: false,
        };
        let (sent, stats, result) = replay(&spec);
        result.unwrap();
        let expect: Vec<(u64, bool)> = [0, 1, 2, 4, 5, 7, 8, 9]
            .into_iter()
            .map(|i| (i, i == 4 || i == 7))
            .collect();
        assert_eq!(sent, expect);
        assert_eq!(stats.unreadable.load(Ordering::Relaxed), 2);
        assert_eq!(stats.produced.load(Ordering::Relaxed), 8);

        // Every frame unreadable: an error, not an endless loop.
        for i in 1..=10 {
            std::fs::write(dir.path().join(format!("{i:04}.exr")), b"").unwrap();
        }
        let looped = SourceSpec::Dump {
            dir: dir.path().into(),
            looped: true,
        };
        let (sent, stats, result) = replay(&looped);
        assert!(sent.is_empty());
        let error = format!("{:#}", result.unwrap_err());
        assert!(error.contains("no frame of the dump"), "{error}");
        assert_eq!(stats.unreadable.load(Ordering::Relaxed), 10);
    }
}
