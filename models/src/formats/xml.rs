//! Position-keeping XML access shared by the URDF and SRDF readers: every error names
//! `file:line:column` and what was expected there.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use roxmltree::{Document, Node};

use crate::error::ModelError;

/// A parsed XML document with its file name, for errors that name `file:line:column`.
pub(crate) struct Xml<'i> {
    pub(crate) doc: Document<'i>,
    pub(crate) file: PathBuf,
}

impl<'i> Xml<'i> {
    pub(crate) fn parse(text: &'i str, file: &Path) -> Result<Self, ModelError> {
        if let Err(message) = super::limits::check_values(text, super::limits::Syntax::Xml) {
            return Err(ModelError::Parse { file: file.to_path_buf(), line: 1, column: 1, message });
        }
        match Document::parse(text) {
            Ok(doc) => Ok(Self { doc, file: file.to_path_buf() }),
            Err(e) => {
                let pos = e.pos();
                Err(ModelError::Parse {
                    file: file.to_path_buf(),
                    line: pos.row,
                    column: pos.col,
                    message: format!("malformed XML (expected well-formed XML): {e}"),
                })
            }
        }
    }

    pub(crate) fn err_at(&self, byte: usize, message: String) -> ModelError {
        let pos = self.doc.text_pos_at(byte);
        ModelError::Parse { file: self.file.clone(), line: pos.row, column: pos.col, message }
    }

    pub(crate) fn err(&self, node: Node, message: String) -> ModelError {
        self.err_at(node.range().start, message)
    }

    /// Line and column (1-based) where `node` starts.
    pub(crate) fn position(&self, node: Node) -> (u32, u32) {
        let pos = self.doc.text_pos_at(node.range().start);
        (pos.row, pos.col)
    }

    pub(crate) fn line(&self, node: Node) -> u32 {
        self.doc.text_pos_at(node.range().start).row
    }

    /// Byte position of an attribute's value (or of the element if absent).
    pub(crate) fn attr_pos(&self, node: Node, name: &str) -> usize {
        node.attribute_node(name).map_or(node.range().start, |a| a.range_value().start)
    }

    /// A required attribute.
    pub(crate) fn attr<'a>(&self, node: Node<'a, 'i>, name: &str, expected: &str) -> Result<&'a str, ModelError> {
        node.attribute(name).ok_or_else(|| {
            self.err(
                node,
                format!(
                    "<{}> is missing the required attribute `{name}` (expected {expected})",
                    node.tag_name().name()
                ),
            )
        })
    }

    /// Whitespace-separated finite numbers of an attribute value, exactly `n` of them.
    pub(crate) fn numbers(
        &self,
        node: Node,
        name: &str,
        text: &str,
        n: usize,
        expected: &str,
    ) -> Result<Vec<f64>, ModelError> {
        let pos = self.attr_pos(node, name);
        let tag = node.tag_name().name();
        let mut out = Vec::with_capacity(n);
        for word in text.split_whitespace() {
            match word.parse::<f64>() {
                Ok(v) if v.is_finite() => out.push(v),
                _ => {
                    return Err(self.err_at(
                        pos,
                        format!("attribute `{name}` of <{tag}>: `{word}` is not a finite number (expected {expected})"),
                    ));
                }
            }
        }
        if out.len() != n {
            return Err(self.err_at(
                pos,
                format!("attribute `{name}` of <{tag}> has {} numbers in `{text}` (expected {expected})", out.len()),
            ));
        }
        Ok(out)
    }

    /// A required single number.
    pub(crate) fn number(&self, node: Node, name: &str, expected: &str) -> Result<f64, ModelError> {
        let text = self.attr(node, name, expected)?;
        Ok(self.numbers(node, name, text, 1, expected)?[0])
    }

    /// An optional single number.
    pub(crate) fn number_or(&self, node: Node, name: &str, default: f64, expected: &str) -> Result<f64, ModelError> {
        match node.attribute(name) {
            Some(text) => Ok(self.numbers(node, name, text, 1, expected)?[0]),
            None => Ok(default),
        }
    }

    /// A non-negative required number.
    pub(crate) fn length(&self, node: Node, name: &str, expected: &str) -> Result<f64, ModelError> {
        let v = self.number(node, name, expected)?;
        if v < 0.0 {
            return Err(self.err_at(
                self.attr_pos(node, name),
                format!("attribute `{name}` of <{}> is negative: {v} (expected {expected})", node.tag_name().name()),
            ));
        }
        Ok(v)
    }

    /// An optional 3-vector.
    pub(crate) fn vec3_or(&self, node: Node, name: &str, default: [f64; 3]) -> Result<Vector3<f64>, ModelError> {
        match node.attribute(name) {
            Some(text) => {
                let v = self.numbers(node, name, text, 3, "three numbers \"x y z\"")?;
                Ok(Vector3::new(v[0], v[1], v[2]))
            }
            None => Ok(Vector3::from(default)),
        }
    }
}

pub(crate) fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.is_element() && n.tag_name().name() == tag)
}

pub(crate) fn children<'a, 'i>(node: Node<'a, 'i>, tag: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(move |n| n.is_element() && n.tag_name().name() == tag)
}
