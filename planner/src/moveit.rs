//! MoveIt in and out: plan what a `MotionPlanRequest` asks in a planning scene, write the result
//! as a `trajectory_msgs/JointTrajectory`, and turn a JointTrajectory that anything else made
//! into a [`Trajectory`] over a [`CollisionModel`] for the certified checker
//! ([`crate::verify::certified::check_trajectory`]).
//!
//! The readers (scene, request, joint limits, joint trajectory) live in
//! [`embodied_models::formats`] and are re-exported here.

pub use embodied_models::formats::moveit::*;
pub use embodied_models::formats::trajectory::{
    JointTrajectory, LocatedTrajectory, TrajectoryPoint, load_joint_trajectory, parse_joint_trajectory,
};

use embodied_models::srdf::Srdf;
use embodied_models::{CollisionModel, Environment, ModelError, Robot};

use crate::PlanError;
use crate::motion::{Goal, MotionSettings, MotionStats, plan_motion};
use crate::trajectory::{Trajectory, time_parameterize};

/// A request made concrete: the planning robot (the group's joints; every other joint frozen)
/// among the scene's obstacles, with the start and goal over the group's joints.
#[derive(Debug, Clone)]
pub struct MoveitProblem {
    /// The group's joints, start, goal and frozen values.
    pub resolved: ResolvedRequest,
    /// The planning robot and the scene's obstacles.
    pub model: CollisionModel,
}

/// Build the planning problem of `request` in `scene` for `robot` (with `srdf`'s groups): the
/// scene's frames are checked, its allowed collisions applied, the group resolved and every
/// joint outside it frozen at the start state.
pub fn moveit_problem(
    robot: &Robot,
    srdf: &Srdf,
    scene: &PlanningScene,
    request: &MotionRequest,
) -> Result<MoveitProblem, MoveitError> {
    scene.check_frames(robot)?;
    let mut robot = robot.clone();
    scene.apply_allowed_collisions(&mut robot);
    let resolved = request.resolve(&robot, srdf, scene.robot_state.as_ref())?;
    let arm = resolved.planning_robot(&robot)?;
    Ok(MoveitProblem { model: CollisionModel::new(&arm, scene.environment()), resolved })
}

/// A planned request: the collision-free path, its time parameterisation and what planning cost.
#[derive(Debug, Clone)]
pub struct MoveitPlan {
    /// Waypoints from the start to the goal (the group's joints).
    pub path: Vec<Vec<f64>>,
    /// The path timed within every joint's velocity and acceleration limits, sampled at its knots.
    pub trajectory: Trajectory,
    /// Planner statistics.
    pub stats: MotionStats,
}

/// Plan `problem` from its start to its joint goal.
pub fn plan_request(problem: &MoveitProblem, settings: &MotionSettings) -> Result<MoveitPlan, PlanError> {
    let goal = Goal::Configuration(problem.resolved.goal.clone());
    let plan = plan_motion(&problem.model, &problem.resolved.start, &goal, settings)?;
    let trajectory = time_parameterize(&plan.path, problem.model.robot(), 0.0);
    Ok(MoveitPlan { path: plan.path, trajectory, stats: plan.stats })
}

/// A [`Trajectory`] as a JointTrajectory: every sample a point with its position and velocity;
/// the acceleration of a point is that of the interval it starts (constant over the interval;
/// 0 at the last point).
pub fn to_joint_trajectory(traj: &Trajectory) -> JointTrajectory {
    let n = traj.t.len();
    let points = (0..n)
        .map(|k| {
            let accelerations = if k + 1 < n {
                let h = traj.t[k + 1] - traj.t[k];
                traj.qd[k].iter().zip(&traj.qd[k + 1]).map(|(a, b)| (b - a) / h).collect()
            } else {
                vec![0.0; traj.q[k].len()]
            };
            TrajectoryPoint {
                positions: traj.q[k].clone(),
                velocities: traj.qd[k].clone(),
                accelerations,
                time_from_start: traj.t[k],
            }
        })
        .collect();
    JointTrajectory { joint_names: traj.joint_names.clone(), points }
}

/// What a JointTrajectory is checked against: the robot with every joint the trajectory does not
/// name frozen, among obstacles, and the trajectory over that robot's joints.
#[derive(Debug, Clone)]
pub struct TrajectoryProblem {
    /// The moving robot and the obstacles.
    pub model: CollisionModel,
    /// The trajectory in the moving robot's joint order.
    pub trajectory: Trajectory,
    /// The frozen joints and their values.
    pub frozen: Vec<(String, f64)>,
}

/// Turn a JointTrajectory into a [`TrajectoryProblem`] for `robot`: joints the trajectory does
/// not name are frozen at `state` (a scene's robot state) where it gives them, else at the
/// robot's home; `environment` holds the obstacles. Velocities are the points' own when every
/// point gives them, else central finite differences of the positions (zero at both ends).
/// Points are kept as they are (times from the first point's); a joint name the robot does not
/// have is an error naming the file.
pub fn trajectory_problem(
    robot: &Robot,
    state: Option<&JointState>,
    environment: Environment,
    traj: &JointTrajectory,
    file: &std::path::Path,
) -> Result<TrajectoryProblem, MoveitError> {
    let names = robot.joint_names();
    for n in &traj.joint_names {
        if !names.contains(n) {
            return Err(MoveitError::Parse {
                file: file.to_path_buf(),
                line: 1,
                column: 1,
                message: format!(
                    "joint `{n}` of joint_names is not a degree of freedom of robot `{}` (expected some of: {})",
                    robot.name(),
                    names.join(", ")
                ),
            });
        }
    }
    let home = robot.home();
    let frozen: Vec<(String, f64)> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| !traj.joint_names.contains(n))
        .map(|(d, n)| (n.clone(), state.and_then(|s| s.get(n)).unwrap_or(home[d])))
        .collect();
    let borrowed: Vec<(&str, f64)> = frozen.iter().map(|(n, v)| (n.as_str(), *v)).collect();
    let arm = robot.freeze_joints(&borrowed)?;
    let order: Vec<usize> = arm
        .joint_names()
        .iter()
        .map(|n| traj.joint_names.iter().position(|m| m == n))
        .collect::<Option<Vec<usize>>>()
        .ok_or_else(|| {
            MoveitError::Model(ModelError::Invalid {
                robot: robot.name().to_string(),
                message: "freezing the joints the trajectory does not name left other joints".into(),
            })
        })?;
    let pick = |v: &[f64]| order.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let t: Vec<f64> = traj.points.iter().map(|p| p.time_from_start).collect();
    let q: Vec<Vec<f64>> = traj.points.iter().map(|p| pick(&p.positions)).collect();
    let qd: Vec<Vec<f64>> = if traj.points.iter().all(|p| !p.velocities.is_empty()) {
        traj.points.iter().map(|p| pick(&p.velocities)).collect()
    } else {
        let n = q.len();
        (0..n)
            .map(|k| {
                if k == 0 || k + 1 == n {
                    vec![0.0; order.len()]
                } else {
                    let h = t[k + 1] - t[k - 1];
                    q[k + 1].iter().zip(&q[k - 1]).map(|(b, a)| (b - a) / h).collect()
                }
            })
            .collect()
    };
    let trajectory = Trajectory { joint_names: arm.joint_names(), t, q, qd };
    Ok(TrajectoryProblem { model: CollisionModel::new(&arm, environment), trajectory, frozen })
}
