//! Typed events: what happened in a control step, as the log and the summaries read it.
//!
//! A transition function notes events in its output images ([`crate::OutputImages::event`]);
//! the runtime hands them on in each [`crate::StepRecord`]. In a run log each event is a JSON
//! object tagged by `kind` (`{"kind":"plan_landed","id":3,...}`); on the terminal it prints as
//! one readable line ([`std::fmt::Display`]). Nothing reads an event back from its text.

use std::borrow::Cow;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::effector::StopMotion;

/// Why an effector is being halted.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum HaltReason {
    /// The plan needed now has not landed.
    PlanLate,
    /// No valid plan is in `c_c` (e.g. it was invalidated or discarded).
    NoValidPlan,
    /// A sensor fault: the agent cannot trust its world model.
    Fault,
    /// The force-limited reaction.
    ForceLimit,
    /// The closed-chain controller cannot go on (QP infeasible, contact, singular chain).
    ClosedChain,
    /// The agent's specification was violated (a setter misused, a transition function failed).
    Specification,
}

impl HaltReason {
    /// The reason's name as in the log.
    pub fn as_str(&self) -> &'static str {
        match self {
            HaltReason::PlanLate => "plan_late",
            HaltReason::NoValidPlan => "no_valid_plan",
            HaltReason::Fault => "fault",
            HaltReason::ForceLimit => "force_limit",
            HaltReason::ClosedChain => "closed_chain",
            HaltReason::Specification => "specification",
        }
    }
}

/// Why an agent plans again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum ReplanReason {
    /// The plan that landed was made for another world or start state.
    StalePlan,
    /// An obstacle not on the map entered the remaining path.
    ObstacleInPath,
    /// The world changed and the agent replans on any change.
    WorldChanged,
    /// Another agent's reserved space (its body or planned sweep) lies in the path.
    ReservedSpace,
}

impl ReplanReason {
    /// The reason's name as in the log.
    pub fn as_str(&self) -> &'static str {
        match self {
            ReplanReason::StalePlan => "stale_plan",
            ReplanReason::ObstacleInPath => "obstacle_in_path",
            ReplanReason::WorldChanged => "world_changed",
            ReplanReason::ReservedSpace => "reserved_space",
        }
    }
}

/// Wall-clock figures of a plan delivery: present only when planning time is counted on the
/// wall clock, so that a simulated-clock log replays byte for byte.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WallTiming {
    /// Planning time on the wall clock, µs.
    pub elapsed_us: u64,
    /// How long past its deadline a stopped search returned, µs (`None`: it was not stopped).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overshoot_us: Option<u64>,
}

