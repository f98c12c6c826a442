//! The wgpu forward renderer (DESIGN §10): the ground truth every quality
//! measurement compares against. For each frame it outputs HDR linear color,
//! linear view depth (`+inf` for sky), motion vectors current → previous in
//! pixels (from every object's previous-frame transform and the previous
//! camera), and the camera and time.
//!
//! It builds only the passes the scene's effects call for ([`plan`]):
//!
//! | pass          | built when                | writes                          |
//! |---------------|---------------------------|---------------------------------|
//! | `Shadow`      | `shadows`                 | shadow map (`shadow.wgsl`)      |
//! | `Opaque`      | always                    | color, depth, motion (`surface.wgsl`) |
//! | `Background`  | always                    | sky or flat color, +inf, rotation-only motion (`background.wgsl`) |
//! | `Translucent` | `translucency`            | blended color (`surface.wgsl`)  |
//!
//! `specular` and `sky` are shader features of the opaque and background
//! passes; `moving_lights` is data. Positions are camera-relative in `f32`
//! after `f64` math on the CPU, so huge worlds keep sub-pixel motion.

pub mod gpu;
mod passes;
mod targets;
mod uniforms;
pub mod window;

use std::path::Path;
use std::time::Instant;

use glam::{DMat4, DVec3};
use wgpu::util::DeviceExt;

pub use gpu::Gpu;
pub use window::WindowSettings;

use crate::{Effect, Instance, Scene, SceneError, SceneState, mesh::Mesh};
use protocol::frame::ExtraBuffer;
use protocol::{BufferKind, Camera, Frame, FrameMeta, FrameSize, Pose, Projection};
use targets::{SHADOW_FORMAT, Targets};
use uniforms::{FrameInputs, OBJECT_STRIDE};

/// Shadow-map texels a side per pixel of the frame's longer side: 2048 at
/// 1280×720, the size this scale was set at.
pub const SHADOW_TEXELS_PER_PIXEL: f64 = 1.6;

/// The square shadow map's side is a multiple of this and within
/// `SHADOW_MAP_MIN..=SHADOW_MAP_MAX` texels.
const SHADOW_MAP_STEP: u32 = 64;
/// Smallest shadow-map side, texels. The receiver's biases grow with the
/// texel (`surface.wgsl`), and below this they reach several centimetres
/// on the built-in scenes' 60–80 m grounds: contacts leak light, and
/// surfaces that shadow themselves at grazing angles (the inside of
/// `pan`'s centre block, where its camera stands) flip between lit and
/// shadowed.
pub const SHADOW_MAP_MIN: u32 = 1024;
/// Largest shadow-map side, texels.
pub const SHADOW_MAP_MAX: u32 = 2048;

/// Side of the square shadow map for frames of `size`, texels: a fixed
/// density against the frame's pixels ([`SHADOW_TEXELS_PER_PIXEL`] a
/// pixel of the longer side, rounded up to a multiple of 64, within
/// `SHADOW_MAP_MIN..=SHADOW_MAP_MAX`), so a shadow's edge spans about as
/// many pixels at every size, and a small frame does not pay for a large
/// frame's map: the shadow pass's clear and raster of a 2048² map are a
/// large part of a small frame's render on a software rasteriser, and the
/// live demo renders beside the client on one machine.
pub fn shadow_map_side(size: FrameSize) -> u32 {
    let longer = f64::from(size.width.max(size.height));
    let want = (longer * SHADOW_TEXELS_PER_PIXEL / f64::from(SHADOW_MAP_STEP)).ceil();
    // Saturating float-to-int cast; the clamp bounds it either way.
    (want as u32)
        .saturating_mul(SHADOW_MAP_STEP)
        .clamp(SHADOW_MAP_MIN, SHADOW_MAP_MAX)
}

/// A pass of the render graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Pass {
    /// Depth from the shadow-casting light.
    Shadow,
    /// Opaque geometry into color, depth and motion.
    Opaque,
    /// Pixels without geometry: sky or flat color, +inf depth.
    Background,
    /// Alpha-blended geometry, back to front.
    Translucent,
}

/// The passes a scene needs, in execution order.
pub fn plan(scene: &Scene) -> Vec<Pass> {
    let mut passes = Vec::with_capacity(4);
    if scene.has(Effect::Shadows) {
        passes.push(Pass::Shadow);
    }
    passes.push(Pass::Opaque);
    passes.push(Pass::Background);
    if scene.has(Effect::Translucency) {
        passes.push(Pass::Translucent);
    }
    passes
}

