//! A scenario as a [`System`] of embodied agents in the simulated world.
//!
//! Every scenario agent with a goal is a deliberative agent: its transition functions ask for a
//! motion plan through the [`embodied_executor::deliberation::Deliberator`] in its `c_c`; the
//! search ([`embodied_planner::motion::plan_motion`] under a deadline) runs off the control
//! thread; while no verified plan is there the agent halts safely; it resumes when one lands,
//! discards stale ones, and replans when its obstacle sensor reports something entering its
//! path. Its program is a priority list (subsumption): a force-limited reaction, waiting for the
//! coordinator's go, and the plan follower as the main reaction.
//!
//! With several agents a coordinator (an agent with no effector) grants the motions, either one
//! after the other (each agent plans around where the others stand) or all at once (each agent
//! plans around the space the agents granted before it will sweep: their plans, transmitted to
//! the coordinator and handed on). Plans travel between agents as messages over the
//! transmissions `T`.
//!
//! Planning time is counted on the wall clock (real runs; the run is paced to real time while
//! a plan is being computed) or simulated from the planner's collision checks, which makes the
//! log byte-identical for a seed.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use embodied_executor::closed_chain::ClosedChainConfig;
use embodied_executor::closed_chain::carry::{
    CarryRecord, CarrySetup, ClosedChainSummary, carry_agent, carry_agent_with_fault, finish,
};
use embodied_executor::deliberation::{
    AsDeliberation, DeliberationSettings, DeliberativeState, PlanBudget, PlanClock, PlanFollower, PlanMotion,
    UnmappedObstacle,
};
use embodied_executor::{
    Agent, AgentId, Behaviour, Contact, Coordinator, Event, HaltReason, InputImages, Link, Message, OutputImages,
    Predicate, Primitive, Reactive, ReceptorSpec, ReplanReason, Runtime, RuntimeConfig, SafeHalt, SensorConfig,
    ServoModel, Status, StepRecord, TransitionFunction, Violation, World,
};
use embodied_models::{Robot, Shape};
use embodied_planner::carry::plan_carry;
use embodied_planner::deadline::Deadline;
use serde::Serialize;

use crate::SystemError;
use crate::faults::{
    FaultKind, FaultSpec, FaultyEffector, FaultyPlanner, FaultySensor, Injection, Injections, LinkFaultState,
    SharedLinkFaults, Windows, draw, place_obstacle, qp_fault,
};
use crate::log::{LOG_FORMAT, LogHeader, LogStep, LoggedAgent, RunLog};
use crate::plan::{agent_problem, bodies_as_obstacles, goal_of, motion_settings};
use crate::scenario::{ClockSpec, Coordination, GoalSpec, Scenario, load_scenario};

/// Largest joint step between the configurations that stand for another agent's swept volume.
pub const SWEEP_STEP: f64 = 0.02;

/// The scenario's agents as other agents see them.
struct Roster {
    names: Vec<String>,
    robots: Vec<Robot>,
}

/// `c_c` of a scenario agent: deliberation plus what the coordinator told it.
struct RunAgent {
    delib: DeliberativeState,
    index: usize,
    go: bool,
    coordinator: Option<AgentId>,
    roster: Arc<Roster>,
    /// Per scenario agent: the configurations it occupies, as far as this agent knows.
    occupancy: Vec<Arc<[Vec<f64>]>>,
    announced: Option<u64>,
    done_sent: bool,
    force_sensor: Option<usize>,
    /// Per scenario agent: whether the coordinator told this agent where it is.
    told: Vec<bool>,
    /// The last announcement sent to the coordinator (repeated until the run ends: a lost one
    /// must not stall the others), and the step it was last sent.
    last_announcement: Option<Arc<[Vec<f64>]>>,
    repeated_at: u64,
}

/// Steps after which the coordinator sends an unacknowledged grant again, and an agent repeats
/// its last announcement and its `done`.
pub const RESEND_STEPS: u64 = 100;

impl AsDeliberation for RunAgent {
    fn deliberation(&mut self) -> &mut DeliberativeState {
        &mut self.delib
    }
}

impl RunAgent {
    fn known_obstacles(&self) -> Vec<embodied_models::Obstacle> {
        let mut out = Vec::new();
        for (m, path) in self.occupancy.iter().enumerate() {
            if m != self.index {
                out.extend(bodies_as_obstacles(&self.roster.robots[m], path, SWEEP_STEP, &self.roster.names[m]));
            }
        }
        out
    }

    /// Read the transmissions: the grant, and other agents' bodies or planned sweeps. A grant
    /// counts once the occupancies it depends on have arrived (a lost one is sent again with the
    /// grant); it is acknowledged every time it counts. An occupancy heard before is no news.
    fn read_messages(&mut self, i: &InputImages, o: &mut OutputImages) {
        for env in i.messages() {
            match &env.message {
                Message::Grant { told } => {
                    let known = self.told.iter().enumerate().filter(|(m, t)| **t && *m != self.index).count();
                    if known < *told {
                        continue;
                    }
                    if !self.go {
                        o.event(Event::GrantReceived);
                    }
                    self.go = true;
                    if let Some(c) = self.coordinator {
                        o.send(c, Message::GrantAck);
                    }
                }
                Message::Occupancy { agent, configurations } => {
                    let Some(slot) = self.occupancy.get_mut(*agent) else { continue };
                    let seen = self.told.get(*agent).copied().unwrap_or(false);
                    if seen && slot[..] == configurations[..] {
                        continue;
                    }
                    if let Some(t) = self.told.get_mut(*agent) {
                        *t = true;
                    }
                    *slot = configurations.clone();
                    let (agent, configurations) = (self.roster.names[*agent].clone(), configurations.len());
                    o.event(Event::Told { agent, configurations });
                    let known = self.known_obstacles();
                    if self.delib.set_known_obstacles(known, i.step(), i.dt()) {
                        let reason = ReplanReason::ReservedSpace;
                        o.event(Event::PlanInvalidated { id: None, reason });
                        o.event(Event::Replan { reason });
                    }
                }
                _ => {}
            }
        }
    }

    fn hold(i: &InputImages, o: &mut OutputImages) {
        let q = i.q().to_vec();
        o.set_position_target(&q, &vec![0.0; q.len()]);
    }
}

/// The main reaction: the plan follower, announcing each new plan to the coordinator and
/// reporting when it is done.
struct Deliberate {
    follower: PlanFollower,
}

impl Behaviour<RunAgent> for Deliberate {
    fn name(&self) -> &str {
        Behaviour::<RunAgent>::name(&self.follower)
    }

