//! Corrupt and unsupported inputs give typed errors; damaged frames are
//! skipped and reported, never fatal. The Blender fixture is the base that
//! each case damages.

use std::fs;
use std::path::{Path, PathBuf};

use super::blender::BlenderDump;
use super::unreal::{UnrealDump, UnrealWriter, WriteOptions};
use super::*;
use crate::dump::{DumpReader, PlaneOut, read_planes, write_planes};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/blender")
}

/// A copy of the Blender fixture whose sidecar `edit` may change.
fn blender_copy(edit: impl FnOnce(&mut serde_json::Value)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for entry in fs::read_dir(fixture()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap();
        if path.extension().is_some_and(|e| e == "exr" || e == "json") {
            fs::copy(&path, dir.path().join(name)).unwrap();
        }
    }
    let sidecar = dir.path().join(SIDECAR);
    let mut json: serde_json::Value = serde_json::from_slice(&fs::read(&sidecar).unwrap()).unwrap();
    edit(&mut json);
    fs::write(&sidecar, serde_json::to_vec(&json).unwrap()).unwrap();
    dir
}

/// A change to a sidecar's JSON.
type Edit = fn(&mut serde_json::Value);

fn camera_of(json: &mut serde_json::Value, frame: usize) -> &mut serde_json::Value {
    &mut json["frames"][frame]["camera"]
}

#[test]
fn the_fixture_opens_as_blender() {
    assert_eq!(Format::detect(&fixture()).unwrap(), Format::Blender);
    let dump = AnyDump::open(fixture()).unwrap();
    assert_eq!(dump.len(), 10);
    assert_eq!(dump.size(), FrameSize::new(64, 36));
    assert_eq!(dump.fps(), 30.0);
}

#[test]
fn unsupported_cameras_are_refused() {
    let cases: [(&str, Edit); 4] = [
        ("ORTHO", |j| camera_of(j, 3)["type"] = "ORTHO".into()),
        ("lens shift", |j| camera_of(j, 0)["shift_x"] = 0.1.into()),
        ("sensor fit", |j| {
            camera_of(j, 0)["sensor_fit"] = "DIAGONAL".into()
        }),
        ("non-square", |j| {
            j["frames"][2]["pixel_aspect"] = serde_json::json!([1.0, 2.0])
        }),
    ];
    for (what, edit) in cases {
        let dir = blender_copy(edit);
        match BlenderDump::open(dir.path()) {
            Err(ImportError::Unsupported(detail)) => {
                assert!(detail.contains(what), "{what}: {detail}")
            }
            other => panic!("{what}: expected Unsupported, got {other:?}"),
        }
    }
}

#[test]
fn malformed_sidecars_are_typed_errors() {
    let cases: [(&str, Edit); 8] = [
        ("format", |j| j["format"] = "something-else".into()),
        ("file name", |j| {
            j["frames"][1]["file"] = "../0002.exr".into()
        }),
        ("increase", |j| j["frames"][4]["frame"] = 2.into()),
        ("size must not change", |j| {
            j["frames"][5]["resolution"] = serde_json::json!([32, 18])
        }),
        ("fps", |j| j["fps"] = (-1.0).into()),
        ("mirrored", |j| {
            let m = &mut camera_of(j, 0)["matrix_world"];
            for r in 0..3 {
                m[r][0] = (-m[r][0].as_f64().unwrap()).into();
            }
        }),
        ("clip", |j| camera_of(j, 0)["clip_start"] = 0.0.into()),
        ("span", |j| {
            j["frames"][0]["frame"] = i64::MIN.into();
            j["frames"][9]["frame"] = i64::MAX.into();
        }),
    ];
    for (what, edit) in cases {
        let dir = blender_copy(edit);
        let err = AnyDump::open(dir.path()).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, ImportError::Sidecar { .. }),
            "{what}: expected a sidecar error, got {err:?}"
        );
        let expect = if what == "clip" { "out of range" } else { what };
        assert!(text.contains(expect), "{what}: {text}");
    }
    // Not JSON at all; and a directory with nothing recognisable.
    let dir = blender_copy(|_| {});
    fs::write(dir.path().join(SIDECAR), b"{\"format\": ").unwrap();
    assert!(matches!(
        AnyDump::open(dir.path()),
        Err(ImportError::Json { .. })
    ));
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        AnyDump::open(empty.path()),
        Err(ImportError::NotRecognized(_))
    ));
}

