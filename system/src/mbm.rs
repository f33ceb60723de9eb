//! `embodied bench mbm`: run the motion planner on MotionBenchMaker problems and verify every path.
//!
//! MotionBenchMaker (Chamzas et al., RA-L 2022) ships each problem as a MoveIt planning scene
//! (`sceneNNNN.yaml`) and a motion plan request (`requestNNNN.yaml`) in one folder per family.
//! For every problem this module freezes the joints outside the request's group at their start
//! values, builds the collision environment from the scene, plans from the start to the goal's
//! joint constraints under a deadline, and then checks the returned path independently
//! ([`Verifier::verify_path`] sampled at [`VERIFY_RESOLUTION`], plus its end points). Only the call to
//! [`plan_motion`] is timed: loading and checking the problem is not planning time.
//!
//! Problems whose start or goal is in collision (or outside the joint limits) are reported as
//! invalid, not as planner failures: MotionBenchMaker has a few by construction.
//!
//! [`versus`] plans every problem with two sets of settings in turns and compares them problem
//! by problem.

pub mod versus;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use embodied_models::collision::{disable_always_colliding, disable_never_colliding};
use embodied_models::srdf::{Srdf, load_srdf};
use embodied_models::urdf::load_urdf;
use embodied_models::{CollisionModel, ConfigSpace, Robot, Warning};
use embodied_planner::PlanError;
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{CERTIFY_TOLERANCE, EdgeCheck, Goal, MotionSettings, PlannerKind, Sampler, plan_motion};
use embodied_planner::moveit::{MoveitError, MoveitProblem, goal_configurations, goal_miss, load_request, load_scene};
use embodied_planner::verify::Verifier;
use serde::{Deserialize, Serialize};

use crate::SystemError as AppError;
use crate::batch::{BATCH_FORMAT, Header, JsonlWriter, Machine, MergedShards, Shard};

/// The resolution (rad, largest joint step) at which every returned path is re-checked.
pub const VERIFY_RESOLUTION: f64 = 0.005;

/// How far (joint-space distance) a path's first/last waypoint may be from the request's
/// start/goal.
pub const ENDPOINT_TOLERANCE: f64 = 1e-6;

/// What `embodied bench mbm` is asked to do.
#[derive(Debug, Clone)]
pub struct MbmArgs {
    /// The robot (the spherized UR5 for the public UR5 problems).
    pub urdf: PathBuf,
    /// Its SRDF (groups, disabled collision pairs).
    pub srdf: PathBuf,
    /// A folder of family folders (`problems/<family>/sceneNNNN.yaml`), the folder above it, or a
    /// single family folder.
    pub problems: PathBuf,
    /// Planning deadline per problem, milliseconds.
    pub deadline_ms: f64,
    /// Base seed; each problem plans with a seed derived from it and the problem's place.
    pub seed: u64,
    /// How the planner checks its edges: certified (default: free for the whole continuum) or
    /// sampled at `resolution`.
    pub edge_check: EdgeCheck,
    /// Collision-checking resolution of the planner's edges when sampled (rad, largest joint step).
    pub resolution: f64,
    /// Random shortcut attempts after the greedy shortcut pass (the planner's default: 5).
    pub shortcut_attempts: usize,
    /// The least share of the path's length a random shortcut must gain to be checked (the
    /// planner's default: 0.01).
    pub shortcut_min_gain: f64,
    /// Shortcuts and straight segments longer than this are screened by an eight-point probe
    /// before their certificate (the planner's default: 2 rad; infinite: never).
    pub screen_above: f64,
    /// The planner after the straight segment (default: RRT-Connect).
    pub algorithm: PlannerKind,
    /// RRT-Connect's largest step (rad).
    pub rrt_range: f64,
    /// RRT-Connect with dynamic domain.
    pub dynamic_domain: bool,
    /// RRT-Connect first one independent group of joints at a time (two arms on a fixed torso).
    pub by_groups: bool,
    /// With more than one thread, the legs of a plan by groups searched two at a time instead
    /// of racing seeds (the planner's default: on; see `MotionSettings::parallel_legs`).
    pub parallel_legs: bool,
    /// RRT-Connect grows the smaller tree while the other has twice its nodes.
    pub balance: bool,
    /// RRT-Connect's goal retreats (the planner's default: off; see
    /// `MotionSettings::rrt_goal_retreat`).
    pub goal_retreat: bool,
    /// How RRT-Connect draws samples.
    pub sampler: Sampler,
    /// The share of RRT-Connect's samples drawn near a node of the tree about to grow (the
    /// planner's default: 0.5; see `MotionSettings::rrt_local_bias`).
    pub rrt_local_bias: f64,
    /// That share once an attempt has drawn `rrt_late_after` samples (the planner's default:
    /// 0.9 after 128; see `MotionSettings::rrt_late_local_bias`).
    pub rrt_late_local_bias: f64,
    /// Samples of an attempt before `rrt_late_local_bias` applies.
    pub rrt_late_after: usize,
    /// The half-width of those samples' box around their node, as a share of each joint's
    /// sampling width (the planner's default: 0.5), at most `rrt_local_reach`.
    pub rrt_local_span: f64,
    /// The most a joint of those samples is drawn from its node (rad, or m; the planner's
    /// default: 2; infinite: the span alone).
    pub rrt_local_reach: f64,
    /// Samples an RRT-Connect attempt may draw before it starts again with new trees (the
    /// planner's default: 50,000; see `MotionSettings::max_samples`).
    pub max_samples: usize,
    /// Attempts after the first (the planner's default: 64; see `MotionSettings::rrt_restarts`).
    pub rrt_restarts: usize,
    /// RRT-Connect's tree edges probed at this step (rad) and certified once on a path; 0:
    /// each certified as it is added (the planner's default: 0.1; see
    /// `MotionSettings::lazy_probe`).
    pub lazy_probe: f64,
    /// Planners racing per problem (1: one planner on one thread; 2: two differently seeded
    /// planners, the second on a thread of its own; first path wins).
    pub threads: usize,
    /// Only these families (all when `None`).
    pub families: Option<Vec<String>>,
    /// At most this many problems per family (the lowest indices).
    pub limit: Option<usize>,
    /// Whether the caller shows progress (the CLI's progress bar); `run_mbm` always reports
    /// through its callback.
    pub progress: bool,
    /// Which share of the problems to plan (problem `i` of the sorted set goes to shard
    /// `(i mod N) + 1`).
    pub shard: Shard,
    /// Plans per problem; run `r` plans with base seed `seed + r`.
    pub runs: usize,
}

