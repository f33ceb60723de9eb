//! When deliberation must stop.
//!
//! The paper (end of section 4): if planning takes so long that the plan is not in
//! `c_c^{i+1}` when the control step needs it, the agent must compute `c^{i+1}` without the
//! plan and halt the effector. A [`Deadline`] is how the caller tells the search when "late"
//! begins: a wall-clock instant, an expansion budget (reproducible on any machine), a
//! cancellation flag raised by another thread, any combination of these, or none.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Why a search stopped before it could decide.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Interrupt {
    /// The wall-clock deadline passed.
    WallClock,
    /// The expansion budget was used up.
    ExpansionBudget,
    /// Another thread raised the cancellation flag.
    Cancelled,
    /// The collision-check budget was used up.
    CheckBudget,
}

/// A limit on deliberation: wall clock, expansion budget, cancellation flag, or none of them.
///
/// Build with [`Deadline::none`], [`Deadline::after`], [`Deadline::at`] or
/// [`Deadline::expansions`], then combine with the `and_*`/`with_*` methods: the search stops at
/// whichever limit comes first.
#[derive(Debug, Clone, Default)]
pub struct Deadline {
    at: Option<Instant>,
    max_expansions: Option<u64>,
    /// At most this many collision checks (simulated planning time is counted in them).
    max_checks: Option<u64>,
    cancel: Option<Arc<AtomicBool>>,
    /// A second flag: a race of planners stops its losers with it, whatever flag the caller
    /// gave.
    race: Option<Arc<AtomicBool>>,
}

impl Deadline {
    /// No limit: the search runs until it is solved or proven infeasible.
    pub fn none() -> Self {
        Self::default()
    }

    /// A wall-clock deadline `budget` from now. A budget too large to represent means no wall clock.
    pub fn after(budget: Duration) -> Self {
        Self { at: Instant::now().checked_add(budget), ..Self::default() }
    }

    /// A wall-clock deadline at `instant`.
    pub fn at(instant: Instant) -> Self {
        Self { at: Some(instant), ..Self::default() }
    }

    /// An expansion budget: at most `n` states are expanded. Reproducible on any machine.
    pub fn expansions(n: u64) -> Self {
        Self { max_expansions: Some(n), ..Self::default() }
    }

    /// Adds (or tightens to) an expansion budget of `n`.
    #[must_use]
    pub fn and_expansions(mut self, n: u64) -> Self {
        self.max_expansions = Some(self.max_expansions.map_or(n, |m| m.min(n)));
        self
    }

    /// Adds (or tightens to) a collision-check budget: the search stops once it has made `n`
    /// collision checks (a certificate in progress ends first, at most
    /// `embodied_models::collision::CERTIFY_MAX_CHECKS` checks later). Reproducible on any
    /// machine; a simulated planning clock, which counts time in collision checks, bounds a
    /// search's wall time with it.
    #[must_use]
    pub fn and_checks(mut self, n: u64) -> Self {
        self.max_checks = Some(self.max_checks.map_or(n, |m| m.min(n)));
        self
    }

    /// Adds (or tightens to) a wall-clock deadline `budget` from now.
    #[must_use]
    pub fn and_after(self, budget: Duration) -> Self {
        match Instant::now().checked_add(budget) {
            Some(instant) => self.and_at(instant),
            None => self,
        }
    }

    /// Adds (or tightens to) a wall-clock deadline at `instant`.
    #[must_use]
    pub fn and_at(mut self, instant: Instant) -> Self {
        self.at = Some(self.at.map_or(instant, |a| a.min(instant)));
        self
    }

    /// Adds a cancellation flag: when another thread stores `true`, the search stops at its
    /// next deadline check (the executor's control thread uses this to abort a stale request).
    #[must_use]
    pub fn with_cancel_flag(mut self, flag: Arc<AtomicBool>) -> Self {
        self.cancel = Some(flag);
        self
    }

