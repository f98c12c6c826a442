//! Blender renders: multilayer OpenEXR with the Combined, Depth and Vector
//! passes, and the `cameras.json` sidecar that
//! `tools/blender/framegen_export.py` writes (Blender does not store the
//! camera in its EXRs).
//!
//! # Blender's conventions, and the evidence for each
//!
//! The evidence is the committed fixture (`tests/fixtures/blender/`, Cycles,
//! Blender 3.4.1) measured by this module's [`super::reprojection`] check;
//! `tests/tests/import_blender.rs` asserts each.
//!
//! * **Channels.** A multilayer EXR names channels `<view layer>.<pass>.<c>`:
//!   `ViewLayer.Combined.R/G/B/A`, `ViewLayer.Depth.Z`,
//!   `ViewLayer.Vector.X/Y/Z/W`, `ViewLayer.IndexOB.X`. Names without the
//!   view-layer prefix are accepted too.
//! * **Rows.** The EXR's first row is the top of the image (the fixture's sky
//!   is in its first rows), as in this crate.
//! * **Vector pass.** Four components: `X, Y` hold the motion *to the
//!   previous frame* (`previous − current`), `Z, W` the motion from the next
//!   frame (`current − next`), in pixels with the **y axis pointing up**
//!   (Blender's image origin is the bottom-left). So this crate's motion is
//!   `(X, −Y)`. On the fixture, `(X, −Y)` matches depth + camera to a mean of
//!   0.0089 px; `(−X, Y)` is off by 4.29 px, `(−X, −Y)` by 4.28 px and
//!   `(X, Y)` by 0.089 px (10× worse: the truck is mostly horizontal).
//!   Blender offers the Vector pass only with motion blur off.
//! * **Depth pass.** `Z` is **planar** depth: the distance along the camera's
//!   view axis, as in this crate (Cycles' `camera_z_depth`). Read as the
//!   distance along each pixel's ray it fits the motion 16× worse on the
//!   fixture (0.141 px against 0.0089 px).
//! * **Background.** Where no geometry is hit, Cycles writes `Z = 1e10` (the
//!   fixture's sky); other engines write the far clip distance. There is no
//!   usable depth there, so every `Z` at or beyond the camera's `clip_end`
//!   (nothing nearer can be geometry that was rendered) becomes `+inf`, the
//!   sky of this crate. The Vector pass there does not follow the camera's
//!   rotation (on the fixture it moves the sky 0.21 px a frame where the
//!   pan moves it 0.64 px, errors up to 1.8 px), so the sky's motion is
//!   recomputed from the two cameras (rotation only, DESIGN §3) and left
//!   out of the import check.
//! * **Camera.** Blender's world is right-handed with **Z up**; this crate's
//!   is right-handed with Y up: `(x, y, z) ↦ (x, z, −y)`, a rotation. A
//!   Blender camera looks down its local −Z with +Y up, as here, so the
//!   camera-to-world matrix converts column by column (its scale is
//!   removed). The field of view follows Blender's sensor fit: `AUTO` fits
//!   `sensor_width` to the larger image side, `HORIZONTAL` fits
//!   `sensor_width` to the width, `VERTICAL` fits `sensor_height` to the
//!   height; `tan(fov/2) = sensor / (2 · lens)` on the fitted side.
//! * **Animated objects** become this crate's mask, and the import check
//!   uses only the unmasked pixels. The export script gives every animated
//!   object without one a pass index of its own and lists the animated
//!   objects' indices in the sidecar (`animated_pass_indices`): pixels of
//!   the Object Index pass with a listed index are masked, and nothing
//!   else, so a scene that uses pass indices for compositing keeps its
//!   static objects unmasked. A sidecar without the list (older exports,
//!   other tools) gets the mask from the motion itself: a pixel whose
//!   Vector pass disagrees with its depth + the two cameras by more than
//!   [`MOVING_PX`] moved on its own (the fixture's static pixels agree to
//!   a mean of 0.0089 px); the first frame, with no camera before it, has
//!   no mask then.
//!
//! Not supported, with a typed error: orthographic and panoramic cameras,
//! lens shift (an off-centre frustum this crate's projection cannot
//! express), non-square pixels.