/// Why rendering failed.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No usable GPU: no adapter, a target format it cannot render, a frame
    /// too large for it, or an error wgpu reported (never wgpu's panic).
    #[error(transparent)]
    Gpu(#[from] gpu_device::GpuError),
    /// Device creation or a device operation failed.
    #[error("GPU device: {0}")]
    Device(String),
    /// The scene's meshes could not be built.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The requested size is unusable.
    #[error("frame size {0}x{1} is outside 1..={2}")]
    BadSize(u32, u32, u32),
}

struct GpuMesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    count: u32,
    /// Object-space bounding sphere (centre, radius).
    bounds: (DVec3, f64),
}

/// The viewer's cameras for [`Renderer::render_posed`]: the frame's own,
/// the previous frame's (motion vectors lead to it) and the one before that
/// (the previous frame's adaptive window).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewerPoses {
    /// This frame's camera.
    pub now: Pose,
    /// The previous frame's camera.
    pub prev: Pose,
    /// The camera of the frame before the previous one.
    pub before: Pose,
}

/// Renders frames of one scene at one size.
pub struct Renderer {
    gpu: Gpu,
    scene: Scene,
    passes: Vec<Pass>,
    size: FrameSize,
    instances: Vec<Instance>,
    meshes: Vec<GpuMesh>,
    opaque: wgpu::RenderPipeline,
    background: wgpu::RenderPipeline,
    shadow: Option<(wgpu::RenderPipeline, wgpu::Texture)>,
    translucent: Option<wgpu::RenderPipeline>,
    shadow_bind: wgpu::BindGroup,
    shadow_layout: wgpu::BindGroupLayout,
    frame_buffer: wgpu::Buffer,
    frame_bind: wgpu::BindGroup,
    object_buffer: wgpu::Buffer,
    object_bind: wgpu::BindGroup,
    targets: Targets,
    last_ids: Vec<u32>,
    window: WindowSettings,
}

impl Renderer {
    /// Prepares a renderer for `scene` at `size`: GPU, meshes, and the
    /// pipelines of the planned passes only. `base` resolves glTF paths.
    pub fn new(scene: Scene, size: FrameSize, base: &Path) -> Result<Self, RenderError> {
        // The size first: a bad one is an error before any device opens.
        Self::check_size(size)?;
        Self::on(gpu::open()?, scene, size, base)
    }

    /// [`Renderer::new`] on a device the caller opened
    /// ([`gpu::on_adapter`]), e.g. on a given backend.
    pub fn on(gpu: Gpu, scene: Scene, size: FrameSize, base: &Path) -> Result<Self, RenderError> {
        Self::check_size(size)?;
        Targets::check(&gpu, (size.width, size.height))?;
        let scope = gpu.scope("building the renderer");
        let renderer = Self::build(gpu, scene, size, base)?;
        scope.finish()?;
        Ok(renderer)
    }

    fn check_size(size: FrameSize) -> Result<(), RenderError> {
        let max = protocol::Limits::MAX_DIMENSION;
        if size.width == 0 || size.height == 0 || size.width > max || size.height > max {
            return Err(RenderError::BadSize(size.width, size.height, max));
        }
        Ok(())
    }

