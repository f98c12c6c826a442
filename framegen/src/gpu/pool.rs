//! Bind groups and pass parameters kept from one frame to the next (issue
//! 15): creating a bind group and a parameter buffer for every dispatch
//! cost allocations and driver calls on every pass of every frame.
//!
//! * **Parameters** go into a ring of small read-only storage buffers
//!   ([`crate::gpu::Binding::Params`] says why not uniform ones), one slot per
//!   dispatch of a submission, rewritten with `Queue::write_buffer` (which
//!   wgpu orders before the submission that reads them, and after the
//!   submissions before it). The ring restarts at every submission, so a
//!   plan that records the same dispatches each frame uses the same slots.
//! * **Bind groups** are cached by layout and bound buffers. The executor
//!   reuses its buffers (they are created once per size), so after the
//!   first frame every dispatch finds its group. The cache holds its
//!   buffers alive: the executor clears it when it replaces one.
//!
//! One pool per executor ([`crate::exec::gpu::GpuBackend`]): two executors
//! may share a device, never a ring.

use std::cell::RefCell;
use std::collections::HashMap;

use super::GpuContext;

/// Bytes of a parameter slot (every pass's parameters fit; a larger block
/// gets a larger slot).
const SLOT_BYTES: u64 = 512;

/// The reusable resources of one executor.
#[derive(Debug, Default)]
pub struct Pool {
    inner: RefCell<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    /// Parameter buffers; `next` is the first one free in this submission.
    params: Vec<wgpu::Buffer>,
    next: usize,
    groups: HashMap<(wgpu::BindGroupLayout, Vec<wgpu::Buffer>), wgpu::BindGroup>,
    /// A read-only binding's stand-in where a pass has nothing to bind.
    placeholder: Option<wgpu::Buffer>,
}

impl Pool {
    /// Starts a new submission: its dispatches take the slots from the
    /// first one again.
    pub fn restart(&self) {
        self.inner.borrow_mut().next = 0;
    }

    /// Forgets every cached bind group (and so the buffers they hold).
    pub fn clear_groups(&self) {
        self.inner.borrow_mut().groups.clear();
    }

    /// Number of cached bind groups.
    pub fn groups(&self) -> usize {
        self.inner.borrow().groups.len()
    }
}

/// What a pass records with: the device and its executor's [`Pool`]. Derefs
/// to the [`GpuContext`].
#[derive(Clone, Copy, Debug)]
pub struct Rec<'a> {
    ctx: &'a GpuContext,
    pool: &'a Pool,
}

impl std::ops::Deref for Rec<'_> {
    type Target = GpuContext;

    fn deref(&self) -> &GpuContext {
        self.ctx
    }
}

impl<'a> Rec<'a> {
    /// Records on `ctx` with the resources of `pool`.
    pub fn new(ctx: &'a GpuContext, pool: &'a Pool) -> Self {
        Self { ctx, pool }
    }

    /// The next parameter slot of this submission, holding `data`.
    pub fn params(&self, data: &[u8]) -> wgpu::Buffer {
        let mut inner = self.pool.inner.borrow_mut();
        let i = inner.next;
        inner.next += 1;
        let bytes = (data.len() as u64)
            .next_multiple_of(SLOT_BYTES)
            .max(SLOT_BYTES);
        if inner.params.get(i).is_none_or(|b| b.size() < bytes) {
            let buffer = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pass params"),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            if i < inner.params.len() {
                // Groups bound to the old slot would keep it alive.
                inner.groups.clear();
                inner.params[i] = buffer;
            } else {
                inner.params.push(buffer);
            }
        }
        let buffer = inner.params[i].clone();
        self.ctx.queue.write_buffer(&buffer, 0, data);
        buffer
    }

    /// A small storage buffer to bind read-only where a pass has nothing to
    /// read (it must not alias a buffer the pass writes).
    pub fn placeholder(&self) -> wgpu::Buffer {
        let mut inner = self.pool.inner.borrow_mut();
        inner
            .placeholder
            .get_or_insert_with(|| self.ctx.storage("nothing to read", 16))
            .clone()
    }

    /// The bind group of `layout` with `entries` (binding numbers and
    /// buffers, whole), from the cache or made once.
    pub fn bind_group(
        &self,
        layout: &wgpu::BindGroupLayout,
        label: &str,
        entries: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let key = (
            layout.clone(),
            entries
                .iter()
                .map(|(_, b)| (*b).clone())
                .collect::<Vec<_>>(),
        );
        let mut inner = self.pool.inner.borrow_mut();
        if let Some(group) = inner.groups.get(&key) {
            return group.clone();
        }
        let group = self
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &entries
                    .iter()
                    .map(|(i, b)| wgpu::BindGroupEntry {
                        binding: *i,
                        resource: b.as_entire_binding(),
                    })
                    .collect::<Vec<_>>(),
            });
        inner.groups.insert(key, group.clone());
        group
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{Binding, Kernel};

    const SHADER: &str = "
@group(0) @binding(0) var<storage, read> add: vec4<u32>;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;

@compute @workgroup_size(256)
fn add_to(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i < arrayLength(&data) {
        data[i] += add.x;
    }
}
";

    /// Frame after frame, the same dispatches find their bind group and
    /// their parameter slot again; each dispatch of one submission still
    /// reads its own parameters.
    #[test]
    fn dispatches_reuse_their_groups_and_slots() {
        let ctx = GpuContext::new().expect("a GPU adapter (tools/setup.sh installs lavapipe)");
        let kernel = Kernel::new(
            &ctx,
            SHADER,
            "add_to",
            &[Binding::Params, Binding::ReadWrite],
        );
        let data = ctx.storage_init("data", bytemuck::cast_slice(&[0u32; 300]));
        let pool = Pool::default();
        let gpu = Rec::new(&ctx, &pool);
        let mut slots = Vec::new();
        for frame in 0..3u32 {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            // Two dispatches in one submission, with different parameters.
            let a = gpu.params(bytemuck::cast_slice(&[1u32, 0, 0, 0]));
            kernel.dispatch(&gpu, &mut encoder, &[&a, &data], 300);
            let b = gpu.params(bytemuck::cast_slice(&[10u32, 0, 0, 0]));
            kernel.dispatch(&gpu, &mut encoder, &[&b, &data], 300);
            ctx.queue.submit([encoder.finish()]);
            pool.restart();
            ctx.wait().unwrap();
            assert_ne!(a, b, "one slot per dispatch of a submission");
            slots.push((a, b));
            assert_eq!(pool.groups(), 2, "frame {frame}");
            let got: Vec<u32> = ctx.read_pod(&data, 300).unwrap();
            assert!(
                got.iter().all(|&v| v == 11 * (frame + 1)),
                "frame {frame}: {:?}",
                &got[..4]
            );
        }
        assert!(
            slots.windows(2).all(|w| w[0] == w[1]),
            "the same slots every frame"
        );
        pool.clear_groups();
        assert_eq!(pool.groups(), 0);
    }
}
