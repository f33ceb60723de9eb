//! Deliberation in the loop (end of section 4 of the paper): "if planning takes long, the plan
//! may not be ready at step i+1; then the next state must be computed without it and must halt
//! the effector, to be on the safe side."
//!
//! * [`Deliberator`] (in `c_c`): requests run on their own thread under a
//!   [`embodied_planner::deadline::Deadline`]; [`Deliberator::poll`] never blocks the control
//!   step in wall-clock mode; planner panics are caught; every plan passes the
//!   [`embodied_planner::verify::Verifier`] (certified by default) before it is delivered as
//!   ready.
//! * [`PlanClock`]: wall clock for real runs, or simulated time derived from the planner's
//!   expansion count, so that logs replay bit for bit.
//! * [`PlanFollower`]: the behaviour that follows a verified plan and otherwise makes a
//!   [`crate::SafeHalt`]; stale plans (old world version or old start state) are discarded,
//!   never followed; a sensed obstacle in the path invalidates the plan and a new one is asked
//!   for from the halted state.
//! * [`PlanMotion`]: the planner, [`embodied_planner::motion::plan_motion`] under the
//!   request's deadline, its path time-parameterised into an
//!   [`embodied_planner::trajectory::Trajectory`]; plans are checked by the
//!   [`embodied_planner::verify::Verifier`] before they may drive an effector.
//! * [`PlanQueue`]: a shared planning service for many agents, bounded workers and a fair
//!   queue (earliest deadline first or first come first served), in simulated time.
//! * [`UnmappedObstacle`]: the virtual sensor that reports obstacles missing from the map.
//! * [`deliberative_agent`]: a scenario agent with a goal, as a deliberative agent.
//!
//! Events written to the step record: `plan_requested`, `plan_landed` (with the planning time),
//! `plan_late`, `plan_failed`, `plan_rejected` (with the reason), `planner_panicked`,
//! `plan_discarded_stale`, `plan_lost`, `plan_abandoned`, `plan_invalidated`, `plan_revalidated`,
//! `plan_suspended`, `replan`, `resumed`, `world_changed`, `sensor_fault`, `sensor_recovered`,
//! `safe_halt_started`, `safe_halt_finished` (distance and time), `goal_reached`.

pub mod follower;
pub mod planning;
pub mod queue;
pub mod sensing;
pub mod worker;

pub use embodied_planner::trajectory::Trajectory;
pub use follower::{AsDeliberation, DeliberationSettings, DeliberativeState, PlanFollower, deliberative_agent};
pub use planning::PlanMotion;
pub use queue::{PlanQueue, QueuePolicy, QueueStats, SharedQueue};
pub use sensing::UnmappedObstacle;
pub use worker::{
    Deliberator, MotionPlanner, PlanBudget, PlanClock, PlanDelivery, PlanFailure, PlanOutcome, PlanRequest,
    PlanVerifier, Planned, misses_goal,
};
