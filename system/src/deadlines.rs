//! `embodied bench deadlines`: how deliberative agents fare under planning deadlines.
//!
//! For every deadline and every problem (the agents with goals of the built-in scenarios, and
//! optionally a sample of MotionBenchMaker UR5 problems), a deliberative agent
//! ([`embodied_executor::deliberative_agent`], wall-clock [`PlanClock`]) asks for a plan from its
//! start to its goal; the search ([`embodied_planner::motion::plan_motion`]) is stopped at the
//! deadline. Once the agent moves, a far obstacle appears (its world model changes), so it
//! halts from speed and must replan under the same deadline. Everything is read back from the
//! run's log events: the share of plans delivered within the deadline, the safe halts with
//! their stopping distance and time, and the deadline overshoot (how long past the deadline a
//! stopped search took to return).
//!
//! Scenarios with a `[task]` form a third set, `tasks`: the whole system runs on the wall
//! clock with the task-level deliberation (A* over production rules plus the refinement of
//! its operators into certified motion) given the deadline as its budget. A task plan counts
//! as in time when it lands within the deadline; while none is there the arms hold at rest
//! (a halt at zero speed); a deliberation stopped by the deadline reports its overshoot.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use embodied_executor::deliberation::{DeliberationSettings, PlanBudget, PlanClock, deliberative_agent};
use embodied_executor::{Event, Obstacle, Runtime, RuntimeConfig, StepRecord, WallTiming};
use embodied_models::CollisionModel;
use embodied_planner::motion::Goal;

use crate::SystemError;
use crate::plan::{agent_problem, goal_of};
use crate::scenario::load_scenario;

/// A sample of MotionBenchMaker problems to add to the built-in scenarios.
#[derive(Debug, Clone)]
pub struct MbmSample {
    /// The robot's URDF file.
    pub urdf: PathBuf,
    /// The robot's SRDF file.
    pub srdf: PathBuf,
    /// Folder of family folders (e.g. the unpacked `problems/`).
    pub problems: PathBuf,
    /// How many problems, spread evenly over the families.
    pub count: usize,
}

/// What to run.
#[derive(Debug, Clone)]
pub struct DeadlineArgs {
    /// Planning deadlines, milliseconds.
    pub deadlines_ms: Vec<f64>,
    /// Built-in scenario names or scenario files (empty: every built-in scenario).
    pub scenarios: Vec<String>,
    /// MotionBenchMaker problems to add.
    pub mbm: Option<MbmSample>,
    /// Upper bound on control steps per run (dt = 1 ms).
    pub max_steps: u64,
    /// Seed of the runtime and the planner.
    pub seed: u64,
    /// Planner seeds per planning problem (at least 1): a scenario agent's problem is planned
    /// with its scenario's planner seed and the next `planner_seeds - 1`, a MotionBenchMaker
    /// problem with `seed` and the next ones; each seed counts as a problem of its own
    /// (`name#k` from the second). A planner's time on one problem depends on its random
    /// stream far more than on a setting, so comparing settings at tight deadlines needs many.
    pub planner_seeds: u64,
}

impl Default for DeadlineArgs {
    fn default() -> Self {
        Self {
            deadlines_ms: vec![0.5, 1.0, 2.0, 5.0, 10.0, 50.0],
            scenarios: Vec::new(),
            mbm: None,
            max_steps: 60_000,
            seed: 1,
            planner_seeds: 1,
        }
    }
}

/// One safe halt.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct HaltRecord {
    /// `scenario/agent` or `family/index` of the problem.
    pub problem: String,
    /// Largest joint travel from the start of the halt to rest (rad or m).
    pub distance: f64,
    /// Duration of the halt, ms.
    pub time_ms: f64,
}

/// Results for one deadline over one problem set.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DeadlineRow {
    /// `scenarios` or `mbm`.
    pub set: String,
    /// The planning deadline, ms.
    pub deadline_ms: f64,
    /// Problems run.
    pub problems: usize,
    /// Plans asked for.
    pub requested: usize,
    /// Verified plans that came within the deadline.
    pub delivered_in_time: usize,
    /// `delivered_in_time / requested` (0 when nothing was asked).
    pub delivered_share: f64,
    /// Problems whose goal was reached.
    pub goals_reached: usize,
    /// Safe halts begun.
    pub safe_halts: usize,
    /// Halts from speed (the others are holds at rest while a plan is late).
    pub halts_from_speed: usize,
    /// Largest joint travel during a halt from speed (rad or m): mean and max.
    pub halt_distance_mean: f64,
    /// Largest joint travel of any halt from speed (rad or m).
    pub halt_distance_max: f64,
    /// Duration of a halt from speed, ms: mean and max.
    pub halt_time_mean_ms: f64,
    /// Longest halt from speed, ms.
    pub halt_time_max_ms: f64,
    /// Searches stopped by the deadline.
    pub stopped: usize,
    /// How long past the deadline a stopped search returned, µs: median and max.
    pub overshoot_p50_us: f64,
    /// Largest overshoot of a stopped search past the deadline, µs.
    pub overshoot_max_us: f64,
    /// Every halt from speed.
    pub halts: Vec<HaltRecord>,
}

