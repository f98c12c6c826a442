//! The depth-tested forward warp (GFFE §4.1 "Warping", DESIGN §4 step 4):
//! every pixel's next position is projected into the generated frame's
//! camera and splatted; where several land in one pixel the nearest wins
//! (see `splat.rs` for the deterministic atomics).
//!
//! A warped pixel takes the source pixel's color, the projected depth, and a
//! motion vector pointing to where the source pixel is in the rendered
//! frame's displayed region (DESIGN §4: generated motion points from the
//! generated frame to the frame it was made from).
//!
//! **Cracks.** Splatting one pixel per source leaves one-pixel gaps where a
//! surface is magnified. Left alone, the background layers would fill such
//! a gap inside a foreground object with what lies *behind* it. A hole
//! whose two opposite neighbours (left/right, up/down, or either diagonal
//! pair) were both warped at depths within [`CRACK_DEPTH_RATIO`] of each
//! other is a crack, not a disocclusion: `warp_cracks` closes it with the
//! mean of the first such pair. It reads only pixels the splat wrote
//! ([`WARPED`]) and writes only holes ([`CRACK`]), so it is
//! order-independent.

use glam::Vec2;

use crate::gpu::{Binding, GpuContext, Kernel, Rec};
use crate::output::{CRACK, DisplayMap, EMPTY, GpuOutput, Output, Pixel, Rows, WARPED};
use crate::passes::common::camera::{Columns, PassCamera, cell};
use crate::passes::common::lanes::{LANES, Lanes3, cells4, project4};
use crate::passes::common::pack;
use crate::passes::common::resample::{self, Resample, Source};
use crate::passes::common::resample_run::{self, Planes, RUN, max, min};
use crate::passes::common::splat::{Candidate, Winners, depth_key};

/// CPU reference of `warp_project`: one candidate per source pixel.
/// `next` and `target` are relative to the same origin.
pub fn project(next: &[[f32; 4]], target: &PassCamera) -> Vec<Candidate> {
    use rayon::prelude::*;
    next.par_iter().map(|&p| candidate(p, target)).collect()
}

/// One element of [`project`]: where the position `p` lands in `target`,
/// and its depth key.
#[inline]
pub fn candidate(p: [f32; 4], target: &PassCamera) -> Candidate {
    candidate_at(p, target).0
}

/// [`candidate`] and the continuous target position it lands at (only
/// meaningful when the candidate has a slot).
#[inline]
pub fn candidate_at(p: [f32; 4], target: &PassCamera) -> (Candidate, Vec2) {
    let Some(r) = target.project(p) else {
        return (Candidate::MISS, Vec2::ZERO);
    };
    let c = cell(r.pixel, target.width(), target.height(), 1.0).map(|slot| Candidate {
        slot,
        key: depth_key(r.depth),
    });
    (c.unwrap_or(Candidate::MISS), r.pixel)
}

/// [`candidate_at`] of four positions, projected in lanes (`lanes.rs`: the
/// same bits).
#[inline]
pub fn candidates_at4(p: &[[f32; 4]; LANES], target: &PassCamera) -> [(Candidate, Vec2); LANES] {
    let (q, w) = Lanes3::from_positions(p);
    let r = project4(target, q, w);
    let cells = cells4(&r, target.width(), target.height(), 1.0);
    std::array::from_fn(|l| match cells[l] {
        Some(slot) => {
            let key = depth_key(r.depth[l]);
            (Candidate { slot, key }, r.pixel(l))
        }
        None => (Candidate::MISS, Vec2::ZERO),
    })
}

/// How `warp_resolve` takes a winner's colour: the filter, and the map
/// from rendered to displayed pixels (motion vectors point through it).
#[derive(Clone, Copy, Debug)]
pub struct Resolve {
    /// Rendered pixels → displayed pixels of the rendered frame.
    pub map: DisplayMap,
    /// The colour filter.
    pub filter: Resample,
    /// Target width and height.
    pub size: (u32, u32),
}

