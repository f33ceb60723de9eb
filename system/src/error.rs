//! The crate's one error type: each error names the file, the place and what was expected.

use std::path::PathBuf;

/// What can go wrong when a system is read, assembled, run, planned or checked.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SystemError {
    /// A robot model could not be made.
    #[error(transparent)]
    Model(#[from] embodied_models::ModelError),
    /// A file does not say what it must, at `file:line:column`.
    #[error("{}:{line}:{column}: {message}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What was expected.
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file could not be written.
    #[error("cannot write {}: {source}", file.display())]
    Write {
        /// The file.
        file: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The request itself is wrong (an unknown name, a value out of range).
    #[error("{0}")]
    Usage(String),
    /// The work ran but did not succeed (no plan, a plan rejected, a run that failed).
    #[error("{0}")]
    Failed(String),
}

impl SystemError {
    /// A read error on `file`.
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SystemError::Io { file: file.into(), source }
    }

    /// A write error on `file`.
    pub fn write(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SystemError::Write { file: file.into(), source }
    }
}
