//! Four pixels at a time: the lanes of glam's `Vec4` (SSE2 on x86-64,
//! plain arrays elsewhere), for the CPU passes' hottest loops (issue 15:
//! the per-pixel camera maths is most of their time).
//!
//! Every function here is its scalar counterpart in `camera.rs`, operation
//! by operation and in the same order. Each of those operations is
//! correctly rounded in a lane as in a scalar (no fused multiply-add is
//! formed), so a lane holds the scalar result's exact bits: a pass that
//! takes four pixels here and the rest one by one is still the same
//! reference, bit for bit, for any grouping and thread count. Each user
//! tests that against its one-by-one path.

use glam::{BVec4A, Mat4, Vec2, Vec4};

use crate::passes::common::camera::{PassCamera, cell_inside};

/// Pixels at a time.
pub const LANES: usize = 4;

/// Four points or directions, one coordinate a `Vec4` of lanes.
#[derive(Clone, Copy, Debug)]
pub struct Lanes3 {
    /// The `x` of each.
    pub x: Vec4,
    /// The `y` of each.
    pub y: Vec4,
    /// The `z` of each.
    pub z: Vec4,
}

impl Lanes3 {
    /// One vector (the first three of `v`) in every lane.
    #[inline]
    pub fn splat(v: [f32; 4]) -> Self {
        Self {
            x: Vec4::splat(v[0]),
            y: Vec4::splat(v[1]),
            z: Vec4::splat(v[2]),
        }
    }

    /// `Vec3::dot(self, o)` in each lane, in its order.
    #[inline]
    pub fn dot(self, o: Self) -> Vec4 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// `a` in the lanes of `mask`, `b` in the others.
    #[inline]
    pub fn select(mask: BVec4A, a: Self, b: Self) -> Self {
        Self {
            x: Vec4::select(mask, a.x, b.x),
            y: Vec4::select(mask, a.y, b.y),
            z: Vec4::select(mask, a.z, b.z),
        }
    }

    /// Four positions' coordinates, and their `w`s.
    #[inline]
    pub fn from_positions(q: &[[f32; 4]; LANES]) -> (Self, Vec4) {
        let t = Mat4::from_cols_array_2d(q).transpose();
        let (x, y, z) = (t.x_axis, t.y_axis, t.z_axis);
        (Self { x, y, z }, t.w_axis)
    }

    /// The four as positions with `w`s `w`.
    #[inline]
    pub fn positions(self, w: Vec4) -> [[f32; 4]; LANES] {
        Mat4::from_cols(self.x, self.y, self.z, w)
            .transpose()
            .to_cols_array_2d()
    }
}

