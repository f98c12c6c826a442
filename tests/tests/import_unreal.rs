//! The Unreal folder-per-buffer layout: frames from our own renderer written
//! as a UE 4 capture (UE4 velocity encoding, centimetres, left-handed Z-up
//! camera rotators) and imported back.

use protocol::dump::DumpReader;
use protocol::import::unreal::{UnrealWriter, WriteOptions};
use protocol::import::{AnyDump, Format, Hypothesis, import};
use protocol::{Frame, FrameSize};

const SIZE: FrameSize = FrameSize::new(96, 54);

/// The default scene: a moving camera and animated objects.
fn rendered() -> Vec<Frame> {
    tests::render_scene("default", SIZE, 30.0, 0..6)
}

fn write_capture(frames: &[Frame], dir: &std::path::Path, options: WriteOptions) {
    let mut w = UnrealWriter::create(dir, "Shot", 30.0, SIZE, options).unwrap();
    for f in frames {
        w.write_frame(f).unwrap();
    }
    w.finish().unwrap();
}

/// Largest angle between two rotations, radians.
fn angle(a: glam::DQuat, b: glam::DQuat) -> f64 {
    a.normalize().angle_between(b.normalize())
}

#[test]
fn a_rendered_sequence_round_trips_through_the_unreal_layout() {
    let frames = rendered();
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("capture");
    write_capture(&frames, &capture, WriteOptions::default());
    for folder in ["PreTonemapHDRColor", "SceneDepth", "MotionVector"] {
        assert!(
            capture.join(folder).join("Shot.0005.exr").is_file(),
            "{folder}"
        );
    }
    let dump = AnyDump::open(&capture).unwrap();
    assert_eq!(dump.format(), Format::Unreal);
    let out = dir.path().join("dump");
    let report = import(&dump, &out, |_| {}).unwrap();
    assert_eq!(report.written, 6);
    assert!(report.problems.is_empty(), "{:?}", report.problems);

    let back: Vec<Frame> = DumpReader::open(&out)
        .unwrap()
        .frames()
        .map(Result::unwrap)
        .collect();
    let mut worst_motion = 0.0f32;
    for (a, b) in frames.iter().zip(&back) {
        assert_eq!(
            (a.meta.index, a.meta.time, a.meta.cut),
            (b.meta.index, b.meta.time, b.meta.cut)
        );
        let (ca, cb) = (&a.meta.camera, &b.meta.camera);
        assert!((ca.pose.position - cb.pose.position).length() < 1e-9);
        assert!(angle(ca.pose.rotation, cb.pose.rotation) < 1e-9);
        let (pa, pb) = (&ca.projection, &cb.projection);
        assert!((pa.fov_y - pb.fov_y).abs() < 1e-12 && (pa.aspect - pb.aspect).abs() < 1e-12);
        assert!((pa.near - pb.near).abs() < 1e-12);
        // UE renders with an infinite far plane; the import says so.
        assert_eq!(pb.far, f64::INFINITY);
        assert_eq!(a.color, b.color, "colour is carried bit for bit");
        for (&da, &db) in a.depth.iter().zip(&b.depth) {
            assert!(
                da == db || ((da - db) / da).abs() < 1e-6,
                "depth {da} came back as {db}"
            );
        }
        for (ma, mb) in a.motion.iter().zip(&b.motion) {
            worst_motion = worst_motion.max((ma[0] - mb[0]).abs().max((ma[1] - mb[1]).abs()));
        }
    }
    // The f32 encoding keeps ~1e-5 px at this size.
    assert!(worst_motion < 1e-3, "motion off by {worst_motion} px");

    // The static majority agrees with depth + camera; the flipped reading
    // does not. Moving objects are unmasked here and raise the mean.
    let r = &report.reprojection;
    eprintln!("{r:#?}");
    assert!(r.median_px < 0.05, "{r:?}");
    let flipped = r.alternative(Hypothesis::SignFlipped).unwrap();
    assert!(
        flipped.median_px > 10.0 * r.median_px.max(0.01),
        "{flipped:?}"
    );
}

/// UE4's default: static geometry writes no velocity (the clear value 0);
/// the importer computes it from depth and the two cameras, as UE4's TAA
/// does, and gets the renderer's motion back (measured: within 0.0004 px
/// on 25 800 pixels).
#[test]
fn static_pixels_without_velocity_get_camera_motion() {
    let frames = rendered();
    let dir = tempfile::tempdir().unwrap();
    write_capture(
        &frames,
        dir.path(),
        WriteOptions {
            velocity_for_static: false,
            ..WriteOptions::default()
        },
    );
    let dump = AnyDump::open(dir.path()).unwrap();
    let (mut worst, mut computed) = (0.0f32, 0usize);
    for (i, original) in frames.iter().enumerate().skip(1) {
        let (frame, from_file) = dump.read_with_origin(i as u64).unwrap();
        let from_file = from_file.unwrap();
        for (p, (a, b)) in original.motion.iter().zip(&frame.motion).enumerate() {
            if !from_file[p] {
                computed += 1;
                worst = worst.max((a[0] - b[0]).abs().max((a[1] - b[1]).abs()));
            }
        }
    }
    eprintln!("{computed} computed pixels, worst {worst} px");
    assert!(computed > 5 * SIZE.pixels() as usize / 2, "{computed}");
    assert!(worst < 0.01, "camera motion off by {worst} px");
}
