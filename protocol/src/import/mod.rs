//! Importers: dumps that other tools wrote, converted *into* this crate's
//! conventions (DESIGN §3) and dump format.
//!
//! * [`blender`]: multilayer OpenEXR renders with Combined, Depth and Vector
//!   passes, plus the `cameras.json` sidecar that
//!   `tools/blender/framegen_export.py` writes.
//! * [`unreal`]: Unreal-Engine-style captures, one folder per buffer
//!   (`PreTonemapHDRColor/`, `SceneDepth/`, `MotionVector/`), UE4's velocity
//!   encoding, and a `cameras.json` sidecar.
//!
//! [`AnyDump`] opens any of them, or a native dump, and reads frames one at
//! a time in this crate's conventions, so the server streams a foreign dump
//! directly. [`import`] converts one into a native dump: frames that cannot
//! be read (a missing buffer, a corrupt file, a size mismatch) are skipped
//! and reported, never fatal, and the next frame is flagged as a cut;
//! non-finite values are counted; and every frame's motion vectors are
//! checked against its depth and the two cameras ([`reprojection`]), with
//! loud warnings when the conventions look wrong.

pub mod blender;
pub mod reprojection;
mod timeline;
pub mod unreal;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use serde::Deserialize;

use crate::dump::{DumpError, DumpReader, DumpWriter, Manifest, read_capped};
use crate::frame::{Frame, FrameMeta, FrameSize};
use crate::{Effects, Limits};

pub use reprojection::{Hypothesis, ReprojectionCheck, ReprojectionReport};
pub(crate) use timeline::Entry;
pub use timeline::{Sequence, Timeline};

/// Name of the camera sidecar both importers read.
pub const SIDECAR: &str = "cameras.json";
/// Largest sidecar accepted.
pub const MAX_SIDECAR_BYTES: u64 = 64 << 20;

/// A foreign dump that cannot be opened or converted.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// Reading or writing files failed (I/O, OpenEXR, sizes, channels).
    #[error(transparent)]
    Dump(#[from] DumpError),
    /// The sidecar is malformed or inconsistent.
    #[error("{path}: {detail}")]
    Sidecar {
        /// The sidecar file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// The sidecar is not valid JSON of the expected shape.
    #[error("{path}: {source}")]
    Json {
        /// The sidecar file.
        path: PathBuf,
        /// Where and what.
        #[source]
        source: serde_json::Error,
    },
    /// Data this importer does not convert (a camera type, an encoding, an
    /// engine version), with what is supported.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// The directory is none of the known layouts.
    #[error(
        "{0}: not a dump this build reads (expected manifest.json, or cameras.json from \
         tools/blender/framegen_export.py or an Unreal capture)"
    )]
    NotRecognized(PathBuf),
    /// The source has no frames.
    #[error("{0}: no frames")]
    Empty(String),
}

impl ImportError {
    pub(crate) fn sidecar(path: &Path, detail: impl Into<String>) -> Self {
        ImportError::Sidecar {
            path: path.to_owned(),
            detail: detail.into(),
        }
    }
}

/// Which layout a directory holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// This crate's own dump (`manifest.json`).
    Native,
    /// Blender multilayer EXRs + sidecar.
    Blender,
    /// Unreal folder-per-buffer capture + sidecar.
    Unreal,
}

impl Format {
    /// Tells the layout of `dir` from its `manifest.json` or its sidecar's
    /// `format` field.
    pub fn detect(dir: &Path) -> Result<Format, ImportError> {
        if dir.join("manifest.json").is_file() {
            return Ok(Format::Native);
        }
        let path = dir.join(SIDECAR);
        if !path.is_file() {
            return Err(ImportError::NotRecognized(dir.to_owned()));
        }
        #[derive(Deserialize)]
        struct Head {
            format: String,
        }
        let head: Head = read_json(&path)?;
        match head.format.as_str() {
            blender::FORMAT => Ok(Format::Blender),
            unreal::FORMAT => Ok(Format::Unreal),
            other => Err(ImportError::sidecar(
                &path,
                format!(
                    "format {other:?} is neither {:?} nor {:?}",
                    blender::FORMAT,
                    unreal::FORMAT
                ),
            )),
        }
    }

