//! The numbers of an `eval` run, their Pareto fronts, and the files:
//! `report.json` (every number) and `report.md` (tables per scene).
//!
//! A variant is on a Pareto front when no other variant of the same scene,
//! resolution and n is at least as fast (ms per generated frame on that
//! backend) and at least as accurate (mean ꟻLIP), one of them strictly.
//! Two fronts are marked: among the methods that add no latency (★), and
//! among all, interpolation included (☆ where only that front holds it):
//! interpolation buys its accuracy with a render interval of latency.

use std::fmt::Write as _;
use std::path::Path;

use framegen::GpuContext;
use serde::Serialize;

use super::measure::{Quality, RegionQuality};
use super::sequence::{RenderCost, RenderOrigin};
use super::timing::{CopyFloor, Timing, TimingAcc};
use super::variant::{Axis, CODEC_METHODS, EVERY_STAGE, Variant};
use super::{BackendKind, EvalConfig};

/// Everything an `eval` run measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// How it was produced.
    pub command: String,
    /// Seconds since the Unix epoch when it was written.
    pub created_unix: u64,
    /// The machine.
    pub machine: Machine,
    /// Frames per sequence at the display rate.
    pub frames: u64,
    /// First frame.
    pub start: u64,
    /// Display rate of rendered scenes.
    pub fps: f64,
    /// Fed frames before scoring.
    pub warmup: usize,
    /// Backends, first = the one quality is scored on.
    pub backends: Vec<BackendKind>,
    /// The bandwidth floor per size.
    pub copy_floor: Vec<CopyFloor>,
    /// Per scene (or dump).
    pub scenes: Vec<SceneReport>,
    /// Heat-map images, relative to the report directory.
    pub heatmaps: Vec<String>,
}

/// Where it ran.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    /// Logical CPUs.
    pub cpu_threads: usize,
    /// The wgpu adapter, if one was used.
    pub adapter: Option<String>,
}

/// One scene's rows.
#[derive(Clone, Debug, Serialize)]
pub struct SceneReport {
    /// Scene or dump name.
    pub scene: String,
    /// One per variant, in sweep order.
    pub rows: Vec<Row>,
    /// What the fed frames' streams cost, per fed rate (empty when frames
    /// are fed as rendered).
    pub stream: Vec<super::transport::StreamCost>,
}

/// One variant's numbers.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// The variant's label.
    pub label: String,
    /// What it varies.
    pub axis: Axis,
    /// Method name.
    pub method: String,
    /// Generated frames per rendered frame.
    pub n: u32,
    /// History length (gffe).
    pub history: u32,
    /// Background levels (gffe).
    pub background_levels: u32,
    /// Push-pull levels.
    pub pushpull_levels: u32,
    /// Static threshold ε (px).
    pub static_epsilon: f32,
    /// Whether shading correction ran (gffe, where the effects call for it).
    pub shading: bool,
    /// The stages it ran, planned from the method and the stream's effects
    /// ([`framegen::pipeline::plan::Plan`]).
    pub plan: String,
    /// The warp's colour filter.
    pub resample: &'static str,
    /// Adaptive window mode.
    pub window: &'static str,
    /// `WxH`.
    pub size: String,
    /// How its fed frames' colour travelled (`raw`, `h264@8`, ...).
    pub color_codec: String,
    /// All buffers of the stream it was fed, Mbit/s at the fed rate;
    /// `None` when frames were fed as rendered.
    pub stream_mbit: Option<f64>,
    /// Render intervals of added latency.
    pub added_latency_frames: u32,
    /// Generated with the skipped frame's own camera (what late input
    /// gives an interactive stream) instead of GFFE eq. 2's: on no front,
    /// since a stream without input cannot have it.
    pub given_camera: bool,
    /// gffe without shading correction given the exact shading change
    /// (the shading oracle, `framegen::oracle::shade`): the bound of shading
    /// correction, on no front.
    pub shading_oracle: bool,
    /// Quality against ground truth.
    pub quality: Quality,
    /// Per backend.
    pub timing: Vec<Timing>,
    /// What rendering one fed frame of this variant's sequence cost.
    pub render: Option<RenderCost>,
    /// Lowest PSNR between the first backend's output and another's.
    pub backend_agreement_psnr: Option<f64>,
    /// Backends on whose zero-latency front it lies.
    pub front_zero_latency: Vec<BackendKind>,
    /// Backends on whose all-methods front it lies.
    pub front_all: Vec<BackendKind>,
}

