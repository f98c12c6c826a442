//! `client`: the streaming client's command line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::{Args, Parser, Subcommand};
use client::frame_writer::{DumpSink, FrameWriter};
use client::impair::{Impairment, Relay};
use client::present::{PresentConfig, ViewerSource, run_headless};
use client::{ConnectConfig, Pin};
use framegen::Method;
use framegen::accounting::Percentiles;
use protocol::FrameSize;
use protocol::dump::{DumpWriter, Manifest};
use protocol::wire::WindowMode;

#[derive(Parser)]
#[command(
    version,
    about = "Frame-generation streaming client: receives rendered frames over QUIC and generates the ones in between (repeat, reproject, gffe, interp)",
    after_help = "Main commands:
  client                              the demo: an in-process server, gffe 30 -> 60 fps, 5 s
  client run --method interp -n 2     another method (repeat, reproject, gffe, interp) and n
  client connect --pin FP --token T   receive from `server serve`
  client eval                         quality against milliseconds for every method

The GPU: Vulkan first (Mesa's lavapipe without a GPU), OpenGL as the fallback;
--adapter NAME or WGPU_BACKEND=vulkan|gl choose. Without any adapter:
apt-get install -y mesa-vulkan-drivers libvulkan1"
)]
struct Cli {
    /// Without a subcommand: `run` with its defaults (the demo).
    #[command(subcommand)]
    command: Option<Command>,
    /// Use the GPU adapter whose name contains NAME (e.g. llvmpipe,
    /// lavapipe, nvidia); WGPU_BACKEND restricts the backends.
    #[arg(long, global = true, env = "WGPU_ADAPTER_NAME", value_name = "NAME")]
    adapter: Option<String>,
}