    /// Lower-case name, as the CLI spells it.
    pub fn name(self) -> &'static str {
        match self {
            Format::Native => "native",
            Format::Blender => "blender",
            Format::Unreal => "unreal",
        }
    }
}

/// Reads and parses a JSON sidecar, capped at [`MAX_SIDECAR_BYTES`].
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, ImportError> {
    let bytes = read_capped(path, MAX_SIDECAR_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|source| ImportError::Json {
        path: path.to_owned(),
        source,
    })
}

/// Checks a sidecar's frame rate and image size.
pub(crate) fn check_rate_and_size(
    path: &Path,
    fps: f64,
    size: [u32; 2],
) -> Result<(), ImportError> {
    if !(fps.is_finite() && fps > 0.0 && fps <= 1000.0) {
        return Err(ImportError::sidecar(
            path,
            format!("fps {fps} is not in (0, 1000]"),
        ));
    }
    Limits::default()
        .check_size(size[0], size[1])
        .map_err(|e| ImportError::sidecar(path, e.to_string()))
}

/// A file name from a sidecar must name a file in its folder: no separators,
/// no `..`, not empty.
pub(crate) fn check_file_name(path: &Path, name: &str) -> Result<(), ImportError> {
    let bad = name.is_empty()
        || name == "."
        || name == ".."
        || name.contains(['/', '\\'])
        || name.contains('\0');
    if bad {
        return Err(ImportError::sidecar(
            path,
            format!("file name {name:?} must be a plain name inside the dump"),
        ));
    }
    Ok(())
}

/// Any dump this crate reads, opened for frame-by-frame reading in this
/// crate's conventions.
#[derive(Debug)]
pub enum AnyDump {
    /// A native dump.
    Native(DumpReader),
    /// A Blender render.
    Blender(blender::BlenderDump),
    /// An Unreal capture.
    Unreal(unreal::UnrealDump),
}

impl AnyDump {
    /// Opens `dir`, telling its layout with [`Format::detect`].
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ImportError> {
        let dir = dir.as_ref();
        Self::open_as(dir, Format::detect(dir)?)
    }

    /// Opens `dir` as `format`.
    pub fn open_as(dir: impl AsRef<Path>, format: Format) -> Result<Self, ImportError> {
        let dir = dir.as_ref();
        Ok(match format {
            Format::Native => AnyDump::Native(DumpReader::open(dir)?),
            Format::Blender => AnyDump::Blender(blender::BlenderDump::open(dir)?),
            Format::Unreal => AnyDump::Unreal(unreal::UnrealDump::open(dir)?),
        })
    }

    /// The layout.
    pub fn format(&self) -> Format {
        match self {
            AnyDump::Native(_) => Format::Native,
            AnyDump::Blender(_) => Format::Blender,
            AnyDump::Unreal(_) => Format::Unreal,
        }
    }

    /// Number of frames.
    pub fn len(&self) -> u64 {
        match self {
            AnyDump::Native(d) => d.len(),
            AnyDump::Blender(d) => d.timeline().len(),
            AnyDump::Unreal(d) => d.timeline().len(),
        }
    }

    /// True when there are no frames.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Frames per second of the source.
    pub fn fps(&self) -> f64 {
        match self {
            AnyDump::Native(d) => d.manifest().fps,
            AnyDump::Blender(d) => d.timeline().fps(),
            AnyDump::Unreal(d) => d.timeline().fps(),
        }
    }

    /// Displayed size.
    pub fn size(&self) -> FrameSize {
        match self {
            AnyDump::Native(d) => d.manifest().size(),
            AnyDump::Blender(d) => d.timeline().size(),
            AnyDump::Unreal(d) => d.timeline().size(),
        }
    }

    /// What the source is, for manifests and logs.
    pub fn describe(&self) -> String {
        match self {
            AnyDump::Native(d) => d.manifest().source.clone(),
            AnyDump::Blender(d) => d.describe(),
            AnyDump::Unreal(d) => d.describe(),
        }
    }

