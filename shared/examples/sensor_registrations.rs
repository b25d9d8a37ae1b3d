//! What light paths and their ghost paths bring to a sensor camera's pixels (docs/estimator.md, "The ghost
//! layer"): traces a phase's worth of light paths per phase at one light path per pixel, as a run's phases
//! would, with the scene's ghost paths, and counts the ghost chains and lens images they register, the pixels
//! the ghosts land on, how the ghost values spread, and the rays each kind of path cost.
//!
//! `cargo run --release -p photonfarm --example sensor_registrations -- SCENE.toml [PHASES]`

use photonfarm::color::{luminance_f64, Rgb};
use photonfarm::pbpm::{trace_ghost_paths, trace_light_path, ForwardStats, LightEvent, LightSettings};
use photonfarm::ray_map::Unrecorded;
use photonfarm::render::{Method, RenderSettings};
use photonfarm::sampling::Sampler;
use photonfarm::scene::Scene;
use photonfarm::spectrum::join;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args_os().skip(1);
    let path = PathBuf::from(args.next().ok_or("usage: sensor_registrations SCENE.toml [PHASES]")?);
    let phases: u64 = match args.next() {
        Some(a) => a.to_str().and_then(|a| a.parse().ok()).ok_or("PHASES: a whole number")?,
        None => 40,
    };
    let scene = Scene::load(&path)?;
    if !photonfarm::scene::ghost::sensor_ghosts(&scene) {
        return Err(format!("{}: no light registers on this scene's sensor", path.display()).into());
    }
    if let Some(table) = photonfarm::pbpm::ghost_pairs(&scene) {
        // The pairs the pilot found ghosts through: those above the share every pair gets.
        let pairs: Vec<_> = table.iter().collect();
        let even = photonfarm::pbpm::ghost_paths::EVEN_SHARE / pairs.len() as f32;
        let found: Vec<_> = pairs.iter().filter(|(_, p)| *p > 1.5 * even).collect();
        let share: f32 = found.iter().map(|(_, p)| p).sum();
        println!(
            "ghost pairs: {}, of which {} take {:.0}% of the ghost paths",
            pairs.len(),
            found.len(),
            100.0 * share
        );
    }
    let settings = RenderSettings::for_scene(&scene, Method::Pbpm, 1);
    let ghost_paths = photonfarm::scene::ghost::ghost_paths(&scene);
    let light = LightSettings { max_depth: scene.render.max_depth, sensor: true, vertices: false, ghost_paths };
    let pixels = scene.camera.pixel_count();
    let (mut stats, mut ghost_stats) = (ForwardStats::default(), ForwardStats::default());
    let (mut ghost_pixels, mut ghost_values, mut image_registrations) = (vec![0u32; pixels], Vec::new(), 0u64);
    // Per pixel, the sum and the sum of squares of its phases' ghost luminance, for the error of the mean.
    let (mut pixel_sum, mut pixel_sq) = (vec![0.0f64; pixels], vec![0.0f64; pixels]);
    // The ghost light over the whole image per phase, for its mean and standard error.
    let mut totals = Vec::new();
    for phase in 0..phases {
        let spectrum = settings.phase_spectrum(&scene, phase);
        let mut this_phase = vec![0.0f64; pixels];
        for index in 0..pixels as u64 {
            let mut sampler = Sampler::light(settings.seed, phase, index);
            let mut visit = |e: &LightEvent| {
                let LightEvent::Sensor(hit) = e else { return };
                if !hit.ghost {
                    image_registrations += 1;
                    return;
                }
                let v = join(Rgb::ONE, 0, hit.value, hit.spectrum, &spectrum);
                let y = luminance_f64([v.x as f64, v.y as f64, v.z as f64]);
                ghost_values.push(y);
                ghost_pixels[hit.pixel as usize] += 1;
                this_phase[hit.pixel as usize] += y / pixels as f64;
            };
            trace_light_path(&scene, light, &spectrum, index, &mut sampler, &mut stats, &mut visit, &mut Unrecorded);
            trace_ghost_paths(
                &scene,
                light,
                &spectrum,
                index,
                settings.seed,
                phase,
                &mut ghost_stats,
                &mut visit,
                None,
            );
        }
        totals.push(this_phase.iter().sum::<f64>());
        for (p, v) in this_phase.into_iter().enumerate() {
            pixel_sum[p] += v;
            pixel_sq[p] += v * v;
        }
    }
    let paths = phases * pixels as u64;
    // The error of the light paths' ghost layer after these phases, over all pixels: sqrt(Σ SEM² / Σ mean²).
    let n = phases as f64;
    let (mut sem2, mut mean2) = (0.0, 0.0);
    let mut by_pixel = Vec::new();
    for (s, q) in pixel_sum.iter().zip(&pixel_sq) {
        let mean = s / n;
        let e = (q / n - mean * mean).max(0.0) / (n - 1.0).max(1.0);
        sem2 += e;
        by_pixel.push(e);
        mean2 += mean * mean;
    }
    by_pixel.sort_by(|a, b| b.total_cmp(a));
    let total = totals.iter().sum::<f64>() / n;
    let spread = totals.iter().map(|t| (t - total).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    println!("ghost light over the image: {total:.5e} ± {:.1e} (one standard error)", (spread / n).sqrt());
    let top: f64 = by_pixel.iter().take(100).sum();
    println!("share of the squared error in the 100 worst pixels: {:.1}%", 100.0 * top / sem2);
    println!("{phases} phases, {paths} light paths, {} rays", stats.rays);
    println!("{} ghost paths ({ghost_paths} per light path), {} rays", paths * ghost_paths as u64, ghost_stats.rays);
    println!("lens-image registrations: {image_registrations}");
    println!(
        "error of the light paths' ghost layer after {phases} phases: {:.1}% (Σ SEM² {sem2:.4e}, Σ mean² {mean2:.4e})",
        100.0 * (sem2 / mean2).sqrt()
    );
    println!(
        "ghost registrations: {} ({:.3} per light path), on {} pixels",
        ghost_values.len(),
        ghost_values.len() as f64 / paths as f64,
        ghost_pixels.iter().filter(|&&n| n > 0).count()
    );
    if !ghost_values.is_empty() {
        let mean = ghost_values.iter().sum::<f64>() / ghost_values.len() as f64;
        let max = ghost_values.iter().copied().fold(0.0, f64::max);
        println!("ghost values: mean {mean:.4e}, largest {max:.4e} ({:.1}× the mean)", max / mean);
        // What the registrations are worth as equal-valued ones: (Σv)² / Σv².
        let sum_sq = ghost_values.iter().map(|v| v * v).sum::<f64>();
        let effective = (mean * ghost_values.len() as f64).powi(2) / sum_sq;
        println!(
            "effective ghost registrations: {effective:.0} ({:.4} per light path, {:.3} per thousand rays)",
            effective / paths as f64,
            1e3 * effective / (stats.rays + ghost_stats.rays) as f64
        );
    }
    Ok(())
}