impl MbmArgs {
    /// Arguments with the defaults of the CLI: 1 s deadline, seed 1, and certified edges (when
    /// sampled instead, at [`VERIFY_RESOLUTION`]: at 0.02 rad 37 of 296 MotionBenchMaker paths,
    /// at 0.05 rad 107, pass the planner's sampled checks and fail the 0.005 rad re-check: thin
    /// finger-tip spheres clip cans and shelf edges between checked points).
    pub fn new(urdf: impl Into<PathBuf>, srdf: impl Into<PathBuf>, problems: impl Into<PathBuf>) -> Self {
        Self {
            urdf: urdf.into(),
            srdf: srdf.into(),
            problems: problems.into(),
            deadline_ms: 1000.0,
            seed: 1,
            edge_check: EdgeCheck::Certified { tolerance: CERTIFY_TOLERANCE },
            resolution: VERIFY_RESOLUTION,
            shortcut_attempts: MotionSettings::default().shortcut_attempts,
            shortcut_min_gain: MotionSettings::default().shortcut_min_gain,
            screen_above: MotionSettings::default().screen_above,
            algorithm: PlannerKind::RrtConnect,
            rrt_range: MotionSettings::default().rrt_range,
            dynamic_domain: MotionSettings::default().rrt_dynamic_domain,
            by_groups: MotionSettings::default().rrt_by_groups,
            parallel_legs: MotionSettings::default().parallel_legs,
            balance: MotionSettings::default().rrt_balance,
            goal_retreat: MotionSettings::default().rrt_goal_retreat,
            sampler: MotionSettings::default().sampler,
            rrt_local_bias: MotionSettings::default().rrt_local_bias,
            rrt_late_local_bias: MotionSettings::default().rrt_late_local_bias,
            rrt_late_after: MotionSettings::default().rrt_late_after,
            rrt_local_span: MotionSettings::default().rrt_local_span,
            rrt_local_reach: MotionSettings::default().rrt_local_reach,
            max_samples: MotionSettings::default().max_samples,
            rrt_restarts: MotionSettings::default().rrt_restarts,
            lazy_probe: MotionSettings::default().lazy_probe,
            threads: 1,
            families: None,
            limit: None,
            progress: false,
            shard: Shard::ALL,
            runs: 1,
        }
    }
}

/// How one problem ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProblemStatus {
    /// A path that verifies came back within the deadline.
    Solved,
    /// The request's start configuration is in collision or outside the joint limits.
    InvalidStart,
    /// The goal configuration is in collision or outside the joint limits.
    InvalidGoal,
    /// The planner gave up at the deadline.
    OutOfTime,
    /// The planner failed before the deadline, or returned a path that does not verify.
    Failed,
}

impl ProblemStatus {
    /// Whether the problem itself is invalid (start or goal in collision or outside the limits).
    pub fn is_invalid(self) -> bool {
        matches!(self, ProblemStatus::InvalidStart | ProblemStatus::InvalidGoal)
    }
}

/// One problem's outcome; `path` runs from the request's start to its goal over `joint_names`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProblemResult {
    /// The problem's family (its folder name).
    pub family: String,
    /// The problem's index within its family.
    pub index: u32,
    /// Which of the repeated runs (`--runs`), from 0.
    #[serde(default)]
    pub run: u32,
    /// Whether the status is [`ProblemStatus::Solved`].
    pub solved: bool,
    /// How the problem ended.
    pub status: ProblemStatus,
    /// Wall-clock time of the `plan_motion` call, microseconds (absent for invalid problems).
    pub planning_us: Option<f64>,
    /// Names of the joints of `path`, in order.
    pub joint_names: Vec<String>,
    /// The path's waypoints, rad (empty when none came back).
    pub path: Vec<Vec<f64>>,
    /// Joint-space length of `path` (the configuration space's metric).
    pub path_length: Option<f64>,
    /// Whether the independent check of `path` passed (absent when there is no path).
    pub verified: Option<bool>,
    /// What planning cost (samples, segments and configurations checked), when a plan came back.
    /// ([`embodied_planner::motion::MotionStats`] as JSON.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stats: Option<serde_json::Value>,
    /// Why the problem is invalid, failed, or did not verify.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
}

/// Counts and planning-time percentiles of a set of problems (a family or all).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Summary {
    /// The family's name, or `overall`.
    pub name: String,
    /// Problems in the set.
    pub total: usize,
    /// Problems with a valid start and goal.
    pub valid: usize,
    /// Problems with a start or goal in collision or outside the joint limits.
    pub invalid: usize,
    /// Problems solved.
    pub solved: usize,
    /// Problems the planner gave up at the deadline.
    pub out_of_time: usize,
    /// Problems failed before the deadline or with a path that does not verify.
    pub failed: usize,
    /// Percentiles of the planning time of the solved problems, microseconds.
    pub p50_us: Option<f64>,
    /// 95th percentile planning time of the solved problems, µs.
    pub p95_us: Option<f64>,
    /// Longest planning time of the solved problems, µs.
    pub max_us: Option<f64>,
    /// Mean planning time of the solved problems, µs.
    pub mean_us: Option<f64>,
    /// Share of the valid problems solved within 1 ms (0..=1).
    pub within_1ms: Option<f64>,
    /// Median joint-space path length of the solved problems (rad).
    pub median_path_length: Option<f64>,
    /// Mean joint-space path length of the solved problems (rad).
    pub mean_path_length: Option<f64>,
    /// Returned paths that failed the independent check (must be 0).
    pub verification_failures: usize,
    /// Whether every returned path passed the independent check.
    pub all_paths_valid: bool,
}

