//! Mitsuba 3 scene files: the XML format read into a typed, format-independent `Document` (plugins with their
//! parameters, children and source positions), and Mitsuba's `serialized` mesh format. Turning a `Document`
//! into photonfarm's scene is a separate step; what the reader accepts is in docs/scenes.md.
//!
//! `xml` reads files (substitution, includes, references), `transform` computes the transform elements,
//! `spectrum` holds spectra and their conversion to RGB, `document` the result, `error` the errors that name
//! file, line, column and element, and `serialized` the mesh format.

pub mod document;
pub mod error;
pub mod files;
pub(crate) mod meshes;
pub mod ply;
pub mod serialized;
pub mod spectrum;
mod to_scene;
mod transform;
pub mod xml;

pub use document::{Category, Child, Document, Param, Plugin, Value};
pub use error::{MitsubaError, SourcePos};
pub use files::FileSource;
pub use spectrum::{Spectrum, SpectrumUse};
pub use xml::{read_file, read_str, read_str_from};

use serde::{Deserialize, Serialize};

/// How a Mitsuba scene file is imported: its `$name` parameters (Mitsuba's `-D name=value`), and whether what
/// photonfarm has no exact counterpart for is imported as the nearest thing it renders, each substitution
/// noted, instead of refused (`--approximate`). Both are part of the scene, so both go into its hash.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MitsubaOptions {
    pub defines: Vec<(String, String)>,
    pub approximate: bool,
}
