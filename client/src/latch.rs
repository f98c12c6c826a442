//! Late latching for late input (issue 20): when the presenter takes the
//! viewer's pose for a slot, and what it does with an image that missed
//! its vsync. Sans-IO: every call takes the presenter's clock.
//!
//! A compositor that warps to the newest pose (Oculus ASW, Meta
//! Application SpaceWarp) does not take the pose when it starts a slot but
//! as late as still lets the warp finish before the vsync: the pose then
//! ages by only the warp's time when it is shown. [`LateLatch`] learns how
//! long a slot takes from its input to its image and puts the input twice
//! the longest of the last [`WINDOW`], plus [`MARGIN`] for the wake-up and
//! the presenter's own work, before the slot's vsync. Twice: on a loaded
//! machine a slot's time varies by that much from one to the next, and a
//! latch that left a slot only the longest recent time lost a quarter of
//! the frames (74 % within one vsync's turn in a CI run where the
//! unlatched presenter had 96 %); while slots take more than half an
//! interval the input is taken at once, as without the latch.
//!
//! An image finished after its vsync would show a pose more than a vsync
//! old at the next one. When a fresh slot still fits before that next
//! vsync, the late image is replaced (dropped unshown, its vsync counted as
//! missed) and the next slot takes a newer pose; otherwise it is shown
//! late, since showing nothing new would be worse.

use std::collections::VecDeque;
use std::time::Duration;

/// How many recent slots the lead is learned from.
pub const WINDOW: usize = 32;

/// Added to the longest recent slot: timer wake-up and the presenter's
/// bookkeeping between the input and the image.
pub const MARGIN: Duration = Duration::from_millis(3);

/// When to take the viewer's input, learned from recent slots.
#[derive(Clone, Debug)]
pub struct LateLatch {
    display_interval: Duration,
    recent: VecDeque<Duration>,
}

impl LateLatch {
    /// A latch for a display of `display_interval`; it knows no slot yet.
    pub fn new(display_interval: Duration) -> Self {
        Self {
            display_interval,
            recent: VecDeque::with_capacity(WINDOW),
        }
    }

    /// How long before its vsync a slot's input is taken: twice the
    /// longest of the recent slots plus [`MARGIN`]; `None` before any slot.
    pub fn lead(&self) -> Option<Duration> {
        self.recent.iter().max().map(|&m| 2 * m + MARGIN)
    }

    /// Records that a slot took `took` from its input to its image.
    pub fn observe(&mut self, took: Duration) {
        if self.recent.len() == WINDOW {
            self.recent.pop_front();
        }
        self.recent.push_back(took);
    }

    /// When to take the input of a slot to be shown at `vsync`, at `now`:
    /// [`LateLatch::lead`] before it, never before `now` (at once while the
    /// lead is unknown or longer than what is left).
    pub fn input_at(&self, now: Duration, vsync: Duration) -> Duration {
        match self.lead() {
            Some(lead) => vsync.saturating_sub(lead).max(now),
            None => now,
        }
    }

    /// Whether an image finished at `done`, for `vsync` and after it, is
    /// replaced: a fresh slot started at `done` would still be ready, at
    /// the lead, for the next vsync.
    pub fn replace(&self, done: Duration, vsync: Duration) -> bool {
        done > vsync
            && self
                .lead()
                .is_some_and(|lead| done + lead <= vsync + self.display_interval)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn the_input_waits_until_the_slot_just_fits() {
        let mut latch = LateLatch::new(ms(25));
        // Nothing learned: at once.
        assert_eq!(latch.lead(), None);
        assert_eq!(latch.input_at(ms(101), ms(125)), ms(101));
        latch.observe(ms(2));
        latch.observe(ms(5));
        latch.observe(ms(3));
        assert_eq!(latch.lead(), Some(ms(10) + MARGIN));
        assert_eq!(latch.input_at(ms(101), ms(125)), ms(125) - ms(10) - MARGIN);
        // Already later than that: at once.
        assert_eq!(latch.input_at(ms(120), ms(125)), ms(120));
        // A slot longer than the interval: at once, never before now.
        latch.observe(ms(40));
        assert_eq!(latch.input_at(ms(101), ms(125)), ms(101));
    }

    #[test]
    fn the_lead_follows_the_recent_slots() {
        let mut latch = LateLatch::new(ms(25));
        latch.observe(ms(20));
        for _ in 0..WINDOW - 1 {
            latch.observe(ms(1));
        }
        assert_eq!(latch.lead(), Some(ms(40) + MARGIN));
        // The long slot leaves the window.
        latch.observe(ms(1));
        assert_eq!(latch.lead(), Some(ms(2) + MARGIN));
    }

    #[test]
    fn a_late_image_is_replaced_only_when_a_fresh_one_fits() {
        let mut latch = LateLatch::new(ms(25));
        // Unknown lead: shown late.
        assert!(!latch.replace(ms(130), ms(125)));
        latch.observe(ms(4));
        // On time: shown.
        assert!(!latch.replace(ms(125), ms(125)));
        assert!(!latch.replace(ms(110), ms(125)));
        // Late, and a fresh slot (twice 4 ms + margin) fits before 150 ms.
        assert!(latch.replace(ms(126), ms(125)));
        assert!(latch.replace(ms(150) - ms(8) - MARGIN, ms(125)));
        // Too late for a fresh one: shown late.
        assert!(!latch.replace(ms(150) - ms(8) - MARGIN + ms(1), ms(125)));
        // Slots that never fit are never replaced, so something is shown.
        latch.observe(ms(30));
        assert!(!latch.replace(ms(126), ms(125)));
    }
}
