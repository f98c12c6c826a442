//! Numerical stability of frame generation (issue 4, DESIGN §11): on every
//! hard-case scene and on poisoned inputs, every method on both backends
//! produces finite, bounded outputs, and bad input values are counted.
//!
//! "Bounded": color in [0, 65504] (the f16 range the frame carries), depth
//! positive (`+inf` only as the sky convention, never NaN), motion finite
//! and within 64 frame sizes.

use std::sync::Arc;

use framegen::{FrameGenerator, Generated, GpuContext, Method, Settings};
use half::f16;
use protocol::{Frame, FrameSize};

const SIZE: FrameSize = FrameSize::new(96, 54);

fn ctx() -> Arc<GpuContext> {
    GpuContext::new().expect("a wgpu adapter (lavapipe in CI)")
}

fn generators(ctx: &Arc<GpuContext>, method: Method) -> [FrameGenerator; 2] {
    let s = Settings::for_method(method);
    [
        FrameGenerator::cpu(s).unwrap(),
        FrameGenerator::gpu(s, ctx.clone()).unwrap(),
    ]
}

fn assert_bounded(g: &Generated, what: &str) {
    let limit = 64.0 * SIZE.width.max(SIZE.height) as f32;
    for (i, c) in g.frame.color.iter().enumerate() {
        for v in c {
            let v = v.to_f32();
            assert!(
                v.is_finite() && (0.0..=65504.0).contains(&v),
                "{what}: color {v} at {i}"
            );
        }
    }
    for (i, c) in g.output.color.iter().enumerate() {
        assert!(
            c.iter().all(|v| v.is_finite()),
            "{what}: f32 color {c:?} at {i}"
        );
    }
    for (i, &d) in g.frame.depth.iter().enumerate() {
        assert!(d > 0.0, "{what}: depth {d} at {i}");
    }
    for (i, m) in g.frame.motion.iter().enumerate() {
        assert!(
            m.iter().all(|v| v.is_finite() && v.abs() <= limit),
            "{what}: motion {m:?} at {i}"
        );
    }
    assert_eq!(g.mask.len(), g.frame.color.len());
}

/// The α values a method accepts: interpolation lives in [0, 1] (its
/// α = 1 is the current frame), the others extrapolate beyond.
fn alphas(method: Method, wanted: &[f64]) -> Vec<f64> {
    wanted
        .iter()
        .map(|&a| {
            if method == Method::Interp {
                a.min(1.0)
            } else {
                a
            }
        })
        .collect()
}

fn frames(scene: &str) -> Vec<Frame> {
    let all = tests::render_scene(scene, SIZE, 60.0, 40..48);
    framegen::decimate::decimate(&all, 2)
}

#[test]
fn every_hard_case_every_method_both_backends() {
    let ctx = ctx();
    for scene in tests::HARD_CASES.into_iter().chain(["default"]) {
        let fs = frames(scene);
        for method in Method::ALL {
            for mut g in generators(&ctx, method) {
                for f in &fs {
                    g.push(f).unwrap();
                }
                for alpha in alphas(method, &[1e-6, 0.5, 1.0, 2.0, 3.0]) {
                    let out = g.generate(alpha).unwrap();
                    assert_bounded(
                        &out,
                        &format!("{scene} {method} {} α={alpha}", g.backend_name()),
                    );
                }
            }
        }
    }
}

/// Eight extrapolations in a row from one rendered frame (a stalled
/// network), out to α = 8.
#[test]
fn a_chain_of_eight_extrapolations() {
    let ctx = ctx();
    for scene in ["fast_rotation", "crossing", "huge"] {
        let fs = frames(scene);
        for mut g in generators(&ctx, Method::Gffe) {
            for f in &fs {
                g.push(f).unwrap();
            }
            for j in 1..=8 {
                let out = g.generate(f64::from(j)).unwrap();
                assert_bounded(&out, &format!("{scene} {} chain {j}", g.backend_name()));
            }
        }
    }
}

