//! Unreal Engine captures laid out one folder per buffer, as the ExtraNet and
//! learnable-motion-vector tool chains export them:
//!
//! ```text
//! DIR/cameras.json                          the camera sidecar (below)
//! DIR/PreTonemapHDRColor/<name>.0000.exr    linear HDR colour: R, G, B
//! DIR/SceneDepth/<name>.0000.exr            scene depth, cm: R
//! DIR/MotionVector/<name>.0000.exr          encoded velocity: R, G
//! ```
//!
//! Folder names, the capture name and the frame-number width are in the
//! sidecar. UE keeps camera matrices outside the EXRs, so the sidecar holds,
//! per frame, what a capture blueprint reads off the camera: location (cm),
//! rotation (pitch, yaw, roll in degrees, `FRotator`), horizontal field of
//! view (degrees) and near clip (cm); plus the frame time.
//!
//! # Supported versions and encodings
//!
//! `velocity_encoding: "ue4"`, from `engine_version` 4.x (4.22–4.27 share
//! it): the velocity render target as `EncodeVelocityToTexture` writes it,
//! `enc = V · (0.499 · 0.5) + 32767 / 65535` with `V = ScreenPos −
//! PrevScreenPos` in NDC (y up), exported as 32-bit float EXR (a 16-bit
//! float export quantises `enc` to 2⁻¹¹ near 0.5, about 0.6 px at 640 px
//! wide; the import check then reports it). A pixel with `enc.x = 0` (the
//! clear value: static geometry that drew no velocity) gets its motion from
//! depth and the two cameras, as UE4's TAA does (`if (Velocity.x > 0)`).
//! Engine version 5 packs extra flags into the velocity target and is refused
//! with [`ImportError::Unsupported`], as is any other encoding name.
//!
//! # Conversion
//!
//! * UE's world is **left-handed**, X forward, Y right, Z up, in cm. This
//!   crate's is right-handed, Y up: `(X, Y, Z) ↦ (Y, Z, −X) / world_to_meters`
//!   (a reflection, which is what turns left- into right-handed; 100 cm/m by
//!   default).
//! * A camera looks along its rotator's X axis with Z up; here it looks down
//!   local −Z with +Y up. `FRotator (pitch, yaw, roll)` gives UE's axes with
//!   `FRotationMatrix`'s formulas.
//! * UE's FOV is horizontal (the default `AspectRatio_MaintainXFOV`).
//! * `SceneDepth` is planar depth in cm; values at or beyond `sky_depth`
//!   (default 65504, where a half-float export of the infinite far plane
//!   saturates) are sky, `+inf` here.
//! * Motion here is current → previous in pixels, y down:
//!   `(−V.x · W/2, V.y · H/2)`.
//!
//! [`UnrealWriter`] writes this layout from frames in this crate's
//! conventions: the synthetic fixture of `tests/tests/import_unreal.rs`.

use std::fs;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec2, DVec3};
use serde::{Deserialize, Serialize};

use super::{
    Entry, ImportError, SIDECAR, Sequence, Timeline, camera_motion, check_file_name,
    check_rate_and_size,
};
use crate::camera::{Camera, Pose, Projection, size_f};
use crate::dump::{DumpError, PlaneOut, missing_as_frame, read_planes, rgb_pixel, write_planes};
use crate::frame::{Frame, FrameSize};

/// The sidecar's `format`.
pub const FORMAT: &str = "framegen-unreal-cameras";
/// The sidecar version this build reads.
pub const VERSION: u32 = 1;
/// The one velocity encoding this build reads.
pub const ENCODING_UE4: &str = "ue4";
/// UE4's velocity encoding scale (`EncodeVelocityToTexture`).
const VELOCITY_SCALE: f64 = 0.499 * 0.5;
/// UE4's velocity encoding bias.
const VELOCITY_BIAS: f64 = 32767.0 / 65535.0;

