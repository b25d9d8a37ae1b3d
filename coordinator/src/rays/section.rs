//! The section of a selection: its heaviest paths seen from the side, projected orthographically onto the plane
//! of the camera's axis and its up direction, over the outlines where that plane cuts the scene's surfaces. For
//! a camera behind a lens it shows the lens from its sensor to its front element, as a lens drawing does, with
//! the surfaces where the drawn paths reflected picked out and named: which surfaces make a ghost.

use super::canvas::{event_colour, Canvas, EVENT_COLOURS, OTHER_COLOUR};
use super::overlay::{heaviest, relative_weights};
use anyhow::Result;
use glam::{Vec2, Vec3};
use photonfarm::ray_map::{Events, PathKind, RecordedPath};
use photonfarm::scene::Scene;
use std::path::Path;

/// The picture's width in pixels; its height follows the drawn region, within these bounds.
const WIDTH: usize = 720;
const HEIGHT: (usize, usize) = (240, 720);
/// Margin around the drawn region, as a fraction of its size.
const MARGIN: f32 = 0.06;
/// Outline colours: surfaces, glass, and the surfaces the drawn paths reflected at.
const SURFACE: [f32; 3] = [0.5, 0.5, 0.5];
const GLASS: [f32; 3] = [0.55, 0.7, 0.85];
const REFLECTING: [f32; 3] = [1.0, 0.75, 0.3];
const SENSOR: [f32; 3] = [0.9, 0.9, 0.9];

/// The plane the section is drawn in: its origin (the camera's position), the direction drawn to the right
/// (the camera's axis) and the one drawn upward (its up).
struct Plane {
    origin: Vec3,
    across: Vec3,
    up: Vec3,
}

impl Plane {
    fn coords(&self, p: Vec3) -> Vec2 {
        let d = p - self.origin;
        Vec2::new(d.dot(self.across), d.dot(self.up))
    }

    /// Where the plane cuts a triangle: a segment, in plane coordinates.
    fn cut(&self, t: &[Vec3; 3]) -> Option<(Vec2, Vec2)> {
        let normal = self.across.cross(self.up);
        let side = t.map(|v| (v - self.origin).dot(normal));
        let mut points = Vec::with_capacity(2);
        for i in 0..3 {
            let (a, b) = (side[i], side[(i + 1) % 3]);
            if (a < 0.0) != (b < 0.0) {
                let s = a / (a - b);
                points.push(self.coords(t[i] + (t[(i + 1) % 3] - t[i]) * s));
            }
        }
        (points.len() == 2).then(|| (points[0], points[1]))
    }
}

