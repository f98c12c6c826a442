//! `client eval`: what accuracy costs in time (issue 8, DESIGN §9).
//!
//! A sequence rendered at the display rate (a dump, or a scene rendered on
//! the fly) is fed to every variant at 1/(n+1) of its rate, with motion to
//! the previous fed frame: a scene's fed frames are rendered at the fed
//! rate ([`sequence::Sequence::render_fed`]), a dump's motion is composed
//! back through the skipped frames ([`framegen::decimate::kept`]); each
//! generated frame is compared with the rendered frame it stands for:
//! the skipped frame after the last fed one for the extrapolators, the
//! skipped frame before it for interpolation. Every variant runs on each
//! chosen backend in lockstep over one pass of the sequence; quality is
//! scored on the first backend's output (the backends agree; the report
//! gives their PSNR against each other) and time is measured on each.
//!
//! * [`variant`]: the settings swept;
//! * [`sequence`]: the frames;
//! * [`measure`]: PSNR, SSIM, ꟻLIP, regions;
//! * [`timing`]: per-pass and total milliseconds, the copy floor;
//! * [`report`]: Pareto fronts, `report.md`, `report.json`;
//! * [`plot`] and [`heatmap`]: the images;
//! * [`save`]: the generated frames themselves (`--save-frames`).

pub mod heatmap;
pub mod measure;
pub mod plot;
pub mod report;
pub mod save;
pub mod sequence;
pub mod timing;
pub mod transport;
pub mod variant;

use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use framegen::{FrameGenerator, GpuBackend, GpuContext};
use indicatif::{ProgressBar, ProgressStyle};
use protocol::wire::WindowMode;
use protocol::{Frame, FrameSize};
use serde::Serialize;

use measure::{Accumulator, score};
use report::{Report, Row, SceneReport};
use sequence::{Input, Sequence, Step};
use timing::TimingAcc;
use variant::{Axis, Sweep, Variant};

/// Where a variant runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// The plain Rust reference, on all cores (rayon).
    Cpu,
    /// wgpu compute.
    Wgpu,
}

impl BackendKind {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Cpu => "cpu",
            BackendKind::Wgpu => "wgpu",
        }
    }
}

/// What to evaluate and where to write it.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// Scenes or dumps, one report section each.
    pub inputs: Vec<Input>,
    /// Displayed size of rendered scenes.
    pub size: FrameSize,
    /// Display rate of rendered scenes.
    pub fps: f64,
    /// First frame.
    pub start: u64,
    /// Frames at the display rate per sequence.
    pub frames: u64,
    /// Which variants.
    pub sweep: Sweep,
    /// Backends to time (quality is scored on the first).
    pub backends: Vec<BackendKind>,
    /// Extra resolutions for the first (rendered) input.
    pub resolutions: Vec<FrameSize>,
    /// How wgpu passes are timed: `None` = [`framegen::PassClock::preferred`]
    /// (timestamps on hardware, wall time on software rasterisers).
    pub pass_clock: Option<framegen::PassClock>,
    /// Keep only variants whose label contains one of these (all if empty).
    pub only: Vec<String>,
    /// How fed frames' depth and motion reach the generator: as rendered
    /// (lossless), or through the stream's quantised codecs (compact).
    pub geometry: protocol::wire::BufferSet,
    /// How fed frames' colour travels (issue 19): every variant through
    /// the first setting (raw if empty), and gffe and interp through each
    /// further one ([`variant::with_codecs`], the bitrate sweep).
    pub colors: Vec<video::ColorCodec>,
    /// Fed frames before scoring starts (history and background warm up).
    pub warmup: usize,
    /// Heat maps for the first this many inputs...
    pub heatmap_inputs: usize,
    /// ...at this many frames each.
    pub heatmap_frames: usize,
    /// Output directory.
    pub out: PathBuf,
    /// Where to write every scored generated frame ([`save`]), if anywhere.
    pub save_frames: Option<PathBuf>,
    /// The command line, quoted in the report.
    pub command: String,
    /// Show progress bars.
    pub progress: bool,
}

