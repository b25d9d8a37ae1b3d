//! Turning a Mitsuba 3 `Document` into photonfarm's `Scene`, the same description the TOML loader builds: the
//! sensor (`camera`), the shapes with their materials and area emitters (`shapes`, `meshes`, `bsdfs`,
//! `textures`), the other emitters (`emitters`) and the integrator's depth. Every plugin and parameter is either
//! mapped to an exact counterpart, ignored with a note in `Scene::notes` (sampler, reconstruction filter, film
//! output format), or refused with the file, line and element (`params` checks that nothing is left unread).
//! The scene's hash covers the XML, its includes and every mesh and texture, in the order they are read, so that
//! a worker rebuilding the scene from a job's files gets the coordinator's scene.

mod bsdfs;
mod camera;
mod emitters;
mod meshes;
mod params;
mod shapes;
mod textures;

use super::files::{relative_key, FileSource};
use super::{Document, MitsubaError, MitsubaOptions, Plugin, SourcePos};
use crate::color::Rgb;
use crate::geometry::{Analytic, MeshTriangle, SceneGeometry};
use crate::light::{EmissionTexture, Light, Lights};
use crate::material::Material;
use crate::scene::{Scene, SceneError, SceneObject, SceneRenderSettings};
use crate::texture::{Bitmap, Encoding};
use glam::Vec2;
use meshes::IndexedMesh;
use params::Params;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

impl Scene {
    /// Reads a Mitsuba 3 scene file and everything it references, as `options` say.
    pub fn load_mitsuba(path: &Path, options: &MitsubaOptions) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            file: path.to_path_buf(),
            line: None,
            field: None,
            message: format!("cannot read the scene file: {e}"),
        })?;
        let document = super::read_file(path, &options.defines).map_err(scene_error)?;
        Importer::new(&document, &text, options, FileSource::Disk).import().map_err(scene_error)
    }

    /// Builds a Mitsuba scene from its text and the files a job sent, keyed by their path relative to the scene
    /// file's folder (`mesh_files`), as a worker does; `name` is the scene file's name.
    pub fn from_mitsuba_with_files(
        text: &str,
        name: &Path,
        options: &MitsubaOptions,
        files: &BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        let source = FileSource::Memory(files);
        let document = super::read_str_from(text, name, &options.defines, source).map_err(scene_error)?;
        Importer::new(&document, text, options, source).import().map_err(scene_error)
    }
}

/// A Mitsuba error as a scene error: the file and line, the element as the field.
fn scene_error(e: MitsubaError) -> SceneError {
    SceneError {
        file: e.position.file.as_ref().clone(),
        line: Some(e.position.line as usize),
        field: e.element,
        message: e.message,
    }
}

/// The mapping of one document: what it reads (files, hashed in order) and what it gathers.
struct Importer<'d> {
    doc: &'d Document,
    source: FileSource<'d>,
    hasher: Sha256,
    /// Every file read besides the scene file, by its path relative to the scene's folder, and its SHA-256.
    files: Vec<(String, String)>,
    /// Keys already hashed: a mesh or texture used twice is sent once.
    hashed: HashMap<PathBuf, String>,
    /// `--approximate`: what has no exact counterpart is substituted (`Importer::approximate`) instead of refused.
    approximating: bool,
    bitmaps: HashMap<(PathBuf, Encoding), Arc<Bitmap>>,
    notes: Vec<String>,
    materials: Vec<Material>,
    /// The material of each BSDF plugin already mapped (by address: a referenced BSDF is mapped once).
    material_of: HashMap<*const Plugin, u32>,
    /// The mesh of each mesh shape already read (by address: an instanced shape is read once).
    meshes: HashMap<*const Plugin, Arc<IndexedMesh>>,
    objects: Vec<SceneObject>,
    triangles: Vec<(u32, MeshTriangle)>,
    triangle_uvs: Vec<Option<[Vec2; 3]>>,
    analytic: Vec<(u32, Analytic)>,
    lights: Vec<Light>,
    light_textures: Vec<Option<EmissionTexture>>,
}