    /// What the content does, as far as the source says: a native dump's
    /// manifest, a Blender sidecar's list of animated objects (an empty list:
    /// no dynamic objects). Shading is never known from a render's passes,
    /// so it stays "may move".
    pub fn effects(&self) -> Effects {
        match self {
            AnyDump::Native(d) => d.manifest().effects.unwrap_or_default(),
            AnyDump::Blender(d) => Effects {
                dynamic_objects: d.animated().is_none_or(|list| !list.is_empty()),
                ..Effects::UNKNOWN
            },
            AnyDump::Unreal(_) => Effects::UNKNOWN,
        }
    }

    /// Metadata of frame `position` (cheap: no pixels are read).
    pub fn read_meta(&self, position: u64) -> Result<FrameMeta, ImportError> {
        Ok(match self {
            AnyDump::Native(d) => d.read_meta(position)?,
            AnyDump::Blender(d) => d.timeline().meta(position)?,
            AnyDump::Unreal(d) => d.timeline().meta(position)?,
        })
    }

    /// Frame `position`, converted to this crate's conventions.
    pub fn read_frame(&self, position: u64) -> Result<Frame, ImportError> {
        Ok(self.read_with_origin(position)?.0)
    }

    /// Frame `position` and, where only some of its motion vectors come from
    /// the source's files (the importers compute the rest from depth and
    /// camera: Blender's sky, Unreal's static geometry), which pixels' do.
    /// `None`: all of them.
    pub fn read_with_origin(
        &self,
        position: u64,
    ) -> Result<(Frame, Option<Vec<bool>>), ImportError> {
        Ok(match self {
            AnyDump::Native(d) => (d.read_frame(position)?, None),
            AnyDump::Blender(d) => {
                let (frame, from_file) = d.read_frame_with_origin(position)?;
                (frame, Some(from_file))
            }
            AnyDump::Unreal(d) => {
                let (frame, from_file) = d.read_frame_with_origin(position)?;
                (frame, Some(from_file))
            }
        })
    }
}

/// The rotation whose local X, Y, Z axes are (the directions of) `x`, `y`,
/// `z`, after removing scale and shear (Gram–Schmidt). A mirrored or
/// degenerate frame is an error.
pub(crate) fn rotation_of(x: DVec3, y: DVec3, z: DVec3) -> Result<DQuat, String> {
    let x = x.try_normalize().ok_or("camera matrix is degenerate")?;
    let y = (y - x * x.dot(y))
        .try_normalize()
        .ok_or("camera matrix is degenerate")?;
    let z_ortho = x.cross(y);
    if z_ortho.dot(z) <= 0.0 {
        return Err("camera matrix is mirrored (negative scale)".into());
    }
    Ok(DQuat::from_mat3(&DMat3::from_cols(x, y, z_ortho)).normalize())
}

/// The motion of pixel `i` (row-major in an image of `size`) of a static
/// surface at `depth` seen by `camera`, when the previous frame was seen by
/// `prev` (same size): what importers put where the source has no usable
/// motion. Zero without a previous camera or for an invalid point.
pub(crate) fn camera_motion(
    camera: &crate::Camera,
    prev: Option<&crate::Camera>,
    size: FrameSize,
    i: usize,
    depth: f32,
) -> [f32; 2] {
    let f = crate::camera::size_f(size.width, size.height);
    let pixel = glam::DVec2::new(
        (i % size.width as usize) as f64 + 0.5,
        (i / size.width as usize) as f64 + 0.5,
    );
    prev.and_then(|prev| camera.static_motion(prev, pixel, f64::from(depth), f, f))
        .map_or([0.0; 2], |m| [m.x as f32, m.y as f32])
}

/// A frame that was skipped or needs attention.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameProblem {
    /// Position in the source.
    pub position: u64,
    /// What happened.
    pub detail: String,
    /// True when the frame is not in the output.
    pub skipped: bool,
}

