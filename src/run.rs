//! `embodied run`: a scenario as a system of embodied agents in the simulated world.
//!
//! Each scenario agent with a goal gets a plan from deliberation before the run (offline plan
//! generation; deliberation under deadlines *during* a run is `embodied_executor::deliberation`)
//! and a behaviour that follows it: a priority list (subsumption) of a force-limited reaction,
//! waiting for the coordinator's go, holding when done, and the main reaction that tracks the
//! plan. When a scenario has several agents, a coordinator (an agent with no effector) lets them
//! move one after the other and each plan accounts for where the others will be.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use embodied_executor::{
    Agent, AgentId, Contact, Coordinator, Message, Predicate, Primitive, Reactive, ReceptorSpec, Runtime,
    RuntimeConfig, SensorConfig, StepRecord,
};
use embodied_models::Robot;
use embodied_models::collision::{CollisionModel, Environment};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{Goal, MotionSettings, plan_motion};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use serde::Serialize;
use serde_json::json;

use crate::AppError;
use crate::runlog::{RunLog, plot_joints};
use crate::scenario::{GoalSpec, Scenario, load_scenario};

/// Message tags between agents and their coordinator.
const GO: u32 = 1;
const DONE: u32 = 2;

/// What `embodied run` was asked to do.
#[derive(Debug, Clone)]
pub struct RunArgs {
    pub scenario: String,
    pub duration: Option<f64>,
    pub seed: Option<u64>,
    pub log: Option<PathBuf>,
    pub plot: Option<PathBuf>,
}

/// The terminal/JSON summary of a run.
#[derive(Debug, Serialize)]
pub struct RunSummary {
    pub scenario: String,
    pub seed: u64,
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
}

#[derive(Debug, Serialize)]
pub struct AgentSummary {
    pub name: String,
    pub planned: bool,
    pub plan_duration_s: Option<f64>,
    pub planning_ms: Option<f64>,
    pub final_q: Vec<f64>,
    pub goal_error: Option<f64>,
    pub max_speed_ratio: f64,
}

/// c_c of a plan-following agent.
struct Follow {
    plan: Option<Trajectory>,
    /// Time at which following started (when the go arrived).
    started: Option<f64>,
    go: bool,
    done_sent: bool,
    coordinator: Option<AgentId>,
}

impl Follow {
    fn finished(&self, t: f64) -> bool {
        match (&self.plan, self.started) {
            (Some(p), Some(t0)) => t - t0 >= p.duration(),
            (None, _) => true,
            _ => false,
        }
    }
}

fn follower(force_limit: Option<f64>) -> Reactive<Follow> {
    let hold = |_: &mut Follow, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
        let q = i.q().to_vec();
        o.set_position_target(&q, &vec![0.0; q.len()]);
    };
    let mut program = Reactive::priority("main");
    if force_limit.is_some() {
        // Force-limited reaction: contact above the limit suppresses the plan follower; the arm
        // stops where it is and reports it.
        program = program.rule(
            Predicate::new("force_over_limit", |_: &Follow, i| i.sensor_count() > 0 && i.sensor(0).values[1] > 0.5),
            Primitive::new(
                "force_stop",
                1,
                move |c: &mut Follow, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
                    hold(c, i, o);
                    if c.plan.is_some() {
                        o.event(format!("force limit: {:.1} N, plan abandoned", i.sensor(0).values[0]));
                        c.plan = None;
                    }
                },
            ),
        );
    }
    program
        .rule(
            Predicate::new("awaiting_go", |c: &Follow, _| !c.go),
            Primitive::new(
                "wait_for_go",
                1,
                move |c: &mut Follow, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
                    hold(c, i, o);
                    if i.messages().iter().any(|m| m.message.tag == GO) {
                        c.go = true;
                        o.event("go received");
                    }
                },
            ),
        )
        .rule(
            Predicate::new("plan_done", |c: &Follow, i| c.started.is_some() && c.finished(i.step() as f64 * i.dt())),
            Primitive::new(
                "hold",
                1,
                move |c: &mut Follow, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
                    let end = c.plan.as_ref().and_then(|p| p.q.last().cloned());
                    match end {
                        Some(q) => o.set_position_target(&q, &vec![0.0; q.len()]),
                        None => hold(c, i, o),
                    }
                    if !c.done_sent {
                        c.done_sent = true;
                        o.event("plan completed");
                        if let Some(coord) = c.coordinator {
                            o.send(coord, Message::new(DONE, &[]));
                        }
                    }
                },
            ),
        )
        .main_reaction(Primitive::new(
            "follow_plan",
            1,
            move |c: &mut Follow, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
                let t = i.step() as f64 * i.dt();
                let t0 = *c.started.get_or_insert(t);
                match &c.plan {
                    Some(p) => {
                        let (q, qd, _) = p.sample(t - t0 + i.dt());
                        o.set_position_target(&q, &qd);
                    }
                    None => hold(c, i, o),
                }
            },
        ))
}