    fn step(&mut self, c: &mut RunAgent, i: &InputImages, o: &mut OutputImages) -> Result<Status, Violation> {
        c.read_messages(i, o);
        let status = self.follower.step(c, i, o)?;
        if let Some(coordinator) = c.coordinator {
            let id = c.delib.plan_id();
            if id.is_some() && id != c.announced {
                c.announced = id;
                // The plan's waypoints: the samples at rest (every segment starts and ends at rest).
                let waypoints: Vec<Vec<f64>> = c
                    .delib
                    .trajectory()
                    .map(|t| {
                        t.q.iter()
                            .zip(&t.qd)
                            .filter(|(_, v)| v.iter().all(|x| *x == 0.0))
                            .map(|(q, _)| q.clone())
                            .collect()
                    })
                    .unwrap_or_default();
                let waypoints: Arc<[Vec<f64>]> = waypoints.into();
                c.last_announcement = Some(waypoints.clone());
                c.repeated_at = i.step();
                o.send(coordinator, Message::Occupancy { agent: c.index, configurations: waypoints });
            }
            let failed = c.delib.abandoned();
            if (c.delib.goal_reached() || failed) && !c.done_sent {
                c.done_sent = true;
                c.repeated_at = i.step();
                o.event(Event::TaskDone { failed });
                o.send(coordinator, Message::Done { failed });
            }
            // Repeat what the coordinator must hear (lost messages must not stall the others).
            if i.step() >= c.repeated_at + RESEND_STEPS && (c.done_sent || c.last_announcement.is_some()) {
                c.repeated_at = i.step();
                if let Some(w) = &c.last_announcement {
                    o.send(coordinator, Message::Occupancy { agent: c.index, configurations: w.clone() });
                }
                if c.done_sent {
                    o.send(coordinator, Message::Done { failed });
                }
            }
        } else if c.delib.goal_reached() && !c.done_sent {
            c.done_sent = true;
            o.event(Event::TaskDone { failed: false });
        }
        Ok(status)
    }

    fn reset(&mut self) {
        Behaviour::<RunAgent>::reset(&mut self.follower);
    }

    fn describe(&self, out: &mut String) {
        Behaviour::<RunAgent>::describe(&self.follower, out);
    }
}

fn program(force_limit: Option<f64>) -> Reactive<RunAgent> {
    let mut program = Reactive::priority("main");
    if force_limit.is_some() {
        // Force-limited reaction: contact above the limit suppresses the plan follower; the arm
        // makes a controlled stop and the task is abandoned.
        program = program.rule(
            Predicate::new("force_over_limit", |c: &RunAgent, i| {
                c.force_sensor.is_some_and(|k| i.sensor_count() > k && i.sensor(k).values[1] > 0.5)
            }),
            Primitive::new("force_stop", 1, move |c: &mut RunAgent, i: &InputImages, o: &mut OutputImages| {
                TransitionFunction::compute(&mut SafeHalt, c, i, o);
                if !c.delib.abandoned() {
                    let k = c.force_sensor.unwrap_or(0);
                    let speed = i.qd().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                    o.event(Event::ForceLimit { force_n: i.sensor(k).values[0] });
                    o.event(Event::HaltStarted { reason: HaltReason::ForceLimit, speed, detail: None });
                    c.delib.abandon();
                }
            }),
        );
    }
    program
        .rule(
            Predicate::new("awaiting_go", |c: &RunAgent, _| !c.go),
            Primitive::new("wait_for_go", 1, |c: &mut RunAgent, i: &InputImages, o: &mut OutputImages| {
                RunAgent::hold(i, o);
                c.read_messages(i, o);
            }),
        )
        .main_reaction(Deliberate { follower: PlanFollower::new("deliberate") })
}

/// `c_c` of the coordinator.
struct Grants {
    mode: Coordination,
    /// Agent ids in grant order, with their scenario index.
    order: Vec<(AgentId, usize)>,
    /// Scenario index of each agent id.
    index_of: Vec<Option<usize>>,
    roster: Arc<Roster>,
    /// Latest plan (or start) of each scenario agent.
    paths: Vec<Arc<[Vec<f64>]>>,
    /// Agents granted so far.
    granted: usize,
    done: Vec<bool>,
    announced: Vec<bool>,
    all_done: bool,
    /// Per grant (in grant order): what it told (agent, configurations), when it was last sent,
    /// how many times, and whether the agent acknowledged it.
    grants: Vec<GrantSent>,
}

/// One grant as the coordinator sent it.
struct GrantSent {
    told: Vec<(usize, Arc<[Vec<f64>]>)>,
    sent_at: u64,
    times: u32,
    acknowledged: bool,
}

impl Grants {
    fn grant(&mut self, step: u64, o: &mut OutputImages) {
        let (id, k) = self.order[self.granted];
        // What the agents granted before it occupy: where they stand (sequential) or the space
        // their plans sweep (concurrent).
        let mut told = Vec::new();
        for &(_, m) in &self.order[..self.granted] {
            let configurations: Arc<[Vec<f64>]> = match self.mode {
                Coordination::Sequential => self.paths[m].last().cloned().into_iter().collect(),
                Coordination::Concurrent => self.paths[m].clone(),
            };
            told.push((m, configurations));
        }
        let g = GrantSent { told, sent_at: step, times: 1, acknowledged: false };
        Self::send_grant(id, &g, o);
        self.grants.push(g);
        o.event(Event::Granted { agent: self.roster.names[k].clone() });
        self.granted += 1;
    }

    fn send_grant(id: AgentId, g: &GrantSent, o: &mut OutputImages) {
        for (m, configurations) in &g.told {
            o.send(id, Message::Occupancy { agent: *m, configurations: configurations.clone() });
        }
        o.send(id, Message::Grant { told: g.told.len() });
    }

    /// Send every grant not acknowledged within [`RESEND_STEPS`] again (the same grant: what it
    /// told does not change).
    fn resend(&mut self, step: u64, o: &mut OutputImages) {
        for (n, g) in self.grants.iter_mut().enumerate() {
            let (id, k) = self.order[n];
            if g.acknowledged || self.done[k] || step < g.sent_at + RESEND_STEPS {
                continue;
            }
            g.sent_at = step;
            g.times += 1;
            Self::send_grant(id, g, o);
            o.event(Event::GrantResent { agent: self.roster.names[k].clone(), times: g.times });
        }
    }
}

