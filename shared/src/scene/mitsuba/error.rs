//! Errors of the Mitsuba reader: each names the file, line and column and the element a user has to fix.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where an element or attribute starts in a scene file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SourcePos {
    /// The file (the including file's path joined with the `<include>` name for included files).
    pub file: Arc<PathBuf>,
    /// 1-based line.
    pub line: u32,
    /// 1-based column, in characters.
    pub column: u32,
}

impl SourcePos {
    /// The start of `file`, for problems with a file as a whole.
    pub fn file_start(file: &Path) -> SourcePos {
        SourcePos { file: Arc::new(file.to_path_buf()), line: 1, column: 1 }
    }
}

impl fmt::Display for SourcePos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// A problem in a Mitsuba scene file, or in a file it names.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{position}: {}{message}", element.as_deref().map(|e| format!("{e}: ")).unwrap_or_default())]
pub struct MitsubaError {
    /// Where the problem is.
    pub position: SourcePos,
    /// The element as written, e.g. `<bsdf type="hair">`, when the problem belongs to one.
    pub element: Option<String>,
    /// What is wrong and, where possible, what would be right.
    pub message: String,
}

impl MitsubaError {
    /// An error at `position` in `element`.
    pub fn at(position: &SourcePos, element: impl Into<String>, message: impl Into<String>) -> MitsubaError {
        MitsubaError { position: position.clone(), element: Some(element.into()), message: message.into() }
    }

    /// An error about a whole file (it cannot be read, or is not XML).
    pub fn in_file(position: SourcePos, message: impl Into<String>) -> MitsubaError {
        MitsubaError { position, element: None, message: message.into() }
    }
}