/// Options of `run`.
#[derive(Args, Clone, Debug)]
struct RunArgs {
    /// Frame generation method: repeat, reproject, gffe (extrapolation, no
    /// added latency) or interp (interpolation, one render interval later).
    #[arg(long, default_value = "gffe")]
    method: Method,
    /// Generated frames per rendered frame (display = (n+1) × render rate).
    #[arg(short, long, default_value_t = 1)]
    n: u32,
    /// No shading correction (GFFE §4.4; gffe), which otherwise runs where
    /// the stream's effects say shading moves (README, "Shading
    /// correction").
    #[arg(long)]
    no_shading: bool,
    /// Run every stage of the method, whatever the stream's effects (the
    /// plan otherwise leaves out what the content does not call for).
    #[arg(long)]
    every_stage: bool,
    /// Rendered size (in-process server).
    #[arg(long, default_value = "320x180", value_parser = clap::value_parser!(FrameSize))]
    size: FrameSize,
    /// Render rate (in-process server).
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Scene of the in-process server: builtin:NAME or a RON file.
    #[arg(long, default_value = "builtin:default")]
    scene: String,
    /// Seconds to present.
    #[arg(long, default_value_t = 5.0)]
    seconds: f64,
    /// Largest α extrapolated before the last frame is held.
    #[arg(long, default_value_t = 3.0)]
    max_alpha: f64,
    /// Use a remote server instead of the in-process one (needs --pin and --token).
    #[arg(long)]
    server: Option<SocketAddr>,
    /// SHA-256 fingerprint of the remote server's certificate.
    #[arg(long)]
    pin: Option<String>,
    /// Access token of the remote server.
    #[arg(long, env = "FRAMEGEN_TOKEN")]
    token: Option<String>,
    /// Where frames are generated: `wgpu`, `cpu` (the reference), or
    /// `auto`: wgpu on a hardware adapter, the CPU reference when the only
    /// adapter is a software rasteriser (lavapipe shares the CPU with the
    /// in-process server's renderer, and the reference, on all cores, is
    /// faster there; see the README).
    #[arg(long, default_value = "auto", value_parser = ["auto", "wgpu", "cpu"])]
    backend: String,
    /// Write every presented frame as a PNG into this directory.
    #[arg(long)]
    png: Option<PathBuf>,
    /// Write the full report (every displayed frame) as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Present in a window: `auto` when a display exists (DISPLAY or
    /// WAYLAND_DISPLAY), `on`, or `off` (headless).
    #[arg(long, default_value = "auto", value_parser = ["auto", "on", "off"])]
    window: String,
    /// Save the window's last frame (overlay included) as a PNG on exit.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Display refresh rate in Hz (default: (n + 1) × the render rate).
    #[arg(long)]
    refresh: Option<f64>,
    /// Stream this dump (looped) from the in-process server instead of
    /// rendering the scene.
    #[arg(long, conflicts_with = "server")]
    from_dump: Option<PathBuf>,
    /// Write every presented frame into a dump here.
    #[arg(long)]
    dump_to: Option<PathBuf>,
    /// Impair the network between client and server through a relay on
    /// 127.0.0.1, e.g. `loss=10%,delay=30ms,jitter=20ms,rate=50mbit`
    /// (also reorder=P%, limit=DATAGRAMS, seed=N; netem's meanings).
    #[arg(long, value_name = "SPEC")]
    impair: Option<Impairment>,
    /// Reconnect to a server that went away for up to this many seconds
    /// (0: end with the session), presenting what is there meanwhile.
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    reconnect_for: f64,
    /// Congestion control of the in-process server's frames: cubic or bbr
    /// (as `server serve --congestion`).
    #[arg(long, default_value = "cubic")]
    congestion: host::tls::Congestion,
    /// Colour codec of the in-process server (as `server serve
    /// --color-codec`): `h264` (0.6 bits a pixel a frame), `h264@MBIT`,
    /// `h264-444[@MBIT]`; `raw` or `zstd` for research.
    #[arg(long, default_value = "h264", value_parser = clap::value_parser!(video::ColorCodec))]
    color_codec: video::ColorCodec,
    /// The viewer drives the camera (issue 20): the client sends its input
    /// every vsync, the server renders from it (`serve --interactive`; the
    /// in-process server does so with this flag), and with --late-input on
    /// every displayed frame is warped to the newest pose.
    #[arg(long)]
    interactive: bool,
    /// What moves the viewer (with --interactive): `builtin:turn` (90°/s),
    /// `builtin:look-around`, `builtin:walk` or a JSON track file (README,
    /// "Interactive streaming").
    /// Default: the window's mouse and keys in a window, `builtin:turn`
    /// headless.
    #[arg(long, value_name = "TRACK")]
    input_track: Option<String>,
    /// Late input (with --interactive): generated frames take the newest
    /// viewer pose instead of eq. 2, rendered frames are re-projected to
    /// it; `off` shows the camera the server rendered.
    #[arg(long, default_value = "on", value_parser = ["on", "off"])]
    late_input: String,
    /// The in-process server's adaptive rendering window (GFFE §4.3, as
    /// `server serve --window`): off, keep-density or keep-size. Off by
    /// default: the in-process renderer shares this machine's cores, and
    /// the widened frames cost it more than the borders they save
    /// (README, "Evaluate"); `serve` renders keep-density by default.
    #[arg(long, default_value = "off", value_parser = clap::value_parser!(WindowMode))]
    render_window: WindowMode,
    /// How far the in-process server's rendering and encoding step back
    /// from the presenter and the generator on this machine's cores:
    /// `low` (nice 10) or `idle` (Linux's SCHED_IDLE: only time nothing
    /// else wants; fewer missed vsyncs where the server and the client
    /// share few cores, but a machine busy with other work starves the
    /// server). README, "Live demo".
    #[arg(long, value_enum, default_value_t = client::priority::Background::Low)]
    server_priority: client::priority::Background,
}

impl Default for RunArgs {
    fn default() -> Self {
        /// `RunArgs` alone, to take its defaults from clap.
        #[derive(Parser)]
        struct Only {
            #[command(flatten)]
            args: RunArgs,
        }
        Only::parse_from(["client"]).args
    }
}

