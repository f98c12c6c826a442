//! The streaming host: what the `server` binary serves and the client's
//! in-process demo embeds.
//!
//! * [`source`]: the paced frame producer, from a scene rendered with
//!   `scene::render` or a dump replayed from disk;
//! * [`input`]: sans-IO viewer input of a session (issue 20): which input
//!   datagrams are taken, and the camera an interactive producer renders
//!   from;
//! * [`pacer`]: sans-IO pacing of a frame sequence by simulation time, with
//!   stale-frame skipping when the sender falls behind;
//! * [`recovery`]: sans-IO keyframe recovery of one session's video-coded
//!   colour;
//! * [`tls`], [`session`], [`serve`]: the QUIC streaming endpoint: identity
//!   and pinning, the handshake, and per-client sessions.

pub mod input;
pub mod pacer;
pub mod recovery;
pub mod serve;
pub mod session;
pub mod source;
pub mod tls;
