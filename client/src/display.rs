//! The display transform on the window's GPU (issue 15 §2).
//!
//! Presented frames are linear HDR colour (RGBA `f16`). The window used to
//! receive them display-encoded by the presenting thread
//! ([`protocol::display::display_encode`], then 8-bit RGBA): about 4.5 ms
//! of that thread's time per 640×360 frame, a quarter of a 60 Hz vsync.
//! Here the frame is uploaded as it is (one `Rgba16Float` texture) and one
//! full-screen draw applies the same transform (exposure 1, Reinhard, sRGB;
//! `display.wgsl`, [`WGSL`]) into an 8-bit texture of the frame's size,
//! which the window then scales onto its surface.
//!
//! The CPU function is the reference: every `f16` value goes through both
//! in the test below, within one 8-bit step.

use anyhow::Context;
use half::f16;

/// The WGSL of the transform (`display.wgsl`).
pub const WGSL: &str = include_str!("display.wgsl");

/// The format presented frames are uploaded in (linear RGBA `f16`, as
/// frames carry their colour).
pub const SOURCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The display transform as a render pipeline into one target format.
#[derive(Debug)]
pub struct DisplayPass {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    format: wgpu::TextureFormat,
}

/// One frame's textures on the device: its linear colour, bound for the
/// pass, and the display-encoded image the pass draws.
#[derive(Debug)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    source: wgpu::Texture,
    group: wgpu::BindGroup,
    /// The display-encoded image, in the pass's format (render target,
    /// sampled, copyable).
    pub encoded: wgpu::Texture,
}

impl Image {
    /// The linear colour the pass reads (`SOURCE_FORMAT`, copy
    /// destination): a generator on the same device writes its frames
    /// here ([`framegen::FrameGenerator::generate_to`]).
    pub fn source(&self) -> &wgpu::Texture {
        &self.source
    }
}

impl DisplayPass {
    /// The pass into `format`, an 8-bit colour format: an sRGB one applies
    /// the OETF itself as it stores, so the shader leaves it out there.
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("display transform"),
            entries: &[image_entry(0, false)],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("display transform"),
            source: wgpu::ShaderSource::Wgsl(WGSL.into()),
        });
        // An sRGB target applies the OETF itself as it stores.
        let fragment = if format.is_srgb() {
            "fs_linear"
        } else {
            "fs_encoded"
        };
        let pipeline = full_screen(
            device,
            "display transform",
            &module,
            &layout,
            fragment,
            format,
        );
        Self {
            layout,
            pipeline,
            format,
        }
    }

    /// The textures of a `width × height` frame.
    pub fn image(&self, device: &wgpu::Device, width: u32, height: u32) -> Image {
        let texture = |label, format, usage| {
            gpu_device::texture_2d(device, label, (width, height), format, usage)
        };
        let source = texture(
            "presented frame (linear)",
            SOURCE_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        let encoded = texture(
            "presented frame (display-encoded)",
            self.format,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let view = source.create_view(&Default::default());
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("display transform"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(&view),
            }],
        });
        Image {
            width,
            height,
            source,
            group,
            encoded,
        }
    }

    /// Writes a frame's linear colour (`width × height` pixels, row-major)
    /// into `image`'s source; a colour of another length is refused.
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        image: &Image,
        color: &[[f16; 4]],
    ) -> anyhow::Result<()> {
        let pixels = u64::from(image.width) * u64::from(image.height);
        anyhow::ensure!(
            color.len() as u64 == pixels,
            "a frame of {} pixels for a {}x{} image",
            color.len(),
            image.width,
            image.height
        );
        queue.write_texture(
            image.source.as_image_copy(),
            bytemuck::cast_slice(color),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(
                    image
                        .width
                        .checked_mul(8)
                        .context("a frame row too wide to upload")?,
                ),
                rows_per_image: Some(image.height),
            },
            image.source.size(),
        );
        Ok(())
    }

    /// Records the transform of `image`'s source into its encoded image.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, image: &Image) {
        let view = image.encoded.create_view(&Default::default());
        let mut pass = begin(encoder, &view);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &image.group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The layout entry of a 2D float texture that fragments read at
