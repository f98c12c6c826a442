//! Interactive streaming on loopback (issue 20): each session's viewer
//! input drives the camera its frames are rendered from, every such frame
//! echoes the input, and bad input from one client (NaN poses, replayed or
//! overtaken sequence numbers, a flood, garbage) disturbs nothing but its
//! own session's camera, which it never takes over.

mod loopback;

use std::time::{Duration, Instant};

use client::{Arrived, Session};
use glam::{DQuat, DVec3};
use loopback::*;
use protocol::Pose;
use protocol::wire::{self, Input, Message};

fn input(seq: u64, pose: Pose) -> Input {
    Input {
        seq,
        client_time_us: 1_000_000 + seq * 16_667,
        camera: Some(pose),
        buttons: 0,
        axes: [0.0; 4],
    }
}

/// A viewer at `x` on the ground, looking at the origin.
fn viewer(x: f64) -> Pose {
    Pose::look_at(DVec3::new(x, 1.7, 8.0), DVec3::new(0.0, 1.0, 0.0), DVec3::Y)
}

fn same_pose(a: &Pose, b: &Pose) -> bool {
    (a.position - b.position).length() < 1e-9 && a.rotation.dot(b.rotation).abs() > 1.0 - 1e-12
}

/// The next frame within 10 s.
async fn next(session: &mut Session) -> Arrived {
    tokio::time::timeout(Duration::from_secs(10), session.frames.recv())
        .await
        .expect("a frame within 10 s")
        .expect("the session goes on")
}

/// Frames until one echoes input `seq` or later (at most 10 s).
async fn until_echo(session: &mut Session, seq: u64) -> (Vec<Arrived>, Arrived) {
    let start = Instant::now();
    let mut before = Vec::new();
    loop {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no echo of {seq}"
        );
        let f = next(session).await;
        if f.input.is_some_and(|e| e.seq >= seq) {
            return (before, f);
        }
        before.push(f);
    }
}

/// An input datagram whose camera position's x is NaN (the wire refuses to
/// encode one, so the bytes of a marker value are replaced).
fn nan_input(seq: u64) -> Vec<u8> {
    let marker = 1234.5f64;
    let pose = Pose::new(DVec3::new(marker, 0.0, 0.0), DQuat::IDENTITY);
    let mut bytes = wire::encode(&Message::Input(input(seq, pose))).unwrap();
    let at = bytes
        .windows(8)
        .position(|w| w == marker.to_le_bytes())
        .expect("the marker is in the datagram");
    bytes[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    bytes
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_viewer_drives_its_own_camera_and_bad_input_changes_nothing_else() {
    let fx = fixture(fx_buffers()).await;
    let (server, config) = fx.interactive_server("builtin:default");
    let mut a = client::connect(config.clone()).await.unwrap();
    let mut b = client::connect(config).await.unwrap();

    // Before any input, the scene's own path, echoing nothing.
    let first = next(&mut a).await;
    assert!(first.input.is_none());

    // A's viewer: its frames come from its pose and echo its input.
    let pose_a = viewer(-2.0);
    for seq in 1..=3 {
        a.send_input(&input(seq, pose_a)).unwrap();
    }
    let (_, echoed) = until_echo(&mut a, 1).await;
    let echo = echoed.input.unwrap();
    assert!(same_pose(&echoed.frame.meta.camera.pose, &pose_a));
    assert_eq!(echo.client_time_us, input(echo.seq, pose_a).client_time_us);

    // B's viewer, then B misbehaves: NaN, garbage, a replayed and an
    // overtaken sequence number with other poses, and a flood of stale
    // inputs.
    let pose_b = viewer(3.0);
    b.send_input(&input(100, pose_b)).unwrap();
    let (_, from_b) = until_echo(&mut b, 100).await;
    assert!(same_pose(&from_b.frame.meta.camera.pose, &pose_b));
    let conn = b.connection();
    conn.send_datagram(nan_input(101).into()).unwrap();
    conn.send_datagram(vec![0xAB; 64].into()).unwrap();
    b.send_input(&input(100, viewer(40.0))).unwrap();
    b.send_input(&input(50, viewer(50.0))).unwrap();
    for _ in 0..2000 {
        // A full send buffer drops datagrams; that is the point of a flood.
        let _ = b.send_input(&input(7, viewer(60.0)));
    }
    // B's session goes on from its own last good pose.
    for _ in 0..6 {
        let f = next(&mut b).await;
        assert!(
            same_pose(&f.frame.meta.camera.pose, &pose_b),
            "B's camera moved"
        );
        assert_eq!(f.input.map(|e| e.seq), Some(100));
    }
    // A moves on; none of B's poses ever shows in A's frames.
    let pose_a2 = viewer(-1.0);
    a.send_input(&input(4, pose_a2)).unwrap();
    let (between, moved) = until_echo(&mut a, 4).await;
    assert!(same_pose(&moved.frame.meta.camera.pose, &pose_a2));
    for f in &between {
        assert!(
            same_pose(&f.frame.meta.camera.pose, &pose_a),
            "A's camera moved"
        );
        assert!(f.input.is_some_and(|e| e.seq <= 3));
    }
    assert!(b.failure().is_none() && b.close_reason().is_none());
    a.close().await;
    b.close().await;
    server.shutdown().await;
    fx.server.shutdown().await;
}

/// Motion vectors of a frame rendered from the viewer's camera lead to the
/// previous frame's camera: a static surface reprojects through depth.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_from_a_turning_viewer_carry_its_camera_motion() {
    let fx = fixture(fx_buffers()).await;
    let (server, config) = fx.interactive_server("builtin:pan");
    let mut s = client::connect(config).await.unwrap();
    let mut previous: Option<Arrived> = None;
    let mut checked = 0;
    let start = Instant::now();
    let mut seq = 0;
    while checked < 4 {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "{checked} frames checked"
        );
        seq += 1;
        // Turning 2° a step about the vertical.
        let yaw = DQuat::from_rotation_y((seq as f64 * 2.0).to_radians());
        let base = viewer(0.0);
        s.send_input(&input(seq, Pose::new(base.position, yaw * base.rotation)))
            .unwrap();
        let f = next(&mut s).await;
        if let Some(p) = &previous {
            let consecutive = f.frame.meta.index == p.frame.meta.index + 1;
            let moved = !same_pose(&f.frame.meta.camera.pose, &p.frame.meta.camera.pose);
            if consecutive && moved && f.input.is_some() && p.input.is_some() {
                let (max, n) = static_reprojection_error(&f.frame, &p.frame);
                assert!(n > SIZE.pixels() as usize / 2, "{n} pixels");
                assert!(max < 0.05, "motion off the camera's by {max} px");
                checked += 1;
            }
        }
        previous = Some(f);
    }
    s.close().await;
    server.shutdown().await;
    fx.server.shutdown().await;
}

