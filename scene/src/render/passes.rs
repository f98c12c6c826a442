//! Pipeline creation for each pass. Which passes exist is decided by the
//! scene's effects ([`super::plan`]); a pass that is not planned is never
//! built, so its shader is never compiled.

use super::targets::{
    COLOR_FORMAT, DEPTH_FORMAT, ID_FORMAT, LINEAR_DEPTH_FORMAT, MOTION_FORMAT, SHADOW_FORMAT,
};
use crate::mesh::Vertex;

/// Bind group layouts shared by the passes.
pub struct Layouts {
    /// group(0): frame uniforms.
    pub frame: wgpu::BindGroupLayout,
    /// group(1): object uniforms, dynamic offset.
    pub object: wgpu::BindGroupLayout,
    /// group(2): shadow map + comparison sampler.
    pub shadow: wgpu::BindGroupLayout,
}

impl Layouts {
    /// Creates the layouts.
    pub fn new(device: &wgpu::Device) -> Self {
        let uniform = |dynamic: bool| wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: dynamic,
                min_binding_size: None,
            },
            count: None,
        };
        let frame = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &[uniform(false)],
        });
        let object = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object"),
            entries: &[uniform(true)],
        });
        let shadow = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shadow map"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                    count: None,
                },
            ],
        });
        Self {
            frame,
            object,
            shadow,
        }
    }
}

const COMMON: &str = include_str!("common.wgsl");

/// A pass's shader: `common.wgsl`, the pass's WGSL, and the Rust constants
/// the WGSL needs (`SHADOW_MAP_MAX`: the receiver's shadow biases were set
/// for the largest map and grow with the texel).
fn module(device: &wgpu::Device, label: &str, pass_source: &str) -> wgpu::ShaderModule {
    let constants = format!("const SHADOW_MAP_MAX: f32 = {}.0;", super::SHADOW_MAP_MAX);
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(format!("{constants}\n{COMMON}\n{pass_source}").into()),
    })
}

fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRS: [wgpu::VertexAttribute; 3] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2];
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRS,
    }
}

fn gbuffer_targets(blend_color: bool) -> [Option<wgpu::ColorTargetState>; 4] {
    let masked = |format| {
        Some(wgpu::ColorTargetState {
            format,
            blend: None,
            write_mask: if blend_color {
                wgpu::ColorWrites::empty()
            } else {
                wgpu::ColorWrites::ALL
            },
        })
    };
    [
        Some(wgpu::ColorTargetState {
            format: COLOR_FORMAT,
            blend: blend_color.then_some(wgpu::BlendState::ALPHA_BLENDING),
            write_mask: wgpu::ColorWrites::ALL,
        }),
        masked(LINEAR_DEPTH_FORMAT),
        masked(MOTION_FORMAT),
        masked(ID_FORMAT),
    ]
}

/// What differs between the passes' pipelines; [`build`] does the rest.
struct PipelineSpec<'a> {
    label: &'a str,
    /// The pass's WGSL (appended to `common.wgsl`).
    source: &'a str,
    groups: &'a [&'a wgpu::BindGroupLayout],
    vertex_entry: &'a str,
    /// Whether the pass reads mesh vertices (the background does not).
    mesh_vertices: bool,
    depth: wgpu::DepthStencilState,
    /// Fragment entry point and color targets; none for depth-only passes.
    fragment: Option<(&'a str, [Option<wgpu::ColorTargetState>; 4])>,
}

fn build(device: &wgpu::Device, spec: PipelineSpec<'_>) -> wgpu::RenderPipeline {
    let shader = module(device, spec.label, spec.source);
    let groups: Vec<Option<&wgpu::BindGroupLayout>> =
        spec.groups.iter().map(|g| Some(*g)).collect();
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(spec.label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    let buffers = [Some(vertex_layout())];
    let targets;
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(spec.label),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some(spec.vertex_entry),
            compilation_options: Default::default(),
            buffers: if spec.mesh_vertices { &buffers } else { &[] },
        },
        // Planes and thin geometry are seen from both sides.
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(spec.depth),
        multisample: Default::default(),
        fragment: match spec.fragment {
            Some((entry, t)) => {
                targets = t;
                Some(wgpu::FragmentState {
                    module: &shader,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &targets,
                })
            }
            None => None,
        },
        multiview_mask: None,
        cache: None,
    })
}

fn depth(
    format: wgpu::TextureFormat,
    write: bool,
    compare: wgpu::CompareFunction,
    bias: wgpu::DepthBiasState,
) -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format,
        depth_write_enabled: Some(write),
        depth_compare: Some(compare),
        stencil: Default::default(),
        bias,
    }
}

/// Opaque or translucent surfaces (`surface.wgsl`). Reversed Z: nearer is
/// greater; translucent surfaces test against the opaque depth but do not
/// write it.
pub fn surface(
    device: &wgpu::Device,
    layouts: &Layouts,
    translucent: bool,
) -> wgpu::RenderPipeline {
    build(
        device,
        PipelineSpec {
            label: if translucent { "translucent" } else { "opaque" },
            source: include_str!("surface.wgsl"),
            groups: &[&layouts.frame, &layouts.object, &layouts.shadow],
            vertex_entry: "vs_surface",
            mesh_vertices: true,
            depth: depth(
                DEPTH_FORMAT,
                !translucent,
                wgpu::CompareFunction::Greater,
                Default::default(),
            ),
            fragment: Some((
                if translucent {
                    "fs_translucent"
                } else {
                    "fs_opaque"
                },
                gbuffer_targets(translucent),
            )),
        },
    )
}

/// The background pass (`background.wgsl`): a fullscreen triangle at the
/// far plane that passes only where no geometry wrote depth.
pub fn background(device: &wgpu::Device, layouts: &Layouts) -> wgpu::RenderPipeline {
    build(
        device,
        PipelineSpec {
            label: "background",
            source: include_str!("background.wgsl"),
            groups: &[&layouts.frame],
            vertex_entry: "vs_fullscreen",
            mesh_vertices: false,
            depth: depth(
                DEPTH_FORMAT,
                false,
                wgpu::CompareFunction::Equal,
                Default::default(),
            ),
            fragment: Some(("fs_background", gbuffer_targets(false))),
        },
    )
}

/// The shadow map pass (`shadow.wgsl`): depth only, standard Z, with slope
/// bias against acne.
pub fn shadow(device: &wgpu::Device, layouts: &Layouts) -> wgpu::RenderPipeline {
    build(
        device,
        PipelineSpec {
            label: "shadow",
            source: include_str!("shadow.wgsl"),
            groups: &[&layouts.frame, &layouts.object],
            vertex_entry: "vs_shadow",
            mesh_vertices: true,
            depth: depth(
                SHADOW_FORMAT,
                true,
                wgpu::CompareFunction::Less,
                wgpu::DepthBiasState {
                    constant: 2,
                    slope_scale: 2.0,
                    clamp: 0.0,
                },
            ),
            fragment: None,
        },
    )
}
