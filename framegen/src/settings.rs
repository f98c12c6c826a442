//! What a [`crate::FrameGenerator`] does and with which trade-offs; every
//! field is one of the knobs the `eval` report sweeps (DESIGN §9).

use protocol::Effects;

use crate::FramegenError;
use crate::method::History;
pub use crate::method::Method;
pub use crate::passes::common::resample::Resample;
use crate::passes::gffe::background::MAX_LEVELS;
use crate::passes::gffe::history::MAX_HISTORY;
use crate::pipeline::plan::Plan;

/// Settings of a generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// The method.
    pub method: Method,
    /// Generated frames per rendered frame: α = j / (n + 1), j = 1..=n.
    pub n: u32,
    /// History length `k` (GFFE Alg. 1), 2..=8; `gffe` only.
    pub history: u32,
    /// Background levels `L` (GFFE §4.2), 0..=4; `gffe` only.
    pub background_levels: u32,
    /// Static-test threshold ε in pixels (Alg. 1). `eval` over the 11
    /// built-in scenes at 320×180 prefers 2 (mean gffe ꟻLIP 0.0329 at 0.5,
    /// 0.0323 at 2, 0.0326 at 4): at silhouettes a pixel's motion and depth
    /// come from different surfaces and disagree by a pixel or so, and a
    /// tight ε takes them for moving objects. But a threshold in pixels
    /// also takes every object slower than ε per frame for still: at 96×54
    /// `crossing`'s objects move 1–2 px per frame and with ε = 2 gffe is
    /// exactly `repeat` there. The default stays 0.5; the silhouette noise
    /// wants a test that knows about silhouettes, not a looser threshold.
    pub static_epsilon: f32,
    /// Relative depth margin for "deeper" in background case 2.
    pub depth_tolerance: f32,
    /// Push-pull pyramid levels for the remaining holes (≥ 1; capped at
    /// the frame's full depth). The default, [`Settings::FULL_PYRAMID`],
    /// goes down to 1×1, so a hole of any width is filled: GeoMotionGen's
    /// 7 levels (128 px cells) left holes wider than ~512 px black, e.g. at
    /// 8192×16 under a fast turn. The extra levels are tiny.
    pub pushpull_levels: u32,
    /// A frame whose share of dynamic pixels exceeds this is treated as a
    /// camera cut (history and background restart). > 1 disables it.
    pub cut_dynamic_fraction: f32,
    /// Largest α accepted (extrapolating far beyond one interval is the
    /// scheduler's call, up to this limit).
    pub max_alpha: f64,
    /// The displayed size, when the stream's adaptive window keeps the
    /// rendered size (`KeepSize`); `None` derives it from the window.
    pub display_size: Option<(u32, u32)>,
    /// How a generated pixel takes its colour from a rendered frame:
    /// resampled at the sub-pixel position the pixel maps back to
    /// (`passes/common/resample.rs`), or the nearest pixel as in the seeds'
    /// forward warp (gffe, reproject). Interpolation's resolve reads both
    /// frames with it.
    pub resample: Resample,
    /// Shading correction (GFFE §4.4, `passes/gffe/shading.rs`): the
    /// shading change from the previous frame continued to α before the
    /// warp; gffe only, and only where the stream's effects say shading
    /// moves ([`Settings::effective_shading`]).
    pub shading: bool,
    /// What the stream's content does (issue 17): the generator leaves out
    /// the stages it does not call for ([`crate::pipeline::plan::Plan`]).
    /// The default, [`Effects::UNKNOWN`], runs every stage.
    pub effects: Effects,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            method: Method::Gffe,
            n: 1,
            history: 2,
            background_levels: 2,
            static_epsilon: 0.5,
            depth_tolerance: 0.02,
            pushpull_levels: Self::FULL_PYRAMID,
            cut_dynamic_fraction: 0.9,
            max_alpha: 16.0,
            display_size: None,
            resample: Resample::CatmullRom,
            shading: true,
            effects: Effects::UNKNOWN,
        }
    }
}

impl Settings {
    /// A push-pull pyramid as deep as the frame allows (down to 1×1): the
    /// largest accepted `pushpull_levels`, capped per frame.
    pub const FULL_PYRAMID: u32 = 16;

    /// Settings for `method` with every other value at its default (the
    /// colour filter is the method's own, [`crate::Descriptor::resample`]).
    pub fn for_method(method: Method) -> Self {
        Self {
            method,
            resample: method.descriptor().resample,
            ..Self::default()
        }
    }

    /// Checks every range.
    pub fn validate(&self) -> Result<(), FramegenError> {
        let bad = |m: String| Err(FramegenError::Settings(m));
        if !(1..=16).contains(&self.n) {
            return bad(format!("n = {} must be in 1..=16", self.n));
        }
        if !(2..=MAX_HISTORY as u32).contains(&self.history) {
            return bad(format!(
                "history k = {} must be in 2..={MAX_HISTORY}",
                self.history
            ));
        }
        if self.background_levels > MAX_LEVELS {
            return bad(format!(
                "background levels L = {} must be at most {MAX_LEVELS}",
                self.background_levels
            ));
        }
        if !(self.static_epsilon.is_finite() && self.static_epsilon >= 0.0) {
            return bad("static epsilon must be finite and ≥ 0".into());
        }
        if !(self.depth_tolerance.is_finite() && self.depth_tolerance >= 0.0) {
            return bad("depth tolerance must be finite and ≥ 0".into());
        }
        if !(1..=Self::FULL_PYRAMID).contains(&self.pushpull_levels) {
            return bad("push-pull levels must be in 1..=16".into());
        }
        if self.cut_dynamic_fraction.is_nan() {
            return bad("cut fraction is NaN".into());
        }
        if !(self.max_alpha.is_finite() && self.max_alpha > 0.0) {
            return bad("max α must be finite and > 0".into());
        }
        if let Some((w, h)) = self.display_size {
            protocol::Limits::default()
                .check_size(w, h)
                .map_err(|e| FramegenError::Settings(format!("display size: {e}")))?;
        }
        Ok(())
    }

    /// `k` as the passes use it: the setting for gffe in a stream with
    /// dynamic objects; 1 (this frame's positions and the static test,
    /// which detects cuts) for gffe without them (camera-only: no
    /// trajectory to track), reproject and interp; 0 (no tracking) for
    /// repeat, which only crops.
    pub fn effective_history(&self) -> u32 {
        match self.method.descriptor().history {
            History::Chain if self.effects.dynamic_objects => self.history,
            History::Chain => 1,
            History::Positions => 1,
            History::None => 0,
        }
    }

    /// Whether shading correction runs: the setting, for gffe, in a
    /// stream whose shading moves.
    pub fn effective_shading(&self) -> bool {
        self.shading && self.method == Method::Gffe && self.effects.moving_shading
    }

    /// Whether the generated frames are warped with the Catmull-Rom filter,
    /// whose runs read the rendered colour as planes
    /// (`resample_run::Planes`): the CPU executor makes them as it takes
    /// the frame in.
    pub fn warps_catmull_rom(&self) -> bool {
        matches!(self.method, Method::Gffe | Method::Reproject)
            && self.resample == Resample::CatmullRom
    }

    /// The stages these settings run ([`Plan::of`]).
    pub fn plan(&self) -> Plan {
        Plan::of(self)
    }

    /// `L` as the passes use it: 0 for the baselines.
    pub fn effective_levels(&self) -> u32 {
        if self.method.descriptor().background {
            self.background_levels
        } else {
            0
        }
    }
}
