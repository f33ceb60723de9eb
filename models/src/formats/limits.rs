//! How big an input file may be, checked before it is read, so that a 1 GB mesh or a plan with
//! ten million waypoints is refused with an error naming the file and the limit instead of
//! being swallowed into memory.
//!
//! Two bounds, both process-wide ([`set_input_limits`]; the command line sets them from
//! `--max-input-mb` and `--max-input-values`):
//!
//! - **bytes**, from the file's metadata before a byte is read ([`read_text_limited`],
//!   [`read_bytes_limited`]): [`InputLimits::max_text_bytes`] for descriptions, scenarios,
//!   YAML, plan files and trajectories, [`InputLimits::max_mesh_bytes`] for meshes and
//!   [`InputLimits::max_log_bytes`] for run logs;
//! - **values**, an upper bound on how many values (array elements, map entries, XML elements)
//!   a text holds, counted in one pass over its bytes before it is parsed ([`check_values`]):
//!   the separators `,` `:` `[` `{` and line breaks for TOML, YAML and JSON, the `<` of every
//!   tag for XML. A parser's tree costs tens of bytes per value, so this bounds its memory where
//!   the byte limit alone would not (a 60 MB YAML list of zeros is 30 million nodes).
//!
//! The refusal is an [`std::io::Error`] of kind [`std::io::ErrorKind::FileTooLarge`], so every
//! loader reports it as it reports any other file it cannot read: `cannot read FILE: ...`.

use std::io::{Error, ErrorKind, Read};
use std::path::Path;
use std::sync::RwLock;

/// The size bounds of input files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputLimits {
    /// Largest text file (URDF, SRDF, scenario, MoveIt YAML, plan, trajectory), bytes.
    pub max_text_bytes: u64,
    /// Largest mesh file (STL, OBJ, Collada), bytes.
    pub max_mesh_bytes: u64,
    /// Largest run log, bytes.
    pub max_log_bytes: u64,
    /// Most values a text file may hold (see the module documentation for how they are counted).
    pub max_values: usize,
    /// Most triangles a mesh may have.
    pub max_mesh_triangles: usize,
    /// Most links a URDF may have.
    pub max_links: usize,
}

/// 1 MiB.
pub const MIB: u64 = 1 << 20;

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            max_text_bytes: 256 * MIB,
            max_mesh_bytes: 256 * MIB,
            max_log_bytes: 4096 * MIB,
            max_values: 10_000_000,
            max_mesh_triangles: 5_000_000,
            max_links: 10_000,
        }
    }
}

static LIMITS: RwLock<Option<InputLimits>> = RwLock::new(None);

/// Set the process-wide input limits (a program sets them once, from its options).
pub fn set_input_limits(limits: InputLimits) {
    if let Ok(mut l) = LIMITS.write() {
        *l = Some(limits);
    }
}

/// The process-wide input limits ([`InputLimits::default`] unless set).
pub fn input_limits() -> InputLimits {
    LIMITS.read().ok().and_then(|l| *l).unwrap_or_default()
}

/// What kind of file is read: which byte limit applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// A text file: robot description, scenario, YAML, plan, trajectory.
    Text,
    /// A mesh.
    Mesh,
    /// A run log.
    Log,
}

impl InputKind {
    fn limit(self, l: &InputLimits) -> u64 {
        match self {
            InputKind::Text => l.max_text_bytes,
            InputKind::Mesh => l.max_mesh_bytes,
            InputKind::Log => l.max_log_bytes,
        }
    }

    fn noun(self) -> &'static str {
        match self {
            InputKind::Text => "a text input (description, scenario, YAML, plan or trajectory)",
            InputKind::Mesh => "a mesh",
            InputKind::Log => "a run log",
        }
    }
}

/// A size in words: `1.5 GB`, `312 kB`, `12 bytes`.
pub fn human_bytes(n: u64) -> String {
    let f = n as f64;
    if f >= 1e9 {
        format!("{:.2} GB", f / 1e9)
    } else if f >= 1e6 {
        format!("{:.1} MB", f / 1e6)
    } else if f >= 1e3 {
        format!("{:.1} kB", f / 1e3)
    } else {
        format!("{n} bytes")
    }
}

fn too_large(message: String) -> Error {
    Error::new(ErrorKind::FileTooLarge, message)
}

/// Refuse `size` bytes of a `kind` input if it exceeds its limit.
pub fn check_size(size: u64, kind: InputKind) -> std::io::Result<()> {
    let limit = kind.limit(&input_limits());
    if size > limit {
        return Err(too_large(format!(
            "{} is larger than the limit of {} for {} (raise it with --max-input-mb)",
            human_bytes(size),
            human_bytes(limit),
            kind.noun()
        )));
    }
    Ok(())
}

/// The bytes of `path`, refused before reading if its size exceeds `kind`'s limit. A file that
/// grows while it is read is cut at the limit and refused too.
pub fn read_bytes_limited(path: &Path, kind: InputKind) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let len = file.metadata()?.len();
    check_size(len, kind)?;
    let limit = kind.limit(&input_limits());
    let mut out = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(limit.saturating_add(1)).read_to_end(&mut out)?;
    check_size(out.len() as u64, kind)?;
    Ok(out)
}

/// The text (UTF-8) of `path`, refused before reading if its size exceeds `kind`'s limit.
pub fn read_text_limited(path: &Path, kind: InputKind) -> std::io::Result<String> {
    let bytes = read_bytes_limited(path, kind)?;
    String::from_utf8(bytes).map_err(|_| Error::new(ErrorKind::InvalidData, "stream did not contain valid UTF-8"))
}

/// How values are separated in a text format, for [`count_values`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Syntax {
    /// TOML, YAML and JSON: `,` `:` `[` `{` and line breaks.
    Data,
    /// XML: `<`.
    Xml,
}

/// An upper bound (up to a small constant) on the number of values in `text`.
pub fn count_values(text: &str, syntax: Syntax) -> usize {
    let bytes = text.as_bytes();
    match syntax {
        Syntax::Data => bytes.iter().filter(|b| matches!(b, b',' | b':' | b'[' | b'{' | b'\n')).count(),
        Syntax::Xml => bytes.iter().filter(|&&b| b == b'<').count(),
    }
}

/// The message refusing a text with more values than [`InputLimits::max_values`], if it has.
pub fn check_values(text: &str, syntax: Syntax) -> Result<(), String> {
    let max = input_limits().max_values;
    // Fewer bytes than the limit cannot hold more values: no need to count.
    if text.len() <= max {
        return Ok(());
    }
    let n = count_values(text, syntax);
    if n > max {
        return Err(format!(
            "the file holds about {n} values, more than the limit of {max} (raise it with --max-input-values)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_counted_by_separator() {
        assert_eq!(count_values("[1, 2, 3]\n", Syntax::Data), 4);
        assert_eq!(count_values("<a><b/></a>", Syntax::Xml), 3);
        assert!(check_values("[1,2]", Syntax::Data).is_ok());
    }

    #[test]
    fn sizes_read_as_words() {
        assert_eq!(human_bytes(12), "12 bytes");
        assert_eq!(human_bytes(1_500_000_000), "1.50 GB");
    }
}
