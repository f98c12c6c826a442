//! The loopback fixture of the QUIC tests (`transport.rs`,
//! `transport_memory.rs`, `video_stream.rs`, `interactive.rs`): a dump, a
//! server identity and a live server on 127.0.0.1, and helpers to replay,
//! connect (raw QUIC too) and compare. Each test binary uses a part of it.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use client::{ConnectConfig, Pin};
use glam::DVec3;
use host::serve::Server;
use host::session::Policy;
use host::source::{Feed, Source, SourceSpec};
use host::tls::{Congestion, Identity};
use protocol::dump::{DumpReader, DumpWriter, Manifest};
use protocol::wire::{StreamBuffer, WindowMode};
use protocol::{Codec, Frame, FrameSize};

pub const SIZE: FrameSize = FrameSize::new(96, 54);
pub const FRAMES: u64 = 24;
pub const TOKEN: &str = "let-me-in";
/// Replay rate of the fixture's dump (its frames are timed at this rate,
/// which is what a replay paces by). A live feed drops frames for a
/// client that falls behind (by design); 20 fps leaves a loaded 2-core CI
/// machine, running the other tests in parallel, room to keep up, so the
/// "every frame arrives" checks test the transport, not the machine.
pub const REPLAY_FPS: f64 = 20.0;

pub struct Fixture {
    pub _dir: tempfile::TempDir,
    pub dump: std::path::PathBuf,
    pub identity: Identity,
    pub server: Server,
    pub frames: host::source::Channel,
    pub buffers: Vec<StreamBuffer>,
}

pub fn write_dump(dir: &std::path::Path) {
    let mut w = DumpWriter::create(dir, Manifest::new(REPLAY_FPS, SIZE, "transport test")).unwrap();
    for i in 0..FRAMES {
        w.write_frame(&tests::render(i, REPLAY_FPS, DVec3::ZERO, SIZE))
            .unwrap();
    }
    w.finish().unwrap();
}

pub async fn fixture(buffers: Vec<StreamBuffer>) -> Fixture {
    fixture_with(buffers, host::session::DEFAULT_MAX_SESSIONS).await
}

pub async fn fixture_with(buffers: Vec<StreamBuffer>, max_sessions: usize) -> Fixture {
    fixture_under(buffers, max_sessions, Congestion::default()).await
}

pub async fn fixture_under(
    buffers: Vec<StreamBuffer>,
    max_sessions: usize,
    congestion: Congestion,
) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dump");
    write_dump(&dump);
    let identity = Identity::load_or_create(&dir.path().join("identity")).unwrap();
    let policy = Policy {
        token: TOKEN.into(),
        server_name: "test".into(),
        size: SIZE,
        max_frame: SIZE,
        fps: REPLAY_FPS,
        buffers: buffers.clone(),
        window_mode: WindowMode::Off,
        max_sessions,
        congestion,
        effects: protocol::Effects::UNKNOWN,
    };
    let frames = Source::channel();
    let server = Server::start(
        "127.0.0.1:0".parse().unwrap(),
        &identity,
        policy,
        Feed::Live(frames.clone()),
    )
    .unwrap();
    Fixture {
        _dir: dir,
        dump,
        identity,
        server,
        frames,
        buffers,
    }
}

impl Fixture {
    pub fn addr(&self) -> SocketAddr {
        self.server.local_addr().unwrap()
    }

    pub fn config(&self) -> ConnectConfig {
        ConnectConfig::new(self.addr(), Pin::Sha256(self.identity.fingerprint()), TOKEN)
    }

    /// A session through a relay that loses 1 % of the datagrams, delays
    /// them by 5 ms (± 2 ms) and reorders 0.5 %, its randomness from `seed`
    /// (the relay must outlive the session).
    pub async fn connect_impaired(&self, seed: u64) -> (client::impair::Relay, client::Session) {
        self.connect_through(&format!(
            "loss=1%,delay=5ms,jitter=2ms,reorder=0.5%,seed={seed}"
        ))
        .await
    }

    /// A session through a relay impaired as `impairment` says (the
    /// `--impair` syntax).
    pub async fn connect_through(
        &self,
        impairment: &str,
    ) -> (client::impair::Relay, client::Session) {
        let imp: client::impair::Impairment = impairment.parse().unwrap();
        let relay = client::impair::Relay::start(self.addr(), imp)
            .await
            .unwrap();
        let mut config = self.config();
        config.addr = relay.local_addr();
        let session = client::connect(config).await.unwrap();
        (relay, session)
    }

    /// The dump's frames as written.
    pub fn originals(&self) -> Vec<Frame> {
        DumpReader::open(&self.dump)
            .unwrap()
            .frames()
            .map(Result::unwrap)
            .collect()
    }

    /// The fixture's policy for another server `name`, sending `buffers`.
    fn policy(&self, name: &str, buffers: &[StreamBuffer], max_sessions: usize) -> Policy {
        Policy {
            token: TOKEN.into(),
            server_name: name.into(),
            size: SIZE,
            max_frame: SIZE,
            fps: REPLAY_FPS,
            buffers: buffers.to_vec(),
            window_mode: WindowMode::Off,
            max_sessions,
            congestion: Congestion::default(),
            effects: protocol::Effects::UNKNOWN,
        }
    }