/// Damaged frames: each one is a typed error on its own, and an import
/// skips it, reports it, flags the next frame as a cut and carries on.
#[test]
fn damaged_frames_are_skipped_and_reported() {
    let dir = blender_copy(|_| {});
    let frame = |i: u64| dir.path().join(format!("{:04}.exr", i + 1));
    // 2: missing. 4: truncated. 6: a valid EXR of another size. 8: no Vector pass.
    fs::remove_file(frame(2)).unwrap();
    let bytes = fs::read(frame(4)).unwrap();
    fs::write(frame(4), &bytes[..bytes.len() / 2]).unwrap();
    let small = FrameSize::new(8, 8);
    let plane = |name| PlaneOut {
        name,
        values: vec![1.0; 64],
        half: false,
    };
    write_planes(&frame(6), small, vec![plane("R"), plane("G"), plane("B")]).unwrap();
    let full = FrameSize::new(64, 36);
    let full_plane = |name| PlaneOut {
        name,
        values: vec![1.0; full.pixels() as usize],
        half: false,
    };
    write_planes(
        &frame(8),
        full,
        ["Combined.R", "Combined.G", "Combined.B", "Depth.Z"]
            .map(full_plane)
            .into(),
    )
    .unwrap();

    let dump = AnyDump::open(dir.path()).unwrap();
    let err = |i| dump.read_frame(i).unwrap_err();
    assert!(matches!(
        err(2),
        ImportError::Dump(DumpError::MissingFrame { position: 2, .. })
    ));
    assert!(matches!(err(4), ImportError::Dump(DumpError::Exr { .. })));
    assert!(matches!(
        err(6),
        ImportError::Dump(DumpError::SizeMismatch { .. })
    ));
    match err(8) {
        ImportError::Dump(DumpError::MissingChannel { channel, .. }) => {
            assert_eq!(channel, "ViewLayer.Vector.X")
        }
        other => panic!("expected a missing channel, got {other:?}"),
    }

    let out = tempfile::tempdir().unwrap();
    let out = out.path().join("dump");
    let report = import(&dump, &out, |_| {}).unwrap();
    assert_eq!(report.written, 6);
    let skipped: Vec<u64> = report
        .problems
        .iter()
        .filter(|p| p.skipped)
        .map(|p| p.position)
        .collect();
    assert_eq!(skipped, [2, 4, 6, 8]);
    let reader = DumpReader::open(&out).unwrap();
    let cuts: Vec<u64> = reader
        .frames()
        .map(|f| f.unwrap())
        .filter(|f| f.meta.cut)
        .map(|f| f.meta.index)
        .collect();
    // The frames after the skipped ones (source positions 3, 5, 7, 9).
    assert_eq!(cuts, [3, 5, 7, 9]);
}

#[test]
fn non_finite_values_are_counted_and_kept() {
    let dir = blender_copy(|_| {});
    let size = FrameSize::new(64, 36);
    let n = size.pixels() as usize;
    // Frame 3 rewritten from its own planes with NaN poked into each buffer.
    let src = dir.path().join("0004.exr");
    let planes = read_planes(&src, size, &[]).unwrap();
    let mut out = Vec::new();
    for name in [
        "Combined.R",
        "Combined.G",
        "Combined.B",
        "Depth.Z",
        "Vector.X",
        "Vector.Y",
    ] {
        let full = format!("ViewLayer.{name}");
        let mut values = planes.require(&full).unwrap().to_vec();
        match name {
            "Combined.G" => values[10] = f32::NAN,
            "Depth.Z" => values[11..14].fill(f32::NAN),
            // On the floor: the sky's motion is recomputed, not read.
            "Vector.Y" => values[64 * 30 + 20] = f32::NEG_INFINITY,
            _ => {}
        }
        assert_eq!(values.len(), n);
        out.push((full, values));
    }
    write_planes(
        &src,
        size,
        out.iter()
            .map(|(name, values)| PlaneOut {
                name,
                values: values.clone(),
                half: false,
            })
            .collect(),
    )
    .unwrap();
    let dump = AnyDump::open(dir.path()).unwrap();
    let target = tempfile::tempdir().unwrap();
    let report = import(&dump, &target.path().join("d"), |_| {}).unwrap();
    assert_eq!(report.written, 10);
    assert_eq!(
        report.non_finite,
        NonFinite {
            color: 1,
            depth: 3,
            motion: 1
        }
    );
    assert_eq!(report.problems.len(), 1);
    assert_eq!(report.problems[0].position, 3);
    assert!(!report.problems[0].skipped);
    // The check skips the bad pixels and still agrees.
    assert!(
        report.reprojection.median_px < 0.05,
        "{:?}",
        report.reprojection
    );
}

