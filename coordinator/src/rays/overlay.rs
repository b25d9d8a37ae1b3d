//! The overlay of a selection: its heaviest paths projected through the scene's camera and drawn over the
//! render's preview (enlarged, greyed and dimmed so that the paths stand out on it), each segment coloured by the
//! event at its end or by the path's own colour, wider and more opaque the more the path weighs, with a legend.

use super::canvas::{event_colour, Canvas, EVENT_COLOURS};
use crate::cli::PathColour;
use anyhow::{Context, Result};
use glam::{Vec2, Vec3};
use photonfarm::color::luminance;
use photonfarm::ray_map::{Events, PathKind, RecordedPath};
use photonfarm::scene::Scene;
use std::path::Path;

/// The overlay is enlarged to about this width (by a whole factor, at most `MAX_SCALE`), so that lines and the
/// legend's text are legible on small images.
const TARGET_WIDTH: usize = 720;
const MAX_SCALE: usize = 8;
/// Brightness of the preview under the paths.
const BACKGROUND_DIM: f32 = 0.7;
/// Line width (pixels of the preview) and opacity of the lightest and the heaviest drawn path.
const WIDTH: (f32, f32) = (0.5, 1.6);
const ALPHA: (f32, f32) = (0.18, 0.9);

/// How the overlay draws a selection.
#[derive(Clone, Copy, Debug)]
pub struct OverlayStyle {
    pub colour: PathColour,
    /// Most paths drawn: the heaviest of the selection.
    pub max_paths: usize,
}

/// What an overlay drew.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Drawn {
    pub paths: usize,
    pub scale: usize,
}

/// Each path's weight relative to the heaviest of its kind, in (0, 1] (1 for a kind whose paths weigh nothing):
/// a camera path's weight (its contribution to its pixel) and a light path's (its flux) are not comparable.
pub fn relative_weights(paths: &[RecordedPath]) -> Vec<f32> {
    let weight = |p: &RecordedPath| luminance(Vec3::from_array(p.weight)).abs();
    let max = |kind| paths.iter().filter(|p| p.kind == kind).map(weight).filter(|w| w.is_finite()).fold(0.0, f32::max);
    let (camera, light) = (max(PathKind::Camera), max(PathKind::Light));
    paths
        .iter()
        .map(|p| {
            let m = if p.kind == PathKind::Camera { camera } else { light };
            let w = weight(p);
            if m > 0.0 && w.is_finite() {
                (w / m).clamp(1e-6, 1.0)
            } else {
                1.0
            }
        })
        .collect()
}

/// The indices of the `max` heaviest paths (by `relative_weights`), lightest first so that the heavy ones are
/// drawn on top; ties keep the selection's order.
pub fn heaviest(weights: &[f32], max: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
    order.truncate(max);
    order.reverse();
    order
}

