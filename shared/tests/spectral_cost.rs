//! RGB scenes pay nothing for spectral rendering: their per-pixel memory is the same whether or not the
//! `spectral` feature is compiled in (.ci/run runs this file in both builds), and rendering a spectral scene in
//! the same process leaves their images bit for bit the same. Their speed is compared by scripts/spectral-cost.

mod common;

use photonfarm::accumulation::PixelSums;
use photonfarm::integrator::LayerValues;
use photonfarm::pbpm::BackwardPhoton;
use photonfarm::render::{Engine, Method};
use photonfarm::spectrum::{PhaseSpectrum, ENABLED};

/// Renders `phases` phases of a shipped scene and returns its sums.
fn render(name: &str, phases: usize) -> photonfarm::accumulation::Accumulator {
    let scene = common::shipped(name);
    let mut engine = Engine::new(&scene, common::settings(&scene, Method::Pbpm, 3));
    for _ in 0..phases {
        engine.run_phase();
    }
    engine.sums().clone()
}

#[test]
fn rgb_scene_bytes_per_pixel_are_those_of_the_rgb_only_build() {
    // The same sizes in both builds: the photon keeps its colour state in what would otherwise be padding,
    // and no per-pixel buffer has a field for spectral rendering.
    assert_eq!(std::mem::size_of::<BackwardPhoton>(), 52);
    assert_eq!(std::mem::size_of::<PixelSums>(), 192);
    assert_eq!(std::mem::size_of::<LayerValues>(), 48);
    let scene = common::shipped("cornell.toml");
    let settings = common::settings(&scene, Method::Pbpm, 3);
    assert_eq!(settings.phase_spectrum(&scene, 1), PhaseSpectrum::RGB, "cornell has no dispersive glass");
    let engine = Engine::new(&scene, settings);
    // Sums with their four replicates, the phase's layer values and replicate, two gathered layers, the map's
    // reserve of one photon per diffuse vertex allowed to store one (cornell's backward_diffuse_depth is 1),
    // and the two grey blur layers' sums and per-phase values: 192 + 48 + 1 + 24 + 1 × 52 + 2 × (8 + 4 + 4).
    assert_eq!(settings.backward_diffuse_depth, 1);
    assert_eq!(engine.bytes_per_pixel(), 349.0, "cornell's bytes per pixel (spectral code compiled in: {ENABLED})");
}

#[cfg(not(feature = "spectral"))]
#[test]
fn an_rgb_only_build_refuses_a_dispersive_scene_with_a_reason() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/prism.toml");
    let error = photonfarm::scene::Scene::load(&path).err().expect("the prism needs spectral rendering").to_string();
    assert!(error.contains("abbe") && error.contains("spectral"), "{error}");
}

#[test]
fn rendering_a_spectral_scene_leaves_rgb_images_bit_for_bit_the_same() {
    let before = render("cornell.toml", 2);
    if ENABLED {
        let prism = common::shipped("prism.toml");
        assert!(prism.is_spectral());
        render("prism.toml", 2);
    }
    assert_eq!(render("cornell.toml", 2), before);
}
