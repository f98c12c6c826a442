//! Plots of error against milliseconds (the `plotters` crate): one PNG
//! per scene with a panel per backend, every variant a point coloured by
//! method (grey repeat, blue reproject, red gffe, green interp; rings add
//! latency), the zero-latency Pareto front drawn as a line, points on
//! either front labelled; plus `summary.png`, the means over scenes; and,
//! for a bitrate sweep, `bitrate.png`: ꟻLIP against Mbit/s (log scale),
//! a panel each for the decoded colour, gffe and interp, a line per scene
//! and their mean.
//!
//! Text needs a TrueType font: the first of a few system paths (DejaVu
//! Sans, which `.ci/run` installs) is registered with `plotters`' ab_glyph
//! backend. Without one, plots are skipped with a warning.

use std::path::Path;
use std::sync::OnceLock;

use plotters::prelude::*;

use super::BackendKind;
use super::report::{BitratePoint, Report, Row, pareto, plot_name};
use super::variant::{Axis, CODEC_METHODS};

const FONT_PATHS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

/// Registers a font once; false when none exists.
fn font() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| {
        for path in FONT_PATHS {
            if let Ok(bytes) = std::fs::read(path) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return true;
                }
            }
        }
        false
    })
}

fn method_color(method: &str) -> RGBColor {
    match method {
        "repeat" => RGBColor(120, 120, 120),
        "reproject" => RGBColor(31, 119, 180),
        "gffe" => RGBColor(214, 39, 40),
        _ => RGBColor(44, 160, 44),
    }
}

/// One point of a panel.
struct Point {
    label: String,
    method: String,
    ms: f64,
    flip: f64,
    zero_latency: bool,
}

/// Writes `plots/<scene>.png` for every scene and `plots/summary.png`.
pub fn write_all(report: &Report, out: &Path) -> anyhow::Result<()> {
    if !font() {
        tracing::warn!("no TrueType font found ({FONT_PATHS:?}): plots skipped");
        return Ok(());
    }
    let dir = out.join("plots");
    std::fs::create_dir_all(&dir)?;
    for scene in &report.scenes {
        // The main resolution only: other sizes have other errors and times.
        let size = scene
            .rows
            .first()
            .map(|r| r.size.clone())
            .unwrap_or_default();
        let rows: Vec<&Row> = scene
            .rows
            .iter()
            .filter(|r| r.size == size && r.n == 1)
            .collect();
        let panels: Vec<(BackendKind, Vec<Point>)> = report
            .backends
            .iter()
            .map(|&b| (b, points(&rows, b)))
            .collect();
        let title = format!("{} ({size}, n = 1)", scene.scene);
        draw(
            &dir.join(format!("{}.png", plot_name(&scene.scene))),
            &title,
            &panels,
        )?;
    }
    // Means over the scenes that have the variant.
    if let Some(first) = report.scenes.first() {
        let panels: Vec<(BackendKind, Vec<Point>)> = report
            .backends
            .iter()
            .map(|&b| {
                let pts = first
                    .rows
                    .iter()
                    .filter(|r| r.n == 1 && r.axis != Axis::Resolution)
                    .filter_map(|row| {
                        let same: Vec<&Row> = report
                            .scenes
                            .iter()
                            .filter_map(|s| s.rows.iter().find(|r| r.label == row.label))
                            .collect();
                        let ms: Vec<f64> = same.iter().filter_map(|r| r.ms(b)).collect();
                        (!ms.is_empty()).then(|| Point {
                            label: row.label.clone(),
                            method: row.method.clone(),
                            ms: ms.iter().sum::<f64>() / ms.len() as f64,
                            flip: same.iter().map(|r| r.quality.flip).sum::<f64>()
                                / same.len() as f64,
                            zero_latency: row.added_latency_frames == 0,
                        })
                    })
                    .collect();
                (b, pts)
            })
            .collect();
        let title = format!("mean over {} scenes (n = 1)", report.scenes.len());
        draw(&dir.join("summary.png"), &title, &panels)?;
    }
    bitrate_plot(report, &dir.join("bitrate.png"))?;
    Ok(())
}

/// A line of the bitrate plot: (Mbit/s, ꟻLIP, setting) per point.
type Line = Vec<(f64, f64, String)>;

