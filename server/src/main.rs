//! `server`: the frame server's command line.

mod inspect;

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};
use host::source::{Feed, Source, SourceSpec};
use indicatif::{ProgressBar, ProgressStyle};
use protocol::FrameSize;
use protocol::dump::{DumpWriter, Manifest};
use protocol::import::{AnyDump, Format};
use protocol::wire::{BufferSet, WindowMode};
use scene::render::{Renderer, WindowSettings, plan};
use scene::{Scene, builtin};

#[derive(Parser)]
#[command(
    version,
    about = "Frame-generation streaming server: renders scenes (wgpu) or replays dumps and streams HDR colour, depth, motion and camera over QUIC",
    after_help = "Main commands:
  server record                     render builtin:default (1280x720, 2 s) into dumps/
  server serve                      stream builtin:default live at 640x360 over QUIC
  server serve --dump DIR --loop    stream a dump (native, Blender or Unreal)
  server info --list                the built-in scenes
  server inspect DIR                check a dump
  server import SRC --out DIR       convert a Blender render or an Unreal capture

The GPU: Vulkan first (Mesa's lavapipe without a GPU), OpenGL as the fallback;
--adapter NAME or WGPU_BACKEND=vulkan|gl choose. Without any adapter:
apt-get install -y mesa-vulkan-drivers libvulkan1"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Use the GPU adapter whose name contains NAME (e.g. llvmpipe,
    /// lavapipe, nvidia); WGPU_BACKEND restricts the backends.
    #[arg(long, global = true, env = "WGPU_ADAPTER_NAME", value_name = "NAME")]
    adapter: Option<String>,
}

#[derive(clap::Args)]
struct RecordArgs {
    /// `builtin:NAME` or a path to a RON scene file.
    #[arg(default_value = "builtin:default")]
    scene: String,
    /// Output directory (must not hold a dump yet); default
    /// `dumps/SCENE-UNIXTIME`.
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Frames per second of the recording.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Size as WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = clap::value_parser!(FrameSize))]
    size: FrameSize,
    /// Duration in seconds.
    #[arg(long, default_value_t = 2.0)]
    seconds: f64,
    /// First frame index (time = index / fps).
    #[arg(long, default_value_t = 0)]
    start: u64,
    /// Also write display-encoded PNGs of the color to OUT/png/.
    #[arg(long)]
    png: bool,
    /// Adaptive rendering window (GFFE §4.3): off, keep-density (the
    /// rendered size grows) or keep-size (lower density).
    #[arg(long, default_value = "off", value_parser = clap::value_parser!(WindowMode))]
    window: WindowMode,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene into a dump (OpenEXR + JSON per frame).
    #[command(after_help = "Examples:
  server record                                      builtin:default, 1280x720, 2 s
  server record builtin:crossing --size 640x360 --seconds 1 --png --out /tmp/crossing")]
    Record(RecordArgs),
    /// Stream a scene (rendered live) or a dump over QUIC to clients.
    #[command(after_help = "Examples:
  server serve                                   builtin:default at 640x360, 30 fps on 127.0.0.1:4433
  server serve --dump dumps/default-1 --loop     a dump, looped, as one live stream
  server serve --interactive --size 320x180      each client's input drives its own camera