/// `cameras.json` of an Unreal capture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The engine that captured, e.g. `"4.27"`.
    pub engine_version: String,
    /// How the motion buffer is encoded; only [`ENCODING_UE4`].
    pub velocity_encoding: String,
    /// Frames per second.
    pub fps: f64,
    /// Image size, pixels.
    pub resolution: [u32; 2],
    /// World units per metre (UE: 100, centimetres).
    #[serde(default = "centimetres")]
    pub world_to_meters: f64,
    /// Depth at or beyond which a pixel is sky, world units.
    #[serde(default = "half_max")]
    pub sky_depth: f64,
    /// Capture name: files are `<folder>/<name>.<frame>.exr`.
    pub name: String,
    /// Digits of the zero-padded frame number.
    #[serde(default = "four")]
    pub frame_digits: usize,
    /// Folder of each buffer.
    #[serde(default)]
    pub buffers: Buffers,
    /// One entry per frame, in order.
    pub frames: Vec<SidecarFrame>,
}

fn centimetres() -> f64 {
    100.0
}

fn half_max() -> f64 {
    65504.0
}

fn four() -> usize {
    4
}

/// Folder names of the buffers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Buffers {
    /// Linear HDR colour before tone mapping.
    pub color: String,
    /// Scene depth.
    pub depth: String,
    /// Encoded velocity.
    pub motion: String,
}

impl Default for Buffers {
    fn default() -> Self {
        Self {
            color: "PreTonemapHDRColor".into(),
            depth: "SceneDepth".into(),
            motion: "MotionVector".into(),
        }
    }
}

/// One frame of the sidecar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SidecarFrame {
    /// Frame number in the file names.
    pub frame: i64,
    /// Game time, seconds.
    pub time: f64,
    /// Camera location, UE world (cm).
    pub location: [f64; 3],
    /// Camera rotation: pitch, yaw, roll in degrees (`FRotator`).
    pub rotation: [f64; 3],
    /// Horizontal field of view, degrees.
    pub fov: f64,
    /// Near clip plane, world units.
    #[serde(default = "near_default")]
    pub near: f64,
}

fn near_default() -> f64 {
    10.0
}

/// UE world axes (left-handed, X forward, Y right, Z up) → this crate's.
pub fn ue_to_y_up(v: DVec3) -> DVec3 {
    DVec3::new(v.y, v.z, -v.x)
}

/// The inverse of [`ue_to_y_up`].
pub fn y_up_to_ue(v: DVec3) -> DVec3 {
    DVec3::new(-v.z, v.x, v.y)
}

/// UE's `FRotationMatrix` axes (forward X, right Y, up Z) of a rotator in
/// degrees, in UE world coordinates.
pub fn rotator_axes(pitch: f64, yaw: f64, roll: f64) -> [DVec3; 3] {
    let (sp, cp) = pitch.to_radians().sin_cos();
    let (sy, cy) = yaw.to_radians().sin_cos();
    let (sr, cr) = roll.to_radians().sin_cos();
    [
        DVec3::new(cp * cy, cp * sy, sp),
        DVec3::new(sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, -sr * cp),
        DVec3::new(-(cr * sp * cy + sr * sy), cy * sr - cr * sp * sy, cr * cp),
    ]
}

/// The rotator (pitch, yaw, roll, degrees) whose forward and right axes are
/// `forward` and `right` (UE world coordinates).
pub fn rotator_of(forward: DVec3, right: DVec3) -> [f64; 3] {
    let pitch = forward.z.clamp(-1.0, 1.0).asin();
    let yaw = forward.y.atan2(forward.x);
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    // right = cos(roll) · right₀ − sin(roll) · up₀ (FRotationMatrix).
    let right0 = DVec3::new(-sy, cy, 0.0);
    let up0 = DVec3::new(-sp * cy, -sp * sy, cp);
    let roll = (-right.dot(up0)).atan2(right.dot(right0));
    [pitch.to_degrees(), yaw.to_degrees(), roll.to_degrees()]
}