fn coordinator_program() -> Primitive<Grants> {
    Primitive::new("grant", 1, |c: &mut Grants, i: &InputImages, o: &mut OutputImages| {
        for env in i.messages() {
            let Some(k) = c.index_of.get(env.from.0).copied().flatten() else { continue };
            // Anything from a granted agent acknowledges its grant.
            if let Some(n) = c.order.iter().position(|(_, m)| *m == k)
                && let Some(g) = c.grants.get_mut(n)
            {
                g.acknowledged = true;
            }
            match &env.message {
                Message::Done { failed } => {
                    if !c.done[k] && *failed {
                        o.event(Event::AgentFailed { agent: c.roster.names[k].clone() });
                    }
                    c.done[k] = true;
                }
                Message::Occupancy { agent, configurations } if *agent < c.paths.len() => {
                    c.paths[*agent] = configurations.clone();
                    c.announced[*agent] = true;
                }
                _ => {}
            }
        }
        if c.granted < c.order.len() {
            let ready = match c.granted.checked_sub(1).map(|p| c.order[p].1) {
                None => true,
                Some(prev) => match c.mode {
                    Coordination::Sequential => c.done[prev],
                    Coordination::Concurrent => c.announced[prev] || c.done[prev],
                },
            };
            if ready {
                c.grant(i.step(), o);
            }
        }
        c.resend(i.step(), o);
        if !c.all_done && c.order.iter().all(|(_, k)| c.done[*k]) {
            c.all_done = true;
            o.event(Event::AllDone);
        }
    })
}

/// Deliberation settings of a scenario's agents.
pub fn deliberation_settings(scenario: &Scenario, clock: ClockSpec, dt: f64) -> DeliberationSettings {
    let steps = |ms: f64| (ms / 1e3 / dt).ceil().max(0.0) as u64;
    let give_up_steps = steps(scenario.planner.give_up_ms);
    DeliberationSettings {
        clock: match clock {
            ClockSpec::Wall => PlanClock::WallClock,
            ClockSpec::Simulated { us_per_check } => {
                PlanClock::Simulated { steps_per_unit: us_per_check * 1e-6 / dt, fixed_steps: 0 }
            }
        },
        budget: PlanBudget {
            steps: steps(scenario.planner.deadline_ms),
            wall: Some(Duration::from_secs_f64(scenario.planner.give_up_ms / 1e3)),
            give_up_steps: Some(give_up_steps),
            work: scenario.planner.expansions.map(|n| n as u64),
        },
        motion: motion_settings(scenario, Deadline::none()),
        planner: None,
        verify_resolution: scenario.planner.resolution.min(0.01),
        plan_check: embodied_planner::verify::Verifier::default(),
        goal_tolerance: 1e-3,
        retry_after_steps: 100,
        max_attempts: 3,
        plan_timeout_steps: give_up_steps + 1000,
        obstacle_sensing: None,
        sensor_max_age: 50,
        sensor_max_abs: 1e4,
        move_tolerance: 0.02,
        halt_on_any_change: false,
        replan_in_motion: true,
        // Half of each acceleration limit brakes towards a replan's start; the other half is what
        // the new plan's first segment may use while superposed on the braking (a join at speed).
        brake_fraction: 0.5,
    }
}

fn clock_name(clock: ClockSpec) -> String {
    match clock {
        ClockSpec::Wall => "wall".into(),
        ClockSpec::Simulated { us_per_check } => format!("simulated ({us_per_check} us per collision check)"),
    }
}

/// How to run a scenario (each `None` takes the scenario's own setting).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Simulated seconds (default: the scenario's `[run] duration`, else 6).
    pub duration: Option<f64>,
    /// Seed of all simulated noise (default: the scenario's).
    pub seed: Option<u64>,
    /// How planning time is counted (default: the scenario's `[planner] clock`).
    pub clock: Option<ClockSpec>,
    /// Closed-chain controller settings for a carry (default: the controller's defaults).
    pub closed_chain: Option<ClosedChainConfig>,
    /// Solve every closed-chain QP with clarabel as well (`embodied bench qp`).
    pub qp_compare: bool,
    /// The link between the coordinator and each agent (default: ideal, no latency or loss).
    pub link: Option<Link>,
}

/// What a run did, per agent.
#[derive(Debug, Clone, Serialize, Default)]
pub struct AgentSummary {
    /// The agent.
    pub name: String,
    /// A verified plan landed.
    pub planned: bool,
    /// Motion time of the last plan that landed, s.
    pub plan_duration_s: Option<f64>,
    /// Planning time of the last plan that landed (simulated or wall, as the clock), ms.
    pub planning_ms: Option<f64>,
    /// Plans asked for.
    pub plans_requested: usize,
    /// Plans that landed.
    pub plans_landed: usize,
    /// Plans the verifier refused.
    pub plans_rejected: usize,
    /// Controlled stops begun.
    pub safe_halts: usize,
    /// Replans.
    pub replans: usize,
    /// Whether its goal was reached.
    pub goal_reached: bool,
    /// Its configuration at the end.
    pub final_q: Vec<f64>,
    /// Distance of `final_q` from a configuration goal.
    pub goal_error: Option<f64>,
    /// Largest |qd| / max velocity over the run.
    pub max_speed_ratio: f64,
    /// Task operators it finished (an arm of a `[task]`).
    pub operators_done: usize,
}

/// What a run did. Serialised into the log (without the wall-clock figures, so that the
/// log replays byte for byte) and printed on the terminal (with them).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// How planning time was counted.
    pub clock: String,
    /// Control steps run.
    pub steps: u64,
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall-clock time of the run, s (not in the log).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wall_s: Option<f64>,
    /// Simulated / wall time (not in the log).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub real_time_factor: Option<f64>,
    /// Wall-clock time the carry's planning took before the run, ms (not in the log).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub carry_wall_planning_ms: Option<f64>,
    /// Per agent.
    pub agents: Vec<AgentSummary>,
    /// (time, agent, event) in order.
    pub events: Vec<(f64, String, Event)>,
    /// (time, agent, behaviour) whenever an agent's active behaviour changed.
    pub behaviour_switches: Vec<(f64, String, String)>,
    /// Why the run stopped early, if it did.
    pub failure: Option<String>,
    /// Lines written to the log (0 without one).
    pub log_lines: usize,
    /// The two-handed carry, when the scenario has one (its QP timings and wall planning
    /// time are wall-clock figures: zero in the log).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closed_chain: Option<ClosedChainSummary>,
}

impl RunSummary {
    /// The summary as the log keeps it: only what the simulation computed.
    pub fn replayable(&self) -> RunSummary {
        let mut s = self.clone();
        s.wall_s = None;
        s.real_time_factor = None;
        s.carry_wall_planning_ms = None;
        if let Some(c) = &mut s.closed_chain {
            c.qp_p50_us = 0.0;
            c.qp_p99_us = 0.0;
            c.qp_max_us = 0.0;
            c.qp_late_steps = 0;
        }
        s
    }
}

