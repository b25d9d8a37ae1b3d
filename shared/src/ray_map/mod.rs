//! Ray maps (the seed paper's "visualization of ray propagation"): a recorded fraction of a render's camera
//! and light paths, stored compressed in portions, read back in parallel and selected by logical expressions
//! of optical events (`select`). docs/ray-maps.md describes the format and the commands.

pub mod events;
pub mod format;
pub mod path;
pub mod quantise;
pub mod reader;
pub mod select;
pub mod writer;

pub use events::Events;
pub use format::MapHeader;
pub use path::{PathKind, PathLog, RecordedPath, Unrecorded, Vertex};
pub use writer::{Portion, PortionSink, Recorder, StreamStats};

use crate::light::Light;
use crate::scene::Scene;

/// What can go wrong recording or reading a ray map.
#[derive(Debug, thiserror::Error)]
pub enum RayMapError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{0} is not a ray map stream (it does not start with the ray map's magic bytes)")]
    NotAMap(String),
    #[error("{path} is a ray map of format version {found}; this build reads version {supported}")]
    Version { path: String, found: u32, supported: u32 },
    #[error("{path}: its header cannot be read: {reason}")]
    Header { path: String, reason: String },
    #[error("{path}: the portion at byte {offset} is corrupt: {reason} (the portions before it are whole)")]
    Corrupt { path: String, offset: u64, reason: String },
    #[error("no ray map stream (*.pfrm) in {0}")]
    NoStreams(String),
    #[error("{first} and {other} were recorded from different scenes")]
    Mixed { first: String, other: String },
    #[error("--ray-map-fraction must be in (0, 1], not {0}")]
    Fraction(f64),
    #[error("a ray map stores object numbers in 16 bits; this scene has {0} objects")]
    TooManyObjects(usize),
    #[error("the ray map writer of {0} stopped unexpectedly")]
    WriterPanicked(String),
    #[error("the ray map {0} was already finished")]
    Finished(String),
}

/// The object names of a scene, by object index.
pub fn object_names(scene: &Scene) -> Vec<String> {
    scene.objects.iter().map(|o| o.name.clone()).collect()
}

/// The emitters of a scene: the emitting objects (by object index), then the `[[lights]]` entries.
pub fn emitter_names(scene: &Scene) -> Vec<String> {
    let mut names = object_names(scene);
    let entries = scene.lights.all().iter().filter(|l| is_entry(l)).count();
    names.extend((0..entries).map(|i| format!("lights[{i}]")));
    names
}

/// True for a light of a `[[lights]]` entry; the others are the surfaces of emitting objects.
fn is_entry(light: &Light) -> bool {
    !matches!(light, Light::Area { .. } | Light::Sphere { .. } | Light::Disc { .. })
}

/// The emitter (index into `emitter_names`) of light number `light`.
pub fn emitter_of(scene: &Scene, light: u32) -> u32 {
    let all = scene.lights.all();
    match all.get(light as usize) {
        Some(Light::Area { triangle, .. }) => scene.geometry.object_of_triangle(*triangle),
        Some(Light::Sphere { object, .. } | Light::Disc { object, .. }) => *object,
        _ => {
            let entry = all[..(light as usize).min(all.len())].iter().filter(|l| is_entry(l));
            (scene.objects.len() + entry.count()) as u32
        }
    }
}

/// A map header for a render of `scene`.
pub fn header_for(scene: &Scene, method: &str, seed: u64, fraction: f64, stream: u32) -> MapHeader {
    MapHeader {
        scene: scene.path.display().to_string(),
        scene_hash: scene.hash.clone(),
        width: scene.camera.width,
        height: scene.camera.height,
        objects: object_names(scene),
        emitters: emitter_names(scene),
        method: method.to_string(),
        seed,
        fraction,
        stream,
    }
}
