//! The CPU reference runs on all cores (rayon) and must give the same bits
//! for any thread count: every method, on hard-case frames, with one thread
//! and with several, compared bit for bit (colour, depth, motion, mask,
//! history snapshot, push outcomes). And the passes that write into the
//! buffers of a frame no longer needed (history, background) leave nothing
//! of what those buffers held.

use framegen::input::Prepared;
use framegen::passes::common::camera::PassCamera;
use framegen::passes::gffe::history::{History, PrevHistory, SeenAgain};
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
                let generated = g.generate(alpha).unwrap();
                // The packed frame, and the passes' f32 frame where the CPU
                // keeps it (all but repeat's still copy, made packed).
                let f = &generated.frame;
                let mut bits: Vec<u32> = f
                    .color
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits().into())
                    .collect();
                bits.extend(f.depth.iter().map(|v| v.to_bits()));
                bits.extend(f.motion.iter().flatten().map(|v| v.to_bits()));
                bits.extend(generated.mask.iter().map(|&m| m as u32));
                assert_eq!(generated.output.is_none(), method == Method::Repeat);
                if let Some(out) = &generated.output {
                    bits.extend(out.color.iter().flatten().map(|v| v.to_bits()));
                    bits.extend(out.depth.iter().map(|v| v.to_bits()));
                    bits.extend(out.motion.iter().flatten().map(|v| v.to_bits()));
                    bits.extend(&out.mask);
                }
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

