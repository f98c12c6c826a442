//! The dump format: a directory of rendered frames on disk.
//!
//! ```text
//! DIR/manifest.json          Manifest: format, versions, fps, size, count, source
//! DIR/frames/000000.exr      pixels of frame 0 (channels: see `exr_io`)
//! DIR/frames/000000.json     FrameMeta of frame 0: index, time, camera, size, …
//! DIR/frames/000001.exr
//! …
//! ```
//!
//! Files are numbered by position in the dump (0 .. frame_count); the frame's
//! own `index` (stream numbering) is in its JSON and must increase strictly.
//! The manifest's size is the *displayed* size; a frame with a widened
//! window may be larger (its JSON says so) — a frame with the plain window
//! must match it.
//!
//! The [`DumpWriter`] rewrites the manifest atomically (a synced temporary
//! file and a rename) after every frame, so an interrupted recording, even by
//! a crash, is still a valid dump of the frames so far. Color is stored as
//! RGB: alpha is not part of the data contract and reads back as 1. The
//! [`DumpReader`] loads one frame at a time, checks every file's size before
//! reading it, and turns missing, truncated or corrupt files into
//! [`DumpError`]s.

mod exr_io;

use std::fs;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use exr_io::{MAX_EXR_CHANNELS, PANIC_DETAIL, channel_names, read_exr, write_exr};
pub(crate) use exr_io::{PlaneOut, mask_bytes, read_planes, rgb_pixel, write_planes};

use crate::frame::{Frame, FrameMeta, FrameSize};
use crate::{CONVENTIONS_VERSION, Effects, Limits, ValidationError};

/// The `format` string every manifest carries.
pub const FORMAT_NAME: &str = "framegen-stream-dump";
/// Version of the directory layout this crate reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// Largest manifest file accepted.
pub const MAX_MANIFEST_BYTES: u64 = 1 << 20;
/// Largest per-frame JSON file accepted.
pub const MAX_FRAME_JSON_BYTES: u64 = 64 << 10;
/// Largest frame count a manifest may claim.
pub const MAX_FRAMES: u64 = 10_000_000;

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// Layout version, [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Data conventions version, [`CONVENTIONS_VERSION`].
    pub conventions_version: u32,
    /// Frames per second of the recording (the rate frames were rendered at).
    pub fps: f64,
    /// Displayed size in pixels.
    pub width: u32,
    /// Displayed size in pixels.
    pub height: u32,
    /// Number of frames in `frames/`.
    pub frame_count: u64,
    /// Free-form description: scene, renderer, importer, command line.
    pub source: String,
    /// What the recorded content does (the client plans its stages from
    /// it); absent in dumps that do not know, which then run every stage.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects: Option<Effects>,
}

impl Manifest {
    /// A manifest for an empty dump.
    pub fn new(fps: f64, size: FrameSize, source: impl Into<String>) -> Self {
        Self {
            format: FORMAT_NAME.to_owned(),
            format_version: FORMAT_VERSION,
            conventions_version: CONVENTIONS_VERSION,
            fps,
            width: size.width,
            height: size.height,
            frame_count: 0,
            source: source.into(),
            effects: None,
        }
    }

    /// The same manifest, recording `effects`.
    pub fn with_effects(self, effects: Effects) -> Self {
        Self {
            effects: Some(effects),
            ..self
        }
    }

    /// The displayed size.
    pub fn size(&self) -> FrameSize {
        FrameSize::new(self.width, self.height)
    }

    /// Checks the format name, versions, fps, size and count.
    pub fn validate(&self) -> Result<(), DumpError> {
        if self.format != FORMAT_NAME {
            return Err(DumpError::BadManifest(format!(
                "format is {:?}, expected {FORMAT_NAME:?}",
                self.format
            )));
        }
        if self.format_version != FORMAT_VERSION {
            return Err(DumpError::UnsupportedVersion {
                what: "format_version",
                got: self.format_version,
                supported: FORMAT_VERSION,
            });
        }
        if self.conventions_version != CONVENTIONS_VERSION {
            return Err(DumpError::UnsupportedVersion {
                what: "conventions_version",
                got: self.conventions_version,
                supported: CONVENTIONS_VERSION,
            });
        }
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 1000.0) {
            return Err(DumpError::BadManifest(format!(
                "fps {} is not in (0, 1000]",
                self.fps
            )));
        }
        if self.frame_count > MAX_FRAMES {
            return Err(DumpError::BadManifest(format!(
                "frame_count {} exceeds {MAX_FRAMES}",
                self.frame_count
            )));
        }
        Limits::default()
            .check_size(self.width, self.height)
            .map_err(|e| DumpError::BadManifest(e.to_string()))
    }
}