/// The whole benchmark.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DeadlineReport {
    /// The program (version and commit) that made the report.
    pub generator: String,
    /// `scenario/agent` or `family/index` of every problem, per set.
    pub problems: Vec<(String, String)>,
    /// One row per deadline and problem set.
    pub rows: Vec<DeadlineRow>,
}

struct Problem {
    set: &'static str,
    name: String,
    collision: CollisionModel,
    start: Vec<f64>,
    goal: Goal,
    seed: u64,
    resolution: f64,
}

/// The scenarios with a `[task]` among those the benchmark covers.
fn task_scenarios(args: &DeadlineArgs) -> Result<Vec<crate::scenario::Scenario>, SystemError> {
    let names: Vec<String> = if args.scenarios.is_empty() && args.mbm.is_none() {
        crate::scenario::BUILTIN_SCENARIOS.iter().map(|(n, _)| (*n).to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let mut out = Vec::new();
    for name in &names {
        let sc = load_scenario(name)?;
        if sc.task.is_some() {
            out.push(sc);
        }
    }
    Ok(out)
}

/// One task-level deliberation under deadline `deadline_ms`, run in the system on the wall
/// clock until its plan (or its failure) lands, read back from the coordinator's events.
fn run_task(scenario: &crate::scenario::Scenario, deadline_ms: f64, args: &DeadlineArgs) -> Result<Tally, SystemError> {
    let mut sc = scenario.clone();
    if let Some(task) = &mut sc.task {
        task.deadline_ms = deadline_ms;
        task.give_up_ms = deadline_ms;
    }
    let options = crate::system::RunOptions {
        seed: Some(args.seed),
        clock: Some(crate::scenario::ClockSpec::Wall),
        duration: Some(args.max_steps as f64 * 1e-3),
        ..crate::system::RunOptions::default()
    };
    let mut system = crate::system::System::new(&sc, &options)?;
    let mut t = Tally { requested: 1, ..Tally::default() };
    let mut landed = false;
    while !landed && system.time() < system.duration() {
        let record = system.step()?;
        for agent in &record.agents {
            for e in &agent.events {
                match e {
                    Event::TaskPlanFound { in_time, planning_ms, .. } => {
                        landed = true;
                        if *in_time && *planning_ms <= deadline_ms {
                            t.in_time += 1;
                        } else {
                            // Not there when needed: the arms held at rest.
                            t.halts += 1;
                        }
                        t.goal = true;
                    }
                    Event::TaskPlanFailed { reason, planning_ms, .. } => {
                        landed = true;
                        t.halts += 1;
                        if reason.starts_with("out_of_time") {
                            t.overshoot_us.push(((planning_ms - deadline_ms) * 1e3).max(0.0));
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(t)
}

fn problems(args: &DeadlineArgs) -> Result<Vec<Problem>, SystemError> {
    let names: Vec<String> = if args.scenarios.is_empty() && args.mbm.is_none() {
        crate::scenario::BUILTIN_SCENARIOS.iter().map(|(n, _)| (*n).to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let mut out = Vec::new();
    for name in &names {
        let sc = load_scenario(name)?;
        let starts: Vec<Vec<Vec<f64>>> = sc.agents.iter().map(|a| vec![a.start.clone()]).collect();
        for (k, a) in sc.agents.iter().enumerate() {
            if let Some(goal) = &a.goal {
                let collision = agent_problem(&sc, k, &starts);
                for j in 0..args.planner_seeds.max(1) {
                    out.push(Problem {
                        set: "scenarios",
                        name: seeded_name(format!("{}/{}", sc.name, a.name), j),
                        collision: collision.clone(),
                        start: a.start.clone(),
                        goal: goal_of(goal),
                        seed: sc.planner.seed.wrapping_add(j),
                        resolution: sc.planner.resolution,
                    });
                }
            }
        }
    }
    if let Some(m) = &args.mbm {
        let mut margs = crate::mbm::MbmArgs::new(&m.urdf, &m.srdf, &m.problems);
        margs.seed = args.seed;
        for p in crate::mbm::sample_problems(&margs, m.count)? {
            for j in 0..args.planner_seeds.max(1) {
                out.push(Problem {
                    set: "mbm",
                    name: seeded_name(p.name.clone(), j),
                    collision: p.model.clone(),
                    start: p.start.clone(),
                    goal: Goal::Configuration(p.goal.clone()),
                    seed: args.seed.wrapping_add(j),
                    resolution: margs.resolution,
                });
            }
        }
    }
    if out.is_empty() && task_scenarios(args)?.is_empty() {
        return Err(SystemError::Usage(
            "no problem to plan: no scenario agent with a goal, no [task], no MBM problem".into(),
        ));
    }
    Ok(out)
}

/// A problem's name under its `j`-th planner seed: the name itself for the first, `name#j`
/// after it.
fn seeded_name(name: String, j: u64) -> String {
    if j == 0 { name } else { format!("{name}#{j}") }
}

/// Per-run tallies read from the log.
#[derive(Default)]
struct Tally {
    requested: usize,
    in_time: usize,
    goal: bool,
    halts: usize,
    halts_from_speed: Vec<HaltRecord>,
    overshoot_us: Vec<f64>,
}

fn tally_event(t: &mut Tally, problem: &str, e: &Event, deadline_us: f64) {
    let elapsed_us = |wall: &Option<WallTiming>| wall.map_or(f64::INFINITY, |w| w.elapsed_us as f64);
    match e {
        Event::PlanRequested { .. } => t.requested += 1,
        Event::PlanLanded { in_time: true, wall, .. } if elapsed_us(wall) <= deadline_us => t.in_time += 1,
        Event::GoalReached { .. } => t.goal = true,
        Event::HaltStarted { .. } => t.halts += 1,
        Event::HaltFinished { distance, time_s, steps } if *steps > 0 => {
            t.halts_from_speed.push(HaltRecord {
                problem: problem.to_string(),
                distance: *distance,
                time_ms: time_s * 1e3,
            });
        }
        _ => {}
    }
    // A search that ran to the deadline: how long past it it returned.
    if let Event::PlanFailed { wall: Some(w), .. } | Event::PlanLanded { wall: Some(w), .. } = e
        && w.elapsed_us as f64 >= deadline_us
    {
        t.overshoot_us.push(w.elapsed_us as f64 - deadline_us);
    }
}

fn run_one(p: &Problem, deadline_ms: f64, args: &DeadlineArgs) -> Result<Tally, SystemError> {
    let dt = 0.001;
    let deadline = Duration::from_secs_f64(deadline_ms.max(0.0) / 1e3);
    let settings = DeliberationSettings {
        clock: PlanClock::WallClock,
        budget: PlanBudget {
            steps: (deadline_ms / 1e3 / dt).ceil() as u64,
            wall: Some(deadline),
            give_up_steps: None,
            work: None,
        },
        motion: embodied_planner::motion::MotionSettings {
            seed: p.seed,
            resolution: p.resolution,
            ..embodied_planner::motion::MotionSettings::default()
        },
        obstacle_sensing: Some(f64::INFINITY),
        halt_on_any_change: true,
        retry_after_steps: 50,
        max_attempts: 3,
        goal_tolerance: 1e-3,
        ..DeliberationSettings::default()
    };
    let robot = Arc::new(p.collision.robot().clone());
    let agent = deliberative_agent(&p.name, robot, p.collision.clone(), &p.start, p.goal.clone(), settings)
        .map_err(|e| SystemError::Failed(format!("{}: {e}", p.name)))?;
    let mut rt = Runtime::new(RuntimeConfig { dt, seed: args.seed, ..RuntimeConfig::default() });
    rt.add_agent(agent);
    let mut t = Tally::default();
    let mut pending = false;
    let mut disturbed = false;
    let deadline_us = deadline.as_secs_f64() * 1e6;
    let mut pace: Option<(std::time::Instant, u64)> = None;
    for _ in 0..args.max_steps {
        let rec: StepRecord = rt.step().map_err(|e| SystemError::Failed(format!("{}: {e}", p.name)))?.clone();
        for e in &rec.agents[0].events {
            tally_event(&mut t, &p.name, e, deadline_us);
            match e {
                Event::PlanRequested { .. } => pending = true,
                Event::PlanLanded { .. }
                | Event::PlanFailed { .. }
                | Event::PlanRejected { .. }
                | Event::PlannerPanicked { .. }
                | Event::PlanDiscarded { .. } => pending = false,
                _ => {}
            }
            if matches!(e, Event::PlanLanded { .. }) && !disturbed {
                // Once it moves, the world changes: halt from speed, replan.
                disturbed = true;
                let at = rec.step + 200;
                rt.world_mut()
                    .add_obstacle(Obstacle { appears_at: at, ..Obstacle::fixed("far", [50.0, 0.0, 0.0], 0.1) });
            }
            if matches!(e, Event::PlanAbandoned { .. }) {
                return Ok(t);
            }
        }
        if t.goal && disturbed && rt.is_at_rest() {
            break;
        }
        // The control loop runs in real time while a plan is being computed, so that steps and
        // the wall-clock deadline mean the same thing then.
        if pending {
            let (t0, s0) = *pace.get_or_insert((std::time::Instant::now(), rec.step));
            let due = t0 + Duration::from_secs_f64((rec.step + 1 - s0) as f64 * dt);
            if let Some(wait) = due.checked_duration_since(std::time::Instant::now()) {
                std::thread::sleep(wait);
            }
        } else {
            pace = None;
        }
    }
    Ok(t)
}

fn mean_max(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (v.iter().sum::<f64>() / v.len() as f64, v.iter().copied().fold(0.0, f64::max))
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Run the benchmark.
pub fn run_deadline_bench(args: &DeadlineArgs) -> Result<DeadlineReport, SystemError> {
    if args.deadlines_ms.is_empty() || args.deadlines_ms.iter().any(|d| !d.is_finite() || *d < 0.0) {
        return Err(SystemError::Usage("deadlines must be a non-empty list of non-negative milliseconds".into()));
    }
    let problems = problems(args)?;
    let mut rows = Vec::new();
    for set in ["scenarios", "mbm"] {
        let in_set: Vec<&Problem> = problems.iter().filter(|p| p.set == set).collect();
        if in_set.is_empty() {
            continue;
        }
        for &d in &args.deadlines_ms {
            let mut total = Tally::default();
            let mut goals = 0;
            for p in &in_set {
                let t = run_one(p, d, args)?;
                total.requested += t.requested;
                total.in_time += t.in_time;
                goals += usize::from(t.goal);
                total.halts += t.halts;
                total.halts_from_speed.extend(t.halts_from_speed);
                total.overshoot_us.extend(t.overshoot_us);
            }
            let distances: Vec<f64> = total.halts_from_speed.iter().map(|h| h.distance).collect();
            let times: Vec<f64> = total.halts_from_speed.iter().map(|h| h.time_ms).collect();
            let (hd_mean, hd_max) = mean_max(&distances);
            let (ht_mean, ht_max) = mean_max(&times);
            rows.push(DeadlineRow {
                set: set.to_string(),
                deadline_ms: d,
                problems: in_set.len(),
                requested: total.requested,
                delivered_in_time: total.in_time,
                delivered_share: if total.requested == 0 { 0.0 } else { total.in_time as f64 / total.requested as f64 },
                goals_reached: goals,
                safe_halts: total.halts,
                halts_from_speed: total.halts_from_speed.len(),
                halt_distance_mean: hd_mean,
                halt_distance_max: hd_max,
                halt_time_mean_ms: ht_mean,
                halt_time_max_ms: ht_max,
                stopped: total.overshoot_us.len(),
                overshoot_p50_us: median(&total.overshoot_us),
                overshoot_max_us: total.overshoot_us.iter().copied().fold(0.0, f64::max),
                halts: total.halts_from_speed,
            });
        }
    }
    let tasks = task_scenarios(args)?;
    if !tasks.is_empty() {
        for &d in &args.deadlines_ms {
            let mut total = Tally::default();
            let mut planned = 0;
            for sc in &tasks {
                let t = run_task(sc, d, args)?;
                total.requested += t.requested;
                total.in_time += t.in_time;
                planned += usize::from(t.goal);
                total.halts += t.halts;
                total.overshoot_us.extend(t.overshoot_us);
            }
            rows.push(DeadlineRow {
                set: "tasks".to_string(),
                deadline_ms: d,
                problems: tasks.len(),
                requested: total.requested,
                delivered_in_time: total.in_time,
                delivered_share: if total.requested == 0 { 0.0 } else { total.in_time as f64 / total.requested as f64 },
                // Task plans found at all (in time or late).
                goals_reached: planned,
                safe_halts: total.halts,
                halts_from_speed: 0,
                halt_distance_mean: 0.0,
                halt_distance_max: 0.0,
                halt_time_mean_ms: 0.0,
                halt_time_max_ms: 0.0,
                stopped: total.overshoot_us.len(),
                overshoot_p50_us: median(&total.overshoot_us),
                overshoot_max_us: total.overshoot_us.iter().copied().fold(0.0, f64::max),
                halts: Vec::new(),
            });
        }
    }
    let mut names: Vec<(String, String)> = problems.into_iter().map(|p| (p.set.to_string(), p.name)).collect();
    names.extend(tasks.iter().map(|sc| ("tasks".to_string(), sc.name.clone())));
    Ok(DeadlineReport { generator: crate::generator(), problems: names, rows })
}

/// The report as a terminal table.
pub fn render_table(report: &DeadlineReport) -> String {
    let mut s = String::new();
    for set in ["scenarios", "mbm", "tasks"] {
        let names: Vec<&str> = report.problems.iter().filter(|(k, _)| k == set).map(|(_, n)| n.as_str()).collect();
        if !names.is_empty() {
            s.push_str(&format!("{set} ({}): {}\n", names.len(), names.join(", ")));
        }
    }
    s.push_str(&format!(
        "{:<10} {:>8} {:>5} {:>7} {:>6} {:>6} {:>6} {:>6} {:>10} {:>10} {:>10} {:>10} {:>7} {:>9} {:>9}\n",
        "set",
        "deadline",
        "asked",
        "in time",
        "share",
        "goals",
        "halts",
        "moving",
        "halt d avg",
        "halt d max",
        "halt t avg",
        "halt t max",
        "stopped",
        "overshoot",
        "overshoot"
    ));
    s.push_str(&format!(
        "{:<10} {:>8} {:>5} {:>7} {:>6} {:>6} {:>6} {:>6} {:>10} {:>10} {:>10} {:>10} {:>7} {:>9} {:>9}\n",
        "", "ms", "", "", "", "", "", "", "rad|m", "rad|m", "ms", "ms", "", "p50 µs", "max µs"
    ));
    for r in &report.rows {
        s.push_str(&format!(
            "{:<10} {:>8.1} {:>5} {:>7} {:>6.2} {:>6} {:>6} {:>6} {:>10.4} {:>10.4} {:>10.1} {:>10.1} {:>7} {:>9.0} {:>9.0}\n",
            r.set,
            r.deadline_ms,
            r.requested,
            r.delivered_in_time,
            r.delivered_share,
            format!("{}/{}", r.goals_reached, r.problems),
            r.safe_halts,
            r.halts_from_speed,
            r.halt_distance_mean,
            r.halt_distance_max,
            r.halt_time_mean_ms,
            r.halt_time_max_ms,
            r.stopped,
            r.overshoot_p50_us,
            r.overshoot_max_us
        ));
    }
    s
}

/// SVG plot of the share of plans delivered in time against the deadline (log x axis).
pub fn plot_svg(report: &DeadlineReport, path: &Path) -> Result<(), SystemError> {
    use plotters::prelude::*;
    let fail = |e: String| SystemError::Failed(format!("plot {}: {e}", path.display()));
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let xs: Vec<f64> = report.rows.iter().map(|r| r.deadline_ms.max(0.1)).collect();
    let (x0, x1) = xs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(*x), b.max(*x)));
    let (x0, x1) = if x0.is_finite() && x1 > x0 { (x0 * 0.8, x1 * 1.25) } else { (0.1, 100.0) };
    let mut chart = ChartBuilder::on(&root)
        .caption("plans delivered within the deadline", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((x0..x1).log_scale(), 0.0..1.05)
        .map_err(|e| fail(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("deadline [ms]")
        .y_desc("delivered in time")
        .draw()
        .map_err(|e| fail(e.to_string()))?;
    for (set, colour) in [("scenarios", BLUE), ("mbm", RED), ("tasks", GREEN)] {
        let pts: Vec<(f64, f64)> =
            report.rows.iter().filter(|r| r.set == set).map(|r| (r.deadline_ms.max(0.1), r.delivered_share)).collect();
        if pts.is_empty() {
            continue;
        }
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), colour.stroke_width(2)))
            .map_err(|e| fail(e.to_string()))?
            .label(set)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 4, colour.filled())))
            .map_err(|e| fail(e.to_string()))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()
        .map_err(|e| fail(e.to_string()))?;
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}
