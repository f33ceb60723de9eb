//! `trajectory_msgs/JointTrajectory` in YAML or JSON, the way `ros2 topic echo`, `rostopic echo`
//! and rosbag tools write it: `joint_names` and `points`, each point with `positions`,
//! `velocities`, `accelerations` (each empty or one value per joint) and `time_from_start`
//! (`{sec, nanosec}` as ROS 2 writes it, `{secs, nsecs}` as ROS 1 does, or plain seconds).
//! A `moveit_msgs/RobotTrajectory` (a mapping with `joint_trajectory`) is read too. `header` and
//! `effort` are accepted and not used.
//!
//! JSON is read with the YAML reader (JSON is YAML), so errors in both name `file:line:column`.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::formats::trajectory::{JointTrajectory, TrajectoryPoint, parse_joint_trajectory};
//! let t = JointTrajectory {
//!     joint_names: vec!["a".into()],
//!     points: vec![TrajectoryPoint { positions: vec![0.5], time_from_start: 1.25, ..Default::default() }],
//! };
//! let back = parse_joint_trajectory(&t.to_yaml(), Path::new("t.yaml")).unwrap();
//! assert_eq!(back, t);
//! let back = parse_joint_trajectory(&t.to_json(), Path::new("t.json")).unwrap();
//! assert_eq!(back, t);
//! ```

use std::fmt::Write as _;
use std::path::Path;

use saphyr::YamlDataOwned;

use super::yaml::{Doc, Location, Node, YamlError, describe, is_null};

/// One waypoint.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrajectoryPoint {
    /// One position per joint (rad or m).
    pub positions: Vec<f64>,
    /// One velocity per joint, or empty.
    pub velocities: Vec<f64>,
    /// One acceleration per joint, or empty.
    pub accelerations: Vec<f64>,
    /// Seconds from the trajectory's start.
    pub time_from_start: f64,
}

/// A `trajectory_msgs/JointTrajectory`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointTrajectory {
    /// The joints, in the order of every point's values.
    pub joint_names: Vec<String>,
    /// Waypoints with strictly increasing `time_from_start`.
    pub points: Vec<TrajectoryPoint>,
}

/// A read trajectory with where each point stands in its file (for error messages).
#[derive(Debug, Clone, PartialEq)]
pub struct LocatedTrajectory {
    /// The trajectory.
    pub trajectory: JointTrajectory,
    /// Where each point starts, same order as `trajectory.points`.
    pub locations: Vec<Location>,
}

/// Read a trajectory file (YAML or JSON).
pub fn load_joint_trajectory(path: &Path) -> Result<LocatedTrajectory, YamlError> {
    let text = super::limits::read_text_limited(path, super::limits::InputKind::Text)
        .map_err(|source| YamlError::Io { file: path.to_path_buf(), source })?;
    parse_located(&text, path)
}

/// Parse trajectory text (YAML or JSON); `file` names it in errors.
pub fn parse_joint_trajectory(text: &str, file: &Path) -> Result<JointTrajectory, YamlError> {
    Ok(parse_located(text, file)?.trajectory)
}

fn time(doc: &Doc, n: &Node) -> Result<f64, YamlError> {
    if !n.data.is_mapping() {
        let t = doc.number(n, "time_from_start (seconds)")?;
        return Ok(t);
    }
    let part = |keys: [&str; 2]| -> Result<f64, YamlError> {
        match keys.iter().find_map(|k| doc.get(n, k)) {
            Some(v) => doc.number(v, keys[0]),
            None => Ok(0.0),
        }
    };
    let sec = part(["sec", "secs"])?;
    let nanosec = part(["nanosec", "nsecs"])?;
    Ok(sec + nanosec * 1e-9)
}

