//! A shared planning service for many agents: a bounded number of planner workers and a fair
//! queue in front of them.
//!
//! Without it every [`Deliberator`](super::Deliberator) plans on a thread of its own, which is
//! right for a handful of agents and wrong for a thousand asking at once on two cores. With a
//! [`PlanQueue`], a deliberator ([`Deliberator::with_queue`](super::Deliberator::with_queue))
//! puts its request in the queue instead; `workers` planners serve the queue, each request in
//! turn by the queue's [`QueuePolicy`] (earliest deadline first, or first come first served),
//! ties broken by the request step, then the agent, so no agent can be passed over for ever.
//!
//! Time is the run's simulated time, as in [`PlanClock::Simulated`]: a request waits in the
//! queue until a worker is free, then takes `fixed_steps + ceil(work * steps_per_unit)` steps
//! of that worker. A request whose waiting and planning would end after its give-up step is
//! delivered as out of time at that step (its agent has been halting safely since its deadline
//! passed); one still waiting at its give-up step is never planned. The outcome is the same
//! whatever the thread timing, so a run replays bit for bit. Requests made during step `i` are
//! served from step `i + 1` on, so the order in which agents stepping in parallel ask does not
//! matter.
//!
//! **Where the planners run.** A queue made with [`PlanQueue::new`] runs each planning job on
//! the thread that serves the queue, which is the control thread (inside a step). One made with
//! [`PlanQueue::with_worker_threads`] starts `workers` planner threads of its own: a request is
//! handed to them when it is made, and they plan the waiting requests ahead, in the queue's
//! order, while the control steps go on; serving the queue then only takes their answers. The
//! simulated timeline is the same in both (an answer depends only on its request, not on when
//! or where it was computed), so a run gives the same events, plans and queue figures either
//! way; only wall-clock figures differ. Should the simulated timeline reach a request the
//! threads have not finished yet, serving the queue waits for it (counted in
//! [`QueueStats::worker_waits`]): determinism is kept, at the price of that step's wall time.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use embodied_planner::request::PlanFailure;

use super::worker::{PlanClock, PlanOutcome};

/// The order in which waiting requests are served.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum QueuePolicy {
    /// Earliest deadline first (then the earlier request, then the lower agent key).
    EarliestDeadline,
    /// First come, first served (then the lower agent key).
    Fifo,
}

/// What a planning job computes: its outcome and the work it took.
pub(crate) type Work = Box<dyn FnOnce() -> (PlanOutcome, u64) + Send>;

/// Where a waiting request's answer comes from.
enum Job {
    /// Computed when it is served, on the serving thread.
    Inline(Work),
    /// Handed to the planner threads (the ticket of [`Pool`]).
    Pooled(u64),
}

struct Waiting {
    key: usize,
    id: u64,
    submitted: u64,
    deadline: u64,
    give_up: Option<u64>,
    job: Job,
}

/// An answer computed by a planner thread.
struct Computed {
    outcome: PlanOutcome,
    work: u64,
    elapsed: Duration,
}

/// A job waiting for a planner thread, with the queue's order.
struct Pending {
    ticket: u64,
    order: (u64, u64, usize, u64),
    work: Work,
}

#[derive(Default)]
struct PoolState {
    pending: Vec<Pending>,
    results: HashMap<u64, Computed>,
    /// Tickets whose answer is no longer wanted (withdrawn or given up while running).
    dropped: HashSet<u64>,
    /// A ticket the queue is waiting for: planned next.
    urgent: Option<u64>,
    shutdown: bool,
}

struct PoolShared {
    state: Mutex<PoolState>,
    /// A job was added (or the pool shuts down).
    work: Condvar,
    /// An answer is ready.
    done: Condvar,
}

impl PoolShared {
    fn lock(&self) -> MutexGuard<'_, PoolState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Planner threads that compute the queue's jobs ahead of the simulated timeline.
struct Pool {
    shared: Arc<PoolShared>,
    threads: Vec<JoinHandle<()>>,
    next_ticket: u64,
}

impl Pool {
    fn new(workers: usize) -> Self {
        let shared = Arc::new(PoolShared {
            state: Mutex::new(PoolState::default()),
            work: Condvar::new(),
            done: Condvar::new(),
        });
        let threads = (0..workers.max(1))
            .filter_map(|k| {
                let shared = shared.clone();
                std::thread::Builder::new().name(format!("planner-{k}")).spawn(move || serve(&shared)).ok()
            })
            .collect();
        Self { shared, threads, next_ticket: 0 }
    }

