//! The [`Deliberator`]: the part of `c_c` that asks for plans and receives them.
//!
//! A request starts a planning job on its own thread; the control step only ever calls
//! [`Deliberator::poll`], which never blocks in [`PlanClock::WallClock`] mode. Every plan is
//! checked by the planner crate's independent [`Verifier`] (by default certified: the whole
//! path between the samples proven collision-free, as strong as the planner's own edge
//! certificate; position, velocity and acceleration limits) and against the request's start and
//! goal on the worker thread, after the planner; a planner panic is caught there and delivered as an outcome. In
//! [`PlanClock::Simulated`] mode the delivery step is computed from the planner's count of work
//! units (for [`embodied_planner::motion::plan_motion`]: collision checks), so runs replay bit
//! for bit whatever the thread timing.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::{Duration, Instant};

use embodied_models::CollisionModel;
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::Goal;
pub use embodied_planner::request::{MotionPlanner, PlanBudget, PlanFailure, PlanRequest, Planned};
use embodied_planner::trajectory::Trajectory;
use embodied_planner::verify::Verifier;

/// How planning time is counted.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum PlanClock {
    /// Real runs: the plan lands when the worker finishes; the deadline is wall-clock time.
    WallClock,
    /// Reproducible runs: planning time is simulated from the work the planner reports; the
    /// plan lands `fixed_steps + ceil(work * steps_per_unit)` control steps after the request
    /// (at least one). The control step waits for the worker's result (only in this mode) to
    /// learn the work count.
    Simulated {
        /// Control steps per unit of work the planner reports.
        steps_per_unit: f64,
        /// Control steps added to every request.
        fixed_steps: u64,
    },
}

/// What came back for a request.
#[derive(Debug, Clone)]
pub enum PlanOutcome {
    /// A plan that passed the verifier.
    Ready(Arc<Trajectory>),
    /// The planner's plan failed the verifier (the violation, in words).
    Rejected(String),
    /// The planner gave no plan.
    Failed(PlanFailure),
    /// The planner panicked (the panic message).
    Panicked(String),
}

/// A plan delivered into `c_c`, with the stamps of its request.
#[derive(Debug, Clone)]
pub struct PlanDelivery {
    /// The request's id.
    pub id: u64,
    /// Version of the agent's world model when the request was made.
    pub world_version: u64,
    /// The start configuration of the request.
    pub start: Vec<f64>,
    /// Step at which the request was made.
    pub requested_at: u64,
    /// Step at which the plan was needed (request step + budget steps).
    pub needed_at: u64,
    /// What came back.
    pub outcome: PlanOutcome,
    /// Work units the planner reported.
    pub work: u64,
    /// Step at which the delivery landed in `c_c`.
    pub landed_at: u64,
    /// Wall-clock time the planner took (not for logs: it is not reproducible).
    pub elapsed: Duration,
    /// Wall-clock time past the wall deadline, if the planner ran over it.
    pub overshoot: Option<Duration>,
}

struct Job {
    id: u64,
    world_version: u64,
    start: Vec<f64>,
    requested_at: u64,
    needed_at: u64,
    wall: Option<Duration>,
    give_up_steps: Option<u64>,
    cancel: Arc<AtomicBool>,
    rx: Receiver<WorkerResult>,
    /// Simulated mode: the worker's result and the step it lands at.
    held: Option<(WorkerResult, u64)>,
    /// The answer was lost in transit: it will never be delivered.
    lost: bool,
}

/// A deliberator's place in a shared [`PlanQueue`](super::queue::PlanQueue).
struct QueueSeat {
    queue: super::queue::SharedQueue,
    key: usize,
}

fn lock(queue: &super::queue::SharedQueue) -> std::sync::MutexGuard<'_, super::queue::PlanQueue> {
    queue.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

struct WorkerResult {
    outcome: PlanOutcome,
    work: u64,
    elapsed: Duration,
}

