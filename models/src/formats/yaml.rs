//! YAML read with positions (saphyr's marked nodes): every error names `file:line:column`
//! (1-based) and what was expected there. Shared by the MoveIt, joint-limits and trajectory
//! readers.

use std::path::{Path, PathBuf};

use saphyr::{LoadableYamlNode, MarkedYamlOwned, ScalarOwned, YamlDataOwned};

use crate::error::ModelError;

/// What can go wrong reading a YAML file (a MoveIt scene or request, `joint_limits.yaml`, a
/// joint trajectory).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum YamlError {
    /// Malformed YAML or content that is not what a scene/request holds; 1-based line and column.
    #[error("{}:{line}:{column}: {message}", file.display())]
    Parse {
        /// The file that is malformed.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
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
    /// The robot model refused something (unknown group, joint that cannot be frozen, ...).
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// A 1-based line and column in the source file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Location {
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
}

/// A YAML node with its position.
pub type Node = MarkedYamlOwned;

/// Whether a node is YAML null.
pub fn is_null(n: &Node) -> bool {
    matches!(n.data, YamlDataOwned::Value(ScalarOwned::Null))
}

/// A short description of a node's kind and value for "got ..." in error messages.
pub fn describe(n: &Node) -> String {
    match &n.data {
        YamlDataOwned::Value(ScalarOwned::Null) => "nothing (null)".into(),
        YamlDataOwned::Value(ScalarOwned::Boolean(b)) => format!("the boolean {b}"),
        YamlDataOwned::Value(ScalarOwned::Integer(i)) => format!("the number {i}"),
        YamlDataOwned::Value(ScalarOwned::FloatingPoint(f)) => format!("the number {}", f.0),
        YamlDataOwned::Value(ScalarOwned::String(s)) => format!("the string `{s}`"),
        YamlDataOwned::Representation(s, _, _) => format!("`{s}`"),
        YamlDataOwned::Sequence(s) => format!("a list of {} item{}", s.len(), if s.len() == 1 { "" } else { "s" }),
        YamlDataOwned::Mapping(_) => "a mapping".into(),
        YamlDataOwned::Tagged(tag, _) => format!("a value tagged {tag}"),
        YamlDataOwned::Alias(_) => "an alias".into(),
        YamlDataOwned::BadValue => "an invalid value".into(),
    }
}

/// A parsed YAML file.
pub struct Doc<'a> {
    /// The file, named in errors.
    pub file: &'a Path,
    docs: Vec<Node>,
}

impl<'a> Doc<'a> {
    /// Parse `text`; `file` names it in errors.
    pub fn load(text: &str, file: &'a Path) -> Result<Self, YamlError> {
        if let Err(message) = super::limits::check_values(text, super::limits::Syntax::Data) {
            return Err(YamlError::Parse { file: file.to_path_buf(), line: 1, column: 1, message });
        }
        match Node::load_from_str(text) {
            Ok(docs) => Ok(Self { file, docs }),
            Err(e) => {
                let m = e.marker();
                Err(YamlError::Parse {
                    file: file.to_path_buf(),
                    line: m.line(),
                    column: m.col() + 1,
                    message: format!("invalid YAML: {}", e.info()),
                })
            }
        }
    }

    /// The one document of the file.
    pub fn root(&self) -> Result<&Node, YamlError> {
        match self.docs.as_slice() {
            [one] => Ok(one),
            [] => Err(YamlError::Parse {
                file: self.file.to_path_buf(),
                line: 1,
                column: 1,
                message: "expected a YAML document, the file is empty".into(),
            }),
            [_, second, ..] => Err(self.err(second, "expected one YAML document, found several")),
        }
    }

    /// Where a node starts.
    pub fn loc(&self, n: &Node) -> Location {
        Location { line: n.span.start.line().max(1), column: n.span.start.col() + 1 }
    }

