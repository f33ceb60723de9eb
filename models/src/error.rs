//! The one error type of `embodied-models`.

use std::path::PathBuf;

/// Everything that can go wrong when building, loading or querying a robot model.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A name that is not one of the built-in robots.
    #[error("unknown robot model `{name}`; built-in models are: {}", known.join(", "))]
    UnknownModel { name: String, known: Vec<String> },
    /// A joint vector of the wrong length.
    #[error("robot `{robot}` has {expected} joints, got {got} joint values")]
    WrongDof { robot: String, expected: usize, got: usize },
    /// A joint value outside its position limits.
    #[error("joint `{joint}` value {value} is outside its limits [{lower}, {upper}]")]
    OutOfLimits { joint: String, value: f64, lower: f64, upper: f64 },
    /// A joint value that is NaN or infinite.
    #[error("joint `{joint}` value {value} is not a finite number")]
    NotFinite { joint: String, value: f64 },
    /// A malformed URDF/SRDF/XML file.
    #[error("{}:{line}:{column}: {message}", file.display())]
    Parse { file: PathBuf, line: u32, column: u32, message: String },
    /// A file that could not be read.
    #[error("cannot read {}: {source}", file.display())]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A mesh referenced by a URDF that is missing or unreadable.
    #[error("{}:{line}: mesh `{uri}` -> {}: {reason}", urdf.display(), resolved.display())]
    Mesh { urdf: PathBuf, line: u32, uri: String, resolved: PathBuf, reason: String },
    /// A structurally invalid robot (cycles, unknown links, several roots...).
    #[error("invalid robot `{robot}`: {message}")]
    Invalid { robot: String, message: String },
    /// Inverse kinematics did not converge.
    #[error("inverse kinematics did not converge for `{frame}`: residual {residual:.3e} after {iterations} iterations")]
    IkFailed { frame: String, residual: f64, iterations: usize },
    /// A closed-form inverse kinematics asked of an end effector that has none.
    #[error("robot `{robot}`: end effector `{frame}` has no closed-form inverse kinematics (use the numerical one)")]
    NoClosedForm { robot: String, frame: String },
    /// A frame, link or joint name that the robot does not have.
    #[error("robot `{robot}` has no {what} named `{name}`")]
    NoSuchName { robot: String, what: &'static str, name: String },
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