/// The benchmark's settings, echoed in the report.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MbmSettings {
    /// The robot's URDF file.
    pub urdf: PathBuf,
    /// The robot's SRDF file.
    pub srdf: PathBuf,
    /// Folder of the problem families.
    pub problems: PathBuf,
    /// Planning deadline per problem, ms.
    pub deadline_ms: f64,
    /// Base seed.
    pub seed: u64,
    /// How the planner checked its edges.
    pub edge_check: EdgeCheck,
    /// Collision-checking resolution of sampled edges (rad, largest joint step).
    pub resolution: f64,
    /// Random shortcut attempts after the greedy shortcut pass.
    pub shortcut_attempts: usize,
    /// The least share of the path's length a random shortcut had to gain to be checked
    /// (absent in reports written before it existed: read as 0).
    #[serde(default)]
    pub shortcut_min_gain: f64,
    /// The length above which shortcuts and straight segments were screened by a probe before
    /// their certificate (absent in reports written before it existed, which screened none: read
    /// as infinite; written as `null` when infinite).
    #[serde(default = "no_screen", with = "finite_or_null")]
    pub screen_above: f64,
    /// The planner after the straight segment.
    pub algorithm: PlannerKind,
    /// RRT-Connect's largest step, rad.
    pub rrt_range: f64,
    /// Whether RRT-Connect's sampling was restricted to a dynamic domain around each tree.
    pub dynamic_domain: bool,
    /// Whether RRT-Connect planned one independent group of joints at a time first (absent in
    /// reports written before it existed, which did not: read as false).
    #[serde(default)]
    pub by_groups: bool,
    /// Whether, with more than one thread, a plan by groups searched its legs two at a time
    /// instead of racing seeds (absent in reports written before it existed, which raced: read
    /// as false).
    #[serde(default)]
    pub parallel_legs: bool,
    /// Whether the smaller tree was grown while the other had twice its nodes.
    pub balance: bool,
    /// Whether the goal's tree got retreat chains (absent in reports written before they
    /// existed, which had none: read as false).
    #[serde(default)]
    pub goal_retreat: bool,
    /// How RRT-Connect drew its samples.
    pub sampler: Sampler,
    /// The share of RRT-Connect's samples drawn near a node of the growing tree (absent in
    /// reports written before it existed: read as 0, every sample over the whole box).
    #[serde(default)]
    pub rrt_local_bias: f64,
    /// That share once an attempt has drawn `rrt_late_after` samples (absent in reports written
    /// before it existed: read as 0, with `rrt_late_after` read as never).
    #[serde(default)]
    pub rrt_late_local_bias: f64,
    /// Samples of an attempt before `rrt_late_local_bias` applies (`usize::MAX`: never).
    #[serde(default = "never")]
    pub rrt_late_after: usize,
    /// The half-width of their box around the node, as a share of each joint's sampling width
    /// (absent in reports written before it existed: read as 0).
    #[serde(default)]
    pub rrt_local_span: f64,
    /// The most a joint of those samples is drawn from its node (rad, or m); `None`: no
    /// bound but the span (and in reports written before it existed).
    #[serde(default)]
    pub rrt_local_reach: Option<f64>,
    /// Samples an RRT-Connect attempt could draw before starting again (`None` in reports
    /// written before it was recorded).
    #[serde(default)]
    pub max_samples: Option<usize>,
    /// Attempts after the first (`None` in reports written before it was recorded).
    #[serde(default)]
    pub rrt_restarts: Option<usize>,
    /// The step tree edges were probed at (rad; 0: each certified as added; `None` in reports
    /// written before it was recorded).
    #[serde(default)]
    pub lazy_probe: Option<f64>,
    /// Planners racing per problem.
    pub threads: usize,
    /// Plans per problem (run `r` with base seed `seed + r`).
    #[serde(default = "one")]
    pub runs: usize,
    /// Only the first N problems of each family, when limited.
    #[serde(default)]
    pub limit: Option<usize>,
    /// Only these families, when chosen.
    #[serde(default)]
    pub families: Option<Vec<String>>,
    /// Resolution at which every returned path was re-checked (rad, largest joint step).
    pub verify_resolution: f64,
    /// Self-collision pairs disabled because they touch in every sampled configuration.
    pub always_colliding_disabled: Vec<(String, String)>,
    /// Self-collision pairs disabled because they are proven never to touch within the joint
    /// limits ([`disable_never_colliding`]: a certificate, not sampling).
    pub never_colliding_disabled: Vec<(String, String)>,
}

/// `MbmSettings::rrt_late_after` of a report written before it existed: the first share held
/// throughout.
fn never() -> usize {
    usize::MAX
}

fn one() -> usize {
    1
}

/// `MbmSettings::screen_above` of a report written before it existed: no screen.
fn no_screen() -> f64 {
    f64::INFINITY
}

/// A length that may be infinite, as JSON: a number, or `null` for infinity (JSON has none).
mod finite_or_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        if x.is_finite() { s.serialize_f64(*x) } else { s.serialize_none() }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// The whole benchmark: per-family and overall summaries and every problem with its path.
#[derive(Debug, Clone, Serialize)]
pub struct MbmReport {
    /// The program (version and commit) that made the report.
    pub generator: String,
    /// The share of the problems this report holds (absent: all of them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// The settings the benchmark ran with.
    pub settings: MbmSettings,
    /// One summary per family.
    pub families: Vec<Summary>,
    /// The summary over every problem.
    pub overall: Summary,
    /// Every problem's outcome.
    pub problems: Vec<ProblemResult>,
}

/// One problem found on disk.
#[derive(Debug, Clone)]
pub struct ProblemFiles {
    /// The family (its folder's name).
    pub family: String,
    /// The problem's index in its family.
    pub index: u32,
    /// The planning scene (`sceneNNNN.yaml`).
    pub scene: PathBuf,
    /// The motion plan request (`requestNNNN.yaml`).
    pub request: PathBuf,
}

/// The problems of `args.problems` (its families and limit) in the benchmark's stable order:
/// families sorted by name, problems by index.
pub fn find_problems(args: &MbmArgs) -> Result<Vec<ProblemFiles>, AppError> {
    discover(args)
}

fn from_moveit(e: MoveitError) -> AppError {
    match e {
        MoveitError::Parse { file, line, column, message } => AppError::Parse { file, line, column, message },
        MoveitError::Io { file, source } => AppError::Io { file, source },
        MoveitError::Model(m) => AppError::Model(m),
        other => AppError::Failed(other.to_string()),
    }
}

