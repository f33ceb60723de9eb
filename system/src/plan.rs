//! `embodied plan`: offline plan generation for every agent of a scenario that has a goal.
//!
//! The plan file (JSON) holds, per agent, the joint names, the timed trajectory
//! (`t`, `q`, `qd` sampled at the control step), the joint-space path, the robot and the
//! scenario it is for (name + SHA-256 of the file) and the planner's statistics.

use std::time::Duration;

use embodied_models::Robot;
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_planner::carry::{ClosedChainSpan, plan_carry};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{CERTIFY_TOLERANCE, EdgeCheck, Goal, MotionSettings, MotionStats, plan_motion};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use embodied_planner::verify::Verifier;
use serde::{Deserialize, Serialize};

use crate::SystemError;
use crate::scenario::{GoalSpec, Scenario};

/// Format tag of plan files.
pub const PLAN_FORMAT: &str = "embodied-plan/1";

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
/// A name and the SHA-256 of what it names (a robot's kinematic description, a scenario).
pub struct NamedHash {
    /// The name.
    pub name: String,
    /// The SHA-256, hex.
    pub hash: String,
}

/// One agent's plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AgentPlan {
    /// The agent's name.
    pub agent: String,
    /// The agent's robot and the hash of its kinematic description.
    pub robot: NamedHash,
    /// Names of the degrees of freedom, in the order of the values in `path`.
    pub joint_names: Vec<String>,
    /// The planned waypoints (rad or m).
    pub path: Vec<Vec<f64>>,
    /// The timed trajectory along `path`.
    pub trajectory: Trajectory,
    /// What planning cost (the planner's statistics, as JSON).
    pub stats: serde_json::Value,
    /// Spans where two end effectors hold one object (two-arm plans); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub closed_chain: Vec<ClosedChainSpan>,
}

/// A plan file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlanFile {
    /// Format tag ([`PLAN_FORMAT`]).
    pub format: String,
    /// The program (version and commit) that made the file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<String>,
    /// The scenario planned for, with its hash.
    pub scenario: NamedHash,
    /// One plan per planned agent.
    pub plans: Vec<AgentPlan>,
    /// Groups of agents (by name) whose plans run at the same time, all from `t = 0`; plans
    /// not in a group run one after another in file order. Absent: every plan runs alone.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub together: Vec<Vec<String>>,
}

/// SHA-256 of a robot's kinematic description (names, kinds, limits, frames, base).
pub fn robot_hash(robot: &embodied_models::Robot) -> String {
    use sha2::Digest;
    // The robot's kinematic description as the model prints it: names, kinds, limits, frames.
    let mut text = String::new();
    for j in robot.joints() {
        text.push_str(&format!(
            "{}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}\n",
            j.name, j.kind, j.origin, j.post, j.axis, j.offset, j.limits
        ));
    }
    text.push_str(&format!("{:?}", robot.base()));
    sha2::Sha256::digest(text.as_bytes()).iter().map(|b| format!("{b:02x}")).collect()
}

/// The planner's goal for a scenario goal.
pub fn goal_of(spec: &GoalSpec) -> Goal {
    match spec {
        GoalSpec::Configuration(q) => Goal::Configuration(q.clone()),
        GoalSpec::AnyOf(qs) => Goal::AnyOf(qs.clone()),
        GoalSpec::ToolPose { end_effector, pose } => Goal::ToolPose { end_effector: *end_effector, pose: *pose },
    }
}

/// The link shapes of `robot` at each configuration of `path` (and at points between them no
/// more than `step` apart in any joint, so that the union covers the swept volume), named
/// `prefix/...`: another agent's body, or the space it will sweep, as obstacles.
pub fn bodies_as_obstacles(robot: &Robot, path: &[Vec<f64>], step: f64, prefix: &str) -> Vec<Obstacle> {
    let model = CollisionModel::new(robot, Environment::new());
    let space = robot.config_space();
    let mut configurations: Vec<Vec<f64>> = Vec::new();
    for (k, q) in path.iter().enumerate() {
        if q.len() != robot.dof() {
            continue;
        }
        if let Some(prev) = k.checked_sub(1).and_then(|p| path.get(p)).filter(|p| p.len() == q.len()) {
            let n = (space.max_joint_step(prev, q) / step.max(1e-3)).ceil().clamp(1.0, 10_000.0) as usize;
            configurations.extend((1..n).map(|i| space.interpolate(prev, q, i as f64 / n as f64)));
        }
        configurations.push(q.clone());
    }
    let mut out = Vec::new();
    for (k, q) in configurations.iter().enumerate() {
        for mut o in model.link_shapes_world(q) {
            o.name = format!("{prefix}/{k}/{}", o.name);
            out.push(o);
        }
    }
    out
}

/// Motion-planner settings of a scenario (seed, edge check, resolution) with `deadline`.
pub fn motion_settings(scenario: &Scenario, deadline: Deadline) -> MotionSettings {
    let edge_check = if scenario.planner.certify {
        EdgeCheck::Certified { tolerance: CERTIFY_TOLERANCE }
    } else {
        EdgeCheck::Sampled
    };
    MotionSettings {
        seed: scenario.planner.seed,
        edge_check,
        resolution: scenario.planner.resolution,
        deadline,
        ..MotionSettings::default()
    }
}

