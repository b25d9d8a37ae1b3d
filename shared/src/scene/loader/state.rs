//! What every step of the reader reads and gathers: the scene text and where its files come from, the files
//! read so far (their bytes and their references), and errors and sources that point into the text.

use crate::scene::description::{FileRef, Source};
use crate::scene::error::line_of;
use crate::scene::SceneError;
use std::collections::BTreeMap;
use std::path::Path;

/// Where mesh and texture files come from.
pub(super) enum MeshSource<'a> {
    /// Paths relative to the scene file's folder.
    Folder(&'a Path),
    /// Contents by the path the scene writes.
    Memory(&'a BTreeMap<String, Vec<u8>>),
}

/// One scene file being read: its text, where its files come from, and the files read so far.
pub(super) struct Loader<'a> {
    pub(super) text: &'a str,
    pub(super) file: &'a Path,
    pub(super) source: MeshSource<'a>,
    /// Every file read, once, in the order first read.
    pub(super) file_refs: Vec<FileRef>,
    /// Their bytes, by the path the scene writes: what the build step reads.
    pub(super) bytes: BTreeMap<String, Vec<u8>>,
}

impl<'a> Loader<'a> {
    /// A reader of `text`, read from `file`, whose referenced files come from `source`.
    pub(super) fn new(text: &'a str, file: &'a Path, source: MeshSource<'a>) -> Self {
        Loader { text, file, source, file_refs: Vec::new(), bytes: BTreeMap::new() }
    }

    /// Where `field` is written, at `span` of the text (no line for a span the file does not have, such as a
    /// default's).
    pub(super) fn source(&self, span: Option<std::ops::Range<usize>>, field: impl Into<String>) -> Source {
        Source {
            file: self.file.to_path_buf(),
            line: span.filter(|s| !(s.start == 0 && s.end == 0)).map(|s| line_of(self.text, s.start)),
            element: Some(field.into()),
        }
    }

    /// An error at `span` of the text.
    pub(super) fn error(
        &self,
        span: Option<std::ops::Range<usize>>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> SceneError {
        self.source(span, field).error(message)
    }
}
