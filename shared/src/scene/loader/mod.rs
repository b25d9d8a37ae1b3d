//! Reading a TOML scene file into a `SceneDescription`: parsing, checking every field with an error that names
//! the file, line and field, and reading the meshes and images the scene references (which the build step,
//! `crate::scene::build`, parses and decodes). The description is read in steps, one file each: `materials`,
//! `objects` (with their shapes), `lights` and `camera`; `files` reads the files a scene references, `values`
//! checks single numbers, vectors and colours, `textures` reads texture values (constants, bitmaps,
//! checkerboards), and `state` holds what every step reads and gathers.

mod camera;
mod files;
mod lights;
mod materials;
mod objects;
mod state;
mod textures;
mod values;

use super::description::{SceneDescription, SourceFormat};
use super::error::line_of;
use super::file::{RenderSection, SceneFile};
use super::{Scene, SceneError, SceneRenderSettings};
use state::{Loader, MeshSource};
use std::collections::BTreeMap;
use std::path::Path;

/// The files a reader read, by the path the scene writes: what `Scene::from_description` builds from.
pub type SceneFiles = BTreeMap<String, Vec<u8>>;

impl Scene {
    /// Reads and validates a scene file, TOML or (by the extension `.xml`) Mitsuba 3; meshes and textures are
    /// resolved relative to its folder.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let (desc, files) = SceneDescription::read(path, &crate::scene::MitsubaOptions::default())?;
        Scene::from_hashed_files(&desc, &files)
    }

    /// Parses scene text; `file` names it in errors and `base_dir` resolves mesh paths.
    pub fn from_toml(text: &str, file: &Path, base_dir: &Path) -> Result<Scene, SceneError> {
        let (desc, files) = SceneDescription::from_toml(text, file, base_dir)?;
        Scene::from_hashed_files(&desc, &files)
    }

    /// Parses scene text whose meshes and textures are given in memory, keyed by the path the scene writes.
    pub fn from_toml_with_meshes(
        text: &str,
        file: &Path,
        meshes: &BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        let (desc, files) = Loader::new(text, file, MeshSource::Memory(meshes)).load()?;
        Scene::from_hashed_files(&desc, &files)
    }
}

impl SceneDescription {
    /// Reads a TOML scene file into its description and the files it references; `file` names it in errors
    /// and `base_dir` resolves the files' paths.
    pub fn from_toml(text: &str, file: &Path, base_dir: &Path) -> Result<(SceneDescription, SceneFiles), SceneError> {
        Loader::new(text, file, MeshSource::Folder(base_dir)).load()
    }
}

impl Loader<'_> {
    /// Reads the description step by step. Errors are reported, and referenced files read, in this order: the
    /// render settings, the materials (with their textures), the objects (with their meshes and emission
    /// textures), the lights, then the camera.
    fn load(mut self) -> Result<(SceneDescription, SceneFiles), SceneError> {
        let parsed = self.parse()?;
        let render = self.render_settings(&parsed.render)?;
        let materials = self.materials(&parsed.materials)?;
        let mut objects = Vec::new();
        for (i, object) in parsed.objects.iter().enumerate() {
            objects.push(self.object(i, object, &materials)?);
        }
        let lights = self.lights(&parsed.lights)?;
        let camera = self.camera(&parsed.camera)?;
        let desc = SceneDescription {
            path: self.file.to_path_buf(),
            format: SourceFormat::Toml,
            render,
            camera,
            materials: materials.list,
            objects,
            lights,
            files: self.file_refs,
            notes: Vec::new(),
        };
        Ok((desc, self.bytes))
    }

    /// The file's TOML structure; a syntax or schema error names the line and, where the line has one, its key.
    fn parse(&self) -> Result<SceneFile, SceneError> {
        toml::from_str(self.text).map_err(|e| {
            let line = e.span().map(|s| line_of(self.text, s.start));
            let field = line.and_then(|l| {
                let src = self.text.lines().nth(l - 1)?;
                let key = src.split('=').next()?.trim();
                (!key.is_empty() && src.contains('=')).then(|| key.to_string())
            });
            SceneError { file: self.file.to_path_buf(), line, field, message: e.message().trim().to_string() }
        })
    }

    /// The `[render]` table: the defaults, with each value given checked.
    fn render_settings(&self, r: &RenderSection) -> Result<SceneRenderSettings, SceneError> {
        let mut s = SceneRenderSettings::default();
        if let Some(d) = &r.max_depth {
            if !(1..=1024).contains(d.get_ref()) {
                return Err(self.error(
                    Some(d.span()),
                    "render.max_depth",
                    format!("must be 1..=1024, got {}", d.get_ref()),
                ));
            }
            s.max_depth = *d.get_ref();
        }
        if let Some(d) = &r.backward_diffuse_depth {
            if !(1..=2).contains(d.get_ref()) {
                return Err(self.error(
                    Some(d.span()),
                    "render.backward_diffuse_depth",
                    format!("must be 1 or 2, got {}", d.get_ref()),
                ));
            }
            s.backward_diffuse_depth = Some(*d.get_ref());
        }
        if let Some(x) = &r.radius_scale {
            s.radius_scale =
                self.scalar(*x.get_ref(), &x.span(), "render.radius_scale", |v| v > 0.0, "a positive number")?;
        }
        if let Some(x) = &r.light_paths_per_pixel {
            s.light_paths_per_pixel = Some(self.scalar(
                *x.get_ref(),
                &x.span(),
                "render.light_paths_per_pixel",
                |v| v > 0.0 && v <= 1000.0,
                "in (0, 1000]",
            )?);
        }
        if let Some(b) = r.ghost_light_paths {
            s.ghost_light_paths = b;
        }
        if let Some(k) = &r.ghost_paths {
            if *k.get_ref() > super::ghost::MAX_GHOST_PATHS {
                return Err(self.error(
                    Some(k.span()),
                    "render.ghost_paths",
                    format!("must be at most {}, got {}", super::ghost::MAX_GHOST_PATHS, k.get_ref()),
                ));
            }
            s.ghost_paths = *k.get_ref();
        }
        if let Some(x) = &r.ghost_radius {
            let max = super::ghost::MAX_GHOST_RADIUS;
            s.ghost_radius = self.scalar(
                *x.get_ref(),
                &x.span(),
                "render.ghost_radius",
                |v| (0.0..=max).contains(&v),
                &format!("in [0, {max}] (pixels)"),
            )?;
        }
        Ok(s)
    }
}
