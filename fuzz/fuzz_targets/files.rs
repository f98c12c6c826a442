//! The dump readers on arbitrary files. The input, split at its first two
//! `\n--\n` separators, becomes a native dump's `manifest.json`, frame 0's
//! metadata JSON and frame 0's EXR; the dump is opened and its first frames
//! read, and the EXR is also read on its own into a 16×9 frame. Every
//! outcome is a frame or a typed error: never a panic, a hang or an
//! allocation beyond the limits.
#![no_main]

use std::path::Path;
use std::sync::OnceLock;

use glam::{DQuat, DVec3};
use libfuzzer_sys::fuzz_target;
use protocol::dump::{DumpReader, frame_paths, read_exr};
use protocol::{Camera, Frame, FrameMeta, FrameSize, Pose, Projection};

const SEPARATOR: &[u8] = b"\n--\n";

/// `data` cut at the first `n − 1` separators (missing parts are empty).
fn parts(mut data: &[u8], n: usize) -> Vec<&[u8]> {
    let mut out = Vec::with_capacity(n);
    for _ in 1..n {
        match data.windows(SEPARATOR.len()).position(|w| w == SEPARATOR) {
            Some(i) => {
                out.push(&data[..i]);
                data = &data[i + SEPARATOR.len()..];
            }
            None => {
                out.push(data);
                data = &[];
            }
        }
    }
    out.push(data);
    out
}

fn dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary directory"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let dir = dir();
    let [manifest, meta, exr] = parts(data, 3)[..] else {
        return;
    };
    let (exr_path, meta_path) = frame_paths(dir, 0);
    std::fs::create_dir_all(dir.join("frames")).expect("the frames directory");
    std::fs::write(dir.join("manifest.json"), manifest).expect("the manifest");
    std::fs::write(&meta_path, meta).expect("the frame metadata");
    std::fs::write(&exr_path, exr).expect("the EXR");
    if let Ok(reader) = DumpReader::open(dir) {
        for position in 0..reader.len().min(2) {
            let _ = reader.read_frame(position);
        }
    }
    let size = FrameSize::new(16, 9);
    let mut frame = Frame::empty(FrameMeta {
        index: 0,
        time: 0.0,
        camera: Camera::new(
            Pose::new(DVec3::ZERO, DQuat::IDENTITY),
            Projection::perspective(1.0, 16.0 / 9.0, 0.1, 100.0),
        ),
        size,
        host_processing: std::time::Duration::ZERO,
        cut: false,
    });
    if read_exr(&exr_path, &mut frame).is_ok() {
        assert_eq!(frame.color.len(), size.pixels() as usize);
    }
});
