//! The typed, format-independent form of a Mitsuba 3 scene: plugins by category with their parameters,
//! nested children and resolved references, each with the position it was written at.

use super::error::{MitsubaError, SourcePos};
use super::files::FileSource;
use super::spectrum::Spectrum;
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What kind of object a plugin element makes: its tag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Category {
    Sensor,
    Film,
    Sampler,
    /// A reconstruction filter (`<rfilter>`).
    ReconstructionFilter,
    Integrator,
    Shape,
    Bsdf,
    Texture,
    Emitter,
    Medium,
    /// A phase function (`<phase>`).
    Phase,
    /// A volume grid (`<volume>`).
    Volume,
    /// A spectrum written as a plugin (`<spectrum type="...">`), not as a value.
    Spectrum,
}

impl Category {
    /// The category of an element tag, or None when the tag is not a plugin tag.
    pub fn from_tag(tag: &str) -> Option<Category> {
        Some(match tag {
            "sensor" => Category::Sensor,
            "film" => Category::Film,
            "sampler" => Category::Sampler,
            "rfilter" => Category::ReconstructionFilter,
            "integrator" => Category::Integrator,
            "shape" => Category::Shape,
            "bsdf" => Category::Bsdf,
            "texture" => Category::Texture,
            "emitter" => Category::Emitter,
            "medium" => Category::Medium,
            "phase" => Category::Phase,
            "volume" => Category::Volume,
            "spectrum" => Category::Spectrum,
            _ => return None,
        })
    }

    /// The element tag of this category, as written in a scene file.
    pub fn tag(self) -> &'static str {
        match self {
            Category::Sensor => "sensor",
            Category::Film => "film",
            Category::Sampler => "sampler",
            Category::ReconstructionFilter => "rfilter",
            Category::Integrator => "integrator",
            Category::Shape => "shape",
            Category::Bsdf => "bsdf",
            Category::Texture => "texture",
            Category::Emitter => "emitter",
            Category::Medium => "medium",
            Category::Phase => "phase",
            Category::Volume => "volume",
            Category::Spectrum => "spectrum",
        }
    }
}

/// A typed parameter value, after `$name` substitution.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    String(String),
    /// An `<rgb>` colour (one value stands for three equal ones).
    Rgb([f64; 3]),
    /// A `<spectrum>` value; `Spectrum::to_rgb` turns it into RGB as Mitsuba's RGB variants do.
    Spectrum(Spectrum),
    Point(DVec3),
    Vector(DVec3),
    /// A `<transform>`: its elements composed in document order (each later one applied after the earlier).
    Transform(DMat4),
}

impl Value {
    /// The tag the value was written with, for messages.
    pub fn tag(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Integer(_) => "integer",
            Value::Boolean(_) => "boolean",
            Value::String(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Spectrum(_) => "spectrum",
            Value::Point(_) => "point",
            Value::Vector(_) => "vector",
            Value::Transform(_) => "transform",
        }
    }
}

/// A named parameter of a plugin.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    pub name: String,
    pub value: Value,
    /// Where the value's element starts.
    pub position: SourcePos,
}

/// A plugin nested in another (a BSDF in a shape, a film in a sensor), written in place or by `<ref>`.
#[derive(Clone, Debug)]
pub struct Child {
    /// The parameter name (`name` attribute), when given: e.g. a texture's `reflectance`.
    pub name: Option<String>,
    /// The plugin; the same `Arc` as every other reference to the same `id`.
    pub plugin: Arc<Plugin>,
    /// Where the child's element (or its `<ref>`) starts.
    pub position: SourcePos,
    /// The id the child was referenced by, when it was written as `<ref id="...">`.
    pub reference: Option<String>,
}

/// One plugin element: `<bsdf type="diffuse" id="white">` with its parameters and children.
#[derive(Clone, Debug)]
pub struct Plugin {
    pub category: Category,
    /// The `type` attribute, as written (case is kept: Mitsuba's own plugin names are lower case).
    pub kind: String,
    pub id: Option<String>,
    /// Where the element starts.
    pub position: SourcePos,
    /// Typed parameters in document order; names are unique within a plugin.
    pub params: Vec<Param>,
    /// Nested and referenced plugins in document order.
    pub children: Vec<Child>,
}

impl Plugin {
    /// The parameter called `name`.
    pub fn param(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }

    /// The children of one category, in document order.
    pub fn children_of(&self, category: Category) -> impl Iterator<Item = &Child> {
        self.children.iter().filter(move |c| c.plugin.category == category)
    }

    /// The element as written, e.g. `<bsdf type="hair">`, for messages that point at it.
    pub fn element(&self) -> String {
        format!("<{} type=\"{}\">", self.category.tag(), self.kind)
    }

    /// An error at this plugin's element.
    pub fn error(&self, message: impl Into<String>) -> MitsubaError {
        MitsubaError::at(&self.position, self.element(), message)
    }
}

/// A whole scene file with its includes, references resolved.
#[derive(Clone, Debug, Default)]
pub struct Document {
    /// The file that was read.
    pub path: PathBuf,
    /// The `version` attribute of the root `<scene>`.
    pub version: String,
    /// Top-level sensors in document order.
    pub sensors: Vec<Arc<Plugin>>,
    /// The top-level integrator; a file with two is refused.
    pub integrator: Option<Arc<Plugin>>,
    /// Top-level shapes in document order, `shapegroup` and `instance` among them as written.
    pub shapes: Vec<Arc<Plugin>>,
    /// Top-level emitters (not those inside shapes, which are the shapes' children).
    pub emitters: Vec<Arc<Plugin>>,
    /// BSDFs declared at the top level (named so that shapes reference them).
    pub bsdfs: Vec<Arc<Plugin>>,
    /// Textures declared at the top level.
    pub textures: Vec<Arc<Plugin>>,
    /// Other top-level plugins (media, films or samplers outside a sensor, ...), for the mapping to refuse or use.
    pub others: Vec<Arc<Plugin>>,
    /// Folders named by `<path value="...">`, most recent first: where `filename` parameters are looked up
    /// before the scene's own folder.
    pub search_paths: Vec<PathBuf>,
    /// The files read besides the scene file (included XML, spectrum files), in the order they were read.
    pub files: Vec<PathBuf>,
}

impl Document {
    /// Resolves a `filename` parameter as Mitsuba's file resolver does: an absolute path as is, otherwise the
    /// first folder of `search_paths` and then the scene's folder where the file exists; when it exists
    /// nowhere, the path in the scene's folder (so that the error names it).
    pub fn resolve_file(&self, name: &str) -> PathBuf {
        let scene_folder = self.path.parent().unwrap_or(Path::new("."));
        resolve_in(name, &self.search_paths, scene_folder, Path::exists)
    }

    /// `resolve_file` with existence judged by `files` (a job's files on a worker).
    pub fn resolve_file_in(&self, name: &str, files: FileSource) -> PathBuf {
        let scene_folder = self.path.parent().unwrap_or(Path::new("."));
        resolve_in(name, &self.search_paths, scene_folder, |p| files.exists(p))
    }
}

/// Looks `name` up in `search_paths`, then in `folder`.
pub(crate) fn resolve_in(
    name: &str,
    search_paths: &[PathBuf],
    folder: &Path,
    exists: impl Fn(&Path) -> bool,
) -> PathBuf {
    let path = Path::new(name);
    if path.is_absolute() {
        return path.to_path_buf();
    }
    search_paths
        .iter()
        .map(|dir| dir.join(path))
        .find(|candidate| exists(candidate))
        .unwrap_or_else(|| folder.join(path))
}
