//! One frame's pixels as a multi-channel OpenEXR file (crate `exr`).
//!
//! Channel names are chosen so tools read them without help:
//!
//! | channel                  | type  | content                                   |
//! |--------------------------|-------|-------------------------------------------|
//! | `R`, `G`, `B`            | half  | linear HDR color                          |
//! | `Z`                      | float | linear view depth, `+inf` for sky         |
//! | `motion.X`, `motion.Y`   | float | motion current → previous, pixels, y down |
//! | `normal.X/Y/Z` (extra)   | half  | world-space normal                        |
//! | `albedo.R/G/B` (extra)   | half  | albedo                                    |
//! | `mask.Y` (extra)         | half  | 8-bit mask value / 255                    |
//!
//! `R, G, B, Z` is the layout of Blender's plain (single-layer) OpenEXR
//! output with a Z pass, so Blender opens the color and depth directly; the
//! dotted names are ordinary layer channels, which Python `OpenEXR` and
//! `oiiotool` list and read by name. Files are scan-line ZIP compressed.
//! Readers accept half or float for any channel.

use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, MetaData,
    ReadChannels, ReadLayers, SmallVec, WritableImage, read,
};
use half::f16 as Half;

use super::DumpError;
use crate::frame::{BufferKind, ExtraBuffer, Frame, FrameSize};

/// Names of the channels that hold `kind`, in order.
pub fn channel_names(kind: BufferKind) -> &'static [&'static str] {
    match kind {
        BufferKind::Color => &["R", "G", "B"],
        BufferKind::Depth => &["Z"],
        BufferKind::Motion => &["motion.X", "motion.Y"],
        BufferKind::Normal => &["normal.X", "normal.Y", "normal.Z"],
        BufferKind::Albedo => &["albedo.R", "albedo.G", "albedo.B"],
        BufferKind::Mask => &["mask.Y"],
    }
}

/// Most channels an EXR read as a frame may have. A dump frame has at most
/// 13 (every [`channel_names`]); a Blender multilayer render with every
/// pass the importer reads, some 40. The `exr` decoder allocates every
/// channel of a layer before it returns, so a crafted header with a
/// thousand channels would cost a thousand frame-sized planes: it is
/// refused from the header (issue 18 §4).
pub const MAX_EXR_CHANNELS: usize = 64;

/// Detail of the error reported when the `exr` decoder panics.
pub const PANIC_DETAIL: &str = "decoder panicked on this file";

/// The error detail of a B44 or B44A compressed file (not read).
pub const B44_DETAIL: &str = "B44 compression is not read; re-save with ZIP, PIZ or none";

/// The channel list type `exr` wants.
type SmallChannels = SmallVec<[AnyChannel<FlatSamples>; 4]>;

/// One channel to write: its name, its samples and whether to store them as
/// half floats (colour-like data) or full floats (depth, motion).
pub(crate) struct PlaneOut<'a> {
    /// Channel name.
    pub name: &'a str,
    /// One value per pixel, row by row from the top.
    pub values: Vec<f32>,
    /// Store as `f16`.
    pub half: bool,
}

/// Writes channels of `size` pixels to `path` as one scan-line ZIP layer.
pub(crate) fn write_planes(
    path: &Path,
    size: FrameSize,
    planes: Vec<PlaneOut<'_>>,
) -> Result<(), DumpError> {
    let channels: SmallChannels = planes
        .into_iter()
        .map(|p| {
            let samples = if p.half {
                FlatSamples::F16(p.values.into_iter().map(Half::from_f32).collect())
            } else {
                FlatSamples::F32(p.values)
            };
            AnyChannel::new(p.name, samples)
        })
        .collect();
    let layer = Layer::new(
        (size.width as usize, size.height as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| DumpError::exr(path, e))
}

/// Writes the pixel buffers of `frame` to `path`.
pub fn write_exr(path: &Path, frame: &Frame) -> Result<(), DumpError> {
    let n = frame.meta.size.pixels() as usize;
    let mut planes = Vec::new();
    let mut add = |name, half, get: &dyn Fn(usize) -> f32| {
        planes.push(PlaneOut {
            name,
            values: (0..n).map(get).collect(),
            half,
        });
    };
    for (c, name) in channel_names(BufferKind::Color).iter().enumerate() {
        add(name, true, &|i| frame.color[i][c].to_f32());
    }
    add("Z", false, &|i| frame.depth[i]);
    for (c, name) in channel_names(BufferKind::Motion).iter().enumerate() {
        add(name, false, &|i| frame.motion[i][c]);
    }
    for extra in &frame.extras {
        let names = channel_names(extra.kind);
        if extra.kind == BufferKind::Mask {
            add(names[0], true, &|i| f32::from(extra.data[i]) / 255.0);
            continue;
        }
        // Normal and albedo are held as RGB(A) f16; write the first 3 channels.
        let stride = extra.kind.canonical_format().channels() as usize;
        for (c, name) in names.iter().enumerate() {
            add(name, true, &|i| {
                let o = (i * stride + c) * 2;
                Half::from_le_bytes([extra.data[o], extra.data[o + 1]]).to_f32()
            });
        }
    }
    write_planes(path, frame.meta.size, planes)
}

/// The channels of one EXR file as `f32` planes, by name.
pub(crate) struct ExrPlanes {
    path: std::path::PathBuf,
    planes: Vec<(String, Vec<f32>)>,
}

impl ExrPlanes {
    /// The plane called `name`, if the file has it.
    pub fn get(&self, name: &str) -> Option<&[f32]> {
        self.planes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p.as_slice())
    }

    /// The plane called `name`, or a [`DumpError::MissingChannel`].
    pub fn require(&self, name: &str) -> Result<&[f32], DumpError> {
        self.get(name).ok_or_else(|| DumpError::MissingChannel {
            path: self.path.clone(),
            channel: name.to_owned(),
        })
    }
}

