//! What each variant costs: wall time of push (ingest) and of each
//! generated frame, per pass, and the bandwidth floor to compare with.
//!
//! The wgpu backend alternates between plain intervals, whose wall times
//! are the totals (push, generate: one submission each, as the client runs
//! it), and profiled intervals in between, which give the per-pass times:
//! one submission per pass, waited for. On a hardware adapter with
//! timestamp queries each pass's time is the GPU time between timestamps
//! around it ([`framegen::PassClock`]); on a software rasteriser such as
//! lavapipe, whose timestamps read near zero for real work (DEVELOPERS.md),
//! it is the submit + wait wall time. The report labels which. The CPU
//! reference is wall time on all cores (rayon; `RAYON_NUM_THREADS` sets how many).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use framegen::accounting::Percentiles;
use framegen::{GpuContext, PassTime};
use protocol::FrameSize;
use serde::Serialize;

use super::BackendKind;

/// How the numbers of a backend were taken.
pub fn method_of(backend: BackendKind, timestamps: bool) -> &'static str {
    match (backend, timestamps) {
        (BackendKind::Cpu, _) => "wall time, CPU reference on all cores (rayon)",
        (BackendKind::Wgpu, false) => {
            "totals: wall time of the plain (unprofiled) intervals; per pass: wall time of submit + wait in the profiled intervals between them (the adapter's timestamps are not used)"
        }
        (BackendKind::Wgpu, true) => {
            "totals: wall time of the plain (unprofiled) intervals; per pass: GPU time from timestamp queries around each pass in the profiled intervals between them"
        }
    }
}

/// Accumulates the times of one variant on one backend.
pub struct TimingAcc {
    backend: BackendKind,
    push: Vec<f64>,
    generate: Vec<f64>,
    per_generated: Vec<f64>,
    passes: BTreeMap<&'static str, f64>,
    intervals: usize,
    timestamps: bool,
}

impl TimingAcc {
    /// Empty, for `backend`.
    pub fn new(backend: BackendKind) -> Self {
        Self {
            backend,
            push: Vec::new(),
            generate: Vec::new(),
            per_generated: Vec::new(),
            passes: BTreeMap::new(),
            intervals: 0,
            timestamps: false,
        }
    }

    /// One rendered frame: its push and its generated frames (counted in
    /// the totals when `totals`), and the passes the backend timed for them
    /// (none when it ran unprofiled).
    pub fn add(
        &mut self,
        push: Duration,
        generated: &[Duration],
        passes: &[PassTime],
        totals: bool,
    ) {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        if totals {
            self.push.push(ms(push));
            self.generate.extend(generated.iter().map(|&d| ms(d)));
            let total = ms(push) + generated.iter().map(|&d| ms(d)).sum::<f64>();
            self.per_generated
                .push(total / generated.len().max(1) as f64);
        }
        if !passes.is_empty() {
            for p in passes {
                self.timestamps |= p.gpu.is_some();
                *self.passes.entry(p.pass.name()).or_default() += ms(p.gpu.unwrap_or(p.time));
            }
            self.intervals += 1;
        }
    }

    /// The summary.
    pub fn finish(&self) -> Timing {
        let n = self.intervals.max(1) as f64;
        Timing {
            backend: self.backend,
            how: method_of(self.backend, self.timestamps),
            push_ms: median(&self.push),
            generate_ms: median(&self.generate),
            per_generated_ms: median(&self.per_generated),
            per_generated_p95_ms: Percentiles::of(self.per_generated.clone()).p95,
            passes: self
                .passes
                .iter()
                .map(|(&name, &sum)| PassMs {
                    pass: name,
                    ms: sum / n,
                })
                .collect(),
        }
    }
}

/// The times of one variant on one backend.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Timing {
    /// The backend.
    pub backend: BackendKind,
    /// How it was measured.
    pub how: &'static str,
    /// Median push (ingest of a rendered frame), ms.
    pub push_ms: f64,
    /// Median generation of one frame, ms.
    pub generate_ms: f64,
    /// Median of (push + all n generations) / n per rendered frame: the
    /// cost of one generated frame with its share of the ingest. The
    /// x axis of the plots and the Pareto fronts.
    pub per_generated_ms: f64,
    /// Its 95th percentile.
    pub per_generated_p95_ms: f64,
    /// Mean ms per rendered frame, per pass (ingest + its n generations).
    pub passes: Vec<PassMs>,
}

