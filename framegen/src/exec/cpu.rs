//! The CPU reference executor: the passes' plain Rust references, run on
//! all cores in the order the plans of [`crate::pipeline`] give. The
//! yardstick the wgpu executor is tested against, and the fallback where
//! the only adapter is a software rasteriser.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::Instant;

use crate::FramegenError;
use crate::input::Prepared;
use crate::output::{EMPTY, Output};
use crate::passes::common::lanes::LANES;
use crate::passes::common::levels::Levels;
use crate::passes::common::pack::{self, Packed};
use crate::passes::common::resample::{Resample, Source};
use crate::passes::common::resample_run::Planes;
use crate::passes::common::splat;
use crate::passes::common::{crop, pushpull, widen};
use crate::passes::gffe::{background, bgfill, history, motion, shading, warp};
use crate::passes::interp::{reproject, resolve};
use crate::pipeline::{Backend, Executor, IngestPlan, Job, Pass, PassTime, Snapshot};

/// One ingested frame.
#[derive(Clone, Debug)]
struct FrameState {
    camera: crate::passes::common::camera::PassCamera,
    frame: Arc<Prepared>,
    /// The frame's colour widened to the `f32` the passes read (its upload,
    /// `widen`); empty until a pass needs it where nothing is tracked
    /// (`repeat`, whose still copy packs the `f16` as it is).
    color: Vec<[f32; 4]>,
    history: history::History,
    k: u32,
    levels: Levels,
    /// Its background, level 0's seeds not stored (they are `history`'s
    /// `P_0` and `frame`'s colour, [`FrameState::seeds`]), with the slots
    /// of its fragments carried over from earlier frames, which background
    /// fill projects.
    background: background::Unseeded,
    /// Shading correction's `(r_t, aligned r_{t−1})` per pixel and flow
    /// per block; empty without an estimate.
    ratio: Vec<[f32; 2]>,
    flow: Vec<[f32; 4]>,
    /// Its luminances, written by its estimate for the next one's.
    luma: Vec<f32>,
    /// Its colour as planes of one channel, for the warp's Catmull-Rom
    /// runs (`resample_run.rs`): made as the colour is widened where the
    /// plan warps with them (`IngestPlan::planes`), else at the first
    /// warp; shading correction's changes are written into them as into
    /// `color`, and undone alike.
    planes: Planes,
}

impl FrameState {
    /// What its background's level 0 is seeded with, not stored there
    /// (`background::Unseeded`): its confirmed static pixels.
    fn seeds(&self) -> background::Seeds<'_> {
        let n = self.frame.depth.len();
        background::Seeds {
            p0: self.history.positions.get(..n).unwrap_or_default(),
            track: &self.history.track,
            color: &self.frame.color,
        }
    }
}

/// A rendered frame being ingested (between `upload` and `ingested`).
#[derive(Debug)]
struct Ingest {
    /// What the frame will be once ingested (its history and background
    /// filled in by the passes).
    state: FrameState,
    /// The previous frame with its camera, when the history continues.
    prev: Option<(crate::passes::common::camera::PassCamera, FrameState)>,
    /// The frame before the previous one, no longer needed: the passes
    /// write into its buffers instead of allocating and clearing new ones.
    spare: Option<FrameState>,
    /// Whether the frame's motion points to `prev` (no gap between them).
    follows: bool,
}

