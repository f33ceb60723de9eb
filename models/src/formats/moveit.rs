//! MoveIt planning scenes and motion plan requests in YAML, as MotionBenchMaker distributes them.
//!
//! A planning scene (`sceneNNNN.yaml`) gives `world.collision_objects`: each object has an `id`,
//! an optional `header.frame_id`, an optional `pose`, and `primitives` (`box`, `sphere`,
//! `cylinder`) with one `primitive_poses` entry each. The pose of a primitive in the scene frame is
//! `object pose * primitive pose` (MoveIt's convention since the object `pose` field exists; files
//! without it give the primitive poses directly). Dimensions follow `shape_msgs/SolidPrimitive`:
//! a box has its full sizes `[x, y, z]`, a cylinder `[height, radius]` along its z axis, a sphere
//! `[radius]`. Cones are not supported (the collision checker has no cone) and are refused with a
//! clear error rather than approximated.
//!
//! A motion plan request (`requestNNNN.yaml`) gives `group_name`, `start_state.joint_state`
//! (`name[]`, `position[]`) and `goal_constraints[]`, alternatives each made of
//! `joint_constraints[]` (`joint_name`, `position`, optional `tolerance_above`/`tolerance_below`),
//! `position_constraints[]` (`link_name`, `target_point_offset`, `constraint_region` of box,
//! sphere or cylinder primitives, `header.frame_id`) and `orientation_constraints[]`
//! (`link_name`, `orientation`, `absolute_{x,y,z}_axis_tolerance`, `parameterization`).
//! [`MotionRequest::resolve`] turns it into a start configuration over the group's joints
//! (resolved through the SRDF), the values at which every other degree of freedom is frozen, and
//! each goal alternative either as a configuration (joint constraints on every joint of the
//! group) or as a [`PoseGoal`] in the world frame (one link's position and/or orientation, with
//! any joint constraints of the same entry as bounds). Visibility constraints are refused.
//!
//! Positions and orientations may be written as lists (`[x, y, z]`, `[x, y, z, w]`, as
//! MotionBenchMaker does) or as mappings (`{x: .., y: .., z: ..}`, as `rostopic echo` does).
//! Every error names `file:line:column` (1-based) and what was expected there.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::formats::moveit::parse_scene;
//! let text = "world:\n  collision_objects:\n    - id: table\n      primitives:\n        - type: box\n          dimensions: [1.0, 2.0, 0.1]\n      primitive_poses:\n        - position: [0.5, 0, 0.4]\n          orientation: [0, 0, 0, 1]\n";
//! let scene = parse_scene(text, Path::new("scene.yaml")).unwrap();
//! let obstacles = scene.obstacles();
//! assert_eq!(obstacles[0].name, "table");
//! assert!((obstacles[0].pose.translation.vector.z - 0.4).abs() < 1e-12);
//! ```

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::srdf::Srdf;
use crate::collision::{Environment, Obstacle};
use crate::error::{ModelError, Warning};
use crate::geometry::Shape;
use crate::robot::Robot;
use saphyr::{ScalarOwned, YamlDataOwned};

pub use super::yaml::Location;
use super::yaml::{Doc, Node, YamlError, describe, is_null};

/// How far past a joint's position limit a request's start or goal value may lie and be taken at
/// the limit (rad or m): a limit written with six significant digits, such as 3.14159 for pi in
/// VAMP's spherized Fetch, is this close to the value it stands for.
pub const LIMIT_ROUNDING: f64 = 1e-5;

/// What can go wrong reading a MoveIt scene or request.
pub type MoveitError = YamlError;

/// A `sensor_msgs/JointState` (names and positions only).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// Joint names.
    pub names: Vec<String>,
    /// Joint positions (rad or m), in the order of `names`.
    pub positions: Vec<f64>,
    /// Where each name stands in the file (same order as `names`).
    pub locations: Vec<Location>,
}

impl JointState {
    /// The position given for `joint`, if any.
    pub fn get(&self, joint: &str) -> Option<f64> {
        self.names.iter().position(|n| n == joint).map(|i| self.positions[i])
    }
}

/// One solid primitive of a collision object, placed in the scene frame.
#[derive(Debug, Clone)]
pub struct Primitive {
    /// `object pose * primitive pose`.
    pub pose: Isometry3<f64>,
    /// The primitive's shape, in its own frame.
    pub shape: Shape,
}

/// A `moveit_msgs/CollisionObject` with its primitives.
#[derive(Debug, Clone)]
pub struct CollisionObject {
    /// The object's `id`.
    pub id: String,
    /// `header.frame_id` (empty when absent).
    pub frame_id: String,
    /// The object's solid primitives.
    pub primitives: Vec<Primitive>,
    /// Where the object starts in the file.
    pub location: Location,
}

/// A `moveit_msgs/PlanningScene`: the world's collision objects and the robot state, if given.
#[derive(Debug, Clone)]
pub struct PlanningScene {
    /// The file the scene was read from.
    pub file: PathBuf,
    /// The scene's `name` (empty when absent).
    pub name: String,
    /// The world's collision objects.
    pub objects: Vec<CollisionObject>,
    /// The robot state's joint positions, if the scene gives one.
    pub robot_state: Option<JointState>,
    /// Pairs of links the scene's `allowed_collision_matrix` lets touch (its `entry_values` true
    /// in either direction), each pair once, in matrix order. The `default_entry_*` fields are
    /// not read.
    pub allowed_collisions: Vec<(String, String)>,
}

/// A joint-space goal on one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointGoal {
    /// The joint's name.
    pub joint: String,
    /// Goal position (rad or m).
    pub position: f64,
    /// Allowed excess above `position` (rad or m).
    pub tolerance_above: f64,
    /// Allowed shortfall below `position` (rad or m).
    pub tolerance_below: f64,
    /// Where the constraint stands in the file.
    pub location: Location,
}

/// A `moveit_msgs/PositionConstraint`: the point `offset` (in `link`'s frame) must lie in
/// `region`, the union of the constraint region's primitives, posed in frame `frame_id`.
#[derive(Debug, Clone)]
pub struct PositionGoal {
    /// The constrained link (`link_name`).
    pub link: String,
    /// `header.frame_id` of the region (empty when absent: the world frame).
    pub frame_id: String,
    /// `target_point_offset`: the constrained point in the link's frame.
    pub offset: [f64; 3],
    /// `constraint_region.primitives` at their `primitive_poses`, in frame `frame_id`.
    pub region: Vec<Primitive>,
    /// Where the constraint stands in the file.
    pub location: Location,
}

