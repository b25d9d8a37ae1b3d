//! On the shipped glossy scenes (scenes/materials.toml and scenes/glossy-room.toml, at a small size), PBPM
//! converges per pixel to the path tracer: every glossy vertex is counted once, by the camera side where its
//! lobe passes and by the gather where it is stored (docs/estimator.md, "Glossy surfaces"), also where the
//! stored lobe is a rough glass's transmission.

use crate::common::{mean_z2, settings, shipped_at, shipped_edited};
use photonfarm::accumulation::Accumulator;
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;

/// Runs PBPM and the path tracer side by side, single-threaded, and returns their sums.
fn render_both(scene: &Scene, pbpm_phases: usize, path_phases: usize) -> (Accumulator, Accumulator) {
    render_both_at_radius(scene, pbpm_phases, path_phases, None)
}

/// `render_both` with PBPM's photons at `radius_scale` pixel footprints instead of the scene's.
fn render_both_at_radius(
    scene: &Scene,
    pbpm_phases: usize,
    path_phases: usize,
    radius_scale: Option<f32>,
) -> (Accumulator, Accumulator) {
    let render = |method, seed, phases| {
        let mut s = settings(scene, method, seed);
        s.radius_scale = radius_scale.unwrap_or(s.radius_scale);
        let mut engine = Engine::new(scene, s);
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

#[test]
fn pbpm_converges_per_pixel_to_the_path_tracer_through_rough_glass_whose_lobes_store_photons() {
    // The room's glass sphere made rough enough (α = 0.4) that camera paths store photons on it: what it shows
    // of the room behind it reaches those photons from inside the sphere, through the stored transmission lobe.
    let glass = "ior = 1.5\nalpha = 0.1";
    let scene = shipped_edited("glossy-room.toml", 32, 24, |text| {
        assert!(text.contains(glass), "the glossy room's glass changed");
        text.replace(glass, "ior = 1.5\nalpha = 0.4")
    });
    assert!(photonfarm::bsdf::stores_glossy(0.4), "α = 0.4 no longer stores photons");
    // At 32 × 24 pixels the default disc of 3 pixel footprints spans a good part of the sphere, whose
    // transmitted image of the room varies within it: the blur's bias would exceed the sums' noise. A third of
    // the radius leaves a ninth of that bias.
    let (pbpm, path) = render_both_at_radius(&scene, 1000, 4000, Some(1.0));
    assert_converge("glossy room, glass of α = 0.4", &pbpm, &path);
}
