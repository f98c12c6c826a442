//! Per-pass times of the GFFE and GeoMotionGen pipelines, and every
//! method's total (push + one generated frame), on the CPU reference and on
//! wgpu, at 540p, 720p and 1080p on the default scene.
//!
//! wgpu per-pass times are wall time of submit + wait per pass (the profiled
//! backend); lavapipe's timestamp queries report ~0 for real work. Each
//! group has a `copy` entry in the same run: a copy of the bytes a frame's
//! inputs take (color f32x4 + depth + motion, 28 B/px), a device buffer
//! copy for wgpu and a host memcpy for the CPU. It is the bandwidth floor:
//! divide a pass's time by it for the pass's cost in copies. Each group
//! also has a `render` entry: the renderer drawing the same frames (submit
//! + readback); divide a method's `total` by it for its cost in renders.
//!
//! `gffe-nearest/total` is gffe with the seed's nearest-pixel colour
//! instead of the default resampling filter (what the filter costs).
//!
//! `gffe/total-on-device` and `interp/total-on-device` (wgpu) are the
//! totals with the generated frame left on the device, as a window that
//! shares it shows it (`FrameGenerator::generate_to`): what the read-back
//! costs, against `total`.
//!
//! `repeat/upload`, `repeat/crop` and `repeat/readback` split the cheapest
//! method on wgpu into its transfers and its one kernel: what a frame costs
//! to move on and off the device against what a trivial kernel costs there.
//!
//! `shading` and `shade` are shading correction's estimate (per fed frame)
//! and its application (per generated frame); a scene whose shading moves
//! (`FRAMEGEN_BENCH_SCENE=sun_sweep`) gives them real work.
//!
//! `FRAMEGEN_BENCH_STREAM=live` feeds the frames as `client run` receives
//! them from its in-process server instead of as rendered: depth and
//! motion through the compact set's quantising codecs, colour through
//! H.264 at the automatic rate (`client::eval::transport`). Codec noise
//! makes some passes do more work than on the rendered frames (e.g.
//! shading correction's estimate, whose "unchanged" test is finer than
//! the noise).
//!
//! `cargo bench -p tests --bench framegen [-- FILTER]`, e.g. `-- wgpu/1280x720`;
//! `FRAMEGEN_BENCH_SIZES=960x540,1280x720,1920x1080`,
//! `FRAMEGEN_BENCH_SCENE=default` and `FRAMEGEN_BENCH_STREAM=rendered` by
//! default.

use std::sync::Arc;
use std::time::Duration;

mod common;

use criterion::{Criterion, criterion_group};
use framegen::{FrameGenerator, GpuBackend, GpuContext, Method, Pass, Resample, Settings};
use protocol::{Frame, FrameSize};

fn sizes() -> Vec<FrameSize> {
    let s = std::env::var("FRAMEGEN_BENCH_SIZES")
        .unwrap_or_else(|_| "960x540,1280x720,1920x1080".into());
    s.split(',')
        .map(|s| s.parse().expect("WIDTHxHEIGHT"))
        .collect()
}

/// Fed frames with times that keep increasing when the sequence wraps. A
/// frame is handed out as the client hands a received one over
/// (`FrameGenerator::push_shared`, its buffers read where they are), with
/// its meta rewritten in place, so the bench times the generator, not a
/// copy of the frame.
struct Feed {
    frames: Vec<Arc<Frame>>,
    /// Each frame's original time and index.
    base: Vec<(f64, u64)>,
    next: usize,
}

impl Feed {
    fn new(frames: Vec<Frame>) -> Self {
        let base = frames.iter().map(|f| (f.meta.time, f.meta.index)).collect();
        Self {
            frames: frames.into_iter().map(Arc::new).collect(),
            base,
            next: 0,
        }
    }

    fn next(&mut self) -> &Arc<Frame> {
        let len = self.frames.len();
        let i = self.next % len;
        let lap = (self.next / len) as u64;
        let (time, index) = self.base[i];
        let f = Arc::get_mut(&mut self.frames[i])
            .expect("the generator let go of a frame before the feed comes round to it again");
        f.meta.time = time + lap as f64 * 10.0;
        f.meta.index = index + lap * 1000;
        self.next += 1;
        &self.frames[i]
    }