/// A path's own colour: its wavelength's, or its weight's hue; grey for a path of no weight.
fn natural_colour(p: &RecordedPath) -> [f32; 3] {
    let c = if p.wavelength_nm > 0.0 {
        photonfarm::spectrum::rgb_matching(p.wavelength_nm).max(Vec3::ZERO).to_array()
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

/// The points of a path on the image (pixels of the preview) with the events of the segment that ends at each,
/// the origin first (its events unused). A camera path starts at its pixel; a light path that registered on
/// the sensor ends its segment there at the pixel it registered in. Inside a sensor camera's lens the
/// first-order projection means nothing: vertices on its glass are not drawn, and their events go to the next
/// drawn segment, so that a path reflected inside the lens is drawn in the reflection's colour. A vertex
/// behind the camera is None, which breaks the line.
pub fn image_points(scene: &Scene, path: &RecordedPath, world: &[Vec3]) -> Vec<(Option<Vec2>, Events)> {
    let cam = &scene.camera;
    let sensor = matches!(cam.lens, photonfarm::camera::Lens::Sensor { .. });
    let in_lens = |object: u16| {
        sensor
            && scene.objects.get(object as usize).is_some_and(|o| scene.materials[o.material as usize].is_dielectric())
    };
    let pixel_centre = |pixel: u32| {
        (pixel < cam.width * cam.height)
            .then(|| Vec2::new((pixel % cam.width) as f32 + 0.5, (pixel / cam.width) as f32 + 0.5))
    };
    let mut out = Vec::with_capacity(path.vertices.len());
    let mut pending = Events::default();
    for (k, (q, v)) in world.iter().zip(&path.vertices).enumerate() {
        pending |= v.events;
        let point = if k == 0 && path.kind == PathKind::Camera {
            pixel_centre(path.source)
        } else if k > 0 && path.kind == PathKind::Light && v.events.contains(Events::SENSOR) {
            pixel_centre(v.primitive)
        } else if in_lens(v.object) {
            continue;
        } else {
            cam.project(*q)
        };
        out.push((point, pending));
        pending = Events::default();
    }
    out
}

/// Draws the heaviest `style.max_paths` of `paths` (with their world points `polylines`) over the preview at
/// `preview` (black where there is none) and writes the PNG with its legend.
pub fn write_overlay(
    png: &Path,
    preview: &Path,
    scene: &Scene,
    paths: &[RecordedPath],
    polylines: &[Vec<Vec3>],
    style: OverlayStyle,
) -> Result<Drawn> {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let scale = TARGET_WIDTH.div_ceil(w.max(1)).clamp(1, MAX_SCALE);
    let background = read_rgb8(preview, w, h).unwrap_or_else(|e| {
        tracing::warn!("the overlay is drawn on black: {e}");
        vec![0; w * h * 3]
    });
    let mut canvas = Canvas::from_background(&background, w, h, scale, BACKGROUND_DIM);
    let weights = relative_weights(paths);
    let drawn = heaviest(&weights, style.max_paths);
    let mut used = [false; EVENT_COLOURS.len() + 1];
    let s = scale as f32;
    let sensor_camera = matches!(cam.lens, photonfarm::camera::Lens::Sensor { .. });
    // Reflections are drawn last, over everything else: they are what a selection of ghosts is about.
    for reflections in [false, true] {
        for &i in &drawn {
            let (p, r) = (&paths[i], weights[i].sqrt());
            let (width, alpha) = (s * (WIDTH.0 + (WIDTH.1 - WIDTH.0) * r), ALPHA.0 + (ALPHA.1 - ALPHA.0) * r);
            let natural = natural_colour(p);
            for pair in image_points(scene, p, &polylines[i]).windows(2) {
                let ((Some(a), _), (Some(b), events)) = (pair[0], pair[1]) else { continue };
                if events.contains(Events::REFLECT) != reflections {
                    continue;
                }
                let (colour, index) = match style.colour {
                    PathColour::Natural => (natural, None),
                    PathColour::Event => event_colour(events),
                };
                if style.colour == PathColour::Event {
                    used[index.unwrap_or(EVENT_COLOURS.len())] = true;
                }
                if p.kind == PathKind::Light && events.contains(Events::SENSOR) {
                    // A light path that registered on the sensor: where it landed is what the image shows, a dot,
                    // so that a ghost's footprint shows. Behind a lens the line to it would stand for its way
                    // through the lens from a point the first-order projection misplaces: it is left out.
                    if !sensor_camera {
                        canvas.segment(a * s, b * s, 0.6 * width, colour, 0.3 * alpha);
                    }
                    canvas.dot(b * s, width.max(s), colour, alpha);
                } else {
                    canvas.segment(a * s, b * s, width, colour, alpha);
                }
            }
        }
    }
    let landed = drawn.iter().any(|&i| {
        paths[i].kind == PathKind::Light && paths[i].vertices[1..].iter().any(|v| v.events.contains(Events::SENSOR))
    });
    let caption = format!(
        "{} of {} selected paths, the heaviest; width and opacity by weight{}{}",
        drawn.len(),
        paths.len(),
        if style.colour == PathColour::Natural { "; colour: wavelength or weight" } else { "" },
        if landed { "; dots: light landed on the sensor" } else { "" }
    );
    let legend: Vec<([f32; 3], String)> = match style.colour {
        PathColour::Natural => Vec::new(),
        PathColour::Event => EVENT_COLOURS
            .iter()
            .enumerate()
            .filter(|(i, _)| used[*i])
            .map(|(_, (_, name, c))| (*c, name.to_string()))
            .chain(used[EVENT_COLOURS.len()].then(|| (super::canvas::OTHER_COLOUR, "path end".to_string())))
            .collect(),
    };
    canvas.write_png(png, &caption, &legend)?;
    Ok(Drawn { paths: drawn.len(), scale })
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

#[cfg(test)]
mod tests {
    use super::*;

    fn path(kind: PathKind, weight: f32) -> RecordedPath {
        let mut p = RecordedPath::new(kind, 1, 0, 0);
        p.weight = [weight; 3];
        p
    }

    #[test]
    fn the_heaviest_paths_of_each_kind_are_drawn_lightest_first() {
        // A light path's flux dwarfs a camera path's contribution: each is measured against its own kind.
        let paths = [path(PathKind::Camera, 0.01), path(PathKind::Light, 50.0), path(PathKind::Camera, 0.02)];
        let paths: Vec<RecordedPath> = paths.into_iter().chain([path(PathKind::Light, 5.0)]).collect();
        let w = relative_weights(&paths);
        assert_eq!(w, [0.5, 1.0, 1.0, 0.1]);
        assert_eq!(heaviest(&w, 3), [0, 2, 1]);
        assert_eq!(heaviest(&w, 10), [3, 0, 2, 1]);
        assert!(heaviest(&w, 0).is_empty());
        // Paths of no weight are all drawn alike.
        assert_eq!(relative_weights(&[path(PathKind::Camera, 0.0)]), [1.0]);
    }
}
