//! The dump format: round trips, streaming reads, and typed errors for
//! truncated, corrupted and missing files.

use std::fs;
use std::time::Duration;

use glam::{DQuat, DVec3};
use half::f16;
use protocol::dump::{DumpError, DumpReader, DumpWriter, Manifest, PANIC_DETAIL, frame_paths};
use protocol::frame::ExtraBuffer;
use protocol::{BufferKind, Camera, Frame, FrameMeta, FrameSize, Pose, Projection, Window};

const SIZE: FrameSize = FrameSize::new(33, 19);

fn frame(index: u64) -> Frame {
    let n = SIZE.pixels() as usize;
    let mut camera = Camera::new(
        Pose::new(
            DVec3::new(1e5 + index as f64, 3.0, -7.0),
            DQuat::from_rotation_y(0.1 * index as f64),
        ),
        Projection::perspective(1.1, 33.0 / 19.0, 0.1, f64::INFINITY),
    );
    camera.window = Window::FULL;
    Frame {
        meta: FrameMeta {
            index,
            time: index as f64 / 30.0,
            camera,
            size: SIZE,
            host_processing: Duration::from_micros(1234 + index),
            cut: index == 2,
        },
        color: (0..n)
            .map(|i| {
                let v = (i + index as usize) as f32;
                [
                    f16::from_f32(v * 0.5),
                    f16::from_f32(1000.0 + v),
                    f16::from_f32(-0.25),
                    f16::ONE,
                ]
            })
            .collect(),
        depth: (0..n)
            .map(|i| {
                if i % 5 == 0 {
                    f32::INFINITY
                } else {
                    1e-6 + i as f32 * 3.5
                }
            })
            .collect(),
        motion: (0..n)
            .map(|i| [i as f32 * 0.01 - 1.0, 123.456 - i as f32])
            .collect(),
        extras: vec![],
    }
}

fn write_dump(dir: &std::path::Path, count: u64) -> Vec<Frame> {
    let mut w = DumpWriter::create(dir, Manifest::new(30.0, SIZE, "test: synthetic")).unwrap();
    let frames: Vec<Frame> = (0..count).map(frame).collect();
    for f in &frames {
        w.write_frame(f).unwrap();
    }
    let m = w.finish().unwrap();
    assert_eq!(m.frame_count, count);
    frames
}

#[test]
fn frames_round_trip_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let mut frames = write_dump(dir.path(), 3);
    let r = DumpReader::open(dir.path()).unwrap();
    assert_eq!(r.len(), 3);
    assert_eq!(r.manifest().size(), SIZE);
    assert_eq!(r.manifest().source, "test: synthetic");
    for (i, f) in r.frames().enumerate() {
        assert_eq!(f.unwrap(), frames[i], "frame {i}");
    }
    // Extras survive too (mask quantised to 8 bits exactly).
    let extra_dir = tempfile::tempdir().unwrap();
    let mut w = DumpWriter::create(extra_dir.path(), Manifest::new(60.0, SIZE, "extras")).unwrap();
    let n = SIZE.pixels() as usize;
    frames[0].extras = vec![
        ExtraBuffer {
            kind: BufferKind::Mask,
            data: (0..n).map(|i| (i * 7 % 256) as u8).collect(),
        },
        ExtraBuffer {
            kind: BufferKind::Albedo,
            data: (0..n)
                .flat_map(|i| {
                    [
                        f16::from_f32(i as f32 / n as f32),
                        f16::from_f32(0.5),
                        f16::from_f32(0.25),
                        f16::ONE,
                    ]
                })
                .flat_map(f16::to_le_bytes)
                .collect(),
        },
    ];
    w.write_frame(&frames[0]).unwrap();
    let back = DumpReader::open(extra_dir.path())
        .unwrap()
        .read_frame(0)
        .unwrap();
    let mut expect = frames[0].clone();
    expect.extras.sort_by_key(|e| e.kind);
    let mut got = back;
    got.extras.sort_by_key(|e| e.kind);
    assert_eq!(got, expect);
}

#[test]
fn the_exr_has_the_documented_channels() {
    let dir = tempfile::tempdir().unwrap();
    write_dump(dir.path(), 1);
    let (exr, json) = frame_paths(dir.path(), 0);
    let meta = exr::meta::MetaData::read_from_file(&exr, true).unwrap();
    let channels: Vec<(String, exr::meta::attribute::SampleType)> = meta.headers[0]
        .channels
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_type))
        .collect();
    use exr::meta::attribute::SampleType::{F16, F32};
    assert_eq!(
        channels,
        vec![
            ("B".into(), F16),
            ("G".into(), F16),
            ("R".into(), F16),
            ("Z".into(), F32),
            ("motion.X".into(), F32),
            ("motion.Y".into(), F32),
        ]
    );
    // The JSON is readable by anything: far = "inf" since JSON lacks infinity.
    let text = fs::read_to_string(json).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["camera"]["projection"]["far"], "inf");
    assert_eq!(v["index"], 0);
}

