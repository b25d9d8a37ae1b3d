//! On the shipped glossy scenes (scenes/materials.toml and scenes/glossy-room.toml, at a small size), PBPM
//! converges per pixel to the path tracer: every glossy vertex is counted once, by the camera side where its
//! lobe passes and by the gather where it is stored (docs/estimator.md, "Glossy surfaces").

use crate::common::{mean_z2, settings, shipped_at};
use photonfarm::accumulation::Accumulator;
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;

/// Runs PBPM and the path tracer side by side, single-threaded, and returns their sums.
fn render_both(scene: &Scene, pbpm_phases: usize, path_phases: usize) -> (Accumulator, Accumulator) {
    let render = |method, seed, phases| {
        let mut engine = Engine::new(scene, settings(scene, method, seed));
        for _ in 0..phases {
            engine.run_phase();
        }
        engine.sums().clone()
    };
    std::thread::scope(|s| {
        let pbpm = s.spawn(|| render(Method::Pbpm, 11, pbpm_phases));
        let path = render(Method::Path, 12, path_phases);
        (pbpm.join().unwrap(), path)
    })
}

/// Asserts that the two images agree per pixel (mean z² = (a − b)² / (SEM_a² + SEM_b²) within 4 standard
/// deviations of 1, z² having variance 2) and over the image, layer by layer.
fn assert_converge(name: &str, pbpm: &Accumulator, path: &Accumulator) {
    let pixels = pbpm.pixels.len();
    let (mean_z2, n) = mean_z2(pbpm, path);
    let bound = 1.0 + 4.0 * (2.0 / n).sqrt();
    eprintln!("{name}: mean z² {mean_z2:.3} over {n} pixels (bound {bound:.3})");
    assert!(n > 0.9 * pixels as f64, "{name}: only {n} of {pixels} pixels have light");
    assert!(mean_z2 < bound, "{name}: mean z² {mean_z2:.3} of PBPM against the path tracer exceeds {bound:.3}");

    let image = |s: &Accumulator, layer: Option<Layer>| -> (f64, f64) {
        let values: Vec<f64> =
            (0..pixels).map(|i| luminance_f64(layer.map_or_else(|| s.mean_total(i), |l| s.mean(i, l)))).collect();
        let sem2: f64 = (0..pixels).map(|i| s.sem2(i)).sum();
        (values.iter().sum::<f64>(), sem2.sqrt())
    };
    let (a, b) = (image(pbpm, None), image(path, None));
    eprintln!("{name}: image sum PBPM {:.3} ± {:.3}, path {:.3} ± {:.3}", a.0, a.1, b.0, b.1);
    assert!((a.0 - b.0).abs() < 4.0 * (a.1 * a.1 + b.1 * b.1).sqrt(), "{name}: the image sums differ");
    // Layers the camera side estimates alone are unbiased and agree closely; the rest is split differently
    // between the methods, so only their sum (checked above) must agree.
    for layer in [Layer::VisibleLights, Layer::Direct] {
        let (la, lb) = (image(pbpm, Some(layer)).0, image(path, Some(layer)).0);
        eprintln!("{name}: {} PBPM {la:.3} path {lb:.3}", layer.name());
        assert!((la - lb).abs() <= 0.02 * lb.max(1e-9) + 1e-9, "{name}: layer {} PBPM {la} vs path {lb}", layer.name());
    }
}

#[test]
fn pbpm_converges_per_pixel_to_the_path_tracer_on_the_material_spheres() {
    let scene = shipped_at("materials.toml", 32, 32);
    let (pbpm, path) = render_both(&scene, 1000, 4000);
    assert_converge("materials", &pbpm, &path);
}

#[test]
fn pbpm_converges_per_pixel_to_the_path_tracer_in_the_glossy_room() {
    let scene = shipped_at("glossy-room.toml", 32, 24);
    let (pbpm, path) = render_both(&scene, 1000, 4000);
    assert_converge("glossy room", &pbpm, &path);
}