    /// A second server on `feed` under the fixture's identity; a config to
    /// connect to it.
    fn second_server(&self, policy: Policy, feed: Feed) -> (Server, ConnectConfig) {
        let server =
            Server::start("127.0.0.1:0".parse().unwrap(), &self.identity, policy, feed).unwrap();
        let mut config = self.config();
        config.addr = server.local_addr().unwrap();
        (server, config)
    }

    /// A second server replaying the dump afresh for every session (at
    /// [`REPLAY_FPS`]), encoded as `encoding` says; a config to connect to
    /// it.
    pub fn replay_server(&self, encoding: host::source::Encoding) -> (Server, ConnectConfig) {
        let policy = self.policy(
            "replay",
            &encoding.buffers,
            host::session::DEFAULT_MAX_SESSIONS,
        );
        let feed = Feed::PerSession {
            spec: SourceSpec::Dump {
                dir: self.dump.clone(),
                looped: false,
            },
            encoding,
        };
        self.second_server(policy, feed)
    }

    /// A server rendering `scene` at [`SIZE`] and [`REPLAY_FPS`] for each
    /// session from its viewer's input (issue 20), colour raw; a config to
    /// connect to it.
    pub fn interactive_server(&self, scene: &str) -> (Server, ConnectConfig) {
        let encoding = host::source::Encoding::new(
            protocol::wire::BufferSet::Lossless,
            video::ColorCodec::Raw,
        );
        let policy = self.policy("interactive", &encoding.buffers, 2);
        let spec = SourceSpec::Scene {
            spec: scene.into(),
            size: SIZE,
            fps: REPLAY_FPS,
            window: Default::default(),
            base: ".".into(),
        };
        self.second_server(policy, Feed::interactive(spec, encoding, None).unwrap())
    }

    pub fn start_source(&self) -> Source {
        self.start_source_with(false, self.buffers.clone().into())
    }

    /// The dump replayed into the live channel, `looped` or once, encoded
    /// as `encoding` says.
    pub fn start_source_with(&self, looped: bool, encoding: host::source::Encoding) -> Source {
        let spec = SourceSpec::Dump {
            dir: self.dump.clone(),
            looped,
        };
        Source::start(spec, encoding, self.frames.clone()).unwrap()
    }
}

/// Frames equal except the host time, which the server extends by its
/// encode time.
pub fn same_frame(got: &Frame, want: &Frame) -> bool {
    let mut g = got.clone();
    g.meta.host_processing = want.meta.host_processing;
    got.meta.host_processing >= want.meta.host_processing && g == *want
}

pub async fn receive_all(session: &mut client::Session) -> Vec<Frame> {
    let mut out = Vec::new();
    while out.len() < FRAMES as usize {
        match tokio::time::timeout(Duration::from_secs(10), session.frames.recv()).await {
            Ok(Some(a)) => out.push(std::sync::Arc::unwrap_or_clone(a.frame)),
            Ok(None) | Err(_) => break,
        }
    }
    out
}

pub fn all_raw() -> Vec<StreamBuffer> {
    let mut b = StreamBuffer::default_set(Codec::Raw).to_vec();
    for x in &mut b {
        x.codec = Codec::Raw;
    }
    b
}

/// A raw QUIC connection that pins the fixture's certificate.
pub async fn raw_connection(
    fx: &Fixture,
    max_streams: u32,
) -> (quinn::Endpoint, quinn::Connection) {
    let tls = Pin::Sha256(fx.identity.fingerprint())
        .client_config()
        .unwrap();
    let crypto = quinn::crypto::rustls::QuicClientConfig::try_from(tls).unwrap();
    let mut config = quinn::ClientConfig::new(Arc::new(crypto));
    let mut transport = quinn::TransportConfig::default();
    transport.max_concurrent_uni_streams(max_streams.into());
    config.transport_config(Arc::new(transport));
    let endpoint = quinn::Endpoint::client("127.0.0.1:0".parse().unwrap()).unwrap();
    let conn = endpoint
        .connect_with(config, fx.addr(), "localhost")
        .unwrap()
        .await
        .unwrap();
    (endpoint, conn)
}

pub fn hello_bytes() -> Vec<u8> {
    protocol::wire::encode(&protocol::wire::Message::Hello(protocol::wire::Hello {
        version: protocol::wire::WIRE_VERSION,
        client_name: "raw".into(),
        token: TOKEN.into(),
        codecs: vec![Codec::Raw, Codec::Zstd],
        max_size: FrameSize::new(8192, 8192),
        window_modes: vec![],
        extras: vec![],
    }))
    .unwrap()
}

/// Streams the fixture's dump to `session`, checks every frame arrives,
/// then ends the session and the server.
pub async fn every_frame_then_shut_down(fx: Fixture, mut session: client::Session) {
    let source = fx.start_source();
    let got = receive_all(&mut session).await;
    assert_eq!(got.len(), FRAMES as usize);
    source.stop();
    session.close().await;
    fx.server.shutdown().await;
}
