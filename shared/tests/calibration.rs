//! δ is an honest error figure: on the shipped scenes, PBPM's true relative RMSE against the long path-traced
//! reference in `scenes/references/` stays within a factor of 2 of δ once δ < 10%. The reference has noise of
//! its own (its `sem` layer), which adds in quadrature to the error measured against it.

#![allow(clippy::needless_range_loop)]

mod common;

use common::{settings, shipped};
use photonfarm::accumulation::LitMask;
use photonfarm::color::luminance_f64;
use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use photonfarm::render::{Engine, Method};
use std::path::Path;

fn check_calibration(scene_file: &str, reference_file: &str) {
    let sc = shipped(scene_file);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references").join(reference_file);
    let layers = read_exr(&path).unwrap_or_else(|e| panic!("{e}"));
    let reference = find_layer(&layers, &path, "total").unwrap();
    let ref_sem = find_layer(&layers, &path, "sem").unwrap();

    let settings = settings(&sc, Method::Pbpm, 2024);
    // The run's mask of lit pixels, decided before the render: δ and the true error use the same pixel sets.
    let lit = LitMask::of_scene(&sc, settings.max_depth);
    let mut engine = Engine::new(&sc, settings);
    let mut phases = 0;
    loop {
        engine.run_phase();
        phases += 1;
        let e = engine.sums().error(&lit);
        if e.delta_unlit < 0.10 && phases >= 8 {
            break;
        }
        assert!(phases < 400, "{scene_file}: δ (unlit) still {} after {phases} phases", e.delta_unlit);
    }
    let sums = engine.sums();
    for (name, include) in [("all pixels", None), ("unlit pixels", Some(false))] {
        let (mut sem2, mut ref_sem2, mut err2, mut norm) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..sums.pixels.len() {
            if include.is_some_and(|want| lit.is_lit(i) != want) {
                continue;
            }
            let mine = luminance_f64(sums.mean_total(i));
            let theirs = luminance_of(reference.rgb[i]);
            sem2 += sums.replicate_sem2(i);
            ref_sem2 += luminance_of(ref_sem.rgb[i]).powi(2);
            err2 += (mine - theirs).powi(2);
            norm += theirs * theirs;
        }
        let delta = (sem2 / norm).sqrt();
        let delta_ref = (ref_sem2 / norm).sqrt();
        let true_error = (err2 / norm).sqrt();
        let expected = (delta * delta + delta_ref * delta_ref).sqrt();
        let ratio = true_error / expected;
        eprintln!(
            "{scene_file}, {name}, {phases} phases: δ {:.2}%, reference δ {:.2}%, true relative RMSE {:.2}%, ratio {ratio:.2}",
            100.0 * delta,
            100.0 * delta_ref,
            100.0 * true_error
        );
        assert!((0.5..=2.0).contains(&ratio), "{scene_file} ({name}): true error / δ = {ratio:.2}");
    }
}

#[test]
fn delta_is_calibrated_against_the_path_traced_reference_on_cornell() {
    check_calibration("cornell.toml", "cornell-path.exr");
}

#[test]
fn delta_is_calibrated_against_the_path_traced_reference_on_caustic() {
    check_calibration("caustic.toml", "caustic-path.exr");
}
