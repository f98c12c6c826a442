//! The frame server.
//!
//! * [`scene`]: scene files (RON): camera paths, objects, animation,
//!   materials, lights, and the effects a scene needs;
//! * [`render`]: the wgpu forward renderer (color, linear depth, motion),
//!   building only the passes a scene's effects need;
//! * [`pacer`]: sans-IO pacing of a frame sequence by simulation time, with
//!   stale-frame skipping when the sender falls behind;
//! * [`tls`], [`session`], [`source`], [`serve`]: the QUIC streaming
//!   endpoint: identity and pinning, the handshake, the paced frame
//!   producer, and per-client sessions;
//! * [`inspect`]: a health check of a dump on disk (`server inspect DIR`).

pub mod inspect;
pub mod pacer;
pub mod render;
pub mod scene;
pub mod serve;
pub mod session;
pub mod source;
pub mod tls;