    /// Adds a second cancellation flag beside the caller's (a race of planners stops its
    /// losers with it); the search stops when either flag is raised.
    #[must_use]
    pub fn with_race_flag(mut self, flag: Arc<AtomicBool>) -> Self {
        self.race = Some(flag);
        self
    }

    /// The wall-clock instant, if any.
    pub fn instant(&self) -> Option<Instant> {
        self.at
    }

    /// The expansion budget, if any.
    pub fn expansion_budget(&self) -> Option<u64> {
        self.max_expansions
    }

    /// The collision-check budget, if any.
    pub fn check_budget(&self) -> Option<u64> {
        self.max_checks
    }

    /// True when the search, having expanded `expansions` states, must stop now.
    pub fn is_past(&self, expansions: u64) -> bool {
        self.check(expansions, 0, true).is_some()
    }

    /// Time left before the wall-clock deadline (`None` without one, zero once past).
    pub fn remaining(&self) -> Option<Duration> {
        self.at.map(|at| at.saturating_duration_since(Instant::now()))
    }

    /// The reason to stop, if any, after `expansions` units of work and `checks` collision
    /// checks. The budgets are integer compares and the cancellation and race flags one relaxed
    /// load each, always checked; the clock is read only when `read_clock` is set, so that a hot
    /// loop can read `Instant::now()` every few expansions.
    #[inline]
    pub(crate) fn check(&self, expansions: u64, checks: u64, read_clock: bool) -> Option<Interrupt> {
        if self.max_expansions.is_some_and(|max| expansions >= max) {
            return Some(Interrupt::ExpansionBudget);
        }
        if self.max_checks.is_some_and(|max| checks >= max) {
            return Some(Interrupt::CheckBudget);
        }
        // The flags are one relaxed load each, so they are read every time (a race's loser
        // stops within one unit of work); the clock only when asked.
        if self.flag_raised() {
            return Some(Interrupt::Cancelled);
        }
        if read_clock && self.at.is_some_and(|at| Instant::now() >= at) {
            return Some(Interrupt::WallClock);
        }
        None
    }

    /// The cancellation or race flag is up.
    #[inline(always)]
    fn flag_raised(&self) -> bool {
        self.cancel.as_ref().is_some_and(|flag| flag.load(Ordering::Relaxed))
            || self.race.as_ref().is_some_and(|flag| flag.load(Ordering::Relaxed))
    }

    /// True when the deadline needs a clock read or a flag load at all.
    #[inline]
    pub(crate) fn has_clock(&self) -> bool {
        self.at.is_some() || self.cancel.is_some() || self.race.is_some()
    }
}

/// Units of planning work against a [`Deadline`]: samples drawn, tree extensions, A*
/// expansions. The expansion budget of the deadline bounds this count, its check budget the
/// collision checks the caller reports with each unit; the clock and the cancellation flag are
/// read every few units (a unit costs at most a few collision checks, or one certificate).
pub(crate) struct Budget<'d> {
    deadline: &'d Deadline,
    pub work: u64,
    /// Collision checks made so far, as last reported to [`Self::spend`].
    checks: u64,
    /// `checks` when the clock was last read.
    checks_at_clock: u64,
    since_clock: u32,
    pub started: Instant,
    /// The limit that stopped planning, once one has.
    stopped: Option<Interrupt>,
    /// Called once, at the first clock read at least this long after the start (a race of
    /// planners hands its other racers to the thread pool then: see [`Self::with_hand_over`]).
    hand_over: Option<(&'d dyn Fn(), Duration)>,
    /// The hand-over waits (see [`Self::hold_hand_over`]).
    hand_over_held: bool,
    /// The hand-over waits whatever [`Self::hold_hand_over`] says (see
    /// [`Self::suspend_hand_over`]).
    hand_over_suspended: bool,
    /// The deadline's expansion and check budgets (`u64::MAX`: none).
    max_work: u64,
    max_checks: u64,
}

