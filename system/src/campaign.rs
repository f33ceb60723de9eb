//! The fault campaign: many random scenarios with injected faults, every run's log checked by
//! the independent log verifier.
//!
//! Each run draws, from its seed, a scenario: one or two arms (built-in robots or a random
//! URDF arm), obstacles on the map, an obstacle that appears and may move, start and goal
//! configurations, a planning deadline, and zero to three faults ([`crate::faults`]). It runs
//! with the simulated planning clock and writes its log; then, from the log alone:
//!
//! * [`verify_log`]: positions, velocities and accelerations within the limits at every step,
//!   the log complete and parseable to its end;
//! * [`verify_log_environment`]: no robot touches an obstacle on the map between steps; contacts
//!   with obstacles that appear or move are counted, apart for robots at rest;
//! * every injected fault answered by its reaction ([`crate::faults`]'s table) within one
//!   control step of when it is due;
//! * every `determinism_every`-th run is run twice: the same seed must give the same bytes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use embodied_executor::{Event, HaltReason};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::{Isometry3, Vector3};
use embodied_models::rng::Rng;
use embodied_models::{Robot, Shape};
use embodied_planner::verify::CheckSettings;
use serde::Serialize;
use serde_json::Value;

use crate::SystemError;
use crate::faults::{FaultKind, FaultSpec, FaultTrigger, Injection};
use crate::log::{LogStep, RunLog};
use crate::scenario::{AgentSpec, ClockSpec, GoalSpec, ObstacleSpec, PlannerSpec, Scenario};
use crate::system::{RunOptions, System};
use crate::verify::{verify_log, verify_log_environment};

/// Simulated seconds per run.
pub const RUN_SECONDS: f64 = 3.0;

/// Steps of sensor silence an agent tolerates (the deliberation settings' `sensor_max_age`).
const SENSOR_MAX_AGE: u64 = 50;

/// A campaign's settings.
#[derive(Debug, Clone)]
pub struct CampaignSettings {
    /// Runs.
    pub runs: usize,
    /// Seed of the first run (run `k` has seed `seed + k`).
    pub seed: u64,
    /// Every this many runs, one is run twice and its bytes compared (0: never).
    pub determinism_every: usize,
    /// Where the logs are written (each is removed after it is checked, unless kept).
    pub dir: PathBuf,
    /// Keep every run's log (`campaign-SEED-PID.jsonl` in `dir`), not only those of runs that
    /// broke a promise.
    pub keep_logs: bool,
}

/// How one injected fault was answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Answer {
    /// Its reaction came when due.
    Answered,
    /// No reaction was due: the agent was already halting for a sensor fault, had not been
    /// granted its motion, the request was dropped before its answer was due, the run ended
    /// first, or a sensor dropout shorter than the agent tolerates.
    NotDue,
    /// No reaction, or a wrong one (a bad plan followed, a late plan followed in time).
    Unanswered,
}

/// One run of a campaign.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Its seed.
    pub seed: u64,
    /// Robots of its agents.
    pub robots: Vec<String>,
    /// The faults injected and how each was answered.
    pub faults: Vec<(Injection, Answer)>,
    /// `goal_reached`, `goal_not_reached` or `failed` (the run stopped early).
    pub outcome: String,
    /// Controlled stops begun.
    pub halts: usize,
    /// Stops whose path was blocked (`stop_path_blocked`).
    pub stops_blocked: usize,
    /// Longest halt, s.
    pub longest_halt_s: f64,
    /// Limit violations the log verifier found.
    pub limit_violations: usize,
    /// Largest |qd| / max velocity.
    pub max_velocity_ratio: f64,
    /// Largest |qdd| / max acceleration.
    pub max_acceleration_ratio: f64,
    /// Motions touching an obstacle on the map.
    pub map_collisions: usize,
    /// Steps a moving robot touched an obstacle that appeared or moves.
    pub moving_contacts: usize,
    /// Steps an obstacle that appeared or moves touched a robot at rest.
    pub resting_contacts: usize,
    /// Closest approach to an obstacle on the map, m.
    pub closest_approach_m: f64,
    /// Whether the log was complete and parseable to its end.
    pub log_complete: bool,
    /// Whether a second run gave the same bytes (`None`: not checked).
    pub deterministic: Option<bool>,
    /// What went wrong, if anything.
    pub problems: Vec<String>,
    /// Where the run's log was kept: when something went wrong, or when asked to keep every
    /// log (deleted otherwise).
    pub kept_log: Option<String>,
}

impl RunReport {
    /// Whether the run broke a promise: limits, map collisions, an unanswered fault, an
    /// incomplete log, another log for the same seed.
    pub fn violated(&self) -> bool {
        !self.problems.is_empty()
    }
}

/// Per fault kind: injected, answered, not due, unanswered.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultCount {
    /// Injected.
    pub injected: usize,
    /// Answered when due.
    pub answered: usize,
    /// No reaction due.
    pub not_due: usize,
    /// Not answered.
    pub unanswered: usize,
}

