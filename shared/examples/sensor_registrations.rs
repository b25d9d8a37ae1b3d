//! What light paths bring to a sensor camera's pixels (docs/estimator.md, "The ghost layer"): traces a phase's
//! worth of light paths per phase at one light path per pixel, as a run's phases would, and counts the ghost
//! chains and lens images they register, the pixels the ghosts land on, and how the ghost values spread.
//!
//! `cargo run --release -p photonfarm --example sensor_registrations -- SCENE.toml [PHASES]`

use photonfarm::color::{luminance_f64, Rgb};
use photonfarm::pbpm::{trace_light_path, ForwardStats, LightEvent, LightSettings};
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
    if !photonfarm::ghost::sensor_ghosts(&scene) {
        return Err(format!("{}: no light registers on this scene's sensor", path.display()).into());
    }
    let settings = RenderSettings::for_scene(&scene, Method::Pbpm, 1);
    let light = LightSettings { max_depth: scene.render.max_depth, sensor: true, vertices: false };
    let pixels = scene.camera.pixel_count();
    let mut stats = ForwardStats::default();
    let (mut ghost_pixels, mut ghost_values, mut image_registrations) = (vec![0u32; pixels], Vec::new(), 0u64);
    for phase in 0..phases {
        let spectrum = settings.phase_spectrum(&scene, phase);
        for index in 0..pixels as u64 {
            let mut sampler = Sampler::light(settings.seed, phase, index);
            trace_light_path(&scene, light, &spectrum, index, &mut sampler, &mut stats, &mut |e| {
                let LightEvent::Sensor(hit) = e else { return };
                if !hit.ghost {
                    image_registrations += 1;
                    return;
                }
                let v = join(Rgb::ONE, 0, hit.value, hit.spectrum, &spectrum);
                ghost_values.push(luminance_f64([v.x as f64, v.y as f64, v.z as f64]));
                ghost_pixels[hit.pixel as usize] += 1;
            });
        }
    }
    let paths = phases * pixels as u64;
    println!("{phases} phases, {paths} light paths, {} rays", stats.rays);
    println!("lens-image registrations: {image_registrations}");
    println!(
        "ghost registrations: {} ({:.3}% of the light paths), on {} pixels",
        ghost_values.len(),
        100.0 * ghost_values.len() as f64 / paths as f64,
        ghost_pixels.iter().filter(|&&n| n > 0).count()
    );
    if !ghost_values.is_empty() {
        let mean = ghost_values.iter().sum::<f64>() / ghost_values.len() as f64;
        let max = ghost_values.iter().copied().fold(0.0, f64::max);
        println!("ghost values: mean {mean:.4e}, largest {max:.4e} ({:.1}× the mean)", max / mean);
    }
    Ok(())
}
