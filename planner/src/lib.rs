//! `embodied-planner`: deliberation (section 4 of Zieliński's paper) for multi-robot systems.
//!
//! Search needs a search space, an initial state, operators, a data structure of generated
//! states, a goal test and a path cost with a heuristic ([`search::SearchProblem`]); the
//! search must also know when to stop, because a late plan makes the agent halt its effector
//! ([`deadline::Deadline`]). Task-level deliberation over production rules lives in [`task`].
#![forbid(unsafe_code)]

pub mod carry;
pub mod deadline;
pub mod error;
pub mod motion;
pub mod moveit;
pub mod roadmap;
pub mod search;
pub mod task;
pub mod trajectory;
pub mod verify;

pub use error::PlanError;