    /// The α of the frame generated after the last one handed out: about
    /// ½ (n = 1), a little different every time, as the live presenter's
    /// slots are (vsync timing). A fixed α hides a driver that compiles a
    /// kernel for every new parameter value (lavapipe's inlined uniforms,
    /// `framegen::gpu::Binding::Params`).
    fn alpha(&self) -> f64 {
        0.5 + 0.04 * ((self.next as f64 * 0.618_034).fract() - 0.5)
    }
}

fn run(g: &mut FrameGenerator, feed: &mut Feed) {
    g.push_shared(feed.next()).expect("push");
    g.generate(feed.alpha()).expect("generate");
}

/// The time of `pass` in one push and generation. The feed's first frame
/// of each lap does not continue the last one, so the passes that need a
/// previous frame (shading correction's) do not run on it: that frame is
/// skipped and the next one timed, so that every sample times the pass
/// where it runs (criterion rejects a sample of zero).
fn pass_time(g: &mut FrameGenerator, feed: &mut Feed, pass: Pass) -> Duration {
    let mut time = None;
    for _ in 0..2 {
        run(g, feed);
        let times = g.timings();
        let mut ran = times.iter().filter(|t| t.pass == pass).peekable();
        if ran.peek().is_some() {
            time = Some(ran.map(|t| t.time).sum());
            break;
        }
    }
    time.unwrap_or_default()
}

/// The built-in scene rendered for the benches.
fn scene_name() -> String {
    std::env::var("FRAMEGEN_BENCH_SCENE").unwrap_or_else(|_| "default".into())
}

fn bench(c: &mut Criterion) {
    for size in sizes() {
        bench_size(c, size);
    }
}

/// The fed frames as the live client receives them (`FRAMEGEN_BENCH_STREAM`
/// `live`), or as rendered (`rendered`, the default).
fn as_streamed(frames: Vec<Frame>, fps: f64) -> Vec<Frame> {
    let stream = std::env::var("FRAMEGEN_BENCH_STREAM").unwrap_or_else(|_| "rendered".into());
    match stream.as_str() {
        "rendered" => frames,
        "live" => {
            use client::eval::transport::Transport;
            let color = video::ColorCodec::DEFAULT_LIVE;
            let set = protocol::wire::BufferSet::Compact;
            let mut transport = Transport::new(set, &[color], fps);
            let mut previous = None;
            frames
                .into_iter()
                .map(|f| {
                    let meta = f.meta;
                    let carried = transport.carry(f, previous.as_ref(), 1, color);
                    previous = Some(meta);
                    carried.expect("the live stream's codecs")
                })
                .collect()
        }
        other => panic!("FRAMEGEN_BENCH_STREAM={other}: rendered or live"),
    }
}

