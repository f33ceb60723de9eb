//! `embodied view`: a run or a plan as one self-contained HTML page with a 3-D scene.
//!
//! Everything is computed here: the pose of every link shape of every agent at each frame
//! (forward kinematics, frames every [`FRAME_S`] seconds), the obstacles' poses while they are
//! present, the carried object, the events and the clearance (the smallest distance between the
//! agents, with what they hold, and the obstacles and other agents). The result is a neutral
//! [`ViewScene`], embedded as JSON into the page; the page's script only draws it with three.js
//! (vendored in `src/view/assets/three/`, embedded in the binary), so the page opens offline.
//!
//! Sources: a plan file with its scenario ([`track_from_plan`]) or a run log
//! ([`read_run_log`]); both become a [`Track`] (timed configurations and events), from which
//! [`build_scene`] makes the scene.

use std::path::Path;

use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use embodied_models::{Robot, Shape};
use embodied_planner::carry::{CarriedObject, tool_pose};
use serde::Serialize;

use embodied_executor::Event;

use crate::SystemError as AppError;
use crate::plan::PlanFile;
use crate::scenario::Scenario;

/// Time between two frames of a view, s (40 frames per second).
pub const FRAME_S: f64 = 0.025;

/// Format tag of the scene embedded in a page.
pub const VIEW_FORMAT: &str = "embodied-view/1";

/// A pose: x, y, z, then the unit quaternion x, y, z, w (the order three.js uses).
pub type Pose = [f64; 7];

/// A shape in its body's frame. Cylinders and capsules run along their local z axis.
#[derive(Debug, Clone, Serialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ViewShape {
    /// A box of these full sizes.
    Box {
        /// Full sizes along x, y, z, m.
        size: [f64; 3],
        /// Pose in the body's frame.
        pose: Pose,
    },
    /// A ball.
    Sphere {
        /// Radius, m.
        radius: f64,
        /// Pose in the body's frame.
        pose: Pose,
    },
    /// A cylinder of this full length along z.
    Cylinder {
        /// Radius, m.
        radius: f64,
        /// Full length along z, m.
        length: f64,
        /// Pose in the body's frame.
        pose: Pose,
    },
    /// A capsule whose axis segment has this length along z.
    Capsule {
        /// Radius, m.
        radius: f64,
        /// Length of the axis segment along z, m.
        length: f64,
        /// Pose in the body's frame.
        pose: Pose,
    },
    /// A triangle mesh: vertex coordinates (x, y, z, ...) and vertex index triples.
    Mesh {
        /// Vertex coordinates x, y, z, ..., m.
        vertices: Vec<f64>,
        /// Vertex indices, three per triangle.
        triangles: Vec<u32>,
        /// Pose in the body's frame.
        pose: Pose,
    },
}

/// What a body of the scene is.
#[derive(Debug, Clone, Copy, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BodyKind {
    /// A link of an agent's robot.
    Link,
    /// An obstacle of the scenario.
    Obstacle,
    /// The object an agent carries.
    Object,
}

/// A rigid body: its shapes and its pose at each frame.
#[derive(Debug, Clone, Serialize)]
pub struct ViewBody {
    /// The body's name.
    pub name: String,
    /// Link, obstacle or carried object.
    pub kind: BodyKind,
    /// The agent it belongs to (links and carried objects).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agent: Option<String>,
    /// CSS colour.
    pub color: String,
    /// Its shapes, in the body's frame.
    pub shapes: Vec<ViewShape>,
    /// One pose per frame (`null`: absent at that frame), or a single pose for a body that never
    /// moves.
    pub poses: Vec<Option<Pose>>,
}

/// A marked moment of the timeline.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ViewEvent {
    /// When, s.
    pub t: f64,
    /// Which agent.
    pub agent: String,
    /// `plan`, `halt`, `resume`, `grasp`, `release`, `goal`, `failure` or `other`.
    pub kind: String,
    /// What the page shows.
    pub label: String,
}

/// The clearance at one frame: the distance and the two bodies that are nearest.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ViewClearance {
    /// The distance, m.
    pub m: f64,
    /// One body of the nearest pair.
    pub a: String,
    /// The other body of the nearest pair.
    pub b: String,
}