/// A `moveit_msgs/OrientationConstraint`: `link`'s orientation within the tolerances of
/// `orientation` (in frame `frame_id`).
#[derive(Debug, Clone)]
pub struct OrientationGoal {
    /// The constrained link (`link_name`).
    pub link: String,
    /// `header.frame_id` of the orientation (empty when absent: the world frame).
    pub frame_id: String,
    /// The wanted orientation.
    pub orientation: UnitQuaternion<f64>,
    /// `absolute_x_axis_tolerance`, `absolute_y_axis_tolerance`, `absolute_z_axis_tolerance` (rad).
    pub tolerance: [f64; 3],
    /// `parameterization`: `true` for a rotation vector (1), `false` for XYZ Euler angles (0,
    /// MoveIt's default).
    pub rotation_vector: bool,
    /// Where the constraint stands in the file.
    pub location: Location,
}

/// One entry of `goal_constraints` (a `moveit_msgs/Constraints`): all of its constraints must
/// hold at once. The entries of a request are alternatives: reaching any one is the goal.
#[derive(Debug, Clone)]
pub struct GoalConstraints {
    /// `joint_constraints`, in file order.
    pub joints: Vec<JointGoal>,
    /// `position_constraints`.
    pub positions: Vec<PositionGoal>,
    /// `orientation_constraints`.
    pub orientations: Vec<OrientationGoal>,
    /// Where the entry stands in the file.
    pub location: Location,
}

/// A `moveit_msgs/MotionPlanRequest` with a joint-space or link-pose goal.
#[derive(Debug, Clone)]
pub struct MotionRequest {
    /// The file the request was read from.
    pub file: PathBuf,
    /// The planning group (`group_name`).
    pub group_name: String,
    /// Where `group_name` stands in the file.
    pub group_location: Location,
    /// The start state (`start_state.joint_state`).
    pub start: JointState,
    /// `goal_constraints`: alternatives, each a set of joint, position and orientation
    /// constraints.
    pub goals: Vec<GoalConstraints>,
    /// The requested planner (`planner_id`), if given.
    pub planner_id: Option<String>,
    /// The requested planning time budget (s), if given.
    pub allowed_planning_time: Option<f64>,
}

/// A request made concrete for one robot: the group's degrees of freedom, in the robot's joint
/// order, with start and goal values, and the value of every other degree of freedom.
#[derive(Debug, Clone)]
pub struct ResolvedRequest {
    /// The group's joints, in the robot's degree-of-freedom order.
    pub joint_names: Vec<String>,
    /// Start configuration over `joint_names`.
    pub start: Vec<f64>,
    /// The first goal alternative when it is a configuration (over `joint_names`), as
    /// MotionBenchMaker's requests give it; empty when it is a link pose (see `goals`).
    pub goal: Vec<f64>,
    /// Every goal alternative (`goal_constraints` in order): reaching any one is the goal.
    pub goals: Vec<ResolvedGoal>,
    /// Every degree of freedom of the robot outside the group, with the value it keeps.
    pub frozen: Vec<(String, f64)>,
    /// What was ignored or changed: joints the start state names that the robot does not have,
    /// start and goal values taken at a limit they were just past (see [`LIMIT_ROUNDING`]).
    pub warnings: Vec<Warning>,
}

/// A goal alternative of a request made concrete.
#[derive(Debug, Clone)]
pub enum ResolvedGoal {
    /// Every joint of the group at these values (over the group's joints).
    Configuration(Vec<f64>),
    /// A link's position and/or orientation, in the world frame.
    Pose(PoseGoal),
}

/// An orientation constraint in the world frame.
#[derive(Debug, Clone)]
pub struct OrientationTarget {
    /// The wanted orientation of the link, world frame.
    pub orientation: UnitQuaternion<f64>,
    /// Largest error about x, y and z (rad), in the parameterisation below.
    pub tolerance: [f64; 3],
    /// The error as a rotation vector (`true`) or as XYZ Euler angles (`false`).
    pub rotation_vector: bool,
}

/// Slack on a goal's regions and tolerances (m, rad): a solution found by numerical inverse
/// kinematics to 1e-6 satisfies a region of zero size.
pub const POSE_GOAL_SLACK: f64 = 1e-5;

/// A link-pose goal (`position_constraints` and `orientation_constraints` of one entry), world
/// frame. The error of the orientation is that of MoveIt's `OrientationConstraint`: the rotation
/// `wanted⁻¹ · actual`, as a rotation vector or as XYZ Euler angles (`R = Rx(a) Ry(b) Rz(c)`),
/// each component within its tolerance.
#[derive(Debug, Clone)]
pub struct PoseGoal {
    /// The constrained link.
    pub link: String,
    /// The constrained point in the link's frame (`target_point_offset`).
    pub offset: Vector3<f64>,
    /// The point must lie in one of these primitives (world frame); empty: no position goal.
    pub region: Vec<Primitive>,
    /// The orientation goal, if any.
    pub orientation: Option<OrientationTarget>,
    /// Joint constraints of the same entry: (index among the group's joints, lowest, highest).
    pub joints: Vec<(usize, f64, f64)>,
}

impl PoseGoal {
    /// The pose aimed at: the first region's centre (or `None` without a position goal) and
    /// the wanted orientation (or `None` without one).
    pub fn aim(&self) -> (Option<Vector3<f64>>, Option<UnitQuaternion<f64>>) {
        (self.region.first().map(|r| r.pose.translation.vector), self.orientation.as_ref().map(|o| o.orientation))
    }

