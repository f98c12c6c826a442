//! The data model and its encodings: what every other crate agrees on.
//!
//! * [`camera`]: pose, projection, the adaptive window; `project` /
//!   `unproject` helpers. The coordinate conventions are documented there.
//! * [`frame`]: frame metadata, buffer descriptors and decoded frames.
//! * [`codec`]: buffer codecs (raw, zstd).
//! * [`wire`]: versioned, length-prefixed messages (bincode 2) and a sans-IO
//!   decoder; [`assemble`] turns one frame's messages back into a frame.
//! * [`dump`]: the on-disk dump format (OpenEXR + JSON).
//! * [`effects`]: what a stream's content does (dynamic objects, moving
//!   shading), from which the client plans its stages.
//! * [`import`]: Blender and Unreal dumps converted into the conventions.
//! * [`display`]: the one fixed display transform (exposure 1, Reinhard,
//!   sRGB) that presenters, PNG output and quality metrics all use.
//!
//! # The conventions in one place (DESIGN §3)
//!
//! * Pixels: origin top-left, x right, y down; pixel `(i, j)` has its centre
//!   at `(i + 0.5, j + 0.5)`.
//! * Camera: right-handed world, +Y up; the camera looks down local −Z, +Y up,
//!   +X right. NDC z in [0, 1] (wgpu).
//! * Depth: linear view depth (positive distance along the view axis, world
//!   units); `+inf` is sky and moves only with camera rotation.
//! * Motion: pixels, from the pixel centre in the current frame to where the
//!   same surface point was in the previous frame: `prev = cur + mv`.
//! * Color: linear scene-referred RGB, `f16`.
//! * Time: each frame carries its index and the simulation time (s) it shows.
//!
//! Nothing in this crate panics on data from the network or from disk: every
//! length is validated against [`Limits`] before anything is allocated.

pub mod assemble;
pub mod camera;
pub mod codec;
pub mod display;
pub mod dump;
pub mod effects;
pub mod frame;
pub mod import;
pub mod memory;
pub mod wire;

pub use camera::{Camera, Pose, Projected, Projection, Window, WorldPoint};
pub use codec::{Codec, CodecError};
pub use effects::Effects;
pub use frame::{BufferDesc, BufferKind, Frame, FrameMeta, FrameSize, PixelFormat};

/// Version of the data conventions (DESIGN §3). Dumps record it; bump it when
/// a convention changes so old data is converted, not misread.
pub const CONVENTIONS_VERSION: u32 = 1;

/// A value that breaks the data contract.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidationError {
    /// A value that must be finite is NaN or infinite.
    #[error("{0} is not finite")]
    NonFinite(&'static str),
    /// A rotation quaternion is too far from unit length.
    #[error("camera rotation is not a unit quaternion (length {0})")]
    NotUnitQuaternion(f64),
    /// A value is outside its allowed range.
    #[error("{0} is out of range")]
    OutOfRange(&'static str),
    /// Image dimensions are zero or exceed the limits.
    #[error("frame size {width}x{height} is outside 1..={max}")]
    BadSize {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// The largest allowed side.
        max: u32,
    },
    /// A frame larger in area than the limits allow.
    #[error("frame size {width}x{height} has more than {max} pixels")]
    TooManyPixels {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// The largest allowed area.
        max: u64,
    },
    /// A pixel format that a buffer kind cannot use.
    #[error("pixel format {format:?} is not allowed for {kind:?} buffers")]
    FormatNotAllowed {
        /// The buffer kind.
        kind: BufferKind,
        /// The rejected format.
        format: PixelFormat,
    },
    /// A codec that cannot carry a buffer kind (the quantised codecs carry
    /// only the buffer they model).
    #[error("codec {codec:?} cannot carry {kind:?} buffers")]
    CodecNotSuited {
        /// The buffer kind.
        kind: BufferKind,
        /// The rejected codec.
        codec: Codec,
    },
    /// A payload length that does not fit the dimensions, format and codec.
    #[error(
        "{kind:?} payload of {len} bytes does not fit {codec:?} ({min}..={max} bytes expected)"
    )]
    PayloadLength {
        /// The buffer kind.
        kind: BufferKind,
        /// The codec.
        codec: Codec,
        /// The announced or received length.
        len: u64,
        /// Smallest acceptable length.
        min: u64,
        /// Largest acceptable length.
        max: u64,
    },
    /// A list holds the same buffer kind twice.
    #[error("buffer {0:?} appears twice")]
    DuplicateBuffer(BufferKind),
    /// A required buffer is missing.
    #[error("required buffer {0:?} is missing")]
    MissingBuffer(BufferKind),
    /// A list is longer than allowed.
    #[error("{what} has {len} entries, at most {max} allowed")]
    TooMany {
        /// What the list is.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The limit.
        max: usize,
    },
}