/// Everything a viewer page draws.
#[derive(Debug, Clone, Serialize)]
pub struct ViewScene {
    /// Format tag ([`VIEW_FORMAT`]).
    pub format: String,
    /// The page's title.
    pub title: String,
    /// What the scene was made from (a run log, a plan file, a run).
    pub source: String,
    /// Version and commit of the program that made it.
    pub generator: String,
    /// Time between frames, s.
    pub frame_s: f64,
    /// Frame times, s.
    pub times: Vec<f64>,
    /// The agents' names.
    pub agents: Vec<String>,
    /// Every body drawn.
    pub bodies: Vec<ViewBody>,
    /// The timeline's marked moments.
    pub events: Vec<ViewEvent>,
    /// Per frame; `null` where nothing is there to be near.
    pub clearance: Vec<Option<ViewClearance>>,
}

/// One timed configuration of every scenario agent (`None`: not known at that time).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackFrame {
    /// Time, s.
    pub t: f64,
    /// Per scenario agent, its joint values (`None`: not known at that time).
    pub q: Vec<Option<Vec<f64>>>,
}

/// One event of a track.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackEvent {
    /// When, s.
    pub t: f64,
    /// Which agent.
    pub agent: String,
    /// The timeline's mark for it (see [`event_mark`]).
    pub kind: &'static str,
    /// What the page shows.
    pub label: String,
}

impl TrackEvent {
    /// A logged event of `agent` at `t`.
    pub fn of(t: f64, agent: &str, event: &Event) -> Self {
        Self { t, agent: agent.to_string(), kind: event_mark(event), label: event.to_string() }
    }
}

/// The motion to show: frames in time order and events, for the scenario's agents in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Track {
    /// Timed configurations, in time order.
    pub frames: Vec<TrackFrame>,
    /// The events to mark.
    pub events: Vec<TrackEvent>,
}

/// What a run log's header says about where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct LogOrigin {
    /// The scenario named in the header.
    pub scenario: String,
    /// The scenario's hash from the header, if given.
    pub scenario_hash: Option<String>,
}

/// Read a run log (`embodied run --log`, JSON Lines: a header, one line per step, a summary)
/// into a track for the agents named `agents`. Steps are kept every `keep_s` seconds (the
/// events of every step are kept). `file` names the log in errors.
///
/// This is the one place that knows the log's layout.
pub fn read_run_log(text: &str, file: &Path, agents: &[String], keep_s: f64) -> Result<Track, AppError> {
    let parse_error =
        |line: usize, message: String| AppError::Parse { file: file.to_path_buf(), line, column: 1, message };
    let mut track = Track::default();
    let mut next_keep = f64::NEG_INFINITY;
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let value: serde_json::Value =
            serde_json::from_str(line).map_err(|e| parse_error(n + 1, format!("not a JSON line: {e}")))?;
        if value.get("header").is_some() || value.get("summary").is_some() {
            continue;
        }
        let (Some(t), Some(by_agent)) = (value.get("t").and_then(|t| t.as_f64()), value.get("agents")) else {
            return Err(parse_error(n + 1, "expected a step line with `t` and `agents`".into()));
        };
        let Some(by_agent) = by_agent.as_object() else {
            return Err(parse_error(n + 1, "`agents` must be an object".into()));
        };
        for (agent, record) in by_agent {
            let events: Vec<Event> = match record.get("events") {
                None => Vec::new(),
                Some(v) => serde_json::from_value(v.clone())
                    .map_err(|e| parse_error(n + 1, format!("agents.{agent}.events: expected typed events ({e})")))?,
            };
            track.events.extend(events.iter().map(|e| TrackEvent::of(t, agent, e)));
        }
        if t + 1e-9 >= next_keep {
            next_keep = t + keep_s;
            let mut q = Vec::with_capacity(agents.len());
            for name in agents {
                let values = match by_agent.get(name).and_then(|r| r.get("q")) {
                    Some(v) => Some(
                        serde_json::from_value::<Vec<f64>>(v.clone())
                            .map_err(|e| parse_error(n + 1, format!("agent `{name}`: `q` must be numbers: {e}")))?,
                    ),
                    None => None,
                };
                q.push(values);
            }
            track.frames.push(TrackFrame { t, q });
        }
    }
    if track.frames.is_empty() {
        return Err(parse_error(1, "no step lines: expected a run log of `embodied run --log`".into()));
    }
    Ok(track)
}