/// What the verifier checks a plan against.
#[derive(Clone)]
pub struct PlanVerifier {
    /// The robot and its world (the environment is replaced by the request's, when given).
    pub collision: CollisionModel,
    /// The check every plan must pass ([`Verifier::default`]: certified).
    pub verifier: Verifier,
    /// Largest distance (C-space, or metres and radians for a tool pose) between the plan's end
    /// and its goal.
    pub goal_tolerance: f64,
}

/// The deliberation part of `c_c`: issues requests, runs them off the control thread, and
/// hands back deliveries.
pub struct Deliberator {
    planner: Arc<dyn MotionPlanner>,
    verifier: Arc<PlanVerifier>,
    clock: PlanClock,
    next_id: u64,
    job: Option<Job>,
    /// Fault injection: this many upcoming deliveries are lost in transit.
    lose: u32,
    /// The shared planning queue the requests go to, if any (else a thread per request).
    seat: Option<QueueSeat>,
}

impl Deliberator {
    /// A deliberator that runs `planner`, checks every plan with `verifier` and counts time by `clock`.
    pub fn new(planner: Arc<dyn MotionPlanner>, verifier: PlanVerifier, clock: PlanClock) -> Self {
        Self { planner, verifier: Arc::new(verifier), clock, next_id: 1, job: None, lose: 0, seat: None }
    }

    /// Send every request to the shared `queue` (as agent `key`, unique among its users)
    /// instead of planning on a thread of its own: bounded workers, a fair order, planning
    /// time simulated ([`super::queue`]).
    pub fn use_queue(&mut self, queue: super::queue::SharedQueue, key: usize) {
        self.cancel();
        self.seat = Some(QueueSeat { queue, key });
    }

    /// How planning time is counted.
    pub fn clock(&self) -> PlanClock {
        self.clock
    }

    /// Lose the next `n` deliveries between the worker and `c_c` (a lost transmission).
    pub fn lose_next_deliveries(&mut self, n: u32) {
        self.lose = n;
    }

    /// Id of the outstanding request, if any.
    pub fn pending(&self) -> Option<u64> {
        self.job.as_ref().map(|j| j.id)
    }