use std::path::Path;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::{
    Entry, ImportError, SIDECAR, Sequence, Timeline, camera_motion, check_file_name,
    check_rate_and_size,
};
use crate::camera::{Camera, Pose, Projection};
use crate::dump::{DumpError, mask_bytes, missing_as_frame, read_planes, rgb_pixel};
use crate::frame::{BufferKind, ExtraBuffer, Frame, FrameSize};

/// Motion that disagrees with depth + camera by more than this (pixels)
/// marks an animated pixel when the sidecar lists no pass indices.
pub const MOVING_PX: f32 = 0.5;

/// The sidecar's `format`.
pub const FORMAT: &str = "framegen-blender-cameras";
/// The sidecar version this build reads.
pub const VERSION: u32 = 1;

/// `cameras.json` as `tools/blender/framegen_export.py` writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// `bpy.app.version_string`.
    #[serde(default)]
    pub blender_version: String,
    /// Render engine (`CYCLES`, `BLENDER_EEVEE`, …).
    #[serde(default)]
    pub engine: String,
    /// Frames per second (`fps / fps_base`).
    pub fps: f64,
    /// View layer whose passes to read.
    #[serde(default = "default_view_layer")]
    pub view_layer: String,
    /// Pass indices of the animated objects (the Object Index pass's
    /// values to mask); absent: the mask comes from the motion.
    #[serde(default)]
    pub animated_pass_indices: Option<Vec<u32>>,
    /// One entry per rendered frame, in order.
    pub frames: Vec<SidecarFrame>,
}

fn default_view_layer() -> String {
    "ViewLayer".to_owned()
}

/// One frame of the sidecar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SidecarFrame {
    /// Blender frame number.
    pub frame: i64,
    /// Scene time, seconds (`frame · fps_base / fps`).
    pub time: f64,
    /// The frame's EXR, a file name in the sidecar's folder.
    pub file: String,
    /// Rendered size in pixels (resolution × percentage).
    pub resolution: [u32; 2],
    /// Pixel aspect ratio, x and y.
    #[serde(default = "square")]
    pub pixel_aspect: [f64; 2],
    /// The active camera.
    pub camera: BlenderCamera,
}

fn square() -> [f64; 2] {
    [1.0, 1.0]
}

/// A Blender camera at one frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlenderCamera {
    /// `PERSP`, `ORTHO` or `PANO`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Camera-to-world, row-major, Blender's world axes (Z up).
    pub matrix_world: [[f64; 4]; 4],
    /// Focal length, mm.
    pub lens: f64,
    /// Sensor width, mm.
    pub sensor_width: f64,
    /// Sensor height, mm.
    pub sensor_height: f64,
    /// `AUTO`, `HORIZONTAL` or `VERTICAL`.
    pub sensor_fit: String,
    /// Lens shift, x (fraction of the larger side).
    pub shift_x: f64,
    /// Lens shift, y.
    pub shift_y: f64,
    /// Near clip distance.
    pub clip_start: f64,
    /// Far clip distance.
    pub clip_end: f64,
}

