//! The deliberative behaviour: [`PlanFollower`] asks for plans through the [`Deliberator`] in
//! `c_c` ([`DeliberativeState`]), follows a verified trajectory, and performs a [`SafeHalt`]
//! whenever no valid plan is available or a fault is detected.

use std::sync::Arc;

use embodied_models::{CollisionModel, Environment, Obstacle, Robot, Shape};
use embodied_planner::motion::{Goal, MotionSettings};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use embodied_planner::verify::{CheckSettings, LimitsChecker, Verifier};
use nalgebra::Isometry3;

use crate::agent::Agent;
use crate::behaviour::{Behaviour, Status};
use crate::effector::{BrakeHalt, PathHalt, SafeHalt, StopMotion, predict_stop, tracking_bound};
use crate::error::{ExecutorError, Violation};
use crate::event::{Event, HaltReason, ReplanReason, WallTiming};
use crate::image::{InputImages, JointCommand, OutputImages, SensorConfig};
use crate::world::ReceptorSpec;

use super::planning::PlanMotion;
use super::sensing::UnmappedObstacle;
use super::worker::{
    Deliberator, MotionPlanner, PlanBudget, PlanClock, PlanDelivery, PlanOutcome, PlanRequest, PlanVerifier,
};

/// Settings of a deliberative agent.
#[derive(Clone)]
pub struct DeliberationSettings {
    /// How planning time is counted (wall clock or simulated from work).
    pub clock: PlanClock,
    /// Deadline (steps, wall clock) and work budget of each plan request.
    pub budget: PlanBudget,
    /// Settings of [`embodied_planner::motion::plan_motion`] (used when `planner` is `None`;
    /// its deadline is replaced by each request's).
    pub motion: MotionSettings,
    /// An injected planner instead of [`PlanMotion`].
    pub planner: Option<Arc<dyn MotionPlanner>>,
    /// Collision-check resolution (rad or m) of the check of the rest of the plan being
    /// followed when the world changes (on the control thread).
    pub verify_resolution: f64,
    /// The check every plan must pass before it may drive the effector (the online plan gate,
    /// on the planning thread). [`Verifier::default`]: certified, touching counts as collision.
    pub plan_check: Verifier,
    /// Largest distance between a plan's end and its goal that the verifier accepts.
    pub goal_tolerance: f64,
    /// Steps to wait after a failed, rejected or panicked plan before asking again.
    pub retry_after_steps: u64,
    /// Requests after which the agent gives up and holds (`plan_abandoned`).
    pub max_attempts: u32,
    /// Steps after `needed_at` after which an outstanding request counts as lost.
    pub plan_timeout_steps: u64,
    /// Obstacle detector range (m); `Some` adds an [`UnmappedObstacle`] virtual sensor (index 0).
    pub obstacle_sensing: Option<f64>,
    /// Steps without a fresh obstacle reading after which the sensor counts as failed.
    pub sensor_max_age: u64,
    /// Largest magnitude (m) an obstacle reading may have: a larger one is a sensor fault.
    pub sensor_max_abs: f64,
    /// Movement of a sensed obstacle (m) that counts as a change of the world.
    pub move_tolerance: f64,
    /// Halt and replan on every change of the world, not only when the plan is hit.
    pub halt_on_any_change: bool,
    /// When the path being followed is hit, ask for a new plan while moving (from where the
    /// path, braked from the deadline on, comes to rest) instead of halting first; the agent
    /// halts only if that plan is late.
    pub replan_in_motion: bool,
    /// Fraction of each joint's acceleration limit used to brake on the path before a plan
    /// asked for in motion (below 1 leaves room for the effector's rounding).
    pub brake_fraction: f64,
}

impl Default for DeliberationSettings {
    fn default() -> Self {
        Self {
            clock: PlanClock::WallClock,
            budget: PlanBudget::default(),
            motion: MotionSettings::default(),
            planner: None,
            verify_resolution: 0.01,
            plan_check: Verifier::default(),
            goal_tolerance: 1e-6,
            retry_after_steps: 100,
            max_attempts: 3,
            plan_timeout_steps: 2000,
            obstacle_sensing: None,
            sensor_max_age: 50,
            sensor_max_abs: 1e4,
            move_tolerance: 0.02,
            halt_on_any_change: false,
            replan_in_motion: true,
            brake_fraction: 0.9,
        }
    }
}

struct ActivePlan {
    trajectory: Arc<Trajectory>,
    id: u64,
    started_at: u64,
}

struct Halt {
    started_at: u64,
    q0: Vec<f64>,
    stop: Stop,
    /// World-model version the stopping motion was last checked against.
    checked: Option<u64>,
}

/// A plan asked for while moving: where and when it joins the plan being followed.
struct Join {
    /// The request.
    id: u64,
    /// The plan being followed.
    plan: u64,
    /// Last step at which the new plan is in time.
    needed_at: u64,
    /// Time along the followed trajectory at which the braking begins, s.
    t_brake: f64,
    /// Largest joint speed there, rad/s or m/s.
    speed: f64,
    /// The braking samples after `t_brake` (every control step; the last one at rest): the
    /// current path brought to rest within the acceleration limits.
    brake_q: Vec<Vec<f64>>,
    brake_qd: Vec<Vec<f64>>,
}

/// How a halt stops.
enum Stop {
    /// Along the trajectory that was being followed.
    Path { trajectory: Arc<Trajectory>, halt: PathHalt },
    /// Off any path.
    Off(StopMotion),
}

/// Longest stop predicted for the collision check of a stopping motion, steps.
const MAX_STOP_STEPS: usize = 20_000;

