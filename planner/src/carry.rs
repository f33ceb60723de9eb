//! Two end effectors holding one rigid object: the closed-chain part of a plan.

use embodied_models::Robot;
use embodied_models::geometry::{PlacedShape, Shape};
use embodied_models::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// A rigid box carried by two end effectors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CarriedObject {
    /// The object's name.
    pub name: String,
    /// Full box sizes along the object's x, y, z, m.
    pub size: [f64; 3],
    /// Pose of the object in the first end effector's tool frame: x, y, z, then the unit
    /// quaternion w, x, y, z.
    pub in_tool: [f64; 7],
}

impl CarriedObject {
    /// `in_tool` as an isometry (the quaternion normalised; `None` if it is zero or not finite).
    pub fn pose_in_tool(&self) -> Option<Isometry3<f64>> {
        let [x, y, z, qw, qx, qy, qz] = self.in_tool;
        let q = Quaternion::new(qw, qx, qy, qz);
        if !self.in_tool.iter().all(|v| v.is_finite()) || q.norm() < 1e-9 {
            return None;
        }
        Some(Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_quaternion(q)))
    }

    /// `pose` (object in tool frame) in the `in_tool` layout.
    pub fn encode_pose(pose: &Isometry3<f64>) -> [f64; 7] {
        let t = pose.translation.vector;
        let q = pose.rotation.into_inner();
        [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
    }

    /// A copy of `robot` with the object rigidly attached to the flange link of end effector
    /// `holder`; collisions between that link and the links in `touching` (the other
    /// gripper) are no longer checked, since the object's shape is part of the holder's link.
    pub fn attach(&self, robot: &Robot, holder: usize, touching: &[usize]) -> Option<Robot> {
        let ee = robot.end_effectors().get(holder)?;
        if !self.size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return None;
        }
        let pose = ee.tool * self.pose_in_tool()?;
        let shape = Shape::cuboid(self.size[0] / 2.0, self.size[1] / 2.0, self.size[2] / 2.0);
        let link = ee.link;
        let mut out = robot.clone();
        out.attach_shapes(link, [PlacedShape::new(pose, shape)]);
        for &other in touching {
            if other != link && other < robot.links().len() {
                out.disable_pair(link, other);
            }
        }
        Some(out)
    }
}

/// A span of a plan during which two end effectors hold one rigid object (a closed chain):
/// the pose of the second tool frame relative to the first must stay what it is at `from_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClosedChainSpan {
    /// Start of the span, s from the trajectory's start.
    pub from_s: f64,
    /// End of the span, s from the trajectory's start.
    pub to_s: f64,
    /// End-effector names of the robot (see [`Robot::end_effectors`]).
    pub end_effectors: [String; 2],
    /// Largest allowed change of the relative position, m, and rotation angle, rad.
    pub tolerance_m: f64,
    /// Largest allowed change of the relative rotation angle, rad (see `tolerance_m`).
    pub tolerance_rad: f64,
    /// The object, attached to the first end effector (its collisions count too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<CarriedObject>,
}

// ---------------------------------------------------------------------------------------------
// Planning a two-handed carry.

use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::time::Instant;

use embodied_models::IkOptions;
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::Vector3;

use crate::PlanError;
use crate::deadline::Deadline;
use crate::motion::{Goal, MotionSettings, plan_motion};
use crate::search::{Cost, SearchProblem, Successor, solve};
use crate::trajectory::{Trajectory, time_parameterize};

/// What a two-handed carry is: the robot (one model holding both arms), where the object
/// stands and where it must go, and how the two end effectors grasp it.
#[derive(Debug, Clone)]
pub struct CarryTask {
    /// The two-arm robot, without the object.
    pub robot: Robot,
    /// The obstacles (not the object).
    pub environment: Environment,
    /// Joint values at the start (arms free).
    pub start: Vec<f64>,
    /// The object's name and full box sizes, m.
    pub object_name: String,
    /// Full box sizes of the object along its x, y, z, m (see `object_name`).
    pub object_size: [f64; 3],
    /// The object's pose at the start and at the goal (world frame).
    pub object_start: Isometry3<f64>,
    /// The object's goal pose (world frame); see `object_start`.
    pub object_goal: Isometry3<f64>,
    /// End effectors `[holder, other]` and their tool frames in the object frame.
    pub end_effectors: [usize; 2],
    /// The tool frames of `end_effectors[0]` and `end_effectors[1]` in the object frame.
    pub grasps: [Isometry3<f64>; 2],
}