/// CPU reference of `warp_resolve`: the `width × height` output with every
/// won pixel written, the rest holes. A winner's colour is resampled at
/// the sub-pixel position its target pixel's centre maps back to
/// (`resample.rs`); `landing(i)` is where source pixel `i` lands in the
/// target. Its motion points to that position in the rendered frame's
/// displayed region, so colour and motion agree. One pixel at a time;
/// [`resolve_runs`] is the same frame, faster.
pub fn resolve(
    winners: &Winners,
    source: Source<'_>,
    landing: impl Fn(usize) -> Vec2 + Sync + Send,
    how: Resolve,
) -> Output {
    resolve_with(winners, source, None, landing, how, Isa::Baseline)
}

/// [`resolve`], bit for bit, with runs of [`RUN`] target pixels won by
/// consecutive source pixels filtered at once (`resample_run.rs`) from
/// `planes`, the colour planes of `source` ([`Planes::fill`]); with AVX2
/// where the CPU has it (eight lanes a register instead of four).
pub fn resolve_runs(
    winners: &Winners,
    source: Source<'_>,
    planes: &Planes,
    landing: impl Fn(usize) -> Vec2 + Sync + Send,
    how: Resolve,
) -> Output {
    resolve_with(winners, source, Some(planes), landing, how, Isa::detect())
}

/// The instructions [`resolve_runs`] is compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    /// The build's target (SSE2 on x86-64).
    Baseline,
    /// AVX2, chosen at run time.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Isa {
    /// The best the CPU has.
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            return Isa::Avx2;
        }
        Isa::Baseline
    }
}

fn resolve_with<F: Fn(usize) -> Vec2 + Sync + Send>(
    winners: &Winners,
    source: Source<'_>,
    planes: Option<&Planes>,
    landing: F,
    how: Resolve,
    isa: Isa,
) -> Output {
    let resolver = Resolver::new(winners, source, planes, landing, how);
    let (width, height) = how.size;
    Output::from_rows(width, height, |rows| resolver.write(rows, isa))
}

/// [`resolve_runs`] from `planes`, [`resolve`] without them (the same
/// frame), packed band by band as it is made, with its holes listed
/// ([`pack::resolved`]): for an executor that hands the frame over packed
/// (the CPU executor's `generate_packed`).
pub fn resolve_packed(
    winners: &Winners,
    source: Source<'_>,
    planes: Option<&Planes>,
    landing: impl Fn(usize) -> Vec2 + Sync + Send,
    how: Resolve,
) -> pack::Resolved {
    let isa = match planes {
        Some(_) => Isa::detect(),
        None => Isa::Baseline,
    };
    let resolver = Resolver::new(winners, source, planes, landing, how);
    let (width, height) = how.size;
    pack::resolved(width, height, |rows| resolver.write(rows, isa))
}

/// What [`resolve`] reads, and the band loop that writes its pixels.
struct Resolver<'a, F> {
    winners: &'a Winners,
    source: Source<'a>,
    planes: Option<&'a Planes>,
    landing: F,
    how: Resolve,
    /// Source pixels per target pixel (`resample::position`).
    per_pixel: Vec2,
    target: Columns,
    image: Columns,
}

impl<'a, F: Fn(usize) -> Vec2> Resolver<'a, F> {
    /// What [`resolve`] of `how` reads, with the colour `planes` of
    /// `source` where runs can be taken from them.
    fn new(
        winners: &'a Winners,
        source: Source<'a>,
        planes: Option<&'a Planes>,
        landing: F,
        how: Resolve,
    ) -> Self {
        Self {
            winners,
            source,
            planes: planes.filter(|p| p.usable(source.color.len())),
            landing,
            how,
            per_pixel: Vec2::ONE / how.map.scale,
            target: Columns::new(how.size.0),
            image: Columns::new(source.size.0),
        }
    }

    /// Every pixel of a band of rows, compiled for `isa`.
    fn write(&self, rows: Rows<'_>, isa: Isa) {
        match isa {
            Isa::Baseline => self.band(rows),
            // SAFETY: `Isa::detect` found AVX2 on this CPU.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { self.band_avx2(rows) },
        }
    }

