//! `client eval --save-frames DIR` (issue 16 §10): every scored generated
//! frame on disk, so any other tool can judge or view it. Per scene and
//! variant, `DIR/<scene>/<variant>/NNNNNN.{exr,json,png}`, named by the
//! index of the rendered (ground-truth) frame it stands for:
//!
//! * `.exr`: colour (half RGB), depth `Z` and `motion.X/Y` (float), the
//!   channels of a dump frame (`protocol::dump`), readable by
//!   [`protocol::dump::read_exr`] and any OpenEXR viewer;
//! * `.json`: the generated frame's metadata (camera, α's time, size);
//! * `.png`: the display-encoded colour that was scored.
//!
//! The first backend's output is saved (the one quality is scored on).

use std::path::{Path, PathBuf};

use anyhow::Context;
use protocol::Frame;
use protocol::display::DisplayImage;

use super::report::plot_name;

/// Where one variant's frames of one scene go.
pub fn dir(root: &Path, scene: &str, variant: &str) -> PathBuf {
    root.join(plot_name(scene)).join(plot_name(variant))
}

/// The three files of the generated frame standing for truth frame `index`.
pub fn paths(dir: &Path, index: u64) -> [PathBuf; 3] {
    ["exr", "json", "png"].map(|ext| dir.join(format!("{index:06}.{ext}")))
}

/// Writes `frame` (and `encoded`, its display-encoded colour) as the
/// generated frame standing for truth frame `index`.
pub fn write(dir: &Path, index: u64, frame: &Frame, encoded: &DisplayImage) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let [exr, json, png] = paths(dir, index);
    protocol::dump::write_exr(&exr, frame)?;
    let meta = serde_json::to_vec_pretty(&frame.meta)?;
    std::fs::write(&json, meta).with_context(|| format!("writing {}", json.display()))?;
    let (w, h) = (encoded.width, encoded.height);
    image::RgbImage::from_raw(w, h, encoded.to_rgb8())
        .context("display image size")?
        .save(&png)
        .with_context(|| format!("writing {}", png.display()))?;
    Ok(())
}
