//! The camera model every pass shares, in `f32` and camera-relative
//! coordinates (DESIGN §3, precision). Mirrors `gpu/common.wgsl` operation
//! by operation so the CPU reference and the shaders agree to rounding.
//!
//! Per-pixel positions are stored relative to a *reference origin*: the
//! centre of the camera of the current rendered frame. A camera is described
//! by its rotation columns and its centre relative to that origin; the
//! difference of two world positions is taken in `f64` before it is rounded,
//! so a world at 1e7 keeps its precision near the camera.
//!
//! A position is a `[f32; 4]` whose `w` says what it is: [`W_POINT`] a point,
//! [`W_DIRECTION`] a unit direction (sky, `+inf` depth, moved only by
//! rotation), [`W_INVALID`] nothing.

use glam::{DVec3, Vec2, Vec3, Vec4};
use protocol::{Camera, FrameSize};

/// `w` of a finite position.
pub const W_POINT: f32 = 1.0;
/// `w` of a direction (a point at infinity).
pub const W_DIRECTION: f32 = 0.0;
/// `w` of an empty slot.
pub const W_INVALID: f32 = -1.0;

/// A camera as seen by a pass; the layout of WGSL's `Cam`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PassCamera {
    /// World-from-view rotation columns (w unused).
    pub col0: [f32; 4],
    /// Second column.
    pub col1: [f32; 4],
    /// Third column (the camera's +Z, i.e. minus the view direction).
    pub col2: [f32; 4],
    /// Camera centre relative to the reference origin.
    pub eye: [f32; 4],
    /// `tan(fov_y/2)·aspect`, `tan(fov_y/2)`, and the projection's pixel
    /// scales `a_x = width / (proj_x · window_w)`, `a_y = −height / (proj_y ·
    /// window_h)`: a view-space point `v` at depth `z` lands at pixel
    /// `(v_x / z · a_x + b_x, v_y / z · a_y + b_y)`, one division per
    /// projection.
    pub proj: [f32; 4],
    /// The unprojection's ray map, folded from the window (`u0`, `v1`,
    /// width, height in base NDC), the image size and `proj`: pixel `p`
    /// looks along the view-space ray `(r_0 + p_x·r_1, r_2 + p_y·r_3, −1)`,
    /// no division per pixel.
    pub ray: [f32; 4],
    /// Image width and height in pixels, and the projection's pixel
    /// offsets `b_x = −u0 · width / window_w`, `b_y = v1 · height /
    /// window_h` (see `proj`).
    pub size: [f32; 4],
}

/// A projected point (see [`PassCamera::project`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proj {
    /// Continuous pixel position.
    pub pixel: Vec2,
    /// Linear view depth, `+inf` for directions.
    pub depth: f32,
}

impl PassCamera {
    /// `camera` seen from the reference origin `origin` (world space), for
    /// an image of `size` pixels.
    pub fn new(camera: &Camera, size: FrameSize, origin: DVec3) -> Self {
        let r = camera.pose.rotation.normalize();
        let col = |v: DVec3| {
            let v = (r * v).as_vec3();
            [v.x, v.y, v.z, 0.0]
        };
        let eye = (camera.pose.position - origin).as_vec3();
        let t = camera.projection.tan_half_fov();
        let w = &camera.window;
        let (px, py) = (t * camera.projection.aspect, t);
        let (sw, sh) = (f64::from(size.width), f64::from(size.height));
        // The image-from-view map, folded in f64 once per camera.
        let (ax, ay) = (sw / (px * w.width()), -sh / (py * w.height()));
        let (bx, by) = (-w.u0 * sw / w.width(), w.v1 * sh / w.height());
        // The view-from-image map (rays through pixels), folded the same way.
        let (rx, ry) = (px * w.width() / sw, -py * w.height() / sh);
        Self {
            col0: col(DVec3::X),
            col1: col(DVec3::Y),
            col2: col(DVec3::Z),
            eye: [eye.x, eye.y, eye.z, 0.0],
            proj: [px as f32, py as f32, ax as f32, ay as f32],
            ray: [(w.u0 * px) as f32, rx as f32, (w.v1 * py) as f32, ry as f32],
            size: [size.width as f32, size.height as f32, bx as f32, by as f32],
        }
    }

    #[inline]
    fn c(&self, i: usize) -> Vec3 {
        let c = [self.col0, self.col1, self.col2][i];
        Vec3::new(c[0], c[1], c[2])
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.size[0] as u32
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.size[1] as u32
    }