    /// Where target pixel `t`, won by `i`, takes its colour from.
    #[inline(always)]
    fn at(&self, t: usize, i: usize) -> Vec2 {
        let (own, center) = (self.image.center(i), self.target.center(t));
        resample::position(
            own,
            || (self.landing)(i),
            center,
            self.per_pixel,
            self.how.filter,
        )
    }

    /// Writes won pixel `t` with colour `c` from position `at`.
    #[inline(always)]
    fn set(&self, rows: &mut Rows<'_>, t: usize, at: Vec2, c: [f32; 3]) {
        rows.set(
            t,
            Pixel {
                color: [c[0], c[1], c[2], 1.0],
                depth: self.winners.depth(t).unwrap_or(f32::INFINITY),
                motion: (self.how.map.apply(at) - self.target.center(t)).to_array(),
                mask: WARPED,
            },
        );
    }

    /// Target pixel `t` alone.
    #[inline(always)]
    fn one(&self, rows: &mut Rows<'_>, t: usize) {
        let Some(i) = self.winners.winner(t) else {
            return;
        };
        let at = self.at(t, i);
        let c = resample::resample(self.source, i, at, self.how.filter);
        self.set(rows, t, at, c);
    }

    /// Target pixels from `t` (in one row, at least [`RUN`] of them left):
    /// the next [`RUN`] at once where their winners are consecutive source
    /// pixels of one row (and the run's filter takes them, else one by
    /// one); otherwise those before the first that breaks the sequence
    /// (at least one), one by one, so that the next run starts there (a
    /// crack or an edge inside a run costs the pixels before it, not the
    /// whole run). Returns how many pixels it wrote.
    #[allow(clippy::needless_range_loop)] // lane loops, as in `resample_run.rs`
    #[inline(always)]
    fn run(&self, rows: &mut Rows<'_>, t: usize, planes: &Planes) -> usize {
        let source_width = self.source.size.0;
        let first = self.winners.winner(t);
        let first = first.filter(|&i| self.image.split(i as u32).0 + RUN as u32 <= source_width);
        // Without early exits: most runs are consecutive.
        let mut consecutive = first.is_some();
        let (starts, first) = (first.is_some(), first.unwrap_or(0));
        for l in 1..RUN {
            consecutive &= self.winners.stored(t + l) == !((first + l) as u32);
        }
        if !consecutive {
            let mut before = 1;
            while starts && self.winners.stored(t + before) == !((first + before) as u32) {
                before += 1;
            }
            for t in t..t + before {
                self.one(rows, t);
            }
            return before;
        }
        // The centres of the run's pixels and of their winners are those of
        // its first ones moved by whole pixels (exact: half-integers).
        let (center, own) = (self.target.center(t), self.image.center(first));
        let filter = self.how.filter;
        // `resample::position` and the motion of `set`, lane by lane in
        // their order of operations (glam's `Vec2` takes them component
        // by component).
        let (mut x, mut y) = ([0.0f32; RUN], [own.y; RUN]);
        for l in 0..RUN {
            x[l] = own.x + l as f32;
        }
        if filter != Resample::Nearest {
            let (mut lx, mut ly) = ([0.0f32; RUN], [0.0f32; RUN]);
            for l in 0..RUN {
                let p = (self.landing)(first + l);
                (lx[l], ly[l]) = (p.x, p.y);
            }
            let k = self.per_pixel;
            for l in 0..RUN {
                let dx = (center.x + l as f32 - lx[l]) * k.x;
                let dy = (center.y - ly[l]) * k.y;
                x[l] += min(max(dx, -0.5), 0.5);
                y[l] += min(max(dy, -0.5), 0.5);
            }
        }
        let at: [Vec2; RUN] = std::array::from_fn(|l| Vec2::new(x[l], y[l]));
        let colors = resample_run::run(self.source, planes, first, &at, filter);
        let mut color = [[0.0f32; 4]; RUN];
        let mut depth = [0.0f32; RUN];
        let mut motion = [[0.0f32; 2]; RUN];
        let map = self.how.map;
        for l in 0..RUN {
            let c = match &colors {
                Some(c) => [c[0][l], c[1][l], c[2][l]],
                None => resample::resample(self.source, first + l, at[l], filter),
            };
            color[l] = [c[0], c[1], c[2], 1.0];
            depth[l] = self.winners.depth(t + l).unwrap_or(f32::INFINITY);
        }
        for l in 0..RUN {
            motion[l] = [
                (x[l] - map.offset.x) * map.scale.x - (center.x + l as f32),
                (y[l] - map.offset.y) * map.scale.y - center.y,
            ];
        }
        rows.set_run(t, &color, &depth, &motion, WARPED);
        RUN
    }

