//! `embodied verify`: check a plan file (and/or a run log) against a scenario, independently of
//! the planner and the executor.
//!
//! **Plans.** The plan must name the scenario (a different name is an error; a different
//! SHA-256 of the scenario text is a *warning*: the plan is then checked against the scenario as
//! it is now, which is what certification means). Every agent plan must name an agent of the
//! scenario, its robot, and the robot's joint names in order (else an error naming the place).
//! Each trajectory is checked by the certified [`embodied_planner::verify::Verifier`]
//! (limits, continuous collisions with a certificate, closed-chain spans) plus the timing and
//! endpoints here: it starts at `t = 0` at rest at the scenario's start configuration and ends
//! at rest.
//!
//! **Other agents.** Plans in a file run one after another in file order (this is how
//! `embodied plan` makes them): while agent `k` moves, every agent whose plan comes earlier in
//! the file stands where its plan ends, every other agent stands at its start configuration.
//! Plans the file's `together` groups name run at the same time, from `t = 0`: each pair of
//! them is certified against each other in time (agent A at `t` against agent B at `t`, both
//! sampled at the finer of their sample steps; a plan that has ended stands at its end), not one
//! after another.
//! Obstacles are those present at time zero (scripted obstacles that appear later are the run's
//! business, not the plan's).
//!
//! **Logs.** `--log FILE.jsonl` checks a run log line by line: joint positions against the
//! scenario robot's limits, the logged `qd` against the velocity limits, the finite difference
//! of the logged `qd` over the header's `step_s` against the acceleration limits, and when the
//! header names a `closed_chain`, the relative tool pose between each `grasp` event of that
//! agent and the next `release` (the release step itself is not checked). Every logged motion
//! is certified collision-free between consecutive steps by the certified
//! [`embodied_planner::verify::Verifier`]: each robot against the scenario's obstacles at their
//! times (scripted ones where and once they are there) and against itself, and every two robots
//! against each other at the same steps (see [`crate::clearance`]). A log whose last line
//! is incomplete, or that has no summary line, is checked up to its last complete line and the
//! report says so (`complete: false`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use embodied_executor::Event;
use embodied_models::Robot;
use embodied_models::nalgebra::Isometry3;
use embodied_planner::trajectory::Trajectory;
use embodied_planner::verify::certified::pose_error;
use embodied_planner::verify::{CheckSettings, EvaluationBudget, Finding, LimitsChecker, TrajectoryReport, Verifier};
use serde::Serialize;
use serde_json::Value;

use crate::SystemError;
use crate::clearance::{LoggedMotion, MotionCheck, ObstacleTimeline, certify_environment, certify_pair};
use crate::plan::{PlanFile, agent_problem, read_plan};
use crate::scenario::{GoalSpec, Scenario, load_scenario};

/// The distance evaluations `embodied verify` lets the collision checks of one plan file (or one
/// run log) spend unless told otherwise (`--max-evaluations`): a few minutes at most of
/// the slowest robot's pairs, and many times what a plan or log of the built-in scenarios needs.
pub const DEFAULT_MAX_EVALUATIONS: usize = 2_000_000;

/// Exit status of `embodied verify` when the input was read but is not certified.
pub const EXIT_NOT_CERTIFIED: u8 = 1;

/// One agent's plan, checked.
#[derive(Debug, Clone, Serialize)]
pub struct AgentVerification {
    /// The agent's name.
    pub agent: String,
    /// The agent's robot.
    pub robot: String,
    /// Where the other agents stood while this one moved.
    pub others: Vec<String>,
    /// Whether the trajectory is certified and timing and endpoints are fine.
    pub certified: bool,
    /// Timing and endpoints: problems found (empty: fine).
    pub timing: Vec<String>,
    /// The certified check of the trajectory (its own `certified` says whether the trajectory
    /// alone passed; the agent's `certified` above adds timing and endpoints).
    #[serde(rename = "trajectory")]
    pub report: TrajectoryReport,
}

/// A plan file checked against a scenario.
#[derive(Debug, Clone, Serialize)]
pub struct PlanVerification {
    /// The program (version and commit) that made the report.
    pub generator: String,
    /// The plan file checked.
    pub plan_file: PathBuf,
    /// The scenario checked against.
    pub scenario: String,
    /// Whether every agent's plan is certified.
    pub certified: bool,
    /// Problems with the input that did not stop the check.
    pub warnings: Vec<String>,
    /// One result per agent.
    pub agents: Vec<AgentVerification>,
    /// Plans that run together, certified against each other in time.
    pub together: Vec<MotionCheck>,
    /// The settings of the certified check.
    pub settings: CheckSettings,
    /// Distance evaluations spent by all the collision checks together (at most
    /// `settings.max_evaluations`).
    pub distance_evaluations: usize,
    /// Whether the budget of distance evaluations ran out (the plan is then not certified).
    pub budget_exhausted: bool,
    /// Wall-clock time of the check, s.
    pub time_s: f64,
}

fn usage(file: &Path, message: String) -> SystemError {
    SystemError::Usage(format!("{}: {message}", file.display()))
}