impl<'d> Importer<'d> {
    /// The mapping of `doc`, read from `text` with `options`: both go into the hash, since the same text with
    /// other defines, or approximated, is another scene.
    fn new(doc: &'d Document, text: &str, options: &MitsubaOptions, source: FileSource<'d>) -> Self {
        let mut hasher = Sha256::new();
        hasher.update(text.as_bytes());
        for (name, value) in &options.defines {
            hasher.update(format!("\0{name}={value}").as_bytes());
        }
        if options.approximate {
            hasher.update(b"\0--approximate");
        }
        Importer {
            doc,
            source,
            hasher,
            files: Vec::new(),
            hashed: HashMap::new(),
            approximating: options.approximate,
            bitmaps: HashMap::new(),
            notes: Vec::new(),
            materials: Vec::new(),
            material_of: HashMap::new(),
            meshes: HashMap::new(),
            objects: Vec::new(),
            triangles: Vec::new(),
            triangle_uvs: Vec::new(),
            analytic: Vec::new(),
            lights: Vec::new(),
            light_textures: Vec::new(),
        }
    }

    /// The scene, mapped in this order (the order files are read and hashed in): included files, the
    /// integrator, the shapes (with their BSDFs, textures and meshes), the other emitters, the sensor.
    fn import(mut self) -> Result<Scene, MitsubaError> {
        let start = SourcePos::file_start(&self.doc.path);
        for path in &self.doc.files {
            self.hash_file(path, &start)?;
        }
        let render = self.integrator()?;
        for other in &self.doc.others {
            let refusal = other.error(format!(
                "a top-level {} is not supported (photonfarm renders surfaces in vacuum)",
                other.element()
            ));
            self.approximate(refusal, "without it")?;
        }
        // BSDFs and textures declared at the top level and referenced by no shape are unused, as in Mitsuba.
        for shape in &self.doc.shapes {
            self.shape(shape)?;
        }
        for emitter in &self.doc.emitters {
            let light = self.emitter(emitter)?;
            self.lights.push(light);
            self.light_textures.push(None);
        }
        let camera = self.camera()?;
        self.assemble(render, camera)
    }

    /// The integrator's depth; other settings are noted.
    fn integrator(&mut self) -> Result<SceneRenderSettings, MitsubaError> {
        let mut render = SceneRenderSettings::default();
        let Some(plugin) = self.doc.integrator.clone() else {
            // Mitsuba's default integrator is `path` with max_depth −1 (unbounded).
            self.notes.push(format!(
                "the scene names no integrator: Mitsuba's default path tracer has no depth limit, rendered here with \
                 max_depth {}",
                render.max_depth
            ));
            return Ok(render);
        };
        let p = Params::new(&plugin);
        let exact = matches!(plugin.kind.as_str(), "path" | "volpath" | "direct");
        if !exact {
            let refusal = p.error(format!(
                "the integrator `{}` has no counterpart (photonfarm renders what `path` computes); give \
                 <integrator type=\"path\"> or, where the file reads `$integrator`, --define integrator=path",
                plugin.kind
            ));
            self.approximate(refusal, "as `path` with its max_depth, its other parameters ignored")?;
        }
        match plugin.kind.as_str() {
            "direct" => {
                // Emitters seen directly and light reflected once: paths of at most two segments.
                render.max_depth = 2;
                p.ignore(&["emitter_samples", "bsdf_samples", "shading_samples"]);
                self.notes.push(format!("{} is rendered as paths of at most two segments", plugin.element()));
            }
            _ => {
                let depth = p.integer("max_depth")?.unwrap_or(-1);
                match depth {
                    -1 => self.notes.push(format!(
                        "{} max_depth −1 (unbounded) is rendered with max_depth {}",
                        plugin.element(),
                        render.max_depth
                    )),
                    1..=1024 => render.max_depth = depth as u32,
                    _ => {
                        let param = plugin.param("max_depth").expect("read above");
                        return Err(p.error_at(param, format!("must be −1 or 1..=1024, got {depth}")));
                    }
                }
                if !exact {
                    // Another integrator's parameters mean what it makes of them: only the depth carries over.
                    return Ok(render);
                }
                if p.integer("rr_depth")?.is_some() {
                    self.notes.push("the integrator's rr_depth is ignored (photonfarm chooses its own)".into());
                }
                if p.boolean("hide_emitters", false)? {
                    self.approximate(p.error("hide_emitters = true is not supported"), "with the emitters seen")?;
                }
            }
        }
        p.finish()?;
        Ok(render)
    }