fn read_dir_sorted(dir: &Path) -> Result<Vec<PathBuf>, AppError> {
    let entries = std::fs::read_dir(dir).map_err(|e| AppError::io(dir, e))?;
    let mut out = Vec::new();
    for entry in entries {
        out.push(entry.map_err(|e| AppError::io(dir, e))?.path());
    }
    out.sort();
    Ok(out)
}

/// `sceneNNNN.yaml` -> `NNNN`.
fn scene_index(path: &Path) -> Option<u32> {
    let name = path.file_name()?.to_str()?;
    let digits = name.strip_prefix("scene")?.strip_suffix(".yaml")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

fn scenes_in(dir: &Path) -> Result<Vec<(u32, PathBuf)>, AppError> {
    let mut scenes: Vec<(u32, PathBuf)> =
        read_dir_sorted(dir)?.into_iter().filter_map(|p| scene_index(&p).map(|i| (i, p))).collect();
    scenes.sort();
    Ok(scenes)
}

/// The family folders under `root`: its sub-folders that hold scenes; else those of
/// `root/problems` (the tarball's layout); else `root` itself as one family.
fn family_dirs(root: &Path) -> Result<Vec<(String, PathBuf)>, AppError> {
    if !root.is_dir() {
        return Err(AppError::Usage(format!("problem folder {} does not exist or is not a folder", root.display())));
    }
    let families_under = |dir: &Path| -> Result<Vec<(String, PathBuf)>, AppError> {
        let mut out = Vec::new();
        for p in read_dir_sorted(dir)? {
            if p.is_dir() && !scenes_in(&p)?.is_empty() {
                let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                out.push((name, p));
            }
        }
        Ok(out)
    };
    let direct = families_under(root)?;
    if !direct.is_empty() {
        return Ok(direct);
    }
    let nested = root.join("problems");
    if nested.is_dir() {
        let deeper = families_under(&nested)?;
        if !deeper.is_empty() {
            return Ok(deeper);
        }
    }
    if !scenes_in(root)?.is_empty() {
        let name = root
            .canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "problems".to_string());
        return Ok(vec![(name, root.to_path_buf())]);
    }
    Err(AppError::Usage(format!(
        "no MotionBenchMaker problems under {}: expected <family>/sceneNNNN.yaml with requestNNNN.yaml \
         (or problems/<family>/...)",
        root.display()
    )))
}

fn discover(args: &MbmArgs) -> Result<Vec<ProblemFiles>, AppError> {
    let mut families = family_dirs(&args.problems)?;
    if let Some(wanted) = &args.families {
        let known: Vec<String> = families.iter().map(|(n, _)| n.clone()).collect();
        for w in wanted {
            if !known.contains(w) {
                return Err(AppError::Usage(format!(
                    "no family `{w}` under {}; families found: {}",
                    args.problems.display(),
                    known.join(", ")
                )));
            }
        }
        families.retain(|(n, _)| wanted.contains(n));
    }
    let mut out = Vec::new();
    for (family, dir) in families {
        let mut scenes = scenes_in(&dir)?;
        if let Some(limit) = args.limit {
            scenes.truncate(limit);
        }
        for (index, scene) in scenes {
            let Some(name) = scene.file_name().and_then(|n| n.to_str()) else { continue };
            let request = dir.join(name.replacen("scene", "request", 1));
            if !request.is_file() {
                return Err(AppError::Failed(format!(
                    "{} has no matching request file {}",
                    scene.display(),
                    request.display()
                )));
            }
            out.push(ProblemFiles { family: family.clone(), index, scene, request });
        }
    }
    Ok(out)
}

/// Why `q` cannot be a start or goal: outside the limits or in collision.
fn invalid_reason(model: &CollisionModel, q: &[f64]) -> Option<String> {
    if let Err(e) = model.robot().check_configuration(q) {
        return Some(e.to_string());
    }
    model.first_collision(q).map(|c| format!("in collision: {c}"))
}

fn path_length(space: &ConfigSpace, path: &[Vec<f64>]) -> f64 {
    path.windows(2).map(|w| space.distance(&w[0], &w[1])).sum()
}

/// Check a returned path independently of the planner: end points at the request's start and
/// goal, every waypoint and every segment collision-free at [`VERIFY_RESOLUTION`].
fn check_path(model: &CollisionModel, path: &[Vec<f64>], start: &[f64], goal: &[f64]) -> Result<(), String> {
    let space = model.robot().config_space();
    let (Some(first), Some(last)) = (path.first(), path.last()) else {
        return Err("the planner returned an empty path".to_string());
    };
    if let Some(bad) = path.iter().position(|q| q.len() != start.len()) {
        return Err(format!("waypoint {bad} has {} values, expected {}", path[bad].len(), start.len()));
    }
    let d_start = space.distance(first, start);
    if d_start.is_nan() || d_start > ENDPOINT_TOLERANCE {
        return Err(format!("the path starts {d_start:.3e} rad away from the request's start"));
    }
    let d_goal = space.distance(last, goal);
    if d_goal.is_nan() || d_goal > ENDPOINT_TOLERANCE {
        return Err(format!("the path ends {d_goal:.3e} rad away from the request's goal"));
    }
    Verifier::sampled(VERIFY_RESOLUTION).verify_path(model, path).map_err(|v| format!("verification failed: {v}"))
}

/// A per-problem seed: the base seed mixed with the family and index (SplitMix64 finaliser), so
/// that a problem plans the same whatever subset of the benchmark is run.
fn problem_seed(base: u64, family: &str, index: u32) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in family.bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    let mut z = base ^ h ^ (u64::from(index) << 1);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Random configurations sampled to find self-collision pairs that are always in contact.
pub const ALWAYS_COLLIDING_SAMPLES: usize = 2000;

pub(crate) struct Loaded {
    pub(crate) robot: Robot,
    pub(crate) srdf: Srdf,
    always_colliding: Vec<(String, String)>,
    never_colliding: Vec<(String, String)>,
}

/// Pairs moved relative to each other by at most this many joints are tried for a proof that
/// they never touch.
const NEVER_COLLIDING_DOFS: usize = 2;
/// Pair checks spent at most on each such proof.
const NEVER_COLLIDING_CHECKS: usize = 200_000;