/// Non-finite values found in imported frames (NaN or ±inf where the
/// contract does not allow them: `+inf` depth is sky and is not counted).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NonFinite {
    /// Colour channel values.
    pub color: u64,
    /// Depth values that are NaN, `-inf`, zero or negative.
    pub depth: u64,
    /// Motion components.
    pub motion: u64,
}

impl NonFinite {
    /// Counts the bad values of one frame.
    pub fn of(frame: &Frame) -> Self {
        let color = frame
            .color
            .iter()
            .flat_map(|p| &p[..3])
            .filter(|v| !v.is_finite())
            .count() as u64;
        let depth = frame
            .depth
            .iter()
            .filter(|d| d.is_nan() || **d <= 0.0)
            .count() as u64;
        let motion = frame
            .motion
            .iter()
            .flatten()
            .filter(|v| !v.is_finite())
            .count() as u64;
        Self {
            color,
            depth,
            motion,
        }
    }

    /// Sum of all three counts.
    pub fn total(&self) -> u64 {
        self.color + self.depth + self.motion
    }

    fn add(&mut self, other: Self) {
        self.color += other.color;
        self.depth += other.depth;
        self.motion += other.motion;
    }
}

/// What [`import`] did.
#[derive(Clone, Debug)]
pub struct ImportReport {
    /// Layout of the source.
    pub format: Format,
    /// Frames in the source.
    pub source_frames: u64,
    /// Frames written to the output dump.
    pub written: u64,
    /// Skipped frames and frames with bad values, in order.
    pub problems: Vec<FrameProblem>,
    /// Bad values over all written frames.
    pub non_finite: NonFinite,
    /// Motion vectors against depth + camera.
    pub reprojection: ReprojectionReport,
}

/// Converts the dump `source` into a native dump at `out`, calling `progress`
/// after each source frame. Frames that fail to read are skipped and
/// reported; the frame after a skipped one is flagged as a cut.
pub fn import(
    source: &AnyDump,
    out: &Path,
    mut progress: impl FnMut(u64),
) -> Result<ImportReport, ImportError> {
    if source.is_empty() {
        return Err(ImportError::Empty(source.describe()));
    }
    let manifest = Manifest::new(
        source.fps(),
        source.size(),
        format!("imported from {}", source.describe()),
    )
    .with_effects(source.effects());
    let mut writer = DumpWriter::create(out, manifest)?;
    let mut report = ImportReport {
        format: source.format(),
        source_frames: source.len(),
        written: 0,
        problems: Vec::new(),
        non_finite: NonFinite::default(),
        reprojection: ReprojectionReport::default(),
    };
    let mut check = ReprojectionCheck::new();
    let mut previous: Option<FrameMeta> = None;
    let mut after_skip = false;
    for position in 0..source.len() {
        match source.read_with_origin(position) {
            Ok((mut frame, from_file)) => {
                if after_skip {
                    frame.meta.cut = true;
                    after_skip = false;
                }
                let bad = NonFinite::of(&frame);
                if bad.total() > 0 {
                    tracing::warn!(position, ?bad, "non-finite values in frame");
                    report.problems.push(FrameProblem {
                        position,
                        detail: format!(
                            "non-finite values: {} colour, {} depth, {} motion",
                            bad.color, bad.depth, bad.motion
                        ),
                        skipped: false,
                    });
                    report.non_finite.add(bad);
                }
                if let Some(prev) = previous.as_ref().filter(|_| !frame.meta.cut) {
                    check.add(prev, &frame, from_file.as_deref());
                }
                writer.write_frame(&frame)?;
                report.written += 1;
                previous = Some(frame.meta);
            }
            Err(e) => {
                tracing::warn!(position, error = %e, "frame skipped");
                report.problems.push(FrameProblem {
                    position,
                    detail: e.to_string(),
                    skipped: true,
                });
                after_skip = true;
            }
        }
        progress(position + 1);
    }
    writer.finish()?;
    report.reprojection = check.finish();
    report.reprojection.warn();
    Ok(report)
}