/// What a campaign found (`embodied campaign --json` writes it; `--merge` reads several back).
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignReport {
    /// Runs.
    pub runs: usize,
    /// First seed.
    pub seed: u64,
    /// Per fault kind.
    pub faults: BTreeMap<String, FaultCount>,
    /// Per outcome.
    pub outcomes: BTreeMap<String, usize>,
    /// Runs per robot.
    pub robots: BTreeMap<String, usize>,
    /// Controlled stops begun.
    pub halts: usize,
    /// Stops whose path was blocked.
    pub stops_blocked: usize,
    /// Runs that broke a promise.
    pub violating_runs: usize,
    /// Limit violations.
    pub limit_violations: usize,
    /// Motions touching an obstacle on the map.
    pub map_collisions: usize,
    /// Steps a moving robot touched an obstacle that appeared or moves.
    pub moving_contacts: usize,
    /// Steps an obstacle that appeared or moves touched a robot at rest.
    pub resting_contacts: usize,
    /// Incomplete logs.
    pub incomplete_logs: usize,
    /// Runs checked for determinism, and how many gave other bytes.
    pub determinism_checked: usize,
    /// Runs whose second run gave other bytes.
    pub nondeterministic: usize,
    /// Worst: closest approach to an obstacle on the map, m (infinite, written `null`, when no
    /// run had one).
    #[serde(deserialize_with = "infinite_if_null")]
    pub closest_approach_m: f64,
    /// Worst: largest velocity ratio.
    pub max_velocity_ratio: f64,
    /// Worst: largest acceleration ratio.
    pub max_acceleration_ratio: f64,
    /// Worst: longest halt, s.
    pub longest_halt_s: f64,
    /// Seeds of the runs that broke a promise, with the first problem.
    pub violations: Vec<(u64, String)>,
}

/// JSON has no infinity: serde_json writes it `null`.
fn infinite_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// One report of the campaigns `reports` (each with the file it came from) ran: their seeds
/// must make one range with no seed twice and none missing (the chunks of one campaign run
/// apart, e.g. one per core or machine).
pub fn merge_reports(reports: &[(PathBuf, CampaignReport)]) -> Result<CampaignReport, SystemError> {
    let mut order: Vec<&(PathBuf, CampaignReport)> = reports.iter().collect();
    order.sort_by_key(|(_, r)| r.seed);
    let Some((_, first)) = order.first() else {
        return Err(SystemError::Usage("campaign --merge: no report given".into()));
    };
    let mut merged = CampaignReport { seed: first.seed, closest_approach_m: f64::INFINITY, ..Default::default() };
    let mut next: Option<(u64, &PathBuf)> = None;
    for (file, r) in order {
        if let Some((expected, previous)) = next
            && r.seed != expected
        {
            let what = if r.seed < expected { "overlap" } else { "leave a gap" };
            return Err(SystemError::Usage(format!(
                "{} (seeds {}-{}) and {} (from seed {}) {what}: the next report must start at seed {expected}",
                previous.display(),
                merged.seed,
                expected.saturating_sub(1),
                file.display(),
                r.seed
            )));
        }
        merged.merge(r);
        next = Some((r.seed.saturating_add(r.runs as u64), file));
    }
    Ok(merged)
}

impl CampaignReport {
    /// Add the counts and worst figures of `other` (a campaign over other seeds).
    pub fn merge(&mut self, other: &CampaignReport) {
        self.runs += other.runs;
        for (kind, c) in &other.faults {
            let m = self.faults.entry(kind.clone()).or_default();
            m.injected += c.injected;
            m.answered += c.answered;
            m.not_due += c.not_due;
            m.unanswered += c.unanswered;
        }
        for (k, v) in &other.outcomes {
            *self.outcomes.entry(k.clone()).or_default() += v;
        }
        for (k, v) in &other.robots {
            *self.robots.entry(k.clone()).or_default() += v;
        }
        self.halts += other.halts;
        self.stops_blocked += other.stops_blocked;
        self.violating_runs += other.violating_runs;
        self.limit_violations += other.limit_violations;
        self.map_collisions += other.map_collisions;
        self.moving_contacts += other.moving_contacts;
        self.resting_contacts += other.resting_contacts;
        self.incomplete_logs += other.incomplete_logs;
        self.determinism_checked += other.determinism_checked;
        self.nondeterministic += other.nondeterministic;
        self.closest_approach_m = self.closest_approach_m.min(other.closest_approach_m);
        self.max_velocity_ratio = self.max_velocity_ratio.max(other.max_velocity_ratio);
        self.max_acceleration_ratio = self.max_acceleration_ratio.max(other.max_acceleration_ratio);
        self.longest_halt_s = self.longest_halt_s.max(other.longest_halt_s);
        self.violations.extend(other.violations.iter().cloned());
    }

    /// The report of the one run `r`.
    fn of_run(r: &RunReport) -> CampaignReport {
        let mut one = CampaignReport {
            runs: 1,
            seed: r.seed,
            halts: r.halts,
            stops_blocked: r.stops_blocked,
            limit_violations: r.limit_violations,
            map_collisions: r.map_collisions,
            moving_contacts: r.moving_contacts,
            resting_contacts: r.resting_contacts,
            incomplete_logs: usize::from(!r.log_complete),
            determinism_checked: usize::from(r.deterministic.is_some()),
            nondeterministic: usize::from(r.deterministic == Some(false)),
            closest_approach_m: r.closest_approach_m,
            max_velocity_ratio: r.max_velocity_ratio,
            max_acceleration_ratio: r.max_acceleration_ratio,
            longest_halt_s: r.longest_halt_s,
            ..CampaignReport::default()
        };
        for (inj, answer) in &r.faults {
            let c = one.faults.entry(inj.kind.as_str().to_string()).or_default();
            c.injected += 1;
            match answer {
                Answer::Answered => c.answered += 1,
                Answer::NotDue => c.not_due += 1,
                Answer::Unanswered => c.unanswered += 1,
            }
        }
        one.outcomes.insert(r.outcome.clone(), 1);
        for robot in &r.robots {
            *one.robots.entry(robot.clone()).or_default() += 1;
        }
        if r.violated() {
            one.violating_runs = 1;
            let log = r.kept_log.as_ref().map(|p| format!(" (log kept: {p})")).unwrap_or_default();
            one.violations.push((r.seed, format!("{}{log}", r.problems[0])));
        }
        one
    }