    /// The position (or direction for `depth = +inf`) seen through the
    /// continuous pixel position `px` at linear depth `depth` (> 0).
    #[inline]
    pub fn unproject(&self, px: Vec2, depth: f32) -> [f32; 4] {
        let ray = Vec3::new(
            self.ray[0] + px.x * self.ray[1],
            self.ray[2] + px.y * self.ray[3],
            -1.0,
        );
        let world = self.c(0) * ray.x + self.c(1) * ray.y + self.c(2) * ray.z;
        if depth == f32::INFINITY {
            let d = world.normalize();
            return [d.x, d.y, d.z, W_DIRECTION];
        }
        let p = Vec3::new(self.eye[0], self.eye[1], self.eye[2]) + world * depth;
        [p.x, p.y, p.z, W_POINT]
    }

    /// Projects a position or direction; `None` behind the camera, for
    /// invalid input, or for non-finite / absurdly far image positions.
    /// One division: the image map is folded into `proj` and `size`.
    #[inline]
    pub fn project(&self, p: [f32; 4]) -> Option<Proj> {
        if p[3] < 0.0 {
            return None;
        }
        let mut rel = Vec3::new(p[0], p[1], p[2]);
        if p[3] > 0.5 {
            rel -= Vec3::new(self.eye[0], self.eye[1], self.eye[2]);
        }
        let v = Vec3::new(self.c(0).dot(rel), self.c(1).dot(rel), self.c(2).dot(rel));
        let z = -v.z;
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        let inv = 1.0 / z;
        let px = v.x * inv * self.proj[2] + self.size[2];
        let py = v.y * inv * self.proj[3] + self.size[3];
        let ok = px.abs() < 1e30 && py.abs() < 1e30;
        ok.then(|| Proj {
            pixel: Vec2::new(px, py),
            depth: if p[3] > 0.5 { z } else { f32::INFINITY },
        })
    }

    /// Linear view depth of a stored position (`+inf` for directions, NaN
    /// for invalid slots, which every comparison then rejects).
    #[inline]
    pub fn depth_of(&self, p: [f32; 4]) -> f32 {
        if p[3] < 0.0 {
            return f32::NAN;
        }
        if p[3] < 0.5 {
            return f32::INFINITY;
        }
        let rel = Vec3::new(p[0], p[1], p[2]) - Vec3::new(self.eye[0], self.eye[1], self.eye[2]);
        -self.c(2).dot(rel)
    }
}

/// Centre of pixel `i` of a `width`-wide image.
#[inline]
pub fn pixel_center(i: usize, width: u32) -> Vec2 {
    // In 32 bits (pixel indices are `u32` on the GPU too): a 64-bit
    // division costs up to twice as much, per pixel of several passes.
    let i = i as u32;
    Vec2::new((i % width) as f32 + 0.5, (i / width) as f32 + 0.5)
}

/// The pixels of a `width`-wide image by index, for a loop that asks
/// [`pixel_center`] of arbitrary indices (a warp's winners): the division
/// by the width as two multiplications (Lemire, Kaser and Kurz, "Faster
/// remainder by direct computation", 2019), exact for every `u32` index
/// and width. A 32-bit `div` costs some ten cycles and stalls what waits
/// on it; the warp asked two per pixel.
#[derive(Clone, Copy, Debug)]
pub struct Columns {
    width: u32,
    /// `⌈2⁶⁴ / width⌉` (0 for a width of 1, taken apart).
    magic: u64,
}

impl Columns {
    /// The columns of a `width`-wide image (at least 1).
    pub fn new(width: u32) -> Self {
        let width = width.max(1);
        let magic = (u64::MAX / u64::from(width)).wrapping_add(1);
        Self { width, magic }
    }

    /// `(i % width, i / width)`.
    #[inline]
    pub fn split(&self, i: u32) -> (u32, u32) {
        if self.width == 1 {
            return (0, i);
        }
        let low = self.magic.wrapping_mul(u64::from(i));
        let x = (u128::from(low) * u128::from(self.width)) >> 64;
        let y = (u128::from(self.magic) * u128::from(i)) >> 64;
        (x as u32, y as u32)
    }

    /// [`pixel_center`] of pixel `i`.
    #[inline]
    pub fn center(&self, i: usize) -> Vec2 {
        let (x, y) = self.split(i as u32);
        Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
    }
}

/// Linear index of the cell containing `px` in a `w`×`h` grid whose cells are
/// `scale` pixels wide; `None` outside. WGSL `cell`.
#[inline]
pub fn cell(px: Vec2, w: u32, h: u32, scale: f32) -> Option<u32> {
    let q = px / scale;
    if !(q.x >= 0.0 && q.y >= 0.0 && q.x < w as f32 && q.y < h as f32) {
        return None;
    }
    // SAFETY: checked just above.
    Some(unsafe { cell_inside(q, w) })
}