/// Check that `plan` fits `scenario` (names, robots, joint names, DOF); returns the warnings
/// and, per plan, the scenario's agent index.
fn match_plan(scenario: &Scenario, plan: &PlanFile, file: &Path) -> Result<(Vec<String>, Vec<usize>), SystemError> {
    let mut warnings = Vec::new();
    if plan.scenario.name != scenario.name {
        return Err(usage(
            file,
            format!("scenario: the plan is for scenario `{}`, not `{}`", plan.scenario.name, scenario.name),
        ));
    }
    if plan.scenario.hash != scenario.hash {
        warnings.push(format!(
            "scenario `{}` changed since the plan was made (SHA-256 {} in the plan, {} now): checked against it as it is now",
            scenario.name, plan.scenario.hash, scenario.hash
        ));
    }
    if plan.plans.is_empty() {
        return Err(usage(file, "plans: empty, nothing to verify".into()));
    }
    let mut index = Vec::new();
    for (j, p) in plan.plans.iter().enumerate() {
        let place = format!("plans[{j}] (agent `{}`)", p.agent);
        let Some(k) = scenario.agents.iter().position(|a| a.name == p.agent) else {
            let names: Vec<&str> = scenario.agents.iter().map(|a| a.name.as_str()).collect();
            return Err(usage(
                file,
                format!("{place}: scenario `{}` has no such agent (it has: {})", scenario.name, names.join(", ")),
            ));
        };
        if index.contains(&k) {
            return Err(usage(file, format!("{place}: a second plan for the same agent")));
        }
        let robot = &scenario.agents[k].robot;
        if p.robot.name != robot.name() {
            return Err(usage(
                file,
                format!("{place}.robot: `{}`, but the scenario's agent is a `{}`", p.robot.name, robot.name()),
            ));
        }
        if p.robot.hash != crate::plan::robot_hash(robot) {
            warnings.push(format!(
                "{place}: the kinematic model of `{}` changed since the plan was made: checked against it as it is now",
                robot.name()
            ));
        }
        let names = robot.joint_names();
        for (what, got) in [("joint_names", &p.joint_names), ("trajectory.joint_names", &p.trajectory.joint_names)] {
            if *got != names {
                return Err(usage(
                    file,
                    format!("{place}.{what}: {got:?}, but robot `{}` has joints {names:?}", robot.name()),
                ));
            }
        }
        let dof = robot.dof();
        let rows = [("path", &p.path), ("trajectory.q", &p.trajectory.q), ("trajectory.qd", &p.trajectory.qd)];
        for (what, rows) in rows {
            if let Some((i, row)) = rows.iter().enumerate().find(|(_, r)| r.len() != dof) {
                return Err(usage(
                    file,
                    format!("{place}.{what}[{i}]: {} values, robot `{}` has {dof} joints", row.len(), robot.name()),
                ));
            }
        }
        let n = p.trajectory.t.len();
        if n == 0 || p.trajectory.q.len() != n || p.trajectory.qd.len() != n {
            return Err(usage(
                file,
                format!(
                    "{place}.trajectory: {n} times, {} positions, {} velocities (must be equal and non-zero)",
                    p.trajectory.q.len(),
                    p.trajectory.qd.len()
                ),
            ));
        }
        index.push(k);
    }
    for (g, group) in plan.together.iter().enumerate() {
        for (m, name) in group.iter().enumerate() {
            if !plan.plans.iter().any(|p| p.agent == *name) {
                return Err(usage(file, format!("together[{g}][{m}]: no plan for agent `{name}` in the file")));
            }
            let elsewhere = plan.together.iter().enumerate().any(|(h, other)| h != g && other.contains(name));
            if elsewhere || group[..m].contains(name) {
                return Err(usage(file, format!("together[{g}][{m}]: agent `{name}` is named twice")));
            }
        }
    }
    Ok((warnings, index))
}

/// Group of plan `j`'s agent in `plan.together`, if any.
fn group_of(plan: &PlanFile, j: usize) -> Option<usize> {
    plan.together.iter().position(|g| g.contains(&plan.plans[j].agent))
}

/// Plans `a` and `b` sampled at the same times from `t = 0` (the finer sample step; a plan
/// that has ended stands at its end).
fn in_time(a: &Trajectory, b: &Trajectory) -> (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let step = |t: &Trajectory| t.t.windows(2).map(|w| w[1] - w[0]).filter(|h| *h > 0.0).fold(f64::INFINITY, f64::min);
    let h = step(a).min(step(b));
    let end = a.duration().max(b.duration());
    let h = if h.is_finite() && h > 0.0 { h.max(end / 1e6) } else { end.max(1e-3) };
    let n = (end / h).ceil() as usize;
    let times: Vec<f64> = (0..=n).map(|k| (k as f64 * h).min(end)).collect();
    let qa = times.iter().map(|&t| a.sample(t).0).collect();
    let qb = times.iter().map(|&t| b.sample(t).0).collect();
    (times, qa, qb)
}

/// Start at t = 0 at rest at the scenario's start, end at rest (and at the goal, for
/// configuration goals).
fn timing(scenario: &Scenario, k: usize, plan: &crate::plan::AgentPlan) -> Vec<String> {
    let agent = &scenario.agents[k];
    let space = agent.robot.config_space();
    let traj = &plan.trajectory;
    let mut out = Vec::new();
    let close = |a: &[f64], b: &[f64]| (0..a.len()).all(|i| space.delta(i, a[i], b[i]).abs() <= 1e-6);
    let at_rest = |qd: &[f64]| qd.iter().all(|v| v.abs() <= 1e-9);
    if traj.t[0].abs() > 1e-12 {
        out.push(format!("the trajectory starts at t = {} s, not 0", traj.t[0]));
    }
    if !close(&traj.q[0], &agent.start) {
        out.push(format!("the trajectory starts at {:?}, not at the scenario's start {:?}", traj.q[0], agent.start));
    }
    if !at_rest(&traj.qd[0]) {
        out.push(format!("the trajectory does not start at rest (qd = {:?})", traj.qd[0]));
    }
    let (last_q, last_qd) = (&traj.q[traj.q.len() - 1], &traj.qd[traj.qd.len() - 1]);
    if !at_rest(last_qd) {
        out.push(format!("the trajectory does not end at rest (qd = {last_qd:?})"));
    }
    let goals = match &agent.goal {
        Some(GoalSpec::Configuration(q)) => vec![q.clone()],
        Some(GoalSpec::AnyOf(qs)) => qs.clone(),
        _ => Vec::new(),
    };
    if !goals.is_empty() && !goals.iter().any(|g| g.len() == last_q.len() && close(last_q, g)) {
        out.push(format!("the trajectory ends at {last_q:?}, not at the scenario's goal"));
    }
    out
}

