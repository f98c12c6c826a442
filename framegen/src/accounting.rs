//! Per-displayed-frame accounting (DESIGN §8) on the latency model of
//! ExtraNet §3.1: latency runs from the moment a frame is *ready* (a
//! rendered frame decoded, a generated frame finished) to the moment it is
//! *presented*. Field names follow PresentMon where one fits
//! (`ms_between_presents`, `ms_animation_error`).
//!
//! Per rendered frame four times are kept: *received* (its last byte
//! taken from the connection), *ready* (decoded: a display could show it
//! from then on), *ingested* (frame generation done with it: upload,
//! history, background) and *present*. **Added latency** is what frame
//! generation costs a rendered frame: its present against a display that
//! shows rendered frames directly, through the same presenter (the first
//! vsync after it was ready, plus the presenter's queue). Framegen work on
//! the path to showing it (its ingest, a generation before it) counts;
//! an ingest that ends before the frame's vsync costs nothing.
//!
//! "Present" is what the presenter reports: wgpu has no presentation-timing
//! API, so the presenters here report the vsync the frame was submitted for
//! (the slot's vsync when the submission finished before it, otherwise the
//! next vsync after the submission). The JSON report says so.

use std::time::Duration;

use serde::Serialize;

use crate::schedule::{Drops, ScheduleConfig, Slot, SlotKind};

/// One displayed frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Record {
    /// Consecutive display id.
    pub display_id: u64,
    /// What was shown.
    pub kind: SlotKind,
    /// Source rendered frame (the older one for interpolation).
    pub source: u64,
    /// Newer rendered frame of an interpolation.
    pub next: Option<u64>,
    /// α of a generated frame.
    pub alpha: f64,
    /// The source's host processing time (from its header), ms.
    pub host_processing_ms: f64,
    /// When the source's last byte arrived, ms since the session start.
    pub received_ms: f64,
    /// When what was shown was ready (a rendered frame decoded, a
    /// generated one finished), ms.
    pub ready_ms: f64,
    /// When frame generation had ingested the source rendered frame, ms
    /// (none if it had not been by the present).
    pub ingested_ms: Option<f64>,
    /// When it was presented, ms.
    pub present_ms: f64,
    /// ExtraNet latency: present − ready, ms.
    pub latency_ms: f64,
    /// For rendered frames: how much later it was shown than a display
    /// showing rendered frames directly would (the first vsync after it was
    /// ready, plus the presenter's queue; never below 0), ms. What frame
    /// generation adds, its work on the way included.
    pub added_latency_ms: Option<f64>,
    /// Time between this present and the previous one, ms.
    pub ms_between_presents: Option<f64>,
    /// |Δ present time − Δ simulation time shown|, ms: judder.
    pub ms_animation_error: Option<f64>,
    /// The viewer input whose camera was shown (interactive streams,
    /// issue 20): its sequence number.
    pub input_seq: Option<u64>,
    /// When that input was taken, ms.
    pub input_ms: Option<f64>,
    /// Input to photon: present − input time, ms.
    pub input_to_photon_ms: Option<f64>,
}

/// The viewer input a displayed frame's camera reflects: the newest one
/// taken when the client warps to its own pose (late input), else the one
/// the server echoed with the rendered frame shown or generated from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InputShown {
    /// The input's sequence number.
    pub seq: u64,
    /// When it was taken, on the presenter's clock.
    pub at: Duration,
}

/// Percentiles of one quantity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Percentiles {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of `values` (NaN-free).
    pub fn of(mut values: Vec<f64>) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        values.sort_by(f64::total_cmp);
        let at =
            |p: f64| values[((p * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1];
        Self {
            count: values.len(),
            p50: at(0.50),
            p95: at(0.95),
            p99: at(0.99),
            max: values[values.len() - 1],
        }
    }
}