/// One event of one agent in one control step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[non_exhaustive]
pub enum Event {
    /// A plan was asked of the deliberator (`id`), for world model `world`, needed within
    /// `deadline_ms`.
    PlanRequested {
        /// Request id.
        id: u64,
        /// World-model version the request was made for.
        world: u64,
        /// When the plan is needed, ms after the request.
        deadline_ms: f64,
    },
    /// A verified plan landed in `c_c` and drives the effector from now on.
    PlanLanded {
        /// Request id.
        id: u64,
        /// World-model version it was made for.
        world: u64,
        /// Whether it came within its deadline.
        in_time: bool,
        /// Work the planner spent (collision checks or expansions).
        work: u64,
        /// Planning time as the run's clock counts it, ms.
        planning_ms: f64,
        /// Motion time of the plan, s.
        duration_s: f64,
        /// Wall-clock figures (wall clock only).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        wall: Option<WallTiming>,
    },
    /// The plan needed now has not landed.
    PlanLate {
        /// Request id.
        id: u64,
    },
    /// The verifier refused a plan.
    PlanRejected {
        /// Request id.
        id: u64,
        /// The verifier's finding.
        reason: String,
    },
    /// The planner found no plan.
    PlanFailed {
        /// Request id.
        id: u64,
        /// Whether the failure came within the deadline.
        in_time: bool,
        /// The planner's reason.
        reason: String,
        /// Planning time as the run's clock counts it, ms.
        planning_ms: f64,
        /// Wall-clock figures (wall clock only).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        wall: Option<WallTiming>,
    },
    /// The planner panicked; the agent survives and may retry.
    PlannerPanicked {
        /// Request id.
        id: u64,
        /// The panic message.
        message: String,
    },
    /// A plan was made for another world or start state and is never followed.
    PlanDiscarded {
        /// Request id.
        id: u64,
        /// What no longer matches.
        reason: String,
    },
    /// An answer that never came (e.g. its transmission was lost).
    PlanLost {
        /// Request id.
        id: u64,
    },
    /// The agent gave up planning.
    PlanAbandoned {
        /// Attempts made.
        attempts: u32,
    },
    /// A higher-priority behaviour took over; the plan was dropped.
    PlanSuspended,
    /// The plan in `c_c` is no longer valid.
    PlanInvalidated {
        /// Its id, when the deliberator made it.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        id: Option<u64>,
        /// Why.
        reason: ReplanReason,
    },
    /// The world changed but the remaining plan is still free.
    PlanRevalidated {
        /// Plan id.
        id: u64,
        /// The new world-model version.
        world: u64,
    },
    /// The agent plans again.
    Replan {
        /// Why.
        reason: ReplanReason,
    },
    /// The agent asks for a new plan while it keeps moving: the new plan starts where the
    /// current path, braked from the deadline on, comes to rest, and is joined there.
    ReplanInMotion {
        /// The plan being followed.
        plan: u64,
        /// Id of the request.
        id: u64,
        /// Time from now until the braking begins (the deadline), s.
        join_after_s: f64,
        /// Largest joint speed at the deadline on the current path, rad/s or m/s.
        speed: f64,
    },
    /// A plan asked for in motion landed in time and was joined to the path being followed
    /// (no halt).
    PlanJoined {
        /// The new plan's id.
        id: u64,
        /// The plan it continues.
        plan: u64,
        /// Time until the new plan's start, s.
        join_in_s: f64,
        /// Whether the arm turns onto the new plan at speed (the braking and the new plan
        /// superposed), else the path is braked to rest where the new plan starts.
        #[serde(default)]
        moving: bool,
    },
    /// A plan landed after a halt: the agent moves again.
    Resumed {
        /// Plan id.
        id: u64,
        /// Time since the halt began, s.
        after_s: f64,
    },
    /// A controlled stop began.
    HaltStarted {
        /// Why.
        reason: HaltReason,
        /// Largest joint speed at the start, rad/s or m/s.
        speed: f64,
        /// Detail (e.g. the QP's error), when there is one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        detail: Option<String>,
    },
    /// The stop along the path being followed would collide (an obstacle entered the stopping
    /// path), checked before the stop was committed. `chosen` is the stop taken instead: the
    /// quickest the limits allow along a collision-free direction when one exists (`free`), or,
    /// when every stop within the limits would collide, the quickest stop (`free: false`).
    StopPathBlocked {
        /// The stop taken.
        chosen: StopMotion,
        /// Whether the stop taken is collision-free in the agent's world model.
        free: bool,
    },
    /// A controlled stop reached rest.
    HaltFinished {
        /// Largest joint travel from the start of the halt, rad or m.
        distance: f64,
        /// Duration, s.
        time_s: f64,
        /// Duration in control steps.
        steps: u64,
    },
    /// The agent's world model changed (an obstacle appeared, moved or vanished).
    WorldChanged {
        /// The new world-model version.
        version: u64,
    },
    /// A sensor stopped answering.
    SensorSilent {
        /// Steps since its last fresh reading.
        steps: u64,
    },
    /// A sensor gave a non-finite reading.
    SensorNonFinite,
    /// A sensor gave a finite but implausible reading (beyond the agent's plausibility bound).
    SensorImplausible {
        /// The largest magnitude read.
        value: f64,
    },
    /// A faulty sensor reads well again.
    SensorRecovered,
    /// The effector did not follow its last command: a joint's measured position is off the
    /// position the command asked for by more than the bound (a healthy effector follows a
    /// limited command exactly, to rounding).
    TrackingError {
        /// The joint furthest off.
        joint: usize,
        /// How far off, rad or m.
        error: f64,
        /// The bound, rad or m.
        bound: f64,
    },
    /// The effector follows its commands again (at rest, every joint within its bound for the
    /// agent's tolerance of steps).
    EffectorRecovered,
    /// The plan's goal was reached.
    GoalReached {
        /// Plan id, when a deliberator made the plan.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        id: Option<u64>,
    },
    /// The coordinator's grant arrived.
    GrantReceived,
    /// The coordinator granted agent `agent` its motion.
    Granted {
        /// The agent granted.
        agent: String,
    },
    /// The coordinator sent agent `agent`'s grant again: no acknowledgement came (the grant or
    /// the acknowledgement was lost or is late in transit).
    GrantResent {
        /// The agent granted.
        agent: String,
        /// How many times it was sent so far.
        times: u32,
    },
    /// Told by the coordinator that `agent` occupies `configurations` configurations.
    Told {
        /// The other agent.
        agent: String,
        /// How many configurations stand for its body or sweep.
        configurations: usize,
    },
    /// The agent finished its task (`failed`: without reaching its goal).
    TaskDone {
        /// Whether it failed.
        failed: bool,
    },
    /// The coordinator heard that `agent` failed.
    AgentFailed {
        /// The agent.
        agent: String,
    },
    /// The coordinator heard from every agent that it is done.
    AllDone,
    /// The force-limited reaction fired: contact force over the limit, plan abandoned.
    ForceLimit {
        /// The force read, N.
        force_n: f64,
    },
    /// The tool touched the surface it works on (the force along the surface normal passed the
    /// contact threshold).
    ContactMade {
        /// Force along the surface normal, N.
        force_n: f64,
    },
    /// The force regulator holds the contact force within its band around the setpoint.
    ForceRegulated {
        /// Force along the surface normal, N.
        force_n: f64,
        /// The setpoint, N.
        setpoint_n: f64,
        /// How far the regulator pushes the tool below its planned path, mm.
        depth_mm: f64,
    },
    /// One pass of a coverage path was finished in contact.
    PassFinished {
        /// The pass (0-based).
        pass: usize,
        /// How many passes the path has.
        passes: usize,
        /// Mean force along the surface normal over the pass, N.
        mean_force_n: f64,
    },
    /// Both hands hold the object: the closed chain begins.
    Grasp,
    /// The object is let go: the closed chain ends.
    Release,
    /// Where the object was put down, against its goal.
    ObjectPlaced {
        /// Distance from its goal, m.
        error_m: f64,
    },
    /// The agent broke its specification; it halts.
    SpecificationError {
        /// What went wrong.
        message: String,
    },
    /// The task-level search (production-rule A* in the coordinator's `c_c`, its operators
    /// refined lazily into certified motion) delivered a plan.
    TaskPlanFound {
        /// Operators in the plan.
        operators: usize,
        /// The plan's path cost (estimated execution time of its operators, s).
        cost: f64,
        /// A* expansions over every search (one per pruning).
        expansions: u64,
        /// Searches run (the first, and one after every failed refinement).
        searches: u32,
        /// Operator refinements tried (each a motion plan, certified).
        refinements: u32,
        /// Refinements that failed (each pruned its operator instance).
        refinements_failed: u32,
        /// Collision checks the motion planners and the concurrency checks spent.
        collision_checks: u64,
        /// Task-level planning time (search and refinement) as the run's clock counts it, ms.
        planning_ms: f64,
        /// Of which motion planning (refinements), ms.
        motion_ms: f64,
        /// Whether it came within the deadline.
        in_time: bool,
    },
    /// The task-level search ended without a plan: out of time or infeasible (the arms hold).
    TaskPlanFailed {
        /// `out_of_time` or `infeasible`, with detail.
        reason: String,
        /// A* expansions over every search.
        expansions: u64,
        /// Operators of the best partial plan, when the search ran out of time.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        best_partial: Option<usize>,
        /// Planning time as the run's clock counts it, ms.
        planning_ms: f64,
    },
    /// An operator of the task plan was refined into a certified motion.
    OperatorRefined {
        /// Index in the task plan.
        index: usize,
        /// The ground operator (`pick(arm=irp6p, part=p1, stand=b, level=0)`).
        operator: String,
        /// The agent that runs it.
        agent: String,
        /// Motion time of its trajectory, s.
        duration_s: f64,
        /// Collision checks its motion planning took.
        work: u64,
        /// Operators of the plan it must wait for (other than the agent's own previous one).
        after: Vec<usize>,
    },
    /// An operator could not be refined into motion: that operator instance is pruned and the
    /// search goes on.
    RefinementFailed {
        /// The ground operator.
        operator: String,
        /// The agent that would have run it.
        agent: String,
        /// Why (the motion planner's or the verifier's words).
        reason: String,
    },
    /// An agent began an operator's `Move`.
    OperatorStarted {
        /// Index in the task plan.
        index: usize,
        /// The ground operator.
        operator: String,
    },
    /// An operator's `Move` met its terminal condition.
    OperatorFinished {
        /// Index in the task plan.
        index: usize,
        /// The ground operator.
        operator: String,
        /// Largest joint distance from the operator's final configuration at the end, rad or m.
        error: f64,
    },
    /// A user's own event (free text, never parsed).
    Note {
        /// The text.
        text: Cow<'static, str>,
    },
}

