//! Wire format: versioned, length-prefixed messages, and a sans-IO decoder.
//!
//! Every message is an 8-byte header followed by a body:
//!
//! | bytes | field   | meaning                                            |
//! |-------|---------|----------------------------------------------------|
//! | 0..4  | `len`   | body length in bytes, u32 little-endian            |
//! | 4..6  | version | [`WIRE_VERSION`], u16 little-endian                |
//! | 6..8  | kind    | [`MessageKind`] tag, u16 little-endian             |
//! | 8..   | body    | bincode 2 (serde, standard config) of the message  |
//!
//! A [`BufferPayload`] body is a bincode head (frame index, buffer kind)
//! followed by the raw payload bytes. The header is checked — version, kind,
//! and `len` against the kind's limit in [`Limits`] — before a single body
//! byte is buffered, and decoded values are validated
//! ([`Message::validate`]) before they are returned, so a peer can neither
//! make the receiver allocate beyond the limits nor hand it a non-finite
//! camera.

mod messages;

pub use messages::*;

use bincode::config::{Configuration, Limit, LittleEndian, Varint};
use serde::{Deserialize, Serialize};

use crate::{BufferKind, Limits, ValidationError};

/// The wire format version this crate speaks.
pub const WIRE_VERSION: u16 = 6;

/// Size of the fixed message header.
pub const HEADER_LEN: usize = 8;

/// Most bytes a bincode-encoded structure may claim while decoding: bounds any
/// allocation serde makes for strings and lists, whatever the body length.
const BINCODE_LIMIT: usize = 1 << 20;

type Config = Configuration<LittleEndian, Varint, Limit<BINCODE_LIMIT>>;

fn config() -> Config {
    bincode::config::standard().with_limit::<BINCODE_LIMIT>()
}

/// Tag of each message in the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum MessageKind {
    /// [`Hello`]
    Hello = 1,
    /// [`Welcome`]
    Welcome = 2,
    /// [`Reject`]
    Reject = 3,
    /// [`FrameHeader`]
    FrameHeader = 4,
    /// [`BufferPayload`]
    Payload = 5,
    /// [`ClientStats`]
    ClientStats = 6,
    /// [`ServerStats`]
    ServerStats = 7,
    /// [`Input`]
    Input = 8,
    /// [`Ping`]
    Ping = 9,
    /// [`Pong`]
    Pong = 10,
    /// [`Bye`]
    Bye = 11,
    /// [`KeyframeRequest`]
    KeyframeRequest = 12,
}

impl MessageKind {
    /// The kind for a header tag, if known.
    pub fn from_tag(tag: u16) -> Option<Self> {
        use MessageKind::*;
        Some(match tag {
            1 => Hello,
            2 => Welcome,
            3 => Reject,
            4 => FrameHeader,
            5 => Payload,
            6 => ClientStats,
            7 => ServerStats,
            8 => Input,
            9 => Ping,
            10 => Pong,
            11 => Bye,
            12 => KeyframeRequest,
            _ => return None,
        })
    }

    /// The largest body this kind may have under `limits`.
    pub fn max_body(self, limits: &Limits) -> u64 {
        match self {
            MessageKind::Payload => limits.max_payload.saturating_add(PAYLOAD_HEAD_MAX),
            _ => u64::from(limits.max_control),
        }
    }
}

/// Largest encoded [`PayloadHead`]: two varints and an enum tag.
const PAYLOAD_HEAD_MAX: u64 = 16;

#[derive(Serialize, Deserialize)]
struct PayloadHead {
    frame_index: u64,
    kind: BufferKind,
}

impl Message {
    /// This message's header tag.
    pub fn kind(&self) -> MessageKind {
        match self {
            Message::Hello(_) => MessageKind::Hello,
            Message::Welcome(_) => MessageKind::Welcome,
            Message::Reject(_) => MessageKind::Reject,
            Message::FrameHeader(_) => MessageKind::FrameHeader,
            Message::Payload(_) => MessageKind::Payload,
            Message::ClientStats(_) => MessageKind::ClientStats,
            Message::ServerStats(_) => MessageKind::ServerStats,
            Message::Input(_) => MessageKind::Input,
            Message::Ping(_) => MessageKind::Ping,
            Message::Pong(_) => MessageKind::Pong,
            Message::Bye(_) => MessageKind::Bye,
            Message::KeyframeRequest(_) => MessageKind::KeyframeRequest,
        }
    }
}

