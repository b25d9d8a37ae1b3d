//! What `rays select` writes: an overlay PNG of the selected paths over the render's preview, the paths as OBJ
//! polylines, and a report of their vertices as JSON and as a readable table.

use super::render_folder;
use super::selection::Selection;
use crate::cli::PathColour;
use anyhow::{Context, Result};
use photonfarm::ray_map::path::NO_OBJECT;
use photonfarm::ray_map::{Events, MapHeader, PathKind, RecordedPath};
use photonfarm::scene::Scene;
use serde_json::json;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Length an escaped path's last segment is drawn with, relative to its longest segment (at least one unit).
const ESCAPE_LENGTH: f32 = 2.0;
/// Weight of the preview under the drawn paths.
const BACKGROUND_DIM: f32 = 0.55;

/// Writes the overlay (when the scene file can be loaded for its camera), the OBJ file and the report into
/// `out`; returns what was written.
pub fn write_all(
    out: &Path,
    map: &Path,
    header: &MapHeader,
    sel: &Selection,
    expr: &str,
    colour: PathColour,
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
    match Scene::load(Path::new(&header.scene)) {
        Ok(scene) => {
            if scene.hash != header.scene_hash {
                eprintln!(
                    "note: {} changed since the map was recorded; the overlay uses its camera as it is now",
                    header.scene
                );
            }
            let png = out.join("overlay.png");
            write_overlay(&png, &render_folder(map).join("preview.png"), &scene, &sel.paths, colour)?;
            written.push(("overlay", png));
        }
        Err(e) => eprintln!("note: no overlay: the map's scene {} cannot be loaded for its camera ({e})", header.scene),
    }
    Ok(written)
}

