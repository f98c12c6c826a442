//! The server side of the handshake, sans-IO (DESIGN §7): a [`Hello`] is
//! checked against the server's policy and answered with a [`Welcome`] or a
//! [`Reject`] that says why.

use protocol::wire::{
    Hello, Reject, RejectReason, StreamBuffer, WIRE_VERSION, Welcome, WindowMode,
};
use protocol::{Codec, FrameSize};

/// What the server offers and requires.
#[derive(Clone, Debug)]
pub struct Policy {
    /// The access token clients must present.
    pub token: String,
    /// Name shown to clients.
    pub server_name: String,
    /// Displayed size of the stream.
    pub size: FrameSize,
    /// Largest rendered size (a widened window makes frames larger).
    pub max_frame: FrameSize,
    /// Render rate.
    pub fps: f64,
    /// Buffers every frame carries.
    pub buffers: Vec<StreamBuffer>,
    /// Window mode of the stream.
    pub window_mode: WindowMode,
    /// Most sessions served at once; one more is refused with
    /// [`RejectReason::ServerFull`].
    pub max_sessions: usize,
    /// Congestion control of the frames sent.
    pub congestion: crate::tls::Congestion,
    /// What the stream's content does (sent in the welcome).
    pub effects: protocol::Effects,
}

/// Sessions a server admits by default: a live scene is rendered once for
/// all of them, but each replayed dump is read and encoded per session, two
/// cores' worth at 640×360 (`serve --max-sessions`).
pub const DEFAULT_MAX_SESSIONS: usize = 16;

/// Default cap of interactive sessions: each renders its own frames, and
/// this machine's software renderer takes 30-50 ms a 320x180 frame.
pub const DEFAULT_MAX_INTERACTIVE_SESSIONS: usize = 2;

/// The largest frame a stream of displayed `size` sends with `window`: a
/// widened window at the same pixel density (keep-density) grows each side
/// by up to the window's `max_extent`; keep-size keeps the size.
pub fn max_frame(size: FrameSize, window: &scene::render::WindowSettings) -> FrameSize {
    match window.mode {
        WindowMode::KeepDensity => {
            let grow = |v: u32| {
                ((f64::from(v) * window.max_extent.max(1.0)).ceil() as u32).saturating_add(1)
            };
            FrameSize::new(grow(size.width), grow(size.height))
        }
        WindowMode::Off | WindowMode::KeepSize => size,
    }
}

/// A fresh access token: 128 random bits as 32 hex digits (`server serve`
/// without `--token`, and the in-process demo).
pub fn random_token() -> String {
    use rand::Rng;
    let bytes: [u8; 16] = rand::rng().random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Compares two byte strings in time independent of where they differ.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for i in 0..a.len().max(b.len()) {
        diff |= usize::from(a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0xff));
    }
    diff == 0
}