/// Why bytes could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// Not enough bytes yet (only from [`decode_message`]; the streaming
    /// [`Decoder`] waits instead).
    #[error("incomplete message: {needed} more bytes needed")]
    Incomplete {
        /// Bytes still missing.
        needed: usize,
    },
    /// The header names a wire version this crate does not speak.
    #[error("unsupported wire version {got} (this side speaks {supported})")]
    UnsupportedVersion {
        /// The version in the header.
        got: u16,
        /// [`WIRE_VERSION`].
        supported: u16,
    },
    /// The header's kind tag is unknown.
    #[error("unknown message kind {0}")]
    UnknownKind(u16),
    /// The announced body is longer than this kind may be.
    #[error("{kind:?} body of {len} bytes exceeds the limit of {max}")]
    TooLong {
        /// The message kind.
        kind: MessageKind,
        /// Announced length.
        len: u64,
        /// The limit.
        max: u64,
    },
    /// The body is not a valid encoding of its kind.
    #[error("malformed {kind:?} body: {detail}")]
    Malformed {
        /// The message kind.
        kind: MessageKind,
        /// What bincode reported.
        detail: String,
    },
    /// The body has bytes left over after the message.
    #[error("{kind:?} body has {extra} trailing bytes")]
    TrailingBytes {
        /// The message kind.
        kind: MessageKind,
        /// Bytes left over.
        extra: usize,
    },
    /// The message decoded but breaks the data contract.
    #[error("invalid {kind:?}: {source}")]
    Invalid {
        /// The message kind.
        kind: MessageKind,
        /// What is wrong.
        #[source]
        source: ValidationError,
    },
    /// A message could not be encoded.
    #[error("cannot encode {kind:?}: {detail}")]
    Encode {
        /// The message kind.
        kind: MessageKind,
        /// Why.
        detail: String,
    },
    /// A kind this stream does not carry at this point (refused from the
    /// header, before any of its body is buffered).
    #[error("unexpected {got:?} (this stream carries {expected:?} here)")]
    UnexpectedKind {
        /// The kind in the header.
        got: MessageKind,
        /// The kinds accepted.
        expected: &'static [MessageKind],
    },
    /// A previous error left the stream in an unknown state.
    #[error("decoder already failed; the stream must be closed")]
    Poisoned,
}

