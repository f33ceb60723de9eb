//! Fault injection: faults as a typed part of a scenario (`[[faults]]`), injected into a run at
//! a time or with a probability, reproducibly from a seed, and the reaction each one must get.
//!
//! | kind | injected where | reaction (typed events) |
//! |---|---|---|
//! | `planner_late` | the planner's answer (a plan or a failure) takes far longer than the deadline | `plan_late` for that request at its deadline step, with a halt (`halt_started reason=plan_late`); the plan never drives the effector late |
//! | `planner_panic` | the planner panics | `planner_panicked` for that request the step its answer is due; the agent holds and retries |
//! | `plan_over_limits` | the planner's trajectory made at least three times faster, its fastest joint at 1.5 times its velocity limit at least | `plan_rejected` for that request the step its answer is due: the verifier refuses it, it never drives the effector |
//! | `plan_collides` | the planner's plan made to pass through a configuration in collision (an obstacle, the floor or the robot itself) | `plan_rejected` for that request the step its answer is due: the gate's certificate refuses it, it never drives the effector; the agent holds and plans again |
//! | `sensor_dropout` | the obstacle sensor gives no fresh reading for `duration` | `sensor_silent` once the sensor has been silent longer than the agent tolerates (`sensor_max_age` steps), then a halt (`reason=fault`) until `sensor_recovered` |
//! | `sensor_nan` | the obstacle sensor reads NaN | `sensor_non_finite` the same step, a halt (`reason=fault`) |
//! | `sensor_wild` | the obstacle sensor reads an absurd finite value (1e9 m) | `sensor_implausible` the same step, a halt (`reason=fault`) |
//! | `qp_infeasible` | the two-handed carry's closed-chain QP reports infeasible (from the first closed-chain step at or after `at`) | `halt_started reason=closed_chain` the same step: the pair stops and stays stopped, the object held |
//! | `link_loss` | messages on `link` (`"coordinator->arm1"`, or every link) are lost, each with probability `loss`, for `duration` | the protocol's: an agent never moves without its grant; a grant counts only once the occupancies it depends on arrived; the coordinator sends an unacknowledged grant again (`grant_resent`) every 100 steps; agents repeat their last announcement and `done` |
//! | `link_delay` | messages on `link` are delayed by `delay` s for `duration` (in order: none overtakes another) | the same protocol: late messages are waited for; a late acknowledgement makes a `grant_resent`, harmless |
//! | `tracking_error` | the effector's fastest joint stops following its commands (it brakes at its acceleration limit and stays) for `duration` | `tracking_error` one step after the joint is first off its command by more than the bound (`0.1 a dt^2`), with a halt (`reason=fault`, every joint braking at its limit) until `effector_recovered` |
//! | `obstacle_in_path` | a ball appears on the path being executed, where the tool will be 0.05 to 0.3 s later (or on the straight way to the goal when at rest) | `world_changed` the same step (the detector reports the nearest unmapped obstacle), then a replan in motion, a halt along the path, or a stop off it (`stop_path_blocked`) when the stop along the path would hit it |
//!
//! A sensor fault while the sensor is already in fault, or during a dropout of the same sensor
//! (the reading never reaches the agent), needs no new reaction (the agent is already halting
//! for it). Planner faults are drawn per request, QP faults per closed-chain step, the others
//! per control step.

use std::sync::{Arc, Mutex};

use embodied_executor::deliberation::PlanMotion;
use embodied_executor::world::ReceptorReadings;
use embodied_executor::{
    AgentId, Effector, JointCommand, LinkFaults, Reading, SensorConfig, Transit, VirtualSensor, tracking_bound,
};
use embodied_models::JointLimits;
use embodied_planner::deadline::Deadline;
use embodied_planner::request::{MotionPlanner, PlanFailure, PlanRequest, Planned};
use serde::{Deserialize, Serialize};

