//! Scenes: the loaded scene the renderer reads (objects, materials, geometry, lights, camera), and how it is
//! made. A reader turns a scene file into a `SceneDescription` (`description`), which knows nothing of the
//! format: `loader` reads TOML files (`file` holds the format) and `mitsuba` Mitsuba 3 files. One build step
//! (`build`) turns a description and the files it references into a `Scene`, on the coordinator and on every
//! worker alike. `error` holds the error that points at the file, line and field; `ghost` what a scene
//! declares about the ghosts its lens makes; `obj` reads OBJ meshes.

pub mod build;
pub mod description;
pub mod error;
pub mod file;
pub mod ghost;
mod loader;

pub use loader::SceneFiles;
pub mod mitsuba;
pub mod obj;

pub use error::SceneError;
pub use mitsuba::MitsubaOptions;

use crate::bsdf::Bsdf;
use crate::camera::Camera;
use crate::color::Rgb;
use crate::geometry::{PerTriangle, SceneGeometry, SurfaceHit};
use crate::light::Lights;
use crate::material::Material;
use crate::texture::{barycentric, interpolate_uv, uv_tangent};
use glam::{Vec2, Vec3};
use std::path::PathBuf;
use std::sync::OnceLock;

/// One object of the scene.
#[derive(Clone, Debug)]
pub struct SceneObject {
    pub name: String,
    pub material: u32,
    pub emission: Option<Rgb>,
}

/// Integrator settings a scene carries (the `[render]` table), each overridable from the command line.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneRenderSettings {
    /// Longest path in segments over the joined camera and light sub-paths: 1 = emitters seen directly.
    pub max_depth: u32,
    /// Diffuse vertices on a camera path that store backward photons, 1 or 2 (paper §2: 2); None: the run
    /// chooses in its first steps (`render::light_balance`).
    pub backward_diffuse_depth: Option<u32>,
    /// Initial photon radius in pixel footprints.
    pub radius_scale: f32,
    /// Light paths per phase, per pixel of the image; None: the run chooses them as it goes
    /// (`render::light_balance`), from 1.
    pub light_paths_per_pixel: Option<f32>,
    /// For a lens that can make ghosts: whether light paths bring the all-specular ghost chains to the sensor
    /// (the default), or camera paths alone find them, as they find everything else.
    pub ghost_light_paths: bool,
    /// Ghost paths traced per light path where light paths bring the ghost chains (`ghost::ghost_paths`); 0 leaves
    /// the chains to the light paths themselves.
    pub ghost_paths: u32,
    /// The radius in pixels, at the first phase, of the disc on the sensor each ghost chain's registration is
    /// spread over (`crate::pbpm::sensor_kernel`); below 1, a chain registers on its pixel alone.
    pub ghost_radius: f32,
}

impl Default for SceneRenderSettings {
    fn default() -> Self {
        SceneRenderSettings {
            max_depth: 12,
            backward_diffuse_depth: None,
            radius_scale: 3.0,
            light_paths_per_pixel: None,
            ghost_light_paths: true,
            ghost_paths: ghost::GHOST_PATHS_PER_LIGHT_PATH,
            ghost_radius: ghost::GHOST_RADIUS,
        }
    }
}

/// A loaded, validated scene (`Scene::load` and the other constructors are in `loader`).
pub struct Scene {
    /// The scene file it came from.
    pub path: PathBuf,
    pub camera: Camera,
    pub materials: Vec<Material>,
    /// Texture coordinates of each triangle, by the index it was added with.
    pub triangle_uvs: PerTriangle<[Vec2; 3]>,
    pub objects: Vec<SceneObject>,
    pub geometry: SceneGeometry,
    pub lights: Lights,
    pub render: SceneRenderSettings,
    /// The description it was built from (`description::SceneDescription`): what a job carries to workers.
    pub description: description::SceneDescription,
    /// SHA-256 of the description (`SceneDescription::hash`), which names every file it references by its own.
    pub hash: String,
    /// Every file the scene references, meshes and textures: its path as written in the scene and its SHA-256
    /// (hex). Jobs send these to workers.
    pub mesh_files: Vec<(String, String)>,
    /// True when any object has a specular material (then caustics exist).
    pub has_delta_surfaces: bool,
    /// The pairs of reflecting surfaces ghost paths draw from, where the scene traces ghost paths: filled by
    /// the estimator's pilot on first use (`crate::pbpm::ghost_pairs`), which needs the estimator, and kept
    /// here so that every phase of the run reads the same table.
    pub(crate) ghost_pairs: OnceLock<Option<ghost::GhostPairs>>,
    /// What an imported scene's mapping ignored or rendered differently, one sentence each, for the run record
    /// (empty for TOML scenes, whose every key maps exactly).
    pub notes: Vec<String>,
    /// Set once the geometry was let go (`release_geometry`): the scene can no longer be traced.
    released: bool,
}

/// True when the file is a Mitsuba 3 scene, told by its extension `.xml`; other files are TOML scenes.
pub fn is_mitsuba(path: &std::path::Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml"))
}