    /// Every pixel of a band of rows.
    #[inline(always)]
    fn band(&self, mut rows: Rows<'_>) {
        let width = self.how.size.0 as usize;
        for row in rows.pixels().step_by(width.max(1)) {
            let mut x = 0;
            if let Some(planes) = self.planes {
                while x + RUN <= width {
                    x += self.run(&mut rows, row + x, planes);
                }
            }
            (row + x..row + width).for_each(|t| self.one(&mut rows, t));
        }
    }

    /// [`Resolver::band`] compiled for AVX2: the run's lanes fill one
    /// register.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn band_avx2(&self, rows: Rows<'_>) {
        self.band(rows)
    }
}

/// Largest ratio between the depths of a crack's two neighbours: one
/// surface, as the resampling filter takes it.
pub const CRACK_DEPTH_RATIO: f32 = resample::SAME_SURFACE_RATIO;

/// The neighbour pairs a crack is closed from, in the order they are tried.
const PAIRS: [[(i32, i32); 2]; 4] = [
    [(-1, 0), (1, 0)],
    [(0, -1), (0, 1)],
    [(-1, -1), (1, 1)],
    [(1, -1), (-1, 1)],
];

/// CPU reference of `warp_cracks`.
pub fn close_cracks(out: &mut Output) {
    let holes = out.holes();
    close_cracks_at(out, &holes);
}