/// `binding` (`filterable` where a filtering sampler samples it).
pub(crate) fn image_entry(binding: u32, filterable: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// A render pipeline of one full-screen triangle (`vs` in `module`, the
/// fragment entry `fragment`) into one target of `format`, its only bind
/// group laid out by `layout`: the display transform, the window's blit.
pub(crate) fn full_screen(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    fragment: &str,
    format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fragment),
            compilation_options: Default::default(),
            targets: &[Some(format.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A render pass into `view`, cleared to black first.
pub(crate) fn begin<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    view: &'a wgpu::TextureView,
) -> wgpu::RenderPass<'a> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("full screen"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `f16` value, through the shader into both kinds of target
    /// (the shader's OETF into UNORM, the hardware's into sRGB), lands
    /// within one 8-bit step of the CPU reference (`pow` and the sRGB
    /// store round on their own); NaN, infinities and negatives included.
    #[test]
    fn every_f16_value_is_encoded_as_the_reference_encodes_it() {
        let adapter = gpu_device::adapter().expect("an adapter (lavapipe here)");
        let gpu = gpu_device::Device::open(&adapter, &Default::default()).unwrap();
        // 256 × 256 pixels: red takes every bit pattern in order, green
        // the same with the sign flipped, blue shifted by a prime.
        let (w, h) = (256u32, 256u32);
        let color: Vec<[f16; 4]> = (0..w * h)
            .map(|i| {
                let bits = i as u16;
                [
                    f16::from_bits(bits),
                    f16::from_bits(bits ^ 0x8000),
                    f16::from_bits(bits.wrapping_add(12_347)),
                    f16::from_bits(bits.rotate_left(5)),
                ]
            })
            .collect();
        let reference = protocol::display::display_encode(w, h, &color)
            .unwrap()
            .to_rgb8();
        for format in [
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        ] {
            let pass = DisplayPass::new(&gpu.device, format);
            let image = pass.image(&gpu.device, w, h);
            pass.upload(&gpu.queue, &image, &color).unwrap();
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            pass.encode(&mut encoder, &image);
            gpu.queue.submit([encoder.finish()]);
            let got = gpu.read_texture(&image.encoded).unwrap();
            gpu.check("the display transform").unwrap();
            let mut worst = 0;
            for (i, (px, want)) in got
                .chunks_exact(4)
                .zip(reference.chunks_exact(3))
                .enumerate()
            {
                for c in 0..3 {
                    let d = px[c].abs_diff(want[c]);
                    assert!(
                        d <= 1,
                        "{format:?}: pixel {i} channel {c} ({:?}): {} against {}",
                        color[i][c],
                        px[c],
                        want[c]
                    );
                    worst = worst.max(d);
                }
                assert_eq!(px[3], 255, "{format:?}: opaque");
            }
            // Not all black or one colour: the comparison compared something.
            assert!(
                got.chunks_exact(4).any(|p| p[0] == 255) && got.chunks_exact(4).any(|p| p[0] == 0)
            );
            tracing::debug!(?format, worst, "display transform");
        }
    }

    #[test]
    fn a_colour_of_another_size_is_refused() {
        let adapter = gpu_device::adapter().expect("an adapter (lavapipe here)");
        let gpu = gpu_device::Device::open(&adapter, &Default::default()).unwrap();
        let pass = DisplayPass::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
        let image = pass.image(&gpu.device, 4, 2);
        let err = pass
            .upload(&gpu.queue, &image, &[[f16::ONE; 4]; 7])
            .unwrap_err();
        assert!(err.to_string().contains("7 pixels"), "{err}");
    }
}