/// At most this many collision checks between two reads of the clock (a few hundred µs).
const CHECKS_PER_CLOCK_READ: u64 = 256;

impl<'d> Budget<'d> {
    pub fn new(deadline: &'d Deadline) -> Self {
        Self {
            deadline,
            work: 0,
            checks: 0,
            checks_at_clock: 0,
            since_clock: 0,
            started: Instant::now(),
            stopped: None,
            hand_over: None,
            hand_over_held: false,
            hand_over_suspended: false,
            max_work: deadline.max_expansions.unwrap_or(u64::MAX),
            max_checks: deadline.max_checks.unwrap_or(u64::MAX),
        }
    }

    /// Calls `f` once, at the first clock read (every few units of work, see [`Self::spend`])
    /// at least `after` past the start, unless planning ends before.
    pub fn with_hand_over(mut self, f: &'d dyn Fn(), after: Duration) -> Self {
        self.hand_over = Some((f, after));
        self
    }

    /// Hold the hand-over (`true`) while this racer tries the straight segment (which may solve
    /// the problem with no race) or certifies or shortens a path it found, or let it happen
    /// again (`false`, at the first clock read past its time): another racer would start its
    /// search from nothing, and handing it over costs this one a clone and a queue push.
    pub fn hold_hand_over(&mut self, hold: bool) {
        self.hand_over_held = hold;
    }

    /// Suspend the hand-over (`true`) through stages that hold and let it go themselves (see
    /// [`Self::hold_hand_over`]), or end the suspension (`false`): a plan whose legs take the
    /// racer thread two at a time hands no racer over meanwhile.
    pub fn suspend_hand_over(&mut self, suspend: bool) {
        self.hand_over_suspended = suspend;
    }

    /// Count `units` of work, `checks` being the collision checks made so far; true when
    /// planning must stop now. Inlined, it only counts and compares, and the flags are loaded;
    /// the clock (every 8 units, or sooner after many checks: a unit may be a whole
    /// certificate) and a limit reached go to [`Self::spend_rarely`]. (Called whole: about 50
    /// instructions a sample of the generated MotionBenchMaker cage problems.)
    #[inline(always)]
    pub fn spend(&mut self, units: u64, checks: u64) -> bool {
        self.work += units;
        self.checks = self.checks.max(checks);
        self.since_clock += 1;
        let due = self.since_clock >= 8 || self.checks - self.checks_at_clock >= CHECKS_PER_CLOCK_READ;
        if due || self.work >= self.max_work || self.checks >= self.max_checks || self.deadline.flag_raised() {
            return self.spend_rarely(due);
        }
        false
    }

    /// [`Self::spend`] when the clock is due (`due`) or a limit may be reached.
    #[cold]
    #[inline(never)]
    fn spend_rarely(&mut self, due: bool) -> bool {
        let read_clock = due && self.deadline.has_clock();
        if due {
            self.since_clock = 0;
            self.checks_at_clock = self.checks;
        }
        if read_clock
            && !self.hand_over_held
            && !self.hand_over_suspended
            && let Some((f, after)) = self.hand_over
            && self.started.elapsed() >= after
        {
            self.hand_over = None;
            f();
        }
        match self.deadline.check(self.work, self.checks, read_clock) {
            Some(cause) => {
                self.stopped.get_or_insert(cause);
                true
            }
            None => false,
        }
    }

    /// Collision checks made so far, as last reported.
    pub fn checks(&self) -> u64 {
        self.checks
    }

    /// True when the deadline has passed (reads the clock now).
    pub fn expired(&mut self) -> bool {
        match self.deadline.check(self.work, self.checks, true) {
            Some(cause) => {
                self.stopped.get_or_insert(cause);
                true
            }
            None => false,
        }
    }

