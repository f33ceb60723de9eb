//! `embodied plan --batch INPUT [--shard K/N] [--jsonl FILE]`: plan and certify many problems,
//! one JSON object per problem.
//!
//! INPUT is either a folder of MoveIt problems in MotionBenchMaker's layout
//! (`<family>/sceneNNNN.yaml` + `requestNNNN.yaml`, with `--urdf` and `--srdf`), or a text file
//! listing scenarios (a built-in name or a TOML file per line, relative to the list's folder;
//! blank lines and `#` comments skipped). Problems are taken in a stable order (families sorted,
//! then problem index; a list in its own order) and shared out by [`Shard`].

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use embodied_planner::deadline::Deadline;
use embodied_planner::motion::MotionSettings;
use embodied_planner::moveit::{load_request, load_scene, moveit_problem, plan_request, to_joint_trajectory};
use embodied_planner::verify::Verifier;
use embodied_system::batch::{JsonlWriter, MergedShards, Shard};
use embodied_system::mbm::{MbmArgs, batch_header, find_problems, with_ordinal};
use serde::{Deserialize, Serialize};

use crate::AppError;
use crate::moveit_cli::{from_moveit, load_moveit_robot};

/// Kind of the batch results files of `plan --batch --jsonl`.
pub const PLAN_BATCH_KIND: &str = "plan-batch";

/// What `plan --batch` is asked.
#[derive(Debug, Clone)]
pub struct BatchPlanArgs {
    /// A folder of MoveIt problems or a list of scenarios.
    pub input: PathBuf,
    /// The robot of MoveIt problems.
    pub urdf: Option<PathBuf>,
    /// Its SRDF.
    pub srdf: Option<PathBuf>,
    /// MoveIt's joint_limits.yaml.
    pub limits: Option<PathBuf>,
    /// Planning deadline per problem (default: the request's or the scenario's).
    pub deadline_ms: Option<f64>,
    /// Which share of the problems to plan.
    pub shard: Shard,
}

/// The settings of a batch, echoed in the header and the report.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct BatchPlanSettings {
    /// `moveit` (a problem folder) or `scenarios` (a list).
    pub input_kind: String,
    /// The problem folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problems: Option<PathBuf>,
    /// The scenario list.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub list: Option<PathBuf>,
    /// The robot of MoveIt problems.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub urdf: Option<PathBuf>,
    /// Its SRDF.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub srdf: Option<PathBuf>,
    /// MoveIt's joint_limits.yaml.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<PathBuf>,
    /// Planning deadline per problem, when set for all.
    pub deadline_ms: Option<f64>,
}

/// One problem's outcome.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct BatchPlanResult {
    /// `family/NNNN` or the scenario's name as listed.
    pub name: String,
    /// Whether a plan came back and the certified checker accepted it.
    pub certified: bool,
    /// Wall time of planning, microseconds (scenarios: planning and certifying every agent).
    pub planning_us: Option<f64>,
    /// Waypoints of the path (all agents' for a scenario).
    pub waypoints: usize,
    /// Seconds of motion (the longest agent's for a scenario).
    pub duration_s: Option<f64>,
    /// Certified clearance of the trajectory, m (MoveIt problems).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance_m: Option<f64>,
    /// Why there is no certified plan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// The plan: a `trajectory_msgs/JointTrajectory` (MoveIt problems) or an `embodied-plan/1`
    /// plan file (scenarios).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<serde_json::Value>,
}

/// Counts and planning-time percentiles of a batch.
#[derive(Debug, Clone, Serialize)]
pub struct BatchPlanReport {
    /// The program (version and commit) that made the report.
    pub generator: String,
    /// The share this report holds (absent: all of it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// The batch's settings.
    pub settings: BatchPlanSettings,
    /// Problems planned.
    pub total: usize,
    /// Problems with a certified plan.
    pub certified: usize,
    /// Median planning time of the certified problems, µs.
    pub p50_us: Option<f64>,
    /// 95th percentile planning time of the certified problems, µs.
    pub p95_us: Option<f64>,
    /// Longest planning time of the certified problems, µs.
    pub max_us: Option<f64>,
    /// Every problem's outcome, in the batch's order.
    pub problems: Vec<BatchPlanResult>,
}

/// One item of the batch.
enum Item {
    Moveit { name: String, scene: PathBuf, request: PathBuf },
    Scenario { name: String, source: String },
}