    /// Start planning for `request` (its `id` is assigned here and returned). An outstanding
    /// request is cancelled: its answer, should it still come, is never delivered.
    pub fn request(&mut self, mut request: PlanRequest) -> u64 {
        self.cancel();
        request.id = self.next_id;
        self.next_id += 1;
        let cancel = Arc::new(AtomicBool::new(false));
        let mut deadline = Deadline::none().with_cancel_flag(cancel.clone());
        if let Some(n) = request.budget.work {
            deadline = deadline.and_expansions(n);
        }
        // Simulated time never reads the clock: the give-up step is applied on delivery, and
        // the search is stopped by the collision checks that put it past that step (it would be
        // out of time whatever it found; without this its wall time has no bound).
        let (wall, give_up_steps) = match self.clock {
            PlanClock::WallClock => (request.budget.wall, None),
            PlanClock::Simulated { steps_per_unit, fixed_steps } => {
                if let Some(n) = request.budget.give_up_steps.and_then(|g| work_past(g, steps_per_unit, fixed_steps)) {
                    deadline = deadline.and_checks(n);
                }
                (None, request.budget.give_up_steps)
            }
        };
        if let Some(w) = wall {
            deadline = deadline.and_after(w);
        }
        let (tx, rx) = channel();
        let job = Job {
            id: request.id,
            world_version: request.world_version,
            start: request.start.clone(),
            requested_at: request.step,
            needed_at: request.step + request.budget.steps,
            wall,
            give_up_steps,
            cancel,
            rx,
            held: None,
            lost: false,
        };
        let planner = self.planner.clone();
        let verifier = self.verifier.clone();
        let id = request.id;
        if let Some(seat) = &self.seat {
            let (step, needed_at) = (job.requested_at, job.needed_at);
            let give_up = request.budget.give_up_steps;
            let work: super::queue::Work = Box::new(move || {
                let result =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| planner.plan(&request, &deadline)));
                match result {
                    Err(payload) => (PlanOutcome::Panicked(panic_message(payload.as_ref())), 0),
                    Ok(Err(failure)) => {
                        let n = failure.work();
                        (PlanOutcome::Failed(failure), n)
                    }
                    Ok(Ok(planned)) => (verify(&verifier, &request, planned.trajectory), planned.work),
                }
            });
            lock(&seat.queue).submit(seat.key, id, step, needed_at, give_up, work);
            drop(tx);
            self.job = Some(job);
            return id;
        }
        // Planning time runs from the request (thread start-up included).
        let started = Instant::now();
        std::thread::spawn(move || {
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| planner.plan(&request, &deadline)));
            let (outcome, work) = match result {
                Err(payload) => (PlanOutcome::Panicked(panic_message(payload.as_ref())), 0),
                Ok(Err(failure)) => {
                    let n = failure.work();
                    (PlanOutcome::Failed(failure), n)
                }
                Ok(Ok(planned)) => (verify(&verifier, &request, planned.trajectory), planned.work),
            };
            // The plan is usable only once the gate has passed it: its time counts too.
            let elapsed = started.elapsed();
            // The receiver may be gone (request superseded): nothing to do then.
            let _ = tx.send(WorkerResult { outcome, work, elapsed });
        });
        self.job = Some(job);
        id
    }

    /// Abandon the outstanding request (its worker is asked to stop).
    pub fn cancel(&mut self) {
        if let Some(job) = self.job.take() {
            job.cancel.store(true, Ordering::Relaxed);
            if let Some(seat) = &self.seat {
                lock(&seat.queue).withdraw(seat.key, job.id);
            }
        }
    }

    /// A delivery, if one has landed by `step`. Never blocks in wall-clock mode. A job whose
    /// worker vanished without answering is delivered as a failure.
    pub fn poll(&mut self, step: u64) -> Option<PlanDelivery> {
        let job = self.job.as_mut()?;
        if job.lost {
            return None;
        }
        let result = match (&self.seat, self.clock) {
            (Some(seat), _) => {
                let f = lock(&seat.queue).take(seat.key, job.id, step)?;
                WorkerResult { outcome: f.outcome, work: f.work, elapsed: f.elapsed }
            }
            (None, PlanClock::WallClock) => match job.rx.try_recv() {
                Ok(r) => r,
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => lost_worker(),
            },
            (None, PlanClock::Simulated { steps_per_unit, fixed_steps }) => {
                if job.held.is_none() {
                    let mut r = job.rx.recv().unwrap_or_else(|_| lost_worker());
                    let mut latency = simulated_latency(r.work, steps_per_unit, fixed_steps);
                    if let Some(limit) = job.give_up_steps
                        && latency > limit
                    {
                        // The search would still be running when it is stopped: out of time.
                        let work = if steps_per_unit > 0.0 {
                            (limit.saturating_sub(fixed_steps) as f64 / steps_per_unit).floor() as u64
                        } else {
                            r.work
                        };
                        r.outcome = PlanOutcome::Failed(PlanFailure::OutOfTime {
                            work,
                            reason: format!("simulated planning time over {limit} steps"),
                        });
                        r.work = work;
                        latency = limit.max(1);
                    }
                    job.held = Some((r, job.requested_at + latency));
                }
                match &job.held {
                    Some((_, due)) if *due <= step => {}
                    _ => return None,
                }
                job.held.take()?.0
            }
        };
        if self.lose > 0 {
            // Still outstanding as far as `c_c` can tell; only a timeout reveals the loss.
            self.lose -= 1;
            job.lost = true;
            return None;
        }
        let job = self.job.take()?;
        let overshoot = job.wall.and_then(|w| result.elapsed.checked_sub(w)).filter(|d| !d.is_zero());
        Some(PlanDelivery {
            id: job.id,
            world_version: job.world_version,
            start: job.start,
            requested_at: job.requested_at,
            needed_at: job.needed_at,
            outcome: result.outcome,
            work: result.work,
            landed_at: step,
            elapsed: result.elapsed,
            overshoot,
        })
    }
}

