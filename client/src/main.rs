//! `client`: the streaming client's command line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand};
use client::{ConnectConfig, Pin};
use protocol::dump::{DumpWriter, Manifest};

#[derive(Parser)]
#[command(version, about = "Frame-generation streaming client")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Connect to a server and receive frames.
    Connect {
        /// Server address.
        #[arg(default_value = "127.0.0.1:4433")]
        addr: SocketAddr,
        /// SHA-256 fingerprint of the server certificate (as `server serve`
        /// prints it).
        #[arg(long, conflicts_with_all = ["pin_file", "dangerous_accept_any_certificate"])]
        pin: Option<String>,
        /// The server certificate (DER) to pin.
        #[arg(long)]
        pin_file: Option<PathBuf>,
        /// Trust any certificate. Anyone on the path can impersonate the
        /// server: for debugging only.
        #[arg(long)]
        dangerous_accept_any_certificate: bool,
        /// Access token.
        #[arg(long, env = "FRAMEGEN_TOKEN")]
        token: String,
        /// Stop after this many frames.
        #[arg(long)]
        frames: Option<u64>,
        /// Stop after this many seconds.
        #[arg(long)]
        seconds: Option<f64>,
        /// Write the received frames as a dump.
        #[arg(long)]
        dump_to: Option<PathBuf>,
    },
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .init();
    let Command::Connect {
        addr,
        pin,
        pin_file,
        dangerous_accept_any_certificate,
        token,
        frames,
        seconds,
        dump_to,
    } = Cli::parse().command;
    let pin = match (pin, pin_file, dangerous_accept_any_certificate) {
        (Some(hex), _, _) => Pin::Sha256(hex),
        (None, Some(file), _) => Pin::CertFile(file),
        (None, None, true) => {
            eprintln!(
                "WARNING: accepting any server certificate; the connection can be impersonated"
            );
            Pin::DangerousAcceptAnyCertificate
        }
        (None, None, false) => {
            anyhow::bail!("give --pin FINGERPRINT or --pin-file CERT (see `server serve` output)")
        }
    };
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async move {
        let mut session = client::connect(ConnectConfig::new(addr, pin, token)).await?;
        let w = &session.welcome;
        println!(
            "session {} with {}: {}x{} at {} fps, buffers {:?}, window {:?}",
            w.session_id, w.server_name, w.size.width, w.size.height, w.fps, w.buffers, w.window_mode
        );
        let mut writer = match &dump_to {
            Some(dir) => Some(DumpWriter::create(
                dir,
                Manifest::new(w.fps, w.size, format!("client connect {addr}")),
            )?),
            None => None,
        };
        let started = Instant::now();
        let deadline = seconds.map(|s| started + Duration::from_secs_f64(s.max(0.0)));
        let mut count = 0u64;
        loop {
            if frames.is_some_and(|n| count >= n) || deadline.is_some_and(|d| Instant::now() >= d) {
                break;
            }
            let frame = match tokio::time::timeout(Duration::from_millis(250), session.frames.recv()).await {
                Ok(Some(f)) => f,
                Ok(None) => break,
                Err(_) => continue,
            };
            count += 1;
            if let Some(w) = writer.as_mut() {
                w.write_frame(&frame)?;
            }
            if count % 30 == 0 {
                let s = session.stats();
                eprintln!(
                    "{count} frames, {:.1} fps, {:.1} MB, rtt {:.1} ms, late {}, dropped {}",
                    count as f64 / started.elapsed().as_secs_f64(),
                    s.client.bytes_received as f64 / 1e6,
                    s.client.rtt_us as f64 / 1000.0,
                    s.client.frames_late,
                    s.client.frames_dropped
                );
            }
        }
        let s = session.stats();
        if let Some(reason) = session.close_reason() {
            println!("connection closed: {reason}");
        }
        println!(
            "received {count} frames in {:.2} s; {} bytes; late {}, dropped {}; server reports sent {}, dropped {}",
            started.elapsed().as_secs_f64(),
            s.client.bytes_received,
            s.client.frames_late,
            s.client.frames_dropped,
            s.server.map_or(0, |x| x.frames_sent),
            s.server.map_or(0, |x| x.frames_dropped),
        );
        if let Some(w) = writer {
            let m = w.finish()?;
            println!("wrote {} frames to {}", m.frame_count, dump_to.unwrap_or_default().display());
        }
        session.close().await;
        anyhow::Ok(())
    })
}