/// Draws the heaviest `max_paths` of `paths` (with their world points `polylines`) over the section of the
/// scene's surfaces (`triangles`, by object) and writes the PNG with its legend.
pub fn write_section(
    png: &Path,
    scene: &Scene,
    triangles: &[Vec<[Vec3; 3]>],
    paths: &[RecordedPath],
    polylines: &[Vec<Vec3>],
    max_paths: usize,
) -> Result<usize> {
    let cam = &scene.camera;
    let plane = Plane { origin: cam.position, across: cam.forward(), up: cam.up() };
    let glass: Vec<bool> = scene.objects.iter().map(|o| scene.materials[o.material as usize].is_dielectric()).collect();
    let weights = relative_weights(paths);
    let drawn = heaviest(&weights, max_paths);
    // A lens is drawn from its sensor to its front element; any other scene around the drawn paths' vertices.
    let sensor_half_height = match cam.lens {
        photonfarm::camera::Lens::Sensor { width, .. } => Some(0.5 * width * cam.height as f32 / cam.width as f32),
        _ => None,
    };
    let region: Vec<Vec2> = if let (Some(half), true) = (sensor_half_height, glass.iter().any(|&g| g)) {
        let lens = triangles.iter().zip(&glass).filter(|(_, g)| **g).flat_map(|(t, _)| t.iter().flatten());
        lens.map(|&p| plane.coords(p)).chain([Vec2::new(0.0, -half), Vec2::new(0.0, half)]).collect()
    } else {
        drawn
            .iter()
            .flat_map(|&i| polylines[i].iter().zip(&paths[i].vertices))
            .filter(|(_, v)| !v.events.contains(Events::ESCAPED))
            .map(|(p, _)| plane.coords(*p))
            .collect()
    };
    let (lo, hi) = region.iter().fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
    let (lo, hi) = if lo.cmple(hi).all() { (lo, hi) } else { (Vec2::splat(-1.0), Vec2::splat(1.0)) };
    let size = (hi - lo).max(Vec2::splat(1e-6));
    let (lo, size) = (lo - size * MARGIN, size * (1.0 + 2.0 * MARGIN));
    let height = ((WIDTH as f32 * size.y / size.x).round() as usize).clamp(HEIGHT.0, HEIGHT.1);
    // One scale for both axes, the region centred.
    let scale = (WIDTH as f32 / size.x).min(height as f32 / size.y);
    let centre = lo + size * 0.5;
    let to_px = |p: Vec2| {
        let q = (p - centre) * scale;
        Vec2::new(WIDTH as f32 * 0.5 + q.x, height as f32 * 0.5 - q.y)
    };
    let mut canvas = Canvas::filled(WIDTH, height, [0.06, 0.06, 0.07]);
    // The surfaces at which at least a quarter of the drawn paths reflected, to pick out and name: those the
    // selection is about, not every surface a few of its paths also met.
    let mut reflections = vec![0usize; scene.objects.len()];
    for &i in &drawn {
        let mut objects: Vec<u16> =
            paths[i].vertices.iter().filter(|v| v.events.contains(Events::REFLECT)).map(|v| v.object).collect();
        objects.sort_unstable();
        objects.dedup();
        for o in objects {
            if let Some(n) = reflections.get_mut(o as usize) {
                *n += 1;
            }
        }
    }
    let reflecting: Vec<bool> = reflections.iter().map(|&n| n > 0 && 4 * n >= drawn.len()).collect();
    let mut labels = Vec::new();
    for (object, tris) in triangles.iter().enumerate() {
        let colour = if reflecting[object] {
            REFLECTING
        } else if glass[object] {
            GLASS
        } else {
            SURFACE
        };
        let mut top: Option<Vec2> = None;
        for t in tris {
            if let Some((a, b)) = plane.cut(t) {
                let (a, b) = (to_px(a), to_px(b));
                canvas.segment(a, b, if reflecting[object] { 2.0 } else { 1.2 }, colour, 0.9);
                for p in [a, b] {
                    if top.is_none_or(|t| p.y < t.y) {
                        top = Some(p);
                    }
                }
            }
        }
        if let (true, Some(t)) = (reflecting[object], top) {
            labels.push((t - Vec2::new(0.0, 10.0), scene.objects[object].name.clone(), REFLECTING));
        }
    }
    let mut used = [false; EVENT_COLOURS.len() + 1];
    if let Some(half) = sensor_half_height {
        let (a, b) = (to_px(Vec2::new(0.0, -half)), to_px(Vec2::new(0.0, half)));
        canvas.segment(a, b, 2.5, SENSOR, 0.9);
        labels.push((b.max(Vec2::new(0.0, 18.0)) - Vec2::new(0.0, 4.0), "sensor".to_string(), SENSOR));
    }
    // Reflections last, over everything else, as in the overlay.
    for reflections in [false, true] {
        for &i in &drawn {
            let (p, r) = (&paths[i], weights[i].sqrt());
            let (width, alpha) = (0.6 + 1.2 * r, 0.2 + 0.7 * r);
            // A light path's story ends where it registered on the sensor.
            let end = match p.kind {
                PathKind::Light => p.vertices.iter().skip(1).position(|v| v.events.contains(Events::SENSOR)),
                PathKind::Camera => None,
            };
            let points = &polylines[i][..end.map_or(polylines[i].len(), |k| k + 2)];
            for (k, pair) in points.windows(2).enumerate() {
                let events = p.vertices[k + 1].events;
                if events.contains(Events::REFLECT) != reflections {
                    continue;
                }
                let (colour, index) = event_colour(events);
                used[index.unwrap_or(EVENT_COLOURS.len())] = true;
                canvas.segment(to_px(plane.coords(pair[0])), to_px(plane.coords(pair[1])), width, colour, alpha);
            }
        }
    }
    let legend: Vec<([f32; 3], String)> = EVENT_COLOURS
        .iter()
        .enumerate()
        .filter(|(i, _)| used[*i])
        .map(|(_, (_, name, c))| (*c, format!("{name} at the end")))
        .chain(used[EVENT_COLOURS.len()].then(|| (OTHER_COLOUR, "path end".to_string())))
        .chain((!labels.is_empty()).then(|| (REFLECTING, "surface reflected at".to_string())))
        .collect();
    let caption = format!(
        "side view: {} of {} selected paths, the heaviest; {:.3} {} across",
        drawn.len(),
        paths.len(),
        WIDTH as f32 / scale,
        "scene units"
    );
    canvas.write_png_labelled(png, &caption, &legend, &labels)?;
    Ok(drawn.len())
}