/// Runs the evaluation and writes `report.md`, `report.json`, the plots
/// and the heat maps into `config.out`.
pub fn run(config: &EvalConfig) -> anyhow::Result<Report> {
    anyhow::ensure!(!config.inputs.is_empty(), "nothing to evaluate");
    anyhow::ensure!(!config.backends.is_empty(), "no backend chosen");
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("creating {}", config.out.display()))?;
    let ctx = if config.backends.contains(&BackendKind::Wgpu) {
        Some(GpuContext::new().context("wgpu backend")?)
    } else {
        None
    };
    let mut scenes = Vec::new();
    let mut heatmaps = Vec::new();
    let mut sizes = vec![config.size];
    for (index, input) in config.inputs.iter().enumerate() {
        let rendered = matches!(input, Input::Scene(_));
        let size = match input {
            Input::Scene(_) => config.size,
            Input::Dump(dir) => protocol::dump::DumpReader::open(dir)?.manifest().size(),
        };
        let mut variants = variant::sweep(config.sweep, size, rendered);
        if index == 0 && rendered {
            variants.extend(variant::resolutions(&config.resolutions));
        }
        variant::with_codecs(&mut variants, &config.colors, size, rendered);
        if !config.only.is_empty() {
            variants.retain(|v| config.only.iter().any(|o| v.label.contains(o.as_str())));
        }
        let effects = input.effects()?;
        variant::for_stream(&mut variants, effects);
        anyhow::ensure!(
            !variants.is_empty(),
            "no variant matches --only {:?}",
            config.only
        );
        // One pass of the sequence per (size, window): the frames differ.
        let mut groups: Vec<((FrameSize, WindowMode), Vec<Variant>)> = Vec::new();
        for v in variants.iter().cloned() {
            let key = (v.size, v.window);
            match groups.iter_mut().find(|(k, _)| *k == key) {
                Some((_, vs)) => vs.push(v),
                None => groups.push((key, vec![v])),
            }
        }
        // The group of gffe's geometry-aware result first: GFFE eq. 3's
        // focus region is defined from it, for the groups at its size
        // that follow (each method renders with its default window).
        groups.sort_by_key(|(_, vs)| !vs.iter().any(geometry_aware));
        let mut focus: HashMap<usize, Vec<bool>> = HashMap::new();
        let name = input.name();
        let mut rows = Vec::new();
        let mut stream = Vec::new();
        let mut captured: Vec<(usize, Vec<heatmap::Capture>)> = Vec::new();
        let group_count = groups.len();
        let group_sizes: Vec<FrameSize> = groups.iter().map(|((s, _), _)| *s).collect();
        for (g, ((gsize, window), vs)) in groups.into_iter().enumerate() {
            if !sizes.contains(&gsize) {
                sizes.push(gsize);
            }
            let mut seq = Sequence::open(
                input,
                gsize,
                config.fps,
                window,
                config.start,
                config.frames,
            )?;
            let bar = progress_bar(
                config,
                seq.len(),
                &format!(
                    "{name} [{}/{}] {}x{} window {}",
                    g + 1,
                    group_count,
                    gsize.width,
                    gsize.height,
                    window.name()
                ),
            );
            let heat = (index < config.heatmap_inputs && gsize == size)
                .then(|| heatmap_frames(seq.len() as usize, config.warmup, config.heatmap_frames));
            let save = config
                .save_frames
                .as_deref()
                .map(|root| (root, name.as_str()));
            let mut own = HashMap::new();
            let out = run_group(
                &mut seq,
                &vs,
                ctx.as_ref(),
                config,
                (heat.as_deref(), save),
                if gsize == size {
                    // Kept whole only for the groups at this size that
                    // follow (a frame-sized mask per truth frame).
                    (&mut focus, group_sizes[g + 1..].contains(&size))
                } else {
                    (&mut own, false)
                },
                &bar,
            )?;
            bar.finish_and_clear();
            rows.extend(out.rows);
            // The stream table: the plain stream at the main size where one
            // was fed, else the first at that size.
            if gsize == size && (stream.is_empty() || window == WindowMode::Off) {
                stream = out.stream;
            }
            // The methods' rows of one truth frame come from the groups
            // of their windows: one heat map of them all.
            for (truth_index, captures) in out.heat {
                match captured.iter_mut().find(|(t, _)| *t == truth_index) {
                    Some((_, all)) => all.extend(captures),
                    None => captured.push((truth_index, captures)),
                }
            }
        }
        for (truth_index, mut captures) in captured {
            captures.sort_by_key(|c| variants.iter().position(|v| v.label == c.label));
            let file = heatmap::write(
                &config.out,
                &name,
                config.start + truth_index as u64,
                &captures,
            )?;
            heatmaps.push(file);
        }
        // Report order: the sweep's.
        rows.sort_by_key(|r: &Row| variants.iter().position(|v| v.label == r.label));
        tracing::info!("{name}: {} variants", rows.len());
        scenes.push(SceneReport {
            scene: name,
            rows,
            stream,
        });
    }
    let copy_floor = sizes
        .iter()
        .map(|&s| timing::copy_floor(s, ctx.as_deref()))
        .collect::<Result<Vec<_>, _>>()?;
    let mut report = Report::new(config, ctx.as_deref(), scenes, copy_floor, heatmaps);
    report.mark_pareto();
    report.write(&config.out)?;
    plot::write_all(&report, &config.out)?;
    Ok(report)
}

