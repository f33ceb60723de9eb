//! # embodied: the command-line toolkit
//!
//! The CLI is a thin shell over the library crates: [`embodied_models`] (what a robot is),
//! [`embodied_planner`] (deliberation), `embodied_executor` (what an agent does each control
//! step) and [`embodied_system`] (a scenario assembled and run as a system of agents). This
//! package holds only what the CLI needs beyond them: robot loading by name or URDF path for
//! the `model` report, and the MotionBenchMaker benchmark.
#![forbid(unsafe_code)]

pub mod batch_plan;
pub mod model_report;
pub mod moveit_cli;

pub use embodied_system::SystemError as AppError;
pub use embodied_system::{VERSION, generator};
pub use embodied_system::{
    batch, bench_qp, campaign, deadlines, error, faults, fuzz, load, log, mbm, mbm_generate, ompl_log, plan, plot,
    scenario, system, verify, view,
};

/// `println!` that returns [`AppError::Output`] instead of panicking when standard output is
/// closed (`embodied plan X | head`).
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout(), $($arg)*).map_err($crate::AppError::Output)?
    }};
}

/// `print!` that returns [`AppError::Output`] instead of panicking when standard output is closed.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout(), $($arg)*).map_err($crate::AppError::Output)?
    }};
}