    fn add(&mut self, r: &RunReport) {
        self.merge(&Self::of_run(r));
    }
}

/// A random serial arm as URDF text: 3 or 4 revolute joints, random link lengths and limits.
pub fn random_urdf(rng: &mut Rng) -> String {
    let n = 3 + rng.below(2);
    let mut links = String::from("<link name=\"base\"/>\n");
    let mut joints = String::new();
    let mut parent = "base".to_string();
    for i in 0..n {
        let length = rng.range(0.2, 0.45);
        let radius = rng.range(0.03, 0.06);
        let axis = if i == 0 { "0 0 1" } else { "0 1 0" };
        let offset = if i == 0 { 0.1 } else { 0.0 };
        let lim = rng.range(1.5, 3.0);
        let vel = rng.range(0.5, 2.0);
        let name = format!("l{i}");
        links.push_str(&format!(
            "<link name=\"{name}\"><collision><origin xyz=\"0 0 {h}\"/><geometry><cylinder radius=\"{radius:.3}\" length=\"{length:.3}\"/></geometry></collision></link>\n",
            h = length / 2.0
        ));
        let z = if i == 0 { offset } else { 0.0 };
        let prev_len = if i == 0 { 0.0 } else { 1.0 };
        let _ = prev_len;
        joints.push_str(&format!(
            "<joint name=\"j{i}\" type=\"revolute\"><parent link=\"{parent}\"/><child link=\"{name}\"/><origin xyz=\"0 0 {z:.3}\"/><axis xyz=\"{axis}\"/><limit lower=\"{lo:.3}\" upper=\"{lim:.3}\" velocity=\"{vel:.3}\" effort=\"10\"/></joint>\n",
            lo = -lim
        ));
        // The next joint sits at the end of this link.
        links.push_str(&format!("<link name=\"{name}_end\"/>\n"));
        joints.push_str(&format!(
            "<joint name=\"{name}_tip\" type=\"fixed\"><parent link=\"{name}\"/><child link=\"{name}_end\"/><origin xyz=\"0 0 {length:.3}\"/></joint>\n"
        ));
        parent = format!("{name}_end");
    }
    format!("<?xml version=\"1.0\"?>\n<robot name=\"random-arm\">\n{links}{joints}</robot>\n")
}

fn robot_for(rng: &mut Rng) -> Result<(String, Robot), SystemError> {
    let pick = rng.below(4);
    let name = ["rnt", "polycrank", "irp6-postument", "urdf"][pick];
    if name == "urdf" {
        let text = random_urdf(rng);
        let options = embodied_models::urdf::UrdfOptions::default();
        let robot = embodied_models::urdf::parse_urdf(&text, Path::new("<campaign>/random-arm.urdf"), &options)?;
        return Ok(("urdf-arm".into(), robot));
    }
    Ok((name.into(), embodied_models::builtin(name)?))
}

/// A collision-free configuration in the middle of the limits (self-collision and `env`), within
/// the strokes of the robot's screws.
fn free_configuration(robot: &Robot, model: &CollisionModel, rng: &mut Rng) -> Option<Vec<f64>> {
    let limits = robot.limits();
    for _ in 0..60 {
        let q: Vec<f64> = limits
            .iter()
            .map(|l| {
                let (lo, hi) = if l.is_bounded() { (l.lower, l.upper) } else { (-3.0, 3.0) };
                lo + rng.range(0.2, 0.8) * (hi - lo)
            })
            .collect();
        if robot.check_configuration(&q).is_ok() && !model.collides(&q) {
            return Some(q);
        }
    }
    None
}

/// One run in this many is the two-handed carry with a `qp_infeasible` fault.
pub const CARRY_EVERY: u64 = 40;

/// Simulated seconds of a carry run (the bar is held from 1.80 s to 3.34 s, the goal reached at
/// 3.88 s).
pub const CARRY_SECONDS: f64 = 6.0;

/// The carry run of seed `seed`: the built-in `two-irp6-carry`, shortened, its closed-chain QP
/// reporting infeasible once at a random time of the hold (or, one run in four, never).
pub fn carry_scenario(seed: u64) -> Result<Scenario, SystemError> {
    let mut rng = Rng::new(seed ^ 0xCA22_7000);
    let mut scenario = crate::scenario::load_scenario("two-irp6-carry")?;
    scenario.name = format!("campaign-{seed}");
    scenario.seed = seed;
    scenario.run.duration = Some(CARRY_SECONDS);
    if rng.below(4) != 0 {
        let trigger = if rng.below(3) == 0 {
            FaultTrigger::Probability(rng.range(0.0005, 0.003))
        } else {
            FaultTrigger::At(rng.range(1.75, 3.4))
        };
        scenario
            .faults
            .push(FaultSpec { seed: Some(rng.next_u64()), ..FaultSpec::new(FaultKind::QpInfeasible, trigger) });
    }
    Ok(scenario)
}

