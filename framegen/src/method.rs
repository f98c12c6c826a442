//! What a method is, for everything outside its passes: how the presenter
//! schedules it, which α it accepts and where α is measured from, how many
//! rendered frames it holds back, what it tracks. One [`Descriptor`] per
//! method replaces checks of "is this interpolation?" spread over the
//! generator, the presenter and `eval` (DESIGN §2, `method.rs`).

use crate::passes::common::resample::Resample;
use crate::schedule::Policy;

/// A frame generation method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Show the last rendered frame again (DESIGN §6).
    Repeat,
    /// Camera-only reprojection with depth (timewarp / ASW style): no
    /// object motion, no background layers; holes are push-pull filled.
    Reproject,
    /// G-buffer-free frame extrapolation, GFFE §4.1–4.3.
    Gffe,
    /// GeoMotionGen interpolation between the previous and the current
    /// rendered frame (seed 003); α ∈ [0, 1], adds latency.
    Interp,
}

impl Method {
    /// What the method is, for everything outside its passes.
    pub const fn descriptor(self) -> &'static Descriptor {
        match self {
            Method::Repeat => &REPEAT,
            Method::Reproject => &REPROJECT,
            Method::Gffe => &GFFE,
            Method::Interp => &INTERP,
        }
    }

    /// Every method, baselines first.
    pub const ALL: [Method; 4] = [
        Method::Repeat,
        Method::Reproject,
        Method::Gffe,
        Method::Interp,
    ];

    /// The extrapolating methods (no added latency), baselines first.
    pub const EXTRAPOLATING: [Method; 3] = [Method::Repeat, Method::Reproject, Method::Gffe];

    /// The name used on command lines and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Repeat => "repeat",
            Method::Reproject => "reproject",
            Method::Gffe => "gffe",
            Method::Interp => "interp",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown method {s:?} (repeat, reproject, gffe, interp)"))
    }
}

/// What per-pixel history a method tracks on ingest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum History {
    /// Nothing (repeat only crops).
    None,
    /// Every pixel's position (`k = 1`): camera-only warps, the static test
    /// for cut detection.
    Positions,
    /// GFFE's `k`-long trajectories (Alg. 1).
    Chain,
}

/// Where a method's α is measured from and how far it goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaRange {
    /// From the newest rendered frame forward, up to the settings' largest
    /// α (extrapolation: no added latency).
    Ahead,
    /// From the rendered frame before the newest (α = 0) to the newest
    /// (α = 1): interpolation, one render interval behind.
    Between,
}

/// What a method is ([`Method::descriptor`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Descriptor {
    /// How the presenter fills display slots with it.
    pub policy: Policy,
    /// α's origin and range.
    pub alpha: AlphaRange,
    /// Rendered frames held back before display (interpolation needs the
    /// next frame: DESIGN §6); also the render intervals of added latency.
    pub held_back: u32,
    /// What ingest tracks.
    pub history: History,
    /// Whether it collects GFFE's background layers (§4.2).
    pub background: bool,
    /// Whether it generates on the rendered grid (its window included)
    /// rather than the displayed view.
    pub rendered_grid: bool,
    /// Its default colour filter ([`crate::Settings::resample`]), the one
    /// that measured best for it in `eval` (README, "colour filter").
    pub resample: Resample,
}

impl Descriptor {
    /// The largest α accepted, given the settings' largest extrapolation.
    pub fn max_alpha(&self, extrapolation_limit: f64) -> f64 {
        match self.alpha {
            AlphaRange::Ahead => extrapolation_limit,
            AlphaRange::Between => 1.0,
        }
    }

    /// α in render intervals after the newest rendered frame (eq. 2's α):
    /// α itself ahead, α − 1 between the last two frames.
    pub fn along(&self, alpha: f64) -> f64 {
        match self.alpha {
            AlphaRange::Ahead => alpha,
            AlphaRange::Between => alpha - 1.0,
        }
    }
}

const REPEAT: Descriptor = Descriptor {
    policy: Policy::Repeat,
    alpha: AlphaRange::Ahead,
    held_back: 0,
    history: History::None,
    background: false,
    rendered_grid: false,
    resample: Resample::CatmullRom,
};

const REPROJECT: Descriptor = Descriptor {
    policy: Policy::Extrapolate,
    alpha: AlphaRange::Ahead,
    held_back: 0,
    history: History::Positions,
    background: false,
    rendered_grid: false,
    resample: Resample::CatmullRom,
};

const GFFE: Descriptor = Descriptor {
    policy: Policy::Extrapolate,
    alpha: AlphaRange::Ahead,
    held_back: 0,
    history: History::Chain,
    background: true,
    rendered_grid: false,
    resample: Resample::CatmullRom,
};

const INTERP: Descriptor = Descriptor {
    policy: Policy::Interpolate,
    alpha: AlphaRange::Between,
    held_back: 1,
    history: History::Positions,
    background: false,
    rendered_grid: true,
    // Over the 11 built-in scenes (320×180, CPU) the two-sided resolve
    // scores mean ꟻLIP 0.0263 with the nearest pixel of each frame, 0.0275
    // with Catmull-Rom and 0.0285 bilinear (nearest best on 9 of 11, tied on
    // `moving_light`, worse on `pan`):
    // blending two frames whose sub-pixel phases differ already averages,
    // and a reconstruction filter on each side blurs on top of it.
    resample: Resample::Nearest,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_alone_holds_a_frame_back_and_lives_in_0_to_1() {
        for m in Method::ALL {
            let d = m.descriptor();
            let interp = m == Method::Interp;
            assert_eq!(d.held_back, u32::from(interp), "{m}");
            assert_eq!(d.max_alpha(3.0), if interp { 1.0 } else { 3.0 }, "{m}");
            assert_eq!(d.along(0.5), if interp { -0.5 } else { 0.5 }, "{m}");
            assert_eq!(d.policy == Policy::Interpolate, interp, "{m}");
            assert_eq!(Method::EXTRAPOLATING.contains(&m), !interp, "{m}");
        }
        assert_eq!(Method::Repeat.descriptor().history, History::None);
    }
}
