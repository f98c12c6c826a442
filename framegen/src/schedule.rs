//! The presentation scheduler (DESIGN §8, ExtraNet §3.1 and Fig. 2): a
//! sans-IO state machine that decides, at every vsync, what the display
//! shows. It is fed events with `now` and does no IO, so every policy is
//! tested with a fake clock.
//!
//! * [`Scheduler::frame_ready`]: a rendered frame is decoded and can be
//!   shown or generated from ("ready", ExtraNet's start of latency).
//! * [`Scheduler::vsync`]: a display slot begins; the answer is a [`Slot`]
//!   saying what to show (or `None` before the first frame).
//!
//! Policies:
//! * **Extrapolate** (GFFE, no added latency): a rendered frame is shown at
//!   the first vsync after it is ready. Until the next one is ready, the
//!   slots show frames extrapolated from it at
//!   `α = (vsync − its present time) / render interval` (α = j/(n+1) when
//!   the display runs at (n+1)× the render rate). A late frame is covered
//!   by extrapolating beyond α = 1 up to `max_alpha`, then the last frame
//!   is held.
//! * **Interpolate** (GeoMotionGen, adds latency): rendered frame t+1 is
//!   held back until the frames between t and t+1 have been shown; a slot
//!   never waits on the network (a missing t+1 holds t). Exactly one frame
//!   is held back: a backlog beyond that is dropped. A rendered frame is
//!   shown n vsyncs after the first one after it is ready (t+1 ready just
//!   after t was shown: the minimum) or one render interval (t+1 ready
//!   before t was shown), so with the presenter's one-vsync queue its
//!   latency is at least one render interval (ExtraNet §3.1). The phase
//!   is kept where frames arrive in time for the slots between them:
//!   ahead by more than a vsync, the scheduler catches up a vsync; a frame
//!   shown as it arrives with none behind it makes it fall back a vsync
//!   (`Scheduler::pace`).
//! * **Repeat**: the newest ready frame, again and again (the baseline).
//!
//! Frames that become ready but are never shown are counted as drops by
//! cause: `network` (ids that never arrived), `late` (ready after a newer
//! frame was already shown) and `scheduler` (superseded by a newer ready
//! frame before any vsync showed them).

use std::collections::VecDeque;
use std::time::Duration;

use serde::Serialize;

/// How slots are filled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Policy {
    /// Show the newest rendered frame again.
    Repeat,
    /// Extrapolate from the newest rendered frame (no added latency).
    Extrapolate,
    /// Interpolate between the last two rendered frames (adds latency).
    Interpolate,
}

/// What a slot shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SlotKind {
    /// A rendered frame.
    Rendered,
    /// Extrapolated from `source` at `alpha`.
    Extrapolated,
    /// Interpolated between `source` and `next` at `alpha`.
    Interpolated,
    /// `source` shown again (no generation, or beyond the α limit).
    Repeated,
}

/// Scheduler settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduleConfig {
    /// The policy.
    pub policy: Policy,
    /// Time between rendered frames (1 / render rate).
    pub render_interval: Duration,
    /// Time between vsyncs (1 / display rate).
    pub display_interval: Duration,
    /// Largest α extrapolated before the last frame is held.
    pub max_alpha: f64,
}

impl ScheduleConfig {
    /// A display at (n + 1)× `render_fps`.
    pub fn multiple(policy: Policy, render_fps: f64, n: u32) -> Self {
        let render = Duration::from_secs_f64(1.0 / render_fps);
        Self {
            policy,
            render_interval: render,
            display_interval: render / (n + 1),
            max_alpha: 3.0,
        }
    }

    /// A display at a given refresh rate (Hz), whatever the render rate.
    pub fn refresh(policy: Policy, render_fps: f64, refresh_hz: f64) -> Self {
        Self {
            display_interval: Duration::from_secs_f64(1.0 / refresh_hz),
            ..Self::multiple(policy, render_fps, 1)
        }
    }
}

