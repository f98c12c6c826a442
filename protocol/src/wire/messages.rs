//! The messages of the streaming protocol (DESIGN §7).
//!
//! * Control stream (bidirectional, opened by the client): [`Hello`] →
//!   [`Welcome`] or [`Reject`], then [`ClientStats`] / [`ServerStats`] both
//!   ways, and [`Bye`].
//! * One unidirectional stream per frame (server → client): a
//!   [`FrameHeader`], then one [`BufferPayload`] per buffer it lists.
//! * Datagrams: [`Input`], [`Ping`] / [`Pong`].

use serde::{Deserialize, Serialize};

use crate::camera::Pose;
use crate::frame::{BufferDesc, BufferKind, FrameMeta, FrameSize, PixelFormat};
use crate::{Codec, Effects, Limits, ValidationError};

/// Longest client name, server name, token or free-text reason, in bytes.
pub const MAX_TEXT: usize = 1024;
/// Most codecs a hello may list.
pub const MAX_CODECS: usize = 8;
/// Most buffers a frame may carry (one per [`BufferKind`]).
pub const MAX_BUFFERS: usize = BufferKind::ALL.len();

/// How the server widens the rendering window (GFFE §4.3, DESIGN §4.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum WindowMode {
    /// Always render the plain window.
    Off,
    /// Widen the window and grow the rendered size to keep pixel density.
    KeepDensity,
    /// Widen the window at a fixed rendered size (lower density).
    KeepSize,
}

impl WindowMode {
    /// Every mode.
    pub const ALL: [WindowMode; 3] = [
        WindowMode::Off,
        WindowMode::KeepDensity,
        WindowMode::KeepSize,
    ];

    /// The name on command lines and in reports.
    pub fn name(self) -> &'static str {
        match self {
            WindowMode::Off => "off",
            WindowMode::KeepDensity => "keep-density",
            WindowMode::KeepSize => "keep-size",
        }
    }
}

/// A window mode name other than `off`, `keep-density` or `keep-size`.
#[derive(Debug, thiserror::Error)]
#[error("expected off, keep-density or keep-size, not {0:?}")]
pub struct UnknownWindowMode(String);

impl std::str::FromStr for WindowMode {
    type Err = UnknownWindowMode;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| UnknownWindowMode(s.to_string()))
    }
}

/// First message of a session, client → server, on the control stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// The wire version the client speaks (also in every message's header).
    pub version: u16,
    /// Free-form client name for logs.
    pub client_name: String,
    /// Access token (DESIGN §7); compared in constant time by the server.
    pub token: String,
    /// Codecs the client can decode.
    pub codecs: Vec<Codec>,
    /// Largest frame the client accepts.
    pub max_size: FrameSize,
    /// Window modes the client can crop.
    pub window_modes: Vec<WindowMode>,
    /// Optional extra buffers the client would like.
    pub extras: Vec<BufferKind>,
}

/// One buffer of the stream as negotiated: its format and codec.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamBuffer {
    /// What the buffer holds.
    pub kind: BufferKind,
    /// Pixel layout.
    pub format: PixelFormat,
    /// Compression.
    pub codec: Codec,
}

/// The server's acceptance, server → client, on the control stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// Identifies the session in logs on both sides.
    pub session_id: u64,
    /// Free-form server name.
    pub server_name: String,
    /// Size of the displayed region (frames may be larger with a widened window).
    pub size: FrameSize,
    /// Render rate in frames per second.
    pub fps: f64,
    /// The buffers every frame carries.
    pub buffers: Vec<StreamBuffer>,
    /// How the rendering window is widened.
    pub window_mode: WindowMode,
    /// The largest frame the stream sends (the widened window makes frames
    /// larger than `size`): the client tightens its limits to it.
    pub max_frame: FrameSize,
    /// What the stream's content does: the client runs only the generation
    /// stages it calls for.
    pub effects: Effects,
}

