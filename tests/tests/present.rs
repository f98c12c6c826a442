//! The presenter end to end: an in-process server renders a built-in scene
//! live, the client connects over QUIC on loopback, generates frames and
//! presents them headless; the accounting must show the scheduling model's
//! properties. Bounds are frame counts and ratios, never absolute times.

use std::time::Duration;

use client::present::{PresentConfig, run_headless};
use framegen::Method;
use framegen::accounting::Percentiles;
use framegen::schedule::SlotKind;
use protocol::FrameSize;
use protocol::wire::WindowMode;

const SIZE: FrameSize = FrameSize::new(160, 90);

static ALONE: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Presents `method` for `seconds`. The timing properties are checked on
/// the CPU reference backend: on this project's CI machines the only wgpu
/// adapter is lavapipe, which shares two cores with the in-process server's
/// renderer and misses most vsyncs (the scheduling itself does not depend
/// on the backend); `gpu` runs the wgpu backend for a smoke check.
async fn present(method: Method, seconds: f64, gpu: bool) -> client::present::Report {
    present_with(method, seconds, gpu, |_| {}).await
}

async fn present_with(
    method: Method,
    seconds: f64,
    gpu: bool,
    adjust: impl Fn(&mut PresentConfig),
) -> client::present::Report {
    present_at(WindowMode::Off, 30.0, method, seconds, gpu, adjust).await
}

/// Runs of a presenter, at most, until one receives [`ENOUGH`] of the
/// stream.
const TRIES: usize = 3;
/// Share of the frames the stream renders in a run that the client must
/// receive for the run to show the presenter's properties. On a machine
/// too loaded for the in-process server to render at its rate (9 frames a
/// second of 30 with four busy loops on the two cores), the frames come
/// with gaps, interpolation has nothing in time to go toward, and shading
/// correction no consecutive frames to compare: such a run says nothing
/// about the presenter, and is run again (the last one is judged whatever
/// it received).
const ENOUGH: f64 = 0.75;

/// Whether a run of `seconds` of a stream rendered at `fps` received
/// [`ENOUGH`] of its frames.
fn enough(report: &client::present::Report, fps: f64, seconds: f64) -> bool {
    report.received as f64 >= ENOUGH * fps * seconds
}

/// [`present_with`] with the server rendering at `fps` with its adaptive
/// window in `mode`.
async fn present_at(
    mode: WindowMode,
    fps: f64,
    method: Method,
    seconds: f64,
    gpu: bool,
    adjust: impl Fn(&mut PresentConfig),
) -> client::present::Report {
    // One presenter at a time: each runs a server and a client on a machine
    // with two cores.
    let _alone = ALONE.lock().await;
    let rendered = fps * seconds;
    for attempt in 1.. {
        let local = client::demo::start_local_windowed("builtin:default", SIZE, fps, mode).unwrap();
        let mut session = local.connect().await.unwrap();
        let mut config = PresentConfig {
            method,
            duration: Duration::from_secs_f64(seconds),
            cpu: !gpu,
            ..PresentConfig::default()
        };
        adjust(&mut config);
        if let Some(dump) = config.dump_dir.as_ref().filter(|_| attempt > 1) {
            // The previous attempt's.
            std::fs::remove_dir_all(dump).unwrap();
        }
        let ctx = gpu.then(|| client::demo::gpu().unwrap());
        let report = run_headless(&mut session, &config, ctx).await.unwrap();
        session.close().await;
        local.server.shutdown().await;
        if enough(&report, fps, seconds) || attempt == TRIES {
            return report;
        }
        eprintln!(
            "attempt {attempt}: {} of {rendered} frames received (a loaded machine): again",
            report.received
        );
    }
    unreachable!("the last attempt returns")
}