    fn build(gpu: Gpu, scene: Scene, size: FrameSize, base: &Path) -> Result<Self, RenderError> {
        let device = &gpu.device;
        let passes = plan(&scene);
        let layouts = passes::Layouts::new(device);
        let meshes = scene
            .objects
            .iter()
            .map(|o| Ok(upload(device, &o.mesh.build(base)?)))
            .collect::<Result<Vec<_>, SceneError>>()?;
        let instances = scene.instances();

        let shadow_pipeline = passes
            .contains(&Pass::Shadow)
            .then(|| passes::shadow(device, &layouts));
        let (shadow_map, shadow_bind) = shadow_resources(
            device,
            &layouts.shadow,
            shadow_pipeline.as_ref().map(|_| shadow_map_side(size)),
        );
        let shadow = shadow_pipeline.zip(shadow_map);
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame uniforms"),
            size: std::mem::size_of::<uniforms::FrameGpu>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &layouts.frame,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: frame_buffer.as_entire_binding(),
            }],
        });
        let object_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("object uniforms"),
            size: OBJECT_STRIDE * instances.len().max(1) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let object_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("object"),
            layout: &layouts.object,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &object_buffer,
                    offset: 0,
                    size: std::num::NonZeroU64::new(OBJECT_STRIDE),
                }),
            }],
        });
        let opaque = passes::surface(device, &layouts, false);
        let background = passes::background(device, &layouts);
        let translucent = passes
            .contains(&Pass::Translucent)
            .then(|| passes::surface(device, &layouts, true));
        let targets = Targets::new(&gpu, (size.width, size.height));
        Ok(Self {
            gpu,
            scene,
            passes,
            size,
            instances,
            meshes,
            opaque,
            background,
            shadow,
            translucent,
            shadow_bind,
            shadow_layout: layouts.shadow,
            frame_buffer,
            frame_bind,
            object_buffer,
            object_bind,
            targets,
            last_ids: Vec::new(),
            window: WindowSettings::default(),
        })
    }

    /// The shadow map's side in texels; `None` for a scene without the
    /// shadow pass.
    pub fn shadow_map(&self) -> Option<u32> {
        self.shadow.as_ref().map(|(_, map)| map.width())
    }

    /// Draws the shadow map at `side` texels a side (clamped to 1 and the
    /// device's largest texture) instead of [`shadow_map_side`]'s for the
    /// frame size: e.g. the sharp shadows of a large frame's map in a
    /// small frame. Nothing for a scene without the shadow pass. A map the
    /// device cannot make (out of memory) is an error, and the renderer
    /// keeps the map it had.
    pub fn set_shadow_map(&mut self, side: u32) -> Result<(), RenderError> {
        let Some((_, map)) = &mut self.shadow else {
            return Ok(());
        };
        let device = &self.gpu.device;
        let side = side.clamp(1, device.limits().max_texture_dimension_2d);
        let (new, bind) = self.gpu.checked("making a shadow map", || {
            shadow_resources(device, &self.shadow_layout, Some(side))
        })?;
        if let Some(new) = new {
            *map = new;
            self.shadow_bind = bind;
        }
        Ok(())
    }

    /// Sets the adaptive rendering window (GFFE §4.3); off by default.
    pub fn set_window(&mut self, settings: WindowSettings) {
        self.window = settings;
    }

    /// The window and rendered size for a frame whose camera is `cur` and
    /// whose previous camera pose was `prev`.
    fn window_for(&self, prev: &Pose, cur: &Camera) -> (protocol::Window, FrameSize) {
        let w = window::adaptive_window(&self.window, prev, cur);
        window::snap(self.window.mode, w, self.size)
    }

    /// Instance id + 1 of every pixel of the last rendered frame (0 for the
    /// background); index [`Renderer::instances`] with `id − 1`.
    pub fn last_ids(&self) -> &[u32] {
        &self.last_ids
    }

    /// The drawn instances.
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// The passes this renderer executes, in order.
    pub fn passes(&self) -> &[Pass] {
        &self.passes
    }

    /// The displayed size it renders at (a widened window renders more).
    pub fn size(&self) -> FrameSize {
        self.size
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Adapter name and backend.
    pub fn adapter(&self) -> &wgpu::AdapterInfo {
        &self.gpu.adapter_info
    }

    /// The camera of a scene state.
    pub fn camera(&self, state: &SceneState) -> Camera {
        let spec = &self.scene.camera;
        Camera::new(
            Pose::look_at(state.eye, state.target, DVec3::Y),
            Projection::perspective(
                spec.fov_y_deg.to_radians(),
                f64::from(self.size.width) / f64::from(self.size.height),
                spec.near,
                spec.far.unwrap_or(f64::INFINITY),
            ),
        )
    }

    /// Renders frame `index` of a stream at `fps`: time `index / fps`, with
    /// motion to time `(index − 1) / fps`. Frame 0 and the first frame of a
    /// new camera shot have zero motion and (for a shot) `cut = true`.
    pub fn render(&mut self, index: u64, fps: f64) -> Result<Frame, RenderError> {
        let time = |k: u64| k as f64 / fps;
        self.render_at(
            index,
            time(index),
            time(index.saturating_sub(1)),
            time(index.saturating_sub(2)),
        )
    }

    /// Renders the state at time `t` with motion vectors to the frame at
    /// `prev_t`, whose own predecessor (for its adaptive window) was at
    /// `prev_prev_t`.
    pub fn render_at(
        &mut self,
        index: u64,
        t: f64,
        prev_t: f64,
        prev_prev_t: f64,
    ) -> Result<Frame, RenderError> {
        let scope = self.gpu.scope("rendering a frame");
        let frame = self.render_in_scope(index, [t, prev_t, prev_prev_t], None, None);
        scope.finish()?;
        frame
    }

    /// [`Renderer::render_at`] with the lights and the shadow map of time
    /// `shading_t` (the shadow casters where they were then): the frame at
    /// `t` as it would look had its shading stopped at `shading_t`. What a
    /// perfect shading correction (GFFE §4.4) would have to add to a frame
    /// generated from the one rendered at `shading_t` is the change from
    /// this image to the plain render; `eval`'s shading-oracle row applies
    /// exactly that change.
    pub fn render_shaded_at(
        &mut self,
        index: u64,
        [t, prev_t, prev_prev_t]: [f64; 3],
        shading_t: f64,
    ) -> Result<Frame, RenderError> {
        let scope = self.gpu.scope("rendering a frame");
        let frame = self.render_in_scope(index, [t, prev_t, prev_prev_t], None, Some(shading_t));
        scope.finish()?;
        frame
    }

    /// Renders the scene's state at time `t` (animation stays a function of
    /// time) seen from the viewer's cameras instead of the scene's path
    /// (interactive streaming, issue 20): motion vectors lead to
    /// `poses.prev` at `prev_t`, and the adaptive window is chosen from
    /// `poses.before` → `poses.prev` as for a scripted camera. The scene's
    /// shots do not apply: a frame is never a cut.
    pub fn render_posed(
        &mut self,
        index: u64,
        t: f64,
        prev_t: f64,
        poses: &ViewerPoses,
    ) -> Result<Frame, RenderError> {
        let scope = self.gpu.scope("rendering a frame");
        let frame = self.render_in_scope(index, [t, prev_t, prev_t], Some(poses), None);
        scope.finish()?;
        frame
    }

    fn render_in_scope(
        &mut self,
        index: u64,
        [t, prev_t, prev_prev_t]: [f64; 3],
        given: Option<&ViewerPoses>,
        shading_t: Option<f64>,
    ) -> Result<Frame, RenderError> {
        let started = Instant::now();
        let state = self.scene.evaluate(t);
        // Lights and shadow casters: at `t`, or where they were at the
        // shading time asked for.
        let shading = shading_t.map(|s| self.scene.evaluate(s));
        let lit = shading.as_ref().unwrap_or(&state);
        let mut prev = self.scene.evaluate(prev_t);
        let cut = given.is_none() && prev.shot != state.shot;
        if cut {
            prev = state.clone();
        }
        let mut camera = self.camera(&state);
        let mut prev_camera = self.camera(&prev);
        if let Some(poses) = given {
            camera.pose = poses.now;
            prev_camera.pose = poses.prev;
        }
        // Windows of this and of the previous frame (motion vectors land in
        // the previous frame's pixel grid, which its own window defines).
        let (window, size) = if cut {
            self.window_for(&camera.pose, &camera)
        } else {
            self.window_for(&prev_camera.pose, &camera)
        };
        let (prev_window, prev_size) = if cut {
            (window, size)
        } else {
            let before = match given {
                Some(poses) => poses.before,
                None => {
                    let before_state = self.scene.evaluate(prev_prev_t);
                    if before_state.shot == prev.shot {
                        self.camera(&before_state).pose
                    } else {
                        prev_camera.pose
                    }
                }
            };
            self.window_for(&before, &prev_camera)
        };
        camera.window = window;
        prev_camera.window = prev_window;
        if self.targets.size != (size.width, size.height) {
            Targets::check(&self.gpu, (size.width, size.height))?;
            self.targets = Targets::new(&self.gpu, (size.width, size.height));
        }
        let shadow_from_world = self
            .shadow
            .as_ref()
            .and_then(|_| self.shadow_projection(lit));
        let frame_u = uniforms::frame_uniforms(
            &self.scene,
            &FrameInputs {
                camera: &camera,
                prev_camera: &prev_camera,
                size: (size.width, size.height),
                prev_size: (prev_size.width, prev_size.height),
                lights: &lit.lights,
                shadow_from_world,
            },
        );
        let queue = &self.gpu.queue;
        queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&frame_u));
        let objects = |models: &[DMat4]| -> Vec<uniforms::ObjectGpu> {
            self.instances
                .iter()
                .enumerate()
                .map(|(i, inst)| {
                    let material = &self.scene.materials[&self.scene.objects[inst.object].material];
                    uniforms::object_uniforms(&camera, i, models[i], prev.models[i], material)
                })
                .collect()
        };
        let write_objects = |objects: &[uniforms::ObjectGpu]| {
            if !objects.is_empty() {
                queue.write_buffer(&self.object_buffer, 0, bytemuck::cast_slice(objects));
            }
        };
        // The shadow casters where the shading time has them; written (and
        // the shadow pass submitted) before this frame's own.
        write_objects(&objects(&lit.models));
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        if let (Some((pipeline, map)), true) = (&self.shadow, shadow_from_world.is_some()) {
            let view = map.create_view(&Default::default());
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &self.frame_bind, &[]);
            self.draw(&mut pass, |m| m.alpha >= 1.0);
        }
        if shading.is_some() {
            self.gpu.queue.submit([encoder.finish()]);
            encoder = self.gpu.device.create_command_encoder(&Default::default());
            write_objects(&objects(&state.models));
        }
        {
            let views = [
                &self.targets.color,
                &self.targets.linear_depth,
                &self.targets.motion,
                &self.targets.ids,
            ]
            .map(|t| t.create_view(&Default::default()));
            let depth_view = self.targets.depth.create_view(&Default::default());
            let attachments = views.each_ref().map(|v| {
                Some(wgpu::RenderPassColorAttachment {
                    view: v,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            });
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("main"),
                color_attachments: &attachments,
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            // Opaque.
            pass.set_pipeline(&self.opaque);
            pass.set_bind_group(0, &self.frame_bind, &[]);
            pass.set_bind_group(2, &self.shadow_bind, &[]);
            self.draw(&mut pass, |m| m.alpha >= 1.0);
            // Background: only where no geometry wrote depth.
            pass.set_pipeline(&self.background);
            pass.set_bind_group(0, &self.frame_bind, &[]);
            pass.draw(0..3, 0..1);
            // Translucent, back to front.
            if let Some(pipeline) = &self.translucent {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.frame_bind, &[]);
                pass.set_bind_group(2, &self.shadow_bind, &[]);
                let mut order: Vec<usize> = (0..self.instances.len())
                    .filter(|&i| self.material_of(i).alpha < 1.0)
                    .collect();
                let dist = |i: usize| {
                    (state.models[i].w_axis.truncate() - camera.pose.position).length_squared()
                };
                order.sort_by(|&a, &b| dist(b).total_cmp(&dist(a)));
                for i in order {
                    self.draw_instance(&mut pass, i);
                }
            }
        }
        self.targets.encode_readback(&mut encoder);
        self.gpu.queue.submit([encoder.finish()]);
        let out = self.targets.read(&self.gpu)?;
        // The dynamic mask: 255 where an animated object is visible.
        let mask = out
            .ids
            .iter()
            .map(|&id| {
                let animated = id
                    .checked_sub(1)
                    .and_then(|i| self.instances.get(i as usize))
                    .is_some_and(|inst| !self.scene.objects[inst.object].animation.is_empty());
                if animated { 255 } else { 0 }
            })
            .collect();
        self.last_ids = out.ids;
        Ok(Frame {
            meta: FrameMeta {
                index,
                time: t,
                camera,
                size,
                host_processing: started.elapsed(),
                cut,
            },
            color: out.color,
            depth: out.depth,
            motion: out.motion,
            extras: vec![ExtraBuffer {
                kind: BufferKind::Mask,
                data: mask,
            }],
        })
    }

    fn material_of(&self, instance: usize) -> &crate::Material {
        &self.scene.materials[&self.scene.objects[self.instances[instance].object].material]
    }

    fn draw(&self, pass: &mut wgpu::RenderPass<'_>, keep: impl Fn(&crate::Material) -> bool) {
        for i in 0..self.instances.len() {
            if keep(self.material_of(i)) {
                self.draw_instance(pass, i);
            }
        }
    }

    fn draw_instance(&self, pass: &mut wgpu::RenderPass<'_>, i: usize) {
        let mesh = &self.meshes[self.instances[i].object];
        pass.set_bind_group(1, &self.object_bind, &[(i as u64 * OBJECT_STRIDE) as u32]);
        pass.set_vertex_buffer(0, mesh.vertices.slice(..));
        pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.count, 0, 0..1);
    }

    /// The shadow map projection for the first shadow-casting light, fitted
    /// to the bounding sphere of all opaque instances.
    fn shadow_projection(&self, state: &SceneState) -> Option<DMat4> {
        let light = state
            .lights
            .iter()
            .find(|l| crate::casts_shadow(&l.light))?;
        let spheres: Vec<(DVec3, f64)> = self
            .instances
            .iter()
            .enumerate()
            .map(|(i, inst)| {
                let (c, r) = self.meshes[inst.object].bounds;
                let m = state.models[i];
                let scale = m
                    .x_axis
                    .truncate()
                    .length()
                    .max(m.y_axis.truncate().length())
                    .max(m.z_axis.truncate().length());
                (m.transform_point3(c), r * scale)
            })
            .collect();
        let (lo, hi) = spheres.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), (c, r)| (lo.min(*c - *r), hi.max(*c + *r)),
        );
        let center = (lo + hi) * 0.5;
        let radius = (hi - lo).length() * 0.5;
        Some(uniforms::shadow_from_world(light, center, radius))
    }

    /// The passes whose pipelines were actually built (compiled), which
    /// tests compare with [`plan`].
    pub fn built_pipelines(&self) -> Vec<Pass> {
        let mut built = Vec::with_capacity(4);
        if self.shadow.is_some() {
            built.push(Pass::Shadow);
        }
        built.extend([Pass::Opaque, Pass::Background]);
        if self.translucent.is_some() {
            built.push(Pass::Translucent);
        }
        built
    }
}

