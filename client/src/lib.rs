//! The streaming client: transport, presentation and `eval`.
//!
//! * [`connect`] and [`tls`]: the QUIC session with a pinned certificate;
//! * [`reconnect`]: a stream that reconnects when its server goes away;
//! * [`impair`]: a lossy, jittery relay for tests and demos;
//! * [`present`]: the presentation loop, headless or into [`window`],
//!   which display-encodes on its GPU ([`display`]);
//! * [`frame_writer`]: writes the presented frames (a dump, PNGs) off the
//!   presenting thread;
//! * [`priority`]: a lower CPU priority for the writer and the in-process
//!   server, which must not take the presenter's time;
//! * [`latch`]: when late input takes the viewer's pose, and what
//!   becomes of an image that missed its vsync;
//! * [`eval`]: `client eval`, quality against milliseconds for every
//!   method and setting;
//! * [`viewer`]: the viewer's camera (issue 20): scripted input tracks;
//! * [`receiver`]: reassembles frames from per-frame streams, delivers them
//!   in order, supersedes late ones and keeps the statistics the client
//!   reports to the server.

pub mod connect;
pub mod demo;
pub mod display;
pub mod eval;
pub mod frame_writer;
pub mod impair;
pub mod latch;
pub mod present;
pub mod priority;
pub mod receiver;
pub mod reconnect;
pub mod tls;
pub mod viewer;
pub mod window;

pub use connect::{Arrived, ConnectConfig, ConnectError, Session, SessionStats, connect};
pub use receiver::{Delivery, FrameReceiver, Order, ReceiveError, StreamId};
pub use reconnect::{ReconnectPolicy, Stream, StreamStats};
pub use tls::Pin;