/// Check every agent plan of `plan` against `scenario`.
pub fn verify_plan(
    scenario: &Scenario,
    plan: &PlanFile,
    file: &Path,
    settings: &CheckSettings,
) -> Result<PlanVerification, SystemError> {
    let start = Instant::now();
    let (warnings, index) = match_plan(scenario, plan, file)?;
    let mut budget = EvaluationBudget::new(settings.max_evaluations);
    let mut agents = Vec::new();
    for (j, (p, &k)) in plan.plans.iter().zip(&index).enumerate() {
        let mut occupied = Vec::new();
        let mut others = Vec::new();
        let group = group_of(plan, j);
        for (m, a) in scenario.agents.iter().enumerate() {
            let moves_along = |jj: usize| index[jj] == m && group.is_some() && group_of(plan, jj) == group;
            if m != k && (0..plan.plans.len()).any(moves_along) {
                occupied.push(Vec::new());
                others.push(format!("{}: moving at the same time (checked in time)", a.name));
                continue;
            }
            let earlier = plan.plans[..j].iter().zip(&index).find(|(_, mi)| **mi == m);
            match earlier.and_then(|(ep, _)| ep.trajectory.q.last()) {
                Some(end) => {
                    occupied.push(vec![end.clone()]);
                    if m != k {
                        others.push(format!("{}: where its plan ends", a.name));
                    }
                }
                None => {
                    occupied.push(vec![a.start.clone()]);
                    if m != k {
                        others.push(format!("{}: at its start", a.name));
                    }
                }
            }
        }
        let model = agent_problem(scenario, k, &occupied);
        let mut report = Verifier::certified(0.0).with_settings(*settings).check_trajectory_within(
            &model,
            &p.trajectory,
            &p.closed_chain,
            &mut budget,
        );
        report.collision.violation = report.collision.violation.take().map(|f| f.of_agent(&p.agent));
        let timing = timing(scenario, k, p);
        agents.push(AgentVerification {
            agent: p.agent.clone(),
            robot: p.robot.name.clone(),
            others,
            certified: report.certified && timing.is_empty(),
            timing,
            report,
        });
    }
    let verifier = Verifier::certified(0.0).with_settings(*settings);
    let mut together = Vec::new();
    for i in 0..plan.plans.len() {
        for j in i + 1..plan.plans.len() {
            if group_of(plan, i).is_none() || group_of(plan, i) != group_of(plan, j) {
                continue;
            }
            let (pa, pb) = (&plan.plans[i], &plan.plans[j]);
            let (ra, rb) = (&scenario.agents[index[i]].robot, &scenario.agents[index[j]].robot);
            let (times, qa, qb) = in_time(&pa.trajectory, &pb.trajectory);
            let steps: Vec<u64> = (0..times.len() as u64).collect();
            let a = LoggedMotion { agent: &pa.agent, robot: ra, steps: &steps, t: &times, q: &qa };
            let b = LoggedMotion { agent: &pb.agent, robot: rb, steps: &steps, t: &times, q: &qb };
            together.push(certify_pair(&a, &b, &verifier, &mut budget));
        }
    }
    let budget_exhausted = agents.iter().any(|a| is_spent(a.report.collision.violation.as_ref()))
        || together.iter().any(|c| is_spent(c.violation.as_ref()));
    Ok(PlanVerification {
        generator: crate::generator(),
        plan_file: file.to_path_buf(),
        scenario: scenario.name.clone(),
        certified: agents.iter().all(|a| a.certified) && together.iter().all(|c| c.ok),
        warnings,
        agents,
        together,
        settings: *settings,
        distance_evaluations: budget.used,
        budget_exhausted,
        time_s: start.elapsed().as_secs_f64(),
    })
}

fn is_spent(f: Option<&Finding>) -> bool {
    matches!(f, Some(Finding::BudgetExhausted { .. }))
}

/// The closing line of a report: certified or not, the evaluations spent, the time.
fn closing_line(
    s: &mut String,
    certified: bool,
    evaluations: usize,
    settings: &CheckSettings,
    exhausted: bool,
    time_s: f64,
) {
    let of = settings.max_evaluations.map(|m| format!(" of {m} allowed")).unwrap_or_default();
    s.push_str(&format!(
        "certified: {} [{:.1} ms, {evaluations} distance evaluations{of}]\n",
        if certified { "yes" } else { "no" },
        time_s * 1e3
    ));
    if exhausted {
        s.push_str(
            "note: the budget of distance evaluations ran out before the motion was certified \
             (`--max-evaluations` raises it)\n",
        );
    }
}

fn ok_word(ok: bool) -> &'static str {
    if ok { "ok" } else { "VIOLATION" }
}