impl Row {
    /// Assembles a row.
    pub fn new(
        v: &Variant,
        quality: Quality,
        timing: Vec<TimingAcc>,
        agreement: Option<f64>,
    ) -> Self {
        let s = &v.settings;
        Self {
            label: v.label.clone(),
            axis: v.axis,
            method: s.method.name().into(),
            n: s.n,
            history: s.effective_history(),
            background_levels: s.effective_levels(),
            pushpull_levels: s.pushpull_levels,
            static_epsilon: s.static_epsilon,
            shading: s.effective_shading(),
            plan: s.plan().to_string(),
            resample: s.resample.name(),
            window: v.window.name(),
            size: format!("{}x{}", v.size.width, v.size.height),
            color_codec: v.color.to_string(),
            stream_mbit: None,
            added_latency_frames: v.added_latency_frames(),
            given_camera: v.given_camera,
            shading_oracle: v.shading_oracle,
            quality,
            timing: timing.iter().map(TimingAcc::finish).collect(),
            render: None,
            backend_agreement_psnr: agreement,
            front_zero_latency: Vec::new(),
            front_all: Vec::new(),
        }
    }

    /// Its time on `backend`, ms per generated frame.
    pub fn ms(&self, backend: BackendKind) -> Option<f64> {
        self.timing
            .iter()
            .find(|t| t.backend == backend)
            .map(|t| t.per_generated_ms)
    }

    /// Its time on `backend` as a multiple of rendering the frame it is fed
    /// ([`Row::render`]): frame generation pays off only well below 1.
    pub fn render_multiple(&self, backend: BackendKind) -> Option<f64> {
        let render = self.render.filter(|r| r.ms > 0.0)?;
        Some(self.ms(backend)? / render.ms)
    }

    fn front_mark(&self, backend: BackendKind) -> &'static str {
        if self.front_zero_latency.contains(&backend) {
            "★"
        } else if self.front_all.contains(&backend) {
            "☆"
        } else {
            ""
        }
    }
}

/// One colour setting of a bitrate sweep in one scene (issue 19 §5).
#[derive(Clone, Debug)]
pub struct BitratePoint {
    /// The colour setting as given (`raw`, `h264@8`, ...).
    pub setting: String,
    /// The fed stream's Mbit/s, all buffers; `None` when not coded.
    pub mbit: Option<f64>,
    /// The decoded colour's mean ꟻLIP against the rendered (video codecs).
    pub color_flip: Option<f64>,
    /// The colour codec's median encode and decode ms per frame.
    pub color_ms: Option<(f64, f64)>,
    /// Mean ꟻLIP of each of [`CODEC_METHODS`] fed that stream.
    pub flip: [Option<f64>; 2],
}