Then: client connect --pin FINGERPRINT --token TOKEN (both printed at start)")]
    Serve {
        /// `builtin:NAME` or a RON scene file (ignored with --dump).
        #[arg(default_value = "builtin:default")]
        scene: String,
        /// Replay this dump instead of rendering.
        #[arg(long)]
        dump: Option<PathBuf>,
        /// Loop the dump.
        #[arg(long = "loop")]
        looped: bool,
        /// Address to listen on.
        #[arg(long, default_value = "127.0.0.1:4433")]
        listen: std::net::SocketAddr,
        /// Where the TLS certificate and key live (created on first start).
        #[arg(long, default_value = "server-identity")]
        identity: PathBuf,
        /// Access token clients must present; a random one is made and
        /// printed if absent.
        #[arg(long, env = "FRAMEGEN_TOKEN")]
        token: Option<String>,
        /// Render rate for scenes.
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Displayed size for scenes, WIDTHxHEIGHT.
        #[arg(long, default_value = "640x360", value_parser = clap::value_parser!(FrameSize))]
        size: FrameSize,
        /// Adaptive rendering window (GFFE §4.3): off, keep-density or
        /// keep-size. Default: keep-density for scenes (extrapolated frames
        /// get content at their borders for a few % more pixels; README,
        /// "Evaluate"), off for dumps (they play as recorded).
        #[arg(long, value_parser = clap::value_parser!(WindowMode))]
        window: Option<WindowMode>,
        /// Colour codec: `h264` (libx264 at 0.6 bits a pixel a frame, e.g.
        /// 4.1 Mbit/s for 640x360 at 30 fps), `h264@MBIT`, `h264-444[@MBIT]`;
        /// `raw` or lossless `zstd` f16 for research.
        #[arg(long, default_value = "h264", value_parser = clap::value_parser!(video::ColorCodec))]
        color_codec: video::ColorCodec,
        /// How depth and motion travel: `compact` (depth quantised with a
        /// bounded error, motion as the residual over the camera) or
        /// `lossless` (zstd).
        #[arg(long, default_value = "compact", value_parser = clap::value_parser!(BufferSet))]
        geometry: BufferSet,
        /// Render the scene for each client from the camera its input
        /// sends (issue 20; the scene's path until the first input), each
        /// frame echoing the input it was rendered with. Every session
        /// costs a render.
        #[arg(long, conflicts_with = "dump")]
        interactive: bool,
        /// Most sessions at once; one more is refused as "server full".
        /// Default: 16, or 2 with --interactive (each renders).
        #[arg(long)]
        max_sessions: Option<usize>,
        /// Congestion control of the frames sent: cubic (loss-based) or bbr
        /// (model-based: keeps a stream through random loss, starves under
        /// strongly varying delay; see the README's "Impaired networks").
        #[arg(long, default_value = "cubic")]
        congestion: host::tls::Congestion,
    },
    /// Show what a scene declares and which passes it builds.
    #[command(after_help = "Examples:
  server info --list
  server info builtin:default")]
    Info {
        /// `builtin:NAME` or a path; omit with --list.
        scene: Option<String>,
        /// List the built-in scenes.
        #[arg(long)]
        list: bool,
    },
    /// Read every frame of a dump and report its contents and any problem.
    #[command(after_help = "Example:
  server inspect dumps/default-1700000000")]
    Inspect {
        /// The dump directory (holding manifest.json).
        dir: PathBuf,
    },
    /// Convert a Blender render or an Unreal capture into a dump, checking
    /// its motion vectors against depth + camera.
    #[command(after_help = "Example:
  server import tests/fixtures/blender --out /tmp/blender-dump")]
    Import {
        /// The source directory (holding cameras.json).
        src: PathBuf,
        /// Output directory (must not hold a dump yet).
        #[arg(long, short)]
        out: PathBuf,
        /// What the source is; `auto` tells it from the sidecar.
        #[arg(long, value_enum, default_value_t = ImportFormat::Auto)]
        format: ImportFormat,
    },
}

/// `server import --format`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum ImportFormat {
    /// From cameras.json's `format`.
    Auto,
    /// A Blender render with the framegen_export.py sidecar.
    Blender,
    /// An Unreal folder-per-buffer capture.
    Unreal,
}

/// An error ends the process with one line on stderr (the whole chain, no
/// backtrace) and a non-zero status.
fn main() -> Result<(), gpu_device::OneLine> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .init();
    // The renderer's readback and the encoders free and allocate
    // frame-sized buffers every frame: keep them in the heap instead of
    // faulting fresh pages in each time.
    protocol::memory::retain_freed_memory();
    Ok(command(Cli::parse())?)
}

