//! `server`: the frame server's command line.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(version, about = "Frame-generation streaming server")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Read every frame of a dump and report its contents and any problem.
    Inspect {
        /// The dump directory (holding manifest.json).
        dir: PathBuf,
    },
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .init();
    match Cli::parse().command {
        Command::Inspect { dir } => inspect(&dir),
    }
}

fn inspect(dir: &std::path::Path) -> anyhow::Result<()> {
    let reader = protocol::dump::DumpReader::open(dir)
        .with_context(|| format!("opening {}", dir.display()))?;
    let m = reader.manifest();
    println!(
        "{}: {} frames, {}x{} at {} fps, format v{}, conventions v{}\nsource: {}",
        dir.display(),
        m.frame_count,
        m.width,
        m.height,
        m.fps,
        m.format_version,
        m.conventions_version,
        m.source
    );
    let bar = ProgressBar::new(reader.len()).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = server::inspect::inspect(&reader, |i| bar.set_position(i));
    bar.finish_and_clear();
    println!(
        "cuts: {}  sky pixels: {}  max motion: {:.2} px  mean frame interval: {:.4} s",
        report.cuts, report.sky_pixels, report.max_motion, report.mean_frame_interval
    );
    for (i, e) in &report.unreadable {
        println!("frame {i}: {e}");
    }
    if report.time_not_increasing > 0 {
        println!(
            "{} frames do not advance in time",
            report.time_not_increasing
        );
    }
    if report.bad_values > 0 {
        println!(
            "{} NaN or non-positive values in color/depth/motion",
            report.bad_values
        );
    }
    anyhow::ensure!(report.is_clean(), "the dump has problems (see above)");
    println!("ok");
    Ok(())
}