/// A minimal Unreal capture from the Blender fixture's first frames, to
/// damage.
fn unreal_copy() -> tempfile::TempDir {
    let blender = AnyDump::open(fixture()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut w = UnrealWriter::create(
        dir.path(),
        "Shot",
        blender.fps(),
        blender.size(),
        WriteOptions {
            sky_depth: 1e9,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    for i in 0..3 {
        w.write_frame(&blender.read_frame(i).unwrap()).unwrap();
    }
    w.finish().unwrap();
    dir
}

fn edit_unreal(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let sidecar = dir.join(SIDECAR);
    let mut json: serde_json::Value = serde_json::from_slice(&fs::read(&sidecar).unwrap()).unwrap();
    edit(&mut json);
    fs::write(&sidecar, serde_json::to_vec(&json).unwrap()).unwrap();
}

#[test]
fn unreal_versions_and_encodings_outside_ue4_are_refused() {
    let dir = unreal_copy();
    assert_eq!(Format::detect(dir.path()).unwrap(), Format::Unreal);
    UnrealDump::open(dir.path()).unwrap();
    for (field, value, expect) in [
        ("engine_version", "5.3", "UE 5"),
        ("velocity_encoding", "ue5", "velocity encoding"),
        ("version", "2", "sidecar version"),
    ] {
        let dir = unreal_copy();
        edit_unreal(dir.path(), |j| {
            j[field] = if field == "version" {
                2.into()
            } else {
                value.into()
            }
        });
        match UnrealDump::open(dir.path()) {
            Err(ImportError::Unsupported(d)) => assert!(d.contains(expect), "{d}"),
            other => panic!("{field}: expected Unsupported, got {other:?}"),
        }
    }
}

#[test]
fn unreal_layout_damage_is_typed() {
    let dir = unreal_copy();
    fs::remove_dir_all(dir.path().join("SceneDepth")).unwrap();
    let err = UnrealDump::open(dir.path()).unwrap_err();
    assert!(
        matches!(err, ImportError::Sidecar { ref detail, .. } if detail.contains("SceneDepth")),
        "{err:?}"
    );

    let dir = unreal_copy();
    edit_unreal(dir.path(), |j| j["frames"][1]["fov"] = 0.0.into());
    assert!(matches!(
        UnrealDump::open(dir.path()),
        Err(ImportError::Sidecar { .. })
    ));

    let dir = unreal_copy();
    fs::remove_file(dir.path().join("MotionVector/Shot.0001.exr")).unwrap();
    let dump = AnyDump::open(dir.path()).unwrap();
    assert!(matches!(
        dump.read_frame(1),
        Err(ImportError::Dump(DumpError::MissingFrame {
            position: 1,
            ..
        }))
    ));
    let out = tempfile::tempdir().unwrap();
    let report = import(&dump, &out.path().join("d"), |_| {}).unwrap();
    assert_eq!(report.written, 2);
    assert!(report.problems[0].skipped && report.problems[0].position == 1);
}

/// The evidence for the Blender conventions (see `blender.rs`): imported
/// as documented, the fixture's motion agrees with depth + camera far below
/// a pixel, and every other reading fits worse.
#[test]
fn blender_conventions_fit_the_fixture() {
    let dump = AnyDump::open(fixture()).unwrap();
    let out = tempfile::tempdir().unwrap();
    let report = import(&dump, &out.path().join("d"), |_| {}).unwrap();
    let r = &report.reprojection;
    eprintln!("{r:#?}");
    assert_eq!(report.written, 10);
    assert!(report.problems.is_empty(), "{:?}", report.problems);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert_eq!(r.frames, 9);
    assert!(r.pixels > 9 * 1500, "{} pixels checked", r.pixels);
    assert!(r.mean_px < 0.02 && r.median_px < 0.005, "{r:?}");
    // The rest are silhouette pixels, whose depth and motion come from
    // different surfaces.
    assert!(r.within_1px > 0.995);
    for (h, at_least) in [
        (Hypothesis::SignFlipped, 1.0),
        (Hypothesis::YFlipped, 0.02),
        (Hypothesis::XFlipped, 1.0),
        (Hypothesis::DepthAlongRay, 0.05),
    ] {
        let alt = r.alternative(h).unwrap();
        assert!(
            alt.mean_px > at_least && alt.mean_px > 5.0 * r.mean_px,
            "{alt:?}"
        );
    }

    // Sky: Cycles' 1e10 became +inf; the top row is open sky.
    let frame = DumpReader::open(out.path().join("d"))
        .unwrap()
        .read_frame(4)
        .unwrap();
    assert!(frame.depth[..64].iter().all(|d| *d == f32::INFINITY));
    assert!(frame.depth.iter().all(|d| *d > 0.0));
    // The sliding box is masked, and only it: a small share of the frame.
    let mask = &frame.extras[0];
    assert_eq!(mask.kind, crate::BufferKind::Mask);
    let masked = mask.data.iter().filter(|v| **v != 0).count();
    assert!((20..400).contains(&masked), "{masked} masked pixels");
}

/// The mask of Blender frame `position` read from a copy of the fixture
/// whose sidecar lists `listed` animated pass indices (`None`: no list).
fn blender_mask(listed: Option<&[u32]>, position: u64) -> Result<Option<Vec<bool>>, TestError> {
    let listed = listed.map(<[u32]>::to_vec);
    let dir = blender_copy(move |json| match listed {
        Some(l) => json["animated_pass_indices"] = serde_json::json!(l),
        None => {
            if let Some(sidecar) = json.as_object_mut() {
                sidecar.remove("animated_pass_indices");
            }
        }
    });
    let frame = AnyDump::open(dir.path())?.read_frame(position)?;
    Ok(frame
        .extras
        .iter()
        .find(|e| e.kind == crate::BufferKind::Mask)
        .map(|m| m.data.iter().map(|v| *v != 0).collect()))
}

/// Any error a test reports instead of panicking.
type TestError = Box<dyn std::error::Error>;

/// Issue 16 §9: only the listed pass indices are animated (a scene that
/// uses indices for compositing keeps its static objects unmasked);
/// without a list the mask comes from motion that depth + camera do not
/// explain, and it finds the same sliding box.
#[test]
fn blender_masks_come_from_the_listed_indices_or_the_motion() -> Result<(), TestError> {
    let listed = blender_mask(Some(&[1]), 4)?.ok_or("no mask")?;
    let boxed = listed.iter().filter(|m| **m).count();
    assert!((20..400).contains(&boxed), "{boxed}");
    // The box's index used for compositing only, or another index listed:
    // nothing moves on its own.
    for other in [&[][..], &[2]] {
        let mask = blender_mask(Some(other), 4)?.ok_or("no mask")?;
        assert!(mask.iter().all(|m| !m), "{other:?}");
    }
    // No list: from the motion. The first frame has no camera before it.
    assert!(blender_mask(None, 0)?.is_none());
    for position in [2, 4, 8] {
        let listed = blender_mask(Some(&[1]), position)?.ok_or("no mask")?;
        let derived = blender_mask(None, position)?.ok_or("no mask")?;
        let both = listed
            .iter()
            .zip(&derived)
            .filter(|(a, b)| **a && **b)
            .count();
        let either = listed
            .iter()
            .zip(&derived)
            .filter(|(a, b)| **a || **b)
            .count();
        // Measured: every box pixel, plus a few silhouette pixels whose
        // depth and motion come from different surfaces (frame 2: 18 of
        // 24, 4: 36 of 36, 8: 36 of 43).
        let boxed = listed.iter().filter(|m| **m).count();
        assert_eq!(both, boxed, "frame {position}");
        assert!(
            both * 10 >= either * 7,
            "frame {position}: {both} of {either}"
        );
    }
    Ok(())
}
