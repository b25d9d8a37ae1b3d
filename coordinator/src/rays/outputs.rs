//! What `rays select` writes: an overlay PNG of the selected paths over the render's preview (`overlay`), the
//! paths with the scene's geometry as a glTF binary (`gltf_export`), the paths as OBJ polylines, and a report of
//! their vertices as JSON and as a readable table.

use super::gltf_export::write_glb;
use super::overlay::{write_overlay, OverlayStyle};
use super::section::write_section;
use super::surfaces::object_triangles;
use super::{render_folder, Selection};
use anyhow::{Context, Result};
use glam::Vec3;
use photonfarm::ray_map::path::NO_OBJECT;
use photonfarm::ray_map::{Events, MapHeader, PathKind, RecordedPath};
use photonfarm::scene::Scene;
use serde_json::json;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Length an escaped path's last segment is drawn with, relative to its longest segment (at least one unit).
const ESCAPE_LENGTH: f32 = 2.0;

/// What `rays select` draws and exports beyond its reports.
#[derive(Clone, Copy, Debug)]
pub struct Pictures {
    pub overlay: OverlayStyle,
    /// Write `selection.glb`.
    pub glb: bool,
}

/// Writes the OBJ file and the report into `out`, and, when the map's scene file can be loaded (for its camera
/// and geometry), the overlay and the glTF file; returns what was written.
pub fn write_all(
    out: &Path,
    map: &Path,
    header: &MapHeader,
    sel: &Selection,
    expr: &str,
    pictures: Pictures,
) -> Result<Vec<(&'static str, PathBuf)>> {
    let mut written = Vec::new();
    let obj = out.join("paths.obj");
    std::fs::write(&obj, obj_text(header, &sel.paths)).with_context(|| format!("cannot write {}", obj.display()))?;
    written.push(("paths (OBJ polylines)", obj));
    let json = out.join("report.json");
    let report = serde_json::to_string_pretty(&report_json(header, sel, expr)).expect("JSON of plain values");
    std::fs::write(&json, report).with_context(|| format!("cannot write {}", json.display()))?;
    written.push(("report", json));
    let table = out.join("report.txt");
    std::fs::write(&table, report_table(header, sel, expr))
        .with_context(|| format!("cannot write {}", table.display()))?;
    written.push(("table", table));
    let scene = match Scene::load(Path::new(&header.scene)) {
        Ok(scene) => scene,
        Err(e) => {
            tracing::warn!(
                "no overlay and no glTF file: the map's scene {} cannot be loaded for its camera and geometry \
                 ({e})",
                header.scene
            );
            return Ok(written);
        }
    };
    if scene.hash != header.scene_hash {
        tracing::warn!(
            "{} changed since the map was recorded; the overlay and the glTF file show it as it is now",
            header.scene
        );
    }
    let polylines: Vec<Vec<Vec3>> = sel.paths.iter().map(polyline).collect();
    let png = out.join("overlay.png");
    let preview = render_folder(map).join("preview.png");
    write_overlay(&png, &preview, &scene, &sel.paths, &polylines, pictures.overlay)?;
    written.push(("overlay", png));
    let triangles = object_triangles(&scene);
    let side = out.join("section.png");
    write_section(&side, &scene, &triangles, &sel.paths, &polylines, pictures.overlay.max_paths)?;
    written.push(("side view", side));
    if pictures.glb {
        let glb = out.join("selection.glb");
        write_glb(&glb, &scene, &triangles, &sel.paths, &polylines)?;
        written.push(("scene and paths (glTF binary)", glb));
    }
    Ok(written)
}

/// The points a path is drawn through: escaped directions become points one escape length out.
pub fn polyline(path: &RecordedPath) -> Vec<Vec3> {
    let longest = path
        .vertices
        .windows(2)
        .filter(|w| !w[1].events.contains(Events::ESCAPED))
        .map(|w| (w[1].position() - w[0].position()).length())
        .fold(1.0f32, f32::max);
    let mut points: Vec<Vec3> = Vec::with_capacity(path.vertices.len());
    for v in &path.vertices {
        let p = match (v.events.contains(Events::ESCAPED), points.last()) {
            (true, Some(&last)) => last + v.position() * longest * ESCAPE_LENGTH,
            _ => v.position(),
        };
        points.push(p);
    }
    points
}

