//! What every step of the loader reads and gathers: the scene text and where its files come from, the hash and
//! file list built while reading them, and errors that point into the text.

use crate::scene::error::line_of;
use crate::scene::SceneError;
use crate::texture::{Bitmap, Encoding};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where mesh and texture files come from.
pub(super) enum MeshSource<'a> {
    /// Paths relative to the scene file's folder.
    Folder(&'a Path),
    /// Contents by the path the scene writes.
    Memory(&'a BTreeMap<String, Vec<u8>>),
}

/// One scene file being loaded: its text, where its files come from, and what reading them gathers (the hash,
/// the list of files, the decoded textures).
pub(super) struct Loader<'a> {
    pub(super) text: &'a str,
    pub(super) file: &'a Path,
    pub(super) source: MeshSource<'a>,
    pub(super) hasher: Sha256,
    pub(super) mesh_files: Vec<(String, String)>,
    /// Textures decoded so far, by the path the scene writes and the encoding they were decoded with: a texture
    /// used twice is decoded once.
    pub(super) textures: BTreeMap<(String, Encoding), Arc<Bitmap>>,
    /// The bytes of the texture files read so far, by the path the scene writes, and where they were read: a file
    /// decoded in two encodings is read and hashed once.
    pub(super) texture_bytes: BTreeMap<String, (PathBuf, Arc<Vec<u8>>)>,
}

impl<'a> Loader<'a> {
    /// A loader of `text`, read from `file`, whose referenced files come from `source`.
    pub(super) fn new(text: &'a str, file: &'a Path, source: MeshSource<'a>) -> Self {
        Loader {
            text,
            file,
            source,
            hasher: Sha256::new(),
            mesh_files: Vec::new(),
            textures: BTreeMap::new(),
            texture_bytes: BTreeMap::new(),
        }
    }

    /// An error at `span` of the text (no line for a span the file does not have, such as a default's).
    pub(super) fn error(
        &self,
        span: Option<std::ops::Range<usize>>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> SceneError {
        SceneError {
            file: self.file.to_path_buf(),
            line: span.filter(|s| !(s.start == 0 && s.end == 0)).map(|s| line_of(self.text, s.start)),
            field: Some(field.into()),
            message: message.into(),
        }
    }
}
