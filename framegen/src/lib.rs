//! Frame generation for the streaming client: the methods (repeat,
//! reprojection, GFFE extrapolation, GeoMotionGen interpolation) arrive in
//! their own modules; this crate already owns what every method is measured
//! by.
//!
//! * [`display`]: the one fixed display transform of DESIGN §9 (exposure 1,
//!   Reinhard per channel, sRGB OETF, clamp), from `protocol`.
//! * [`metrics`]: PSNR and SSIM on display-encoded images.

pub mod metrics;

/// The fixed display transform lives in `protocol` (it is part of the data
/// contract); re-exported here for the metrics' users.
pub use protocol::display;

pub use display::{DisplayImage, display_encode};
pub use metrics::{MetricsError, psnr, ssim};
