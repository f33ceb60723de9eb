//! # embodied: the command-line toolkit
//!
//! The CLI is a thin shell over the library crates: [`embodied_models`] (what a robot is),
//! [`embodied_planner`] (deliberation), [`embodied_executor`] (what an agent does each control
//! step) and [`embodied_system`] (a scenario assembled and run as a system of agents). This
//! package holds only what the CLI needs beyond them: robot loading by name or URDF path for
//! the `model` report, and the MotionBenchMaker benchmark.
#![forbid(unsafe_code)]

pub mod model_report;

pub use embodied_system::SystemError as AppError;
pub use embodied_system::{bench_qp, campaign, deadlines, faults, log, mbm, plan, scenario, system, verify};
