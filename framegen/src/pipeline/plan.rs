//! The generation plan (issue 17): the stages a generator runs for its
//! settings and the stream's [`Effects`], as the renderer builds only the
//! passes a scene's effects call for.
//!
//! * No moving shading (no moving light, no shadow of a moving object) ⇒
//!   no shading correction: geometry-aware warping already carries the
//!   shading with its surface (GFFE §4.4 corrects what it cannot).
//! * No dynamic objects ⇒ no trajectories: every surface is static, its
//!   position at α is its current one, and the history keeps one plane
//!   (`k = 1`: positions and the static test, which still detects cuts and
//!   confirms the background) — camera-only reprojection of the static
//!   history. Pixels that fail the static test in such a stream are
//!   silhouette noise (motion and depth from different surfaces), which a
//!   trajectory would only extrapolate wrongly.
//!
//! The plan is not a second copy of the pipeline: [`Plan::of`] runs the
//! pipeline's own [`super::ingest`] and [`super::generate`] on a recording
//! executor, so the passes it lists are the ones those functions call, in
//! their order, for a frame that continues its history.

use std::sync::Arc;

use bytemuck::Zeroable;
use protocol::Effects;

use super::{Executor, IngestPlan, Job, Pass};
use crate::FramegenError;
use crate::input::Prepared;
use crate::output::{DisplayMap, Output};
use crate::passes::common::camera::PassCamera;
use crate::passes::common::crop::Crop;
use crate::passes::common::levels::Levels;
use crate::settings::{Method, Settings};

/// What a generator runs, decided once from its settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The method.
    pub method: Method,
    /// The stream's effects the plan was made for.
    pub effects: Effects,
    /// History planes tracked (`k`; 1 = positions and the static test
    /// only, 0 = none).
    pub history: u32,
    /// Background levels collected (`L`).
    pub background_levels: u32,
    /// Whether shading correction runs.
    pub shading: bool,
    /// The passes ingesting a rendered frame runs, upload aside.
    pub ingest: Vec<Pass>,
    /// The passes each generated frame runs, read-back aside.
    pub generate: Vec<Pass>,
}

impl Plan {
    /// The plan of a generator with `settings`, for a rendered frame that
    /// continues its history (after a restart, interpolation shows the
    /// frame as it is and shading correction has nothing to continue).
    pub fn of(settings: &Settings) -> Self {
        let ingest_plan = IngestPlan {
            camera: PassCamera::zeroed(),
            prev: Some(PassCamera::zeroed()),
            follows: true,
            k: settings.effective_history(),
            epsilon: settings.static_epsilon,
            levels: Levels::new(settings.effective_levels(), 1, 1),
            tolerance: settings.depth_tolerance,
            shading: settings.effective_shading(),
            planes: settings.warps_catmull_rom(),
        };
        let job = Job {
            method: settings.method,
            target: PassCamera::zeroed(),
            current: PassCamera::zeroed(),
            alpha: 0.5,
            k: ingest_plan.k,
            map: DisplayMap {
                offset: glam::Vec2::ZERO,
                scale: glam::Vec2::ONE,
            },
            bg_target: ingest_plan.levels,
            bg_source: ingest_plan.levels,
            pushpull: settings.pushpull_levels,
            crop: Crop {
                source: (1, 1),
                origin: glam::Vec2::ZERO,
                extent: glam::Vec2::ONE,
                output: (1, 1),
            },
            resample: settings.resample,
            shading: ingest_plan.shading,
        };
        let mut recorder = Recorder::default();
        let frame = Arc::new(Prepared::empty());
        // The recorder fails nothing: every pass only records its name.
        let _ = super::ingest(&mut recorder, &frame, &ingest_plan);
        let ingest = std::mem::take(&mut recorder.passes);
        let _ = super::generate(&mut recorder, &job);
        Self {
            method: settings.method,
            effects: settings.effects,
            history: ingest_plan.k,
            background_levels: ingest_plan.levels.count,
            shading: ingest_plan.shading,
            ingest,
            generate: recorder.passes,
        }
    }

    /// Every pass, ingest first.
    pub fn passes(&self) -> impl Iterator<Item = Pass> + '_ {
        self.ingest.iter().chain(&self.generate).copied()
    }

    /// Pass names joined by spaces.
    fn names(passes: &[Pass]) -> String {
        let names: Vec<&str> = passes.iter().map(|p| p.name()).collect();
        names.join(" ")
    }
}