/// What goes wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum FaultKind {
    /// The planner answers far past its deadline.
    PlannerLate,
    /// The planner panics.
    PlannerPanic,
    /// The planner's plan violates the velocity and acceleration limits.
    PlanOverLimits,
    /// The obstacle sensor stops answering for a while.
    SensorDropout,
    /// The obstacle sensor reads NaN.
    SensorNan,
    /// The obstacle sensor reads an absurd finite value.
    SensorWild,
    /// The planner's plan passes through a configuration in collision.
    PlanCollides,
    /// The carry's closed-chain QP reports infeasible.
    QpInfeasible,
    /// Messages on a link are lost.
    LinkLoss,
    /// Messages on a link are delayed.
    LinkDelay,
    /// A joint of the effector does not follow its commands.
    TrackingError,
    /// An obstacle appears on the path being executed.
    ObstacleInPath,
}

impl FaultKind {
    /// Every kind, in the order of the table above.
    pub const ALL: [FaultKind; 12] = [
        FaultKind::PlannerLate,
        FaultKind::PlannerPanic,
        FaultKind::PlanOverLimits,
        FaultKind::PlanCollides,
        FaultKind::SensorDropout,
        FaultKind::SensorNan,
        FaultKind::SensorWild,
        FaultKind::QpInfeasible,
        FaultKind::LinkLoss,
        FaultKind::LinkDelay,
        FaultKind::TrackingError,
        FaultKind::ObstacleInPath,
    ];

    /// The name as in a scenario (`kind = "..."`).
    pub fn as_str(&self) -> &'static str {
        match self {
            FaultKind::PlannerLate => "planner_late",
            FaultKind::PlannerPanic => "planner_panic",
            FaultKind::PlanOverLimits => "plan_over_limits",
            FaultKind::SensorDropout => "sensor_dropout",
            FaultKind::SensorNan => "sensor_nan",
            FaultKind::SensorWild => "sensor_wild",
            FaultKind::PlanCollides => "plan_collides",
            FaultKind::QpInfeasible => "qp_infeasible",
            FaultKind::LinkLoss => "link_loss",
            FaultKind::LinkDelay => "link_delay",
            FaultKind::TrackingError => "tracking_error",
            FaultKind::ObstacleInPath => "obstacle_in_path",
        }
    }

    /// The kind named `name`.
    pub fn parse(name: &str) -> Option<FaultKind> {
        FaultKind::ALL.into_iter().find(|k| k.as_str() == name)
    }

    /// Whether the fault is the planner's (drawn per request).
    pub fn is_planner(&self) -> bool {
        matches!(
            self,
            FaultKind::PlannerLate | FaultKind::PlannerPanic | FaultKind::PlanOverLimits | FaultKind::PlanCollides
        )
    }

    /// Whether the fault is the obstacle sensor's.
    pub fn is_sensor(&self) -> bool {
        matches!(self, FaultKind::SensorDropout | FaultKind::SensorNan | FaultKind::SensorWild)
    }

    /// Whether the fault is a link's.
    pub fn is_link(&self) -> bool {
        matches!(self, FaultKind::LinkLoss | FaultKind::LinkDelay)
    }
}

/// When a fault strikes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultTrigger {
    /// Once, at this time (s): a sensor fault at the step, a planner fault on the first request
    /// made at or after it.
    At(f64),
    /// With this probability per control step (sensor faults) or per plan request (planner faults).
    Probability(f64),
}

/// One `[[faults]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultSpec {
    /// What goes wrong.
    pub kind: FaultKind,
    /// The agent it strikes (`None`: every agent that plans).
    pub agent: Option<String>,
    /// When.
    pub trigger: FaultTrigger,
    /// How long a fault lasts, s (at least one step).
    pub duration: f64,
    /// Seed of the draws (`None`: the scenario's).
    pub seed: Option<u64>,
    /// Link faults: the link (`"coordinator->arm1"`, `"arm1->coordinator"`; `None`: every link).
    pub link: Option<String>,
    /// `link_loss`: probability that each message in the window is lost.
    pub loss: f64,
    /// `link_delay`: extra time in transit, s.
    pub delay: f64,
}

