//! # embodied: the command-line toolkit
//!
//! The root package ties the three crates together: [`embodied_models`] (what a robot is),
//! [`embodied_planner`] (deliberation) and [`embodied_executor`] (what an agent does each
//! control step). This library holds what the CLI needs beyond them: robot loading by name or
//! URDF path, the `model` report, scenario files and reports.
#![forbid(unsafe_code)]

pub mod carry_run;
pub mod deadlines;
pub mod error;
pub mod mbm;
pub mod model_report;
pub mod plan;
pub mod plot;
pub mod run;
pub mod runlog;
pub mod scenario;
pub mod verify;
pub mod view;

pub use error::AppError;