fn bench_size(c: &mut Criterion, size: FrameSize) {
    let name = scene_name();
    let rendered = tests::render_scene(&name, size, 60.0, 60..76);
    let frames = as_streamed(framegen::decimate::decimate(&rendered, 2), 30.0);
    let ctx = GpuContext::new().expect("GPU");
    let label = format!("{}x{}", size.width, size.height);
    for gpu in [false, true] {
        let backend = if gpu { "wgpu" } else { "cpu" };
        // Per-pass times come from the profiled backend (a submit and a
        // wait per pass); totals from the plain one (one submission per
        // push and per generation), which is what the client runs.
        let make_with = |s: Settings, profiled: bool| {
            let s = Settings {
                cut_dynamic_fraction: 2.0,
                ..s
            };
            if gpu {
                let backend = if profiled {
                    GpuBackend::profiled(ctx.clone())
                } else {
                    GpuBackend::new(ctx.clone())
                };
                FrameGenerator::with_backend(s, Box::new(backend))
            } else {
                FrameGenerator::cpu(s)
            }
            .expect("generator")
        };
        let make = |method, profiled: bool| make_with(Settings::for_method(method), profiled);
        let mut group = c.benchmark_group(format!("{backend}/{label}"));
        group
            // Per-pass benches report one pass's time but run the whole
            // pipeline per iteration: criterion's time targets count the
            // reported time, so short targets still mean many full runs.
            .sample_size(10)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_millis(1500));
        let per_pass = [
            (
                Method::Gffe,
                vec![
                    Pass::Upload,
                    Pass::History,
                    Pass::Background,
                    Pass::Motion,
                    Pass::Warp,
                    Pass::BgFill,
                    Pass::Holes,
                    Pass::Shading,
                    Pass::Shade,
                    Pass::Pack,
                    Pass::Readback,
                ],
            ),
            (
                Method::Repeat,
                vec![Pass::Upload, Pass::Crop, Pass::Pack, Pass::Readback],
            ),
            (
                Method::Interp,
                vec![Pass::Reproject, Pass::Holes, Pass::Resolve],
            ),
        ];
        let mut feed = Feed::new(frames.clone());
        for (method, passes) in per_pass {
            let mut g = make(method, true);
            for _ in 0..3 {
                run(&mut g, &mut feed);
            }
            for pass in passes {
                // The CPU executor has no upload, packing kernel or
                // read-back, and evaluates eq. 1 inside the warp (its time
                // is the warp's).
                let host_only = [Pass::Upload, Pass::Pack, Pass::Readback, Pass::Motion];
                if !gpu && host_only.contains(&pass) {
                    continue;
                }
                group.bench_function(format!("{method}/{}", pass.name()), |b| {
                    b.iter_custom(|iters| {
                        let mut total = Duration::ZERO;
                        for _ in 0..iters {
                            total += pass_time(&mut g, &mut feed, pass);
                        }
                        total
                    })
                });
            }
        }
        for method in Method::ALL {
            let mut g = make(method, false);
            group.bench_function(format!("{method}/total"), |b| {
                b.iter(|| run(&mut g, &mut feed))
            });
        }
        // The same totals with the generated frame left on the device, as
        // a window sharing it shows it (`generate_to`): no read-back.
        if gpu {
            for method in [Method::Gffe, Method::Interp] {
                let mut g = make(method, false);
                run(&mut g, &mut feed);
                let size = g.generated_size().expect("a frame was pushed");
                let target = gpu_device::texture_2d(
                    &ctx.device,
                    "generated frame",
                    (size.width, size.height),
                    wgpu::TextureFormat::Rgba16Float,
                    wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::TEXTURE_BINDING,
                );
                group.bench_function(format!("{method}/total-on-device"), |b| {
                    b.iter(|| {
                        g.push_shared(feed.next()).expect("push");
                        let alpha = feed.alpha();
                        g.generate_to(alpha, framegen::CameraSource::Extrapolated, &target)
                            .expect("generate");
                    })
                });
            }
        }
        // What the warp's default colour filter costs: gffe with the seed's
        // nearest pixel, in the same run.
        let nearest = Settings {
            resample: Resample::Nearest,
            ..Settings::for_method(Method::Gffe)
        };
        let mut g = make_with(nearest, false);
        group.bench_function("gffe-nearest/total", |b| b.iter(|| run(&mut g, &mut feed)));
        let bytes = size.pixels() * 28;
        if !gpu {
            let src = vec![1u8; bytes as usize];
            let mut dst = vec![0u8; bytes as usize];
            group.bench_function("copy", |b| {
                b.iter(|| dst.copy_from_slice(std::hint::black_box(&src)))
            });
        }
        if gpu {
            let src = ctx.storage("copy src", bytes);
            let dst = ctx.storage("copy dst", bytes);
            group.bench_function("copy", |b| {
                b.iter(|| {
                    let mut enc = ctx.device.create_command_encoder(&Default::default());
                    enc.copy_buffer_to_buffer(&src, 0, &dst, 0, bytes);
                    ctx.queue.submit([enc.finish()]);
                    ctx.wait().expect("wait");
                })
            });
        }
        // The render of the same frames (the same scene at this size,
        // submit + readback, as `server record` reports it): what a
        // generated frame must cost a fraction of. In both groups, so that
        // each group holds its own yardstick from the same run.
        let scene = scene::Scene::load(&format!("builtin:{name}")).expect("scene");
        let mut renderer =
            scene::render::Renderer::new(scene, size, std::path::Path::new(".")).expect("renderer");
        let mut index = 60;
        group.bench_function("render", |b| {
            b.iter(|| {
                index = 60 + (index - 59) % 16;
                renderer.render(index, 60.0).expect("render")
            })
        });
        group.finish();
    }
}

criterion_group!(benches, bench);

fn main() {
    common::main(benches);
}