impl BlenderCamera {
    /// This crate's camera for an image of `size`.
    pub fn to_camera(&self, size: FrameSize) -> Result<Camera, CameraProblem> {
        if self.kind != "PERSP" {
            return Err(CameraProblem::Unsupported(format!(
                "camera type {} (only PERSP cameras are imported)",
                self.kind
            )));
        }
        if self.shift_x.abs() > 1e-9 || self.shift_y.abs() > 1e-9 {
            return Err(CameraProblem::Unsupported(format!(
                "lens shift ({}, {}): an off-centre frustum has no equivalent here",
                self.shift_x, self.shift_y
            )));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.lens) && positive(self.sensor_width) && positive(self.sensor_height)) {
            return Err(CameraProblem::Invalid(
                "lens and sensor sizes must be finite and positive".into(),
            ));
        }
        let (w, h) = (f64::from(size.width), f64::from(size.height));
        // tan of the half angle on the fitted side.
        let tan_half = |sensor: f64| sensor / (2.0 * self.lens);
        let tan_half_y = match self.sensor_fit.as_str() {
            "AUTO" if w >= h => tan_half(self.sensor_width) * h / w,
            "AUTO" => tan_half(self.sensor_width),
            "HORIZONTAL" => tan_half(self.sensor_width) * h / w,
            "VERTICAL" => tan_half(self.sensor_height),
            other => return Err(CameraProblem::Unsupported(format!("sensor fit {other}"))),
        };
        let projection = Projection::perspective(
            2.0 * tan_half_y.atan(),
            w / h,
            self.clip_start,
            self.clip_end,
        );
        let m = &self.matrix_world;
        if m.iter().flatten().any(|v| !v.is_finite()) {
            return Err(CameraProblem::Invalid("matrix_world is not finite".into()));
        }
        if m[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(CameraProblem::Invalid(
                "matrix_world's last row is not (0, 0, 0, 1)".into(),
            ));
        }
        let column = |c: usize| z_up_to_y_up(DVec3::new(m[0][c], m[1][c], m[2][c]));
        let rotation =
            super::rotation_of(column(0), column(1), column(2)).map_err(CameraProblem::Invalid)?;
        let camera = Camera::new(Pose::new(column(3), rotation), projection);
        camera
            .validate()
            .map_err(|e| CameraProblem::Invalid(e.to_string()))?;
        Ok(camera)
    }
}

/// Why a sidecar camera has no camera here.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CameraProblem {
    /// A Blender feature this importer does not convert.
    Unsupported(String),
    /// Values that make no camera.
    Invalid(String),
}

/// Blender world (right-handed, Z up) → this crate's (right-handed, Y up).
pub fn z_up_to_y_up(v: DVec3) -> DVec3 {
    DVec3::new(v.x, v.z, -v.y)
}

/// A Blender render opened for reading.
pub type BlenderDump = Sequence<Sidecar>;

