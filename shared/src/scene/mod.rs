//! Scenes: the TOML file format, its validation with precise errors, and the loaded scene the renderer uses.

pub mod error;
pub mod file;

pub use error::SceneError;

use crate::camera::{Camera, Lens, RearElement};
use crate::color::Rgb;
use crate::geometry::{Analytic, Annulus, LensSurface, Mesh, MeshTriangle, SceneGeometry, Sphere, SurfaceHit};
use crate::light::{EmissionTexture, Light, Lights};
use crate::material::Material;
use crate::spectrum::{Dispersive, RefractiveIndex};
use crate::texture::{barycentric, interpolate_uv, quad_uvs, Texture};
use error::line_of;
use file::{LightSection, MaterialSection, SceneFile};
use glam::{Vec2, Vec3};
use sha2::{Digest, Sha256};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use toml::Spanned;

/// One object of the scene.
#[derive(Clone, Debug)]
pub struct SceneObject {
    pub name: String,
    pub material: u32,
    pub emission: Option<Rgb>,
}

/// Integrator settings a scene carries (the `[render]` table), each overridable from the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneRenderSettings {
    /// Longest path in segments over the joined camera and light sub-paths: 1 = emitters seen directly.
    pub max_depth: u32,
    /// Diffuse vertices on a camera path that store backward photons (paper §2: 2).
    pub backward_diffuse_depth: u32,
    /// Initial photon radius in pixel footprints.
    pub radius_scale: f32,
    /// Light paths per phase, per pixel of the image.
    pub light_paths_per_pixel: f32,
}

impl Default for SceneRenderSettings {
    fn default() -> Self {
        SceneRenderSettings { max_depth: 12, backward_diffuse_depth: 2, radius_scale: 3.0, light_paths_per_pixel: 1.0 }
    }
}

/// A loaded, validated scene.
pub struct Scene {
    /// The scene file it came from.
    pub path: PathBuf,
    pub camera: Camera,
    pub materials: Vec<Material>,
    /// The albedo texture of each material, parallel to `materials`; it multiplies a diffuse albedo.
    pub albedo_textures: Vec<Option<Arc<Texture>>>,
    /// Texture coordinates of each triangle, by the index it was added with; None where its shape has none.
    pub triangle_uvs: Vec<Option<[Vec2; 3]>>,
    pub objects: Vec<SceneObject>,
    pub geometry: SceneGeometry,
    pub lights: Lights,
    pub render: SceneRenderSettings,
    /// SHA-256 over the scene file and every mesh and texture it references, in order.
    pub hash: String,
    /// Every file the scene references, meshes and textures: its path as written in the scene and its SHA-256
    /// (hex). Jobs send these to workers.
    pub mesh_files: Vec<(String, String)>,
    /// True when any object has a specular material (then caustics exist).
    pub has_delta_surfaces: bool,
}

impl Scene {
    /// Reads and validates a scene file; meshes and textures are resolved relative to its folder.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
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

    /// The material at the surface hit, its albedo multiplied by the material's texture there if it has one
    /// (a copy, so that textured and plain materials look the same to the integrators).
    #[inline]
    /// True when a material disperses light: the scene then renders spectrally (after dispersive events).
    pub fn is_spectral(&self) -> bool {
        self.materials.iter().any(Material::is_dispersive)
    }

    pub fn material(&self, hit: &SurfaceHit) -> Material {
        let index = self.objects[hit.object as usize].material as usize;
        let material = self.materials[index];
        match (material, &self.albedo_textures[index]) {
            (Material::Diffuse { albedo }, Some(texture)) => {
                Material::Diffuse { albedo: albedo * self.texture_at(texture, hit) }
            }
            _ => material,
        }
    }

    /// The texture's value at the hit point (one where the surface has no texture coordinates, which the
    /// loader does not let happen).
    fn texture_at(&self, texture: &Texture, hit: &SurfaceHit) -> Vec3 {
        match self.triangle_uvs.get(hit.triangle as usize) {
            Some(Some(uv)) => {
                let b = barycentric(&self.geometry.triangle(hit.triangle).v, hit.p);
                texture.lookup(interpolate_uv(uv, b))
            }
            _ => Vec3::ONE,
        }
    }
}

/// Texture coordinates of a shape's triangles, in order, when it has them.
type TriangleUvs = Option<Vec<[Vec2; 3]>>;