/// The plan report as text: one block per agent, the first violation of each check.
pub fn render_plan(v: &PlanVerification) -> String {
    let mut s = format!("plan {} against scenario `{}`\n", v.plan_file.display(), v.scenario);
    for w in &v.warnings {
        s.push_str(&format!("warning: {w}\n"));
    }
    for a in &v.agents {
        let r = &a.report;
        s.push_str(&format!(
            "{}: {} ({:.3} s, {} samples)\n",
            a.agent,
            if a.certified { "CERTIFIED" } else { "NOT CERTIFIED" },
            r.duration_s,
            r.samples
        ));
        let l = &r.limits;
        s.push_str(&format!(
            "  limits:    {} (peak velocity {:.3}, acceleration {:.3} of limit) [{:.1} ms]\n",
            ok_word(l.ok),
            l.max_velocity_ratio,
            l.max_acceleration_ratio,
            l.time_s * 1e3
        ));
        let c = &r.collision;
        s.push_str(&format!(
            "  collision: {} ({}/{} segments certified, {} pairs, {} distance evaluations, {} subdivisions, depth {}; \
             clearance >= {:.4} m certified, {:.4} m smallest measured{}) [{:.1} ms]\n",
            ok_word(c.ok),
            c.certified_segments,
            c.segments,
            c.pairs,
            c.distance_evaluations,
            c.subdivisions,
            c.max_depth,
            c.certified_clearance_m,
            c.min_clearance_m,
            c.closest_pair.as_ref().map(|[a, b]| format!(" between {a} and {b}")).unwrap_or_default(),
            c.time_s * 1e3
        ));
        let z = &r.closure;
        s.push_str(&format!(
            "  closure:   {} ({} spans, {} samples, largest error {:.2e} m, {:.2e} rad) [{:.1} ms]\n",
            ok_word(z.ok),
            z.spans,
            z.samples,
            z.max_position_error_m,
            z.max_angle_error_rad,
            z.time_s * 1e3
        ));
        s.push_str(&format!("  timing:    {}\n", ok_word(a.timing.is_empty())));
        for f in r.findings() {
            s.push_str(&format!("  first violation: {f}\n"));
        }
        for t in &a.timing {
            s.push_str(&format!("  timing: {t}\n"));
        }
        s.push_str(&format!("  others: {}\n", a.others.join("; ")));
    }
    for c in &v.together {
        render_motion_check(&mut s, c);
    }
    closing_line(&mut s, v.certified, v.distance_evaluations, &v.settings, v.budget_exhausted, v.time_s);
    s
}

// ---------------------------------------------------------------------------------------------
// Run logs.

/// The closed-chain declaration of a log header.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct LogClosedChain {
    /// The holding agent's name.
    pub agent: String,
    /// The two end effectors that hold the object.
    pub end_effectors: [String; 2],
    /// Largest allowed drift of the relative tool position, m.
    pub tolerance_m: f64,
    /// Largest allowed drift of the relative tool rotation angle, rad.
    pub tolerance_rad: f64,
}

/// Closure between grasp and release events of one agent.
#[derive(Debug, Clone, Serialize)]
pub struct LogClosure {
    /// Whether the relative tool pose stayed within the tolerances while held.
    pub ok: bool,
    /// The first drift beyond the tolerances, if any.
    pub violation: Option<Finding>,
    /// Grasp events seen.
    pub grasps: usize,
    /// Steps checked while holding.
    pub samples: usize,
    /// Largest drift of the relative tool position while held, m.
    pub max_position_error_m: f64,
    /// Largest drift of the relative tool rotation angle while held, rad.
    pub max_angle_error_rad: f64,
}

/// One agent of a run log, checked.
#[derive(Debug, Clone, Serialize)]
pub struct LogAgent {
    /// The agent's name.
    pub agent: String,
    /// Whether its logged motion stayed within the limits (and the closure, if any, held).
    pub certified: bool,
    /// Logged steps of this agent.
    pub steps: usize,
    /// The first limit violation, if any.
    pub violation: Option<Finding>,
    /// Limit violations found.
    pub violations: usize,
    /// Largest |velocity| / limit over the log.
    pub max_velocity_ratio: f64,
    /// Largest |acceleration| / limit over the log.
    pub max_acceleration_ratio: f64,
    /// The closed-chain check, for an agent that holds an object with two end effectors.
    pub closure: Option<LogClosure>,
    /// Its motion certified free of the obstacles and of itself, step to step.
    pub collision: Option<MotionCheck>,
}

/// A run log checked against a scenario.
#[derive(Debug, Clone, Serialize)]
pub struct LogVerification {
    /// The program (version and commit) that made the report.
    pub generator: String,
    /// The run log checked.
    pub log_file: PathBuf,
    /// The scenario checked against.
    pub scenario: String,
    /// Whether every agent is certified.
    pub certified: bool,
    /// Whether the log ends with its summary line; `note` says where a truncated log stops.
    pub complete: bool,
    /// Where a truncated log stops (see `complete`).
    pub note: Option<String>,
    /// Steps in the log.
    pub steps: usize,
    /// Control period from the log header, s.
    pub step_s: f64,
    /// Problems with the input that did not stop the check.
    pub warnings: Vec<String>,
    /// One result per agent.
    pub agents: Vec<LogAgent>,
    /// Every two robots certified apart, step to step.
    pub robot_robot: Vec<MotionCheck>,
    /// The settings of the certified check.
    pub settings: CheckSettings,
    /// Distance evaluations spent by all the collision checks together (at most
    /// `settings.max_evaluations`).
    pub distance_evaluations: usize,
    /// Whether the budget of distance evaluations ran out (the log is then not certified).
    pub budget_exhausted: bool,
    /// Wall-clock time of the check, s.
    pub time_s: f64,
}

/// The logged motion of an agent, for the collision certificate.
fn motion<'b>(st: &'b AgentState<'_>) -> LoggedMotion<'b> {
    LoggedMotion { agent: &st.name, robot: st.robot, steps: &st.steps, t: &st.times, q: &st.qs }
}