/// Default `loss` of a `link_loss`: every message in the window.
pub const DEFAULT_LOSS: f64 = 1.0;
/// Default `delay` of a `link_delay`, s.
pub const DEFAULT_DELAY: f64 = 0.05;
/// Longest `delay` accepted, s.
pub const MAX_DELAY: f64 = 60.0;

impl FaultSpec {
    /// `kind` at time `at` (s), on every planning agent, lasting one step.
    pub fn at(kind: FaultKind, at: f64) -> Self {
        Self::new(kind, FaultTrigger::At(at))
    }

    /// `kind` struck by `trigger`, on every planning agent (every link), lasting one step.
    pub fn new(kind: FaultKind, trigger: FaultTrigger) -> Self {
        Self {
            kind,
            agent: None,
            trigger,
            duration: 0.0,
            seed: None,
            link: None,
            loss: DEFAULT_LOSS,
            delay: DEFAULT_DELAY,
        }
    }

    /// `kind` with probability `p` per step or request, on every planning agent.
    pub fn with_probability(kind: FaultKind, p: f64) -> Self {
        Self::new(kind, FaultTrigger::Probability(p))
    }

    /// Only on link `link` (`"from->to"`).
    pub fn on_link(mut self, link: impl Into<String>) -> Self {
        self.link = Some(link.into());
        self
    }

    /// The ends of the link (`"from->to"`), when one is named.
    pub fn link_ends(&self) -> Option<Result<(&str, &str), String>> {
        let link = self.link.as_deref()?;
        Some(match link.split_once("->") {
            Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() => Ok((a.trim(), b.trim())),
            _ => Err(format!("link: expected \"FROM->TO\" (e.g. \"coordinator->arm1\"), got \"{link}\"")),
        })
    }

    /// Only on agent `name`.
    pub fn on(mut self, name: impl Into<String>) -> Self {
        self.agent = Some(name.into());
        self
    }

    /// Lasting `seconds` (sensor faults).
    pub fn lasting(mut self, seconds: f64) -> Self {
        self.duration = seconds;
        self
    }

    /// Check the numbers; the message names what was expected.
    pub fn check(&self) -> Result<(), String> {
        match self.trigger {
            FaultTrigger::At(t) if !(t.is_finite() && t >= 0.0) => {
                return Err(format!("at: expected a time >= 0 s, got {t}"));
            }
            FaultTrigger::Probability(p) if !(p.is_finite() && (0.0..=1.0).contains(&p)) => {
                return Err(format!("probability: expected a number in [0, 1], got {p}"));
            }
            _ => {}
        }
        if !(self.duration.is_finite() && self.duration >= 0.0) {
            return Err(format!("duration: expected a time >= 0 s, got {}", self.duration));
        }
        if !(self.loss.is_finite() && (0.0..=1.0).contains(&self.loss)) {
            return Err(format!("loss: expected a probability in [0, 1], got {}", self.loss));
        }
        if !(self.delay.is_finite() && (0.0..=MAX_DELAY).contains(&self.delay)) {
            return Err(format!("delay: expected a time in [0, {MAX_DELAY}] s, got {}", self.delay));
        }
        if let Some(Err(e)) = self.link_ends() {
            return Err(e);
        }
        if self.link.is_some() && !self.kind.is_link() {
            return Err(format!(
                "link: only link faults (link_loss, link_delay) name a link, not {}",
                self.kind.as_str()
            ));
        }
        Ok(())
    }
}

/// One fault as it was injected.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Injection {
    /// What.
    pub kind: FaultKind,
    /// The agent's scenario index (link faults: the scenario's agent count, the coordinator).
    pub agent: usize,
    /// The step it struck, or the step of the request it struck (planner faults).
    pub step: u64,
    /// The request it struck (planner faults).
    pub request: Option<u64>,
    /// Steps it lasts.
    pub steps: u64,
    /// Link faults: the link (`None`: every link).
    pub link: Option<String>,
    /// Link faults: messages lost or delayed.
    pub messages: u64,
    /// `link_delay`: extra steps in transit.
    pub delay_steps: u64,
    /// `tracking_error`: the step at which a joint was first off its command by more than the
    /// bound (the reaction is due the step after).
    pub due: Option<u64>,
    /// `obstacle_in_path`: the ball that appeared (centre, radius), when one could be placed.
    pub obstacle: Option<([f64; 3], f64)>,
}