/// A dump that cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum DumpError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A JSON file is malformed.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// Where and what.
        #[source]
        source: serde_json::Error,
    },
    /// An EXR file is malformed or unsupported.
    #[error("{path}: OpenEXR: {detail}")]
    Exr {
        /// The file.
        path: PathBuf,
        /// What the decoder reported.
        detail: String,
    },
    /// The manifest is inconsistent.
    #[error("manifest: {0}")]
    BadManifest(String),
    /// A version this crate does not read.
    #[error("manifest {what} is {got}, this build reads {supported}")]
    UnsupportedVersion {
        /// Which version field.
        what: &'static str,
        /// Found.
        got: u32,
        /// Supported.
        supported: u32,
    },
    /// The manifest lists a frame whose files are missing.
    #[error("frame {position} listed in the manifest is missing: {path}")]
    MissingFrame {
        /// Position in the dump.
        position: u64,
        /// The missing file.
        path: PathBuf,
    },
    /// A frame position beyond the manifest's count.
    #[error("frame {position} is beyond the dump's {count} frames")]
    OutOfRange {
        /// Requested position.
        position: u64,
        /// Frames in the dump.
        count: u64,
    },
    /// A file is larger than its kind may be.
    #[error("{path} is {len} bytes, more than the {max} allowed")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        len: u64,
        /// The limit.
        max: u64,
    },
    /// Image size differs from the metadata.
    #[error("{path}: size {}x{} differs from the expected {}x{}", got.width, got.height, expected.width, expected.height)]
    SizeMismatch {
        /// The file.
        path: PathBuf,
        /// From metadata.
        expected: FrameSize,
        /// In the file.
        got: FrameSize,
    },
    /// An EXR header lists more channels than any frame can need.
    #[error("{path}: {count} channels, more than the {max} a frame may have")]
    TooManyChannels {
        /// The file.
        path: PathBuf,
        /// Channels in its header.
        count: usize,
        /// The limit ([`MAX_EXR_CHANNELS`]).
        max: usize,
    },
    /// A required channel is absent.
    #[error("{path}: channel {channel:?} is missing")]
    MissingChannel {
        /// The file.
        path: PathBuf,
        /// The channel name.
        channel: String,
    },
    /// Frame metadata breaks the data contract.
    #[error("{path}: {source}")]
    Invalid {
        /// The file (or the dump directory for a frame being written).
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: ValidationError,
    },
    /// Frame indices must increase strictly.
    #[error("frame index {got} does not follow the previous index {previous}")]
    IndexOrder {
        /// The previous frame's index.
        previous: u64,
        /// This frame's index.
        got: u64,
    },
    /// The writer would overwrite an existing dump.
    #[error("{0} already holds a dump")]
    AlreadyExists(PathBuf),
}

impl DumpError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        DumpError::Io {
            path: path.to_owned(),
            source,
        }
    }

    fn exr(path: &Path, e: exr::error::Error) -> Self {
        DumpError::Exr {
            path: path.to_owned(),
            detail: e.to_string(),
        }
    }

    fn exr_msg(path: &Path, detail: &str) -> Self {
        DumpError::Exr {
            path: path.to_owned(),
            detail: detail.to_owned(),
        }
    }
}

/// Paths of frame `position`'s files under `dir`.
pub fn frame_paths(dir: &Path, position: u64) -> (PathBuf, PathBuf) {
    let frames = dir.join("frames");
    (
        frames.join(format!("{position:06}.exr")),
        frames.join(format!("{position:06}.json")),
    )
}