/// Where mesh and texture files come from.
enum MeshSource<'a> {
    /// Paths relative to the scene file's folder.
    Folder(&'a Path),
    /// Contents by the path the scene writes.
    Memory(&'a BTreeMap<String, Vec<u8>>),
}

struct Loader<'a> {
    text: &'a str,
    file: &'a Path,
    source: MeshSource<'a>,
    hasher: Sha256,
    mesh_files: Vec<(String, String)>,
    /// Textures decoded so far, by the path the scene writes: a texture used twice is read once.
    textures: BTreeMap<String, Arc<Texture>>,
}

impl<'a> Loader<'a> {
    fn new(text: &'a str, file: &'a Path, source: MeshSource<'a>) -> Self {
        Loader { text, file, source, hasher: Sha256::new(), mesh_files: Vec::new(), textures: BTreeMap::new() }
    }

    fn error(
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

    fn vec3(&self, v: [f32; 3], span: &std::ops::Range<usize>, field: &str) -> Result<Vec3, SceneError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(Vec3::from(v))
        } else {
            Err(self.error(Some(span.clone()), field, format!("every component must be a finite number, got {v:?}")))
        }
    }

    fn scalar(
        &self,
        x: f32,
        span: &std::ops::Range<usize>,
        field: &str,
        ok: impl Fn(f32) -> bool,
        rule: &str,
    ) -> Result<f32, SceneError> {
        if x.is_finite() && ok(x) {
            Ok(x)
        } else {
            Err(self.error(Some(span.clone()), field, format!("must be {rule}, got {x}")))
        }
    }

    /// An index of refraction, dispersive when the glass has an Abbe number.
    fn refractive_index(
        &self,
        n_d: f32,
        abbe: Option<f32>,
        span: &std::ops::Range<usize>,
        field: &str,
    ) -> Result<RefractiveIndex, SceneError> {
        let Some(v) = abbe else { return Ok(RefractiveIndex::constant(n_d)) };
        if !crate::spectrum::ENABLED {
            return Err(self.error(
                Some(span.clone()),
                field,
                "this build renders RGB only (built without the `spectral` feature): a dispersive glass needs the \
                 default build",
            ));
        }
        // Real glasses lie between about 15 (dense flints) and 100 (fluorite); outside that is a typo.
        let v = self.scalar(v, span, field, |v| (5.0..=150.0).contains(&v), "an Abbe number between 5 and 150")?;
        if n_d <= 1.0 {
            return Err(self.error(
                Some(span.clone()),
                field,
                format!("an Abbe number needs a glass index above 1 (dispersion of n − 1), got {n_d}"),
            ));
        }
        Ok(RefractiveIndex::from_abbe(n_d, v))
    }

    fn colour(
        &self,
        v: [f32; 3],
        span: &std::ops::Range<usize>,
        field: &str,
        max: Option<f32>,
    ) -> Result<Rgb, SceneError> {
        let c = self.vec3(v, span, field)?;
        if c.min_element() < 0.0 {
            return Err(self.error(Some(span.clone()), field, format!("must not be negative, got {v:?}")));
        }
        if let Some(m) = max {
            if c.max_element() > m {
                return Err(self.error(
                    Some(span.clone()),
                    field,
                    format!("must be at most {m} (a surface cannot reflect more than it receives), got {v:?}"),
                ));
            }
        }
        Ok(c)
    }

    fn load(mut self) -> Result<Scene, SceneError> {
        self.hasher.update(self.text.as_bytes());
        let parsed: SceneFile = toml::from_str(self.text).map_err(|e| {
            let line = e.span().map(|s| line_of(self.text, s.start));
            let field = line.and_then(|l| {
                let src = self.text.lines().nth(l - 1)?;
                let key = src.split('=').next()?.trim();
                (!key.is_empty() && src.contains('=')).then(|| key.to_string())
            });
            SceneError { file: self.file.to_path_buf(), line, field, message: e.message().trim().to_string() }
        })?;

        let render = self.render_settings(&parsed)?;

        let mut materials = Vec::new();
        let mut albedo_textures = Vec::new();
        let mut material_index = BTreeMap::new();
        for (name, m) in &parsed.materials {
            material_index.insert(name.clone(), materials.len() as u32);
            let (material, texture) = self.material(name, m)?;
            materials.push(material);
            albedo_textures.push(texture);
        }

        let mut objects = Vec::new();
        let mut triangles: Vec<(u32, MeshTriangle)> = Vec::new();
        let mut triangle_uvs: Vec<Option<[Vec2; 3]>> = Vec::new();
        let mut analytic = Vec::new();
        let mut lights = Vec::new();
        // Named lens surfaces, for the sensor camera's rear element (the first object of a name wins).
        let mut lens_surfaces: BTreeMap<String, LensSurface> = BTreeMap::new();
        let mut light_textures = Vec::new();
        for (i, o) in parsed.objects.iter().enumerate() {
            let span = o.span();
            let obj = o.get_ref();
            let field = |f: &str| format!("objects[{i}].{f}");
            let Some(&material) = material_index.get(obj.material.get_ref()) else {
                let known: Vec<&String> = material_index.keys().collect();
                return Err(self.error(
                    Some(obj.material.span()),
                    field("material"),
                    format!("unknown material '{}' (defined: {known:?})", obj.material.get_ref()),
                ));
            };
            let emission = match &obj.emission {
                Some(e) => Some(self.colour(*e.get_ref(), &e.span(), &field("emission"), None)?),
                // An emission texture alone emits its own values.
                None if obj.emission_texture.is_some() => Some(Rgb::ONE),
                None => None,
            };
            let emission_texture = match &obj.emission_texture {
                Some(t) => Some(self.texture(t.get_ref(), Some(t.span()), &field("emission_texture"))?),
                None => None,
            };
            let shapes = [
                obj.mesh.is_some(),
                obj.quad.is_some(),
                obj.box_shape.is_some(),
                obj.sphere.is_some(),
                obj.lens_surface.is_some(),
                obj.annulus.is_some(),
            ];
            let count = shapes.iter().filter(|&&s| s).count();
            if count != 1 {
                return Err(self.error(
                    Some(span.clone()),
                    format!("objects[{i}]"),
                    format!(
                        "needs exactly one shape (mesh, quad, box, sphere, lens_surface or annulus), found {count}"
                    ),
                ));
            }
            let id = objects.len() as u32;
            let mut uvs: TriangleUvs = None;
            let mesh = if let Some(m) = &obj.mesh {
                let (mesh, mesh_uvs) = self.mesh(m, &field("mesh"))?;
                uvs = mesh_uvs;
                Some(mesh)
            } else if let Some(q) = &obj.quad {
                let s = q.span();
                let q = q.get_ref();
                let (c, e1, e2) = (
                    self.vec3(q.corner, &s, &field("quad.corner"))?,
                    self.vec3(q.edge1, &s, &field("quad.edge1"))?,
                    self.vec3(q.edge2, &s, &field("quad.edge2"))?,
                );
                if e1.cross(e2).length_squared() <= 0.0 {
                    return Err(self.error(
                        Some(s),
                        field("quad"),
                        "edge1 and edge2 are parallel: the quad has no area",
                    ));
                }
                uvs = Some(quad_uvs().to_vec());
                Some(Mesh::quad(c, e1, e2))
            } else if let Some(b) = &obj.box_shape {
                let s = b.span();
                let (lo, hi) = (
                    self.vec3(b.get_ref().min, &s, &field("box.min"))?,
                    self.vec3(b.get_ref().max, &s, &field("box.max"))?,
                );
                if (hi - lo).min_element() <= 0.0 {
                    return Err(self.error(Some(s), field("box"), "max must exceed min on every axis"));
                }
                Some(Mesh::axis_box(lo, hi))
            } else {
                None
            };
            if uvs.is_none() {
                // Textures need texture coordinates, which only quads and OBJ meshes with `vt` have.
                let shape = if obj.box_shape.is_some() {
                    "a box"
                } else if obj.mesh.is_some() {
                    "this OBJ mesh (it has no vt lines)"
                } else if obj.sphere.is_some() {
                    "a sphere"
                } else {
                    "a lens_surface"
                };
                if let Some(t) = &obj.emission_texture {
                    return Err(self.error(
                        Some(t.span()),
                        field("emission_texture"),
                        format!("{shape} has no texture coordinates; use a quad or an OBJ mesh with vt"),
                    ));
                }
                if albedo_textures[material as usize].is_some() {
                    return Err(self.error(
                        Some(obj.material.span()),
                        field("material"),
                        format!(
                            "material '{}' has an albedo_texture but {shape} has no texture coordinates; use a \
                             quad or an OBJ mesh with vt",
                            obj.material.get_ref()
                        ),
                    ));
                }
            }
            match mesh {
                Some(mesh) => {
                    for (k, t) in mesh.triangles.into_iter().enumerate() {
                        let uv = uvs.as_ref().map(|u| u[k]);
                        if let Some(le) = emission {
                            if le != Rgb::ZERO {
                                let c = t.cross();
                                lights.push(Light::Area {
                                    triangle: triangles.len() as u32,
                                    emission: le,
                                    area: 0.5 * c.length(),
                                    normal: c.normalize(),
                                });
                                light_textures.push(match (&emission_texture, uv) {
                                    (Some(texture), Some(uv)) => {
                                        Some(EmissionTexture { texture: texture.clone(), vertices: t.v, uv })
                                    }
                                    _ => None,
                                });
                            }
                        }
                        triangles.push((id, t));
                        triangle_uvs.push(uv);
                    }
                }
                None => {
                    if emission.is_some_and(|e| e != Rgb::ZERO) {
                        return Err(self.error(
                            obj.emission.as_ref().map(|e| e.span()),
                            field("emission"),
                            "analytic surfaces (sphere, lens_surface, annulus) cannot emit; use a mesh, quad or box",
                        ));
                    }
                    let shape = self.analytic(obj, &field)?;
                    if let (Analytic::Lens(l), Some(name)) = (&shape, &obj.name) {
                        lens_surfaces.entry(name.clone()).or_insert(*l);
                    }
                    analytic.push((id, shape));
                }
            }
            objects.push(SceneObject {
                name: obj.name.clone().unwrap_or_else(|| format!("object {i}")),
                material,
                emission,
            });
        }

        for (i, l) in parsed.lights.iter().enumerate() {
            lights.push(self.light(l, i)?);
        }
        // After the objects: a sensor camera refers to one of them.
        let camera = self.camera(&parsed.camera, &lens_surfaces)?;
        let geometry = SceneGeometry::build(triangles, analytic);
        let lights = Lights::with_textures(lights, light_textures, geometry.triangle_count());
        if !lights.any() {
            return Err(SceneError {
                file: self.file.to_path_buf(),
                line: None,
                field: None,
                message: "the scene has no light: give an object an `emission` or add a [[lights]] entry".into(),
            });
        }
        let has_delta_surfaces = objects.iter().any(|o| materials[o.material as usize].is_delta());
        Ok(Scene {
            path: self.file.to_path_buf(),
            camera,
            materials,
            albedo_textures,
            triangle_uvs,
            objects,
            geometry,
            lights,
            render,
            hash: format!("{:x}", self.hasher.finalize()),
            mesh_files: self.mesh_files,
            has_delta_surfaces,
        })
    }

    fn render_settings(&self, f: &SceneFile) -> Result<SceneRenderSettings, SceneError> {
        let mut s = SceneRenderSettings::default();
        let r = &f.render;
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
            s.backward_diffuse_depth = *d.get_ref();
        }
        if let Some(x) = &r.radius_scale {
            s.radius_scale =
                self.scalar(*x.get_ref(), &x.span(), "render.radius_scale", |v| v > 0.0, "a positive number")?;
        }
        if let Some(x) = &r.light_paths_per_pixel {
            s.light_paths_per_pixel = self.scalar(
                *x.get_ref(),
                &x.span(),
                "render.light_paths_per_pixel",
                |v| v > 0.0 && v <= 1000.0,
                "in (0, 1000]",
            )?;
        }
        Ok(s)
    }

    fn camera(
        &self,
        c: &Spanned<file::CameraSection>,
        lens_surfaces: &BTreeMap<String, LensSurface>,
    ) -> Result<Camera, SceneError> {
        let cam = c.get_ref();
        let position = self.vec3(*cam.position.get_ref(), &cam.position.span(), "camera.position")?;
        let look_at = self.vec3(*cam.look_at.get_ref(), &cam.look_at.span(), "camera.look_at")?;
        let up = self.vec3(*cam.up.get_ref(), &cam.up.span(), "camera.up")?;
        let forward = look_at - position;
        if forward.length_squared() == 0.0 {
            return Err(self.error(Some(cam.look_at.span()), "camera.look_at", "must differ from camera.position"));
        }
        if forward.normalize().cross(up).length_squared() < 1e-8 {
            return Err(self.error(Some(cam.up.span()), "camera.up", "must not be parallel to the view direction"));
        }
        for (v, name) in [(&cam.width, "camera.width"), (&cam.height, "camera.height")] {
            if !(1..=16384).contains(v.get_ref()) {
                return Err(self.error(Some(v.span()), name, format!("must be 1..=16384 pixels, got {}", v.get_ref())));
            }
        }
        let (width, height) = (*cam.width.get_ref(), *cam.height.get_ref());
        let kind = cam.kind.get_ref().as_str();
        match kind {
            "pinhole" | "thin_lens" => {}
            "sensor" => return self.sensor_camera(c, position, look_at, up, lens_surfaces),
            other => {
                return Err(self.error(
                    Some(cam.kind.span()),
                    "camera.type",
                    format!("unknown camera type '{other}' (known: pinhole, thin_lens, sensor)"),
                ));
            }
        }
        let fov = cam.fov_y_deg.as_ref().ok_or_else(|| {
            self.error(
                Some(c.span()),
                "camera.fov_y_deg",
                format!("a {kind} camera needs fov_y_deg (the full vertical field of view in degrees)"),
            )
        })?;
        let fov = self.scalar(
            *fov.get_ref(),
            &fov.span(),
            "camera.fov_y_deg",
            |v| v > 0.0 && v < 180.0,
            "between 0 and 180 degrees",
        )?;
        let lens = if kind == "pinhole" {
            Lens::Pinhole
        } else {
            let radius = cam.lens_radius.as_ref().ok_or_else(|| {
                self.error(Some(c.span()), "camera.lens_radius", "a thin_lens camera needs lens_radius (m)")
            })?;
            let focus = cam.focus_distance.as_ref().ok_or_else(|| {
                self.error(Some(c.span()), "camera.focus_distance", "a thin_lens camera needs focus_distance (m)")
            })?;
            Lens::Thin {
                radius: self.scalar(
                    *radius.get_ref(),
                    &radius.span(),
                    "camera.lens_radius",
                    |v| v > 0.0,
                    "a positive number",
                )?,
                focus_distance: self.scalar(
                    *focus.get_ref(),
                    &focus.span(),
                    "camera.focus_distance",
                    |v| v > 0.0,
                    "a positive number",
                )?,
            }
        };
        Ok(Camera::new(position, look_at, up, fov, width, height, lens))
    }

    /// A sensor behind a lens of the scene: `position` is the sensor's centre, `look_at` a point along the
    /// optical axis in front of it, and `rear_element` names the lens surface nearest the sensor.
    fn sensor_camera(
        &self,
        c: &Spanned<file::CameraSection>,
        position: Vec3,
        look_at: Vec3,
        up: Vec3,
        lens_surfaces: &BTreeMap<String, LensSurface>,
    ) -> Result<Camera, SceneError> {
        let cam = c.get_ref();
        if let Some(fov) = &cam.fov_y_deg {
            return Err(self.error(
                Some(fov.span()),
                "camera.fov_y_deg",
                "a sensor camera's field of view follows from sensor_width and the lens: remove fov_y_deg",
            ));
        }
        let sensor_width = cam.sensor_width.as_ref().ok_or_else(|| {
            self.error(Some(c.span()), "camera.sensor_width", "a sensor camera needs sensor_width (m)")
        })?;
        let sensor_width = self.scalar(
            *sensor_width.get_ref(),
            &sensor_width.span(),
            "camera.sensor_width",
            |v| v > 0.0,
            "a positive width in metres",
        )?;
        let rear_name = cam.rear_element.as_ref().ok_or_else(|| {
            self.error(
                Some(c.span()),
                "camera.rear_element",
                "a sensor camera needs rear_element, the name of the lens_surface object nearest the sensor",
            )
        })?;
        let Some(surface) = lens_surfaces.get(rear_name.get_ref()) else {
            let known: Vec<&String> = lens_surfaces.keys().collect();
            return Err(self.error(
                Some(rear_name.span()),
                "camera.rear_element",
                format!("no lens_surface object is named '{}' (named lens surfaces: {known:?})", rear_name.get_ref()),
            ));
        };
        let rear = RearElement {
            center: surface.vertex + surface.axis * surface.rim_sag(),
            axis: surface.axis,
            radius: surface.aperture_radius,
        };
        // Every point of the disc must lie in front of the sensor, or some rays would leave it backwards.
        let forward = (look_at - position).normalize();
        let depth = (rear.center - position).dot(forward);
        let tilt = (1.0 - rear.axis.dot(forward).powi(2)).max(0.0).sqrt();
        if depth <= rear.radius * tilt {
            return Err(self.error(
                Some(rear_name.span()),
                "camera.rear_element",
                format!(
                    "the rear element's clear aperture must lie entirely in front of the sensor (toward look_at); \
                     its centre is {depth} m in front"
                ),
            ));
        }
        Ok(Camera::sensor(position, look_at, up, sensor_width, *cam.width.get_ref(), *cam.height.get_ref(), rear))
    }

    /// A material and its albedo texture.
    fn material(
        &mut self,
        name: &str,
        m: &Spanned<MaterialSection>,
    ) -> Result<(Material, Option<Arc<Texture>>), SceneError> {
        let s = m.span();
        let f = |x: &str| format!("materials.{name}.{x}");
        Ok((
            match m.get_ref() {
                MaterialSection::Diffuse { albedo, albedo_texture } => {
                    let texture = match albedo_texture {
                        Some(t) => Some(self.texture(t, Some(s.clone()), &f("albedo_texture"))?),
                        None => None,
                    };
                    let albedo = match (albedo, &texture) {
                        (Some(a), _) => self.colour(*a, &s, &f("albedo"), Some(1.0))?,
                        // Texture values are at most 1, so the product stays a valid albedo.
                        (None, Some(_)) => Rgb::ONE,
                        (None, None) => {
                            return Err(self.error(Some(s), f("albedo"), "a diffuse material needs albedo = [r, g, b]"))
                        }
                    };
                    return Ok((Material::Diffuse { albedo }, texture));
                }
                MaterialSection::Mirror { reflectance } => {
                    Material::Mirror { reflectance: self.colour(*reflectance, &s, &f("reflectance"), Some(1.0))? }
                }
                MaterialSection::Dielectric { ior, ext_ior, anti_reflection, abbe, ext_abbe } => {
                    let ior = self.scalar(*ior, &s, &f("ior"), |v| v > 0.0, "a positive index of refraction")?;
                    let ext_ior =
                        self.scalar(*ext_ior, &s, &f("ext_ior"), |v| v > 0.0, "a positive index of refraction")?;
                    Material::Dielectric {
                        ior: self.refractive_index(ior, *abbe, &s, &f("abbe"))?,
                        ext_ior: self.refractive_index(ext_ior, *ext_abbe, &s, &f("ext_abbe"))?,
                        anti_reflection: *anti_reflection,
                    }
                }
                MaterialSection::Coating { reflectance, transmittance } => {
                    let r = self.colour(*reflectance, &s, &f("reflectance"), Some(1.0))?;
                    let t = self.colour(*transmittance, &s, &f("transmittance"), Some(1.0))?;
                    if (r + t).max_element() > 1.0 + 1e-6 {
                        return Err(self.error(
                            Some(s),
                            f("transmittance"),
                            "reflectance + transmittance must not exceed 1 in any channel",
                        ));
                    }
                    Material::Coating { reflectance: r, transmittance: t }
                }
            },
            None,
        ))
    }

    fn analytic(&self, obj: &file::ObjectSection, field: &dyn Fn(&str) -> String) -> Result<Analytic, SceneError> {
        if let Some(sp) = &obj.sphere {
            let s = sp.span();
            let center = self.vec3(sp.get_ref().center, &s, &field("sphere.center"))?;
            let radius =
                self.scalar(sp.get_ref().radius, &s, &field("sphere.radius"), |v| v > 0.0, "a positive radius")?;
            return Ok(Analytic::Sphere(Sphere { center, radius }));
        }
        if let Some(an) = &obj.annulus {
            let s = an.span();
            let a = an.get_ref();
            let center = self.vec3(a.center, &s, &field("annulus.center"))?;
            let axis = self.vec3(a.axis, &s, &field("annulus.axis"))?;
            if axis.length_squared() == 0.0 {
                return Err(self.error(Some(s), field("annulus.axis"), "must not be the zero vector"));
            }
            let inner = self.scalar(
                a.inner_radius,
                &s,
                &field("annulus.inner_radius"),
                |v| v >= 0.0,
                "zero (a full disc) or a positive radius",
            )?;
            let outer = self.scalar(
                a.outer_radius,
                &s,
                &field("annulus.outer_radius"),
                |v| v > inner,
                &format!("larger than inner_radius = {inner}"),
            )?;
            return Ok(Analytic::Annulus(Annulus {
                center,
                axis: axis.normalize(),
                inner_radius: inner,
                outer_radius: outer,
            }));
        }
        let Some(l) = &obj.lens_surface else {
            unreachable!("the caller checked that the object has exactly one shape")
        };
        let s = l.span();
        let lens = l.get_ref();
        let vertex = self.vec3(lens.vertex, &s, &field("lens_surface.vertex"))?;
        let axis = self.vec3(lens.axis, &s, &field("lens_surface.axis"))?;
        if axis.length_squared() == 0.0 {
            return Err(self.error(Some(s), field("lens_surface.axis"), "must not be the zero vector"));
        }
        let aperture = self.scalar(
            lens.aperture_radius,
            &s,
            &field("lens_surface.aperture_radius"),
            |v| v > 0.0,
            "a positive radius",
        )?;
        let r = self.scalar(
            lens.curvature_radius,
            &s,
            &field("lens_surface.curvature_radius"),
            |_| true,
            "a finite number",
        )?;
        if r != 0.0 && r.abs() <= aperture {
            return Err(self.error(
                Some(s),
                field("lens_surface.aperture_radius"),
                format!("must be smaller than |curvature_radius| = {}", r.abs()),
            ));
        }
        Ok(Analytic::Lens(LensSurface {
            vertex,
            axis: axis.normalize(),
            curvature_radius: r,
            aperture_radius: aperture,
        }))
    }

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

    /// Reads and decodes a PNG texture once per path.
    fn texture(
        &mut self,
        name: &str,
        span: Option<std::ops::Range<usize>>,
        field: &str,
    ) -> Result<Arc<Texture>, SceneError> {
        if let Some(t) = self.textures.get(name) {
            return Ok(t.clone());
        }
        let (path, bytes) = self.external_file(name, span.clone(), field, "texture")?;
        let texture =
            Texture::from_png(&bytes).map_err(|e| self.error(span, field, format!("{}: {e}", path.display())))?;
        let texture = Arc::new(texture);
        self.textures.insert(name.to_string(), texture.clone());
        Ok(texture)
    }

    /// A mesh and, when every triangle has them (OBJ `vt`), its texture coordinates.
    fn mesh(&mut self, m: &Spanned<String>, field: &str) -> Result<(Mesh, TriangleUvs), SceneError> {
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
            // With single_index every vertex has a texture coordinate, or none has.
            let model_uvs = tex.len() >= 2 * vertices && vertices > 0;
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

    fn light(&self, l: &Spanned<LightSection>, i: usize) -> Result<Light, SceneError> {
        let s = l.span();
        let f = |x: &str| format!("lights[{i}].{x}");
        Ok(match l.get_ref() {
            LightSection::Point { position, intensity } => Light::Point {
                position: self.vec3(*position, &s, &f("position"))?,
                intensity: self.colour(*intensity, &s, &f("intensity"), None)?,
            },
            LightSection::Spot { position, direction, intensity, cone_angle_deg, falloff_start_deg } => {
                let dir = self.vec3(*direction, &s, &f("direction"))?;
                if dir.length_squared() == 0.0 {
                    return Err(self.error(Some(s), f("direction"), "must not be the zero vector"));
                }
                let cone = self.scalar(
                    *cone_angle_deg,
                    &s,
                    &f("cone_angle_deg"),
                    |v| v > 0.0 && v <= 90.0,
                    "in (0, 90] degrees",
                )?;
                let start = self.scalar(
                    falloff_start_deg.unwrap_or(cone),
                    &s,
                    &f("falloff_start_deg"),
                    |v| (0.0..=cone).contains(&v),
                    "between 0 and cone_angle_deg",
                )?;
                Light::Spot {
                    position: self.vec3(*position, &s, &f("position"))?,
                    direction: dir.normalize(),
                    intensity: self.colour(*intensity, &s, &f("intensity"), None)?,
                    cos_total: cone.to_radians().cos(),
                    cos_falloff_start: start.to_radians().cos(),
                }
            }
        })
    }
}