    /// Why configuration `q` of `robot` (over the group's joints, its other joints frozen)
    /// misses this goal, or `None` when it meets it (within [`POSE_GOAL_SLACK`]).
    pub fn miss(&self, robot: &Robot, q: &[f64]) -> Option<String> {
        let Some(link) = robot.link_index(&self.link) else {
            return Some(format!("robot `{}` has no link `{}`", robot.name(), self.link));
        };
        for &(i, lo, hi) in &self.joints {
            let v = q.get(i).copied().unwrap_or(f64::NAN);
            if !(v >= lo - POSE_GOAL_SLACK && v <= hi + POSE_GOAL_SLACK) {
                return Some(format!("joint {i} at {v:.6}, outside its goal [{lo:.6}, {hi:.6}]"));
            }
        }
        let pose = robot.link_pose(q, link);
        if !self.region.is_empty() {
            let point = pose * Point3::from(self.offset);
            let inside = self.region.iter().any(|r| {
                let p = r.pose.inverse_transform_point(&point);
                let s = POSE_GOAL_SLACK;
                match &r.shape {
                    Shape::Sphere { radius } => p.coords.norm() <= radius + s,
                    Shape::Cuboid { half_extents } => {
                        p.x.abs() <= half_extents.x + s
                            && p.y.abs() <= half_extents.y + s
                            && p.z.abs() <= half_extents.z + s
                    }
                    Shape::Cylinder { radius, half_height } => {
                        (p.x * p.x + p.y * p.y).sqrt() <= radius + s && p.z.abs() <= half_height + s
                    }
                    _ => false,
                }
            });
            if !inside {
                let centre = self.region[0].pose.translation.vector;
                return Some(format!(
                    "link `{}`'s point is {:.6} m from the region's centre, outside the region",
                    self.link,
                    (point.coords - centre).norm()
                ));
            }
        }
        if let Some(o) = &self.orientation {
            let e = orientation_error(&o.orientation, &pose.rotation, o.rotation_vector);
            if (0..3).any(|k| e[k].is_nan() || e[k].abs() > o.tolerance[k] + POSE_GOAL_SLACK) {
                return Some(format!(
                    "link `{}`'s orientation error ({:.6}, {:.6}, {:.6}) rad exceeds the tolerances {:?}",
                    self.link, e[0], e[1], e[2], o.tolerance
                ));
            }
        }
        None
    }
}

/// The error `wanted⁻¹ · actual` as a rotation vector or as XYZ Euler angles
/// (`R = Rx(a) Ry(b) Rz(c)`, each in (-π, π]).
pub fn orientation_error(
    wanted: &UnitQuaternion<f64>,
    actual: &UnitQuaternion<f64>,
    rotation_vector: bool,
) -> [f64; 3] {
    let diff = wanted.inverse() * actual;
    if rotation_vector {
        let v = diff.scaled_axis();
        return [v.x, v.y, v.z];
    }
    let r = diff.to_rotation_matrix();
    let m = r.matrix();
    let b = m[(0, 2)].clamp(-1.0, 1.0).asin();
    let a = (-m[(1, 2)]).atan2(m[(2, 2)]);
    let c = (-m[(0, 1)]).atan2(m[(0, 0)]);
    [a, b, c]
}

impl ResolvedRequest {
    /// The robot with every non-group degree of freedom frozen: its joints are `joint_names`.
    pub fn planning_robot(&self, robot: &Robot) -> Result<Robot, ModelError> {
        let frozen: Vec<(&str, f64)> = self.frozen.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        let arm = robot.freeze_joints(&frozen)?;
        if arm.joint_names() != self.joint_names {
            return Err(ModelError::Invalid {
                robot: robot.name().to_string(),
                message: format!(
                    "freezing the non-group joints left {:?}, expected the group's joints {:?}",
                    arm.joint_names(),
                    self.joint_names
                ),
            });
        }
        Ok(arm)
    }
}

/// Read and parse a planning scene file.
pub fn load_scene(path: &Path) -> Result<PlanningScene, MoveitError> {
    let text = read(path)?;
    parse_scene(&text, path)
}

/// Read and parse a motion plan request file.
pub fn load_request(path: &Path) -> Result<MotionRequest, MoveitError> {
    let text = read(path)?;
    parse_request(&text, path)
}

fn read(path: &Path) -> Result<String, MoveitError> {
    super::limits::read_text_limited(path, super::limits::InputKind::Text)
        .map_err(|source| MoveitError::Io { file: path.to_path_buf(), source })
}

/// Parse planning-scene YAML; `file` names the source in error messages.
pub fn parse_scene(text: &str, file: &Path) -> Result<PlanningScene, MoveitError> {
    let doc = Doc::load(text, file)?;
    let root = doc.root()?;
    doc.expect_mapping(root, "a planning scene (a mapping with `world`, `robot_state`, ...)")?;
    let name = match doc.get(root, "name") {
        Some(n) if !is_null(n) => doc.string(n, "the scene's name")?,
        _ => String::new(),
    };
    let robot_state = match doc.get(root, "robot_state") {
        Some(rs) if !is_null(rs) => {
            doc.expect_mapping(rs, "the robot state")?;
            match doc.get(rs, "joint_state") {
                Some(js) if !is_null(js) => Some(doc.joint_state(js, "robot_state.joint_state")?),
                _ => None,
            }
        }
        _ => None,
    };
    let allowed_collisions = match doc.get(root, "allowed_collision_matrix").filter(|m| !is_null(m)) {
        Some(acm) => doc.allowed_collision_matrix(acm)?,
        None => Vec::new(),
    };
    let mut objects: Vec<CollisionObject> = Vec::new();
    if let Some(world) = doc.get(root, "world").filter(|w| !is_null(w)) {
        doc.expect_mapping(world, "the world (a mapping with `collision_objects`)")?;
        if let Some(list) = doc.get(world, "collision_objects").filter(|l| !is_null(l)) {
            for node in doc.seq(list, "collision_objects")? {
                let (object, remove) = doc.collision_object(node)?;
                if remove {
                    objects.retain(|o| o.id != object.id);
                } else if let Some(existing) = objects.iter_mut().find(|o| o.id == object.id) {
                    // ADD replaces an object of the same id; APPEND adds primitives to it.
                    existing.primitives.extend(object.primitives);
                } else {
                    objects.push(object);
                }
            }
        }
    }
    Ok(PlanningScene { file: file.to_path_buf(), name, objects, robot_state, allowed_collisions })
}