/// [`close_cracks`] where `holes` lists every hole of `out`, as the
/// resolve left them ([`resolve_packed`]), instead of a scan for them
/// (an index that is not a hole of `out` is passed over).
pub fn close_cracks_at(out: &mut Output, holes: &[usize]) {
    use rayon::prelude::*;
    let (w, h) = (out.width as i32, out.height as i32);
    let read = &*out;
    // Cracks are few: find them in parallel (reading only pixels that
    // were warped before, never one being written), then write them.
    let fixes: Vec<(usize, [f32; 4], f32, [f32; 2])> = (holes.par_iter())
        .filter(|&&t| read.mask.get(t) == Some(&EMPTY))
        .filter_map(|&t| {
            let (x, y) = ((t as i32) % w, (t as i32) / w);
            PAIRS.iter().find_map(|pair| {
                let [a, b] = pair.map(|(dx, dy)| {
                    let (nx, ny) = (x + dx, y + dy);
                    (nx >= 0 && ny >= 0 && nx < w && ny < h).then(|| (ny * w + nx) as usize)
                });
                let (a, b) = (a?, b?);
                if read.mask[a] != WARPED || read.mask[b] != WARPED {
                    return None;
                }
                let (da, db) = (read.depth[a], read.depth[b]);
                if da.max(db) > da.min(db) * CRACK_DEPTH_RATIO {
                    return None;
                }
                let (ca, cb) = (read.color[a], read.color[b]);
                let (ma, mb) = (read.motion[a], read.motion[b]);
                let color = [
                    (ca[0] + cb[0]) * 0.5,
                    (ca[1] + cb[1]) * 0.5,
                    (ca[2] + cb[2]) * 0.5,
                    1.0,
                ];
                let motion = [(ma[0] + mb[0]) * 0.5, (ma[1] + mb[1]) * 0.5];
                Some((t, color, (da + db) * 0.5, motion))
            })
        })
        .collect();
    for (t, color, depth, motion) in fixes {
        out.color[t] = color;
        out.depth[t] = depth;
        out.motion[t] = motion;
        out.mask[t] = CRACK;
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    target: PassCamera,
    /// source count, target width, target height, source width
    sizes: [u32; 4],
    map: [f32; 4],
    /// filter code, source height, 0, 0
    resample: [u32; 4],
}

/// The GPU pass (project + resolve; the splat between them is shared).
#[derive(Debug)]
pub struct GpuWarp {
    project: Kernel,
    resolve: Kernel,
    cracks: Kernel,
}

impl GpuWarp {
    /// Compiles the kernels.
    pub fn new(ctx: &GpuContext) -> Self {
        use Binding::*;
        let src = &format!("{}\n{}", resample::WGSL, include_str!("warp.wgsl"));
        Self {
            project: Kernel::new(
                ctx,
                src,
                "warp_project",
                &[Params, Read, Skip, Skip, Skip, Skip, Skip, Skip, ReadWrite],
            ),
            resolve: Kernel::new(
                ctx,
                src,
                "warp_resolve",
                &[
                    Params, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite, Skip,
                    Read, Read,
                ],
            ),
            cracks: Kernel::new(
                ctx,
                src,
                "warp_cracks",
                &[
                    Params, Skip, Skip, Skip, ReadWrite, ReadWrite, ReadWrite, ReadWrite,
                ],
            ),
        }
    }

    /// The kernels' uniform: `resample` is the filter code and the source
    /// height (`warp_resolve` only).
    fn params(
        ctx: &Rec<'_>,
        target: &PassCamera,
        sizes: [u32; 4],
        map: DisplayMap,
        resample: [u32; 2],
    ) -> wgpu::Buffer {
        ctx.params(bytemuck::bytes_of(&Params {
            target: *target,
            sizes,
            map: map.to_array(),
            resample: [resample[0], resample[1], 0, 0],
        }))
    }

    /// Records `warp_project`: `next` (n positions) → `candidates`.
    pub fn encode_project(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        target: &PassCamera,
        next: &wgpu::Buffer,
        n: u32,
        candidates: &wgpu::Buffer,
    ) {
        let sizes = [n, target.width(), target.height(), 0];
        let params = Self::params(ctx, target, sizes, DisplayMap::IDENTITY, [0, 0]);
        self.project
            .dispatch(ctx, encoder, &[&params, next, candidates], u64::from(n));
    }

    /// Records `warp_resolve` and `warp_cracks` over the target pixels, with
    /// the map from rendered to displayed pixels and the colour filter.
    /// `source` is the rendered frame's colour and depth with its size,
    /// `next` the positions at α the candidates were projected from.
    pub fn encode_resolve(
        &self,
        ctx: &Rec<'_>,
        encoder: &mut wgpu::CommandEncoder,
        (target, map, filter): (&PassCamera, DisplayMap, Resample),
        source: GpuSource<'_>,
        (keys, winners): (&wgpu::Buffer, &wgpu::Buffer),
        out: GpuOutput<'_>,
    ) {
        let (sw, sh) = source.size;
        let sizes = [0, target.width(), target.height(), sw];
        let params = Self::params(ctx, target, sizes, map, [filter.code(), sh]);
        let pixels = u64::from(target.width()) * u64::from(target.height());
        self.resolve.dispatch(
            ctx,
            encoder,
            &[
                &params,
                source.color,
                keys,
                winners,
                out.color,
                out.depth,
                out.motion,
                out.mask,
                source.next,
                source.depth,
            ],
            pixels,
        );
        self.cracks.dispatch(
            ctx,
            encoder,
            &[&params, out.color, out.depth, out.motion, out.mask],
            pixels,
        );
    }
}

/// The rendered frame as `warp_resolve` reads it.
#[derive(Debug, Clone, Copy)]
pub struct GpuSource<'a> {
    /// `vec4<f32>` colour.
    pub color: &'a wgpu::Buffer,
    /// `f32` sanitised depth.
    pub depth: &'a wgpu::Buffer,
    /// `vec4<f32>` positions at α (GFFE eq. 1).
    pub next: &'a wgpu::Buffer,
    /// Width and height.
    pub size: (u32, u32),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs of `resample_run.rs` resolve the same frame as the pixels
    /// one by one, bit for bit, on the build's instructions and on AVX2:
    /// a textured image with flat patches, highlights, edges between
    /// surfaces, sky and points with no surface, warped by a smooth
    /// sub-pixel pan and zoom (most runs taken at once; the holes it opens
    /// break runs) and zoomed out (winners that skip a source pixel break
    /// them), with the filters the runs do not take and with a source that
    /// is not opaque.
    #[test]
    fn runs_resolve_as_pixels_one_by_one() {
        use crate::passes::common::splat;
        let (w, h) = (97u32, 61u32);
        let n = (w * h) as usize;
        let noise = |i: usize| ((i as f32 * 0.618_034).fract() * 7.31).fract();
        let color: Vec<[f32; 4]> = (0..n)
            .map(|i| {
                let (x, y) = (i % w as usize, i / w as usize);
                let v = match (x / 16 + y / 16) % 3 {
                    0 => 0.25,                                     // flat
                    1 => 0.1 + noise(i),                           // texture
                    _ => [0.5, 60000.0][usize::from(i % 23 == 0)], // highlights
                };
                [v, v * 0.5 + noise(i + 1) * 0.01, 1.0 - v.min(1.0), 1.0]
            })
            .collect();
        let depth: Vec<f32> = (0..n)
            .map(|i| {
                let (x, y) = (i % w as usize, i / w as usize);
                match (x * 5 / w as usize, y % 29) {
                    (_, 0) => 0.0,
                    (0, _) => f32::INFINITY,
                    (1, _) => 2.0 + 0.001 * x as f32,
                    _ => 3.0 + 0.002 * y as f32 + 0.05 * noise(i),
                }
            })
            .collect();
        // Source pixel `i` lands at its centre zoomed about the middle and
        // panned by a fraction of a pixel; or, as under a camera that
        // stands still, a hair to either side of its centre (neighbouring
        // windows shifted differently: runs left to the pixels).
        let (image, middle) = (Columns::new(w), Vec2::new(w as f32, h as f32) * 0.5);
        let pan = |i: usize| (image.center(i) - middle) * 1.013 + middle + Vec2::new(0.37, -0.21);
        let still = |i: usize| image.center(i) + (Vec2::new(noise(i), noise(i + 99)) - 0.5) * 2e-4;
        // Zoomed out: a source pixel now and then lands where its
        // neighbour does and loses, and the winners skip one (a run broken
        // by a winner, not by a hole).
        let out = |i: usize| (image.center(i) - middle) * 0.987 + middle + Vec2::new(0.37, -0.21);
        let warps: [(&str, &(dyn Fn(usize) -> Vec2 + Sync + Send)); 3] = [
            ("pan and zoom", &pan),
            ("still", &still),
            ("zoomed out", &out),
        ];
        for (warp, land) in warps {
            let candidates: Vec<Candidate> = (0..n)
                .map(|i| match cell(land(i), w, h, 1.0) {
                    Some(slot) if depth[i] > 0.0 => Candidate {
                        slot,
                        key: depth_key(depth[i]),
                    },
                    _ => Candidate::MISS,
                })
                .collect();
            let winners = splat::resolve(&candidates, n);
            let bits = |o: &Output| {
                let c = o.color.iter().flatten().map(|v| v.to_bits());
                let d = o.depth.iter().map(|v| v.to_bits());
                let m = o.motion.iter().flatten().map(|v| v.to_bits());
                (
                    c.collect::<Vec<_>>(),
                    d.collect::<Vec<_>>(),
                    m.collect::<Vec<_>>(),
                    o.mask.clone(),
                )
            };
            let map = DisplayMap {
                offset: Vec2::new(1.5, -0.5),
                scale: Vec2::new(0.75, 0.75),
            };
            let mut isas = vec![Isa::Baseline];
            if Isa::detect() != Isa::Baseline {
                isas.push(Isa::detect());
            }
            let target = Columns::new(w);
            let (mut runs, mut taken) = (0, 0);
            for (filter, opaque) in [
                (Resample::CatmullRom, true),
                (Resample::Bilinear, true),
                (Resample::Nearest, true),
                (Resample::CatmullRom, false),
            ] {
                let mut color = color.clone();
                if !opaque {
                    color[n / 2][3] = 0.5;
                }
                let source = Source {
                    color: &color,
                    depth: &depth,
                    size: (w, h),
                };
                let mut planes = Planes::default();
                planes.fill(&color);
                assert_eq!(planes.usable(n), opaque);
                for map in [DisplayMap::IDENTITY, map] {
                    let how = Resolve {
                        map,
                        filter,
                        size: (w, h),
                    };
                    let one = bits(&resolve(&winners, source, land, how));
                    for &isa in &isas {
                        let runs = resolve_with(&winners, source, Some(&planes), land, how, isa);
                        assert!(one == bits(&runs), "{warp}: {filter} {isa:?} {map:?}");
                    }
                }
                if (warp, filter, opaque) != ("pan and zoom", Resample::CatmullRom, true) {
                    continue;
                }
                for t in (0..n).step_by(RUN) {
                    let Some(first) = winners.winner(t) else {
                        continue;
                    };
                    if target.split(t as u32).0 + RUN as u32 > w
                        || (0..RUN).any(|l| winners.winner(t + l) != Some(first + l))
                        || image.split(first as u32).0 + RUN as u32 > w
                    {
                        continue;
                    }
                    let at: [Vec2; RUN] = std::array::from_fn(|l| {
                        let (i, c) = (first + l, target.center(t + l));
                        resample::position(image.center(i), || land(i), c, Vec2::ONE, filter)
                    });
                    runs += 1;
                    let run = resample_run::run(source, &planes, first, &at, filter);
                    taken += usize::from(run.is_some());
                }
            }
            // Most runs of the textured, opaque case panned and zoomed are
            // taken at once.
            assert!(
                warp != "pan and zoom" || (runs > 300 && taken * 2 > runs),
                "{taken} of {runs} runs taken"
            );
        }
    }

    /// Four positions at a time land where each lands alone: points on and
    /// off the target, behind it, skies, nothing and NaN, seen from a
    /// camera that moved.
    #[test]
    fn four_lanes_land_as_one_by_one() {
        let (eye, size) = ([0.0, 1.0, 3.0], (96, 54));
        let source = crate::testutil::looking(eye, [0.5, 0.0, -4.0], size, eye);
        let target = crate::testutil::looking([0.2, 1.1, 2.9], [0.6, 0.0, -4.0], size, eye);
        let noise = |i: usize| (i as f32 * 0.618_034).fract();
        let p: Vec<[f32; 4]> = (0..4000)
            .map(|i| {
                let pixel = Vec2::new(noise(i) * 120.0 - 12.0, noise(i + 7919) * 68.0 - 7.0);
                let depth = [3.0 + 9.0 * noise(i * 5), f32::INFINITY, -2.0][i % 7 / 5];
                let mut p = source.unproject(pixel, depth);
                match i % 31 {
                    0 => p[3] = -1.0,
                    1 => p[0] = f32::NAN,
                    _ => {}
                }
                p
            })
            .collect();
        let mut landed = 0;
        for four in p.chunks_exact(LANES) {
            let four: &[[f32; 4]; LANES] = four.try_into().unwrap();
            for (l, (c, at)) in candidates_at4(four, &target).into_iter().enumerate() {
                let (one, one_at) = candidate_at(four[l], &target);
                assert_eq!(c, one, "{:?}", four[l]);
                if c.slot != crate::passes::common::splat::NONE {
                    assert_eq!(
                        at.to_array().map(f32::to_bits),
                        one_at.to_array().map(f32::to_bits)
                    );
                    landed += 1;
                }
            }
        }
        assert!(landed > 1000 && landed < 3500, "{landed} of 4000 landed");
    }
}
