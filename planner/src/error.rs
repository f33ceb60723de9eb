//! The one error type of `embodied-planner`.

/// Everything that can go wrong when building or refining a plan.
///
/// An *outcome* of a search (solved, out of time, infeasible) is not an error: see
/// [`crate::search::SearchOutcome`]. Errors are malformed inputs and failed hooks.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A path cost that is NaN: it has no place in the total order A* needs.
    #[error("path cost {context} is NaN")]
    NanCost { context: String },
    /// A negative path cost: A* (and Dijkstra) are only optimal for non-negative operator costs.
    #[error("path cost {context} is negative ({value})")]
    NegativeCost { context: String, value: f64 },
    /// A task problem that refers to something it does not define.
    #[error("invalid task problem: {message}")]
    InvalidTask { message: String },
    /// A plan operator that does not belong to the problem it is used with.
    #[error("operator #{index} is not an operator of this problem ({count} operators)")]
    UnknownOperator { index: usize, count: usize },
    /// The refinement hook (e.g. a motion planner) could not refine one action of a task plan.
    #[error("cannot refine step {step} `{action}` of the task plan: {source}")]
    RefinementFailed {
        step: usize,
        action: String,
        #[source]
        source: Box<PlanError>,
    },
    /// A refiner's own failure, described in words.
    #[error("refinement failed: {reason}")]
    Refiner { reason: String },
}