/// How to plan a carry.
#[derive(Debug, Clone)]
pub struct CarrySettings {
    /// Lattice step of the object's position search, m.
    pub lattice_step: f64,
    /// Margin of the search box around the start and goal positions, m (per axis).
    pub margin: [f64; 3],
    /// The object's centre never goes below this height, m.
    pub floor: f64,
    /// How far the tools back out along their approach axis before grasping and after releasing, m.
    pub retreat: f64,
    /// Control step the trajectory is sampled at, s.
    pub dt: f64,
    /// Fraction of every joint's velocity and acceleration limit the closed-chain motions use.
    pub speed_fraction: f64,
    /// Largest joint change between neighbouring lattice poses, rad (or m): larger means the
    /// inverse kinematics jumped to another solution branch.
    pub max_joint_jump: f64,
    /// Allowed drift of the grasp while the object is held (the plan's closed-chain tolerance).
    pub tolerance_m: f64,
    /// Allowed rotation drift of the grasp while the object is held, rad (see `tolerance_m`).
    pub tolerance_rad: f64,
    /// The free approach motion (joint space).
    pub motion: MotionSettings,
    /// Clearance the object's path keeps from obstacles where it can, m: closer lattice poses
    /// cost more (weight `clearance_weight`), and a shortcut may not come closer than the
    /// lattice path it replaces.
    pub clearance: f64,
    /// Weight of the clearance term in a lattice edge's cost (see `clearance`).
    pub clearance_weight: f64,
    /// Lazy search rounds (an edge found in collision is removed and the search repeated).
    pub max_rounds: usize,
    /// Expansion budget of one search round.
    pub max_expansions: u64,
}

impl Default for CarrySettings {
    fn default() -> Self {
        Self {
            lattice_step: 0.05,
            margin: [0.4, 0.3, 0.5],
            floor: 0.3,
            retreat: 0.08,
            dt: 0.001,
            speed_fraction: 0.8,
            max_joint_jump: 0.35,
            tolerance_m: 1e-3,
            tolerance_rad: 2e-3,
            motion: MotionSettings::default(),
            clearance: 0.04,
            clearance_weight: 3.0,
            max_rounds: 40,
            max_expansions: 200_000,
        }
    }
}

/// What planning a carry cost.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CarryStats {
    /// What made the plan.
    pub planner: String,
    /// Wall-clock time of the whole carry planning, ms.
    pub planning_ms: f64,
    /// Wall-clock time of planning the free approach motion, ms.
    pub approach_ms: f64,
    /// Lazy search rounds run.
    pub search_rounds: usize,
    /// A* expansions over every round.
    pub expansions: u64,
    /// Lattice poses whose two-arm inverse kinematics was tried.
    pub lattice_poses: usize,
    /// Lattice poses with no acceptable two-arm configuration (no IK solution, a jump larger than `max_joint_jump`, or in collision).
    pub ik_failures: usize,
    /// Lattice edges the held object could not follow (removed before the next round).
    pub edges_rejected: usize,
    /// Straight object segments after shortcutting, and lattice steps before.
    pub object_segments: usize,
    /// Lattice steps of the found object path, before shortcutting (see `object_segments`).
    pub lattice_steps: usize,
    /// Length of the object's path after shortcutting, m.
    pub object_path_m: f64,
    /// Collision checks made.
    pub collision_checks: u64,
}

/// A carry plan: one timed joint trajectory (approach, insert, carry, retreat) and the span in
/// which the object is held.
#[derive(Debug, Clone)]
pub struct CarryPlan {
    /// The timed joint trajectory: approach, insert, carry, retreat.
    pub trajectory: Trajectory,
    /// The joint-space waypoints at rest (phase ends and object segment ends).
    pub waypoints: Vec<Vec<f64>>,
    /// The span in which both end effectors hold the object.
    pub span: ClosedChainSpan,
    /// Object positions at the ends of its straight segments, start to goal.
    pub object_path: Vec<[f64; 3]>,
    /// What planning took.
    pub stats: CarryStats,
}

fn failed(reason: impl Into<String>) -> PlanError {
    PlanError::Refiner { reason: reason.into() }
}

