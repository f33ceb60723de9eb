//! MoveIt in and out: plan what a `MotionPlanRequest` asks in a planning scene, write the result
//! as a `trajectory_msgs/JointTrajectory`, and turn a JointTrajectory that anything else made
//! into a [`Trajectory`] over a [`CollisionModel`] for the certified checker
//! ([`crate::verify::Verifier::check_trajectory`]).
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

/// Plan `problem` from its start to its goal: the joint goal, or any configuration meeting one
/// of the request's goal alternatives (link poses through [`goal_configurations`]). The path's
/// last configuration is checked against the request's goals before it is returned.
pub fn plan_request(problem: &MoveitProblem, settings: &MotionSettings) -> Result<MoveitPlan, PlanError> {
    let goal = match problem.resolved.goals.as_slice() {
        [ResolvedGoal::Configuration(q)] => Goal::Configuration(q.clone()),
        _ => Goal::AnyOf(goal_configurations(problem, settings)?),
    };
    let plan = plan_motion(&problem.model, &problem.resolved.start, &goal, settings)?;
    let Some(last) = plan.path.last() else {
        return Err(PlanError::InvalidInput { message: "the planner returned an empty path".into() });
    };
    if let Some(why) = goal_miss(problem, last) {
        return Err(PlanError::GoalUnreachable { reason: format!("the path ends off the goal: {why}") });
    }
    let trajectory = time_parameterize(&plan.path, problem.model.robot(), 0.0);
    Ok(MoveitPlan { path: plan.path, trajectory, stats: plan.stats })
}

/// Largest joint-space distance (rad or m) from a configuration goal at which it counts as
/// reached.
pub const CONFIGURATION_GOAL_TOLERANCE: f64 = 1e-6;

/// Why configuration `q` (the group's joints) meets none of the problem's goal alternatives, or
/// `None` when it meets one.
pub fn goal_miss(problem: &MoveitProblem, q: &[f64]) -> Option<String> {
    let robot = problem.model.robot();
    let space = robot.config_space();
    let mut reasons = Vec::new();
    for (k, goal) in problem.resolved.goals.iter().enumerate() {
        let miss = match goal {
            ResolvedGoal::Configuration(g) => {
                let d = space.distance(g, q);
                (d > CONFIGURATION_GOAL_TOLERANCE).then(|| format!("{d:.3e} from the goal configuration"))
            }
            ResolvedGoal::Pose(p) => p.miss(robot, q),
        };
        match miss {
            None => return None,
            Some(why) => reasons.push(format!("goal {k}: {why}")),
        }
    }
    Some(reasons.join("; "))
}

/// Goal configurations of the problem: every configuration goal, and for every link-pose goal
/// up to `settings.ik_solutions` distinct collision-free inverse-kinematics solutions that meet
/// it. The solver (damped least squares, [`Robot::inverse_kinematics`]) aims the constrained
/// point at the first region's centre and the link at the wanted orientation (position only
/// when the goal has no orientation; the start's point when it has no position), seeded at the
/// start and then at random configurations drawn from `settings.seed`. Every solution is checked
/// against the whole goal ([`PoseGoal::miss`]), the joint limits and collisions.
pub fn goal_configurations(problem: &MoveitProblem, settings: &MotionSettings) -> Result<Vec<Vec<f64>>, PlanError> {
    let robot = problem.model.robot();
    let start = &problem.resolved.start;
    let space = robot.config_space();
    let mut out: Vec<Vec<f64>> = Vec::new();
    let mut last_miss = None;
    for (k, goal) in problem.resolved.goals.iter().enumerate() {
        let pose_goal = match goal {
            ResolvedGoal::Configuration(q) => {
                out.push(q.clone());
                continue;
            }
            ResolvedGoal::Pose(p) => p,
        };
        let tool = nalgebra::Isometry3::translation(pose_goal.offset.x, pose_goal.offset.y, pose_goal.offset.z);
        let (arm, ee) = robot
            .with_end_effector("goal", &pose_goal.link, tool)
            .map_err(|e| PlanError::InvalidInput { message: format!("goal {k}: {e}") })?;
        let (_, at_start) = arm.end_effector_poses(start, ee);
        let (position, orientation) = pose_goal.aim();
        let target = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(position.unwrap_or(at_start.translation.vector)),
            orientation.unwrap_or(at_start.rotation),
        );
        let wanted = settings.ik_solutions.max(1);
        let mut rng = embodied_models::Rng::new(settings.seed ^ 0x90a1_5eed ^ k as u64);
        let mut found = 0;
        for attempt in 0..4 * wanted + 4 {
            if found >= wanted {
                break;
            }
            let mut seed = if attempt == 0 { start.clone() } else { arm.random_configuration(&mut rng) };
            // Joint constraints of the goal bound the seeds too: the solver starts where the
            // goal allows (drawn within the allowed interval, or clamped into it at the start).
            for &(i, lo, hi) in &pose_goal.joints {
                let limits = arm.limits()[i];
                let (lo, hi) = (lo.max(limits.lower), hi.min(limits.upper));
                if lo <= hi {
                    seed[i] = if attempt == 0 { seed[i].clamp(lo, hi) } else { lo + (hi - lo) * rng.uniform() };
                }
            }
            let options = embodied_models::ik::IkOptions {
                seed: settings.seed.wrapping_add(attempt as u64),
                restarts: if attempt == 0 { 20 } else { 3 },
                position_only: orientation.is_none(),
                ..embodied_models::ik::IkOptions::default()
            };
            let Ok(q) = arm.inverse_kinematics(ee, &target, &seed, &options) else { continue };
            if let Some(why) = pose_goal.miss(robot, &q) {
                last_miss = Some(why);
                continue;
            }
            if robot.check_configuration(&q).is_err() || problem.model.first_collision(&q).is_some() {
                last_miss = Some("every solution found collides or breaks a joint limit".into());
                continue;
            }
            if out.iter().all(|o| space.distance(o, &q) > 1e-3) {
                out.push(q);
                found += 1;
            }
        }
    }
    if out.is_empty() {
        let reason = match last_miss {
            Some(why) => format!("no configuration meets the goal: {why}"),
            None => "no inverse-kinematics solution reaches the goal pose".into(),
        };
        return Err(PlanError::GoalUnreachable { reason });
    }
    Ok(out)
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