/// The scenario a run log was made from, from its header line.
pub fn log_origin(text: &str, file: &Path) -> Result<LogOrigin, AppError> {
    let first = text.lines().next().unwrap_or("");
    let header = serde_json::from_str::<serde_json::Value>(first)
        .ok()
        .and_then(|v| v.get("header").cloned())
        .ok_or_else(|| AppError::Parse {
            file: file.to_path_buf(),
            line: 1,
            column: 1,
            message: "expected the header line of a run log (`{\"header\": ...}`)".into(),
        })?;
    let scenario = header.get("scenario").and_then(|s| s.as_str()).ok_or_else(|| AppError::Parse {
        file: file.to_path_buf(),
        line: 1,
        column: 1,
        message: "the header names no `scenario`".into(),
    })?;
    Ok(LogOrigin {
        scenario: scenario.to_string(),
        scenario_hash: header.get("scenario_hash").and_then(|s| s.as_str()).map(str::to_string),
    })
}

/// The track of a plan file: the agents move one after the other in the file's order (as
/// `embodied plan` planned them: each around where the earlier ones end), the others stand at
/// their start.
pub fn track_from_plan(scenario: &Scenario, plan: &PlanFile) -> Result<Track, AppError> {
    let n = scenario.agents.len();
    let mut windows: Vec<(usize, f64, &crate::plan::AgentPlan)> = Vec::new();
    let mut offset = 0.0;
    for p in &plan.plans {
        let Some(k) = scenario.agents.iter().position(|a| a.name == p.agent) else {
            return Err(AppError::Usage(format!(
                "the plan is for agent `{}`, which scenario `{}` does not have",
                p.agent, scenario.name
            )));
        };
        let dof = scenario.agents[k].robot.dof();
        if p.trajectory.q.iter().any(|q| q.len() != dof) {
            return Err(AppError::Usage(format!(
                "agent `{}`: the plan's configurations do not have the robot's {dof} joints",
                p.agent
            )));
        }
        windows.push((k, offset, p));
        offset += p.trajectory.duration();
    }
    let total = offset;
    let mut current: Vec<Vec<f64>> = scenario.agents.iter().map(|a| a.start.clone()).collect();
    let mut frames = Vec::new();
    let count = (total / FRAME_S).ceil() as usize + 1;
    for i in 0..count {
        let t = (i as f64 * FRAME_S).min(total);
        for &(k, start, p) in &windows {
            if t >= start {
                current[k] = p.trajectory.sample(t - start).0;
            }
        }
        frames.push(TrackFrame { t, q: current.iter().cloned().map(Some).collect() });
    }
    let mut events = Vec::new();
    for &(k, start, p) in &windows {
        let agent = scenario.agents[k].name.clone();
        let stats = &p.stats;
        let planner = stats.get("planner").and_then(|s| s.as_str()).unwrap_or("planner");
        events.push(TrackEvent {
            t: start,
            agent: agent.clone(),
            kind: "plan",
            label: format!("plan starts ({planner})"),
        });
        for span in &p.closed_chain {
            events.push(TrackEvent::of(start + span.from_s, &agent, &Event::Grasp));
            events.push(TrackEvent::of(start + span.to_s, &agent, &Event::Release));
        }
        events.push(TrackEvent::of(start + p.trajectory.duration(), &agent, &Event::GoalReached { id: None }));
    }
    events.sort_by(|a, b| a.t.total_cmp(&b.t));
    debug_assert!(frames.iter().all(|f| f.q.len() == n));
    Ok(Track { frames, events })
}

/// The timeline's mark of an event: `plan`, `halt`, `resume`, `grasp`, `release`, `goal`,
/// `failure` or `other`.
pub fn event_mark(event: &Event) -> &'static str {
    match event {
        Event::PlanLanded { .. } => "plan",
        Event::HaltStarted { .. } | Event::ForceLimit { .. } => "halt",
        Event::Resumed { .. } => "resume",
        Event::Grasp => "grasp",
        Event::Release => "release",
        Event::GoalReached { .. } | Event::AllDone => "goal",
        Event::TaskDone { failed: false } => "goal",
        Event::PlanRejected { .. }
        | Event::PlanFailed { .. }
        | Event::PlannerPanicked { .. }
        | Event::AgentFailed { .. }
        | Event::TaskDone { .. }
        | Event::SpecificationError { .. } => "failure",
        _ => "other",
    }
}

