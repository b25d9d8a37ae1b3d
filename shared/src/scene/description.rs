//! A scene as its readers describe it, knowing nothing of TOML or XML: the camera, the materials with their
//! textures, the objects with their shapes, the lights and the render settings, with every file the scene
//! references named by its path relative to the scene's folder and its SHA-256, and every element by where it
//! is written. Both readers (`super::loader` for TOML, `super::mitsuba` for Mitsuba 3 XML) produce one;
//! `Scene::from_description` (`super::build`) reads its files, checks what needs them, and builds the scene. A
//! description is what a job carries to workers, so that they build the coordinator's scene without its file.

use super::{SceneError, SceneRenderSettings};
use crate::color::Rgb;
use crate::geometry::{Analytic, MeshTriangle};
use crate::material::{Back, Surface};
use crate::texture::{Encoding, Texture};
use glam::{DMat4, Mat3, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::PathBuf;

/// Where an element is written: the file, the 1-based line when known, and the element (a TOML field such as
/// `objects[3].material`, or a Mitsuba element such as `<shape type="obj">`), so that an error the build step
/// finds names what to fix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Source {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub element: Option<String>,
}

impl Source {
    /// The error `message` at this element.
    pub fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError { file: self.file.clone(), line: self.line, field: self.element.clone(), message: message.into() }
    }
}

/// Which format a description was read from: the build step words a few of its errors as that format's reader
/// words the rest, in the format's own terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SourceFormat {
    Toml,
    Mitsuba,
}

/// A file the scene references (a mesh or an image): its path relative to the scene file's folder, which is
/// also the key it is sent under, and its SHA-256 (hex).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct FileRef {
    pub path: String,
    pub sha256: String,
}

/// An image file in a texture or an environment map: the file, how its integer samples are encoded, the bound
/// its values (times the texture's factor) must stay within, and where it is named.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageRef {
    pub file: FileRef,
    pub encoding: Encoding,
    pub bound: Option<Bound>,
    pub source: Source,
}

/// The largest value a textured parameter may take anywhere (a reflectance's 1), and where the parameter is
/// written, which an error names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bound {
    pub max: f32,
    pub source: Source,
}

/// A texture of a description: its bitmaps are image files.
pub type TextureDesc = Texture<ImageRef>;

/// Sets the bound of every image of `t` (`ImageRef::bound`).
pub fn bound_images(t: &mut TextureDesc, bound: &Bound) {
    match t {
        Texture::Constant(_) => {}
        Texture::Bitmap(b) => b.image.bound = Some(bound.clone()),
        Texture::Checkerboard(c) => {
            bound_images(&mut c.color0, bound);
            bound_images(&mut c.color1, bound);
        }
    }
}

/// The largest value `t` reaches where it is constant (its images count as 0: the build step checks those).
pub fn constant_max(t: &TextureDesc) -> f32 {
    match t {
        Texture::Constant(c) => c.max_element(),
        Texture::Bitmap(_) => 0.0,
        Texture::Checkerboard(c) => constant_max(&c.color0).max(constant_max(&c.color1)),
    }
}

/// A material: its front family, its back and its opacity, with image files where they are textured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialDesc {
    /// The name the scene gives it (for errors).
    pub name: String,
    pub front: Surface<ImageRef>,
    pub back: Back<ImageRef>,
    pub opacity: Option<TextureDesc>,
    pub source: Source,
}

impl MaterialDesc {
    /// True when a parameter depends on texture coordinates, which the shapes wearing it must then have.
    pub fn uses_uv(&self) -> bool {
        let back = match &self.back {
            Back::Other(s) => s.varies(),
            _ => false,
        };
        self.front.varies() || back || self.opacity.as_ref().is_some_and(Texture::varies)
    }
}

/// The mesh file formats a placed mesh is read from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum MeshFormat {
    /// Wavefront OBJ, its texture coordinates' v flipped when `flip_tex_coords` (Mitsuba's default).
    Obj { flip_tex_coords: bool },
    /// Stanford PLY.
    Ply,
    /// Mesh `shape_index` of a Mitsuba `serialized` file.
    Serialized { shape_index: u32 },
}

/// An object's shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ShapeDesc {
    /// Triangles given in the description (a quad, a box, a shape built from a few triangles), with their
    /// texture coordinates when every one has them.
    Triangles { triangles: Vec<MeshTriangle>, uvs: Option<Vec<[Vec2; 3]>> },
    /// An OBJ file in world coordinates, every triangle of which must have an area (a TOML scene's `mesh`);
    /// `source` is where it is named.
    Obj { file: FileRef, source: Source },
    /// A mesh file moved by `to_world` (its triangles without an area left out, with a note), `face_normals`
    /// dropping its vertex normals and `flip_normals` turning it over (a Mitsuba mesh shape).
    PlacedMesh { file: FileRef, format: MeshFormat, face_normals: bool, to_world: DMat4, flip_normals: bool },
    /// An analytic surface.
    Analytic(Analytic),
}

