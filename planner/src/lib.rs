//! `embodied-planner`: deliberation (section 4 of Zieliński's paper) for multi-robot systems.
//!
//! Search needs a search space, an initial state, operators, a data structure of generated
//! states, a goal test and a path cost with a heuristic ([`search::SearchProblem`]); the
//! search must also know when to stop, because a late plan makes the agent halt its effector
//! ([`deadline::Deadline`]). Task-level deliberation over production rules lives in [`task`].
#![forbid(unsafe_code)]

pub mod deadline;
pub mod error;
pub mod search;
pub mod task;

pub use error::PlanError;
pub mod moveit;