fn command(cli: Cli) -> anyhow::Result<()> {
    if let Some(name) = &cli.adapter {
        gpu_device::prefer_adapter(name);
    }
    match cli.command {
        Command::Record(args) => record(&args),
        Command::Info { scene, list } => info(scene.as_deref(), list),
        Command::Serve {
            scene,
            dump,
            looped,
            listen,
            identity,
            token,
            fps,
            size,
            window,
            color_codec,
            geometry,
            interactive,
            max_sessions,
            congestion,
        } => {
            let max_sessions = max_sessions.unwrap_or(if interactive {
                host::session::DEFAULT_MAX_INTERACTIVE_SESSIONS
            } else {
                host::session::DEFAULT_MAX_SESSIONS
            });
            let window = window.unwrap_or(if dump.is_some() {
                WindowMode::Off
            } else {
                WindowMode::KeepDensity
            });
            let (source, size, fps) = match dump {
                Some(dir) => {
                    // Native dumps, Blender renders and Unreal captures alike.
                    let dump = AnyDump::open(&dir)?;
                    let (size, fps) = (dump.size(), dump.fps());
                    (SourceSpec::Dump { dir, looped }, size, fps)
                }
                None => (
                    SourceSpec::Scene {
                        base: scene_base(&scene),
                        spec: scene,
                        size,
                        fps,
                        window: WindowSettings {
                            mode: window,
                            ..WindowSettings::default()
                        },
                    },
                    size,
                    fps,
                ),
            };
            let runtime = tokio::runtime::Runtime::new()?;
            runtime.block_on(serve(ServeArgs {
                source,
                size,
                fps,
                listen,
                identity,
                token,
                window,
                color_codec,
                geometry,
                interactive,
                max_sessions,
                congestion,
            }))
        }
        Command::Inspect { dir } => inspect(&dir),
        Command::Import { src, out, format } => import(&src, &out, format),
    }
}

/// `dumps/NAME-UNIXTIME` for a scene spec.
fn default_out(spec: &str) -> PathBuf {
    let name = Path::new(spec.trim_start_matches("builtin:"))
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    PathBuf::from("dumps").join(format!("{name}-{secs}"))
}

/// Directory that relative glTF paths of a scene resolve against.
fn scene_base(spec: &str) -> PathBuf {
    match spec.strip_prefix("builtin:") {
        Some(_) => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes"),
        None => Path::new(spec)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default(),
    }
}

fn progress(len: u64, what: &str) -> ProgressBar {
    let style = ProgressStyle::with_template(&format!(
        "{{bar:40}} {{pos}}/{{len}} {what} {{elapsed}} eta {{eta}}"
    ))
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    ProgressBar::new(len).with_style(style)
}