fn object_name(header: &MapHeader, object: u16) -> String {
    if object == NO_OBJECT {
        return "-".into();
    }
    header.objects.get(object as usize).cloned().unwrap_or_else(|| format!("object {object}"))
}

fn source_name(header: &MapHeader, path: &RecordedPath) -> String {
    match path.kind {
        PathKind::Camera => {
            let w = header.width.max(1);
            format!("pixel ({}, {})", path.source % w, path.source / w)
        }
        PathKind::Light => {
            header.emitters.get(path.source as usize).cloned().unwrap_or_else(|| format!("emitter {}", path.source))
        }
    }
}

fn kind_name(k: PathKind) -> &'static str {
    match k {
        PathKind::Camera => "camera",
        PathKind::Light => "light",
    }
}

/// The OBJ file: one object and one polyline per path, named by kind, phase and number.
fn obj_text(header: &MapHeader, paths: &[RecordedPath]) -> String {
    let mut s =
        format!("# ray map selection of {} ({} paths); open with the scene's meshes\n", header.scene, paths.len());
    let mut next = 1usize;
    for (i, p) in paths.iter().enumerate() {
        let points = polyline(p);
        let _ = writeln!(s, "o path{i}_{}_phase{}_item{}", kind_name(p.kind), p.phase, p.item);
        for v in &points {
            let _ = writeln!(s, "v {} {} {}", v.x, v.y, v.z);
        }
        if points.len() >= 2 {
            let indices: Vec<String> = (next..next + points.len()).map(|k| k.to_string()).collect();
            let _ = writeln!(s, "l {}", indices.join(" "));
        }
        next += points.len();
    }
    s
}

fn report_json(header: &MapHeader, sel: &Selection, expr: &str) -> serde_json::Value {
    let paths: Vec<serde_json::Value> = sel
        .paths
        .iter()
        .map(|p| {
            let vertices: Vec<serde_json::Value> = p
                .vertices
                .iter()
                .map(|v| {
                    json!({
                        "point": v.point,
                        "object": object_name(header, v.object),
                        "primitive": (v.primitive != u32::MAX).then_some(v.primitive),
                        "normal": v.normal().to_array(),
                        "events": v.events.names(),
                    })
                })
                .collect();
            json!({
                "kind": kind_name(p.kind),
                "source": source_name(header, p),
                "phase": p.phase,
                "item": p.item,
                "wavelength_nm": (p.wavelength_nm > 0.0).then_some(p.wavelength_nm),
                "weight": p.weight,
                "vertices": vertices,
            })
        })
        .collect();
    json!({
        "scene": header.scene,
        "expression": expr,
        "matched_paths": sel.matched_paths,
        "matched_segments": sel.matched_segments,
        "total_paths": sel.total_paths,
        "total_segments": sel.total_segments,
        "truncated": sel.truncated.iter().map(|(f, b)| json!({"stream": f.display().to_string(), "bytes_left": b})).collect::<Vec<_>>(),
        "damaged": sel.damaged,
        "paths": paths,
    })
}

fn report_table(header: &MapHeader, sel: &Selection, expr: &str) -> String {
    let mut s = format!(
        "selection: {expr}\n{} of {} paths match ({} of {} segments); {} listed\n",
        sel.matched_paths,
        sel.total_paths,
        sel.matched_segments,
        sel.total_segments,
        sel.paths.len()
    );
    for (i, p) in sel.paths.iter().enumerate() {
        let colour = if p.wavelength_nm > 0.0 { format!("{:.1} nm", p.wavelength_nm) } else { "RGB".into() };
        let _ = writeln!(
            s,
            "\npath {i}: {} path from {}, phase {}, item {}, {colour}, weight [{:.4e}, {:.4e}, {:.4e}]",
            kind_name(p.kind),
            source_name(header, p),
            p.phase,
            p.item,
            p.weight[0],
            p.weight[1],
            p.weight[2]
        );
        let _ = writeln!(s, "  {:>3}  {:>34}  {:<16} events", "#", "point (or escape direction)", "object");
        for (k, v) in p.vertices.iter().enumerate() {
            let [x, y, z] = v.point;
            let _ = writeln!(
                s,
                "  {k:>3}  {:>34}  {:<16} {}",
                format!("({x:.5}, {y:.5}, {z:.5})"),
                object_name(header, v.object),
                v.events.names()
            );
        }
    }
    s
}