/// Per agent, two shades that alternate along its links.
const AGENT_COLORS: [[&str; 2]; 6] = [
    ["#4a7bd0", "#6f98e0"],
    ["#d07a3a", "#e09a62"],
    ["#3aa37a", "#62c098"],
    ["#a25ac8", "#bb80da"],
    ["#c8b23a", "#dac862"],
    ["#3ab4c8", "#62cada"],
];

fn pose_of(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.into_inner();
    let r = |v: f64| (v * 1e5).round() / 1e5;
    [r(t.x), r(t.y), r(t.z), r(q.i), r(q.j), r(q.k), r(q.w)]
}

/// A model shape as the viewer draws it, placed by `pose` in its body's frame.
pub fn view_shape(shape: &Shape, pose: &Isometry3<f64>) -> ViewShape {
    match shape {
        Shape::Sphere { radius } => ViewShape::Sphere { radius: *radius, pose: pose_of(pose) },
        Shape::Cuboid { half_extents: h } => {
            ViewShape::Box { size: [2.0 * h.x, 2.0 * h.y, 2.0 * h.z], pose: pose_of(pose) }
        }
        Shape::Cylinder { radius, half_height } => {
            ViewShape::Cylinder { radius: *radius, length: 2.0 * half_height, pose: pose_of(pose) }
        }
        Shape::Capsule { a, b, radius } => {
            let axis = b - a;
            let length = axis.norm();
            let rotation = if length > 1e-12 {
                UnitQuaternion::rotation_between(&Vector3::z(), &axis)
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI))
            } else {
                UnitQuaternion::identity()
            };
            let mid = a + axis * 0.5;
            let local = Isometry3::from_parts(Translation3::from(mid.coords), rotation);
            ViewShape::Capsule { radius: *radius, length, pose: pose_of(&(pose * local)) }
        }
        Shape::ConvexMesh(hull) => {
            let (points, triangles) = hull.polyhedron.to_trimesh();
            let r = |v: f64| (v * 1e5).round() / 1e5;
            ViewShape::Mesh {
                vertices: points.iter().flat_map(|p| [r(p.x), r(p.y), r(p.z)]).collect(),
                triangles: triangles.iter().flatten().copied().collect(),
                pose: pose_of(pose),
            }
        }
    }
}

/// A body's poses: one if it never moves, else one per frame.
fn compact(poses: Vec<Option<Pose>>) -> Vec<Option<Pose>> {
    match poses.first() {
        Some(first) if poses.iter().all(|p| p == first) => vec![*first],
        _ => poses,
    }
}

/// The configuration of every agent at time `t`: the last track frame at or before `t`.
fn frame_at(track: &Track, t: f64, cursor: &mut usize) -> usize {
    while *cursor + 1 < track.frames.len() && track.frames[*cursor + 1].t <= t + 1e-9 {
        *cursor += 1;
    }
    *cursor
}

