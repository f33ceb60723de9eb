//! `embodied bench mbm --ompl-log DIR`: the results in OMPL's benchmark log format, the text
//! that `ompl_benchmark_statistics.py` reads into the SQLite database Planner Arena shows, so
//! that these runs sit next to OMPL's and MoveIt's planners.
//!
//! The format is the one `ompl::tools::Benchmark::saveResultsToStream` writes (OMPL 1.5/1.6):
//! one experiment per file, and, as OMPL and MoveIt benchmark, one experiment per problem:
//!
//! ```text
//! embodied version 0.1.0
//! Experiment box_ur5_0001
//! 4 experiment properties
//! git_commit STRING = 1a2b3c4
//! ...
//! Running on HOST
//! Starting at 2026-11-24T20:00:00Z
//! <<<|
//! (setup: problem files and settings)
//! |>>>
//! <<<|
//! (CPU model and cores)
//! |>>>
//! SEED is the random seed
//! T seconds per run
//! 0 MB per run
//! R runs per planner
//! S seconds spent to collect the data
//! 1 enum type
//! status|Unknown status|Invalid start|...
//! 1 planners
//! embodied_rrt_connect
//! C common properties
//! name = value            (C lines)
//! P properties for each run
//! name TYPE               (P lines, sorted)
//! R runs
//! v1; v2; ...; vP;        (R lines; an empty value is a property the run has not)
//! .
//! ```
//!
//! `status` follows OMPL's `PlannerStatus` order. Memory is not measured: the memory limit is
//! written as 0 and runs have no `memory` property.

use std::path::{Path, PathBuf};

use embodied_planner::motion::EdgeCheck;

use crate::SystemError;
use crate::batch::Machine;
use crate::mbm::{MbmReport, ProblemResult, ProblemStatus};

/// OMPL's `PlannerStatus` names, in the order of its enum (the value written is the index).
pub const OMPL_STATUS: [&str; 10] = [
    "Unknown status",
    "Invalid start",
    "Invalid goal",
    "Unrecognized goal type",
    "Timeout",
    "Approximate solution",
    "Exact solution",
    "Crashed",
    "Abort",
    "Infeasible",
];

fn status_value(status: ProblemStatus) -> usize {
    match status {
        ProblemStatus::InvalidStart => 1,
        ProblemStatus::InvalidGoal => 2,
        ProblemStatus::OutOfTime => 4,
        ProblemStatus::Solved => 6,
        // The planner stopped before the deadline without a path, or its path did not verify.
        ProblemStatus::Failed => 8,
    }
}

/// The planner's name in the log: `embodied_` and the algorithm (`embodied_rrt_connect`).
pub fn planner_name(report: &MbmReport) -> String {
    format!("embodied_{}", report.settings.algorithm.name().replace('-', "_"))
}

fn flag(b: bool) -> &'static str {
    if b { "1" } else { "0" }
}

/// The run properties written per run, in OMPL's (sorted) order, and each run's values.
fn run_properties(report: &MbmReport, r: &ProblemResult) -> Vec<(&'static str, String)> {
    let certified_edges = matches!(report.settings.edge_check, EdgeCheck::Certified { .. });
    let stat = |key: &str| -> String {
        r.stats
            .as_ref()
            .and_then(|s| s.get(key))
            .and_then(serde_json::Value::as_u64)
            .map_or(String::new(), |v| v.to_string())
    };
    let has_path = !r.path.is_empty();
    let segments = if has_path { (r.path.len() - 1).to_string() } else { String::new() };
    let length = r.path_length.filter(|_| has_path).map_or(String::new(), |l| l.to_string());
    let verified = r.verified.map_or(String::new(), |v| flag(v).to_string());
    vec![
        (
            "certified solution BOOLEAN",
            if has_path { flag(r.solved && certified_edges).to_string() } else { String::new() },
        ),
        ("collision checks INTEGER", stat("collision_checks")),
        ("correct solution BOOLEAN", verified.clone()),
        ("samples INTEGER", stat("samples")),
        ("simplified correct solution BOOLEAN", verified),
        ("simplified solution length REAL", length.clone()),
        ("simplified solution segments INTEGER", segments.clone()),
        ("solution length REAL", length),
        ("solution segments INTEGER", segments),
        ("solved BOOLEAN", flag(r.solved).to_string()),
        ("status ENUM", status_value(r.status).to_string()),
        ("time REAL", r.planning_us.map_or(String::new(), |us| (us / 1e6).to_string())),
    ]
}

