//! `embodied plan --urdf U --srdf S --scene SCENE.yaml --request REQUEST.yaml` and
//! `embodied verify --urdf U [--srdf S] [--scene SCENE.yaml] --trajectory T.yaml`: MoveIt
//! problems in, `trajectory_msgs/JointTrajectory` out and in. The work is done by
//! [`embodied_planner::moveit`]; this module reads the files, prints and maps errors.

use std::path::{Path, PathBuf};
use std::time::Duration;

use embodied_models::formats::joint_limits::load_joint_limits;
use embodied_models::formats::load_description;
use embodied_models::urdf::UrdfOptions;
use embodied_models::{Environment, Robot};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::MotionSettings;
use embodied_planner::moveit::{
    MoveitError, load_joint_trajectory, load_request, load_scene, moveit_problem, plan_request, to_joint_trajectory,
    trajectory_problem,
};
use embodied_planner::verify::Verifier;

use crate::AppError;
use crate::plan::{AgentPlan, NamedHash, PLAN_FORMAT, PlanFile, robot_hash};

/// Output format of `plan`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlanFormat {
    /// `embodied-plan/1` JSON.
    Embodied,
    /// `trajectory_msgs/JointTrajectory`, JSON if the file ends in `.json`, else YAML.
    JointTrajectory,
}

/// Map a MoveIt/YAML reader error to the CLI's.
pub fn from_moveit(e: MoveitError) -> AppError {
    match e {
        MoveitError::Parse { file, line, column, message } => AppError::Parse { file, line, column, message },
        MoveitError::Io { file, source } => AppError::Io { file, source },
        MoveitError::Model(m) => AppError::Model(m),
        other => AppError::Failed(other.to_string()),
    }
}

/// The robot of a MoveIt problem: URDF, SRDF, and `joint_limits.yaml` if given. Warnings go
/// to standard error.
pub fn load_moveit_robot(
    urdf: &Path,
    srdf: Option<&Path>,
    limits: Option<&Path>,
) -> Result<(Robot, Option<embodied_models::srdf::Srdf>), AppError> {
    let d = load_description(urdf, srdf, &UrdfOptions::default())?;
    for w in &d.warnings {
        eprintln!("{w}");
    }
    let mut robot = d.robot;
    if let Some(l) = limits {
        load_joint_limits(l).and_then(|f| f.apply(&mut robot)).map_err(from_moveit)?;
    }
    Ok((robot, d.srdf))
}

/// What `embodied plan` was asked for a MoveIt request.
#[derive(Debug, Clone)]
pub struct MoveitPlanArgs {
    /// The robot's URDF file.
    pub urdf: PathBuf,
    /// The robot's SRDF file.
    pub srdf: PathBuf,
    /// The MoveIt planning scene file (YAML).
    pub scene: PathBuf,
    /// The MoveIt motion plan request file (YAML).
    pub request: PathBuf,
    /// An optional `joint_limits.yaml` applied to the robot.
    pub limits: Option<PathBuf>,
    /// Deadline in milliseconds; default: the request's `allowed_planning_time`, else 5 s.
    pub deadline_ms: Option<f64>,
}

