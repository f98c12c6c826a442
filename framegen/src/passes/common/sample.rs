//! Reading an image at a continuous pixel position, clamped at the edges:
//! the CPU side of the gathers in `window.wgsl` and `interp/resolve.wgsl`.

use glam::{Vec2, Vec4};

/// Index of the pixel containing `p`, clamped into the `w × h` image.
pub fn clamp_index(p: Vec2, w: u32, h: u32) -> usize {
    let x = (p.x.max(0.0) as u32).min(w - 1);
    let y = (p.y.max(0.0) as u32).min(h - 1);
    (y * w + x) as usize
}

/// Whether continuous position `p` lies inside a `w × h` image.
#[inline]
pub fn inside(p: Vec2, (w, h): (u32, u32)) -> bool {
    p.x >= 0.0 && p.y >= 0.0 && p.x < w as f32 && p.y < h as f32
}

/// Bilinear sample of `image` at continuous position `p` (pixel centres at
/// `i + 0.5`), edges clamped.
pub fn bilinear(image: &[[f32; 4]], w: u32, h: u32, p: Vec2) -> Vec4 {
    let q = p - 0.5;
    let base = q.floor();
    let f = q - base;
    let at =
        |dx: f32, dy: f32| Vec4::from_array(image[clamp_index(base + Vec2::new(dx, dy), w, h)]);
    (at(0.0, 0.0) * (1.0 - f.x) + at(1.0, 0.0) * f.x) * (1.0 - f.y)
        + (at(0.0, 1.0) * (1.0 - f.x) + at(1.0, 1.0) * f.x) * f.y
}
