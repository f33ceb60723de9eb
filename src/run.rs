//! `embodied run`: a scenario as a system of embodied agents in the simulated world.
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
use std::sync::Arc;
use std::time::{Duration, Instant};

use embodied_executor::deliberation::{
    AsDeliberation, DeliberationSettings, DeliberativeState, PlanBudget, PlanClock, PlanFollower, UnmappedObstacle,
};
use embodied_executor::{
    Agent, AgentId, Behaviour, Contact, Coordinator, InputImages, Message, OutputImages, Predicate, Primitive,
    Reactive, ReceptorSpec, Runtime, RuntimeConfig, SafeHalt, SensorConfig, Status, StepRecord, TransitionFunction,
    Violation,
};
use embodied_models::Robot;
use embodied_planner::deadline::Deadline;
use serde::Serialize;
use serde_json::json;

use crate::AppError;
use crate::plan::{agent_problem, bodies_as_obstacles, goal_of, motion_settings};
use crate::runlog::RunLog;
use crate::scenario::{ClockSpec, Coordination, GoalSpec, Scenario, load_scenario};

/// Message tags between agents and their coordinator.
const GO: u32 = 1;
const DONE: u32 = 2;
/// A chunk of a path: `[agent, waypoint, waypoints, offset, v0, v1, v2, v3]`.
const PATH: u32 = 3;
const CHUNK: usize = 4;

/// Largest joint step between the configurations that stand for another agent's swept volume.
pub const SWEEP_STEP: f64 = 0.02;

/// What `embodied run` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct RunArgs {
    pub scenario: String,
    pub duration: Option<f64>,
    pub seed: Option<u64>,
    pub log: Option<PathBuf>,
    pub plot: Option<PathBuf>,
    /// Write the viewer page (`embodied view`) of the run here.
    pub html: Option<PathBuf>,
    /// How planning time is counted (default: the scenario's `[planner] clock`).
    pub clock: Option<ClockSpec>,
    /// Closed-chain controller settings for a carry (default: the controller's defaults).
    pub closed_chain: Option<embodied_executor::closed_chain::ClosedChainConfig>,
    /// Solve every closed-chain QP with clarabel as well (`embodied bench qp`).
    pub qp_compare: bool,
}

/// The terminal/JSON summary of a run.
#[derive(Debug, Serialize)]
pub struct RunSummary {
    pub scenario: String,
    pub seed: u64,
    pub clock: String,
    pub steps: u64,
    pub simulated_s: f64,
    pub wall_s: f64,
    pub real_time_factor: f64,
    pub agents: Vec<AgentSummary>,
    /// (time, agent, event) in order.
    pub events: Vec<(f64, String, String)>,
    pub behaviour_switches: Vec<(f64, String, String)>,
    pub failure: Option<String>,
    pub log_lines: usize,
    /// The two-handed carry, when the scenario has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closed_chain: Option<crate::carry_run::ClosedChainSummary>,
    /// The carry's per-step measurements (not serialised).
    #[serde(skip)]
    pub closed_chain_record: Option<Arc<std::sync::Mutex<crate::carry_run::CarryRecord>>>,
}

#[derive(Debug, Serialize, Default)]
pub struct AgentSummary {
    pub name: String,
    /// A verified plan landed.
    pub planned: bool,
    /// Motion time of the last plan that landed, s.
    pub plan_duration_s: Option<f64>,
    /// Planning time of the last plan that landed (simulated or wall, as the clock), ms.
    pub planning_ms: Option<f64>,
    pub plans_requested: usize,
    pub plans_landed: usize,
    pub plans_rejected: usize,
    pub safe_halts: usize,
    pub replans: usize,
    pub goal_reached: bool,
    pub final_q: Vec<f64>,
    pub goal_error: Option<f64>,
    pub max_speed_ratio: f64,
}