/// The CPU reference backend.
#[derive(Debug, Default)]
pub struct CpuBackend {
    current: Option<FrameState>,
    /// The frame before `current` (interpolation's α = 0 when `paired`).
    previous: Option<FrameState>,
    /// Whether `current`'s motion points to `previous` (no frame between
    /// them went missing).
    paired: bool,
    timings: Vec<PassTime>,
    /// The rendered frame being ingested.
    ingest: Option<Ingest>,
    /// The generated frame being made.
    out: Option<Output>,
    /// Or, made by `repeat`'s still copy of the whole frame, the packed
    /// frame itself, with the crop it is (`crop::still_packed`).
    copied: Option<(crop::Crop, Packed)>,
    /// Whether the generated frame being made is handed over packed
    /// ([`Backend::generate_packed`]): then the warp packs it as it
    /// resolves it (`warp::resolve_packed`).
    packing: bool,
    /// That packing, with the holes the resolve left, the only pixels the
    /// passes after it write: packed again at the end (`pack::repack`).
    packed: Option<(Packed, Vec<usize>)>,
    /// GFFE's α, between `motion` and `warp`: eq. 1 is evaluated per
    /// pixel inside the warp's projection, so no frame of positions at α
    /// is stored.
    motion: Option<f32>,
    /// Where each source pixel landed in the last warp (the bits of its
    /// continuous target position), for the resampling filter; kept from
    /// frame to frame.
    landings: Vec<AtomicU64>,
    /// The pixels shading correction changed in the current frame's colour
    /// for the warp of the generated frame being made, with the colours
    /// they had: put back after the warp ([`CpuBackend::restore`]), so
    /// the colour is the rendered one again for the next generated frame.
    undo: Vec<(u32, [f32; 4])>,
    /// Push-pull's maps of the texels it made, kept between frames.
    holes: pushpull::Scratch,
    /// The splat slots of background collection and background fill,
    /// empty between passes.
    sparse: splat::Sparse,
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
        crate::pipeline::ingest(self, frame, plan)
    }

    fn generate(&mut self, job: &Job) -> Result<Output, FramegenError> {
        crate::pipeline::generate(self, job)
    }

    /// Packs the `f32` frame the passes made, which it hands over too; a
    /// still copy made packed is handed over as it is, without an `f32`
    /// frame.
    fn generate_packed(&mut self, job: &Job) -> Result<(Packed, Option<Output>), FramegenError> {
        self.packing = true;
        let passes = crate::pipeline::passes(self, job);
        self.packing = false;
        passes?;
        if let Some((_, packed)) = self.copied.take() {
            return Ok((packed, None));
        }
        let out = self.finish()?;
        let packed = match self.packed.take() {
            // Packed as the warp resolved it; the holes it left since
            // filled are packed again.
            Some((mut packed, holes)) => {
                pack::repack(&out, &mut packed, &holes);
                debug_assert!(packed == pack::pack(&out), "only holes were written");
                packed
            }
            None => pack::pack(&out),
        };
        Ok((packed, Some(out)))
    }

    fn reset(&mut self) {
        self.restore();
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
            positions: c.history.clone().expanded().positions,
            track: c.history.track.clone(),
            background: background::seeded(c.background.texels.clone(), c.seeds()),
            seen: {
                let words = c.history.seen.words();
                (0..c.history.track.len())
                    .map(|i| words.get(i).copied().unwrap_or(0))
                    .collect()
            },
        }))
    }
}

/// The frame being ingested.
fn ingesting(ingest: &mut Option<Ingest>) -> Result<&mut Ingest, FramegenError> {
    ingest.as_mut().ok_or(FramegenError::PassOrder(
        "an ingest pass ran before upload()",
    ))
}

/// A frame's colour and depth, as interpolation's resolve reads them.
fn image(s: &FrameState) -> Source<'_> {
    Source {
        color: &s.color,
        depth: &s.frame.depth,
        size: (s.camera.width(), s.camera.height()),
    }
}

impl CpuBackend {
    /// Widens the current frame's colour where its upload left it
    /// unwidened (nothing tracked).
    fn widened(&mut self) -> Result<(), FramegenError> {
        let cur = self.current.as_mut().ok_or(FramegenError::NoFrame)?;
        if cur.color.len() != cur.frame.color.len() {
            cur.color = widen::widen_into(&cur.frame.color, std::mem::take(&mut cur.color));
        }
        Ok(())
    }

    /// The ingested frame, the output being made and the timings.
    fn parts(
        &mut self,
    ) -> Result<(&FrameState, &mut Option<Output>, &mut Vec<PassTime>), FramegenError> {
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        Ok((cur, &mut self.out, &mut self.timings))
    }

    /// Puts back the colours shading correction changed in the current
    /// frame (its warp has moved them, or it did not run).
    fn restore(&mut self) {
        if let Some(cur) = self.current.as_mut() {
            for (i, c) in self.undo.drain(..) {
                cur.color[i as usize] = c;
                cur.planes.set(i as usize, c);
            }
        }
        self.undo.clear();
    }

