//! Motion as a residual over the camera, [`super::Codec::MotionResidual`]
//! (issue 19 §2, DESIGN §7).
//!
//! A static surface's motion vector is a function of its depth and the two
//! camera poses (DESIGN §3: `prev = cur + mv`), both of which the client
//! has. The codec subtracts that camera-induced motion and sends what is
//! left: zero on static pixels, the object's own motion on dynamic ones.
//!
//! **Exact reconstruction.** The prediction is a fixed sequence of `f64`
//! additions, multiplications and divisions (correctly rounded in IEEE 754,
//! so the same on every machine) over 20 coefficients the server derives
//! from the two cameras and sends in the payload; the client never
//! evaluates a trigonometric function for it. Both sides predict from the
//! depth the client decodes (the server runs the depth codec's round trip
//! first), so the prediction agrees bit for bit. The residual is quantised
//! to a step of [`QUANTUM`] pixels: every vector comes back within
//! `QUANTUM / 2` (0.0039 px) of the original, static or not, plus the
//! rounding of the buffer's format (f32: none that matters; f16: half a
//! unit in its last place).
//!
//! The residual's two planes go through [`super::planar`], whose predictor
//! makes a rigidly translating object cost about as little as a static one.
//! Non-finite vectors (invalid input) come back as the camera's prediction.
//!
//! Payload: tag, quantum (f64), width (u32), the 20 coefficients (f64),
//! then the packed planes (x, then y).

use glam::{DMat3, DVec3};

use crate::FrameMeta;

use super::{CodecError, depth::check_width, planar};

/// Step of the quantised residual, pixels.
pub const QUANTUM: f64 = 1.0 / 128.0;

const TAG: u8 = 0xA1;
const COEFFICIENTS: usize = 20;
/// Tag, quantum, width, coefficients.
pub(crate) const HEADER: usize = 1 + 8 + 4 + 8 * COEFFICIENTS;

/// Largest residual, in quanta, a pixel may carry (some 8 million pixels).
const MAX_QUANTA: f64 = (1u32 << 30) as f64;

/// The camera-induced motion of every pixel of one frame, as coefficients
/// of the map from (pixel, depth) to the previous frame's pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Predictor {
    /// View ray of pixel `(x, y)` in the current camera:
    /// `(ax + bx·x, ay + by·y, −1)`.
    ray: [f64; 4],
    /// Current view → previous view: rotation (rows) …
    rotation: [f64; 9],
    /// … and translation (in previous-view axes).
    translation: [f64; 3],
    /// Previous view → previous pixel: `(cx + sx·X/Z, cy + sy·Y/Z)` with
    /// `Z = −z` the depth along the previous view axis.
    projection: [f64; 4],
}

impl Predictor {
    /// The motion a static point of `meta`'s frame gets when the motion
    /// vectors point into a frame seen as `reference` (the previous frame;
    /// `meta` itself when there is none, which predicts zero motion).
    pub fn new(meta: &FrameMeta, reference: &FrameMeta) -> Self {
        let cur = &meta.camera;
        let prev = &reference.camera;
        let (w, h) = meta.size.as_f64();
        let t = cur.projection.tan_half_fov();
        let a = cur.projection.aspect;
        let win = &cur.window;
        let ray = [
            win.u0 * t * a,
            win.width() / w * t * a,
            win.v1 * t,
            -win.height() / h * t,
        ];
        let to_prev = prev.pose.rotation.normalize().conjugate();
        let m = DMat3::from_quat(to_prev * cur.pose.rotation.normalize());
        let rotation = [
            m.x_axis.x, m.y_axis.x, m.z_axis.x, m.x_axis.y, m.y_axis.y, m.z_axis.y, m.x_axis.z,
            m.y_axis.z, m.z_axis.z,
        ];
        let tr: DVec3 = to_prev * (cur.pose.position - prev.pose.position);
        let (pw, ph) = reference.size.as_f64();
        let pt = prev.projection.tan_half_fov();
        let pwin = &prev.window;
        let projection = [
            -pwin.u0 * pw / pwin.width(),
            pw / (pwin.width() * pt * prev.projection.aspect),
            pwin.v1 * ph / pwin.height(),
            -ph / (pwin.height() * pt),
        ];
        Self {
            ray,
            rotation,
            translation: tr.to_array(),
            projection,
        }
    }