    /// Under `--approximate`, notes that the element `refusal` names is rendered `instead` and lets the mapping
    /// go on; otherwise `refusal` is the error.
    fn approximate(&mut self, refusal: MitsubaError, instead: &str) -> Result<(), MitsubaError> {
        if !self.approximating {
            return Err(refusal);
        }
        self.notes.push(format!("approximated: {refusal}; rendered {instead}"));
        Ok(())
    }

    /// Reads a file the scene references (relative to the scene's folder as Mitsuba resolves it), adds it to
    /// the hash and to the files a job sends.
    fn read_file(&mut self, name: &str, at: &SourcePos, element: &str) -> Result<(PathBuf, Vec<u8>), MitsubaError> {
        let path = self.doc.resolve_file_in(name, self.source);
        let bytes = self.source.read(&path).map_err(|m| MitsubaError::at(at, element, m))?;
        self.hash_bytes(&path, &bytes, at)?;
        Ok((path, bytes.into_owned()))
    }

    /// Hashes an included file (read by the XML reader).
    fn hash_file(&mut self, path: &Path, at: &SourcePos) -> Result<(), MitsubaError> {
        let bytes = self.source.read(path).map_err(|m| MitsubaError::in_file(at.clone(), m))?;
        self.hash_bytes(path, &bytes, at)
    }

    fn hash_bytes(&mut self, path: &Path, bytes: &[u8], at: &SourcePos) -> Result<(), MitsubaError> {
        if self.hashed.contains_key(path) {
            return Ok(());
        }
        let key = match self.source {
            FileSource::Disk => {
                let folder = self.doc.path.parent().unwrap_or(Path::new(""));
                relative_key(folder, path).map_err(|m| MitsubaError::in_file(at.clone(), m))?
            }
            FileSource::Memory(_) => path.to_string_lossy().into_owned(),
        };
        self.hasher.update(bytes);
        let digest = format!("{:x}", Sha256::digest(bytes));
        self.hashed.insert(path.to_path_buf(), key.clone());
        self.files.push((key, digest));
        Ok(())
    }

    /// A texture image, read and decoded once per file and encoding.
    fn bitmap(
        &mut self,
        name: &str,
        encoding: Encoding,
        at: &SourcePos,
        element: &str,
    ) -> Result<Arc<Bitmap>, MitsubaError> {
        let path = self.doc.resolve_file_in(name, self.source);
        if let Some(b) = self.bitmaps.get(&(path.clone(), encoding)) {
            return Ok(b.clone());
        }
        let (path, bytes) = self.read_file(name, at, element)?;
        let bitmap = Bitmap::decode(&bytes, name, encoding)
            .map_err(|e| MitsubaError::at(at, element, format!("{}: {e}", path.display())))?;
        let bitmap = Arc::new(bitmap);
        self.bitmaps.insert((path, encoding), bitmap.clone());
        Ok(bitmap)
    }

    /// The scene from its mapped parts.
    fn assemble(self, render: SceneRenderSettings, camera: crate::camera::Camera) -> Result<Scene, MitsubaError> {
        let start = SourcePos::file_start(&self.doc.path);
        let geometry = SceneGeometry::build(self.triangles, self.analytic)
            .map_err(|e| MitsubaError::in_file(start.clone(), e.to_string()))?;
        let sphere = crate::light::infinite::SceneSphere::around(geometry.bounds());
        let lights = Lights::with_textures(self.lights, self.light_textures, geometry.triangle_count(), sphere);
        if !lights.any() {
            return Err(MitsubaError::in_file(
                start,
                "the scene has no light photonfarm renders: give a shape an <emitter type=\"area\"> or add a point, \
                 spot, envmap, constant or directional emitter",
            ));
        }
        let has_delta_surfaces = self.objects.iter().any(|o| self.materials[o.material as usize].has_delta());
        Ok(Scene {
            path: self.doc.path.clone(),
            camera,
            materials: self.materials,
            triangle_uvs: self.triangle_uvs,
            objects: self.objects,
            geometry,
            lights,
            render,
            hash: format!("{:x}", self.hasher.finalize()),
            mesh_files: self.files,
            has_delta_surfaces,
            ghost_pairs: OnceLock::new(),
            notes: self.notes,
        })
    }
}

/// A colour as photonfarm's single precision.
fn rgb(c: [f64; 3]) -> Rgb {
    Rgb::new(c[0] as f32, c[1] as f32, c[2] as f32)
}