impl std::ops::Add for Lanes3 {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl std::ops::Sub for Lanes3 {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl std::ops::Mul<Vec4> for Lanes3 {
    type Output = Self;
    #[inline]
    fn mul(self, s: Vec4) -> Self {
        Self {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

/// [`PassCamera::project`] of four positions.
#[derive(Clone, Copy, Debug)]
pub struct Projected4 {
    /// The lanes it projects (where `project` gives `Some`).
    pub valid: BVec4A,
    /// Image `x` of each.
    pub x: Vec4,
    /// Image `y` of each.
    pub y: Vec4,
    /// View depth of each (`+inf` for a direction).
    pub depth: Vec4,
}

impl Projected4 {
    /// Lane `l`'s image position.
    #[inline]
    pub fn pixel(&self, l: usize) -> Vec2 {
        Vec2::new(self.x[l], self.y[l])
    }
}

/// [`PassCamera::project`] of the four positions `p` with `w`s `w`,
/// operation by operation: a point (`w > 0.5`) is taken relative to the
/// eye, a direction as it is; a lane it refuses (nothing, behind the
/// camera, NaN, absurdly far) is not `valid`.
#[inline]
pub fn project4(cam: &PassCamera, p: Lanes3, w: Vec4) -> Projected4 {
    let point = w.cmpgt(Vec4::splat(0.5));
    let rel = Lanes3::select(point, p - Lanes3::splat(cam.eye), p);
    let column = Lanes3::splat;
    let (vx, vy, vz) = (
        column(cam.col0).dot(rel),
        column(cam.col1).dot(rel),
        column(cam.col2).dot(rel),
    );
    let z = -vz;
    let inv = Vec4::ONE / z;
    let x = vx * inv * cam.proj[2] + cam.size[2];
    let y = vy * inv * cam.proj[3] + cam.size[3];
    let far = Vec4::splat(1e30);
    let valid = !w.cmplt(Vec4::ZERO) & z.cmpgt(Vec4::ZERO);
    Projected4 {
        valid: valid & x.abs().cmplt(far) & y.abs().cmplt(far),
        x,
        y,
        depth: Vec4::select(point, z, Vec4::INFINITY),
    }
}

/// [`cell`](crate::passes::common::camera::cell) of each lane of `r` that
/// projects, on a `w × h` grid of `scale`-pixel cells: the division in
/// lanes, then [`cells`].
#[inline]
pub fn cells4(r: &Projected4, w: u32, h: u32, scale: f32) -> [Option<u32>; LANES] {
    cells(r.x / scale, r.y / scale, r.valid, w, h)
}

/// [`cell`](crate::passes::common::camera::cell) at scale 1 of the
/// positions `(x, y)` in the lanes of `valid` (`None` in the others): the
/// bounds tested in lanes, the index made one by one.
#[inline]
pub fn cells(x: Vec4, y: Vec4, valid: BVec4A, w: u32, h: u32) -> [Option<u32>; LANES] {
    // `cell`'s test, lane by lane (NaN fails every comparison).
    let inside = valid
        & x.cmpge(Vec4::ZERO)
        & y.cmpge(Vec4::ZERO)
        & x.cmplt(Vec4::splat(w as f32))
        & y.cmplt(Vec4::splat(h as f32));
    let inside = inside.bitmask();
    std::array::from_fn(|l| {
        // SAFETY: the lane passed `cell`'s test above.
        (inside & (1 << l) != 0).then(|| unsafe { cell_inside(Vec2::new(x[l], y[l]), w) })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::passes::common::camera::cell;

    /// `cells` is `cell` lane by lane, for positions on, beside and off
    /// the grid, not numbers and infinite, in lanes valid or not.
    #[test]
    fn cells_are_cell_lane_by_lane() {
        let values = [
            0.0,
            -0.0,
            -1e-30,
            0.5,
            6.999_999_5,
            7.0,
            2.999_999_8,
            3.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -3.5,
            1e30,
        ];
        let mut found = [0usize; 2];
        for i in 0..values.len().pow(2) * 4 {
            let v = |j: usize| values[(i * 5 + j * 7 + i / 9) % values.len()];
            let (x, y) = ([v(0), v(1), v(2), v(3)], [v(4), v(5), v(6), v(7)]);
            let valid = BVec4A::new(i % 3 != 0, true, i % 5 != 1, true);
            let lanes = cells(Vec4::from(x), Vec4::from(y), valid, 7, 3);
            for l in 0..LANES {
                let one = cell(Vec2::new(x[l], y[l]), 7, 3, 1.0);
                let valid = valid.bitmask() & (1 << l) != 0;
                assert_eq!(lanes[l], one.filter(|_| valid), "{} {}", x[l], y[l]);
                found[usize::from(lanes[l].is_some())] += 1;
            }
        }
        assert!(found.iter().all(|&n| n > 50), "{found:?}");
    }

    /// Lanes agree with the scalar camera bit for bit, over points,
    /// directions, nothing, NaN, points behind the camera and far off.
    #[test]
    fn lanes_are_the_scalar_camera() {
        let camera = crate::testutil::looking(
            [3.0, 1.0, 2.0],
            [0.0, 0.5, -4.0],
            (1280, 720),
            [2.5, 1.0, 2.0],
        );
        let specials = [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-30, 1e30];
        let mut seen = [0usize; 3];
        for i in 0..4000usize {
            // Points and directions through pixels around the image
            // (some off it, some behind the camera), nothing, specials.
            let v = |j: usize| ((i * 7 + j * 13) as f32 * 0.618_034).fract();
            let mut q = [[0.0f32; 4]; LANES];
            for (l, q) in q.iter_mut().enumerate() {
                let pixel = Vec2::new(v(l) * 1600.0 - 160.0, v(l + 4) * 900.0 - 90.0);
                let depth = [v(l + 8) * 40.0 - 2.0, f32::INFINITY][(i + l) % 5 / 4];
                *q = camera.unproject(pixel, depth);
                if (i + l) % 7 == 0 {
                    q[3] = -1.0;
                }
                if (i + l) % 37 == 0 {
                    q[(i / 37) % 4] = specials[(i / 148 + l) % specials.len()];
                }
            }
            let (p, w) = Lanes3::from_positions(&q);
            assert_eq!(
                p.positions(w).map(|q| q.map(f32::to_bits)),
                q.map(|q| q.map(f32::to_bits))
            );
            let r = project4(&camera, p, w);
            let cells = cells4(&r, 1280 / 4, 720 / 4, 4.0);
            for l in 0..LANES {
                let one = camera.project(q[l]);
                assert_eq!(
                    r.valid.bitmask() & (1 << l) != 0,
                    one.is_some(),
                    "{:?}",
                    q[l]
                );
                if let Some(one) = one {
                    assert_eq!(
                        r.pixel(l).to_array().map(f32::to_bits),
                        one.pixel.to_array().map(f32::to_bits)
                    );
                    assert_eq!(r.depth[l].to_bits(), one.depth.to_bits());
                    assert_eq!(cells[l], cell(one.pixel, 320, 180, 4.0));
                    seen[usize::from(cells[l].is_some())] += 1;
                } else {
                    assert_eq!(cells[l], None);
                    seen[2] += 1;
                }
            }
        }
        // Every outcome was met often.
        assert!(seen.iter().all(|&n| n > 500), "{seen:?}");
    }
}