/// c_c of the coordinator: whose turn it is.
struct Sequencer {
    order: Vec<AgentId>,
    next: usize,
    waiting: bool,
}

fn sequencer() -> Primitive<Sequencer> {
    Primitive::new(
        "sequence",
        1,
        |c: &mut Sequencer, i: &embodied_executor::InputImages, o: &mut embodied_executor::OutputImages| {
            if c.waiting && i.messages().iter().any(|m| m.message.tag == DONE) {
                c.waiting = false;
                c.next += 1;
            }
            if !c.waiting && c.next < c.order.len() {
                o.send(c.order[c.next], Message::new(GO, &[]));
                o.event(format!("go -> agent {}", c.order[c.next].0));
                c.waiting = true;
            } else if !c.waiting && c.next == c.order.len() {
                o.event("all agents done");
                c.next += 1;
            }
        },
    )
}

/// Where each agent's body is, as obstacles for the others' planning.
fn bodies_as_obstacles(robot: &Robot, q: &[f64], env: &mut Environment, prefix: &str) {
    let model = CollisionModel::new(robot, Environment::new());
    for mut o in model.link_shapes_world(q) {
        o.name = format!("{prefix}/{}", o.name);
        env.add(o);
    }
}

/// Plan every agent's motion before the run, in coordinator order.
/// Each agent's trajectory (if it has a goal) and how long planning took, ms.
type Plans = Vec<(Option<Trajectory>, Option<f64>)>;

