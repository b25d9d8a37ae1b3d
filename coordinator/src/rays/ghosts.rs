//! `coordinator rays ghosts`: ranks the pairs of lens surfaces at which ghost paths took their first two
//! reflections (camera paths, and light paths whose ghost chain registered on the sensor), by their share of the ghost light the recorded paths carry, with each pair's footprint on the
//! image, and compares the recorded ghost light with the render's ghost layer.

use super::render_folder;
use crate::cli::RaysGhostsArgs;
use anyhow::{bail, Context, Result};
use photonfarm::color::luminance;
use photonfarm::ray_map::reader::open_streams;
use photonfarm::ray_map::{Events, PathKind};
use photonfarm::render::Method;
use photonfarm::scene::Scene;
use rayon::prelude::*;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// The two surfaces of a ghost: the object indices of its first and second dielectric reflections (the second
/// None for a path that reflected once).
type Pair = (u16, Option<u16>);

/// What one pair carries.
#[derive(Clone, Default)]
struct PairTotals {
    energy: f64,
    paths: u64,
    /// Luminance per pixel of the image.
    footprint: Vec<f32>,
}

/// The ghost pair of a path and the pixel its ghost light lands on, or None for a path that carries no ghost
/// light; `vertices` are the path's (object, events, primitive), the origin first. A camera path's pair is its
/// dielectric reflections before its first diffuse vertex (the ghost layer's rule); a light path's, one that
/// registered on the sensor (a ghost chain the light side owns), is its dielectric reflections before the sensor
/// taken from the sensor's side, so that both name a ghost alike.
fn ghost_pair(
    kind: PathKind,
    source: u32,
    vertices: impl Iterator<Item = (u16, Events, u32)>,
    dielectric: &[bool],
) -> Option<(Pair, u32)> {
    let is_reflection = |object: u16, events: Events| {
        events.contains(Events::REFLECT) && dielectric.get(object as usize) == Some(&true)
    };
    match kind {
        PathKind::Camera => {
            let mut reflections = vertices
                .take_while(|v| !v.1.contains(Events::DIFFUSE))
                .filter(|v| is_reflection(v.0, v.1))
                .map(|v| v.0);
            let first = reflections.next()?;
            Some(((first, reflections.next()), source))
        }
        PathKind::Light => {
            // The last two reflections before the first sensor vertex after the origin, the later one first.
            let (mut last, mut before) = (None, None);
            for (i, (object, events, primitive)) in vertices.enumerate() {
                if i > 0 && events.contains(Events::SENSOR) {
                    return Some(((last?, before), primitive));
                }
                if is_reflection(object, events) {
                    (before, last) = (last, Some(object));
                }
            }
            None
        }
    }
}

