//! The one build step from a `SceneDescription` to a `Scene`, whichever format it was read from: the files it
//! references are looked up by their path and checked against their SHA-256, meshes read and images decoded,
//! what only the files tell checked (a texture's values, a mesh's triangles and texture coordinates), and the
//! geometry, its acceleration structure and the light table built. Errors name the file, line and element of
//! the description's `Source`.

use super::description::{
    CameraDesc, FileRef, ImageRef, LensDesc, LightDesc, LightKind, MaterialDesc, MeshFormat, ObjectDesc,
    SceneDescription, ShapeDesc, Source, SourceFormat,
};
use super::mitsuba::meshes::{read_obj, read_ply, read_serialized, Placement};
use super::obj::{self, Coverage, ObjMesh};
use super::{Scene, SceneError, SceneObject};
use crate::camera::{Camera, Lens, RearElement};
use crate::color::Rgb;
use crate::geometry::{Analytic, LensSurface, Mesh, MeshTriangle, PerTriangle, SceneGeometry};
use crate::light::directional::Sun;
use crate::light::environment::{ConstantEnvironment, EnvironmentMap};
use crate::light::infinite::{InfiniteLight, SceneSphere};
use crate::light::{EmissionTexture, Light, Lights};
use crate::material::Material;
use crate::texture::{Bitmap, BitmapTexture, Encoding};
use glam::Vec2;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

impl Scene {
    /// Builds the scene `desc` describes from the files it references, keyed by their path relative to the
    /// scene's folder (`FileRef::path`); each must match its SHA-256.
    pub fn from_description(desc: &SceneDescription, files: &BTreeMap<String, Vec<u8>>) -> Result<Scene, SceneError> {
        Builder::new(desc, files).build()
    }

    /// `from_description` for files already known to match the description's SHA-256s: those the reader that
    /// made `desc` hashed as it read them, or those a worker's file cache checked on arrival. Hashing a mesh
    /// of hundreds of megabytes again takes a noticeable part of its load.
    pub fn from_hashed_files(desc: &SceneDescription, files: &BTreeMap<String, Vec<u8>>) -> Result<Scene, SceneError> {
        Builder::hashed(desc, files).build()
    }

    /// `from_hashed_files` without the tracing structures: every file is read and checked, and the lights,
    /// camera and objects are those of the traced scene (less the lights' aim at a sensor camera's lens, which
    /// is found by tracing), but no BVH is built and the scene comes released (`Scene::is_released`). What a
    /// distributed run's coordinator, which merges and saves, keeps.
    pub fn untraced_from_hashed_files(
        desc: &SceneDescription,
        files: &BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        Builder { traced: false, ..Builder::hashed(desc, files) }.build()
    }
}

/// Texture coordinates of a shape's triangles, in order, when it has them.
type TriangleUvs = Option<Vec<[Vec2; 3]>>;

/// One build: the description, its files, and what reading them gathers.
struct Builder<'a> {
    desc: &'a SceneDescription,
    files: &'a BTreeMap<String, Vec<u8>>,
    /// The scene's folder, which names a file in errors as the reader found it.
    folder: PathBuf,
    /// Files whose bytes have been checked against their hash.
    checked: BTreeSet<String>,
    /// Images decoded so far, by path and encoding: an image used twice is decoded once.
    bitmaps: BTreeMap<(String, Encoding), Arc<Bitmap>>,
    notes: Vec<String>,
    parts: Parts,
    /// Whether the scene is built to be traced (its BVH), or only described (`untraced_from_hashed_files`).
    traced: bool,
}

/// What the objects add to the scene, gathered object by object.
#[derive(Default)]
struct Parts {
    objects: Vec<SceneObject>,
    /// Every triangle, and the object each belongs to.
    triangles: Vec<MeshTriangle>,
    triangle_objects: Vec<u32>,
    /// Texture coordinates of the triangles, by their index in `triangles`.
    triangle_uvs: PerTriangle<[Vec2; 3]>,
    analytic: Vec<(u32, Analytic)>,
    /// One area light per emitting triangle or analytic surface, and its emission texture.
    lights: Vec<Light>,
    light_textures: Vec<Option<EmissionTexture>>,
    /// Named lens surfaces, for the sensor camera's rear element (the first object of a name wins).
    lens_surfaces: BTreeMap<String, LensSurface>,
}

