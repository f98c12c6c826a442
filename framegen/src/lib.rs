//! Frame generation for the streaming client (DESIGN §4–§6): rendered
//! frames go in one by one, generated frames at any α come out.
//!
//! * [`FrameGenerator`] is the one API for every [`Method`]: `repeat`,
//!   `reproject` (camera-only, with depth), `gffe` (G-buffer-free frame
//!   extrapolation, seed 000) and `interp` (GeoMotionGen interpolation,
//!   seed 003), on the CPU reference or on wgpu ([`exec`]).
//! * Each pass is a module in [`passes`] with its WGSL shader beside it
//!   and a plain CPU reference of the same computation.
//! * [`display`] and [`metrics`] are what every method is measured by.

pub mod accounting;
pub mod decimate;
pub mod exec;
pub mod generator;
pub mod gpu;
pub mod input;
pub mod method;
pub mod metrics;
pub mod oracle;
pub mod output;
mod par;
pub mod passes;
pub mod pipeline;
pub mod schedule;
pub mod settings;
#[cfg(test)]
mod testutil;

/// The fixed display transform lives in `protocol` (it is part of the data
/// contract); re-exported here for the metrics' users.
pub use protocol::display;

pub use display::{DisplayImage, display_encode};
pub use exec::cpu::CpuBackend;
pub use exec::gpu::GpuBackend;
pub use generator::{CameraSource, FrameGenerator, Generated, PushOutcome};
pub use gpu::GpuContext;
pub use gpu::timestamps::PassClock;
pub use method::{AlphaRange, Descriptor, Method};
pub use metrics::{MetricsError, psnr, psnr_of_mse, squared_error_map, ssim, ssim_map};
pub use output::PixelSource;
pub use pipeline::{Backend, IngestPlan, Job, Pass, PassTime, Snapshot};
pub use protocol::Effects;
pub use settings::{Resample, Settings};

/// Everything that can go wrong in frame generation.
#[derive(Debug, thiserror::Error)]
pub enum FramegenError {
    /// No usable GPU: no adapter, a missing capability, a frame too large
    /// for the device, or an error wgpu reported.
    #[error(transparent)]
    Gpu(#[from] gpu_device::GpuError),
    /// A plan called an executor's passes out of order (a bug in a plan
    /// of `pipeline`, never a property of the input).
    #[error("executor passes out of order: {0}")]
    PassOrder(&'static str),
    /// The device failed or was lost.
    #[error("GPU device error: {0}")]
    Device(String),
    /// The settings are out of range.
    #[error("invalid settings: {0}")]
    Settings(String),
    /// The frame's buffers do not match its metadata.
    #[error("invalid frame: {0}")]
    Frame(#[from] protocol::ValidationError),
    /// Two frames that must share a size do not.
    #[error("frames of different sizes: {0}x{1} and {2}x{3}")]
    Sizes(u32, u32, u32, u32),
    /// A frame was asked for before any rendered frame arrived.
    #[error("no rendered frame yet")]
    NoFrame,
    /// α must be finite, ≥ 0 and at most the configured limit.
    #[error("α = {0} is outside [0, {1}]")]
    Alpha(f64, f64),
    /// A camera given for the generated frame is invalid.
    #[error("invalid target camera: {0}")]
    Camera(protocol::ValidationError),
    /// A generated frame was asked for on a device, from a generator that
    /// runs on the CPU.
    #[error("the {0} generator has no device to leave a frame on")]
    NotOnDevice(String),
    /// The texture a generated frame was asked into does not fit it.
    #[error("a {width}x{height} {format:?} texture cannot take a {0}x{1} generated frame (an Rgba16Float copy destination of its size)", width = .2.0, height = .2.1, format = .2.2)]
    Target(u32, u32, (u32, u32, wgpu::TextureFormat)),
}