/// Runs `rays ghosts`.
pub fn ghosts(args: RaysGhostsArgs) -> Result<()> {
    let mut streams = open_streams(&args.map)?;
    let header = streams[0].header().clone();
    let scene = Scene::load(Path::new(&header.scene))
        .with_context(|| format!("the map's scene {} is needed for its lens surfaces", header.scene))?;
    let dielectric: Vec<bool> =
        scene.objects.iter().map(|o| scene.materials[o.material as usize].is_dielectric()).collect();
    if !dielectric.iter().any(|&d| d) {
        bail!("{} has no dielectric surface, so no ghosts", header.scene);
    }
    let (w, h) = (header.width as usize, header.height as usize);
    let mut pairs: HashMap<Pair, PairTotals> = HashMap::new();
    let mut total = 0.0f64;
    let mut portions = Vec::new();
    for s in &mut streams {
        // A mapped stream's portions are ranges of its mapping: holding them all costs no memory.
        while let Some(p) = s.next_portion()? {
            portions.push(p);
        }
        if let Some(bytes) = s.truncated_bytes() {
            tracing::warn!("{} ends inside a portion; its last {bytes} bytes were left", s.path().display());
        }
    }
    // A light path's weight is what it registered before the division by its phase's light paths; the record
    // of the render says how many each phase traced, once a light path is found that needs it.
    let light_paths_per_phase = std::sync::OnceLock::new();
    let pixels = w * h;
    // Paths are read in place, as `rays select` reads them: only a ghost's pair, weight and pixel are taken.
    let per_portion: Vec<Vec<(Pair, f64, u32)>> = portions
        .par_iter()
        .map(|p| -> Result<_> {
            let found = p.with_paths(|views| {
                let mut found = Vec::new();
                for view in views {
                    let view = view?;
                    let Some((pair, pixel)) =
                        ghost_pair(view.kind, view.source, view.objects_events_primitives(), &dielectric)
                    else {
                        continue;
                    };
                    let energy = luminance(glam::Vec3::from_array(view.weight)) as f64;
                    found.push((pair, energy, pixel, view.kind, view.phase));
                }
                Ok(found)
            })?;
            found
                .into_iter()
                .map(|(pair, energy, pixel, kind, phase)| match kind {
                    PathKind::Camera => Ok((pair, energy, pixel)),
                    PathKind::Light => {
                        match light_paths_per_phase
                            .get_or_init(|| light_paths_per_phase_of(&args.map, pixels, &header.method))
                        {
                            Ok(n) => Ok((pair, energy / n.of(phase), pixel)),
                            Err(e) => Err(anyhow::anyhow!("{e}")),
                        }
                    }
                })
                .collect()
        })
        .collect::<Result<_>>()?;
    for (pair, energy, pixel) in per_portion.into_iter().flatten() {
        let t = pairs.entry(pair).or_insert_with(|| PairTotals { footprint: vec![0.0; w * h], ..Default::default() });
        t.energy += energy;
        t.paths += 1;
        if let Some(f) = t.footprint.get_mut(pixel as usize) {
            *f += energy as f32;
        }
        total += energy;
    }
    let mut ranked: Vec<(Pair, PairTotals)> = pairs.into_iter().collect();
    // Pairs of equal light (none, often) by their surfaces, so that the ranking does not follow the hash order.
    ranked.sort_by(|a, b| b.1.energy.total_cmp(&a.1.energy).then(a.0.cmp(&b.0)));

    let out = args.out.clone().unwrap_or_else(|| render_folder(&args.map).join("ghosts"));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let name = |o: u16| header.objects.get(o as usize).cloned().unwrap_or_else(|| format!("object {o}"));
    let mut table = String::new();
    let _ = writeln!(table, "{:>4}  {:<14} {:<14} {:>9} {:>8}  footprint", "rank", "first", "second", "share", "paths");
    let mut json = Vec::new();
    for (rank, ((a, b), t)) in ranked.iter().take(args.top).enumerate() {
        let second = b.map_or_else(|| "(once)".to_string(), name);
        let png = out.join(format!("pair-{}.png", rank + 1));
        write_footprint(&png, &t.footprint, w, h)?;
        let share = t.energy / total.max(f64::MIN_POSITIVE);
        let _ = writeln!(
            table,
            "{:>4}  {:<14} {:<14} {:>8.2}% {:>8}  {}",
            rank + 1,
            name(*a),
            second,
            100.0 * share,
            t.paths,
            png.display()
        );
        json.push(serde_json::json!({
            "rank": rank + 1, "first": name(*a), "second": b.map(name), "share": share,
            "paths": t.paths, "energy": t.energy, "footprint": png.display().to_string(),
        }));
    }
    say!("{}", table.trim_end_matches('\n'));
    // With tile masks a group's phase takes the sensor registrations of its own pixels only, while the map holds
    // every registration of the paths it recorded: the recorded light then overstates the layer's, and only the
    // shares are comparable (the masks are dealt at random, whatever the ghost).
    let masked = header.method.parse::<Method>().is_ok_and(|m| m.layout().masks);
    let layer = if masked {
        Err(anyhow::anyhow!(
            "--method {} renders tile masks, whose groups register light on their own pixels only, while the map \
             holds every registration; render with a method without masks (pbpm, path, sync, async, combination) \
             to compare",
            header.method
        ))
    } else {
        ghost_layer_total(&args.map)
    };
    match &layer {
        Ok((image_total, phases)) => say!(
            "recorded ghost light / fraction: {:.4e}; the ghost layer of image.exr over its pixels' phases (about \
             {phases} each): {:.4e} ({:.1}%)",
            total / header.fraction,
            image_total,
            100.0 * total / header.fraction / image_total.max(f64::MIN_POSITIVE)
        ),
        Err(e) => tracing::warn!("no comparison with the ghost layer: {e:#}"),
    }
    std::fs::write(out.join("ghosts.txt"), &table).context("cannot write ghosts.txt")?;
    let report = serde_json::json!({
        "scene": header.scene, "ghost_light": total, "fraction": header.fraction, "pairs": json,
        "ghost_layer": layer.ok().map(|(t, p)| serde_json::json!({"total": t, "phases": p})),
    });
    std::fs::write(out.join("ghosts.json"), serde_json::to_string_pretty(&report).expect("plain JSON"))
        .context("cannot write ghosts.json")?;
    say!("wrote {}", out.display());
    Ok(())
}