/// One object: a shape with a material and, when it emits, its radiance and emission texture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectDesc {
    pub name: String,
    /// The name a sensor camera's `rear_element` finds a lens surface by, when the scene gives one.
    pub lens_name: Option<String>,
    /// Index into `SceneDescription::materials`.
    pub material: u32,
    pub emission: Option<Rgb>,
    /// An image that multiplies `emission`, on a shape with texture coordinates.
    pub emission_texture: Option<ImageRef>,
    pub shape: ShapeDesc,
    /// The object's element.
    pub source: Source,
    /// Where its material is named.
    pub material_source: Source,
}

/// A light that is not an emitting object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum LightKind {
    Point {
        position: Vec3,
        intensity: Rgb,
    },
    Spot {
        position: Vec3,
        direction: Vec3,
        intensity: Rgb,
        cos_total: f32,
        cos_falloff_start: f32,
    },
    /// The sun: the way toward it, the irradiance it gives and its disc's angular radius in radians.
    Sun {
        toward: Vec3,
        irradiance: Rgb,
        angular_radius: f32,
    },
    /// The same radiance from every direction.
    Constant {
        radiance: Rgb,
    },
    /// An equirectangular environment map times `scale`, turned by `rotation`; `mirrored` reads it with its
    /// columns in reverse order (a mirroring transform, the rest of which is `rotation`).
    Map {
        image: ImageRef,
        scale: f32,
        rotation: Mat3,
        mirrored: bool,
    },
}

/// A light and where it is written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightDesc {
    pub kind: LightKind,
    pub source: Source,
}

/// The camera's lens.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum LensDesc {
    Pinhole {
        fov_y_deg: f32,
    },
    Thin {
        fov_y_deg: f32,
        radius: f32,
        focus_distance: f32,
    },
    /// A sensor behind a lens of the scene, whose rear element is the lens surface named `rear_element`,
    /// written at `rear_source`.
    Sensor {
        sensor_width: f32,
        rear_element: String,
        rear_source: Source,
    },
}

/// The camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraDesc {
    pub position: Vec3,
    pub look_at: Vec3,
    pub up: Vec3,
    pub width: u32,
    pub height: u32,
    pub lens: LensDesc,
}

/// A whole scene as its reader describes it (see the module's doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneDescription {
    /// The scene file it was read from.
    pub path: PathBuf,
    pub format: SourceFormat,
    pub render: SceneRenderSettings,
    pub camera: CameraDesc,
    pub materials: Vec<MaterialDesc>,
    pub objects: Vec<ObjectDesc>,
    pub lights: Vec<LightDesc>,
    /// Every file the objects, materials and lights reference, once each, in the order they were read.
    pub files: Vec<FileRef>,
    /// What the reader ignored or mapped approximately, one sentence each.
    pub notes: Vec<String>,
}

impl SceneDescription {
    /// The description as bytes: bincode's standard encoding, which the hash is taken over and jobs carry.
    pub fn to_bytes(&self) -> Vec<u8> {
        bincode::serde::encode_to_vec(self, bincode::config::standard()).expect("a description always encodes")
    }

    /// SHA-256 (hex) of what the description says about the scene: its `to_bytes` without the paths of the
    /// files it was read from and without its notes, so that the same scene read from another folder (or from
    /// memory, as tests do) hashes the same. A description names every file by its content's hash, so this is
    /// the hash of the whole scene.
    pub fn hash(&self) -> String {
        format!("{:x}", Sha256::digest(self.without_locations().to_bytes()))
    }

    /// The description with its path, every source's file and its notes (which name files) left empty.
    fn without_locations(&self) -> SceneDescription {
        fn source(s: &mut Source) {
            s.file = PathBuf::new();
        }
        fn image(i: &ImageRef) -> ImageRef {
            let mut i = i.clone();
            source(&mut i.source);
            if let Some(b) = &mut i.bound {
                source(&mut b.source);
            }
            i
        }
        let mut texture =
            |b: &crate::texture::BitmapTexture<ImageRef>| Ok::<_, std::convert::Infallible>(image(&b.image));
        let mut d = self.clone();
        d.path = PathBuf::new();
        d.notes.clear();
        for m in &mut d.materials {
            source(&mut m.source);
            let Ok(front) = m.front.try_map(&mut texture);
            let Ok(back) = m.back.try_map(&mut texture);
            (m.front, m.back) = (front, back);
            if let Some(t) = &m.opacity {
                let Ok(t) = t.try_map(&mut texture);
                m.opacity = Some(t);
            }
        }
        for o in &mut d.objects {
            source(&mut o.source);
            source(&mut o.material_source);
            o.emission_texture = o.emission_texture.as_ref().map(image);
            if let ShapeDesc::Obj { source: s, .. } = &mut o.shape {
                source(s);
            }
        }
        for l in &mut d.lights {
            source(&mut l.source);
            if let LightKind::Map { image: i, .. } = &mut l.kind {
                *i = image(i);
            }
        }
        if let LensDesc::Sensor { rear_source, .. } = &mut d.camera.lens {
            source(rear_source);
        }
        d
    }
}
