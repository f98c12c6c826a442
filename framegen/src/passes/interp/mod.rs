//! GeoMotionGen 1.0 interpolation (seed 003, DESIGN §5): a frame between
//! the previous rendered frame (α = 0) and the current one (α = 1) from
//! both frames' color and depth and the current frame's motion vectors
//! only. It needs the *next* frame, so it adds latency (the scheduler's
//! `Interpolate` policy accounts for it).
//!
//! | seed pass | here | |
//! |---|---|---|
//! | 1 clear | `clear_buffer` of the splat buffers | the unwritten value is 0 |
//! | 2 normalize | [`reproject::normalize`] | pixels → uv |
//! | 3 reproject | [`reproject::project`] + `crate::passes::common::splat` | depth-aware, exact |
//! | 4 merge | [`reproject::merge`] | winner → motion, depth, written |
//! | 5 pull / 6 push | [`crate::passes::common::pushpull`] | the same push-pull as GFFE's holes |
//! | 7 resolve | [`resolve`] | written → both frames where visible in both, else current; unwritten → previous |
//!
//! Choices where the seed is ambiguous or wrong, each tested:
//!
//! * **Direction.** The seed's motion points from the current frame to the
//!   previous one and writes the middle ground at `(x, y) − 0.5·m`; with
//!   that convention the middle is at `x + 0.5·m` (the minus would
//!   extrapolate past the current frame). Here a current pixel `x` lands at
//!   `x + (1 − α)·m`: at α = 1 on itself, at α = 0 where it was.
//! * **Normalised motion.** The seed's "[0, 1] NDC like a uv" mixes NDC (y
//!   up) and uv (y down). Here uv = pixels / size, y down like pixels, so
//!   the conversion is a scale per axis and never flips a sign.
//! * **Packing.** The seed packs a 19-bit depth with a 13-bit coordinate
//!   in two buffers (x and y) and resolves with `atomicMax`, which needs a
//!   reversed depth (larger = nearer) and loses depth precision. Here the
//!   exact two-step splat of `splat.rs` (full 32-bit depth key, then the
//!   smallest source index) picks the nearest fragment deterministically,
//!   with no resolution limit beyond 2³² pixels.
//! * **Push-pull.** The seed's pyramid is 7 levels (6 pull and 6 push
//!   passes); the level count is the `pushpull_levels` setting, by default
//!   the frame's full depth (down to 1×1), which lifts the limit below.
//!   A coarse texel averages the written motion of its children; a pixel
//!   left unwritten takes the (bilinear) coarser value and stays flagged
//!   unwritten.
//! * **The 512-pixel limit** (of a 7-level pyramid). A texel of level 6
//!   spans 64 pixels, and the bilinear push reaches about as far again, so
//!   motion dissipates about `2^(levels+2)` = 512 pixels from where it was
//!   written. With fewer levels, an unwritten region wider than that gets
//!   the pyramid's average motion (0 if nothing was written at all) and fetches the previous frame nearly in place:
//!   the seed's tearing, but never a NaN or an out-of-bounds read (every
//!   fetch is clamped to the image).
//! * **Two-sided resolve.** The seed fetches every pixel from one frame,
//!   so shading that changes between the frames jumps; a pixel whose
//!   surface is visible in both frames blends them by α (see [`resolve`]),
//!   with the warp's sharp resampling.
//! * **Outputs.** Depth is the fetched frames' depth (blended by α where
//!   both are fetched); the
//!   motion vector points to the *previous* rendered frame (`α·m`, §3
//!   convention); the mask says written ([`crate::output::WARPED`]) or
//!   unwritten ([`crate::output::FILLED`]).

pub mod reproject;
pub mod resolve;