/// Largest distance between a frame's motion vectors and the reprojection
/// of its depth into `prev`'s camera, over the finite-depth pixels.
fn static_reprojection_error(cur: &protocol::Frame, prev: &protocol::Frame) -> (f64, usize) {
    let (w, dims) = (cur.meta.size.width as usize, cur.meta.size.as_f64());
    let (mut max, mut n) = (0.0f64, 0);
    for (i, (m, &d)) in cur.motion.iter().zip(&cur.depth).enumerate() {
        let px = glam::DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
        let Some(want) =
            cur.meta
                .camera
                .static_motion(&prev.meta.camera, px, f64::from(d), dims, dims)
        else {
            continue;
        };
        let got = glam::DVec2::new(f64::from(m[0]), f64::from(m[1]));
        max = max.max((got - want).length());
        n += 1;
    }
    (max, n)
}

fn fx_buffers() -> Vec<protocol::wire::StreamBuffer> {
    protocol::wire::StreamBuffer::default_set(protocol::Codec::Zstd).to_vec()
}

/// How often [`open_elsewhere`] was called.
static OPENED_ELSEWHERE: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Opens a session's source on a thread of its own (as the in-process
/// demo does, at a lower priority) and counts the calls.
fn open_elsewhere(open: &mut (dyn FnMut() + Send)) {
    OPENED_ELSEWHERE.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    let caller = std::thread::current().id();
    std::thread::scope(|s| {
        s.spawn(|| {
            assert_ne!(std::thread::current().id(), caller);
            open();
        });
    });
}

/// An opener that forgets to open.
fn never_open(_: &mut (dyn FnMut() + Send)) {}

/// An interactive feed's opener opens each session's source once, where
/// it says; one that never opens it is an error of the subscription, not
/// a session without frames.
#[test]
fn an_interactive_session_source_is_opened_by_the_feed_s_opener() {
    let spec = |scene: &str| host::source::SourceSpec::Scene {
        spec: scene.into(),
        size: SIZE,
        fps: REPLAY_FPS,
        window: Default::default(),
        base: ".".into(),
    };
    let encoding =
        || host::source::Encoding::new(protocol::wire::BufferSet::Lossless, video::ColorCodec::Raw);
    let feed =
        host::source::Feed::interactive(spec("builtin:default"), encoding(), Some(open_elsewhere))
            .unwrap();
    let subscription = feed.subscribe().expect("the source opens");
    assert!(subscription.source.is_some() && subscription.viewer.is_some());
    assert_eq!(
        OPENED_ELSEWHERE.load(std::sync::atomic::Ordering::SeqCst),
        1
    );
    let forgetful =
        host::source::Feed::interactive(spec("builtin:default"), encoding(), Some(never_open))
            .unwrap();
    let Err(e) = forgetful.subscribe() else {
        panic!("a source that was never opened was subscribed to");
    };
    assert!(e.to_string().contains("never opened"), "{e:#}");
}