fn plan_all(scenario: &Scenario, dt: f64) -> Result<Plans, AppError> {
    let mut out = Vec::new();
    // Where each agent will be when the ones before it have finished.
    let mut resting: Vec<Vec<f64>> = scenario.agents.iter().map(|a| a.start.clone()).collect();
    for (k, agent) in scenario.agents.iter().enumerate() {
        let Some(goal) = &agent.goal else {
            out.push((None, None));
            continue;
        };
        let mut env = scenario.initial_environment();
        for (m, other) in scenario.agents.iter().enumerate() {
            if m != k {
                bodies_as_obstacles(&other.robot, &resting[m], &mut env, &other.name);
            }
        }
        let model = CollisionModel::new(&agent.robot, env);
        let goal = match goal {
            GoalSpec::Configuration(q) => Goal::Configuration(q.clone()),
            GoalSpec::AnyOf(qs) => Goal::AnyOf(qs.clone()),
            GoalSpec::ToolPose { end_effector, pose } => Goal::ToolPose { end_effector: *end_effector, pose: *pose },
        };
        let settings = MotionSettings {
            seed: scenario.planner.seed,
            resolution: scenario.planner.resolution,
            deadline: Deadline::after(std::time::Duration::from_secs_f64(scenario.planner.deadline_ms / 1000.0)),
            ..MotionSettings::default()
        };
        let t = Instant::now();
        let plan = plan_motion(&model, &agent.start, &goal, &settings).map_err(|e| {
            AppError::Failed(format!("scenario `{}`: agent `{}`: planning failed: {e}", scenario.name, agent.name))
        })?;
        let planning_ms = t.elapsed().as_secs_f64() * 1e3;
        let traj = time_parameterize(&plan.path, &agent.robot, dt);
        if let Some(last) = plan.path.last() {
            resting[k] = last.clone();
        }
        out.push((Some(traj), Some(planning_ms)));
    }
    Ok(out)
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

/// Run a scenario; the log (if asked for) is complete up to the last step even on failure.
pub fn run_scenario(args: &RunArgs) -> Result<RunSummary, AppError> {
    let scenario = load_scenario(&args.scenario)?;
    let run_table = scenario.run.clone().unwrap_or_default();
    let duration = match args.duration {
        Some(d) if d.is_finite() && d > 0.0 => d,
        Some(d) => return Err(AppError::Usage(format!("--duration must be a positive number of seconds, got {d}"))),
        None => {
            run_table.get("duration").and_then(|v| v.as_float().or(v.as_integer().map(|i| i as f64))).unwrap_or(6.0)
        }
    };
    let seed = args.seed.unwrap_or(scenario.seed);
    let dt = 0.001;
    let plans = plan_all(&scenario, dt)?;
    let mut runtime = Runtime::new(RuntimeConfig { dt, seed, ..RuntimeConfig::default() });
    for o in &scenario.obstacles {
        let (c, r) = o.obstacle.shape.bounding_sphere();
        let p = o.obstacle.pose * c;
        runtime.world_mut().add_obstacle(embodied_executor::Obstacle {
            name: o.obstacle.name.clone(),
            position: [p.x, p.y, p.z],
            velocity: o.velocity.map_or([0.0; 3], |v| [v.x, v.y, v.z]),
            radius: r,
            appears_at: o.appear_at.map_or(0, |t| (t / dt).round().max(0.0) as u64),
            vanishes_at: None,
        });
    }
    let coordinated = scenario.agents.len() > 1;
    let coordinator_id = AgentId(scenario.agents.len());
    let mut ids = Vec::new();
    for (agent, (plan, _)) in scenario.agents.iter().zip(&plans) {
        let robot = Arc::new(agent.robot.clone());
        let force_limit = agent.behaviour.as_ref().and_then(|b| b.get("force_limit")).and_then(|v| v.as_float());
        let state = Follow {
            plan: plan.clone(),
            started: None,
            go: !coordinated,
            done_sent: false,
            coordinator: coordinated.then_some(coordinator_id),
        };
        let mut a = Agent::embodied(agent.name.clone(), robot, Some(&agent.start), state, follower(force_limit))
            .map_err(|e| AppError::Failed(format!("agent `{}`: {e}", agent.name)))?;
        if let Some(limit) = force_limit {
            a = a.with_sensor(Contact, SensorConfig { threshold: limit, ..SensorConfig::default() }).with_receptors(
                ReceptorSpec { force_stiffness: Some(2.0e4), force_noise: 0.5, ..ReceptorSpec::default() },
            );
        }
        ids.push(runtime.add_agent(a));
    }
    if coordinated {
        let order = ids.clone();
        let id = runtime.add_agent(Coordinator::new(
            "coordinator",
            Sequencer { order, next: 0, waiting: false },
            sequencer(),
        ));
        debug_assert_eq!(id, coordinator_id);
        for &a in &ids {
            runtime.connect_both(id, a, embodied_executor::Link::IDEAL).map_err(|e| AppError::Failed(e.to_string()))?;
        }
    }

    let mut log = RunLog::create(args.log.as_deref())?;
    let mut header_agents = serde_json::Map::new();
    for agent in &scenario.agents {
        header_agents.insert(agent.name.clone(), agent_limits_json(&agent.robot));
    }
    log.line(&json!({"header": {
        "scenario": scenario.name, "scenario_hash": scenario.hash, "seed": seed, "step_s": dt,
        "duration_s": duration, "agents": header_agents,
    }}))?;

    let steps = (duration / dt).round() as u64;
    let started = Instant::now();
    let mut events = Vec::new();
    let mut switches = Vec::new();
    let mut last_behaviour: Vec<String> = vec![String::new(); scenario.agents.len() + usize::from(coordinated)];
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for agent in &scenario.agents {
        for name in agent.robot.joint_names() {
            series.push((format!("{}/{name}", agent.name), Vec::new()));
        }
    }
    let mut max_ratio = vec![0.0f64; scenario.agents.len()];
    let mut log_error = None;
    let mut on_record = |r: &StepRecord| {
        if log_error.is_none()
            && let Err(e) = log.line(&step_line(r))
        {
            log_error = Some(e);
        }
        let mut s = 0;
        for (k, a) in r.agents.iter().enumerate() {
            for e in &a.events {
                events.push((r.time, a.agent.clone(), e.clone()));
            }
            if last_behaviour[k] != a.behaviour {
                switches.push((r.time, a.agent.clone(), a.behaviour.clone()));
                last_behaviour[k] = a.behaviour.clone();
            }
            if k < scenario.agents.len() {
                let limits = scenario.agents[k].robot.limits();
                for (j, (&q, &qd)) in a.q.iter().zip(&a.qd).enumerate() {
                    max_ratio[k] = max_ratio[k].max(qd.abs() / limits[j].max_velocity);
                    if r.step.is_multiple_of(10) {
                        series[s].1.push((r.time, q));
                    }
                    s += 1;
                }
            }
        }
    };
    let result = runtime.run(steps, &mut on_record);
    let wall = started.elapsed().as_secs_f64();
    if let Some(e) = log_error {
        return Err(e);
    }
    let last = runtime.last_record().clone();
    let failure = result.err().map(|e| e.to_string());
    let agents = scenario
        .agents
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let final_q = last.agents.get(k).map(|r| r.q.clone()).unwrap_or_default();
            let goal_error = match &a.goal {
                Some(GoalSpec::Configuration(g)) => Some(a.robot.config_space().distance(g, &final_q)),
                _ => None,
            };
            AgentSummary {
                name: a.name.clone(),
                planned: plans[k].0.is_some(),
                plan_duration_s: plans[k].0.as_ref().map(|p| p.duration()),
                planning_ms: plans[k].1,
                final_q,
                goal_error,
                max_speed_ratio: max_ratio[k],
            }
        })
        .collect();
    let summary = RunSummary {
        scenario: scenario.name.clone(),
        seed,
        steps: runtime.current_step(),
        simulated_s: runtime.current_step() as f64 * dt,
        wall_s: wall,
        real_time_factor: runtime.current_step() as f64 * dt / wall.max(1e-9),
        agents,
        events,
        behaviour_switches: switches,
        failure,
        log_lines: 0,
    };
    let mut summary = summary;
    log.line(&json!({"summary": &summary}))?;
    summary.log_lines = log.lines();
    if let Some(path) = &args.plot {
        plot_joints(path, &format!("{}: joint positions", scenario.name), &series, "q [rad | m]")?;
    }
    Ok(summary)
}