#[derive(Subcommand)]
enum Command {
    /// Receive frames, generate the in-between ones and present them
    /// (in a window when there is a display, else headless), then print the
    /// latency summary. Without --server it starts an in-process server on
    /// loopback rendering the scene.
    #[command(after_help = "Examples:
  client run                                         gffe, 320x180, 30 -> 60 fps, 5 s
  client run --method interp --size 640x360 --seconds 10
  client run --server 127.0.0.1:4433 --pin FP --token T --json report.json")]
    Run(Box<RunArgs>),
    /// Connect to a server and receive frames.
    #[command(after_help = "Example:
  client connect --pin FINGERPRINT --token TOKEN --seconds 5 --dump-to /tmp/rx")]
    Connect(ConnectArgs),
    /// Measure every method and setting against ground truth and time:
    /// writes report.md, report.json, plots and ꟻLIP heat maps.
    #[command(after_help = "Examples:
  client eval                                        builtin:default, every setting -> eval-report/
  client eval --all-scenes --sweep methods
  client eval --dump DIR --sweep methods --out /tmp/report")]
    Eval(EvalArgs),
}

/// Options of `eval`.
#[derive(Args)]
struct EvalArgs {
    /// Scenes (builtin:NAME or a RON file), each rendered at --fps.
    #[arg(long, value_delimiter = ',', default_value = "builtin:default")]
    scenes: Vec<String>,
    /// Add every built-in scene (the default scene and the hard cases).
    #[arg(long)]
    all_scenes: bool,
    /// Evaluate dumps rendered at the display rate instead of scenes.
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["scenes", "all_scenes"])]
    dump: Vec<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "eval-report")]
    out: PathBuf,
    /// Displayed size of rendered scenes.
    #[arg(long, default_value = "320x180", value_parser = clap::value_parser!(FrameSize))]
    size: FrameSize,
    /// Display rate of rendered scenes (the render rate is fps / (n + 1)).
    #[arg(long, default_value_t = 60.0)]
    fps: f64,
    /// First frame.
    #[arg(long, default_value_t = 30)]
    start: u64,
    /// Frames per sequence at the display rate.
    #[arg(long, default_value_t = 36)]
    frames: u64,
    /// `methods` (the four at their defaults) or `full` (every axis).
    #[arg(long, value_enum, default_value = "full")]
    sweep: client::eval::variant::Sweep,
    /// Backends to time; quality is scored on the first.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "cpu,wgpu")]
    backends: Vec<client::eval::BackendKind>,
    /// How wgpu passes are timed: `auto` (GPU timestamps on a hardware
    /// adapter, wall time on a software rasteriser, whose timestamps are
    /// unreliable), `wall` or `timestamps`.
    #[arg(long, default_value = "auto", value_parser = ["auto", "wall", "timestamps"])]
    pass_clock: String,
    /// Only the variants whose label contains one of these (e.g. `gffe,repeat n=2`).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Extra resolutions (the methods at their defaults) for the first scene, e.g. 640x360,960x540.
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(FrameSize))]
    resolutions: Vec<FrameSize>,
    /// How the fed frames' depth and motion reach the generator:
    /// `lossless` (as rendered) or `compact` (through the stream's
    /// quantised codecs, encoded and decoded as `serve` and `connect` do).
    #[arg(long, default_value = "lossless", value_parser = clap::value_parser!(protocol::wire::BufferSet))]
    geometry: protocol::wire::BufferSet,
    /// How fed frames' colour travels: through H.264 at a bitrate, e.g.
    /// `h264@12` (4:2:0, Mbit/s at the fed rate) or `h264-444@12`, or
    /// `h264` at 0.6 bits a pixel a frame of the fed rate; `raw` (or
    /// lossless `zstd`) as rendered. A list is a bitrate sweep: every
    /// variant through the first, gffe and interp through each further
    /// one (e.g. `raw,h264@8,h264@16,h264@32`), with a table and a plot
    /// of ꟻLIP against Mbit/s.
    #[arg(long, alias = "codecs", default_value = "raw", value_delimiter = ',', value_parser = clap::value_parser!(video::ColorCodec))]
    color_codec: Vec<video::ColorCodec>,
    /// Fed frames before scoring starts.
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    /// Heat maps for the first this many scenes...
    #[arg(long, default_value_t = 1)]
    heatmap_scenes: usize,
    /// ...at this many frames each.
    #[arg(long, default_value_t = 2)]
    heatmap_frames: usize,
    /// Also write every scored generated frame under DIR/<scene>/<variant>/
    /// as EXR (colour, depth, motion), JSON metadata and the scored PNG,
    /// named by the ground-truth frame it stands for.
    #[arg(long, value_name = "DIR")]
    save_frames: Option<PathBuf>,
}