/// The bitrate sweep of a scene: per colour setting, in the order given,
/// what its stream cost and what [`CODEC_METHODS`] made of it (n = 1, the
/// main size); empty unless more than one setting was fed.
pub fn bitrate(scene: &SceneReport) -> Vec<BitratePoint> {
    let Some(size) = scene.rows.first().map(|r| r.size.as_str()) else {
        return Vec::new();
    };
    let rows: Vec<&Row> = scene
        .rows
        .iter()
        .filter(|r| r.size == size && r.n == 1)
        .filter(|r| match r.axis {
            Axis::Method => r.label == r.method,
            Axis::Codec => true,
            _ => false,
        })
        .collect();
    let mut settings: Vec<&str> = Vec::new();
    for r in &rows {
        if !settings.contains(&r.color_codec.as_str()) {
            settings.push(&r.color_codec);
        }
    }
    if settings.len() < 2 {
        return Vec::new();
    }
    settings
        .into_iter()
        .map(|setting| {
            let of = |m: framegen::Method| {
                rows.iter()
                    .find(|r| r.method == m.name() && r.color_codec == setting)
            };
            let stream = scene
                .stream
                .iter()
                .find(|c| c.step == 2 && c.setting == setting);
            BitratePoint {
                setting: setting.to_string(),
                mbit: stream.map(|c| c.total_mbit),
                color_flip: stream.and_then(|c| c.color_flip),
                color_ms: stream.and_then(|c| c.color_ms),
                flip: CODEC_METHODS.map(|m| of(m).map(|r| r.quality.flip)),
            }
        })
        .collect()
}

/// Indices of the Pareto-optimal points (minimise both coordinates).
pub fn pareto(points: &[(f64, f64)]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let (a, b) = points[i];
            !points
                .iter()
                .enumerate()
                .any(|(j, &(c, d))| j != i && c <= a && d <= b && (c < a || d < b))
        })
        .collect()
}

impl Report {
    /// Collects the parts.
    pub fn new(
        config: &EvalConfig,
        ctx: Option<&GpuContext>,
        scenes: Vec<SceneReport>,
        copy_floor: Vec<CopyFloor>,
        heatmaps: Vec<String>,
    ) -> Self {
        Self {
            command: config.command.clone(),
            created_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            machine: Machine {
                cpu_threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
                adapter: ctx.map(|c| {
                    format!(
                        "{} ({:?}, {:?})",
                        c.adapter_info.name, c.adapter_info.device_type, c.adapter_info.backend
                    )
                }),
            },
            frames: config.frames,
            start: config.start,
            fps: config.fps,
            warmup: config.warmup,
            backends: config.backends.clone(),
            copy_floor,
            scenes,
            heatmaps,
        }
    }