impl Drop for Deliberator {
    fn drop(&mut self) {
        self.cancel();
    }
}

/// Simulated planning time, in control steps, of `work` units (at least one step).
pub(crate) fn simulated_latency(work: u64, steps_per_unit: f64, fixed_steps: u64) -> u64 {
    fixed_steps.saturating_add((work as f64 * steps_per_unit.max(0.0)).ceil() as u64).max(1)
}

/// The least work whose simulated time is over `give_up` steps (`None` when no work is:
/// work costs no time). A search stopped at that much work loses nothing it could deliver.
pub(crate) fn work_past(give_up: u64, steps_per_unit: f64, fixed_steps: u64) -> Option<u64> {
    if !(steps_per_unit > 0.0 && steps_per_unit.is_finite()) {
        return None;
    }
    if simulated_latency(0, steps_per_unit, fixed_steps) > give_up {
        return Some(0);
    }
    // Near the answer from the real quotient, then exact against the same rounding as delivery.
    let estimate = (give_up.saturating_sub(fixed_steps) as f64 / steps_per_unit).floor();
    if estimate >= 2f64.powi(52) {
        // Past exact integers in f64: no bound worth the name.
        return None;
    }
    let mut w = estimate.max(0.0) as u64;
    while w > 0 && simulated_latency(w - 1, steps_per_unit, fixed_steps) > give_up {
        w -= 1;
    }
    while simulated_latency(w, steps_per_unit, fixed_steps) <= give_up {
        w = w.checked_add(1)?;
    }
    Some(w)
}

fn lost_worker() -> WorkerResult {
    WorkerResult {
        outcome: PlanOutcome::Failed(PlanFailure::Error("planner channel lost".into())),
        work: 0,
        elapsed: Duration::ZERO,
    }
}

fn verify(verifier: &PlanVerifier, request: &PlanRequest, trajectory: Trajectory) -> PlanOutcome {
    let mut model = verifier.collision.clone();
    if let Some(env) = &request.environment {
        model.set_environment(env.clone());
    }
    let robot = model.robot();
    let space = robot.config_space();
    let (Some(first), Some(last)) = (trajectory.q.first(), trajectory.q.last()) else {
        return PlanOutcome::Rejected("empty trajectory".into());
    };
    if first.len() != request.start.len() || space.distance(first, &request.start) > 1e-6 {
        return PlanOutcome::Rejected("does not start at the requested start state".into());
    }
    if let Some(why) = misses_goal(robot, last, &request.goal, verifier.goal_tolerance) {
        return PlanOutcome::Rejected(why);
    }
    match verifier.verifier.verify_trajectory(&model, &trajectory) {
        Ok(()) => PlanOutcome::Ready(Arc::new(trajectory)),
        Err(v) => PlanOutcome::Rejected(v.to_string()),
    }
}

/// Why `q` does not satisfy `goal` (`None` when it does). Continuous joints compare modulo a turn.
pub fn misses_goal(robot: &embodied_models::Robot, q: &[f64], goal: &Goal, tolerance: f64) -> Option<String> {
    let space = robot.config_space();
    let near = |g: &Vec<f64>| g.len() == q.len() && space.distance(g, q) <= tolerance;
    match goal {
        Goal::Configuration(g) if near(g) => None,
        Goal::AnyOf(gs) if gs.iter().any(near) => None,
        Goal::ToolPose { end_effector, pose }
            if *end_effector < robot.end_effectors().len() && q.len() == robot.dof() =>
        {
            let tool = robot.end_effector_poses(q, *end_effector).1;
            let dp = (tool.translation.vector - pose.translation.vector).norm();
            let dr = tool.rotation.angle_to(&pose.rotation);
            (dp > tolerance || dr > tolerance).then(|| format!("ends {dp:.4} m and {dr:.4} rad from the goal pose"))
        }
        _ => Some("does not end at the goal".into()),
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}