/// Each vsync shows at most one image: an image finished after its vsync
/// takes the next one, whose own slot is then not made (it would be a
/// second image for that vsync) and the vsync passed counts as missed.
fn one_image_a_vsync(r: &client::present::Report) {
    for w in r.records.windows(2) {
        assert!(
            w[0].present_ms < w[1].present_ms,
            "two images for one vsync: {:?} and {:?}",
            w[0],
            w[1]
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extrapolation_fills_every_slot_without_adding_latency() {
    let r = present(Method::Gffe, 3.0, false).await;
    let s = &r.summary;
    eprintln!("{}", s.to_text());
    eprintln!(
        "received {}, missed {}, generation {:?}",
        r.received, r.missed_vsyncs, r.generation_ms
    );
    assert!((r.display_fps - 60.0).abs() < 0.01);
    // Every vsync from the first shown frame to the end is presented or
    // counted as missed, exactly once.
    let first = r.records.first().expect("something was shown");
    let slots = ((3000.0 - first.present_ms) / (1000.0 / 60.0)).floor() as i64 + 1;
    let accounted = r.records.len() as i64 + r.missed_vsyncs as i64;
    assert!(
        (accounted - slots).abs() <= 2,
        "{accounted} accounted vs {slots} slots"
    );
    let ids: Vec<u64> = r.records.iter().map(|x| x.display_id).collect();
    assert_eq!(ids, (0..ids.len() as u64).collect::<Vec<_>>());
    one_image_a_vsync(&r);
    // Most slots are presented (the machine may miss a few under load).
    assert!(
        r.records.len() as f64 >= 0.6 * slots as f64,
        "{} of {slots}",
        r.records.len()
    );
    // Rendered frames and extrapolated frames alternate: about as many of each.
    assert!(
        s.rendered >= 30 && s.extrapolated >= s.rendered / 2,
        "{s:?}"
    );
    // No added latency beyond one vsync quantum plus the generation time
    // (rounded up to vsyncs): median ≤ 2 vsyncs.
    assert!(
        s.added_latency_ms.p50 <= 2.0 * 1000.0 / 60.0 + 0.5,
        "{:?}",
        s.added_latency_ms
    );
    assert!(r.records.iter().all(|x| x.latency_ms >= 0.0));
    // Every rendered frame's path in order: its last byte, decoded,
    // presented. The generator ingests it after it was handed over
    // (extrapolation needs it only for the slots after it), so no ingest
    // is on its path: none had ingested it by its present (but the first
    // frame, ingested before the clock started).
    let first_frame = first.source;
    let rendered = r.records.iter().filter(|x| x.kind == SlotKind::Rendered);
    for x in rendered.filter(|x| x.source != first_frame) {
        assert!(
            x.received_ms <= x.ready_ms && x.ready_ms <= x.present_ms,
            "{x:?}"
        );
        assert_eq!(x.ingested_ms, None, "shown before its ingest: {x:?}");
        assert!(x.added_latency_ms.unwrap() >= -1e-6, "{x:?}");
    }
    // Each was ingested after its present (the first before the clock
    // started, which the ingest times leave out).
    assert!(r.ingest_ms.count + 1 >= s.rendered, "{:?}", r.ingest_ms);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn repeat_shows_only_rendered_and_repeated_frames() {
    let r = present(Method::Repeat, 2.0, false).await;
    let kinds: std::collections::HashSet<SlotKind> = r.records.iter().map(|x| x.kind).collect();
    assert!(
        kinds
            .iter()
            .all(|k| matches!(k, SlotKind::Rendered | SlotKind::Repeated))
    );
    assert!(
        r.summary.rendered >= 20 && r.summary.repeated >= 10,
        "{:?}",
        r.summary
    );
}

/// The wgpu backend in the same loop: it runs and accounts every slot it
/// presents (how many it keeps up with depends on the adapter). A slot
/// between two rendered frames is extrapolated only when the push of the
/// first ends before that slot's vsync, half a render interval on: at
/// 2 fps (4 Hz display, 250 ms), for six seconds. On lavapipe a push took
/// longer than a 30 fps render interval on a loaded two-core machine (11
/// and 28 rendered frames, no generated one), and 187 ms at the median,
/// more than 10 fps's half interval, in a clean-clone CI run whose
/// neighbouring tests each ran a server (5 rendered, none generated).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_wgpu_backend_presents_generated_frames() {
    let seconds = 6.0;
    // Without shading correction (its cost is not what this checks), as
    // lavapipe shares the two cores with the server's renderer.
    let r = present_at(WindowMode::Off, 2.0, Method::Gffe, seconds, true, |c| {
        c.shading = false
    })
    .await;
    assert!(r.backend.starts_with("wgpu"), "{}", r.backend);
    assert!(
        r.summary.rendered >= 1 && r.summary.extrapolated >= 1,
        "{:?}; received {}, generation ms {:?}, ingest ms {:?}",
        r.summary,
        r.received,
        r.generation_ms,
        r.ingest_ms
    );
    assert!((r.display_fps - 4.0).abs() < 0.01);
    let slots = (seconds * r.display_fps).floor() as i64 + 1;
    assert!((r.records.len() as i64 + r.missed_vsyncs as i64 - slots).abs() <= 1);
}

/// Interpolation holds each rendered frame back until the frames between
/// it and the one before are shown (ExtraNet §3.1, DESIGN §8): a rendered
/// frame that follows the frame interpolated towards it is shown a vsync
/// after a direct display would have shown it, so its latency (present −
/// ready, the presenter's one-vsync queue included) is a render interval
/// or more; extrapolation's added latency is 0 in the median.
///
/// A frame ready just after t was shown is held one vsync (the least, at
/// 30 -> 60); one ready before is held two, and the scheduler catches up
/// from such a phase (its unit tests check both exactly on a fake clock).
/// Here the bounds are medians: a presenter loop running late on this
/// shared machine can take a frame into the slot of a vsync that passed
/// before it was ready.
///
/// At 15 fps (→ 30 Hz): interpolation needs the frame it goes toward in
/// time, and a server that cannot render at its rate on a loaded machine
/// sends them late and with gaps (about 40 % of 30 fps with three busy
/// loops on two cores here).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn interpolation_adds_at_least_one_render_interval() {
    const FPS: f64 = 15.0;
    let r = present_at(WindowMode::Off, FPS, Method::Interp, 4.0, false, |_| {}).await;
    let s = &r.summary;
    eprintln!("{}", s.to_text());
    // At least one interpolated frame for every three rendered ones: a
    // loaded CI machine showed 32 for 79 (the presenter falls behind and
    // shows rendered frames it had no time to interpolate towards).
    assert!(
        s.rendered >= 30 && s.interpolated >= s.rendered / 3,
        "{s:?}"
    );
    let interval = 1000.0 / FPS;
    let vsync = interval / 2.0;
    // The rendered frames shown after the frame interpolated towards them.
    let held: Vec<_> = r
        .records
        .windows(2)
        .filter(|w| {
            w[1].kind == SlotKind::Rendered
                && w[0].kind == SlotKind::Interpolated
                && w[0].next == Some(w[1].source)
        })
        .map(|w| &w[1])
        .collect();
    assert!(
        held.len() >= 10 && held.len() >= s.rendered / 3,
        "{} of {}",
        held.len(),
        s.rendered
    );
    // The frame the slots between go toward is ingested as it arrives:
    // mostly before the vsync of the first slot between (which is
    // presented a vsync later), so that slot only generates.
    let first_between = |id: u64| {
        r.records
            .iter()
            .find(|x| x.kind == SlotKind::Interpolated && x.next == Some(id))
    };
    let early = held
        .iter()
        .filter(|x| {
            let between = first_between(x.source).expect("a slot toward it");
            x.ingested_ms
                .is_some_and(|i| i < between.present_ms - vsync)
        })
        .count();
    assert!(
        2 * early >= held.len(),
        "{early} of {} ingested early",
        held.len()
    );
    let added = Percentiles::of(held.iter().filter_map(|x| x.added_latency_ms).collect());
    let latency = Percentiles::of(held.iter().map(|x| x.latency_ms).collect());
    assert!(added.p50 >= vsync - 0.5, "{added:?}");
    assert!(latency.p50 >= interval - 0.5, "{latency:?}");
    // Where most rendered frames were held, so is the summary's median (a
    // loaded machine shows more rendered frames directly, unheld: 33 of 77
    // held in one CI run).
    assert!(
        s.added_latency_ms.p50 >= vsync - 0.5 || 2 * held.len() < s.rendered,
        "{:?}",
        s.added_latency_ms
    );
    assert!(
        r.records
            .iter()
            .filter(|x| x.kind == SlotKind::Interpolated)
            .all(|x| x.next.is_some_and(|n| n > x.source) && x.alpha > 0.0 && x.alpha < 1.0)
    );
}

/// A display refresh rate unrelated to the render rate (75 Hz for a 30 fps
/// stream), and the presented frames written to a dump.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_given_refresh_rate_and_a_dump_of_what_was_presented() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("presented");
    let target = dump.clone();
    // 4 s: on a loaded machine a 2 s run once showed no extrapolated frame.
    let r = present_with(Method::Gffe, 4.0, false, move |c| {
        c.refresh_hz = Some(75.0);
        c.dump_dir = Some(target.clone());
    })
    .await;
    assert!((r.display_fps - 75.0).abs() < 0.01);
    let slots = (4000.0f64 / (1000.0 / 75.0)).floor() as i64 + 1;
    assert!((r.records.len() as i64 + r.missed_vsyncs as i64 - slots).abs() <= 1);
    // 75 / 30 = 2.5 slots per rendered frame: α steps of 0.4 (which of
    // them the loaded machine meets varies).
    let alphas: Vec<f64> = r
        .records
        .iter()
        .filter(|x| x.kind == SlotKind::Extrapolated)
        .map(|x| x.alpha)
        .collect();
    assert!(!alphas.is_empty(), "{:?}", r.summary);
    assert!(
        alphas
            .iter()
            .all(|a| *a > 0.2 && ((a / 0.4) - (a / 0.4).round()).abs() < 0.02),
        "{alphas:?}"
    );
    let reader = protocol::dump::DumpReader::open(&dump).unwrap();
    assert_eq!(reader.len(), r.records.len() as u64);
    assert!((reader.manifest().fps - 75.0).abs() < 0.01);
}

/// A stream rendered with the adaptive window (GFFE §4.3): every presented
/// frame, rendered or generated, is the displayed view at the session's
/// size (a rendered frame is cropped to it), and neither mode restarts the
/// history after the first frame (keep-size changes the displayed
/// region's size every frame, the display size stays).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn windowed_streams_are_presented_as_the_displayed_view() {
    for mode in [WindowMode::KeepDensity, WindowMode::KeepSize] {
        let dir = tempfile::tempdir().unwrap();
        let dump = dir.path().join("presented");
        let target = dump.clone();
        // Shading correction's cost on two loaded cores is not what this
        // checks (`the_generation_plan_runs_live` runs it live): without
        // it, more slots are met.
        let r = present_at(mode, 30.0, Method::Gffe, 2.0, false, move |c| {
            c.dump_dir = Some(target.clone());
            c.shading = false;
        })
        .await;
        assert_eq!(r.restarts, 1, "{mode:?}: {} restarts", r.restarts);
        let reader = protocol::dump::DumpReader::open(&dump).unwrap();
        assert_eq!(reader.len(), r.records.len() as u64);
        let mut rendered = 0;
        for (k, record) in r.records.iter().enumerate() {
            let f = reader.read_frame(k as u64).unwrap();
            assert_eq!(f.meta.size, SIZE, "{mode:?} slot {k}");
            assert!(f.meta.camera.window.is_full(), "{mode:?} slot {k}");
            rendered += usize::from(record.kind == SlotKind::Rendered);
        }
        assert!(rendered > 0 && rendered < r.records.len(), "{mode:?}");
    }
}

