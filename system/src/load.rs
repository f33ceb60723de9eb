//! `embodied bench load`: many agents on one runtime, a share of them deliberative, all asking
//! one bounded [`PlanQueue`] for their plans.
//!
//! Reactive agents track a sine on joint 1 (a rule halts them if they move too fast).
//! Deliberative agents run errands: each goal reached, the next one is set (joint 1 swings
//! between two angles), so each asks for a plan every errand; all ask at step 1 at once. Every
//! agent drives the RNT robot, with a pillar beside it on the map. The queue serves requests
//! with `workers` planners by its policy in simulated planning time (2 µs per collision check by
//! default), so the figures are the same on every machine except the wall-clock ones: the
//! step's wall time and the real-time factor (simulated time / wall time; above 1 the 1 ms step
//! is kept in real time).
//!
//! By default the queue has planner threads of its own ([`PlanQueue::with_worker_threads`]): the
//! control step only puts requests in the queue and takes the answers, the planners run beside
//! it. `planner_threads: false` runs them inside the steps, on the control thread, as before.
//! Both give the same events and queue figures (the queue's timeline is simulated); only the
//! wall-clock figures differ.
//!
//! The promise checked: every request is answered (a plan or a failure delivered) by its
//! deadline, or its agent gets `plan_late` at the deadline and halts safely until the answer
//! comes; no agent goes without a plan for the whole run.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use embodied_executor::deliberation::{
    AsDeliberation, DeliberationSettings, DeliberativeState, PlanBudget, PlanClock, PlanFollower, PlanQueue,
    QueuePolicy,
};
use embodied_executor::{
    Agent, Behaviour, Event, InputImages, JointState, OutputImages, Parallelism, Predicate, Primitive, Reactive,
    ReceptorSpec, Runtime, RuntimeConfig, SafeHalt, SensorConfig, Status, Violation,
};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::{Robot, Shape};
use embodied_planner::motion::Goal;
use nalgebra::Isometry3;
use serde::Serialize;

use crate::SystemError;

/// What to run.
#[derive(Debug, Clone)]
pub struct LoadSettings {
    /// Agents in all.
    pub agents: usize,
    /// Share of them that deliberate (0..=1).
    pub deliberative_share: f64,
    /// Planner workers serving the queue.
    pub workers: usize,
    /// The queue's order.
    pub policy: QueuePolicy,
    /// Simulated seconds.
    pub duration_s: f64,
    /// When a plan is needed, ms after its request.
    pub deadline_ms: f64,
    /// When a request is given up, ms after it.
    pub give_up_ms: f64,
    /// Simulated planning time per collision check, µs.
    pub us_per_check: f64,
    /// Step the agents in parallel (rayon) or one after the other.
    pub parallel: bool,
    /// Plan on the queue's own planner threads (else inside the steps, on the control thread).
    pub planner_threads: bool,
    /// Seed of the planners and the noise.
    pub seed: u64,
}

impl Default for LoadSettings {
    fn default() -> Self {
        Self {
            agents: 1000,
            deliberative_share: 0.5,
            workers: 2,
            policy: QueuePolicy::EarliestDeadline,
            duration_s: 3.0,
            deadline_ms: 50.0,
            give_up_ms: 500.0,
            us_per_check: 2.0,
            parallel: true,
            planner_threads: true,
            seed: 1,
        }
    }
}

/// What happened.
#[derive(Debug, Clone, Serialize)]
pub struct LoadReport {
    /// Agents in all.
    pub agents: usize,
    /// Deliberative agents.
    pub deliberative: usize,
    /// Planner workers.
    pub workers: usize,
    /// Queue order.
    pub policy: QueuePolicy,
    /// Steps run.
    pub steps: u64,
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Simulated time / wall time.
    pub real_time_factor: f64,
    /// Wall time of a step: median, 99th percentile, largest, µs.
    pub step_p50_us: f64,
    /// 99th percentile.
    pub step_p99_us: f64,
    /// Largest.
    pub step_max_us: f64,
    /// Steps whose wall time exceeded the 1 ms step.
    pub steps_over_1ms: u64,
    /// Plan requests (`plan_requested`).
    pub requests: u64,
    /// Plans landed by their deadline.
    pub landed_in_time: u64,
    /// Plans landed after their deadline (the agent had halted).
    pub landed_late: u64,
    /// Failures delivered (out of time included).
    pub failed: u64,
    /// `plan_late` events: a deadline passed without an answer, the agent halted.
    pub late: u64,
    /// Halts started (any reason).
    pub halts: u64,
    /// Requests whose deadline passed with neither an answer nor `plan_late`: must be 0.
    pub unanswered_without_halt: u64,
    /// Goals reached (errands done).
    pub goals_reached: u64,
    /// Fewest and most plans landed by one deliberative agent.
    pub min_plans_per_agent: u64,
    /// Most.
    pub max_plans_per_agent: u64,
    /// Deliberative agents that never got a plan: must be 0.
    pub starved_agents: usize,
    /// The queue: requests planned, given up, withdrawn.
    pub queue_planned: u64,
    /// Given up (waited or planned past the give-up step).
    pub queue_expired: u64,
    /// Withdrawn.
    pub queue_withdrawn: u64,
    /// Wait for a worker: median, 99th percentile, largest, ms.
    pub wait_p50_ms: f64,
    /// 99th percentile.
    pub wait_p99_ms: f64,
    /// Largest.
    pub wait_max_ms: f64,
    /// Most requests waiting at once.
    pub max_waiting: usize,
    /// Wall time spent planning, s (on the planner threads, or inside the steps).
    pub planning_wall_s: f64,
    /// Planner threads of the queue (0: planning ran inside the steps, on the control thread).
    pub planner_threads: usize,
    /// Answers the simulated timeline reached before a planner thread had them: the step waited.
    pub worker_waits: u64,
    /// Wall time the steps waited for planner threads, s.
    pub worker_wait_wall_s: f64,
}

