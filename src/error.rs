//! Errors of the CLI layer: each names the file, the place and what was expected.

use std::path::PathBuf;

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
    #[error("{0}")]
    Usage(String),
    #[error("{0}")]
    Failed(String),
}

impl AppError {
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        AppError::Io { file: file.into(), source }
    }
}