/// Build the scene of `track` in `scenario`. `title` and `source` label the page.
pub fn build_scene(scenario: &Scenario, track: &Track, title: &str, source: &str) -> Result<ViewScene, AppError> {
    let n = scenario.agents.len();
    if let Some(f) = track.frames.iter().find(|f| f.q.len() != n) {
        return Err(AppError::Failed(format!("track frame at t={} has {} agents, expected {n}", f.t, f.q.len())));
    }
    let t_end = track.frames.last().map_or(0.0, |f| f.t);
    let count = (t_end / FRAME_S).floor() as usize + 1;
    let times: Vec<f64> = (0..count).map(|i| ((i as f64 * FRAME_S) * 1e6).round() / 1e6).collect();
    // Every agent's configuration at every frame (its start where the track does not say).
    let mut configurations: Vec<Vec<Vec<f64>>> = vec![Vec::with_capacity(count); n];
    let mut cursor = 0;
    for &t in &times {
        let f = &track.frames[frame_at(track, t, &mut cursor)];
        for (k, agent) in scenario.agents.iter().enumerate() {
            let q = f.q[k].as_ref().filter(|q| q.len() == agent.robot.dof()).unwrap_or(&agent.start);
            configurations[k].push(q.clone());
        }
    }
    let mut bodies = Vec::new();
    for (k, agent) in scenario.agents.iter().enumerate() {
        let colors = AGENT_COLORS[k % AGENT_COLORS.len()];
        let robot = &agent.robot;
        let fk: Vec<Vec<Isometry3<f64>>> = configurations[k].iter().map(|q| robot.forward_kinematics(q)).collect();
        for (l, link) in robot.links().iter().enumerate() {
            if link.shapes.is_empty() {
                continue;
            }
            let color = colors[bodies.len() % 2];
            bodies.push(ViewBody {
                name: format!("{}/{}", agent.name, link.name),
                kind: BodyKind::Link,
                agent: Some(agent.name.clone()),
                color: color.to_string(),
                shapes: link.shapes.iter().map(|s| view_shape(&s.shape, &s.pose)).collect(),
                poses: compact(fk.iter().map(|poses| Some(pose_of(&poses[l]))).collect()),
            });
        }
    }
    // Obstacles: present from their appearance on, moving at their velocity from then.
    let mut obstacle_poses: Vec<Vec<Option<Isometry3<f64>>>> = Vec::new();
    for o in &scenario.obstacles {
        let appear = o.appear_at.unwrap_or(0.0);
        let poses: Vec<Option<Isometry3<f64>>> = times
            .iter()
            .map(|&t| {
                (t + 1e-9 >= appear).then(|| {
                    let shift = o.velocity.map_or(Vector3::zeros(), |v| v * (t - appear).max(0.0));
                    Translation3::from(shift) * o.obstacle.pose
                })
            })
            .collect();
        bodies.push(ViewBody {
            name: o.obstacle.name.clone(),
            kind: BodyKind::Obstacle,
            agent: None,
            color: if o.on_map() { "#9a9a9a".into() } else { "#d04a4a".into() },
            shapes: vec![view_shape(&o.obstacle.shape, &Isometry3::identity())],
            poses: compact(poses.iter().map(|p| p.as_ref().map(pose_of)).collect()),
        });
        obstacle_poses.push(poses);
    }
    // The carried object: at its start until the grasp, with the holding tool until the
    // release, where it was let go after.
    let mut held: Vec<Option<(usize, Robot)>> = vec![None; count];
    if let Some(spec) = &scenario.carry {
        let agent = &scenario.agents[spec.agent];
        let grasp = track.events.iter().find(|e| e.agent == agent.name && e.kind == "grasp").map(|e| e.t);
        let release = track.events.iter().find(|e| e.agent == agent.name && e.kind == "release").map(|e| e.t);
        let in_tool = spec.grasps[0].inverse();
        let object =
            CarriedObject { name: spec.object.clone(), size: spec.size, in_tool: CarriedObject::encode_pose(&in_tool) };
        let holder = spec.end_effectors[0];
        let other_link = agent.robot.end_effectors().get(spec.end_effectors[1]).map(|e| e.link);
        let held_robot = object.attach(&agent.robot, holder, &other_link.into_iter().collect::<Vec<_>>());
        let mut pose = spec.object_start;
        let mut poses = Vec::with_capacity(count);
        for (i, &t) in times.iter().enumerate() {
            let holding = grasp.is_some_and(|g| t + 1e-9 >= g) && release.is_none_or(|r| t < r - 1e-9);
            if holding {
                pose = tool_pose(&agent.robot, &configurations[spec.agent][i], holder) * in_tool;
                if let Some(r) = &held_robot {
                    held[i] = Some((spec.agent, r.clone()));
                }
            }
            poses.push(Some(pose_of(&pose)));
        }
        let h = Vector3::from(spec.size) * 0.5;
        bodies.push(ViewBody {
            name: spec.object.clone(),
            kind: BodyKind::Object,
            agent: Some(agent.name.clone()),
            color: "#e0a020".into(),
            shapes: vec![view_shape(&Shape::cuboid(h.x, h.y, h.z), &Isometry3::identity())],
            poses: compact(poses),
        });
    }
    let clearance = clearances(scenario, &configurations, &obstacle_poses, &held);
    let mut events: Vec<ViewEvent> = track
        .events
        .iter()
        .map(|e| ViewEvent { t: e.t, agent: e.agent.clone(), kind: e.kind.to_string(), label: e.label.clone() })
        .collect();
    events.sort_by(|a, b| a.t.total_cmp(&b.t));
    Ok(ViewScene {
        format: VIEW_FORMAT.to_string(),
        title: title.to_string(),
        source: source.to_string(),
        generator: crate::generator(),
        frame_s: FRAME_S,
        times,
        agents: scenario.agents.iter().map(|a| a.name.clone()).collect(),
        bodies,
        events,
        clearance,
    })
}