/// The degrees of freedom that move end effector `ee`.
pub fn arm_dofs(robot: &Robot, ee: usize) -> Vec<usize> {
    let Some(e) = robot.end_effectors().get(ee) else { return Vec::new() };
    robot.chain_to(e.link).into_iter().filter_map(|ji| robot.joints()[ji].dof_index).collect()
}

/// Tool pose of end effector `ee` at `q`.
pub fn tool_pose(robot: &Robot, q: &[f64], ee: usize) -> Isometry3<f64> {
    robot.end_effector_poses(q, ee).1
}

/// Pose of tool `ee1` in the frame of tool `ee0`.
pub fn relative_tool_pose(robot: &Robot, q: &[f64], ee: [usize; 2]) -> Isometry3<f64> {
    tool_pose(robot, q, ee[0]).inv_mul(&tool_pose(robot, q, ee[1]))
}

/// Position (m) and angle (rad) between two poses.
pub fn pose_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inv_mul(b);
    (d.translation.vector.norm(), d.rotation.angle())
}

/// Solve both arms' inverse kinematics for tool targets `targets[k]` of `ee[k]`, each arm from
/// `seed`; only each arm's own joints change. `restarts` random restarts per arm.
pub fn two_arm_ik(
    robot: &Robot,
    ee: [usize; 2],
    targets: [&Isometry3<f64>; 2],
    seed: &[f64],
    restarts: usize,
    tolerance: f64,
) -> Option<Vec<f64>> {
    let options = IkOptions {
        position_tolerance: tolerance,
        orientation_tolerance: tolerance,
        max_iterations: 60,
        restarts,
        ..IkOptions::default()
    };
    let mut q = seed.to_vec();
    for k in 0..2 {
        // The closed form's nearest solution (a track held where it is), else the numerical one.
        let closed = robot.closed_form(ee[k]).and_then(|_| {
            let nearest = robot.inverse_kinematics_all(ee[k], targets[k], &q).ok()?.into_iter().next()?;
            // The solver's own error measure (a rotation vector: `angle()` of a near-identity
            // rotation is only good to about 1e-8 rad, too coarse for a 1e-10 tolerance).
            let e = embodied_models::ik::pose_error(&tool_pose(robot, &nearest, ee[k]), targets[k]);
            let within = e.fixed_rows::<3>(0).norm() <= tolerance && e.fixed_rows::<3>(3).norm() <= tolerance;
            within.then_some(nearest)
        });
        let solution = match closed {
            Some(s) => s,
            None => robot.inverse_kinematics(ee[k], targets[k], &q, &options).ok()?,
        };
        for d in arm_dofs(robot, ee[k]) {
            q[d] = solution[d];
        }
    }
    Some(q)
}

/// Largest joint change between two configurations (the short way on continuous joints).
fn largest_jump(robot: &Robot, a: &[f64], b: &[f64]) -> f64 {
    robot.config_space().max_joint_step(a, b)
}

/// The quintic rest-to-rest time law s(u), u in [0, 1], and its first two derivatives.
fn quintic(u: f64) -> (f64, f64, f64) {
    let u = u.clamp(0.0, 1.0);
    let (u2, u3) = (u * u, u * u * u);
    (
        10.0 * u3 - 15.0 * u2 * u2 + 6.0 * u3 * u2,
        30.0 * u2 - 60.0 * u3 + 30.0 * u2 * u2,
        60.0 * u - 180.0 * u2 + 120.0 * u3,
    )
}
/// max |s'| and max |s''| of the quintic law.
const QUINTIC_V: f64 = 1.875;
const QUINTIC_A: f64 = 5.773_502_691_896_258;

/// Tool targets along a motion: `targets(s)` for s in [0, 1].
type Targets<'a> = &'a dyn Fn(f64) -> [Isometry3<f64>; 2];