/// Load the robot once. Self-collision pairs in contact in every sampled configuration are
/// disabled, as MoveIt's setup assistant does: a spherized model's conservative spheres can make
/// neighbouring links overlap everywhere (the spherized UR5's `wrist_2_link` and `fts_robotside`,
/// which the SRDF written for the mesh model does not disable), which would make every
/// configuration invalid. Pairs proven never to touch are disabled too (see
/// [`disable_never_colliding`]).
pub(crate) fn load_robot(args: &MbmArgs) -> Result<Loaded, AppError> {
    let mut robot = load_urdf(&args.urdf, Some(&args.srdf))?;
    let srdf = load_srdf(&args.srdf)?;
    let always = disable_always_colliding(&mut robot, ALWAYS_COLLIDING_SAMPLES, 0x5eed);
    let never = disable_never_colliding(&mut robot, NEVER_COLLIDING_DOFS, NEVER_COLLIDING_CHECKS);
    let links = robot.links();
    let names = |pairs: &[(usize, usize)]| -> Vec<(String, String)> {
        pairs.iter().map(|&(a, b)| (links[a].name.clone(), links[b].name.clone())).collect()
    };
    let (always_colliding, never_colliding) = (names(&always), names(&never));
    Ok(Loaded { robot, srdf, always_colliding, never_colliding })
}

/// One loaded MotionBenchMaker problem: the planning arm among the scene's obstacles.
pub struct MbmProblem {
    /// `family/index`.
    pub name: String,
    /// The planning arm among the scene's obstacles.
    pub model: CollisionModel,
    /// Start configuration, rad.
    pub start: Vec<f64>,
    /// Goal configuration, rad.
    pub goal: Vec<f64>,
}

/// Up to `n` problems spread evenly over all problems of `args` (every family, in order), with
/// the problems whose start or goal is invalid left out.
pub fn sample_problems(args: &MbmArgs, n: usize) -> Result<Vec<MbmProblem>, AppError> {
    let loaded = load_robot(args)?;
    let files = discover(args)?;
    let total = files.len();
    let mut picked: Vec<usize> = (0..n.min(total)).map(|i| i * total / n.min(total).max(1)).collect();
    picked.dedup();
    let mut out = Vec::new();
    for i in picked {
        let p = &files[i];
        let scene = load_scene(&p.scene).map_err(from_moveit)?;
        let request = load_request(&p.request).map_err(from_moveit)?;
        scene.check_frames(&loaded.robot).map_err(from_moveit)?;
        let mut robot = loaded.robot.clone();
        scene.apply_allowed_collisions(&mut robot);
        let resolved = request.resolve(&robot, &loaded.srdf, scene.robot_state.as_ref()).map_err(from_moveit)?;
        let arm = resolved.planning_robot(&robot)?;
        let model = CollisionModel::new(&arm, scene.environment());
        if invalid_reason(&model, &resolved.start).is_some() || invalid_reason(&model, &resolved.goal).is_some() {
            continue;
        }
        out.push(MbmProblem {
            name: format!("{}/{:04}", p.family, p.index),
            model,
            start: resolved.start.clone(),
            goal: resolved.goal.clone(),
        });
    }
    Ok(out)
}

/// Warnings of the problems' files, each message written to standard error once (with the
/// first file and place it came from), then how many more problems gave it.
#[derive(Default)]
struct Warned {
    /// Each message, in the order first seen, with how many times it came.
    seen: Vec<(String, usize)>,
    /// Nothing written (the same problems' second reading, see [`versus`]).
    silent: bool,
}

impl Warned {
    fn note(&mut self, warnings: &[Warning]) {
        for w in warnings {
            match self.seen.iter_mut().find(|(m, _)| *m == w.message) {
                Some((_, n)) => *n += 1,
                None => {
                    if !self.silent {
                        eprintln!("{w}");
                    }
                    self.seen.push((w.message.clone(), 1));
                }
            }
        }
    }

    fn finish(&self) {
        if self.silent {
            return;
        }
        for (message, n) in self.seen.iter().filter(|(_, n)| *n > 1) {
            eprintln!("warning: {} more problems: {message}", n - 1);
        }
    }
}