/// Parse motion-plan-request YAML; `file` names the source in error messages.
pub fn parse_request(text: &str, file: &Path) -> Result<MotionRequest, MoveitError> {
    let doc = Doc::load(text, file)?;
    let root = doc.root()?;
    doc.expect_mapping(root, "a motion plan request (a mapping with `group_name`, `start_state`, `goal_constraints`)")?;
    let group = doc.require(root, "group_name", "the planning group's name")?;
    let group_name = doc.string(group, "the planning group's name")?;
    let start = match doc.get(root, "start_state").filter(|s| !is_null(s)) {
        Some(ss) => {
            doc.expect_mapping(ss, "the start state")?;
            match doc.get(ss, "joint_state").filter(|j| !is_null(j)) {
                Some(js) => doc.joint_state(js, "start_state.joint_state")?,
                None => JointState::default(),
            }
        }
        None => JointState::default(),
    };
    let goals_node = doc.require(root, "goal_constraints", "the goal constraints (a list)")?;
    let entries = doc.seq(goals_node, "goal_constraints")?;
    if entries.is_empty() {
        return Err(doc.err(goals_node, "expected at least one entry in goal_constraints, got an empty list"));
    }
    let goals = entries.iter().map(|entry| doc.goal_constraints(entry)).collect::<Result<Vec<_>, _>>()?;
    let planner_id = match doc.get(root, "planner_id").filter(|n| !is_null(n)) {
        Some(n) => Some(doc.string(n, "the planner id")?),
        None => None,
    };
    let allowed_planning_time = match doc.get(root, "allowed_planning_time").filter(|n| !is_null(n)) {
        Some(n) => Some(doc.number(n, "the allowed planning time (s)")?),
        None => None,
    };
    Ok(MotionRequest {
        file: file.to_path_buf(),
        group_name,
        group_location: doc.loc(group),
        start,
        goals,
        planner_id,
        allowed_planning_time,
    })
}

impl MotionRequest {
    fn err_at(&self, at: Location, message: String) -> MoveitError {
        MoveitError::Parse { file: self.file.clone(), line: at.line, column: at.column, message }
    }

    fn warn_at(&self, at: Location, message: String) -> Warning {
        let line = u32::try_from(at.line).unwrap_or(u32::MAX);
        Warning { file: self.file.clone(), line, column: u32::try_from(at.column).unwrap_or(u32::MAX), message }
    }

    /// `value` of degree of freedom `d` of `robot`, taken at its limit when past it by at most
    /// [`LIMIT_ROUNDING`] or by at most the constraint's `tolerance` (below, above) that side (the
    /// nearest value MoveIt's joint-constraint sampler would draw): then with a warning at `at`.
    /// Any other value is kept as it is (a value past a limit makes the problem invalid).
    fn onto_limits(
        &self,
        robot: &Robot,
        d: usize,
        value: f64,
        (below, above): (f64, f64),
        (what, at): (&str, Location),
        warnings: &mut Vec<Warning>,
    ) -> f64 {
        let joint = robot.dof_joint(d);
        let (lo, hi) = (joint.limits.lower, joint.limits.upper);
        let onto = if value > hi && value - hi <= LIMIT_ROUNDING.max(below) {
            hi
        } else if value < lo && lo - value <= LIMIT_ROUNDING.max(above) {
            lo
        } else {
            return value;
        };
        warnings.push(self.warn_at(
            at,
            format!(
                "{what} joint `{}` value {value} is past its limit {onto} by {:.3e}; taken at the limit",
                joint.name,
                (value - onto).abs()
            ),
        ));
        onto
    }

    /// Entry `k` of the goal constraints over the group's joints: a configuration when it
    /// constrains joints only (every joint of the group), else a [`PoseGoal`] in the world frame.
    /// `dofs` holds the robot's index of each of `joint_names`. Joint values past a limit by at
    /// most [`LIMIT_ROUNDING`] are taken at the limit, with a warning in `warnings`.
    fn resolve_goal(
        &self,
        robot: &Robot,
        k: usize,
        entry: &GoalConstraints,
        (joint_names, dofs): (&[String], &[usize]),
        (start, frozen): (&[f64], &[(String, f64)]),
        warnings: &mut Vec<Warning>,
    ) -> Result<ResolvedGoal, MoveitError> {
        for g in &entry.joints {
            if !joint_names.contains(&g.joint) {
                return Err(self.err_at(
                    g.location,
                    format!(
                        "goal constrains joint `{}`, which is not a movable joint of group `{}` (its joints: {})",
                        g.joint,
                        self.group_name,
                        joint_names.join(", ")
                    ),
                ));
            }
        }
        if entry.positions.is_empty() && entry.orientations.is_empty() {
            let mut goal = Vec::with_capacity(joint_names.len());
            for (name, &d) in joint_names.iter().zip(dofs) {
                match entry.joints.iter().find(|g| &g.joint == name) {
                    Some(g) => {
                        let tolerance = (g.tolerance_below, g.tolerance_above);
                        goal.push(self.onto_limits(robot, d, g.position, tolerance, ("goal", g.location), warnings));
                    }
                    None => {
                        return Err(self.err_at(
                            entry.location,
                            format!(
                                "goal_constraints[{k}] does not constrain joint `{name}` of group `{}`",
                                self.group_name
                            ),
                        ));
                    }
                }
            }
            return Ok(ResolvedGoal::Configuration(goal));
        }
        // Frames are placed by the robot's forward kinematics at the start state.
        let mut full = robot.home().to_vec();
        for (name, value) in joint_names.iter().zip(start).chain(frozen.iter().map(|(n, v)| (n, v))) {
            if let Some(d) = robot.joint_names().iter().position(|j| j == name) {
                full[d] = *value;
            }
        }
        let root = robot.links().iter().find(|l| l.parent_joint.is_none()).map(|l| l.name.clone()).unwrap_or_default();
        let frame = |frame_id: &str, at: Location| -> Result<Isometry3<f64>, MoveitError> {
            let f = frame_id.trim_start_matches('/');
            if f.is_empty() || f == "world" || f == root {
                return Ok(Isometry3::identity());
            }
            match robot.link_index(f) {
                Some(l) => Ok(robot.link_pose(&full, l)),
                None => Err(self.err_at(
                    at,
                    format!(
                        "frame `{frame_id}` is neither the world, the root link `{root}` nor a link of robot `{}`",
                        robot.name()
                    ),
                )),
            }
        };
        let link = entry
            .positions
            .first()
            .map(|p| (&p.link, p.location))
            .or_else(|| entry.orientations.first().map(|o| (&o.link, o.location)));
        let Some((link, link_at)) = link else {
            return Err(self.err_at(entry.location, "expected a position or orientation constraint".into()));
        };
        if robot.link_index(link).is_none() {
            return Err(self.err_at(link_at, format!("robot `{}` has no link `{link}`", robot.name())));
        }
        let others = entry.positions.iter().map(|p| (&p.link, p.location));
        if let Some((other, at)) =
            others.chain(entry.orientations.iter().map(|o| (&o.link, o.location))).find(|(l, _)| *l != link)
        {
            return Err(self.err_at(
                at,
                format!(
                    "this goal constrains links `{link}` and `{other}`; a goal may constrain the pose of one link only"
                ),
            ));
        }
        if entry.positions.len() > 1 || entry.orientations.len() > 1 {
            return Err(self.err_at(
                entry.location,
                "expected at most one position and one orientation constraint per goal".into(),
            ));
        }
        let (offset, region) = match entry.positions.first() {
            Some(p) => {
                let f = frame(&p.frame_id, p.location)?;
                let region = p.region.iter().map(|r| Primitive { pose: f * r.pose, shape: r.shape.clone() }).collect();
                (Vector3::from(p.offset), region)
            }
            None => (Vector3::zeros(), Vec::new()),
        };
        let orientation = match entry.orientations.first() {
            Some(o) => {
                let f = frame(&o.frame_id, o.location)?;
                Some(OrientationTarget {
                    orientation: f.rotation * o.orientation,
                    tolerance: o.tolerance,
                    rotation_vector: o.rotation_vector,
                })
            }
            None => None,
        };
        let joints = entry
            .joints
            .iter()
            .filter_map(|g| {
                joint_names
                    .iter()
                    .position(|n| n == &g.joint)
                    .map(|i| (i, g.position - g.tolerance_below, g.position + g.tolerance_above))
            })
            .collect();
        Ok(ResolvedGoal::Pose(PoseGoal { link: link.clone(), offset, region, orientation, joints }))
    }