impl Injection {
    /// `kind` on agent `agent` at step `step`, lasting `steps`.
    pub fn new(kind: FaultKind, agent: usize, step: u64, steps: u64) -> Self {
        Self {
            kind,
            agent,
            step,
            request: None,
            steps,
            link: None,
            messages: 0,
            delay_steps: 0,
            due: None,
            obstacle: None,
        }
    }
}

/// Push `inj` into `injections`; its index.
fn record(injections: &Injections, inj: Injection) -> usize {
    let mut v = injections.lock().unwrap_or_else(|e| e.into_inner());
    v.push(inj);
    v.len() - 1
}

/// Change injection `index`.
fn update(injections: &Injections, index: usize, f: impl FnOnce(&mut Injection)) {
    let mut v = injections.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(inj) = v.get_mut(index) {
        f(inj);
    }
}

/// The windows of one windowed fault (sensor, link, effector, obstacle): when each starts and
/// how long it lasts.
#[derive(Debug, Clone)]
pub struct Windows {
    /// Index of the fault in the scenario.
    pub index: usize,
    /// The fault.
    pub spec: FaultSpec,
    /// Seed of its draws.
    pub seed: u64,
    /// The step its current window ends (exclusive).
    pub until: u64,
}

impl Windows {
    /// The windows of fault `index` (`spec`, drawn from `seed`).
    pub fn new(index: usize, spec: FaultSpec, seed: u64) -> Self {
        Self { index, spec, seed, until: 0 }
    }

    /// Whether a window starts at `step` (and if so, it is open from now on for [`Self::steps`]).
    pub fn starts(&mut self, step: u64, dt: f64) -> bool {
        let starts = match self.spec.trigger {
            FaultTrigger::At(t) => step == (t / dt).round() as u64,
            FaultTrigger::Probability(p) => step >= self.until && draw(self.seed, self.index as u64, step) < p,
        };
        if starts {
            self.until = step + self.steps(dt);
        }
        starts
    }

    /// Steps a window lasts (at least one).
    pub fn steps(&self, dt: f64) -> u64 {
        ((self.spec.duration / dt).round() as u64).max(1)
    }

    /// Whether a window is open at `step`.
    pub fn open(&self, step: u64) -> bool {
        step < self.until
    }
}

/// The injections of a run, shared by the injecting wrappers.
pub type Injections = Arc<Mutex<Vec<Injection>>>;

/// A draw in [0, 1) from `(seed, a, b)`: splitmix64, so that runs replay.
pub fn draw(seed: u64, a: u64, b: u64) -> f64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED69);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Work added to a late plan: at the simulated clock's microseconds per check, hours.
const LATE_WORK: u64 = 1_000_000_000;

/// The planner of an agent with planner faults: the motion planner, with the faults injected.
pub struct FaultyPlanner {
    inner: PlanMotion,
    agent: usize,
    faults: Vec<(usize, FaultSpec, u64)>,
    dt: f64,
    fired: Mutex<Vec<bool>>,
    injections: Injections,
}

impl FaultyPlanner {
    /// `inner` with `faults` (index in the scenario, spec, seed) for scenario agent `agent`.
    pub fn new(
        inner: PlanMotion,
        agent: usize,
        faults: Vec<(usize, FaultSpec, u64)>,
        dt: f64,
        injections: Injections,
    ) -> Self {
        let fired = Mutex::new(vec![false; faults.len()]);
        Self { inner, agent, faults, dt, fired, injections }
    }

    /// The fault that strikes `request`, if any (the first in scenario order).
    fn strikes(&self, request: &PlanRequest) -> Option<FaultKind> {
        let mut fired = self.fired.lock().unwrap_or_else(|e| e.into_inner());
        for (k, (index, spec, seed)) in self.faults.iter().enumerate() {
            let hit = match spec.trigger {
                FaultTrigger::At(t) => !fired[k] && request.step as f64 * self.dt >= t - 1e-12,
                FaultTrigger::Probability(p) => draw(*seed, *index as u64, request.id) < p,
            };
            if hit {
                fired[k] = true;
                return Some(spec.kind);
            }
        }
        None
    }
}

