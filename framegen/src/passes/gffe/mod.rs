//! G-buffer-free frame extrapolation (GFFE, seed 000 §4.1–4.3; DESIGN §4).
//! One module per pass, its WGSL shader beside it, each with a plain CPU
//! reference:
//!
//! | step | module | paper |
//! |---|---|---|
//! | 1 history tracking + static test | [`history`] | Alg. 1 (appendix B) |
//! | 2 position estimation | [`motion`] | eq. 1 |
//! | 3 camera extrapolation | `protocol::Pose::extrapolate` | eq. 2 (rotation at constant angular velocity) |
//! | 4 depth-tested forward warp | [`warp`] + `crate::passes::common::splat` | §4.1 |
//! | 5 layered background collection | [`background`] | §4.2, Fig. 5 |
//! | 6 background projection into holes | [`bgfill`] | §4.2 |
//! | 7 push-pull fill of what remains | [`crate::passes::common::pushpull`] | DESIGN §4 step 7 |
//! | 8 adaptive window crop | [`crate::passes::common::crop`] | §4.3, appendix C |
//! | 9 shading correction (hand-built) | [`shading`] | §4.4, eq. 3–4 |
//!
//! Shading correction estimates at ingest (after step 1) how the shading
//! moved from `t−1` to `t`, and corrects the colour the warp (step 4)
//! moves; see [`shading`] for why it runs before the warp.

pub mod background;
pub mod bgfill;
pub mod history;
pub mod motion;
pub mod shading;
pub mod warp;