#[test]
fn an_interrupted_recording_is_still_a_valid_dump() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = DumpWriter::create(dir.path(), Manifest::new(30.0, SIZE, "x")).unwrap();
    w.write_frame(&frame(0)).unwrap();
    w.write_frame(&frame(1)).unwrap();
    drop(w); // no finish()
    let r = DumpReader::open(dir.path()).unwrap();
    assert_eq!(r.len(), 2);
    assert_eq!(r.read_frame(1).unwrap(), frame(1));
    // And a second writer refuses to overwrite it.
    assert!(matches!(
        DumpWriter::create(dir.path(), Manifest::new(30.0, SIZE, "y")),
        Err(DumpError::AlreadyExists(_))
    ));
}

#[test]
fn writer_refuses_bad_frames() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = DumpWriter::create(dir.path(), Manifest::new(30.0, SIZE, "x")).unwrap();
    w.write_frame(&frame(5)).unwrap();
    assert!(matches!(
        w.write_frame(&frame(5)),
        Err(DumpError::IndexOrder {
            previous: 5,
            got: 5
        })
    ));
    let mut bad = frame(6);
    bad.depth.pop();
    assert!(matches!(
        w.write_frame(&bad),
        Err(DumpError::Invalid { .. })
    ));
    let mut nan = frame(6);
    nan.meta.camera.pose.position.z = f64::NAN;
    assert!(matches!(
        w.write_frame(&nan),
        Err(DumpError::Invalid { .. })
    ));
    assert_eq!(w.len(), 1);
}

#[test]
fn missing_frames_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    write_dump(dir.path(), 3);
    let (exr1, _) = frame_paths(dir.path(), 1);
    let (_, json2) = frame_paths(dir.path(), 2);
    fs::remove_file(&exr1).unwrap();
    fs::remove_file(&json2).unwrap();
    let r = DumpReader::open(dir.path()).unwrap();
    assert!(r.read_frame(0).is_ok());
    assert!(matches!(
        r.read_frame(1),
        Err(DumpError::MissingFrame { position: 1, .. })
    ));
    assert!(matches!(
        r.read_frame(2),
        Err(DumpError::MissingFrame { position: 2, .. })
    ));
    assert!(matches!(
        r.read_frame(3),
        Err(DumpError::OutOfRange {
            position: 3,
            count: 3
        })
    ));
    // A manifest claiming more frames than exist.
    let m = dir.path().join("manifest.json");
    let text = fs::read_to_string(&m)
        .unwrap()
        .replace("\"frame_count\": 3", "\"frame_count\": 9");
    fs::write(&m, text).unwrap();
    let r = DumpReader::open(dir.path()).unwrap();
    assert!(matches!(
        r.read_frame(8),
        Err(DumpError::MissingFrame { position: 8, .. })
    ));
    let errors = r.frames().filter(Result::is_err).count();
    assert_eq!(errors, 8);
}

#[test]
fn truncated_and_corrupted_exr_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    write_dump(dir.path(), 1);
    let (exr, _) = frame_paths(dir.path(), 0);
    let original = fs::read(&exr).unwrap();
    let r = DumpReader::open(dir.path()).unwrap();
    // Truncations at many points, including inside the header.
    for cut in [0, 4, 20, 100, original.len() / 2, original.len() - 1] {
        fs::write(&exr, &original[..cut]).unwrap();
        let e = r.read_frame(0).expect_err("truncated file must fail");
        assert!(
            matches!(e, DumpError::Exr { .. } | DumpError::SizeMismatch { .. }),
            "cut {cut}: {e}"
        );
    }
    // Byte corruption across the file: an error or a frame, never a panic.
    let mut errors = 0;
    for i in (0..original.len()).step_by(original.len() / 97 + 1) {
        let mut b = original.clone();
        b[i] ^= 0xa5;
        fs::write(&exr, &b).unwrap();
        match r.read_frame(0) {
            Ok(_) => {}
            Err(DumpError::Exr { detail, .. }) => {
                assert_ne!(detail, PANIC_DETAIL, "the EXR decoder panicked at byte {i}");
                errors += 1;
            }
            Err(e @ (DumpError::SizeMismatch { .. } | DumpError::MissingChannel { .. })) => {
                let _ = e;
                errors += 1;
            }
            Err(e) => panic!("unexpected error kind at byte {i}: {e}"),
        }
    }
    assert!(errors > 0);
    // Wrong size in the file vs the metadata.
    fs::write(&exr, &original).unwrap();
    let small = tempfile::tempdir().unwrap();
    let mut f = frame(0);
    f.meta.size = FrameSize::new(2, 2);
    f.color.truncate(4);
    f.depth.truncate(4);
    f.motion.truncate(4);
    f.meta.camera.window = Window {
        u0: -1.0,
        v0: -1.0,
        u1: 1.5,
        v1: 1.0,
    };
    let mut w = DumpWriter::create(small.path(), Manifest::new(30.0, SIZE, "small")).unwrap();
    w.write_frame(&f).unwrap();
    fs::copy(frame_paths(small.path(), 0).0, &exr).unwrap();
    assert!(matches!(
        r.read_frame(0),
        Err(DumpError::SizeMismatch { .. })
    ));
}

