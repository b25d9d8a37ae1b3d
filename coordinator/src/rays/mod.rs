//! `coordinator rays`: reading the ray maps `render --ray-map` records. `select` is the `rays select` command:
//! it runs a selection expression over a map's portions in parallel and writes what `outputs` makes of the
//! selection (the overlay of `overlay` and the side view of `section`, drawn on a `canvas`; the glTF scene of
//! `gltf_export`; both of the latter with the scene's `surfaces` as triangles; OBJ polylines and reports);
//! `ghosts` is `rays ghosts`, which ranks a lens's ghost pairs. docs/ray-maps.md describes them.

pub mod canvas;
pub mod ghosts;
pub mod gltf_export;
pub mod outputs;
pub mod overlay;
pub mod section;
pub mod select;
pub mod surfaces;

use photonfarm::ray_map::RecordedPath;
use std::path::{Path, PathBuf};

/// What a selection found.
#[derive(Debug, Default)]
pub struct Selection {
    /// The first matches in map order, up to the limit.
    pub paths: Vec<RecordedPath>,
    pub matched_paths: u64,
    pub matched_segments: u64,
    pub total_paths: u64,
    pub total_segments: u64,
    /// Bytes cut off truncated streams, per stream file.
    pub truncated: Vec<(PathBuf, u64)>,
    /// Damaged portions, skipped (a damaged frame) or ending their stream (a damaged portion header): why.
    pub damaged: Vec<String>,
}

/// The render's output folder of a map given as that folder, its raymap/ folder or a stream file in it.
pub fn render_folder(map: &Path) -> PathBuf {
    let dir = if map.is_file() { map.parent().unwrap_or(Path::new(".")) } else { map };
    if dir.join("raymap").is_dir() {
        dir.to_path_buf()
    } else {
        dir.parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf)
    }
}
