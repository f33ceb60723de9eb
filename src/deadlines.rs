//! `embodied bench deadlines`: how deliberative agents fare under planning deadlines.
//!
//! For every deadline and every problem (the configuration-goal agents of the built-in
//! scenarios), a deliberative agent ([`embodied_executor::deliberative_agent`], wall-clock
//! [`PlanClock`]) plans from its start to its goal. Once it moves, a far obstacle appears (the
//! agent's world model changes), so it halts from speed and must replan under the same deadline.
//! Everything is read back from the run's log events: the share of plans delivered within the
//! deadline, the safe halts with their stopping distance and time, and the deadline overshoot.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use embodied_executor::deliberation::{DeliberationSettings, PlanBudget, PlanClock, deliberative_agent};
use embodied_executor::{Obstacle, Runtime, RuntimeConfig, StepRecord};
use embodied_models::CollisionModel;

use crate::error::AppError;
use crate::scenario::{GoalSpec, load_scenario};

/// What to run.
#[derive(Debug, Clone)]
pub struct DeadlineArgs {
    /// Planning deadlines, milliseconds.
    pub deadlines_ms: Vec<f64>,
    /// Built-in scenario names or scenario files (empty: every built-in scenario).
    pub scenarios: Vec<String>,
    /// Upper bound on control steps per run (dt = 1 ms).
    pub max_steps: u64,
    /// Seed of the runtime.
    pub seed: u64,
}

impl Default for DeadlineArgs {
    fn default() -> Self {
        Self { deadlines_ms: vec![0.5, 1.0, 2.0, 5.0, 10.0, 50.0], scenarios: Vec::new(), max_steps: 20_000, seed: 1 }
    }
}

/// Results for one deadline over all problems.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DeadlineRow {
    pub deadline_ms: f64,
    pub problems: usize,
    /// Plans asked for.
    pub requested: usize,
    /// Verified plans that came within the deadline.
    pub delivered_in_time: usize,
    /// `delivered_in_time / requested` (0 when nothing was asked).
    pub delivered_share: f64,
    /// Problems whose goal was reached.
    pub goals_reached: usize,
    pub safe_halts: usize,
    /// Largest joint travel during a halt (rad or m): mean and max over halts.
    pub halt_distance_mean: f64,
    pub halt_distance_max: f64,
    /// Halt duration, ms: mean and max.
    pub halt_time_mean_ms: f64,
    pub halt_time_max_ms: f64,
    /// Time the planner ran past the deadline, µs: mean and max over plans that overshot.
    pub overshoot_mean_us: f64,
    pub overshoot_max_us: f64,
}

/// The whole benchmark.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DeadlineReport {
    /// `scenario/agent` of every problem.
    pub problems: Vec<String>,
    pub rows: Vec<DeadlineRow>,
}

struct Problem {
    name: String,
    robot: Arc<embodied_models::Robot>,
    collision: CollisionModel,
    start: Vec<f64>,
    goal: Vec<f64>,
}