fn run_problem(
    args: &MbmArgs,
    loaded: &Loaded,
    p: &ProblemFiles,
    run: u32,
    warned: &mut Warned,
) -> Result<ProblemResult, AppError> {
    let scene = load_scene(&p.scene).map_err(from_moveit)?;
    let request = load_request(&p.request).map_err(from_moveit)?;
    scene.check_frames(&loaded.robot).map_err(from_moveit)?;
    // The scene's allowed collision matrix amends the SRDF's disabled pairs, as in MoveIt.
    let mut robot = loaded.robot.clone();
    scene.apply_allowed_collisions(&mut robot);
    let resolved = request.resolve(&robot, &loaded.srdf, scene.robot_state.as_ref()).map_err(from_moveit)?;
    if run == 0 {
        warned.note(&resolved.warnings);
    }
    let arm = resolved.planning_robot(&robot)?;
    let model = CollisionModel::new(&arm, scene.environment());
    let mut result = ProblemResult {
        family: p.family.clone(),
        index: p.index,
        run,
        solved: false,
        status: ProblemStatus::Failed,
        planning_us: None,
        joint_names: resolved.joint_names.clone(),
        path: Vec::new(),
        path_length: None,
        verified: None,
        stats: None,
        message: None,
    };
    if let Some(why) = invalid_reason(&model, &resolved.start) {
        result.status = ProblemStatus::InvalidStart;
        result.message = Some(format!("start {why}"));
        return Ok(result);
    }
    // A link-pose goal (no joint goal) is planned to the configurations inverse kinematics
    // finds for it, within the timed planning; its path must end on the goal.
    let pose_goal = resolved.goal.is_empty();
    if !pose_goal && let Some(why) = invalid_reason(&model, &resolved.goal) {
        result.status = ProblemStatus::InvalidGoal;
        result.message = Some(format!("goal {why}"));
        return Ok(result);
    }
    let budget = Duration::from_secs_f64(args.deadline_ms.max(0.0) / 1000.0);
    let settings = MotionSettings {
        seed: problem_seed(args.seed.wrapping_add(u64::from(run)), &p.family, p.index),
        resolution: args.resolution,
        edge_check: args.edge_check,
        deadline: Deadline::after(budget),
        shortcut_attempts: args.shortcut_attempts,
        shortcut_min_gain: args.shortcut_min_gain,
        screen_above: args.screen_above,
        planner: args.algorithm,
        rrt_range: args.rrt_range,
        rrt_dynamic_domain: args.dynamic_domain,
        rrt_by_groups: args.by_groups,
        parallel_legs: args.parallel_legs,
        rrt_balance: args.balance,
        rrt_goal_retreat: args.goal_retreat,
        sampler: args.sampler,
        rrt_local_bias: args.rrt_local_bias,
        rrt_late_local_bias: args.rrt_late_local_bias,
        rrt_late_after: args.rrt_late_after,
        rrt_local_span: args.rrt_local_span,
        rrt_local_reach: args.rrt_local_reach,
        max_samples: args.max_samples,
        rrt_restarts: args.rrt_restarts,
        lazy_probe: args.lazy_probe,
        racers: args.threads.max(1),
        ..MotionSettings::default()
    };
    let problem = pose_goal.then(|| MoveitProblem { resolved: resolved.clone(), model: model.clone() });
    let t0 = Instant::now();
    let outcome = match &problem {
        Some(problem) => goal_configurations(problem, &settings)
            .and_then(|goals| plan_motion(&model, &resolved.start, &Goal::AnyOf(goals), &settings)),
        None => plan_motion(&model, &resolved.start, &Goal::Configuration(resolved.goal.clone()), &settings),
    };
    let elapsed = t0.elapsed();
    result.planning_us = Some((elapsed.as_secs_f64() * 1e7).round() / 10.0);
    match outcome {
        Ok(plan) => {
            let space = arm.config_space();
            result.path_length = Some(path_length(&space, &plan.path));
            result.stats = serde_json::to_value(&plan.stats).ok();
            let goal_end = match (&problem, plan.path.last()) {
                (Some(problem), Some(last)) => match goal_miss(problem, last) {
                    Some(why) => Err(format!("the path ends off the request's goal: {why}")),
                    None => Ok(last.clone()),
                },
                _ => Ok(resolved.goal.clone()),
            };
            let checked = goal_end.and_then(|end| check_path(&model, &plan.path, &resolved.start, &end));
            match checked {
                Ok(()) => {
                    result.solved = true;
                    result.status = ProblemStatus::Solved;
                    result.verified = Some(true);
                }
                Err(why) => {
                    result.verified = Some(false);
                    result.message = Some(why);
                }
            }
            result.path = plan.path;
        }
        Err(e) => {
            result.status = match e {
                PlanError::OutOfTime { .. } => ProblemStatus::OutOfTime,
                _ => ProblemStatus::Failed,
            };
            result.message = Some(e.to_string());
        }
    }
    Ok(result)
}

/// Run the benchmark. `on_progress(done, total)` is called once before the first problem and
/// after each one. Errors are for unreadable or malformed inputs; planner failures are results.
pub fn run_mbm(args: &MbmArgs, on_progress: &mut dyn FnMut(usize, usize)) -> Result<MbmReport, AppError> {
    run_mbm_to(args, on_progress, None)
}

/// Kind of the batch results files of `bench mbm --jsonl`.
pub const MBM_BATCH_KIND: &str = "bench-mbm";

/// [`run_mbm`], also writing the results as JSON Lines to `jsonl` as they come: a
/// [`Header`] line, then one line per problem and run (the [`ProblemResult`] with the
/// problem's ordinal `i` in the whole sorted set).
pub fn run_mbm_to(
    args: &MbmArgs,
    on_progress: &mut dyn FnMut(usize, usize),
    mut jsonl: Option<&mut JsonlWriter>,
) -> Result<MbmReport, AppError> {
    check_numbers(args)?;
    let loaded = load_robot(args)?;
    let problems = discover(args)?;
    let settings = settings_of(args, &loaded);
    if let Some(out) = jsonl.as_deref_mut() {
        out.line(&batch_header(MBM_BATCH_KIND, args.shard, &problem_names(&problems), args.runs, &settings)?)?;
    }
    let mine: Vec<(usize, &ProblemFiles)> = problems.iter().enumerate().filter(|(i, _)| args.shard.holds(*i)).collect();
    let total = mine.len() * args.runs;
    on_progress(0, total);
    let mut results = Vec::with_capacity(total);
    let mut warned = Warned::default();
    for (i, p) in mine {
        for run in 0..args.runs {
            let result = run_problem(args, &loaded, p, run as u32, &mut warned)?;
            if let Some(out) = jsonl.as_deref_mut() {
                out.line(&with_ordinal(i, &result)?)?;
            }
            results.push(result);
            on_progress(results.len(), total);
        }
    }
    warned.finish();
    let shard = (args.shard != Shard::ALL).then_some(args.shard);
    Ok(assemble(crate::generator(), shard, settings, results))
}

/// The deadline, resolution and runs of `args` are usable: an error names the first that is not.
fn check_numbers(args: &MbmArgs) -> Result<(), AppError> {
    if !(args.deadline_ms > 0.0 && args.deadline_ms.is_finite()) {
        return Err(AppError::Usage(format!("--deadline-ms must be a positive number, got {}", args.deadline_ms)));
    }
    if !(args.resolution > 0.0 && args.resolution.is_finite()) {
        return Err(AppError::Usage(format!("the resolution must be a positive number, got {}", args.resolution)));
    }
    if args.runs == 0 || args.runs > u32::MAX as usize {
        return Err(AppError::Usage(format!("--runs must be at least 1, got {}", args.runs)));
    }
    Ok(())
}

/// `family/NNNN` of every problem, in the batch's order.
fn problem_names(problems: &[ProblemFiles]) -> Vec<String> {
    problems.iter().map(|p| format!("{}/{:04}", p.family, p.index)).collect()
}

/// The header line of a batch results file.
pub fn batch_header<S: Serialize>(
    kind: &str,
    shard: Shard,
    names: &[String],
    runs: usize,
    settings: &S,
) -> Result<Header, AppError> {
    Ok(Header {
        format: BATCH_FORMAT.to_string(),
        kind: kind.to_string(),
        generator: crate::generator(),
        machine: Machine::this(),
        date: crate::batch::utc_now(),
        shard,
        problems_total: names.len(),
        problem_set: crate::batch::problem_set_hash(names.iter().map(String::as_str)),
        runs,
        settings: serde_json::to_value(settings).map_err(|e| AppError::Failed(e.to_string()))?,
    })
}