    fn add(&mut self, order: (u64, u64, usize, u64), work: Work) -> u64 {
        let ticket = self.next_ticket;
        self.next_ticket += 1;
        self.shared.lock().pending.push(Pending { ticket, order, work });
        self.shared.work.notify_one();
        ticket
    }

    /// The answer of `ticket`, waiting for it if a thread has not computed it yet (and whether
    /// it had to wait). Without planner threads (none could be started) the job is computed
    /// here.
    fn wait_for(&self, ticket: u64) -> (Computed, bool) {
        let mut state = self.shared.lock();
        let mut waited = false;
        loop {
            if let Some(c) = state.results.remove(&ticket) {
                return (c, waited);
            }
            if let Some(k) = state.pending.iter().position(|p| p.ticket == ticket) {
                if self.threads.is_empty() {
                    let job = state.pending.swap_remove(k);
                    drop(state);
                    return (compute(job.work), false);
                }
                state.urgent = Some(ticket);
                self.shared.work.notify_one();
            }
            waited = true;
            state = self.shared.done.wait(state).unwrap_or_else(PoisonError::into_inner);
        }
    }

    /// `ticket`'s answer is not wanted: not computed if it still waits, dropped if it comes.
    fn discard(&self, ticket: u64) {
        let mut state = self.shared.lock();
        let before = state.pending.len();
        state.pending.retain(|p| p.ticket != ticket);
        if state.pending.len() == before && state.results.remove(&ticket).is_none() {
            state.dropped.insert(ticket);
        }
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        {
            let mut state = self.shared.lock();
            state.shutdown = true;
            state.pending.clear();
        }
        self.shared.work.notify_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Run one job, a panic caught as an outcome (the jobs catch their planner's panics already).
fn compute(work: Work) -> Computed {
    let started = Instant::now();
    let (outcome, work) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work))
        .unwrap_or_else(|_| (PlanOutcome::Panicked("planning job panicked".into()), 0));
    Computed { outcome, work, elapsed: started.elapsed() }
}

/// A planner thread: the urgent job first, else the first in the queue's order.
fn serve(shared: &PoolShared) {
    loop {
        let job = {
            let mut state = shared.lock();
            loop {
                if state.shutdown {
                    return;
                }
                let urgent = state.urgent.and_then(|t| state.pending.iter().position(|p| p.ticket == t));
                let next =
                    urgent.or_else(|| state.pending.iter().enumerate().min_by_key(|(_, p)| p.order).map(|(k, _)| k));
                if let Some(k) = next {
                    if urgent.is_some() {
                        state.urgent = None;
                    }
                    break state.pending.swap_remove(k);
                }
                state = shared.work.wait(state).unwrap_or_else(PoisonError::into_inner);
            }
        };
        let computed = compute(job.work);
        let mut state = shared.lock();
        if !state.dropped.remove(&job.ticket) {
            state.results.insert(job.ticket, computed);
        }
        drop(state);
        shared.done.notify_all();
    }
}

/// A result waiting to land.
pub(crate) struct Finished {
    pub(crate) key: usize,
    pub(crate) id: u64,
    pub(crate) done_at: u64,
    pub(crate) outcome: PlanOutcome,
    pub(crate) work: u64,
    pub(crate) elapsed: std::time::Duration,
}

/// Figures of a queue's service so far.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct QueueStats {
    /// Requests put in the queue.
    pub requests: u64,
    /// Requests a worker planned.
    pub planned: u64,
    /// Requests withdrawn by their agent before they were planned (superseded).
    pub withdrawn: u64,
    /// Requests answered (planned or out of time) by their deadline step.
    pub answered_in_time: u64,
    /// Requests answered after their deadline (their agents halted meanwhile).
    pub answered_late: u64,
    /// Of those, requests given up as out of time: still waiting, or still planning, at their
    /// give-up step.
    pub expired: u64,
    /// Steps each planned or expired request waited for a worker.
    pub waits: Vec<u64>,
    /// Most requests waiting at once.
    pub max_waiting: usize,
    /// Wall-clock time spent planning, s (on the planner threads, with
    /// [`PlanQueue::with_worker_threads`]; else on the thread that served the queue).
    pub planning_wall_s: f64,
    /// Planner threads (0: the jobs run on the thread that serves the queue).
    pub worker_threads: usize,
    /// Answers the simulated timeline reached before a planner thread had computed them: the
    /// serving thread waited.
    pub worker_waits: u64,
    /// Wall-clock time the serving thread waited for planner threads, s.
    pub worker_wait_wall_s: f64,
}

impl QueueStats {
    /// The `p`-quantile (0..=1) of the waits, steps (0 without waits).
    pub fn wait_quantile(&self, p: f64) -> u64 {
        if self.waits.is_empty() {
            return 0;
        }
        let mut w = self.waits.clone();
        w.sort_unstable();
        let k = ((w.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize;
        w[k]
    }
}

/// A bounded set of planner workers with a fair queue, shared by many deliberators.
pub struct PlanQueue {
    policy: QueuePolicy,
    steps_per_unit: f64,
    fixed_steps: u64,
    /// The step at which each worker is free again.
    free_at: Vec<u64>,
    waiting: Vec<Waiting>,
    finished: Vec<Finished>,
    stats: QueueStats,
    /// Planner threads, if the queue has its own.
    pool: Option<Pool>,
}

/// A queue shared by the deliberators of many agents.
pub type SharedQueue = Arc<Mutex<PlanQueue>>;

impl PlanQueue {
    /// A queue served by `workers` planners (at least one), by `policy`, planning time counted
    /// as `clock` counts it (a wall clock counts as the simulated default, 2 µs per unit of
    /// work at 1 ms steps: a queue needs reproducible time).
    pub fn new(workers: usize, policy: QueuePolicy, clock: PlanClock) -> Self {
        let (steps_per_unit, fixed_steps) = match clock {
            PlanClock::Simulated { steps_per_unit, fixed_steps } => (steps_per_unit.max(0.0), fixed_steps),
            PlanClock::WallClock => (0.002, 0),
        };
        Self {
            policy,
            steps_per_unit,
            fixed_steps,
            free_at: vec![0; workers.max(1)],
            waiting: Vec::new(),
            finished: Vec::new(),
            stats: QueueStats::default(),
            pool: None,
        }
    }

    /// The same queue with `workers` planner threads of its own (as many as the simulated
    /// workers): requests are planned on them, ahead of the simulated timeline, and serving
    /// the queue only collects their answers (see the [module documentation](self)).
    pub fn with_worker_threads(mut self) -> Self {
        let pool = Pool::new(self.free_at.len());
        self.stats.worker_threads = pool.threads.len();
        self.pool = Some(pool);
        self
    }

    /// The queue, shareable.
    pub fn shared(self) -> SharedQueue {
        Arc::new(Mutex::new(self))
    }

    /// Figures of the service so far.
    pub fn stats(&self) -> &QueueStats {
        &self.stats
    }

    /// Requests waiting for a worker.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    pub(crate) fn submit(
        &mut self,
        key: usize,
        id: u64,
        submitted: u64,
        deadline: u64,
        give_up: Option<u64>,
        work: Work,
    ) {
        self.stats.requests += 1;
        let job = match &mut self.pool {
            Some(pool) => {
                let order = match self.policy {
                    QueuePolicy::EarliestDeadline => (deadline, submitted, key, id),
                    QueuePolicy::Fifo => (submitted, 0, key, id),
                };
                Job::Pooled(pool.add(order, work))
            }
            None => Job::Inline(work),
        };
        self.waiting.push(Waiting { key, id, submitted, deadline, give_up, job });
        self.stats.max_waiting = self.stats.max_waiting.max(self.waiting.len());
    }

    /// Withdraw agent `key`'s request `id` (superseded): not planned if it still waits, never
    /// delivered if it is done.
    pub(crate) fn withdraw(&mut self, key: usize, id: u64) {
        if let Some(k) = self.waiting.iter().position(|w| w.key == key && w.id == id) {
            let w = self.waiting.swap_remove(k);
            self.stats.withdrawn += 1;
            if let (Job::Pooled(ticket), Some(pool)) = (w.job, &self.pool) {
                pool.discard(ticket);
            }
        }
        self.finished.retain(|f| !(f.key == key && f.id == id));
    }

    fn next_index(&self, now: u64) -> Option<usize> {
        let ready = self.waiting.iter().enumerate().filter(|(_, w)| w.submitted < now);
        match self.policy {
            QueuePolicy::EarliestDeadline => {
                ready.min_by_key(|(_, w)| (w.deadline, w.submitted, w.key, w.id)).map(|(k, _)| k)
            }
            QueuePolicy::Fifo => ready.min_by_key(|(_, w)| (w.submitted, w.key, w.id)).map(|(k, _)| k),
        }
    }

    /// Serve the queue up to and including `step`: every worker free by then takes the next
    /// request (by the policy) that was made before the step it starts at.
    pub fn advance(&mut self, step: u64) {
        loop {
            let Some((worker, &free)) = self.free_at.iter().enumerate().min_by_key(|(_, f)| **f) else { return };
            let Some(first) = self.waiting.iter().map(|w| w.submitted + 1).min() else { return };
            let now = free.max(first);
            if now > step {
                return;
            }
            let Some(k) = self.next_index(now) else { return };
            let job = self.waiting.swap_remove(k);
            let answer = |s: &mut QueueStats, done_at: u64| {
                if done_at <= job.deadline {
                    s.answered_in_time += 1;
                } else {
                    s.answered_late += 1;
                }
            };
            self.stats.waits.push(now - job.submitted);
            if let Some(g) = job.give_up
                && now >= job.submitted + g
            {
                // Waited until its give-up step: never planned, the worker stays free.
                if let (Job::Pooled(ticket), Some(pool)) = (&job.job, &self.pool) {
                    pool.discard(*ticket);
                }
                let done_at = job.submitted + g;
                answer(&mut self.stats, done_at);
                self.stats.expired += 1;
                self.finished.push(Finished {
                    key: job.key,
                    id: job.id,
                    done_at,
                    outcome: PlanOutcome::Failed(PlanFailure::OutOfTime {
                        work: 0,
                        reason: format!("waited {g} steps in the planning queue"),
                    }),
                    work: 0,
                    elapsed: std::time::Duration::ZERO,
                });
                continue;
            }
            let computed = match (job.job, &self.pool) {
                (Job::Pooled(ticket), Some(pool)) => {
                    let started = Instant::now();
                    let (c, waited) = pool.wait_for(ticket);
                    if waited {
                        self.stats.worker_waits += 1;
                        self.stats.worker_wait_wall_s += started.elapsed().as_secs_f64();
                    }
                    c
                }
                (Job::Inline(work), _) => compute(work),
                (Job::Pooled(_), None) => Computed {
                    outcome: PlanOutcome::Failed(PlanFailure::Error("planning job without planner threads".into())),
                    work: 0,
                    elapsed: Duration::ZERO,
                },
            };
            let Computed { mut outcome, mut work, elapsed } = computed;
            self.stats.planning_wall_s += elapsed.as_secs_f64();
            self.stats.planned += 1;
            let latency = super::worker::simulated_latency(work, self.steps_per_unit, self.fixed_steps);
            let mut done_at = now + latency;
            if let Some(g) = job.give_up
                && done_at > job.submitted + g
            {
                // Still planning at its give-up step: stopped there, out of time.
                let left = (job.submitted + g).saturating_sub(now).saturating_sub(self.fixed_steps);
                work =
                    if self.steps_per_unit > 0.0 { (left as f64 / self.steps_per_unit).floor() as u64 } else { work };
                outcome = PlanOutcome::Failed(PlanFailure::OutOfTime {
                    work,
                    reason: format!("simulated planning time over {g} steps (queue included)"),
                });
                done_at = job.submitted + g;
                self.stats.expired += 1;
            }
            self.free_at[worker] = done_at;
            answer(&mut self.stats, done_at);
            self.finished.push(Finished { key: job.key, id: job.id, done_at, outcome, work, elapsed });
        }
    }

    /// Agent `key`'s answer to request `id`, if it has landed by `step` (the queue is served
    /// up to `step` first).
    pub(crate) fn take(&mut self, key: usize, id: u64, step: u64) -> Option<Finished> {
        self.advance(step);
        let k = self.finished.iter().position(|f| f.key == key && f.id == id && f.done_at <= step)?;
        Some(self.finished.swap_remove(k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(work: u64) -> Work {
        Box::new(move || (PlanOutcome::Rejected("test".into()), work))
    }

    #[test]
    fn earliest_deadline_is_served_first_and_late_requests_expire() {
        // One worker, 1 step per unit of work: each job of 10 units takes 10 steps.
        let clock = PlanClock::Simulated { steps_per_unit: 1.0, fixed_steps: 0 };
        let mut q = PlanQueue::new(1, QueuePolicy::EarliestDeadline, clock);
        q.submit(0, 1, 0, 100, Some(100), job(10));
        q.submit(1, 1, 0, 20, Some(25), job(10));
        q.submit(2, 1, 0, 50, Some(15), job(10));
        q.advance(1);
        // Agent 1 (deadline 20) first: from step 1 to 11.
        assert!(q.take(1, 1, 10).is_none());
        let a = q.take(1, 1, 11).expect("agent 1 answered at step 11");
        assert_eq!(a.done_at, 11);
        // Agent 2 (deadline 50, give-up after 15 steps) would run 11..21 > 15: out of time at 15.
        let b = q.take(2, 1, 15).expect("agent 2 given up at step 15");
        assert!(matches!(b.outcome, PlanOutcome::Failed(PlanFailure::OutOfTime { .. })));
        // Agent 0 starts at 15.
        let c = q.take(0, 1, 25).expect("agent 0 answered at step 25");
        assert_eq!(c.done_at, 25);
        let s = q.stats();
        assert_eq!((s.requests, s.planned, s.expired, s.answered_in_time, s.answered_late), (3, 3, 1, 3, 0));
        assert_eq!(s.waits, vec![1, 11, 15]);
    }

    /// Planner threads compute the same answers at the same simulated steps; withdrawn and
    /// given-up requests are never delivered.
    #[test]
    fn planner_threads_serve_the_same_timeline() {
        let run = |threads: bool| {
            let clock = PlanClock::Simulated { steps_per_unit: 1.0, fixed_steps: 0 };
            let mut q = PlanQueue::new(2, QueuePolicy::EarliestDeadline, clock);
            if threads {
                q = q.with_worker_threads();
            }
            for key in 0..12u64 {
                let give_up = if key % 5 == 4 { Some(12) } else { None };
                q.submit(key as usize, 1, key / 3, 30 + (key * 7) % 11, give_up, job(3 + key % 4));
            }
            q.withdraw(3, 1);
            let mut answers = Vec::new();
            for step in 0..80 {
                for key in 0..12 {
                    if let Some(f) = q.take(key, 1, step) {
                        let failed = matches!(f.outcome, PlanOutcome::Failed(_));
                        answers.push((key, f.done_at, f.work, failed));
                    }
                }
            }
            let s = q.stats().clone();
            (answers, s.planned, s.expired, s.withdrawn, s.waits, s.answered_in_time, s.answered_late)
        };
        let inline = run(false);
        assert_eq!(inline.0.len(), 11, "{:?}", inline.0);
        assert_eq!(run(true), inline);
    }

    #[test]
    fn requests_of_the_current_step_wait_for_the_next() {
        let clock = PlanClock::Simulated { steps_per_unit: 0.0, fixed_steps: 0 };
        let mut q = PlanQueue::new(2, QueuePolicy::Fifo, clock);
        q.submit(3, 7, 5, 10, None, job(1));
        assert!(q.take(3, 7, 5).is_none());
        assert_eq!(q.take(3, 7, 7).map(|f| f.done_at), Some(7));
        q.submit(4, 8, 9, 10, None, job(1));
        q.withdraw(4, 8);
        assert!(q.take(4, 8, 20).is_none());
        assert_eq!(q.stats().withdrawn, 1);
    }
}