/// The render's ghost layer summed over pixels and each pixel's phases (luminance): what the recorded ghost
/// light, over the recorded fraction, estimates. Returns it with the image's mean phases per pixel.
fn ghost_layer_total(map: &Path) -> Result<(f64, u64)> {
    let dir = render_folder(map);
    let exr = dir.join("image.exr");
    let layers = photonfarm::image_io::exr_file::read_exr(&exr)?;
    let ghost = photonfarm::image_io::exr_file::find_layer(&layers, &exr, photonfarm::ghost::GHOST_LAYER)?;
    // Each pixel is its phases' mean: in a parallel or distributed run the pixels have different phase counts.
    let phases = photonfarm::image_io::exr_file::find_layer(&layers, &exr, photonfarm::render::images::PHASES_LAYER)?;
    let sum: f64 = ghost
        .rgb
        .iter()
        .zip(&phases.rgb)
        .map(|(g, n)| luminance(glam::Vec3::from_array(*g)) as f64 * n[0] as f64)
        .sum();
    let mean_phases = phases.rgb.iter().map(|n| n[0] as f64).sum::<f64>() / phases.rgb.len().max(1) as f64;
    Ok((sum, mean_phases.round() as u64))
}

/// The light paths each phase of a render traced: what a light path's registered value is divided by in the
/// image.
struct LightPathsPerPhase {
    /// Per phase (index = phase − 1), from the record's history, where the run chose its light paths per
    /// pixel phase by phase.
    by_phase: Vec<f64>,
    /// The run's mean, for phases the history does not name.
    mean: f64,
}

impl LightPathsPerPhase {
    fn of(&self, phase: u32) -> f64 {
        self.by_phase.get((phase as usize).wrapping_sub(1)).copied().unwrap_or(self.mean)
    }
}

/// The light paths each phase of the map's render counted, from its run.json: per phase for the single-threaded
/// methods, which render one phase per history step, and the run's mean for the others, whose group phases
/// overlap. A phase divides its light by the light paths counted against its map, which with shared maps
/// (two-level, three-level) include other groups' paths; a path registers on the sensor into the one map
/// whose mask holds its pixel, so that is the divisor of its recorded light too. Errors are kept as text so
/// that every thread can report the one error.
fn light_paths_per_phase_of(
    map: &Path,
    pixels: usize,
    method: &str,
) -> std::result::Result<LightPathsPerPhase, String> {
    let dir = render_folder(map);
    let read = || -> Result<LightPathsPerPhase> {
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("run.json"))
                .with_context(|| format!("no run.json in {}", dir.display()))?,
        )?;
        let phases = record["totals"]["phases"].as_u64().context("run.json has no totals.phases")?;
        // Records from before maps counted their paths have only the paths traced.
        let light_paths = record["totals"]["map_light_paths"]
            .as_u64()
            .or_else(|| record["totals"]["light_paths"].as_u64())
            .context("run.json has no totals.map_light_paths")?;
        if phases == 0 || light_paths == 0 {
            bail!("run.json records {light_paths} light paths over {phases} phases");
        }
        let mut by_phase = Vec::new();
        let one_phase_per_step = method == Method::Pbpm.name() || method == Method::Path.name();
        for step in record["history"].as_array().into_iter().flatten().take_while(|_| one_phase_per_step) {
            let (Some(phase), Some(l)) = (step["phase"].as_u64(), step["light_paths_per_pixel"].as_f64()) else {
                break;
            };
            if phase != by_phase.len() as u64 + 1 {
                break;
            }
            // As `RenderSettings::light_paths_per_phase`, in f32 as the engine held L.
            by_phase.push(((l as f32 as f64 * pixels as f64).round()).max(1.0));
        }
        Ok(LightPathsPerPhase { by_phase, mean: light_paths as f64 / phases as f64 })
    };
    read().map_err(|e| {
        format!("light paths reached the sensor, but their share needs the render's light paths per phase: {e:#}")
    })
}

