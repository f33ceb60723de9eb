//! Errors of the CLI layer: each names the file, the place and what was expected.

use std::io::Read;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AppError {
    #[error(transparent)]
    Model(#[from] embodied_models::ModelError),
    #[error("{}:{line}:{column}: {message}", file.display())]
    Parse { file: PathBuf, line: usize, column: usize, message: String },
    #[error("cannot read {}: {source}", file.display())]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file that could not be created or written.
    #[error("cannot write {}: {source}", file.display())]
    Write {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Standard output could not be written (a closed pipe: the reader has what it wanted).
    #[error("cannot write to standard output: {0}")]
    Output(std::io::Error),
    #[error("{0}")]
    Usage(String),
    /// The input was good and the work was done, but it did not succeed (no plan, not
    /// certified, goal not reached, a run that failed).
    #[error("{0}")]
    Failed(String),
}

/// Exit status: the work was done and succeeded.
pub const EXIT_OK: u8 = 0;
/// Exit status: the work was done but did not succeed (no plan, not certified, goal not reached).
pub const EXIT_NOT_SUCCEEDED: u8 = 1;
/// Exit status: bad input (arguments, files), nothing was done.
pub const EXIT_BAD_INPUT: u8 = 2;

impl AppError {
    /// A file that could not be read.
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        AppError::Io { file: file.into(), source }
    }

    /// A file that could not be written.
    pub fn write(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        AppError::Write { file: file.into(), source }
    }

    /// The process exit status this error stands for.
    pub fn exit_code(&self) -> u8 {
        match self {
            AppError::Failed(_) => EXIT_NOT_SUCCEEDED,
            AppError::Output(e) if e.kind() == std::io::ErrorKind::BrokenPipe => EXIT_OK,
            _ => EXIT_BAD_INPUT,
        }
    }
}

/// The text of a file argument; `-` reads standard input.
pub fn read_input(path: &Path) -> Result<String, AppError> {
    if path == Path::new("-") {
        let mut text = String::new();
        std::io::stdin().read_to_string(&mut text).map_err(|e| AppError::io("<stdin>", e))?;
        Ok(text)
    } else {
        std::fs::read_to_string(path).map_err(|e| AppError::io(path, e))
    }
}