impl MotionPlanner for FaultyPlanner {
    fn plan(&self, request: &PlanRequest, deadline: &Deadline) -> Result<Planned, PlanFailure> {
        let Some(kind) = self.strikes(request) else { return self.inner.plan(request, deadline) };
        record(
            &self.injections,
            Injection { request: Some(request.id), ..Injection::new(kind, self.agent, request.step, 0) },
        );
        match kind {
            FaultKind::PlannerPanic => panic!("injected fault: planner panic"),
            FaultKind::PlannerLate => match self.inner.plan(request, deadline) {
                Ok(mut planned) => {
                    planned.work = planned.work.saturating_add(LATE_WORK);
                    Ok(planned)
                }
                // No plan: the failure comes late instead.
                Err(e) => Err(PlanFailure::OutOfTime { work: LATE_WORK, reason: format!("late: {e}") }),
            },
            FaultKind::PlanOverLimits => {
                let mut planned = self.inner.plan(request, deadline)?;
                // Compress time by `f` (velocities times f, accelerations times f^2) so that the
                // fastest joint runs at 1.5 times its velocity limit at least (3 times faster
                // than planned at least, even for a tiny motion).
                let limits = self.inner.model.robot().limits();
                let traj = &mut planned.trajectory;
                let ratio = traj
                    .qd
                    .iter()
                    .flat_map(|qd| qd.iter().zip(&limits).map(|(v, l)| v.abs() / l.max_velocity))
                    .fold(0.0_f64, f64::max);
                if !(ratio > 0.0 && traj.duration() > 0.0) {
                    // A plan that does not move is within any limits.
                    return Err(PlanFailure::Error("injected fault: no motion to speed up".into()));
                }
                let f = (1.5 / ratio).max(3.0);
                for t in &mut traj.t {
                    *t /= f;
                }
                for qd in &mut traj.qd {
                    for v in qd {
                        *v *= f;
                    }
                }
                Ok(planned)
            }
            FaultKind::PlanCollides => {
                let planned = self.inner.plan(request, deadline)?;
                let Some(end) = planned.trajectory.q.last().cloned() else {
                    return Err(PlanFailure::Error("injected fault: an empty plan".into()));
                };
                let mut model = self.inner.model.clone();
                if let Some(env) = &request.environment {
                    model.set_environment(env.clone());
                }
                let Some(bad) = colliding_configuration(&model, &request.start, &end, request.id) else {
                    // Nothing in reach collides: the fault cannot be made; the planner says so.
                    return Err(PlanFailure::Error("injected fault: no configuration in collision found".into()));
                };
                let path = vec![request.start.clone(), bad, end];
                let trajectory = embodied_planner::trajectory::time_parameterize(&path, model.robot(), 0.0);
                Ok(Planned { trajectory, work: planned.work })
            }
            _ => self.inner.plan(request, deadline),
        }
    }
}

/// A configuration in collision near the way from `start` to `end`: on the straight line
/// first, then drawn within the limits (seeded by `id`).
fn colliding_configuration(
    model: &embodied_models::CollisionModel,
    start: &[f64],
    end: &[f64],
    id: u64,
) -> Option<Vec<f64>> {
    for k in 1..20 {
        let s = k as f64 / 20.0;
        let q: Vec<f64> = start.iter().zip(end).map(|(a, b)| a + s * (b - a)).collect();
        if model.collides(&q) {
            return Some(q);
        }
    }
    let limits = model.robot().limits();
    let mut rng = embodied_models::rng::Rng::new(0xC011_1DE5 ^ id);
    for _ in 0..2000 {
        let q: Vec<f64> = limits
            .iter()
            .map(|l| {
                let (lo, hi) = if l.is_bounded() { (l.lower, l.upper) } else { (-3.0, 3.0) };
                rng.range(lo, hi)
            })
            .collect();
        if model.collides(&q) {
            return Some(q);
        }
    }
    None
}

