//! Prints the PSNR / SSIM table of every method on every hard-case scene at
//! 30 → 60 (render at 60 fps, feed every other frame, generate α = 0.5;
//! extrapolation stands in for the frame after the last fed one,
//! interpolation for the one before it).
//!
//! `cargo run --release -p tests --example quality_table -- [WIDTH HEIGHT FRAMES] [--gpu]`

use framegen::{FrameGenerator, GpuContext, Method, Settings};
use protocol::FrameSize;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let gpu = args.iter().any(|a| a == "--gpu");
    let nums: Vec<u32> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let (w, h, n) = match nums.as_slice() {
        [w, h, n, ..] => (*w, *h, *n),
        _ => (320, 180, 24),
    };
    let ctx = gpu.then(|| GpuContext::new().expect("GPU"));
    println!(
        "{w}x{h}, {n} frames at 60 fps, every other frame fed, α = 0.5, backend {}",
        if gpu { "wgpu" } else { "cpu" }
    );
    println!(
        "| scene | repeat PSNR / SSIM | reproject PSNR / SSIM | gffe PSNR / SSIM | interp PSNR / SSIM | gffe bg % | gffe filled % |"
    );
    println!("|---|---|---|---|---|---|---|");
    for scene in std::iter::once("default").chain(tests::HARD_CASES) {
        let frames = tests::render_scene(scene, FrameSize::new(w, h), 60.0, 30..30 + u64::from(n));
        let mut row = format!("| {scene} |");
        let mut last = None;
        for method in Method::ALL {
            let s = Settings::for_method(method);
            let mut g = match &ctx {
                Some(ctx) => FrameGenerator::gpu(s, ctx.clone()),
                None => FrameGenerator::cpu(s),
            }
            .expect("generator");
            let q = tests::quality(&mut g, &frames);
            row += &format!(" {:.2} / {:.4} |", q.psnr, q.ssim);
            if method == Method::Gffe {
                last = Some(q);
            }
        }
        let q = last.expect("gffe ran");
        row += &format!(" {:.2} | {:.2} |", 100.0 * q.background, 100.0 * q.filled);
        println!("{row}");
    }
}