impl<'a> Builder<'a> {
    fn new(desc: &'a SceneDescription, files: &'a BTreeMap<String, Vec<u8>>) -> Self {
        Builder {
            desc,
            files,
            folder: desc.path.parent().map(PathBuf::from).unwrap_or_default(),
            checked: BTreeSet::new(),
            bitmaps: BTreeMap::new(),
            notes: desc.notes.clone(),
            parts: Parts::default(),
            traced: true,
        }
    }

    /// A builder for files already checked against the description's hashes.
    fn hashed(desc: &'a SceneDescription, files: &'a BTreeMap<String, Vec<u8>>) -> Self {
        let mut builder = Builder::new(desc, files);
        builder.checked = desc.files.iter().map(|f| f.path.clone()).filter(|p| files.contains_key(p)).collect();
        builder
    }

    /// The scene, built in the order the TOML reader has always reported errors in: the materials (with their
    /// images), the objects (with their meshes), the lights, then the camera, which may name an object.
    fn build(mut self) -> Result<Scene, SceneError> {
        let desc = self.desc;
        let materials: Vec<Material> = desc.materials.iter().map(|m| self.material(m)).collect::<Result<_, _>>()?;
        for (i, object) in desc.objects.iter().enumerate() {
            self.object(i as u32, object, &desc.materials)?;
        }
        for light in &desc.lights {
            let light = self.light(light)?;
            self.parts.lights.push(light);
            self.parts.light_textures.push(None);
        }
        let camera = camera(&desc.camera, &self.parts.lens_surfaces)?;
        let front = super::ghost::front_element(&camera, self.parts.lens_surfaces.values().copied());
        let traced = self.traced;
        let mut scene = self.assemble(camera, materials)?;
        // Aiming the lights at the lens traces the scene: an untraced one is never rendered from.
        if let Some(front) = front.filter(|_| traced && super::ghost::sensor_ghosts(&scene)) {
            scene.lights.aim_at(front);
            let lens_images = super::ghost::lens_images_by_light_paths(&scene, &front);
            scene.lights.set_lens_images_by_light_paths(lens_images);
        }
        Ok(scene)
    }