/// A footprint as a grey PNG, the brightest pixel white.
fn write_footprint(path: &Path, footprint: &[f32], w: usize, h: usize) -> Result<()> {
    let max = footprint.iter().cloned().fold(0.0f32, f32::max);
    let grey: Vec<u8> =
        footprint.iter().map(|&v| if max > 0.0 { (255.0 * (v / max).sqrt()) as u8 } else { 0 }).collect();
    let file = std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(&grey)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::ray_map::format::{encode_path, path_views};
    use photonfarm::ray_map::{RecordedPath, Vertex};

    /// The pair as the decoded path states it, written from the rule's words rather than in one pass: the
    /// reflections before the first diffuse vertex (camera), or before the first sensor vertex after the
    /// origin, the latest first (light).
    fn decoded_pair(path: &RecordedPath, dielectric: &[bool]) -> Option<(Pair, u32)> {
        let is_reflection = |v: &&Vertex| {
            v.events.contains(Events::REFLECT) && dielectric.get(v.object as usize).copied().unwrap_or(false)
        };
        match path.kind {
            PathKind::Camera => {
                let before = path.vertices.iter().take_while(|v| !v.events.contains(Events::DIFFUSE));
                let reflections: Vec<u16> = before.filter(is_reflection).map(|v| v.object).collect();
                Some(((*reflections.first()?, reflections.get(1).copied()), path.source))
            }
            PathKind::Light => {
                let sensor = path.vertices.iter().skip(1).position(|v| v.events.contains(Events::SENSOR))? + 1;
                let reflections: Vec<u16> =
                    path.vertices[..sensor].iter().rev().filter(is_reflection).map(|v| v.object).collect();
                Some(((*reflections.first()?, reflections.get(1).copied()), path.vertices[sensor].primitive))
            }
        }
    }

    #[test]
    fn pairs_read_in_place_are_the_decoded_paths_pairs() {
        // Objects 0, 2 and 3 are dielectric; events drawn from reflect, diffuse and sensor so that every branch of
        // the rule (no reflection, one, two, more, a diffuse or sensor vertex before or after them) occurs.
        let dielectric = [true, false, true, true];
        let choices = [Events::REFLECT, Events::DIFFUSE, Events::SENSOR, Events::REFRACT, Events::default()];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: usize| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % n as u64) as usize
        };
        let mut paths = Vec::new();
        for i in 0..4000 {
            let kind = if i % 2 == 0 { PathKind::Camera } else { PathKind::Light };
            // A camera path's item is its pixel, which the map stores once for both.
            let (item, source) = if kind == PathKind::Camera { (i % 64, i % 64) } else { (i, i % 2) };
            let mut p = RecordedPath::new(kind, 1 + (i % 3) as u32, item as u32, source as u32);
            p.begin(glam::Vec3::ZERO, glam::Vec3::Y);
            for _ in 0..next(9) {
                let events = choices[next(choices.len())] | choices[next(choices.len())];
                let object = if next(8) == 0 { u16::MAX } else { next(4) as u16 };
                p.vertices.push(Vertex { point: [0.0; 3], normal: 0, object, primitive: next(1000) as u32, events });
            }
            paths.push(p);
        }
        let mut raw = Vec::new();
        for p in &paths {
            encode_path(p, &mut raw);
        }
        // Pairs found per kind, and of them pairs of two reflections.
        let mut found = [[0; 2]; 2];
        for (view, path) in path_views(&raw, paths.len()).zip(&paths) {
            let view = view.unwrap();
            let expected = decoded_pair(path, &dielectric);
            if let Some(((_, second), _)) = expected {
                found[path.kind as usize][second.is_some() as usize] += 1;
            }
            assert_eq!(ghost_pair(view.kind, view.source, view.objects_events_primitives(), &dielectric), expected);
        }
        assert!(found.iter().flatten().all(|&n| n >= 50), "too few pairs of some kind to compare: {found:?}");
    }
}