/// Per-step bookkeeping of a run: summaries, events, behaviour switches.
struct Observer {
    summaries: Vec<AgentSummary>,
    pending: Vec<bool>,
    /// The task-level deliberation has not delivered yet.
    task_pending: bool,
    events: Vec<(f64, String, Event)>,
    switches: Vec<(f64, String, String)>,
    last_behaviour: Vec<String>,
    limits: Vec<Vec<embodied_models::JointLimits>>,
}

impl Observer {
    fn new(scenario: &Scenario, agents: usize) -> Self {
        Self {
            summaries: scenario
                .agents
                .iter()
                .map(|a| AgentSummary { name: a.name.clone(), ..AgentSummary::default() })
                .collect(),
            pending: vec![false; scenario.agents.len()],
            task_pending: scenario.task.is_some(),
            events: Vec::new(),
            switches: Vec::new(),
            last_behaviour: vec![String::new(); agents],
            limits: scenario.agents.iter().map(|a| a.robot.limits()).collect(),
        }
    }

    fn observe(&mut self, r: &StepRecord) {
        for (k, a) in r.agents.iter().enumerate() {
            for e in &a.events {
                if matches!(e, Event::TaskPlanFound { .. } | Event::TaskPlanFailed { .. }) {
                    self.task_pending = false;
                }
                self.events.push((r.time, a.agent.clone(), e.clone()));
                if k < self.summaries.len() {
                    tally(&mut self.summaries[k], &mut self.pending[k], e);
                }
            }
            if self.last_behaviour.get(k).is_some_and(|b| *b != a.behaviour) {
                self.switches.push((r.time, a.agent.clone(), a.behaviour.clone()));
                self.last_behaviour[k].clone_from(&a.behaviour);
            }
            if let Some(limits) = self.limits.get(k) {
                for (j, &qd) in a.qd.iter().enumerate() {
                    let ratio = qd.abs() / limits[j].max_velocity;
                    self.summaries[k].max_speed_ratio = self.summaries[k].max_speed_ratio.max(ratio);
                }
            }
        }
    }
}

/// Count one event of a scenario agent into its summary.
fn tally(s: &mut AgentSummary, pending: &mut bool, e: &Event) {
    match e {
        Event::PlanRequested { .. } => {
            s.plans_requested += 1;
            *pending = true;
        }
        Event::PlanLanded { planning_ms, duration_s, .. } => {
            s.plans_landed += 1;
            s.planned = true;
            s.planning_ms = Some(*planning_ms);
            s.plan_duration_s = Some(*duration_s);
            *pending = false;
        }
        Event::PlanRejected { .. } => {
            s.plans_rejected += 1;
            *pending = false;
        }
        Event::PlanFailed { .. }
        | Event::PlannerPanicked { .. }
        | Event::PlanDiscarded { .. }
        | Event::PlanLost { .. } => *pending = false,
        Event::HaltStarted { .. } => s.safe_halts += 1,
        Event::Replan { .. } => s.replans += 1,
        Event::GoalReached { .. } => s.goal_reached = true,
        Event::OperatorFinished { .. } => s.operators_done += 1,
        _ => {}
    }
}

/// A scenario assembled as a system of embodied agents: one agent per scenario agent (a
/// deliberative agent for each goal, the carrying agent for a carry, a holding agent
/// otherwise), a coordinator when several agents plan, links between them, and the world
/// with the scenario's obstacles.
pub struct System {
    scenario: Scenario,
    runtime: Runtime,
    seed: u64,
    clock: ClockSpec,
    duration: f64,
    coordinator: Option<AgentId>,
    /// The carry's record, its log header and its wall-clock planning time, ms.
    carry: Option<(Arc<Mutex<CarryRecord>>, serde_json::Value, f64)>,
    observer: Observer,
    started: Option<Instant>,
    wall: Duration,
    pace: Option<(Instant, u64)>,
    injections: Injections,
    link_faults: Option<Arc<Mutex<LinkFaultState>>>,
    obstacle_faults: Vec<(Windows, Vec<usize>)>,
}

