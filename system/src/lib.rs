//! # embodied-system: a robot system as a library
//!
//! A *system* in the sense of Zieliński's paper is a set of embodied agents placed in a world,
//! with a coordinator and the transmissions between them. This crate assembles one from a
//! [`Scenario`] — a typed value made in code with [`Scenario::builder`] or read from TOML with
//! [`Scenario::from_toml`] — and runs it ([`System`]), plans it offline ([`plan::plan_scenario`]),
//! writes and reads its run log ([`log`]) and checks plans and logs ([`verify`]).
//!
//! | layer | crate |
//! |---|---|
//! | what a robot is | `embodied-models` |
//! | deliberation as search, the verifier | `embodied-planner` |
//! | what an agent does each control step | `embodied-executor` |
//! | the system: scenario, agents, coordinator, protocol, runs, logs | this crate |
//!
//! ## Example: two arms and a coordinator, built in code
//!
//! ```
//! use embodied_system::{Scenario, AgentSpec, GoalSpec, RunOptions, System};
//!
//! let robot = embodied_models::builtin("polycrank")?;
//! let mut goal = robot.home().to_vec();
//! goal[0] += 0.5;
//! let scenario = Scenario::builder("two-polycranks")
//!     .agent(AgentSpec::new("left", robot.clone()).at([0.0, -1.0, 0.0]).goal(GoalSpec::Configuration(goal.clone())))
//!     .agent(AgentSpec::new("right", robot).at([0.0, 1.0, 0.0]).goal(GoalSpec::Configuration(goal)))
//!     .simulated_clock(2.0)
//!     .build()?;
//! let mut system = System::new(&scenario, &RunOptions::default())?;
//! system.run_for(3.0, |_| {})?;
//! let summary = system.summary();
//! assert!(summary.agents.iter().all(|a| a.goal_reached), "{summary:?}");
//! # Ok::<(), embodied_system::SystemError>(())
//! ```
#![forbid(unsafe_code)]

pub mod batch;
pub mod bench_qp;
pub mod campaign;
pub mod clearance;
pub mod deadlines;
pub mod error;
pub mod faults;
pub mod fuzz;
pub mod load;
pub mod log;
pub mod mbm;
pub mod mbm_generate;
pub mod ompl_log;
pub mod plan;
pub mod plot;
pub mod polish;
pub mod scenario;
pub mod system;
pub mod task;
pub mod verify;
pub mod view;

pub use error::SystemError;
pub use faults::{FaultKind, FaultSpec, FaultTrigger};
pub use scenario::{
    AgentSpec, CarrySpec, ClockSpec, Coordination, GoalSpec, ObstacleSpec, PlannerSpec, RunSpec, Scenario,
    ScenarioBuilder, StandSpec, TaskSpec,
};
pub use system::{AgentSummary, RunOptions, RunSummary, System};

/// The program's version and the git commit it was built from (`unknown` when built outside
/// a git checkout), as `--version`, log headers, plan files and reports give it.
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("EMBODIED_GIT_COMMIT"), ")");

/// `embodied VERSION`: what made a file.
pub fn generator() -> String {
    format!("embodied {VERSION}")
}