/// Distance (largest joint travel) and duration (s) of a halt.
fn halt_report(h: &Halt, q: &[f64], step: u64, dt: f64) -> Event {
    let distance = q.iter().zip(&h.q0).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let steps = step - h.started_at;
    Event::HaltFinished { distance, time_s: steps as f64 * dt, steps }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct SensedObstacle {
    id: usize,
    centre: [f64; 3],
    radius: f64,
}

/// `c_c` of a deliberative agent: the deliberator, the goal, the world model and the plan.
pub struct DeliberativeState {
    /// Issues plan requests and receives their deliveries.
    pub deliberator: Deliberator,
    /// The goal the agent plans towards.
    pub goal: Goal,
    settings: DeliberationSettings,
    robot: Arc<Robot>,
    base_env: Environment,
    /// Obstacles the agent was told about (e.g. other agents' bodies or reserved space).
    known: Vec<Obstacle>,
    collision: CollisionModel,
    sensed: Vec<SensedObstacle>,
    world_version: u64,
    plan: Option<ActivePlan>,
    /// A plan asked for in motion, to be joined to `plan`.
    join: Option<Join>,
    /// Why the next halt from speed starts, when it is not the default.
    halt_reason: Option<HaltReason>,
    /// The trajectory of a plan just dropped and the time reached on it: a halt that begins
    /// now stops along it.
    dropped: Option<(Arc<Trajectory>, f64)>,
    halt: Option<Halt>,
    fault: Option<String>,
    /// The effector did not follow its command (a tracking error), and the steps since it
    /// last deviated.
    effector_fault: Option<u64>,
    attempts: u32,
    next_request_at: u64,
    late_reported: bool,
    /// Step at which the agent last started halting (from speed or for a late plan), until it
    /// resumes.
    halted_since: Option<u64>,
    goal_reached: bool,
    abandoned: bool,
    last_fresh: u64,
    scratch: JointCommand,
}

impl DeliberativeState {
    /// `c_c` for `robot` planning to `goal` in `collision`'s environment.
    pub fn new(robot: Arc<Robot>, collision: CollisionModel, goal: Goal, settings: DeliberationSettings) -> Self {
        let planner: Arc<dyn MotionPlanner> = match &settings.planner {
            Some(p) => p.clone(),
            None => Arc::new(PlanMotion::new(collision.clone(), settings.motion.clone())),
        };
        let verifier = PlanVerifier {
            collision: collision.clone(),
            verifier: settings.plan_check,
            goal_tolerance: settings.goal_tolerance,
        };
        let dof = robot.dof();
        Self {
            deliberator: Deliberator::new(planner, verifier, settings.clock),
            goal,
            base_env: collision.environment().clone(),
            known: Vec::new(),
            collision,
            robot,
            settings,
            sensed: Vec::new(),
            world_version: 0,
            plan: None,
            join: None,
            halt_reason: None,
            dropped: None,
            halt: None,
            fault: None,
            effector_fault: None,
            attempts: 0,
            next_request_at: 0,
            late_reported: false,
            halted_since: None,
            goal_reached: false,
            abandoned: false,
            last_fresh: 0,
            scratch: JointCommand::hold(&vec![0.0; dof]),
        }
    }
    /// A new goal from `step` on: the plan being followed (if any) is dropped, the agent halts
    /// along it and asks for a plan to the new goal.
    pub fn set_goal(&mut self, goal: Goal, step: u64, dt: f64) {
        self.goal = goal;
        if self.plan.is_some() {
            drop_plan(self, step, dt);
        }
        self.join = None;
        self.deliberator.cancel();
        self.goal_reached = false;
        self.abandoned = false;
        self.attempts = 0;
        self.next_request_at = step;
    }

    /// Version of the agent's world model (increases with every sensed change).
    pub fn world_version(&self) -> u64 {
        self.world_version
    }
    /// Whether a verified plan is being followed.
    pub fn is_following(&self) -> bool {
        self.plan.is_some()
    }
    /// Whether a fault (a sensor's or the effector's) keeps the agent halted.
    pub fn faulty(&self) -> bool {
        self.fault.is_some() || self.effector_fault.is_some()
    }
    /// Whether the goal has been reached.
    pub fn goal_reached(&self) -> bool {
        self.goal_reached
    }
    /// Whether the agent gave up planning (`plan_abandoned`).
    pub fn abandoned(&self) -> bool {
        self.abandoned
    }
    /// Id of the plan being followed, if any.
    pub fn plan_id(&self) -> Option<u64> {
        self.plan.as_ref().map(|p| p.id)
    }
    /// Give up: drop the plan, cancel any request, ask for no more plans (e.g. a reaction
    /// decided the task cannot go on). The behaviour halts from then on.
    pub fn abandon(&mut self) {
        self.plan = None;
        self.join = None;
        self.deliberator.cancel();
        self.abandoned = true;
    }
    /// The trajectory being followed, if any.
    pub fn trajectory(&self) -> Option<&Trajectory> {
        self.plan.as_ref().map(|p| &*p.trajectory)
    }
    /// The agent's settings.
    pub fn settings(&self) -> &DeliberationSettings {
        &self.settings
    }
    /// The robot.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Replace the obstacles the agent was told about (other agents' bodies, reserved space):
    /// a change of its world model, so an outstanding request becomes stale and a plan whose
    /// remaining path now collides is dropped (the agent halts and replans). Returns whether
    /// the plan being followed was dropped.
    pub fn set_known_obstacles(&mut self, obstacles: Vec<Obstacle>, step: u64, dt: f64) -> bool {
        self.known = obstacles;
        self.world_version += 1;
        let env = self.environment();
        self.collision.set_environment(env);
        let Some(plan) = &self.plan else { return false };
        let k = sample_at(&plan.trajectory, step.saturating_sub(plan.started_at) as f64 * dt);
        if remaining_collides(&self.collision, &plan.trajectory, k, self.settings.verify_resolution) {
            drop_plan(self, step, dt);
            self.join = None;
            self.goal_reached = false;
            self.attempts = 0;
            self.next_request_at = step;
            true
        } else {
            if self.join.take().is_some() {
                // The path is free again in the new world: the plan asked for is not needed.
                self.deliberator.cancel();
            }
            false
        }
    }

    /// The environment as the agent knows it: the map, what it was told, what it sensed.
    pub fn environment(&self) -> Environment {
        let mut env = self.base_env.clone();
        for o in &self.known {
            env.add(o.clone());
        }
        for o in &self.sensed {
            let [x, y, z] = o.centre;
            env.add(Obstacle::new(
                format!("sensed-{}", o.id),
                Isometry3::translation(x, y, z),
                Shape::Sphere { radius: o.radius },
            ));
        }
        env
    }
}

/// Something a deliberative `c_c` type contains, so that [`PlanFollower`] can run inside a
/// larger program with its own `c_c`.
pub trait AsDeliberation {
    /// The deliberative part of `c_c`.
    fn deliberation(&mut self) -> &mut DeliberativeState;
}

impl AsDeliberation for DeliberativeState {
    fn deliberation(&mut self) -> &mut DeliberativeState {
        self
    }
}

/// The deliberative behaviour (a primitive behaviour whose transition function consults the
/// plan in `c_c`; it never ends by itself: at the goal it holds).
pub struct PlanFollower {
    name: String,
    phase: &'static str,
    suspended: bool,
}

impl PlanFollower {
    /// A plan follower named `name`.
    pub fn new(name: impl Into<String>) -> Self {
        Self { name: name.into(), phase: "waiting", suspended: false }
    }
}

fn at_rest(qd: &[f64]) -> bool {
    qd.iter().all(|v| v.abs() < 1e-9)
}

impl<C: AsDeliberation + Send> Behaviour<C> for PlanFollower {
    fn name(&self) -> &str {
        &self.name
    }

    fn step(&mut self, cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages) -> Result<Status, Violation> {
        let s = cc.deliberation();
        let step = inputs.step();
        if std::mem::take(&mut self.suspended) {
            if s.join.take().is_some() {
                // The plan asked for in motion would join a plan that is no longer followed.
                s.deliberator.cancel();
            }
            if s.plan.take().is_some() {
                outputs.event(Event::PlanSuspended);
            }
        }
        sense(s, inputs, outputs);
        track_effector(s, inputs, outputs);
        if let Some(d) = s.deliberator.poll(step) {
            deliver(s, d, inputs, outputs);
        }
        // An answer that never comes (e.g. its transmission was lost).
        let timeout = s.next_request_at + s.settings.budget.steps + s.settings.plan_timeout_steps;
        if s.deliberator.pending().is_some_and(|_| step > timeout)
            && let Some(id) = s.deliberator.pending()
        {
            s.deliberator.cancel();
            outputs.event(Event::PlanLost { id });
            s.attempts += 1;
            s.next_request_at = step;
        }
        if s.faulty() {
            drop_plan(s, step, inputs.dt());
            s.join = None;
            s.deliberator.cancel();
        }
        if let Some(j) = s.join.as_ref().filter(|j| step > j.needed_at) {
            // The plan asked for in motion is late: c^{i+1} is computed without it and halts the
            // effector from speed; the agent resumes from wherever it stops.
            let id = j.id;
            s.join = None;
            s.plan = None;
            s.late_reported = true;
            s.halt_reason = Some(HaltReason::PlanLate);
            s.halted_since.get_or_insert(step);
            outputs.event(Event::PlanLate { id });
        }
        if let Some(plan) = &s.plan {
            let k = step.saturating_sub(plan.started_at) + 1;
            let t = k as f64 * inputs.dt();
            // The consistent one-step command: the next point of the trajectory with the chord
            // velocity to it, so that an effector on the trajectory stays exactly on it.
            let (q, _, _) = plan.trajectory.sample(t);
            let (q_prev, _, _) = plan.trajectory.sample((k - 1) as f64 * inputs.dt());
            let qd: Vec<f64> = q.iter().zip(&q_prev).map(|(a, b)| (a - b) / inputs.dt()).collect();
            outputs.set_position_target(&q, &qd);
            if t >= plan.trajectory.duration() {
                if !s.goal_reached {
                    s.goal_reached = true;
                    outputs.event(Event::GoalReached { id: Some(plan.id) });
                }
                self.phase = "at-goal";
            } else {
                self.phase = "following";
            }
            return Ok(Status::Running);
        }
        // No valid plan: c^{i+1} is computed without it and halts the effector.
        halt(s, inputs, outputs);
        self.phase = if s.faulty() {
            "fault"
        } else if s.halt.is_some() {
            "halting"
        } else {
            "waiting"
        };
        if !s.faulty() && !s.goal_reached && !s.abandoned && s.halt.is_none() && at_rest(inputs.qd()) {
            maybe_request(s, inputs, outputs);
        }
        Ok(Status::Running)
    }

    fn reset(&mut self) {
        self.suspended = true;
        self.phase = "suspended";
    }

    fn describe(&self, out: &mut String) {
        out.push_str(&self.name);
        out.push('/');
        out.push_str(self.phase);
    }
}

fn maybe_request(s: &mut DeliberativeState, inputs: &InputImages, outputs: &mut OutputImages) {
    let step = inputs.step();
    if let Some(id) = s.deliberator.pending() {
        if step >= s.next_request_at + s.settings.budget.steps && !s.late_reported {
            s.late_reported = true;
            late_halt(s, id, step, outputs);
        }
        return;
    }
    if step < s.next_request_at {
        return;
    }
    if s.attempts >= s.settings.max_attempts {
        s.abandoned = true;
        outputs.event(Event::PlanAbandoned { attempts: s.attempts });
        return;
    }
    let request = PlanRequest {
        id: 0,
        world_version: s.world_version,
        step,
        start: inputs.q().to_vec(),
        goal: s.goal.clone(),
        dt: inputs.dt(),
        environment: Some(s.environment()),
        budget: s.settings.budget,
    };
    let id = s.deliberator.request(request);
    s.next_request_at = step;
    s.late_reported = false;
    outputs.event(Event::PlanRequested {
        id,
        world: s.world_version,
        deadline_ms: s.settings.budget.steps as f64 * inputs.dt() * 1e3,
    });
    if s.settings.budget.steps == 0 {
        // The plan is needed now and cannot be there.
        s.late_reported = true;
        late_halt(s, id, step, outputs);
    }
}

/// The plan is late: `c^{i+1}` is computed without it and halts the effector. The agent is at
/// rest when it asks for a plan, so this halt is a hold: no distance, no time.
fn late_halt(s: &mut DeliberativeState, id: u64, step: u64, outputs: &mut OutputImages) {
    outputs.event(Event::PlanLate { id });
    outputs.event(Event::HaltStarted { reason: HaltReason::PlanLate, speed: 0.0, detail: None });
    outputs.event(Event::HaltFinished { distance: 0.0, time_s: 0.0, steps: 0 });
    s.halted_since.get_or_insert(step);
}

/// Drop the plan being followed, keeping its trajectory and the time reached on it so that a
/// halt stops along it.
fn drop_plan(s: &mut DeliberativeState, step: u64, dt: f64) {
    if let Some(plan) = s.plan.take() {
        let t = step.saturating_sub(plan.started_at) as f64 * dt;
        s.dropped = Some((plan.trajectory, t));
    }
}

/// Halt command for this step, with the halt's start and end logged. The stop follows the
/// trajectory that was being followed ([`PathHalt`]); its motion is checked for collision in
/// the agent's world model before it is committed and again whenever the world changes; when
/// it would collide, the halt takes the first collision-free stop off the path
/// ([`StopMotion::Straight`], then [`StopMotion::JointBrake`]), or the joint brake when none is
/// free, and says so ([`Event::StopPathBlocked`]).
fn halt(s: &mut DeliberativeState, inputs: &InputImages, outputs: &mut OutputImages) {
    let (q, qd) = (inputs.q(), inputs.qd());
    let dropped = s.dropped.take();
    if !at_rest(qd) && s.halt.is_none() {
        let stop = match dropped {
            // An effector that does not follow its command brakes its joints at their limits
            // (a stuck joint does): every joint at its limit is the stop that then happens.
            _ if s.effector_fault.is_some() => Stop::Off(StopMotion::JointBrake),
            Some((trajectory, t)) => Stop::Path { trajectory, halt: PathHalt::new(t, 1.0) },
            None => Stop::Off(StopMotion::Straight),
        };
        s.halt = Some(Halt { started_at: inputs.step(), q0: q.to_vec(), stop, checked: None });
        s.halted_since = Some(inputs.step());
        let speed = qd.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let reason = match s.halt_reason.take() {
            _ if s.faulty() => HaltReason::Fault,
            Some(r) => r,
            None => HaltReason::NoValidPlan,
        };
        outputs.event(Event::HaltStarted { reason, speed, detail: None });
    }
    if at_rest(qd) && s.halt.is_none() {
        // Nothing to stop: a reason set for this halt does not carry over to a later one.
        s.halt_reason = None;
    }
    if at_rest(qd)
        && let Some(h) = s.halt.take()
    {
        outputs.event(halt_report(&h, q, inputs.step(), inputs.dt()));
    }
    let (limits, dt) = (inputs.limits(), inputs.dt());
    if s.halt.as_ref().is_some_and(|h| h.checked != Some(s.world_version)) {
        check_stop(s, q, qd, limits, dt, outputs);
    }
    match s.halt.as_mut().map(|h| &mut h.stop) {
        Some(Stop::Path { trajectory, halt }) => {
            halt.command_into(&**trajectory, q, qd, limits, dt, &mut s.scratch);
        }
        Some(Stop::Off(StopMotion::JointBrake)) => BrakeHalt::command_into(q, qd, limits, dt, &mut s.scratch),
        _ => SafeHalt::command_into(q, qd, limits, dt, &mut s.scratch),
    }
    outputs.set_command(&s.scratch);
}

/// Check the halt's stopping motion against the agent's world model before it is committed;
/// switch to a free stop off the path when it would collide.
fn check_stop(
    s: &mut DeliberativeState,
    q: &[f64],
    qd: &[f64],
    limits: &[embodied_models::JointLimits],
    dt: f64,
    outputs: &mut OutputImages,
) {
    let Some(h) = s.halt.as_mut() else { return };
    h.checked = Some(s.world_version);
    let resolution = s.settings.verify_resolution;
    let free = |positions: &[Vec<f64>]| path_free(&s.collision, positions, resolution);
    let current = match &h.stop {
        Stop::Path { trajectory, halt } => {
            predict_stop(StopMotion::Path, Some((&**trajectory, halt)), q, qd, limits, dt, MAX_STOP_STEPS)
        }
        Stop::Off(m) => predict_stop::<Trajectory>(*m, None, q, qd, limits, dt, MAX_STOP_STEPS),
    };
    if free(&current) {
        return;
    }
    for m in [StopMotion::Straight, StopMotion::JointBrake] {
        if free(&predict_stop::<Trajectory>(m, None, q, qd, limits, dt, MAX_STOP_STEPS)) {
            h.stop = Stop::Off(m);
            outputs.event(Event::StopPathBlocked { chosen: m, free: true });
            return;
        }
    }
    h.stop = Stop::Off(StopMotion::JointBrake);
    outputs.event(Event::StopPathBlocked { chosen: StopMotion::JointBrake, free: false });
}

/// Whether the motion through `positions` (consecutive configurations) is collision-free.
fn path_free(model: &CollisionModel, positions: &[Vec<f64>], resolution: f64) -> bool {
    let mut scratch = model.scratch();
    let stride = 4.0 * resolution.max(1e-4);
    let Some(first) = positions.first() else { return true };
    if model.collides_with(first, &mut scratch) {
        return false;
    }
    let mut knot = 0;
    let n = positions.len();
    for k in 1..n {
        let last = k + 1 == n;
        let next_far = !last && positions[k + 1].iter().zip(&positions[knot]).any(|(a, b)| (a - b).abs() > stride);
        if last || next_far {
            if !model.motion_is_free_with(&positions[knot], &positions[k], resolution, &mut scratch) {
                return false;
            }
            knot = k;
        }
    }
    true
}

fn deliver(s: &mut DeliberativeState, d: PlanDelivery, inputs: &InputImages, outputs: &mut OutputImages) {
    let step = inputs.step();
    let in_time = step <= d.needed_at;
    let id = d.id;
    // Planning time: simulated (reproducible) or wall clock. Wall-clock figures only in
    // wall-clock mode: simulated-time logs must replay exactly.
    let (planning_ms, wall) = match s.deliberator.clock() {
        PlanClock::WallClock => (
            d.elapsed.as_secs_f64() * 1e3,
            Some(WallTiming {
                elapsed_us: d.elapsed.as_micros() as u64,
                overshoot_us: d.overshoot.map(|o| o.as_micros() as u64),
            }),
        ),
        PlanClock::Simulated { .. } => ((d.landed_at - d.requested_at) as f64 * inputs.dt() * 1e3, None),
    };
    let retry = |s: &mut DeliberativeState| {
        s.attempts += 1;
        s.next_request_at = step + s.settings.retry_after_steps;
    };
    let join = s.join.take_if(|j| j.id == id);
    if let Some(j) = join {
        deliver_join(s, j, d, in_time, planning_ms, wall, inputs, outputs);
        return;
    }
    match d.outcome {
        PlanOutcome::Ready(trajectory) => {
            let stale = if d.world_version != s.world_version {
                Some(format!("world {} != {}", d.world_version, s.world_version))
            } else if d.start.len() != inputs.dof()
                || d.start.iter().zip(inputs.q()).any(|(a, b)| (a - b).abs() > 1e-6)
                || !at_rest(inputs.qd())
            {
                Some("start state moved".to_string())
            } else if s.faulty() {
                Some("fault".to_string())
            } else {
                None
            };
            match stale {
                Some(why) => {
                    outputs.event(Event::PlanDiscarded { id, reason: why });
                    outputs.event(Event::Replan { reason: ReplanReason::StalePlan });
                    s.next_request_at = step;
                }
                None => {
                    outputs.event(Event::PlanLanded {
                        id,
                        world: d.world_version,
                        in_time,
                        work: d.work,
                        planning_ms,
                        duration_s: trajectory.duration(),
                        wall,
                    });
                    if let Some(since) = s.halted_since.take() {
                        let after_s = step.saturating_sub(since) as f64 * inputs.dt();
                        outputs.event(Event::Resumed { id, after_s });
                    }
                    s.attempts = 0;
                    s.plan = Some(ActivePlan { trajectory, id, started_at: step });
                }
            }
        }
        PlanOutcome::Rejected(v) => {
            outputs.event(Event::PlanRejected { id, reason: v.to_string() });
            retry(s);
        }
        PlanOutcome::Failed(f) => {
            outputs.event(Event::PlanFailed { id, in_time, reason: f.to_string(), planning_ms, wall });
            retry(s);
        }
        PlanOutcome::Panicked(m) => {
            outputs.event(Event::PlannerPanicked { id, message: m.to_string() });
            retry(s);
        }
    }
}

/// Compare the measured position with where the last (limited) command asked the effector to
/// be: a joint off by more than its [`tracking_bound`] is a tracking error (an event and a
/// fault: the agent halts, every joint braking at its limit). The fault clears once the agent
/// has been at rest with every joint on its command for `sensor_max_age` steps.
fn track_effector(s: &mut DeliberativeState, inputs: &InputImages, outputs: &mut OutputImages) {
    let Some(commanded) = inputs.q_commanded() else { return };
    let (q, limits, dt) = (inputs.q(), inputs.limits(), inputs.dt());
    if commanded.len() != q.len() || limits.len() != q.len() {
        return;
    }
    let mut worst: Option<(usize, f64, f64)> = None;
    for (j, ((a, b), lim)) in q.iter().zip(commanded).zip(limits).enumerate() {
        let (error, bound) = ((a - b).abs(), tracking_bound(lim, dt));
        if error > bound && worst.is_none_or(|(_, e, b)| error / bound > e / b) {
            worst = Some((j, error, bound));
        }
    }
    match (worst, s.effector_fault) {
        (Some((joint, error, bound)), None) => {
            s.effector_fault = Some(0);
            outputs.event(Event::TrackingError { joint, error, bound });
        }
        (Some(_), Some(_)) => s.effector_fault = Some(0),
        (None, Some(quiet)) if at_rest(inputs.qd()) => {
            if quiet + 1 > s.settings.sensor_max_age {
                s.effector_fault = None;
                s.attempts = 0;
                outputs.event(Event::EffectorRecovered);
            } else {
                s.effector_fault = Some(quiet + 1);
            }
        }
        (None, Some(_)) => s.effector_fault = Some(0),
        (None, None) => {}
    }
}

/// Read the obstacle sensor: faults (NaN, silence), and changes of the world.
fn sense(s: &mut DeliberativeState, inputs: &InputImages, outputs: &mut OutputImages) {
    if s.settings.obstacle_sensing.is_none() {
        return;
    }
    let step = inputs.step();
    let r = inputs.sensor(0);
    if !r.fresh {
        if step.saturating_sub(s.last_fresh) > s.settings.sensor_max_age && s.fault.is_none() {
            s.fault = Some("sensor silent".into());
            outputs.event(Event::SensorSilent { steps: step - s.last_fresh });
        }
        return;
    }
    s.last_fresh = step;
    if r.as_slice().iter().any(|v| !v.is_finite()) {
        if s.fault.is_none() {
            s.fault = Some("sensor NaN".into());
            outputs.event(Event::SensorNonFinite);
        }
        return;
    }
    let largest = r.as_slice().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if largest > s.settings.sensor_max_abs {
        if s.fault.is_none() {
            s.fault = Some("sensor implausible".into());
            outputs.event(Event::SensorImplausible { value: largest });
        }
        return;
    }
    if s.fault.take().is_some() {
        outputs.event(Event::SensorRecovered);
        s.attempts = 0;
    }
    let changed = if r.len < 5 {
        if s.sensed.is_empty() {
            false
        } else {
            s.sensed.clear();
            true
        }
    } else {
        let v = r.as_slice();
        let id = v[4].max(0.0) as usize;
        let centre = [v[1], v[2], v[3]];
        let q = inputs.q();
        let p = if q.len() == s.robot.dof() && !s.robot.end_effectors().is_empty() {
            s.robot.end_effector_poses(q, 0).1.translation.vector
        } else {
            nalgebra::Vector3::zeros()
        };
        let centre_dist = ((p.x - centre[0]).powi(2) + (p.y - centre[1]).powi(2) + (p.z - centre[2]).powi(2)).sqrt();
        // A sensor that reports the radius (word 5) is believed; otherwise it is inferred from
        // the distance to the sensing point.
        let radius = if r.len >= 6 { v[5].max(0.0) } else { (centre_dist - v[0]).max(0.0) };
        let tol = s.settings.move_tolerance;
        match s.sensed.iter_mut().find(|o| o.id == id) {
            Some(o) => {
                let moved = (0..3).any(|k| (o.centre[k] - centre[k]).abs() > tol) || (o.radius - radius).abs() > tol;
                if moved {
                    *o = SensedObstacle { id, centre, radius };
                }
                moved
            }
            None => {
                s.sensed.push(SensedObstacle { id, centre, radius });
                true
            }
        }
    };
    if !changed {
        return;
    }
    s.world_version += 1;
    let env = s.environment();
    s.collision.set_environment(env);
    outputs.event(Event::WorldChanged { version: s.world_version });
    let Some(plan) = &s.plan else { return };
    let k = sample_at(&plan.trajectory, step.saturating_sub(plan.started_at) as f64 * inputs.dt());
    let hit = remaining_collides(&s.collision, &plan.trajectory, k, s.settings.verify_resolution);
    if hit
        && s.settings.replan_in_motion
        && !s.settings.halt_on_any_change
        && replan_in_motion(s, step, inputs.dt(), outputs)
    {
        return;
    }
    let Some(plan) = &s.plan else { return };
    if hit || s.settings.halt_on_any_change {
        let reason = if hit { ReplanReason::ObstacleInPath } else { ReplanReason::WorldChanged };
        outputs.event(Event::PlanInvalidated { id: Some(plan.id), reason });
        outputs.event(Event::Replan { reason });
        drop_plan(s, step, inputs.dt());
        s.join = None;
        s.attempts = 0;
        s.goal_reached = false;
        s.next_request_at = step;
    } else {
        outputs.event(Event::PlanRevalidated { id: plan.id, world: s.world_version });
        if s.join.take().is_some() {
            // The path is free again in the new world: the plan asked for is not needed.
            s.deliberator.cancel();
        }
    }
}

/// Ask for a plan while following `s.plan`, whose remaining path the world now blocks: the
/// new plan starts where the path comes to rest if it brakes (every joint at
/// `brake_fraction` of its acceleration limit, on the path's straight segment) from the
/// deadline on. `None` (and nothing asked) when that cannot work: no time before the
/// deadline, the path ends first, the braking leaves the limits, or the path up to the stop
/// is blocked too. Returns whether it asked.
fn replan_in_motion(s: &mut DeliberativeState, step: u64, dt: f64, outputs: &mut OutputImages) -> bool {
    let Some((join, start)) = prepare_join(s, step, dt) else { return false };
    let request = PlanRequest {
        id: 0,
        world_version: s.world_version,
        step,
        start,
        goal: s.goal.clone(),
        dt,
        environment: Some(s.environment()),
        budget: s.settings.budget,
    };
    let id = s.deliberator.request(request);
    s.next_request_at = step;
    s.late_reported = false;
    s.attempts = 0;
    let t_now = s.plan.as_ref().map_or(0.0, |p| step.saturating_sub(p.started_at) as f64 * dt);
    outputs.event(Event::Replan { reason: ReplanReason::ObstacleInPath });
    outputs.event(Event::ReplanInMotion { plan: join.plan, id, join_after_s: join.t_brake - t_now, speed: join.speed });
    outputs.event(Event::PlanRequested {
        id,
        world: s.world_version,
        deadline_ms: s.settings.budget.steps as f64 * dt * 1e3,
    });
    s.join = Some(Join { id, ..join });
    true
}

/// Where and when a plan asked for now would join `s.plan` (see [`replan_in_motion`]), and
/// the new plan's start.
fn prepare_join(s: &DeliberativeState, step: u64, dt: f64) -> Option<(Join, Vec<f64>)> {
    let plan = s.plan.as_ref()?;
    let budget = s.settings.budget.steps;
    if budget == 0 || s.faulty() || s.abandoned || step < plan.started_at {
        return None;
    }
    let (traj, plan_id) = (plan.trajectory.clone(), plan.id);
    let needed_at = step + budget;
    let t_now = (step - plan.started_at) as f64 * dt;
    // The follower commands the sample at (step - started_at + 1) dt: braking begins after the
    // command of step `needed_at`.
    let t_brake = (needed_at + 1 - plan.started_at) as f64 * dt;
    if t_brake >= traj.duration() {
        return None;
    }
    let (qb, qdb, _) = traj.sample(t_brake);
    let limits = s.robot.limits();
    if qb.len() != limits.len() {
        return None;
    }
    let frac = s.settings.brake_fraction.clamp(0.05, 1.0);
    let t_stop = qdb.iter().zip(&limits).map(|(v, l)| v.abs() / (frac * l.max_acceleration)).fold(0.0, f64::max);
    if !t_stop.is_finite() {
        return None;
    }
    let n = (t_stop / dt - 1e-9).ceil().max(0.0) as usize;
    let total = n as f64 * dt;
    let mut brake_q = Vec::with_capacity(n);
    let mut brake_qd = Vec::with_capacity(n);
    for k in 1..=n {
        let tau = k as f64 * dt;
        let (x, v) = (tau - tau * tau / (2.0 * total), 1.0 - tau / total);
        brake_q.push(qb.iter().zip(&qdb).map(|(q, qd)| q + qd * x).collect::<Vec<f64>>());
        brake_qd.push(qdb.iter().map(|qd| if k == n { 0.0 } else { qd * v }).collect::<Vec<f64>>());
    }
    let start = brake_q.last().cloned().unwrap_or_else(|| qb.clone());
    if start.iter().zip(&limits).any(|(q, l)| *q < l.lower || *q > l.upper) {
        return None;
    }
    let res = s.settings.verify_resolution;
    let (k0, k1) = (sample_at(&traj, t_now), (sample_at(&traj, t_brake) + 1).min(traj.q.len().saturating_sub(1)));
    if path_collides(&s.collision, &traj, k0, k1, res) || !s.collision.motion_is_free(&qb, &start, res) {
        return None;
    }
    let speed = qdb.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    Some((Join { id: 0, plan: plan_id, needed_at, t_brake, speed, brake_q, brake_qd }, start))
}

/// The followed trajectory up to `j.t_brake`, the braking, then `new` (which starts at rest
/// where the braking ends).
fn splice(old: &Trajectory, j: &Join, new: &Trajectory, dt: f64) -> Trajectory {
    let mut out = Trajectory { joint_names: old.joint_names.clone(), t: Vec::new(), q: Vec::new(), qd: Vec::new() };
    for k in 0..old.t.len() {
        if old.t[k] >= j.t_brake - 1e-9 {
            break;
        }
        out.t.push(old.t[k]);
        out.q.push(old.q[k].clone());
        out.qd.push(old.qd[k].clone());
    }
    let (qb, qdb, _) = old.sample(j.t_brake);
    out.t.push(j.t_brake);
    out.q.push(qb);
    out.qd.push(qdb);
    for (k, (q, qd)) in j.brake_q.iter().zip(&j.brake_qd).enumerate() {
        out.t.push(j.t_brake + (k + 1) as f64 * dt);
        out.q.push(q.clone());
        out.qd.push(qd.clone());
    }
    let t0 = out.t.last().copied().unwrap_or(0.0);
    for k in 1..new.t.len() {
        out.t.push(t0 + new.t[k] - new.t[0]);
        out.q.push(new.q[k].clone());
        out.qd.push(new.qd[k].clone());
    }
    out
}

/// The join without a stop: the new plan (which starts at rest where the braked path would
/// stop) superposed on the braking, so that the arm turns onto the new path at speed instead of
/// coming to rest at the join. From `t_brake` on, the joined motion is
/// `B(tau) + N(tau) - q_stop`: the braking `B` (every joint at most `frac` of its acceleration
/// limit, to rest at `q_stop` after `T`) plus the new plan `N` from its start, its first segment
/// re-timed with `1 - frac` of each acceleration limit (so the sum stays within the limits);
/// after `T` it is `N` itself. Position and velocity are continuous at `t_brake` (the braking
/// starts with the path's velocity, `N` at rest) and at `T` (the braking ends at rest).
/// `None` when the superposed motion breaks a limit (joint or screw) or is not free in the
/// agent's world model at `resolution`: then the join comes to rest ([`splice`]).
#[allow(clippy::too_many_arguments)]
fn blend(
    old: &Trajectory,
    j: &Join,
    new: &Trajectory,
    dt: f64,
    robot: &Robot,
    frac: f64,
    model: &CollisionModel,
    resolution: f64,
) -> Option<Trajectory> {
    let n = j.brake_q.len();
    if n == 0 || new.t.len() < 2 || frac >= 1.0 {
        return None;
    }
    let dof = robot.dof();
    let (qb, qdb, _) = old.sample(j.t_brake);
    let q_stop = j.brake_q.last()?.clone();
    if new.q[0].len() != dof || new.q[0].iter().zip(&q_stop).any(|(a, b)| (a - b).abs() > 1e-9) {
        return None;
    }
    // The new plan's first segment (to its first rest after the start), re-timed gentler.
    let e1 = (1..new.t.len()).find(|&k| new.qd[k].iter().all(|v| *v == 0.0))?;
    let mut gentle = robot.clone();
    for (i, &ji) in robot.dof_joints().iter().enumerate() {
        let mut l = robot.limits()[i];
        l.max_acceleration *= 1.0 - frac;
        gentle.set_joint_limits(ji, l);
    }
    let first = time_parameterize(&[new.q[0].clone(), new.q[e1].clone()], &gentle, 0.0);
    let shift = first.duration() - new.t[e1];
    let mut renewed = first;
    for k in e1 + 1..new.t.len() {
        renewed.t.push(new.t[k] + shift);
        renewed.q.push(new.q[k].clone());
        renewed.qd.push(new.qd[k].clone());
    }
    // Superpose over the braking's span T, at every control step and every knot of N there.
    let total = n as f64 * dt;
    let mut times: Vec<f64> = (1..=n).map(|k| k as f64 * dt).collect();
    times.extend(renewed.t.iter().copied().filter(|&t| t > 0.0 && t < total));
    times.sort_by(f64::total_cmp);
    times.dedup_by(|a, b| (*a - *b).abs() < 1e-7);
    let mut out = Trajectory { joint_names: old.joint_names.clone(), t: Vec::new(), q: Vec::new(), qd: Vec::new() };
    for k in 0..old.t.len() {
        if old.t[k] >= j.t_brake - 1e-9 {
            break;
        }
        out.t.push(old.t[k]);
        out.q.push(old.q[k].clone());
        out.qd.push(old.qd[k].clone());
    }
    let first_blended = out.t.len();
    out.t.push(j.t_brake);
    out.q.push(qb.clone());
    out.qd.push(qdb.clone());
    for &tau in &times {
        let (x, v) = (tau - tau * tau / (2.0 * total), 1.0 - tau / total);
        let (qn, qdn, _) = renewed.sample(tau);
        out.t.push(j.t_brake + tau);
        out.q.push((0..dof).map(|i| qb[i] + qdb[i] * x + qn[i] - q_stop[i]).collect());
        out.qd.push((0..dof).map(|i| qdb[i] * v + qdn[i]).collect());
    }
    for k in 1..renewed.t.len() {
        if renewed.t[k] > total + 1e-7 {
            out.t.push(j.t_brake + renewed.t[k]);
            out.q.push(renewed.q[k].clone());
            out.qd.push(renewed.qd[k].clone());
        }
    }
    // The superposed part (and the first sample of N after it) within every limit and free.
    let last_blended = (first_blended + times.len() + 1).min(out.t.len() - 1);
    let mut limits = LimitsChecker::new(robot, &CheckSettings::default());
    for k in first_blended..=last_blended {
        limits.push(out.t[k], &out.q[k], &out.qd[k]);
    }
    if limits.violations() > 0 {
        return None;
    }
    let mut scratch = model.scratch();
    for k in first_blended..last_blended {
        if !model.motion_is_free_with(&out.q[k], &out.q[k + 1], resolution, &mut scratch) {
            return None;
        }
    }
    Some(out)
}

/// A delivery of the plan asked for in motion: joined to the path being followed when it is in
/// time, for this world and the plan still followed; discarded otherwise.
#[allow(clippy::too_many_arguments)]
fn deliver_join(
    s: &mut DeliberativeState,
    j: Join,
    d: PlanDelivery,
    in_time: bool,
    planning_ms: f64,
    wall: Option<WallTiming>,
    inputs: &InputImages,
    outputs: &mut OutputImages,
) {
    let (step, id) = (inputs.step(), d.id);
    let following = s.plan.as_ref().filter(|p| p.id == j.plan).map(|p| (p.trajectory.clone(), p.started_at));
    match d.outcome {
        PlanOutcome::Ready(trajectory) => {
            let stale = if d.world_version != s.world_version {
                Some(format!("world {} != {}", d.world_version, s.world_version))
            } else if !in_time || following.is_none() {
                Some("start state moved".to_string())
            } else if s.faulty() {
                Some("fault".to_string())
            } else {
                None
            };
            match (stale, following) {
                (None, Some((old, started_at))) => {
                    outputs.event(Event::PlanLanded {
                        id,
                        world: d.world_version,
                        in_time,
                        work: d.work,
                        planning_ms,
                        duration_s: trajectory.duration(),
                        wall,
                    });
                    let frac = s.settings.brake_fraction.clamp(0.05, 1.0);
                    let blended = blend(
                        &old,
                        &j,
                        &trajectory,
                        inputs.dt(),
                        &s.robot,
                        frac,
                        &s.collision,
                        s.settings.verify_resolution,
                    );
                    let moving = blended.is_some();
                    let joined = blended.unwrap_or_else(|| splice(&old, &j, &trajectory, inputs.dt()));
                    let now = step.saturating_sub(started_at) as f64 * inputs.dt();
                    let join_in_s = (j.t_brake + j.brake_q.len() as f64 * inputs.dt() - now).max(0.0);
                    outputs.event(Event::PlanJoined { id, plan: j.plan, join_in_s, moving });
                    s.attempts = 0;
                    s.goal_reached = false;
                    s.plan = Some(ActivePlan { trajectory: Arc::new(joined), id, started_at });
                }
                (why, _) => {
                    let reason = why.unwrap_or_else(|| "the plan it joins is gone".into());
                    outputs.event(Event::PlanDiscarded { id, reason });
                    outputs.event(Event::Replan { reason: ReplanReason::StalePlan });
                    s.next_request_at = step;
                }
            }
        }
        other => {
            // No plan to join: the path ahead is blocked, so stop now.
            match other {
                PlanOutcome::Rejected(v) => outputs.event(Event::PlanRejected { id, reason: v.to_string() }),
                PlanOutcome::Failed(f) => {
                    outputs.event(Event::PlanFailed { id, in_time, reason: f.to_string(), planning_ms, wall })
                }
                PlanOutcome::Panicked(m) => outputs.event(Event::PlannerPanicked { id, message: m.to_string() }),
                PlanOutcome::Ready(_) => {}
            }
            s.plan = None;
            s.attempts += 1;
            s.next_request_at = step + s.settings.retry_after_steps;
        }
    }
}

/// Index of the last sample at or before time `t` of `traj`.
fn sample_at(traj: &Trajectory, t: f64) -> usize {
    traj.t.partition_point(|x| *x <= t).saturating_sub(1)
}

fn remaining_collides(model: &CollisionModel, traj: &Trajectory, from: usize, resolution: f64) -> bool {
    path_collides(model, traj, from, traj.q.len().saturating_sub(1), resolution)
}

/// Whether the path through samples `from..=to` of `traj` collides.
fn path_collides(model: &CollisionModel, traj: &Trajectory, from: usize, to: usize, resolution: f64) -> bool {
    let mut scratch = model.scratch();
    let stride = 4.0 * resolution.max(1e-4);
    let mut knot = from;
    let n = (to + 1).min(traj.q.len());
    for k in from + 1..n {
        let last = k + 1 == n;
        let next_far = !last && traj.q[k + 1].iter().zip(&traj.q[knot]).any(|(a, b)| (a - b).abs() > stride);
        if (last || next_far) && !model.motion_is_free_with(&traj.q[knot], &traj.q[k], resolution, &mut scratch) {
            return true;
        }
        if last || next_far {
            knot = k;
        }
    }
    from < n && model.collides_with(&traj.q[from], &mut scratch)
}

/// A deliberative agent in a few lines: `robot` at `start` planning to `goal` in `collision`'s
/// environment, its program the [`PlanFollower`]; with `settings.obstacle_sensing` it also gets
/// an obstacle detector and an [`UnmappedObstacle`] virtual sensor (index 0).
pub fn deliberative_agent(
    name: impl Into<String>,
    robot: Arc<Robot>,
    collision: CollisionModel,
    start: &[f64],
    goal: Goal,
    settings: DeliberationSettings,
) -> Result<Agent<DeliberativeState>, ExecutorError> {
    let dof = robot.dof();
    let mut sizes = vec![("start configuration", start.len())];
    match &goal {
        Goal::Configuration(q) => sizes.push(("goal configuration", q.len())),
        Goal::AnyOf(qs) => sizes.extend(qs.iter().map(|q| ("goal configuration", q.len()))),
        Goal::ToolPose { .. } => {}
    }
    for (what, len) in sizes {
        if len != dof {
            return Err(ExecutorError::DimensionMismatch { what: what.into(), expected: dof, got: len });
        }
    }
    let sensing = settings.obstacle_sensing;
    let state = DeliberativeState::new(robot.clone(), collision, goal, settings);
    let mut agent = Agent::embodied(name, robot, Some(start), state, PlanFollower::new("deliberative"))?;
    if let Some(range) = sensing {
        agent = agent
            .with_sensor(UnmappedObstacle::default(), SensorConfig::default())
            .with_receptors(ReceptorSpec { detector_range: Some(range), ..ReceptorSpec::default() });
    }
    Ok(agent)
}