fn progress_bar(config: &EvalConfig, len: u64, message: &str) -> ProgressBar {
    if !config.progress {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:48} {bar:30} {pos}/{len} frames  {elapsed}<{eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(message.to_string());
    bar
}

/// The truth frames (sequence positions) to draw heat maps for: odd
/// positions that both the extrapolators (fed the frame before) and
/// interpolation (fed the frame after) are scored on at n = 1, spread over
/// the scored range.
fn heatmap_frames(len: usize, warmup: usize, count: usize) -> Vec<usize> {
    let first = 2 * warmup + 1;
    let candidates: Vec<usize> = (first..len.saturating_sub(1)).step_by(2).collect();
    if candidates.is_empty() || count == 0 {
        return Vec::new();
    }
    let count = count.min(candidates.len());
    (0..count)
        .map(|i| candidates[(2 * i + 1) * candidates.len() / (2 * count)])
        .collect()
}

/// A variant with its generators and accumulators.
struct Run<'a> {
    variant: &'a Variant,
    generators: Vec<(BackendKind, FrameGenerator)>,
    quality: Accumulator,
    timing: Vec<TimingAcc>,
    agreement: Option<f64>,
}

/// What one pass over a sequence produced.
struct GroupOutput {
    rows: Vec<Row>,
    /// What the fed frames' streams cost (when they are coded).
    stream: Vec<transport::StreamCost>,
    /// Per heat-map truth frame: (label, generated image, truth image, ꟻLIP map).
    heat: Vec<(usize, Vec<heatmap::Capture>)>,
}

/// Whether `v` is gffe's geometry-aware result at its defaults, without
/// shading correction: the frame GFFE eq. 3's focus region is defined from
/// (the `no-shading` row, or the gffe row where the stream's effects plan
/// no shading correction).
fn geometry_aware(v: &Variant) -> bool {
    let s = &v.settings;
    matches!(v.axis, Axis::Method | Axis::Shading)
        && !v.oracle
        && !v.given_camera
        && !v.shading_oracle
        && s.method == framegen::Method::Gffe
        && !s.effective_shading()
}