/// Appends the encoding of `msg` (header + body) to `out`.
///
/// Payload bytes are copied once into `out`; to send a large payload without
/// the copy, write [`payload_prefix`] and then the data.
pub fn encode_into(msg: &Message, out: &mut Vec<u8>) -> Result<(), WireError> {
    let kind = msg.kind();
    let start = out.len();
    out.extend_from_slice(&[0; HEADER_LEN]);
    let enc = |r: Result<usize, bincode::error::EncodeError>| {
        r.map(|_| ()).map_err(|e| WireError::Encode {
            kind,
            detail: e.to_string(),
        })
    };
    let mut w = VecWriter(out);
    let c = config();
    match msg {
        Message::Hello(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Welcome(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Reject(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::FrameHeader(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Payload(p) => {
            let head = PayloadHead {
                frame_index: p.frame_index,
                kind: p.kind,
            };
            enc(bincode::serde::encode_into_std_write(&head, &mut w, c))?;
            w.0.extend_from_slice(&p.data);
        }
        Message::ClientStats(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::ServerStats(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Input(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Ping(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Pong(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::Bye(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
        Message::KeyframeRequest(m) => enc(bincode::serde::encode_into_std_write(m, &mut w, c))?,
    }
    let body = out.len() - start - HEADER_LEN;
    let len = u32::try_from(body).map_err(|_| WireError::Encode {
        kind,
        detail: format!("body of {body} bytes does not fit a u32 length"),
    })?;
    write_header(&mut out[start..start + HEADER_LEN], len, kind);
    Ok(())
}

/// The encoding of `msg` (header + body).
pub fn encode(msg: &Message) -> Result<Vec<u8>, WireError> {
    let mut out = Vec::new();
    encode_into(msg, &mut out)?;
    Ok(out)
}

/// Header and payload head of a [`BufferPayload`] whose `data_len` data bytes
/// the caller sends right after, without copying them.
pub fn payload_prefix(
    frame_index: u64,
    kind: BufferKind,
    data_len: usize,
) -> Result<Vec<u8>, WireError> {
    let mut out = vec![0; HEADER_LEN];
    let head = PayloadHead { frame_index, kind };
    bincode::serde::encode_into_std_write(&head, &mut VecWriter(&mut out), config()).map_err(
        |e| WireError::Encode {
            kind: MessageKind::Payload,
            detail: e.to_string(),
        },
    )?;
    let body = out.len() - HEADER_LEN + data_len;
    let len = u32::try_from(body).map_err(|_| WireError::Encode {
        kind: MessageKind::Payload,
        detail: format!("body of {body} bytes does not fit a u32 length"),
    })?;
    write_header(&mut out[..HEADER_LEN], len, MessageKind::Payload);
    Ok(out)
}

fn write_header(dst: &mut [u8], len: u32, kind: MessageKind) {
    dst[0..4].copy_from_slice(&len.to_le_bytes());
    dst[4..6].copy_from_slice(&WIRE_VERSION.to_le_bytes());
    dst[6..8].copy_from_slice(&(kind as u16).to_le_bytes());
}

struct VecWriter<'a>(&'a mut Vec<u8>);

impl std::io::Write for VecWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Parses and checks a message header: version, kind, and length against the
/// kind's limit. Returns the kind and the body length.
pub fn parse_header(
    header: &[u8; HEADER_LEN],
    limits: &Limits,
) -> Result<(MessageKind, usize), WireError> {
    let len = u32::from_le_bytes([header[0], header[1], header[2], header[3]]);
    let version = u16::from_le_bytes([header[4], header[5]]);
    let tag = u16::from_le_bytes([header[6], header[7]]);
    if version != WIRE_VERSION {
        return Err(WireError::UnsupportedVersion {
            got: version,
            supported: WIRE_VERSION,
        });
    }
    let kind = MessageKind::from_tag(tag).ok_or(WireError::UnknownKind(tag))?;
    let max = kind.max_body(limits);
    // The body plus header must also fit a usize (32-bit targets).
    if u64::from(len) > max || (len as usize).checked_add(HEADER_LEN).is_none() {
        return Err(WireError::TooLong {
            kind,
            len: u64::from(len),
            max,
        });
    }
    Ok((kind, len as usize))
}

fn decode_serde<T: serde::de::DeserializeOwned>(
    kind: MessageKind,
    body: &[u8],
) -> Result<(T, usize), WireError> {
    bincode::serde::decode_from_slice(body, config()).map_err(|e| WireError::Malformed {
        kind,
        detail: e.to_string(),
    })
}

fn decode_exact<T: serde::de::DeserializeOwned>(
    kind: MessageKind,
    body: &[u8],
) -> Result<T, WireError> {
    let (value, used) = decode_serde(kind, body)?;
    if used != body.len() {
        return Err(WireError::TrailingBytes {
            kind,
            extra: body.len() - used,
        });
    }
    Ok(value)
}

/// Decodes a body of `kind` (its header already checked) and validates it.
pub fn decode_body(kind: MessageKind, body: &[u8], limits: &Limits) -> Result<Message, WireError> {
    let msg = match kind {
        MessageKind::Hello => Message::Hello(decode_exact(kind, body)?),
        MessageKind::Welcome => Message::Welcome(decode_exact(kind, body)?),
        MessageKind::Reject => Message::Reject(decode_exact(kind, body)?),
        MessageKind::FrameHeader => Message::FrameHeader(decode_exact(kind, body)?),
        MessageKind::Payload => {
            let (head, used): (PayloadHead, usize) = decode_serde(kind, body)?;
            Message::Payload(BufferPayload {
                frame_index: head.frame_index,
                kind: head.kind,
                data: body[used..].to_vec(),
            })
        }
        MessageKind::ClientStats => Message::ClientStats(decode_exact(kind, body)?),
        MessageKind::ServerStats => Message::ServerStats(decode_exact(kind, body)?),
        MessageKind::Input => Message::Input(decode_exact(kind, body)?),
        MessageKind::Ping => Message::Ping(decode_exact(kind, body)?),
        MessageKind::Pong => Message::Pong(decode_exact(kind, body)?),
        MessageKind::Bye => Message::Bye(decode_exact(kind, body)?),
        MessageKind::KeyframeRequest => Message::KeyframeRequest(decode_exact(kind, body)?),
    };
    msg.validate(limits)
        .map_err(|source| WireError::Invalid { kind, source })?;
    Ok(msg)
}

/// Decodes one message from the start of `bytes`: the message and the number
/// of bytes it used. [`WireError::Incomplete`] if `bytes` holds only part of
/// it. Datagrams are decoded with this and must hold exactly one message.
pub fn decode_message(bytes: &[u8], limits: &Limits) -> Result<(Message, usize), WireError> {
    let Some(header) = bytes.first_chunk::<HEADER_LEN>() else {
        return Err(WireError::Incomplete {
            needed: HEADER_LEN - bytes.len(),
        });
    };
    let (kind, len) = parse_header(header, limits)?;
    let total = HEADER_LEN + len;
    if bytes.len() < total {
        return Err(WireError::Incomplete {
            needed: total - bytes.len(),
        });
    }
    Ok((decode_body(kind, &bytes[HEADER_LEN..total], limits)?, total))
}

/// Sans-IO streaming decoder: feed it bytes as they arrive, take complete
/// messages out. After any error it stays failed ([`WireError::Poisoned`]):
/// the stream's framing can no longer be trusted.
#[derive(Debug)]
pub struct Decoder {
    limits: Limits,
    buf: Vec<u8>,
    /// Start of unread data in `buf`.
    pos: usize,
    /// The validated header of the message being received.
    pending: Option<(MessageKind, usize)>,
    /// The kinds accepted; any kind when `None`.
    expected: Option<&'static [MessageKind]>,
    failed: bool,
}

impl Decoder {
    /// A decoder enforcing `limits`.
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            buf: Vec::new(),
            pos: 0,
            pending: None,
            expected: None,
            failed: false,
        }
    }

    /// From the next header on, accept only `kinds`: any other is a
    /// [`WireError::UnexpectedKind`] from its 8-byte header alone, before
    /// a byte of its body is buffered (a server waiting for a `Hello`
    /// never holds a payload-sized body from an unauthenticated peer).
    pub fn accept_only(&mut self, kinds: &'static [MessageKind]) {
        self.expected = Some(kinds);
    }

    /// [`Decoder::new`] accepting only `kinds` ([`Decoder::accept_only`]).
    pub fn accepting(limits: Limits, kinds: &'static [MessageKind]) -> Self {
        let mut d = Self::new(limits);
        d.accept_only(kinds);
        d
    }

    /// Appends bytes received from the transport.
    pub fn feed(&mut self, bytes: &[u8]) {
        if self.failed {
            return;
        }
        if self.pos > 0 && self.pos >= self.buf.len() / 2 {
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// The next complete message, `Ok(None)` if more bytes are needed.
    pub fn next_message(&mut self) -> Result<Option<Message>, WireError> {
        if self.failed {
            return Err(WireError::Poisoned);
        }
        let result = self.step();
        if result.is_err() {
            self.failed = true;
            self.buf = Vec::new();
            self.pos = 0;
        }
        result
    }

    fn step(&mut self) -> Result<Option<Message>, WireError> {
        let avail = &self.buf[self.pos..];
        let (kind, len) = match self.pending {
            Some(p) => p,
            None => {
                let Some(header) = avail.first_chunk::<HEADER_LEN>() else {
                    return Ok(None);
                };
                let p = parse_header(header, &self.limits)?;
                if let Some(expected) = self.expected
                    && !expected.contains(&p.0)
                {
                    return Err(WireError::UnexpectedKind { got: p.0, expected });
                }
                self.pending = Some(p);
                p
            }
        };
        if avail.len() < HEADER_LEN + len {
            // Memory grows with the bytes that actually arrive, never with
            // what a header merely announces.
            return Ok(None);
        }
        let body = &avail[HEADER_LEN..HEADER_LEN + len];
        let msg = decode_body(kind, body, &self.limits)?;
        self.pos += HEADER_LEN + len;
        self.pending = None;
        Ok(Some(msg))
    }

    /// Bytes received but not yet returned as messages.
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.pos
    }

    /// True when no partial message is buffered and no error occurred (a
    /// clean end of stream).
    pub fn is_at_boundary(&self) -> bool {
        !self.failed && self.buffered() == 0
    }

    /// True once an error has poisoned the decoder.
    pub fn has_failed(&self) -> bool {
        self.failed
    }
}