fn problems(args: &DeadlineArgs) -> Result<Vec<Problem>, AppError> {
    let names: Vec<String> = if args.scenarios.is_empty() {
        crate::scenario::BUILTIN_SCENARIOS.iter().map(|(n, _)| (*n).to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let mut out = Vec::new();
    for name in &names {
        let sc = load_scenario(name)?;
        let env = sc.initial_environment();
        for a in &sc.agents {
            if let Some(GoalSpec::Configuration(goal)) = &a.goal {
                out.push(Problem {
                    name: format!("{}/{}", sc.name, a.name),
                    robot: Arc::new(a.robot.clone()),
                    collision: CollisionModel::new(&a.robot, env.clone()),
                    start: a.start.clone(),
                    goal: goal.clone(),
                });
            }
        }
    }
    if out.is_empty() {
        return Err(AppError::Usage("no scenario agent with a configuration goal to plan for".into()));
    }
    Ok(out)
}

/// Per-run tallies read from the log.
#[derive(Default)]
struct Tally {
    requested: usize,
    in_time: usize,
    goal: bool,
    halts: usize,
    halt_distance: Vec<f64>,
    halt_ms: Vec<f64>,
    overshoot_us: Vec<f64>,
}

fn field(event: &str, key: &str) -> Option<f64> {
    let start = event.find(key)? + key.len();
    let rest = &event[start..];
    let end = rest.find(|c: char| c.is_whitespace() || c == ':').unwrap_or(rest.len());
    rest[..end].parse().ok()
}

fn tally_event(t: &mut Tally, e: &str, deadline: Duration, dt: f64) {
    if e.starts_with("plan_requested") {
        t.requested += 1;
    } else if e.starts_with("plan_ready") {
        let elapsed = field(e, "elapsed_us=").unwrap_or(f64::INFINITY);
        if elapsed <= deadline.as_secs_f64() * 1e6 {
            t.in_time += 1;
        }
    } else if e.starts_with("goal_reached") {
        t.goal = true;
    } else if e.starts_with("safe_halt_started") {
        t.halts += 1;
    } else if e.starts_with("safe_halt_done") {
        t.halt_distance.push(field(e, "distance=").unwrap_or(0.0));
        t.halt_ms.push(field(e, "steps=").unwrap_or(0.0) * dt * 1e3);
    }
    if let Some(o) = field(e, "overshoot_us=") {
        t.overshoot_us.push(o);
    }
}

fn run_one(p: &Problem, deadline_ms: f64, args: &DeadlineArgs) -> Result<Tally, AppError> {
    let dt = 0.001;
    let deadline = Duration::from_secs_f64(deadline_ms.max(0.0) / 1e3);
    let settings = DeliberationSettings {
        clock: PlanClock::WallClock,
        budget: PlanBudget { wall: Some(deadline), steps: (deadline_ms / 1e3 / dt).ceil() as u64, expansions: None },
        obstacle_sensing: Some(f64::INFINITY),
        halt_on_any_change: true,
        retry_after_steps: 50,
        max_attempts: 3,
        ..DeliberationSettings::default()
    };
    let agent = deliberative_agent(&p.name, p.robot.clone(), p.collision.clone(), &p.start, p.goal.clone(), settings)
        .map_err(|e| AppError::Failed(format!("{}: {e}", p.name)))?;
    let mut rt = Runtime::new(RuntimeConfig { dt, seed: args.seed, ..RuntimeConfig::default() });
    rt.add_agent(agent);
    let mut t = Tally::default();
    let mut pending = false;
    let mut disturbed = false;
    for _ in 0..args.max_steps {
        let rec: StepRecord = rt.step().map_err(|e| AppError::Failed(format!("{}: {e}", p.name)))?.clone();
        for e in &rec.agents[0].events {
            tally_event(&mut t, e, deadline, dt);
            if e.starts_with("plan_requested") {
                pending = true;
            } else if e.starts_with("plan_ready") || e.starts_with("plan_failed") || e.starts_with("plan_rejected") {
                pending = false;
            }
            if e.starts_with("plan_ready") && !disturbed {
                // Once it moves, the world changes: halt from speed, replan.
                disturbed = true;
                let at = rec.step + 200;
                rt.world_mut()
                    .add_obstacle(Obstacle { appears_at: at, ..Obstacle::fixed("far", [50.0, 0.0, 0.0], 0.1) });
            }
            if e.starts_with("plan_abandoned") {
                return Ok(t);
            }
        }
        if t.goal && disturbed && rt.is_at_rest() {
            break;
        }
        // The control loop runs in real time while a plan is being computed, so that steps and
        // the wall-clock deadline mean the same thing then.
        if pending {
            std::thread::sleep(Duration::from_secs_f64(dt));
        }
    }
    Ok(t)
}

fn stats(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (v.iter().sum::<f64>() / v.len() as f64, v.iter().copied().fold(0.0, f64::max))
}

/// Run the benchmark.
pub fn run_deadline_bench(args: &DeadlineArgs) -> Result<DeadlineReport, AppError> {
    if args.deadlines_ms.is_empty() || args.deadlines_ms.iter().any(|d| !d.is_finite() || *d < 0.0) {
        return Err(AppError::Usage("deadlines must be a non-empty list of non-negative milliseconds".into()));
    }
    let problems = problems(args)?;
    let mut rows = Vec::new();
    for &d in &args.deadlines_ms {
        let mut total = Tally::default();
        let mut goals = 0;
        for p in &problems {
            let t = run_one(p, d, args)?;
            total.requested += t.requested;
            total.in_time += t.in_time;
            goals += usize::from(t.goal);
            total.halts += t.halts;
            total.halt_distance.extend(t.halt_distance);
            total.halt_ms.extend(t.halt_ms);
            total.overshoot_us.extend(t.overshoot_us);
        }
        let (hd_mean, hd_max) = stats(&total.halt_distance);
        let (ht_mean, ht_max) = stats(&total.halt_ms);
        let (os_mean, os_max) = stats(&total.overshoot_us);
        rows.push(DeadlineRow {
            deadline_ms: d,
            problems: problems.len(),
            requested: total.requested,
            delivered_in_time: total.in_time,
            delivered_share: if total.requested == 0 { 0.0 } else { total.in_time as f64 / total.requested as f64 },
            goals_reached: goals,
            safe_halts: total.halts,
            halt_distance_mean: hd_mean,
            halt_distance_max: hd_max,
            halt_time_mean_ms: ht_mean,
            halt_time_max_ms: ht_max,
            overshoot_mean_us: os_mean,
            overshoot_max_us: os_max,
        });
    }
    Ok(DeadlineReport { problems: problems.into_iter().map(|p| p.name).collect(), rows })
}

/// The report as a terminal table.
pub fn render_table(report: &DeadlineReport) -> String {
    let mut s = format!("problems: {}\n", report.problems.join(", "));
    s.push_str(&format!(
        "{:>9} {:>5} {:>9} {:>7} {:>6} {:>6} {:>10} {:>10} {:>10} {:>10} {:>11} {:>11}\n",
        "deadline",
        "asked",
        "in time",
        "share",
        "goals",
        "halts",
        "halt d avg",
        "halt d max",
        "halt t avg",
        "halt t max",
        "overshoot",
        "overshoot"
    ));
    s.push_str(&format!(
        "{:>9} {:>5} {:>9} {:>7} {:>6} {:>6} {:>10} {:>10} {:>10} {:>10} {:>11} {:>11}\n",
        "ms", "", "", "", "", "", "rad|m", "rad|m", "ms", "ms", "avg µs", "max µs"
    ));
    for r in &report.rows {
        s.push_str(&format!(
            "{:>9.1} {:>5} {:>9} {:>7.2} {:>6} {:>6} {:>10.4} {:>10.4} {:>10.1} {:>10.1} {:>11.0} {:>11.0}\n",
            r.deadline_ms,
            r.requested,
            r.delivered_in_time,
            r.delivered_share,
            format!("{}/{}", r.goals_reached, r.problems),
            r.safe_halts,
            r.halt_distance_mean,
            r.halt_distance_max,
            r.halt_time_mean_ms,
            r.halt_time_max_ms,
            r.overshoot_mean_us,
            r.overshoot_max_us
        ));
    }
    s
}

/// SVG plot of the share of plans delivered in time against the deadline (log x axis).
pub fn plot_svg(report: &DeadlineReport, path: &Path) -> Result<(), AppError> {
    use plotters::prelude::*;
    let fail = |e: String| AppError::Failed(format!("plot {}: {e}", path.display()));
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
    let pts: Vec<(f64, f64)> = xs.iter().zip(&report.rows).map(|(x, r)| (*x, r.delivered_share)).collect();
    chart.draw_series(LineSeries::new(pts.iter().copied(), BLUE.stroke_width(2))).map_err(|e| fail(e.to_string()))?;
    chart
        .draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 4, BLUE.filled())))
        .map_err(|e| fail(e.to_string()))?;
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}