    /// The bytes of `file`, checked against its hash; `what` ("mesh", "texture") names it in errors.
    fn bytes(&mut self, file: &FileRef, source: &Source, what: &str) -> Result<&'a [u8], SceneError> {
        let files: &'a BTreeMap<String, Vec<u8>> = self.files;
        let bytes = files
            .get(&file.path)
            .ok_or_else(|| source.error(format!("{what} {} was not sent with the job", file.path)))?;
        if !self.checked.contains(&file.path) {
            if format!("{:x}", Sha256::digest(bytes)) != file.sha256 {
                return Err(source.error(format!(
                    "{what} {} is not the file the scene was read with (its SHA-256 differs)",
                    file.path
                )));
            }
            self.checked.insert(file.path.clone());
        }
        Ok(bytes)
    }

    /// How errors name `file`: by its path as the reader found it.
    fn shown(&self, file: &FileRef) -> String {
        self.folder.join(&file.path).display().to_string()
    }

    /// The decoded image of `image`, once per file and encoding.
    fn bitmap(&mut self, image: &ImageRef) -> Result<Arc<Bitmap>, SceneError> {
        let key = (image.file.path.clone(), image.encoding);
        if let Some(b) = self.bitmaps.get(&key) {
            return Ok(b.clone());
        }
        let bytes = self.bytes(&image.file, &image.source, "texture")?;
        let bitmap = Bitmap::decode(bytes, &image.file.path, image.encoding)
            .map_err(|e| image.source.error(format!("{}: {e}", self.shown(&image.file))))?;
        let bitmap = Arc::new(bitmap);
        self.bitmaps.insert(key, bitmap.clone());
        Ok(bitmap)
    }

    /// The image of a bitmap texture, its values (texels times factor) checked against the image's bound.
    fn texture_image(&mut self, b: &BitmapTexture<ImageRef>) -> Result<Arc<Bitmap>, SceneError> {
        let bitmap = self.bitmap(&b.image)?;
        if let Some(bound) = &b.image.bound {
            let max = bound.max;
            let top = bitmap.max_texel().max_element() * b.factor.max_element();
            if top > max {
                let message = match self.desc.format {
                    SourceFormat::Toml => {
                        let why = if max == 1.0 { " (a surface cannot reflect more than it receives)" } else { "" };
                        format!("reaches {top} somewhere (texels times factor), and must stay at most {max}{why}")
                    }
                    SourceFormat::Mitsuba => {
                        format!("reaches {top}, above {max} (a surface cannot reflect more than it receives)")
                    }
                };
                return Err(bound.source.error(message));
            }
        }
        Ok(bitmap)
    }

    /// A material with its images decoded.
    fn material(&mut self, m: &MaterialDesc) -> Result<Material, SceneError> {
        let mut image = |b: &BitmapTexture<ImageRef>| self.texture_image(b);
        let front = m.front.try_map(&mut image)?;
        let back = m.back.try_map(&mut image)?;
        let opacity = match &m.opacity {
            Some(t) => Some(t.try_map(&mut image)?),
            None => None,
        };
        Ok(Material::new(front, back, opacity))
    }

    /// Object `id`: its shape's triangles or analytic surface, and its area lights.
    fn object(&mut self, id: u32, o: &ObjectDesc, materials: &[MaterialDesc]) -> Result<(), SceneError> {
        let emission_texture = match &o.emission_texture {
            Some(image) => Some(self.bitmap(image)?),
            None => None,
        };
        match &o.shape {
            ShapeDesc::Triangles { triangles, uvs } => {
                self.add_triangles(id, triangles.clone(), uvs.clone(), o.emission, emission_texture);
            }
            ShapeDesc::Obj { file, source } => {
                let (mesh, uvs) = self.obj_mesh(file, source)?;
                if uvs.is_none() {
                    let shape = "this OBJ mesh (it has no vt lines)";
                    let material = &materials[o.material as usize];
                    if let Some(t) = &o.emission_texture {
                        return Err(t
                            .source
                            .error(format!("{shape} has no texture coordinates; use a quad or an OBJ mesh with vt")));
                    }
                    if material.uses_uv() {
                        return Err(o.material_source.error(format!(
                            "material '{}' is textured (an albedo_texture or a texture table) but {shape} has no \
                             texture coordinates; use a quad or an OBJ mesh with vt",
                            material.name
                        )));
                    }
                }
                self.add_triangles(id, mesh.triangles, uvs, o.emission, emission_texture);
            }
            ShapeDesc::PlacedMesh { file, format, face_normals, to_world, flip_normals } => {
                let bytes = self.bytes(file, &o.source, "mesh")?;
                let name = &file.path;
                let fail = |m: String| o.source.error(format!("{name}: {m}"));
                let (mut mesh, own_face_normals) = match format {
                    MeshFormat::Obj { flip_tex_coords } => (read_obj(bytes, *flip_tex_coords).map_err(fail)?, false),
                    MeshFormat::Ply => (read_ply(bytes).map_err(fail)?, false),
                    MeshFormat::Serialized { shape_index } => read_serialized(bytes, *shape_index).map_err(fail)?,
                };
                if *face_normals || own_face_normals {
                    mesh.normals = None;
                }
                if mesh.triangles.is_empty() {
                    return Err(o.source.error("the mesh has no triangles"));
                }
                let placement = Placement { to_world: *to_world, flip_normals: *flip_normals };
                let (triangles, skipped) = placement.triangles(&mesh).map_err(|m| o.source.error(m))?;
                if skipped > 0 {
                    self.notes.push(format!("{}: {skipped} degenerate triangles (no area) left out", o.name));
                }
                if triangles.is_empty() {
                    return Err(o.source.error("the shape has no triangle with an area"));
                }
                let has_uvs = triangles.iter().all(|t| t.uv.is_some());
                if materials[o.material as usize].uses_uv() && !has_uvs {
                    return Err(o.source.error("its BSDF is textured but the shape has no texture coordinates"));
                }
                let uvs = has_uvs.then(|| triangles.iter().map(|t| t.uv.expect("checked above")).collect());
                let triangles = triangles.into_iter().map(|t| MeshTriangle { v: t.v, n: t.n }).collect();
                self.add_triangles(id, triangles, uvs, o.emission, emission_texture);
            }
            ShapeDesc::Analytic(shape) => {
                if let Some(le) = o.emission.filter(|&e| e != Rgb::ZERO) {
                    let light = Light::of_analytic(id, shape, le)
                        .ok_or_else(|| o.source.error("this analytic surface cannot emit"))?;
                    self.parts.lights.push(light);
                    self.parts.light_textures.push(None);
                }
                if let (Analytic::Lens(l), Some(name)) = (shape, &o.lens_name) {
                    self.parts.lens_surfaces.entry(name.clone()).or_insert(*l);
                }
                self.parts.analytic.push((id, *shape));
            }
        }
        self.parts.objects.push(SceneObject { name: o.name.clone(), material: o.material, emission: o.emission });
        Ok(())
    }

    /// Adds the triangles of object `id`, with an area light for each one that emits.
    fn add_triangles(
        &mut self,
        id: u32,
        triangles: Vec<MeshTriangle>,
        uvs: TriangleUvs,
        emission: Option<Rgb>,
        emission_texture: Option<Arc<Bitmap>>,
    ) {
        let parts = &mut self.parts;
        // A list collected in place from one of larger items (a placed mesh's) holds their memory.
        let mut triangles = triangles;
        triangles.shrink_to_fit();
        let first = parts.triangles.len() as u32;
        for (k, t) in triangles.iter().enumerate() {
            let index = first + k as u32;
            let uv = uvs.as_ref().map(|u| u[k]);
            if let Some(le) = emission.filter(|&e| e != Rgb::ZERO) {
                let c = t.cross();
                parts.lights.push(Light::Area {
                    triangle: index,
                    emission: le,
                    area: 0.5 * c.length(),
                    normal: c.normalize(),
                });
                parts.light_textures.push(match (&emission_texture, uv) {
                    (Some(texture), Some(uv)) => Some(EmissionTexture { texture: texture.clone(), vertices: t.v, uv }),
                    _ => None,
                });
            }
            parts.triangle_uvs.push(index, uv);
        }
        parts.triangle_objects.resize(parts.triangle_objects.len() + triangles.len(), id);
        // The longer list keeps its memory and the shorter one is put before or after it: a mesh of millions of
        // triangles is not copied into new pages for the few quads read before it.
        if parts.triangles.len() < triangles.len() {
            let mut merged = triangles;
            merged.splice(0..0, std::mem::take(&mut parts.triangles));
            parts.triangles = merged;
        } else {
            parts.triangles.extend(triangles);
        }
    }

    /// An OBJ mesh in world coordinates and, when every triangle has them (`vt`), its texture coordinates. Each
    /// of the file's objects (`o`, `g`) gives its triangles vertex normals when all its face corners name one,
    /// and none when none do.
    fn obj_mesh(&mut self, file: &FileRef, source: &Source) -> Result<(Mesh, TriangleUvs), SceneError> {
        let bytes = self.bytes(file, source, "mesh")?;
        let path = self.shown(file);
        let obj = obj::read(bytes).map_err(|e| source.error(format!("cannot parse OBJ {path}: {e}")))?;
        let mut mesh = Mesh { triangles: Vec::with_capacity(obj.triangles.len()) };
        let mut uvs = Some(Vec::with_capacity(if obj.triangle_texcoords.is_empty() { 0 } else { obj.triangles.len() }));
        for object in &obj.objects {
            let range = object.triangles.clone();
            let partial = |what: &str, tag: &str| {
                source.error(format!(
                    "{path}: '{}' gives {what} ({tag}) for some face corners but not for others; give them on every \
                     face of the object or on none",
                    object.name
                ))
            };
            let normals = obj::coverage(&obj.triangle_normals, range.clone());
            if normals == Coverage::Partial {
                return Err(partial("vertex normals", "f v/vt/vn"));
            }
            let texcoords = obj::coverage(&obj.triangle_texcoords, range.clone());
            if texcoords == Coverage::Partial {
                return Err(partial("texture coordinates", "f v/vt"));
            }
            let start = mesh.triangles.len();
            if let Some(list) = &mut uvs {
                if texcoords == Coverage::All {
                    list.par_extend(
                        range
                            .clone()
                            .into_par_iter()
                            .map(|t| obj.triangle_texcoords[t].map(|i| obj.texcoords[i as usize])),
                    );
                } else {
                    uvs = None;
                }
            }
            // Each triangle is checked as it is made; the smallest index that fails is the error a serial pass
            // would stop at.
            let normals = normals == Coverage::All;
            let uv = |k: usize| uvs.as_ref().map(|list| &list[start + k]);
            let first_bad = AtomicUsize::new(usize::MAX);
            mesh.triangles.par_extend(range.clone().into_par_iter().map(|t| {
                let triangle = obj_triangle(&obj, t, normals);
                let k = t - range.start;
                if triangle_problem(&triangle, uv(k)).is_some() {
                    first_bad.fetch_min(k, Ordering::Relaxed);
                }
                triangle
            }));
            let k = first_bad.into_inner();
            if k < range.len() {
                let what = triangle_problem(&mesh.triangles[start + k], uv(k)).unwrap_or_default();
                return Err(source.error(format!("{path}: triangle {k} of '{}' {what}", object.name)));
            }
        }
        if mesh.triangles.is_empty() {
            return Err(source.error(format!("{path} contains no triangles")));
        }
        Ok((mesh, uvs))
    }

    /// A light that is not an emitting object.
    fn light(&mut self, l: &LightDesc) -> Result<Light, SceneError> {
        let s = &l.source;
        Ok(match &l.kind {
            &LightKind::Point { position, intensity } => Light::Point { position, intensity },
            &LightKind::Spot { position, direction, intensity, cos_total, cos_falloff_start } => {
                Light::Spot { position, direction, intensity, cos_total, cos_falloff_start }
            }
            &LightKind::Sun { toward, irradiance, angular_radius } => {
                let sun = Sun::new(toward, irradiance, angular_radius).map_err(|e| s.error(e.to_string()))?;
                Light::Infinite(InfiniteLight::Sun(sun))
            }
            &LightKind::Constant { radiance } => {
                let env = ConstantEnvironment::new(radiance).map_err(|e| s.error(e.to_string()))?;
                Light::Infinite(InfiniteLight::Constant(env))
            }
            LightKind::Map { image, scale, rotation, mirrored } => {
                let bitmap = self.bitmap(image)?;
                let name = &image.file.path;
                let (w, h) = (bitmap.width() as usize, bitmap.height() as usize);
                if self.desc.format == SourceFormat::Mitsuba && (w < 2 || h < 3) {
                    return Err(
                        s.error(format!("{name}: Mitsuba needs an envmap of at least 2 × 3 texels, it is {w} × {h}"))
                    );
                }
                let map = if *mirrored {
                    // The map read with its columns in reverse order (u turned into 1 − u), texel centres and
                    // bilinear weights included, is the mirrored one.
                    let texels = (0..w * h).map(|k| bitmap.texel((w - 1 - k % w) as i64, (k / w) as i64)).collect();
                    EnvironmentMap::new(w, h, texels, *scale, *rotation)
                } else {
                    EnvironmentMap::from_bitmap(&bitmap, *scale, *rotation)
                };
                let map = map.map_err(|e| s.error(format!("{name}: {e}")))?;
                Light::Infinite(InfiniteLight::Map(Arc::new(map)))
            }
        })
    }

    /// The scene from its built parts: the geometry and the light table built, and at least one light.
    fn assemble(self, camera: Camera, materials: Vec<Material>) -> Result<Scene, SceneError> {
        let desc = self.desc;
        let at_file = Source { file: desc.path.clone(), line: None, element: None };
        let parts = self.parts;
        let (geometry, bounds, triangle_count) = if self.traced {
            let geometry = SceneGeometry::build_objects(parts.triangles, parts.triangle_objects, parts.analytic)
                .map_err(|e| at_file.error(e.to_string()))?;
            let (bounds, count) = (geometry.bounds(), geometry.triangle_count());
            (geometry, bounds, count)
        } else {
            let bounds = SceneGeometry::bounds_of(&parts.triangles, &parts.analytic);
            (SceneGeometry::empty(), bounds, parts.triangles.len())
        };
        let sphere = SceneSphere::around(bounds);
        let lights = Lights::with_textures(parts.lights, parts.light_textures, triangle_count, sphere);
        if !lights.any() {
            return Err(at_file.error(
                "the scene has no light that gives off light: give an object an emission (an area emitter) or add \
                 a point, spot, sun or environment light",
            ));
        }
        let has_delta_surfaces = parts.objects.iter().any(|o| materials[o.material as usize].has_delta());
        Ok(Scene {
            path: desc.path.clone(),
            camera,
            materials,
            triangle_uvs: if self.traced { parts.triangle_uvs } else { PerTriangle::default() },
            objects: parts.objects,
            geometry,
            lights,
            render: desc.render,
            description: desc.clone(),
            hash: desc.hash(),
            mesh_files: desc.files.iter().map(|f| (f.path.clone(), f.sha256.clone())).collect(),
            has_delta_surfaces,
            ghost_pairs: OnceLock::new(),
            notes: self.notes,
            released: !self.traced,
        })
    }
}

