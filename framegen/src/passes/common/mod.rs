//! What several methods share: the pass camera ([`camera`]), the
//! deterministic depth-tested splat ([`splat`]), push-pull hole filling
//! ([`pushpull`]), the window crop ([`crop`]), bilinear sampling
//! ([`sample`]), the warp's sub-pixel colour filter ([`resample`]), the
//! pyramid layout ([`levels`]), four pixels at a time on the CPU
//! ([`lanes`]), the rendered colour's widening after its
//! upload ([`widen`]) and the generated frame's packing for the host
//! ([`pack`]).

pub mod camera;
pub mod crop;
pub mod lanes;
pub mod levels;
pub mod pack;
pub mod pushpull;
pub mod resample;
pub mod resample_run;
pub mod sample;
pub mod splat;
pub mod widen;