/// The OMPL log of one problem (every run of `family`/`index` in `report`).
pub fn ompl_log(report: &MbmReport, family: &str, index: u32, machine: &Machine, date: &str) -> String {
    let runs: Vec<&ProblemResult> = report.problems.iter().filter(|p| p.family == family && p.index == index).collect();
    let s = &report.settings;
    let (version, commit) = split_generator(&report.generator);
    let mut out = String::new();
    let mut line = |text: String| {
        out.push_str(&text);
        out.push('\n');
    };
    line(format!("embodied version {version}"));
    line(format!("Experiment {family}_{index:04}"));
    let props = [
        format!("git_commit STRING = {commit}"),
        format!("family STRING = {family}"),
        format!("problem INTEGER = {index}"),
        format!("cores INTEGER = {}", machine.cores),
    ];
    line(format!("{} experiment properties", props.len()));
    for p in props {
        line(p);
    }
    line(format!("Running on {}", machine.hostname.split_whitespace().collect::<Vec<_>>().join("_")));
    line(format!("Starting at {date}"));
    line("<<<|".into());
    line(format!("{} (MotionBenchMaker problem {family}/{index:04})", report.generator));
    line(format!("robot {} (SRDF {})", s.urdf.display(), s.srdf.display()));
    line(format!("problems {}", s.problems.display()));
    line(format!("paths re-checked at {} rad", s.verify_resolution));
    line("|>>>".into());
    line("<<<|".into());
    line(format!("{} ({} cores)", machine.cpu, machine.cores));
    line("|>>>".into());
    line(format!("{} is the random seed", s.seed));
    line(format!("{} seconds per run", s.deadline_ms / 1000.0));
    line("0 MB per run".into());
    line(format!("{} runs per planner", runs.len()));
    let total: f64 = runs.iter().filter_map(|r| r.planning_us).sum::<f64>() / 1e6;
    line(format!("{total} seconds spent to collect the data"));
    line("1 enum type".into());
    line(format!("status|{}", OMPL_STATUS.join("|")));
    line("1 planners".into());
    line(planner_name(report));
    let edges = match s.edge_check {
        EdgeCheck::Certified { tolerance } => format!("certified (tolerance {tolerance} m)"),
        EdgeCheck::Sampled => format!("sampled at {} rad", s.resolution),
    };
    let mut common = vec![
        format!("balance = {}", flag(s.balance)),
        format!("dynamic_domain = {}", flag(s.dynamic_domain)),
        format!("edge_check = {edges}"),
        format!("goal_retreat = {}", flag(s.goal_retreat)),
        format!("local_bias = {}", s.rrt_local_bias),
        format!("late_after = {}", s.rrt_late_after),
        format!("late_local_bias = {}", s.rrt_late_local_bias),
        format!("local_span = {}", s.rrt_local_span),
        format!("local_reach = {}", s.rrt_local_reach.unwrap_or(f64::INFINITY)),
        format!("range = {}", s.rrt_range),
        format!(
            "sampler = {}",
            serde_json::to_value(s.sampler).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default()
        ),
        format!("shortcut_attempts = {}", s.shortcut_attempts),
        format!("shortcut_min_gain = {}", s.shortcut_min_gain),
        format!("screen_above = {}", s.screen_above),
        format!("threads = {}", s.threads),
    ];
    // Recorded since these settings became options; older reports leave them out.
    common.extend(s.lazy_probe.map(|v| format!("lazy_probe = {v}")));
    common.extend(s.max_samples.map(|v| format!("max_samples = {v}")));
    common.extend(s.rrt_restarts.map(|v| format!("restarts = {v}")));
    line(format!("{} common properties", common.len()));
    for c in common {
        line(c);
    }
    let names: Vec<&str> =
        runs.first().map(|r| run_properties(report, r)).unwrap_or_default().iter().map(|(n, _)| *n).collect();
    let names = if names.is_empty() {
        run_properties(report, &empty_result()).iter().map(|(n, _)| *n).collect()
    } else {
        names
    };
    line(format!("{} properties for each run", names.len()));
    for n in &names {
        line((*n).to_string());
    }
    line(format!("{} runs", runs.len()));
    for r in &runs {
        let mut row = String::new();
        for (_, v) in run_properties(report, r) {
            row.push_str(&v);
            row.push_str("; ");
        }
        line(row);
    }
    line(".".into());
    out
}

fn empty_result() -> ProblemResult {
    ProblemResult {
        family: String::new(),
        index: 0,
        run: 0,
        solved: false,
        status: ProblemStatus::Failed,
        planning_us: None,
        joint_names: Vec::new(),
        path: Vec::new(),
        path_length: None,
        verified: None,
        stats: None,
        message: None,
    }
}

/// `embodied 0.1.0 (commit abc)` -> (`0.1.0`, `abc`).
fn split_generator(generator: &str) -> (String, String) {
    let rest = generator.strip_prefix("embodied ").unwrap_or(generator);
    match rest.split_once(" (commit ") {
        Some((v, c)) => (v.to_string(), c.trim_end_matches(')').to_string()),
        None => (rest.to_string(), "unknown".to_string()),
    }
}

/// Write one OMPL log per problem of `report` into `dir` (created if missing), named
/// `<family>_<NNNN>.log`; returns the files written.
pub fn write_ompl_logs(report: &MbmReport, dir: &Path) -> Result<Vec<PathBuf>, SystemError> {
    std::fs::create_dir_all(dir).map_err(|e| SystemError::write(dir, e))?;
    let machine = Machine::this();
    let date = crate::batch::utc_now();
    let mut problems: Vec<(&str, u32)> = Vec::new();
    for p in &report.problems {
        if !problems.contains(&(p.family.as_str(), p.index)) {
            problems.push((&p.family, p.index));
        }
    }
    let mut written = Vec::new();
    for (family, index) in problems {
        let path = dir.join(format!("{family}_{index:04}.log"));
        std::fs::write(&path, ompl_log(report, family, index, &machine, &date))
            .map_err(|e| SystemError::write(&path, e))?;
        written.push(path);
    }
    Ok(written)
}