impl std::fmt::Display for Plan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} for a stream with {}: ", self.method, self.effects)?;
        if self.method.descriptor().history == crate::method::History::Chain {
            match self.history {
                1 => write!(f, "camera-only history (no trajectories), ")?,
                k => write!(f, "trajectories of k = {k}, ")?,
            }
            write!(f, "L = {} background levels, ", self.background_levels)?;
            let on = if self.shading { "on" } else { "off" };
            write!(f, "shading correction {on}; ")?;
        }
        write!(
            f,
            "ingest: [{}], each generated frame: [{}]",
            Self::names(&self.ingest),
            Self::names(&self.generate)
        )
    }
}

/// An executor that runs nothing and records which pass each call asks
/// for.
#[derive(Default)]
struct Recorder {
    passes: Vec<Pass>,
}

impl Recorder {
    fn record(&mut self, pass: Pass) -> Result<(), FramegenError> {
        self.passes.push(pass);
        Ok(())
    }
}

impl Executor for Recorder {
    fn upload(&mut self, _: &Arc<Prepared>, _: &IngestPlan) -> Result<(), FramegenError> {
        Ok(())
    }
    fn history(&mut self, _: &IngestPlan) -> Result<(), FramegenError> {
        self.record(Pass::History)
    }
    fn background(&mut self, _: &IngestPlan) -> Result<(), FramegenError> {
        self.record(Pass::Background)
    }
    fn shading(&mut self, _: &IngestPlan) -> Result<(), FramegenError> {
        self.record(Pass::Shading)
    }
    fn ingested(&mut self) -> Result<u32, FramegenError> {
        Ok(0)
    }
    fn begin(&mut self, _: &Job) -> Result<(), FramegenError> {
        Ok(())
    }
    fn has_previous(&self) -> bool {
        true
    }
    fn crop(&mut self, _: &Crop, _: bool) -> Result<(), FramegenError> {
        self.record(Pass::Crop)
    }
    fn shade(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Shade)
    }
    fn motion(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Motion)
    }
    fn warp(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Warp)
    }
    fn bgfill(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::BgFill)
    }
    fn pushpull(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Holes)
    }
    fn reproject(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Reproject)
    }
    fn resolve(&mut self, _: &Job) -> Result<(), FramegenError> {
        self.record(Pass::Resolve)
    }
    fn finish(&mut self) -> Result<Output, FramegenError> {
        Ok(Output::empty(0, 0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(method: Method, effects: Effects) -> Plan {
        Plan::of(&Settings {
            effects,
            ..Settings::for_method(method)
        })
    }

    #[test]
    fn gffe_runs_only_what_the_effects_call_for() {
        let all = plan(Method::Gffe, Effects::UNKNOWN);
        assert_eq!(all.history, 2);
        assert!(all.shading);
        assert_eq!(all.ingest, [Pass::History, Pass::Background, Pass::Shading]);
        assert_eq!(
            all.generate,
            [
                Pass::Shade,
                Pass::Motion,
                Pass::Warp,
                Pass::BgFill,
                Pass::Holes
            ]
        );
        let still = plan(Method::Gffe, Effects::STATIC);
        assert_eq!(still.history, 1);
        assert!(!still.shading);
        assert_eq!(still.ingest, [Pass::History, Pass::Background]);
        assert_eq!(
            still.generate,
            [Pass::Motion, Pass::Warp, Pass::BgFill, Pass::Holes]
        );
        let lit = plan(
            Method::Gffe,
            Effects {
                dynamic_objects: false,
                moving_shading: true,
            },
        );
        assert_eq!((lit.history, lit.shading), (1, true));
        assert!(lit.to_string().contains("camera-only history"), "{lit}");
    }

    #[test]
    fn the_baselines_do_not_depend_on_the_effects() {
        for method in [Method::Repeat, Method::Reproject, Method::Interp] {
            let (a, b) = (
                plan(method, Effects::UNKNOWN),
                plan(method, Effects::STATIC),
            );
            assert_eq!(
                (a.history, &a.ingest, &a.generate),
                (b.history, &b.ingest, &b.generate)
            );
            assert!(!a.shading);
        }
        assert_eq!(
            plan(Method::Repeat, Effects::UNKNOWN).generate,
            [Pass::Crop]
        );
        assert_eq!(
            plan(Method::Interp, Effects::UNKNOWN).generate,
            [Pass::Reproject, Pass::Holes, Pass::Resolve]
        );
    }
}