/// Per frame, the smallest distance between an agent (with what it holds, self pairs aside)
/// and the obstacles present and the other agents' bodies.
fn clearances(
    scenario: &Scenario,
    configurations: &[Vec<Vec<f64>>],
    obstacle_poses: &[Vec<Option<Isometry3<f64>>>],
    held: &[Option<(usize, Robot)>],
) -> Vec<Option<ViewClearance>> {
    // One model per agent (and one with the held object), their environment set per frame.
    let mut plain: Vec<CollisionModel> = scenario
        .agents
        .iter()
        .map(|a| CollisionModel::new(&a.robot.without_self_collisions(), Environment::new()))
        .collect();
    let mut holding: Option<(usize, CollisionModel)> = held
        .iter()
        .flatten()
        .next()
        .map(|(k, r)| (*k, CollisionModel::new(&r.without_self_collisions(), Environment::new())));
    let bodies: Vec<CollisionModel> =
        scenario.agents.iter().map(|a| CollisionModel::new(&a.robot, Environment::new())).collect();
    let count = configurations.first().map_or(0, Vec::len);
    let mut out = Vec::with_capacity(count);
    for i in 0..count {
        let mut best: Option<ViewClearance> = None;
        for (k, agent) in scenario.agents.iter().enumerate() {
            let mut env = Environment::new();
            for (o, poses) in scenario.obstacles.iter().zip(obstacle_poses) {
                if let Some(pose) = poses[i] {
                    env.add(Obstacle { name: o.obstacle.name.clone(), pose, shape: o.obstacle.shape.clone() });
                }
            }
            for (m, other) in scenario.agents.iter().enumerate() {
                if m != k {
                    for mut o in bodies[m].link_shapes_world(&configurations[m][i]) {
                        o.name = format!("{}/{}", other.name, o.name);
                        env.add(o);
                    }
                }
            }
            if env.obstacles().is_empty() {
                continue;
            }
            let model = match (&held[i], holding.as_mut()) {
                (Some((h, _)), Some((hk, model))) if *h == k && *hk == k => model,
                _ => &mut plain[k],
            };
            model.set_environment(env);
            let report = model.distance(&configurations[k][i]);
            if best.as_ref().is_none_or(|b| report.distance < b.m) {
                best = Some(ViewClearance {
                    m: (report.distance * 1e5).round() / 1e5,
                    a: format!("{}/{}", agent.name, report.a.name()),
                    b: report.b.name().to_string(),
                });
            }
        }
        out.push(best);
    }
    out
}

const PAGE: &str = include_str!("assets/viewer.html");
const VIEWER_JS: &str = include_str!("assets/viewer.js");
const THREE_CORE: &str = include_str!("assets/three/three.core.min.js");
const THREE_MODULE: &str = include_str!("assets/three/three.module.min.js");
const ORBIT_CONTROLS: &str = include_str!("assets/three/OrbitControls.js");

/// JSON safe inside a `<script>` element: every `<` escaped (it only occurs inside strings).
fn script_json<T: Serialize>(value: &T) -> Result<String, AppError> {
    let text = serde_json::to_string(value).map_err(|e| AppError::Failed(format!("view: {e}")))?;
    Ok(text.replace('<', "\\u003c"))
}

/// The page: the scene as JSON, three.js and the viewer's script, all inline.
pub fn render_html(scene: &ViewScene) -> Result<String, AppError> {
    let title: String = scene
        .title
        .chars()
        .map(|c| match c {
            '<' => "&lt;".to_string(),
            '>' => "&gt;".to_string(),
            '&' => "&amp;".to_string(),
            c => c.to_string(),
        })
        .collect();
    let mut page = String::with_capacity(PAGE.len() + THREE_CORE.len() + THREE_MODULE.len() + (1 << 20));
    // Placeholders are replaced in one pass, so nothing inserted is scanned again.
    let mut rest = PAGE;
    while let Some(start) = rest.find("{{") {
        let Some(len) = rest[start..].find("}}") else { break };
        page.push_str(&rest[..start]);
        match &rest[start + 2..start + len] {
            "TITLE" => page.push_str(&title),
            "SCENE" => page.push_str(&script_json(scene)?),
            "THREE_CORE" => page.push_str(THREE_CORE),
            "THREE_MODULE" => page.push_str(THREE_MODULE),
            "ORBIT_CONTROLS" => page.push_str(ORBIT_CONTROLS),
            "VIEWER_JS" => page.push_str(VIEWER_JS),
            other => return Err(AppError::Failed(format!("viewer template: unknown placeholder `{other}`"))),
        }
        rest = &rest[start + len + 2..];
    }
    page.push_str(rest);
    Ok(page)
}

