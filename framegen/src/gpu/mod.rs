//! The wgpu side shared by every pass: the device, compute kernels built from
//! WGSL with an explicit binding list, storage buffers, dispatch and
//! read-back.
//!
//! Every pass works on plain storage buffers (no textures), so a pass and its
//! CPU reference index the same arrays the same way and can be compared
//! element by element. Shaders are the pass's own `.wgsl` file, prefixed with
//! `common.wgsl` (the camera model and the splat keys).

use std::sync::Arc;

use crate::FramegenError;

/// Threads per workgroup of every 1-D kernel (see `common.wgsl`).
pub const WORKGROUP: u32 = 256;

/// Largest workgroup count along one dispatch dimension (WebGPU's default).
const MAX_GROUPS_X: u32 = 32768;

pub mod pool;
pub mod timestamps;

pub use pool::{Pool, Rec};

/// The WGSL every pass shader is prefixed with (see `common.wgsl`).
pub const COMMON_WGSL: &str = include_str!("common.wgsl");

/// An opened GPU device, shareable between generators (and with a
/// presenter): a [`gpu_device::Device`] (adapter choice, typed errors) with
/// the storage-buffer helpers every pass uses. Its `device`, `queue` and
/// `adapter_info` are the inner device's.
#[derive(Debug)]
pub struct GpuContext {
    gpu: gpu_device::Device,
}

impl std::ops::Deref for GpuContext {
    type Target = gpu_device::Device;

    fn deref(&self) -> &Self::Target {
        &self.gpu
    }
}

impl GpuContext {
    /// Opens the process's adapter ([`gpu_device::adapter`]: `--adapter`,
    /// `WGPU_BACKEND`, else Vulkan first and any other backend as the
    /// fallback).
    pub fn new() -> Result<Arc<Self>, FramegenError> {
        Self::from_adapter(&gpu_device::adapter()?)
    }

    /// Opens a device on an adapter the caller picked (e.g. one compatible
    /// with a window surface). The device gets the adapter's own limits,
    /// because 8192-pixel frames need storage buffers beyond WebGPU's
    /// defaults.
    pub fn from_adapter(adapter: &wgpu::Adapter) -> Result<Arc<Self>, FramegenError> {
        Self::with_limits(adapter, adapter.limits())
    }

    /// Opens a device on `adapter` with `limits` (at most the adapter's):
    /// a device smaller than the adapter, e.g. to check that a frame too
    /// large for it is refused with a typed error naming the limit.
    pub fn with_limits(
        adapter: &wgpu::Adapter,
        limits: wgpu::Limits,
    ) -> Result<Arc<Self>, FramegenError> {
        let gpu = gpu_device::Device::open(
            adapter,
            &wgpu::DeviceDescriptor {
                required_limits: limits,
                ..Self::descriptor(adapter)
            },
        )?;
        Ok(Self::from_device(gpu))
    }