struct AgentState<'a> {
    name: String,
    robot: &'a Robot,
    limits: LimitsChecker,
    names: Vec<String>,
    prev_step: Option<u64>,
    out: LogAgent,
    closure: Option<(usize, usize)>,
    holding: Option<Isometry3<f64>>,
    /// Logged steps, times and joints, for the collision certificate.
    steps: Vec<u64>,
    times: Vec<f64>,
    qs: Vec<Vec<f64>>,
}

/// Longest control period a log header may state, s: a longer one is not a control step (and
/// times of `step * step_s` would overflow towards infinity).
pub const MAX_STEP_S: f64 = 1.0;

fn parse_err(file: &Path, line: usize, column: usize, message: String) -> SystemError {
    SystemError::Parse { file: file.to_path_buf(), line, column, message }
}

/// Check a run log against `scenario` (see the module documentation).
pub fn verify_log(scenario: &Scenario, file: &Path, settings: &CheckSettings) -> Result<LogVerification, SystemError> {
    let start = Instant::now();
    let text = crate::error::read_input(file, embodied_models::formats::limits::InputKind::Log)?;
    let mut v = verify_log_text(scenario, &text, file, settings)?;
    v.time_s = start.elapsed().as_secs_f64();
    Ok(v)
}

/// [`verify_log`] of a log's text; `file` names it in errors.
pub fn verify_log_text(
    scenario: &Scenario,
    text: &str,
    file: &Path,
    settings: &CheckSettings,
) -> Result<LogVerification, SystemError> {
    let start = Instant::now();
    let lines: Vec<&str> = text.split('\n').collect();
    let last_nonempty = lines.iter().rposition(|l| !l.trim().is_empty());
    let header_line = lines.first().copied().unwrap_or("");
    let header: Value = serde_json::from_str(header_line)
        .map_err(|e| parse_err(file, 1, e.column(), format!("not a run log header: {e}")))?;
    let Some(header) = header.get("header") else {
        return Err(parse_err(file, 1, 1, "the first line is not {\"header\": ...}".into()));
    };
    let mut warnings = Vec::new();
    let name = header.get("scenario").and_then(Value::as_str).unwrap_or("");
    if name != scenario.name {
        return Err(parse_err(
            file,
            1,
            1,
            format!("header.scenario: the log is for `{name}`, not `{}`", scenario.name),
        ));
    }
    if header.get("scenario_hash").and_then(Value::as_str).is_some_and(|h| h != scenario.hash) {
        warnings.push(format!("scenario `{}` changed since the run: checked against it as it is now", scenario.name));
    }
    let step_s = header.get("step_s").and_then(Value::as_f64).unwrap_or(f64::NAN);
    if !(step_s > 0.0 && step_s <= MAX_STEP_S) {
        return Err(parse_err(
            file,
            1,
            1,
            format!("header.step_s: missing or not a control period in (0, {MAX_STEP_S}] s"),
        ));
    }
    let Some(header_agents) = header.get("agents").and_then(Value::as_object) else {
        return Err(parse_err(file, 1, 1, "header.agents: missing or not an object".into()));
    };
    let mut agents: Vec<AgentState> = Vec::new();
    for (a, spec) in header_agents {
        let Some(agent) = scenario.agents.iter().find(|s| s.name == *a) else {
            return Err(parse_err(
                file,
                1,
                1,
                format!("header.agents: scenario `{}` has no agent `{a}`", scenario.name),
            ));
        };
        let names = agent.robot.joint_names();
        let logged: Vec<String> =
            spec.get("joint_names").and_then(|v| serde_json::from_value(v.clone()).ok()).unwrap_or_default();
        if logged != names {
            return Err(parse_err(
                file,
                1,
                1,
                format!("header.agents.{a}.joint_names: {logged:?}, but robot `{}` has {names:?}", agent.robot.name()),
            ));
        }
        let limits = agent.robot.limits();
        if let Some(logged) = spec.get("limits").and_then(Value::as_array) {
            let differs = logged.len() != limits.len()
                || logged.iter().zip(&limits).any(|(v, l)| {
                    let get = |k: &str, inf: f64| match v.get(k) {
                        Some(Value::Null) | None => inf,
                        Some(x) => x.as_f64().unwrap_or(f64::NAN),
                    };
                    get("lower", f64::NEG_INFINITY) != l.lower
                        || get("upper", f64::INFINITY) != l.upper
                        || get("max_velocity", f64::NAN) != l.max_velocity
                        || get("max_acceleration", f64::NAN) != l.max_acceleration
                });
            if differs {
                warnings.push(format!("header.agents.{a}.limits differ from the model's: the model's are checked"));
            }
        }
        agents.push(AgentState {
            name: a.clone(),
            robot: &agent.robot,
            limits: LimitsChecker::new(&agent.robot, settings)
                .with_velocity_source("logged qd")
                .without_position_differences(),
            names,
            prev_step: None,
            out: LogAgent {
                agent: a.clone(),
                certified: true,
                steps: 0,
                violation: None,
                violations: 0,
                max_velocity_ratio: 0.0,
                max_acceleration_ratio: 0.0,
                closure: None,
                collision: None,
            },
            closure: None,
            holding: None,
            steps: Vec::new(),
            times: Vec::new(),
            qs: Vec::new(),
        });
    }
    let chain: Option<LogClosedChain> = match header.get("closed_chain") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            serde_json::from_value(v.clone())
                .map_err(|e| parse_err(file, 1, 1, format!("header.closed_chain: {e}")))?,
        ),
    };
    let mut chain_tol = (0.0, 0.0);
    if let Some(c) = &chain {
        let Some(st) = agents.iter_mut().find(|s| s.name == c.agent) else {
            return Err(parse_err(
                file,
                1,
                1,
                format!("header.closed_chain.agent: no agent `{}` in the header", c.agent),
            ));
        };
        let ees = st.robot.end_effectors();
        let find = |n: &str| ees.iter().position(|e| e.name == n);
        let (Some(e0), Some(e1)) = (find(&c.end_effectors[0]), find(&c.end_effectors[1])) else {
            let have: Vec<&str> = ees.iter().map(|e| e.name.as_str()).collect();
            return Err(parse_err(
                file,
                1,
                1,
                format!(
                    "header.closed_chain.end_effectors: {:?}, but robot `{}` has {have:?}",
                    c.end_effectors,
                    st.robot.name()
                ),
            ));
        };
        st.closure = Some((e0, e1));
        st.out.closure = Some(LogClosure {
            ok: true,
            violation: None,
            grasps: 0,
            samples: 0,
            max_position_error_m: 0.0,
            max_angle_error_rad: 0.0,
        });
        chain_tol = (c.tolerance_m, c.tolerance_rad);
    }

    let mut complete = false;
    let mut note = None;
    let mut steps = 0;
    for (i, line) in lines.iter().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let number = i + 1;
        let value: Value = match serde_json::from_str(line) {
            Ok(v) => v,
            Err(e) if Some(i) == last_nonempty => {
                note = Some(format!(
                    "the last line ({number}) is incomplete ({e}): the run stopped there; checked up to line {}",
                    number - 1
                ));
                break;
            }
            Err(e) => return Err(parse_err(file, number, e.column(), format!("not a log line: {e}"))),
        };
        if value.get("summary").is_some() {
            complete = true;
            break;
        }
        let Some(step) = value.get("step").and_then(Value::as_u64) else {
            return Err(parse_err(file, number, 1, "neither a step line nor the summary".into()));
        };
        let t = value.get("t").and_then(Value::as_f64).unwrap_or(step as f64 * step_s);
        steps += 1;
        let Some(step_agents) = value.get("agents").and_then(Value::as_object) else {
            return Err(parse_err(file, number, 1, "agents: missing".into()));
        };
        for st in &mut agents {
            let Some(a) = step_agents.get(&st.name) else { continue };
            let vec = |k: &str| -> Result<Vec<f64>, SystemError> {
                let v: Vec<f64> = a.get(k).and_then(|v| serde_json::from_value(v.clone()).ok()).ok_or_else(|| {
                    parse_err(file, number, 1, format!("agents.{}.{k}: missing or not an array of numbers", st.name))
                })?;
                if v.len() != st.names.len() {
                    return Err(parse_err(
                        file,
                        number,
                        1,
                        format!("agents.{}.{k}: {} values, the robot has {} joints", st.name, v.len(), st.names.len()),
                    ));
                }
                Ok(v)
            };
            let (q, qd) = (vec("q")?, vec("qd")?);
            st.out.steps += 1;
            let h = st.prev_step.map_or(f64::NAN, |p| step.saturating_sub(p).max(1) as f64 * step_s);
            st.limits.push_with_interval(t, h, &q, &qd);
            st.prev_step = Some(step);
            st.steps.push(step);
            st.times.push(t);
            st.qs.push(q.clone());
            let events: Vec<Event> = match a.get("events") {
                None => Vec::new(),
                Some(v) => serde_json::from_value(v.clone()).map_err(|e| {
                    parse_err(file, number, 1, format!("agents.{}.events: expected typed events ({e})", st.name))
                })?,
            };
            if let Some((e0, e1)) = st.closure {
                let rel = {
                    let (_, t0) = st.robot.end_effector_poses(&q, e0);
                    let (_, t1) = st.robot.end_effector_poses(&q, e1);
                    t0.inverse() * t1
                };
                let Some(c) = st.out.closure.as_mut() else { continue };
                if events.iter().any(|e| matches!(e, Event::Release)) {
                    st.holding = None;
                } else if events.iter().any(|e| matches!(e, Event::Grasp)) {
                    c.grasps += 1;
                    st.holding = Some(rel);
                } else if let Some(reference) = &st.holding {
                    c.samples += 1;
                    let (dp, da) = pose_error(reference, &rel);
                    c.max_position_error_m = c.max_position_error_m.max(dp);
                    c.max_angle_error_rad = c.max_angle_error_rad.max(da);
                    if c.violation.is_none() && (dp > chain_tol.0 || da > chain_tol.1) {
                        c.ok = false;
                        c.violation = Some(Finding::ClosureDrift {
                            t,
                            span: c.grasps.saturating_sub(1),
                            position_error_m: dp,
                            angle_error_rad: da,
                            tolerance_m: chain_tol.0,
                            tolerance_rad: chain_tol.1,
                        });
                    }
                }
            }
        }
    }
    if !complete && note.is_none() {
        note = Some(format!("no summary line: the run did not finish; checked its {steps} steps"));
    }
    // Collisions: every robot against the obstacles at their times, every two robots at the
    // same steps.
    let verifier = Verifier::certified(0.0).with_settings(*settings);
    let mut budget = EvaluationBudget::new(settings.max_evaluations);
    let timeline = ObstacleTimeline::new(scenario, step_s);
    let mut robot_robot = Vec::new();
    for (i, a) in agents.iter().enumerate() {
        for b in &agents[i + 1..] {
            if a.steps == b.steps {
                robot_robot.push(certify_pair(&motion(a), &motion(b), &verifier, &mut budget));
            } else {
                warnings.push(format!(
                    "agents {} and {} are not logged at the same steps: not checked against each other",
                    a.name, b.name
                ));
            }
        }
    }
    let collisions: Vec<MotionCheck> =
        agents.iter().map(|st| certify_environment(&motion(st), &timeline, &verifier, &mut budget)).collect();
    let budget_exhausted = collisions.iter().chain(&robot_robot).any(|c| is_spent(c.violation.as_ref()));
    let agents: Vec<LogAgent> = agents
        .into_iter()
        .zip(collisions)
        .map(|(st, collision)| {
            let mut a = st.out;
            a.collision = Some(collision);
            a.violation = st.limits.first().cloned();
            a.violations = st.limits.violations();
            a.max_velocity_ratio = st.limits.max_velocity_ratio();
            a.max_acceleration_ratio = st.limits.max_acceleration_ratio();
            a.certified = a.violation.is_none()
                && a.closure.as_ref().is_none_or(|c| c.ok)
                && a.collision.as_ref().is_none_or(|c| c.ok);
            a
        })
        .collect();
    Ok(LogVerification {
        generator: crate::generator(),
        log_file: file.to_path_buf(),
        scenario: scenario.name.clone(),
        certified: agents.iter().all(|a| a.certified) && robot_robot.iter().all(|c| c.ok),
        complete,
        note,
        steps,
        step_s,
        warnings,
        agents,
        robot_robot,
        settings: *settings,
        distance_evaluations: budget.used,
        budget_exhausted,
        time_s: start.elapsed().as_secs_f64(),
    })
}

