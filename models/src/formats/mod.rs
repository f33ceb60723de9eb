//! Every file format a robot or a MoveIt problem comes in, each in its own module:
//!
//! - [`urdf`]: the kinematic tree and collision geometry;
//! - [`srdf`]: MoveIt's semantic description (groups, states, end effectors, collision pairs);
//! - [`mesh`]: STL, Collada and OBJ collision meshes and their convex pieces;
//! - [`moveit`]: MoveIt planning scenes and motion plan requests (YAML);
//! - [`joint_limits`]: MoveIt's `joint_limits.yaml` (acceleration limits URDF lacks);
//! - [`trajectory`]: `trajectory_msgs/JointTrajectory` in YAML or JSON, in and out;
//! - [`limits`]: how big an input may be, checked before it is read;
//! - `xml` and [`yaml`]: reading with positions, so every error names `file:line:column`.
//!
//! None of these modules uses another except the position helpers; this module joins a URDF and
//! its SRDF ([`load_description`]).

pub mod joint_limits;
pub mod limits;
pub mod mesh;
pub mod moveit;
pub mod srdf;
pub mod trajectory;
pub mod urdf;
pub(crate) mod xml;
pub mod yaml;

use std::path::Path;

use crate::error::{ModelError, Warning};
use crate::robot::Robot;
use srdf::{Srdf, parse_srdf};
use urdf::{HomeState, Semantics, UrdfOptions, parse_urdf_with, read_urdf_text};

/// A robot with the SRDF it was loaded with and every warning raised on the way.
#[derive(Debug, Clone)]
pub struct Description {
    /// The robot, with the SRDF's end effectors, `home` and collision pairs applied.
    pub robot: Robot,
    /// The SRDF, if one was given.
    pub srdf: Option<Srdf>,
    /// Warnings from the URDF (missing name, dropped meshes) and the SRDF (unknown elements).
    pub warnings: Vec<Warning>,
}

/// What the URDF loader takes from an SRDF: end effectors, the `home` group state (values of
/// the SRDF's virtual joints and of multi-value joints skipped: the URDF has no such joint) and
/// the collision pairs to ignore.
pub fn semantics(srdf: &Srdf) -> Semantics {
    let end_effectors =
        srdf.end_effectors.iter().map(|e| (e.name.clone(), e.parent_link.clone(), e.line, e.column)).collect();
    let home = srdf.group_state("home").map(|s| {
        let values = s
            .values
            .iter()
            .filter(|(j, v)| v.len() == 1 && !srdf.is_virtual_joint(j))
            .map(|(j, v)| (j.clone(), v[0]))
            .collect();
        HomeState { values, line: s.line, column: s.column }
    });
    Semantics { file: srdf.file.clone(), end_effectors, home, disabled: Vec::new() }
}

/// Load a URDF (or `.xacro`) file and, if given, its SRDF.
pub fn load_description(urdf: &Path, srdf: Option<&Path>, options: &UrdfOptions) -> Result<Description, ModelError> {
    let text = read_urdf_text(urdf)?;
    let srdf = match srdf {
        Some(p) => Some(parse_srdf(&read_text(p)?, p)?),
        None => None,
    };
    describe(&text, urdf, options, srdf)
}

fn describe(text: &str, file: &Path, options: &UrdfOptions, srdf: Option<Srdf>) -> Result<Description, ModelError> {
    let sem = srdf.as_ref().map(semantics);
    let load = parse_urdf_with(text, file, options, sem.as_ref())?;
    let mut robot = load.robot;
    let mut warnings = load.warnings;
    let mut srdf = srdf;
    if let Some(s) = &mut srdf {
        s.reconcile(&robot);
        for (a, b) in s.disabled_pairs(&robot) {
            robot.disable_pair(a, b);
        }
        warnings.extend(s.warnings.iter().cloned());
    }
    Ok(Description { robot, srdf, warnings })
}

static WARNING_SINK: std::sync::RwLock<Option<fn(&Warning)>> = std::sync::RwLock::new(None);

/// Where [`load_urdf`] and [`load_urdf_with`] send their warnings (a program prints them; by
/// default they are dropped). [`load_description`] returns them instead.
pub fn set_warning_sink(sink: fn(&Warning)) {
    if let Ok(mut s) = WARNING_SINK.write() {
        *s = Some(sink);
    }
}

/// Load a URDF file (meshes loaded, default limits), applying an SRDF file if given
/// (collision pairs, the `home` group state, end effectors). Warnings go to the sink set with
/// [`set_warning_sink`]; use [`load_description`] to get them.
pub fn load_urdf(path: &Path, srdf: Option<&Path>) -> Result<Robot, ModelError> {
    load_urdf_with(path, srdf, &UrdfOptions::default())
}

/// [`load_urdf`] with explicit options.
pub fn load_urdf_with(path: &Path, srdf: Option<&Path>, options: &UrdfOptions) -> Result<Robot, ModelError> {
    let d = load_description(path, srdf, options)?;
    if let Some(sink) = WARNING_SINK.read().ok().and_then(|s| *s) {
        d.warnings.iter().for_each(sink);
    }
    Ok(d.robot)
}

/// Parse URDF text and apply an already parsed SRDF (collision pairs, `home`, end effectors).
pub fn parse_urdf_with_srdf(text: &str, file: &Path, options: &UrdfOptions, srdf: &Srdf) -> Result<Robot, ModelError> {
    Ok(describe(text, file, options, Some(srdf.clone()))?.robot)
}

fn read_text(path: &Path) -> Result<String, ModelError> {
    limits::read_text_limited(path, limits::InputKind::Text)
        .map_err(|source| ModelError::Io { file: path.to_path_buf(), source })
}
