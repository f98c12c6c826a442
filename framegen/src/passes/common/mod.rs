//! What several methods share: the pass camera ([`camera`]), the
//! deterministic depth-tested splat ([`splat`]), push-pull hole filling
//! ([`pushpull`]), the window crop ([`crop`]), bilinear sampling
//! ([`sample`]), the warp's sub-pixel colour filter ([`resample`]) and the
//! pyramid layout ([`levels`]).

pub mod camera;
pub mod crop;
pub mod levels;
pub mod pushpull;
pub mod resample;
pub mod sample;
pub mod splat;
