//! Scenes and the renderer that draws them, with no networking: used by the
//! streaming host (`host`), the `server` binary's `record`, and the client's
//! `eval` and demo.
//!
//! Scene files (DESIGN §10): camera path, objects and their animation,
//! materials, lights, and the **effects the scene needs**. Scenes are RON
//! files in `scene/scenes/`; the built-in ones are embedded in the binary
//! ([`builtin`]). [`render`] is the wgpu forward renderer (colour, linear
//! depth, motion), building only the passes a scene's effects need.
//!
//! Animation is a pure function of time: [`Scene::evaluate`] gives the
//! camera, every object transform and every light at any `t`, so frame `k` at
//! any fps is reproducible. All positions are `f64`; a scene's `origin`
//! shifts the whole world (huge-coordinate scenes place it around 1e5).

pub mod animation;
pub mod builtin;
pub mod camera_path;
pub mod mesh;
pub mod render;

use std::collections::{BTreeMap, BTreeSet};

use glam::{DMat4, DQuat, DVec3};
use serde::{Deserialize, Serialize};

pub use animation::Animation;
pub use camera_path::{CameraPath, CameraSpec};
pub use mesh::MeshSpec;

/// An effect a scene needs. The renderer builds only the passes these call
/// for (see `render::passes`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// Shadow map from the first shadow-casting directional or spot light.
    Shadows,
    /// Lights animate (shadows and shading move on static geometry).
    MovingLights,
    /// Blinn-Phong specular highlights.
    Specular,
    /// Alpha-blended objects (a blending pass after the opaque one).
    Translucency,
    /// A procedural sky (gradient and sun) instead of a flat background.
    Sky,
}

impl Effect {
    /// Every effect.
    pub const ALL: [Effect; 5] = [
        Effect::Shadows,
        Effect::MovingLights,
        Effect::Specular,
        Effect::Translucency,
        Effect::Sky,
    ];
}

/// A procedural texture, evaluated in the shader from the mesh UVs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Texture {
    /// Plain albedo.
    #[default]
    None,
    /// Checkerboard with `scale` squares per UV unit.
    Checker {
        /// Squares per UV unit.
        scale: f32,
        /// 0 = flat, 1 = black and white.
        contrast: f32,
    },
    /// Stripes along U.
    Stripes {
        /// Stripes per UV unit.
        scale: f32,
        /// 0 = flat, 1 = full.
        contrast: f32,
    },
    /// Value noise, high frequency.
    Noise {
        /// Cells per UV unit.
        scale: f32,
        /// 0 = flat, 1 = full.
        contrast: f32,
    },
    /// Thin grid lines.
    Grid {
        /// Cells per UV unit.
        scale: f32,
        /// Line width as a fraction of a cell.
        line: f32,
    },
}

/// Surface appearance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Linear base color.
    pub albedo: [f32; 3],
    /// Procedural pattern modulating the albedo.
    #[serde(default)]
    pub texture: Texture,
    /// 0 = mirror-like, 1 = fully rough.
    #[serde(default = "default_roughness")]
    pub roughness: f32,
    /// Specular strength (used only with the `specular` effect).
    #[serde(default)]
    pub specular: f32,
    /// Emitted linear radiance.
    #[serde(default)]
    pub emissive: [f32; 3],
    /// Opacity; below 1 needs the `translucency` effect.
    #[serde(default = "one")]
    pub alpha: f32,
}

fn default_roughness() -> f32 {
    0.8
}

fn one() -> f32 {
    1.0
}

fn unit_scale() -> [f64; 3] {
    [1.0; 3]
}

/// Placement of an object before its animation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// Position relative to the scene origin.
    #[serde(default)]
    pub position: [f64; 3],
    /// Euler angles in degrees, applied X then Y then Z.
    #[serde(default)]
    pub rotation_deg: [f64; 3],
    /// Per-axis scale.
    #[serde(default = "unit_scale")]
    pub scale: [f64; 3],
}

impl Default for Transform {
    fn default() -> Self {
        Self {
            position: [0.0; 3],
            rotation_deg: [0.0; 3],
            scale: [1.0; 3],
        }
    }
}

impl Transform {
    /// The local → parent matrix.
    pub fn matrix(&self) -> DMat4 {
        let [rx, ry, rz] = self.rotation_deg.map(f64::to_radians);
        let rotation = DQuat::from_euler(glam::EulerRot::ZYX, rz, ry, rx);
        DMat4::from_scale_rotation_translation(
            DVec3::from(self.scale),
            rotation,
            DVec3::from(self.position),
        )
    }
}

