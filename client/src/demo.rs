//! The one-command demo (the README's main job): an in-process server on
//! loopback renders a built-in scene live, the client connects over real
//! QUIC + TLS (pinning the server's fresh self-signed certificate),
//! generates frames and presents them.

use std::net::SocketAddr;
use std::sync::Arc;

use host::serve::Server;
use host::session::Policy;
use host::source::{Encoding, Feed, Source, SourceSpec};
use host::tls::{Congestion, Identity};
use protocol::FrameSize;
use protocol::wire::{BufferSet, WindowMode};
use scene::render::WindowSettings;

use crate::priority::Background;
use crate::{ConnectConfig, Pin, Stream};

/// A running in-process server and its source.
pub struct LocalServer {
    /// The QUIC endpoint.
    pub server: Server,
    /// Where it listens.
    pub addr: SocketAddr,
    /// The certificate fingerprint to pin.
    pub fingerprint: String,
    /// The access token.
    pub token: String,
    _source: Option<Source>,
    _identity_dir: tempfile::TempDir,
}

/// How the in-process server sends: congestion control and colour codec
/// (as `server serve --congestion --color-codec`; depth and motion go as
/// the compact set).
#[derive(Clone, Copy, Debug)]
pub struct Link {
    /// Congestion control of the frames.
    pub congestion: Congestion,
    /// The colour codec.
    pub color: video::ColorCodec,
    /// Render for each client from the camera its input sends (`serve
    /// --interactive`, issue 20) instead of one live stream.
    pub interactive: bool,
    /// The adaptive rendering window of a scene (`serve --window`).
    pub window: WindowMode,
    /// How far the in-process server's rendering, encoding and producing
    /// step back from the presenter's and the generator's work.
    pub server_priority: Background,
}

impl Default for Link {
    /// Cubic, colour through H.264 at the automatic rate, no adaptive
    /// window, the server at [`Background::Low`].
    fn default() -> Self {
        Self {
            congestion: Congestion::default(),
            color: video::ColorCodec::DEFAULT_LIVE,
            interactive: false,
            window: WindowMode::Off,
            server_priority: Background::Low,
        }
    }
}

/// Starts a server on 127.0.0.1 (a free port) rendering `scene` at `size`
/// and `fps`, its frames sent over `link`: live, or for each client from
/// its viewer's input (`link.interactive`).
pub fn start_local(
    scene: &str,
    size: FrameSize,
    fps: f64,
    link: Link,
) -> anyhow::Result<LocalServer> {
    let window = WindowSettings {
        mode: link.window,
        ..WindowSettings::default()
    };
    start_local_from(
        scene_spec(scene, size, fps, window),
        (size, fps),
        window,
        link,
    )
}

fn scene_spec(scene: &str, size: FrameSize, fps: f64, window: WindowSettings) -> SourceSpec {
    SourceSpec::Scene {
        spec: scene.into(),
        size,
        fps,
        window,
        base: std::path::PathBuf::from("."),
    }
}

/// [`start_local`] with the adaptive rendering window in `mode` (GFFE §4.3).
pub fn start_local_windowed(
    scene: &str,
    size: FrameSize,
    fps: f64,
    mode: WindowMode,
) -> anyhow::Result<LocalServer> {
    let window = WindowSettings {
        mode,
        ..WindowSettings::default()
    };
    start_local_from(
        scene_spec(scene, size, fps, window),
        (size, fps),
        window,
        Link::default(),
    )
}

/// Starts a server on 127.0.0.1 replaying the dump in `dir` (looped, as one
/// live stream) at its own size and rate: a native dump, a Blender render or
/// an Unreal capture.
pub fn start_local_dump(dir: &std::path::Path, link: Link) -> anyhow::Result<LocalServer> {
    let dump = protocol::import::AnyDump::open(dir)?;
    start_local_from(
        SourceSpec::Dump {
            dir: dir.to_path_buf(),
            looped: true,
        },
        (dump.size(), dump.fps()),
        WindowSettings::default(),
        link,
    )
}

fn start_local_from(
    spec: SourceSpec,
    (size, fps): (FrameSize, f64),
    window: WindowSettings,
    link: Link,
) -> anyhow::Result<LocalServer> {
    let interactive = link.interactive;
    let identity_dir = tempfile::tempdir()?;
    let identity = Identity::load_or_create(identity_dir.path())?;
    let token = host::session::random_token();
    let encoding = Encoding::new(BufferSet::Compact, link.color);
    let buffers = encoding.buffers.clone();
    let policy = Policy {
        token: token.clone(),
        server_name: "in-process demo server".into(),
        size,
        max_frame: host::session::max_frame(size, &window),
        fps,
        buffers: buffers.clone(),
        window_mode: window.mode,
        max_sessions: if interactive {
            host::session::DEFAULT_MAX_INTERACTIVE_SESSIONS
        } else {
            host::session::DEFAULT_MAX_SESSIONS
        },
        congestion: link.congestion,
        effects: spec.effects()?,
    };
    let (feed, source) = if interactive {
        // Each session's renderer, encoder and producer, as the live
        // stream's below.
        let opener: host::source::Opener = match link.server_priority {
            Background::Low => crate::priority::open_in_background,
            Background::Idle => crate::priority::open_idle,
        };
        (Feed::interactive(spec, encoding, Some(opener))?, None)
    } else {
        let frames = Source::channel();
        // The renderer (its driver's threads, the software rasteriser's
        // here), the encoder and the producer loop run at a lower
        // priority: they stand in for a remote machine, and on this one
        // they must not take the presenter's and the generator's time.
        let channel = frames.clone();
        let what = "the in-process server";
        let source = crate::priority::start_at(what, link.server_priority, || {
            Source::start(spec, encoding, channel)
        })??;
        (Feed::Live(frames), Some(source))
    };
    let server = Server::start("127.0.0.1:0".parse()?, &identity, policy, feed)?;
    let addr = server.local_addr()?;
    Ok(LocalServer {
        server,
        addr,
        fingerprint: identity.fingerprint(),
        token,
        _source: source,
        _identity_dir: identity_dir,
    })
}

impl LocalServer {
    /// How a client reaches and authenticates to it.
    pub fn config(&self) -> ConnectConfig {
        ConnectConfig::new(
            self.addr,
            Pin::Sha256(self.fingerprint.clone()),
            self.token.clone(),
        )
    }

    /// Connects a client stream to it.
    pub async fn connect(&self) -> anyhow::Result<Stream> {
        Ok(Stream::connect(self.config(), crate::ReconnectPolicy::default()).await?)
    }
}

/// Opens the GPU for frame generation, or says why not.
pub fn gpu() -> anyhow::Result<Arc<framegen::GpuContext>> {
    Ok(framegen::GpuContext::new()?)
}