/// One pass's mean time.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PassMs {
    /// Pass name.
    pub pass: &'static str,
    /// Mean ms per rendered frame.
    pub ms: f64,
}

/// Median (nearest rank, as every percentile in the project:
/// [`Percentiles`]); 0 for no samples.
pub fn median(v: &[f64]) -> f64 {
    Percentiles::of(v.to_vec()).p50
}

/// The bandwidth reference at one size: copying the bytes a rendered
/// frame's inputs take (color as f32×4, depth, motion: 28 B/px), which
/// every pass at least has to read once.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CopyFloor {
    /// `WxH`.
    pub size: String,
    /// Bytes copied.
    pub bytes: u64,
    /// Median ms of a host memory copy.
    pub cpu_ms: f64,
    /// Median ms of a device buffer copy (submit + wait).
    pub wgpu_ms: Option<f64>,
}

/// Bytes per pixel of the inputs (f32×4 color, f32 depth, f32×2 motion).
pub const BYTES_PER_PIXEL: u64 = 28;

/// Measures the [`CopyFloor`] at `size` (median of 15 copies each).
pub fn copy_floor(size: FrameSize, ctx: Option<&GpuContext>) -> anyhow::Result<CopyFloor> {
    let bytes = size.pixels() * BYTES_PER_PIXEL;
    let src = vec![1u8; bytes as usize];
    let mut dst = vec![0u8; bytes as usize];
    let mut cpu = Vec::new();
    for _ in 0..15 {
        let start = Instant::now();
        dst.copy_from_slice(std::hint::black_box(&src));
        std::hint::black_box(&mut dst);
        cpu.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let wgpu_ms = match ctx {
        Some(ctx) => {
            let (a, b) = (
                ctx.storage("copy src", bytes),
                ctx.storage("copy dst", bytes),
            );
            let mut t = Vec::new();
            for _ in 0..15 {
                let start = Instant::now();
                let mut enc = ctx.device.create_command_encoder(&Default::default());
                enc.copy_buffer_to_buffer(&a, 0, &b, 0, bytes);
                ctx.queue.submit([enc.finish()]);
                ctx.wait()?;
                t.push(start.elapsed().as_secs_f64() * 1e3);
            }
            Some(median(&t))
        }
        None => None,
    };
    Ok(CopyFloor {
        size: format!("{}x{}", size.width, size.height),
        bytes,
        cpu_ms: median(&cpu),
        wgpu_ms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_are_nearest_rank() {
        assert_eq!(median(&[5.0, 1.0, 4.0, 2.0, 3.0]), 3.0);
        assert_eq!(median(&[]), 0.0);
    }

    #[test]
    fn per_generated_time_shares_the_push() {
        let mut t = TimingAcc::new(BackendKind::Cpu);
        let ms = Duration::from_millis;
        t.add(ms(6), &[ms(2), ms(4)], &[], true);
        let s = t.finish();
        assert_eq!(s.push_ms, 6.0);
        assert_eq!(s.per_generated_ms, 6.0);
        assert_eq!(s.generate_ms, 2.0);
    }

    /// Profiled intervals give the per-pass times and stay out of the
    /// totals; plain ones give the totals and no pass times.
    #[test]
    fn profiled_intervals_time_passes_and_plain_ones_the_totals() {
        let mut t = TimingAcc::new(BackendKind::Wgpu);
        let ms = Duration::from_millis;
        let warp = |d| PassTime {
            pass: framegen::Pass::Warp,
            time: ms(d),
            gpu: None,
        };
        t.add(ms(10), &[ms(10)], &[], true);
        t.add(ms(50), &[ms(50)], &[warp(30)], false);
        t.add(ms(12), &[ms(12)], &[], true);
        t.add(ms(60), &[ms(60)], &[warp(40)], false);
        let s = t.finish();
        // Totals: medians of 20 and 24 ms only (nearest rank).
        assert!(
            s.per_generated_ms == 20.0 || s.per_generated_ms == 24.0,
            "{s:?}"
        );
        assert_eq!(s.passes.len(), 1);
        assert_eq!(s.passes[0].ms, 35.0);
    }
}