impl System {
    /// Assemble `scenario` (plans a carry, if there is one, before the first step).
    pub fn new(scenario: &Scenario, options: &RunOptions) -> Result<Self, SystemError> {
        let duration = match options.duration {
            Some(d) if d.is_finite() && d > 0.0 => d,
            Some(d) => {
                return Err(SystemError::Usage(format!("duration must be a positive number of seconds, got {d}")));
            }
            None => scenario.run.duration.unwrap_or(6.0),
        };
        let seed = options.seed.unwrap_or(scenario.seed);
        let clock = options.clock.unwrap_or(scenario.planner.clock);
        let dt = 0.001;
        let failed = |name: &str, e: &dyn std::fmt::Display| SystemError::Failed(format!("agent `{name}`: {e}"));
        let mut runtime = Runtime::new(RuntimeConfig { dt, seed, ..RuntimeConfig::default() });
        let mut mapped = Vec::new();
        let polish = match &scenario.polish {
            Some(spec) => Some(Arc::new(crate::polish::PolishJob::plan(scenario, spec)?)),
            None => None,
        };
        for (i, o) in scenario.obstacles.iter().enumerate() {
            let (c, r) = o.obstacle.shape.bounding_sphere();
            let p = o.obstacle.pose * c;
            // A polished workpiece is felt as its box through the pad's compliant skin, not as
            // its bounding sphere; its sphere entry (never present) keeps obstacle ids in order.
            let workpiece = polish.as_ref().filter(|j| j.spec.workpiece == i);
            if let (Some(job), Shape::Cuboid { half_extents: h }) = (workpiece, &o.obstacle.shape) {
                let t = o.obstacle.pose.translation.vector;
                runtime.world_mut().add_solid(embodied_executor::Solid {
                    name: o.obstacle.name.clone(),
                    centre: [t.x, t.y, t.z],
                    half: [h.x, h.y, h.z],
                    skin: job.spec.skin,
                });
            }
            let id = runtime.world_mut().add_obstacle(embodied_executor::Obstacle {
                name: o.obstacle.name.clone(),
                position: [p.x, p.y, p.z],
                velocity: o.velocity.map_or([0.0; 3], |v| [v.x, v.y, v.z]),
                radius: r,
                appears_at: if workpiece.is_some() {
                    u64::MAX
                } else {
                    o.appear_at.map_or(0, |t| (t / dt).round().max(0.0) as u64)
                },
                vanishes_at: None,
            });
            if o.on_map() {
                mapped.push(id);
            }
        }
        let injections: Injections = Arc::default();
        // Per scenario agent: its faults (index in the scenario, spec, seed).
        let faults_of = |k: usize, which: &dyn Fn(FaultKind) -> bool| -> Vec<(usize, FaultSpec, u64)> {
            let name = &scenario.agents[k].name;
            scenario
                .faults
                .iter()
                .enumerate()
                .filter(|(_, f)| which(f.kind) && f.agent.as_ref().is_none_or(|a| a == name))
                .map(|(i, f)| (i, f.clone(), f.seed.unwrap_or(seed).wrapping_add(k as u64)))
                .collect()
        };
        let sensing = scenario.obstacles.iter().any(|o| !o.on_map())
            || scenario.faults.iter().any(|f| f.kind.is_sensor() || f.kind == FaultKind::ObstacleInPath);
        let roster = Arc::new(Roster {
            names: scenario.agents.iter().map(|a| a.name.clone()).collect(),
            robots: scenario.agents.iter().map(|a| a.robot.clone()).collect(),
        });
        let starts: Vec<Arc<[Vec<f64>]>> = scenario.agents.iter().map(|a| Arc::from(vec![a.start.clone()])).collect();
        let planners: Vec<usize> = (0..scenario.agents.len()).filter(|&k| scenario.agents[k].goal.is_some()).collect();
        let coordinated = planners.len() > 1;
        let coordinator_id = AgentId(scenario.agents.len());
        let mut settings = deliberation_settings(scenario, clock, dt);
        if sensing {
            settings.obstacle_sensing = Some(f64::INFINITY);
        }
        let mut carry = None;
        let task_domain = match &scenario.task {
            Some(_) => Some(Arc::new(crate::task::TaskDomain::new(scenario)?)),
            None => None,
        };
        for (k, agent) in scenario.agents.iter().enumerate() {
            let robot = Arc::new(agent.robot.clone());
            if scenario.task.as_ref().is_some_and(|t| t.arms.contains(&k)) {
                let state = crate::task::TaskArm::new(coordinator_id);
                let a =
                    Agent::embodied(agent.name.clone(), robot, Some(&agent.start), state, crate::task::arm_program())
                        .map_err(|e| failed(&agent.name, &e))?;
                runtime.add_agent(a);
                continue;
            }
            if let Some(job) = polish.as_ref().filter(|j| j.spec.agent == k) {
                let force_limit = agent.behaviour.force_limit;
                let state = crate::polish::PolishArm::new(job.clone(), robot.clone(), 0);
                let program = crate::polish::polish_program(force_limit);
                let threshold = force_limit.unwrap_or(f64::INFINITY);
                let a = Agent::embodied(agent.name.clone(), robot, Some(&agent.start), state, program)
                    .map_err(|e| failed(&agent.name, &e))?
                    .with_sensor(Contact, SensorConfig { threshold, ..SensorConfig::default() })
                    .with_receptors(ReceptorSpec {
                        force_stiffness: Some(crate::polish::CONTACT_STIFFNESS),
                        force_noise: 0.5,
                        ..ReceptorSpec::default()
                    });
                runtime.add_agent(a);
                continue;
            }
            if let Some(spec) = scenario.carry.as_ref().filter(|c| c.agent == k) {
                let qp_faults = faults_of(k, &|f| f == FaultKind::QpInfeasible);
                let qp = (!qp_faults.is_empty()).then(|| qp_fault(k, qp_faults, dt, injections.clone()));
                let (a, record, header, wall_ms) = carry_parts(scenario, spec, dt, clock, options, qp)?;
                runtime.add_agent(a);
                carry = Some((record, header, wall_ms));
                continue;
            }
            let Some(goal) = &agent.goal else {
                // No goal: it holds where it stands.
                let hold = Primitive::new("hold", 1, |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                    RunAgent::hold(i, o);
                });
                let a = Agent::embodied(agent.name.clone(), robot, Some(&agent.start), (), hold)
                    .map_err(|e| failed(&agent.name, &e))?;
                runtime.add_agent(a);
                continue;
            };
            let force_limit = agent.behaviour.force_limit;
            // The map: the obstacles there from the start; the other agents where they stand.
            let model = agent_problem(scenario, k, &[]);
            let mut settings = settings.clone();
            let planner_faults = faults_of(k, &|f| f.is_planner());
            if !planner_faults.is_empty() {
                let inner = PlanMotion::new(model.clone(), settings.motion.clone());
                let faulty = FaultyPlanner::new(inner, k, planner_faults, dt, injections.clone());
                settings.planner = Some(Arc::new(faulty));
            }
            let delib = DeliberativeState::new(robot.clone(), model, goal_of(goal), settings);
            let mut state = RunAgent {
                delib,
                index: k,
                go: !coordinated,
                coordinator: coordinated.then_some(coordinator_id),
                roster: roster.clone(),
                occupancy: starts.clone(),
                announced: None,
                done_sent: false,
                force_sensor: None,
                told: vec![false; scenario.agents.len()],
                last_announcement: None,
                repeated_at: 0,
            };
            let known = state.known_obstacles();
            state.delib.set_known_obstacles(known, 0, dt);
            let mut receptors = ReceptorSpec::default();
            let mut sensors = 0;
            if sensing {
                receptors.detector_range = Some(f64::INFINITY);
                sensors += 1;
            }
            if force_limit.is_some() {
                receptors.force_stiffness = Some(2.0e4);
                receptors.force_noise = 0.5;
                state.force_sensor = Some(sensors);
            }
            let effector_faults = faults_of(k, &|f| f == FaultKind::TrackingError);
            let mut a = if effector_faults.is_empty() {
                Agent::embodied(agent.name.clone(), robot, Some(&agent.start), state, program(force_limit))
            } else {
                let servo = ServoModel::new(robot.limits(), &agent.start).map_err(|e| failed(&agent.name, &e))?;
                let faulty = FaultyEffector::new(servo, k, effector_faults, dt, injections.clone());
                Agent::new(agent.name.clone(), state, program(force_limit))
                    .with_effector(faulty)
                    .map(|a| a.with_robot_model(robot, 0))
            }
            .map_err(|e| failed(&agent.name, &e))?;
            if sensing {
                let sensor = UnmappedObstacle::new(mapped.clone(), false);
                let sensor_faults = faults_of(k, &|f| f.is_sensor());
                if sensor_faults.is_empty() {
                    a = a.with_sensor(sensor, SensorConfig::default());
                } else {
                    let faulty = FaultySensor::new(sensor, k, sensor_faults, dt, injections.clone());
                    a = a.with_sensor(faulty, SensorConfig::default());
                }
            }
            if let Some(limit) = force_limit {
                a = a.with_sensor(Contact, SensorConfig { threshold: limit, ..SensorConfig::default() });
            }
            if sensing || force_limit.is_some() {
                a = a.with_receptors(receptors);
            }
            runtime.add_agent(a);
        }
        let mut coordinator = None;
        if let (Some(domain), Some(task)) = (task_domain, &scenario.task) {
            let arm_ids: Vec<AgentId> = task.arms.iter().map(|&k| AgentId(k)).collect();
            let c = crate::task::TaskCoordinator::new(domain, Arc::new(scenario.clone()), clock, dt, arm_ids.clone());
            let id = runtime.add_agent(Coordinator::new("coordinator", c, crate::task::coordinator_program()));
            let link = options.link.unwrap_or(Link::IDEAL);
            for k in arm_ids {
                runtime.connect_both(id, k, link).map_err(|e| SystemError::Failed(e.to_string()))?;
            }
            coordinator = Some(id);
        } else if coordinated {
            let order: Vec<(AgentId, usize)> = planners.iter().map(|&k| (AgentId(k), k)).collect();
            let n = scenario.agents.len();
            let mut index_of = vec![None; n + 1];
            for &k in &planners {
                index_of[k] = Some(k);
            }
            let grants = Grants {
                mode: scenario.run.coordination,
                order,
                index_of,
                roster: roster.clone(),
                paths: starts,
                granted: 0,
                done: vec![false; n],
                announced: vec![false; n],
                all_done: false,
                grants: Vec::new(),
            };
            let id = runtime.add_agent(Coordinator::new("coordinator", grants, coordinator_program()));
            let link = options.link.unwrap_or(Link::IDEAL);
            for &k in &planners {
                runtime.connect_both(id, AgentId(k), link).map_err(|e| SystemError::Failed(e.to_string()))?;
            }
            coordinator = Some(id);
        }
        // Link faults: on the links named (`from->to`, by agent name or `coordinator`), or all.
        let link_specs: Vec<(usize, &FaultSpec)> =
            scenario.faults.iter().enumerate().filter(|(_, f)| f.kind.is_link()).collect();
        let mut link_faults = None;
        if let (Some(c), false) = (coordinator, link_specs.is_empty()) {
            let id_of = |name: &str| {
                if name == "coordinator" {
                    Some(c)
                } else {
                    scenario.agents.iter().position(|a| a.name == name).map(AgentId)
                }
            };
            let mut faults = Vec::new();
            for (i, f) in link_specs {
                let ends = match f.link_ends() {
                    None => None,
                    Some(Ok((a, b))) => match (id_of(a), id_of(b)) {
                        (Some(a), Some(b)) => Some((a, b)),
                        _ => {
                            return Err(SystemError::Usage(format!(
                                "scenario `{}`: fault #{} ({}): link `{a}->{b}`: expected agent names or `coordinator`",
                                scenario.name,
                                i + 1,
                                f.kind.as_str()
                            )));
                        }
                    },
                    Some(Err(e)) => return Err(SystemError::Usage(format!("scenario `{}`: {e}", scenario.name))),
                };
                faults.push((i, f.clone(), f.seed.unwrap_or(seed), ends));
            }
            let state =
                Arc::new(Mutex::new(LinkFaultState::new(faults, dt, scenario.agents.len(), injections.clone())));
            runtime.set_link_faults(Box::new(SharedLinkFaults(state.clone())));
            link_faults = Some(state);
        }
        // Obstacles entering the path: per fault, its windows and the agents it strikes.
        let obstacle_faults: Vec<(Windows, Vec<usize>)> = scenario
            .faults
            .iter()
            .enumerate()
            .filter(|(_, f)| f.kind == FaultKind::ObstacleInPath)
            .map(|(i, f)| {
                let agents = (0..scenario.agents.len())
                    .filter(|&k| scenario.agents[k].goal.is_some())
                    .filter(|&k| f.agent.as_ref().is_none_or(|a| *a == scenario.agents[k].name))
                    .collect();
                (Windows::new(i, f.clone(), f.seed.unwrap_or(seed)), agents)
            })
            .collect();
        // Every agent's body is in the world: other agents' detectors see it, and every step
        // records the smallest robot-robot and robot-environment distance.
        runtime.set_monitor(Box::new(crate::clearance::ClearanceMeter::new(scenario, dt)));
        let observer = Observer::new(scenario, runtime.agent_count());
        Ok(Self {
            scenario: scenario.clone(),
            runtime,
            seed,
            clock,
            duration,
            coordinator,
            carry,
            observer,
            started: None,
            wall: Duration::ZERO,
            pace: None,
            injections,
            link_faults,
            obstacle_faults,
        })
    }

    /// Faults struck at the start of a step: link windows open, obstacles enter paths.
    fn before_step(&mut self) {
        let step = self.runtime.current_step();
        let dt = self.runtime.config().dt;
        if let Some(l) = &self.link_faults {
            l.lock().unwrap_or_else(|e| e.into_inner()).advance(step);
        }
        for (w, agents) in &mut self.obstacle_faults {
            if !w.starts(step, dt) {
                continue;
            }
            for &k in agents.iter() {
                let Some(images) = self.runtime.images(AgentId(k)) else { continue };
                let agent = &self.scenario.agents[k];
                let goal = match &agent.goal {
                    Some(GoalSpec::Configuration(g)) => Some(&g[..]),
                    _ => None,
                };
                let ahead = 0.05 + 0.25 * draw(w.seed, w.index as u64 + 1000, step);
                let radius = 0.04 + 0.04 * draw(w.seed, w.index as u64 + 2000, step);
                let at = place_obstacle(&agent.robot, images.q(), images.qd(), goal, ahead, radius);
                let mut inj = Injection::new(FaultKind::ObstacleInPath, k, step, 1);
                if let Some(p) = at {
                    self.runtime.world_mut().add_obstacle(embodied_executor::Obstacle {
                        name: format!("in-path-{}-{step}", w.index),
                        position: p,
                        velocity: [0.0; 3],
                        radius,
                        appears_at: step,
                        vanishes_at: None,
                    });
                    inj.obstacle = Some((p, radius));
                }
                self.injections.lock().unwrap_or_else(|e| e.into_inner()).push(inj);
            }
        }
    }

    /// The faults injected so far, in the order they struck.
    pub fn injections(&self) -> Vec<Injection> {
        self.injections.lock().map(|v| v.clone()).unwrap_or_else(|e| e.into_inner().clone())
    }

    /// The scenario it was assembled from.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The runtime: every agent's images ([`Runtime::images`]), the last step's record, the
    /// channels' statistics.
    pub fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The simulated world (obstacles as the receptors see them).
    pub fn world(&self) -> &World {
        self.runtime.world()
    }

    /// Id of scenario agent `name` (the coordinator is `coordinator`).
    pub fn agent_id(&self, name: &str) -> Option<AgentId> {
        self.runtime.agent_id(name)
    }

    /// The coordinator's id, when several agents plan.
    pub fn coordinator(&self) -> Option<AgentId> {
        self.coordinator
    }

    /// Simulated seconds the run lasts (the options' or the scenario's).
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// Simulated time so far, s.
    pub fn time(&self) -> f64 {
        self.runtime.current_step() as f64 * self.runtime.config().dt
    }

    /// The run log's header.
    pub fn header(&self) -> LogHeader {
        let agents = self.scenario.agents.iter().map(|a| (a.name.clone(), LoggedAgent::of(&a.robot))).collect();
        LogHeader {
            format: LOG_FORMAT.to_string(),
            generator: crate::generator(),
            scenario: self.scenario.name.clone(),
            scenario_hash: self.scenario.hash.clone(),
            seed: self.seed,
            step_s: self.runtime.config().dt,
            duration_s: self.duration,
            planning_clock: clock_name(self.clock),
            agents,
            closed_chain: self.carry.as_ref().map(|(_, h, _)| h.clone()),
        }
    }

    /// One control step of every agent. With the wall clock, while a plan is being computed
    /// a step takes a step's real time, so that deadlines in steps and the planner's
    /// wall-clock deadline mean the same.
    pub fn step(&mut self) -> Result<&StepRecord, SystemError> {
        self.before_step();
        let started = Instant::now();
        let result = self.runtime.step().map(|_| ());
        self.after_step(started);
        result.map_err(|e| SystemError::Failed(e.to_string()))?;
        Ok(self.runtime.last_record())
    }

    fn after_step(&mut self, started: Instant) {
        let r = self.runtime.last_record();
        self.observer.observe(r);
        self.started.get_or_insert(started);
        if self.clock == ClockSpec::Wall && (self.observer.task_pending || self.observer.pending.iter().any(|p| *p)) {
            let dt = self.runtime.config().dt;
            let (t0, s0) = *self.pace.get_or_insert((Instant::now(), r.step));
            let due = t0 + Duration::from_secs_f64((r.step + 1 - s0) as f64 * dt);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        } else {
            self.pace = None;
        }
        self.wall += started.elapsed();
    }

    /// Run until simulated time `until_s` (or the end of a failure's safe halt), handing every
    /// step's record to `on_record`. A failure (a specification error) is returned after every
    /// effector has come to rest; its records were handed on.
    pub fn run_until(&mut self, until_s: f64, mut on_record: impl FnMut(&StepRecord)) -> Result<(), SystemError> {
        let dt = self.runtime.config().dt;
        let target = (until_s / dt).round().max(0.0) as u64;
        while self.runtime.current_step() < target {
            self.before_step();
            let started = Instant::now();
            match self.runtime.step() {
                Ok(_) => {
                    self.after_step(started);
                    on_record(self.runtime.last_record());
                }
                Err(e) => {
                    if self.runtime.last_record().step + 1 == self.runtime.current_step() {
                        self.after_step(started);
                        on_record(self.runtime.last_record());
                    }
                    let mut n = 0;
                    while !self.runtime.is_at_rest() && n < embodied_executor::runtime::MAX_HALT_STEPS {
                        let started = Instant::now();
                        self.runtime.halt_step();
                        self.after_step(started);
                        on_record(self.runtime.last_record());
                        n += 1;
                    }
                    return Err(SystemError::Failed(e.to_string()));
                }
            }
        }
        Ok(())
    }

    /// Run for `seconds` more simulated time; see [`System::run_until`].
    pub fn run_for(&mut self, seconds: f64, on_record: impl FnMut(&StepRecord)) -> Result<(), SystemError> {
        let until = self.time() + seconds;
        self.run_until(until, on_record)
    }

    /// The carry's per-step measurements (QP timings, closure), when the scenario has a carry.
    pub fn carry_record(&self) -> Option<Arc<Mutex<CarryRecord>>> {
        self.carry.as_ref().map(|(r, _, _)| r.clone())
    }

    /// What the run did so far (wall-clock figures included; see [`RunSummary::replayable`]).
    pub fn summary(&self) -> RunSummary {
        let last = self.runtime.last_record();
        let mut agents = self.observer.summaries.clone();
        for (k, a) in self.scenario.agents.iter().enumerate() {
            let final_q = last.agents.get(k).map(|r| r.q.clone()).unwrap_or_else(|| a.start.clone());
            agents[k].goal_error = match &a.goal {
                Some(GoalSpec::Configuration(g)) if g.len() == final_q.len() => {
                    Some(a.robot.config_space().distance(g, &final_q))
                }
                _ => None,
            };
            agents[k].final_q = final_q;
        }
        let dt = self.runtime.config().dt;
        let steps = self.runtime.current_step();
        let wall = self.wall.as_secs_f64();
        RunSummary {
            scenario: self.scenario.name.clone(),
            seed: self.seed,
            clock: clock_name(self.clock),
            steps,
            simulated_s: steps as f64 * dt,
            wall_s: Some(wall),
            real_time_factor: Some(steps as f64 * dt / wall.max(1e-9)),
            agents,
            events: self.observer.events.clone(),
            behaviour_switches: self.observer.switches.clone(),
            failure: self.runtime.failure().map(|e| e.to_string()),
            log_lines: 0,
            closed_chain: self.carry.as_ref().and_then(|(r, _, _)| finish(r)),
            carry_wall_planning_ms: self.carry.as_ref().map(|(_, _, ms)| *ms),
        }
    }
}

