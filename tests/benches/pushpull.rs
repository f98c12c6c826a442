//! Push-pull on the CPU at 720p: `fill`, which makes only the texels the
//! holes read within its budget (`pushpull::fill_near`) and builds the whole
//! pyramid otherwise, against `fill_pyramid`, the whole pyramid alone, on
//! hole patterns from the typical to the worst for the near path:
//!
//! * `sliver`: a 4-pixel strip along the left edge and a crack, a typical
//!   frame's holes (about 4 400): filled near;
//! * `blocks`: 200 blocks of 8×8 holes 32 pixels apart (12 800): few enough
//!   to try, but deep and many texels, so it gives up at its budget;
//! * `scattered`: one pixel in 67 (13 700): it gives up while planning
//!   level 1;
//! * `many`: 800 such blocks (51 200): refused on their count.
//!
//! Each entry restores the frame's holes before filling; `restore` is that
//! copy alone, to subtract. A pattern's `fill` minus its `pyramid` is what
//! trying costs where it gives up, and what it saves where it does not.
//!
//! `cargo bench -p tests --bench pushpull`.

mod common;

use criterion::{Criterion, criterion_group};
use framegen::output::{Output, Pixel, WARPED};
use framegen::passes::common::pushpull::{self, Scratch};

const W: u32 = 1280;
const H: u32 = 720;
/// The seed's pyramid depth, as the settings' default.
const LEVELS: u32 = 7;

/// A warped frame with holes where `hole(x, y)`.
fn frame(hole: impl Fn(u32, u32) -> bool + Sync + Send) -> Output {
    Output::from_fn(W, H, |t| {
        let (x, y) = (t as u32 % W, t as u32 / W);
        if hole(x, y) {
            return Pixel::EMPTY;
        }
        let v = ((x * 3 + y * 5) % 256) as f32 / 255.0;
        Pixel {
            color: [v, 1.0 - v, 0.5, 1.0],
            depth: 1.0 + 8.0 * v,
            motion: [x as f32 * 0.01, -1.0],
            mask: WARPED,
        }
    })
}

/// `out` set back to `from` (same size), in place.
fn restore(out: &mut Output, from: &Output) {
    out.color.copy_from_slice(&from.color);
    out.depth.copy_from_slice(&from.depth);
    out.motion.copy_from_slice(&from.motion);
    out.mask.copy_from_slice(&from.mask);
}

fn bench(c: &mut Criterion) {
    let blocks = |rows: u32| move |x: u32, y: u32| x % 32 < 8 && y % 32 < 8 && y < 32 * rows;
    let patterns: [(&str, Output); 4] = [
        ("sliver", frame(|x, y| x < 4 || (x == 600 && y % 7 != 0))),
        ("blocks", frame(blocks(5))),
        ("scattered", frame(|x, y| (x * 7 + y * 13) % 67 == 0)),
        ("many", frame(blocks(20))),
    ];
    let mut group = c.benchmark_group(format!("pushpull/{W}x{H}"));
    let mut out = patterns[0].1.clone();
    let mut scratch = Scratch::default();
    for (name, from) in &patterns {
        group.bench_function(format!("{name}/fill"), |b| {
            b.iter(|| {
                restore(&mut out, from);
                pushpull::fill(&mut out, LEVELS, &mut scratch);
            })
        });
        group.bench_function(format!("{name}/pyramid"), |b| {
            b.iter(|| {
                restore(&mut out, from);
                pushpull::fill_pyramid(&mut out, LEVELS);
            })
        });
    }
    group.bench_function("restore", |b| b.iter(|| restore(&mut out, &patterns[0].1)));
    group.finish();
}

criterion_group!(benches, bench);

fn main() {
    common::main(benches);
}