    fn coefficients(&self) -> [f64; COEFFICIENTS] {
        let mut c = [0.0; COEFFICIENTS];
        c[..4].copy_from_slice(&self.ray);
        c[4..13].copy_from_slice(&self.rotation);
        c[13..16].copy_from_slice(&self.translation);
        c[16..].copy_from_slice(&self.projection);
        c
    }

    fn from_coefficients(c: &[f64; COEFFICIENTS]) -> Result<Self, CodecError> {
        if c.iter().any(|v| !v.is_finite()) {
            return Err(CodecError::BadParameters("motion predictor"));
        }
        Ok(Self {
            ray: std::array::from_fn(|i| c[i]),
            rotation: std::array::from_fn(|i| c[4 + i]),
            translation: std::array::from_fn(|i| c[13 + i]),
            projection: std::array::from_fn(|i| c[16 + i]),
        })
    }

    /// The camera-induced motion of pixel `(x, y)` (integer coordinates; its
    /// centre is at `+0.5`) at linear `depth`; zero where there is none (an
    /// invalid depth, or a point behind the previous camera).
    pub fn predict(&self, x: u32, y: u32, depth: f32) -> [f64; 2] {
        self.row(y).predict(x, depth)
    }

    /// What the prediction of row `y` shares: the view ray's rotated
    /// constant and slope, `M·ray = a + b·(x + 0.5)`.
    fn row(&self, y: u32) -> Row<'_> {
        let py = f64::from(y) + 0.5;
        let ry = self.ray[2] + self.ray[3] * py;
        let m = &self.rotation;
        Row {
            p: self,
            py,
            a: std::array::from_fn(|k| m[3 * k] * self.ray[0] + m[3 * k + 1] * ry - m[3 * k + 2]),
            b: std::array::from_fn(|k| m[3 * k] * self.ray[1]),
        }
    }
}

/// One row of a [`Predictor`].
struct Row<'a> {
    p: &'a Predictor,
    py: f64,
    a: [f64; 3],
    b: [f64; 3],
}

impl Row<'_> {
    fn predict(&self, x: u32, depth: f32) -> [f64; 2] {
        let px = f64::from(x) + 0.5;
        let d = f64::from(depth);
        if d.is_nan() || d <= 0.0 {
            return [0.0; 2];
        }
        let dir: [f64; 3] = std::array::from_fn(|k| self.a[k] + self.b[k] * px);
        // A finite point moves with the whole pose; one at infinity (sky)
        // only with the rotation.
        let v: [f64; 3] = if d.is_finite() {
            std::array::from_fn(|k| dir[k] * d + self.p.translation[k])
        } else {
            dir
        };
        let z = -v[2];
        if z.is_nan() || z <= 0.0 {
            return [0.0; 2];
        }
        let inv = 1.0 / z;
        let pr = &self.p.projection;
        let motion = [
            pr[0] + pr[1] * (v[0] * inv) - px,
            pr[2] + pr[3] * (v[1] * inv) - self.py,
        ];
        if motion
            .iter()
            .all(|m| m.is_finite() && m.abs() < MAX_QUANTA * QUANTUM)
        {
            motion
        } else {
            [0.0; 2]
        }
    }
}

/// Encodes `motion` (one vector a pixel, `width` wide) against `predictor`,
/// evaluated at `depth` as the receiver decodes it, at zstd `level`.
pub fn encode(
    predictor: &Predictor,
    motion: &[[f32; 2]],
    depth: &[f32],
    width: u32,
    level: i32,
) -> Result<Vec<u8>, CodecError> {
    check_width(width, motion.len())?;
    if depth.len() != motion.len() {
        return Err(CodecError::WrongLength {
            got: depth.len() as u64,
            expected: motion.len() as u64,
        });
    }
    let n = motion.len();
    let mut planes = vec![0i32; 2 * n];
    for_each_pixel(predictor, width, n, |i, x, row| {
        let pred = row.predict(x, depth[i]);
        for c in 0..2 {
            let q = (f64::from(motion[i][c]) - pred[c]) / QUANTUM;
            // NaN becomes 0: an invalid vector comes back as predicted.
            planes[c * n + i] = super::round_i32(q.clamp(-MAX_QUANTA, MAX_QUANTA));
        }
    });
    let packed = pack_planes(&planes, width, level)?;
    let mut out = Vec::with_capacity(HEADER + packed.len());
    out.push(TAG);
    out.extend_from_slice(&QUANTUM.to_le_bytes());
    out.extend_from_slice(&width.to_le_bytes());
    for c in predictor.coefficients() {
        out.extend_from_slice(&c.to_le_bytes());
    }
    out.extend_from_slice(&packed);
    Ok(out)
}

