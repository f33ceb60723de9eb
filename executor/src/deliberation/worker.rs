//! The [`Deliberator`]: the part of `c_c` that asks for plans and receives them.
//!
//! A request starts a planning job on its own thread; the control step only ever calls
//! [`Deliberator::poll`], which never blocks in [`PlanClock::WallClock`] mode. Every plan is
//! checked by [`verify_trajectory`] on the worker thread, after the planner and independently
//! of it, and a planner panic is caught there and delivered as an outcome. In
//! [`PlanClock::Simulated`] mode the delivery step is computed from the planner's expansion
//! count, so runs replay bit for bit whatever the thread timing.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::{Duration, Instant};

use embodied_models::{CollisionModel, Environment, JointLimits};
use embodied_planner::deadline::Deadline;

use super::trajectory::{Trajectory, verify_trajectory};

/// How planning time is counted.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum PlanClock {
    /// Real runs: the plan lands when the worker finishes; the deadline is wall-clock time.
    WallClock,
    /// Reproducible runs: the plan lands `fixed_steps + ceil(expansions * steps_per_expansion)`
    /// control steps after the request, and the deadline is that many steps. The control step
    /// waits for the worker's result (only in this mode) to learn the expansion count.
    Simulated { steps_per_expansion: f64, fixed_steps: u64 },
}

/// How long a plan may take.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanBudget {
    /// Wall-clock deadline (in [`PlanClock::WallClock`] mode).
    pub wall: Option<Duration>,
    /// Deadline in control steps after the request: the step at which the plan is needed
    /// (in [`PlanClock::Simulated`] mode this also bounds the expansions).
    pub steps: u64,
    /// Expansion budget given to the search (deterministic in both modes).
    pub expansions: Option<u64>,
}

impl Default for PlanBudget {
    fn default() -> Self {
        Self { wall: Some(Duration::from_millis(50)), steps: 50, expansions: None }
    }
}

/// A request for a plan, stamped so that a late answer can be recognised as stale.
#[derive(Debug, Clone)]
pub struct PlanRequest {
    /// Increases with every request of one deliberator.
    pub id: u64,
    /// Version of the agent's world model when the request was made.
    pub world_version: u64,
    /// Step at which the request was made.
    pub step: u64,
    /// Start configuration (the agent is at rest there).
    pub start: Vec<f64>,
    /// Goal configuration.
    pub goal: Vec<f64>,
    /// Control period, s (the trajectory's sampling period).
    pub dt: f64,
    /// The environment as the agent knows it (base environment plus sensed obstacles); `None`
    /// means the planner's own.
    pub environment: Option<Environment>,
    pub budget: PlanBudget,
}

/// A successful plan and the work it took.
#[derive(Debug, Clone)]
pub struct Planned {
    pub trajectory: Trajectory,
    pub expansions: u64,
}

/// Why no plan came back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanFailure {
    #[error("out of time after {expansions} expansions ({reason})")]
    OutOfTime { expansions: u64, reason: String },
    #[error("infeasible after {expansions} expansions")]
    Infeasible { expansions: u64 },
    #[error("{0}")]
    Error(String),
}

impl PlanFailure {
    fn expansions(&self) -> u64 {
        match self {
            PlanFailure::OutOfTime { expansions, .. } | PlanFailure::Infeasible { expansions } => *expansions,
            PlanFailure::Error(_) => 0,
        }
    }
}

/// A motion planner: anything that turns a request into a trajectory under a deadline.
/// Closures `Fn(&PlanRequest, &Deadline) -> Result<Planned, PlanFailure>` are planners, so tests
/// can inject panicking, slow or wrong ones.
pub trait MotionPlanner: Send + Sync {
    fn plan(&self, request: &PlanRequest, deadline: &Deadline) -> Result<Planned, PlanFailure>;
}

impl<F> MotionPlanner for F
where
    F: Fn(&PlanRequest, &Deadline) -> Result<Planned, PlanFailure> + Send + Sync,
{
    fn plan(&self, request: &PlanRequest, deadline: &Deadline) -> Result<Planned, PlanFailure> {
        self(request, deadline)
    }
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
    pub id: u64,
    pub world_version: u64,
    pub start: Vec<f64>,
    pub requested_at: u64,
    /// Step at which the plan was needed (request step + budget steps).
    pub needed_at: u64,
    pub outcome: PlanOutcome,
    pub expansions: u64,
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
    cancel: Arc<AtomicBool>,
    rx: Receiver<WorkerResult>,
    /// Simulated mode: the worker's result and the step it lands at.
    held: Option<(WorkerResult, u64)>,
    /// The answer was lost in transit: it will never be delivered.
    lost: bool,
}