/// The generation plan runs live: the stream announces `builtin:default`'s
/// effects (animated objects, a moving light), so gffe tracks trajectories
/// and corrects shading, and the CPU reference's pass list of the last
/// frame is the plan's, in its order; without shading correction neither
/// of its passes runs.
///
/// At 10 fps: the shading estimate compares a frame with the one before,
/// so it runs on a frame that followed its predecessor, and a server too
/// loaded to render 30 frames a second leaves gaps between every two it
/// sends (9 a second of 30 with four busy loops on two cores here).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_generation_plan_runs_live() {
    let ran = |r: &client::present::Report| -> Vec<String> {
        r.passes
            .iter()
            .filter(|p| *p != "upload" && *p != "readback")
            .cloned()
            .collect()
    };
    let planned = |r: &client::present::Report| -> Vec<String> {
        r.plan.passes().map(|p| p.name().to_string()).collect()
    };
    const FPS: f64 = 10.0;
    let r = present_at(WindowMode::Off, FPS, Method::Gffe, 3.0, false, |_| {}).await;
    eprintln!(
        "plan {}; passes {:?}; {}",
        r.plan,
        r.passes,
        r.summary.to_text()
    );
    assert_eq!(r.plan.effects, protocol::Effects::UNKNOWN);
    assert!(r.plan.shading && r.plan.history == 2, "{}", r.plan);
    assert_eq!(ran(&r), planned(&r));
    let at = |name: &str| r.passes.iter().position(|p| p == name);
    let (estimate, correct, warp) = (at("shading"), at("shade"), at("warp"));
    assert!(estimate.is_some() && correct.is_some(), "{:?}", r.passes);
    assert!(estimate < correct && correct < warp, "{:?}", r.passes);
    assert!(r.summary.extrapolated > 0, "{:?}", r.summary);
    let plain = present_at(WindowMode::Off, FPS, Method::Gffe, 1.0, false, |c| {
        c.shading = false;
    })
    .await;
    assert!(!plain.plan.shading);
    assert!(!plain.passes.iter().any(|p| p.starts_with("shad")));
    assert_eq!(ran(&plain), planned(&plain));
}

