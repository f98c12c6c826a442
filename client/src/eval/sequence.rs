//! Where `eval` gets its frames: a dump rendered at the display rate, or a
//! built-in (or RON) scene rendered on the fly by the server's renderer,
//! the same frames `server record` would write. Frames are streamed, never
//! all held: a 300-frame 720p dump does not fit in memory comfortably.
//!
//! Each step yields the frame to *feed* (rendered with the variant group's
//! adaptive window) and the ground *truth* to compare with (the plain
//! frame of the displayed view; the same frame when no window is used).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use protocol::dump::DumpReader;
use protocol::wire::WindowMode;
use protocol::{Frame, FrameSize};
use scene::Scene;
use scene::render::{Renderer, WindowSettings};

/// What to evaluate on.
#[derive(Clone, Debug, PartialEq)]
pub enum Input {
    /// A scene (`builtin:NAME` or a RON file), rendered at `fps`.
    Scene(String),
    /// A dump rendered at the display rate.
    Dump(PathBuf),
}

impl Input {
    /// Name in the report.
    pub fn name(&self) -> String {
        match self {
            Input::Scene(s) => s.strip_prefix("builtin:").unwrap_or(s).to_string(),
            Input::Dump(d) => d
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| d.display().to_string()),
        }
    }
}

impl Input {
    /// What a stream of it does: a scene's from its file, a dump's from its
    /// manifest (unknown, every stage, where the manifest does not say).
    pub fn effects(&self) -> anyhow::Result<framegen::Effects> {
        Ok(match self {
            Input::Scene(spec) => Scene::load(spec)
                .with_context(|| format!("scene {spec}"))?
                .stream_effects(),
            Input::Dump(dir) => DumpReader::open(dir)
                .with_context(|| format!("dump {}", dir.display()))?
                .manifest()
                .effects
                .unwrap_or_default(),
        })
    }
}

/// One step of a sequence: the frame to feed and the ground truth.
#[derive(Clone)]
pub struct Step {
    /// Rendered with the window (what a server would stream).
    pub fed: Arc<Frame>,
    /// The plain frame of the displayed view.
    pub truth: Arc<Frame>,
}

/// A stream of [`Step`]s.
pub struct Sequence {
    source: Source,
    next: u64,
    end: u64,
    fps: f64,
    /// Render time of every fed frame, ms (`FrameMeta::host_processing`).
    render_ms: Vec<f64>,
}

enum Source {
    Rendered {
        plain: Box<Renderer>,
        windowed: Option<Box<Renderer>>,
    },
    Dump(DumpReader),
}

impl Sequence {
    /// Frames `start..start + count` of `input` at `size` and `fps` (a
    /// dump keeps its own size and rate), rendered with `window`.
    pub fn open(
        input: &Input,
        size: FrameSize,
        fps: f64,
        window: WindowMode,
        start: u64,
        count: u64,
    ) -> anyhow::Result<Self> {
        match input {
            Input::Scene(spec) => {
                let renderer = || -> anyhow::Result<Box<Renderer>> {
                    let scene = Scene::load(spec).with_context(|| format!("scene {spec}"))?;
                    Ok(Box::new(Renderer::new(
                        scene,
                        size,
                        std::path::Path::new("."),
                    )?))
                };
                let windowed = if window == WindowMode::Off {
                    None
                } else {
                    let mut r = renderer()?;
                    r.set_window(WindowSettings {
                        mode: window,
                        ..WindowSettings::default()
                    });
                    Some(r)
                };
                Ok(Self {
                    source: Source::Rendered {
                        plain: renderer()?,
                        windowed,
                    },
                    next: start,
                    end: start + count,
                    fps,
                    render_ms: Vec::new(),
                })
            }
            Input::Dump(dir) => {
                let reader =
                    DumpReader::open(dir).with_context(|| format!("dump {}", dir.display()))?;
                let len = reader.len();
                anyhow::ensure!(
                    start < len,
                    "the dump has {len} frames; --start {start} is past it"
                );
                let fps = reader.manifest().fps;
                Ok(Self {
                    source: Source::Dump(reader),
                    next: start,
                    end: (start + count).min(len),
                    fps,
                    render_ms: Vec::new(),
                })
            }
        }
    }

    /// Steps this sequence yields.
    pub fn len(&self) -> u64 {
        self.end.saturating_sub(self.next)
    }

