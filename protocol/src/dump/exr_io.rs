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

/// Detail of the error reported when the `exr` decoder panics.
pub const PANIC_DETAIL: &str = "decoder panicked on this file";

/// The channel list type `exr` wants.
type SmallChannels = SmallVec<[AnyChannel<FlatSamples>; 4]>;

/// Writes the pixel buffers of `frame` to `path`.
pub fn write_exr(path: &Path, frame: &Frame) -> Result<(), DumpError> {
    let n = frame.meta.size.pixels() as usize;
    let mut channels = SmallChannels::new();
    let half_plane = |get: &dyn Fn(usize) -> Half| FlatSamples::F16((0..n).map(get).collect());
    let f32_plane = |get: &dyn Fn(usize) -> f32| FlatSamples::F32((0..n).map(get).collect());
    for (c, name) in channel_names(BufferKind::Color).iter().enumerate() {
        channels.push(AnyChannel::new(*name, half_plane(&|i| frame.color[i][c])));
    }
    channels.push(AnyChannel::new("Z", f32_plane(&|i| frame.depth[i])));
    for (c, name) in channel_names(BufferKind::Motion).iter().enumerate() {
        channels.push(AnyChannel::new(*name, f32_plane(&|i| frame.motion[i][c])));
    }
    for extra in &frame.extras {
        let names = channel_names(extra.kind);
        if extra.kind == BufferKind::Mask {
            let plane = half_plane(&|i| Half::from_f32(f32::from(extra.data[i]) / 255.0));
            channels.push(AnyChannel::new(names[0], plane));
            continue;
        }
        // Normal and albedo are held as RGB(A) f16; write the first 3 channels.
        let stride = extra.kind.canonical_format().channels() as usize;
        for (c, name) in names.iter().enumerate() {
            let plane = half_plane(&|i| {
                let o = (i * stride + c) * 2;
                Half::from_le_bytes([extra.data[o], extra.data[o + 1]])
            });
            channels.push(AnyChannel::new(*name, plane));
        }
    }
    let size = (
        frame.meta.size.width as usize,
        frame.meta.size.height as usize,
    );
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| DumpError::exr(path, e))
}

/// Reads the pixels of one frame from `path` into `frame`, whose metadata is
/// already known. The header is checked (size, channels) before any pixel is
/// decoded.
pub fn read_exr(path: &Path, frame: &mut Frame) -> Result<(), DumpError> {
    let size = frame.meta.size;
    // Opening first turns a missing file into an I/O "not found" error that
    // the reader reports as a missing frame.
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
    let got = FrameSize::new(header.layer_size.0 as u32, header.layer_size.1 as u32);
    if header.layer_size.0 != size.width as usize || header.layer_size.1 != size.height as usize {
        return Err(DumpError::SizeMismatch {
            path: path.to_owned(),
            expected: size,
            got,
        });
    }
    if header.deep {
        return Err(DumpError::exr_msg(path, "deep data is not a frame"));
    }
    let has = |name: &str| {
        header
            .channels
            .list
            .iter()
            .any(|c| c.name.to_string() == name)
    };
    for kind in BufferKind::REQUIRED {
        for name in channel_names(kind) {
            if !has(name) {
                return Err(DumpError::MissingChannel {
                    path: path.to_owned(),
                    channel: (*name).to_owned(),
                });
            }
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
    let layer = &read.layer_data;
    if layer.size.0 != size.width as usize || layer.size.1 != size.height as usize {
        return Err(DumpError::SizeMismatch {
            path: path.to_owned(),
            expected: size,
            got: FrameSize::new(layer.size.0 as u32, layer.size.1 as u32),
        });
    }
    let n = size.pixels() as usize;
    let find = |name: &str| -> Option<&FlatSamples> {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .map(|c| &c.sample_data)
            .filter(|s| s.len() == n)
    };
    let plane = |name: &str| -> Result<Vec<f32>, DumpError> {
        find(name)
            .map(|s| s.values_as_f32().collect())
            .ok_or_else(|| DumpError::MissingChannel {
                path: path.to_owned(),
                channel: name.to_owned(),
            })
    };
    let [r, g, b] = [plane("R")?, plane("G")?, plane("B")?];
    frame.color = (0..n)
        .map(|i| {
            [
                Half::from_f32(r[i]),
                Half::from_f32(g[i]),
                Half::from_f32(b[i]),
                Half::ONE,
            ]
        })
        .collect();
    frame.depth = plane("Z")?;
    let [mx, my] = [plane("motion.X")?, plane("motion.Y")?];
    frame.motion = mx.into_iter().zip(my).map(|(x, y)| [x, y]).collect();
    frame.extras.clear();
    for kind in [BufferKind::Normal, BufferKind::Albedo, BufferKind::Mask] {
        let names = channel_names(kind);
        if !names.iter().all(|n| find(n).is_some()) {
            continue;
        }
        let planes = names
            .iter()
            .map(|n| plane(n))
            .collect::<Result<Vec<_>, _>>()?;
        let data = if kind == BufferKind::Mask {
            planes[0]
                .iter()
                .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect()
        } else {
            let stride = kind.canonical_format().channels() as usize;
            let mut data = Vec::with_capacity(n * stride * 2);
            for i in 0..n {
                for c in 0..stride {
                    let v = planes.get(c).map_or(1.0, |p| p[i]);
                    data.extend_from_slice(&Half::from_f32(v).to_le_bytes());
                }
            }
            data
        };
        frame.extras.push(ExtraBuffer { kind, data });
    }
    Ok(())
}
