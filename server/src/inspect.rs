//! `server inspect DIR`: reads every frame of a dump (native, or a Blender
//! or Unreal folder through the importers) and reports what a stream of it
//! would carry, and anything wrong: unreadable frames, indices or times that
//! do not increase, non-finite pixels, and motion vectors that disagree
//! with depth + camera (`protocol::import::reprojection`).

use protocol::Frame;
use protocol::import::{AnyDump, ReprojectionCheck, ReprojectionReport};

/// Per-dump findings.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    /// Frames the manifest lists.
    pub frames: u64,
    /// Frames that could not be read, with the reason.
    pub unreadable: Vec<(u64, String)>,
    /// Frames whose time does not increase over the previous frame.
    pub time_not_increasing: u64,
    /// Frames marked as camera cuts.
    pub cuts: u64,
    /// Pixels with `+inf` depth (sky), over all frames.
    pub sky_pixels: u64,
    /// Color, depth or motion values that are NaN, or depth that is not > 0.
    pub bad_values: u64,
    /// Largest motion vector length, pixels.
    pub max_motion: f32,
    /// Mean time between frames, seconds.
    pub mean_frame_interval: f64,
    /// Motion vectors against depth + camera on static pixels.
    pub reprojection: ReprojectionReport,
}

impl Report {
    /// True when nothing is wrong.
    pub fn is_clean(&self) -> bool {
        self.unreadable.is_empty() && self.time_not_increasing == 0 && self.bad_values == 0
    }

    fn add_frame(&mut self, f: &Frame) {
        self.cuts += u64::from(f.meta.cut);
        for d in &f.depth {
            if *d == f32::INFINITY {
                self.sky_pixels += 1;
            } else if d.is_nan() || *d <= 0.0 {
                self.bad_values += 1;
            }
        }
        for m in &f.motion {
            if m[0].is_nan() || m[1].is_nan() {
                self.bad_values += 1;
            } else {
                self.max_motion = self.max_motion.max(m[0].hypot(m[1]));
            }
        }
        self.bad_values += f
            .color
            .iter()
            .filter(|c| c[..3].iter().any(|v| v.is_nan()))
            .count() as u64;
    }
}

/// Reads the whole dump, calling `progress` after each frame.
pub fn inspect(reader: &AnyDump, mut progress: impl FnMut(u64)) -> Report {
    let mut report = Report {
        frames: reader.len(),
        ..Report::default()
    };
    let mut last_time: Option<(f64, u64)> = None;
    let (mut first_time, mut last_ok_time) = (None, None);
    let mut check = ReprojectionCheck::new();
    let mut previous = None;
    for i in 0..reader.len() {
        match reader.read_with_origin(i) {
            Ok((f, from_file)) => {
                if let Some(prev) = previous.as_ref().filter(|_| !f.meta.cut) {
                    check.add(prev, &f, from_file.as_deref());
                }
                if let Some((t, _)) = last_time {
                    if f.meta.time <= t {
                        report.time_not_increasing += 1;
                    }
                }
                last_time = Some((f.meta.time, f.meta.index));
                first_time.get_or_insert(f.meta.time);
                last_ok_time = Some(f.meta.time);
                report.add_frame(&f);
                previous = Some(f.meta);
            }
            Err(e) => {
                report.unreadable.push((i, e.to_string()));
                // The next frame's motion points into this one.
                previous = None;
            }
        }
        progress(i + 1);
    }
    let read = report.frames - report.unreadable.len() as u64;
    if let (Some(a), Some(b)) = (first_time, last_ok_time) {
        if read > 1 {
            report.mean_frame_interval = (b - a) / (read - 1) as f64;
        }
    }
    report.reprojection = check.finish();
    report
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use glam::{DQuat, DVec3};
    use half::f16;
    use protocol::dump::{DumpWriter, Manifest, frame_paths};
    use protocol::{Camera, FrameMeta, FrameSize, Pose, Projection};

    use super::*;

    fn frame(index: u64, time: f64) -> Frame {
        let size = FrameSize::new(4, 2);
        Frame {
            meta: FrameMeta {
                index,
                time,
                camera: Camera::new(
                    Pose::new(DVec3::ZERO, DQuat::IDENTITY),
                    Projection::perspective(1.0, 2.0, 0.1, 10.0),
                ),
                size,
                host_processing: Duration::ZERO,
                cut: index == 2,
            },
            color: vec![[f16::ONE; 4]; 8],
            depth: vec![1.0, 2.0, f32::INFINITY, f32::NAN, 1.0, 1.0, 1.0, 1.0],
            motion: vec![[3.0, 4.0]; 8],
            extras: vec![],
        }
    }

    #[test]
    fn reports_contents_and_problems() {
        let dir = tempfile::tempdir().unwrap();
        let mut w =
            DumpWriter::create(dir.path(), Manifest::new(30.0, FrameSize::new(4, 2), "t")).unwrap();
        for (i, t) in [(0, 0.0), (1, 0.5), (2, 0.25), (3, 1.5)] {
            w.write_frame(&frame(i, t)).unwrap();
        }
        w.finish().unwrap();
        std::fs::remove_file(frame_paths(dir.path(), 3).0).unwrap();
        let mut calls = 0;
        let r = inspect(&AnyDump::open(dir.path()).unwrap(), |_| calls += 1);
        assert_eq!(calls, 4);
        assert_eq!(r.frames, 4);
        assert_eq!(r.unreadable.len(), 1);
        assert_eq!(r.unreadable[0].0, 3);
        assert_eq!(r.time_not_increasing, 1);
        assert_eq!(r.cuts, 1);
        assert_eq!(r.sky_pixels, 3);
        assert_eq!(r.bad_values, 3);
        assert_eq!(r.max_motion, 5.0);
        assert!((r.mean_frame_interval - 0.125).abs() < 1e-12);
        assert!(!r.is_clean());
        // Frames 1 and 2 follow a readable frame; 2 is a cut; the camera
        // never moves, so the 3-4-5 vectors are 5 px off wherever depth is
        // valid.
        assert_eq!(r.reprojection.frames, 1);
        assert!((r.reprojection.mean_px - 5.0).abs() < 1e-9);
        assert_eq!(r.reprojection.warnings.len(), 1);
    }
}