/// `c_c` of an errand runner: the deliberation and the goals it visits in turn.
struct Errands {
    state: DeliberativeState,
    goals: Vec<Vec<f64>>,
    next: usize,
}

impl AsDeliberation for Errands {
    fn deliberation(&mut self) -> &mut DeliberativeState {
        &mut self.state
    }
}

/// The plan follower; each goal reached, the next goal is set.
struct RunErrands {
    follower: PlanFollower,
}

impl Behaviour<Errands> for RunErrands {
    fn name(&self) -> &str {
        "errands"
    }

    fn step(
        &mut self,
        cc: &mut Errands,
        inputs: &InputImages,
        outputs: &mut OutputImages,
    ) -> Result<Status, Violation> {
        let status = self.follower.step(cc, inputs, outputs)?;
        if cc.state.goal_reached() {
            cc.next = (cc.next + 1) % cc.goals.len();
            let goal = Goal::Configuration(cc.goals[cc.next].clone());
            cc.state.set_goal(goal, inputs.step() + 1, inputs.dt());
        }
        Ok(status)
    }

    fn reset(&mut self) {
        Behaviour::<Errands>::reset(&mut self.follower);
    }

    fn describe(&self, out: &mut String) {
        out.push_str("errands/");
        Behaviour::<Errands>::describe(&self.follower, out);
    }
}

fn reactive(k: usize, robot: &Arc<Robot>) -> Result<Agent<()>, SystemError> {
    let phase = k as f64 * 0.01;
    let dof = robot.dof();
    let home = robot.home().to_vec();
    let program = Reactive::priority("reactive")
        .rule(
            Predicate::new("too-fast", |_: &(), i: &InputImages| i.qd().iter().any(|v| v.abs() > 10.0)),
            Primitive::new("halt", 1, SafeHalt),
        )
        .main_reaction(Primitive::new("track", 1, move |_: &mut (), i: &InputImages, o: &mut OutputImages| {
            let mut q = home.clone();
            q[0] += 0.3 * (i.step() as f64 * 0.002 + phase).sin();
            o.set_position_target(&q, &vec![0.0; dof]);
        }));
    let agent = Agent::embodied(format!("reactive{k}"), robot.clone(), None, (), program)
        .map_err(|e| SystemError::Failed(e.to_string()))?
        .with_sensor(JointState, SensorConfig::default())
        .with_receptors(ReceptorSpec { encoder_noise: 1e-5, ..ReceptorSpec::default() });
    Ok(agent)
}