/// History and background collection into recycled buffers full of garbage
/// give the same bits as into fresh ones.
#[test]
fn recycled_buffers_leave_no_trace() {
    use framegen::passes::common::levels::Levels;
    use framegen::passes::common::splat::Sparse;
    use framegen::passes::gffe::background::{self, PrevBackground, Seeds, Texel, Work};
    use framegen::passes::gffe::history::{self, Tracker};
    let bits = |v: &[[f32; 4]]| -> Vec<u32> { v.iter().flatten().map(|x| x.to_bits()).collect() };
    // One set of splat slots for every collection: each leaves them empty.
    let mut slots = Sparse::default();
    let all = tests::render_scene("crossing", SIZE, 60.0, 30..34);
    let frames = framegen::decimate::decimate(&all, 2);
    let (a, mut b) = (&frames[0], frames[1].clone());
    // Some pixels without a surface: they write "no position" entries.
    b.depth.iter_mut().step_by(97).for_each(|d| *d = 0.0);
    let b = &b;
    let (pa, pb) = (framegen::input::prepare(a), framegen::input::prepare(b));
    let n = pb.depth.len();
    let (k, eps, tol) = (3, 0.5, 0.02);
    let levels = Levels::new(3, SIZE.width, SIZE.height);
    // Frame a at its own origin, then b continuing it.
    let cam_a = PassCamera::new(&a.meta.camera, a.meta.size, a.meta.camera.pose.position);
    let hist_a = history::track(&cam_a, &pa.depth, &pa.motion, None, k, eps, tol);
    let seeds_a = Seeds {
        p0: &hist_a.positions[..n],
        track: &hist_a.track,
        color: &pa.color,
    };
    let bg_a = background::collect(
        Vec::new(),
        &cam_a,
        seeds_a,
        levels,
        None,
        tol,
        Work {
            carried: &mut Vec::new(),
            slots: &mut slots,
        },
    );
    let origin = b.meta.camera.pose.position;
    let cam_b = PassCamera::new(&b.meta.camera, b.meta.size, origin);
    let prev_cam = PassCamera::new(&a.meta.camera, a.meta.size, origin);
    let prev = PrevHistory {
        camera: prev_cam,
        positions: &hist_a.positions,
        track: &hist_a.track,
        depth: &pa.depth,
    };
    let tracker = Tracker {
        camera: &cam_b,
        depth: &pb.depth,
        motion: &pb.motion,
        prev: Some(&prev),
        k,
        epsilon: eps,
        tolerance: Some(tol),
    };
    // Compared whole: a pixel that is not dynamic stores only `P_0`.
    let fresh = tracker.track_into(History::empty()).expanded();
    // Flags all set, of the previous frame's length: each is cleared.
    let garbage = History {
        positions: vec![[f32::NAN, 1e30, -7.0, 1.0]; k as usize * n],
        track: vec![0xdead_beef; n],
        dynamic: 12345,
        seen: SeenAgain::from_words(&vec![1; n]),
    };
    let recycled = tracker.track_into(garbage).expanded();
    assert!(
        fresh.dynamic > 0,
        "the frames move, so some pixels are dynamic"
    );
    assert_eq!(bits(&fresh.positions), bits(&recycled.positions));
    assert_eq!(fresh.track, recycled.track);
    assert_eq!(fresh.dynamic, recycled.dynamic);
    assert_eq!(fresh.seen, recycled.seen);
    assert_eq!(fresh.seen.len(), n);
    // Without a tolerance (no background to seed) nothing is confirmed and
    // nothing else changes.
    let unconfirmed = Tracker {
        tolerance: None,
        ..tracker
    }
    .track_into(History::empty())
    .expanded();
    assert!(fresh.track.iter().any(|w| history::is_confirmed(*w)));
    // A confirmed pixel always has a position (the background seeds level
    // 0 from the track word alone, `background::seeds`), also where the
    // depth has none.
    let invalid = framegen::passes::common::camera::W_INVALID;
    let positioned = |(w, p): (&u32, &[f32; 4])| !history::is_confirmed(*w) || p[3] != invalid;
    assert!(fresh.track.iter().zip(&fresh.positions).all(positioned));
    assert!(fresh.positions[..n].iter().any(|p| p[3] == invalid));
    assert!(!unconfirmed.track.iter().any(|w| history::is_confirmed(*w)));
    let without = |t: &[u32]| t.iter().map(|w| w & !2).collect::<Vec<_>>();
    assert_eq!(without(&fresh.track), without(&unconfirmed.track));
    assert_eq!(bits(&fresh.positions), bits(&unconfirmed.positions));

    let seeds_b = Seeds {
        p0: &fresh.positions[..n],
        track: &fresh.track,
        color: &pb.color,
    };
    let prev_bg = PrevBackground {
        camera: prev_cam,
        levels,
        texels: &bg_a,
        seeds: None,
        seen: Some(&fresh.seen),
    };
    let junk = Texel {
        pos: [3.0, f32::NAN, 1.0, 1.0],
        color: [9.0, 9.0, 9.0, 1.0].map(half::f16::from_f32),
    };
    let mut collect = |reuse| {
        background::collect(
            reuse,
            &cam_b,
            seeds_b,
            levels,
            Some(prev_bg),
            tol,
            Work {
                carried: &mut Vec::new(),
                slots: &mut slots,
            },
        )
    };
    let clean = collect(Vec::new());
    let dirty = collect(vec![junk; levels.total() as usize]);
    assert!(clean.iter().any(Texel::is_valid));
    assert_eq!(
        bytemuck::cast_slice::<_, u32>(&clean),
        bytemuck::cast_slice::<_, u32>(&dirty)
    );
    // The fragments carried over are every valid texel that is not one of
    // this frame's seeds, each once, ascending, whatever the list held:
    // with frame b's background as the previous one of a camera moved
    // back and aside, so that much of it lands elsewhere, some behind.
    let mut aside = b.meta.camera;
    aside.pose.position -= glam::DVec3::new(0.3, 0.2, 0.6);
    let again = PrevBackground {
        camera: PassCamera::new(&aside, b.meta.size, origin),
        texels: &clean,
        levels,
        seeds: None,
        seen: None,
    };
    let mut carried = vec![7, 7, 3];
    let reuse = vec![junk; levels.total() as usize];
    let prev = Some(again);
    let clean = background::collect(
        Vec::new(),
        &cam_b,
        seeds_b,
        levels,
        prev,
        tol,
        Work {
            carried: &mut Vec::new(),
            slots: &mut slots,
        },
    );
    let work = Work {
        carried: &mut carried,
        slots: &mut slots,
    };
    let listed = background::collect(reuse, &cam_b, seeds_b, levels, prev, tol, work);
    assert_eq!(
        bytemuck::cast_slice::<_, u32>(&listed),
        bytemuck::cast_slice::<_, u32>(&clean)
    );
    let seeded = |i: usize| fresh.track.get(i).is_some_and(|&t| background::seeds(t));
    let expected: Vec<u32> = (0..clean.len())
        .filter(|&i| clean[i].is_valid() && !seeded(i))
        .map(|i| i as u32)
        .collect();
    assert!(expected.len() > 100, "{} carried", expected.len());
    assert!(expected.iter().any(|&i| i < n as u32), "some on level 0");
    assert!(expected.iter().any(|&i| i >= n as u32), "some coarser");
    assert_eq!(carried, expected);
}

