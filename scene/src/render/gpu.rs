//! The wgpu device the renderer runs on: the process's adapter
//! ([`gpu_device::adapter`]: `--adapter`, `WGPU_BACKEND`, else Vulkan first,
//! Mesa's lavapipe on this project's machines, and OpenGL as the fallback),
//! checked for every target format before a pipeline is built.

use super::RenderError;
use super::targets::REQUIRED_FORMATS;

/// Device, queue and what was picked; errors are typed, never a panic.
pub type Gpu = gpu_device::Device;

/// Opens the process's adapter for rendering.
pub fn open() -> Result<Gpu, RenderError> {
    on_adapter(&gpu_device::adapter()?)
}

/// Opens `adapter` for rendering, after checking that it can render, blend
/// and copy every target format the renderer uses.
pub fn on_adapter(adapter: &wgpu::Adapter) -> Result<Gpu, RenderError> {
    for (format, usages, flags, what) in REQUIRED_FORMATS {
        gpu_device::require_format(adapter, format, usages, flags, what)?;
    }
    let limits = adapter.limits();
    Ok(gpu_device::Device::open(
        adapter,
        &wgpu::DeviceDescriptor {
            label: Some("renderer"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits {
                max_texture_dimension_2d: limits.max_texture_dimension_2d,
                max_buffer_size: limits.max_buffer_size,
                ..wgpu::Limits::downlevel_defaults()
            },
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        },
    )?)
}