/// `bitrate.png` when some scene swept colour settings: per panel (the
/// decoded colour, then each of [`CODEC_METHODS`]) a thin line per scene
/// and, over several scenes, their mean in black with the settings named.
fn bitrate_plot(report: &Report, path: &Path) -> anyhow::Result<()> {
    let sweeps = report.bitrate_sweeps();
    if sweeps.is_empty() {
        return Ok(());
    }
    // Panels: the decoded colour (None), then each method (Some(i)).
    let value = |p: &BitratePoint, panel: Option<usize>| match panel {
        None => p.color_flip,
        Some(i) => p.flip[i],
    };
    let names = std::iter::once("decoded colour").chain(CODEC_METHODS.iter().map(|m| m.name()));
    let panels: Vec<(&str, Vec<(String, Line)>)> = names
        .zip(std::iter::once(None).chain((0..CODEC_METHODS.len()).map(Some)))
        .map(|(name, panel)| {
            let mut lines: Vec<(String, Line)> = sweeps
                .iter()
                .map(|(scene, points)| {
                    // Each line runs from the cheapest stream to the dearest.
                    let mut l: Line = points
                        .iter()
                        .filter_map(|p| Some((p.mbit?, value(p, panel)?, p.setting.clone())))
                        .filter(|(m, f, _)| *m > 0.0 && f.is_finite())
                        .collect();
                    l.sort_by(|a, b| a.0.total_cmp(&b.0));
                    (scene.to_string(), l)
                })
                .filter(|(_, l)| !l.is_empty())
                .collect();
            if lines.len() > 1 {
                lines.push(("mean".into(), mean_line(&lines)));
            }
            (name, lines)
        })
        .collect();
    let (w, h) = (620u32, 480u32);
    let cols = panels.len() as u32;
    let mut buf = vec![255u8; (w * cols * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w * cols, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        for (area, (name, lines)) in root.split_evenly((1, cols as usize)).iter().zip(&panels) {
            draw_bitrate_panel(area, name, lines)?;
        }
        root.present().map_err(plot_err)?;
    }
    let img = image::RgbImage::from_raw(w * cols, h, buf)
        .ok_or_else(|| anyhow::anyhow!("plot buffer size"))?;
    img.save(path)?;
    Ok(())
}

/// The mean over lines that name the same settings in the same order
/// (every scene is fed the same ones); settings some line lacks are left
/// out.
fn mean_line(lines: &[(String, Line)]) -> Line {
    let Some((_, first)) = lines.first() else {
        return Vec::new();
    };
    let mut mean: Line = first
        .iter()
        .filter_map(|(_, _, setting)| {
            let at: Vec<(f64, f64)> = lines
                .iter()
                .filter_map(|(_, l)| l.iter().find(|p| &p.2 == setting).map(|p| (p.0, p.1)))
                .collect();
            (at.len() == lines.len()).then(|| {
                let n = at.len() as f64;
                (
                    at.iter().map(|p| p.0).sum::<f64>() / n,
                    at.iter().map(|p| p.1).sum::<f64>() / n,
                    setting.clone(),
                )
            })
        })
        .collect();
    mean.sort_by(|a, b| a.0.total_cmp(&b.0));
    mean
}

fn draw_bitrate_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    lines: &[(String, Line)],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let all = || lines.iter().flat_map(|(_, l)| l);
    let lo_x = all().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let hi_x = all().map(|p| p.0).fold(0.0, f64::max);
    let hi_y = all().map(|p| p.1).fold(0.0, f64::max);
    if !lo_x.is_finite() || hi_x <= 0.0 {
        return Ok(());
    }
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{title}: FLIP against Mbit/s"), ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (lo_x / 1.3..hi_x * 1.3).log_scale(),
            0.0..(hi_y * 1.15).max(1e-4),
        )
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .max_light_lines(1)
        .x_labels(6)
        .x_desc("Mbit/s, all buffers (log)")
        .y_desc("mean FLIP (lower is better)")
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(plot_err)?;
    let several = lines.len() > 1;
    for (i, (name, line)) in lines.iter().enumerate() {
        let mean = several && name == "mean";
        let color = if mean {
            BLACK.to_rgba()
        } else {
            Palette99::pick(i).to_rgba()
        };
        let width = if mean { 3 } else { 1 };
        chart
            .draw_series(LineSeries::new(
                line.iter().map(|p| (p.0, p.1)),
                ShapeStyle::from(&color).stroke_width(width),
            ))
            .map_err(plot_err)?
            .label(name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(width))
            });
        chart
            .draw_series(
                line.iter()
                    .map(|p| Circle::new((p.0, p.1), 3, color.filled())),
            )
            .map_err(plot_err)?;
        // The settings named once: on the mean, or on the only line.
        if mean || !several {
            chart
                .draw_series(line.iter().map(|p| {
                    Text::new(
                        format!(" {}", p.2),
                        (p.0, p.1),
                        ("sans-serif", 13).into_font().color(&BLACK),
                    )
                }))
                .map_err(plot_err)?;
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 11))
        .draw()
        .map_err(plot_err)?;
    Ok(())
}

