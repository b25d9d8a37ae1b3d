//! Turning a Mitsuba 3 `Document` into a `SceneDescription`, the same description the TOML reader gives: the
//! sensor (`camera`), the shapes with their materials and area emitters (`shapes`, `bsdfs`, `textures`), the
//! other emitters (`emitters`) and the integrator's depth. Every plugin and parameter is either mapped to an
//! exact counterpart, ignored with a note in the description's notes (sampler, reconstruction filter, film
//! output format), or refused with the file, line and element (`params` checks that nothing is left unread).
//! Mesh and image files are read here only to be named by their hash; the build step parses and decodes them.

mod bsdfs;
mod camera;
mod emitters;
mod params;
mod shapes;
mod textures;

use super::files::{relative_key, FileSource};
use super::{Document, MitsubaError, MitsubaOptions, Plugin, SourcePos};
use crate::color::Rgb;
use crate::scene::description::{
    CameraDesc, FileRef, ImageRef, LightDesc, MaterialDesc, ObjectDesc, SceneDescription, Source, SourceFormat,
};
use crate::scene::{Scene, SceneError, SceneFiles, SceneRenderSettings};
use crate::texture::Encoding;
use params::Params;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

impl Scene {
    /// Reads a Mitsuba 3 scene file and everything it references, as `options` say.
    pub fn load_mitsuba(path: &Path, options: &MitsubaOptions) -> Result<Scene, SceneError> {
        let (desc, files) = SceneDescription::from_mitsuba(path, options)?;
        Scene::from_hashed_files(&desc, &files)
    }

    /// Builds a Mitsuba scene from its text and the files it references, keyed by their path relative to the
    /// scene file's folder; `name` is the scene file's name.
    pub fn from_mitsuba_with_files(
        text: &str,
        name: &Path,
        options: &MitsubaOptions,
        files: &BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        let source = FileSource::Memory(files);
        let document = super::read_str_from(text, name, &options.defines, source).map_err(scene_error)?;
        let (desc, files) = Importer::new(&document, options, source).import().map_err(scene_error)?;
        Scene::from_hashed_files(&desc, &files)
    }
}

impl SceneDescription {
    /// Reads a Mitsuba 3 scene file into its description and the files it references, as `options` say.
    pub fn from_mitsuba(path: &Path, options: &MitsubaOptions) -> Result<(SceneDescription, SceneFiles), SceneError> {
        std::fs::read_to_string(path).map_err(|e| SceneError {
            file: path.to_path_buf(),
            line: None,
            field: None,
            message: format!("cannot read the scene file: {e}"),
        })?;
        let document = super::read_file(path, &options.defines).map_err(scene_error)?;
        Importer::new(&document, options, FileSource::Disk).import().map_err(scene_error)
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

/// Where an element is written, as a description's source.
fn source(at: &SourcePos, element: impl Into<String>) -> Source {
    Source { file: at.file.as_ref().clone(), line: Some(at.line as usize), element: Some(element.into()) }
}

/// The mapping of one document: what it reads (files, named by their hash) and what it gathers.
struct Importer<'d> {
    doc: &'d Document,
    source: FileSource<'d>,
    /// Every file read, by its path relative to the scene's folder, and its SHA-256, in the order first read.
    files: Vec<FileRef>,
    /// Their bytes, by the same path.
    bytes: SceneFiles,
    /// `--approximate`: what has no exact counterpart is substituted (`Importer::approximate`) instead of refused.
    approximating: bool,
    notes: Vec<String>,
    materials: Vec<MaterialDesc>,
    /// The material of each BSDF plugin already mapped (by address: a referenced BSDF is mapped once).
    material_of: HashMap<*const Plugin, u32>,
    objects: Vec<ObjectDesc>,
    lights: Vec<LightDesc>,
}

impl<'d> Importer<'d> {
    /// The mapping of `doc`, read with `options`.
    fn new(doc: &'d Document, options: &MitsubaOptions, source: FileSource<'d>) -> Self {
        Importer {
            doc,
            source,
            files: Vec::new(),
            bytes: BTreeMap::new(),
            approximating: options.approximate,
            notes: Vec::new(),
            materials: Vec::new(),
            material_of: HashMap::new(),
            objects: Vec::new(),
            lights: Vec::new(),
        }
    }

    /// The description, mapped in this order (the order files are read in): the integrator, the shapes (with
    /// their BSDFs, textures and meshes), the other emitters, the sensor.
    fn import(mut self) -> Result<(SceneDescription, SceneFiles), MitsubaError> {
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
        }
        let camera: CameraDesc = self.camera()?;
        let desc = SceneDescription {
            path: self.doc.path.clone(),
            format: SourceFormat::Mitsuba,
            render,
            camera,
            materials: self.materials,
            objects: self.objects,
            lights: self.lights,
            files: self.files,
            notes: self.notes,
        };
        Ok((desc, self.bytes))
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

    /// Reads a file the scene references (relative to the scene's folder as Mitsuba resolves it) the first
    /// time it is named, and gives its reference.
    fn read_file(&mut self, name: &str, at: &SourcePos, element: &str) -> Result<FileRef, MitsubaError> {
        let path = self.doc.resolve_file_in(name, self.source);
        let bytes = self.source.read(&path).map_err(|m| MitsubaError::at(at, element, m))?;
        let key = match self.source {
            FileSource::Disk => {
                let folder = self.doc.path.parent().unwrap_or(Path::new(""));
                relative_key(folder, &path).map_err(|m| MitsubaError::in_file(at.clone(), m))?
            }
            FileSource::Memory(_) => path.to_string_lossy().into_owned(),
        };
        if let Some(known) = self.files.iter().find(|f| f.path == key) {
            return Ok(known.clone());
        }
        let file = FileRef { path: key.clone(), sha256: format!("{:x}", Sha256::digest(&bytes)) };
        self.bytes.insert(key, bytes.into_owned());
        self.files.push(file.clone());
        Ok(file)
    }

    /// A texture image, decoded with `encoding` by the build step.
    fn bitmap(
        &mut self,
        name: &str,
        encoding: Encoding,
        at: &SourcePos,
        element: &str,
    ) -> Result<ImageRef, MitsubaError> {
        let file = self.read_file(name, at, element)?;
        Ok(ImageRef { file, encoding, bound: None, source: source(at, element) })
    }
}

/// A colour as photonfarm's single precision.
fn rgb(c: [f64; 3]) -> Rgb {
    Rgb::new(c[0] as f32, c[1] as f32, c[2] as f32)
}