impl Event {
    /// The event's kind as in the log (`plan_landed`, `halt_started`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            Event::PlanRequested { .. } => "plan_requested",
            Event::PlanLanded { .. } => "plan_landed",
            Event::PlanLate { .. } => "plan_late",
            Event::PlanRejected { .. } => "plan_rejected",
            Event::PlanFailed { .. } => "plan_failed",
            Event::PlannerPanicked { .. } => "planner_panicked",
            Event::PlanDiscarded { .. } => "plan_discarded",
            Event::PlanLost { .. } => "plan_lost",
            Event::PlanAbandoned { .. } => "plan_abandoned",
            Event::PlanSuspended => "plan_suspended",
            Event::PlanInvalidated { .. } => "plan_invalidated",
            Event::PlanRevalidated { .. } => "plan_revalidated",
            Event::Replan { .. } => "replan",
            Event::Resumed { .. } => "resumed",
            Event::ReplanInMotion { .. } => "replan_in_motion",
            Event::PlanJoined { .. } => "plan_joined",
            Event::HaltStarted { .. } => "halt_started",
            Event::StopPathBlocked { .. } => "stop_path_blocked",
            Event::HaltFinished { .. } => "halt_finished",
            Event::WorldChanged { .. } => "world_changed",
            Event::SensorSilent { .. } => "sensor_silent",
            Event::SensorNonFinite => "sensor_non_finite",
            Event::SensorImplausible { .. } => "sensor_implausible",
            Event::SensorRecovered => "sensor_recovered",
            Event::TrackingError { .. } => "tracking_error",
            Event::EffectorRecovered => "effector_recovered",
            Event::GoalReached { .. } => "goal_reached",
            Event::GrantReceived => "grant_received",
            Event::Granted { .. } => "granted",
            Event::GrantResent { .. } => "grant_resent",
            Event::Told { .. } => "told",
            Event::TaskDone { .. } => "task_done",
            Event::AgentFailed { .. } => "agent_failed",
            Event::AllDone => "all_done",
            Event::ForceLimit { .. } => "force_limit",
            Event::ContactMade { .. } => "contact_made",
            Event::ForceRegulated { .. } => "force_regulated",
            Event::PassFinished { .. } => "pass_finished",
            Event::Grasp => "grasp",
            Event::Release => "release",
            Event::ObjectPlaced { .. } => "object_placed",
            Event::SpecificationError { .. } => "specification_error",
            Event::TaskPlanFound { .. } => "task_plan_found",
            Event::TaskPlanFailed { .. } => "task_plan_failed",
            Event::OperatorRefined { .. } => "operator_refined",
            Event::RefinementFailed { .. } => "refinement_failed",
            Event::OperatorStarted { .. } => "operator_started",
            Event::OperatorFinished { .. } => "operator_finished",
            Event::Note { .. } => "note",
        }
    }

    /// A user's note.
    pub fn note(text: impl Into<Cow<'static, str>>) -> Self {
        Event::Note { text: text.into() }
    }
}

