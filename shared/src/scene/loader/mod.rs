//! Building a `Scene` from its TOML file: parsing, checking every field with an error that names the file, line
//! and field, reading the meshes and textures the scene references, and hashing all of it. The scene is built
//! in steps, one file each: `materials`, `objects` (with their shapes), `lights` and `camera`; `files` reads the
//! files a scene references, `values` checks single numbers, vectors and colours, `textures` reads texture
//! values (constants, bitmaps, checkerboards), and `state` holds what
//! every step reads and gathers.

mod camera;
mod files;
mod lights;
mod materials;
mod objects;
mod state;
mod textures;
mod values;

use super::error::line_of;
use super::file::{RenderSection, SceneFile};
use super::{Scene, SceneError, SceneRenderSettings};
use crate::camera::Camera;
use crate::geometry::SceneGeometry;
use crate::light::infinite::SceneSphere;
use crate::light::{Light, Lights};
use materials::Materials;
use objects::ObjectParts;
use sha2::Digest;
use state::{Loader, MeshSource};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;

impl Scene {
    /// Reads and validates a scene file, TOML or (by the extension `.xml`) Mitsuba 3; meshes and textures are
    /// resolved relative to its folder.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        if super::is_mitsuba(path) {
            return Scene::load_mitsuba(path, &crate::scene::MitsubaOptions::default());
        }
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            file: path.to_path_buf(),
            line: None,
            field: None,
            message: format!("cannot read the scene file: {e}"),
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Scene::from_toml(&text, path, base)
    }

    /// Parses scene text; `file` names it in errors and `base_dir` resolves mesh paths.
    pub fn from_toml(text: &str, file: &Path, base_dir: &Path) -> Result<Scene, SceneError> {
        Loader::new(text, file, MeshSource::Folder(base_dir)).load()
    }

    /// Parses scene text whose meshes and textures are given in memory, keyed by the path the scene writes (a
    /// worker that received them over the network).
    pub fn from_toml_with_meshes(
        text: &str,
        file: &Path,
        meshes: &BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        Loader::new(text, file, MeshSource::Memory(meshes)).load()
    }
}

impl Loader<'_> {
    /// Builds the scene step by step. Errors are reported, and referenced files read and hashed, in this order:
    /// the render settings, the materials (with their textures), the objects (with their meshes and emission
    /// textures), the lights, then the camera, which may name an object.
    fn load(mut self) -> Result<Scene, SceneError> {
        self.hasher.update(self.text.as_bytes());
        let parsed = self.parse()?;
        let render = self.render_settings(&parsed.render)?;
        let materials = self.materials(&parsed.materials)?;
        let mut parts = ObjectParts::default();
        for (i, object) in parsed.objects.iter().enumerate() {
            self.object(i, object, &materials, &mut parts)?;
        }
        let mut lights = std::mem::take(&mut parts.area_lights);
        lights.extend(self.lights(&parsed.lights)?);
        // After the objects: a sensor camera refers to one of them.
        let camera = self.camera(&parsed.camera, &parts.lens_surfaces)?;
        let front = super::ghost::front_element(&camera, parts.lens_surfaces.values().copied());
        let mut scene = self.assemble(render, camera, materials, parts, lights)?;
        if let Some(front) = front.filter(|_| super::ghost::sensor_ghosts(&scene)) {
            scene.lights.aim_at(front);
            let lens_images = super::ghost::lens_images_by_light_paths(&scene, &front);
            scene.lights.set_lens_images_by_light_paths(lens_images);
        }
        Ok(scene)
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

    /// The scene from its checked parts: the geometry and the light table built, and at least one light.
    fn assemble(
        self,
        render: SceneRenderSettings,
        camera: Camera,
        materials: Materials,
        parts: ObjectParts,
        lights: Vec<Light>,
    ) -> Result<Scene, SceneError> {
        let geometry = SceneGeometry::build(parts.triangles, parts.analytic).map_err(|e| SceneError {
            file: self.file.to_path_buf(),
            line: None,
            field: None,
            message: e.to_string(),
        })?;
        let sphere = SceneSphere::around(geometry.bounds());
        let lights = Lights::with_textures(lights, parts.light_textures, geometry.triangle_count(), sphere);
        if !lights.any() {
            return Err(SceneError {
                file: self.file.to_path_buf(),
                line: None,
                field: None,
                message: "the scene has no light: give an object an `emission` or add a [[lights]] entry".into(),
            });
        }
        let has_delta_surfaces = parts.objects.iter().any(|o| materials.list[o.material as usize].has_delta());
        Ok(Scene {
            path: self.file.to_path_buf(),
            camera,
            materials: materials.list,
            triangle_uvs: parts.triangle_uvs,
            objects: parts.objects,
            geometry,
            lights,
            render,
            hash: format!("{:x}", self.hasher.finalize()),
            mesh_files: self.mesh_files,
            has_delta_surfaces,
            ghost_pairs: OnceLock::new(),
            notes: Vec::new(),
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
