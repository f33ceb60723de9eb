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
//! (`name[]`, `position[]`) and `goal_constraints[0].joint_constraints[]` (`joint_name`,
//! `position`, optional `tolerance_above`/`tolerance_below`). [`MotionRequest::resolve`] turns it
//! into a start and goal configuration over the group's joints (resolved through the SRDF) plus the
//! values at which every other degree of freedom is frozen.
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

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::srdf::Srdf;
use crate::collision::{Environment, Obstacle};
use crate::error::ModelError;
use crate::geometry::Shape;
use crate::robot::Robot;
use saphyr::{ScalarOwned, YamlDataOwned};

pub use super::yaml::Location;
use super::yaml::{Doc, Node, YamlError, describe, is_null};

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

/// A `moveit_msgs/MotionPlanRequest` with a joint-space goal.
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
    /// `goal_constraints[0].joint_constraints`, in file order.
    pub goal: Vec<JointGoal>,
    /// The requested planner (`planner_id`), if given.
    pub planner_id: Option<String>,
    /// The requested planning time budget (s), if given.
    pub allowed_planning_time: Option<f64>,
}

/// A request made concrete for one robot: the group's degrees of freedom, in the robot's joint
/// order, with start and goal values, and the value of every other degree of freedom.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedRequest {
    /// The group's joints, in the robot's degree-of-freedom order.
    pub joint_names: Vec<String>,
    /// Start configuration over `joint_names`.
    pub start: Vec<f64>,
    /// Goal configuration over `joint_names`.
    pub goal: Vec<f64>,
    /// Every degree of freedom of the robot outside the group, with the value it keeps.
    pub frozen: Vec<(String, f64)>,
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
    let goals = doc.require(root, "goal_constraints", "the goal constraints (a list)")?;
    let goals = doc.seq(goals, "goal_constraints")?;
    let Some(first) = goals.first() else {
        return Err(doc.err(
            doc.require(root, "goal_constraints", "")?,
            "expected at least one entry in goal_constraints, got an empty list",
        ));
    };
    doc.expect_mapping(first, "a goal constraint (a mapping with `joint_constraints`)")?;
    for other in ["position_constraints", "orientation_constraints", "visibility_constraints"] {
        if let Some(n) = doc.get(first, other)
            && !is_null(n)
            && !doc.seq(n, other)?.is_empty()
        {
            return Err(doc.err(
                n,
                &format!("{other} are not supported: only joint-space goals (joint_constraints) can be planned to"),
            ));
        }
    }
    let jc = doc.require(first, "joint_constraints", "the goal's joint constraints")?;
    let mut goal = Vec::new();
    for c in doc.seq(jc, "joint_constraints")? {
        doc.expect_mapping(c, "a joint constraint (a mapping with `joint_name` and `position`)")?;
        let name_node = doc.require(c, "joint_name", "the constrained joint's name")?;
        let joint = doc.string(name_node, "a joint name")?;
        let position = doc.number(doc.require(c, "position", "the joint's goal position")?, "a joint goal position")?;
        let tol = |key: &str| -> Result<f64, MoveitError> {
            match doc.get(c, key).filter(|n| !is_null(n)) {
                Some(n) => {
                    let v = doc.number(n, key)?;
                    if v < 0.0 {
                        return Err(doc.err(n, &format!("expected a non-negative {key}, got {v}")));
                    }
                    Ok(v)
                }
                None => Ok(0.0),
            }
        };
        let (tolerance_above, tolerance_below) = (tol("tolerance_above")?, tol("tolerance_below")?);
        if goal.iter().any(|g: &JointGoal| g.joint == joint) {
            return Err(doc.err(name_node, &format!("joint `{joint}` is constrained twice in the goal")));
        }
        goal.push(JointGoal { joint, position, tolerance_above, tolerance_below, location: doc.loc(name_node) });
    }
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
        goal,
        planner_id,
        allowed_planning_time,
    })
}

impl MotionRequest {
    fn err_at(&self, at: Location, message: String) -> MoveitError {
        MoveitError::Parse { file: self.file.clone(), line: at.line, column: at.column, message }
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
        // Every joint the request names must exist in the robot (fixed joints are accepted: a
        // spherized model may have fixed the gripper joints a full model moves).
        for (name, at) in self.start.names.iter().zip(&self.start.locations) {
            if robot.joint_index(name).is_none() {
                return Err(self.err_at(
                    *at,
                    format!("start state names joint `{name}`, which robot `{}` does not have", robot.name()),
                ));
            }
        }
        let names = robot.joint_names();
        let home = robot.home();
        let value_of = |i: usize, name: &str| -> f64 {
            self.start.get(name).or_else(|| scene_state.and_then(|s| s.get(name))).unwrap_or(home[i])
        };
        let mut joint_names = Vec::new();
        let mut start = Vec::new();
        let mut frozen = Vec::new();
        for (i, name) in names.iter().enumerate() {
            if group_joints.contains(name) {
                joint_names.push(name.clone());
                start.push(value_of(i, name));
            } else {
                frozen.push((name.clone(), value_of(i, name)));
            }
        }
        for g in &self.goal {
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
        let mut goal = Vec::with_capacity(joint_names.len());
        for name in &joint_names {
            match self.goal.iter().find(|g| &g.joint == name) {
                Some(g) => goal.push(g.position),
                None => {
                    return Err(self.err_at(
                        self.group_location,
                        format!("goal_constraints[0] does not constrain joint `{name}` of group `{}`", self.group_name),
                    ));
                }
            }
        }
        Ok(ResolvedRequest { joint_names, start, goal, frozen })
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
                let shape = self.primitive(prim, &id)?;
                let local = self.pose(pose, &format!("object `{id}` primitive pose"))?;
                primitives.push(Primitive { pose: object_pose * local, shape });
            }
        }
        Ok((CollisionObject { id, frame_id, primitives, location: self.loc(n) }, remove))
    }

    fn primitive(&self, n: &Node, id: &str) -> Result<Shape, MoveitError> {
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
                return Err(self.err(dims_node, &format!("expected positive {what} of object `{id}`, got {bad}")));
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
                &format!(
                    "object `{id}` has a cone primitive, which is not supported (expected box, sphere or cylinder)"
                ),
            )),
            other => {
                Err(self.err(type_node, &format!("expected a primitive type box, sphere or cylinder, got `{other}`")))
            }
        }
    }
}
