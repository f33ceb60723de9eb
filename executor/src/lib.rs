//! # embodied-executor: what an agent does each control step
//!
//! The transition-function formalism of C. Zieliński, *Systematic approach to the design of
//! robot programming frameworks*, as a multi-agent runtime. Each symbol of the paper is one type:
//!
//! | paper | here |
//! |---|---|
//! | agent `a_j`, state `s_j = <c_j, e_j, V_j, T_j>` (eq. 1) | [`Agent`] |
//! | control subsystem `c_j`, eq. (7) | [`ControlSubsystem`]`<C>`; `c_c` = the user type `C` |
//! | input images `c^i_e, c^i_V, c^i_T` | [`InputImages`] (read-only) |
//! | output images `c^{i+1}_e, c^{i+1}_V, c^{i+1}_T` | [`OutputImages`] (setters only) |
//! | `c^{i+1}_e`: effector command | [`JointCommand`] |
//! | effector `e_j` | [`Effector`], simulated by [`ServoModel`], guarded by [`SafetyLimiter`] |
//! | virtual sensor `v = f_v(c, R)` (eq. 3) | [`VirtualSensor`], configured by [`SensorConfig`] |
//! | receptor bundle `R` (eq. 4) | [`ReceptorReadings`] (simulated: [`ReceptorSpec`], [`World`]) |
//! | transmission `T_j` | [`Transmitter`] with [`Link`] latency and loss, [`Message`] |
//! | partial transition function `^m f_{c_j}` (eq. 8) | [`TransitionFunction`] |
//! | predicate `^q p_{c_j}` (eq. 9) | [`Predicate`] |
//! | primitive behaviour (eq. 11) | [`Primitive`] |
//! | multi-step / nested behaviours, main reaction (eq. 12-13) | [`Reactive`], [`Sequence`] |
//! | exactly one predicate (eq. 10), suppression, composition (eq. 14) | [`Selection`] |
//! | competitive/cooperative composition (eq. 15-16) | [`Composer`] |
//! | `Move(f', f'', f_τ)`, `Wait(f_ι)` (fig. 3, eq. 17-18) | [`Move`], [`Wait`] |
//! | coordinator (section 5) | [`Coordinator`] |
//! | halting the effector when no plan is ready (section 4) | [`SafeHalt`] |
//! | the loop of eq. (10)/(14) for all agents | [`Runtime`], logging [`StepRecord`] |
//!
//! Two-arm closed-chain motion (a QP each step) is in [`closed_chain`].
//!
//! ## Example: an agent that drives joint 0 to a goal and backs off on contact
//!
//! ```
//! use std::sync::Arc;
//! use embodied_executor::*;
//!
//! /// c_c: the agent's internal variables.
//! struct Goal { q0: f64 }
//!
//! let robot = Arc::new(embodied_models::builtin("rnt").expect("built-in robot"));
//! let dof = robot.dof();
//!
//! // Main reaction: track the goal on joint 0, hold the others.
//! let pursue = Primitive::new("pursue", 1, move |cc: &mut Goal, i: &InputImages, o: &mut OutputImages| {
//!     let mut q = i.q().to_vec();
//!     q[0] = cc.q0;
//!     o.set_position_target(&q, &vec![0.0; q.len()]);
//! });
//! // Reflex: on contact (virtual sensor 0 = Contact, reading[1] = 1) stop and say so.
//! let recoil = Primitive::new("recoil", 1, |_: &mut Goal, _: &InputImages, o: &mut OutputImages| {
//!     o.event("contact");
//! });
//! let program = Reactive::priority("main")
//!     .rule(Predicate::new("touching", |_: &Goal, i: &InputImages| i.sensor(0).values[1] > 0.5), recoil)
//!     .main_reaction(pursue);
//!
//! let agent = Agent::embodied("arm", robot.clone(), None, Goal { q0: 0.3 }, program)?
//!     .with_sensor(Contact, SensorConfig { threshold: 5.0, ..SensorConfig::default() })
//!     .with_receptors(ReceptorSpec { force_stiffness: Some(1e4), ..ReceptorSpec::default() });
//!
//! let mut runtime = Runtime::new(RuntimeConfig { seed: 7, ..RuntimeConfig::default() });
//! runtime.add_agent(agent);
//! let mut last = None;
//! runtime.run(2000, |record| last = Some(record.clone()))?;
//! let last = last.expect("records");
//! assert_eq!(last.agents[0].behaviour, "main/pursue");
//! assert!((last.agents[0].q[0] - 0.3).abs() < 1e-3);
//! // Every record serialises as one JSON line.
//! let line = serde_json::to_string(&last).expect("serialisable");
//! assert!(line.starts_with("{\"step\":1999"));
//! # let _ = dof;
//! # Ok::<(), ExecutorError>(())
//! ```

#![forbid(unsafe_code)]

pub mod agent;
pub mod behaviour;
pub mod closed_chain;
pub mod composer;
pub mod deliberation;
pub mod effector;
pub mod error;
pub mod event;
pub mod image;
pub mod motion;
pub mod runtime;
pub mod sensor;
pub mod transition;
pub mod transmitter;
pub mod world;

pub use agent::AgentRecord;
pub use agent::{Agent, ControlSubsystem, Coordinator};
pub use behaviour::{Behaviour, Primitive, Reactive, Selection, Sequence, Status, boxed};
pub use composer::Composer;
pub use deliberation::{
    DeliberationSettings, DeliberativeState, Deliberator, PlanClock, PlanFollower, PlanRequest, deliberative_agent,
};
pub use effector::{
    BrakeHalt, Effector, FollowedPath, PathHalt, SafeHalt, SafetyLimiter, ServoModel, StopMotion, predict_stop,
    tracking_bound, tracking_velocity, velocity_window,
};
pub use error::{ExecutorError, Violation};
pub use event::{Event, HaltReason, ReplanReason, WallTiming};
pub use image::{
    AgentId, CommandMode, Envelope, InputImages, JointCommand, Message, OutputImages, Reading, Region, SensorConfig,
    SensorImage, WORDS,
};
pub use motion::{Move, Wait};
pub use runtime::{Clearance, Parallelism, Runtime, RuntimeConfig, StepMonitor, StepRecord};
pub use sensor::{Contact, JointState, NearestObstacle, VirtualSensor};
pub use transition::{Predicate, TransitionFunction, idle};
pub use transmitter::{ChannelStats, Link, LinkFaults, Transit, Transmitter};
pub use world::{Body, Obstacle, ObstacleEcho, ReceptorReadings, ReceptorSpec, Solid, World, receptor_noise};
