//! The CPU reference backend: the passes' plain Rust references, run in
//! order. Slow, simple, and the yardstick the wgpu backend is tested
//! against.

use std::sync::Arc;
use std::time::Instant;

use crate::FramegenError;
use crate::input::Prepared;
use crate::output::Output;
use crate::passes::common::levels::Levels;
use crate::passes::common::splat;
use crate::passes::common::{crop, pushpull};
use crate::passes::gffe::{background, bgfill, history, motion, warp};
use crate::passes::interp::{reproject, resolve};
use crate::pipeline::{Backend, IngestPlan, Job, Pass, PassTime, Snapshot};
use crate::settings::Method;

/// One ingested frame.
#[derive(Clone, Debug)]
struct FrameState {
    camera: crate::passes::common::camera::PassCamera,
    frame: Arc<Prepared>,
    history: history::History,
    k: u32,
    levels: Levels,
    background: Vec<background::Texel>,
}

/// The CPU reference backend.
#[derive(Debug, Default)]
pub struct CpuBackend {
    current: Option<FrameState>,
    /// The frame before `current` (interpolation's α = 0).
    previous: Option<FrameState>,
    timings: Vec<PassTime>,
}

fn timed<T>(timings: &mut Vec<PassTime>, pass: Pass, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    timings.push(PassTime {
        pass,
        time: start.elapsed(),
        gpu: None,
    });
    out
}

impl Backend for CpuBackend {
    fn ingest(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<u32, FramegenError> {
        self.timings.clear();
        let t = &mut self.timings;
        let prev = if plan.prev.is_some() {
            self.current.take()
        } else {
            None
        };
        let prev_history = prev.as_ref().zip(plan.prev).and_then(|(p, camera)| {
            (p.k == plan.k).then_some(history::PrevHistory {
                camera,
                positions: &p.history.positions,
                track: &p.history.track,
            })
        });
        // k = 0 (repeat): nothing to track or collect.
        let hist = if plan.k == 0 {
            history::History {
                positions: Vec::new(),
                track: Vec::new(),
                dynamic: 0,
            }
        } else {
            timed(t, Pass::History, || {
                history::track(
                    &plan.camera,
                    &frame.depth,
                    &frame.motion,
                    prev_history,
                    plan.k,
                    plan.epsilon,
                    plan.tolerance,
                )
            })
        };
        let n = frame.depth.len();
        let prev_bg = prev
            .as_ref()
            .zip(plan.prev)
            .map(|(p, camera)| background::PrevBackground {
                camera,
                levels: p.levels,
                texels: &p.background,
            });
        let bg = if plan.k == 0 {
            Vec::new()
        } else {
            timed(t, Pass::Background, || {
                background::collect(
                    &plan.camera,
                    &hist.positions[..n],
                    &hist.track,
                    &frame.color,
                    plan.levels,
                    prev_bg,
                    plan.tolerance,
                )
            })
        };
        let dynamic = hist.dynamic;
        self.previous = prev;
        self.current = Some(FrameState {
            camera: plan.camera,
            frame: frame.clone(),
            history: hist,
            k: plan.k,
            levels: plan.levels,
            background: bg,
        });
        Ok(dynamic)
    }

    fn generate(&mut self, job: &Job) -> Result<Output, FramegenError> {
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        let t = &mut self.timings;
        t.retain(|p| matches!(p.pass, Pass::History | Pass::Background));
        if job.method == Method::Interp {
            return Ok(interpolate(cur, self.previous.as_ref(), job, t));
        }
        if job.method == Method::Repeat {
            let mut out = timed(t, Pass::Crop, || {
                crop::crop(
                    &cur.frame.color,
                    &cur.frame.depth,
                    &cur.frame.motion,
                    &job.crop,
                )
            });
            out.motion.iter_mut().for_each(|m| *m = [0.0; 2]);
            return Ok(out);
        }
        let next = timed(t, Pass::Motion, || {
            motion::estimate(&cur.history.positions, &cur.history.track, cur.k, job.alpha)
        });
        let mut out = timed(t, Pass::Warp, || {
            let cands = warp::project(&next, &job.target);
            let winners =
                splat::resolve(&cands, (job.target.width() * job.target.height()) as usize);
            let mut out = Output::empty(job.target.width(), job.target.height());
            warp::resolve(
                &winners,
                &cur.frame.color,
                cur.camera.width(),
                job.map,
                &mut out,
            );
            warp::close_cracks(&mut out);
            out
        });
        if cur.levels.count > 0 && job.bg_target.count == cur.levels.count {
            timed(t, Pass::BgFill, || {
                let cands =
                    bgfill::project(&cur.background, cur.levels, &job.target, job.bg_target);
                let winners = splat::resolve(&cands, job.bg_target.total() as usize);
                bgfill::resolve(
                    &winners,
                    &cur.background,
                    job.bg_target,
                    &cur.camera,
                    job.map,
                    &mut out,
                );
            });
        }
        timed(t, Pass::Holes, || pushpull::fill(&mut out, job.pushpull));
        Ok(out)
    }

    fn reset(&mut self) {
        self.current = None;
        self.previous = None;
    }

    fn timings(&self) -> Vec<PassTime> {
        self.timings.clone()
    }

    fn name(&self) -> String {
        "cpu".into()
    }

    fn snapshot(&self) -> Result<Option<Snapshot>, FramegenError> {
        Ok(self.current.as_ref().map(|c| Snapshot {
            positions: c.history.positions.clone(),
            track: c.history.track.clone(),
            background: c.background.clone(),
        }))
    }
}

/// GeoMotionGen between `previous` and `current` (module `interp`). Without
/// a previous frame of the same size (first frame, restart, size change)
/// the current frame is shown as it is.
fn interpolate(
    cur: &FrameState,
    previous: Option<&FrameState>,
    job: &Job,
    t: &mut Vec<PassTime>,
) -> Output {
    let (w, h) = (cur.camera.width(), cur.camera.height());
    let f = &cur.frame;
    let Some(prev) = previous.filter(|p| p.frame.depth.len() == f.depth.len()) else {
        let identity = crop::Crop {
            source: (w, h),
            origin: glam::Vec2::ZERO,
            extent: glam::Vec2::new(w as f32, h as f32),
            output: (w, h),
        };
        return timed(t, Pass::Crop, || {
            crop::crop(&f.color, &f.depth, &f.motion, &identity)
        });
    };
    let mut out = timed(t, Pass::Reproject, || {
        let uv = reproject::normalize(&f.motion, w, h);
        let cands = reproject::project(&uv, &f.depth, w, h, job.alpha);
        let winners = splat::resolve(&cands, f.depth.len());
        let mut out = Output::empty(w, h);
        reproject::merge(&winners, &uv, &f.depth, &mut out);
        out
    });
    timed(t, Pass::Holes, || pushpull::fill(&mut out, job.pushpull));
    timed(t, Pass::Resolve, || {
        let (current, previous) = (
            resolve::Image {
                color: &cur.frame.color,
                depth: &cur.frame.depth,
            },
            resolve::Image {
                color: &prev.frame.color,
                depth: &prev.frame.depth,
            },
        );
        resolve::resolve(&mut out, current, previous, job.alpha);
    });
    out
}
