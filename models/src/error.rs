//! The one error type of `embodied-models`.

use std::path::PathBuf;

/// Everything that can go wrong when building, loading or querying a robot model.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A name that is not one of the built-in robots.
    #[error("unknown robot model `{name}`; built-in models are: {}", known.join(", "))]
    UnknownModel {
        /// The name asked for.
        name: String,
        /// The built-in model names.
        known: Vec<String>,
    },
    /// A joint vector of the wrong length.
    #[error("robot `{robot}` has {expected} joints, got {got} joint values")]
    WrongDof {
        /// The robot's name.
        robot: String,
        /// Its number of degrees of freedom.
        expected: usize,
        /// The number of joint values given.
        got: usize,
    },
    /// A joint value outside its position limits.
    #[error("joint `{joint}` value {value} is outside its limits [{lower}, {upper}]")]
    OutOfLimits {
        /// The joint's name.
        joint: String,
        /// The value given (rad or m).
        value: f64,
        /// Lower position limit (rad or m).
        lower: f64,
        /// Upper position limit (rad or m).
        upper: f64,
    },
    /// A configuration that puts a joint-driving actuator (screw) outside its stroke.
    #[error("actuator `{actuator}` length {length:.5} m is outside its stroke [{min:.5}, {max:.5}] m")]
    OutOfStroke {
        /// The actuator's name.
        actuator: String,
        /// Its length at the configuration (m).
        length: f64,
        /// Shortest length (m).
        min: f64,
        /// Longest length (m).
        max: f64,
    },
    /// A joint value that is NaN or infinite.
    #[error("joint `{joint}` value {value} is not a finite number")]
    NotFinite {
        /// The joint's name.
        joint: String,
        /// The value given.
        value: f64,
    },
    /// A malformed URDF/SRDF/XML file.
    #[error("{}:{line}:{column}: {message}", file.display())]
    Parse {
        /// The file that is malformed.
        file: PathBuf,
        /// 1-based line.
        line: u32,
        /// 1-based column.
        column: u32,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A file that could not be read.
    #[error("cannot read {}: {source}", file.display())]
    Io {
        /// The file that could not be read.
        file: PathBuf,
        #[source]
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// A mesh referenced by a URDF that is missing or unreadable.
    #[error("{}:{line}: mesh `{uri}` -> {}: {reason}", urdf.display(), resolved.display())]
    Mesh {
        /// The URDF file that references the mesh.
        urdf: PathBuf,
        /// 1-based line of the `<mesh>` element.
        line: u32,
        /// The mesh's `filename` as written in the URDF.
        uri: String,
        /// The path the URI resolved to.
        resolved: PathBuf,
        /// Why the mesh could not be used.
        reason: String,
    },
    /// A structurally invalid robot (cycles, unknown links, several roots...).
    #[error("invalid robot `{robot}`: {message}")]
    Invalid {
        /// The robot's name.
        robot: String,
        /// What is wrong.
        message: String,
    },
    /// Inverse kinematics did not converge.
    #[error("inverse kinematics did not converge for `{frame}`: residual {residual:.3e} after {iterations} iterations")]
    IkFailed {
        /// The end-effector frame asked for.
        frame: String,
        /// The smallest pose error reached over every restart.
        residual: f64,
        /// The iteration budget spent (iterations per attempt times attempts).
        iterations: usize,
    },
    /// A closed-form inverse kinematics asked of an end effector that has none.
    #[error("robot `{robot}`: end effector `{frame}` has no closed-form inverse kinematics (use the numerical one)")]
    NoClosedForm {
        /// The robot's name.
        robot: String,
        /// The end effector asked for.
        frame: String,
    },
    /// A frame, link or joint name that the robot does not have.
    #[error("robot `{robot}` has no {what} named `{name}`")]
    NoSuchName {
        /// The robot's name.
        robot: String,
        /// What kind of name it is ("link", "joint", "end effector", ...).
        what: &'static str,
        /// The name asked for.
        name: String,
    },
}

/// Something noticed while reading a file that did not stop the load (an unknown SRDF element, a
/// dropped mesh, a missing robot name), with where it was written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    /// The file read.
    pub file: PathBuf,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub column: u32,
    /// What was noticed and what was done about it.
    pub message: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}:{}: warning: {}", self.file.display(), self.line, self.column, self.message)
    }
}
