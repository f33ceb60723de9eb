//! What planning produces: one [`Outcome`] for every planner of the crate (A* search under a
//! deadline, RRT-Connect, lazy PRM), and the motion planners' [`MotionPlan`] and
//! [`MotionStats`].

use std::time::Duration;

use embodied_models::ConfigSpace;

use crate::deadline::Interrupt;

/// What a planner produced. It always says what it is: a partial result is never "solved".
///
/// `T` is the plan, `B` the best partial result a planner can offer when stopped (A*: the path
/// to the expanded state that looked closest to a goal; motion planners: the work done so
/// far, no path).
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome<T, B = T> {
    /// A plan that reaches a goal.
    Solved(T),
    /// Deliberation was stopped before deciding; the agent must not assume a plan exists.
    OutOfTime {
        /// The best partial result, if any.
        best: Option<B>,
        /// Which limit stopped the planner.
        cause: Interrupt,
    },
    /// The planner decided there is no plan: the reachable space is exhausted (A*), or the
    /// sample budget is used up without connecting start and goal (sampling planners: no
    /// plan found, which for them is as far as infeasibility can be told).
    Infeasible,
}

impl<T, B> Outcome<T, B> {
    /// The plan, only if solved.
    pub fn solved(&self) -> Option<&T> {
        match self {
            Outcome::Solved(plan) => Some(plan),
            _ => None,
        }
    }

    /// The plan, only if solved, by value.
    pub fn into_solved(self) -> Option<T> {
        match self {
            Outcome::Solved(plan) => Some(plan),
            _ => None,
        }
    }

    /// True for [`Outcome::OutOfTime`].
    pub fn is_out_of_time(&self) -> bool {
        matches!(self, Outcome::OutOfTime { .. })
    }

    /// The same outcome with the plan mapped.
    pub fn map<U>(self, f: impl FnOnce(T) -> U) -> Outcome<U, B> {
        match self {
            Outcome::Solved(t) => Outcome::Solved(f(t)),
            Outcome::OutOfTime { best, cause } => Outcome::OutOfTime { best, cause },
            Outcome::Infeasible => Outcome::Infeasible,
        }
    }
}

/// A collision-free path and how it was found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MotionPlan {
    /// Waypoints from the start to a goal. Continuous joints are unwrapped: consecutive
    /// waypoints differ by the short way, so the last waypoint may differ from the goal by whole
    /// turns on a continuous joint (3.283 for a goal of -3.0 reached from 3.0).
    pub path: Vec<Vec<f64>>,
    /// What planning cost.
    pub stats: MotionStats,
}

/// What planning cost.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MotionStats {
    /// Wall-clock time of planning.
    pub elapsed: Duration,
    /// Random samples drawn (PRM) or tree extension targets (RRT).
    pub samples: usize,
    /// Straight segments collision-checked.
    pub edges_checked: usize,
    /// Calls of the collision check.
    pub collision_checks: u64,
    /// A* expansions (lazy PRM).
    pub astar_expansions: usize,
    /// A* searches run (lazy PRM re-searches after each invalid edge).
    pub searches: usize,
    /// Which planner produced the path: "direct", "rrt-connect", "lazy-prm" (plus "+shortcut").
    pub planner: &'static str,
    /// C-space length of the returned path.
    pub path_length: f64,
    /// Collision checks of lazy RRT-Connect's probes of tree edges (part of `collision_checks`).
    pub probe_checks: u64,
    /// Lazy RRT-Connect: tree edges cut off because their certificate failed on a found path.
    pub cut_edges: usize,
    /// RRT-Connect: attempts started again with new trees after one drew its `max_samples`
    /// samples without a path (see `MotionSettings::rrt_restarts`).
    pub restarts: usize,
    /// Legs of a plan by groups of joints searched on a racer thread beside the caller's (see
    /// `MotionSettings::parallel_legs`).
    pub legs_on_racer: usize,
    /// Legs of such a plan whose path came from the caller's thread racing a leg the racer
    /// thread was still searching (from another random stream).
    pub legs_raced: usize,
}

/// Rewrite continuous joints so that each waypoint differs from the previous by the short way.
pub(crate) fn unwrap_path(space: &ConfigSpace, path: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::with_capacity(path.len());
    for q in path {
        let next = match out.last() {
            Some(prev) => space.unwrap_towards(prev, &q),
            None => q,
        };
        out.push(next);
    }
    out
}

/// C-space length of a path.
pub fn path_length(space: &ConfigSpace, path: &[Vec<f64>]) -> f64 {
    path.windows(2).map(|w| space.distance(&w[0], &w[1])).sum()
}