    /// Resolve the request for `robot`: the group's joints come from the SRDF; start values come
    /// from the request's start state, else from `scene_state` (the scene's robot state, which the
    /// request's start state amends, as in MoveIt), else from the robot's home configuration. The
    /// goal must constrain every joint of the group and only those.
    pub fn resolve(
        &self,
        robot: &Robot,
        srdf: &Srdf,
        scene_state: Option<&JointState>,
    ) -> Result<ResolvedRequest, MoveitError> {
        let group_joints = srdf.group_joints(robot, &self.group_name).map_err(|e| {
            self.err_at(self.group_location, format!("cannot resolve group `{}`: {e}", self.group_name))
        })?;
        if group_joints.is_empty() {
            return Err(self.err_at(
                self.group_location,
                format!("group `{}` has no movable joints in robot `{}`", self.group_name, robot.name()),
            ));
        }
        // A joint the start state names and the robot does not have is ignored with a warning
        // (MotionBenchMaker's requests list every joint of the full model, which a spherized
        // model may have dropped: the Fetch's wheels), as long as every joint of the group still
        // has a value from the request or the scene. Otherwise the unknown name is most likely
        // that joint misspelt: an error at the name. (Fixed joints are known joints: a spherized
        // model may have fixed the gripper joints a full model moves.)
        let unknown: Vec<(&String, Location)> = self
            .start
            .names
            .iter()
            .zip(&self.start.locations)
            .filter(|(name, _)| robot.joint_index(name).is_none())
            .map(|(name, at)| (name, *at))
            .collect();
        let names = robot.joint_names();
        let home = robot.home();
        let given = |name: &str| self.start.get(name).or_else(|| scene_state.and_then(|s| s.get(name)));
        if let Some(&(_, at)) = unknown.first()
            && let Some(missing) = names.iter().find(|n| group_joints.contains(n) && given(n).is_none())
        {
            let unknown: Vec<String> = unknown.iter().map(|(name, _)| format!("`{name}`")).collect();
            return Err(self.err_at(
                at,
                format!(
                    "start state names {}, which robot `{}` does not have, and gives no value for `{missing}` of \
                     group `{}`",
                    unknown.join(", "),
                    robot.name(),
                    self.group_name
                ),
            ));
        }
        let mut warnings: Vec<Warning> = unknown
            .iter()
            .map(|&(name, at)| {
                self.warn_at(
                    at,
                    format!("start state names joint `{name}`, which robot `{}` does not have; ignored", robot.name()),
                )
            })
            .collect();
        let value_of = |i: usize, name: &str| -> f64 { given(name).unwrap_or(home[i]) };
        let mut joint_names = Vec::new();
        let mut dofs = Vec::new();
        let mut start = Vec::new();
        let mut frozen = Vec::new();
        for (i, name) in names.iter().enumerate() {
            if group_joints.contains(name) {
                let at = self
                    .start
                    .names
                    .iter()
                    .position(|n| n == name)
                    .map_or(self.group_location, |k| self.start.locations[k]);
                joint_names.push(name.clone());
                dofs.push(i);
                start.push(self.onto_limits(robot, i, value_of(i, name), (0.0, 0.0), ("start", at), &mut warnings));
            } else {
                frozen.push((name.clone(), value_of(i, name)));
            }
        }
        let mut goals = Vec::with_capacity(self.goals.len());
        for (k, entry) in self.goals.iter().enumerate() {
            goals.push(self.resolve_goal(robot, k, entry, (&joint_names, &dofs), (&start, &frozen), &mut warnings)?);
        }
        let goal = match goals.first() {
            Some(ResolvedGoal::Configuration(q)) => q.clone(),
            _ => Vec::new(),
        };
        Ok(ResolvedRequest { joint_names, start, goal, goals, frozen, warnings })
    }
}

impl PlanningScene {
    /// One obstacle per primitive, named by the object id (`id/k` for the k-th primitive of an
    /// object that has several), posed in the scene frame.
    pub fn obstacles(&self) -> Vec<Obstacle> {
        let mut out = Vec::new();
        for o in &self.objects {
            for (k, p) in o.primitives.iter().enumerate() {
                let name = if o.primitives.len() == 1 { o.id.clone() } else { format!("{}/{k}", o.id) };
                out.push(Obstacle::new(name, p.pose, p.shape.clone()));
            }
        }
        out
    }

    /// The obstacles as a collision [`Environment`].
    pub fn environment(&self) -> Environment {
        let mut env = Environment::new();
        for o in self.obstacles() {
            env.add(o);
        }
        env
    }

    /// Disable self-collision checking between the link pairs the scene's allowed collision
    /// matrix allows (names the robot does not have, e.g. links of another model, are skipped).
    /// Returns how many pairs were disabled.
    pub fn apply_allowed_collisions(&self, robot: &mut Robot) -> usize {
        let mut n = 0;
        for (a, b) in &self.allowed_collisions {
            if let (Some(la), Some(lb)) = (robot.link_index(a), robot.link_index(b)) {
                robot.disable_pair(la, lb);
                n += 1;
            }
        }
        n
    }

