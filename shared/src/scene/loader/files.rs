//! The files a scene references, meshes (OBJ) and images: read from the scene's folder or from what was sent,
//! once each, and named in the description by their path and SHA-256. Parsing and decoding them is the build
//! step's (`crate::scene::build`).

use super::state::{Loader, MeshSource};
use crate::scene::description::{FileRef, ImageRef};
use crate::scene::SceneError;
use crate::texture::Encoding;
use sha2::{Digest, Sha256};

impl Loader<'_> {
    /// Reads a file the scene references (`what`: "mesh" or "texture") the first time it is named, and gives
    /// its reference.
    pub(super) fn external_file(
        &mut self,
        name: &str,
        span: Option<std::ops::Range<usize>>,
        field: &str,
        what: &str,
    ) -> Result<FileRef, SceneError> {
        if let Some(known) = self.file_refs.iter().find(|f| f.path == name) {
            return Ok(known.clone());
        }
        let bytes = match &self.source {
            MeshSource::Folder(dir) => {
                let path = dir.join(name);
                std::fs::read(&path).map_err(|e| {
                    self.error(span.clone(), field, format!("cannot read {what} {}: {e}", path.display()))
                })?
            }
            MeshSource::Memory(files) => files
                .get(name)
                .ok_or_else(|| self.error(span.clone(), field, format!("{what} {name} was not sent with the job")))?
                .clone(),
        };
        let file = FileRef { path: name.to_string(), sha256: format!("{:x}", Sha256::digest(&bytes)) };
        self.bytes.insert(name.to_string(), bytes);
        self.file_refs.push(file.clone());
        Ok(file)
    }

    /// An image file the scene references, decoded with `encoding` by the build step (Mitsuba's `raw` is
    /// `Encoding::Linear`), without a bound.
    pub(super) fn image(
        &mut self,
        name: &str,
        span: Option<std::ops::Range<usize>>,
        field: &str,
        encoding: Encoding,
    ) -> Result<ImageRef, SceneError> {
        let file = self.external_file(name, span.clone(), field, "texture")?;
        Ok(ImageRef { file, encoding, bound: None, source: self.source(span, field) })
    }
}