/// The points a path is drawn through: escaped directions become points one escape length out.
fn polyline(path: &RecordedPath) -> Vec<glam::Vec3> {
    let longest = path
        .vertices
        .windows(2)
        .filter(|w| !w[1].events.contains(Events::ESCAPED))
        .map(|w| (w[1].position() - w[0].position()).length())
        .fold(1.0f32, f32::max);
    let mut points: Vec<glam::Vec3> = Vec::with_capacity(path.vertices.len());
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

/// The colour a segment ending at a vertex with `events` is drawn in by event.
fn event_colour(e: Events) -> [f32; 3] {
    for (bit, c) in [
        (Events::TIR, [1.0, 0.0, 1.0]),
        (Events::REFLECT, [1.0, 0.2, 0.2]),
        (Events::REFRACT, [0.2, 0.9, 1.0]),
        (Events::DIFFUSE, [0.3, 1.0, 0.3]),
        (Events::EMISSION, [1.0, 0.9, 0.2]),
        (Events::ESCAPED, [0.4, 0.5, 1.0]),
    ] {
        if e.contains(bit) {
            return c;
        }
    }
    [0.6, 0.6, 0.6]
}

/// A path's own colour: its wavelength's, or its weight's hue; grey for a path of no weight.
fn natural_colour(p: &RecordedPath) -> [f32; 3] {
    let c = if p.wavelength_nm > 0.0 {
        photonfarm::spectrum::rgb_matching(p.wavelength_nm).max(glam::Vec3::ZERO).to_array()
    } else {
        p.weight
    };
    let m = c.iter().cloned().fold(0.0f32, f32::max);
    if m > 0.0 && m.is_finite() {
        c.map(|v| (v / m).max(0.0))
    } else {
        [0.7, 0.7, 0.7]
    }
}

/// Draws the paths projected through the scene's camera over the preview (black where there is none) and
/// writes the PNG. Path colours add up where paths overlap and are scaled so that the busiest pixels saturate.
fn write_overlay(
    png_path: &Path,
    preview: &Path,
    scene: &Scene,
    paths: &[RecordedPath],
    colour: PathColour,
) -> Result<()> {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let background = read_rgb8(preview, w, h).unwrap_or_else(|e| {
        eprintln!("note: the overlay is drawn on black: {e}");
        vec![0; w * h * 3]
    });
    let mut acc = vec![0f32; w * h * 3];
    // Inside a sensor camera's lens the first-order projection means nothing: paths are drawn from their pixel
    // (camera paths) through their vertices outside the lens's glass.
    let sensor = matches!(cam.lens, photonfarm::camera::Lens::Sensor { .. });
    let in_lens = |object: u16| {
        sensor
            && scene.objects.get(object as usize).is_some_and(|o| {
                matches!(scene.materials[o.material as usize], photonfarm::material::Material::Dielectric { .. })
            })
    };
    for p in paths {
        let points = polyline(p);
        let natural = natural_colour(p);
        let mut drawn: Vec<(glam::Vec2, usize)> = Vec::with_capacity(points.len());
        for (k, (q, v)) in points.iter().zip(&p.vertices).enumerate() {
            let projected = if k == 0 && p.kind == PathKind::Camera {
                // The camera path starts at its pixel, which a sensor camera's projection cannot reach.
                Some(glam::Vec2::new((p.source % cam.width) as f32 + 0.5, (p.source / cam.width) as f32 + 0.5))
            } else if in_lens(v.object) {
                continue;
            } else {
                cam.project(*q)
            };
            match projected {
                Some(x) => drawn.push((x, k)),
                // A point behind the camera breaks the polyline.
                None => drawn.push((glam::Vec2::NAN, k)),
            }
        }
        for pair in drawn.windows(2) {
            let ((a, _), (b, k)) = (pair[0], pair[1]);
            if a.is_nan() || b.is_nan() {
                continue;
            }
            let c = match colour {
                PathColour::Natural => natural,
                PathColour::Event => event_colour(p.vertices[k].events),
            };
            draw_line(&mut acc, w, h, a, b, c);
        }
    }
    let mut sorted: Vec<f32> = acc.chunks(3).map(|c| c[0].max(c[1]).max(c[2])).filter(|&v| v > 0.0).collect();
    let scale = if sorted.is_empty() {
        1.0
    } else {
        let k = (sorted.len() * 95 / 100).min(sorted.len() - 1);
        let (_, v, _) = sorted.select_nth_unstable_by(k, f32::total_cmp);
        1.0 / v.max(1e-6)
    };
    let pixels: Vec<u8> = background
        .iter()
        .zip(&acc)
        .map(|(&b, &a)| (b as f32 * BACKGROUND_DIM + 255.0 * (a * scale).min(1.0)).min(255.0) as u8)
        .collect();
    let file = std::fs::File::create(png_path).with_context(|| format!("cannot write {}", png_path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().context("PNG header")?;
    writer.write_image_data(&pixels).with_context(|| format!("cannot write {}", png_path.display()))?;
    Ok(())
}

/// Adds colour `c` along the segment from `a` to `b` (pixels), one sample per pixel step, clipped to the image.
fn draw_line(acc: &mut [f32], w: usize, h: usize, a: glam::Vec2, b: glam::Vec2, c: [f32; 3]) {
    let d = b - a;
    let steps = d.abs().max_element().ceil();
    // Segments that leave the image by far are drawn up to a bound, so that a point projected near infinity
    // cannot stall the drawing.
    let steps = if steps.is_finite() { steps.min(4.0 * (w + h) as f32) as usize } else { return };
    for i in 0..=steps {
        let p = a + d * (i as f32 / steps.max(1) as f32);
        if p.x < 0.0 || p.y < 0.0 {
            continue;
        }
        let (x, y) = (p.x as usize, p.y as usize);
        if x < w && y < h {
            for k in 0..3 {
                acc[(y * w + x) * 3 + k] += c[k];
            }
        }
    }
}

/// The preview as 8-bit RGB of the image's size.
fn read_rgb8(path: &Path, w: usize, h: usize) -> Result<Vec<u8>> {
    let file = std::fs::File::open(path).with_context(|| format!("{} cannot be opened", path.display()))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().with_context(|| format!("{} is not a PNG", path.display()))?;
    let mut buf = vec![0; reader.output_buffer_size().context("PNG too large")?];
    let info = reader.next_frame(&mut buf).with_context(|| format!("{} cannot be decoded", path.display()))?;
    if (info.width as usize, info.height as usize) != (w, h) {
        anyhow::bail!("{} is {}×{}, the camera's image {w}×{h}", path.display(), info.width, info.height);
    }
    let channels = info.color_type.samples();
    let rgb = buf[..info.buffer_size()]
        .chunks(channels)
        .flat_map(|px| match channels {
            1 | 2 => [px[0], px[0], px[0]],
            _ => [px[0], px[1], px[2]],
        })
        .collect();
    Ok(rgb)
}