/// Why a server refused a client.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RejectReason {
    /// The token is wrong or missing.
    BadToken,
    /// The client's wire version is not one the server speaks.
    UnsupportedVersion {
        /// The version the server speaks.
        server: u16,
    },
    /// No codec or window mode in common, or an unusable size.
    Incompatible,
    /// The server has no room for another client.
    ServerFull,
    /// The server is shutting down.
    ShuttingDown,
    /// The hello was malformed.
    BadRequest,
    /// The client was admitted but the server could not start its stream
    /// (an interactive session's renderer without a usable GPU, say); the
    /// message says why.
    Unavailable,
}

/// A refusal, server → client, followed by closing the connection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reject {
    /// Machine-readable reason.
    pub reason: RejectReason,
    /// Human-readable detail.
    pub message: String,
}

impl Reject {
    /// A refusal whose message is cut to [`MAX_TEXT`] bytes (at a
    /// character boundary), so that it always passes validation.
    pub fn new(reason: RejectReason, message: impl Into<String>) -> Self {
        let mut message = message.into();
        if message.len() > MAX_TEXT {
            let mut end = MAX_TEXT;
            while !message.is_char_boundary(end) {
                end -= 1;
            }
            message.truncate(end);
        }
        Self { reason, message }
    }
}

/// First message of a per-frame stream: metadata and the buffers that follow.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameHeader {
    /// Index, time, camera, size, host processing time.
    pub meta: FrameMeta,
    /// The payloads that follow, one per kind, in any order.
    pub buffers: Vec<BufferDesc>,
    /// The viewer input whose camera rendered the frame (interactive
    /// sessions, issue 20); `None` for a scripted camera.
    pub input: Option<InputEcho>,
}

/// Which [`Input`] a frame was rendered with, echoed in its header so that
/// the client can tell how old the camera it shows is (input-to-photon)
/// without a shared clock: both fields are the client's own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputEcho {
    /// The input's [`Input::seq`].
    pub seq: u64,
    /// The input's [`Input::client_time_us`].
    pub client_time_us: u64,
}

/// One buffer's encoded bytes. On the wire its body is a small bincode head
/// (frame index, kind) followed by the raw payload bytes, so payloads are not
/// copied through serde.
#[derive(Clone, Debug, PartialEq)]
pub struct BufferPayload {
    /// The frame it belongs to.
    pub frame_index: u64,
    /// Which of the header's buffers it is.
    pub kind: BufferKind,
    /// The encoded bytes, as long as the header's `payload_len`.
    pub data: Vec<u8>,
}

/// Periodic receiver statistics, client → server.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClientStats {
    /// Complete frames received.
    pub frames_received: u64,
    /// Frames that arrived after a newer one and were superseded.
    pub frames_late: u64,
    /// Frames lost or cancelled in transit.
    pub frames_dropped: u64,
    /// Payload bytes received.
    pub bytes_received: u64,
    /// Smoothed round-trip time, microseconds.
    pub rtt_us: u64,
}

/// Periodic sender statistics, server → client.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ServerStats {
    /// Frames whose streams were completed.
    pub frames_sent: u64,
    /// Frames dropped or cancelled because the client fell behind.
    pub frames_dropped: u64,
    /// Payload bytes sent.
    pub bytes_sent: u64,
}

/// Viewer input, client → server, as a datagram.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Input {
    /// Increases with every input sent.
    pub seq: u64,
    /// Client clock, microseconds (only compared with other client times).
    pub client_time_us: u64,
    /// The viewer's camera, if the client drives it.
    pub camera: Option<Pose>,
    /// Button bit mask.
    pub buttons: u32,
    /// Analog axes in [−1, 1].
    pub axes: [f32; 4],
}

/// Round-trip probe, either direction, as a datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ping {
    /// Sequence number echoed in the [`Pong`].
    pub seq: u64,
    /// Sender clock, microseconds, echoed in the [`Pong`].
    pub sent_us: u64,
}

/// Answer to a [`Ping`], echoing its fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pong {
    /// The ping's sequence number.
    pub seq: u64,
    /// The ping's sender clock.
    pub sent_us: u64,
}

/// Orderly end of a session, either direction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bye {
    /// Human-readable reason.
    pub reason: String,
}