fn items(args: &BatchPlanArgs) -> Result<(Vec<Item>, BatchPlanSettings), AppError> {
    if args.input.is_dir() {
        let (Some(urdf), Some(srdf)) = (&args.urdf, &args.srdf) else {
            return Err(AppError::Usage(format!(
                "{} is a folder of MoveIt problems: --urdf and --srdf name their robot",
                args.input.display()
            )));
        };
        let files = find_problems(&MbmArgs::new(urdf, srdf, &args.input))?;
        let items = files
            .into_iter()
            .map(|p| Item::Moveit { name: format!("{}/{:04}", p.family, p.index), scene: p.scene, request: p.request })
            .collect();
        let settings = BatchPlanSettings {
            input_kind: "moveit".into(),
            problems: Some(args.input.clone()),
            list: None,
            urdf: Some(urdf.clone()),
            srdf: Some(srdf.clone()),
            limits: args.limits.clone(),
            deadline_ms: args.deadline_ms,
        };
        return Ok((items, settings));
    }
    if args.urdf.is_some() || args.srdf.is_some() || args.limits.is_some() {
        return Err(AppError::Usage(format!(
            "{}: --urdf, --srdf and --limits go with a folder of MoveIt problems; a list names scenarios",
            args.input.display()
        )));
    }
    let text = embodied_system::error::read_input(&args.input, embodied_models::formats::limits::InputKind::Text)?;
    let base = args.input.parent().unwrap_or(Path::new("."));
    let mut items = Vec::new();
    for line in text.lines() {
        let entry = line.split('#').next().unwrap_or("").trim();
        if entry.is_empty() {
            continue;
        }
        let is_builtin = embodied_system::scenario::BUILTIN_SCENARIOS.iter().any(|(n, _)| *n == entry);
        let source = if is_builtin || Path::new(entry).is_absolute() {
            entry.to_string()
        } else {
            base.join(entry).display().to_string()
        };
        items.push(Item::Scenario { name: entry.to_string(), source });
    }
    if items.is_empty() {
        return Err(AppError::Usage(format!(
            "{}: no scenario listed (one name or TOML file per line)",
            args.input.display()
        )));
    }
    let settings = BatchPlanSettings {
        input_kind: "scenarios".into(),
        problems: None,
        list: Some(args.input.clone()),
        urdf: None,
        srdf: None,
        limits: None,
        deadline_ms: args.deadline_ms,
    };
    Ok((items, settings))
}

fn failed(name: &str, planning_us: Option<f64>, message: String) -> BatchPlanResult {
    BatchPlanResult {
        name: name.to_string(),
        certified: false,
        planning_us,
        waypoints: 0,
        duration_s: None,
        clearance_m: None,
        message: Some(message),
        plan: None,
    }
}

fn micros(d: Duration) -> f64 {
    (d.as_secs_f64() * 1e7).round() / 10.0
}

/// Plan this shard's problems, writing each result to `jsonl` as it comes;
/// `on_progress(done, total)` after each.
pub fn plan_batch(
    args: &BatchPlanArgs,
    mut jsonl: Option<&mut JsonlWriter>,
    on_progress: &mut dyn FnMut(usize, usize),
) -> Result<BatchPlanReport, AppError> {
    let (items, settings) = items(args)?;
    if let Some(ms) = args.deadline_ms.filter(|ms| !(ms.is_finite() && *ms > 0.0)) {
        return Err(AppError::Usage(format!("--deadline-ms must be a positive number, got {ms}")));
    }
    let robot = match (&settings.urdf, &settings.srdf) {
        (Some(u), Some(s)) => {
            let (robot, srdf) = load_moveit_robot(u, Some(s), args.limits.as_deref())?;
            let srdf = srdf.ok_or_else(|| AppError::Usage(format!("{}: no SRDF groups", s.display())))?;
            Some((robot, srdf))
        }
        _ => None,
    };
    let names: Vec<String> = items
        .iter()
        .map(|i| match i {
            Item::Moveit { name, .. } | Item::Scenario { name, .. } => name.clone(),
        })
        .collect();
    if let Some(out) = jsonl.as_deref_mut() {
        out.line(&batch_header(PLAN_BATCH_KIND, args.shard, &names, 1, &settings)?)?;
    }
    let mine: Vec<(usize, &Item)> = items.iter().enumerate().filter(|(i, _)| args.shard.holds(*i)).collect();
    let total = mine.len();
    on_progress(0, total);
    let mut results = Vec::with_capacity(total);
    for (i, item) in mine {
        let result = match (item, &robot) {
            (Item::Moveit { name, scene, request }, Some((robot, srdf))) => {
                plan_one_moveit(name, robot, srdf, scene, request, args.deadline_ms)?
            }
            (Item::Scenario { name, source }, _) => plan_one_scenario(name, source, args.deadline_ms)?,
            (Item::Moveit { .. }, None) => {
                return Err(AppError::Usage("MoveIt problems need --urdf and --srdf".into()));
            }
        };
        if let Some(out) = jsonl.as_deref_mut() {
            out.line(&with_ordinal(i, &result)?)?;
        }
        results.push(result);
        on_progress(results.len(), total);
    }
    let shard = (args.shard != Shard::ALL).then_some(args.shard);
    Ok(assemble(embodied_system::generator(), shard, settings, results))
}

