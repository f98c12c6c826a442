//! Loopback QUIC: a real server (TLS 1.3, pinned self-signed certificate)
//! streaming a dump to real clients on 127.0.0.1 with ephemeral ports.
//! Every test is bounded in time.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use client::{ConnectConfig, ConnectError, Pin};
use glam::DVec3;
use protocol::dump::{DumpReader, DumpWriter, Manifest};
use protocol::wire::{RejectReason, StreamBuffer, WindowMode};
use protocol::{Codec, Frame, FrameSize};
use server::serve::Server;
use server::session::Policy;
use server::source::{Source, SourceSpec, StreamFrame};
use server::tls::Identity;
use tokio::sync::broadcast;

const SIZE: FrameSize = FrameSize::new(96, 54);
const FRAMES: u64 = 24;
const TOKEN: &str = "let-me-in";

struct Fixture {
    _dir: tempfile::TempDir,
    dump: std::path::PathBuf,
    identity: Identity,
    server: Server,
    frames: broadcast::Sender<Arc<StreamFrame>>,
    buffers: Vec<StreamBuffer>,
}

fn write_dump(dir: &std::path::Path) {
    let mut w = DumpWriter::create(dir, Manifest::new(60.0, SIZE, "transport test")).unwrap();
    for i in 0..FRAMES {
        w.write_frame(&tests::render(i, 60.0, DVec3::ZERO, SIZE))
            .unwrap();
    }
    w.finish().unwrap();
}

async fn fixture(buffers: Vec<StreamBuffer>) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dump");
    write_dump(&dump);
    let identity = Identity::load_or_create(&dir.path().join("identity")).unwrap();
    let policy = Policy {
        token: TOKEN.into(),
        server_name: "test".into(),
        size: SIZE,
        max_frame: SIZE,
        fps: 60.0,
        buffers: buffers.clone(),
        window_mode: WindowMode::Off,
    };
    let frames = Source::channel();
    let server = Server::start(
        "127.0.0.1:0".parse().unwrap(),
        identity.quic_server_config().unwrap(),
        policy,
        frames.clone(),
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
    fn addr(&self) -> SocketAddr {
        self.server.local_addr().unwrap()
    }

    fn config(&self) -> ConnectConfig {
        ConnectConfig::new(self.addr(), Pin::Sha256(self.identity.fingerprint()), TOKEN)
    }

    fn start_source(&self) -> Source {
        Source::start(
            SourceSpec::Dump {
                dir: self.dump.clone(),
                looped: false,
            },
            self.buffers.clone(),
            self.frames.clone(),
        )
        .unwrap()
    }
}

/// Frames equal except the host time, which the server extends by its
/// encode time.
fn same_frame(got: &Frame, want: &Frame) -> bool {
    let mut g = got.clone();
    g.meta.host_processing = want.meta.host_processing;
    got.meta.host_processing >= want.meta.host_processing && g == *want
}

async fn receive_all(session: &mut client::Session) -> Vec<Frame> {
    let mut out = Vec::new();
    while out.len() < FRAMES as usize {
        match tokio::time::timeout(Duration::from_secs(10), session.frames.recv()).await {
            Ok(Some(f)) => out.push(f),
            Ok(None) | Err(_) => break,
        }
    }
    out
}

fn all_raw() -> Vec<StreamBuffer> {
    let mut b = StreamBuffer::default_set(Codec::Raw).to_vec();
    for x in &mut b {
        x.codec = Codec::Raw;
    }
    b
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_clients_receive_every_frame_in_order_and_intact() {
    for buffers in [all_raw(), StreamBuffer::default_set(Codec::Zstd).to_vec()] {
        let fx = fixture(buffers).await;
        let mut a = client::connect(fx.config()).await.unwrap();
        let mut b = client::connect(fx.config()).await.unwrap();
        assert_eq!(a.welcome.size, SIZE);
        assert_ne!(a.welcome.session_id, b.welcome.session_id);
        let source = fx.start_source();
        let (ra, rb) = tokio::join!(receive_all(&mut a), receive_all(&mut b));
        let originals: Vec<Frame> = DumpReader::open(&fx.dump)
            .unwrap()
            .frames()
            .map(Result::unwrap)
            .collect();
        for got in [&ra, &rb] {
            assert_eq!(got.len(), FRAMES as usize, "every frame arrives");
            for (g, w) in got.iter().zip(&originals) {
                assert!(same_frame(g, w), "frame {} differs", w.meta.index);
            }
        }
        let stats = a.stats();
        assert_eq!(stats.client.frames_received, FRAMES);
        assert_eq!(stats.client.frames_late + stats.client.frames_dropped, 0);
        source.stop();
        a.close().await;
        b.close().await;
        fx.server.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_token_pin_and_version_are_refused_with_the_reason() {
    let fx = fixture(StreamBuffer::default_set(Codec::Zstd).to_vec()).await;
    let mut bad_token = fx.config();
    bad_token.token = "guess".into();
    match client::connect(bad_token).await {
        Err(ConnectError::Rejected(r)) => assert_eq!(r.reason, RejectReason::BadToken),
        Err(e) => panic!("expected a BadToken refusal, got {e}"),
        Ok(_) => panic!("expected a BadToken refusal, got a session"),
    }
    let mut bad_pin = fx.config();
    bad_pin.pin = Pin::Sha256("00".repeat(32));
    match client::connect(bad_pin).await {
        Err(ConnectError::Connection(e)) => {
            assert!(e.to_string().contains("does not match the pin"), "{e}")
        }
        Err(e) => panic!("expected a pin mismatch, got {e}"),
        Ok(_) => panic!("expected a pin mismatch, got a session"),
    }
    let mut old = fx.config();
    old.version = 7;
    match client::connect(old).await {
        Err(ConnectError::Rejected(r)) => {
            assert_eq!(
                r.reason,
                RejectReason::UnsupportedVersion { server: 1 },
                "{}",
                r.message
            )
        }
        Err(e) => panic!("expected a version refusal, got {e}"),
        Ok(_) => panic!("expected a version refusal, got a session"),
    }
    // The certificate file pins as well as the fingerprint.
    let dir = tempfile::tempdir().unwrap();
    let cert = dir.path().join("cert.der");
    std::fs::write(&cert, fx.identity.cert.as_ref()).unwrap();
    let mut by_file = fx.config();
    by_file.pin = Pin::CertFile(cert);
    let s = client::connect(by_file).await.unwrap();
    s.close().await;
    assert!(
        fx.server
            .counters
            .refused
            .load(std::sync::atomic::Ordering::Relaxed)
            >= 2
    );
    fx.server.shutdown().await;
}