/// A client's decoder lost its reference (a frame dropped, late or
/// corrupt): it asks for a keyframe on the control stream, and decodes no
/// video-coded colour until one arrives (issue 19 §1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyframeRequest {
    /// Index of the newest frame the client decoded, if any (for logs).
    pub last_decoded: Option<u64>,
}

/// Every message of the protocol.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// See [`Hello`].
    Hello(Hello),
    /// See [`Welcome`].
    Welcome(Welcome),
    /// See [`Reject`].
    Reject(Reject),
    /// See [`FrameHeader`].
    FrameHeader(FrameHeader),
    /// See [`BufferPayload`].
    Payload(BufferPayload),
    /// See [`ClientStats`].
    ClientStats(ClientStats),
    /// See [`ServerStats`].
    ServerStats(ServerStats),
    /// See [`Input`].
    Input(Input),
    /// See [`Ping`].
    Ping(Ping),
    /// See [`Pong`].
    Pong(Pong),
    /// See [`Bye`].
    Bye(Bye),
    /// See [`KeyframeRequest`].
    KeyframeRequest(KeyframeRequest),
}

fn check_text(what: &'static str, s: &str) -> Result<(), ValidationError> {
    if s.len() > MAX_TEXT {
        return Err(ValidationError::TooMany {
            what,
            len: s.len(),
            max: MAX_TEXT,
        });
    }
    Ok(())
}

fn check_count(what: &'static str, len: usize, max: usize) -> Result<(), ValidationError> {
    if len > max {
        return Err(ValidationError::TooMany { what, len, max });
    }
    Ok(())
}

/// Checks a list of buffer kinds: no duplicates, and the required ones present
/// when `require` is set.
fn check_kinds(
    kinds: impl Iterator<Item = BufferKind> + Clone,
    require: bool,
) -> Result<(), ValidationError> {
    let mut seen = Vec::with_capacity(MAX_BUFFERS);
    for kind in kinds {
        if seen.contains(&kind) {
            return Err(ValidationError::DuplicateBuffer(kind));
        }
        seen.push(kind);
    }
    if require {
        if let Some(&missing) = BufferKind::REQUIRED.iter().find(|k| !seen.contains(k)) {
            return Err(ValidationError::MissingBuffer(missing));
        }
    }
    Ok(())
}

/// Which codecs a stream sends depth and motion with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BufferSet {
    /// [`StreamBuffer::compact_set`]: depth quantised with a bounded error,
    /// motion as the residual over the camera.
    #[default]
    Compact,
    /// [`StreamBuffer::default_set`]: depth and motion exactly, zstd.
    Lossless,
}

impl BufferSet {
    /// The three buffers of the set, with `color` for colour.
    pub fn buffers(self, color: Codec) -> [StreamBuffer; 3] {
        match self {
            BufferSet::Compact => StreamBuffer::compact_set(color),
            BufferSet::Lossless => StreamBuffer::default_set(color),
        }
    }
}

/// A buffer set name other than `compact` or `lossless`.
#[derive(Debug, thiserror::Error)]
#[error("expected compact or lossless, not {0:?}")]
pub struct UnknownBufferSet(String);

impl std::str::FromStr for BufferSet {
    type Err = UnknownBufferSet;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "compact" => Ok(BufferSet::Compact),
            "lossless" => Ok(BufferSet::Lossless),
            other => Err(UnknownBufferSet(other.to_string())),
        }
    }
}

impl StreamBuffer {
    /// The default buffer set: color as RGB f16 uncompressed (`color`
    /// codec chosen by the caller, since color codecs are pluggable), depth
    /// and motion as f32 with lossless zstd (DESIGN §7).
    pub fn default_set(color: Codec) -> [StreamBuffer; 3] {
        [
            StreamBuffer {
                kind: BufferKind::Color,
                format: PixelFormat::Rgb16Float,
                codec: color,
            },
            StreamBuffer {
                kind: BufferKind::Depth,
                format: PixelFormat::R32Float,
                codec: Codec::Zstd,
            },
            StreamBuffer {
                kind: BufferKind::Motion,
                format: PixelFormat::Rg32Float,
                codec: Codec::Zstd,
            },
        ]
    }

