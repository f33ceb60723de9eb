//! The crate's one error type: each error names the file, the place and what was expected.

use std::io::Read;

use embodied_models::formats::limits::{self, InputKind};
use std::path::{Path, PathBuf};

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
    /// Standard output could not be written (a closed pipe: the reader has what it wanted).
    #[error("cannot write to standard output: {0}")]
    Output(std::io::Error),
    /// The request itself is wrong (an unknown name, a value out of range).
    #[error("{0}")]
    Usage(String),
    /// The work ran but did not succeed (no plan, a plan rejected, a run that failed).
    #[error("{0}")]
    Failed(String),
}

/// Exit status: the work was done and succeeded.
pub const EXIT_OK: u8 = 0;
/// Exit status: the work was done but did not succeed (no plan, not certified, goal not reached).
pub const EXIT_NOT_SUCCEEDED: u8 = 1;
/// Exit status: bad input (arguments, files), nothing was done.
pub const EXIT_BAD_INPUT: u8 = 2;

impl SystemError {
    /// The process exit status this error stands for.
    pub fn exit_code(&self) -> u8 {
        match self {
            SystemError::Failed(_) => EXIT_NOT_SUCCEEDED,
            SystemError::Output(e) if e.kind() == std::io::ErrorKind::BrokenPipe => EXIT_OK,
            _ => EXIT_BAD_INPUT,
        }
    }

    /// A read error on `file`.
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SystemError::Io { file: file.into(), source }
    }

    /// A write error on `file`.
    pub fn write(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SystemError::Write { file: file.into(), source }
    }
}

/// The text of a file argument; `-` reads standard input. A file (or standard input) larger than
/// the limit for `kind` ([`embodied_models::formats::limits`]) is refused before it is read.
pub fn read_input(path: &Path, kind: InputKind) -> Result<String, SystemError> {
    if path == Path::new("-") {
        let limit = match kind {
            InputKind::Log => limits::input_limits().max_log_bytes,
            InputKind::Mesh => limits::input_limits().max_mesh_bytes,
            InputKind::Text => limits::input_limits().max_text_bytes,
        };
        let mut bytes = Vec::new();
        std::io::stdin()
            .lock()
            .take(limit.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(|e| SystemError::io("<stdin>", e))?;
        limits::check_size(bytes.len() as u64, kind).map_err(|e| SystemError::io("<stdin>", e))?;
        String::from_utf8(bytes).map_err(|_| {
            SystemError::io("<stdin>", std::io::Error::new(std::io::ErrorKind::InvalidData, "not UTF-8 text"))
        })
    } else {
        limits::read_text_limited(path, kind).map_err(|e| SystemError::io(path, e))
    }
}
