//! The frame server. The renderer (scene files, wgpu) and the QUIC endpoint
//! arrive with their issues; this crate already owns:
//!
//! * [`pacer`]: sans-IO pacing of a frame sequence by simulation time, with
//!   stale-frame skipping when the sender falls behind;
//! * [`inspect`]: a health check of a dump on disk (`server inspect DIR`).

pub mod inspect;
pub mod pacer;
