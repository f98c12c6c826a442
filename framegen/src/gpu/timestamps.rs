//! GPU time of a profiled pass from timestamp queries (issue 8: "GPU
//! timestamp queries where the adapter supports them, wall time
//! otherwise, labelled which").
//!
//! A timestamp is written into the command encoder before and after the
//! pass's commands (`TIMESTAMP_QUERY_INSIDE_ENCODERS`), resolved into a
//! buffer in the same submission and read back once the profiled pass has
//! been waited for. The wall time of submit + wait is recorded beside it.
//!
//! Used only where the adapter is real hardware: a CPU rasteriser such as
//! lavapipe offers the features but its timestamps read near zero for real
//! work (DEVELOPERS.md), so there only wall time is reported.

use std::time::Duration;

use super::GpuContext;
use crate::FramegenError;

/// The features timestamps need.
pub const FEATURES: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);

/// Whether a pass's time comes from timestamps when profiling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassClock {
    /// Wall time of submit + wait only.
    Wall,
    /// Timestamp queries as well (the device must have [`FEATURES`]).
    Timestamps,
}

impl PassClock {
    /// Timestamps on a hardware adapter with the features, wall time
    /// otherwise.
    pub fn preferred(ctx: &GpuContext) -> Self {
        if ctx.device.features().contains(FEATURES)
            && ctx.adapter_info.device_type != wgpu::DeviceType::Cpu
        {
            PassClock::Timestamps
        } else {
            PassClock::Wall
        }
    }
}

/// A two-entry query set and its resolve buffer.
#[derive(Debug)]
pub struct Timestamps {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f64,
}

impl Timestamps {
    /// `None` when the device lacks [`FEATURES`].
    pub fn new(ctx: &GpuContext) -> Option<Self> {
        if !ctx.device.features().contains(FEATURES) {
            return None;
        }
        Some(Self {
            set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolve: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pass timestamps resolve"),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            period_ns: f64::from(ctx.queue.get_timestamp_period()),
        })
    }

    /// Before the pass's commands.
    pub fn begin(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.write_timestamp(&self.set, 0);
    }

    /// After them: the second timestamp, resolved.
    pub fn end(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.write_timestamp(&self.set, 1);
        encoder.resolve_query_set(&self.set, 0..2, &self.resolve, 0);
    }

    /// The time between the two, once the submission has finished.
    pub fn read(&self, ctx: &GpuContext) -> Result<Duration, FramegenError> {
        let t: Vec<u64> = ctx.read_pod(&self.resolve, 2)?;
        let ns = t[1].saturating_sub(t[0]) as f64 * self.period_ns;
        Ok(Duration::from_nanos(if ns.is_finite() {
            ns as u64
        } else {
            0
        }))
    }
}