/// The random scenario of seed `seed` (one in [`CARRY_EVERY`] a [`carry_scenario`]).
pub fn random_scenario(seed: u64) -> Result<Scenario, SystemError> {
    if seed % CARRY_EVERY == CARRY_EVERY - 1 {
        return carry_scenario(seed);
    }
    let mut rng = Rng::new(seed ^ 0x5EED_CA4A_16B1);
    let n_agents = if rng.below(4) == 0 { 2 } else { 1 };
    let mut builder = Scenario::builder(format!("campaign-{seed}"))
        .description("a random scenario of the fault campaign")
        .seed(seed)
        .duration(RUN_SECONDS);
    // Obstacles on the map: spheres and boxes around the first robot's base.
    let mut map = Environment::new();
    for k in 0..rng.below(3) {
        let p = Vector3::new(rng.range(-0.9, 0.9), rng.range(-0.9, 0.9), rng.range(0.0, 1.2));
        let shape = if rng.below(2) == 0 {
            Shape::Sphere { radius: rng.range(0.05, 0.15) }
        } else {
            Shape::Cuboid {
                half_extents: Vector3::new(rng.range(0.03, 0.12), rng.range(0.03, 0.12), rng.range(0.03, 0.12)),
            }
        };
        map.add(Obstacle::new(format!("map-{k}"), Isometry3::translation(p.x, p.y, p.z), shape));
    }
    let mut robots = Vec::new();
    let mut starts = Vec::new();
    let mut goals = Vec::new();
    for k in 0..n_agents {
        let (name, mut robot) = robot_for(&mut rng)?;
        if k == 1 {
            robot.set_base(Isometry3::translation(0.0, 1.8, 0.0) * robot.base());
        }
        let model = CollisionModel::new(&robot, map.clone());
        let (Some(start), Some(goal)) =
            (free_configuration(&robot, &model, &mut rng), free_configuration(&robot, &model, &mut rng))
        else {
            // No free configurations among these obstacles: a scenario without them.
            return random_scenario(seed.wrapping_add(0x9E37_79B9));
        };
        robots.push(name);
        starts.push(start);
        goals.push(goal);
        builder = builder.agent(
            AgentSpec::new(format!("arm{k}"), robot)
                .start(starts[k].clone())
                .goal(GoalSpec::Configuration(goals[k].clone())),
        );
    }
    for o in map.obstacles() {
        builder = builder.obstacle(o.clone());
    }
    // An obstacle that appears during the run, near the first arm's straight path from start to
    // goal, and perhaps moves; not on the arm where it stands at the start.
    if rng.below(3) != 0 {
        let probe = builder.clone().build()?;
        let robot = &probe.agents[0].robot;
        let s = rng.range(0.2, 0.8);
        let q: Vec<f64> = starts[0].iter().zip(&goals[0]).map(|(a, b)| a + s * (b - a)).collect();
        let tool = if robot.end_effectors().is_empty() {
            Vector3::new(0.5, 0.0, 0.5)
        } else {
            robot.end_effector_poses(&q, 0).1.translation.vector
        };
        let p = tool + Vector3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
        let radius = rng.range(0.04, 0.1);
        let obstacle = Obstacle::new("intruder", Isometry3::translation(p.x, p.y, p.z), Shape::Sphere { radius });
        let on_start = CollisionModel::new(robot, Environment::new().with(obstacle.clone())).collides(&starts[0]);
        if !on_start {
            let velocity = (rng.below(2) == 0)
                .then(|| Vector3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.05, 0.05)));
            builder = builder.obstacle_spec(ObstacleSpec { obstacle, appear_at: Some(rng.range(0.1, 2.0)), velocity });
        }
    }
    // Faults: every kind but the carry's QP (link faults only where there are links).
    let kinds: Vec<FaultKind> = FaultKind::ALL
        .into_iter()
        .filter(|k| *k != FaultKind::QpInfeasible && (n_agents > 1 || !k.is_link()))
        .collect();
    for _ in 0..rng.below(4) {
        let kind = kinds[rng.below(kinds.len())];
        let trigger = if kind.is_link() && rng.below(2) == 0 {
            // Around the grants, where the protocol's messages are.
            FaultTrigger::At(rng.range(0.0, 0.3))
        } else if rng.below(10) < 7 {
            FaultTrigger::At(rng.range(0.0, 2.5))
        } else if kind.is_planner() {
            FaultTrigger::Probability(rng.range(0.2, 0.6))
        } else {
            FaultTrigger::Probability(rng.range(0.0005, 0.003))
        };
        let duration = match kind {
            FaultKind::SensorDropout => rng.range(0.01, 0.3),
            FaultKind::LinkLoss | FaultKind::LinkDelay => rng.range(0.05, 1.0),
            FaultKind::TrackingError => rng.range(0.01, 0.5),
            _ => rng.range(0.0, 0.05),
        };
        let mut spec = FaultSpec { duration, seed: Some(rng.next_u64()), ..FaultSpec::new(kind, trigger) };
        if kind.is_link() {
            let k = rng.below(n_agents);
            spec.link = match rng.below(3) {
                0 => None,
                1 => Some(format!("coordinator->arm{k}")),
                _ => Some(format!("arm{k}->coordinator")),
            };
            spec.loss = if rng.below(2) == 0 { 1.0 } else { rng.range(0.3, 1.0) };
            spec.delay = rng.range(0.01, 0.3);
        } else if n_agents > 1 && rng.below(2) == 0 {
            spec.agent = Some(format!("arm{}", rng.below(n_agents)));
        }
        builder = builder.fault(spec);
    }
    let deadline_ms = [0.0, 20.0, 100.0, 300.0][rng.below(4)];
    builder = builder.planner(PlannerSpec {
        deadline_ms,
        give_up_ms: 1000.0,
        seed,
        certify: true,
        resolution: 0.02,
        expansions: None,
        clock: ClockSpec::Simulated { us_per_check: crate::scenario::DEFAULT_US_PER_CHECK },
    });
    builder.build()
}