/// Write the page of `scene` to `path`.
pub fn write_html(path: &Path, scene: &ViewScene) -> Result<(), AppError> {
    let page = render_html(scene)?;
    std::fs::write(path, page).map_err(|e| AppError::write(path, e))
}

/// `embodied view INPUT`: the scene of a run log or a plan file. The scenario is `scenario`, or
/// the built-in one the input names.
pub fn view_file(input: &Path, scenario: Option<&str>) -> Result<ViewScene, AppError> {
    let text = crate::error::read_input(input, embodied_models::formats::limits::InputKind::Log)?;
    let first = text.lines().next().unwrap_or("");
    let is_log = serde_json::from_str::<serde_json::Value>(first).is_ok_and(|v| v.get("header").is_some());
    let load = |named: &str, hash: Option<&str>| -> Result<Scenario, AppError> {
        let sc = crate::scenario::load_scenario(scenario.unwrap_or(named))?;
        if let Some(h) = hash
            && h != sc.hash
        {
            return Err(AppError::Usage(format!(
                "{} was made from scenario `{named}` with hash {h}, but `{}` has hash {}: pass the scenario file it was made from with --scenario",
                input.display(),
                scenario.unwrap_or(named),
                sc.hash
            )));
        }
        Ok(sc)
    };
    if is_log {
        let origin = log_origin(&text, input)?;
        let sc = load(&origin.scenario, origin.scenario_hash.as_deref())?;
        let agents: Vec<String> = sc.agents.iter().map(|a| a.name.clone()).collect();
        let track = read_run_log(&text, input, &agents, FRAME_S)?;
        let source = format!("run log {}", file_name(input));
        build_scene(&sc, &track, &format!("{}: run", sc.name), &source)
    } else {
        let plan = crate::plan::parse_plan(&text, input)?;
        let sc = load(&plan.scenario.name, Some(&plan.scenario.hash))?;
        let track = track_from_plan(&sc, &plan)?;
        let source = format!("plan file {}", file_name(input));
        build_scene(&sc, &track, &format!("{}: plan", sc.name), &source)
    }
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// `track` with the events of a run's summary, (time, agent, event) each.
pub fn with_events(mut track: Track, events: &[(f64, String, Event)]) -> Track {
    track.events = events.iter().map(|(t, agent, e)| TrackEvent::of(*t, agent, e)).collect();
    track
}

/// The page of a run that has just been made (`embodied run --html`).
pub fn write_run_view(path: &Path, scenario: &Scenario, track: &Track) -> Result<(), AppError> {
    let scene = build_scene(scenario, track, &format!("{}: run", scenario.name), "embodied run")?;
    write_html(path, &scene)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn agents() -> Vec<String> {
        vec!["a".to_string(), "b".to_string()]
    }

    #[test]
    fn a_run_log_becomes_frames_and_events() {
        let log = [
            r#"{"header": {"scenario": "x", "scenario_hash": "h"}}"#,
            r#"{"step": 0, "t": 0.0, "agents": {"a": {"q": [0.0, 1.0], "events": [{"kind": "goal_reached", "id": 3}]}, "b": {"q": [2.0], "events": []}}}"#,
            r#"{"step": 1, "t": 0.001, "agents": {"a": {"q": [0.1, 1.0], "events": [{"kind": "grasp"}]}, "b": {"q": [2.0], "events": []}}}"#,
            r#"{"step": 2, "t": 0.002, "agents": {"a": {"q": [0.2, 1.0], "events": []}}}"#,
            r#"{"summary": {}}"#,
        ]
        .join("\n");
        let track = read_run_log(&log, Path::new("run.jsonl"), &agents(), 0.002).unwrap();
        // Kept every 2 ms: steps 0 and 2; agent b is missing from step 2.
        assert_eq!(track.frames.len(), 2);
        assert_eq!(track.frames[0].q, vec![Some(vec![0.0, 1.0]), Some(vec![2.0])]);
        assert_eq!(track.frames[1].q, vec![Some(vec![0.2, 1.0]), None]);
        // The events of every step, typed, with their marks.
        let kinds: Vec<&str> = track.events.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, ["goal", "grasp"]);
        assert_eq!(track.events[1].label, Event::Grasp.to_string());
        // A string where a typed event belongs is named.
        let old = log.replace(r#"[{"kind": "grasp"}]"#, r#"["grasp"]"#);
        let e = read_run_log(&old, Path::new("run.jsonl"), &agents(), 0.002).unwrap_err().to_string();
        assert!(e.starts_with("run.jsonl:3:1:") && e.contains("typed events"), "{e}");
        let origin = log_origin(&log, Path::new("run.jsonl")).unwrap();
        assert_eq!(origin, LogOrigin { scenario: "x".into(), scenario_hash: Some("h".into()) });
    }

    #[test]
    fn a_bad_log_line_is_named() {
        let log = "{\"header\": {\"scenario\": \"x\"}}\n{\"t\": 0.0}\n";
        let e = read_run_log(log, Path::new("run.jsonl"), &agents(), 0.0).unwrap_err().to_string();
        assert!(e.starts_with("run.jsonl:2:1:") && e.contains("`agents`"), "{e}");
        let e = read_run_log("{\"header\": {}}\n", Path::new("r.jsonl"), &agents(), 0.0).unwrap_err().to_string();
        assert!(e.contains("no step lines"), "{e}");
        let e = log_origin("[]", Path::new("r.jsonl")).unwrap_err().to_string();
        assert!(e.contains("header line"), "{e}");
    }

    #[test]
    fn events_are_sorted_into_kinds() {
        for (event, kind) in [
            (Event::ForceLimit { force_n: 12.0 }, "halt"),
            (Event::Grasp, "grasp"),
            (Event::Release, "release"),
            (Event::GoalReached { id: None }, "goal"),
            (Event::AllDone, "goal"),
            (Event::TaskDone { failed: false }, "goal"),
            (Event::TaskDone { failed: true }, "failure"),
            (Event::GrantReceived, "other"),
            (Event::from("a note"), "other"),
        ] {
            assert_eq!(event_mark(&event), kind, "{event}");
        }
    }

    #[test]
    fn the_vendored_scripts_can_sit_inside_script_elements() {
        // A `</script` or `<!--` would end or change the element the page keeps them in.
        for (name, text) in
            [("core", THREE_CORE), ("module", THREE_MODULE), ("orbit", ORBIT_CONTROLS), ("viewer", VIEWER_JS)]
        {
            let lower = text.to_ascii_lowercase();
            assert!(!lower.contains("</script") && !lower.contains("<!--"), "{name}");
        }
        // The specifiers the page rewrites to blob URLs are there.
        assert_eq!(THREE_MODULE.matches("\"./three.core.min.js\"").count(), 2);
        assert!(ORBIT_CONTROLS.contains("from 'three'"));
        assert!(VIEWER_JS.contains("'\"./three.core.min.js\"'") && VIEWER_JS.contains("\"from 'three'\""));
    }

    #[test]
    fn the_carry_plan_scene_moves_the_bar_and_keeps_clear() {
        let sc = crate::scenario::load_scenario("two-irp6-carry").unwrap();
        let plan = crate::plan::plan_scenario(&sc, None).unwrap();
        let track = track_from_plan(&sc, &plan).unwrap();
        let scene = build_scene(&sc, &track, "t <b>", "test").unwrap();
        assert_eq!(scene.times.len(), scene.clearance.len());
        let bar = scene.bodies.iter().find(|b| b.kind == BodyKind::Object).unwrap();
        assert_eq!(bar.poses.len(), scene.times.len(), "the bar moves");
        let (first, last) = (bar.poses[0].unwrap(), bar.poses.last().unwrap().unwrap());
        // Carried from its start to its goal (0.23 m along x).
        let goal = sc.carry.as_ref().unwrap().object_goal.translation.vector;
        assert!((last[0] - goal.x).abs() < 1e-3 && (last[1] - goal.y).abs() < 1e-3, "{last:?} vs {goal:?}");
        assert!((last[0] - first[0] - 0.23).abs() < 1e-3);
        // Never in contact, and the grasp brings the arms near the stands.
        let min = scene.clearance.iter().flatten().map(|c| c.m).fold(f64::INFINITY, f64::min);
        assert!(min > 0.0 && min < 0.1, "clearance {min}");
        // The page: the title escaped, no placeholder left, the scene's `<` escaped.
        let page = render_html(&scene).unwrap();
        assert!(page.contains("<title>t &lt;b&gt;</title>") && !page.contains("{{"));
        assert!(page.contains("\"title\":\"t \\u003cb>\""));
    }
}