impl From<&'static str> for Event {
    fn from(text: &'static str) -> Self {
        Event::note(text)
    }
}

impl From<String> for Event {
    fn from(text: String) -> Self {
        Event::note(text)
    }
}

fn in_time(yes: bool) -> &'static str {
    if yes { "in_time" } else { "late" }
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = self.kind();
        let wall = |f: &mut fmt::Formatter<'_>, w: &Option<WallTiming>| -> fmt::Result {
            if let Some(w) = w {
                write!(f, " elapsed_us={}", w.elapsed_us)?;
                if let Some(o) = w.overshoot_us {
                    write!(f, " overshoot_us={o}")?;
                }
            }
            Ok(())
        };
        match self {
            Event::PlanRequested { id, world, deadline_ms } => {
                write!(f, "{kind} id={id} world={world} deadline_ms={deadline_ms:.3}")
            }
            Event::PlanLanded { id, world, in_time: t, work, planning_ms, duration_s, wall: w } => {
                write!(f, "{kind} id={id} world={world} {} work={work} planning_ms={planning_ms:.3}", in_time(*t))?;
                wall(f, w)?;
                write!(f, " duration_s={duration_s:.3}")
            }
            Event::PlanLate { id } | Event::PlanLost { id } => write!(f, "{kind} id={id}"),
            Event::PlanRejected { id, reason } | Event::PlanDiscarded { id, reason } => {
                write!(f, "{kind} id={id}: {reason}")
            }
            Event::PlanFailed { id, in_time: t, reason, planning_ms, wall: w } => {
                write!(f, "{kind} id={id} {}: {reason} planning_ms={planning_ms:.3}", in_time(*t))?;
                wall(f, w)
            }
            Event::PlannerPanicked { id, message } => write!(f, "{kind} id={id}: {message}"),
            Event::PlanAbandoned { attempts } => write!(f, "{kind} after {attempts} attempts"),
            Event::PlanInvalidated { id, reason } => {
                write!(f, "{kind}")?;
                if let Some(id) = id {
                    write!(f, " id={id}")?;
                }
                write!(f, ": {}", reason.as_str())
            }
            Event::PlanRevalidated { id, world } => write!(f, "{kind} id={id} world={world}"),
            Event::Replan { reason } => write!(f, "{kind} reason={}", reason.as_str()),
            Event::Resumed { id, after_s } => write!(f, "{kind} id={id} after_s={after_s:.3}"),
            Event::ReplanInMotion { plan, id, join_after_s, speed } => {
                write!(f, "{kind} plan={plan} id={id} join_after_s={join_after_s:.3} speed={speed:.6}")
            }
            Event::PlanJoined { id, plan, join_in_s, moving } => {
                let how = if *moving { "at speed" } else { "at rest" };
                write!(f, "{kind} id={id} plan={plan} join_in_s={join_in_s:.3} {how}")
            }
            Event::HaltStarted { reason, speed, detail } => {
                write!(f, "{kind} reason={} speed={speed:.6}", reason.as_str())?;
                if let Some(d) = detail {
                    write!(f, ": {d}")?;
                }
                Ok(())
            }
            Event::StopPathBlocked { chosen, free } => {
                write!(f, "{kind}: stopping {} ({})", chosen.as_str(), if *free { "free" } else { "no free stop" })
            }
            Event::HaltFinished { distance, time_s, steps } => {
                write!(f, "{kind} distance={distance:.6} time_s={time_s:.3} steps={steps}")
            }
            Event::WorldChanged { version } => write!(f, "{kind} version={version}"),
            Event::SensorSilent { steps } => write!(f, "{kind}: no reading for {steps} steps"),
            Event::SensorImplausible { value } => write!(f, "{kind}: read {value:e}"),
            Event::GoalReached { id } => match id {
                Some(id) => write!(f, "{kind} id={id}"),
                None => write!(f, "{kind}"),
            },
            Event::Granted { agent } => write!(f, "{kind} -> {agent}"),
            Event::GrantResent { agent, times } => write!(f, "{kind} -> {agent} (sent {times} times)"),
            Event::TrackingError { joint, error, bound } => {
                write!(f, "{kind}: joint {joint} off its command by {error:.3e} (bound {bound:.3e})")
            }
            Event::Told { agent, configurations } => {
                write!(f, "{kind}: `{agent}` occupies {configurations} configuration(s)")
            }
            Event::TaskDone { failed } => write!(f, "{kind}{}", if *failed { ": failed, no plan" } else { "" }),
            Event::AgentFailed { agent } => write!(f, "{kind}: {agent}"),
            Event::ForceLimit { force_n } => write!(f, "{kind}: {force_n:.1} N, plan abandoned"),
            Event::ObjectPlaced { error_m } => write!(f, "{kind}: {error_m:.4} m from its goal"),
            Event::ContactMade { force_n } => write!(f, "{kind}: {force_n:.1} N"),
            Event::ForceRegulated { force_n, setpoint_n, depth_mm } => {
                write!(f, "{kind}: {force_n:.1} N (setpoint {setpoint_n:.1} N), {depth_mm:.2} mm below the path")
            }
            Event::PassFinished { pass, passes, mean_force_n } => {
                write!(f, "{kind}: pass {} of {passes}, mean {mean_force_n:.1} N", pass + 1)
            }
            Event::SpecificationError { message } => write!(f, "{kind}; safe halt: {message}"),
            Event::TaskPlanFound {
                operators,
                cost,
                expansions,
                searches,
                refinements,
                refinements_failed,
                collision_checks,
                planning_ms,
                motion_ms,
                in_time: t,
            } => write!(
                f,
                "{kind} {} operators={operators} cost={cost:.3} expansions={expansions} searches={searches} refinements={refinements} failed={refinements_failed} checks={collision_checks} planning_ms={planning_ms:.3} motion_ms={motion_ms:.3}",
                in_time(*t)
            ),
            Event::TaskPlanFailed { reason, expansions, best_partial, planning_ms } => {
                write!(f, "{kind}: {reason} expansions={expansions} planning_ms={planning_ms:.3}")?;
                if let Some(n) = best_partial {
                    write!(f, " best_partial={n}")?;
                }
                Ok(())
            }
            Event::OperatorRefined { index, operator, agent, duration_s, work, after } => {
                write!(
                    f,
                    "{kind} #{index} {operator} by {agent}: duration_s={duration_s:.3} work={work} after={after:?}"
                )
            }
            Event::RefinementFailed { operator, agent, reason } => {
                write!(f, "{kind} {operator} by {agent}: {reason}")
            }
            Event::OperatorStarted { index, operator } => write!(f, "{kind} #{index} {operator}"),
            Event::OperatorFinished { index, operator, error } => {
                write!(f, "{kind} #{index} {operator} error={error:.6}")
            }
            Event::Note { text } => f.write_str(text),
            Event::PlanSuspended
            | Event::SensorNonFinite
            | Event::SensorRecovered
            | Event::EffectorRecovered
            | Event::GrantReceived
            | Event::AllDone
            | Event::Grasp
            | Event::Release => f.write_str(kind),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serialises_tagged_and_reads_back() {
        let e = Event::PlanLanded {
            id: 3,
            world: 2,
            in_time: true,
            work: 10,
            planning_ms: 1.5,
            duration_s: 2.0,
            wall: None,
        };
        let text = serde_json::to_string(&e).expect("serialisable");
        assert!(text.starts_with("{\"kind\":\"plan_landed\",\"id\":3"), "{text}");
        assert!(!text.contains("wall"), "{text}");
        let back: Event = serde_json::from_str(&text).expect("reads back");
        assert_eq!(back, e);
        assert_eq!(e.to_string(), "plan_landed id=3 world=2 in_time work=10 planning_ms=1.500 duration_s=2.000");
        let note: Event = "contact".into();
        assert_eq!(serde_json::to_string(&note).expect("serialisable"), "{\"kind\":\"note\",\"text\":\"contact\"}");
    }

    #[test]
    fn every_kind_matches_its_serialised_tag() {
        let all = [
            Event::PlanSuspended,
            Event::Replan { reason: ReplanReason::ReservedSpace },
            Event::HaltStarted { reason: HaltReason::PlanLate, speed: 0.0, detail: None },
            Event::TaskDone { failed: true },
            Event::ObjectPlaced { error_m: 0.1 },
            Event::GoalReached { id: None },
            Event::SensorNonFinite,
            Event::OperatorStarted { index: 0, operator: "pick(arm=a)".into() },
            Event::OperatorFinished { index: 0, operator: "pick(arm=a)".into(), error: 0.0 },
            Event::RefinementFailed { operator: "o".into(), agent: "a".into(), reason: "r".into() },
            Event::TaskPlanFailed { reason: "infeasible".into(), expansions: 3, best_partial: None, planning_ms: 0.0 },
            Event::StopPathBlocked { chosen: StopMotion::JointBrake, free: true },
            Event::SensorImplausible { value: 1e9 },
            Event::ContactMade { force_n: 2.0 },
            Event::ForceRegulated { force_n: 20.0, setpoint_n: 20.0, depth_mm: 1.0 },
            Event::PassFinished { pass: 0, passes: 5, mean_force_n: 20.0 },
            Event::TrackingError { joint: 1, error: 1e-3, bound: 1e-6 },
            Event::EffectorRecovered,
            Event::GrantResent { agent: "a".into(), times: 2 },
        ];
        for e in all {
            let v: serde_json::Value = serde_json::to_value(&e).expect("serialisable");
            assert_eq!(v["kind"], e.kind(), "{e:?}");
        }
    }
}