/// Calls `f(index, x, row)` for the `n` pixels of rows `width` wide.
fn for_each_pixel(
    predictor: &Predictor,
    width: u32,
    n: usize,
    mut f: impl FnMut(usize, u32, &Row<'_>),
) {
    let w = width.max(1) as usize;
    for (y, start) in (0..n).step_by(w).enumerate() {
        let row = predictor.row(y as u32);
        for x in 0..w.min(n - start) {
            f(start + x, x as u32, &row);
        }
    }
}

fn pack_planes(planes: &[i32], width: u32, level: i32) -> Result<Vec<u8>, CodecError> {
    // Both planes in one zstd frame: the x plane's rows continue into the
    // y plane's, which the predictor handles like any other edge.
    planar::pack(planes, width as usize, level)
}

/// Decodes the motion of a frame whose receiver-side depth is `depth`.
pub fn decode(encoded: &[u8], depth: &[f32]) -> Result<Vec<[f32; 2]>, CodecError> {
    let (head, packed) = encoded
        .split_first_chunk::<HEADER>()
        .ok_or(CodecError::BadParameters("motion header"))?;
    if head[0] != TAG {
        return Err(CodecError::BadParameters("motion tag"));
    }
    let f = |at: usize| f64::from_le_bytes(std::array::from_fn(|k| head[at + k]));
    let quantum = f(1);
    if !(quantum.is_finite() && quantum > 0.0 && quantum <= 1.0) {
        return Err(CodecError::BadParameters("motion quantum"));
    }
    let width = u32::from_le_bytes([head[9], head[10], head[11], head[12]]);
    let n = depth.len();
    check_width(width, n)?;
    let coefficients: [f64; COEFFICIENTS] = std::array::from_fn(|i| f(13 + 8 * i));
    let predictor = Predictor::from_coefficients(&coefficients)?;
    let planes = planar::unpack(packed, 2 * n, width as usize)?;
    let mut motion = vec![[0.0f32; 2]; n];
    for_each_pixel(&predictor, width, n, |i, x, row| {
        let pred = row.predict(x, depth[i]);
        motion[i] = [
            (pred[0] + f64::from(planes[i]) * quantum) as f32,
            (pred[1] + f64::from(planes[n + i]) * quantum) as f32,
        ];
    });
    Ok(motion)
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec2, DVec3};

    use super::*;
    use crate::{Camera, FrameSize, Pose, Projection, Window};

    fn meta(position: DVec3, yaw_deg: f64, size: FrameSize, window: Window) -> FrameMeta {
        let mut camera = Camera::new(
            Pose::new(position, DQuat::from_rotation_y(yaw_deg.to_radians())),
            Projection::perspective(55f64.to_radians(), 16.0 / 9.0, 0.05, 500.0),
        );
        camera.window = window;
        FrameMeta {
            index: 2,
            time: 0.0,
            camera,
            size,
            host_processing: std::time::Duration::ZERO,
            cut: false,
        }
    }

    fn depth_at(x: u32, y: u32) -> f32 {
        if y < 10 {
            f32::INFINITY
        } else {
            2.0 + ((x * 7 + y * 3) % 50) as f32 * 0.37
        }
    }

    /// The coefficients reproduce `Camera::static_motion` (to rounding), with
    /// widened windows, different sizes, sky, and coordinates near 1e5.
    #[test]
    fn prediction_equals_the_camera_model() {
        let wide = Window {
            u0: -1.2,
            v0: -1.1,
            u1: 1.1,
            v1: 1.3,
        };
        let cur = meta(
            DVec3::new(1e5, 2.0, -3e4),
            12.0,
            FrameSize::new(96, 54),
            wide,
        );
        let prev = meta(
            DVec3::new(1e5 - 0.3, 2.1, -3e4 + 0.2),
            9.5,
            FrameSize::new(90, 50),
            Window::FULL,
        );
        let p = Predictor::new(&cur, &prev);
        for y in (0..54).step_by(5) {
            for x in (0..96).step_by(7) {
                let d = depth_at(x, y);
                let want = cur
                    .camera
                    .static_motion(
                        &prev.camera,
                        DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5),
                        f64::from(d),
                        cur.size.as_f64(),
                        prev.size.as_f64(),
                    )
                    .unwrap();
                let got = p.predict(x, y, d);
                assert!(
                    (got[0] - want.x).abs() < 1e-6 && (got[1] - want.y).abs() < 1e-6,
                    "({x}, {y}) d {d}: {got:?} vs {want}"
                );
            }
        }
        // Against itself, nothing moves.
        let same = Predictor::new(&cur, &cur);
        let m = same.predict(40, 30, 3.0);
        assert!(m[0].abs() < 1e-9 && m[1].abs() < 1e-9, "{m:?}");
    }

    #[test]
    fn static_pixels_cost_nothing_and_every_vector_comes_back_within_half_a_quantum() {
        let size = FrameSize::new(160, 90);
        let cur = meta(DVec3::new(0.4, 1.0, 3.0), 4.0, size, Window::FULL);
        let prev = meta(DVec3::new(0.3, 1.0, 3.1), 2.0, size, Window::FULL);
        let p = Predictor::new(&cur, &prev);
        let (w, h) = (size.width, size.height);
        let depth: Vec<f32> = (0..w * h).map(|i| depth_at(i % w, i / w)).collect();
        // Static everywhere (in f32, as a renderer writes it) but for a
        // block moving 3.3 px right and 1.7 px down.
        let motion: Vec<[f32; 2]> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let m = p.predict(x, y, depth[i as usize]);
                if (40..80).contains(&x) && (30..60).contains(&y) {
                    [(m[0] - 3.3) as f32, (m[1] - 1.7) as f32]
                } else {
                    [m[0] as f32, m[1] as f32]
                }
            })
            .collect();
        let enc = encode(&p, &motion, &depth, w, 1).unwrap();
        let back = decode(&enc, &depth).unwrap();
        for (a, b) in motion.iter().zip(&back) {
            for c in 0..2 {
                assert!(
                    f64::from((a[c] - b[c]).abs()) <= QUANTUM / 2.0 + 1e-5,
                    "{a:?} vs {b:?}"
                );
            }
        }
        // Raw: 8 bytes a pixel. With the camera subtracted, the static part
        // and the rigid block are nearly free.
        assert!(enc.len() < 2_000, "{} bytes", enc.len());
        // Without a previous camera the same vectors are sent whole.
        let whole = encode(&Predictor::new(&cur, &cur), &motion, &depth, w, 1).unwrap();
        assert!(
            whole.len() > 4 * enc.len(),
            "{} vs {}",
            whole.len(),
            enc.len()
        );
        assert_eq!(decode(&whole, &depth).unwrap().len(), motion.len());
    }

    #[test]
    fn hostile_payloads_are_typed_errors_or_finite() {
        let size = FrameSize::new(8, 4);
        let m = meta(DVec3::ZERO, 0.0, size, Window::FULL);
        let depth = vec![1.0f32; 32];
        let enc = encode(&Predictor::new(&m, &m), &[[0.5, -0.5]; 32], &depth, 8, 1).unwrap();
        assert!(decode(&enc[..HEADER - 1], &depth).is_err());
        let mut bad = enc.clone();
        bad[0] = 0;
        assert!(decode(&bad, &depth).is_err());
        let mut bad = enc.clone();
        bad[13..21].copy_from_slice(&f64::INFINITY.to_le_bytes());
        assert!(decode(&bad, &depth).is_err());
        let mut bad = enc.clone();
        bad[1..9].copy_from_slice(&0.0f64.to_le_bytes());
        assert!(decode(&bad, &depth).is_err());
        assert!(decode(&enc, &depth[..30]).is_err());
        // Huge coefficients still give finite vectors.
        let mut big = enc.clone();
        for i in 0..COEFFICIENTS {
            big[13 + 8 * i..21 + 8 * i].copy_from_slice(&1e300f64.to_le_bytes());
        }
        let out = decode(&big, &[f32::INFINITY; 32]).unwrap();
        assert!(out.iter().flatten().all(|v| v.is_finite()));
        // NaN and infinite inputs encode (as the prediction) rather than fail.
        let odd = [[f32::NAN, f32::INFINITY]; 32];
        let enc = encode(&Predictor::new(&m, &m), &odd, &depth, 8, 1).unwrap();
        assert!(
            decode(&enc, &depth)
                .unwrap()
                .iter()
                .flatten()
                .all(|v| v.is_finite())
        );
    }
}
