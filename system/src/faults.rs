//! Fault injection: faults as a typed part of a scenario (`[[faults]]`), injected into a run at
//! a time or with a probability, reproducibly from a seed, and the reaction each one must get.
//!
//! | kind | injected where | reaction (typed events) |
//! |---|---|---|
//! | `planner_late` | the planner's answer (a plan or a failure) takes far longer than the deadline | `plan_late` for that request at its deadline step, with a halt (`halt_started reason=plan_late`); the plan never drives the effector late |
//! | `planner_panic` | the planner panics | `planner_panicked` for that request the step its answer is due; the agent holds and retries |
//! | `plan_over_limits` | the planner's trajectory made at least three times faster, its fastest joint at 1.5 times its velocity limit at least | `plan_rejected` for that request the step its answer is due: the verifier refuses it, it never drives the effector |
//! | `sensor_dropout` | the obstacle sensor gives no fresh reading for `duration` | `sensor_silent` once the sensor has been silent longer than the agent tolerates (`sensor_max_age` steps), then a halt (`reason=fault`) until `sensor_recovered` |
//! | `sensor_nan` | the obstacle sensor reads NaN | `sensor_non_finite` the same step, a halt (`reason=fault`) |
//! | `sensor_wild` | the obstacle sensor reads an absurd finite value (1e9 m) | `sensor_implausible` the same step, a halt (`reason=fault`) |
//!
//! A sensor fault while the sensor is already in fault, or during a dropout of the same sensor
//! (the reading never reaches the agent), needs no new reaction (the agent is already halting
//! for it). Planner faults are drawn per request, sensor faults per step.

use std::sync::{Arc, Mutex};

use embodied_executor::deliberation::PlanMotion;
use embodied_executor::world::ReceptorReadings;
use embodied_executor::{Reading, SensorConfig, VirtualSensor};
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
}

impl FaultKind {
    /// Every kind, in the order of the table above.
    pub const ALL: [FaultKind; 6] = [
        FaultKind::PlannerLate,
        FaultKind::PlannerPanic,
        FaultKind::PlanOverLimits,
        FaultKind::SensorDropout,
        FaultKind::SensorNan,
        FaultKind::SensorWild,
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
        }
    }

    /// The kind named `name`.
    pub fn parse(name: &str) -> Option<FaultKind> {
        FaultKind::ALL.into_iter().find(|k| k.as_str() == name)
    }

    /// Whether the fault is the planner's (drawn per request) rather than the sensor's (per step).
    pub fn is_planner(&self) -> bool {
        matches!(self, FaultKind::PlannerLate | FaultKind::PlannerPanic | FaultKind::PlanOverLimits)
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
    /// How long a sensor fault lasts, s (at least one step).
    pub duration: f64,
    /// Seed of the draws (`None`: the scenario's).
    pub seed: Option<u64>,
}

impl FaultSpec {
    /// `kind` at time `at` (s), on every planning agent, lasting one step.
    pub fn at(kind: FaultKind, at: f64) -> Self {
        Self { kind, agent: None, trigger: FaultTrigger::At(at), duration: 0.0, seed: None }
    }

    /// `kind` with probability `p` per step or request, on every planning agent.
    pub fn with_probability(kind: FaultKind, p: f64) -> Self {
        Self { kind, agent: None, trigger: FaultTrigger::Probability(p), duration: 0.0, seed: None }
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
        Ok(())
    }
}

/// One fault as it was injected.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Injection {
    /// What.
    pub kind: FaultKind,
    /// The agent's scenario index.
    pub agent: usize,
    /// The step it struck (sensor faults), or the step of the request it struck (planner faults).
    pub step: u64,
    /// The request it struck (planner faults).
    pub request: Option<u64>,
    /// Steps a sensor fault lasts.
    pub steps: u64,
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
        self.injections.lock().unwrap_or_else(|e| e.into_inner()).push(Injection {
            kind,
            agent: self.agent,
            step: request.step,
            request: Some(request.id),
            steps: 0,
        });
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
            _ => self.inner.plan(request, deadline),
        }
    }
}

/// The obstacle sensor of an agent with sensor faults: the wrapped sensor's reading, faulted.
pub struct FaultySensor<S> {
    inner: S,
    agent: usize,
    faults: Vec<(usize, FaultSpec, u64)>,
    dt: f64,
    /// Per fault: the step its current window ends (exclusive).
    until: Vec<u64>,
    /// Whether the last reading dropped out.
    dropped: bool,
    injections: Injections,
}

impl<S> FaultySensor<S> {
    /// `inner` with `faults` (index in the scenario, spec, seed) for scenario agent `agent`.
    pub fn new(inner: S, agent: usize, faults: Vec<(usize, FaultSpec, u64)>, dt: f64, injections: Injections) -> Self {
        let until = vec![0; faults.len()];
        Self { inner, agent, faults, dt, until, dropped: false, injections }
    }
}

/// The absurd value a `sensor_wild` fault reads, m.
pub const WILD_VALUE: f64 = 1e9;

impl<S: VirtualSensor> VirtualSensor for FaultySensor<S> {
    fn aggregate(&mut self, config: &SensorConfig, receptors: &ReceptorReadings) -> Reading {
        let mut reading = self.inner.aggregate(config, receptors);
        let step = receptors.step;
        self.dropped = false;
        for (k, (index, spec, seed)) in self.faults.iter().enumerate() {
            let starts = match spec.trigger {
                FaultTrigger::At(t) => step == (t / self.dt).round() as u64,
                FaultTrigger::Probability(p) => step >= self.until[k] && draw(*seed, *index as u64, step) < p,
            };
            if starts {
                let steps = ((spec.duration / self.dt).round() as u64).max(1);
                self.until[k] = step + steps;
                self.injections.lock().unwrap_or_else(|e| e.into_inner()).push(Injection {
                    kind: spec.kind,
                    agent: self.agent,
                    step,
                    request: None,
                    steps,
                });
            }
            if step < self.until[k] {
                match spec.kind {
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