fn points(rows: &[&Row], backend: BackendKind) -> Vec<Point> {
    rows.iter()
        .filter_map(|r| {
            Some(Point {
                label: r.label.clone(),
                method: r.method.clone(),
                ms: r.ms(backend)?,
                flip: r.quality.flip,
                zero_latency: r.added_latency_frames == 0,
            })
        })
        .collect()
}

fn draw(path: &Path, title: &str, panels: &[(BackendKind, Vec<Point>)]) -> anyhow::Result<()> {
    let (w, h) = (760u32, 520u32);
    let cols = panels.len().max(1) as u32;
    let mut buf = vec![255u8; (w * cols * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w * cols, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let areas = root.split_evenly((1, cols as usize));
        for (area, (backend, pts)) in areas.iter().zip(panels) {
            draw_panel(area, &format!("{title}: {}", backend.name()), pts)?;
        }
        root.present().map_err(plot_err)?;
    }
    let img = image::RgbImage::from_raw(w * cols, h, buf)
        .ok_or_else(|| anyhow::anyhow!("plot buffer size"))?;
    img.save(path)?;
    Ok(())
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("plotting: {e:?}")
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    pts: &[Point],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    // Time from zero (what a budget is measured against); error zoomed to
    // the points, which often differ by a few percent only.
    let max_ms = pts.iter().map(|p| p.ms).fold(0.0, f64::max).max(1e-3) * 1.15;
    let hi = pts.iter().map(|p| p.flip).fold(0.0, f64::max);
    let lo = pts.iter().map(|p| p.flip).fold(hi, f64::min);
    let pad = ((hi - lo) * 0.1).max(hi * 0.01).max(1e-5);
    let (lo, hi) = ((lo - pad).max(0.0), hi + pad);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..max_ms, lo..hi)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .max_light_lines(1)
        .x_desc("ms per generated frame")
        .y_desc("mean FLIP (lower is better)")
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(plot_err)?;
    // The zero-latency front as a polyline, fastest first; points on
    // either front are labelled (the others are only dots, or the plot
    // drowns in text).
    let front_of = |admit: &dyn Fn(&Point) -> bool| -> Vec<&Point> {
        let members: Vec<&Point> = pts.iter().filter(|p| admit(p)).collect();
        let coords: Vec<(f64, f64)> = members.iter().map(|p| (p.ms, p.flip)).collect();
        let mut front: Vec<&Point> = pareto(&coords).into_iter().map(|i| members[i]).collect();
        front.sort_by(|a, b| a.ms.total_cmp(&b.ms));
        front
    };
    let zero = front_of(&|p| p.zero_latency);
    let all = front_of(&|_| true);
    chart
        .draw_series(LineSeries::new(
            zero.iter().map(|p| (p.ms, p.flip)),
            ShapeStyle::from(&BLACK.mix(0.5)).stroke_width(1),
        ))
        .map_err(plot_err)?;
    for p in pts {
        let color = method_color(&p.method);
        let on_front = zero.iter().chain(&all).any(|f| f.label == p.label);
        // Filled: no added latency; ring: interpolation (adds a frame).
        let style = if p.zero_latency {
            color.filled()
        } else {
            color.stroke_width(2)
        };
        let radius = if on_front { 6 } else { 4 };
        chart
            .draw_series(std::iter::once(Circle::new((p.ms, p.flip), radius, style)))
            .map_err(plot_err)?;
        if on_front {
            chart
                .draw_series(std::iter::once(Text::new(
                    format!(" {}", p.label),
                    (p.ms, p.flip),
                    ("sans-serif", 13).into_font().color(&BLACK),
                )))
                .map_err(plot_err)?;
        }
    }
    Ok(())
}