/// The shadow map of `side` texels a side (none without a side) and the
/// bind group that samples it. Without a shadow pass the shader never
/// samples the map, but the layout still needs a texture: a 1×1 one.
fn shadow_resources(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    side: Option<u32>,
) -> (Option<wgpu::Texture>, wgpu::BindGroup) {
    let texture = |label, side, usage| {
        gpu_device::texture_2d(device, label, (side, side), SHADOW_FORMAT, usage)
    };
    let map = side.map(|side| {
        texture(
            "shadow map",
            side,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        )
    });
    let view = match &map {
        Some(map) => map.create_view(&Default::default()),
        None => texture("no shadow map", 1, wgpu::TextureUsages::TEXTURE_BINDING)
            .create_view(&Default::default()),
    };
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("shadow"),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        compare: Some(wgpu::CompareFunction::LessEqual),
        ..Default::default()
    });
    let bind = gpu_device::view_and_sampler(device, "shadow map", layout, &view, &sampler);
    (map, bind)
}

fn upload(device: &wgpu::Device, mesh: &Mesh) -> GpuMesh {
    let (lo, hi) = mesh.bounds();
    let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
    GpuMesh {
        vertices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("vertices"),
            contents: bytemuck::cast_slice(&mesh.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        }),
        indices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("indices"),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage: wgpu::BufferUsages::INDEX,
        }),
        count: mesh.indices.len() as u32,
        bounds: ((lo + hi) * 0.5, (hi - lo).length() * 0.5),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shadow_map_keeps_its_density_against_the_frame() {
        let side = |w, h| shadow_map_side(FrameSize::new(w, h));
        // The density was set at 1280×720 with a 2048² map.
        assert_eq!(side(1280, 720), 2048);
        assert_eq!(side(640, 360), 1024);
        // Portrait frames go by their longer side too.
        assert_eq!(side(360, 640), 1024);
        assert_eq!(side(720, 1280), 2048);
        // Rounded up to a multiple of the step, within the bounds.
        assert_eq!(side(960, 540), 1536);
        assert_eq!(side(1000, 10), 1600);
        assert_eq!(side(320, 180), SHADOW_MAP_MIN);
        assert_eq!(side(96, 54), SHADOW_MAP_MIN);
        assert_eq!(side(1, 1), SHADOW_MAP_MIN);
        assert_eq!(side(1920, 1080), SHADOW_MAP_MAX);
        assert_eq!(side(u32::MAX, u32::MAX), SHADOW_MAP_MAX);
    }
}