impl Sidecar {
    /// This crate's camera for frame `f`.
    pub fn camera(&self, f: &SidecarFrame) -> Result<Camera, String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(finite(&f.location) && finite(&f.rotation)) {
            return Err("location and rotation must be finite".into());
        }
        if !(f.fov.is_finite() && f.fov > 0.0 && f.fov < 180.0) {
            return Err(format!("fov {} is not in (0, 180) degrees", f.fov));
        }
        let s = 1.0 / self.world_to_meters;
        let [forward, right, up] = rotator_axes(f.rotation[0], f.rotation[1], f.rotation[2]);
        let rotation = super::rotation_of(ue_to_y_up(right), ue_to_y_up(up), -ue_to_y_up(forward))?;
        let position = ue_to_y_up(DVec3::from(f.location)) * s;
        let (w, h) = (f64::from(self.resolution[0]), f64::from(self.resolution[1]));
        let tan_half_y = (f.fov.to_radians() / 2.0).tan() * h / w;
        let projection =
            Projection::perspective(2.0 * tan_half_y.atan(), w / h, f.near * s, f64::INFINITY);
        let camera = Camera::new(Pose::new(position, rotation), projection);
        camera.validate().map_err(|e| e.to_string())?;
        Ok(camera)
    }

    /// The sidecar entry that describes `camera` (the inverse of
    /// [`Sidecar::camera`]) at frame `frame`, time `time`.
    pub fn frame_of(&self, frame: i64, time: f64, camera: &Camera) -> SidecarFrame {
        let q: DQuat = camera.pose.rotation.normalize();
        let forward = y_up_to_ue(q * DVec3::NEG_Z);
        let right = y_up_to_ue(q * DVec3::X);
        let p = &camera.projection;
        SidecarFrame {
            frame,
            time,
            location: (y_up_to_ue(camera.pose.position) * self.world_to_meters).to_array(),
            rotation: rotator_of(forward, right),
            fov: 2.0 * (p.tan_half_fov() * p.aspect).atan().to_degrees(),
            near: p.near * self.world_to_meters,
        }
    }

    fn file(&self, dir: &Path, folder: &str, frame: i64) -> PathBuf {
        dir.join(folder).join(format!(
            "{}.{:0width$}.exr",
            self.name,
            frame,
            width = self.frame_digits
        ))
    }

    fn check(&self, path: &Path) -> Result<(), ImportError> {
        if self.format != FORMAT {
            return Err(ImportError::sidecar(
                path,
                format!("format is {:?}, expected {FORMAT:?}", self.format),
            ));
        }
        if self.version != VERSION {
            return Err(ImportError::Unsupported(format!(
                "Unreal sidecar version {} (this build reads {VERSION})",
                self.version
            )));
        }
        let major = self.engine_version.split('.').next().unwrap_or("");
        if major != "4" {
            return Err(ImportError::Unsupported(format!(
                "Unreal Engine {} captures: only UE 4.x velocity buffers ({ENCODING_UE4:?}) are \
                 read; UE 5 packs extra flags into the velocity target",
                self.engine_version
            )));
        }
        if self.velocity_encoding != ENCODING_UE4 {
            return Err(ImportError::Unsupported(format!(
                "velocity encoding {:?}: this build reads {ENCODING_UE4:?}",
                self.velocity_encoding
            )));
        }
        check_rate_and_size(path, self.fps, self.resolution)?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.world_to_meters) && positive(self.sky_depth)) {
            return Err(ImportError::sidecar(
                path,
                "world_to_meters and sky_depth must be finite and positive",
            ));
        }
        if !(1..=12).contains(&self.frame_digits) {
            return Err(ImportError::sidecar(path, "frame_digits must be 1 to 12"));
        }
        check_file_name(path, &self.name)?;
        for folder in [
            &self.buffers.color,
            &self.buffers.depth,
            &self.buffers.motion,
        ] {
            check_file_name(path, folder)?;
        }
        Ok(())
    }
}

/// An Unreal capture opened for reading.
pub type UnrealDump = Sequence<Sidecar>;