/// Agent `k`'s planning problem: its robot among the obstacles present at the start, with the
/// other agents' bodies at the configurations in `occupied[m]` (empty: agent `m` is ignored).
pub fn agent_problem(scenario: &Scenario, k: usize, occupied: &[Vec<Vec<f64>>]) -> CollisionModel {
    let mut env = scenario.initial_environment();
    for (m, other) in scenario.agents.iter().enumerate() {
        if m != k {
            let path = occupied.get(m).map(Vec::as_slice).unwrap_or(&[]);
            for o in bodies_as_obstacles(&other.robot, path, f64::INFINITY, &other.name) {
                env.add(o);
            }
        }
    }
    CollisionModel::new(&scenario.agents[k].robot, env)
}

/// Plan every agent with a goal; other agents' bodies stand at their start poses, except
/// agents planned before, which stand where their plan ends (they move first).
pub fn plan_scenario(scenario: &Scenario, deadline_ms: Option<f64>) -> Result<PlanFile, SystemError> {
    let deadline_ms = deadline_ms.unwrap_or(scenario.planner.deadline_ms);
    if !(deadline_ms.is_finite() && deadline_ms >= 0.0) {
        return Err(SystemError::Usage(format!("--deadline-ms must be a non-negative number, got {deadline_ms}")));
    }
    let mut resting: Vec<Vec<Vec<f64>>> = scenario.agents.iter().map(|a| vec![a.start.clone()]).collect();
    let mut plans = Vec::new();
    for (k, agent) in scenario.agents.iter().enumerate() {
        let Some(goal) = &agent.goal else { continue };
        let model = agent_problem(scenario, k, &resting);
        let goal = goal_of(goal);
        let mut deadline = Deadline::after(Duration::from_secs_f64(deadline_ms / 1000.0));
        if let Some(n) = scenario.planner.expansions {
            deadline = Deadline::expansions(n as u64);
        }
        let settings = motion_settings(scenario, deadline);
        let plan = plan_motion(&model, &agent.start, &goal, &settings)
            .map_err(|e| SystemError::Failed(format!("scenario `{}`: agent `{}`: {e}", scenario.name, agent.name)))?;
        let trajectory = time_parameterize(&plan.path, &agent.robot, 0.001);
        // The verifier, not the planner, says whether the plan may drive an effector.
        Verifier::default().verify_trajectory(&model, &trajectory).map_err(|v| {
            SystemError::Failed(format!(
                "scenario `{}`: agent `{}`: plan rejected by the verifier: {v}",
                scenario.name, agent.name
            ))
        })?;
        if let Some(last) = plan.path.last() {
            resting[k] = vec![last.clone()];
        }
        let stats: &MotionStats = &plan.stats;
        plans.push(AgentPlan {
            agent: agent.name.clone(),
            robot: NamedHash { name: agent.robot.name().to_string(), hash: robot_hash(&agent.robot) },
            joint_names: agent.robot.joint_names(),
            path: plan.path.clone(),
            trajectory,
            stats: serde_json::to_value(stats).map_err(|e| SystemError::Failed(e.to_string()))?,
            closed_chain: Vec::new(),
        });
    }
    if let (Some(task), Some(carry)) = (scenario.carry_task(), &scenario.carry) {
        let agent = &scenario.agents[carry.agent];
        let plan = plan_carry(&task, &scenario.carry_settings()).map_err(|e| {
            SystemError::Failed(format!("scenario `{}`: agent `{}`: carry: {e}", scenario.name, agent.name))
        })?;
        // The certified checker, not the planner, says whether the plan may drive an effector.
        let model = agent_problem(scenario, carry.agent, &resting);
        let report = Verifier::default().check_trajectory(&model, &plan.trajectory, std::slice::from_ref(&plan.span));
        if !report.certified {
            return Err(SystemError::Failed(format!(
                "scenario `{}`: agent `{}`: carry plan rejected by the verifier: {:?}",
                scenario.name,
                agent.name,
                report.findings()
            )));
        }
        plans.push(AgentPlan {
            agent: agent.name.clone(),
            robot: NamedHash { name: agent.robot.name().to_string(), hash: robot_hash(&agent.robot) },
            joint_names: agent.robot.joint_names(),
            path: plan.waypoints.clone(),
            trajectory: plan.trajectory.clone(),
            stats: serde_json::to_value(&plan.stats).map_err(|e| SystemError::Failed(e.to_string()))?,
            closed_chain: vec![plan.span.clone()],
        });
    }
    if plans.is_empty() {
        return Err(SystemError::Usage(format!(
            "scenario `{}` has no agent with a goal: nothing to plan",
            scenario.name
        )));
    }
    Ok(PlanFile {
        format: PLAN_FORMAT.to_string(),
        generator: Some(crate::generator()),
        scenario: NamedHash { name: scenario.name.clone(), hash: scenario.hash.clone() },
        plans,
        together: Vec::new(),
    })
}

/// Read a plan file back, checking its format tag.
pub fn read_plan(path: &std::path::Path) -> Result<PlanFile, SystemError> {
    let text = crate::error::read_input(path, embodied_models::formats::limits::InputKind::Text)?;
    parse_plan(&text, path)
}

/// Parse a plan file's text, checking its format tag; `path` names it in errors.
pub fn parse_plan(text: &str, path: &std::path::Path) -> Result<PlanFile, SystemError> {
    embodied_models::formats::limits::check_values(text, embodied_models::formats::limits::Syntax::Data)
        .map_err(|message| SystemError::Parse { file: path.to_path_buf(), line: 1, column: 1, message })?;
    let plan: PlanFile = serde_json::from_str(text).map_err(|e| SystemError::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: format!("not a plan file: {e}"),
    })?;
    if plan.format != PLAN_FORMAT {
        return Err(SystemError::Parse {
            file: path.to_path_buf(),
            line: 1,
            column: 1,
            message: format!("format `{}`, expected `{PLAN_FORMAT}`", plan.format),
        });
    }
    Ok(plan)
}