/// [`cell`] at scale 1 of a position `q` known to be on the grid.
///
/// Its casts are unchecked: they leave out the saturation `as` adds for
/// values outside a `u32`'s range. This is asked per pixel or fragment by
/// the history, the background, the warp's splat and shading correction,
/// and the saturation was 3–4 % of a generated frame's time at 720p.
///
/// # Safety
///
/// `q.x` and `q.y` are numbers in `0 .. w as f32` and `0 .. h as f32` for
/// the grid's height `h` (`w as f32` is at most 2³², so they fit a `u32`).
#[inline]
pub unsafe fn cell_inside(q: Vec2, w: u32) -> u32 {
    // SAFETY: the caller's promise.
    let (x, y) = unsafe { (q.x.to_int_unchecked::<u32>(), q.y.to_int_unchecked::<u32>()) };
    y * w + x
}

/// Moves a stored position from one reference origin to another: `shift` is
/// the old origin relative to the new one. Directions do not move.
#[inline]
pub fn rebase(p: [f32; 4], shift: Vec3) -> [f32; 4] {
    if p[3] > 0.5 {
        [p[0] + shift.x, p[1] + shift.y, p[2] + shift.z, p[3]]
    } else {
        p
    }
}

/// `[f32; 4]` as a glam vector.
pub fn v4(p: [f32; 4]) -> Vec4 {
    Vec4::from_array(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cell` is the cell a plain floor finds, and `None` for every
    /// position off the grid or not a number: its unchecked casts only
    /// ever see values in range.
    #[test]
    fn cells_are_the_floors_and_nothing_off_the_grid() {
        let reference = |px: Vec2, w: u32, h: u32, scale: f32| {
            let (x, y) = ((px.x / scale).floor(), (px.y / scale).floor());
            let inside = x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32;
            inside.then(|| y as u32 * w + x as u32)
        };
        let specials = [
            0.0,
            -0.0,
            -1e-30,
            1e-30,
            0.5,
            0.999_999_94,
            1.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1.0,
            4_294_967_040.0,
            4_294_967_296.0,
            1e30,
        ];
        let mut found = [0usize; 2];
        for (w, h) in [(1, 1), (7, 3), (1280, 720), (u32::MAX, 1), (1, u32::MAX)] {
            let edges = |n: u32| [n as f32, n as f32 - 0.5, (n as f32).next_down()];
            let values: Vec<f32> = specials
                .iter()
                .copied()
                .chain(edges(w))
                .chain(edges(h))
                .collect();
            for &x in &values {
                for &y in &values {
                    for scale in [1.0, 4.0] {
                        let p = Vec2::new(x, y);
                        let c = cell(p, w, h, scale);
                        assert_eq!(c, reference(p, w, h, scale), "{p} in {w}x{h} at {scale}");
                        found[usize::from(c.is_some())] += 1;
                    }
                }
            }
        }
        assert!(found.iter().all(|&n| n > 50), "{found:?}");
    }

    /// The multiplications are the division, for every width up to a few
    /// thousand and the extremes, at indices up to `u32::MAX` (the edges
    /// of each row, every index of small images, and a scramble).
    #[test]
    fn columns_divide_exactly() {
        let widths = (1..=4100).chain([65_535, 65_536, 1 << 20, u32::MAX - 1, u32::MAX]);
        for w in widths {
            let c = Columns::new(w);
            let check = |i: u32| assert_eq!(c.split(i), (i % w, i / w), "{i} / {w}");
            let ends = [0, 1, w - 1, w, w.wrapping_add(1), u32::MAX - 1, u32::MAX];
            ends.into_iter().for_each(check);
            for k in [2u32, 3, 1000, 65_537] {
                let row = w.saturating_mul(k);
                [row.saturating_sub(1), row, row.saturating_add(1)]
                    .into_iter()
                    .for_each(check);
            }
            let mut v = u64::from(w).wrapping_mul(0x9e37_79b9_7f4a_7c15);
            for _ in 0..200 {
                v ^= v >> 31;
                v = v.wrapping_mul(0xbf58_476d_1ce4_e5b9);
                check((v >> 32) as u32);
            }
        }
        for w in [1, 7, 1280, 1920] {
            let c = Columns::new(w);
            for i in 0..(4_000_000 / w).max(10) * w {
                assert_eq!(c.center(i as usize), pixel_center(i as usize, w));
            }
        }
    }
}