/// Reads every channel of the first layer of `path` as `f32`. The header is
/// checked first: the layer must be `size`, have at most
/// [`MAX_EXR_CHANNELS`] channels and hold every `required` channel before
/// any pixel is decoded, so a wrong or hostile file costs no
/// allocation of its claimed size.
pub(crate) fn read_planes(
    path: &Path,
    size: FrameSize,
    required: &[&str],
) -> Result<ExrPlanes, DumpError> {
    // Opening first turns a missing file into an I/O "not found" error that
    // readers report as a missing frame.
    std::fs::File::open(path).map_err(|source| DumpError::Io {
        path: path.to_owned(),
        source,
    })?;
    // `exr` is a pure-Rust decoder that returns errors for bad files; the
    // unwind guards here and below are a last line of defence so a decoder
    // bug on a corrupt file becomes an error, never a crash of the server.
    let meta = std::panic::catch_unwind(|| MetaData::read_from_file(path, false))
        .map_err(|_| DumpError::exr_msg(path, PANIC_DETAIL))?
        .map_err(|e| DumpError::exr(path, e))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| DumpError::exr_msg(path, "no layer in file"))?;
    let mismatch = |got: (usize, usize)| DumpError::SizeMismatch {
        path: path.to_owned(),
        expected: size,
        got: FrameSize::new(got.0 as u32, got.1 as u32),
    };
    if header.layer_size.0 != size.width as usize || header.layer_size.1 != size.height as usize {
        return Err(mismatch(header.layer_size.into()));
    }
    if header.deep {
        return Err(DumpError::exr_msg(path, "deep data is not a frame"));
    }
    // The exr crate's B44 decoder overflows on corrupt blocks (found by
    // the `files` fuzz target); no dump writer or importer here writes
    // B44, so it is refused before any block is decoded.
    if matches!(
        header.compression,
        exr::compression::Compression::B44 | exr::compression::Compression::B44A
    ) {
        return Err(DumpError::exr_msg(path, B44_DETAIL));
    }
    let count = header.channels.list.len();
    if count > MAX_EXR_CHANNELS {
        return Err(DumpError::TooManyChannels {
            path: path.to_owned(),
            count,
            max: MAX_EXR_CHANNELS,
        });
    }
    for name in required {
        if !header
            .channels
            .list
            .iter()
            .any(|c| c.name.to_string() == *name)
        {
            return Err(DumpError::MissingChannel {
                path: path.to_owned(),
                channel: (*name).to_owned(),
            });
        }
    }

    let read = std::panic::catch_unwind(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(path)
    })
    .map_err(|_| DumpError::exr_msg(path, PANIC_DETAIL))?
    .map_err(|e| DumpError::exr(path, e))?;
    let layer = read.layer_data;
    if layer.size.0 != size.width as usize || layer.size.1 != size.height as usize {
        return Err(mismatch(layer.size.into()));
    }
    let n = size.pixels() as usize;
    let planes = layer
        .channel_data
        .list
        .into_iter()
        .filter(|c| c.sample_data.len() == n)
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    Ok(ExrPlanes {
        path: path.to_owned(),
        planes,
    })
}