/// A run with its log: the system, how the run ended, the log's bytes.
type LoggedRun = (System, Result<(), SystemError>, Vec<u8>);

/// Run `scenario` writing its log to `path`.
fn run_logged(scenario: &Scenario, path: &Path) -> Result<LoggedRun, SystemError> {
    let mut system = System::new(scenario, &RunOptions::default())?;
    let mut log = RunLog::create(Some(path))?;
    log.line(&serde_json::json!({ "header": system.header() }))?;
    let mut log_error = None;
    let until = system.duration();
    let result = system.run_until(until, |r| {
        if log_error.is_none()
            && let Err(e) = log.line(&LogStep::of(r))
        {
            log_error = Some(e);
        }
    });
    if let Some(e) = log_error {
        return Err(e);
    }
    log.line(&serde_json::json!({ "summary": system.summary().replayable() }))?;
    drop(log);
    let bytes = std::fs::read(path).map_err(|e| SystemError::io(path, e))?;
    Ok((system, result, bytes))
}

/// The events of a log: (step, agent, event).
fn log_events(bytes: &[u8]) -> Vec<(u64, String, Event)> {
    let text = String::from_utf8_lossy(bytes);
    let mut out = Vec::new();
    for line in text.lines().skip(1) {
        let Ok(v) = serde_json::from_str::<Value>(line) else { break };
        let Some(step) = v.get("step").and_then(Value::as_u64) else { continue };
        let Some(agents) = v.get("agents").and_then(Value::as_object) else { continue };
        for (name, a) in agents {
            if let Some(events) = a.get("events")
                && let Ok(events) = serde_json::from_value::<Vec<Event>>(events.clone())
            {
                out.extend(events.into_iter().map(|e| (step, name.clone(), e)));
            }
        }
    }
    out
}

/// In a coordinated run (the log has a `granted` event), every agent that moved before its
/// `grant_received`: (agent, first step it moved).
fn moved_without_grant(bytes: &[u8]) -> Vec<(String, u64)> {
    let text = String::from_utf8_lossy(bytes);
    let mut coordinated = false;
    let mut granted: BTreeMap<String, bool> = BTreeMap::new();
    let mut moved: BTreeMap<String, u64> = BTreeMap::new();
    for line in text.lines().skip(1) {
        let Ok(v) = serde_json::from_str::<Value>(line) else { break };
        let Some(step) = v.get("step").and_then(Value::as_u64) else { continue };
        let Some(agents) = v.get("agents").and_then(Value::as_object) else { continue };
        for (name, a) in agents {
            let events: Vec<Event> =
                a.get("events").and_then(|e| serde_json::from_value(e.clone()).ok()).unwrap_or_default();
            coordinated |= events.iter().any(|e| matches!(e, Event::Granted { .. }));
            if events.iter().any(|e| matches!(e, Event::GrantReceived)) {
                granted.insert(name.clone(), true);
            }
            let moving = a
                .get("qd")
                .and_then(Value::as_array)
                .is_some_and(|qd| qd.iter().any(|x| x.as_f64().is_some_and(|x| x != 0.0)));
            if moving && !granted.get(name).copied().unwrap_or(false) {
                moved.entry(name.clone()).or_insert(step);
            }
        }
    }
    if coordinated { moved.into_iter().collect() } else { Vec::new() }
}