impl UnrealDump {
    /// Opens `dir`, validates its sidecar and checks that the buffer folders
    /// exist. No EXR is read yet.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ImportError> {
        let dir = dir.as_ref().to_owned();
        let path = dir.join(SIDECAR);
        let sidecar: Sidecar = super::read_json(&path)?;
        sidecar.check(&path)?;
        if sidecar.frames.is_empty() {
            return Err(ImportError::Empty(dir.display().to_string()));
        }
        for folder in [
            &sidecar.buffers.color,
            &sidecar.buffers.depth,
            &sidecar.buffers.motion,
        ] {
            if !dir.join(folder).is_dir() {
                return Err(ImportError::sidecar(
                    &path,
                    format!("buffer folder {folder:?} is missing from {}", dir.display()),
                ));
            }
        }
        let entries = sidecar
            .frames
            .iter()
            .map(|f| {
                let camera = sidecar.camera(f).map_err(|detail| {
                    ImportError::sidecar(&path, format!("frame {}: {detail}", f.frame))
                })?;
                Ok(Entry {
                    number: f.frame,
                    time: f.time,
                    camera,
                })
            })
            .collect::<Result<Vec<_>, ImportError>>()?;
        let size = FrameSize::new(sidecar.resolution[0], sidecar.resolution[1]);
        let timeline = Timeline::new(&path, sidecar.fps, size, entries)?;
        Ok(Self {
            dir,
            sidecar,
            timeline,
        })
    }

    /// For manifests and logs.
    pub fn describe(&self) -> String {
        format!(
            "Unreal Engine {} capture {:?} in {}",
            self.sidecar.engine_version,
            self.sidecar.name,
            self.dir.display()
        )
    }

    /// Frame `position`, converted (see the module documentation), and
    /// which pixels' motion came from the velocity
    /// buffer (the others were computed from depth and camera).
    pub fn read_frame_with_origin(&self, position: u64) -> Result<(Frame, Vec<bool>), DumpError> {
        let meta = self.timeline.meta(position)?;
        let number = self.timeline.number(position);
        let size = self.timeline.size();
        let buffers = &self.sidecar.buffers;
        let read = |folder: &str, channels: &[&str]| {
            read_planes(
                &self.sidecar.file(&self.dir, folder, number),
                size,
                channels,
            )
            .map_err(|e| missing_as_frame(e, position))
        };
        let color = read(&buffers.color, &["R", "G", "B"])?;
        let depth = read(&buffers.depth, &["R"])?;
        let motion = read(&buffers.motion, &["R", "G"])?;
        let (r, g, b) = (
            color.require("R")?,
            color.require("G")?,
            color.require("B")?,
        );
        let s = 1.0 / self.sidecar.world_to_meters;
        let sky = self.sidecar.sky_depth;
        let depth: Vec<f32> = depth
            .require("R")?
            .iter()
            .map(|&d| {
                let d = f64::from(d);
                if d >= sky {
                    f32::INFINITY
                } else {
                    (d * s) as f32
                }
            })
            .collect();
        let prev_camera = self.timeline.previous_camera(position, &meta);
        let (w, h) = size_f(size.width, size.height);
        let (ex, ey) = (motion.require("R")?, motion.require("G")?);
        let mut from_file = Vec::with_capacity(depth.len());
        let mut vectors = Vec::with_capacity(depth.len());
        for (i, (&x, &y)) in ex.iter().zip(ey).enumerate() {
            let written = x > 0.0;
            from_file.push(written);
            vectors.push(if written {
                let vx = (f64::from(x) - VELOCITY_BIAS) / VELOCITY_SCALE;
                let vy = (f64::from(y) - VELOCITY_BIAS) / VELOCITY_SCALE;
                [(-vx * w / 2.0) as f32, (vy * h / 2.0) as f32]
            } else {
                camera_motion(&meta.camera, prev_camera, size, i, depth[i])
            });
        }
        let mut frame = Frame::empty(meta);
        frame.color = (0..r.len()).map(|i| rgb_pixel(r[i], g[i], b[i])).collect();
        frame.depth = depth;
        frame.motion = vectors;
        Ok((frame, from_file))
    }
}

/// How [`UnrealWriter`] writes velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WriteOptions {
    /// Write velocity for every pixel (UE with velocity output for all
    /// geometry); when false, pixels outside the frame's mask (static) get
    /// the clear value 0, as UE4's static geometry does.
    pub velocity_for_static: bool,
    /// Depth written for sky, world units; finite depth must stay below it.
    pub sky_depth: f64,
}

impl Default for WriteOptions {
    fn default() -> Self {
        Self {
            velocity_for_static: true,
            sky_depth: half_max(),
        }
    }
}

/// Writes frames in this crate's conventions as an Unreal-style capture.
#[derive(Debug)]
pub struct UnrealWriter {
    dir: PathBuf,
    sidecar: Sidecar,
    options: WriteOptions,
}

