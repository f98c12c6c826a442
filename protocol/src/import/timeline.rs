//! What both importers know about a sequence before reading any pixel: its
//! rate, size, frame numbers, times and cameras, from the sidecar.

use std::path::{Path, PathBuf};

use super::ImportError;
use crate::camera::Camera;
use crate::dump::DumpError;
use crate::frame::{FrameMeta, FrameSize};

/// One frame of a [`Timeline`]: the source's frame number, its time (s)
/// and its camera in this crate's conventions.
pub(crate) struct Entry {
    pub number: i64,
    pub time: f64,
    pub camera: Camera,
}

/// A foreign sequence's frames, as its sidecar describes them.
#[derive(Clone, Debug)]
pub struct Timeline {
    fps: f64,
    size: FrameSize,
    numbers: Vec<i64>,
    times: Vec<f64>,
    cameras: Vec<Camera>,
}

impl Timeline {
    /// Checks that frame numbers increase strictly and times are finite;
    /// `sidecar` names the file in errors.
    pub(crate) fn new(
        sidecar: &Path,
        fps: f64,
        size: FrameSize,
        entries: Vec<Entry>,
    ) -> Result<Self, ImportError> {
        for w in entries.windows(2) {
            if w[1].number <= w[0].number {
                return Err(ImportError::sidecar(
                    sidecar,
                    format!(
                        "frame {} follows frame {}: frames must increase",
                        w[1].number, w[0].number
                    ),
                ));
            }
        }
        if let (Some(first), Some(last)) = (entries.first(), entries.last()) {
            // Indices count from the first frame; the span must fit.
            if last.number.checked_sub(first.number).is_none() {
                return Err(ImportError::sidecar(
                    sidecar,
                    format!(
                        "frame numbers {} … {} span more than an index can hold",
                        first.number, last.number
                    ),
                ));
            }
        }
        if let Some(e) = entries.iter().find(|e| !e.time.is_finite()) {
            return Err(ImportError::sidecar(
                sidecar,
                format!("frame {}: time is not finite", e.number),
            ));
        }
        Ok(Self {
            fps,
            size,
            numbers: entries.iter().map(|e| e.number).collect(),
            times: entries.iter().map(|e| e.time).collect(),
            cameras: entries.into_iter().map(|e| e.camera).collect(),
        })
    }

    /// Number of frames.
    pub fn len(&self) -> u64 {
        self.numbers.len() as u64
    }

    /// True when there are no frames.
    pub fn is_empty(&self) -> bool {
        self.numbers.is_empty()
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Image size.
    pub fn size(&self) -> FrameSize {
        self.size
    }

    /// The source's frame number at `position` (which must be in range).
    pub(crate) fn number(&self, position: u64) -> i64 {
        self.numbers[position as usize]
    }

    /// Metadata of frame `position`: index (frame number counted from the
    /// first), time, camera, and a cut where the frame numbers leave a gap
    /// (motion vectors then point to a frame that is not in the sequence).
    pub fn meta(&self, position: u64) -> Result<FrameMeta, DumpError> {
        let p = position as usize;
        if p >= self.numbers.len() {
            return Err(DumpError::OutOfRange {
                position,
                count: self.len(),
            });
        }
        Ok(FrameMeta {
            index: (self.numbers[p] - self.numbers[0]) as u64,
            time: self.times[p],
            camera: self.cameras[p],
            size: self.size,
            host_processing: std::time::Duration::ZERO,
            cut: p > 0 && self.numbers[p] != self.numbers[p - 1] + 1,
        })
    }

    /// The camera of the frame before `meta`'s, unless `meta` is the first
    /// or a cut: where motion computed from cameras points to.
    pub(crate) fn previous_camera(&self, position: u64, meta: &FrameMeta) -> Option<&Camera> {
        let p = position as usize;
        (p > 0 && !meta.cut).then(|| &self.cameras[p - 1])
    }
}

/// A foreign dump opened for reading: its folder, its parsed sidecar `S`
/// and the [`Timeline`] made from it. Each importer adds `open` and its
/// frame reader for its own sidecar type.
#[derive(Debug)]
pub struct Sequence<S> {
    pub(crate) dir: PathBuf,
    pub(crate) sidecar: S,
    pub(crate) timeline: Timeline,
}

impl<S> Sequence<S> {
    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The sidecar.
    pub fn sidecar(&self) -> &S {
        &self.sidecar
    }

    /// Rate, size, frame numbers, times and cameras.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }
}
