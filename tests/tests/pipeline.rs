//! End to end over everything that exists: render analytic frames, record a
//! dump, replay it paced by simulation time, send each frame as a per-frame
//! stream, receive the streams interleaved in small chunks, decode, and check
//! the result against the original and against the data conventions.

use std::time::Duration;

use glam::{DVec2, DVec3};
use host::pacer::{Pace, Pacer};
use protocol::assemble::encode_frame;
use protocol::dump::{DumpReader, DumpWriter, Manifest};
use protocol::wire::StreamBuffer;
use protocol::{Codec, FrameSize, Limits, WorldPoint};

const SIZE: FrameSize = FrameSize::new(64, 36);
const FPS: f64 = 30.0;

fn buffers() -> [StreamBuffer; 3] {
    StreamBuffer::default_set(Codec::Raw)
}

#[test]
fn dump_replay_stream_receive_decode() {
    let dir = tempfile::tempdir().unwrap();
    let originals: Vec<_> = (0..6)
        .map(|i| tests::render(i, FPS, DVec3::ZERO, SIZE))
        .collect();
    let mut w = DumpWriter::create(
        dir.path(),
        Manifest::new(FPS, SIZE, "tests: analytic ground plane"),
    )
    .unwrap();
    for f in &originals {
        w.write_frame(f).unwrap();
    }
    w.finish().unwrap();

    let reader = DumpReader::open(dir.path()).unwrap();
    let mut pacer = Pacer::new(1.0);
    let mut now = Duration::from_secs(100);
    let mut streams = Vec::new();
    for i in 0..reader.len() {
        let frame = reader.read_frame(i).unwrap();
        let next = (i + 1 < reader.len()).then(|| reader.read_meta(i + 1).unwrap().time);
        loop {
            match pacer.decide(now, frame.meta.time, next) {
                Pace::WaitUntil(t) => now = t,
                Pace::Send => break,
                Pace::Skip => panic!("a sender that keeps up never skips"),
            }
        }
        // Sent exactly at the frame's simulation time.
        let expect = Duration::from_secs(100) + Duration::from_secs_f64(frame.meta.time);
        assert!(now.abs_diff(expect) < Duration::from_micros(1));
        streams.push(
            encode_frame(&frame, &buffers(), 1)
                .unwrap()
                .to_stream_bytes()
                .unwrap(),
        );
    }

    // Interleave all streams in 97-byte chunks, as a transport might.
    let mut rx = client::FrameReceiver::new(Limits::default(), 16);
    let mut delivered = Vec::new();
    let mut offsets = vec![0; streams.len()];
    let mut cancelled = Vec::new();
    while offsets.iter().zip(&streams).any(|(o, s)| *o < s.len()) {
        for (id, s) in streams.iter().enumerate() {
            let o = offsets[id];
            if o >= s.len() || cancelled.contains(&(id as u64)) {
                offsets[id] = s.len();
                continue;
            }
            let end = (o + 97).min(s.len());
            let d = rx.on_data(id as u64, &s[o..end]).unwrap();
            offsets[id] = end;
            if end == s.len() {
                rx.on_stream_end(id as u64).unwrap();
            }
            for f in d.frames {
                delivered.push(f.decode().unwrap());
            }
            cancelled.extend(d.cancel);
        }
    }
    // In order, and later frames may supersede earlier ones that completed
    // after them; whatever was delivered is bit-exact.
    assert!(
        delivered
            .windows(2)
            .all(|w| w[0].meta.index < w[1].meta.index)
    );
    assert_eq!(delivered.last().unwrap().meta.index, 5);
    for f in &delivered {
        assert_eq!(f, &originals[f.meta.index as usize]);
    }
    let stats = rx.stats();
    // Every frame is either delivered or superseded (late); none is lost.
    assert_eq!(delivered.len() + stats.frames_late as usize, streams.len());
    assert_eq!(stats.frames_dropped, 0);
    assert!(stats.bytes_received as usize <= streams.iter().map(Vec::len).sum::<usize>());

    // The display transform and metrics see identical images as identical.
    let last = delivered.last().unwrap();
    let a = framegen::display_encode(SIZE.width, SIZE.height, &last.color).unwrap();
    let b = framegen::display_encode(SIZE.width, SIZE.height, &originals[5].color).unwrap();
    assert_eq!(framegen::psnr(&a, &b).unwrap(), f64::INFINITY);
}

/// The motion convention across crates: following `prev = cur + mv` from a
/// ground pixel of frame t lands where frame t−1 shows the same surface
/// point, so the previous frame's depth there matches the point's depth in
/// the previous camera, for ordinary and for huge world coordinates.
#[test]
fn motion_vectors_point_to_the_same_surface_in_the_previous_frame() {
    for origin in [
        DVec3::ZERO,
        DVec3::new(1e5, 0.0, -1e5),
        DVec3::new(1e7, 0.0, 1e7),
    ] {
        let prev = tests::render(9, FPS, origin, SIZE);
        let cur = tests::render(10, FPS, origin, SIZE);
        let dims = SIZE.as_f64();
        let mut checked = 0;
        for j in 0..SIZE.height {
            for i in 0..SIZE.width {
                let k = cur.index(i, j);
                let px = DVec2::new(f64::from(i) + 0.5, f64::from(j) + 0.5);
                let mv = DVec2::new(f64::from(cur.motion[k][0]), f64::from(cur.motion[k][1]));
                let p = px + mv;
                let d = f64::from(cur.depth[k]);
                if d.is_infinite() {
                    // Sky: motion is finite (rotation only).
                    assert!(mv.is_finite());
                    continue;
                }
                let (pi, pj) = (p.x.floor(), p.y.floor());
                if pi < 0.0 || pj < 0.0 || pi >= dims.0 || pj >= dims.1 {
                    continue;
                }
                let Some(WorldPoint::Finite(w)) = cur.meta.camera.unproject(px, d, dims) else {
                    panic!("finite depth must unproject to a point");
                };
                let in_prev = prev
                    .meta
                    .camera
                    .project(WorldPoint::Finite(w), dims)
                    .unwrap();
                assert!(
                    (in_prev.pixel - p).length() < 1e-3,
                    "origin {origin}: {:?} vs {p:?}",
                    in_prev.pixel
                );
                // At the pixel centre nearest to p, the previous frame's depth
                // is close to the point's depth (the plane is smooth).
                // Near the horizon depth changes too fast between pixels.
                let pd = f64::from(prev.depth[prev.index(pi as u32, pj as u32)]);
                if pd.is_finite() && in_prev.depth < 8.0 {
                    assert!(
                        (pd - in_prev.depth).abs() < 0.1 * in_prev.depth,
                        "{pd} vs {}",
                        in_prev.depth
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 500, "only {checked} pixels checked");
    }
}