    /// The output a previous pass of the plan made.
    fn output(out: &mut Option<Output>) -> Result<&mut Output, FramegenError> {
        out.as_mut().ok_or(FramegenError::PassOrder(
            "a pass ran before the output was made",
        ))
    }
}

impl Executor for CpuBackend {
    fn upload(&mut self, frame: &Arc<Prepared>, plan: &IngestPlan) -> Result<(), FramegenError> {
        self.restore();
        self.timings.clear();
        let prev = match plan.prev {
            Some(camera) => self.current.take().map(|p| (camera, p)),
            None => None,
        };
        let mut spare = self.previous.take();
        // Into the colour buffer of the frame before the previous one; a
        // frame nothing tracks is widened only if a crop needs it.
        let reuse = spare.as_mut().map(|s| std::mem::take(&mut s.color));
        let reuse = reuse.unwrap_or_default();
        // With its planes, where the generated frames take them (into
        // those of the frame before the previous one; never kept stale).
        let mut planes = Planes::default();
        let color = match (plan.k, plan.planes) {
            (0, _) => Vec::new(),
            (_, true) => {
                if let Some(s) = spare.as_mut() {
                    planes = std::mem::take(&mut s.planes);
                }
                widen::widen_planes_into(&frame.color, reuse, &mut planes)
            }
            (_, false) => widen::widen_into(&frame.color, reuse),
        };
        self.ingest = Some(Ingest {
            state: FrameState {
                camera: plan.camera,
                frame: frame.clone(),
                color,
                // k = 0 (repeat): nothing tracked, nothing collected.
                history: history::History::empty(),
                k: plan.k,
                levels: plan.levels,
                background: background::Unseeded::default(),
                ratio: Vec::new(),
                flow: Vec::new(),
                luma: Vec::new(),
                planes,
            },
            prev,
            spare,
            follows: plan.follows,
        });
        Ok(())
    }

    fn history(&mut self, plan: &IngestPlan) -> Result<(), FramegenError> {
        let i = ingesting(&mut self.ingest)?;
        // After a gap the motion does not reach the previous frame: the
        // history restarts.
        let prev = i.prev.as_ref().filter(|(_, p)| p.k == plan.k && i.follows);
        let prev = prev.map(|(camera, p)| history::PrevHistory {
            camera: *camera,
            positions: &p.history.positions,
            track: &p.history.track,
            depth: &p.frame.depth,
        });
        let f = &i.state.frame;
        let reuse = match i.spare.as_mut() {
            Some(spare) => std::mem::replace(&mut spare.history, history::History::empty()),
            None => history::History::empty(),
        };
        i.state.history = timed(&mut self.timings, Pass::History, || {
            let tracker = history::Tracker {
                camera: &plan.camera,
                depth: &f.depth,
                motion: &f.motion,
                prev: prev.as_ref(),
                k: plan.k,
                epsilon: plan.epsilon,
                tolerance: plan.confirm_tolerance(),
            };
            tracker.track_into(reuse)
        });
        Ok(())
    }

    fn background(&mut self, plan: &IngestPlan) -> Result<(), FramegenError> {
        let i = ingesting(&mut self.ingest)?;
        let slots = &mut self.sparse;
        let prev = i
            .prev
            .as_ref()
            .map(|(camera, p)| background::PrevBackground {
                camera: *camera,
                levels: p.levels,
                texels: &p.background.texels,
                seeds: Some(p.seeds()),
                // The seeds this frame's history saw again.
                seen: Some(&i.state.history.seen),
            });
        let reuse = match i.spare.as_mut() {
            Some(s) => std::mem::take(&mut s.background),
            None => Default::default(),
        };
        let seeds = i.state.seeds();
        i.state.background = timed(&mut self.timings, Pass::Background, || {
            let (levels, tolerance) = (plan.levels, plan.tolerance);
            let camera = &plan.camera;
            background::collect_unseeded(reuse, camera, seeds, levels, prev, tolerance, slots)
        });
        Ok(())
    }

