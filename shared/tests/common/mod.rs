//! Helpers shared by the renderer's integration tests: scenes from TOML text, per-phase statistics and random
//! rays.
#![allow(dead_code, clippy::needless_range_loop)]

use glam::Vec3;
use photonfarm::accumulation::Accumulator;
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::{Engine, Method, RenderSettings};
use photonfarm::scene::Scene;
use rand_core::RngCore;
use rand_pcg::Pcg32;
use std::path::Path;

/// A scene from TOML text whose meshes resolve against the repository's scenes/ folder.
pub fn scene(toml: &str) -> Scene {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    Scene::from_toml(toml, Path::new("test.toml"), &base).unwrap_or_else(|e| panic!("test scene is invalid: {e}"))
}

/// A shipped scene by file name, e.g. "cornell.toml".
pub fn shipped(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
    Scene::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// The shipped scene `name` rendered at `width` × `height` pixels (its `width` and `height` lines rewritten).
pub fn shipped_at(name: &str, width: u32, height: u32) -> Scene {
    shipped_edited(name, width, height, str::to_string)
}

/// `shipped_at` of the scene's text after `edit`.
pub fn shipped_edited(name: &str, width: u32, height: u32, edit: impl FnOnce(&str) -> String) -> Scene {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let text = edit(&std::fs::read_to_string(dir.join(name)).unwrap());
    let mut resized = String::new();
    for line in text.lines() {
        match line.split('=').next().map(str::trim) {
            Some("width") => resized.push_str(&format!("width = {width}\n")),
            Some("height") => resized.push_str(&format!("height = {height}\n")),
            _ => {
                resized.push_str(line);
                resized.push('\n');
            }
        }
    }
    Scene::from_toml(&resized, &dir.join(name), &dir).unwrap_or_else(|e| panic!("{e}"))
}

/// Settings of the scene with the given method and seed.
pub fn settings(scene: &Scene, method: Method, seed: u64) -> RenderSettings {
    RenderSettings::for_scene(scene, method, seed)
}

/// Mean and standard error of samples.
pub fn mean_sem(samples: &[f64]) -> (f64, f64) {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    let var = samples.iter().map(|s| (s - mean) * (s - mean)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Runs `phases` phases and returns, per phase, the mean luminance of `layer` (None: the total) over the
/// pixels `region` selects. Phase values of one phase share light paths, so the region's SEM must come from
/// these per-phase means, not from per-pixel SEMs.
pub fn region_phase_means(
    engine: &mut Engine,
    phases: usize,
    layer: Option<Layer>,
    region: &dyn Fn(u32, u32) -> bool,
) -> Vec<f64> {
    let w = engine.sums().width;
    let h = engine.sums().height;
    let pixels: Vec<usize> = (0..w * h).filter(|&i| region(i % w, i / w)).map(|i| i as usize).collect();
    regions_phase_means(engine, phases, &[(&pixels, layer)]).remove(0)
}

/// Mean luminance of `layer` (None: the total) summed over phases, averaged over `pixels`.
pub fn region_sum(engine: &Engine, pixels: &[usize], layer: Option<Layer>) -> f64 {
    assert!(!pixels.is_empty(), "empty test region");
    pixels
        .iter()
        .map(|&p| {
            let px = &engine.sums().pixels[p];
            let rgb = match layer {
                Some(l) => px.sum[l as usize],
                None => {
                    let mut t = [0.0; 3];
                    for l in 0..4 {
                        for c in 0..3 {
                            t[c] += px.sum[l][c];
                        }
                    }
                    t
                }
            };
            photonfarm::color::luminance_f64(rgb)
        })
        .sum::<f64>()
        / pixels.len() as f64
}

/// [`region_phase_means`] for several regions (pixel indices and layer) over the same phases: one list of
/// per-phase means per region.
pub fn regions_phase_means(engine: &mut Engine, phases: usize, regions: &[(&[usize], Option<Layer>)]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::with_capacity(phases); regions.len()];
    let mut before: Vec<f64> = regions.iter().map(|(p, l)| region_sum(engine, p, *l)).collect();
    for _ in 0..phases {
        engine.run_phase();
        for (k, (p, l)) in regions.iter().enumerate() {
            let after = region_sum(engine, p, *l);
            out[k].push(after - before[k]);
            before[k] = after;
        }
    }
    out
}

/// Uniform in [0, 1) from 24 random bits.
pub fn uniform(rng: &mut Pcg32) -> f32 {
    (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32
}

/// A uniform direction on the unit sphere.
pub fn direction(rng: &mut Pcg32) -> Vec3 {
    let z = 1.0 - 2.0 * uniform(rng);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * uniform(rng);
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The mean over pixels of z² = (a − b)² / (SEM_a² + SEM_b²) of the total luminance with eq. 7's per-pixel SEMs,
/// and the number of pixels with an error to divide by.
pub fn mean_z2(a: &Accumulator, b: &Accumulator) -> (f64, f64) {
    let z2: Vec<f64> = (0..a.pixels.len())
        .filter(|&i| a.sem2(i) + b.sem2(i) > 0.0)
        .map(|i| {
            let d = luminance_f64(a.mean_total(i)) - luminance_f64(b.mean_total(i));
            d * d / (a.sem2(i) + b.sem2(i))
        })
        .collect();
    let n = z2.len() as f64;
    (z2.iter().sum::<f64>() / n, n)
}
