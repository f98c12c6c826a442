//! The wgpu device the renderer runs on. On this project's machines that is
//! Mesa's lavapipe (software Vulkan); any adapter wgpu finds works. Backends
//! follow wgpu's environment variables (`WGPU_BACKEND`, …).

use super::RenderError;

/// Device, queue and what was picked.
#[derive(Debug)]
pub struct Gpu {
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter_info: wgpu::AdapterInfo,
}

impl Gpu {
    /// Opens a GPU adapter. Without `WGPU_BACKEND` set, Vulkan is preferred
    /// (lavapipe here: the GL backend cannot copy every texture format) and
    /// any other backend is the fallback.
    pub fn new() -> Result<Self, RenderError> {
        let request = |desc: wgpu::InstanceDescriptor| {
            let instance = wgpu::Instance::new(desc);
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
                apply_limit_buckets: false,
            }))
        };
        let from_env = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        let adapter = if std::env::var_os("WGPU_BACKEND").is_some() {
            request(from_env)
        } else {
            let mut vulkan = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
            vulkan.backends = wgpu::Backends::VULKAN;
            request(vulkan).or_else(|_| request(from_env))
        }
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let adapter_info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("renderer"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits {
                max_texture_dimension_2d: limits.max_texture_dimension_2d,
                ..wgpu::Limits::downlevel_defaults()
            },
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| RenderError::Device(e.to_string()))?;
        tracing::debug!(adapter = %adapter_info.name, backend = ?adapter_info.backend, "GPU ready");
        Ok(Self {
            device,
            queue,
            adapter_info,
        })
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) -> Result<(), RenderError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: None,
            })
            .map(|_| ())
            .map_err(|e| RenderError::Device(e.to_string()))
    }
}