    fn shading(&mut self, _plan: &IngestPlan) -> Result<(), FramegenError> {
        let i = ingesting(&mut self.ingest)?;
        // Only a frame whose motion reaches the previous one, at its size,
        // has a change to measure.
        let Some((_, p)) = i
            .prev
            .as_ref()
            .filter(|(_, p)| i.follows && p.frame.depth.len() == i.state.frame.depth.len())
        else {
            return Ok(());
        };
        let (f, s) = (&i.state.frame, &i.state);
        let size = (s.camera.width(), s.camera.height());
        // The planes of the frame before the previous one, written over.
        let (mut ratio, mut flow, mut luma) = match i.spare.as_mut() {
            Some(spare) => (
                std::mem::take(&mut spare.ratio),
                std::mem::take(&mut spare.flow),
                std::mem::take(&mut spare.luma),
            ),
            None => Default::default(),
        };
        timed(&mut self.timings, Pass::Shading, || {
            let cur = shading::Current {
                color: &s.color,
                depth: &f.depth,
                motion: &f.motion,
                track: &s.history.track,
                size,
                planes: s.planes.usable(s.color.len()).then(|| s.planes.rgb()),
            };
            let prev = shading::Previous {
                color: &p.color,
                depth: &p.frame.depth,
                ratio: &p.ratio,
                luma: &p.luma,
            };
            shading::ratio_into(&cur, &prev, &mut ratio, &mut luma);
            shading::flow_into(&ratio, size, &mut flow);
        });
        i.state.ratio = ratio;
        i.state.flow = flow;
        i.state.luma = luma;
        Ok(())
    }

    fn ingested(&mut self) -> Result<u32, FramegenError> {
        let i = self
            .ingest
            .take()
            .ok_or(FramegenError::PassOrder("ingested() before upload()"))?;
        let dynamic = i.state.history.dynamic;
        self.previous = i.prev.map(|(_, p)| p);
        self.paired = i.follows;
        self.current = Some(i.state);
        Ok(dynamic)
    }

    fn begin(&mut self, _job: &Job) -> Result<(), FramegenError> {
        self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        self.timings
            .retain(|p| matches!(p.pass, Pass::History | Pass::Background | Pass::Shading));
        self.out = None;
        self.copied = None;
        self.packed = None;
        self.restore();
        Ok(())
    }

    fn has_previous(&self) -> bool {
        let len = |s: &FrameState| s.frame.depth.len();
        self.paired
            && matches!((&self.current, &self.previous), (Some(c), Some(p)) if len(c) == len(p))
    }

    /// The still copy of the whole frame (`repeat`) is packed at once from
    /// the prepared frame (`crop::still_packed`, the crop and the packing
    /// fused); any other crop resamples the widened colour.
    fn crop(&mut self, c: &crop::Crop, still: bool) -> Result<(), FramegenError> {
        if still && c.is_identity() {
            let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
            let packed = timed(&mut self.timings, Pass::Crop, || {
                crop::still_packed(&cur.frame, c.source)
            });
            self.copied = Some((*c, packed));
            return Ok(());
        }
        self.widened()?;
        let (cur, out, t) = self.parts()?;
        let f = &cur.frame;
        let o = timed(t, Pass::Crop, || {
            crop::crop(&cur.color, &f.depth, &f.motion, c, still)
        });
        *out = Some(o);
        Ok(())
    }

    fn shade(&mut self, job: &Job) -> Result<(), FramegenError> {
        self.restore();
        let cur = self.current.as_mut().ok_or(FramegenError::NoFrame)?;
        if cur.ratio.is_empty() {
            // No estimate (first frame, gap): the rendered colour as it is.
            return Ok(());
        }
        let undo = &mut self.undo;
        timed(&mut self.timings, Pass::Shade, || {
            let e = shading::Estimate {
                color: &cur.color,
                track: &cur.history.track,
                ratio: &cur.ratio,
                flow: &cur.flow,
                size: (cur.camera.width(), cur.camera.height()),
            };
            // Nothing to continue: the warp moves the rendered colour.
            let changes = shading::changes(&e, job.alpha).unwrap_or_default();
            for (i, c) in changes {
                undo.push((i, std::mem::replace(&mut cur.color[i as usize], c)));
                cur.planes.set(i as usize, c);
            }
        });
        Ok(())
    }

