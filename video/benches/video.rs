//! What colour through H.264 costs and keeps (issue 19 §1): per setting,
//! Mbit/s at 30 fps, display-space PSNR of the decoded colour against the
//! rendered, and encode and decode wall time a frame as multiples of the
//! render of the same frames, timed in the same run. Two seconds of the
//! default scene (60 frames, one stream).
//!
//! `cargo bench -p video --bench video` (`RENDER_BENCH_SIZE=WxH` to change
//! the size from 640×360; `VIDEO_BENCH_SETTINGS=h264@4,h264-444@8` to change
//! the settings).

use std::path::Path;
use std::time::Instant;

use protocol::FrameSize;
use scene::Scene;
use scene::render::Renderer;
use video::transfer::display_psnr as psnr;
use video::{ColorDecoder, ColorEncoder, VideoSettings};

const FPS: f64 = 30.0;
const FRAMES: u64 = 60;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let size: FrameSize = std::env::var("RENDER_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(FrameSize::new(640, 360));
    let settings: Vec<VideoSettings> = std::env::var("VIDEO_BENCH_SETTINGS")
        .unwrap_or_else(|_| "h264@2,h264@4,h264@8,h264@16,h264-444@8,h264-444@16".into())
        .split(',')
        .map(|s| s.parse().expect("a colour setting"))
        .collect();
    let scene = Scene::load("builtin:default").expect("built-in scene");
    let mut renderer = Renderer::new(scene, size, Path::new(".")).expect("renderer");
    let mut render_ms = Vec::new();
    let frames: Vec<_> = (0..FRAMES)
        .map(|k| {
            let t = Instant::now();
            let f = renderer.render(k, FPS).expect("frame");
            render_ms.push(t.elapsed().as_secs_f64() * 1e3);
            f
        })
        .collect();
    let render = median(render_ms);
    let (w, h) = (size.width, size.height);
    println!("{w}x{h}, {FRAMES} frames of builtin:default at {FPS} fps; render p50 {render:.2} ms");
    println!("setting        Mbit/s  PSNR dB (min)   encode ×render  decode ×render");
    for s in settings {
        let mut enc = ColorEncoder::new(s, FPS).expect("libx264");
        let mut dec = ColorDecoder::new().expect("H.264 decoder");
        let (mut bytes, mut enc_ms, mut dec_ms, mut q) = (0usize, vec![], vec![], vec![]);
        let mut out = Vec::new();
        for f in &frames {
            let t = Instant::now();
            let payload = enc.encode(w, h, &f.color).expect("encodes");
            enc_ms.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            dec.decode(&payload, w, h, &mut out).expect("decodes");
            dec_ms.push(t.elapsed().as_secs_f64() * 1e3);
            bytes += payload.len();
            q.push(psnr(&f.color, &out));
        }
        let mbit = bytes as f64 * 8.0 * FPS / FRAMES as f64 / 1e6;
        let mean_q = q.iter().sum::<f64>() / q.len() as f64;
        let min_q = q.iter().copied().fold(f64::INFINITY, f64::min);
        let (e, d) = (median(enc_ms), median(dec_ms));
        println!(
            "{:<14} {mbit:>6.2}  {mean_q:>6.2} ({min_q:>5.2})  {e:>6.2} ms {:>5.2}×  {d:>6.2} ms {:>5.2}×",
            s.to_string(),
            e / render,
            d / render
        );
    }
}