/// How the log answered `inj` (see [`Answer`]).
fn answer(
    inj: &Injection,
    all: &[Injection],
    events: &[(u64, String, Event)],
    agent: &str,
    deadline_steps: u64,
    last_step: u64,
) -> Answer {
    let mine = || events.iter().filter(|(_, a, _)| a == agent);
    // Whether the agent's obstacle sensor was in fault at `step` (before the step's events).
    let in_fault = |step: u64| {
        let mut fault = false;
        for (s, _, e) in mine() {
            if *s >= step {
                break;
            }
            match e {
                Event::SensorSilent { .. } | Event::SensorNonFinite | Event::SensorImplausible { .. } => fault = true,
                Event::SensorRecovered => fault = false,
                _ => {}
            }
        }
        fault
    };
    let granted_by = |step: u64| {
        let coordinated = events.iter().any(|(_, _, e)| matches!(e, Event::Granted { .. }));
        !coordinated || mine().any(|(s, _, e)| *s <= step && matches!(e, Event::GrantReceived))
    };
    let event_at =
        |from: u64, to: u64, f: &dyn Fn(&Event) -> bool| mine().any(|(s, _, e)| *s >= from && *s <= to && f(e));
    match inj.kind {
        FaultKind::PlannerPanic | FaultKind::PlanOverLimits | FaultKind::PlannerLate => {
            let Some(id) = inj.request else { return Answer::Unanswered };
            let landed = mine().find_map(|(s, _, e)| match e {
                Event::PlanLanded { id: i, in_time, .. } if *i == id => Some((*s, *in_time)),
                _ => None,
            });
            let answered = mine().any(|(_, _, e)| match (inj.kind, e) {
                (FaultKind::PlannerPanic, Event::PlannerPanicked { id: i, .. }) => *i == id,
                (FaultKind::PlanOverLimits, Event::PlanRejected { id: i, .. } | Event::PlanFailed { id: i, .. }) => {
                    *i == id
                }
                (FaultKind::PlannerLate, Event::PlanLate { id: i }) => *i == id,
                _ => false,
            });
            match (inj.kind, landed) {
                // A bad plan must never drive the effector; a late one never in time.
                (FaultKind::PlanOverLimits | FaultKind::PlannerPanic, Some(_)) => return Answer::Unanswered,
                (FaultKind::PlannerLate, Some((_, true))) => return Answer::Unanswered,
                _ => {}
            }
            if inj.kind == FaultKind::PlannerLate {
                // Due at the deadline: `plan_late` at the request's step + the deadline.
                let due = inj.step + deadline_steps;
                if event_at(inj.step, due + 1, &|e| matches!(e, Event::PlanLate { id: i } if *i == id)) {
                    return Answer::Answered;
                }
                if due + 1 > last_step || answered {
                    return if answered { Answer::Unanswered } else { Answer::NotDue };
                }
            } else if answered {
                return Answer::Answered;
            }
            // The request was dropped before its answer was due (a sensor fault, the effector
            // off its command, the run ended), or a newer request of the agent replaced it.
            let dropped = mine().any(|(s, _, e)| {
                *s >= inj.step
                    && (matches!(
                        e,
                        Event::SensorSilent { .. }
                            | Event::SensorNonFinite
                            | Event::SensorImplausible { .. }
                            | Event::PlanLost { .. }
                            | Event::ForceLimit { .. }
                            | Event::TrackingError { .. }
                    ) || matches!(e, Event::PlanRequested { id: i, .. } if *i > id))
            });
            if dropped || inj.kind != FaultKind::PlannerLate {
                // Panics and over-limit plans are answered when the answer lands, which may be
                // after the run's end or never, if the request was dropped.
                return if dropped || !answered { Answer::NotDue } else { Answer::Answered };
            }
            Answer::Unanswered
        }
        FaultKind::PlanCollides => {
            let Some(id) = inj.request else { return Answer::Unanswered };
            let landed = mine().any(|(_, _, e)| matches!(e, Event::PlanLanded { id: i, .. } if *i == id));
            let refused = mine().any(|(_, _, e)| {
                matches!(e, Event::PlanRejected { id: i, .. } | Event::PlanFailed { id: i, .. } if *i == id)
            });
            if landed {
                Answer::Unanswered
            } else if refused {
                Answer::Answered
            } else {
                // The answer never came back in the run (dropped, or after the end).
                Answer::NotDue
            }
        }
        FaultKind::QpInfeasible => {
            let halted = |e: &Event| matches!(e, Event::HaltStarted { reason: HaltReason::ClosedChain, .. });
            if event_at(inj.step, inj.step + 1, &halted) { Answer::Answered } else { Answer::Unanswered }
        }
        FaultKind::TrackingError => {
            let Some(due) = inj.due else { return Answer::NotDue };
            // Already halted for the effector (no recovery since an earlier tracking error).
            let mut effector_fault = false;
            for (s, _, e) in mine() {
                if *s >= due {
                    break;
                }
                match e {
                    Event::TrackingError { .. } => effector_fault = true,
                    Event::EffectorRecovered => effector_fault = false,
                    _ => {}
                }
            }
            if effector_fault || due + 1 > last_step {
                return Answer::NotDue;
            }
            if event_at(due, due + 1, &|e| matches!(e, Event::TrackingError { .. })) {
                Answer::Answered
            } else {
                Answer::Unanswered
            }
        }
        FaultKind::ObstacleInPath => {
            if inj.obstacle.is_none() || inj.step + 1 > last_step || in_fault(inj.step + 1) || !granted_by(inj.step) {
                return Answer::NotDue;
            }
            let blind = all.iter().any(|d| {
                d.kind == FaultKind::SensorDropout
                    && d.agent == inj.agent
                    && d.step <= inj.step + 1
                    && inj.step < d.step + d.steps
            });
            if blind {
                return Answer::NotDue;
            }
            if event_at(inj.step, inj.step + 1, &|e| matches!(e, Event::WorldChanged { .. })) {
                Answer::Answered
            } else {
                Answer::Unanswered
            }
        }
        FaultKind::LinkLoss | FaultKind::LinkDelay => {
            if inj.messages == 0 {
                return Answer::NotDue;
            }
            // Every grant sent reaches its agent, unless the run ended before the grant could be
            // sent again and arrive (the protocol's answer; motion without a grant is checked
            // for every run apart).
            let granted: Vec<(u64, &str)> = events
                .iter()
                .filter_map(|(s, _, e)| match e {
                    Event::Granted { agent } | Event::GrantResent { agent, .. } => Some((*s, agent.as_str())),
                    _ => None,
                })
                .collect();
            let delay_steps = inj.delay_steps;
            for (_, name) in &granted {
                let received = events.iter().any(|(_, a, e)| a == name && matches!(e, Event::GrantReceived));
                if received {
                    continue;
                }
                let last_sent = granted.iter().filter(|(_, a)| a == name).map(|(s, _)| *s).max().unwrap_or(0);
                let window_end = inj.step + inj.steps;
                if last_step < window_end.max(last_sent) + crate::system::RESEND_STEPS + 2 + delay_steps {
                    return Answer::NotDue;
                }
                return Answer::Unanswered;
            }
            Answer::Answered
        }
        FaultKind::SensorNan | FaultKind::SensorWild | FaultKind::SensorDropout => {
            // A reading during a dropout of the same sensor never reaches the agent.
            let blind = all.iter().any(|d| {
                d.kind == FaultKind::SensorDropout
                    && d.agent == inj.agent
                    && d != inj
                    && d.step <= inj.step
                    && inj.step < d.step + d.steps
            });
            if blind && inj.kind != FaultKind::SensorDropout {
                return Answer::NotDue;
            }
            let due = match inj.kind {
                FaultKind::SensorDropout if inj.steps <= SENSOR_MAX_AGE => return Answer::NotDue,
                FaultKind::SensorDropout => inj.step + SENSOR_MAX_AGE,
                _ => inj.step,
            };
            if due > last_step || in_fault(due) || !granted_by(due) {
                return Answer::NotDue;
            }
            let want = |e: &Event| match inj.kind {
                FaultKind::SensorNan => matches!(e, Event::SensorNonFinite),
                FaultKind::SensorWild => matches!(e, Event::SensorImplausible { .. }),
                _ => matches!(e, Event::SensorSilent { .. }),
            };
            // Another fault of the same sensor may win the step (e.g. a dropout hides a NaN).
            let other = |e: &Event| {
                matches!(e, Event::SensorSilent { .. } | Event::SensorNonFinite | Event::SensorImplausible { .. })
            };
            if event_at(due, due + 1, &want) {
                Answer::Answered
            } else if event_at(inj.step, due + 1, &other) {
                Answer::NotDue
            } else {
                Answer::Unanswered
            }
        }
    }
}