    fn motion(&mut self, job: &Job) -> Result<(), FramegenError> {
        self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        self.motion = Some(job.alpha);
        // Fused into the warp, which times it: listed at zero so that the
        // timings name every pass the plan runs.
        timed(&mut self.timings, Pass::Motion, || ());
        Ok(())
    }

    /// Fused with eq. 1: each source pixel's position at α is computed,
    /// projected and splatted in one loop, without the frame-sized buffers
    /// of positions and candidates between them (the same winners as
    /// `motion::estimate`, `warp::project` and `splat::resolve` in turn;
    /// its time includes the motion pass).
    fn warp(&mut self, job: &Job) -> Result<(), FramegenError> {
        let cur = self.current.as_mut().ok_or(FramegenError::NoFrame)?;
        let alpha = self
            .motion
            .take()
            .ok_or(FramegenError::PassOrder("warp() before motion()"))?;
        let landings = &mut self.landings;
        let runs = job.resample == Resample::CatmullRom;
        let packing = self.packing;
        let (out, packed) = timed(&mut self.timings, Pass::Warp, || {
            // Planes the upload did not make (a plan without them): from
            // the colour as the warp takes it, shading-corrected.
            if runs && !cur.planes.usable(cur.color.len()) {
                cur.planes.fill(&cur.color);
            }
            let cur = &*cur;
            // They are that colour, shading's changes included (checked in
            // debug builds).
            debug_assert!(
                !runs || {
                    let mut fresh = Planes::default();
                    fresh.fill(&cur.color);
                    fresh == cur.planes
                }
            );
            let (w, h) = (job.target.width(), job.target.height());
            let (positions, track) = (&cur.history.positions, &cur.history.track);
            let filtered = job.resample != Resample::Nearest;
            if filtered && landings.len() != track.len() {
                *landings = (0..track.len()).map(|_| AtomicU64::new(0)).collect();
            }
            // Each landing position is kept where it is made (its own
            // element, written once, read only for winners).
            let landings = &*landings;
            let n = track.len();
            // Four at a time, projected in lanes; the last few alone.
            let winners = splat::resolve_lanes(n, 0..(w * h) as usize, |first| {
                let at = |x: usize| motion::estimate_at(positions, track, cur.k, x, alpha);
                let landed: [(splat::Candidate, glam::Vec2); LANES] = match first + LANES <= n {
                    true => {
                        warp::candidates_at4(&std::array::from_fn(|l| at(first + l)), &job.target)
                    }
                    false => std::array::from_fn(|l| match first + l < n {
                        true => warp::candidate_at(at(first + l), &job.target),
                        false => (splat::Candidate::MISS, glam::Vec2::ZERO),
                    }),
                };
                std::array::from_fn(|l| {
                    let (candidate, pixel) = landed[l];
                    if filtered && candidate.slot != splat::NONE {
                        let bits =
                            u64::from(pixel.x.to_bits()) << 32 | u64::from(pixel.y.to_bits());
                        landings[first + l].store(bits, Relaxed);
                    }
                    candidate
                })
            });
            let f = &cur.frame;
            let source = Source {
                // Shading-corrected where `shade` changed it.
                color: &cur.color,
                depth: &f.depth,
                size: (cur.camera.width(), cur.camera.height()),
            };
            let landing = |i: usize| {
                let bits = landings[i].load(Relaxed);
                glam::Vec2::new(
                    f32::from_bits((bits >> 32) as u32),
                    f32::from_bits(bits as u32),
                )
            };
            let how = warp::Resolve {
                map: job.map,
                filter: job.resample,
                size: (w, h),
            };
            // The runs filter Catmull-Rom's taps (`resample_run.rs`).
            let planes = runs.then_some(&cur.planes);
            if packing {
                let r = warp::resolve_packed(&winners, source, planes, landing, how);
                let mut out = r.out;
                warp::close_cracks_at(&mut out, &r.holes);
                return (out, Some((r.packed, r.holes)));
            }
            let mut out = match planes {
                Some(planes) => warp::resolve_runs(&winners, source, planes, landing, how),
                None => warp::resolve(&winners, source, landing, how),
            };
            warp::close_cracks(&mut out);
            (out, None)
        });
        self.restore();
        self.out = Some(out);
        self.packed = packed;
        Ok(())
    }

