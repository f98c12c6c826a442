//! ꟻLIP heat maps: for a few frames, the ground truth beside each method's
//! output (top row) and each method's ꟻLIP error map in the magma colour
//! map (bottom row), as one PNG.

use std::path::Path;

use anyhow::Context;
use protocol::display::DisplayImage;

/// One method's output at a heat-map frame.
pub struct Capture {
    /// The variant's label.
    pub label: String,
    /// Its display-encoded output.
    pub test: DisplayImage,
    /// The ground truth it was compared with.
    pub truth: DisplayImage,
    /// ꟻLIP's error map.
    pub flip: nv_flip::FlipImageFloat,
    /// Its mean.
    pub flip_mean: f64,
}

/// Writes the heat map of `scene` at sequence frame `frame` under
/// `out/heatmaps/` and returns its path relative to `out`.
pub fn write(out: &Path, scene: &str, frame: u64, captures: &[Capture]) -> anyhow::Result<String> {
    let first = captures.first().context("no capture")?;
    let (w, h) = (first.truth.width, first.truth.height);
    let cols = captures.len() as u32 + 1;
    let mut img = image::RgbImage::from_pixel(w * cols, 2 * h, image::Rgb([24, 24, 24]));
    let mut blit = |col: u32, row: u32, rgb: &[u8]| {
        for (i, p) in rgb.chunks_exact(3).enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            if y < h {
                img.put_pixel(col * w + x, row * h + y, image::Rgb([p[0], p[1], p[2]]));
            }
        }
    };
    blit(0, 0, &first.truth.to_rgb8());
    let lut = nv_flip::magma_lut();
    for (c, cap) in captures.iter().enumerate() {
        let col = c as u32 + 1;
        blit(col, 0, &cap.test.to_rgb8());
        blit(col, 1, &cap.flip.apply_color_lut(&lut).to_vec());
        tracing::debug!(
            "{scene} frame {frame}: {} ꟻLIP {:.4}",
            cap.label,
            cap.flip_mean
        );
    }
    let dir = out.join("heatmaps");
    std::fs::create_dir_all(&dir)?;
    let name = format!("{}-{frame:05}.png", super::report::plot_name(scene));
    img.save(dir.join(&name))
        .with_context(|| format!("writing {name}"))?;
    Ok(format!("heatmaps/{name}"))
}
