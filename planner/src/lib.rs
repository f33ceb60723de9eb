//! `embodied-planner`: deliberation (section 4 of Zieliński's paper) for multi-robot systems.
//!
//! Search needs a search space, an initial state, operators, a data structure of generated
//! states, a goal test and a path cost with a heuristic ([`search::SearchProblem`]); the
//! search must also know when to stop, because a late plan makes the agent halt its effector
//! ([`deadline::Deadline`]). Task-level deliberation over production rules lives in [`task`].
//!
//! Every planner says how it ended with one [`outcome::Outcome`] (solved, out of time with the
//! best it has, infeasible). Motion planners ([`motion::RrtConnect`], [`motion::LazyPrm`]) take
//! any [`validity::StateValidity`] (a [`embodied_models::CollisionModel`] is one); an agent's
//! deliberation calls them through [`request::MotionPlanner`]. Plans are checked by the one
//! [`verify::Verifier`], sampled or certified.
#![forbid(unsafe_code)]

pub mod carry;
pub mod deadline;
pub mod error;
pub mod motion;
pub mod moveit;
pub mod outcome;
pub mod request;
pub mod roadmap;
pub mod search;
pub mod task;
pub mod trajectory;
pub mod validity;
pub mod verify;

pub use error::PlanError;