/// Follow tool targets with both arms from `seed`: inverse kinematics at `n` points of the
/// path, checking continuity and collisions. Returns the joint path (n + 1 points, s = k / n).
#[allow(clippy::too_many_arguments)]
fn follow(
    robot: &Robot,
    model: &CollisionModel,
    ee: [usize; 2],
    targets: Targets,
    seed: &[f64],
    n: usize,
    max_jump: f64,
    checks: &mut u64,
) -> Result<Vec<Vec<f64>>, String> {
    let mut path = vec![seed.to_vec()];
    let mut q = seed.to_vec();
    for k in 1..=n {
        let s = k as f64 / n as f64;
        let [a, b] = targets(s);
        let next = two_arm_ik(robot, ee, [&a, &b], &q, 0, 1e-9).ok_or_else(|| format!("no IK at s = {s:.3}"))?;
        if largest_jump(robot, &q, &next) > max_jump {
            return Err(format!("IK jumps {:.3} at s = {s:.3}", largest_jump(robot, &q, &next)));
        }
        *checks += 1;
        if let Some(c) = model.first_collision(&next) {
            return Err(format!("collision at s = {s:.3}: {c}"));
        }
        path.push(next.clone());
        q = next;
    }
    Ok(path)
}

/// Time a tool-space motion: its joint path sampled at `n` points gives the largest joint
/// rates with respect to the path parameter, from which the quintic law's duration follows so
/// that `fraction` of every velocity and acceleration limit is respected. Then inverse
/// kinematics at every control step. Returns samples from t = 0 (excluded) to the end.
#[allow(clippy::too_many_arguments)]
fn timed_follow(
    robot: &Robot,
    model: &CollisionModel,
    ee: [usize; 2],
    targets: Targets,
    seed: &[f64],
    settings: &CarrySettings,
    checks: &mut u64,
) -> Result<(Vec<Vec<f64>>, f64), String> {
    let n = 100;
    let coarse = follow(robot, model, ee, targets, seed, n, settings.max_joint_jump, checks)?;
    let limits = robot.limits();
    let h = 1.0 / n as f64;
    let mut duration: f64 = 0.05;
    for k in 0..=n {
        let (prev, next) = (k.saturating_sub(1), (k + 1).min(n));
        for (j, l) in limits.iter().enumerate() {
            let d1 = (coarse[next][j] - coarse[prev][j]) / ((next - prev) as f64 * h);
            let d2 =
                if k > 0 && k < n { (coarse[next][j] - 2.0 * coarse[k][j] + coarse[prev][j]) / (h * h) } else { 0.0 };
            let v = settings.speed_fraction * l.max_velocity;
            let a = settings.speed_fraction * l.max_acceleration;
            duration = duration.max(QUINTIC_V * d1.abs() / v);
            duration = duration.max(((QUINTIC_V * QUINTIC_V * d2.abs() + QUINTIC_A * d1.abs()) / a).sqrt());
        }
    }
    let steps = (duration / settings.dt).ceil().max(1.0) as usize;
    let duration = steps as f64 * settings.dt;
    let mut out = Vec::with_capacity(steps);
    let mut q = seed.to_vec();
    for k in 1..=steps {
        let (s, _, _) = quintic(k as f64 / steps as f64);
        let [a, b] = targets(s);
        let next = two_arm_ik(robot, ee, [&a, &b], &q, 0, 1e-10).ok_or_else(|| format!("no IK at s = {s:.4}"))?;
        if largest_jump(robot, &q, &next) > settings.max_joint_jump * 0.2 {
            return Err(format!("IK jumps {:.3} at s = {s:.4}", largest_jump(robot, &q, &next)));
        }
        out.push(next.clone());
        q = next;
    }
    // Every sample checked (the coarse pass checked the path; these are the plan itself).
    for q in out.iter().step_by(5) {
        *checks += 1;
        if let Some(c) = model.first_collision(q) {
            return Err(format!("collision: {c}"));
        }
    }
    Ok((out, duration))
}

/// Interpolate two poses: translation linearly, rotation by slerp.
pub fn interpolate_pose(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let t = a.translation.vector.lerp(&b.translation.vector, s);
    let r = a.rotation.slerp(&b.rotation, s);
    Isometry3::from_parts(Translation3::from(t), r)
}

/// The object's position search: a lattice of object positions (orientation kept), each
/// lattice pose holding both arms' joint values found by inverse kinematics seeded from the
/// pose it was first reached from.
struct ObjectLattice<'a> {
    task: &'a CarryTask,
    held: &'a CollisionModel,
    settings: &'a CarrySettings,
    step: Vector3<f64>,
    lo: [i32; 3],
    hi: [i32; 3],
    goal: [i32; 3],
    configurations: RefCell<HashMap<[i32; 3], Option<Vec<f64>>>>,
    /// The arms with the object against the environment only (clearances).
    clear: &'a CollisionModel,
    clearances: RefCell<HashMap<[i32; 3], f64>>,
    blocked: HashSet<([i32; 3], [i32; 3])>,
    ik_failures: RefCell<usize>,
    checks: RefCell<u64>,
}

