//! Render targets and their readback into a [`protocol::Frame`]'s buffers.

use half::f16;

use super::{RenderError, gpu::Gpu};

/// HDR linear color.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// Linear view depth (+inf for sky): the `f32`'s bits (`bitcast` in the
/// shaders). OpenGL cannot render `R32Float`; every backend renders
/// `R32Uint`, and the bytes read back are the same.
pub const LINEAR_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// Motion current → previous, pixels, as the two `f32`s' bits.
pub const MOTION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Uint;
/// Instance id + 1 per pixel (0 = background).
pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// Reversed-Z depth buffer.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Shadow map.
pub const SHADOW_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Every format the renderer needs, with what it needs of it, checked on the
/// adapter before anything is built ([`super::gpu::on_adapter`]).
pub const REQUIRED_FORMATS: [(
    wgpu::TextureFormat,
    wgpu::TextureUsages,
    wgpu::TextureFormatFeatureFlags,
    &str,
); 5] = {
    use wgpu::TextureFormatFeatureFlags as F;
    use wgpu::TextureUsages as U;
    let target = U::RENDER_ATTACHMENT.union(U::COPY_SRC);
    [
        (COLOR_FORMAT, target, F::BLENDABLE, "the HDR colour target"),
        (
            LINEAR_DEPTH_FORMAT,
            target,
            F::empty(),
            "the linear depth target",
        ),
        (MOTION_FORMAT, target, F::empty(), "the motion target"),
        (ID_FORMAT, target, F::empty(), "the instance id target"),
        (
            SHADOW_FORMAT,
            U::RENDER_ATTACHMENT.union(U::TEXTURE_BINDING),
            F::empty(),
            "the shadow map",
        ),
    ]
};

/// The unpacked outputs of one frame.
pub struct Readback {
    /// HDR color.
    pub color: Vec<[f16; 4]>,
    /// Linear view depth.
    pub depth: Vec<f32>,
    /// Motion current → previous.
    pub motion: Vec<[f32; 2]>,
    /// Instance id + 1 (0 = background).
    pub ids: Vec<u32>,
}

/// The frame's targets at one size.
pub struct Targets {
    /// Width and height.
    pub size: (u32, u32),
    /// Color target.
    pub color: wgpu::Texture,
    /// Linear depth target.
    pub linear_depth: wgpu::Texture,
    /// Motion target.
    pub motion: wgpu::Texture,
    /// Instance id target.
    pub ids: wgpu::Texture,
    /// Depth buffer.
    pub depth: wgpu::Texture,
    readback: [wgpu::Buffer; 4],
}

/// Bytes per row of a readback buffer, padded to wgpu's copy alignment.
fn padded_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let row = width * bytes_per_pixel;
    row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

const BPP: [u32; 4] = [8, 4, 8, 4];

impl Targets {
    /// Checks that targets of `size` fit the device (texture dimension,
    /// readback buffer size).
    pub fn check(gpu: &Gpu, size: (u32, u32)) -> Result<(), RenderError> {
        let what = format!("a {}x{} frame", size.0, size.1);
        gpu.require_texture(&what, size.0, size.1)?;
        let largest = u64::from(padded_row(size.0, 8)) * u64::from(size.1);
        gpu.require_buffer(&format!("the readback of {what}"), largest, false)?;
        Ok(())
    }

    /// Allocates targets of `size` (after [`Targets::check`]).
    pub fn new(gpu: &Gpu, size: (u32, u32)) -> Self {
        let rt = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let readback = BPP.map(|bpp| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: u64::from(padded_row(size.0, bpp)) * u64::from(size.1),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            })
        });
        Self {
            size,
            color: gpu_device::texture_2d(&gpu.device, "color", size, COLOR_FORMAT, rt),
            linear_depth: gpu_device::texture_2d(
                &gpu.device,
                "linear depth",
                size,
                LINEAR_DEPTH_FORMAT,
                rt,
            ),
            motion: gpu_device::texture_2d(&gpu.device, "motion", size, MOTION_FORMAT, rt),
            ids: gpu_device::texture_2d(&gpu.device, "ids", size, ID_FORMAT, rt),
            depth: gpu_device::texture_2d(
                &gpu.device,
                "depth",
                size,
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            ),
            readback,
        }
    }

    /// Records copies of the three outputs into the readback buffers.
    pub fn encode_readback(&self, encoder: &mut wgpu::CommandEncoder) {
        for ((tex, buf), bpp) in [&self.color, &self.linear_depth, &self.motion, &self.ids]
            .into_iter()
            .zip(&self.readback)
            .zip(BPP)
        {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture: tex,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: buf,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded_row(self.size.0, bpp)),
                        rows_per_image: Some(self.size.1),
                    },
                },
                wgpu::Extent3d {
                    width: self.size.0,
                    height: self.size.1,
                    depth_or_array_layers: 1,
                },
            );
        }
    }

    /// Maps the readback buffers (after the copies were submitted) and
    /// unpacks color, linear depth, motion and instance ids.
    pub fn read(&self, gpu: &Gpu) -> Result<Readback, RenderError> {
        for buf in &self.readback {
            buf.map_async(wgpu::MapMode::Read, .., |r| {
                if let Err(e) = r {
                    tracing::error!("readback map failed: {e}");
                }
            });
        }
        gpu.wait()?;
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        let rows = |i: usize, bpp: u32| -> Result<Vec<u8>, RenderError> {
            let view = self.readback[i]
                .get_mapped_range(..)
                .map_err(|e| RenderError::Device(format!("readback: {e:?}")))?;
            let pitch = padded_row(self.size.0, bpp) as usize;
            let row = w * bpp as usize;
            let mut out = Vec::with_capacity(row * h);
            for y in 0..h {
                out.extend_from_slice(&view[y * pitch..y * pitch + row]);
            }
            Ok(out)
        };
        let color_bytes = rows(0, BPP[0])?;
        let depth_bytes = rows(1, BPP[1])?;
        let motion_bytes = rows(2, BPP[2])?;
        let id_bytes = rows(3, BPP[3])?;
        for buf in &self.readback {
            buf.unmap();
        }
        let color = bytemuck::pod_collect_to_vec::<u8, [f16; 4]>(&color_bytes);
        let depth = bytemuck::pod_collect_to_vec::<u8, f32>(&depth_bytes);
        let motion = bytemuck::pod_collect_to_vec::<u8, [f32; 2]>(&motion_bytes);
        let ids = bytemuck::pod_collect_to_vec::<u8, u32>(&id_bytes);
        Ok(Readback {
            color,
            depth,
            motion,
            ids,
        })
    }
}