/// The carrying agent, its record, its log header and the wall-clock time its plan took, ms.
type CarryParts =
    (Agent<embodied_executor::closed_chain::carry::CarryAgent>, Arc<Mutex<CarryRecord>>, serde_json::Value, f64);

/// The carrying agent of `scenario` (planned here, before the first step) and its log header.
fn carry_parts(
    scenario: &Scenario,
    spec: &crate::scenario::CarrySpec,
    dt: f64,
    clock: ClockSpec,
    options: &RunOptions,
    qp_fault: Option<embodied_executor::closed_chain::carry::QpFault>,
) -> Result<CarryParts, SystemError> {
    let agent = &scenario.agents[spec.agent];
    let task = scenario
        .carry_task()
        .ok_or_else(|| SystemError::Failed(format!("scenario `{}` has no carry", scenario.name)))?;
    let mut settings = scenario.carry_settings();
    settings.dt = dt;
    let plan = plan_carry(&task, &settings).map_err(|e| {
        SystemError::Failed(format!("scenario `{}`: agent `{}`: carry: {e}", scenario.name, agent.name))
    })?;
    // Planning time as the run counts it: simulated from the collision checks (the log stays
    // byte-identical for a seed) or the wall clock.
    let wall_ms = plan.stats.planning_ms;
    let planning_ms = match clock {
        ClockSpec::Wall => plan.stats.planning_ms,
        ClockSpec::Simulated { us_per_check } => plan.stats.collision_checks as f64 * us_per_check * 1e-3,
    };
    let header = serde_json::json!({
        "agent": agent.name,
        "end_effectors": plan.span.end_effectors,
        "tolerance_m": plan.span.tolerance_m,
        "tolerance_rad": plan.span.tolerance_rad,
        "object": plan.span.object,
    });
    let setup = CarrySetup {
        name: agent.name.clone(),
        robot: agent.robot.clone(),
        plan,
        environment: scenario.initial_environment(),
        object_goal: spec.object_goal,
        config: ClosedChainConfig { dt, ..options.closed_chain.clone().unwrap_or_default() },
        planning_ms,
        compare: options.qp_compare,
    };
    let made = match qp_fault {
        Some(f) => carry_agent_with_fault(setup, f),
        None => carry_agent(setup),
    };
    let (a, record) = made.map_err(|e| {
        SystemError::Failed(format!("scenario `{}`: agent `{}`: carry: {e}", scenario.name, agent.name))
    })?;
    Ok((a, record, header, wall_ms))
}