    /// An error at a node.
    pub fn err(&self, n: &Node, message: &str) -> YamlError {
        let at = self.loc(n);
        YamlError::Parse {
            file: self.file.to_path_buf(),
            line: at.line,
            column: at.column,
            message: message.to_string(),
        }
    }

    /// A mapping, or an error saying `what` was expected.
    pub fn expect_mapping(&self, n: &Node, what: &str) -> Result<(), YamlError> {
        if n.data.is_mapping() { Ok(()) } else { Err(self.err(n, &format!("expected {what}, got {}", describe(n)))) }
    }

    /// The value of `key` in a mapping.
    pub fn get<'n>(&self, map: &'n Node, key: &str) -> Option<&'n Node> {
        match &map.data {
            YamlDataOwned::Mapping(m) => m.iter().find_map(|(k, v)| match &k.data {
                YamlDataOwned::Value(ScalarOwned::String(s)) if s == key => Some(v),
                YamlDataOwned::Representation(s, _, _) if s == key => Some(v),
                _ => None,
            }),
            _ => None,
        }
    }

    /// The value of a required `key`.
    pub fn require<'n>(&self, map: &'n Node, key: &str, what: &str) -> Result<&'n Node, YamlError> {
        self.expect_mapping(map, &format!("a mapping with `{key}`"))?;
        self.get(map, key).ok_or_else(|| self.err(map, &format!("missing `{key}` ({what})")))
    }

    /// A list.
    pub fn seq<'n>(&self, n: &'n Node, what: &str) -> Result<&'n [Node], YamlError> {
        match &n.data {
            YamlDataOwned::Sequence(s) => Ok(s.as_slice()),
            _ => Err(self.err(n, &format!("expected a list for {what}, got {}", describe(n)))),
        }
    }

    /// A string (or a bare integer, as a string).
    pub fn string(&self, n: &Node, what: &str) -> Result<String, YamlError> {
        match &n.data {
            YamlDataOwned::Value(ScalarOwned::String(s)) => Ok(s.clone()),
            YamlDataOwned::Representation(s, _, _) => Ok(s.clone()),
            // Names like `1` are valid ROS names only as strings, but be forgiving.
            YamlDataOwned::Value(ScalarOwned::Integer(i)) => Ok(i.to_string()),
            _ => Err(self.err(n, &format!("expected a string for {what}, got {}", describe(n)))),
        }
    }

    /// A finite number.
    pub fn number(&self, n: &Node, what: &str) -> Result<f64, YamlError> {
        let v = match &n.data {
            YamlDataOwned::Value(ScalarOwned::Integer(i)) => *i as f64,
            YamlDataOwned::Value(ScalarOwned::FloatingPoint(f)) => f.0,
            YamlDataOwned::Representation(s, _, _) => match s.trim().parse::<f64>() {
                Ok(v) => v,
                Err(_) => return Err(self.err(n, &format!("expected a number for {what}, got `{s}`"))),
            },
            _ => return Err(self.err(n, &format!("expected a number for {what}, got {}", describe(n)))),
        };
        if !v.is_finite() {
            return Err(self.err(n, &format!("expected a finite number for {what}, got {v}")));
        }
        Ok(v)
    }

    /// A list of exactly `len` numbers (any length when `len` is `None`).
    pub fn numbers(&self, n: &Node, len: Option<usize>, what: &str) -> Result<Vec<f64>, YamlError> {
        let expected = match len {
            Some(k) => format!("a list of {k} number{}", if k == 1 { "" } else { "s" }),
            None => "a list of numbers".to_string(),
        };
        let YamlDataOwned::Sequence(items) = &n.data else {
            return Err(self.err(n, &format!("expected {expected} for {what}, got {}", describe(n))));
        };
        if let Some(k) = len
            && items.len() != k
        {
            return Err(self.err(n, &format!("expected {expected} for {what}, got {}", items.len())));
        }
        items.iter().map(|x| self.number(x, what)).collect()
    }
}