/// Run the campaign's run of seed `seed`, logging into `dir`; `twice`: run it again and
/// compare the bytes.
pub fn run_one(seed: u64, dir: &Path, twice: bool) -> Result<RunReport, SystemError> {
    let scenario = random_scenario(seed)?;
    run_checked(&scenario, seed, dir, twice)
}

/// [`run_one`], keeping the log whatever the run's verdict when `keep_log` is set.
pub fn run_one_keeping(seed: u64, dir: &Path, twice: bool, keep_log: bool) -> Result<RunReport, SystemError> {
    let scenario = random_scenario(seed)?;
    check_run(&scenario, seed, dir, twice, keep_log)
}

/// Run `scenario` (with its own seed; `seed` names the run), logging into `dir`, and check its
/// log as the campaign does; `twice`: run it again and compare the bytes.
pub fn run_checked(scenario: &Scenario, seed: u64, dir: &Path, twice: bool) -> Result<RunReport, SystemError> {
    check_run(scenario, seed, dir, twice, false)
}

fn check_run(
    scenario: &Scenario,
    seed: u64,
    dir: &Path,
    twice: bool,
    keep_log: bool,
) -> Result<RunReport, SystemError> {
    let scenario = scenario.clone();
    std::fs::create_dir_all(dir).map_err(|e| SystemError::write(dir.to_path_buf(), e))?;
    let path = dir.join(format!("campaign-{seed}-{}.jsonl", std::process::id()));
    let (system, result, bytes) = run_logged(&scenario, &path)?;
    let mut problems = Vec::new();
    let injections = system.injections();
    let verification = verify_log(&scenario, &path, &CheckSettings::default())?;
    // The obstacles that faults put in the way are checked like those that appear.
    let mut seen = scenario.clone();
    for inj in &injections {
        if let Some((c, r)) = inj.obstacle {
            let obstacle = Obstacle::new(
                format!("in-path-{}", inj.step),
                Isometry3::translation(c[0], c[1], c[2]),
                Shape::Sphere { radius: r },
            );
            seen.obstacles.push(ObstacleSpec { obstacle, appear_at: Some(inj.step as f64 * 0.001), velocity: None });
        }
    }
    let environment = verify_log_environment(&seen, &path, scenario.planner.resolution)?;
    let deterministic = if twice {
        let (_, _, again) = run_logged(&scenario, &path)?;
        Some(again == bytes)
    } else {
        None
    };
    let events = log_events(&bytes);
    let last_step = system.runtime().current_step().saturating_sub(1);
    let deadline_steps = (scenario.planner.deadline_ms / 1e3 / 0.001).ceil() as u64;
    let faults: Vec<(Injection, Answer)> = injections
        .iter()
        .map(|inj| {
            let agent = scenario.agents.get(inj.agent).map_or("coordinator", |a| a.name.as_str());
            let a = answer(inj, &injections, &events, agent, deadline_steps, last_step);
            (inj.clone(), a)
        })
        .collect();
    let summary = system.summary();
    let limit_violations: usize = verification.agents.iter().map(|a| a.violations).sum();
    if limit_violations > 0 {
        let first = verification.agents.iter().find_map(|a| a.violation.as_ref()).map(|f| format!("{f:?}"));
        problems.push(format!("{limit_violations} limit violations: {}", first.unwrap_or_default()));
    }
    if !verification.complete {
        problems.push(format!("log incomplete: {}", verification.note.clone().unwrap_or_default()));
    }
    if environment.map_collisions > 0 {
        problems.push(format!("collision: {}", environment.first.clone().unwrap_or_default()));
    }
    for (inj, a) in &faults {
        if *a == Answer::Unanswered {
            problems.push(format!(
                "fault {} at step {} (request {:?}) not answered",
                inj.kind.as_str(),
                inj.step,
                inj.request
            ));
        }
    }
    for (agent, step) in moved_without_grant(&bytes) {
        problems.push(format!("agent {agent} moved at step {step} before its grant arrived"));
    }
    if deterministic == Some(false) {
        problems.push("the same seed gave other bytes".into());
    }
    // A run that broke a promise keeps its log, named in the report, for the post-mortem.
    let kept_log = if problems.is_empty() && !keep_log {
        let _ = std::fs::remove_file(&path);
        None
    } else {
        Some(path.display().to_string())
    };
    let outcome = if result.is_err() || summary.failure.is_some() {
        "failed"
    } else if summary.agents.iter().all(|a| a.goal_reached) {
        "goal_reached"
    } else {
        "goal_not_reached"
    };
    let halts = events.iter().filter(|(_, _, e)| matches!(e, Event::HaltStarted { .. })).count();
    let stops_blocked = events.iter().filter(|(_, _, e)| matches!(e, Event::StopPathBlocked { .. })).count();
    let longest_halt_s = events
        .iter()
        .filter_map(|(_, _, e)| match e {
            Event::HaltFinished { time_s, .. } => Some(*time_s),
            _ => None,
        })
        .fold(0.0, f64::max);
    Ok(RunReport {
        seed,
        robots: scenario.agents.iter().map(|a| a.robot.name().to_string()).collect(),
        faults,
        outcome: outcome.into(),
        halts,
        stops_blocked,
        longest_halt_s,
        limit_violations,
        max_velocity_ratio: verification.agents.iter().map(|a| a.max_velocity_ratio).fold(0.0, f64::max),
        max_acceleration_ratio: verification.agents.iter().map(|a| a.max_acceleration_ratio).fold(0.0, f64::max),
        map_collisions: environment.map_collisions,
        moving_contacts: environment.moving_contacts,
        resting_contacts: environment.resting_contacts,
        closest_approach_m: environment.closest_approach_m,
        log_complete: verification.complete,
        deterministic,
        problems,
        kept_log,
    })
}