/// What `embodied run` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct RunArgs {
    /// A built-in scenario name or a scenario file.
    pub scenario: String,
    /// How to run it.
    pub options: RunOptions,
    /// Write the JSON Lines log here.
    pub log: Option<PathBuf>,
    /// Write an SVG plot of the run here (joints per agent and unit, limits, events, carry
    /// closure error and clearance).
    pub plot: Option<PathBuf>,
    /// Write the viewer page (`embodied view`) of the run here.
    pub html: Option<PathBuf>,
}

/// Load and run a scenario, writing its log (complete up to the last step even on failure)
/// plot and viewer page. The summary's `failure` says whether the run stopped early.
pub fn run_scenario(args: &RunArgs) -> Result<(RunSummary, System), SystemError> {
    let scenario = load_scenario(&args.scenario)?;
    let mut system = System::new(&scenario, &args.options)?;
    let mut log = RunLog::create(args.log.as_deref())?;
    log.line(&serde_json::json!({ "header": system.header() }))?;
    let mut log_error = None;
    let until = system.duration();
    // Frames for the plot and the page: every 5 ms, kept only when one is asked for.
    let mut track = crate::view::Track::default();
    let keep_frames = args.html.is_some() || args.plot.is_some();
    let n = scenario.agents.len();
    let result = system.run_until(until, |r| {
        if log_error.is_none()
            && let Err(e) = log.line(&LogStep::of(r))
        {
            log_error = Some(e);
        }
        if keep_frames && r.step.is_multiple_of(5) {
            let q = r.agents.iter().take(n).map(|a| Some(a.q.clone())).collect();
            track.frames.push(crate::view::TrackFrame { t: r.time, q });
        }
    });
    if let Some(e) = log_error {
        return Err(e);
    }
    let _ = result;
    let mut summary = system.summary();
    log.line(&serde_json::json!({ "summary": summary.replayable() }))?;
    summary.log_lines = log.lines();
    let track = crate::view::with_events(track, &summary.events);
    if let Some(path) = &args.plot {
        crate::plot::plot_run(path, &scenario, &track)?;
    }
    if let Some(path) = &args.html {
        crate::view::write_run_view(path, &scenario, &track)?;
    }
    Ok((summary, system))
}

