//! The run log: JSON Lines, one header line, one line per control step, one summary line.
//!
//! Every line is written and flushed as soon as it exists, so a run that fails or is
//! interrupted leaves a valid log up to its last step.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::AppError;

/// Where log lines go.
pub struct RunLog {
    out: Option<(PathBuf, BufWriter<File>)>,
    lines: usize,
}

impl RunLog {
    /// A log written to `path`, or a log that discards lines when `path` is `None`.
    pub fn create(path: Option<&Path>) -> Result<Self, AppError> {
        let out = match path {
            Some(p) => Some((p.to_path_buf(), BufWriter::new(File::create(p).map_err(|e| AppError::write(p, e))?))),
            None => None,
        };
        Ok(Self { out, lines: 0 })
    }

    /// Append one record as a line and flush it to the file.
    pub fn line<T: Serialize>(&mut self, record: &T) -> Result<(), AppError> {
        self.lines += 1;
        let Some((path, w)) = self.out.as_mut() else { return Ok(()) };
        serde_json::to_writer(&mut *w, record).map_err(|e| AppError::Failed(format!("log {}: {e}", path.display())))?;
        w.write_all(b"\n").and_then(|_| w.flush()).map_err(|e| AppError::write(path.clone(), e))
    }

    /// Number of lines written so far.
    pub fn lines(&self) -> usize {
        self.lines
    }
}