impl ObjectLattice<'_> {
    fn pose(&self, cell: [i32; 3]) -> Isometry3<f64> {
        let offset = Vector3::new(
            f64::from(cell[0]) * self.step.x,
            f64::from(cell[1]) * self.step.y,
            f64::from(cell[2]) * self.step.z,
        );
        Isometry3::from_parts(
            Translation3::from(self.task.object_start.translation.vector + offset),
            self.task.object_start.rotation,
        )
    }

    fn targets(&self, object: &Isometry3<f64>) -> [Isometry3<f64>; 2] {
        [object * self.task.grasps[0], object * self.task.grasps[1]]
    }

    /// Clearance of a lattice pose from the environment (infinite when unknown).
    fn clearance(&self, cell: [i32; 3]) -> f64 {
        self.clearances.borrow().get(&cell).copied().unwrap_or(f64::INFINITY)
    }

    /// 0 at the wanted clearance or more, 1 in contact.
    fn penalty(&self, cell: [i32; 3]) -> f64 {
        let c = self.settings.clearance;
        if c > 0.0 { ((c - self.clearance(cell)) / c).clamp(0.0, 1.0) } else { 0.0 }
    }

    /// Joint values holding the object at `cell`, solved from `from` on first visit.
    fn configuration(&self, cell: [i32; 3], from: &[f64]) -> Option<Vec<f64>> {
        if let Some(known) = self.configurations.borrow().get(&cell) {
            return known.clone();
        }
        let [a, b] = self.targets(&self.pose(cell));
        let q = two_arm_ik(&self.task.robot, self.task.end_effectors, [&a, &b], from, 0, 1e-9).filter(|q| {
            *self.checks.borrow_mut() += 1;
            largest_jump(&self.task.robot, from, q) <= self.settings.max_joint_jump && !self.held.collides(q)
        });
        match &q {
            None => *self.ik_failures.borrow_mut() += 1,
            Some(q) => {
                self.clearances.borrow_mut().insert(cell, self.clear.distance(q).distance);
            }
        }
        self.configurations.borrow_mut().insert(cell, q.clone());
        q
    }
}

impl SearchProblem for ObjectLattice<'_> {
    type State = [i32; 3];
    type Operator = ();

    fn initial(&self) -> [i32; 3] {
        [0, 0, 0]
    }

    fn successors(&self, state: &[i32; 3], out: &mut Vec<Successor<[i32; 3], ()>>) {
        let Some(q) = self.configurations.borrow().get(state).cloned().flatten() else { return };
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if dx == 0 && dy == 0 && dz == 0 {
                        continue;
                    }
                    let next = [state[0] + dx, state[1] + dy, state[2] + dz];
                    if (0..3).any(|k| next[k] < self.lo[k] || next[k] > self.hi[k])
                        || self.blocked.contains(&(*state, next))
                    {
                        continue;
                    }
                    if self.configuration(next, &q).is_none() {
                        continue;
                    }
                    let d = Vector3::new(
                        f64::from(dx) * self.step.x,
                        f64::from(dy) * self.step.y,
                        f64::from(dz) * self.step.z,
                    )
                    .norm();
                    let penalty = (self.penalty(*state) + self.penalty(next)) / 2.0;
                    if let Ok(cost) = Cost::new(d * (1.0 + self.settings.clearance_weight * penalty)) {
                        out.push(Successor { operator: (), state: next, cost });
                    }
                }
            }
        }
    }

    fn is_goal(&self, state: &[i32; 3]) -> bool {
        *state == self.goal
    }

    fn heuristic(&self, state: &[i32; 3]) -> f64 {
        let d = Vector3::new(
            f64::from(self.goal[0] - state[0]) * self.step.x,
            f64::from(self.goal[1] - state[1]) * self.step.y,
            f64::from(self.goal[2] - state[2]) * self.step.z,
        );
        d.norm()
    }
}