impl UnrealWriter {
    /// Creates the folders of a capture called `name` in `dir` (which must
    /// not hold a sidecar yet).
    pub fn create(
        dir: impl AsRef<Path>,
        name: &str,
        fps: f64,
        size: FrameSize,
        options: WriteOptions,
    ) -> Result<Self, ImportError> {
        let dir = dir.as_ref().to_owned();
        let sidecar = Sidecar {
            format: FORMAT.into(),
            version: VERSION,
            engine_version: "4.27".into(),
            velocity_encoding: ENCODING_UE4.into(),
            fps,
            resolution: [size.width, size.height],
            world_to_meters: centimetres(),
            sky_depth: options.sky_depth,
            name: name.into(),
            frame_digits: four(),
            buffers: Buffers::default(),
            frames: Vec::new(),
        };
        let path = dir.join(SIDECAR);
        sidecar.check(&path)?;
        if path.exists() {
            return Err(DumpError::AlreadyExists(dir).into());
        }
        for folder in [
            &sidecar.buffers.color,
            &sidecar.buffers.depth,
            &sidecar.buffers.motion,
        ] {
            let d = dir.join(folder);
            fs::create_dir_all(&d).map_err(|e| DumpError::io(&d, e))?;
        }
        Ok(Self {
            dir,
            sidecar,
            options,
        })
    }

    /// Appends one frame (plain window, the capture's size).
    pub fn write_frame(&mut self, frame: &Frame) -> Result<(), ImportError> {
        let size = frame.meta.size;
        let sc = &self.sidecar;
        if size != FrameSize::new(sc.resolution[0], sc.resolution[1]) {
            return Err(ImportError::Unsupported(format!(
                "frame of {}x{} in a {}x{} capture",
                size.width, size.height, sc.resolution[0], sc.resolution[1]
            )));
        }
        if !frame.meta.camera.window.is_full() {
            return Err(ImportError::Unsupported(
                "a widened rendering window has no Unreal equivalent".into(),
            ));
        }
        let number = frame.meta.index as i64;
        let n = size.pixels() as usize;
        let (w, h) = size_f(size.width, size.height);
        let wtm = sc.world_to_meters;
        let sky = self.options.sky_depth;
        let mut depth = Vec::with_capacity(n);
        for &d in &frame.depth {
            let d = f64::from(d);
            let v = if d == f64::INFINITY { sky } else { d * wtm };
            if d.is_finite() && v >= sky {
                return Err(ImportError::Unsupported(format!(
                    "depth {v} is beyond the capture's sky depth {sky}"
                )));
            }
            depth.push(v as f32);
        }
        let mask = frame
            .extras
            .iter()
            .find(|e| e.kind == crate::BufferKind::Mask);
        let (mut ex, mut ey) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (i, mv) in frame.motion.iter().enumerate() {
            let dynamic = mask.is_some_and(|m| m.data.get(i).is_some_and(|&v| v != 0));
            if !self.options.velocity_for_static && !dynamic {
                ex.push(0.0);
                ey.push(0.0);
                continue;
            }
            let v = DVec2::new(-f64::from(mv[0]) * 2.0 / w, f64::from(mv[1]) * 2.0 / h);
            ex.push((v.x * VELOCITY_SCALE + VELOCITY_BIAS) as f32);
            ey.push((v.y * VELOCITY_SCALE + VELOCITY_BIAS) as f32);
        }
        let channel = |c: usize| frame.color.iter().map(|p| p[c].to_f32()).collect();
        let ones = || vec![1.0; n];
        let plane = |name, values, half| PlaneOut { name, values, half };
        let file = |folder: &str| sc.file(&self.dir, folder, number);
        write_planes(
            &file(&sc.buffers.color),
            size,
            vec![
                plane("R", channel(0), true),
                plane("G", channel(1), true),
                plane("B", channel(2), true),
                plane("A", ones(), true),
            ],
        )?;
        write_planes(
            &file(&sc.buffers.depth),
            size,
            vec![
                plane("R", depth.clone(), false),
                plane("G", depth.clone(), false),
                plane("B", depth, false),
                plane("A", ones(), false),
            ],
        )?;
        write_planes(
            &file(&sc.buffers.motion),
            size,
            vec![
                plane("R", ex, false),
                plane("G", ey, false),
                plane("B", vec![0.0; n], false),
                plane("A", ones(), false),
            ],
        )?;
        let entry = sc.frame_of(number, frame.meta.time, &frame.meta.camera);
        self.sidecar.frames.push(entry);
        Ok(())
    }

    /// Writes the sidecar.
    pub fn finish(self) -> Result<(), ImportError> {
        let path = self.dir.join(SIDECAR);
        let json =
            serde_json::to_vec_pretty(&self.sidecar).map_err(|source| ImportError::Json {
                path: path.clone(),
                source,
            })?;
        fs::write(&path, json).map_err(|e| DumpError::io(&path, e))?;
        Ok(())
    }
}