/// [`parse_joint_trajectory`] keeping each point's position in the file.
pub fn parse_located(text: &str, file: &Path) -> Result<LocatedTrajectory, YamlError> {
    let doc = Doc::load(text, file)?;
    let mut root = doc.root()?;
    doc.expect_mapping(root, "a JointTrajectory (a mapping with `joint_names` and `points`)")?;
    if let Some(inner) = doc.get(root, "joint_trajectory").filter(|n| !is_null(n)) {
        root = inner;
        doc.expect_mapping(root, "a JointTrajectory (a mapping with `joint_names` and `points`)")?;
    }
    let names_node = doc.require(root, "joint_names", "the joints' names (a list)")?;
    let mut joint_names = Vec::new();
    for n in doc.seq(names_node, "joint_names")? {
        let name = doc.string(n, "a joint name")?;
        if joint_names.contains(&name) {
            return Err(doc.err(n, &format!("joint `{name}` is named twice in joint_names")));
        }
        joint_names.push(name);
    }
    if joint_names.is_empty() {
        return Err(doc.err(names_node, "expected at least one joint name, got an empty list"));
    }
    let points_node = doc.require(root, "points", "the waypoints (a list)")?;
    let mut points: Vec<TrajectoryPoint> = Vec::new();
    let mut locations = Vec::new();
    let dof = joint_names.len();
    for p in doc.seq(points_node, "points")? {
        doc.expect_mapping(p, "a trajectory point (a mapping with `positions` and `time_from_start`)")?;
        let positions = doc.numbers(doc.require(p, "positions", "one position per joint")?, Some(dof), "positions")?;
        let optional = |key: &str| -> Result<Vec<f64>, YamlError> {
            match doc.get(p, key).filter(|n| !is_null(n)) {
                None => Ok(Vec::new()),
                Some(n) => match &n.data {
                    YamlDataOwned::Sequence(s) if s.is_empty() => Ok(Vec::new()),
                    _ => doc.numbers(n, Some(dof), key),
                },
            }
        };
        let velocities = optional("velocities")?;
        let accelerations = optional("accelerations")?;
        let t_node = doc.require(p, "time_from_start", "the point's time from the start")?;
        let time_from_start = time(&doc, t_node)?;
        if time_from_start < 0.0 {
            return Err(doc.err(t_node, &format!("expected a time_from_start >= 0, got {time_from_start}")));
        }
        if let Some(prev) = points.last()
            && time_from_start <= prev.time_from_start
        {
            return Err(doc.err(
                t_node,
                &format!(
                    "time_from_start {time_from_start} s is not after the previous point's {} s (expected increasing times)",
                    prev.time_from_start
                ),
            ));
        }
        points.push(TrajectoryPoint { positions, velocities, accelerations, time_from_start });
        locations.push(doc.loc(p));
    }
    if points.is_empty() {
        return Err(doc.err(points_node, &format!("expected at least one point, got {}", describe(points_node))));
    }
    Ok(LocatedTrajectory { trajectory: JointTrajectory { joint_names, points }, locations })
}

/// `(sec, nanosec)` of a time in seconds, nanoseconds rounded.
fn split_time(t: f64) -> (i64, u32) {
    let total = (t * 1e9).round() as i64;
    (total.div_euclid(1_000_000_000), total.rem_euclid(1_000_000_000) as u32)
}

/// A float written so that it reads back exactly (Rust's shortest round-trip form).
fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") { s } else { format!("{s}.0") }
}

fn list(values: &[f64]) -> String {
    format!("[{}]", values.iter().map(|v| num(*v)).collect::<Vec<_>>().join(", "))
}

impl JointTrajectory {
    /// The trajectory as YAML, in the layout of `ros2 topic echo` (flow lists for the values).
    pub fn to_yaml(&self) -> String {
        let mut s = String::from("header:\n  stamp:\n    sec: 0\n    nanosec: 0\n  frame_id: ''\njoint_names:\n");
        for n in &self.joint_names {
            let _ = writeln!(s, "- {}", serde_json::to_string(n).unwrap_or_else(|_| format!("'{n}'")));
        }
        s.push_str("points:\n");
        for p in &self.points {
            let (sec, nanosec) = split_time(p.time_from_start);
            let _ = writeln!(s, "- positions: {}", list(&p.positions));
            let _ = writeln!(s, "  velocities: {}", list(&p.velocities));
            let _ = writeln!(s, "  accelerations: {}", list(&p.accelerations));
            s.push_str("  effort: []\n");
            let _ = writeln!(s, "  time_from_start:\n    sec: {sec}\n    nanosec: {nanosec}");
        }
        s
    }

    /// The trajectory as JSON (the message's fields, `time_from_start` as `{sec, nanosec}`).
    pub fn to_json(&self) -> String {
        let points: Vec<serde_json::Value> = self
            .points
            .iter()
            .map(|p| {
                let (sec, nanosec) = split_time(p.time_from_start);
                serde_json::json!({
                    "positions": p.positions,
                    "velocities": p.velocities,
                    "accelerations": p.accelerations,
                    "effort": [],
                    "time_from_start": {"sec": sec, "nanosec": nanosec},
                })
            })
            .collect();
        let v = serde_json::json!({
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "joint_names": self.joint_names,
            "points": points,
        });
        serde_json::to_string_pretty(&v).unwrap_or_default() + "\n"
    }

    /// The trajectory as JSON if `path` ends in `.json`, else as YAML.
    pub fn to_text_for(&self, path: &Path) -> String {
        if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) { self.to_json() } else { self.to_yaml() }
    }

    /// Duration: the last point's `time_from_start`.
    pub fn duration(&self) -> f64 {
        self.points.last().map_or(0.0, |p| p.time_from_start)
    }
}
