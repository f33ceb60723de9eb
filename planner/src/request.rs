//! A request for a plan, and the [`MotionPlanner`] interface: what an agent's deliberation
//! asks of any motion planner (the crate's [`crate::motion::RrtConnect`] and
//! [`crate::motion::LazyPrm`], or one of the user's) under a [`Deadline`].
//!
//! The executor's deliberator stamps requests, runs the planner on its own thread, checks the
//! answer with the [`crate::verify::Verifier`] and delivers it into the agent's control state.

use std::time::Duration;

use embodied_models::Environment;

use crate::deadline::Deadline;
use crate::motion::Goal;
use crate::trajectory::Trajectory;

/// How long a plan may take: when it is needed, and when the search gives up.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanBudget {
    /// The deadline, in control steps after the request: the step at which the plan is needed.
    /// A plan not in `c_c` by then is late: the agent halts safely and waits for it.
    pub steps: u64,
    /// Wall-clock mode (real runs): the search is stopped this long after the request.
    pub wall: Option<Duration>,
    /// Simulated-time mode (reproducible runs): a search whose simulated time exceeds this many steps is
    /// delivered as out of time at that step.
    pub give_up_steps: Option<u64>,
    /// Work budget given to the search (deterministic in both modes).
    pub work: Option<u64>,
}

impl Default for PlanBudget {
    fn default() -> Self {
        Self { steps: 50, wall: Some(Duration::from_millis(50)), give_up_steps: Some(50), work: None }
    }
}

impl PlanBudget {
    /// The same deadline in both clocks: needed after `steps` steps of `dt` seconds, the search
    /// stopped then.
    pub fn hard(steps: u64, dt: f64) -> Self {
        Self {
            steps,
            wall: Some(Duration::from_secs_f64((steps as f64 * dt).max(0.0))),
            give_up_steps: Some(steps),
            work: None,
        }
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
    /// Where the motion must end.
    pub goal: Goal,
    /// Control period, s (the trajectory's sampling period).
    pub dt: f64,
    /// The environment as the agent knows it (base environment plus sensed obstacles); `None`
    /// means the planner's own.
    pub environment: Option<Environment>,
    /// When the plan is needed and when the search gives up.
    pub budget: PlanBudget,
}

/// A successful plan and the work it took (units of the planner's choosing, deterministic:
/// the executor's `PlanMotion` counts collision checks).
#[derive(Debug, Clone)]
pub struct Planned {
    /// The timed trajectory from the request's start to its goal.
    pub trajectory: Trajectory,
    /// Work units it took.
    pub work: u64,
}

/// Why no plan came back: the [`crate::outcome::Outcome`]s that are not solved, with the work
/// they took, or the planner's error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanFailure {
    /// [`crate::outcome::Outcome::OutOfTime`]: stopped by the deadline.
    #[error("out of time after {work} work units ({reason})")]
    OutOfTime {
        /// Work units spent before stopping.
        work: u64,
        /// Why it stopped.
        reason: String,
    },
    /// [`crate::outcome::Outcome::Infeasible`]: no plan exists (or none within the planner's
    /// sample budget).
    #[error("infeasible after {work} work units")]
    Infeasible {
        /// Work units spent.
        work: u64,
    },
    /// The planner could not plan (malformed input, start or goal in collision...).
    #[error("{0}")]
    Error(String),
}

impl PlanFailure {
    /// The work units spent before the failure (0 for an error).
    pub fn work(&self) -> u64 {
        match self {
            PlanFailure::OutOfTime { work, .. } | PlanFailure::Infeasible { work } => *work,
            PlanFailure::Error(_) => 0,
        }
    }
}

/// A motion planner: anything that turns a request into a trajectory under a deadline.
/// Closures `Fn(&PlanRequest, &Deadline) -> Result<Planned, PlanFailure>` are planners, so tests
/// can inject panicking, slow or wrong ones.
pub trait MotionPlanner: Send + Sync {
    /// Plan for `request`, stopping when `deadline` says so.
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