/// Triangle `t` of an OBJ mesh, with its corners' vertex normals when `normals`.
fn obj_triangle(obj: &ObjMesh, t: usize, normals: bool) -> MeshTriangle {
    MeshTriangle {
        v: obj.triangles[t].map(|i| obj.positions[i as usize]),
        n: normals.then(|| obj.triangle_normals[t].map(|i| obj.normals[i as usize])),
    }
}

/// What is wrong with a triangle of an OBJ mesh and its texture coordinates, if anything: the first of its
/// checks that fails.
fn triangle_problem(t: &MeshTriangle, uv: Option<&[Vec2; 3]>) -> Option<&'static str> {
    let v = t.v;
    if !v.iter().all(|p| p.is_finite()) {
        return Some("has a coordinate that is not a finite number");
    }
    let scale = (v[1] - v[0]).length().max((v[2] - v[0]).length());
    if t.area() <= 1e-7 * scale * scale || t.area() == 0.0 {
        return Some("is degenerate (zero area)");
    }
    if t.n.is_some_and(|n| !n.iter().all(|x| x.is_finite() && x.length_squared() > 0.0)) {
        return Some("has a vertex normal that is zero or not finite");
    }
    if uv.is_some_and(|uv| !uv.iter().all(|c| c.is_finite())) {
        return Some("has a texture coordinate that is not a finite number");
    }
    None
}