/// Reads a whole small regular file, never more than `max` bytes: the file
/// is opened once and the read itself is capped, so a FIFO, a device or a
/// file that grows meanwhile cannot exhaust memory.
pub(crate) fn read_capped(path: &Path, max: u64) -> Result<Vec<u8>, DumpError> {
    let file = fs::File::open(path).map_err(|e| DumpError::io(path, e))?;
    let meta = file.metadata().map_err(|e| DumpError::io(path, e))?;
    if !meta.is_file() {
        return Err(DumpError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file"),
        ));
    }
    let mut bytes = Vec::with_capacity(meta.len().min(max) as usize);
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| DumpError::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(DumpError::TooLarge {
            path: path.to_owned(),
            len: meta.len().max(bytes.len() as u64),
            max,
        });
    }
    Ok(bytes)
}

/// Maps "file not found" to [`DumpError::MissingFrame`], other errors as is.
pub(crate) fn missing_as_frame(e: DumpError, position: u64) -> DumpError {
    match e {
        DumpError::Io { path, source } if source.kind() == std::io::ErrorKind::NotFound => {
            DumpError::MissingFrame { position, path }
        }
        other => other,
    }
}

/// Flushes a written file to stable storage.
fn sync_file(path: &Path) -> Result<(), DumpError> {
    fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| DumpError::io(path, e))
}

/// Flushes a directory entry change (a rename) to stable storage. Best
/// effort: not every platform can open a directory for syncing.
fn sync_dir(dir: &Path) {
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// Writes `bytes` to `path` through a synced temporary file and a rename, so
/// readers never see a half-written file, even after a crash.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), DumpError> {
    let tmp = path.with_extension("tmp");
    let mut f = fs::File::create(&tmp).map_err(|e| DumpError::io(&tmp, e))?;
    f.write_all(bytes)
        .and_then(|()| f.sync_all())
        .map_err(|e| DumpError::io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| DumpError::io(path, e))?;
    if let Some(dir) = path.parent() {
        sync_dir(dir);
    }
    Ok(())
}

/// Streams frames out of a dump, one at a time.
#[derive(Debug)]
pub struct DumpReader {
    dir: PathBuf,
    manifest: Manifest,
}

impl DumpReader {
    /// Opens a dump and validates its manifest. No frame is read yet.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DumpError> {
        let dir = dir.as_ref().to_owned();
        let path = dir.join("manifest.json");
        let bytes = read_capped(&path, MAX_MANIFEST_BYTES)?;
        let manifest: Manifest =
            serde_json::from_slice(&bytes).map_err(|source| DumpError::Json { path, source })?;
        manifest.validate()?;
        Ok(Self { dir, manifest })
    }

    /// The validated manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Number of frames.
    pub fn len(&self) -> u64 {
        self.manifest.frame_count
    }

    /// True for a dump without frames.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Reads only the metadata of frame `position` (cheap: one small JSON).
    pub fn read_meta(&self, position: u64) -> Result<FrameMeta, DumpError> {
        if position >= self.len() {
            return Err(DumpError::OutOfRange {
                position,
                count: self.len(),
            });
        }
        let (_, json) = frame_paths(&self.dir, position);
        let bytes =
            read_capped(&json, MAX_FRAME_JSON_BYTES).map_err(|e| missing_as_frame(e, position))?;
        let meta: FrameMeta = serde_json::from_slice(&bytes).map_err(|source| DumpError::Json {
            path: json.clone(),
            source,
        })?;
        meta.validate(&Limits::default())
            .map_err(|source| DumpError::Invalid {
                path: json.clone(),
                source,
            })?;
        if meta.camera.window.is_full() && meta.size != self.manifest.size() {
            return Err(DumpError::SizeMismatch {
                path: json,
                expected: self.manifest.size(),
                got: meta.size,
            });
        }
        Ok(meta)
    }

    /// Reads frame `position`: metadata, then pixels.
    pub fn read_frame(&self, position: u64) -> Result<Frame, DumpError> {
        let meta = self.read_meta(position)?;
        let (exr, _) = frame_paths(&self.dir, position);
        let mut frame = Frame::empty(meta);
        exr_io::read_exr(&exr, &mut frame).map_err(|e| missing_as_frame(e, position))?;
        Ok(frame)
    }

    /// Iterates over every frame in order, reading each when it is reached.
    ///
    /// Frame indices must increase strictly; a frame that breaks the order
    /// is an [`DumpError::IndexOrder`] item.
    pub fn frames(&self) -> impl Iterator<Item = Result<Frame, DumpError>> + '_ {
        let mut previous = None;
        (0..self.len()).map(move |i| {
            let frame = self.read_frame(i)?;
            if let Some(p) = previous {
                if frame.meta.index <= p {
                    return Err(DumpError::IndexOrder {
                        previous: p,
                        got: frame.meta.index,
                    });
                }
            }
            previous = Some(frame.meta.index);
            Ok(frame)
        })
    }
}