/// Sky everywhere (`+inf` depth) and a surface 1e-6 in front of the camera.
#[test]
fn infinite_and_near_zero_depth() {
    let ctx = ctx();
    let fs = frames("default");
    for depth in [f32::INFINITY, 1e-6] {
        let poisoned: Vec<Frame> = fs
            .iter()
            .map(|f| {
                let mut f = f.clone();
                f.depth.iter_mut().for_each(|d| *d = depth);
                f
            })
            .collect();
        for method in Method::ALL {
            for mut g in generators(&ctx, method) {
                for f in &poisoned {
                    g.push(f).unwrap();
                }
                for alpha in alphas(method, &[0.5, 3.0]) {
                    let out = g.generate(alpha).unwrap();
                    assert_bounded(
                        &out,
                        &format!("depth {depth} {method} {} α={alpha}", g.backend_name()),
                    );
                }
            }
        }
    }
}

/// NaN and ±inf in each input buffer: sanitised, counted, never propagated.
#[test]
fn nan_and_inf_inputs_are_sanitised_and_counted() {
    let ctx = ctx();
    let fs = frames("crossing");
    let n = SIZE.pixels() as usize;
    let poison = |f: &Frame, which: usize| {
        let mut f = f.clone();
        for i in (0..n).step_by(7) {
            let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][i % 3];
            match which {
                0 => f.color[i][i % 3] = f16::from_f32(bad),
                1 => f.depth[i] = bad,
                _ => f.motion[i][i % 2] = bad,
            }
        }
        f
    };
    let injected = n.div_ceil(7) as u64;
    for which in 0..3 {
        let bad: Vec<Frame> = fs.iter().map(|f| poison(f, which)).collect();
        for method in Method::ALL {
            for mut g in generators(&ctx, method) {
                for f in &bad {
                    g.push(f).unwrap();
                }
                let s = g.sanitized();
                let counted = [s.color, s.depth, s.motion][which];
                // +inf depth is the sky, not an error: only NaN and −inf count.
                let expected = if which == 1 {
                    (0..n).step_by(7).filter(|i| i % 3 != 1).count() as u64
                } else {
                    injected
                };
                assert_eq!(
                    counted,
                    expected * bad.len() as u64,
                    "buffer {which} {method}"
                );
                for alpha in alphas(method, &[0.5, 2.0]) {
                    let out = g.generate(alpha).unwrap();
                    assert_bounded(
                        &out,
                        &format!("poisoned buffer {which} {method} {}", g.backend_name()),
                    );
                }
            }
        }
    }
}

/// Duplicated frames (Δt = 0) are ignored, cuts restart the history, and α
/// outside the accepted range is a typed error.
#[test]
fn duplicates_cuts_and_bad_alpha() {
    use framegen::PushOutcome;
    let fs = frames("cut");
    let mut g = FrameGenerator::cpu(Settings::default()).unwrap();
    assert!(matches!(
        g.generate(0.5),
        Err(framegen::FramegenError::NoFrame)
    ));
    g.push(&fs[0]).unwrap();
    g.push(&fs[1]).unwrap();
    assert_eq!(g.push(&fs[1]).unwrap(), PushOutcome::Duplicate);
    let mut cut = fs[2].clone();
    cut.meta.cut = true;
    assert!(matches!(
        g.push(&cut).unwrap(),
        PushOutcome::Restarted { .. }
    ));
    assert_bounded(&g.generate(0.5).unwrap(), "after a cut");
    for alpha in [f64::NAN, -0.1, f64::INFINITY, 1e9] {
        assert!(matches!(
            g.generate(alpha),
            Err(framegen::FramegenError::Alpha(..))
        ));
    }
    // A frame whose buffers do not match its size is refused, not read.
    let mut short = fs[3].clone();
    short.depth.pop();
    assert!(matches!(
        g.push(&short),
        Err(framegen::FramegenError::Frame(_))
    ));
}