/// A session's summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    /// What "present" means here.
    pub present_means: &'static str,
    /// What "ready" and "added latency" mean here.
    pub latency_means: &'static str,
    /// Displayed frames by kind.
    pub rendered: usize,
    /// Extrapolated slots.
    pub extrapolated: usize,
    /// Interpolated slots.
    pub interpolated: usize,
    /// Repeated (held) slots.
    pub repeated: usize,
    /// Extrapolated slots beyond α = 1 (a late rendered frame covered).
    pub beyond_one: usize,
    /// ExtraNet latency of every displayed frame.
    pub latency_ms: Percentiles,
    /// Latency frame generation adds to rendered frames.
    pub added_latency_ms: Percentiles,
    /// PresentMon MsBetweenPresents.
    pub ms_between_presents: Percentiles,
    /// PresentMon MsAnimationError.
    pub ms_animation_error: Percentiles,
    /// Input to photon of the frames whose camera reflects a viewer input
    /// (none without input).
    pub input_to_photon_ms: Percentiles,
    /// Frames never shown, by cause.
    pub drops: Drops,
}

/// What "present" means in every report.
pub const PRESENT_MEANS: &str = "the vsync a frame was submitted for: its slot's vsync if the submission finished before it, else the next vsync (wgpu has no presentation timing)";

/// What the latencies mean in every report.
pub const LATENCY_MEANS: &str = "latency = present - ready; a rendered frame is ready when decoded, a generated one when finished; added latency (rendered frames) = present - (first vsync after ready + the presenter's queue), so frame generation's ingest and any generation on the way count";