/// A rendered frame that has become ready.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FrameReady {
    /// Frame index (consecutive at the source).
    pub id: u64,
    /// Simulation time it shows, seconds.
    pub sim_time: f64,
    /// Host processing duration from its header.
    pub host_processing: Duration,
    /// When its last byte arrived.
    pub received_at: Duration,
    /// When it was decoded: a display could show it from then on
    /// (ExtraNet's "generated"; frame generation's ingest comes after).
    pub ready_at: Duration,
}

/// One display slot's decision.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Slot {
    /// Consecutive display id.
    pub display_id: u64,
    /// The vsync this slot is shown at.
    pub vsync: Duration,
    /// What it shows.
    pub kind: SlotKind,
    /// The rendered frame it comes from (the older one for interpolation).
    pub source: FrameReady,
    /// The newer frame of an interpolation.
    pub next: Option<FrameReady>,
    /// α (0 for rendered and repeated slots).
    pub alpha: f64,
}

impl Slot {
    /// Simulation time of what the slot shows, α render intervals (`Δ`)
    /// after the frame it comes from: `t + α·Δ`; for an interpolation,
    /// `t' − (1 − α)·Δ` before the newer frame `t'`. α counts render
    /// intervals, as the generator takes it (`Descriptor::along`): after a
    /// gap in the stream (frames that never arrived) the newer frame is
    /// more than one interval after the older, and the slots between show
    /// the last interval before it, not a share of the whole gap.
    pub fn sim_time(&self, render_interval: Duration) -> f64 {
        let interval = render_interval.as_secs_f64();
        match self.next {
            Some(next) => next.sim_time - (1.0 - self.alpha) * interval,
            None => self.source.sim_time + self.alpha * interval,
        }
    }
}

/// Frames that were never shown, by cause.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Drops {
    /// Ids the source sent that never became ready.
    pub network: u64,
    /// Ready only after a newer frame was shown.
    pub late: u64,
    /// Superseded by a newer ready frame before a vsync showed them.
    pub scheduler: u64,
}

/// The scheduler.
#[derive(Clone, Debug)]
pub struct Scheduler {
    config: ScheduleConfig,
    /// Ready frames not shown yet, oldest first.
    pending: VecDeque<FrameReady>,
    /// The frame shown last as `Rendered`, and when.
    shown: Option<(FrameReady, Duration)>,
    highest_ready: Option<u64>,
    next_display: u64,
    drops: Drops,
    /// Interpolation: consecutive rendered frames ready more than a vsync
    /// before the first slot between them and the frame before.
    lagging: u32,
}

/// Interpolation catches up a vsync once this many consecutive rendered
/// frames were ready more than a vsync before they were needed: a steady
/// lag, not one frame that arrived early (jitter), which would then cost a
/// hold.
pub const CATCH_UP_AFTER: u32 = 4;

impl Scheduler {
    /// A scheduler with `config`.
    pub fn new(config: ScheduleConfig) -> Self {
        Self {
            config,
            pending: VecDeque::new(),
            shown: None,
            highest_ready: None,
            next_display: 0,
            drops: Drops::default(),
            lagging: 0,
        }
    }

    /// The settings.
    pub fn config(&self) -> &ScheduleConfig {
        &self.config
    }

    /// Drops so far.
    pub fn drops(&self) -> Drops {
        self.drops
    }

    /// The rendered frame the coming slots interpolate toward: the oldest
    /// pending one once a frame is shown (`Interpolate` only). A generator
    /// can take it in as soon as it is ready, before the first slot
    /// between the two.
    pub fn interpolating_toward(&self) -> Option<u64> {
        let shown = self.shown.is_some();
        let interpolating = self.config.policy == Policy::Interpolate;
        self.pending
            .front()
            .filter(|_| shown && interpolating)
            .map(|f| f.id)
    }