/// The camera; a sensor camera's rear element is one of `lens_surfaces`, the named lens surfaces.
fn camera(c: &CameraDesc, lens_surfaces: &BTreeMap<String, LensSurface>) -> Result<Camera, SceneError> {
    let (position, look_at, up) = (c.position, c.look_at, c.up);
    Ok(match &c.lens {
        &LensDesc::Pinhole { fov_y_deg } => {
            Camera::new(position, look_at, up, fov_y_deg, c.width, c.height, Lens::Pinhole)
        }
        &LensDesc::Thin { fov_y_deg, radius, focus_distance } => {
            let lens = Lens::Thin { radius, focus_distance };
            Camera::new(position, look_at, up, fov_y_deg, c.width, c.height, lens)
        }
        LensDesc::Sensor { sensor_width, rear_element, rear_source } => {
            let Some(surface) = lens_surfaces.get(rear_element) else {
                let known: Vec<&String> = lens_surfaces.keys().collect();
                return Err(rear_source.error(format!(
                    "no lens_surface object is named '{rear_element}' (named lens surfaces: {known:?})"
                )));
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
                return Err(rear_source.error(format!(
                    "the rear element's clear aperture must lie entirely in front of the sensor (toward look_at); \
                     its centre is {depth} m in front"
                )));
            }
            Camera::sensor(position, look_at, up, *sensor_width, c.width, c.height, rear)
        }
    })
}

/// The texture `t` of a TOML scene with its images decoded from `files` and checked against their bounds, as
/// the build step decodes a material's textures.
#[cfg(test)]
pub(crate) fn decode_texture(
    t: &super::description::TextureDesc,
    files: &BTreeMap<String, Vec<u8>>,
) -> Result<crate::texture::Texture, SceneError> {
    let desc = SceneDescription {
        path: PathBuf::from("t.toml"),
        format: SourceFormat::Toml,
        render: Default::default(),
        camera: CameraDesc {
            position: glam::Vec3::ZERO,
            look_at: glam::Vec3::Z,
            up: glam::Vec3::Y,
            width: 1,
            height: 1,
            lens: LensDesc::Pinhole { fov_y_deg: 45.0 },
        },
        materials: Vec::new(),
        objects: Vec::new(),
        lights: Vec::new(),
        files: Vec::new(),
        notes: Vec::new(),
    };
    let mut builder = Builder::new(&desc, files);
    t.try_map(&mut |b| builder.texture_image(b))
}