/// Collects [`Record`]s.
#[derive(Clone, Debug)]
pub struct Accounting {
    config: ScheduleConfig,
    /// Time of vsync 0 (the vsync grid is `origin + k · display_interval`).
    origin: Duration,
    /// The presenter's queue: how long after its slot's vsync a frame is
    /// presented at the earliest.
    queued: Duration,
    records: Vec<Record>,
    last: Option<(f64, f64)>,
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl Accounting {
    /// Accounting for a display whose vsyncs are `origin + k·interval` and
    /// whose presenter shows a slot `queued` after its vsync at the
    /// earliest (a swap chain's queue).
    pub fn new(config: ScheduleConfig, origin: Duration, queued: Duration) -> Self {
        Self {
            config,
            origin,
            queued,
            records: Vec::new(),
            last: None,
        }
    }

    /// The first vsync at or after `t`.
    pub fn first_vsync_after(&self, t: Duration) -> Duration {
        let di = self.config.display_interval.as_secs_f64();
        let k = ((t.saturating_sub(self.origin)).as_secs_f64() / di - 1e-9)
            .ceil()
            .max(0.0);
        self.origin + Duration::from_secs_f64(k * di)
    }

    /// Records a presented slot: `ready_at` is when its image was ready
    /// (the source's ready time for rendered and repeated slots, the end of
    /// generation for generated ones), `ingested_at` when frame generation
    /// had ingested its source, `present_at` when it was presented, and
    /// `input` the viewer input its camera reflects, if any.
    pub fn record(
        &mut self,
        slot: &Slot,
        ready_at: Duration,
        ingested_at: Option<Duration>,
        present_at: Duration,
        input: Option<InputShown>,
    ) {
        let sim = slot.sim_time(self.config.render_interval) * 1e3;
        let present = ms(present_at);
        let (between, animation) = match self.last {
            Some((p, s)) => (Some(present - p), Some(((present - p) - (sim - s)).abs())),
            None => (None, None),
        };
        self.last = Some((present, sim));
        // A presenter running late may take a frame that became ready after
        // the vsync it is working on and still show it at that slot's
        // present, earlier than the reference; that is no latency added.
        let direct = self.first_vsync_after(slot.source.ready_at) + self.queued;
        let added = (slot.kind == SlotKind::Rendered).then(|| (present - ms(direct)).max(0.0));
        self.records.push(Record {
            display_id: slot.display_id,
            kind: slot.kind,
            source: slot.source.id,
            next: slot.next.map(|n| n.id),
            alpha: slot.alpha,
            host_processing_ms: ms(slot.source.host_processing),
            received_ms: ms(slot.source.received_at),
            ready_ms: ms(ready_at),
            ingested_ms: ingested_at.map(ms),
            present_ms: present,
            latency_ms: present - ms(ready_at),
            added_latency_ms: added,
            ms_between_presents: between,
            ms_animation_error: animation,
            input_seq: input.map(|i| i.seq),
            input_ms: input.map(|i| ms(i.at)),
            input_to_photon_ms: input.map(|i| present - ms(i.at)),
        });
    }

    /// Every record so far.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// The summary, with the scheduler's drop counts.
    pub fn summary(&self, drops: Drops) -> Summary {
        let count = |k: SlotKind| self.records.iter().filter(|r| r.kind == k).count();
        let collect = |f: &dyn Fn(&Record) -> Option<f64>| {
            Percentiles::of(self.records.iter().filter_map(f).collect())
        };
        Summary {
            present_means: PRESENT_MEANS,
            latency_means: LATENCY_MEANS,
            rendered: count(SlotKind::Rendered),
            extrapolated: count(SlotKind::Extrapolated),
            interpolated: count(SlotKind::Interpolated),
            repeated: count(SlotKind::Repeated),
            beyond_one: self
                .records
                .iter()
                .filter(|r| r.kind == SlotKind::Extrapolated && r.alpha > 1.0)
                .count(),
            latency_ms: collect(&|r| Some(r.latency_ms)),
            added_latency_ms: collect(&|r| r.added_latency_ms),
            ms_between_presents: collect(&|r| r.ms_between_presents),
            ms_animation_error: collect(&|r| r.ms_animation_error),
            input_to_photon_ms: collect(&|r| r.input_to_photon_ms),
            drops,
        }
    }
}

impl Summary {
    /// A one-screen text summary.
    pub fn to_text(&self) -> String {
        let p = |name: &str, q: &Percentiles| {
            format!(
                "  {name:<22} p50 {:7.2}  p95 {:7.2}  p99 {:7.2}  max {:7.2}  (n={})\n",
                q.p50, q.p95, q.p99, q.max, q.count
            )
        };
        let mut s = format!(
            "displayed: {} rendered, {} extrapolated ({} beyond α = 1), {} interpolated, {} repeated (held)\n",
            self.rendered, self.extrapolated, self.beyond_one, self.interpolated, self.repeated
        );
        s += &p("latency ms", &self.latency_ms);
        s += &p("added latency ms", &self.added_latency_ms);
        s += &p("MsBetweenPresents", &self.ms_between_presents);
        s += &p("MsAnimationError", &self.ms_animation_error);
        if self.input_to_photon_ms.count > 0 {
            s += &p("input to photon ms", &self.input_to_photon_ms);
        }
        s += &format!(
            "  drops: network {}, late {}, scheduler {}\n  present = {}\n  {}\n",
            self.drops.network,
            self.drops.late,
            self.drops.scheduler,
            self.present_means,
            self.latency_means
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule::{FrameReady, Policy, Scheduler};

    #[test]
    fn percentiles_use_nearest_rank() {
        let p = Percentiles::of((1..=100).map(f64::from).collect());
        assert_eq!((p.p50, p.p95, p.p99, p.max), (50.0, 95.0, 99.0, 100.0));
        assert_eq!(Percentiles::of(vec![]).count, 0);
    }

    /// A steady 30 fps stream at 60 Hz: extrapolation adds nothing and
    /// generated frames wait only for their vsync; interpolation adds one
    /// render interval to every rendered frame.
    #[test]
    fn extrapolation_adds_nothing_interpolation_adds_an_interval() {
        for (policy, lo, hi) in [
            (Policy::Extrapolate, 0.0, 0.01),
            (Policy::Interpolate, 33.3, 50.1),
        ] {
            let config = ScheduleConfig::multiple(policy, 30.0, 1);
            let di = config.display_interval;
            let mut s = Scheduler::new(config);
            let mut acc = Accounting::new(config, Duration::ZERO, Duration::ZERO);
            for v in 0..120u32 {
                let now = di * v;
                if v % 2 == 1 {
                    let id = u64::from(v / 2);
                    s.frame_ready(FrameReady {
                        id,
                        sim_time: id as f64 / 30.0,
                        host_processing: Duration::from_millis(4),
                        received_at: now - Duration::from_millis(3),
                        ready_at: now - Duration::from_millis(2),
                    });
                }
                if let Some(slot) = s.vsync(now) {
                    // Generation takes 3 ms and finishes before the vsync.
                    let ready =
                        if slot.kind == SlotKind::Rendered || slot.kind == SlotKind::Repeated {
                            slot.source.ready_at
                        } else {
                            now
                        };
                    acc.record(&slot, ready, Some(slot.source.ready_at), now, None);
                }
            }
            let sum = acc.summary(s.drops());
            assert!(
                sum.added_latency_ms.p50 >= lo && sum.added_latency_ms.max <= hi,
                "{policy:?}: {sum:?}"
            );
            assert!((sum.ms_between_presents.p99 - 1000.0 / 60.0).abs() < 0.01);
            assert!(
                sum.ms_animation_error.p99 < 0.01,
                "{policy:?}: {:?}",
                sum.ms_animation_error
            );
            assert!(sum.to_text().contains("MsBetweenPresents"));
            assert!(sum.to_text().contains("ready when decoded"));
        }
    }

    /// A rendered frame decoded before its vsync but ingested after it is
    /// shown a vsync later than a direct display would show it: the ingest
    /// on its path is added latency; one ingested in time adds none.
    #[test]
    fn an_ingest_on_the_path_is_added_latency() {
        let config = ScheduleConfig::multiple(Policy::Extrapolate, 30.0, 1);
        let di = config.display_interval;
        for (ingest_ms, added) in [(1, 0.0), (10, ms(di))] {
            let mut s = Scheduler::new(config);
            let mut acc = Accounting::new(config, Duration::ZERO, Duration::ZERO);
            let ready = di - Duration::from_millis(2);
            s.frame_ready(FrameReady {
                id: 0,
                sim_time: 0.0,
                host_processing: Duration::ZERO,
                received_at: ready - Duration::from_millis(1),
                ready_at: ready,
            });
            let slot = s.vsync(di).expect("a slot");
            assert_eq!(slot.kind, SlotKind::Rendered);
            let ingested = ready + Duration::from_millis(ingest_ms);
            // Shown at the first vsync after the ingest.
            let present = acc.first_vsync_after(ingested);
            acc.record(&slot, ready, Some(ingested), present, None);
            let r = &acc.records()[0];
            assert!((r.added_latency_ms.unwrap() - added).abs() < 1e-9, "{r:?}");
            assert!(r.received_ms < r.ready_ms && r.ingested_ms.unwrap() <= r.present_ms);
        }
    }

    /// Input to photon is present − the input's time, per displayed frame
    /// that reflects an input, and only those are summarised.
    #[test]
    fn input_to_photon_is_present_minus_the_input_time() {
        let config = ScheduleConfig::multiple(Policy::Extrapolate, 30.0, 1);
        let di = config.display_interval;
        let mut s = Scheduler::new(config);
        let mut acc = Accounting::new(config, Duration::ZERO, di);
        s.frame_ready(FrameReady {
            id: 0,
            sim_time: 0.0,
            host_processing: Duration::ZERO,
            received_at: Duration::ZERO,
            ready_at: Duration::ZERO,
        });
        for k in 1..=4u32 {
            let slot = s.vsync(di * k).expect("a slot");
            let input = (k % 2 == 0).then_some(InputShown {
                seq: u64::from(k),
                at: di * k - Duration::from_millis(5),
            });
            acc.record(&slot, di * k, None, di * (k + 1), input);
        }
        let r = acc.records();
        assert_eq!(r[0].input_to_photon_ms, None);
        let want = ms(di + Duration::from_millis(5));
        assert!((r[1].input_to_photon_ms.unwrap() - want).abs() < 1e-9);
        assert_eq!(r[3].input_seq, Some(4));
        let sum = acc.summary(s.drops());
        assert_eq!(sum.input_to_photon_ms.count, 2);
        assert!(sum.to_text().contains("input to photon"));
    }
}