/// Copies of an object on a grid (fences, rows of pillars).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Repeat {
    /// Copies along x, y, z (each ≥ 1).
    pub count: [u32; 3],
    /// Distance between copies along x, y, z.
    pub spacing: [f64; 3],
}

/// Something drawn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Object {
    /// Name for errors and `server info`.
    pub name: String,
    /// Geometry.
    pub mesh: MeshSpec,
    /// Key into the scene's materials.
    pub material: String,
    /// Placement before animation.
    #[serde(default)]
    pub transform: Transform,
    /// Animations, applied in order after the transform.
    #[serde(default)]
    pub animation: Vec<Animation>,
    /// Optional grid of copies.
    #[serde(default)]
    pub repeat: Option<Repeat>,
}

/// How a light moves over time (needs the `moving_lights` effect).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum LightMotion {
    /// The light's position circles `center` in the XZ plane.
    Orbit {
        /// Circle centre.
        center: [f64; 3],
        /// Circle radius.
        radius: f64,
        /// Seconds per turn.
        period_s: f64,
    },
    /// The light's direction turns about the world Y axis.
    Sweep {
        /// Degrees per second.
        deg_per_s: f64,
    },
}

/// Kinds of light.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum LightKind {
    /// Sun-like: parallel rays along `direction`.
    Directional {
        /// Direction the light travels.
        direction: [f64; 3],
    },
    /// Omnidirectional with inverse-square falloff (no shadows).
    Point {
        /// Position relative to the scene origin.
        position: [f64; 3],
    },
    /// A cone from `position` along `direction`.
    Spot {
        /// Position relative to the scene origin.
        position: [f64; 3],
        /// Cone axis.
        direction: [f64; 3],
        /// Half-angle of the cone in degrees.
        angle_deg: f64,
    },
}

/// A light.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Light {
    /// Geometry of the light.
    pub kind: LightKind,
    /// Linear color.
    #[serde(default = "white")]
    pub color: [f32; 3],
    /// Radiometric scale.
    #[serde(default = "one")]
    pub intensity: f32,
    /// Whether it casts the shadow map (first such light only).
    #[serde(default = "yes")]
    pub shadows: bool,
    /// Optional animation.
    #[serde(default)]
    pub motion: Option<LightMotion>,
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

fn yes() -> bool {
    true
}

/// The background.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sky {
    /// Radiance straight up (with the `sky` effect).
    pub zenith: [f32; 3],
    /// Radiance at the horizon (with the `sky` effect).
    pub horizon: [f32; 3],
    /// Flat background radiance without the `sky` effect.
    #[serde(default)]
    pub flat: [f32; 3],
    /// Sun disc radiance, drawn in the direction of the first directional
    /// light (with the `sky` effect).
    #[serde(default)]
    pub sun: [f32; 3],
}

impl Default for Sky {
    fn default() -> Self {
        Self {
            zenith: [0.15, 0.3, 0.8],
            horizon: [0.7, 0.8, 0.95],
            flat: [0.05; 3],
            sun: [20.0, 18.0, 15.0],
        }
    }
}

/// A whole scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Short name.
    pub name: String,
    /// What the scene is for (which challenge it stresses).
    #[serde(default)]
    pub description: String,
    /// The effects it needs.
    pub effects: BTreeSet<Effect>,
    /// World offset added to every position (camera, objects, lights).
    #[serde(default)]
    pub origin: [f64; 3],
    /// The camera and its path.
    pub camera: CameraSpec,
    /// Named materials.
    pub materials: BTreeMap<String, Material>,
    /// The objects.
    pub objects: Vec<Object>,
    /// The lights.
    #[serde(default)]
    pub lights: Vec<Light>,
    /// The background.
    #[serde(default)]
    pub sky: Sky,
    /// Ambient radiance added to every surface.
    #[serde(default)]
    pub ambient: [f32; 3],
}

/// A scene file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file is not valid RON for a scene. The message names the field.
    #[error("{source_name}:{line}:{col}: {message}")]
    Parse {
        /// File name or `builtin:NAME`.
        source_name: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// What is wrong, from the parser.
        message: String,
    },
    /// The file parses but a value is wrong.
    #[error("{source_name}:{line}: {field}: {message}")]
    Invalid {
        /// File name or `builtin:NAME`.
        source_name: String,
        /// Best-effort 1-based line of the offending item (0 if unknown).
        line: usize,
        /// Path of the field, e.g. `objects[2].material`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A glTF file could not be loaded.
    #[error("{path}: glTF: {message}")]
    Gltf {
        /// The path.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// No built-in scene of that name.
    #[error("no built-in scene {0:?} (try `server info --list`)")]
    UnknownBuiltin(String),
}

/// A light at one instant, world-space (origin applied).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightState {
    /// The light (for color, intensity, shadows, cone).
    pub light: Light,
    /// World position (point and spot lights).
    pub position: DVec3,
    /// Unit direction the light travels (directional and spot lights).
    pub direction: DVec3,
}