    fn bgfill(&mut self, job: &Job) -> Result<(), FramegenError> {
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        let out = Self::output(&mut self.out)?;
        let sparse = &mut self.sparse;
        // The warp's resolve listed its holes where it packed.
        let holes = self.packed.as_ref().map(|(_, holes)| holes.as_slice());
        timed(&mut self.timings, Pass::BgFill, || {
            let (bg, camera) = (&cur.background.texels, &cur.camera);
            let slots = 0..job.bg_target.total() as usize;
            // Only the fragments carried over from earlier frames can fill
            // a hole (`background::collect`): level 0's seeds are this
            // frame's static pixels, which land where the warp already
            // wrote (`background::seeds`).
            let layout = bgfill::Layout::new(cur.levels, job.bg_target);
            // A frame without holes has nothing to fill. Where most of the
            // background was carried over (the history restarted: 800 k
            // fragments to project at 720p) that is worth asking first.
            let carried = &cur.background.carried;
            let none = || match holes {
                Some(holes) => holes.iter().all(|&t| out.mask[t] != EMPTY),
                None => out.count(EMPTY) == 0,
            };
            if carried.len() > slots.len() / 8 && none() {
                return;
            }
            let won = sparse.take_listed(carried, slots, |ids| {
                bgfill::candidates4(ids, bg, &job.target, &layout)
            });
            let won = |slot| won.get(slot);
            bgfill::resolve_won(won, bg, job.bg_target, camera, job.map, out, holes);
        });
        Ok(())
    }

    fn pushpull(&mut self, job: &Job) -> Result<(), FramegenError> {
        self.parts()?;
        let out = Self::output(&mut self.out)?;
        let scratch = &mut self.holes;
        let resolved = self.packed.as_ref().map(|(_, holes)| holes);
        timed(&mut self.timings, Pass::Holes, || {
            // The resolve's holes that are holes still, where it listed
            // them.
            let holes = resolved.map(|h| h.iter().copied().filter(|&t| out.mask[t] == EMPTY));
            pushpull::fill_listed(out, job.pushpull, scratch, holes.map(Iterator::collect))
        });
        Ok(())
    }

    fn reproject(&mut self, job: &Job) -> Result<(), FramegenError> {
        let (cur, out, t) = self.parts()?;
        let (w, h) = (cur.camera.width(), cur.camera.height());
        let f = &cur.frame;
        // Passes 2–4 in two loops: the uv motion and the candidates are made
        // per pixel where they are used, without frame-sized buffers
        // between them (the same values as `normalize`, `project` and the
        // splat in turn).
        let o = timed(t, Pass::Reproject, || {
            let uv = |i: usize| reproject::uv(f.motion[i], w, h);
            let n = f.depth.len();
            let winners = splat::resolve_with(n, 0..n, |i| {
                reproject::candidate(i, uv(i), f.depth[i], (w, h), job.alpha)
            });
            reproject::merge(&winners, uv, &f.depth, (w, h))
        });
        *out = Some(o);
        Ok(())
    }

    fn resolve(&mut self, job: &Job) -> Result<(), FramegenError> {
        let prev = self.previous.as_ref().ok_or(FramegenError::PassOrder(
            "interpolation without a previous frame",
        ))?;
        let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
        let out = Self::output(&mut self.out)?;
        timed(&mut self.timings, Pass::Resolve, || {
            resolve::resolve(out, (image(cur), image(prev)), job.alpha, job.resample);
        });
        Ok(())
    }

    /// The `f32` frame; for a still copy made packed, the crop it stands
    /// for, made now (this API's callers, pass-level tests, want it).
    fn finish(&mut self) -> Result<Output, FramegenError> {
        if let Some((c, _)) = self.copied.take() {
            self.widened()?;
            let cur = self.current.as_ref().ok_or(FramegenError::NoFrame)?;
            let f = &cur.frame;
            return Ok(crop::crop(&cur.color, &f.depth, &f.motion, &c, true));
        }
        self.out
            .take()
            .ok_or(FramegenError::PassOrder("no generated frame was made"))
    }
}