/// Five frames of a scene whose objects move (rendered at 60 fps, every
/// other one kept), with each prepared as the passes read it.
fn moving_frames() -> (Vec<Frame>, Vec<Prepared>) {
    let all = tests::render_scene("crossing", SIZE, 60.0, 30..40);
    let frames = framegen::decimate::decimate(&all, 2);
    let prepared = frames.iter().map(framegen::input::prepare).collect();
    (frames, prepared)
}

/// Frame `index`'s camera (centre at its origin) and, after the first,
/// the previous frame's camera as it sees it, with that frame prepared.
fn cameras<'a>(
    frames: &[Frame],
    prepared: &'a [Prepared],
    index: usize,
) -> (PassCamera, Option<(PassCamera, &'a Prepared)>) {
    let meta = &frames[index].meta;
    let origin = meta.camera.pose.position;
    let before = index.checked_sub(1).map(|i| {
        let m = &frames[i].meta;
        (PassCamera::new(&m.camera, m.size, origin), &prepared[i])
    });
    (PassCamera::new(&meta.camera, meta.size, origin), before)
}

/// `h` as the next frame continues it (`before`, from [`cameras`]).
fn continued<'a>(
    h: &'a History,
    before: Option<(PassCamera, &'a Prepared)>,
) -> Option<PrevHistory<'a>> {
    before.map(|(camera, p)| PrevHistory {
        camera,
        positions: &h.positions,
        track: &h.track,
        depth: &p.depth,
    })
}

/// The CPU executor's backgrounds, whose level 0's seeds are not stored
/// (`background::Unseeded`), are the whole ones without them: frame after
/// frame, each collected from the previous unseeded one and its seeds,
/// into the buffer of the one before it (only its listed texels emptied),
/// made whole, is the reference's buffer bit for bit, with the same
/// fragments carried over; the seeds' slots hold nothing, and the texels
/// that hold a fragment are exactly the ones listed.
#[test]
fn unseeded_backgrounds_are_the_whole_ones() {
    use framegen::passes::common::levels::Levels;
    use framegen::passes::common::splat::Sparse;
    use framegen::passes::gffe::background::{self, PrevBackground, Seeds, Texel, Unseeded, Work};
    use framegen::passes::gffe::history::Tracker;
    let (frames, prepared) = moving_frames();
    let n = SIZE.pixels() as usize;
    let (k, eps, tol) = (3, 0.5, 0.02);
    let levels = Levels::new(3, SIZE.width, SIZE.height);
    let mut slots = Sparse::default();
    // The previous frame's history, whole background and unseeded one.
    let mut prev: Option<(History, Vec<background::Texel>, Unseeded)> = None;
    let mut spare = Unseeded::default();
    let (mut carried_seen, mut seen_again) = (0, 0);
    for (index, p) in prepared.iter().enumerate() {
        let (camera, before) = cameras(&frames, &prepared, index);
        let prev_hist = prev.as_ref().and_then(|(h, _, _)| continued(h, before));
        let hist = Tracker {
            camera: &camera,
            depth: &p.depth,
            motion: &p.motion,
            prev: prev_hist.as_ref(),
            k,
            epsilon: eps,
            tolerance: Some(tol),
        }
        .track_into(History::empty());
        let seeds = Seeds {
            p0: &hist.positions[..n],
            track: &hist.track,
            color: &p.color,
        };
        let prev_bg = |unseeded: bool| {
            prev.as_ref()
                .zip(before)
                .map(|((h, w, u), (camera, pp))| PrevBackground {
                    camera,
                    levels,
                    texels: if unseeded { &u.texels } else { w },
                    seeds: unseeded.then_some(Seeds {
                        p0: &h.positions[..n],
                        track: &h.track,
                        color: &pp.color,
                    }),
                    // The seeds this frame saw again.
                    seen: Some(&hist.seen),
                })
        };
        let mut carried = Vec::new();
        let work = Work {
            carried: &mut carried,
            slots: &mut slots,
        };
        let whole = background::collect(
            Vec::new(),
            &camera,
            seeds,
            levels,
            prev_bg(false),
            tol,
            work,
        );
        let mut collect = |reuse| {
            let prev = prev_bg(true);
            background::collect_unseeded(reuse, &camera, seeds, levels, prev, tol, &mut slots)
        };
        let unseeded = collect(std::mem::take(&mut spare));
        // Into a buffer whose listed texels hold junk (every 41st: few
        // enough that only those are emptied).
        let junk = Texel {
            pos: [3.0, f32::NAN, 1.0, 1.0],
            color: [9.0, 9.0, 9.0, 1.0].map(half::f16::from_f32),
        };
        let listed: Vec<u32> = (0..whole.len() as u32).step_by(41).collect();
        let mut texels = vec![Texel::default(); whole.len()];
        listed.iter().for_each(|&s| texels[s as usize] = junk);
        let into_junk = collect(Unseeded {
            texels,
            carried: listed,
        });
        assert_eq!(
            bytemuck::cast_slice::<_, u32>(&into_junk.texels),
            bytemuck::cast_slice::<_, u32>(&unseeded.texels),
            "frame {index}"
        );
        assert_eq!(into_junk.carried, unseeded.carried);
        assert_eq!(unseeded.carried, carried, "frame {index}");
        let valid: Vec<u32> = (0..unseeded.texels.len() as u32)
            .filter(|&s| unseeded.texels[s as usize].is_valid())
            .collect();
        assert_eq!(
            valid, unseeded.carried,
            "frame {index}: only the carried are stored"
        );
        let made_whole = background::seeded(unseeded.texels.clone(), seeds);
        assert_eq!(
            bytemuck::cast_slice::<_, u32>(&made_whole),
            bytemuck::cast_slice::<_, u32>(&whole),
            "frame {index}"
        );
        // Confirmed (seeds) from the second frame on.
        let seeded_here = (0..n).filter(|&x| background::seeds(hist.track[x])).count();
        assert!(
            index == 0 || seeded_here > n / 2,
            "frame {index}: {seeded_here} seeds"
        );
        carried_seen += carried.len();
        seen_again += hist.seen.count();
        if let Some((_, _, u)) = prev.take() {
            spare = u;
        }
        prev = Some((hist, whole, unseeded));
    }
    assert!(
        frames.len() >= 4 && carried_seen > 100 && seen_again > n,
        "{carried_seen} carried, {seen_again} seen again"
    );
}