/// Everything that moves, at one instant.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneState {
    /// Simulation time.
    pub time: f64,
    /// Camera eye and target, world space.
    pub eye: DVec3,
    /// Point the camera looks at.
    pub target: DVec3,
    /// Index of the camera shot (changes at a cut).
    pub shot: usize,
    /// Local → world matrix of every drawn instance, in the order of
    /// [`Scene::instances`].
    pub models: Vec<DMat4>,
    /// Every light.
    pub lights: Vec<LightState>,
}

/// One drawn copy of an object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into [`Scene::objects`].
    pub object: usize,
    /// Offset of this copy (from [`Repeat`]).
    pub offset: DVec3,
}

impl Scene {
    /// Parses and validates a scene from RON text. `source_name` appears in
    /// error messages.
    pub fn from_ron(text: &str, source_name: &str) -> Result<Self, SceneError> {
        let scene: Scene = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
            .from_str(text)
            .map_err(|e| SceneError::Parse {
                source_name: source_name.to_owned(),
                line: e.span.start.line,
                col: e.span.start.col,
                message: e.code.to_string(),
            })?;
        scene
            .validate()
            .map_err(|(field, message, needle)| SceneError::Invalid {
                source_name: source_name.to_owned(),
                line: needle.and_then(|n| line_of(text, &n)).unwrap_or(0),
                field,
                message,
            })?;
        Ok(scene)
    }

    /// Loads a scene: `builtin:NAME` or a path to a RON file.
    pub fn load(spec: &str) -> Result<Self, SceneError> {
        if let Some(name) = spec.strip_prefix("builtin:") {
            let text =
                builtin::source(name).ok_or_else(|| SceneError::UnknownBuiltin(name.to_owned()))?;
            return Self::from_ron(text, spec);
        }
        let text = std::fs::read_to_string(spec).map_err(|source| SceneError::Io {
            path: spec.to_owned(),
            source,
        })?;
        Self::from_ron(&text, spec)
    }

    /// Whether the scene needs `effect`.
    pub fn has(&self, effect: Effect) -> bool {
        self.effects.contains(&effect)
    }

    /// What a stream of this scene does, for the client's generation plan
    /// (issue 17): an object with an animation is dynamic; shading moves
    /// over surfaces where a light moves, or where shadows fall from
    /// dynamic objects. Specular highlights also slide with the camera, but
    /// shading correction gains nothing on them (`translucent` scores the
    /// same with it and without it), so they do not count.
    pub fn stream_effects(&self) -> protocol::Effects {
        let dynamic_objects = self.objects.iter().any(|o| !o.animation.is_empty());
        protocol::Effects {
            dynamic_objects,
            moving_shading: self.has(Effect::MovingLights)
                || (self.has(Effect::Shadows) && dynamic_objects),
        }
    }

    /// Every drawn instance (objects expanded by their [`Repeat`]).
    pub fn instances(&self) -> Vec<Instance> {
        let mut out = Vec::new();
        for (object, o) in self.objects.iter().enumerate() {
            let (count, spacing) = o
                .repeat
                .map_or(([1, 1, 1], [0.0; 3]), |r| (r.count, r.spacing));
            for x in 0..count[0] {
                for y in 0..count[1] {
                    for z in 0..count[2] {
                        let offset = DVec3::new(
                            f64::from(x) * spacing[0],
                            f64::from(y) * spacing[1],
                            f64::from(z) * spacing[2],
                        );
                        out.push(Instance { object, offset });
                    }
                }
            }
        }
        out
    }

    /// The world offset.
    pub fn origin(&self) -> DVec3 {
        DVec3::from(self.origin)
    }

    /// The state of everything at time `t`.
    pub fn evaluate(&self, t: f64) -> SceneState {
        let origin = self.origin();
        let (eye, target, shot) = self.camera.eye_target(t);
        let models = self
            .instances()
            .iter()
            .map(|inst| {
                let o = &self.objects[inst.object];
                let local = DMat4::from_translation(inst.offset) * o.transform.matrix();
                let animated = animation::apply(&o.animation, t, local);
                DMat4::from_translation(origin) * animated
            })
            .collect();
        let lights = self
            .lights
            .iter()
            .map(|l| light_state(l, t, origin, self.has(Effect::MovingLights)))
            .collect();
        SceneState {
            time: t,
            eye: eye + origin,
            target: target + origin,
            shot,
            models,
            lights,
        }
    }