impl BlenderDump {
    /// Opens `dir` and validates its sidecar. No EXR is read yet.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ImportError> {
        let dir = dir.as_ref().to_owned();
        let path = dir.join(SIDECAR);
        let sidecar: Sidecar = super::read_json(&path)?;
        if sidecar.format != FORMAT {
            return Err(ImportError::sidecar(
                &path,
                format!("format is {:?}, expected {FORMAT:?}", sidecar.format),
            ));
        }
        if sidecar.version != VERSION {
            return Err(ImportError::Unsupported(format!(
                "Blender sidecar version {} (this build reads {VERSION})",
                sidecar.version
            )));
        }
        let first = sidecar
            .frames
            .first()
            .ok_or_else(|| ImportError::Empty(dir.display().to_string()))?;
        let size = FrameSize::new(first.resolution[0], first.resolution[1]);
        check_rate_and_size(&path, sidecar.fps, first.resolution)?;
        let mut entries = Vec::with_capacity(sidecar.frames.len());
        for f in &sidecar.frames {
            check_file_name(&path, &f.file)?;
            if f.resolution != first.resolution {
                return Err(ImportError::sidecar(
                    &path,
                    format!(
                        "frame {} is {:?}, frame {} is {:?}: the size must not change",
                        f.frame, f.resolution, first.frame, first.resolution
                    ),
                ));
            }
            if f.pixel_aspect[0] != f.pixel_aspect[1] {
                return Err(ImportError::Unsupported(format!(
                    "non-square pixels ({:?}) in frame {}",
                    f.pixel_aspect, f.frame
                )));
            }
            if !f.time.is_finite() {
                return Err(ImportError::sidecar(
                    &path,
                    format!("frame {}: time", f.frame),
                ));
            }
            let camera = f.camera.to_camera(size).map_err(|problem| match problem {
                CameraProblem::Unsupported(d) => {
                    ImportError::Unsupported(format!("frame {}: {d}", f.frame))
                }
                CameraProblem::Invalid(d) => {
                    ImportError::sidecar(&path, format!("frame {}: {d}", f.frame))
                }
            })?;
            entries.push(Entry {
                number: f.frame,
                time: f.time,
                camera,
            });
        }
        let timeline = Timeline::new(&path, sidecar.fps, size, entries)?;
        Ok(Self {
            dir,
            sidecar,
            timeline,
        })
    }

    /// The pass indices of the animated objects, where the sidecar lists
    /// them.
    pub fn animated(&self) -> Option<&[u32]> {
        self.sidecar.animated_pass_indices.as_deref()
    }

    /// What the dump is, for manifests and logs.
    pub fn describe(&self) -> String {
        format!(
            "Blender {} ({}) render in {}",
            self.sidecar.blender_version,
            self.sidecar.engine,
            self.dir.display()
        )
    }

    /// Frame `position`, converted (see the module documentation), and
    /// which pixels' motion came from the Vector pass
    /// (the sky's is computed from the cameras).
    pub fn read_frame_with_origin(&self, position: u64) -> Result<(Frame, Vec<bool>), DumpError> {
        let meta = self.timeline.meta(position)?;
        let path = self.dir.join(&self.sidecar.frames[position as usize].file);
        let size = self.timeline.size();
        let far = meta.camera.projection.far;
        // The size is checked before any pixel is decoded; channels are
        // looked up with the view layer's prefix, then without.
        let planes = read_planes(&path, size, &[]).map_err(|e| missing_as_frame(e, position))?;
        let layer = &self.sidecar.view_layer;
        let find = |pass: &str| {
            planes
                .get(&format!("{layer}.{pass}"))
                .or_else(|| planes.get(pass))
        };
        let plane = |pass: &str| {
            find(pass).ok_or_else(|| DumpError::MissingChannel {
                path: path.clone(),
                channel: format!("{layer}.{pass}"),
            })
        };
        let (r, g, b) = (
            plane("Combined.R")?,
            plane("Combined.G")?,
            plane("Combined.B")?,
        );
        let n = size.pixels() as usize;
        let mut frame = Frame::empty(meta);
        frame.color = (0..n).map(|i| rgb_pixel(r[i], g[i], b[i])).collect();
        frame.depth = plane("Depth.Z")?
            .iter()
            .map(|&z| if z >= far as f32 { f32::INFINITY } else { z })
            .collect();
        let (vx, vy) = (plane("Vector.X")?, plane("Vector.Y")?);
        let prev = self.timeline.previous_camera(position, &frame.meta);
        let from_file: Vec<bool> = frame.depth.iter().map(|d| d.is_finite()).collect();
        frame.motion = (0..n)
            .map(|i| {
                if from_file[i] || prev.is_none() {
                    [vx[i], -vy[i]]
                } else {
                    camera_motion(&frame.meta.camera, prev, size, i, f32::INFINITY)
                }
            })
            .collect();
        let animated: Option<Vec<bool>> = match (&self.sidecar.animated_pass_indices, prev) {
            (Some(listed), _) => Some(match find("IndexOB.X") {
                Some(index) => index
                    .iter()
                    .map(|&v| v >= 0.5 && listed.contains(&(v.round() as u32)))
                    .collect(),
                None => vec![false; n],
            }),
            (None, Some(prev)) => Some(
                (0..n)
                    .map(|i| {
                        let d = frame.depth[i];
                        from_file[i] && {
                            let m = camera_motion(&frame.meta.camera, Some(prev), size, i, d);
                            let (dx, dy) = (frame.motion[i][0] - m[0], frame.motion[i][1] - m[1]);
                            dx.hypot(dy) > MOVING_PX
                        }
                    })
                    .collect(),
            ),
            (None, None) => None,
        };
        if let Some(animated) = animated {
            let mask: Vec<f32> = animated.iter().map(|&a| f32::from(u8::from(a))).collect();
            frame.extras.push(ExtraBuffer {
                kind: BufferKind::Mask,
                data: mask_bytes(&mask),
            });
        }
        Ok((frame, from_file))
    }
}