/// Run the load benchmark.
pub fn run_load(settings: &LoadSettings) -> Result<LoadReport, SystemError> {
    if settings.agents == 0 || settings.workers == 0 {
        return Err(SystemError::Usage("--agents and --workers must be at least 1".into()));
    }
    if !(0.0..=1.0).contains(&settings.deliberative_share) {
        return Err(SystemError::Usage(format!(
            "--deliberative-share must be between 0 and 1, got {}",
            settings.deliberative_share
        )));
    }
    for (what, v) in [
        ("--deadline-ms", settings.deadline_ms),
        ("--give-up-ms", settings.give_up_ms),
        ("--duration", settings.duration_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(SystemError::Usage(format!("{what} must be a positive number, got {v}")));
        }
    }
    let robot = Arc::new(embodied_models::builtin("rnt")?);
    let clock = PlanClock::Simulated { steps_per_unit: settings.us_per_check.max(0.0) * 1e-3, fixed_steps: 0 };
    let mut queue = PlanQueue::new(settings.workers, settings.policy, clock);
    if settings.planner_threads {
        queue = queue.with_worker_threads();
    }
    let queue = queue.shared();
    let parallelism = if settings.parallel { Parallelism::Rayon { min_agents: 256 } } else { Parallelism::Sequential };
    let mut rt =
        Runtime::new(RuntimeConfig { seed: settings.seed, parallelism, record: true, ..RuntimeConfig::default() });
    let mut env = Environment::new();
    env.add(Obstacle::new("pillar", Isometry3::translation(0.9, 0.0, 0.6), Shape::cylinder(0.1, 0.6)));
    let collision = CollisionModel::new(&robot, env);
    let deliberative = ((settings.agents as f64) * settings.deliberative_share).round() as usize;
    let deadline_steps = (settings.deadline_ms).round().max(1.0) as u64;
    let give_up_steps = (settings.give_up_ms).round().max(deadline_steps as f64) as u64;
    let home = robot.home().to_vec();
    for k in 0..settings.agents {
        if k < deliberative {
            let mut a = home.clone();
            let mut b = home.clone();
            let swing = 0.4 + 0.2 * ((k % 7) as f64 / 7.0);
            a[0] -= swing;
            b[0] += swing;
            let mut s = DeliberationSettings {
                clock,
                budget: PlanBudget {
                    steps: deadline_steps,
                    wall: None,
                    give_up_steps: Some(give_up_steps),
                    work: None,
                },
                ..DeliberationSettings::default()
            };
            s.motion.seed = settings.seed.wrapping_add(k as u64);
            let mut state = DeliberativeState::new(robot.clone(), collision.clone(), Goal::Configuration(a.clone()), s);
            state.deliberator.use_queue(queue.clone(), k);
            let cc = Errands { state, goals: vec![a, b], next: 0 };
            let behaviour = RunErrands { follower: PlanFollower::new("deliberative") };
            let agent = Agent::embodied(format!("deliberative{k}"), robot.clone(), Some(&home), cc, behaviour)
                .map_err(|e| SystemError::Failed(e.to_string()))?;
            rt.add_agent(agent);
        } else {
            rt.add_agent(reactive(k, &robot)?);
        }
    }
    let steps = (settings.duration_s * 1000.0).round() as u64;
    // Per deliberative agent: requests by id (step of the request, answered, late), plans landed.
    let mut open: Vec<HashMap<u64, (u64, bool, bool)>> = vec![HashMap::new(); deliberative];
    let mut landed = vec![0u64; deliberative];
    let mut r = LoadReport {
        agents: settings.agents,
        deliberative,
        workers: settings.workers,
        policy: settings.policy,
        steps,
        simulated_s: 0.0,
        wall_s: 0.0,
        real_time_factor: 0.0,
        step_p50_us: 0.0,
        step_p99_us: 0.0,
        step_max_us: 0.0,
        steps_over_1ms: 0,
        requests: 0,
        landed_in_time: 0,
        landed_late: 0,
        failed: 0,
        late: 0,
        halts: 0,
        unanswered_without_halt: 0,
        goals_reached: 0,
        min_plans_per_agent: 0,
        max_plans_per_agent: 0,
        starved_agents: 0,
        queue_planned: 0,
        queue_expired: 0,
        queue_withdrawn: 0,
        wait_p50_ms: 0.0,
        wait_p99_ms: 0.0,
        wait_max_ms: 0.0,
        max_waiting: 0,
        planning_wall_s: 0.0,
        planner_threads: 0,
        worker_waits: 0,
        worker_wait_wall_s: 0.0,
    };
    let mut step_us = Vec::with_capacity(steps as usize);
    let start = Instant::now();
    for _ in 0..steps {
        let t0 = Instant::now();
        let record = rt.step().map_err(|e| SystemError::Failed(format!("runtime: {e}")))?;
        step_us.push(t0.elapsed().as_secs_f64() * 1e6);
        let step = record.step;
        for (k, a) in record.agents.iter().enumerate().take(deliberative) {
            for e in &a.events {
                match e {
                    Event::PlanRequested { id, .. } => {
                        r.requests += 1;
                        open[k].insert(*id, (step, false, false));
                    }
                    Event::PlanLanded { id, in_time, .. } => {
                        landed[k] += 1;
                        if *in_time {
                            r.landed_in_time += 1;
                        } else {
                            r.landed_late += 1;
                        }
                        if let Some(o) = open[k].get_mut(id) {
                            o.1 = true;
                        }
                    }
                    Event::PlanFailed { id, .. }
                    | Event::PlanRejected { id, .. }
                    | Event::PlannerPanicked { id, .. } => {
                        r.failed += 1;
                        if let Some(o) = open[k].get_mut(id) {
                            o.1 = true;
                        }
                    }
                    Event::PlanDiscarded { id, .. } => {
                        if let Some(o) = open[k].get_mut(id) {
                            o.1 = true;
                        }
                    }
                    Event::PlanLate { id } => {
                        r.late += 1;
                        if let Some(o) = open[k].get_mut(id) {
                            o.2 = true;
                        }
                    }
                    Event::GoalReached { .. } => r.goals_reached += 1,
                    _ => {}
                }
            }
            // A request past its deadline with neither an answer nor `plan_late`.
            open[k].retain(|_, (at, answered, late)| {
                if *answered || *late {
                    return false;
                }
                if step > *at + deadline_steps {
                    r.unanswered_without_halt += 1;
                    return false;
                }
                true
            });
        }
        for a in &record.agents {
            r.halts += a.events.iter().filter(|e| matches!(e, Event::HaltStarted { .. })).count() as u64;
        }
    }
    r.wall_s = start.elapsed().as_secs_f64();
    r.simulated_s = steps as f64 * 1e-3;
    r.real_time_factor = if r.wall_s > 0.0 { r.simulated_s / r.wall_s } else { f64::INFINITY };
    step_us.sort_by(f64::total_cmp);
    let q =
        |p: f64| step_us.get(((step_us.len().saturating_sub(1)) as f64 * p).round() as usize).copied().unwrap_or(0.0);
    r.step_p50_us = q(0.5);
    r.step_p99_us = q(0.99);
    r.step_max_us = step_us.last().copied().unwrap_or(0.0);
    r.steps_over_1ms = step_us.iter().filter(|&&u| u > 1000.0).count() as u64;
    r.min_plans_per_agent = landed.iter().copied().min().unwrap_or(0);
    r.max_plans_per_agent = landed.iter().copied().max().unwrap_or(0);
    r.starved_agents = landed.iter().filter(|&&n| n == 0).count();
    let queue = queue.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let s = queue.stats();
    r.queue_planned = s.planned;
    r.queue_expired = s.expired;
    r.queue_withdrawn = s.withdrawn;
    r.wait_p50_ms = s.wait_quantile(0.5) as f64;
    r.wait_p99_ms = s.wait_quantile(0.99) as f64;
    r.wait_max_ms = s.wait_quantile(1.0) as f64;
    r.max_waiting = s.max_waiting;
    r.planning_wall_s = s.planning_wall_s;
    r.planner_threads = s.worker_threads;
    r.worker_waits = s.worker_waits;
    r.worker_wait_wall_s = s.worker_wait_wall_s;
    Ok(r)
}