#[test]
fn bad_manifests_and_metadata_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(
        DumpReader::open(dir.path()),
        Err(DumpError::Io { .. })
    ));
    write_dump(dir.path(), 1);
    let m = dir.path().join("manifest.json");
    let good = fs::read_to_string(&m).unwrap();
    for (from, to, check) in [
        ("\"format_version\": 1", "\"format_version\": 7", "version"),
        (
            "\"conventions_version\": 1",
            "\"conventions_version\": 0",
            "version",
        ),
        ("\"fps\": 30.0", "\"fps\": -1.0", "manifest"),
        ("\"width\": 33", "\"width\": 9000", "manifest"),
        ("\"framegen-stream-dump\"", "\"something-else\"", "manifest"),
        ("\"fps\": 30.0", "\"fps\": \"fast\"", "json"),
    ] {
        fs::write(&m, good.replace(from, to)).unwrap();
        let e = DumpReader::open(dir.path()).expect_err(from);
        let ok = match check {
            "version" => matches!(e, DumpError::UnsupportedVersion { .. }),
            "manifest" => matches!(e, DumpError::BadManifest(_)),
            _ => matches!(e, DumpError::Json { .. }),
        };
        assert!(ok, "{from} -> {to}: {e}");
    }
    fs::write(&m, &good[..good.len() / 2]).unwrap();
    assert!(matches!(
        DumpReader::open(dir.path()),
        Err(DumpError::Json { .. })
    ));
    fs::write(&m, vec![b' '; 2 << 20]).unwrap();
    assert!(matches!(
        DumpReader::open(dir.path()),
        Err(DumpError::TooLarge { .. })
    ));
    fs::write(&m, &good).unwrap();

    let (_, json) = frame_paths(dir.path(), 0);
    let meta = fs::read_to_string(&json).unwrap();
    let r = DumpReader::open(dir.path()).unwrap();
    fs::write(&json, meta.replace("\"cut\": false", "\"cut\": 3")).unwrap();
    assert!(matches!(r.read_frame(0), Err(DumpError::Json { .. })));
    fs::write(&json, meta.replace("\"fov_y\": 1.1", "\"fov_y\": 9.0")).unwrap();
    assert!(matches!(r.read_frame(0), Err(DumpError::Invalid { .. })));
    fs::write(&json, meta.replace("\"width\": 33", "\"width\": 32")).unwrap();
    assert!(matches!(
        r.read_frame(0),
        Err(DumpError::SizeMismatch { .. })
    ));
    fs::write(&json, &meta).unwrap();
    assert!(r.read_frame(0).is_ok());
}

#[test]
fn frames_iterator_checks_index_order() {
    let dir = tempfile::tempdir().unwrap();
    write_dump(dir.path(), 3);
    // Rewrite frame 2's index to go backwards.
    let (_, json) = frame_paths(dir.path(), 2);
    let text = fs::read_to_string(&json)
        .unwrap()
        .replace("\"index\": 2", "\"index\": 1");
    fs::write(&json, text).unwrap();
    let r = DumpReader::open(dir.path()).unwrap();
    let results: Vec<_> = r.frames().collect();
    assert!(results[0].is_ok() && results[1].is_ok());
    assert!(matches!(
        results[2],
        Err(DumpError::IndexOrder {
            previous: 1,
            got: 1
        })
    ));
}

#[cfg(unix)]
#[test]
fn special_files_are_refused_not_read_forever() {
    let dir = tempfile::tempdir().unwrap();
    write_dump(dir.path(), 1);
    let m = dir.path().join("manifest.json");
    fs::remove_file(&m).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &m).unwrap();
    assert!(matches!(
        DumpReader::open(dir.path()),
        Err(DumpError::Io { .. })
    ));
}

/// A frame JSON whose host processing time is near `u64::MAX` seconds is
/// a typed validation error when read (it used to pass and overflow the
/// server's `+=` when the encode time was added).
#[test]
fn a_host_processing_overflow_is_a_typed_error() -> Result<(), Box<dyn std::error::Error>> {
    let dir = tempfile::tempdir()?;
    write_dump(dir.path(), 1);
    let (_, json) = frame_paths(dir.path(), 0);
    let mut meta: serde_json::Value = serde_json::from_slice(&fs::read(&json)?)?;
    let processing = meta
        .pointer_mut("/host_processing/secs")
        .ok_or("no host_processing.secs in the frame JSON")?;
    *processing = serde_json::Value::from(u64::MAX);
    fs::write(&json, serde_json::to_vec(&meta)?)?;
    let r = DumpReader::open(dir.path())?;
    match r.read_frame(0) {
        Err(DumpError::Invalid { source, .. }) => {
            assert_eq!(
                source,
                protocol::ValidationError::OutOfRange("host processing time")
            );
        }
        other => panic!(
            "expected an invalid frame, got {:?}",
            other.map(|f| f.meta.index)
        ),
    }
    Ok(())
}