/// The summary as text for the terminal (the first 60 events; the rest are in the log).
pub fn render_summary(s: &RunSummary) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "scenario {} (seed {}, planning clock: {}): {} steps, {:.3} s simulated in {:.3} s wall, real-time factor {:.1}",
        s.scenario,
        s.seed,
        s.clock,
        s.steps,
        s.simulated_s,
        s.wall_s.unwrap_or(0.0),
        s.real_time_factor.unwrap_or(0.0)
    );
    for a in &s.agents {
        let plan = match (a.planning_ms, a.plan_duration_s) {
            (Some(ms), Some(d)) => format!("last plan in {ms:.2} ms, {d:.2} s of motion"),
            _ if a.operators_done > 0 => format!("{} task operators done", a.operators_done),
            _ => "no plan".to_string(),
        };
        let goal = a.goal_error.map_or(String::new(), |e| format!(", distance to goal {e:.4}"));
        let _ = writeln!(
            out,
            "  agent {:<12} {plan}{goal}; plans asked {}, landed {}, rejected {}; halts {}, replans {}; goal {}; peak |qd|/vmax {:.2}",
            a.name,
            a.plans_requested,
            a.plans_landed,
            a.plans_rejected,
            a.safe_halts,
            a.replans,
            if a.goal_reached { "reached" } else { "not reached" },
            a.max_speed_ratio
        );
    }
    if let Some(c) = &s.closed_chain {
        let _ = writeln!(
            out,
            "  closed chain ({}): plan {:.1} ms{}, {:.2} s of motion; held {} steps; QP p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} late, {} fallbacks, {} slacked); largest closure error {:.2e} m / {:.2e} rad (residual {:.1e}); object tracking {:.2e} m; nearest obstacle {:.3} m ({} damped steps); halts {}{}; object put down {} from its goal",
            c.agent,
            c.planning_ms,
            s.carry_wall_planning_ms.map_or(String::new(), |ms| format!(" ({ms:.1} ms wall)")),
            c.plan_duration_s,
            c.qp_steps,
            c.qp_p50_us,
            c.qp_p99_us,
            c.qp_max_us,
            c.qp_late_steps,
            c.qp_fallbacks,
            c.slacked_steps,
            c.max_closure_error_m,
            c.max_closure_error_rad,
            c.max_closure_residual,
            c.max_tracking_error_m,
            c.closest_obstacle_m,
            c.damper_steps,
            c.halts,
            c.halt_reason.as_ref().map_or(String::new(), |r| format!(" ({r})")),
            c.object_goal_error_m.map_or("-".to_string(), |e| format!("{e:.4} m")),
        );
    }
    let _ = writeln!(out, "behaviour switches:");
    for (t, agent, b) in &s.behaviour_switches {
        let _ = writeln!(out, "  t={t:7.3}s {agent:<12} -> {b}");
    }
    let _ = writeln!(out, "events:");
    for (t, agent, e) in s.events.iter().take(60) {
        let _ = writeln!(out, "  t={t:7.3}s {agent:<12} {e}");
    }
    if s.events.len() > 60 {
        let _ = writeln!(out, "  ... {} more in the log", s.events.len() - 60);
    }
    if let Some(f) = &s.failure {
        let _ = writeln!(out, "RUN FAILED: {f} (the agents were halted safely; the log is complete up to the failure)");
    }
    out
}