/// A result as a JSON object with the problem's ordinal `i` first.
pub fn with_ordinal<T: Serialize>(i: usize, result: &T) -> Result<serde_json::Value, AppError> {
    let value = serde_json::to_value(result).map_err(|e| AppError::Failed(e.to_string()))?;
    let mut map = serde_json::Map::new();
    map.insert("i".to_string(), serde_json::Value::from(i));
    if let serde_json::Value::Object(fields) = value {
        map.extend(fields);
    }
    Ok(serde_json::Value::Object(map))
}

fn settings_of(args: &MbmArgs, loaded: &Loaded) -> MbmSettings {
    MbmSettings {
        urdf: args.urdf.clone(),
        srdf: args.srdf.clone(),
        problems: args.problems.clone(),
        deadline_ms: args.deadline_ms,
        seed: args.seed,
        edge_check: args.edge_check,
        resolution: args.resolution,
        shortcut_attempts: args.shortcut_attempts,
        shortcut_min_gain: args.shortcut_min_gain,
        screen_above: args.screen_above,
        algorithm: args.algorithm,
        rrt_range: args.rrt_range,
        dynamic_domain: args.dynamic_domain,
        by_groups: args.by_groups,
        parallel_legs: args.parallel_legs,
        balance: args.balance,
        goal_retreat: args.goal_retreat,
        sampler: args.sampler,
        rrt_local_bias: args.rrt_local_bias,
        rrt_late_local_bias: args.rrt_late_local_bias,
        rrt_late_after: args.rrt_late_after,
        rrt_local_span: args.rrt_local_span,
        rrt_local_reach: args.rrt_local_reach.is_finite().then_some(args.rrt_local_reach),
        max_samples: Some(args.max_samples),
        rrt_restarts: Some(args.rrt_restarts),
        lazy_probe: Some(args.lazy_probe),
        threads: args.threads.max(1),
        runs: args.runs,
        limit: args.limit,
        families: args.families.clone(),
        verify_resolution: VERIFY_RESOLUTION,
        always_colliding_disabled: loaded.always_colliding.clone(),
        never_colliding_disabled: loaded.never_colliding.clone(),
    }
}

/// The report of a set of results (in the batch's order): per-family summaries in order of
/// first appearance, and the overall one.
fn assemble(generator: String, shard: Option<Shard>, settings: MbmSettings, results: Vec<ProblemResult>) -> MbmReport {
    let mut by_family: BTreeMap<&str, Vec<&ProblemResult>> = BTreeMap::new();
    let mut order: Vec<&str> = Vec::new();
    for r in &results {
        if !by_family.contains_key(r.family.as_str()) {
            order.push(&r.family);
        }
        by_family.entry(&r.family).or_default().push(r);
    }
    let families = order.iter().map(|f| summarize(f, by_family.get(f).map(Vec::as_slice).unwrap_or(&[]))).collect();
    let all: Vec<&ProblemResult> = results.iter().collect();
    let overall = summarize("overall", &all);
    MbmReport { generator, shard, settings, families, overall, problems: results }
}

/// The report of the whole benchmark from the checked shards of `bench mbm --shard K/N
/// --jsonl` (see [`crate::batch::read_shards`]): the report one unsharded run gives.
pub fn merge_mbm(merged: MergedShards) -> Result<MbmReport, AppError> {
    let MergedShards { header, lines } = merged;
    if header.kind != MBM_BATCH_KIND {
        return Err(AppError::Usage(format!("these are `{}` results, not `{MBM_BATCH_KIND}`", header.kind)));
    }
    let settings: MbmSettings = serde_json::from_value(header.settings.clone())
        .map_err(|e| AppError::Usage(format!("the header's settings are not bench mbm settings: {e}")))?;
    let mut results = Vec::with_capacity(lines.len());
    for l in lines {
        let r: ProblemResult = serde_json::from_value(l.value).map_err(|e| AppError::Parse {
            file: l.file.clone(),
            line: l.line,
            column: 1,
            message: format!("expected a bench mbm problem result: {e}"),
        })?;
        if r.run as usize != l.run {
            return Err(AppError::Parse {
                file: l.file,
                line: l.line,
                column: 1,
                message: format!("run {} does not match the line's run {}", r.run, l.run),
            });
        }
        results.push(r);
    }
    Ok(assemble(header.generator, None, settings, results))
}

/// The `q`-quantile (0..=1) of sorted values, nearest rank.
fn percentile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q * sorted.len() as f64).ceil().max(1.0) as usize;
    Some(sorted[rank.min(sorted.len()) - 1])
}

fn summarize(name: &str, results: &[&ProblemResult]) -> Summary {
    let solved: Vec<&&ProblemResult> = results.iter().filter(|r| r.solved).collect();
    let mut times: Vec<f64> = solved.iter().filter_map(|r| r.planning_us).collect();
    times.sort_by(f64::total_cmp);
    let mut lengths: Vec<f64> = solved.iter().filter_map(|r| r.path_length).collect();
    lengths.sort_by(f64::total_cmp);
    let mean = |v: &[f64]| if v.is_empty() { None } else { Some(v.iter().sum::<f64>() / v.len() as f64) };
    let invalid = results.iter().filter(|r| r.status.is_invalid()).count();
    let verification_failures = results.iter().filter(|r| r.verified == Some(false)).count();
    let valid = results.len() - invalid;
    Summary {
        name: name.to_string(),
        total: results.len(),
        valid,
        invalid,
        solved: solved.len(),
        out_of_time: results.iter().filter(|r| r.status == ProblemStatus::OutOfTime).count(),
        failed: results.iter().filter(|r| r.status == ProblemStatus::Failed).count(),
        p50_us: percentile(&times, 0.5),
        p95_us: percentile(&times, 0.95),
        max_us: times.last().copied(),
        mean_us: mean(&times),
        within_1ms: (valid > 0).then(|| times.iter().filter(|&&t| t <= 1000.0).count() as f64 / valid as f64),
        median_path_length: percentile(&lengths, 0.5),
        mean_path_length: mean(&lengths),
        verification_failures,
        all_paths_valid: verification_failures == 0,
    }
}