/// The log report as text.
pub fn render_log(v: &LogVerification) -> String {
    let mut s = format!(
        "log {} against scenario `{}`: {} steps of {} s{}\n",
        v.log_file.display(),
        v.scenario,
        v.steps,
        v.step_s,
        if v.complete { "" } else { " (truncated)" }
    );
    if let Some(n) = &v.note {
        s.push_str(&format!("note: {n}\n"));
    }
    for w in &v.warnings {
        s.push_str(&format!("warning: {w}\n"));
    }
    for a in &v.agents {
        s.push_str(&format!(
            "{}: {} ({} steps; limits {}: {} violations, peak velocity {:.3}, acceleration {:.3} of limit)\n",
            a.agent,
            if a.certified { "CERTIFIED" } else { "NOT CERTIFIED" },
            a.steps,
            ok_word(a.violation.is_none()),
            a.violations,
            a.max_velocity_ratio,
            a.max_acceleration_ratio
        ));
        if let Some(f) = &a.violation {
            s.push_str(&format!("  first violation: {f}\n"));
        }
        if let Some(c) = &a.closure {
            s.push_str(&format!(
                "  closure: {} ({} grasps, {} steps held, largest error {:.2e} m, {:.2e} rad)\n",
                ok_word(c.ok),
                c.grasps,
                c.samples,
                c.max_position_error_m,
                c.max_angle_error_rad
            ));
            if let Some(f) = &c.violation {
                s.push_str(&format!("  first violation: {f}\n"));
            }
        }
        if let Some(c) = &a.collision {
            render_motion_check(&mut s, c);
        }
    }
    for c in &v.robot_robot {
        render_motion_check(&mut s, c);
    }
    closing_line(&mut s, v.certified, v.distance_evaluations, &v.settings, v.budget_exhausted, v.time_s);
    s
}