/// The report as text.
pub fn render_load(r: &LoadReport) -> String {
    format!(
        "load: {} agents ({} deliberative, {} reactive), {} planner workers ({:?}), {} steps of 1 ms\n\
         wall {:.2} s for {:.2} s simulated: real-time factor {:.2}; step p50 {:.0} us, p99 {:.0} us, max {:.0} us, {} steps over 1 ms\n\
         requests {}: landed in time {}, landed late {}, failed {}; plan_late (halted) {}; unanswered without a halt {}\n\
         queue: planned {}, given up {}, withdrawn {}; wait p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms; at most {} waiting; planning {:.2} s wall {}\n\
         agents: plans landed per deliberative agent {}..{}, starved {}; goals reached {}; halts {}\n",
        r.agents,
        r.deliberative,
        r.agents - r.deliberative,
        r.workers,
        r.policy,
        r.steps,
        r.wall_s,
        r.simulated_s,
        r.real_time_factor,
        r.step_p50_us,
        r.step_p99_us,
        r.step_max_us,
        r.steps_over_1ms,
        r.requests,
        r.landed_in_time,
        r.landed_late,
        r.failed,
        r.late,
        r.unanswered_without_halt,
        r.queue_planned,
        r.queue_expired,
        r.queue_withdrawn,
        r.wait_p50_ms,
        r.wait_p99_ms,
        r.wait_max_ms,
        r.max_waiting,
        r.planning_wall_s,
        if r.planner_threads > 0 {
            format!(
                "on {} planner threads (steps waited for them {} times, {:.3} s)",
                r.planner_threads, r.worker_waits, r.worker_wait_wall_s
            )
        } else {
            "inside the steps (control thread)".to_string()
        },
        r.min_plans_per_agent,
        r.max_plans_per_agent,
        r.starved_agents,
        r.goals_reached,
        r.halts
    )
}