/// Writes a dump frame by frame.
#[derive(Debug)]
pub struct DumpWriter {
    dir: PathBuf,
    manifest: Manifest,
    last_index: Option<u64>,
}

impl DumpWriter {
    /// Creates a dump in `dir` (created if needed). Fails if `dir` already
    /// holds a manifest, so a recording never silently replaces another.
    pub fn create(dir: impl AsRef<Path>, manifest: Manifest) -> Result<Self, DumpError> {
        let dir = dir.as_ref().to_owned();
        let manifest = Manifest {
            frame_count: 0,
            ..manifest
        };
        manifest.validate()?;
        let frames = dir.join("frames");
        fs::create_dir_all(&frames).map_err(|e| DumpError::io(&frames, e))?;
        // Claim the directory atomically: a second writer fails here.
        let manifest_path = dir.join("manifest.json");
        match fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&manifest_path)
        {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(DumpError::AlreadyExists(dir));
            }
            Err(e) => return Err(DumpError::io(&manifest_path, e)),
        }
        let writer = Self {
            dir,
            manifest,
            last_index: None,
        };
        writer.write_manifest()?;
        Ok(writer)
    }

    fn write_manifest(&self) -> Result<(), DumpError> {
        let path = self.dir.join("manifest.json");
        let json = serde_json::to_vec_pretty(&self.manifest).map_err(|source| DumpError::Json {
            path: path.clone(),
            source,
        })?;
        write_atomic(&path, &json)
    }

    /// Appends a frame: pixels, metadata, then the updated manifest.
    pub fn write_frame(&mut self, frame: &Frame) -> Result<(), DumpError> {
        frame
            .validate(&Limits::default())
            .map_err(|source| DumpError::Invalid {
                path: self.dir.clone(),
                source,
            })?;
        if frame.meta.camera.window.is_full() && frame.meta.size != self.manifest.size() {
            return Err(DumpError::SizeMismatch {
                path: self.dir.clone(),
                expected: self.manifest.size(),
                got: frame.meta.size,
            });
        }
        if let Some(previous) = self.last_index {
            if frame.meta.index <= previous {
                return Err(DumpError::IndexOrder {
                    previous,
                    got: frame.meta.index,
                });
            }
        }
        let (exr, json) = frame_paths(&self.dir, self.manifest.frame_count);
        let tmp = exr.with_extension("exr.tmp");
        exr_io::write_exr(&tmp, frame)?;
        sync_file(&tmp)?;
        fs::rename(&tmp, &exr).map_err(|e| DumpError::io(&exr, e))?;
        let meta = serde_json::to_vec_pretty(&frame.meta).map_err(|source| DumpError::Json {
            path: json.clone(),
            source,
        })?;
        write_atomic(&json, &meta)?;
        self.manifest.frame_count += 1;
        self.last_index = Some(frame.meta.index);
        self.write_manifest()
    }

    /// Frames written so far.
    pub fn len(&self) -> u64 {
        self.manifest.frame_count
    }

    /// True before the first frame.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Finishes the dump and returns its manifest.
    pub fn finish(self) -> Result<Manifest, DumpError> {
        self.write_manifest()?;
        Ok(self.manifest)
    }
}