fn render_motion_check(s: &mut String, c: &MotionCheck) {
    s.push_str(&format!(
        "  collision ({}): {} ({} step-to-step motions certified, smallest distance measured {:.4} m)\n",
        c.what,
        ok_word(c.ok),
        c.segments,
        c.min_clearance_m
    ));
    if let Some(f) = &c.violation {
        s.push_str(&format!("  first violation: {f}\n"));
    }
}

/// What `embodied verify SCENARIO [PLAN.json] [--log FILE.jsonl]` found.
#[derive(Debug, Clone, Serialize)]
pub struct Verification {
    /// Everything checked is certified.
    pub certified: bool,
    /// The plan file's report, when a plan was given.
    pub plan: Option<PlanVerification>,
    /// The run log's report, when a log was given.
    pub log: Option<LogVerification>,
}

impl Verification {
    /// The report as one JSON object: the plan's or the log's report alone when only one was
    /// checked, else both under `plan` and `log` with `certified` for all.
    pub fn to_json(&self) -> Result<String, SystemError> {
        match (&self.plan, &self.log) {
            (Some(p), None) => json_of(p),
            (None, Some(l)) => json_of(l),
            _ => json_of(self),
        }
    }

    /// The report as text for the terminal.
    pub fn render(&self) -> String {
        let mut out = String::new();
        if let Some(p) = &self.plan {
            out.push_str(&render_plan(p));
        }
        if let Some(l) = &self.log {
            out.push_str(&render_log(l));
        }
        out
    }
}

/// Check a plan file and/or a run log against a scenario (a built-in name or a file) with
/// `settings` (the plan and the log each get the budget of distance evaluations).
pub fn verify_files(
    scenario: &str,
    plan: Option<&Path>,
    log: Option<&Path>,
    settings: &CheckSettings,
) -> Result<Verification, SystemError> {
    if plan.is_none() && log.is_none() {
        return Err(SystemError::Usage("verify: give a plan file, --log FILE.jsonl, or both".into()));
    }
    let scenario = load_scenario(scenario)?;
    let plan = match plan {
        Some(p) => Some(verify_plan(&scenario, &read_plan(p)?, p, settings)?),
        None => None,
    };
    let log = match log {
        Some(l) => Some(verify_log(&scenario, l, settings)?),
        None => None,
    };
    let certified = plan.as_ref().is_none_or(|r| r.certified) && log.as_ref().is_none_or(|r| r.certified);
    Ok(Verification { certified, plan, log })
}

fn json_of<T: Serialize>(value: &T) -> Result<String, SystemError> {
    serde_json::to_string(value).map_err(|e| SystemError::Failed(e.to_string()))
}

// ---------------------------------------------------------------------------------------------
// Robot-environment collisions of a run log.