/// The obstacle sensor of an agent with sensor faults: the wrapped sensor's reading, faulted.
pub struct FaultySensor<S> {
    inner: S,
    agent: usize,
    faults: Vec<Windows>,
    dt: f64,
    /// Whether the last reading dropped out.
    dropped: bool,
    injections: Injections,
}

impl<S> FaultySensor<S> {
    /// `inner` with `faults` (index in the scenario, spec, seed) for scenario agent `agent`.
    pub fn new(inner: S, agent: usize, faults: Vec<(usize, FaultSpec, u64)>, dt: f64, injections: Injections) -> Self {
        let faults = faults.into_iter().map(|(i, f, seed)| Windows::new(i, f, seed)).collect();
        Self { inner, agent, faults, dt, dropped: false, injections }
    }
}

/// The absurd value a `sensor_wild` fault reads, m.
pub const WILD_VALUE: f64 = 1e9;

impl<S: VirtualSensor> VirtualSensor for FaultySensor<S> {
    fn aggregate(&mut self, config: &SensorConfig, receptors: &ReceptorReadings) -> Reading {
        let mut reading = self.inner.aggregate(config, receptors);
        let step = receptors.step;
        self.dropped = false;
        for w in &mut self.faults {
            if w.starts(step, self.dt) {
                record(&self.injections, Injection::new(w.spec.kind, self.agent, step, w.steps(self.dt)));
            }
            if w.open(step) {
                match w.spec.kind {
                    FaultKind::SensorDropout => self.dropped = true,
                    FaultKind::SensorNan => {
                        reading.values[0] = f64::NAN;
                        reading.len = reading.len.max(1);
                    }
                    FaultKind::SensorWild => {
                        reading.values[0] = WILD_VALUE;
                        reading.len = reading.len.max(1);
                    }
                    _ => {}
                }
            }
        }
        reading
    }
    fn dropped_out(&self) -> bool {
        self.dropped
    }
}

/// The effector of an agent with `tracking_error` faults: a servo whose fastest joint, while a
/// window is open, does not follow its commands: it brakes at its acceleration limit and stays
/// at rest (within every limit: the effector never leaves them, faulty or not).
pub struct FaultyEffector<E> {
    inner: E,
    agent: usize,
    faults: Vec<Windows>,
    dt: f64,
    /// The step of the next command (one command per control step).
    step: u64,
    /// Per fault: the stuck joint of the open window and its injection's index.
    stuck: Vec<Option<(usize, usize, bool)>>,
    scratch: JointCommand,
    injections: Injections,
}

impl<E: Effector> FaultyEffector<E> {
    /// `inner` with `faults` (index in the scenario, spec, seed) for scenario agent `agent`.
    pub fn new(inner: E, agent: usize, faults: Vec<(usize, FaultSpec, u64)>, dt: f64, injections: Injections) -> Self {
        let faults: Vec<Windows> = faults.into_iter().map(|(i, f, seed)| Windows::new(i, f, seed)).collect();
        let stuck = vec![None; faults.len()];
        let n = inner.limits().len();
        Self { inner, agent, faults, dt, step: 0, stuck, scratch: JointCommand::hold(&vec![0.0; n]), injections }
    }
}

