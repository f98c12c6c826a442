//! Pipeline creation for each pass. Which passes exist is decided by the
//! scene's effects ([`super::plan`]); a pass that is not planned is never
//! built, so its shader is never compiled.

use super::targets::{
    COLOR_FORMAT, DEPTH_FORMAT, ID_FORMAT, LINEAR_DEPTH_FORMAT, MOTION_FORMAT, SHADOW_FORMAT,
};
use crate::scene::mesh::Vertex;

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

fn module(device: &wgpu::Device, label: &str, pass_source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(format!("{COMMON}\n{pass_source}").into()),
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

/// Opaque or translucent surfaces (`surface.wgsl`).
pub fn surface(
    device: &wgpu::Device,
    layouts: &Layouts,
    translucent: bool,
) -> wgpu::RenderPipeline {
    let label = if translucent { "translucent" } else { "opaque" };
    let shader = module(device, label, include_str!("surface.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[
            Some(&layouts.frame),
            Some(&layouts.object),
            Some(&layouts.shadow),
        ],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_surface"),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
        },
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(!translucent),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some(if translucent {
                "fs_translucent"
            } else {
                "fs_opaque"
            }),
            compilation_options: Default::default(),
            targets: &gbuffer_targets(translucent),
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The background pass (`background.wgsl`).
pub fn background(device: &wgpu::Device, layouts: &Layouts) -> wgpu::RenderPipeline {
    let shader = module(device, "background", include_str!("background.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("background"),
        bind_group_layouts: &[Some(&layouts.frame)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("background"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_fullscreen"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: Default::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(false),
            depth_compare: Some(wgpu::CompareFunction::Equal),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_background"),
            compilation_options: Default::default(),
            targets: &gbuffer_targets(false),
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The shadow map pass (`shadow.wgsl`).
pub fn shadow(device: &wgpu::Device, layouts: &Layouts) -> wgpu::RenderPipeline {
    let shader = module(device, "shadow", include_str!("shadow.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("shadow"),
        bind_group_layouts: &[Some(&layouts.frame), Some(&layouts.object)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("shadow"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_shadow"),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
        },
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: SHADOW_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: wgpu::DepthBiasState {
                constant: 2,
                slope_scale: 2.0,
                clamp: 0.0,
            },
        }),
        multisample: Default::default(),
        fragment: None,
        multiview_mask: None,
        cache: None,
    })
}