impl description::SceneDescription {
    /// Reads a scene file of either format into its description and the files it references; `options` say how
    /// a Mitsuba scene is imported and are refused for a TOML scene, which has no parameters and maps every key
    /// exactly.
    pub fn read(path: &std::path::Path, options: &MitsubaOptions) -> Result<(Self, SceneFiles), SceneError> {
        if is_mitsuba(path) {
            return Self::from_mitsuba(path, options);
        }
        let refused = match (options.defines.first(), options.approximate) {
            (Some((name, _)), _) => format!("--define {name}=...: only Mitsuba scenes (.xml) take parameters"),
            (None, true) => "--approximate: only Mitsuba scenes (.xml) are imported".into(),
            (None, false) => {
                let text = std::fs::read_to_string(path).map_err(|e| SceneError {
                    file: path.to_path_buf(),
                    line: None,
                    field: None,
                    message: format!("cannot read the scene file: {e}"),
                })?;
                return Self::from_toml(&text, path, path.parent().unwrap_or(std::path::Path::new(".")));
            }
        };
        Err(SceneError { file: path.to_path_buf(), line: None, field: None, message: refused })
    }
}

impl Scene {
    /// Lets go of the triangles, their BVH and their texture coordinates, keeping what describes the scene (the
    /// camera, materials, lights, description and hash): for a process that merges and saves what others
    /// render and never traces a ray, such as the coordinator of a distributed run.
    pub fn release_geometry(&mut self) {
        self.geometry = SceneGeometry::empty();
        self.triangle_uvs = PerTriangle::default();
        self.released = true;
    }

    /// Whether the geometry was let go (`release_geometry`).
    pub fn is_released(&self) -> bool {
        self.released
    }

    /// Panics when the geometry was let go: every renderer calls it before it traces, so that a released scene
    /// fails loudly rather than rendering an empty world.
    pub fn assert_traceable(&self) {
        assert!(!self.released, "the scene's geometry was released: it cannot be traced");
    }

    /// Reads a scene file of either format and builds it; `options` as `SceneDescription::read` takes them.
    pub fn load_with_options(path: &std::path::Path, options: &MitsubaOptions) -> Result<Scene, SceneError> {
        let (desc, files) = description::SceneDescription::read(path, options)?;
        Scene::from_hashed_files(&desc, &files)
    }

    /// `load_with_options` for a process that never traces the scene (`Scene::untraced_from_hashed_files`):
    /// the same checks, lights and camera, no BVH.
    pub fn load_untraced(path: &std::path::Path, options: &MitsubaOptions) -> Result<Scene, SceneError> {
        let (desc, files) = description::SceneDescription::read(path, options)?;
        Scene::untraced_from_hashed_files(&desc, &files)
    }

    /// Builds a scene from a scene file's text, its name (whose extension tells the format), the Mitsuba import
    /// options and the files it references by the path the scene writes, none of them read from disk.
    pub fn from_job_files(
        text: &str,
        name: &std::path::Path,
        options: &MitsubaOptions,
        files: &std::collections::BTreeMap<String, Vec<u8>>,
    ) -> Result<Scene, SceneError> {
        if is_mitsuba(name) {
            Scene::from_mitsuba_with_files(text, name, options, files)
        } else {
            Scene::from_toml_with_meshes(text, name, files)
        }
    }

    /// True when a material disperses light: the scene then renders spectrally (after dispersive events).
    pub fn is_spectral(&self) -> bool {
        self.materials.iter().any(Material::is_dispersive)
    }

    /// The material of the object at `hit`.
    #[inline]
    pub fn material_at(&self, hit: &SurfaceHit) -> &Material {
        &self.materials[self.objects[hit.object as usize].material as usize]
    }

    /// The BSDF at `hit` for a path arriving from `wo` (pointing back along the path), with the material's
    /// textures read at the hit's texture coordinates and, for an anisotropic material, its frame oriented by
    /// the surface's tangent (`Scene::tangent_at`).
    #[inline(always)]
    pub fn bsdf(&self, hit: &SurfaceHit, wo: Vec3) -> Bsdf {
        let material = self.material_at(hit);
        if material.needs_tangent() {
            return self.oriented_bsdf(material, hit, wo);
        }
        let uv = if material.uses_uv() { self.uv_at(hit) } else { Vec2::ZERO };
        material.bsdf(hit, uv, wo)
    }

    /// `bsdf` for a material that reads the tangent, out of the common path's way.
    #[inline(never)]
    fn oriented_bsdf(&self, material: &Material, hit: &SurfaceHit, wo: Vec3) -> Bsdf {
        let uv = if material.uses_uv() { self.uv_at(hit) } else { Vec2::ZERO };
        match self.tangent_at(hit) {
            Some(tangent) => material.bsdf_with_tangent(hit, uv, tangent, wo),
            None => material.bsdf(hit, uv, wo),
        }
    }

    /// ∂p/∂u at the hit, which orients anisotropic materials as Mitsuba 3 orients them: on a triangle with
    /// texture coordinates, the derivative along u of their parametrisation; on one without, along its first
    /// barycentric coordinate (the edge from its first vertex to its second), since Mitsuba then takes the
    /// barycentrics as texture coordinates. None on a triangle whose coordinates lie on a line and on analytic
    /// surfaces: the frame then follows the normal alone.
    pub fn tangent_at(&self, hit: &SurfaceHit) -> Option<Vec3> {
        if hit.triangle == u32::MAX {
            return None;
        }
        let v = &self.geometry.triangle(hit.triangle).v;
        match self.triangle_uvs.get(hit.triangle) {
            Some(uv) => uv_tangent(v, uv),
            _ => Some(v[1] - v[0]),
        }
    }

    /// The texture coordinates at the hit point ((0, 0) where the surface has none, which the loader does not
    /// let a textured material meet).
    fn uv_at(&self, hit: &SurfaceHit) -> Vec2 {
        match self.triangle_uvs.get(hit.triangle) {
            Some(uv) => {
                let b = barycentric(&self.geometry.triangle(hit.triangle).v, hit.p);
                interpolate_uv(uv, b)
            }
            _ => Vec2::ZERO,
        }
    }
}