fn record(args: &RecordArgs) -> anyhow::Result<()> {
    let spec = args.scene.as_str();
    let (fps, size, seconds, start, png, window) = (
        args.fps,
        args.size,
        args.seconds,
        args.start,
        args.png,
        args.window,
    );
    let out = &args.out.clone().unwrap_or_else(|| default_out(spec));
    anyhow::ensure!(
        fps.is_finite() && fps > 0.0 && fps <= 1000.0,
        "fps must be in (0, 1000]"
    );
    anyhow::ensure!(seconds.is_finite() && seconds > 0.0, "seconds must be > 0");
    let scene = Scene::load(spec)?;
    let effects = scene.stream_effects();
    let frames = (seconds * fps).round().max(1.0) as u64;
    let mut renderer = Renderer::new(scene, size, &scene_base(spec))?;
    renderer.set_window(WindowSettings {
        mode: window,
        ..WindowSettings::default()
    });
    let source = format!(
        "server record {spec} --fps {fps} --size {}x{} --seconds {seconds} --start {start} --window {window:?}; adapter {} ({:?}); passes {:?}",
        size.width,
        size.height,
        renderer.adapter().name,
        renderer.adapter().backend,
        renderer.passes()
    );
    let mut writer =
        DumpWriter::create(out, Manifest::new(fps, size, source).with_effects(effects))?;
    if png {
        std::fs::create_dir_all(out.join("png"))?;
    }
    let bar = progress(frames, "frames");
    let mut total = std::time::Duration::ZERO;
    for k in 0..frames {
        let index = start + k;
        let frame = renderer.render(index, fps)?;
        total += frame.meta.host_processing;
        if png {
            let path = out.join("png").join(format!("{k:06}.png"));
            write_png(&path, &frame)?;
        }
        writer.write_frame(&frame)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    writer.finish()?;
    println!(
        "{}: {frames} frames of {spec} at {}x{}, {:.1} ms/frame rendering (submit + readback)",
        out.display(),
        size.width,
        size.height,
        total.as_secs_f64() * 1000.0 / frames as f64
    );
    Ok(())
}

fn write_png(path: &Path, frame: &protocol::Frame) -> anyhow::Result<()> {
    let size = frame.meta.size;
    let img = protocol::display::display_encode(size.width, size.height, &frame.color)
        .context("color buffer does not match the frame size")?;
    image::save_buffer(
        path,
        &img.to_rgb8(),
        size.width,
        size.height,
        image::ExtendedColorType::Rgb8,
    )
    .with_context(|| format!("writing {}", path.display()))
}

struct ServeArgs {
    source: SourceSpec,
    size: FrameSize,
    fps: f64,
    listen: std::net::SocketAddr,
    identity: PathBuf,
    token: Option<String>,
    window: WindowMode,
    color_codec: video::ColorCodec,
    geometry: BufferSet,
    interactive: bool,
    max_sessions: usize,
    congestion: host::tls::Congestion,
}

async fn serve(args: ServeArgs) -> anyhow::Result<()> {
    let identity = host::tls::Identity::load_or_create(&args.identity)?;
    let token = args.token.unwrap_or_else(host::session::random_token);
    anyhow::ensure!(!token.is_empty(), "--token must not be empty");
    let encoding = host::source::Encoding::new(args.geometry, args.color_codec);
    let max_frame = host::session::max_frame(
        args.size,
        &WindowSettings {
            mode: args.window,
            ..WindowSettings::default()
        },
    );
    let effects = args.source.effects()?;
    let policy = host::session::Policy {
        token: token.clone(),
        server_name: "framegen-stream server".into(),
        size: args.size,
        max_frame,
        fps: args.fps,
        buffers: encoding.buffers.clone(),
        window_mode: args.window,
        max_sessions: args.max_sessions,
        congestion: args.congestion,
        effects,
    };
    // A dump replay without --loop starts afresh for every client; a scene
    // (or a looping dump) is one live stream that clients join.
    let per_session = matches!(args.source, SourceSpec::Dump { looped: false, .. });
    let (feed, source) = if args.interactive {
        (Feed::interactive(args.source, encoding, None)?, None)
    } else if per_session {
        (
            Feed::PerSession {
                spec: args.source,
                encoding,
            },
            None,
        )
    } else {
        let frames = Source::channel();
        let source = Source::start(args.source, encoding, frames.clone())?;
        (Feed::Live(frames), Some(source))
    };
    let server = host::serve::Server::start(args.listen, &identity, policy, feed)?;
    println!("listening on {}", server.local_addr()?);
    println!("certificate SHA-256: {}", identity.fingerprint());
    println!("token: {token}");
    println!("stream effects (the client plans its stages from them): {effects}");
    println!(
        "connect with: client connect {} --pin {} --token {token}",
        server.local_addr()?,
        identity.fingerprint()
    );
    tokio::signal::ctrl_c().await?;
    println!("shutting down");
    let load = |f: fn(&host::source::SourceStats) -> &std::sync::atomic::AtomicU64| {
        source.as_ref().map_or(0, |s| {
            f(&s.stats).load(std::sync::atomic::Ordering::Relaxed)
        })
    };
    let (produced, skipped) = (load(|s| &s.produced), load(|s| &s.skipped));
    let unreadable = load(|s| &s.unreadable);
    let c = &server.counters;
    println!(
        "frames produced {produced}, skipped by the pacer {skipped}, unreadable {unreadable}; sessions {}, refused {}, frames sent {}, dropped for slow clients {}",
        c.sessions.load(std::sync::atomic::Ordering::Relaxed),
        c.refused.load(std::sync::atomic::Ordering::Relaxed),
        c.frames_sent.load(std::sync::atomic::Ordering::Relaxed),
        c.frames_dropped.load(std::sync::atomic::Ordering::Relaxed),
    );
    server.shutdown().await;
    if let Some(source) = source {
        source.stop();
    }
    Ok(())
}

fn info(spec: Option<&str>, list: bool) -> anyhow::Result<()> {
    if list || spec.is_none() {
        for name in builtin::names() {
            let s = Scene::load(&format!("builtin:{name}"))?;
            println!("builtin:{name:<15} {}", s.description);
        }
        return Ok(());
    }
    let spec = spec.unwrap_or_default();
    let s = Scene::load(spec)?;
    println!("{} — {}", s.name, s.description);
    println!("effects: {:?}", s.effects);
    println!(
        "stream:  {} (the client's generation plan)",
        s.stream_effects()
    );
    println!("passes:  {:?}", plan(&s));
    println!("origin:  {:?}", s.origin);
    println!("camera:  fov {}°, {:?}", s.camera.fov_y_deg, s.camera.path);
    println!(
        "objects: {} ({} drawn instances)",
        s.objects.len(),
        s.instances().len()
    );
    for o in &s.objects {
        println!(
            "  {:<14} {:?} material {:?} animations {}",
            o.name,
            o.mesh,
            o.material,
            o.animation.len()
        );
    }
    println!("lights:  {}", s.lights.len());
    for l in &s.lights {
        println!(
            "  {:?} intensity {} shadows {} motion {:?}",
            l.kind, l.intensity, l.shadows, l.motion
        );
    }
    Ok(())
}

fn inspect(dir: &Path) -> anyhow::Result<()> {
    let reader = AnyDump::open(dir).with_context(|| format!("opening {}", dir.display()))?;
    match &reader {
        AnyDump::Native(native) => {
            let m = native.manifest();
            println!(
                "{}: {} frames, {}x{} at {} fps, format v{}, conventions v{}\nsource: {}",
                dir.display(),
                m.frame_count,
                m.width,
                m.height,
                m.fps,
                m.format_version,
                m.conventions_version,
                m.source
            );
        }
        foreign => print_source(foreign),
    }
    let bar = progress(reader.len(), "frames");
    let report = inspect::inspect(&reader, |i| bar.set_position(i));
    bar.finish_and_clear();
    println!(
        "cuts: {}  sky pixels: {}  max motion: {:.2} px  mean frame interval: {:.4} s",
        report.cuts, report.sky_pixels, report.max_motion, report.mean_frame_interval
    );
    for (i, e) in &report.unreadable {
        println!("frame {i}: {e}");
    }
    if report.time_not_increasing > 0 {
        println!(
            "{} frames do not advance in time",
            report.time_not_increasing
        );
    }
    if report.bad_values > 0 {
        println!(
            "{} NaN or non-positive values in color/depth/motion",
            report.bad_values
        );
    }
    print_reprojection(&report.reprojection);
    anyhow::ensure!(report.is_clean(), "the dump has problems (see above)");
    println!("ok");
    Ok(())
}

fn import(src: &Path, out: &Path, format: ImportFormat) -> anyhow::Result<()> {
    let format = match format {
        ImportFormat::Auto => Format::detect(src)?,
        ImportFormat::Blender => Format::Blender,
        ImportFormat::Unreal => Format::Unreal,
    };
    let dump = AnyDump::open_as(src, format)
        .with_context(|| format!("opening {} as {}", src.display(), format.name()))?;
    print_source(&dump);
    let bar = progress(dump.len(), "frames");
    let report = protocol::import::import(&dump, out, |i| bar.set_position(i))?;
    bar.finish_and_clear();
    println!(
        "wrote {} of {} frames to {}",
        report.written,
        report.source_frames,
        out.display()
    );
    for p in &report.problems {
        let what = if p.skipped { "skipped" } else { "kept" };
        println!("frame {} ({what}): {}", p.position, p.detail);
    }
    print_reprojection(&report.reprojection);
    Ok(())
}

/// Prints the motion check of `import` and `inspect`, its alternatives and
/// its warnings (on stderr, loudly).
fn print_reprojection(r: &protocol::import::ReprojectionReport) {
    if r.pixels == 0 {
        println!("motion check: no pixel to check (one frame, or every pixel masked)");
    } else {
        println!(
            "motion vs depth + camera: mean {:.4} px, median {:.4} px, {:.1} % within 1 px \
             ({} pixels in {} frames)",
            r.mean_px,
            r.median_px,
            100.0 * r.within_1px,
            r.pixels,
            r.frames
        );
        for a in &r.alternatives {
            println!(
                "  if {}: mean {:.4} px, median {:.4} px",
                a.hypothesis.describe(),
                a.mean_px,
                a.median_px
            );
        }
    }
    for w in &r.warnings {
        eprintln!("WARNING: {w}");
    }
}

/// One line on a dump: what it is, how many frames, size and rate.
fn print_source(dump: &AnyDump) {
    println!(
        "{}: {} frames, {}x{} at {} fps",
        dump.describe(),
        dump.len(),
        dump.size().width,
        dump.size().height,
        dump.fps()
    );
}