impl<E: Effector> Effector for FaultyEffector<E> {
    fn limits(&self) -> &[JointLimits] {
        self.inner.limits()
    }
    fn q(&self) -> &[f64] {
        self.inner.q()
    }
    fn qd(&self) -> &[f64] {
        self.inner.qd()
    }
    fn execute(&mut self, command: &JointCommand, dt: f64) {
        // Only reached through the safety limiter, which calls `execute_limited`; kept exact
        // for any other caller.
        self.inner.execute(command, dt);
        self.step += 1;
    }
    fn execute_limited(&mut self, command: &JointCommand, dt: f64) {
        let step = self.step;
        self.step += 1;
        for (k, w) in self.faults.iter_mut().enumerate() {
            if w.starts(step, self.dt) {
                // The fastest joint (relative to its acceleration limit) gets stuck.
                let joint = self
                    .inner
                    .qd()
                    .iter()
                    .zip(self.inner.limits())
                    .enumerate()
                    .max_by(|(_, (a, la)), (_, (b, lb))| {
                        (a.abs() / la.max_acceleration).total_cmp(&(b.abs() / lb.max_acceleration))
                    })
                    .map_or(0, |(j, _)| j);
                let index = record(
                    &self.injections,
                    Injection::new(FaultKind::TrackingError, self.agent, step, w.steps(self.dt)),
                );
                self.stuck[k] = Some((joint, index, false));
            }
            if !w.open(step) {
                self.stuck[k] = None;
            }
        }
        if self.stuck.iter().all(Option::is_none) {
            self.inner.execute_limited(command, dt);
            return;
        }
        self.scratch.clone_from(command);
        let limits = self.inner.limits();
        for (joint, _, _) in self.stuck.iter().flatten() {
            let (j, v) = (*joint, self.inner.qd().get(*joint).copied().unwrap_or(0.0));
            let (Some(lim), true) = (limits.get(j), j < self.scratch.qd.len()) else { continue };
            let dv = lim.max_acceleration * dt;
            let v_next = v - v.clamp(-dv, dv);
            self.scratch.qd[j] = v_next;
            self.scratch.q[j] = lim.clamp(self.inner.q()[j] + v_next * dt);
        }
        self.inner.execute_limited(&self.scratch, dt);
        // When the joint first leaves its command by more than the bound, the reaction is due.
        for s in self.stuck.iter_mut().flatten() {
            let (j, index, seen) = s;
            if *seen {
                continue;
            }
            let (Some(lim), Some(q), Some(c)) = (limits_of(&self.inner, *j), self.inner.q().get(*j), command.q.get(*j))
            else {
                continue;
            };
            if (q - c).abs() > tracking_bound(&lim, dt) {
                *seen = true;
                update(&self.injections, *index, |inj| inj.due = Some(step));
            }
        }
    }
}

fn limits_of<E: Effector>(e: &E, j: usize) -> Option<JointLimits> {
    e.limits().get(j).copied()
}

/// The ends of a link: from, to.
pub type LinkEnds = (AgentId, AgentId);

/// The link faults of a system: windows per fault, opened step by step by [`LinkFaultState::advance`]
/// and asked by the transmitter for every message ([`LinkFaults`]).
pub struct LinkFaultState {
    /// Per fault: its windows, the ends of its link (`None`: every link) and the index of its
    /// current window's injection.
    faults: Vec<(Windows, Option<LinkEnds>, Option<usize>)>,
    dt: f64,
    coordinator: usize,
    sent: u64,
    injections: Injections,
}

impl LinkFaultState {
    /// Link faults (index, spec, seed, link ends) of a system whose coordinator is scenario agent
    /// count `coordinator`.
    pub fn new(
        faults: Vec<(usize, FaultSpec, u64, Option<LinkEnds>)>,
        dt: f64,
        coordinator: usize,
        injections: Injections,
    ) -> Self {
        let faults = faults.into_iter().map(|(i, f, seed, ends)| (Windows::new(i, f, seed), ends, None)).collect();
        Self { faults, dt, coordinator, sent: 0, injections }
    }

    /// Open the windows that start at `step` (before the step's messages are sent).
    pub fn advance(&mut self, step: u64) {
        for (w, _, current) in &mut self.faults {
            if w.starts(step, self.dt) {
                let delay_steps =
                    if w.spec.kind == FaultKind::LinkDelay { (w.spec.delay / self.dt).round() as u64 } else { 0 };
                let inj = Injection {
                    link: w.spec.link.clone(),
                    delay_steps,
                    ..Injection::new(w.spec.kind, self.coordinator, step, w.steps(self.dt))
                };
                *current = Some(record(&self.injections, inj));
            }
        }
    }

