//! Writes a dump of the analytic ground-plane scene (exact depth and motion),
//! for trying tools on the dump format: `server inspect`, Python `OpenEXR`,
//! Blender. Usage: `cargo run -p tests --example analytic_dump -- DIR [FRAMES]`.

use glam::DVec3;
use protocol::FrameSize;
use protocol::dump::{DumpWriter, Manifest};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().ok_or("usage: analytic_dump DIR [FRAMES]")?;
    let frames: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(30);
    let size = FrameSize::new(320, 180);
    let fps = 30.0;
    let mut w = DumpWriter::create(
        &dir,
        Manifest::new(fps, size, "tests: analytic ground plane"),
    )?;
    for i in 0..frames {
        w.write_frame(&tests::render(i, fps, DVec3::ZERO, size))?;
    }
    let m = w.finish()?;
    eprintln!("wrote {} frames to {dir}", m.frame_count);
    Ok(())
}