/// Reads the pixels of one frame from `path` into `frame`, whose metadata is
/// already known. The header is checked (size, channels) before any pixel is
/// decoded.
pub fn read_exr(path: &Path, frame: &mut Frame) -> Result<(), DumpError> {
    let size = frame.meta.size;
    let required: Vec<&str> = BufferKind::REQUIRED
        .iter()
        .flat_map(|k| channel_names(*k).iter().copied())
        .collect();
    let planes = read_planes(path, size, &required)?;
    let n = size.pixels() as usize;
    let [r, g, b] = [
        planes.require("R")?,
        planes.require("G")?,
        planes.require("B")?,
    ];
    frame.color = (0..n).map(|i| rgb_pixel(r[i], g[i], b[i])).collect();
    frame.depth = planes.require("Z")?.to_vec();
    frame.motion = zip_motion(planes.require("motion.X")?, planes.require("motion.Y")?);
    frame.extras.clear();
    for kind in [BufferKind::Normal, BufferKind::Albedo, BufferKind::Mask] {
        let names = channel_names(kind);
        let Some(found) = names
            .iter()
            .map(|n| planes.get(n))
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let data = if kind == BufferKind::Mask {
            mask_bytes(found[0])
        } else {
            let stride = kind.canonical_format().channels() as usize;
            let mut data = Vec::with_capacity(n * stride * 2);
            for i in 0..n {
                for c in 0..stride {
                    let v = found.get(c).map_or(1.0, |p| p[i]);
                    data.extend_from_slice(&Half::from_f32(v).to_le_bytes());
                }
            }
            data
        };
        frame.extras.push(ExtraBuffer { kind, data });
    }
    Ok(())
}

/// One colour pixel from linear RGB (alpha is not part of the contract: 1).
pub(crate) fn rgb_pixel(r: f32, g: f32, b: f32) -> [Half; 4] {
    [
        Half::from_f32(r),
        Half::from_f32(g),
        Half::from_f32(b),
        Half::ONE,
    ]
}

/// Motion vectors from their x and y planes.
fn zip_motion(x: &[f32], y: &[f32]) -> Vec<[f32; 2]> {
    x.iter().zip(y).map(|(&x, &y)| [x, y]).collect()
}

/// A mask plane in `[0, 1]` as the 8-bit values the mask buffer holds.
pub(crate) fn mask_bytes(plane: &[f32]) -> Vec<u8> {
    plane
        .iter()
        .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An EXR whose header lists a thousand channels (each a frame-sized
    /// plane the decoder would allocate) is refused from the header with a
    /// typed error (issue 18 §4), whatever the caller requires.
    #[test]
    fn a_channel_bomb_is_refused_from_its_header() -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("bomb.exr");
        let size = FrameSize::new(33, 19);
        let names: Vec<String> = (0..1000).map(|i| format!("c{i:04}")).collect();
        let planes = names
            .iter()
            .map(|name| PlaneOut {
                name,
                values: vec![0.0; size.pixels() as usize],
                half: true,
            })
            .collect();
        write_planes(&path, size, planes)?;
        for required in [&[][..], &["R", "G", "B"][..]] {
            match read_planes(&path, size, required) {
                Err(DumpError::TooManyChannels { count, max, .. }) => {
                    assert_eq!((count, max), (1000, MAX_EXR_CHANNELS));
                }
                Err(e) => panic!("expected TooManyChannels, got {e}"),
                Ok(_) => panic!("expected TooManyChannels, got planes"),
            }
        }
        Ok(())
    }

    /// A B44-compressed file (whose decoder the `files` fuzz target made
    /// overflow on a corrupt block) is refused from its header.
    #[test]
    fn b44_is_refused_from_the_header() -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let size = FrameSize::new(16, 8);
        for (name, compression) in [
            ("b44.exr", exr::compression::Compression::B44),
            ("b44a.exr", exr::compression::Compression::B44A),
        ] {
            let path = dir.path().join(name);
            let channels: SmallChannels = ["B", "G", "R"]
                .into_iter()
                .map(|c| AnyChannel::new(c, FlatSamples::F16(vec![Half::ONE; 128])))
                .collect();
            let layer = Layer::new(
                (16, 8),
                LayerAttributes::default(),
                Encoding {
                    compression,
                    ..Encoding::SMALL_LOSSLESS
                },
                AnyChannels::sort(channels),
            );
            Image::from_layer(layer).write().to_file(&path)?;
            match read_planes(&path, size, &["R", "G", "B"]) {
                Err(DumpError::Exr { detail, .. }) => assert_eq!(detail, B44_DETAIL),
                Err(e) => panic!("expected the B44 refusal, got {e}"),
                Ok(_) => panic!("expected the B44 refusal, got planes"),
            }
        }
        Ok(())
    }
}
