//! MoveIt's `joint_limits.yaml`: the velocity, acceleration and position limits MoveIt plans
//! with, which override the URDF's (URDF has no acceleration limits at all).
//!
//! The file is a mapping `joint_limits: {JOINT: {has_velocity_limits, max_velocity,
//! has_acceleration_limits, max_acceleration, has_position_limits, min_position,
//! max_position}}`, possibly under `robot_description_planning:` (ROS 2). A limit is applied only
//! where its `has_*` flag is true, as MoveIt does. Other keys (`default_velocity_scaling_factor`,
//! `has_jerk_limits`, ...) are accepted and not used.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::formats::joint_limits::parse_joint_limits;
//! let text = "joint_limits:\n  elbow:\n    has_acceleration_limits: true\n    max_acceleration: 2.5\n";
//! let limits = parse_joint_limits(text, Path::new("joint_limits.yaml")).unwrap();
//! assert_eq!(limits.joints[0].max_acceleration, Some(2.5));
//! ```

use std::path::{Path, PathBuf};

use saphyr::{ScalarOwned, YamlDataOwned};

use super::yaml::{Doc, Location, Node, YamlError, describe, is_null};
use crate::robot::Robot;

/// The limits a `joint_limits.yaml` gives for one joint (`None`: not given or its flag false).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointLimitEntry {
    /// The joint's name.
    pub joint: String,
    /// `max_velocity` when `has_velocity_limits`.
    pub max_velocity: Option<f64>,
    /// `max_acceleration` when `has_acceleration_limits`.
    pub max_acceleration: Option<f64>,
    /// `(min_position, max_position)` when `has_position_limits`.
    pub position: Option<(f64, f64)>,
    /// Where the joint's entry is.
    pub location: Location,
}

/// The content of a `joint_limits.yaml`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointLimitsFile {
    /// The file read (named in errors).
    pub file: PathBuf,
    /// One entry per joint, in file order.
    pub joints: Vec<JointLimitEntry>,
}

/// Read and parse a `joint_limits.yaml`.
pub fn load_joint_limits(path: &Path) -> Result<JointLimitsFile, YamlError> {
    let text = super::limits::read_text_limited(path, super::limits::InputKind::Text)
        .map_err(|source| YamlError::Io { file: path.to_path_buf(), source })?;
    parse_joint_limits(&text, path)
}

fn flag(doc: &Doc, map: &Node, key: &str) -> Result<bool, YamlError> {
    match doc.get(map, key).filter(|n| !is_null(n)) {
        None => Ok(false),
        Some(n) => match &n.data {
            YamlDataOwned::Value(ScalarOwned::Boolean(b)) => Ok(*b),
            YamlDataOwned::Representation(s, _, _) if s == "true" || s == "True" => Ok(true),
            YamlDataOwned::Representation(s, _, _) if s == "false" || s == "False" => Ok(false),
            _ => Err(doc.err(n, &format!("expected true or false for `{key}`, got {}", describe(n)))),
        },
    }
}

/// Parse `joint_limits.yaml` text; `file` names it in errors.
pub fn parse_joint_limits(text: &str, file: &Path) -> Result<JointLimitsFile, YamlError> {
    let doc = Doc::load(text, file)?;
    let mut root = doc.root()?;
    doc.expect_mapping(root, "a mapping with `joint_limits`")?;
    if let Some(inner) = doc.get(root, "robot_description_planning") {
        root = inner;
    }
    let limits = doc.require(root, "joint_limits", "a mapping from joint names to their limits")?;
    let YamlDataOwned::Mapping(map) = &limits.data else {
        return Err(
            doc.err(limits, &format!("expected a mapping from joint names to limits, got {}", describe(limits)))
        );
    };
    let mut out = JointLimitsFile { file: file.to_path_buf(), joints: Vec::new() };
    for (key, value) in map {
        let joint = doc.string(key, "a joint name")?;
        doc.expect_mapping(value, &format!("the limits of joint `{joint}` (a mapping)"))?;
        let number = |k: &str| -> Result<f64, YamlError> {
            let n = doc.require(value, k, &format!("{k} of joint `{joint}`"))?;
            doc.number(n, k)
        };
        let mut entry = JointLimitEntry { joint: joint.clone(), location: doc.loc(key), ..Default::default() };
        if flag(&doc, value, "has_velocity_limits")? {
            let v = number("max_velocity")?;
            if v <= 0.0 {
                return Err(doc.err(value, &format!("joint `{joint}`: max_velocity {v} (expected > 0)")));
            }
            entry.max_velocity = Some(v);
        }
        if flag(&doc, value, "has_acceleration_limits")? {
            let a = number("max_acceleration")?;
            if a <= 0.0 {
                return Err(doc.err(value, &format!("joint `{joint}`: max_acceleration {a} (expected > 0)")));
            }
            entry.max_acceleration = Some(a);
        }
        if flag(&doc, value, "has_position_limits")? {
            let (lo, hi) = (number("min_position")?, number("max_position")?);
            if lo > hi {
                return Err(doc.err(value, &format!("joint `{joint}`: min_position {lo} > max_position {hi}")));
            }
            entry.position = Some((lo, hi));
        }
        out.joints.push(entry);
    }
    Ok(out)
}

impl JointLimitsFile {
    /// Apply the limits to `robot`'s joints of the same names; returns how many joints changed.
    /// A joint the robot does not have is an error naming the file and line (a file written for
    /// another robot would otherwise be silently ignored).
    pub fn apply(&self, robot: &mut Robot) -> Result<usize, YamlError> {
        let mut changed = 0;
        for e in &self.joints {
            let Some(ji) = robot.joint_index(&e.joint) else {
                return Err(YamlError::Parse {
                    file: self.file.clone(),
                    line: e.location.line,
                    column: e.location.column,
                    message: format!(
                        "joint `{}` is not a joint of robot `{}` (expected one of: {})",
                        e.joint,
                        robot.name(),
                        robot.joint_names().join(", ")
                    ),
                });
            };
            let mut limits = robot.joints()[ji].limits;
            if let Some(v) = e.max_velocity {
                limits.max_velocity = v;
            }
            if let Some(a) = e.max_acceleration {
                limits.max_acceleration = a;
            }
            if let Some((lo, hi)) = e.position
                && limits.is_bounded()
            {
                limits.lower = lo;
                limits.upper = hi;
            }
            if limits != robot.joints()[ji].limits {
                robot.set_joint_limits(ji, limits);
                changed += 1;
            }
        }
        let provenance =
            format!("{}; limits from {} ({changed} joints changed)", robot.provenance(), self.file.display());
        robot.set_provenance(provenance);
        Ok(changed)
    }
}
