//! Loopback throughput of the QUIC transport at 720p, per codec set: frames
//! of the default scene (rendered once on the GPU) go through a real server
//! and client on 127.0.0.1 one at a time; for each we time from the
//! broadcast to the decoded frame at the client.
//!
//! `cargo run --release -p tests --example loopback_throughput [FRAMES]`

use std::sync::Arc;
use std::time::{Duration, Instant};

use client::{ConnectConfig, Pin};
use host::serve::Server;
use host::session::Policy;
use host::source::{Feed, Source, StreamFrame};
use host::tls::Identity;
use protocol::assemble::encode_frame;
use protocol::wire::{StreamBuffer, WindowMode};
use protocol::{Codec, FrameSize};
use scene::Scene;
use scene::render::Renderer;

const SIZE: FrameSize = FrameSize::new(1280, 720);

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let count: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(30);
    let scene = Scene::load("builtin:default")?;
    let mut renderer = Renderer::new(scene, SIZE, std::path::Path::new("."))?;
    let frames: Vec<_> = (0..count as u64)
        .map(|k| renderer.render(30 + k, 30.0))
        .collect::<Result<_, _>>()?;
    let dir = tempfile::tempdir()?;
    let identity = Identity::load_or_create(dir.path())?;
    let mut all_raw = StreamBuffer::default_set(Codec::Raw).to_vec();
    for b in &mut all_raw {
        b.codec = Codec::Raw;
    }
    println!(
        "| codecs (color / depth / motion) | bytes per frame: color, depth, motion | mean ms per frame | p95 ms | Gbit/s |"
    );
    println!("|---|---|---|---|---|");
    for (name, buffers) in [
        ("raw / raw / raw", all_raw),
        (
            "raw / zstd / zstd",
            StreamBuffer::default_set(Codec::Raw).to_vec(),
        ),
        (
            "zstd / zstd / zstd",
            StreamBuffer::default_set(Codec::Zstd).to_vec(),
        ),
    ] {
        let policy = Policy {
            token: "t".into(),
            server_name: "bench".into(),
            size: SIZE,
            max_frame: SIZE,
            fps: 30.0,
            buffers: buffers.clone(),
            window_mode: WindowMode::Off,
            max_sessions: host::session::DEFAULT_MAX_SESSIONS,
            congestion: host::tls::Congestion::default(),
            effects: protocol::Effects::UNKNOWN,
        };
        let tx = Source::channel();
        let server = Server::start(
            "127.0.0.1:0".parse()?,
            &identity,
            policy,
            Feed::Live(tx.clone()),
        )?;
        let mut session = client::connect(ConnectConfig::new(
            server.local_addr()?,
            Pin::Sha256(identity.fingerprint()),
            "t",
        ))
        .await?;
        let encoded: Vec<Arc<StreamFrame>> = frames
            .iter()
            .map(|f| {
                let e = encode_frame(f, &buffers, protocol::codec::DEFAULT_ZSTD_LEVEL)?;
                Ok(Arc::new(StreamFrame {
                    index: f.meta.index,
                    buffer_bytes: e
                        .header
                        .buffers
                        .iter()
                        .map(|b| (b.kind, b.payload_len))
                        .collect(),
                    bytes: e.to_stream_bytes()?,
                    keyframe: true,
                }))
            })
            .collect::<anyhow::Result<_>>()?;
        let mut times = Vec::with_capacity(count);
        let mut total_bytes = 0usize;
        for f in &encoded {
            let start = Instant::now();
            anyhow::ensure!(tx.send(f.clone()) > 0, "no subscriber");
            let got = tokio::time::timeout(Duration::from_secs(10), session.frames.recv())
                .await?
                .ok_or_else(|| anyhow::anyhow!("session ended"))?;
            anyhow::ensure!(got.frame.meta.index == f.index, "frames out of order");
            times.push(start.elapsed().as_secs_f64() * 1000.0);
            total_bytes += f.bytes.len();
        }
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let p95 = sorted[(sorted.len() * 95 / 100).min(sorted.len() - 1)];
        let avg = |i: usize| {
            encoded.iter().map(|f| f.buffer_bytes[i].1).sum::<u64>() / encoded.len() as u64
        };
        println!(
            "| {name} | {}, {}, {} | {mean:.2} | {p95:.2} | {:.2} |",
            avg(0),
            avg(1),
            avg(2),
            total_bytes as f64 * 8.0 / (times.iter().sum::<f64>() / 1000.0) / 1e9
        );
        session.close().await;
        server.shutdown().await;
    }
    Ok(())
}