    /// Check that every object is expressed in the robot's world frame: an empty `frame_id`,
    /// `world`, or the robot's root link (MotionBenchMaker scenes put the URDF root at the world
    /// origin). Objects attached to other frames are refused rather than misplaced.
    pub fn check_frames(&self, robot: &Robot) -> Result<(), MoveitError> {
        let root = robot.links().iter().find(|l| l.parent_joint.is_none()).map(|l| l.name.as_str()).unwrap_or("");
        for o in &self.objects {
            let f = o.frame_id.trim_start_matches('/');
            if !(f.is_empty() || f == "world" || f == root) {
                return Err(MoveitError::Parse {
                    file: self.file.clone(),
                    line: o.location.line,
                    column: o.location.column,
                    message: format!(
                        "object `{}` is in frame `{}`; only the world frame (``, `world` or the root link `{root}`) is supported",
                        o.id, o.frame_id
                    ),
                });
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// MoveIt messages read with positions.

impl Doc<'_> {
    fn joint_state(&self, js: &Node, what: &str) -> Result<JointState, MoveitError> {
        self.expect_mapping(js, &format!("{what} (a mapping with `name` and `position`)"))?;
        let Some(names_node) = self.get(js, "name").filter(|n| !is_null(n)) else {
            return Ok(JointState::default());
        };
        let mut names = Vec::new();
        let mut locations = Vec::new();
        for n in self.seq(names_node, &format!("{what}.name"))? {
            let name = self.string(n, "a joint name")?;
            if names.contains(&name) {
                return Err(self.err(n, &format!("joint `{name}` appears twice in {what}.name")));
            }
            names.push(name);
            locations.push(self.loc(n));
        }
        let positions = match self.get(js, "position").filter(|n| !is_null(n)) {
            Some(p) => self.numbers(p, Some(names.len()), &format!("{what}.position (one per name)"))?,
            None if names.is_empty() => Vec::new(),
            None => return Err(self.err(js, &format!("missing `position` in {what} ({} names given)", names.len()))),
        };
        Ok(JointState { names, positions, locations })
    }

    fn allowed_collision_matrix(&self, acm: &Node) -> Result<Vec<(String, String)>, MoveitError> {
        self.expect_mapping(acm, "the allowed collision matrix (a mapping with `entry_names`, `entry_values`)")?;
        let names = match self.get(acm, "entry_names").filter(|n| !is_null(n)) {
            Some(n) => self
                .seq(n, "allowed_collision_matrix.entry_names")?
                .iter()
                .map(|x| self.string(x, "a link name"))
                .collect::<Result<Vec<_>, _>>()?,
            None => return Ok(Vec::new()),
        };
        let rows_node = self.require(acm, "entry_values", "one row of booleans per entry name")?;
        let rows = self.seq(rows_node, "allowed_collision_matrix.entry_values")?;
        if rows.len() != names.len() {
            return Err(self.err(
                rows_node,
                &format!("expected {} rows in entry_values (one per entry name), got {}", names.len(), rows.len()),
            ));
        }
        let mut allowed = vec![vec![false; names.len()]; names.len()];
        for (i, row) in rows.iter().enumerate() {
            let cells = self.seq(row, "an allowed collision matrix row")?;
            if cells.len() != names.len() {
                return Err(self.err(
                    row,
                    &format!(
                        "expected a list of {} booleans for row `{}` of entry_values, got {}",
                        names.len(),
                        names[i],
                        cells.len()
                    ),
                ));
            }
            for (j, cell) in cells.iter().enumerate() {
                allowed[i][j] = match &cell.data {
                    YamlDataOwned::Value(ScalarOwned::Boolean(b)) => *b,
                    YamlDataOwned::Value(ScalarOwned::Integer(0)) => false,
                    YamlDataOwned::Value(ScalarOwned::Integer(1)) => true,
                    _ => {
                        return Err(
                            self.err(cell, &format!("expected true or false in entry_values, got {}", describe(cell)))
                        );
                    }
                };
            }
        }
        let mut pairs = Vec::new();
        for i in 0..names.len() {
            for j in i + 1..names.len() {
                if allowed[i][j] || allowed[j][i] {
                    pairs.push((names[i].clone(), names[j].clone()));
                }
            }
        }
        Ok(pairs)
    }

    fn pose(&self, n: &Node, what: &str) -> Result<Isometry3<f64>, MoveitError> {
        self.expect_mapping(n, &format!("{what} (a mapping with `position` and `orientation`)"))?;
        let position = match self.get(n, "position").filter(|p| !is_null(p)) {
            Some(p) => self.xyz(p, &["x", "y", "z"], &format!("{what} position"))?,
            None => vec![0.0; 3],
        };
        let orientation = match self.get(n, "orientation").filter(|o| !is_null(o)) {
            Some(o) => {
                let q = self.xyz(o, &["x", "y", "z", "w"], &format!("{what} orientation (quaternion x, y, z, w)"))?;
                let quat = Quaternion::new(q[3], q[0], q[1], q[2]);
                let norm = quat.norm();
                if norm <= 1e-6 {
                    return Err(
                        self.err(o, &format!("expected a non-zero quaternion for {what} orientation, got {q:?}"))
                    );
                }
                if (norm - 1.0).abs() > 1e-3 {
                    return Err(self.err(
                        o,
                        &format!("expected a unit quaternion for {what} orientation, got one of norm {norm:.6}"),
                    ));
                }
                UnitQuaternion::from_quaternion(quat)
            }
            None => UnitQuaternion::identity(),
        };
        Ok(Isometry3::from_parts(Translation3::new(position[0], position[1], position[2]), orientation))
    }

    /// `[x, y, z(, w)]` or `{x: .., y: .., ...}`.
    fn xyz(&self, n: &Node, keys: &[&str], what: &str) -> Result<Vec<f64>, MoveitError> {
        if n.data.is_mapping() {
            keys.iter()
                .map(|k| match self.get(n, k) {
                    Some(v) => self.number(v, &format!("{what} `{k}`")),
                    None => Ok(if *k == "w" { 1.0 } else { 0.0 }),
                })
                .collect()
        } else {
            self.numbers(n, Some(keys.len()), what)
        }
    }

    /// One collision object; the flag is true for a REMOVE operation.
    fn collision_object(&self, n: &Node) -> Result<(CollisionObject, bool), MoveitError> {
        self.expect_mapping(n, "a collision object (a mapping with `id`, `primitives`, `primitive_poses`)")?;
        let id = self.string(self.require(n, "id", "the object's id")?, "the object's id")?;
        let frame_id = match self.get(n, "header").filter(|h| !is_null(h)) {
            Some(h) => {
                self.expect_mapping(h, "the object's header")?;
                match self.get(h, "frame_id").filter(|f| !is_null(f)) {
                    Some(f) => self.string(f, "the header's frame_id")?,
                    None => String::new(),
                }
            }
            None => String::new(),
        };
        let remove = match self.get(n, "operation").filter(|o| !is_null(o)) {
            // moveit_msgs/CollisionObject: ADD=0, REMOVE=1, APPEND=2, MOVE=3.
            Some(op) => match &op.data {
                YamlDataOwned::Value(ScalarOwned::Integer(0 | 2 | 3)) => false,
                YamlDataOwned::Value(ScalarOwned::Integer(1)) => true,
                YamlDataOwned::Value(ScalarOwned::String(s)) | YamlDataOwned::Representation(s, _, _) => {
                    match s.to_ascii_lowercase().as_str() {
                        "add" | "append" | "move" => false,
                        "remove" => true,
                        _ => {
                            return Err(self.err(
                                op,
                                &format!(
                                    "expected an operation 0 (add), 1 (remove), 2 (append) or 3 (move), got `{s}`"
                                ),
                            ));
                        }
                    }
                }
                _ => {
                    return Err(self.err(
                        op,
                        &format!(
                            "expected an operation 0 (add), 1 (remove), 2 (append) or 3 (move), got {}",
                            describe(op)
                        ),
                    ));
                }
            },
            None => false,
        };
        let object_pose = match self.get(n, "pose").filter(|p| !is_null(p)) {
            Some(p) => self.pose(p, &format!("object `{id}` pose"))?,
            None => Isometry3::identity(),
        };
        for unsupported in ["meshes", "planes"] {
            if let Some(m) = self.get(n, unsupported)
                && !is_null(m)
                && !self.seq(m, unsupported)?.is_empty()
            {
                return Err(self.err(
                    m,
                    &format!("object `{id}` has {unsupported}, which are not supported (only box, sphere and cylinder primitives)"),
                ));
            }
        }
        let mut primitives = Vec::new();
        let prims = match self.get(n, "primitives").filter(|p| !is_null(p)) {
            Some(p) => self.seq(p, &format!("object `{id}` primitives"))?,
            None => &[],
        };
        if !prims.is_empty() {
            let poses_node = self.require(n, "primitive_poses", "one pose per primitive")?;
            let poses = self.seq(poses_node, &format!("object `{id}` primitive_poses"))?;
            if poses.len() != prims.len() {
                return Err(self.err(
                    poses_node,
                    &format!(
                        "expected {} primitive pose{} (one per primitive of object `{id}`), got {}",
                        prims.len(),
                        if prims.len() == 1 { "" } else { "s" },
                        poses.len()
                    ),
                ));
            }
            for (prim, pose) in prims.iter().zip(poses) {
                let shape = self.primitive(prim, &format!("object `{id}`"))?;
                let local = self.pose(pose, &format!("object `{id}` primitive pose"))?;
                primitives.push(Primitive { pose: object_pose * local, shape });
            }
        }
        Ok((CollisionObject { id, frame_id, primitives, location: self.loc(n) }, remove))
    }

    /// One `goal_constraints` entry.
    fn goal_constraints(&self, entry: &Node) -> Result<GoalConstraints, MoveitError> {
        self.expect_mapping(
            entry,
            "a goal constraint (a mapping with `joint_constraints`, `position_constraints` or `orientation_constraints`)",
        )?;
        let list = |key: &str| -> Result<&[Node], MoveitError> {
            match self.get(entry, key).filter(|n| !is_null(n)) {
                Some(n) => self.seq(n, key),
                None => Ok(&[]),
            }
        };
        if let Some(v) = self.get(entry, "visibility_constraints")
            && !list("visibility_constraints")?.is_empty()
        {
            return Err(self.err(
                v,
                "visibility_constraints are not supported: a goal is given by joint, position and orientation constraints",
            ));
        }
        let mut joints: Vec<JointGoal> = Vec::new();
        for c in list("joint_constraints")? {
            let goal = self.joint_goal(c)?;
            if joints.iter().any(|g| g.joint == goal.joint) {
                return Err(self.err(c, &format!("joint `{}` is constrained twice in the goal", goal.joint)));
            }
            joints.push(goal);
        }
        let positions =
            list("position_constraints")?.iter().map(|c| self.position_goal(c)).collect::<Result<_, _>>()?;
        let orientations =
            list("orientation_constraints")?.iter().map(|c| self.orientation_goal(c)).collect::<Result<_, _>>()?;
        Ok(GoalConstraints { joints, positions, orientations, location: self.loc(entry) })
    }

    fn joint_goal(&self, c: &Node) -> Result<JointGoal, MoveitError> {
        self.expect_mapping(c, "a joint constraint (a mapping with `joint_name` and `position`)")?;
        let name_node = self.require(c, "joint_name", "the constrained joint's name")?;
        let joint = self.string(name_node, "a joint name")?;
        let position =
            self.number(self.require(c, "position", "the joint's goal position")?, "a joint goal position")?;
        let tolerance_above = self.non_negative(c, "tolerance_above")?.unwrap_or(0.0);
        let tolerance_below = self.non_negative(c, "tolerance_below")?.unwrap_or(0.0);
        Ok(JointGoal { joint, position, tolerance_above, tolerance_below, location: self.loc(name_node) })
    }

    /// An optional non-negative number under `key`.
    fn non_negative(&self, map: &Node, key: &str) -> Result<Option<f64>, MoveitError> {
        match self.get(map, key).filter(|n| !is_null(n)) {
            Some(n) => {
                let v = self.number(n, key)?;
                if !v.is_finite() || v < 0.0 {
                    return Err(self.err(n, &format!("expected a finite non-negative {key}, got {v}")));
                }
                Ok(Some(v))
            }
            None => Ok(None),
        }
    }

    /// `header.frame_id` of a message, empty when absent.
    fn frame_id(&self, n: &Node) -> Result<String, MoveitError> {
        match self.get(n, "header").filter(|h| !is_null(h)) {
            Some(h) => {
                self.expect_mapping(h, "a header")?;
                match self.get(h, "frame_id").filter(|f| !is_null(f)) {
                    Some(f) => self.string(f, "the header's frame_id"),
                    None => Ok(String::new()),
                }
            }
            None => Ok(String::new()),
        }
    }

    fn position_goal(&self, c: &Node) -> Result<PositionGoal, MoveitError> {
        self.expect_mapping(c, "a position constraint (a mapping with `link_name` and `constraint_region`)")?;
        let link = self.string(self.require(c, "link_name", "the constrained link's name")?, "a link name")?;
        let frame_id = self.frame_id(c)?;
        let offset = match self.get(c, "target_point_offset").filter(|n| !is_null(n)) {
            Some(n) => {
                let v = self.xyz(n, &["x", "y", "z"], "target_point_offset")?;
                [v[0], v[1], v[2]]
            }
            None => [0.0; 3],
        };
        let region_node = self.require(c, "constraint_region", "the region the link's point must lie in")?;
        self.expect_mapping(region_node, "a constraint region (a mapping with `primitives` and `primitive_poses`)")?;
        let prims = match self.get(region_node, "primitives").filter(|n| !is_null(n)) {
            Some(p) => self.seq(p, "constraint_region primitives")?,
            None => &[],
        };
        if let Some(m) = self.get(region_node, "meshes").filter(|m| !is_null(m))
            && !self.seq(m, "constraint_region meshes")?.is_empty()
        {
            return Err(self.err(m, "mesh constraint regions are not supported (only box, sphere and cylinder)"));
        }
        if prims.is_empty() {
            return Err(self.err(
                region_node,
                &format!("expected at least one primitive in the constraint region of link `{link}`, got none"),
            ));
        }
        let poses_node = self.require(region_node, "primitive_poses", "one pose per primitive")?;
        let poses = self.seq(poses_node, "constraint_region primitive_poses")?;
        if poses.len() != prims.len() {
            return Err(self.err(
                poses_node,
                &format!("expected {} primitive poses (one per primitive), got {}", prims.len(), poses.len()),
            ));
        }
        let what = format!("the region of link `{link}`");
        let mut region = Vec::with_capacity(prims.len());
        for (prim, pose) in prims.iter().zip(poses) {
            region.push(Primitive { shape: self.primitive(prim, &what)?, pose: self.pose(pose, "a region pose")? });
        }
        Ok(PositionGoal { link, frame_id, offset, region, location: self.loc(c) })
    }

    fn orientation_goal(&self, c: &Node) -> Result<OrientationGoal, MoveitError> {
        self.expect_mapping(c, "an orientation constraint (a mapping with `link_name` and `orientation`)")?;
        let link = self.string(self.require(c, "link_name", "the constrained link's name")?, "a link name")?;
        let frame_id = self.frame_id(c)?;
        let o = self.require(c, "orientation", "the wanted orientation (quaternion x, y, z, w)")?;
        let pose = self.pose_of_orientation(o)?;
        let mut tolerance = [0.0; 3];
        for (t, key) in tolerance.iter_mut().zip([
            "absolute_x_axis_tolerance",
            "absolute_y_axis_tolerance",
            "absolute_z_axis_tolerance",
        ]) {
            *t = self.non_negative(c, key)?.unwrap_or(0.0);
        }
        // moveit_msgs/OrientationConstraint: XYZ_EULER_ANGLES = 0, ROTATION_VECTOR = 1.
        let rotation_vector = match self.get(c, "parameterization").filter(|n| !is_null(n)) {
            Some(p) => match self.number(p, "the parameterization")? {
                0.0 => false,
                1.0 => true,
                v => {
                    return Err(self.err(
                        p,
                        &format!("expected parameterization 0 (XYZ Euler angles) or 1 (rotation vector), got {v}"),
                    ));
                }
            },
            None => false,
        };
        Ok(OrientationGoal { link, frame_id, orientation: pose, tolerance, rotation_vector, location: self.loc(c) })
    }

    /// A quaternion as the orientation of a pose (same checks as a pose's).
    fn pose_of_orientation(&self, o: &Node) -> Result<UnitQuaternion<f64>, MoveitError> {
        let q = self.xyz(o, &["x", "y", "z", "w"], "the orientation (quaternion x, y, z, w)")?;
        let quat = Quaternion::new(q[3], q[0], q[1], q[2]);
        let norm = quat.norm();
        if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
            return Err(self.err(o, &format!("expected a unit quaternion (x, y, z, w), got {q:?} of norm {norm:.6}")));
        }
        Ok(UnitQuaternion::from_quaternion(quat))
    }

    fn primitive(&self, n: &Node, owner: &str) -> Result<Shape, MoveitError> {
        self.expect_mapping(n, "a solid primitive (a mapping with `type` and `dimensions`)")?;
        let type_node = self.require(n, "type", "box, sphere or cylinder")?;
        // shape_msgs/SolidPrimitive: BOX=1, SPHERE=2, CYLINDER=3, CONE=4 (also accepted as numbers).
        let kind = match &type_node.data {
            YamlDataOwned::Value(ScalarOwned::Integer(1)) => "box".to_string(),
            YamlDataOwned::Value(ScalarOwned::Integer(2)) => "sphere".to_string(),
            YamlDataOwned::Value(ScalarOwned::Integer(3)) => "cylinder".to_string(),
            YamlDataOwned::Value(ScalarOwned::Integer(4)) => "cone".to_string(),
            _ => self.string(type_node, "the primitive type")?.to_ascii_lowercase(),
        };
        let dims_node = self.require(n, "dimensions", "the primitive's dimensions")?;
        let positive = |dims: Vec<f64>, what: &str| -> Result<Vec<f64>, MoveitError> {
            if let Some(bad) = dims.iter().find(|d| **d <= 0.0) {
                return Err(self.err(dims_node, &format!("expected positive {what} of {owner}, got {bad}")));
            }
            Ok(dims)
        };
        match kind.as_str() {
            "box" => {
                let d = positive(self.numbers(dims_node, Some(3), "box dimensions")?, "box dimensions")?;
                Ok(Shape::cuboid(d[0] / 2.0, d[1] / 2.0, d[2] / 2.0))
            }
            "sphere" => {
                let d = positive(self.numbers(dims_node, Some(1), "sphere dimensions [radius]")?, "sphere radius")?;
                Ok(Shape::sphere(d[0]))
            }
            "cylinder" => {
                let d = positive(
                    self.numbers(dims_node, Some(2), "cylinder dimensions [height, radius]")?,
                    "cylinder dimensions",
                )?;
                Ok(Shape::cylinder(d[1], d[0] / 2.0))
            }
            "cone" => Err(self.err(
                type_node,
                &format!("{owner} has a cone primitive, which is not supported (expected box, sphere or cylinder)"),
            )),
            other => {
                Err(self.err(type_node, &format!("expected a primitive type box, sphere or cylinder, got `{other}`")))
            }
        }
    }
}