/// Plan a MoveIt request and render it in `format`; returns the text and a one-line summary.
pub fn plan_moveit(
    args: &MoveitPlanArgs,
    format: PlanFormat,
    out: Option<&Path>,
) -> Result<(String, String), AppError> {
    let (robot, srdf) = load_moveit_robot(&args.urdf, Some(&args.srdf), args.limits.as_deref())?;
    let srdf = srdf.ok_or_else(|| AppError::Usage("--srdf is needed to resolve the request's group".into()))?;
    let scene = load_scene(&args.scene).map_err(from_moveit)?;
    let request = load_request(&args.request).map_err(from_moveit)?;
    let problem = moveit_problem(&robot, &srdf, &scene, &request).map_err(from_moveit)?;
    for w in &problem.resolved.warnings {
        eprintln!("{w}");
    }
    let seconds = match args.deadline_ms {
        Some(ms) if ms.is_finite() && ms >= 0.0 => ms / 1000.0,
        Some(ms) => return Err(AppError::Usage(format!("--deadline-ms must be a non-negative number, got {ms}"))),
        None => request.allowed_planning_time.filter(|t| t.is_finite() && *t > 0.0).unwrap_or(5.0),
    };
    let settings =
        MotionSettings { deadline: Deadline::after(Duration::from_secs_f64(seconds)), ..MotionSettings::default() };
    let plan = plan_request(&problem, &settings)
        .map_err(|e| AppError::Failed(format!("{}: group `{}`: {e}", args.request.display(), request.group_name)))?;
    // The certified checker, not the planner, says whether the plan may leave.
    let report = Verifier::default().check_trajectory(&problem.model, &plan.trajectory, &[]);
    if !report.certified {
        return Err(AppError::Failed(format!("plan rejected by the certified checker: {:?}", report.findings())));
    }
    let summary = format!(
        "group `{}`: {} waypoints, {:.3} s of motion, certified clearance {:.4} m",
        request.group_name,
        plan.path.len(),
        plan.trajectory.duration(),
        report.collision.certified_clearance_m
    );
    let text = match format {
        PlanFormat::JointTrajectory => {
            to_joint_trajectory(&plan.trajectory).to_text_for(out.unwrap_or_else(|| Path::new("-.yaml")))
        }
        PlanFormat::Embodied => {
            let arm = problem.model.robot();
            let file = PlanFile {
                format: PLAN_FORMAT.to_string(),
                generator: Some(crate::generator()),
                scenario: NamedHash { name: args.request.display().to_string(), hash: String::new() },
                plans: vec![AgentPlan {
                    agent: request.group_name.clone(),
                    robot: NamedHash { name: arm.name().to_string(), hash: robot_hash(arm) },
                    joint_names: arm.joint_names(),
                    path: plan.path.clone(),
                    trajectory: plan.trajectory.clone(),
                    stats: serde_json::to_value(&plan.stats).map_err(|e| AppError::Failed(e.to_string()))?,
                    closed_chain: Vec::new(),
                }],
                together: Vec::new(),
            };
            serde_json::to_string_pretty(&file).map_err(|e| AppError::Failed(e.to_string()))?
        }
    };
    Ok((text, summary))
}

/// A one-agent scenario plan as a JointTrajectory (JSON or YAML by `out`'s extension).
pub fn plan_file_as_joint_trajectory(plan: &PlanFile, out: Option<&Path>) -> Result<String, AppError> {
    match plan.plans.as_slice() {
        [one] => Ok(to_joint_trajectory(&one.trajectory).to_text_for(out.unwrap_or_else(|| Path::new("-.yaml")))),
        many => Err(AppError::Usage(format!(
            "--format joint-trajectory holds one robot's joints; this plan has {} agents (use --format embodied)",
            many.len()
        ))),
    }
}

/// `embodied verify --urdf U [--srdf S] [--scene SCENE] --trajectory T`: certify a
/// JointTrajectory or print its first violation; returns whether it is certified.
pub fn verify_joint_trajectory(
    urdf: &Path,
    srdf: Option<&Path>,
    scene: Option<&Path>,
    limits: Option<&Path>,
    trajectory: &Path,
    json: bool,
    max_evaluations: Option<usize>,
) -> Result<bool, AppError> {
    let (robot, _) = load_moveit_robot(urdf, srdf, limits)?;
    let scene = scene.map(load_scene).transpose().map_err(from_moveit)?;
    if let Some(s) = &scene {
        s.check_frames(&robot).map_err(from_moveit)?;
    }
    let mut robot = robot;
    if let Some(s) = &scene {
        s.apply_allowed_collisions(&mut robot);
    }
    let env = scene.as_ref().map_or_else(Environment::new, |s| s.environment());
    let located = load_joint_trajectory(trajectory).map_err(from_moveit)?;
    let state = scene.as_ref().and_then(|s| s.robot_state.as_ref());
    let problem = trajectory_problem(&robot, state, env, &located.trajectory, trajectory).map_err(from_moveit)?;
    let settings = embodied_planner::verify::CheckSettings { max_evaluations, ..Default::default() };
    let report = Verifier::default().with_settings(settings).check_trajectory(&problem.model, &problem.trajectory, &[]);
    if json {
        crate::outln!("{}", serde_json::to_string(&report).map_err(|e| AppError::Failed(e.to_string()))?);
    } else {
        crate::outln!(
            "{}: {} points, {:.3} s, joints {}",
            trajectory.display(),
            problem.trajectory.t.len(),
            problem.trajectory.duration(),
            problem.trajectory.joint_names.join(", ")
        );
        crate::outln!(
            "  limits: {}  collision: {} ({} of {} segments certified, certified clearance {:.4} m)",
            if report.limits.ok { "ok" } else { "VIOLATED" },
            if report.collision.ok { "ok" } else { "VIOLATED" },
            report.collision.certified_segments,
            report.collision.segments,
            report.collision.certified_clearance_m
        );
        for f in report.findings() {
            crate::outln!("  first violation: {f}");
        }
        crate::outln!("certified: {}", if report.certified { "yes" } else { "no" });
    }
    Ok(report.certified)
}
