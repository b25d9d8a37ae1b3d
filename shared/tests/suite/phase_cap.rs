//! The single-threaded engine's phase cap: on an image larger than the cap, each phase renders the tiles with
//! the fewest phases, whole, until they hold the cap's pixels. Its image is the whole-image engine's, every
//! pixel's phases stay within one of every other's, and a cap chooses only among the run's adaptive tiles.

use crate::common::{mean_z2, settings, shipped_at};
use photonfarm::render::{ActiveTiles, Engine, Method};

#[test]
fn a_capped_engine_renders_the_whole_image_engines_image_with_every_pixels_phases_within_one() {
    let scene = shipped_at("cornell.toml", 64, 64);
    let mut whole = Engine::new(&scene, settings(&scene, Method::Pbpm, 1));
    for _ in 0..300 {
        whole.run_phase();
    }
    let mut capped = Engine::new(&scene, settings(&scene, Method::Pbpm, 2));
    // 512 pixels a phase: eight of the 64 tiles of 8 × 8 pixels.
    capped.set_phase_cap(512, 8);
    let mut spread = 0;
    while capped.sums().min_phases() < 300 {
        capped.run_phase();
        let phases = capped.sums().pixels.iter().map(|p| p.phases);
        let (lo, hi) = (phases.clone().min().unwrap(), phases.max().unwrap());
        spread = spread.max(hi - lo);
    }
    assert_eq!(capped.totals().phases, 300 * 8, "each phase rendered an eighth of the image");
    assert!(spread <= 1, "pixels' phases spread over {spread}");
    // Eq. 7's SEMs overstate a quasi-random mean's error, so the mean z² is at most about 1.
    let (z2, n) = mean_z2(capped.sums(), whole.sums());
    println!("mean z² {z2:.3} over {n} pixels");
    assert!(n > 3500.0 && z2 <= 1.4, "mean z² {z2:.3} over {n} pixels");
}

#[test]
fn a_capped_engine_renders_only_the_active_tiles_and_an_image_within_the_cap_whole() {
    let scene = shipped_at("cornell.toml", 64, 64);
    let mut engine = Engine::new(&scene, settings(&scene, Method::Pbpm, 3));
    engine.set_phase_cap(1024, 8);
    // The left half's tiles active: 32 tiles of 64 pixels, two phases to cover them.
    let all = ActiveTiles::all(64, 64, 8).unwrap();
    let flags: Vec<bool> = (0..all.len()).map(|t| t % 8 < 4).collect();
    engine.set_active_tiles(&ActiveTiles::from_flags(64, 64, 8, flags.clone()).unwrap());
    for _ in 0..6 {
        engine.run_phase();
    }
    for (t, active) in flags.iter().enumerate() {
        for p in all.pixels_of(t) {
            let phases = engine.sums().pixels[p as usize].phases;
            assert_eq!(phases, if *active { 3 } else { 0 }, "tile {t}, pixel {p}");
        }
    }
    // A cap above the image's pixels renders it whole, phase by phase.
    let mut small = Engine::new(&scene, settings(&scene, Method::Pbpm, 3));
    small.set_phase_cap(64 * 64, 8);
    small.run_phase();
    assert!(small.sums().pixels.iter().all(|p| p.phases == 1));
}
