//! The CPU reference runs on all cores (rayon) and must give the same bits
//! for any thread count: every method, on hard-case frames, with one thread
//! and with several, compared bit for bit (colour, depth, motion, mask,
//! history snapshot, push outcomes).

use framegen::{FrameGenerator, Method, Settings};
use protocol::{Frame, FrameSize};

/// Large enough that the history pass splits into several bands of rows.
const SIZE: FrameSize = FrameSize::new(320, 180);

fn run(threads: usize, method: Method, frames: &[Frame]) -> Vec<(String, Vec<u32>)> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool");
    pool.install(|| {
        let s = Settings {
            history: 3,
            background_levels: 3,
            ..Settings::for_method(method)
        };
        let mut g = FrameGenerator::cpu(s).unwrap();
        let mut seen = Vec::new();
        for f in frames {
            let outcome = g.push(f).unwrap();
            let snap = g.snapshot().unwrap().unwrap();
            let mut bits: Vec<u32> = snap
                .positions
                .iter()
                .flatten()
                .map(|v| v.to_bits())
                .collect();
            bits.extend(&snap.track);
            bits.extend(bytemuck::cast_slice::<_, u32>(&snap.background));
            seen.push((format!("push {outcome:?}"), bits));
            let alphas: &[f64] = if method == Method::Interp {
                &[0.5]
            } else {
                &[0.5, 2.0]
            };
            for &alpha in alphas {
                let out = g.generate(alpha).unwrap().output;
                let mut bits: Vec<u32> = out.color.iter().flatten().map(|v| v.to_bits()).collect();
                bits.extend(out.depth.iter().map(|v| v.to_bits()));
                bits.extend(out.motion.iter().flatten().map(|v| v.to_bits()));
                bits.extend(&out.mask);
                seen.push((format!("generate α={alpha}"), bits));
            }
        }
        seen
    })
}

#[test]
fn cpu_output_is_the_same_for_any_thread_count() {
    for scene in ["crossing", "fast_rotation", "dolly"] {
        let all = tests::render_scene(scene, SIZE, 60.0, 30..38);
        let frames = framegen::decimate::decimate(&all, 2);
        for method in Method::ALL {
            let one = run(1, method, &frames);
            let many = run(4, method, &frames);
            assert_eq!(one.len(), many.len());
            for ((what, a), (_, b)) in one.iter().zip(&many) {
                let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
                assert!(
                    a.len() == b.len() && differ == 0,
                    "{scene} {method} {what}: {differ} of {} values differ between 1 and 4 threads",
                    a.len()
                );
            }
        }
    }
}