    /// What the generator asks of a device on `adapter`: the adapter's
    /// limits, and timestamp queries where offered (profiling on hardware).
    /// A device opened with it elsewhere (a window's, to present from the
    /// device that generates) serves the generator as one of its own.
    pub fn descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
        wgpu::DeviceDescriptor {
            label: Some("framegen"),
            required_features: adapter.features() & timestamps::FEATURES,
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }
    }

    /// The generator's context on a device opened elsewhere with
    /// [`GpuContext::descriptor`].
    pub fn from_device(gpu: gpu_device::Device) -> Arc<Self> {
        Arc::new(Self { gpu })
    }

    /// Blocks until every submitted command buffer has finished; an error
    /// wgpu reported meanwhile is returned.
    pub fn wait(&self) -> Result<(), FramegenError> {
        Ok(self.gpu.wait()?)
    }

    /// A zeroed storage buffer of `bytes` bytes (at least 4, so empty frames
    /// still bind).
    pub fn storage(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16).next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    /// A storage buffer initialised with `data`.
    pub fn storage_init(&self, label: &str, data: &[u8]) -> wgpu::Buffer {
        let buffer = self.storage(label, data.len() as u64);
        if !data.is_empty() {
            self.queue.write_buffer(&buffer, 0, data);
        }
        buffer
    }

    /// A buffer the GPU copies results into for the CPU to read
    /// ([`GpuContext::map_read`]).
    pub fn staging(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        self.mappable(label, bytes, usage)
    }

    /// A buffer the CPU maps, of at least `bytes` bytes.
    fn mappable(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16).next_multiple_of(wgpu::MAP_ALIGNMENT),
            usage,
            mapped_at_creation: false,
        })
    }

    /// Maps `slice` and waits for it (for the submitted work that uses the
    /// buffer first).
    ///
    /// The executors wait for their own submissions as they make them, so
    /// a buffer they map is idle and its mapping ready at the device's next
    /// check, which does not block. Only a buffer still in use waits for
    /// the whole device: that would also wait for whatever others sharing
    /// it (a window presenting from it) submitted since.
    fn map(&self, slice: &wgpu::BufferSlice<'_>, mode: wgpu::MapMode) -> Result<(), FramegenError> {
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(mode, move |r| {
            let _ = tx.send(r);
        });
        let lost = |e: &dyn std::fmt::Display| FramegenError::Device(e.to_string());
        self.device
            .poll(wgpu::PollType::Poll)
            .map_err(|e| lost(&e))?;
        let mapped = match rx.try_recv() {
            Ok(mapped) => {
                // What waiting would have reported.
                self.gpu.check("submitted work")?;
                mapped
            }
            Err(_) => {
                self.wait()?;
                rx.recv().map_err(|e| lost(&e))?
            }
        };
        mapped.map_err(|e| lost(&e))
    }

    /// Maps the first `len` bytes of a staging buffer whose copies were
    /// submitted, waits for them, and hands the bytes to `read`.
    pub fn map_read<T>(
        &self,
        staging: &wgpu::Buffer,
        len: u64,
        read: impl FnOnce(&[u8]) -> T,
    ) -> Result<T, FramegenError> {
        let slice = staging.slice(..len.next_multiple_of(4));
        self.map(&slice, wgpu::MapMode::Read)?;
        let out = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| FramegenError::Device(format!("read-back: {e:?}")))?;
            read(&view[..len as usize])
        };
        staging.unmap();
        Ok(out)
    }

    /// A buffer the CPU writes into for the GPU to copy from
    /// ([`GpuContext::map_write`]), kept from frame to frame: no staging
    /// memory is allocated per upload.
    pub fn upload_staging(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC;
        self.mappable(label, bytes, usage)
    }

    /// Maps the first `len` bytes of an upload staging buffer (waiting for
    /// the copies that last read it), hands them to `write`, and unmaps it:
    /// copies recorded after this read what was written.
    pub fn map_write<T>(
        &self,
        staging: &wgpu::Buffer,
        len: u64,
        write: impl FnOnce(wgpu::WriteOnly<'_, [u8]>) -> T,
    ) -> Result<T, FramegenError> {
        let slice = staging.slice(..len.max(1).next_multiple_of(wgpu::MAP_ALIGNMENT));
        self.map(&slice, wgpu::MapMode::Write)?;
        let out = {
            let mut view = slice
                .get_mapped_range_mut()
                .map_err(|e| FramegenError::Device(format!("upload: {e:?}")))?;
            write(view.slice(..len as usize))
        };
        staging.unmap();
        Ok(out)
    }

    /// Copies `len` bytes of `buffer` back to the CPU (submits and waits).
    pub fn read(&self, buffer: &wgpu::Buffer, len: u64) -> Result<Vec<u8>, FramegenError> {
        if len == 0 {
            return Ok(Vec::new());
        }
        let staging = self.staging("read-back", len);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, len.next_multiple_of(4));
        self.queue.submit([encoder.finish()]);
        self.map_read(&staging, len, <[u8]>::to_vec)
    }

    /// Reads back `count` plain-old-data elements.
    pub fn read_pod<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        count: usize,
    ) -> Result<Vec<T>, FramegenError> {
        let bytes = self.read(buffer, (count * std::mem::size_of::<T>()) as u64)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}

/// `dst` cut into pieces of `N` bytes, to be written on several cores,
/// and what is left after the last whole piece. (A piece of a fixed size
/// can move to another thread; `wgpu` lets only sized write-only views do.)
pub fn write_pieces<const N: usize>(
    dst: wgpu::WriteOnly<'_, [u8]>,
) -> (Vec<wgpu::WriteOnly<'_, [u8; N]>>, wgpu::WriteOnly<'_, [u8]>) {
    let (pieces, rest) = dst.into_chunks::<N>();
    (pieces.into_iter().collect(), rest)
}