    /// Whether it yields nothing.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The display rate (frames per second of the sequence).
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// What rendering one fed frame cost: the median of the frames yielded
    /// so far, measured in this run for scenes (submit + readback, as
    /// `server record` reports it), or as recorded in the dump. `None`
    /// before the first step.
    pub fn render_cost(&self) -> Option<RenderCost> {
        (!self.render_ms.is_empty()).then(|| RenderCost {
            ms: super::timing::median(&self.render_ms),
            frames: self.render_ms.len(),
            origin: match self.source {
                Source::Rendered { .. } => RenderOrigin::ThisRun,
                Source::Dump(_) => RenderOrigin::Recorded,
            },
        })
    }

    /// Frame `index` to feed as a server rendering every `step`th displayed
    /// frame renders it: its motion points `step` frames back, to the
    /// previous frame that server rendered (so a stream's motion costs
    /// what it costs live), and a cut between the two shows as one.
    /// `None` for a dump, whose frames were rendered at the display rate
    /// only (their motion is composed instead, [`framegen::decimate`]), or
    /// for `step` ≤ 1. Not counted in the render cost (a live server
    /// renders each frame once).
    pub fn render_fed(&mut self, index: u64, step: usize) -> anyhow::Result<Option<Frame>> {
        let Source::Rendered { plain, windowed } = &mut self.source else {
            return Ok(None);
        };
        if step <= 1 {
            return Ok(None);
        }
        let renderer = windowed.as_mut().unwrap_or(plain);
        let step = step as u64;
        let time = |k: u64| k as f64 / self.fps;
        let back = index.saturating_sub(step);
        let frame = renderer.render_at(
            index,
            time(index),
            time(back),
            time(back.saturating_sub(step)),
        )?;
        Ok(Some(frame))
    }

    /// Displayed frame `index` (plain, as its truth) with the lights and
    /// shadows of time `shading_t`: what a perfect shading correction
    /// changes a frame generated from one rendered at `shading_t` by is the
    /// change from this to the truth. `None` for a dump. Not counted in the
    /// render cost.
    pub fn render_shaded(&mut self, index: u64, shading_t: f64) -> anyhow::Result<Option<Frame>> {
        let Source::Rendered { plain, .. } = &mut self.source else {
            return Ok(None);
        };
        let time = |k: u64| k as f64 / self.fps;
        let frame = plain.render_shaded_at(
            index,
            [
                time(index),
                time(index.saturating_sub(1)),
                time(index.saturating_sub(2)),
            ],
            shading_t,
        )?;
        Ok(Some(frame))
    }

    /// The next step, `None` at the end.
    pub fn next_step(&mut self) -> anyhow::Result<Option<Step>> {
        if self.next >= self.end {
            return Ok(None);
        }
        let i = self.next;
        self.next += 1;
        let step = match &mut self.source {
            Source::Rendered { plain, windowed } => {
                let truth = Arc::new(plain.render(i, self.fps)?);
                let fed = match windowed {
                    Some(r) => Arc::new(r.render(i, self.fps)?),
                    None => truth.clone(),
                };
                Step { fed, truth }
            }
            Source::Dump(reader) => {
                let f = Arc::new(
                    reader
                        .read_frame(i)
                        .with_context(|| format!("dump frame {i}"))?,
                );
                // A widened frame is no ground truth for the displayed view.
                anyhow::ensure!(
                    f.meta.camera.window == protocol::Window::FULL,
                    "dump frame {i} was rendered with an adaptive window ({:?}); eval needs plain \
                     frames as ground truth (record with --window off)",
                    f.meta.camera.window
                );
                Step {
                    fed: f.clone(),
                    truth: f,
                }
            }
        };
        self.render_ms
            .push(step.fed.meta.host_processing.as_secs_f64() * 1e3);
        Ok(Some(step))
    }
}

/// Where a [`RenderCost`] comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RenderOrigin {
    /// Rendered by this `eval` run, on this machine, beside the variants.
    ThisRun,
    /// The `host_processing` a dump recorded (another run, maybe another
    /// machine): a ratio against it is indicative only.
    Recorded,
}

/// The cost of rendering one fed frame of a sequence: what frame
/// generation has to be a fraction of.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RenderCost {
    /// Median ms per frame.
    pub ms: f64,
    /// Frames measured.
    pub frames: usize,
    /// Where the number comes from.
    pub origin: RenderOrigin,
}