/// Options of `connect`.
#[derive(Args)]
struct ConnectArgs {
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
    /// Impair the network through a relay on 127.0.0.1 (as `run --impair`).
    #[arg(long, value_name = "SPEC")]
    impair: Option<Impairment>,
    /// Reconnect to a server that went away for up to this many seconds
    /// (0: end with the session).
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    reconnect_for: f64,
}

/// An error ends the process with one line on stderr (the whole chain, no
/// backtrace) and a non-zero status.
fn main() -> Result<(), gpu_device::OneLine> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .init();
    // Frame-sized buffers are freed and allocated again every frame: keep
    // them in the heap instead of faulting fresh pages in each time.
    protocol::memory::retain_freed_memory();
    Ok(command(Cli::parse())?)
}

fn command(cli: Cli) -> anyhow::Result<()> {
    if let Some(name) = &cli.adapter {
        gpu_device::prefer_adapter(name);
    }
    match cli.command {
        None => run(RunArgs::default()),
        Some(Command::Run(args)) => run(*args),
        Some(Command::Connect(args)) => connect(args),
        Some(Command::Eval(args)) => eval(args),
    }
}

/// `client eval`: the accuracy-against-time report.
fn eval(args: EvalArgs) -> anyhow::Result<()> {
    use client::eval::sequence::Input;
    let inputs: Vec<Input> = if !args.dump.is_empty() {
        args.dump.iter().cloned().map(Input::Dump).collect()
    } else {
        let mut scenes = args.scenes.clone();
        if args.all_scenes {
            for name in scene::builtin::names() {
                let spec = format!("builtin:{name}");
                if !scenes.contains(&spec) {
                    scenes.push(spec);
                }
            }
        }
        scenes.into_iter().map(Input::Scene).collect()
    };
    let config = client::eval::EvalConfig {
        inputs,
        size: args.size,
        fps: args.fps,
        start: args.start,
        frames: args.frames,
        sweep: args.sweep,
        backends: args.backends,
        resolutions: args.resolutions,
        only: args.only,
        geometry: args.geometry,
        colors: args.color_codec,
        pass_clock: match args.pass_clock.as_str() {
            "wall" => Some(framegen::PassClock::Wall),
            "timestamps" => Some(framegen::PassClock::Timestamps),
            _ => None,
        },
        warmup: args.warmup,
        heatmap_inputs: args.heatmap_scenes,
        heatmap_frames: args.heatmap_frames,
        out: args.out.clone(),
        save_frames: args.save_frames,
        command: std::env::args()
            .enumerate()
            .map(|(i, a)| if i == 0 { "client".into() } else { a })
            .collect::<Vec<_>>()
            .join(" "),
        progress: true,
    };
    let started = Instant::now();
    let report = client::eval::run(&config)?;
    println!(
        "evaluated {} scenes, {} variants in {:.1} s: {}",
        report.scenes.len(),
        report.scenes.iter().map(|s| s.rows.len()).sum::<usize>(),
        started.elapsed().as_secs_f64(),
        args.out.join("report.md").display()
    );
    Ok(())
}

