//! The one error type of `embodied-planner`.

/// Everything that can go wrong when building or refining a plan.
///
/// An *outcome* of a search (solved, out of time, infeasible) is not an error: see
/// [`crate::outcome::Outcome`]. Errors are malformed inputs and failed hooks.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A path cost that is NaN: it has no place in the total order A* needs.
    #[error("path cost {context} is NaN")]
    NanCost {
        /// Which cost (where it was computed).
        context: String,
    },
    /// A negative path cost: A* (and Dijkstra) are only optimal for non-negative operator costs.
    #[error("path cost {context} is negative ({value})")]
    NegativeCost {
        /// Which cost (where it was computed).
        context: String,
        /// The negative cost.
        value: f64,
    },
    /// A task problem that refers to something it does not define.
    #[error("invalid task problem: {message}")]
    InvalidTask {
        /// What the problem refers to that it does not define.
        message: String,
    },
    /// A plan operator that does not belong to the problem it is used with.
    #[error("operator #{index} is not an operator of this problem ({count} operators)")]
    UnknownOperator {
        /// The operator's index.
        index: usize,
        /// How many operators the problem has.
        count: usize,
    },
    /// The refinement hook (e.g. a motion planner) could not refine one action of a task plan.
    #[error("cannot refine step {step} `{action}` of the task plan: {source}")]
    RefinementFailed {
        /// Index of the step in the task plan (0-based).
        step: usize,
        /// The step's action, as written in the plan.
        action: String,
        #[source]
        /// Why refining it failed.
        source: Box<PlanError>,
    },
    /// A refiner's own failure, described in words.
    #[error("refinement failed: {reason}")]
    Refiner {
        /// What went wrong.
        reason: String,
    },
    /// Motion planning: the start configuration is in collision.
    #[error("the start configuration is in collision: {contact}")]
    StartInCollision {
        /// The pair in contact, as words.
        contact: String,
    },
    /// Motion planning: goal configuration `index` (of the goal set, or of the IK solutions of a
    /// tool pose) is in collision.
    #[error("goal {index} is in collision: {contact}")]
    GoalInCollision {
        /// Index of the goal configuration.
        index: usize,
        /// The pair in contact, as words.
        contact: String,
    },
    /// Motion planning: no goal configuration exists (outside the joint limits, IK failed).
    #[error("the goal is unreachable: {reason}")]
    GoalUnreachable {
        /// Why no goal configuration exists.
        reason: String,
    },
    /// Motion planning: the deadline passed before a path was found.
    #[error(
        "motion planning ran out of time after {:.3} ms ({} samples, {} collision checks)",
        stats.elapsed.as_secs_f64() * 1e3, stats.samples, stats.collision_checks
    )]
    OutOfTime {
        /// What the search did before the deadline.
        stats: crate::outcome::MotionStats,
    },
    /// Motion planning: the sample budget was used up without connecting start and goal.
    #[error("no collision-free path found with {samples} samples")]
    NoPath {
        /// Samples drawn.
        samples: usize,
    },
    /// A roadmap query on a roadmap without vertices.
    #[error("the roadmap is empty: build or grow it before querying")]
    EmptyRoadmap,
    /// Malformed motion-planning input: wrong number of joints, NaN, start outside the limits.
    #[error("invalid motion planning input: {message}")]
    InvalidInput {
        /// What is wrong.
        message: String,
    },
}