    /// A rendered frame is ready.
    pub fn frame_ready(&mut self, frame: FrameReady) {
        if let Some(h) = self.highest_ready {
            if frame.id <= h {
                // Out of order: a newer frame is already ready or shown.
                self.drops.late += 1;
                return;
            }
            self.drops.network += frame.id - h - 1;
        }
        self.highest_ready = Some(frame.id);
        self.pending.push_back(frame);
    }

    /// A vsync at `now`: what to show in this slot.
    pub fn vsync(&mut self, now: Duration) -> Option<Slot> {
        let (kind, source, next, alpha) = match self.config.policy {
            Policy::Repeat | Policy::Extrapolate => self.extrapolate(now)?,
            Policy::Interpolate => self.interpolate(now)?,
        };
        let slot = Slot {
            display_id: self.next_display,
            vsync: now,
            kind,
            source,
            next,
            alpha,
        };
        self.next_display += 1;
        Some(slot)
    }

    fn take_newest_pending(&mut self, now: Duration) -> Option<FrameReady> {
        let newest = self.pending.pop_back()?;
        self.drops.scheduler += self.pending.len() as u64;
        self.pending.clear();
        self.shown = Some((newest, now));
        Some(newest)
    }

    fn extrapolate(
        &mut self,
        now: Duration,
    ) -> Option<(SlotKind, FrameReady, Option<FrameReady>, f64)> {
        if let Some(f) = self.take_newest_pending(now) {
            return Some((SlotKind::Rendered, f, None, 0.0));
        }
        let (source, at) = self.shown?;
        let alpha =
            (now.saturating_sub(at)).as_secs_f64() / self.config.render_interval.as_secs_f64();
        if self.config.policy == Policy::Repeat || alpha > self.config.max_alpha {
            return Some((SlotKind::Repeated, source, None, 0.0));
        }
        Some((SlotKind::Extrapolated, source, None, alpha))
    }

    /// Interpolation holds back exactly one frame: when more are pending
    /// (the stream got ahead, e.g. at start-up), the older ones are dropped
    /// (counted) so the added latency stays within one render interval
    /// instead of growing by a whole interval per backlogged frame.
    fn trim_backlog(&mut self) {
        while self.pending.len() > 2 {
            self.pending.pop_front();
            self.drops.scheduler += 1;
        }
    }

    /// When the rendered frame `frame`, shown at `now`, counts as shown for
    /// the α of the slots after it: `now`, a vsync earlier to catch up, or
    /// later to fall back (`alone`: no frame after it is ready yet).
    ///
    /// An interpolating display needs a frame when the first slot between
    /// it and the one before comes up, `render − display interval` before
    /// the frame itself is due; the frame's *margin* is how long before
    /// that slot it was ready.
    ///
    /// **Catching up.** Where the stream's phase leaves more than a vsync
    /// of margin (frame t+1 ready before t was shown, as after start-up,
    /// where the presenter waits for two frames), that vsync is latency for
    /// nothing, for as long as the phase lasts. After [`CATCH_UP_AFTER`]
    /// frames in a row with a margin of a vsync and a quarter, the
    /// scheduler advances the animation by one vsync: the next frame is due
    /// a vsync earlier (one slot between is skipped, an animation step of
    /// one vsync once), and every later frame is shown a vsync sooner with
    /// a quarter vsync of margin left for jitter.
    ///
    /// **Falling back.** A frame shown with a negative margin (ready less
    /// than `render − display interval` before `now`, after a late frame or
    /// when frames arrive just before the slot they are due at) leaves the
    /// slots after it without the next frame, if the stream keeps its pace:
    /// shown on time every time, each one would be followed by holds and no
    /// slot would ever be interpolated again. Such a frame, when no frame
    /// after it is ready yet, counts as shown the whole vsyncs later that
    /// make its margin non-negative: it is shown now, the slots before that
    /// time hold it (one hold, at 2×), and from then on the frames arrive
    /// in time for the slots between them, each waiting less than a
    /// render interval (the policy's contract).
    fn pace(&mut self, frame: &FrameReady, now: Duration, alone: bool) -> Duration {
        let di = self.config.display_interval.as_secs_f64();
        let ri = self.config.render_interval.as_secs_f64();
        let waited = now.saturating_sub(frame.ready_at).as_secs_f64();
        let margin = waited - (ri - di);
        if margin >= 1.25 * di {
            self.lagging += 1;
        } else {
            self.lagging = 0;
        }
        if alone && margin < 0.0 {
            let vsyncs = (-margin / di).ceil() as u32;
            return now + self.config.display_interval * vsyncs;
        }
        if self.lagging < CATCH_UP_AFTER {
            return now;
        }
        self.lagging = 0;
        now.saturating_sub(self.config.display_interval)
    }