/// The CPU executor's histories, whose pixels that are not dynamic store
/// only `P_0`, are the whole ones: frame after frame at `k = 4`, each
/// tracked from the previous compact one into buffers full of garbage,
/// made whole, is `history::track`'s from the previous whole one, bit for
/// bit (a trajectory that continues a static pixel reads its `P_0`).
#[test]
fn compact_histories_are_the_whole_ones() {
    use framegen::passes::gffe::history::{self, Tracker};
    let (frames, prepared) = moving_frames();
    let n = SIZE.pixels() as usize;
    let (k, eps, tol) = (4, 0.5, 0.02);
    let bits = |h: &History| -> Vec<u32> {
        let p = h.positions.iter().flatten().map(|v| v.to_bits());
        p.chain(h.track.iter().copied()).collect()
    };
    let mut prev: Option<(History, History)> = None;
    let mut continued_chains = 0;
    for (index, p) in prepared.iter().enumerate() {
        let (camera, before) = cameras(&frames, &prepared, index);
        let (whole_prev, compact_prev) = match &prev {
            Some((w, c)) => (continued(w, before), continued(c, before)),
            None => (None, None),
        };
        let whole = history::track(&camera, &p.depth, &p.motion, whole_prev, k, eps, tol);
        let garbage = History {
            positions: vec![[f32::NAN, 1e30, -7.0, 1.0]; k as usize * n],
            track: vec![0xdead_beef; n],
            dynamic: 12345,
            seen: SeenAgain::from_words(&[1; 7]),
        };
        let compact = Tracker {
            camera: &camera,
            depth: &p.depth,
            motion: &p.motion,
            prev: compact_prev.as_ref(),
            k,
            epsilon: eps,
            tolerance: Some(tol),
        }
        .track_into(garbage);
        assert_eq!(
            bits(&compact.clone().expanded()),
            bits(&whole),
            "frame {index}"
        );
        assert_eq!(compact.seen, whole.seen, "frame {index}");
        // Trajectories longer than one that continue a static pixel.
        continued_chains += (0..n)
            .filter(|&x| history::is_dynamic(whole.track[x]) && history::chain(whole.track[x]) > 1)
            .count();
        prev = Some((whole, compact));
    }
    assert!(continued_chains > 50, "{continued_chains} chains continued");
}