/// `client connect`: receive frames, optionally into a dump.
fn connect(args: ConnectArgs) -> anyhow::Result<()> {
    let ConnectArgs {
        addr,
        pin,
        pin_file,
        dangerous_accept_any_certificate,
        token,
        frames,
        seconds,
        dump_to,
        impair,
        reconnect_for,
    } = args;
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
        let config = ConnectConfig::new(addr, pin, token);
        let (mut session, relay) = connect_impaired(config, impair, reconnect_for).await?;
        let w = &session.welcome;
        println!(
            "session {} with {}: {}x{} at {} fps, buffers {:?}, window {:?}, effects: {}",
            w.session_id,
            w.server_name,
            w.size.width,
            w.size.height,
            w.fps,
            w.buffers,
            w.window_mode,
            w.effects
        );
        // Written off the receiving loop: a slow disk must not make the
        // receiver supersede frames.
        let mut writer = match &dump_to {
            Some(dir) => Some(FrameWriter::start(
                vec![Box::new(DumpSink(DumpWriter::create(
                    dir,
                    Manifest::new(w.fps, w.size, format!("client connect {addr}"))
                        .with_effects(w.effects),
                )?))],
                FrameWriter::capacity_for(w.size),
                "reception",
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
                Ok(Some(a)) => std::sync::Arc::unwrap_or_clone(a.frame),
                Ok(None) => break,
                Err(_) => continue,
            };
            count += 1;
            if let Some(w) = writer.as_mut() {
                w.write(frame)?;
            }
            if count % 30 == 0 {
                let s = session.stats().session;
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
        let outages = session.stats();
        let s = outages.session;
        if let Some(reason) = session.ended() {
            println!("stream ended: {reason}");
        }
        if outages.reconnects > 0 {
            println!(
                "reconnected {} times after {:.0} ms without a server in all (longest {:.0} ms)",
                outages.reconnects, outages.outage_ms, outages.longest_outage_ms
            );
        }
        println!(
            "received {count} frames in {:.2} s; {} bytes; late {}, dropped {}, colour not decoded {} ({} keyframes asked); server reports sent {}, dropped {}",
            started.elapsed().as_secs_f64(),
            s.client.bytes_received,
            s.client.frames_late,
            s.client.frames_dropped,
            s.color_errors,
            s.keyframe_requests,
            s.server.map_or(0, |x| x.frames_sent),
            s.server.map_or(0, |x| x.frames_dropped),
        );
        if let Some(w) = writer {
            w.finish()?;
            println!("wrote {count} frames to {}", dump_to.unwrap_or_default().display());
        }
        session.close().await;
        report_relay(relay.as_ref());
        anyhow::Ok(())
    })
}

/// Connects as `config` says, through an impairment relay when `impair`
/// is given (the relay must outlive the stream), reconnecting for up to
/// `reconnect_for` seconds when the server goes away.
async fn connect_impaired(
    mut config: ConnectConfig,
    impair: Option<Impairment>,
    reconnect_for: f64,
) -> anyhow::Result<(client::Stream, Option<Relay>)> {
    let relay = match impair {
        Some(imp) => {
            let relay = Relay::start(config.addr, imp).await?;
            println!("impaired network: {imp:?}, through {}", relay.local_addr());
            config.addr = relay.local_addr();
            Some(relay)
        }
        None => None,
    };
    let policy = if reconnect_for > 0.0 && reconnect_for.is_finite() {
        client::ReconnectPolicy {
            give_up_after: Duration::from_secs_f64(reconnect_for),
            ..client::ReconnectPolicy::default()
        }
    } else {
        client::ReconnectPolicy::NEVER
    };
    Ok((client::Stream::connect(config, policy).await?, relay))
}

/// What the impairment relay did, both ways.
fn report_relay(relay: Option<&Relay>) {
    if let Some(r) = relay {
        let line = |(delivered, lost, overflowed): (u64, u64, u64)| {
            format!("{delivered} delivered, {lost} lost, {overflowed} dropped by the queue limit")
        };
        println!(
            "relay datagrams: to the server {}; to the client {}",
            line(r.upstream.snapshot()),
            line(r.downstream.snapshot())
        );
    }
}

/// How long the presenter waits for the window's device before it opens
/// one of its own.
const WINDOW_DEVICE_TIMEOUT: Duration = Duration::from_secs(20);

/// `client run`: the demo, in a window when there is a display.
fn run(args: RunArgs) -> anyhow::Result<()> {
    let display =
        std::env::var_os("DISPLAY").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some();
    let want = match args.window.as_str() {
        "on" => true,
        "off" => false,
        _ => display,
    };
    let event_loop = if want {
        match client::window::event_loop() {
            Ok(el) => Some(el),
            Err(e) if args.window == "on" => return Err(e),
            Err(e) => {
                println!("no window ({e}); presenting headless");
                None
            }
        }
    } else {
        None
    };
    let Some(event_loop) = event_loop else {
        return session(args, None, None, None);
    };
    let proxy = event_loop.create_proxy();
    let screenshot = args.screenshot.clone();
    // An interactive window is driven by its mouse and keys.
    let live = args.interactive.then(client::viewer::LiveViewer::default);
    let keys = live.clone();
    // The window's device, for a generator to share.
    let (share, shared) = std::sync::mpsc::sync_channel(1);
    let worker = std::thread::spawn(move || {
        let result = session(args, Some(proxy.clone()), live, Some(shared));
        let _ = proxy.send_event(client::window::Event::Done);
        result
    });
    let shown = client::window::run(event_loop, screenshot, keys, Some(share));
    let result = worker
        .join()
        .map_err(|_| anyhow::anyhow!("the presenter thread panicked"))?;
    shown.and(result)
}

/// Connects (starting the in-process server if needed), presents, and
/// prints the latency summary.
fn session(
    args: RunArgs,
    window: Option<client::window::Sink>,
    live: Option<client::viewer::LiveViewer>,
    shared: Option<std::sync::mpsc::Receiver<client::window::Shared>>,
) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let link = client::demo::Link {
        congestion: args.congestion,
        color: args.color_codec,
        interactive: args.interactive,
        window: args.render_window,
        server_priority: args.server_priority,
    };
    runtime.block_on(async move {
        let local = match args.server {
            Some(_) => None,
            None => match &args.from_dump {
                Some(dir) => {
                    println!("starting an in-process server replaying {}", dir.display());
                    Some(client::demo::start_local_dump(dir, link)?)
                }
                None => {
                    println!(
                        "starting an in-process server: {} at {}x{}, {} fps",
                        args.scene, args.size.width, args.size.height, args.fps
                    );
                    Some(client::demo::start_local(&args.scene, args.size, args.fps, link)?)
                }
            },
        };
        let config = match (&local, args.server) {
            (Some(l), _) => l.config(),
            (None, Some(addr)) => {
                let (Some(pin), Some(token)) = (args.pin.clone(), args.token.clone()) else {
                    anyhow::bail!("--server needs --pin FINGERPRINT and --token TOKEN");
                };
                ConnectConfig::new(addr, Pin::Sha256(pin), token)
            }
            (None, None) => unreachable!("a local server exists without --server"),
        };
        let viewer = match (args.interactive, args.input_track.as_deref(), live) {
            (false, _, _) => None,
            // A window's mouse and keys, unless a track is given.
            (true, None, Some(live)) => Some(ViewerSource::Live(live)),
            (true, track, _) => Some(ViewerSource::Track(client::viewer::InputTrack::load(
                track.unwrap_or("builtin:turn"),
            )?)),
        }
        .map(|source| client::present::ViewerConfig {
            source,
            late: args.late_input == "on",
        });
        let (mut session, relay) = connect_impaired(config, args.impair, args.reconnect_for).await?;
        // In a window, generation runs on the window's device where the
        // window opened one (waited for here, briefly: it opens as the
        // stream starts), so that generated frames are shown from the
        // device that made them; otherwise on a device of its own.
        let shared = match (args.backend.as_str(), shared) {
            ("cpu", _) | (_, None) => None,
            (_, Some(rx)) => rx.recv_timeout(WINDOW_DEVICE_TIMEOUT).ok(),
        };
        let gpu = match args.backend.as_str() {
            "cpu" => None,
            wanted => match shared
                .as_ref()
                .map_or_else(client::demo::gpu, |s| Ok(s.ctx.clone()))
            {
                Ok(g) if wanted == "wgpu" || g.adapter_info.device_type != wgpu::DeviceType::Cpu => {
                    Some(g)
                }
                Ok(g) => {
                    println!(
                        "the only adapter is a software rasteriser ({}): generating on the CPU reference (--backend wgpu to force it)",
                        g.adapter_info.name
                    );
                    None
                }
                Err(e) if wanted == "wgpu" => return Err(e),
                Err(e) => {
                    println!("no GPU for frame generation ({e}); generating on the CPU reference");
                    None
                }
            },
        };
        println!(
            "presenting {} for {} s ({} -> {} fps, method {}{})",
            if window.is_some() { "in a window" } else { "headless" },
            args.seconds,
            session.welcome.fps,
            args.refresh
                .unwrap_or(session.welcome.fps * f64::from(args.n + 1)),
            args.method,
            if args.no_shading { " without shading correction" } else { "" }
        );
        let config = PresentConfig {
            method: args.method,
            n: args.n,
            duration: Duration::from_secs_f64(args.seconds.max(0.0)),
            max_alpha: args.max_alpha,
            png_dir: args.png.clone(),
            cpu: gpu.is_none(),
            window,
            refresh_hz: args.refresh,
            dump_dir: args.dump_to.clone(),
            shading: !args.no_shading,
            every_stage: args.every_stage,
            viewer,
            // Only where the generator runs on it.
            shared: shared.filter(|s| gpu.as_ref().is_some_and(|g| Arc::ptr_eq(g, &s.ctx))),
        };
        let report = run_headless(&mut session, &config, gpu).await?;
        session.close().await;
        if let Some(l) = local {
            l.server.shutdown().await;
        }
        println!(
            "method {} on {}: received {} frames, {} vsyncs missed; generation ms p50 {:.2} p99 {:.2}; ingest ms p50 {:.2} p99 {:.2}; decode ms p50 {:.2} p99 {:.2}; history restarts {}; frames skipped to keep pace {}",
            report.method,
            report.backend,
            report.received,
            report.missed_vsyncs,
            report.generation_ms.p50,
            report.generation_ms.p99,
            report.ingest_ms.p50,
            report.ingest_ms.p99,
            report.decode_ms.p50,
            report.decode_ms.p99,
            report.restarts,
            report.ingest_skipped,
        );
        println!("  plan: {}", report.plan);
        if !report.passes.is_empty() {
            println!("  passes: {}", report.passes.join(", "));
        }
        print!("{}", report.summary.to_text());
        if let Some(line) = report.stream_shortfall() {
            println!("  {line}");
        }
        let v = &report.viewer;
        if args.interactive {
            println!(
                "  viewer ({}): {} inputs sent ({} not); the last turned {:.1}° and moved {:.2} m from the first frame's camera{}",
                v.mode,
                v.inputs.sent,
                v.inputs.unsent,
                v.turned_deg,
                v.moved_m,
                if args.late_input == "on" {
                    format!(
                        "; {} late images replaced by fresh ones",
                        report.replaced_late
                    )
                } else {
                    String::new()
                }
            );
        }
        if let (Some(turn), Some(within)) = (v.vsync_turn_deg, v.within_vsync_turn()) {
            let errors = Percentiles::of(v.view_error_deg.clone());
            println!(
                "  displayed camera off the viewer's at present: p50 {:.2}° p99 {:.2}°, within one vsync's turn ({turn:.2}°) on {:.1} %",
                errors.p50,
                errors.p99,
                within * 100.0
            );
        }
        if let Some(o) = Some(report.outages).filter(|o| o.reconnects > 0 || o.in_outage) {
            println!(
                "  outages: {} reconnects, {} failed attempts, {:.0} ms without a server (longest {:.0} ms){}",
                o.reconnects,
                o.failed_attempts,
                o.outage_ms,
                o.longest_outage_ms,
                if o.in_outage { ", in an outage at the end" } else { "" }
            );
        }
        report_relay(relay.as_ref());
        if let Some(path) = &args.json {
            std::fs::write(path, serde_json::to_vec_pretty(&report)?)?;
            println!("wrote {}", path.display());
        }
        anyhow::Ok(())
    })
}