    fn interpolate(
        &mut self,
        now: Duration,
    ) -> Option<(SlotKind, FrameReady, Option<FrameReady>, f64)> {
        let ri = self.config.render_interval.as_secs_f64();
        let Some((current, at)) = self.shown else {
            // Start once two frames are ready: show the older, keep the
            // newer as the target of the slots in between.
            if self.pending.len() < 2 {
                return None;
            }
            self.trim_backlog();
            let first = self.pending.pop_front()?;
            self.shown = Some((first, now));
            return Some((SlotKind::Rendered, first, None, 0.0));
        };
        let alpha = now.saturating_sub(at).as_secs_f64() / ri;
        // Half a vsync of slack so rounding never skips a rendered frame,
        // nor interpolates at α ≈ 0 (a frame that fell back, `pace`).
        let slack = 0.5 * self.config.display_interval.as_secs_f64() / ri;
        let due = alpha + slack >= 1.0;
        match self.pending.front().copied() {
            Some(_) if due => {
                self.trim_backlog();
                let next = self.pending.pop_front()?;
                let at = self.pace(&next, now, self.pending.is_empty());
                self.shown = Some((next, at));
                Some((SlotKind::Rendered, next, None, 0.0))
            }
            Some(next) if alpha >= slack => {
                Some((SlotKind::Interpolated, current, Some(next), alpha))
            }
            _ => Some((SlotKind::Repeated, current, None, 0.0)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    fn frame(id: u64, ready_ms: u64) -> FrameReady {
        FrameReady {
            id,
            sim_time: id as f64 / 30.0,
            host_processing: MS(5),
            received_at: MS(ready_ms.saturating_sub(2)),
            ready_at: MS(ready_ms),
        }
    }

    /// A 30 fps source whose frame k is ready at 33k + offset ms, a
    /// display at 60 Hz (vsync every 16.667 ms), run for `vsyncs` slots.
    fn run(policy: Policy, offset: u64, vsyncs: u64, skip: &[u64]) -> (Vec<Slot>, Drops) {
        run_with(policy, vsyncs, |k| {
            let ready = (k as f64 * 1000.0 / 30.0) as u64 + offset;
            (!skip.contains(&k)).then_some(ready)
        })
    }

    /// [`run`] with frame k ready at `ready(k)` ms (`None`: never sent);
    /// ready times must increase.
    fn run_with(
        policy: Policy,
        vsyncs: u64,
        ready: impl Fn(u64) -> Option<u64>,
    ) -> (Vec<Slot>, Drops) {
        let config = ScheduleConfig {
            max_alpha: 1.5,
            ..ScheduleConfig::multiple(policy, 30.0, 1)
        };
        let mut s = Scheduler::new(config);
        let di = config.display_interval;
        let mut slots = Vec::new();
        let mut next_frame = 0u64;
        // A skipped frame is due when the one after it would be.
        let due = |k: u64| (k..).find_map(&ready).unwrap_or(u64::MAX);
        for v in 0..vsyncs {
            let now = di * v as u32;
            while due(next_frame) as f64 <= now.as_secs_f64() * 1000.0 {
                if let Some(at) = ready(next_frame) {
                    s.frame_ready(frame(next_frame, at));
                }
                next_frame += 1;
            }
            if let Some(slot) = s.vsync(now) {
                slots.push(slot);
            }
        }
        (slots, s.drops())
    }

    #[test]
    fn extrapolation_shows_each_frame_at_the_first_vsync_after_it_is_ready() {
        let (slots, drops) = run(Policy::Extrapolate, 3, 60, &[]);
        let di = Duration::from_secs_f64(1.0 / 60.0);
        for s in slots.iter().filter(|s| s.kind == SlotKind::Rendered) {
            let wait = s.vsync - s.source.ready_at;
            assert!(wait <= di, "frame {} waited {wait:?}", s.source.id);
        }
        // Every other slot is extrapolated at α = 1/2.
        let extrapolated: Vec<_> = slots
            .iter()
            .filter(|s| s.kind == SlotKind::Extrapolated)
            .collect();
        assert!(extrapolated.len() >= 28);
        assert!(extrapolated.iter().all(|s| (s.alpha - 0.5).abs() < 0.01));
        assert_eq!(drops, Drops::default());
    }

    #[test]
    fn every_vsync_slot_is_filled_exactly_once() {
        for policy in [Policy::Repeat, Policy::Extrapolate, Policy::Interpolate] {
            let (slots, _) = run(policy, 3, 90, &[7]);
            let ids: Vec<u64> = slots.iter().map(|s| s.display_id).collect();
            assert_eq!(ids, (0..ids.len() as u64).collect::<Vec<_>>(), "{policy:?}");
            for pair in slots.windows(2) {
                assert!(pair[1].vsync > pair[0].vsync, "{policy:?}");
            }
            // Once started, no vsync is skipped.
            let first = slots[0].vsync;
            let di = Duration::from_secs_f64(1.0 / 60.0);
            let expected = ((slots.last().unwrap().vsync - first).as_secs_f64() / di.as_secs_f64())
                .round() as usize
                + 1;
            assert_eq!(slots.len(), expected, "{policy:?}");
        }
    }

    /// How long each rendered slot's frame waited after it was ready.
    fn waits(slots: &[Slot]) -> Vec<(u64, Duration)> {
        slots
            .iter()
            .filter(|s| s.kind == SlotKind::Rendered)
            .map(|s| (s.source.id, s.vsync - s.source.ready_at))
            .collect()
    }

    /// Interpolation holds each rendered frame back by the slot between
    /// frames (ExtraNet §3.1). Frames ready 3 ms after a vsync, 30 -> 60:
    /// start-up (the older of the first two ready is shown) locks into a
    /// phase a vsync later than needed, a render interval; the scheduler
    /// catches up once after `CATCH_UP_AFTER` frames, skipping one slot
    /// between, and holds every later frame one vsync.
    #[test]
    fn interpolation_holds_frames_back_by_the_slots_between() {
        let (slots, drops) = run(Policy::Interpolate, 3, 90, &[]);
        let ri = Duration::from_secs_f64(1.0 / 30.0);
        let di = ri / 2;
        let tick = Duration::from_millis(1);
        let waits = waits(&slots);
        assert!(waits.len() >= 40);
        let lagging = CATCH_UP_AFTER as usize;
        for (i, &(id, wait)) in waits.iter().enumerate().skip(1) {
            assert!(wait + tick >= di, "frame {id} waited only {wait:?}");
            if i <= lagging {
                assert!(wait + tick >= ri, "frame {id} waited {wait:?}");
            } else {
                assert!(wait < ri - tick, "frame {id} waited {wait:?}");
            }
        }
        // One skipped slot: two rendered slots in a row, once.
        let skips = slots
            .windows(2)
            .filter(|w| w[0].kind == SlotKind::Rendered && w[1].kind == SlotKind::Rendered)
            .count();
        assert_eq!(skips, 1);
        let interpolated: Vec<_> = slots
            .iter()
            .filter(|s| s.kind == SlotKind::Interpolated)
            .collect();
        assert!(interpolated.len() >= 40);
        assert!(
            interpolated
                .iter()
                .all(|s| s.next.unwrap().id == s.source.id + 1)
        );
        assert!(interpolated.iter().all(|s| (s.alpha - 0.5).abs() < 0.01));
        assert_eq!(drops, Drops::default());
    }

    /// What the coming slots interpolate toward is known as soon as that
    /// frame is ready: the frame after the one shown, never before a frame
    /// is shown, never for extrapolation; the slots between then go toward
    /// it.
    #[test]
    fn the_frame_interpolated_toward_is_known_when_it_is_ready() {
        let config = ScheduleConfig::multiple(Policy::Interpolate, 30.0, 1);
        let mut s = Scheduler::new(config);
        s.frame_ready(frame(0, 0));
        s.frame_ready(frame(1, 30));
        assert_eq!(s.interpolating_toward(), None, "nothing shown yet");
        assert_eq!(s.vsync(MS(34)).unwrap().source.id, 0);
        assert_eq!(s.interpolating_toward(), Some(1));
        let between = s.vsync(MS(50)).unwrap();
        assert_eq!(
            (between.kind, between.next.map(|n| n.id)),
            (SlotKind::Interpolated, Some(1))
        );
        s.frame_ready(frame(2, 60));
        assert_eq!(s.interpolating_toward(), Some(1), "1 is not shown yet");
        assert_eq!(s.vsync(MS(67)).unwrap().source.id, 1);
        assert_eq!(s.interpolating_toward(), Some(2));
        let between = s.vsync(MS(84)).unwrap();
        assert_eq!(between.next.map(|n| n.id), Some(2));
        let mut e = Scheduler::new(ScheduleConfig::multiple(Policy::Extrapolate, 30.0, 1));
        e.frame_ready(frame(0, 0));
        e.vsync(MS(1));
        e.frame_ready(frame(1, 30));
        assert_eq!(e.interpolating_toward(), None);
    }

    /// A frame that arrives early once (jitter) is not a lag: no slot is
    /// skipped for it, and nothing changes afterwards.
    #[test]
    fn interpolation_does_not_catch_up_on_one_early_frame() {
        let ready = |k: u64| (k as f64 * 1000.0 / 30.0) as u64 + 3;
        let (steady, _) = run(Policy::Interpolate, 3, 90, &[]);
        // Frame 30 comes 10 ms early: before the vsync its predecessor is
        // shown at.
        let (jittered, drops) = run_with(Policy::Interpolate, 90, |k| {
            Some(ready(k) - if k == 30 { 10 } else { 0 })
        });
        assert_eq!(drops, Drops::default());
        let kinds = |s: &[Slot]| s.iter().map(|s| (s.kind, s.source.id)).collect::<Vec<_>>();
        assert_eq!(kinds(&steady), kinds(&jittered));
    }

    /// Frames that straddle a vsync (one just before, the next just after)
    /// leave no margin for catching up: no slot is skipped, none held.
    #[test]
    fn interpolation_does_not_catch_up_without_margin() {
        let (slots, drops) = run_with(Policy::Interpolate, 120, |k| {
            Some((k as f64 * 1000.0 / 30.0) as u64 + 31 + 2 * (k % 2))
        });
        assert_eq!(drops, Drops::default());
        let kinds: Vec<_> = slots.iter().map(|s| s.kind).collect();
        assert!(kinds.windows(2).all(|w| w[0] != w[1]), "{kinds:?}");
    }

    /// Frames that start arriving later (from frame 30 on, 15 ms later:
    /// just after the vsync each is due at) are shown as they come, but
    /// the scheduler falls back a vsync once, so the slots between frames
    /// are interpolated again. Shown on time instead, each frame would be
    /// followed by a hold for the rest of the stream: the next frame comes
    /// just after the slot between them.
    #[test]
    fn interpolation_falls_back_a_vsync_when_frames_come_later() {
        let ready = |k: u64| (k as f64 * 1000.0 / 30.0) as u64 + 3 + if k >= 30 { 15 } else { 0 };
        let (slots, drops) = run_with(Policy::Interpolate, 150, |k| Some(ready(k)));
        assert_eq!(drops, Drops::default());
        let shown = |id| slots.iter().position(|s| s.source.id == id).unwrap();
        let after: Vec<_> = slots[shown(30)..].iter().map(|s| s.kind).collect();
        assert!(after.len() >= 60, "{}", after.len());
        // Frame 30 is shown, and held once.
        assert_eq!(after[..2], [SlotKind::Rendered, SlotKind::Repeated]);
        // From then on, rendered and interpolated slots alternate.
        for (i, pair) in after[2..].chunks_exact(2).enumerate() {
            assert_eq!(
                pair,
                [SlotKind::Interpolated, SlotKind::Rendered],
                "slots {}.. after frame 30: {after:?}",
                2 + 2 * i
            );
        }
        // Every frame still waits less than a render interval.
        let ri = Duration::from_secs_f64(1.0 / 30.0);
        for (id, wait) in waits(&slots).into_iter().filter(|&(id, _)| id >= 30) {
            assert!(wait < ri, "frame {id} waited {wait:?}");
        }
    }

    /// A slot between two frames shows α render intervals of the last
    /// interval before the newer one, as the generator makes it: across a
    /// gap too, where the frame between never arrived.
    #[test]
    fn an_interpolated_slot_shows_the_interval_before_the_newer_frame() {
        let ri = Duration::from_secs_f64(1.0 / 30.0);
        let slot = |next: u64, alpha: f64| Slot {
            display_id: 0,
            vsync: Duration::ZERO,
            kind: SlotKind::Interpolated,
            source: frame(10, 0),
            next: Some(frame(next, 0)),
            alpha,
        };
        let at = |id: u64| id as f64 / 30.0;
        for alpha in [0.25, 0.5, 0.75] {
            let between = slot(11, alpha).sim_time(ri);
            assert!((between - (at(10) + alpha * ri.as_secs_f64())).abs() < 1e-6);
            // Frame 11 never arrived: the slots before frame 12 show the
            // interval between 11 and 12.
            let across = slot(12, alpha).sim_time(ri);
            assert!((across - (at(11) + alpha * ri.as_secs_f64())).abs() < 1e-6);
        }
    }

    #[test]
    fn a_late_frame_is_covered_by_extrapolation_then_a_hold() {
        // Frames 5..=7 never arrive: after frame 4 the slots extrapolate
        // past α = 1 up to the limit (1.5), then hold frame 4.
        let (slots, drops) = run(Policy::Extrapolate, 3, 40, &[5, 6, 7]);
        let after: Vec<_> = slots.iter().filter(|s| s.source.id == 4).collect();
        let alphas: Vec<f64> = after
            .iter()
            .filter(|s| s.kind == SlotKind::Extrapolated)
            .map(|s| s.alpha)
            .collect();
        assert!(alphas.iter().any(|&a| a > 1.0 && a <= 1.5), "{alphas:?}");
        assert!(after.iter().any(|s| s.kind == SlotKind::Repeated));
        assert_eq!(drops.network, 3);
        // Frame 8 is shown as soon as it is ready.
        let f8 = slots.iter().find(|s| s.source.id == 8).unwrap();
        assert_eq!(f8.kind, SlotKind::Rendered);
    }

    #[test]
    fn superseded_and_out_of_order_frames_are_counted() {
        let config = ScheduleConfig::multiple(Policy::Extrapolate, 30.0, 1);
        let mut s = Scheduler::new(config);
        s.frame_ready(frame(0, 0));
        s.frame_ready(frame(1, 1));
        let slot = s.vsync(MS(2)).unwrap();
        assert_eq!(slot.source.id, 1);
        assert_eq!(s.drops().scheduler, 1);
        s.frame_ready(frame(1, 3));
        assert_eq!(s.drops().late, 1);
        s.frame_ready(frame(4, 4));
        assert_eq!(s.drops().network, 2);
    }
}