    /// Which limit stopped planning (asked of the deadline now if none has yet).
    pub fn cause(&self) -> Interrupt {
        self.stopped.or_else(|| self.deadline.check(self.work, self.checks, true)).unwrap_or(Interrupt::ExpansionBudget)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A race's loser stops at its next unit of work once the race is won, not at its next
    /// clock read (every 8 units): the flags are read every time.
    #[test]
    fn a_raised_race_flag_stops_the_next_unit_of_work() {
        let flag = Arc::new(AtomicBool::new(false));
        let deadline = Deadline::none().with_race_flag(Arc::clone(&flag));
        let mut budget = Budget::new(&deadline);
        for _ in 0..3 {
            assert!(!budget.spend(1, 0));
        }
        flag.store(true, Ordering::Relaxed);
        assert!(budget.spend(1, 0), "the unit after the flag is raised stops");
        assert_eq!(budget.cause(), Interrupt::Cancelled);
        let cancel = Arc::new(AtomicBool::new(true));
        let deadline = Deadline::none().with_cancel_flag(cancel);
        assert!(Budget::new(&deadline).spend(1, 0), "the caller's flag too");
    }

    /// The expansion and check budgets stop the very unit that reaches them, between clock
    /// reads too (the inlined count compares them every time), alone or with a clock, and the
    /// cause says which; a wall clock already past stops at the next clock read (the 8th unit).
    #[test]
    fn budgets_stop_the_unit_that_reaches_them() {
        for deadline in [Deadline::expansions(5), Deadline::expansions(5).and_after(Duration::from_secs(3600))] {
            let mut budget = Budget::new(&deadline);
            for unit in 1..5 {
                assert!(!budget.spend(1, 0), "unit {unit}");
            }
            assert!(budget.spend(1, 0), "the fifth unit stops");
            assert_eq!(budget.cause(), Interrupt::ExpansionBudget);
        }
        let deadline = Deadline::none().and_checks(100);
        let mut budget = Budget::new(&deadline);
        assert!(!budget.spend(1, 40));
        assert!(!budget.spend(1, 99));
        assert!(budget.spend(1, 100), "the unit that reports the 100th check stops");
        assert_eq!(budget.cause(), Interrupt::CheckBudget);
        let deadline = Deadline::at(Instant::now());
        let mut budget = Budget::new(&deadline);
        for unit in 1..8 {
            assert!(!budget.spend(1, 0), "unit {unit}: no clock read yet");
        }
        assert!(budget.spend(1, 0), "the clock read of the 8th unit");
        assert_eq!(budget.cause(), Interrupt::WallClock);
    }

    /// The hand-over of a race is called once, at a clock read past its time, and never by
    /// planning that ends before it.
    #[test]
    fn the_hand_over_is_called_once_at_a_clock_read_past_its_time() {
        let calls = std::cell::Cell::new(0);
        let count = || calls.set(calls.get() + 1);
        let deadline = Deadline::none().with_race_flag(Arc::new(AtomicBool::new(false)));
        let mut budget = Budget::new(&deadline).with_hand_over(&count, Duration::ZERO);
        for _ in 0..7 {
            assert!(!budget.spend(1, 0));
        }
        assert_eq!(calls.get(), 0, "no clock read yet");
        for _ in 0..100 {
            assert!(!budget.spend(1, 0));
        }
        assert_eq!(calls.get(), 1, "once, at the first clock read");
        let mut budget = Budget::new(&deadline).with_hand_over(&count, Duration::from_secs(3600));
        for _ in 0..100 {
            assert!(!budget.spend(1, 0));
        }
        assert_eq!(calls.get(), 1, "not before its time");
        // Held, it waits past its time; let go, it happens at the next clock read.
        let mut budget = Budget::new(&deadline).with_hand_over(&count, Duration::ZERO);
        budget.hold_hand_over(true);
        for _ in 0..100 {
            assert!(!budget.spend(1, 0));
        }
        assert_eq!(calls.get(), 1, "held");
        budget.hold_hand_over(false);
        for _ in 0..8 {
            assert!(!budget.spend(1, 0));
        }
        assert_eq!(calls.get(), 2, "let go");
    }
}