struct WorkerResult {
    outcome: PlanOutcome,
    expansions: u64,
    elapsed: Duration,
}

/// What the verifier checks a plan against.
#[derive(Clone)]
pub struct PlanVerifier {
    pub limits: Vec<JointLimits>,
    /// Collision model (its environment is replaced by the request's, when given).
    pub collision: Option<CollisionModel>,
    /// Collision-check resolution, rad or m.
    pub resolution: f64,
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
}

impl Deliberator {
    pub fn new(planner: Arc<dyn MotionPlanner>, verifier: PlanVerifier, clock: PlanClock) -> Self {
        Self { planner, verifier: Arc::new(verifier), clock, next_id: 1, job: None, lose: 0 }
    }

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
        if let Some(n) = request.budget.expansions {
            deadline = deadline.and_expansions(n);
        }
        let wall = match self.clock {
            PlanClock::WallClock => request.budget.wall,
            PlanClock::Simulated { steps_per_expansion, fixed_steps } => {
                // The expansions that fit into the step budget.
                if steps_per_expansion > 0.0 {
                    let fit = (request.budget.steps.saturating_sub(fixed_steps) as f64 / steps_per_expansion).floor();
                    deadline = deadline.and_expansions(fit.max(0.0) as u64);
                }
                None
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
            cancel,
            rx,
            held: None,
            lost: false,
        };
        let planner = self.planner.clone();
        let verifier = self.verifier.clone();
        let id = request.id;
        std::thread::spawn(move || {
            let started = Instant::now();
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| planner.plan(&request, &deadline)));
            let elapsed = started.elapsed();
            let (outcome, expansions) = match result {
                Err(payload) => (PlanOutcome::Panicked(panic_message(payload.as_ref())), 0),
                Ok(Err(failure)) => {
                    let n = failure.expansions();
                    (PlanOutcome::Failed(failure), n)
                }
                Ok(Ok(planned)) => (verify(&verifier, &request, planned.trajectory), planned.expansions),
            };
            // The receiver may be gone (request superseded): nothing to do then.
            let _ = tx.send(WorkerResult { outcome, expansions, elapsed });
        });
        self.job = Some(job);
        id
    }

    /// Abandon the outstanding request (its worker is asked to stop).
    pub fn cancel(&mut self) {
        if let Some(job) = self.job.take() {
            job.cancel.store(true, Ordering::Relaxed);
        }
    }

    /// A delivery, if one has landed by `step`. Never blocks in wall-clock mode. A job whose
    /// worker vanished without answering is delivered as a failure.
    pub fn poll(&mut self, step: u64) -> Option<PlanDelivery> {
        let job = self.job.as_mut()?;
        if job.lost {
            return None;
        }
        let result = match self.clock {
            PlanClock::WallClock => match job.rx.try_recv() {
                Ok(r) => r,
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => lost_worker(),
            },
            PlanClock::Simulated { steps_per_expansion, fixed_steps } => {
                if job.held.is_none() {
                    let r = job.rx.recv().unwrap_or_else(|_| lost_worker());
                    let latency = fixed_steps + (r.expansions as f64 * steps_per_expansion.max(0.0)).ceil() as u64;
                    job.held = Some((r, job.requested_at + latency.max(1)));
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
            expansions: result.expansions,
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

fn lost_worker() -> WorkerResult {
    WorkerResult {
        outcome: PlanOutcome::Failed(PlanFailure::Error("planner channel lost".into())),
        expansions: 0,
        elapsed: Duration::ZERO,
    }
}

fn verify(verifier: &PlanVerifier, request: &PlanRequest, trajectory: Trajectory) -> PlanOutcome {
    let mut model = verifier.collision.clone();
    if let (Some(m), Some(env)) = (model.as_mut(), &request.environment) {
        m.set_environment(env.clone());
    }
    if let Some(first) = trajectory.start() {
        let off = first.iter().zip(&request.start).any(|(a, b)| (a - b).abs() > 1e-6);
        if off || first.len() != request.start.len() {
            return PlanOutcome::Rejected("does not start at the requested start state".into());
        }
    }
    if let Some(last) = trajectory.end() {
        let off = last.iter().zip(&request.goal).any(|(a, b)| (a - b).abs() > 1e-6);
        if off || last.len() != request.goal.len() {
            return PlanOutcome::Rejected("does not end at the goal".into());
        }
    }
    match verify_trajectory(&trajectory, &verifier.limits, model.as_ref(), verifier.resolution) {
        Ok(()) => PlanOutcome::Ready(Arc::new(trajectory)),
        Err(v) => PlanOutcome::Rejected(v.to_string()),
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