/// Interactive streaming (issue 20) on loopback, through a relay that
/// delays every datagram by 30 ms each way, with a scripted 90°/s turn at
/// 96×54, 20 → 40: with late input every displayed frame shows exactly the
/// viewer's pose taken for its slot (its angle to the viewer at present is
/// the turn during its input to photon), latched as late as a slot allows
/// (`client::latch`), so a slot finished before its vsync is within one
/// vsync's turn of the viewer at present. That is asserted exactly: no more
/// frames lie beyond that bound than vsyncs were missed. On a quiet machine
/// every slot is on time (the README's runs, 100 % within); a loaded
/// two-core machine finishes some slots late (98.9 % within in one CI run,
/// 85–93 % with three busy loops beside the test, 60 % on a machine
/// running at half speed), and without late input under 1 % is within:
/// at least half is asserted, which tells late input from the server's
/// camera however loaded the machine (how many slots a machine finishes
/// in time is its speed, measured by the README's runs, not here). Input
/// to photon stays within a display interval plus the generation time;
/// without late input the display shows what the server rendered from an
/// input a round trip and a render old, further off and later.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn late_input_shows_the_newest_viewer_pose() {
    let run = |late: bool| async move {
        let _alone = ALONE.lock().await;
        // Small enough that generating a slot stays well within a vsync
        // on a loaded two-core machine (a late slot is a vsync further
        // off, whatever the input).
        let link = client::demo::Link {
            interactive: true,
            ..client::demo::Link::default()
        };
        let local =
            client::demo::start_local("builtin:default", FrameSize::new(96, 54), 20.0, link)
                .unwrap();
        let delay: client::impair::Impairment = "delay=30ms".parse().unwrap();
        let relay = client::impair::Relay::start(local.addr, delay)
            .await
            .unwrap();
        let mut config = local.config();
        config.addr = relay.local_addr();
        let mut session = client::Stream::connect(config, client::ReconnectPolicy::default())
            .await
            .unwrap();
        let config = PresentConfig {
            method: Method::Gffe,
            duration: Duration::from_secs(3),
            cpu: true,
            viewer: Some(client::present::ViewerConfig {
                source: client::present::ViewerSource::Track(
                    client::viewer::InputTrack::builtin("turn").unwrap(),
                ),
                late,
            }),
            ..PresentConfig::default()
        };
        let report = run_headless(&mut session, &config, None).await.unwrap();
        session.close().await;
        local.server.shutdown().await;
        report
    };
    // As `present_at`: a run that received too little of the stream is
    // run again, a few times at most.
    let mut late = run(true).await;
    for attempt in 1..TRIES {
        if enough(&late, 20.0, 3.0) {
            break;
        }
        eprintln!(
            "attempt {attempt}: {} frames received: again",
            late.received
        );
        late = run(true).await;
    }
    let server = run(false).await;
    // 20 → 40: a 25 ms display interval, so a slot has room on a loaded
    // machine (the renderer's fixed cost a frame dominates at this size).
    let di = 1000.0 / 40.0;
    let turn = late.viewer.vsync_turn_deg.unwrap();
    assert!((turn - 90.0 * di / 1000.0).abs() < 1e-6, "{turn}");
    for r in [&late, &server] {
        let e = Percentiles::of(r.viewer.view_error_deg.clone());
        eprintln!(
            "{}: view error p50 {:.2}° p99 {:.2}°, within {turn}° on {:.3}; input to photon {:?}; missed {} ({} late images replaced), generation {:?}",
            r.viewer.mode,
            e.p50,
            e.p99,
            r.viewer.within_vsync_turn().unwrap(),
            r.summary.input_to_photon_ms,
            r.missed_vsyncs,
            r.replaced_late,
            r.generation_ms
        );
        assert!(
            r.viewer.inputs.sent as f64 >= 0.9 * r.records.len() as f64,
            "{}",
            r.viewer.inputs.sent
        );
        assert_eq!(r.viewer.view_error_deg.len(), r.records.len());
    }
    assert_eq!(late.viewer.mode, "late input");
    one_image_a_vsync(&late);
    // Every displayed frame reflects an input, and the bound holds.
    assert!(late.records.iter().all(|x| x.input_seq.is_some()));
    for (x, error) in late.records.iter().zip(&late.viewer.view_error_deg) {
        let turned = 90.0 * x.input_to_photon_ms.unwrap() / 1000.0;
        assert!(
            (error - turned).abs() < 1e-6,
            "{error}° against {turned}°: {x:?}"
        );
    }
    // The bound itself, whatever the machine's load: a slot takes its
    // input after its start, a vsync before its own, so a displayed frame
    // further off than one vsync's turn is one finished after its vsync;
    // each such slot counts a missed vsync (shown a vsync late, or
    // replaced), so there are no more of them than missed vsyncs.
    let outside = late
        .viewer
        .view_error_deg
        .iter()
        .filter(|&&e| e > turn + 1e-6)
        .count() as u64;
    assert!(
        outside <= late.missed_vsyncs,
        "{outside} frames beyond one vsync's turn, {} vsyncs missed",
        late.missed_vsyncs
    );
    // And that most are within it (see above).
    let within = late.viewer.within_vsync_turn().unwrap();
    assert!(
        within >= 0.5,
        "late input within one vsync's turn on {within}"
    );
    let (ip_late, ip_server) = (
        &late.summary.input_to_photon_ms,
        &server.summary.input_to_photon_ms,
    );
    assert!(
        ip_late.p50 <= di + late.generation_ms.p50 + 1e-6,
        "{ip_late:?} against {:?}",
        late.generation_ms
    );
    // Where slots leave room (the latch's lead, twice the longest recent
    // slot, within half an interval), the pose is latched as late as a
    // slot allows (`client::latch`), not at the slot's vsync: a displayed
    // pose is well under a display interval old (here 22.8 ms of 25 when
    // taken at the vsync, 4.8–15.0 latched). A loaded machine leaves no
    // room, and the pose is taken at once.
    if late.generation_ms.p99 < di / 4.0 {
        assert!(
            ip_late.p50 <= 0.8 * di,
            "{ip_late:?} against {:?}",
            late.generation_ms
        );
    }
    // A replaced late image is a missed vsync, never a displayed frame.
    assert!(late.replaced_late <= late.missed_vsyncs);
    // Without late input: the server's camera, echoing the inputs it
    // rendered from, a render and a round trip behind.
    assert_eq!(server.viewer.mode, "server camera from input");
    let echoed = server
        .records
        .iter()
        .filter(|x| x.input_seq.is_some())
        .count();
    assert!(
        echoed as f64 >= 0.8 * server.records.len() as f64,
        "{echoed} echoed"
    );
    // At least the 60 ms round trip (and the render) over late input's.
    assert!(
        ip_server.p50 > ip_late.p50 + 60.0,
        "{ip_server:?} vs {ip_late:?}"
    );
    let p50 = |r: &client::present::Report| Percentiles::of(r.viewer.view_error_deg.clone()).p50;
    assert!(p50(&server) > p50(&late) + turn / 2.0);
}