/// The messages that carry `path` of scenario agent `agent`.
fn path_messages(agent: usize, path: &[Vec<f64>]) -> Vec<Message> {
    let mut out = Vec::new();
    for (i, q) in path.iter().enumerate() {
        for offset in (0..q.len()).step_by(CHUNK) {
            let mut data = vec![agent as f64, i as f64, path.len() as f64, offset as f64];
            data.extend(q[offset..(offset + CHUNK).min(q.len())].iter());
            out.push(Message::new(PATH, &data));
        }
    }
    out
}

/// Paths being received, per scenario agent.
#[derive(Default)]
struct PathInbox {
    partial: Vec<Vec<Vec<f64>>>,
}

impl PathInbox {
    fn new(agents: usize) -> Self {
        Self { partial: vec![Vec::new(); agents] }
    }

    /// Take a chunk; a complete path is returned with its agent.
    fn take(&mut self, m: &Message, dofs: &[usize]) -> Option<(usize, Vec<Vec<f64>>)> {
        let d = &m.data;
        let (agent, i, n, offset) = (d[0] as usize, d[1] as usize, d[2] as usize, d[3] as usize);
        let dof = *dofs.get(agent)?;
        if i >= n || offset >= dof {
            return None;
        }
        let buf = &mut self.partial[agent];
        if i == 0 && offset == 0 {
            *buf = vec![vec![f64::NAN; dof]; n];
        }
        let q = buf.get_mut(i)?;
        for (k, v) in d[4..].iter().enumerate().take(dof - offset) {
            q[offset + k] = *v;
        }
        let complete = i + 1 == n && offset + CHUNK >= dof;
        if complete && buf.iter().all(|q| q.iter().all(|v| v.is_finite())) {
            return Some((agent, std::mem::take(buf)));
        }
        None
    }
}

/// The scenario's agents as other agents see them.
struct Roster {
    names: Vec<String>,
    robots: Vec<Robot>,
    dofs: Vec<usize>,
}