/// The `--out` file: every problem with its joint names and path, for an independent checker.
#[derive(Debug, Clone, Serialize)]
pub struct PathsFile<'a> {
    /// Every problem's outcome.
    pub problems: &'a [ProblemResult],
}

impl MbmReport {
    /// What `--out` writes: `{"problems": [{family, index, solved, planning_us, joint_names,
    /// path, status, verified, ...}]}`.
    pub fn paths_file(&self) -> PathsFile<'_> {
        PathsFile { problems: &self.problems }
    }
}

fn fmt_us(v: Option<f64>) -> String {
    match v {
        None => "-".to_string(),
        Some(us) if us < 10_000.0 => format!("{us:.0}"),
        Some(us) => format!("{:.0}k", us / 1000.0),
    }
}

/// The attempt length, restarts and edge-probe step of RRT-Connect when any differs from the
/// planner's defaults (`MotionSettings`), for the table's first line; empty otherwise and for
/// reports that did not record them.
fn attempts_note(s: &MbmSettings) -> String {
    let d = MotionSettings::default();
    let mut parts = Vec::new();
    if let (Some(n), Some(r)) = (s.max_samples, s.rrt_restarts)
        && (n != d.max_samples || r != d.rrt_restarts)
    {
        parts.push(format!("attempts of {n} samples, {r} restart{}", if r == 1 { "" } else { "s" }));
    }
    if let Some(step) = s.lazy_probe.filter(|&p| p != d.lazy_probe) {
        parts.push(if step == 0.0 {
            "tree edges certified as added".to_string()
        } else {
            format!("tree edges probed every {step} rad")
        });
    }
    if s.algorithm != PlannerKind::RrtConnect || parts.is_empty() {
        String::new()
    } else {
        format!(", {}", parts.join(", "))
    }
}

/// A plain-text table for the terminal: one row per family and one for all.
pub fn render_table(report: &MbmReport) -> String {
    let header = [
        "family",
        "solved",
        "invalid",
        "timeout",
        "failed",
        "p50 us",
        "p95 us",
        "max us",
        "<=1 ms",
        "path len",
        "bad paths",
    ];
    let row = |s: &Summary| -> Vec<String> {
        vec![
            s.name.clone(),
            format!("{}/{}", s.solved, s.valid),
            s.invalid.to_string(),
            s.out_of_time.to_string(),
            s.failed.to_string(),
            fmt_us(s.p50_us),
            fmt_us(s.p95_us),
            fmt_us(s.max_us),
            s.within_1ms.map_or("-".to_string(), |w| format!("{:.1}%", 100.0 * w)),
            s.median_path_length.map_or("-".to_string(), |l| format!("{l:.2}")),
            s.verification_failures.to_string(),
        ]
    };
    let mut rows: Vec<Vec<String>> = report.families.iter().map(row).collect();
    rows.push(row(&report.overall));
    let edges = match report.settings.edge_check {
        EdgeCheck::Certified { tolerance } => format!("edges certified (tolerance {tolerance} m)"),
        EdgeCheck::Sampled => format!("edges sampled at {} rad", report.settings.resolution),
    };
    let mut out = format!(
        "MotionBenchMaker: deadline {} ms, seed {}, {edges}, paths re-checked at {} rad, {}{}{} ({} thread{}){}{}\n",
        report.settings.deadline_ms,
        report.settings.seed,
        report.settings.verify_resolution,
        report.settings.algorithm,
        if report.settings.algorithm == PlannerKind::RrtConnect && report.settings.rrt_local_bias > 0.0 {
            let late = match report.settings.rrt_late_after.checked_add(1) {
                Some(from) => format!(
                    ", {} from sample {from} of an attempt{}",
                    report.settings.rrt_late_local_bias,
                    if report.settings.goal_retreat { ", with goal retreats" } else { "" }
                ),
                None => String::new(),
            };
            let reach = report.settings.rrt_local_reach.map(|r| format!(", at most {r} rad")).unwrap_or_default();
            format!(
                " with {} of its samples near the growing tree (within {:.3} of each joint's width{reach}){late}",
                report.settings.rrt_local_bias, report.settings.rrt_local_span
            )
        } else {
            String::new()
        },
        attempts_note(&report.settings),
        report.settings.threads,
        if report.settings.threads == 1 { "" } else { "s" },
        if report.settings.runs > 1 { format!(", {} runs per problem", report.settings.runs) } else { String::new() },
        report.shard.map_or(String::new(), |s| format!(", shard {s}")),
    );
    out.push_str(&aligned(&header, &rows));
    out.push_str(
        "solved = solved/valid problems; times are wall-clock plan_motion calls of solved problems; \
         <=1 ms = share of valid problems solved within 1 ms; path len = median\n",
    );
    let unsolved: Vec<String> = report
        .problems
        .iter()
        .filter(|p| !p.solved && !p.status.is_invalid())
        .map(|p| {
            if report.settings.runs > 1 {
                format!("{}#{} run {}", p.family, p.index, p.run)
            } else {
                format!("{}#{}", p.family, p.index)
            }
        })
        .collect();
    if !unsolved.is_empty() {
        out.push_str(&format!("unsolved: {}\n", unsolved.join(", ")));
    }
    out
}

/// `header` and `rows` in columns, the first left-aligned and the others right-aligned, with a
/// rule above the last row (the overall one).
pub(crate) fn aligned(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = header.iter().map(|h| h.len()).collect();
    for r in rows {
        for (w, c) in widths.iter_mut().zip(r) {
            *w = (*w).max(c.len());
        }
    }
    let line = |cells: &[String]| -> String {
        let mut s = String::new();
        for (i, (c, w)) in cells.iter().zip(&widths).enumerate() {
            if i == 0 {
                s.push_str(&format!("{c:<w$}"));
            } else {
                s.push_str(&format!("  {c:>w$}"));
            }
        }
        s.trim_end().to_string() + "\n"
    };
    let mut out = line(&header.iter().map(|h| h.to_string()).collect::<Vec<_>>());
    for (i, r) in rows.iter().enumerate() {
        if i + 1 == rows.len() {
            out.push_str(&"-".repeat(widths.iter().sum::<usize>() + 2 * widths.len().saturating_sub(1)));
            out.push('\n');
        }
        out.push_str(&line(r));
    }
    out
}