/// Size limits enforced before any allocation. Receivers may tighten them
/// (for example to the negotiated frame size) but never need to loosen them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest width or height, in pixels.
    pub max_dimension: u32,
    /// Largest width × height, in pixels.
    pub max_pixels: u64,
    /// Largest body of a single buffer payload message, in bytes.
    pub max_payload: u64,
    /// Largest body of any other message (handshake, header, stats), in bytes.
    pub max_control: u32,
}

impl Limits {
    /// Width and height up to 8192 each.
    pub const MAX_DIMENSION: u32 = 8192;

    /// The limits of a control stream (handshake, statistics, bye): control
    /// messages up to [`Limits::MAX_CONTROL_STREAM`] bytes, no payloads.
    pub fn control() -> Self {
        Self {
            max_payload: 0,
            max_control: Self::MAX_CONTROL_STREAM,
            ..Self::default()
        }
    }

    /// Largest control-stream message body: a `Hello` with a long name,
    /// token and every option is a few hundred bytes.
    pub const MAX_CONTROL_STREAM: u32 = 4 * 1024;

    /// The limits of a stream whose frames are at most `max` (the client's,
    /// once the server's welcome has said so; issue 18 §5): sides and area
    /// up to `max`'s, a payload up to the largest buffer of that area
    /// (8 bytes a pixel) grown by the codec that can grow it most.
    pub fn for_frames(max: FrameSize) -> Self {
        let pixels = u64::from(max.width) * u64::from(max.height);
        Self {
            max_dimension: max.width.max(max.height),
            max_pixels: pixels,
            max_payload: codec::zstd_compress_bound(pixels.saturating_mul(8)) + codec::MAX_HEADER,
            ..Self::default()
        }
    }

    /// The tighter of two limits, field by field.
    pub fn min(self, other: Self) -> Self {
        Self {
            max_dimension: self.max_dimension.min(other.max_dimension),
            max_pixels: self.max_pixels.min(other.max_pixels),
            max_payload: self.max_payload.min(other.max_payload),
            max_control: self.max_control.min(other.max_control),
        }
    }

    /// Checks that a frame size is within `1..=max_dimension` on both sides
    /// and at most `max_pixels` in area.
    pub fn check_size(&self, width: u32, height: u32) -> Result<(), ValidationError> {
        if width == 0 || height == 0 || width > self.max_dimension || height > self.max_dimension {
            return Err(ValidationError::BadSize {
                width,
                height,
                max: self.max_dimension,
            });
        }
        if u64::from(width) * u64::from(height) > self.max_pixels {
            return Err(ValidationError::TooManyPixels {
                width,
                height,
                max: self.max_pixels,
            });
        }
        Ok(())
    }
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_dimension: Self::MAX_DIMENSION,
            max_pixels: u64::from(Self::MAX_DIMENSION) * u64::from(Self::MAX_DIMENSION),
            // The largest raw buffer (8192² pixels at 8 bytes: RGBA f16, RG
            // f32, or motion residuals), encoded by the codec that can grow
            // it most (zstd on incompressible data, after a codec header).
            max_payload: codec::zstd_compress_bound(8192 * 8192 * 8) + codec::MAX_HEADER,
            max_control: 64 * 1024,
        }
    }
}
