//! The photon discs' blur is measured alike in every method: a photon's radius follows its pixel's phase number
//! counted over every group, so the parallel methods' discs, and the blur δ counts, are the single-threaded
//! engine's.

mod common;

use common::scene;
use photonfarm::accumulation::LitMask;
use photonfarm::render::session::Progressive;
use photonfarm::render::{Engine, Method, RenderSettings};
use std::sync::atomic::AtomicBool;
use worker::{EngineConfig, ParallelEngine, ParallelMethod};

/// Phases per pixel each parallel run renders at least.
const PHASES: u32 = 24;

#[test]
fn every_parallel_method_measures_the_blur_the_single_threaded_engine_measures() {
    let sc = scene("caustic.toml", 96);
    // Discs twice the scene's, so that the blur is most of δ and its estimate's own noise is small beside it.
    let settings = |seed| RenderSettings { radius_scale: 6.0, ..RenderSettings::for_scene(&sc, Method::Pbpm, seed) };
    let lit = LitMask::of_scene(&sc, settings(1).max_depth);
    // The single-threaded engine's blur after each phase, for runs that overshoot the phases asked for.
    let mut single = Engine::new(&sc, settings(1));
    let blur_after: Vec<f64> = (0..2 * PHASES)
        .map(|_| {
            single.run_phase();
            single.sums().error(&lit).blur_unlit
        })
        .collect();
    let e = single.sums().error(&lit);
    let noise = (e.delta_unlit.powi(2) - e.blur_unlit.powi(2)).sqrt();
    assert!(e.blur_unlit > 2.0 * noise, "the blur does not dominate: {e:?}");
    for (seed, method) in [(2, ParallelMethod::Sync), (3, ParallelMethod::Async), (4, ParallelMethod::TwoLevel)] {
        let config = EngineConfig::for_method(method, 2, 1, vec![0, 1]).unwrap();
        let mut engine = ParallelEngine::new(&sc, settings(seed), config).unwrap();
        while engine.sums().min_phases() < PHASES {
            engine.run_round(&AtomicBool::new(false), None);
        }
        let phases = engine.sums().image_phases().round() as usize;
        let ratio = engine.sums().error(&lit).blur_unlit / blur_after[phases.min(blur_after.len()) - 1];
        println!("{method:?}: after {phases} phases, blur {ratio:.3} of the single-threaded engine's");
        assert!((0.85..=1.15).contains(&ratio), "{method:?}: blur {ratio:.3} of the single-threaded engine's");
    }
}
