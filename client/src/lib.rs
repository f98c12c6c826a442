//! The streaming client. Transport (quinn), presentation and `eval` arrive
//! with their issues; the sans-IO core that turns per-frame streams into an
//! ordered sequence of frames is here already.
//!
//! * [`connect`] and [`tls`]: the QUIC session with a pinned certificate;
//! * [`eval`]: `client eval`, quality against milliseconds for every
//!   method and setting;
//! * [`receiver`]: reassembles frames from per-frame streams, delivers them
//!   in order, supersedes late ones and keeps the statistics the client
//!   reports to the server.

pub mod connect;
pub mod demo;
pub mod eval;
pub mod impair;
pub mod present;
pub mod receiver;
pub mod tls;
pub mod window;

pub use connect::{Arrived, ConnectConfig, ConnectError, Session, SessionStats, connect};
pub use receiver::{Delivery, FrameReceiver, ReceiveError, StreamId};
pub use tls::Pin;