    /// Checks everything serde cannot: references, ranges, and that the
    /// declared effects match what the scene uses. Errors carry the field
    /// path and a string to locate the line.
    fn validate(&self) -> Result<(), (String, String, Option<String>)> {
        let err =
            |field: String, message: String, needle: Option<String>| Err((field, message, needle));
        if !self.origin.iter().all(|v| v.is_finite()) {
            return err(
                "origin".into(),
                "must be finite".into(),
                Some("origin".into()),
            );
        }
        self.camera
            .validate()
            .map_err(|(f, m)| (format!("camera.{f}"), m, Some("camera".into())))?;
        for (name, m) in &self.materials {
            let field = format!("materials[{name:?}]");
            let needle = Some(format!("\"{name}\""));
            let nums =
                m.albedo
                    .iter()
                    .chain(&m.emissive)
                    .chain([&m.roughness, &m.specular, &m.alpha]);
            if nums.clone().any(|v| !v.is_finite() || *v < 0.0) {
                return err(field, "values must be finite and ≥ 0".into(), needle);
            }
            if m.alpha > 1.0 {
                return err(field + ".alpha", "must be in [0, 1]".into(), needle);
            }
            if m.alpha < 1.0 && !self.has(Effect::Translucency) {
                return err(
                    field + ".alpha",
                    "alpha < 1 needs the `translucency` effect".into(),
                    needle,
                );
            }
        }
        for (i, o) in self.objects.iter().enumerate() {
            let field = format!("objects[{i}] ({})", o.name);
            let needle = Some(format!("\"{}\"", o.name));
            if !self.materials.contains_key(&o.material) {
                return err(
                    field + ".material",
                    format!("unknown material {:?}", o.material),
                    needle,
                );
            }
            o.mesh
                .validate()
                .map_err(|m| (format!("{field}.mesh"), m, needle.clone()))?;
            let t = &o.transform;
            if !t
                .position
                .iter()
                .chain(&t.rotation_deg)
                .chain(&t.scale)
                .all(|v| v.is_finite())
            {
                return err(field + ".transform", "must be finite".into(), needle);
            }
            for (k, a) in o.animation.iter().enumerate() {
                a.validate()
                    .map_err(|m| (format!("{field}.animation[{k}]"), m, needle.clone()))?;
            }
            if let Some(r) = &o.repeat {
                if r.count.contains(&0)
                    || r.count.iter().map(|&c| u64::from(c)).product::<u64>() > 10_000
                {
                    return err(
                        field + ".repeat.count",
                        "each ≥ 1, at most 10000 copies".into(),
                        needle,
                    );
                }
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            let field = format!("lights[{i}]");
            if l.motion.is_some() && !self.has(Effect::MovingLights) {
                return err(
                    field + ".motion",
                    "an animated light needs the `moving_lights` effect".into(),
                    None,
                );
            }
            if !l
                .color
                .iter()
                .chain([&l.intensity])
                .all(|v| v.is_finite() && *v >= 0.0)
            {
                return err(
                    field,
                    "color and intensity must be finite and ≥ 0".into(),
                    None,
                );
            }
            if let LightKind::Spot { angle_deg, .. } = l.kind {
                if !(angle_deg > 0.0 && angle_deg < 90.0) {
                    return err(field + ".kind.angle_deg", "must be in (0, 90)".into(), None);
                }
            }
        }
        if self.has(Effect::MovingLights) && self.lights.iter().all(|l| l.motion.is_none()) {
            return err(
                "effects".into(),
                "`moving_lights` is declared but no light has a motion".into(),
                Some("effects".into()),
            );
        }
        if self.has(Effect::Shadows) && !self.lights.iter().any(casts_shadow) {
            return err(
                "effects".into(),
                "`shadows` needs a directional or spot light with shadows: true".into(),
                Some("effects".into()),
            );
        }
        Ok(())
    }
}

/// Whether a light can cast the shadow map.
pub fn casts_shadow(l: &Light) -> bool {
    l.shadows && !matches!(l.kind, LightKind::Point { .. })
}

fn light_state(l: &Light, t: f64, origin: DVec3, moving: bool) -> LightState {
    let (mut position, mut direction) = match l.kind {
        LightKind::Directional { direction } => (DVec3::ZERO, DVec3::from(direction)),
        LightKind::Point { position } => (DVec3::from(position), DVec3::NEG_Y),
        LightKind::Spot {
            position,
            direction,
            ..
        } => (DVec3::from(position), DVec3::from(direction)),
    };
    if let (true, Some(m)) = (moving, l.motion) {
        match m {
            LightMotion::Orbit {
                center,
                radius,
                period_s,
            } => {
                let a = std::f64::consts::TAU * t / period_s;
                position =
                    DVec3::from(center) + DVec3::new(a.cos() * radius, 0.0, a.sin() * radius);
            }
            LightMotion::Sweep { deg_per_s } => {
                direction = DQuat::from_rotation_y((deg_per_s * t).to_radians()) * direction;
            }
        }
    }
    LightState {
        light: *l,
        position: position + origin,
        direction: direction.normalize_or(DVec3::NEG_Y),
    }
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> Option<usize> {
    let at = text.find(needle)?;
    Some(text[..at].matches('\n').count() + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"(
        name: "t",
        effects: [shadows],
        camera: (fov_y_deg: 60, path: Static(eye: (0, 2, 5), target: (0, 0, 0))),
        materials: { "grey": (albedo: (0.5, 0.5, 0.5)) },
        objects: [ (name: "floor", mesh: Plane(size: (10, 10)), material: "grey") ],
        lights: [ (kind: Directional(direction: (-1, -2, -1))) ],
    )"#;

    #[test]
    fn minimal_scene_parses_and_evaluates() {
        let s = Scene::from_ron(MINIMAL, "t.ron").unwrap();
        assert!(s.has(Effect::Shadows) && !s.has(Effect::Sky));
        let st = s.evaluate(1.5);
        assert_eq!(st.models.len(), 1);
        assert_eq!(st.eye, DVec3::new(0.0, 2.0, 5.0));
        assert!((st.lights[0].direction.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn errors_name_the_field_and_the_line() {
        let typo = MINIMAL.replace("albedo:", "albedoo:");
        let e = Scene::from_ron(&typo, "t.ron").unwrap_err().to_string();
        assert!(e.starts_with("t.ron:5:"), "{e}");
        assert!(e.contains("albedoo"), "{e}");
        let missing = MINIMAL.replace("material: \"grey\"", "material: \"gray\"");
        let e = Scene::from_ron(&missing, "t.ron").unwrap_err().to_string();
        assert!(
            e.contains("objects[0] (floor).material") && e.contains("t.ron:6:"),
            "{e}"
        );
        let no_light = MINIMAL.replace(
            "lights: [ (kind: Directional(direction: (-1, -2, -1))) ],",
            "",
        );
        let e = Scene::from_ron(&no_light, "t.ron").unwrap_err().to_string();
        assert!(e.contains("effects") && e.contains("shadows"), "{e}");
        let glass = MINIMAL.replace(
            "(albedo: (0.5, 0.5, 0.5))",
            "(albedo: (0.5, 0.5, 0.5), alpha: 0.5)",
        );
        let e = Scene::from_ron(&glass, "t.ron").unwrap_err().to_string();
        assert!(e.contains("translucency"), "{e}");
        let moving = MINIMAL.replace(
            "(kind: Directional(direction: (-1, -2, -1)))",
            "(kind: Directional(direction: (-1, -2, -1)), motion: Sweep(deg_per_s: 10))",
        );
        let e = Scene::from_ron(&moving, "t.ron").unwrap_err().to_string();
        assert!(e.contains("moving_lights"), "{e}");
    }

    #[test]
    fn repeat_expands_instances() {
        let fence = MINIMAL.replace(
            "material: \"grey\") ]",
            "material: \"grey\"), (name: \"rods\", mesh: Rod(length: 1, radius: 0.02), material: \"grey\", repeat: (count: (5, 1, 2), spacing: (0.5, 0, 3))) ]",
        );
        let s = Scene::from_ron(&fence, "t").unwrap();
        let inst = s.instances();
        assert_eq!(inst.len(), 11);
        assert_eq!(inst[10].offset, DVec3::new(2.0, 0.0, 3.0));
    }

    #[test]
    fn origin_shifts_everything() {
        let far = MINIMAL.replace(
            "effects: [shadows],",
            "effects: [shadows], origin: (100000, 0, -100000),",
        );
        let s = Scene::from_ron(&far, "t").unwrap();
        let near = Scene::from_ron(MINIMAL, "t").unwrap();
        let (a, b) = (s.evaluate(0.3), near.evaluate(0.3));
        assert_eq!(a.eye - b.eye, DVec3::new(1e5, 0.0, -1e5));
        assert_eq!(
            a.models[0].w_axis.truncate() - b.models[0].w_axis.truncate(),
            DVec3::new(1e5, 0.0, -1e5)
        );
    }
}