/// `c_c` of a scenario agent: deliberation plus what the coordinator told it.
struct RunAgent {
    delib: DeliberativeState,
    index: usize,
    go: bool,
    coordinator: Option<AgentId>,
    roster: Arc<Roster>,
    /// Per scenario agent: the configurations it occupies, as far as this agent knows.
    occupancy: Vec<Vec<Vec<f64>>>,
    inbox: PathInbox,
    announced: Option<u64>,
    done_sent: bool,
    force_sensor: Option<usize>,
}

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

    /// Read the transmissions: the go, and other agents' bodies or planned sweeps.
    fn read_messages(&mut self, i: &InputImages, o: &mut OutputImages) {
        for env in i.messages() {
            match env.message.tag {
                GO => {
                    if !self.go {
                        o.event("go received");
                    }
                    self.go = true;
                }
                PATH => {
                    if let Some((m, path)) = self.inbox.take(&env.message, &self.roster.dofs) {
                        o.event(format!("told: `{}` occupies {} configuration(s)", self.roster.names[m], path.len()));
                        self.occupancy[m] = path;
                        let known = self.known_obstacles();
                        if self.delib.set_known_obstacles(known, i.step(), i.dt()) {
                            o.event("plan_invalidated: another agent's space in path");
                            o.event("replan reason=reserved_space");
                        }
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
                for m in path_messages(c.index, &waypoints) {
                    o.send(coordinator, m);
                }
            }
            let failed = c.delib.abandoned();
            if (c.delib.goal_reached() || failed) && !c.done_sent {
                c.done_sent = true;
                o.event(if failed { "task failed: no plan" } else { "plan completed" });
                o.send(coordinator, Message::new(DONE, &[f64::from(u8::from(failed))]));
            }
        } else if c.delib.goal_reached() && !c.done_sent {
            c.done_sent = true;
            o.event("plan completed");
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
                    o.event(format!("force limit: {:.1} N, plan abandoned", i.sensor(k).values[0]));
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
    paths: Vec<Vec<Vec<f64>>>,
    inbox: PathInbox,
    /// Agents granted so far.
    granted: usize,
    done: Vec<bool>,
    announced: Vec<bool>,
    all_done: bool,
}

impl Grants {
    fn grant(&mut self, o: &mut OutputImages) {
        let (id, k) = self.order[self.granted];
        // What the agents granted before it occupy: where they stand (sequential) or the space
        // their plans sweep (concurrent).
        for &(_, m) in &self.order[..self.granted] {
            let occupied = match self.mode {
                Coordination::Sequential => self.paths[m].last().cloned().into_iter().collect(),
                Coordination::Concurrent => self.paths[m].clone(),
            };
            for msg in path_messages(m, &occupied) {
                o.send(id, msg);
            }
        }
        o.send(id, Message::new(GO, &[]));
        o.event(format!("go -> {}", self.roster.names[k]));
        self.granted += 1;
    }
}

fn coordinator_program() -> Primitive<Grants> {
    Primitive::new("grant", 1, |c: &mut Grants, i: &InputImages, o: &mut OutputImages| {
        for env in i.messages() {
            let Some(k) = c.index_of.get(env.from.0).copied().flatten() else { continue };
            match env.message.tag {
                DONE => {
                    c.done[k] = true;
                    if env.message.data[0] != 0.0 {
                        o.event(format!("{} failed", c.roster.names[k]));
                    }
                }
                PATH => {
                    if let Some((m, path)) = c.inbox.take(&env.message, &c.roster.dofs) {
                        c.paths[m] = path;
                        c.announced[m] = true;
                    }
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
                c.grant(o);
            }
        }
        if !c.all_done && c.order.iter().all(|(_, k)| c.done[*k]) {
            c.all_done = true;
            o.event("all agents done");
        }
    })
}

fn agent_limits_json(robot: &Robot) -> serde_json::Value {
    let limits: Vec<serde_json::Value> = robot
        .limits()
        .iter()
        .map(|l| {
            json!({
                "lower": l.lower.is_finite().then_some(l.lower),
                "upper": l.upper.is_finite().then_some(l.upper),
                "max_velocity": l.max_velocity,
                "max_acceleration": l.max_acceleration,
            })
        })
        .collect();
    json!({"joint_names": robot.joint_names(), "limits": limits})
}

fn step_line(record: &StepRecord) -> serde_json::Value {
    let mut agents = serde_json::Map::new();
    for a in &record.agents {
        agents.insert(a.agent.clone(), json!({"q": a.q, "qd": a.qd, "behaviour": a.behaviour, "events": a.events}));
    }
    json!({"step": record.step, "t": record.time, "agents": agents})
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
        goal_tolerance: 1e-3,
        retry_after_steps: 100,
        max_attempts: 3,
        plan_timeout_steps: give_up_steps + 1000,
        obstacle_sensing: None,
        sensor_max_age: 50,
        move_tolerance: 0.02,
        halt_on_any_change: false,
    }
}

fn clock_name(clock: ClockSpec) -> String {
    match clock {
        ClockSpec::Wall => "wall".into(),
        ClockSpec::Simulated { us_per_check } => format!("simulated ({us_per_check} us per collision check)"),
    }
}

/// A field `key=value` of an event.
pub fn event_field(event: &str, key: &str) -> Option<f64> {
    let pat = format!("{key}=");
    let start = event.find(&pat)? + pat.len();
    let rest = &event[start..];
    let end = rest.find(|c: char| c.is_whitespace() || c == ':' || c == ',').unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// Run a scenario; the log (if asked for) is complete up to the last step even on failure.
pub fn run_scenario(args: &RunArgs) -> Result<RunSummary, AppError> {
    let scenario = load_scenario(&args.scenario)?;
    let duration = match args.duration {
        Some(d) if d.is_finite() && d > 0.0 => d,
        Some(d) => return Err(AppError::Usage(format!("--duration must be a positive number of seconds, got {d}"))),
        None => scenario.run.duration.unwrap_or(6.0),
    };
    let seed = args.seed.unwrap_or(scenario.seed);
    let clock = args.clock.unwrap_or(scenario.planner.clock);
    let dt = 0.001;
    let mut runtime = Runtime::new(RuntimeConfig { dt, seed, ..RuntimeConfig::default() });
    let mut mapped = Vec::new();
    for o in &scenario.obstacles {
        let (c, r) = o.obstacle.shape.bounding_sphere();
        let p = o.obstacle.pose * c;
        let id = runtime.world_mut().add_obstacle(embodied_executor::Obstacle {
            name: o.obstacle.name.clone(),
            position: [p.x, p.y, p.z],
            velocity: o.velocity.map_or([0.0; 3], |v| [v.x, v.y, v.z]),
            radius: r,
            appears_at: o.appear_at.map_or(0, |t| (t / dt).round().max(0.0) as u64),
            vanishes_at: None,
        });
        if o.on_map() {
            mapped.push(id);
        }
    }
    let sensing = scenario.obstacles.iter().any(|o| !o.on_map());
    let roster = Arc::new(Roster {
        names: scenario.agents.iter().map(|a| a.name.clone()).collect(),
        robots: scenario.agents.iter().map(|a| a.robot.clone()).collect(),
        dofs: scenario.agents.iter().map(|a| a.robot.dof()).collect(),
    });
    let starts: Vec<Vec<Vec<f64>>> = scenario.agents.iter().map(|a| vec![a.start.clone()]).collect();
    let planners: Vec<usize> = (0..scenario.agents.len()).filter(|&k| scenario.agents[k].goal.is_some()).collect();
    let coordinated = planners.len() > 1;
    let coordinator_id = AgentId(scenario.agents.len());
    let mut settings = deliberation_settings(&scenario, clock, dt);
    if sensing {
        settings.obstacle_sensing = Some(f64::INFINITY);
    }
    let mut carry = None;
    for (k, agent) in scenario.agents.iter().enumerate() {
        let robot = Arc::new(agent.robot.clone());
        if scenario.carry.as_ref().is_some_and(|c| c.agent == k) {
            let (a, record, header) =
                crate::carry_run::carry_agent(&scenario, dt, clock, args.closed_chain.clone(), args.qp_compare)?;
            runtime.add_agent(a);
            carry = Some((record, header));
            continue;
        }
        let Some(goal) = &agent.goal else {
            // No goal: it holds where it stands.
            let hold = Primitive::new("hold", 1, |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                RunAgent::hold(i, o);
            });
            let a = Agent::embodied(agent.name.clone(), robot, Some(&agent.start), (), hold)
                .map_err(|e| AppError::Failed(format!("agent `{}`: {e}", agent.name)))?;
            runtime.add_agent(a);
            continue;
        };
        let force_limit = agent.behaviour.as_ref().and_then(|b| b.get("force_limit")).and_then(|v| v.as_float());
        // The map: the obstacles there from the start, the other agents where they stand.
        let model = agent_problem(&scenario, k, &[]);
        let delib = DeliberativeState::new(robot.clone(), model, goal_of(goal), settings.clone());
        let mut state = RunAgent {
            delib,
            index: k,
            go: !coordinated,
            coordinator: coordinated.then_some(coordinator_id),
            roster: roster.clone(),
            occupancy: starts.clone(),
            inbox: PathInbox::new(scenario.agents.len()),
            announced: None,
            done_sent: false,
            force_sensor: None,
        };
        let known = state.known_obstacles();
        state.delib.set_known_obstacles(known, 0, dt);
        let mut receptors = ReceptorSpec::default();
        let mut sensors = 0;
        if sensing {
            receptors.detector_range = Some(f64::INFINITY);
            sensors += 1;
        }
        if let Some(_limit) = force_limit {
            receptors.force_stiffness = Some(2.0e4);
            receptors.force_noise = 0.5;
            state.force_sensor = Some(sensors);
        }
        let mut a = Agent::embodied(agent.name.clone(), robot, Some(&agent.start), state, program(force_limit))
            .map_err(|e| AppError::Failed(format!("agent `{}`: {e}", agent.name)))?;
        if sensing {
            a = a.with_sensor(UnmappedObstacle { mapped: mapped.clone() }, SensorConfig::default());
        }
        if let Some(limit) = force_limit {
            a = a.with_sensor(Contact, SensorConfig { threshold: limit, ..SensorConfig::default() });
        }
        if sensing || force_limit.is_some() {
            a = a.with_receptors(receptors);
        }
        runtime.add_agent(a);
    }
    if coordinated {
        let order: Vec<(AgentId, usize)> = planners.iter().map(|&k| (AgentId(k), k)).collect();
        let mut index_of = vec![None; scenario.agents.len() + 1];
        for &k in &planners {
            index_of[k] = Some(k);
        }
        let n = scenario.agents.len();
        let id = runtime.add_agent(Coordinator::new(
            "coordinator",
            Grants {
                mode: scenario.run.coordination,
                order,
                index_of,
                roster: roster.clone(),
                paths: starts.clone(),
                inbox: PathInbox::new(n),
                granted: 0,
                done: vec![false; n],
                announced: vec![false; n],
                all_done: false,
            },
            coordinator_program(),
        ));
        debug_assert_eq!(id, coordinator_id);
        for &k in &planners {
            runtime
                .connect_both(id, AgentId(k), embodied_executor::Link::IDEAL)
                .map_err(|e| AppError::Failed(e.to_string()))?;
        }
    }

    let mut log = RunLog::create(args.log.as_deref())?;
    let mut header_agents = serde_json::Map::new();
    for agent in &scenario.agents {
        header_agents.insert(agent.name.clone(), agent_limits_json(&agent.robot));
    }
    log.line(&json!({"header": {
        "generator": crate::generator(),
        "scenario": scenario.name, "scenario_hash": scenario.hash, "seed": seed, "step_s": dt,
        "duration_s": duration, "planning_clock": clock_name(clock), "agents": header_agents,
        "closed_chain": carry.as_ref().map(|(_, h)| h),
    }}))?;

    let steps = (duration / dt).round() as u64;
    let started = Instant::now();
    let mut events = Vec::new();
    let mut switches = Vec::new();
    let mut last_behaviour: Vec<String> = vec![String::new(); scenario.agents.len() + usize::from(coordinated)];
    let mut summaries: Vec<AgentSummary> =
        scenario.agents.iter().map(|a| AgentSummary { name: a.name.clone(), ..AgentSummary::default() }).collect();
    let mut pending = vec![false; scenario.agents.len()];
    let mut pace: Option<(Instant, u64)> = None;
    let mut log_error = None;
    let mut track = crate::view::Track::default();
    let mut on_record = |r: &StepRecord| {
        if log_error.is_none()
            && let Err(e) = log.line(&step_line(r))
        {
            log_error = Some(e);
        }
        if (args.html.is_some() || args.plot.is_some()) && r.step.is_multiple_of(5) {
            let q = r.agents.iter().take(scenario.agents.len()).map(|a| Some(a.q.clone())).collect();
            track.frames.push(crate::view::TrackFrame { t: r.time, q });
        }
        for (k, a) in r.agents.iter().enumerate() {
            for e in &a.events {
                events.push((r.time, a.agent.clone(), e.clone()));
                if k < summaries.len() {
                    tally(&mut summaries[k], &mut pending[k], e);
                }
            }
            if last_behaviour[k] != a.behaviour {
                switches.push((r.time, a.agent.clone(), a.behaviour.clone()));
                last_behaviour[k] = a.behaviour.clone();
            }
            if k < scenario.agents.len() {
                let limits = scenario.agents[k].robot.limits();
                for (j, &qd) in a.qd.iter().enumerate() {
                    summaries[k].max_speed_ratio = summaries[k].max_speed_ratio.max(qd.abs() / limits[j].max_velocity);
                }
            }
        }
        // Wall clock: while a plan is being computed, a step takes a step's time, so that the
        // deadline in steps and the planner's wall-clock deadline mean the same.
        if clock == ClockSpec::Wall && pending.iter().any(|p| *p) {
            let (t0, s0) = *pace.get_or_insert((Instant::now(), r.step));
            let due = t0 + Duration::from_secs_f64((r.step + 1 - s0) as f64 * dt);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        } else {
            pace = None;
        }
    };
    let result = runtime.run(steps, &mut on_record);
    let wall = started.elapsed().as_secs_f64();
    if let Some(e) = log_error {
        return Err(e);
    }
    let last = runtime.last_record().clone();
    let failure = result.err().map(|e| e.to_string());
    for (k, a) in scenario.agents.iter().enumerate() {
        let final_q = last.agents.get(k).map(|r| r.q.clone()).unwrap_or_default();
        summaries[k].goal_error = match &a.goal {
            Some(GoalSpec::Configuration(g)) if g.len() == final_q.len() => {
                Some(a.robot.config_space().distance(g, &final_q))
            }
            _ => None,
        };
        summaries[k].final_q = final_q;
    }
    let mut summary = RunSummary {
        scenario: scenario.name.clone(),
        seed,
        clock: clock_name(clock),
        steps: runtime.current_step(),
        simulated_s: runtime.current_step() as f64 * dt,
        wall_s: wall,
        real_time_factor: runtime.current_step() as f64 * dt / wall.max(1e-9),
        agents: summaries,
        events,
        behaviour_switches: switches,
        failure,
        log_lines: 0,
        closed_chain: carry.as_ref().and_then(|(r, _)| crate::carry_run::finish(r)),
        closed_chain_record: carry.as_ref().map(|(r, _)| r.clone()),
    };
    log.line(&json!({"summary": &summary}))?;
    summary.log_lines = log.lines();
    let track = crate::view::with_events(track, &summary.events);
    if let Some(path) = &args.plot {
        crate::plot::plot_run(path, &scenario, &track)?;
    }
    if let Some(path) = &args.html {
        crate::view::write_run_view(path, &scenario, &track)?;
    }
    Ok(summary)
}

/// Count one event of a scenario agent into its summary.
fn tally(s: &mut AgentSummary, pending: &mut bool, e: &str) {
    if e.starts_with("plan_requested") {
        s.plans_requested += 1;
        *pending = true;
    } else if e.starts_with("plan_landed") {
        s.plans_landed += 1;
        s.planned = true;
        s.planning_ms = event_field(e, "planning_ms");
        s.plan_duration_s = event_field(e, "duration_s");
        *pending = false;
    } else if e.starts_with("plan_rejected") {
        s.plans_rejected += 1;
        *pending = false;
    } else if ["plan_failed", "planner_panicked", "plan_discarded_stale", "plan_lost"].iter().any(|p| e.starts_with(p))
    {
        *pending = false;
    } else if e.starts_with("safe_halt_started") {
        s.safe_halts += 1;
    } else if e.starts_with("replan") {
        s.replans += 1;
    } else if e.starts_with("goal_reached") {
        s.goal_reached = true;
    }
}

/// Human-readable summary.
pub fn render_summary(s: &RunSummary) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "scenario {} (seed {}, planning clock: {}): {} steps, {:.3} s simulated in {:.3} s wall, real-time factor {:.1}",
        s.scenario, s.seed, s.clock, s.steps, s.simulated_s, s.wall_s, s.real_time_factor
    );
    for a in &s.agents {
        let plan = match (a.planning_ms, a.plan_duration_s) {
            (Some(ms), Some(d)) => format!("last plan in {ms:.2} ms, {d:.2} s of motion"),
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
            "  closed chain ({}): plan {:.1} ms wall, {:.2} s of motion; held {} steps; QP p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} late, {} fallbacks, {} slacked); largest closure error {:.2e} m / {:.2e} rad (residual {:.1e}); object tracking {:.2e} m; nearest obstacle {:.3} m ({} damped steps); halts {}{}; object put down {} from its goal",
            c.agent,
            c.planning_ms,
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