    /// The set for a stream at real bitrates (issue 19): depth quantised
    /// with a bounded error and motion as the residual over the camera
    /// ([`Codec::QuantDepth`], [`Codec::MotionResidual`]); `color` as in
    /// [`StreamBuffer::default_set`].
    pub fn compact_set(color: Codec) -> [StreamBuffer; 3] {
        let [color, mut depth, mut motion] = Self::default_set(color);
        depth.codec = Codec::QuantDepth;
        motion.codec = Codec::MotionResidual;
        [color, depth, motion]
    }

    /// Checks that the format and the codec suit the kind.
    pub fn validate(&self) -> Result<(), ValidationError> {
        if !self.kind.allowed_formats().contains(&self.format) {
            return Err(ValidationError::FormatNotAllowed {
                kind: self.kind,
                format: self.format,
            });
        }
        if !self.codec.suits(self.kind, self.format) {
            return Err(ValidationError::CodecNotSuited {
                kind: self.kind,
                codec: self.codec,
            });
        }
        Ok(())
    }
}

impl Message {
    /// Checks every value against the data contract and `limits`: sizes,
    /// finiteness, formats, payload lengths, list lengths.
    pub fn validate(&self, limits: &Limits) -> Result<(), ValidationError> {
        match self {
            Message::Hello(h) => {
                check_text("client name", &h.client_name)?;
                check_text("token", &h.token)?;
                check_count("codecs", h.codecs.len(), MAX_CODECS)?;
                check_count("window modes", h.window_modes.len(), 3)?;
                check_count("extras", h.extras.len(), MAX_BUFFERS)?;
                check_kinds(h.extras.iter().copied(), false)?;
                limits.check_size(h.max_size.width, h.max_size.height)
            }
            Message::Welcome(w) => {
                check_text("server name", &w.server_name)?;
                limits.check_size(w.size.width, w.size.height)?;
                limits.check_size(w.max_frame.width, w.max_frame.height)?;
                if w.max_frame.width < w.size.width || w.max_frame.height < w.size.height {
                    return Err(ValidationError::OutOfRange("largest frame below the size"));
                }
                if !w.fps.is_finite() {
                    return Err(ValidationError::NonFinite("fps"));
                }
                if !(w.fps > 0.0 && w.fps <= 1000.0) {
                    return Err(ValidationError::OutOfRange("fps"));
                }
                check_count("buffers", w.buffers.len(), MAX_BUFFERS)?;
                check_kinds(w.buffers.iter().map(|b| b.kind), true)?;
                w.buffers.iter().try_for_each(StreamBuffer::validate)
            }
            Message::Reject(r) => check_text("reject message", &r.message),
            Message::FrameHeader(h) => {
                h.meta.validate(limits)?;
                check_count("buffers", h.buffers.len(), MAX_BUFFERS)?;
                check_kinds(h.buffers.iter().map(|b| b.kind), true)?;
                h.buffers
                    .iter()
                    .try_for_each(|b| b.validate(h.meta.size, limits))
            }
            Message::Payload(p) => {
                if p.data.len() as u64 > limits.max_payload {
                    return Err(ValidationError::TooMany {
                        what: "payload bytes",
                        len: p.data.len(),
                        max: usize::try_from(limits.max_payload).unwrap_or(usize::MAX),
                    });
                }
                Ok(())
            }
            Message::Input(i) => {
                if let Some(pose) = &i.camera {
                    pose.validate()?;
                }
                if i.axes.iter().any(|a| !a.is_finite()) {
                    return Err(ValidationError::NonFinite("input axes"));
                }
                if i.axes.iter().any(|a| a.abs() > 1.0) {
                    return Err(ValidationError::OutOfRange("input axes"));
                }
                Ok(())
            }
            Message::Bye(b) => check_text("bye reason", &b.reason),
            Message::ClientStats(_)
            | Message::ServerStats(_)
            | Message::Ping(_)
            | Message::Pong(_)
            | Message::KeyframeRequest(_) => Ok(()),
        }
    }
}