/// Run a campaign, calling `progress` after every run.
pub fn campaign(
    settings: &CampaignSettings,
    mut progress: impl FnMut(&RunReport),
) -> Result<CampaignReport, SystemError> {
    std::fs::create_dir_all(&settings.dir).map_err(|e| SystemError::write(settings.dir.clone(), e))?;
    let mut report =
        CampaignReport { seed: settings.seed, closest_approach_m: f64::INFINITY, ..CampaignReport::default() };
    for k in 0..settings.runs {
        let seed = settings.seed.wrapping_add(k as u64);
        let twice = settings.determinism_every > 0 && k % settings.determinism_every == 0;
        let r = run_one_keeping(seed, &settings.dir, twice, settings.keep_logs)?;
        report.add(&r);
        progress(&r);
    }
    Ok(report)
}

/// The campaign's table as text.
pub fn render_campaign(r: &CampaignReport) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(out, "campaign: {} runs from seed {}", r.runs, r.seed);
    let robots: Vec<String> = r.robots.iter().map(|(k, v)| format!("{k} {v}")).collect();
    let _ = writeln!(out, "robots (agents): {}", robots.join(", "));
    let outcomes: Vec<String> = r.outcomes.iter().map(|(k, v)| format!("{k} {v}")).collect();
    let _ = writeln!(out, "outcomes: {}", outcomes.join(", "));
    let _ = writeln!(out, "{:<18} {:>9} {:>9} {:>8} {:>11}", "fault", "injected", "answered", "not due", "unanswered");
    for (k, c) in &r.faults {
        let _ = writeln!(out, "{k:<18} {:>9} {:>9} {:>8} {:>11}", c.injected, c.answered, c.not_due, c.unanswered);
    }
    let _ = writeln!(out, "halts: {} (stop path blocked: {})", r.halts, r.stops_blocked);
    let _ = writeln!(
        out,
        "violations: {} runs; limits {}, map collisions {}, incomplete logs {}, other bytes for the same seed {} of {} checked",
        r.violating_runs,
        r.limit_violations,
        r.map_collisions,
        r.incomplete_logs,
        r.nondeterministic,
        r.determinism_checked
    );
    let _ = writeln!(
        out,
        "contacts with obstacles that appear or move: {} steps while moving, {} at rest",
        r.moving_contacts, r.resting_contacts
    );
    let _ = writeln!(
        out,
        "worst: closest approach {:.3e} m, |qd|/vmax {:.4}, |qdd|/amax {:.4}, longest halt {:.3} s",
        r.closest_approach_m, r.max_velocity_ratio, r.max_acceleration_ratio, r.longest_halt_s
    );
    for (seed, why) in r.violations.iter().take(20) {
        let _ = writeln!(out, "  seed {seed}: {why}");
    }
    out
}