    fn transit(&mut self, from: AgentId, to: AgentId, step: u64) -> Transit {
        self.sent += 1;
        let mut lose = false;
        let mut extra = 0;
        for (w, ends, current) in &self.faults {
            if !w.open(step) || ends.is_some_and(|e| e != (from, to)) {
                continue;
            }
            let hit = match w.spec.kind {
                FaultKind::LinkLoss => {
                    let lost = draw(w.seed, w.index as u64, self.sent) < w.spec.loss;
                    lose |= lost;
                    lost
                }
                FaultKind::LinkDelay => {
                    let k = (w.spec.delay / self.dt).round() as u64;
                    // A message delayed past the run's end is simply not delivered in the run.
                    extra = extra.max(k);
                    k > 0
                }
                _ => false,
            };
            if hit && let Some(i) = current {
                update(&self.injections, *i, |inj| inj.messages += 1);
            }
        }
        if lose { Transit::Lose } else { Transit::Deliver { extra } }
    }
}

/// [`LinkFaultState`] shared between the system (which opens the windows) and the transmitter.
#[derive(Clone)]
pub struct SharedLinkFaults(pub Arc<Mutex<LinkFaultState>>);

impl LinkFaults for SharedLinkFaults {
    fn transit(&mut self, from: AgentId, to: AgentId, step: u64) -> Transit {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).transit(from, to, step)
    }
}

/// The closed-chain QP fault of a carry: `qp_infeasible` faults of the carrying agent, struck
/// at the first closed-chain step at or after `at`, or with `probability` per closed-chain step.
pub fn qp_fault(
    agent: usize,
    faults: Vec<(usize, FaultSpec, u64)>,
    dt: f64,
    injections: Injections,
) -> embodied_executor::closed_chain::carry::QpFault {
    let mut fired = vec![false; faults.len()];
    Box::new(move |step: u64| {
        for (k, (index, spec, seed)) in faults.iter().enumerate() {
            let hit = match spec.trigger {
                FaultTrigger::At(t) => !fired[k] && step as f64 * dt >= t - 1e-12,
                FaultTrigger::Probability(p) => draw(*seed, *index as u64, step) < p,
            };
            if hit {
                fired[k] = true;
                record(&injections, Injection::new(FaultKind::QpInfeasible, agent, step, 1));
                return true;
            }
        }
        false
    })
}

/// Where an `obstacle_in_path` ball goes for an agent of `robot` at `(q, qd)`: where its tool
/// (or last link) will be `ahead` s later on its current straight segment (or 2, 4, 8 times
/// later, the first clear of the robot where it is now); at rest, a quarter, half, three
/// quarters or all of the straight way to `goal`. `None` when every such place touches the
/// robot where it is (or it rests at its goal: no path).
pub fn place_obstacle(
    robot: &embodied_models::Robot,
    q: &[f64],
    qd: &[f64],
    goal: Option<&[f64]>,
    ahead: f64,
    radius: f64,
) -> Option<[f64; 3]> {
    if q.len() != robot.dof() {
        return None;
    }
    let moving = qd.iter().any(|v| v.abs() > 1e-6);
    let goal = goal.filter(|g| g.len() == q.len());
    let limits = robot.limits();
    for k in 0..4 {
        let target: Vec<f64> = if moving {
            let tau = ahead * f64::from(1u32 << k);
            q.iter().zip(qd).map(|(a, v)| a + v * tau).collect()
        } else {
            let s = 0.25 * f64::from(k + 1);
            q.iter().zip(goal?).map(|(a, b)| a + s * (b - a)).collect()
        };
        let target: Vec<f64> = target.iter().zip(&limits).map(|(x, l)| l.clamp(*x)).collect();
        let p = if robot.end_effectors().is_empty() {
            robot.forward_kinematics(&target).last()?.translation.vector
        } else {
            robot.end_effector_poses(&target, 0).1.translation.vector
        };
        let ball = embodied_models::collision::Obstacle::new(
            "obstacle_in_path",
            embodied_models::nalgebra::Isometry3::translation(p.x, p.y, p.z),
            embodied_models::Shape::Sphere { radius },
        );
        let env = embodied_models::collision::Environment::new().with(ball);
        if !embodied_models::CollisionModel::new(robot, env).collides(q) {
            return Some([p.x, p.y, p.z]);
        }
    }
    None
}