/// Human-readable summary.
pub fn render_summary(s: &RunSummary) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "scenario {} (seed {}): {} steps, {:.3} s simulated in {:.3} s wall, real-time factor {:.1}",
        s.scenario, s.seed, s.steps, s.simulated_s, s.wall_s, s.real_time_factor
    );
    for a in &s.agents {
        let plan = match (a.planning_ms, a.plan_duration_s) {
            (Some(ms), Some(d)) => format!("planned in {ms:.2} ms, {d:.2} s of motion"),
            _ => "no plan".to_string(),
        };
        let goal = a.goal_error.map_or(String::new(), |e| format!(", distance to goal {e:.4}"));
        let _ = writeln!(out, "  agent {:<12} {plan}{goal}, peak |qd|/vmax {:.2}", a.name, a.max_speed_ratio);
    }
    let _ = writeln!(out, "behaviour switches:");
    for (t, agent, b) in &s.behaviour_switches {
        let _ = writeln!(out, "  t={t:7.3}s {agent:<12} -> {b}");
    }
    let _ = writeln!(out, "events:");
    for (t, agent, e) in s.events.iter().take(50) {
        let _ = writeln!(out, "  t={t:7.3}s {agent:<12} {e}");
    }
    if s.events.len() > 50 {
        let _ = writeln!(out, "  ... {} more in the log", s.events.len() - 50);
    }
    if let Some(f) = &s.failure {
        let _ = writeln!(out, "RUN FAILED: {f} (the agents were halted safely; the log is complete up to the failure)");
    }
    out
}