/// Copies `src` into `dst` (of the same length) on all cores: one core
/// alone moves a frame at a fraction of the memory bandwidth.
pub fn par_write(src: &[u8], dst: wgpu::WriteOnly<'_, [u8]>) {
    use rayon::prelude::*;
    const PIECE: usize = 1 << 16;
    let (pieces, mut rest) = write_pieces::<PIECE>(dst);
    let whole = pieces.len() * PIECE;
    pieces
        .into_par_iter()
        .zip(src[..whole].par_chunks_exact(PIECE))
        .for_each(|(d, s)| wgpu::WriteOnly::<[u8]>::from(d).copy_from_slice(s));
    rest.copy_from_slice(&src[whole..]);
}

/// How a kernel sees one binding (its index is its place in the list).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    /// `var<storage, read>`: the pass parameters ([`Rec::params`]). Not a
    /// `var<uniform>`: Mesa's lavapipe inlines the values of a uniform
    /// buffer that a branch or a loop reads into the kernel and compiles
    /// it anew for every new value, so a parameter that changes every
    /// frame (α, the camera) cost a compilation per generated frame there
    /// (about 140 ms at 160×90, against 6 ms for a frame whose α repeats).
    Params,
    /// `var<storage, read>`.
    Read,
    /// `var<storage, read_write>` (plain or atomic).
    ReadWrite,
    /// A binding number this entry point does not use (another entry point
    /// of the same file does); no buffer is passed for it.
    Skip,
}

/// One compute entry point with its explicit bind group layout.
#[derive(Debug)]
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    /// Binding numbers of the buffers `dispatch` takes, in order.
    slots: Vec<u32>,
    name: &'static str,
}

impl Kernel {
    /// Compiles `entry` of `common.wgsl + source`. `bindings` lists group 0's
    /// bindings in order; every entry point of one shader file uses the same
    /// list.
    pub fn new(ctx: &GpuContext, source: &str, entry: &'static str, bindings: &[Binding]) -> Self {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(entry),
                source: wgpu::ShaderSource::Wgsl(format!("{COMMON_WGSL}\n{source}").into()),
            });
        let entries: Vec<_> = bindings
            .iter()
            .enumerate()
            .filter(|(_, b)| **b != Binding::Skip)
            .map(|(i, b)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                // Every binding is a storage buffer, read-only but for
                // `ReadWrite` (the parameters too, see `Binding::Params`).
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage {
                        read_only: *b != Binding::ReadWrite,
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(entry),
                entries: &entries,
            });
        let pipeline_layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(entry),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        let slots = bindings
            .iter()
            .enumerate()
            .filter(|(_, b)| **b != Binding::Skip)
            .map(|(i, _)| i as u32)
            .collect();
        Self {
            pipeline,
            layout,
            slots,
            name: entry,
        }
    }

    /// Records a dispatch over `items` threads (1-D, folded into 2-D
    /// workgroup grids for large counts) with the given buffers bound in
    /// order (skipped binding numbers take no buffer).
    pub fn dispatch(
        &self,
        gpu: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &[&wgpu::Buffer],
        items: u64,
    ) {
        let groups = items.div_ceil(u64::from(WORKGROUP)) as u32;
        self.dispatch_groups(gpu, encoder, buffers, groups);
    }

    /// Records a dispatch of `groups` workgroups of the entry point's own
    /// size (folded into a 2-D grid like [`Self::dispatch`]), for kernels
    /// that give each workgroup one item (e.g. a block of pixels).
    pub fn dispatch_groups(
        &self,
        gpu: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &[&wgpu::Buffer],
        groups: u32,
    ) {
        if groups == 0 {
            return;
        }
        assert_eq!(
            buffers.len(),
            self.slots.len(),
            "kernel {} binds {} buffers",
            self.name,
            self.slots.len()
        );
        let entries: Vec<_> = self
            .slots
            .iter()
            .copied()
            .zip(buffers.iter().copied())
            .collect();
        let group = gpu.bind_group(&self.layout, self.name, &entries);
        let x = groups.min(MAX_GROUPS_X);
        let y = groups.div_ceil(x);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.name),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_parallel_write_copies_every_byte() {
        // Whole pieces and a partial last one.
        let src: Vec<u8> = (0..200_003u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut dst = vec![0u8; src.len()];
        super::par_write(&src, dst.as_mut_slice().into());
        assert_eq!(dst, src);
        let mut empty: [u8; 0] = [];
        super::par_write(&[], empty.as_mut_slice().into());
    }
}
