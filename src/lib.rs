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

/// The program's version and the git commit it was built from (`unknown` when built outside
/// a git checkout), as `--version`, log headers, plan files and reports give it.
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("EMBODIED_GIT_COMMIT"), ")");

/// `embodied VERSION`: what made a file.
pub fn generator() -> String {
    format!("embodied {VERSION}")
}
