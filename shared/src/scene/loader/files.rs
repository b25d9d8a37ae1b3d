//! The files a scene references, meshes (OBJ) and textures (PNG, JPEG, OpenEXR, Radiance HDR, PFM, told apart by
//! their first bytes): read from the scene's folder or from what a job sent, added to the scene's hash and file
//! list, and decoded.

use super::state::{Loader, MeshSource};
use crate::geometry::{Mesh, MeshTriangle};
use crate::scene::SceneError;
use crate::texture::{Bitmap, Encoding};
use glam::{Vec2, Vec3};
use sha2::{Digest, Sha256};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use toml::Spanned;

/// Texture coordinates of a shape's triangles, in order, when it has them.
pub(super) type TriangleUvs = Option<Vec<[Vec2; 3]>>;

impl<'a> Loader<'a> {
    /// Reads a file the scene references (`what`: "mesh" or "texture"), adds it to the hash and to the files a
    /// job sends.
    fn external_file(
        &mut self,
        name: &str,
        span: Option<std::ops::Range<usize>>,
        field: &str,
        what: &str,
    ) -> Result<(PathBuf, Cow<'a, [u8]>), SceneError> {
        let (path, bytes) = match &self.source {
            MeshSource::Folder(dir) => {
                let path = dir.join(name);
                let bytes = std::fs::read(&path).map_err(|e| {
                    self.error(span.clone(), field, format!("cannot read {what} {}: {e}", path.display()))
                })?;
                (path, Cow::Owned(bytes))
            }
            MeshSource::Memory(files) => {
                let files: &'a BTreeMap<String, Vec<u8>> = files;
                let bytes = files.get(name).ok_or_else(|| {
                    self.error(span.clone(), field, format!("{what} {name} was not sent with the job"))
                })?;
                (PathBuf::from(name), Cow::Borrowed(bytes.as_slice()))
            }
        };
        self.hasher.update(&bytes);
        self.mesh_files.push((name.to_string(), format!("{:x}", Sha256::digest(&bytes))));
        Ok((path, bytes))
    }

    /// Reads a texture file once per path and decodes it once per encoding of its integer samples (Mitsuba's
    /// `raw` is `Encoding::Linear`).
    pub(super) fn bitmap(
        &mut self,
        name: &str,
        span: Option<std::ops::Range<usize>>,
        field: &str,
        encoding: Encoding,
    ) -> Result<Arc<Bitmap>, SceneError> {
        let key = (name.to_string(), encoding);
        if let Some(t) = self.textures.get(&key) {
            return Ok(t.clone());
        }
        let bytes = match self.texture_bytes.get(name) {
            Some((path, bytes)) => (path.clone(), bytes.clone()),
            None => {
                let (path, bytes) = self.external_file(name, span.clone(), field, "texture")?;
                let file = (path, Arc::new(bytes.into_owned()));
                self.texture_bytes.insert(name.to_string(), file.clone());
                file
            }
        };
        let (path, bytes) = bytes;
        let texture = Bitmap::decode(&bytes, name, encoding)
            .map_err(|e| self.error(span, field, format!("{}: {e}", path.display())))?;
        let texture = Arc::new(texture);
        self.textures.insert(key, texture.clone());
        Ok(texture)
    }

    /// A mesh and, when every triangle has them (OBJ `vt`), its texture coordinates.
    pub(super) fn mesh(&mut self, m: &Spanned<String>, field: &str) -> Result<(Mesh, TriangleUvs), SceneError> {
        let (path, bytes) = self.external_file(m.get_ref(), Some(m.span()), field, "mesh")?;
        let (models, _) = tobj::load_obj_buf(
            &mut std::io::BufReader::new(&bytes[..]),
            &tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true },
            |_| Err(tobj::LoadError::OpenFileFailed),
        )
        .map_err(|e| self.error(Some(m.span()), field, format!("cannot parse OBJ {}: {e}", path.display())))?;
        let mut mesh = Mesh::default();
        let mut uvs = Some(Vec::new());
        for model in &models {
            let pos = &model.mesh.positions;
            let nrm = &model.mesh.normals;
            let tex = &model.mesh.texcoords;
            let vertices = pos.len() / 3;
            // With single_index tobj gives a vertex a normal or texture coordinate only where its face corner
            // names one: when some corners do and others do not, the lists no longer line up with the vertices.
            let partial = |what: &str, tag: &str| {
                self.error(
                    Some(m.span()),
                    field,
                    format!(
                        "{}: '{}' gives {what} ({tag}) for some face corners but not for others; give them on every \
                        face of the object or on none",
                        path.display(),
                        model.name
                    ),
                )
            };
            if !nrm.is_empty() && nrm.len() != 3 * vertices {
                return Err(partial("vertex normals", "f v/vt/vn"));
            }
            if !tex.is_empty() && tex.len() != 2 * vertices {
                return Err(partial("texture coordinates", "f v/vt"));
            }
            let model_uvs = !tex.is_empty() && vertices > 0;
            let vertex = |i: u32| Vec3::new(pos[3 * i as usize], pos[3 * i as usize + 1], pos[3 * i as usize + 2]);
            let normal = |i: u32| Vec3::new(nrm[3 * i as usize], nrm[3 * i as usize + 1], nrm[3 * i as usize + 2]);
            for (k, tri) in model.mesh.indices.chunks_exact(3).enumerate() {
                let v = [vertex(tri[0]), vertex(tri[1]), vertex(tri[2])];
                let bad = |what: &str| {
                    self.error(
                        Some(m.span()),
                        field,
                        format!("{}: triangle {k} of '{}' {what}", path.display(), model.name),
                    )
                };
                if !v.iter().all(|p| p.is_finite()) {
                    return Err(bad("has a coordinate that is not a finite number"));
                }
                let t = MeshTriangle {
                    v,
                    n: if nrm.is_empty() { None } else { Some([normal(tri[0]), normal(tri[1]), normal(tri[2])]) },
                };
                let scale = (v[1] - v[0]).length().max((v[2] - v[0]).length());
                if t.area() <= 1e-7 * scale * scale || t.area() == 0.0 {
                    return Err(bad("is degenerate (zero area)"));
                }
                if let Some(n) = t.n {
                    if !n.iter().all(|x| x.is_finite() && x.length_squared() > 0.0) {
                        return Err(bad("has a vertex normal that is zero or not finite"));
                    }
                }
                mesh.triangles.push(t);
                if let Some(list) = &mut uvs {
                    if model_uvs {
                        let uv = |i: u32| Vec2::new(tex[2 * i as usize], tex[2 * i as usize + 1]);
                        let uv = [uv(tri[0]), uv(tri[1]), uv(tri[2])];
                        if !uv.iter().all(|c| c.is_finite()) {
                            return Err(bad("has a texture coordinate that is not a finite number"));
                        }
                        list.push(uv);
                    } else {
                        uvs = None;
                    }
                }
            }
        }
        if mesh.triangles.is_empty() {
            return Err(self.error(Some(m.span()), field, format!("{} contains no triangles", path.display())));
        }
        Ok((mesh, uvs))
    }
}