fn plan_one_moveit(
    name: &str,
    robot: &embodied_models::Robot,
    srdf: &embodied_models::srdf::Srdf,
    scene: &Path,
    request: &Path,
    deadline_ms: Option<f64>,
) -> Result<BatchPlanResult, AppError> {
    let scene = load_scene(scene).map_err(from_moveit)?;
    let req = load_request(request).map_err(from_moveit)?;
    let problem = match moveit_problem(robot, srdf, &scene, &req) {
        Ok(p) => p,
        Err(e @ embodied_planner::moveit::MoveitError::Parse { .. }) => return Err(from_moveit(e)),
        Err(e) => return Ok(failed(name, None, e.to_string())),
    };
    for w in &problem.resolved.warnings {
        eprintln!("{w}");
    }
    let seconds = deadline_ms
        .map(|ms| ms / 1000.0)
        .unwrap_or_else(|| req.allowed_planning_time.filter(|t| t.is_finite() && *t > 0.0).unwrap_or(5.0));
    let settings =
        MotionSettings { deadline: Deadline::after(Duration::from_secs_f64(seconds)), ..MotionSettings::default() };
    let t0 = Instant::now();
    let plan = plan_request(&problem, &settings);
    let us = micros(t0.elapsed());
    let plan = match plan {
        Ok(p) => p,
        Err(e) => return Ok(failed(name, Some(us), e.to_string())),
    };
    // The certified checker, not the planner, says whether the plan may leave.
    let report = Verifier::default().check_trajectory(&problem.model, &plan.trajectory, &[]);
    let text = to_joint_trajectory(&plan.trajectory).to_text_for(Path::new("trajectory.json"));
    let trajectory: serde_json::Value = serde_json::from_str(&text).map_err(|e| AppError::Failed(e.to_string()))?;
    Ok(BatchPlanResult {
        name: name.to_string(),
        certified: report.certified,
        planning_us: Some(us),
        waypoints: plan.path.len(),
        duration_s: Some(plan.trajectory.duration()),
        clearance_m: Some(report.collision.certified_clearance_m),
        message: (!report.certified).then(|| format!("rejected by the certified checker: {:?}", report.findings())),
        plan: Some(trajectory),
    })
}

fn plan_one_scenario(name: &str, source: &str, deadline_ms: Option<f64>) -> Result<BatchPlanResult, AppError> {
    let scenario = embodied_system::scenario::load_scenario(source)?;
    let t0 = Instant::now();
    let plan = embodied_system::plan::plan_scenario(&scenario, deadline_ms);
    let us = micros(t0.elapsed());
    match plan {
        // `plan_scenario` certifies every trajectory before it returns a plan file.
        Ok(file) => Ok(BatchPlanResult {
            name: name.to_string(),
            certified: true,
            planning_us: Some(us),
            waypoints: file.plans.iter().map(|p| p.path.len()).sum(),
            duration_s: file.plans.iter().map(|p| p.trajectory.duration()).reduce(f64::max),
            clearance_m: None,
            message: None,
            plan: Some(serde_json::to_value(&file).map_err(|e| AppError::Failed(e.to_string()))?),
        }),
        Err(AppError::Failed(m)) => Ok(failed(name, Some(us), m)),
        Err(other) => Err(other),
    }
}

fn percentile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q * sorted.len() as f64).ceil().max(1.0) as usize;
    Some(sorted[rank.min(sorted.len()) - 1])
}

fn assemble(
    generator: String,
    shard: Option<Shard>,
    settings: BatchPlanSettings,
    problems: Vec<BatchPlanResult>,
) -> BatchPlanReport {
    let mut times: Vec<f64> = problems.iter().filter(|p| p.certified).filter_map(|p| p.planning_us).collect();
    times.sort_by(f64::total_cmp);
    BatchPlanReport {
        generator,
        shard,
        settings,
        total: problems.len(),
        certified: problems.iter().filter(|p| p.certified).count(),
        p50_us: percentile(&times, 0.5),
        p95_us: percentile(&times, 0.95),
        max_us: times.last().copied(),
        problems,
    }
}

/// The report of a whole batch from its checked shards.
pub fn merge_plan_batch(merged: MergedShards) -> Result<BatchPlanReport, AppError> {
    let MergedShards { header, lines } = merged;
    if header.kind != PLAN_BATCH_KIND {
        return Err(AppError::Usage(format!("these are `{}` results, not `{PLAN_BATCH_KIND}`", header.kind)));
    }
    let settings: BatchPlanSettings = serde_json::from_value(header.settings.clone())
        .map_err(|e| AppError::Usage(format!("the header's settings are not plan --batch settings: {e}")))?;
    let mut problems = Vec::with_capacity(lines.len());
    for l in lines {
        problems.push(serde_json::from_value(l.value).map_err(|e| AppError::Parse {
            file: l.file.clone(),
            line: l.line,
            column: 1,
            message: format!("expected a plan --batch result: {e}"),
        })?);
    }
    Ok(assemble(header.generator, None, settings, problems))
}

/// The report as text: counts, planning-time percentiles, and the problems without a
/// certified plan.
pub fn render_batch(report: &BatchPlanReport) -> String {
    let us = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
    let mut out = format!(
        "plan --batch{}: {}/{} problems planned and certified; planning time of the certified: p50 {} us, p95 {} us, max {} us\n",
        report.shard.map_or(String::new(), |s| format!(" (shard {s})")),
        report.certified,
        report.total,
        us(report.p50_us),
        us(report.p95_us),
        us(report.max_us),
    );
    for p in report.problems.iter().filter(|p| !p.certified) {
        out.push_str(&format!("not certified: {}: {}\n", p.name, p.message.as_deref().unwrap_or("")));
    }
    out
}