/// Plan a two-handed carry: a free approach to tool poses backed out from the grasps, a
/// straight insertion, the closed-chain carry of the object along a path found by A* over
/// object positions (inverse kinematics of both arms at every lattice pose, edges checked
/// lazily, the path shortcut into straight segments), the release and a straight retreat.
pub fn plan_carry(task: &CarryTask, settings: &CarrySettings) -> Result<CarryPlan, PlanError> {
    let started = Instant::now();
    let robot = &task.robot;
    let ee = task.end_effectors;
    let mut stats =
        CarryStats { planner: "carry: A* over object positions, closed-chain IK".into(), ..CarryStats::default() };
    if task.start.len() != robot.dof() {
        return Err(PlanError::InvalidInput {
            message: format!("start has {} joint values, the robot has {}", task.start.len(), robot.dof()),
        });
    }
    let other_link = robot.end_effectors().get(ee[1]).map(|e| e.link).ok_or_else(|| failed("no such end effector"))?;
    // In the robot's frame: tool poses relative to each other at the grasp.
    let object = CarriedObject {
        name: task.object_name.clone(),
        size: task.object_size,
        in_tool: CarriedObject::encode_pose(&task.grasps[0].inverse()),
    };
    let held_robot = object.attach(robot, ee[0], &[other_link]).ok_or_else(|| failed("cannot attach the object"))?;
    let held = CollisionModel::new(&held_robot, task.environment.clone());
    let clear = CollisionModel::new(&held_robot.without_self_collisions(), task.environment.clone());
    let object_at = |pose: &Isometry3<f64>| {
        let (hx, hy, hz) = (task.object_size[0] / 2.0, task.object_size[1] / 2.0, task.object_size[2] / 2.0);
        Obstacle::new(task.object_name.clone(), *pose, embodied_models::Shape::cuboid(hx, hy, hz))
    };
    let mut env_start = task.environment.clone();
    env_start.add(object_at(&task.object_start));
    let free_start = CollisionModel::new(robot, env_start);
    let mut env_goal = task.environment.clone();
    env_goal.add(object_at(&task.object_goal));
    let free_goal = CollisionModel::new(robot, env_goal);
    let mut checks = 0u64;

    // Grasp configurations at the start, the pre-grasp from them.
    let back = Isometry3::translation(0.0, 0.0, -settings.retreat);
    let grasp_at = |object: &Isometry3<f64>| [object * task.grasps[0], object * task.grasps[1]];
    let backed = |object: &Isometry3<f64>| [object * task.grasps[0] * back, object * task.grasps[1] * back];
    let [g0, g1] = grasp_at(&task.object_start);
    // Several inverse-kinematics solutions from random seeds: the collision-free one nearest
    // the start (its approach is the shortest).
    let mut rng = embodied_models::Rng::new(settings.motion.seed ^ 0x9e37_79b9);
    let space = robot.config_space();
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut valid = 0;
    for attempt in 0..48 {
        let seed = if attempt == 0 { task.start.clone() } else { robot.random_configuration(&mut rng) };
        let Some(q) = two_arm_ik(robot, ee, [&g0, &g1], &seed, 2, 1e-9) else { continue };
        checks += 1;
        if held.collides(&q) || free_start.collides(&q) {
            continue;
        }
        let d = space.distance(&task.start, &q);
        if best.as_ref().is_none_or(|(b, _)| d < *b) {
            best = Some((d, q));
        }
        valid += 1;
        if valid >= 6 {
            break;
        }
    }
    let q_grasp = best.map(|(_, q)| q).ok_or_else(|| {
        failed("no collision-free configuration holds the object at its start (grasp poses out of reach?)")
    })?;
    // Insertion, planned backwards from the grasp (so it ends exactly there).
    let insertion = |s: f64| {
        let [a0, a1] = backed(&task.object_start);
        [interpolate_pose(&g0, &a0, s), interpolate_pose(&g1, &a1, s)]
    };
    let (mut backwards, _) = timed_follow(robot, &free_start, ee, &insertion, &q_grasp, settings, &mut checks)
        .map_err(|e| failed(format!("inserting the tools at the start: {e}")))?;
    let q_pre = backwards.last().cloned().unwrap_or_else(|| q_grasp.clone());
    backwards.pop();
    backwards.reverse();
    backwards.push(q_grasp.clone());

    // The free approach (joint space).
    let t_approach = Instant::now();
    let approach = plan_motion(&free_start, &task.start, &Goal::Configuration(q_pre.clone()), &settings.motion)?;
    stats.approach_ms = t_approach.elapsed().as_secs_f64() * 1e3;
    stats.collision_checks += approach.stats.collision_checks;
    let approach_traj = time_parameterize(&approach.path, robot, settings.dt);

    // The object's path: A* over the lattice, lazily.
    let d = task.object_goal.translation.vector - task.object_start.translation.vector;
    let mut step = Vector3::repeat(settings.lattice_step);
    let mut goal = [0i32; 3];
    for k in 0..3 {
        let cells = (d[k].abs() / settings.lattice_step).round();
        if cells >= 1.0 {
            step[k] = d[k].abs() / cells;
            goal[k] = (cells as i32) * if d[k] < 0.0 { -1 } else { 1 };
        }
    }
    let (mut lo, mut hi) = ([0i32; 3], [0i32; 3]);
    for k in 0..3 {
        let margin = (settings.margin[k] / step[k]).ceil() as i32;
        lo[k] = goal[k].min(0) - margin;
        hi[k] = goal[k].max(0) + margin;
    }
    let floor_cells = ((settings.floor - task.object_start.translation.z) / step.z).ceil() as i32;
    lo[2] = lo[2].max(floor_cells);
    let mut lattice = ObjectLattice {
        task,
        held: &held,
        settings,
        step,
        lo,
        hi,
        goal,
        configurations: RefCell::new(HashMap::from([([0, 0, 0], Some(q_grasp.clone()))])),
        blocked: HashSet::new(),
        clear: &clear,
        clearances: RefCell::new(HashMap::from([([0, 0, 0], clear.distance(&q_grasp).distance)])),
        ik_failures: RefCell::new(0),
        checks: RefCell::new(0),
    };
    if task.object_goal.rotation.angle_to(&task.object_start.rotation) > 1e-6 {
        return Err(failed("the object's goal orientation must equal its start orientation (positions are searched)"));
    }
    // Segment between two lattice poses: dense inverse kinematics.
    let mut cells: Option<Vec<[i32; 3]>> = None;
    for round in 0..settings.max_rounds {
        stats.search_rounds = round + 1;
        let report = solve(&lattice, &Deadline::expansions(settings.max_expansions));
        stats.expansions += report.stats.expansions;
        let Some(plan) = report.outcome.solved().cloned() else {
            break;
        };
        let mut ok = true;
        for w in plan.states.windows(2) {
            let (Some(qa), Some(qb)) = (
                lattice.configurations.borrow().get(&w[0]).cloned().flatten(),
                lattice.configurations.borrow().get(&w[1]).cloned().flatten(),
            ) else {
                ok = false;
                break;
            };
            let (pa, pb) = (lattice.pose(w[0]), lattice.pose(w[1]));
            let targets = |s: f64| grasp_at(&interpolate_pose(&pa, &pb, s));
            let good = follow(robot, &held, ee, &targets, &qa, 5, settings.max_joint_jump, &mut checks)
                .is_ok_and(|p| p.last().is_some_and(|q| largest_jump(robot, q, &qb) < 1e-3));
            if !good {
                lattice.blocked.insert((w[0], w[1]));
                lattice.blocked.insert((w[1], w[0]));
                stats.edges_rejected += 1;
                ok = false;
            }
        }
        if ok {
            cells = Some(plan.states);
            break;
        }
    }
    stats.lattice_poses = lattice.configurations.borrow().len();
    stats.ik_failures = *lattice.ik_failures.borrow();
    checks += *lattice.checks.borrow();
    let cells = cells.ok_or_else(|| {
        failed(format!(
            "no path for the object: {} lattice poses, {} rejected edges, {} search rounds",
            stats.lattice_poses, stats.edges_rejected, stats.search_rounds
        ))
    })?;
    stats.lattice_steps = cells.len().saturating_sub(1);

    // Shortcut: from each kept pose, the farthest later lattice pose reachable in a straight
    // line (dense inverse kinematics, no collision, no branch jump).
    let mut keep = vec![0usize];
    let mut at = 0usize;
    let mut q_at = q_grasp.clone();
    while at + 1 < cells.len() {
        let pa = lattice.pose(cells[at]);
        let mut chosen = (at + 1, None);
        for j in (at + 2..cells.len()).rev() {
            let pb = lattice.pose(cells[j]);
            let length = (pb.translation.vector - pa.translation.vector).norm();
            let n = (length / 0.01).ceil().max(1.0) as usize;
            let targets = |s: f64| grasp_at(&interpolate_pose(&pa, &pb, s));
            let wanted = cells[at..=j].iter().map(|c| lattice.clearance(*c)).fold(settings.clearance, f64::min);
            if let Ok(p) = follow(robot, &held, ee, &targets, &q_at, n, settings.max_joint_jump, &mut checks) {
                checks += p.len() as u64;
                if p.iter().all(|q| clear.distance(q).distance >= wanted - 1e-9) {
                    chosen = (j, p.last().cloned());
                    break;
                }
            }
        }
        let (j, q_end) = chosen;
        q_at = match q_end {
            Some(q) => q,
            None => lattice.configurations.borrow().get(&cells[j]).cloned().flatten().unwrap_or(q_at),
        };
        keep.push(j);
        at = j;
    }
    let object_poses: Vec<Isometry3<f64>> = keep.iter().map(|&k| lattice.pose(cells[k])).collect();
    stats.object_segments = object_poses.len().saturating_sub(1);
    stats.object_path_m =
        object_poses.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();

    // The timed trajectory.
    let mut traj = approach_traj;
    let mut waypoints: Vec<Vec<f64>> = approach.path.clone();
    append_followed(&mut traj, &backwards, settings.dt);
    waypoints.push(q_grasp.clone());
    let grasp_s = traj.duration();
    let mut q = q_grasp.clone();
    for w in object_poses.windows(2) {
        let (pa, pb) = (w[0], w[1]);
        let targets = |s: f64| grasp_at(&interpolate_pose(&pa, &pb, s));
        let (samples, _) = timed_follow(robot, &held, ee, &targets, &q, settings, &mut checks)
            .map_err(|e| failed(format!("carrying the object: {e}")))?;
        append_followed(&mut traj, &samples, settings.dt);
        if let Some(last) = samples.last() {
            q = last.clone();
        }
        waypoints.push(q.clone());
    }
    let release_s = traj.duration();
    let [r0, r1] = grasp_at(&task.object_goal);
    let retreat = |s: f64| {
        let [a0, a1] = backed(&task.object_goal);
        [interpolate_pose(&r0, &a0, s), interpolate_pose(&r1, &a1, s)]
    };
    let (samples, _) = timed_follow(robot, &free_goal, ee, &retreat, &q, settings, &mut checks)
        .map_err(|e| failed(format!("backing out at the goal: {e}")))?;
    append_followed(&mut traj, &samples, settings.dt);
    if let Some(last) = samples.last() {
        waypoints.push(last.clone());
    }
    stats.collision_checks += checks;
    stats.planning_ms = started.elapsed().as_secs_f64() * 1e3;
    let names = robot.end_effectors();
    Ok(CarryPlan {
        trajectory: traj,
        waypoints,
        span: ClosedChainSpan {
            from_s: grasp_s,
            to_s: release_s,
            end_effectors: [names[ee[0]].name.clone(), names[ee[1]].name.clone()],
            tolerance_m: settings.tolerance_m,
            tolerance_rad: settings.tolerance_rad,
            object: Some(object),
        },
        object_path: object_poses.iter().map(|p| p.translation.vector.into()).collect(),
        stats,
    })
}

/// Append samples one control step apart that start and end at rest; velocities by central
/// differences (zero at the last sample, which the quintic law reaches at rest).
fn append_followed(traj: &mut Trajectory, samples: &[Vec<f64>], dt: f64) {
    let t0 = traj.duration();
    let Some(before) = traj.q.last().cloned() else { return };
    for (k, q) in samples.iter().enumerate() {
        let prev = if k == 0 { &before } else { &samples[k - 1] };
        let qd = match samples.get(k + 1) {
            Some(next) => next.iter().zip(prev).map(|(b, a)| (b - a) / (2.0 * dt)).collect(),
            None => vec![0.0; q.len()],
        };
        traj.t.push(t0 + (k + 1) as f64 * dt);
        traj.q.push(q.clone());
        traj.qd.push(qd);
    }
}