/// The robots of a run log against the scenario's environment.
#[derive(Debug, Clone, Serialize, Default)]
pub struct LogEnvironment {
    /// Step pairs checked (per agent).
    pub motions: usize,
    /// Motions between two logged steps that touch an obstacle on the map (there from the
    /// start and still): the plans and halts must avoid these.
    pub map_collisions: usize,
    /// Steps at which a robot that was moving touches an obstacle that appeared or moves
    /// (the bounding sphere the detector sees).
    pub moving_contacts: usize,
    /// Steps at which an obstacle that appeared or moves touches a robot at rest (the robot
    /// cannot escape; counted apart).
    pub resting_contacts: usize,
    /// The first collision or contact found: time, agent, what.
    pub first: Option<String>,
    /// Smallest distance (m) between a robot and an obstacle on the map at any logged step
    /// (every tenth step and every step with a collision).
    pub closest_approach_m: f64,
}

/// Check the motion between consecutive logged configurations of every agent against the
/// scenario's obstacles: those on the map continuously (sampled at `resolution`), and those
/// that appear or move (as the bounding spheres the detector sees, where they are at that
/// step) at each step.
pub fn verify_log_environment(
    scenario: &Scenario,
    file: &Path,
    resolution: f64,
) -> Result<LogEnvironment, SystemError> {
    use embodied_models::collision::{CollisionModel, Environment, Obstacle};
    use embodied_models::nalgebra::Isometry3;
    let text =
        embodied_models::formats::limits::read_text_limited(file, embodied_models::formats::limits::InputKind::Log)
            .map_err(|e| SystemError::io(file, e))?;
    let step_s = text
        .lines()
        .next()
        .and_then(|l| serde_json::from_str::<Value>(l).ok())
        .and_then(|h| h.get("header")?.get("step_s")?.as_f64())
        .filter(|s| *s > 0.0 && *s <= MAX_STEP_S)
        .ok_or_else(|| {
            parse_err(file, 1, 1, format!("header.step_s: missing or not a control period in (0, {MAX_STEP_S}] s"))
        })?;
    let map = scenario.initial_environment();
    let models: Vec<CollisionModel> =
        scenario.agents.iter().map(|a| CollisionModel::new(&a.robot, map.clone())).collect();
    let dynamic: Vec<_> = scenario.obstacles.iter().filter(|o| !o.on_map()).collect();
    // The obstacles that appear or move, as the bounding spheres the detector sees, moved
    // into place step by step.
    let mut dynamic_models: Vec<Option<CollisionModel>> = scenario
        .agents
        .iter()
        .map(|a| {
            (!dynamic.is_empty()).then(|| {
                let mut env = Environment::new();
                for o in &dynamic {
                    let (_, r) = o.obstacle.shape.bounding_sphere();
                    env.add(Obstacle::new(
                        o.obstacle.name.clone(),
                        Isometry3::identity(),
                        embodied_models::Shape::Sphere { radius: r },
                    ));
                }
                CollisionModel::new(&a.robot, env)
            })
        })
        .collect();
    let mut out = LogEnvironment { closest_approach_m: f64::INFINITY, ..LogEnvironment::default() };
    let mut prev: Vec<Option<Vec<f64>>> = vec![None; scenario.agents.len()];
    for (i, line) in text.lines().enumerate().skip(1) {
        let Ok(value) = serde_json::from_str::<Value>(line) else { break };
        let Some(step) = value.get("step").and_then(Value::as_u64) else { break };
        let t = step as f64 * step_s;
        let Some(step_agents) = value.get("agents").and_then(Value::as_object) else { break };
        for (k, agent) in scenario.agents.iter().enumerate() {
            let Some(a) = step_agents.get(&agent.name) else { continue };
            let q: Vec<f64> = a.get("q").and_then(|v| serde_json::from_value(v.clone()).ok()).ok_or_else(|| {
                parse_err(file, i + 1, 1, format!("agents.{}.q: missing or not an array of numbers", agent.name))
            })?;
            let qd: Vec<f64> = a.get("qd").and_then(|v| serde_json::from_value(v.clone()).ok()).unwrap_or_default();
            let model = &models[k];
            let mut hit = false;
            if let Some(p) = &prev[k] {
                out.motions += 1;
                if !model.motion_is_free(p, &q, resolution) {
                    out.map_collisions += 1;
                    hit = true;
                    out.first
                        .get_or_insert_with(|| format!("t={t:.3}s {}: touches an obstacle on the map", agent.name));
                }
            }
            if (hit || step.is_multiple_of(10)) && !map.obstacles().is_empty() {
                out.closest_approach_m = out.closest_approach_m.min(model.distance(&q).distance);
            }
            if let Some(m) = dynamic_models[k].as_mut() {
                for o in &dynamic {
                    let appear = o.appear_at.unwrap_or(0.0);
                    let (c, _) = o.obstacle.shape.bounding_sphere();
                    let mut p = o.obstacle.pose * c;
                    if t < appear {
                        // Not there yet: far away.
                        p.z += 1e6;
                    } else if let Some(v) = o.velocity {
                        p += v * (t - appear);
                    }
                    m.set_obstacle_pose(&o.obstacle.name, Isometry3::translation(p.x, p.y, p.z));
                }
                if m.collides(&q) {
                    let moving = qd.iter().any(|v| v.abs() > 1e-9);
                    if moving {
                        out.moving_contacts += 1;
                    } else {
                        out.resting_contacts += 1;
                    }
                    out.first.get_or_insert_with(|| {
                        let how = if moving { "moving" } else { "at rest" };
                        format!("t={t:.3}s {}: {how}, touches an obstacle that appeared or moves", agent.name)
                    });
                }
            }
            prev[k] = Some(q);
        }
    }
    Ok(out)
}