    /// Marks both fronts per scene, size, n and backend.
    pub fn mark_pareto(&mut self) {
        let backends = self.backends.clone();
        for scene in &mut self.scenes {
            let mut keys: Vec<(String, u32)> =
                scene.rows.iter().map(|r| (r.size.clone(), r.n)).collect();
            keys.sort();
            keys.dedup();
            for (size, n) in keys {
                for &b in &backends {
                    for zero_latency in [true, false] {
                        let members: Vec<usize> = (0..scene.rows.len())
                            .filter(|&i| {
                                let r = &scene.rows[i];
                                r.size == size
                                    && r.n == n
                                    && !r.given_camera
                                    && !r.shading_oracle
                                    && (!zero_latency || r.added_latency_frames == 0)
                                    && r.ms(b).is_some()
                            })
                            .collect();
                        let points: Vec<(f64, f64)> = members
                            .iter()
                            .map(|&i| {
                                let r = &scene.rows[i];
                                (r.ms(b).unwrap_or(f64::INFINITY), r.quality.flip)
                            })
                            .collect();
                        for k in pareto(&points) {
                            let row = &mut scene.rows[members[k]];
                            if zero_latency {
                                row.front_zero_latency.push(b);
                            } else {
                                row.front_all.push(b);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Writes `report.json` and `report.md` into `dir`.
    pub fn write(&self, dir: &Path) -> anyhow::Result<()> {
        std::fs::write(dir.join("report.json"), serde_json::to_vec(self)?)?;
        std::fs::write(dir.join("report.md"), self.markdown())?;
        Ok(())
    }

    /// The streams' costs, when fed frames went through the stream's codecs
    /// (`--geometry compact`, `--color-codec`).
    fn streams(&self, md: &mut String) {
        if self.scenes.iter().all(|s| s.stream.is_empty()) {
            return;
        }
        let _ = writeln!(md, "\n## Stream codecs\n");
        let _ = writeln!(
            md,
            "Fed frames went through the stream's codecs before the generator saw them; one stream per fed rate and colour setting. \
             Mbit/s per buffer at the stream's rate; colour PSNR is the decoded against the rendered in display \
             space (mean, worst frame), and its ꟻLIP; codes changed: the share of the 8-bit display values ꟻLIP compares \
             that differ (ꟻLIP weighs even one-code changes: one code up everywhere scores 0.034 on a grey ramp); encode and decode are medians over all buffers, of which the colour \
             codec's in parentheses.\n"
        );
        let _ = writeln!(
            md,
            "| scene | fps | colour | colour Mbit/s | depth Mbit/s | motion Mbit/s | total Mbit/s | colour PSNR dB | colour ꟻLIP | codes changed % | encode ms | decode ms |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|");
        for scene in &self.scenes {
            for c in &scene.stream {
                let mbit = |k: &str| c.mbit.get(k).map_or("—".into(), |v| format!("{v:.2}"));
                let _ = writeln!(
                    md,
                    "| {} | {:.1} | {} | {} | {} | {} | {:.2} | {} | {} | {} | {:.2}{} | {:.2}{} |",
                    scene.scene,
                    c.fps,
                    c.color_codec,
                    mbit("color"),
                    mbit("depth"),
                    mbit("motion"),
                    c.total_mbit,
                    c.color_psnr.map_or("—".into(), |(mean, worst)| format!(
                        "{mean:.2} ({worst:.2})"
                    )),
                    c.color_flip.map_or("—".into(), |f| format!("{f:.4}")),
                    c.color_codes_changed
                        .map_or("—".into(), |f| format!("{:.1}", 100.0 * f)),
                    c.encode_ms,
                    c.color_ms
                        .map_or(String::new(), |(e, _)| format!(" ({e:.2})")),
                    c.decode_ms,
                    c.color_ms
                        .map_or(String::new(), |(_, d)| format!(" ({d:.2})")),
                );
            }
        }
    }

    /// Each scene's bitrate sweep ([`bitrate`]), the scenes without one
    /// left out.
    pub fn bitrate_sweeps(&self) -> Vec<(&str, Vec<BitratePoint>)> {
        self.scenes
            .iter()
            .map(|s| (s.scene.as_str(), bitrate(s)))
            .filter(|(_, b)| !b.is_empty())
            .collect()
    }

    /// The bitrate sweep (`--color-codec` with several settings): per
    /// scene and setting, the stream's Mbit/s and what generation made of
    /// it, against the first setting.
    fn bitrates(&self, md: &mut String) {
        let sweeps = self.bitrate_sweeps();
        if sweeps.is_empty() {
            return;
        }
        let names: Vec<&str> = CODEC_METHODS.iter().map(|m| m.name()).collect();
        let _ = writeln!(md, "\n## Bitrate: generated frames against Mbit/s\n");
        let _ = writeln!(
            md,
            "![ꟻLIP against Mbit/s](plots/bitrate.png)\n\n\
             {} fed (n = 1) through each colour setting; Mbit/s of all buffers at the fed rate; in brackets, \
             the change from the first setting. Colour ms: the colour codec's median encode / decode per frame.\n",
            names.join(" and ")
        );
        let _ = write!(md, "| scene | colour | Mbit/s | colour ꟻLIP |");
        for n in &names {
            let _ = write!(md, " {n} ꟻLIP |");
        }
        let _ = writeln!(md, " colour ms |");
        let _ = writeln!(md, "|---|---|---|---|{}---|", "---|".repeat(names.len()));
        for (scene, points) in &sweeps {
            let base = &points[0];
            for p in points {
                let _ = write!(
                    md,
                    "| {scene} | {} | {} | {} |",
                    p.setting,
                    p.mbit.map_or("—".into(), |v| format!("{v:.2}")),
                    p.color_flip.map_or("—".into(), |v| format!("{v:.4}"))
                );
                for (f, b) in p.flip.iter().zip(&base.flip) {
                    let cell = match (f, b) {
                        (Some(f), Some(b)) if !std::ptr::eq(p, base) => {
                            format!("{f:.4} ({:+.4})", f - b)
                        }
                        (Some(f), _) => format!("{f:.4}"),
                        _ => "—".into(),
                    };
                    let _ = write!(md, " {cell} |");
                }
                let _ = writeln!(
                    md,
                    " {} |",
                    p.color_ms
                        .map_or("—".into(), |(e, d)| format!("{e:.2} / {d:.2}"))
                );
            }
        }
    }

    /// The Markdown report.
    pub fn markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(md, "# Frame generation: accuracy against time\n");
        let _ = writeln!(md, "Produced by `{}`.\n", self.command);
        let _ = writeln!(
            md,
            "{} frames per sequence from frame {} at {} fps (the display rate); every (n+1)-th frame is fed, \
             each generated frame is compared with the skipped rendered frame it stands for (the extrapolators: \
             the one after the last fed frame; `interp`: the one before). The first {} fed frames only warm up. \
             Metrics on display-encoded images (Reinhard + sRGB): PSNR (dB, capped at 100), SSIM, and ꟻLIP \
             (mean error, lower is better; `nv-flip`, 67 pixels per degree). Regions: *disoccluded* = no warped \
             source (background layers or push-pull), *dynamic* = on an animated object in the ground truth, \
             *static* = the rest; across them, *focus* (GFFE eq. 3) = where gffe without shading correction (the \
             geometry-aware result) differs from the truth by SMAPE > 0.5 against all 9 truth pixels around it, not dynamic: the shading a \
             geometry-aware warp leaves behind (the same pixels for every variant).\n",
            self.frames, self.start, self.fps, self.warmup
        );
        let _ = writeln!(
            md,
            "Machine: {} CPU threads; wgpu adapter: {}.\n",
            self.machine.cpu_threads,
            self.machine.adapter.as_deref().unwrap_or("none")
        );
        let _ = writeln!(
            md,
            "Times are ms per generated frame: (push + n generations) / n, the median over the sequence.\n"
        );
        for b in &self.backends {
            let how = self
                .scenes
                .iter()
                .flat_map(|s| &s.rows)
                .flat_map(|r| &r.timing)
                .find(|t| t.backend == *b)
                .map_or("not measured", |t| t.how);
            let _ = writeln!(md, "* `{}`: {how}.", b.name());
        }
        let _ = writeln!(
            md,
            "\n★ = on the Pareto front (ms on that backend against mean ꟻLIP, same scene, resolution and n) among \
             the methods that add no latency; ☆ = on the front only when interpolation (one render interval of \
             added latency) is admitted. Two rows stand beside gffe as references, on neither front: `gffe \
             oracle-motion` (the skipped frame's true depth and motion applied to the fed frame: what G-buffers of \
             the future frame would buy; untimed) and `gffe given-camera` (gffe with the skipped frame's own camera \
             instead of GFFE eq. 2's extrapolation: what an interactive stream's late input gives, and what eq. 2's \
             guess of the camera costs). `gffe oracle-shading` (scenes only) bounds shading correction (GFFE §4.4): \
             gffe without it, its frames given the exact change of shading since the fed frame (the truth over the \
             truth rendered with the fed frame's lights and shadows); it is on no front either.\n"
        );
        let _ = writeln!(md, "## Bandwidth floor\n");
        let _ = writeln!(
            md,
            "A copy of the bytes a frame's inputs take (28 B/px), which any pass reads at least once.\n"
        );
        let _ = writeln!(md, "| size | bytes | CPU memcpy ms | wgpu buffer copy ms |");
        let _ = writeln!(md, "|---|---|---|---|");
        for c in &self.copy_floor {
            let _ = writeln!(
                md,
                "| {} | {} | {:.3} | {} |",
                c.size,
                c.bytes,
                c.cpu_ms,
                c.wgpu_ms.map_or("—".into(), |v| format!("{v:.3}"))
            );
        }
        self.summary(&mut md);
        self.plans(&mut md);
        self.streams(&mut md);
        self.bitrates(&mut md);
        for scene in &self.scenes {
            self.scene_section(&mut md, scene);
        }
        if !self.heatmaps.is_empty() {
            let _ = writeln!(md, "\n## ꟻLIP heat maps\n");
            let _ = writeln!(
                md,
                "Top row: the ground truth, then each method's output (repeat, reproject, gffe, interp) at α = 0.5. \
                 Bottom row: each method's ꟻLIP error map (magma: black = no visible error, yellow = large).\n"
            );
            for h in &self.heatmaps {
                let _ = writeln!(md, "![{h}]({h})\n");
            }
        }
        md
    }

    /// Methods at their defaults across scenes, and how often each variant
    /// is on a front.
    fn summary(&self, md: &mut String) {
        let _ = writeln!(md, "\n## Summary: methods at their defaults\n");
        let methods: Vec<String> = framegen::Method::ALL
            .iter()
            .map(|m| m.name().to_string())
            .collect();
        let _ = write!(md, "| scene |");
        for m in &methods {
            let _ = write!(md, " {m} PSNR / ꟻLIP |");
        }
        let _ = writeln!(md);
        let _ = writeln!(md, "|---|{}", "---|".repeat(methods.len()));
        for scene in &self.scenes {
            let _ = write!(md, "| {} |", scene.scene);
            for m in &methods {
                match scene
                    .rows
                    .iter()
                    .find(|r| r.axis == Axis::Method && &r.method == m)
                {
                    Some(r) => {
                        let _ = write!(md, " {:.2} / {:.4} |", r.quality.psnr, r.quality.flip);
                    }
                    None => {
                        let _ = write!(md, " — |");
                    }
                }
            }
            let _ = writeln!(md);
        }
        let _ = writeln!(
            md,
            "\n### How often each variant is on the zero-latency front\n"
        );
        let _ = write!(md, "| variant |");
        for b in &self.backends {
            let _ = write!(md, " {} (of {} scenes) |", b.name(), self.scenes.len());
        }
        let _ = write!(md, " mean ꟻLIP |");
        for b in &self.backends {
            let _ = write!(md, " mean {} ms |", b.name());
        }
        for b in &self.backends {
            let _ = write!(md, " mean {} × render |", b.name());
        }
        let _ = writeln!(md);
        let _ = writeln!(md, "|---|{}", "---|".repeat(3 * self.backends.len() + 1));
        let Some(first) = self.scenes.first() else {
            return;
        };
        for row in &first.rows {
            let same: Vec<&Row> = self
                .scenes
                .iter()
                .filter_map(|s| s.rows.iter().find(|r| r.label == row.label))
                .collect();
            let _ = write!(md, "| {} |", row.label);
            for b in &self.backends {
                let on = same
                    .iter()
                    .filter(|r| r.front_zero_latency.contains(b))
                    .count();
                let _ = write!(md, " {on} / {} |", same.len());
            }
            // The mean over the scenes that have the value ("—" if none:
            // the untimed oracle).
            let mean = |f: &dyn Fn(&Row) -> Option<f64>, digits: usize, unit: &str| {
                let v: Vec<f64> = same.iter().filter_map(|r| f(r)).collect();
                if v.is_empty() {
                    return "—".to_string();
                }
                format!("{:.digits$}{unit}", v.iter().sum::<f64>() / v.len() as f64)
            };
            let _ = write!(md, " {} |", mean(&|r| Some(r.quality.flip), 4, ""));
            for &b in &self.backends {
                let _ = write!(md, " {} |", mean(&|r| r.ms(b), 2, ""));
            }
            for &b in &self.backends {
                let _ = write!(md, " {} |", mean(&|r| r.render_multiple(b), 2, "×"));
            }
            let _ = writeln!(md);
        }
    }

    /// What planning the stages from each stream's effects saves (issue
    /// 17): gffe as planned against gffe running every stage.
    fn plans(&self, md: &mut String) {
        let pairs: Vec<(&str, &Row, &Row)> = self
            .scenes
            .iter()
            .filter_map(|s| {
                let planned = s
                    .rows
                    .iter()
                    .find(|r| r.axis == Axis::Method && r.method == "gffe")?;
                let every = s.rows.iter().find(|r| r.label == EVERY_STAGE)?;
                Some((s.scene.as_str(), planned, every))
            })
            .collect();
        if pairs.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "
## Stages planned from the stream's effects
"
        );
        let _ = writeln!(
            md,
            "gffe runs only the stages its stream's effects call for: shading correction where shading moves, \
             trajectories where objects move (`framegen::pipeline::plan`). Against `{EVERY_STAGE}` (the same \
             settings, effects unknown):\n"
        );
        let _ = write!(md, "| scene | plan |");
        for b in &self.backends {
            let _ = write!(md, " {} ms every stage → planned (saved) |", b.name());
        }
        let _ = writeln!(md, " ꟻLIP every stage → planned |");
        let _ = writeln!(md, "|---|---|{}---|", "---|".repeat(self.backends.len()));
        for (scene, planned, every) in pairs {
            // The stages in words, without the pass lists.
            let stages = planned.plan.split_once(": ").map_or("", |(_, s)| s);
            let stages = stages.split(';').next().unwrap_or(stages);
            let _ = write!(md, "| {scene} | {stages} |");
            for &b in &self.backends {
                match (every.ms(b), planned.ms(b)) {
                    (Some(e), Some(p)) => {
                        let saved = 100.0 * (1.0 - p / e);
                        let _ = write!(md, " {e:.2} → {p:.2} ({saved:.0} %) |");
                    }
                    _ => {
                        let _ = write!(md, " — |");
                    }
                }
            }
            let _ = writeln!(
                md,
                " {:.4} → {:.4} |",
                every.quality.flip, planned.quality.flip
            );
        }
    }

    fn scene_section(&self, md: &mut String, scene: &SceneReport) {
        let _ = writeln!(md, "\n## {}\n", scene.scene);
        let _ = writeln!(
            md,
            "![ꟻLIP against ms](plots/{}.png)\n",
            plot_name(&scene.scene)
        );
        // One render cost per group of frames (size and window).
        let mut renders: Vec<String> = Vec::new();
        for r in &scene.rows {
            let Some(c) = r.render else { continue };
            let origin = match c.origin {
                RenderOrigin::ThisRun => "rendered in this run",
                RenderOrigin::Recorded => "as recorded in the dump",
            };
            let text = format!(
                "{:.2} ms at {} window {} ({origin}, median of {} frames)",
                c.ms, r.size, r.window, c.frames
            );
            if !renders.contains(&text) {
                renders.push(text);
            }
        }
        if !renders.is_empty() {
            let _ = writeln!(
                md,
                "Rendering one fed frame: {}. Each backend's ms per generated frame is followed by that \
                 time as a multiple of the render of the same frames.\n",
                renders.join("; ")
            );
        }
        let _ = write!(
            md,
            "| variant | size | PSNR | SSIM | ꟻLIP | disoccluded % / ꟻLIP | dynamic % / ꟻLIP | static ꟻLIP | focus % / ꟻLIP | bg / filled % |"
        );
        for b in &self.backends {
            let _ = write!(md, " {} ms |", b.name());
        }
        let _ = writeln!(md, " front | backends agree (dB) |");
        let _ = writeln!(
            md,
            "|---|---|---|---|---|---|---|---|---|---|{}---|---|",
            "---|".repeat(self.backends.len())
        );
        let mut axis = None;
        for r in &scene.rows {
            if axis != Some(r.axis) {
                axis = Some(r.axis);
                let _ = writeln!(
                    md,
                    "| *{}* |{}",
                    r.axis.title(),
                    " |".repeat(11 + self.backends.len())
                );
            }
            let q = &r.quality;
            let pooled = |g: &RegionQuality| match g.flip {
                Some(f) => format!("{:.1} / {:.4}", 100.0 * g.share, f),
                None => "0 / —".into(),
            };
            let _ = write!(
                md,
                "| {} | {} | {:.2} | {:.4} | {:.4} | {} | {} | {} | {} | {:.2} / {:.2} |",
                r.label,
                r.size,
                q.psnr,
                q.ssim,
                q.flip,
                pooled(&q.regions[0]),
                pooled(&q.regions[1]),
                q.regions[2].flip.map_or("—".into(), |f| format!("{f:.4}")),
                pooled(&q.focus),
                100.0 * q.sources.background,
                100.0 * q.sources.filled,
            );
            for &b in &self.backends {
                let ms = match (r.ms(b), r.render_multiple(b)) {
                    (Some(v), Some(x)) => format!("{v:.2} ({x:.2}×)"),
                    (Some(v), None) => format!("{v:.2}"),
                    _ => "—".into(),
                };
                let _ = write!(md, " {ms} |");
            }
            let marks: Vec<String> = self
                .backends
                .iter()
                .filter(|&&b| !r.front_mark(b).is_empty())
                .map(|&b| format!("{}{}", r.front_mark(b), b.name()))
                .collect();
            let _ = writeln!(
                md,
                " {} | {} |",
                marks.join(" "),
                r.backend_agreement_psnr
                    .map_or("—".into(), |p| format!("{p:.1}"))
            );
        }
        // Per-pass breakdown of the methods at their defaults, in ms and
        // in copies of the inputs (the bandwidth floor of that backend).
        let _ = writeln!(
            md,
            "\nPer pass, ms per rendered frame (push + its n generations) and, in brackets, that time in \
             copies of the frame's inputs on the same backend (the bandwidth floor above); methods at \
             their defaults:\n"
        );
        for &b in &self.backends {
            for r in scene.rows.iter().filter(|r| r.axis == Axis::Method) {
                let floor = self
                    .copy_floor
                    .iter()
                    .find(|c| c.size == r.size)
                    .and_then(|c| match b {
                        BackendKind::Cpu => Some(c.cpu_ms),
                        BackendKind::Wgpu => c.wgpu_ms,
                    })
                    .filter(|&f| f > 0.0);
                if let Some(t) = r.timing.iter().find(|t| t.backend == b) {
                    let passes: Vec<String> = t
                        .passes
                        .iter()
                        .map(|p| match floor {
                            Some(f) => format!("{} {:.2} ({:.0}×)", p.pass, p.ms, p.ms / f),
                            None => format!("{} {:.2}", p.pass, p.ms),
                        })
                        .collect();
                    let _ = writeln!(md, "* {} `{}`: {}", b.name(), r.label, passes.join(", "));
                }
            }
        }
    }
}

/// File stem of a scene's plot.
pub fn plot_name(scene: &str) -> String {
    scene
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_keeps_only_undominated_points() {
        let pts = [(1.0, 0.5), (2.0, 0.3), (3.0, 0.3), (2.5, 0.6), (0.5, 0.9)];
        assert_eq!(pareto(&pts), vec![0, 1, 4]);
        // Ties: equal points dominate neither each other.
        assert_eq!(pareto(&[(1.0, 1.0), (1.0, 1.0)]), vec![0, 1]);
    }
}