/// Answers a hello: the welcome for session `session_id`, or a refusal.
pub fn answer(policy: &Policy, hello: &Hello, session_id: u64) -> Result<Welcome, Reject> {
    let reject = |reason, message: String| Reject { reason, message };
    if hello.version != WIRE_VERSION {
        return Err(reject(
            RejectReason::UnsupportedVersion {
                server: WIRE_VERSION,
            },
            format!(
                "client speaks wire version {}, server speaks {WIRE_VERSION}",
                hello.version
            ),
        ));
    }
    // An empty token authenticates no one, even against an empty policy.
    if policy.token.is_empty() || !constant_time_eq(hello.token.as_bytes(), policy.token.as_bytes())
    {
        return Err(reject(
            RejectReason::BadToken,
            "wrong or missing access token".into(),
        ));
    }
    if let Some(b) = policy
        .buffers
        .iter()
        .find(|b| b.codec != Codec::Raw && !hello.codecs.contains(&b.codec))
    {
        return Err(reject(
            RejectReason::Incompatible,
            format!(
                "the stream needs codec {:?} for {:?}, which the client does not decode",
                b.codec, b.kind
            ),
        ));
    }
    if policy.max_frame.width > hello.max_size.width
        || policy.max_frame.height > hello.max_size.height
    {
        return Err(reject(
            RejectReason::Incompatible,
            format!(
                "frames up to {}x{} exceed the client's maximum {}x{}",
                policy.max_frame.width,
                policy.max_frame.height,
                hello.max_size.width,
                hello.max_size.height
            ),
        ));
    }
    if policy.window_mode != WindowMode::Off && !hello.window_modes.contains(&policy.window_mode) {
        return Err(reject(
            RejectReason::Incompatible,
            format!(
                "the stream uses window mode {:?}, which the client cannot crop",
                policy.window_mode
            ),
        ));
    }
    Ok(Welcome {
        session_id,
        server_name: policy.server_name.clone(),
        size: policy.size,
        fps: policy.fps,
        buffers: policy.buffers.clone(),
        window_mode: policy.window_mode,
        max_frame: policy.max_frame,
        effects: policy.effects,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy() -> Policy {
        Policy {
            token: "secret".into(),
            server_name: "test".into(),
            size: FrameSize::new(64, 36),
            max_frame: FrameSize::new(96, 54),
            fps: 30.0,
            buffers: StreamBuffer::default_set(Codec::Raw).to_vec(),
            window_mode: WindowMode::Off,
            max_sessions: DEFAULT_MAX_SESSIONS,
            congestion: crate::tls::Congestion::default(),
            effects: protocol::Effects::UNKNOWN,
        }
    }

    fn hello() -> Hello {
        Hello {
            version: WIRE_VERSION,
            client_name: "c".into(),
            token: "secret".into(),
            codecs: vec![Codec::Raw, Codec::Zstd],
            max_size: FrameSize::new(8192, 8192),
            window_modes: vec![WindowMode::KeepDensity, WindowMode::KeepSize],
            extras: vec![],
        }
    }

    #[test]
    fn good_hello_is_welcomed() {
        let w = answer(&policy(), &hello(), 7).unwrap();
        assert_eq!(
            (w.session_id, w.size, w.fps),
            (7, FrameSize::new(64, 36), 30.0)
        );
    }

    #[test]
    fn refusals_say_why() {
        let p = policy();
        let mut h = hello();
        h.token = "secreT".into();
        assert_eq!(
            answer(&p, &h, 1).unwrap_err().reason,
            RejectReason::BadToken
        );
        h.token = String::new();
        assert_eq!(
            answer(&p, &h, 1).unwrap_err().reason,
            RejectReason::BadToken
        );
        let mut h = hello();
        h.version = 99;
        assert_eq!(
            answer(&p, &h, 1).unwrap_err().reason,
            RejectReason::UnsupportedVersion {
                server: WIRE_VERSION
            }
        );
        let mut h = hello();
        h.codecs = vec![Codec::Raw];
        let e = answer(&p, &h, 1).unwrap_err();
        assert_eq!(e.reason, RejectReason::Incompatible);
        assert!(e.message.contains("Zstd"), "{}", e.message);
        let mut h = hello();
        h.max_size = FrameSize::new(64, 36);
        assert_eq!(
            answer(&p, &h, 1).unwrap_err().reason,
            RejectReason::Incompatible
        );
        let mut windowed = policy();
        windowed.window_mode = WindowMode::KeepDensity;
        let mut h = hello();
        h.window_modes.clear();
        assert_eq!(
            answer(&windowed, &h, 1).unwrap_err().reason,
            RejectReason::Incompatible
        );
    }

    /// A policy with an empty token welcomes no one, not even a hello
    /// with an empty token (issue 18 §5); random tokens are 32 hex digits
    /// and differ.
    #[test]
    fn an_empty_token_authenticates_no_one() {
        let open = Policy {
            token: String::new(),
            ..policy()
        };
        let mut h = hello();
        h.token = String::new();
        assert_eq!(
            answer(&open, &h, 1).unwrap_err().reason,
            RejectReason::BadToken
        );
        let (a, b) = (random_token(), random_token());
        assert!(
            a.len() == 32 && a.bytes().all(|c| c.is_ascii_hexdigit()),
            "{a}"
        );
        assert_ne!(a, b);
    }

    #[test]
    fn token_comparison_is_exact() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"ab"));
        assert!(!constant_time_eq(b"", b"a"));
        assert!(constant_time_eq(b"", b""));
    }
}