fn run_group(
    seq: &mut Sequence,
    variants: &[Variant],
    ctx: Option<&Arc<GpuContext>>,
    config: &EvalConfig,
    (heat_frames, save): (Option<&[usize]>, Option<(&std::path::Path, &str)>),
    (focus, keep_focus): (&mut HashMap<usize, Vec<bool>>, bool),
    bar: &ProgressBar,
) -> anyhow::Result<GroupOutput> {
    let mut runs = variants
        .iter()
        .map(|v| {
            // The oracle runs no generator (and is not timed).
            let backends: &[BackendKind] = if v.oracle { &[] } else { &config.backends };
            let generators = backends
                .iter()
                .map(|&b| {
                    let g = match (b, ctx) {
                        (BackendKind::Wgpu, Some(ctx)) => {
                            let backend = match config.pass_clock {
                                None => GpuBackend::profiled(ctx.clone()),
                                Some(clock) => GpuBackend::profiled_with(ctx.clone(), clock)
                                    .map_err(|(_, e)| e)?,
                            };
                            FrameGenerator::with_backend(v.settings, Box::new(backend))
                        }
                        _ => FrameGenerator::cpu(v.settings),
                    }?;
                    Ok((b, g))
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            Ok(Run {
                variant: v,
                timing: backends.iter().map(|&b| TimingAcc::new(b)).collect(),
                generators,
                quality: Accumulator::default(),
                agreement: None,
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let max_step = variants.iter().map(Variant::step).max().unwrap_or(1);
    let mut ring: VecDeque<Step> = VecDeque::with_capacity(2 * max_step);
    let mut transport = transport::Transport::new(config.geometry, &config.colors, seq.fps());
    let mut heat: HashMap<usize, Vec<heatmap::Capture>> = HashMap::new();
    let mut r = 0usize;
    while let Some(step) = seq.next_step()? {
        ring.push_back(step);
        if ring.len() > 2 * max_step {
            ring.pop_front();
        }
        // ring holds sequence positions r + 1 − len ..= r.
        let at = |k: usize| &ring[ring.len() - 1 - (r - k)];
        // Shared by the variants of this step: the fed frame per step size
        // and colour setting, the display-encoded truth per position.
        let mut kept: HashMap<(usize, video::ColorCodec), Arc<Frame>> = HashMap::new();
        // The fed frame per step size before the stream's codecs.
        let mut decimated: HashMap<usize, Frame> = HashMap::new();
        let mut truths: HashMap<usize, Arc<protocol::display::DisplayImage>> = HashMap::new();
        // What each variant generated this step, scored once all are in.
        let mut pending = Vec::new();
        // The variants take turns going first: the first after a new frame
        // pays for its decimation and colder caches (measured: gffe alone
        // first took 15–40 % longer than the same settings run third).
        let count = runs.len();
        for index in (0..count).map(|i| (i + r) % count) {
            let run = &mut runs[index];
            let s = run.variant.step();
            if (r + 1) % s != 0 {
                continue;
            }
            let m = r + 1 - s;
            let color = run.variant.color;
            let fed = match kept.get(&(s, color)) {
                Some(fed) => fed.clone(),
                None => {
                    // The fed frame as rendered, once per step size for
                    // every colour setting.
                    let fed = match decimated.get(&s) {
                        Some(fed) => Frame::clone(fed),
                        None => {
                            // A scene's fed frame is rendered at the fed
                            // rate, as a server at that rate renders it; a
                            // dump's motion is composed through the skipped
                            // frames. Composition takes a vector from the
                            // wrong surface along moving edges (crossing at
                            // 96×54: 15–20 pixels a frame off by over half
                            // a pixel) and, coded, costs ten times the bits
                            // of rendered motion (720p).
                            let fed = match seq.render_fed(at(m).fed.meta.index, s)? {
                                Some(frame) => framegen::decimate::kept(&frame, &[], s),
                                None => {
                                    let skipped: Vec<&Frame> = if m >= s {
                                        (m + 1 - s..m).map(|k| at(k).fed.as_ref()).collect()
                                    } else {
                                        Vec::new()
                                    };
                                    framegen::decimate::kept(&at(m).fed, &skipped, s)
                                }
                            };
                            // Kept for the other colour settings, if any.
                            if config.colors.len() > 1 {
                                decimated.insert(s, fed.clone());
                            }
                            fed
                        }
                    };
                    // Through the stream's codecs, coded against the fed
                    // frame before it, as a server at this rate sends it.
                    let previous = (m >= s).then(|| &at(m - s).fed.meta);
                    let fed = Arc::new(transport.carry(fed, previous, s, color)?);
                    kept.insert((s, color), fed.clone());
                    fed
                }
            };
            let scored = m / s >= config.warmup.max(1);
            // A method that holds frames back shows frames that far behind
            // the newest fed one (interpolation: the interval before it).
            let behind = run.variant.settings.method.descriptor().held_back as usize * s;
            let mut outputs = Vec::new();
            if run.variant.oracle && scored {
                // The skipped frames with their motion composed back to the
                // fed one (`fed` is the plain view: window off).
                let settings = &run.variant.settings;
                let generated = (1..s)
                    .map(|j| {
                        let between: Vec<&Frame> =
                            (m + 1..m + j).map(|k| at(k).truth.as_ref()).collect();
                        let truth = framegen::decimate::kept(&at(m + j).truth, &between, 1);
                        let alpha = j as f64 / s as f64;
                        framegen::oracle::backward_warp(
                            &at(m).truth,
                            &truth,
                            alpha,
                            (settings.resample, settings.pushpull_levels),
                        )
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                outputs.push(generated);
            }
            // The shading oracle's displayed frames with the fed frame's
            // shading, once for every backend.
            let unshaded = if run.variant.shading_oracle && scored {
                (1..s)
                    .map(|j| {
                        let index = at(m + j).truth.meta.index;
                        seq.render_shaded(index, fed.meta.time)?
                            .context("the shading oracle needs a rendered scene")
                    })
                    .collect::<anyhow::Result<Vec<_>>>()?
            } else {
                Vec::new()
            };
            for ((b, g), t) in run.generators.iter_mut().zip(&mut run.timing) {
                // wgpu alternates: plain intervals give the true totals (one
                // submission per push and per generation), profiled ones in
                // between the per-pass times (a submission and a wait per
                // pass). The CPU reference times its passes for free.
                let profiled = *b == BackendKind::Wgpu && (m / s) % 2 == 1;
                g.set_profiling(profiled);
                let start = Instant::now();
                g.push_shared(&fed)?;
                let push = start.elapsed();
                if !scored {
                    continue;
                }
                let mut generated = Vec::new();
                let mut gen_time = Vec::new();
                for j in 1..s {
                    let start = Instant::now();
                    let alpha = j as f64 / s as f64;
                    generated.push(if run.variant.given_camera {
                        // The skipped frame's camera (the plain view's pose:
                        // a window changes the projection, not the pose).
                        let pose = at(m + j).truth.meta.camera.pose;
                        g.generate_with(alpha, framegen::CameraSource::Given(pose))?
                    } else {
                        g.generate(alpha)?
                    });
                    gen_time.push(start.elapsed());
                }
                // Not part of the generator: applied after its timing.
                for (j, unshaded) in unshaded.iter().enumerate() {
                    let truth = &at(m + j + 1).truth;
                    framegen::oracle::shade(&mut generated[j].frame, truth, unshaded)?;
                }
                let passes = if g.profiling() {
                    g.timings()
                } else {
                    Vec::new()
                };
                t.add(push, &gen_time, &passes, !profiled);
                outputs.push(generated);
            }
            if scored {
                pending.push((index, outputs, m, s, behind));
            }
        }
        // GFFE eq. 3's focus region of each truth frame, from the
        // geometry-aware result (gffe without shading correction), for
        // every variant alike (kept in `focus` for the groups that follow).
        for (index, outputs, m, s, behind) in &pending {
            let v = runs[*index].variant;
            if !geometry_aware(v) {
                continue;
            }
            for j in 1..*s {
                let pos = m + j - behind;
                if let Some(mask) = measure::focus_mask(&outputs[0][j - 1].frame, &at(pos).truth) {
                    focus.insert(pos, mask);
                }
            }
        }
        for (index, outputs, m, s, behind) in pending {
            let run = &mut runs[index];
            for j in 1..s {
                let truth_pos = m + j - behind;
                let truth = &at(truth_pos).truth;
                let size = truth.meta.size;
                let g = &outputs[0][j - 1];
                let gs = g.frame.meta.size;
                anyhow::ensure!(
                    gs == size,
                    "{}: generated {}x{} but the truth is {}x{}",
                    run.variant.label,
                    gs.width,
                    gs.height,
                    size.width,
                    size.height
                );
                let encode = |f: &Frame| {
                    framegen::display_encode(size.width, size.height, &f.color)
                        .context("display encode")
                };
                let test = encode(&g.frame)?;
                let truth_image = match truths.get(&truth_pos) {
                    Some(t) => t.clone(),
                    None => {
                        let t = Arc::new(encode(truth)?);
                        truths.insert(truth_pos, t.clone());
                        t
                    }
                };
                if let Some((root, scene)) = save {
                    let dir = save::dir(root, scene, &run.variant.label);
                    save::write(&dir, truth.meta.index, &g.frame, &test)?;
                }
                let regions = measure::regions(g, truth);
                let sc = score(
                    &test,
                    &truth_image,
                    &regions,
                    // Eq. 3's region is the extrapolators' (it is defined
                    // on the frame after the rendered one).
                    focus
                        .get(&truth_pos)
                        .filter(|_| behind == 0)
                        .map(Vec::as_slice),
                )?;
                run.quality.add(&sc, g);
                for other in outputs.iter().skip(1) {
                    let p = framegen::psnr(&test, &encode(&other[j - 1].frame)?)?
                        .min(measure::PSNR_CAP);
                    run.agreement = Some(run.agreement.map_or(p, |a: f64| a.min(p)));
                }
                if run.variant.axis == Axis::Method
                    && !run.variant.given_camera
                    && s == 2
                    && heat_frames.is_some_and(|h| h.contains(&truth_pos))
                {
                    heat.entry(truth_pos).or_default().push(heatmap::Capture {
                        label: run.variant.label.clone(),
                        test,
                        truth: (*truth_image).clone(),
                        flip: sc.flip_map,
                        flip_mean: sc.flip,
                    });
                }
            }
        }
        if !keep_focus {
            // No step of this group scores a position older than the ring.
            focus.retain(|&pos, _| pos + 2 * max_step > r);
        }
        bar.inc(1);
        r += 1;
    }
    let render = seq.render_cost();
    let stream = transport.costs();
    let rows = runs
        .into_iter()
        .map(|run| {
            let mut row = Row::new(run.variant, run.quality.finish(), run.timing, run.agreement);
            row.render = render;
            // The stream this variant was fed, when it was coded.
            row.stream_mbit = stream
                .iter()
                .find(|c| c.step == run.variant.step() && c.setting == row.color_codec)
                .map(|c| c.total_mbit);
            row
        })
        .collect();
    let mut heat: Vec<_> = heat.into_iter().collect();
    heat.sort_by_key(|(k, _)| *k);
    Ok(GroupOutput { rows, stream, heat })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heatmap_frames_are_scored_by_both_kinds_of_method() {
        let f = heatmap_frames(24, 2, 2);
        assert_eq!(f.len(), 2);
        for t in f {
            assert!(t % 2 == 1 && t >= 5 && t + 1 < 24, "{t}");
        }
        assert!(heatmap_frames(4, 2, 3).is_empty());
    }
}
