//! The outdoor scene against Mitsuba 3: `scenes/references/outdoor-mitsuba-80x60.exr` is Mitsuba 3.9.1's image of
//! `scenes/outdoor.toml` at 80 × 60 pixels (32 independent images of 1024 samples per pixel averaged, by this
//! branch's `scripts/mitsuba/reference --size 80 60 --batches 32` before main's `--batches` replaced it; the `-sem` file holds each pixel's standard error from their spread). PBPM's
//! and the path tracer's images must differ from it by no more than their own error δ and the reference's
//! noise allow: relative RMSE ≤ 2 √(δ² + δ_ref²), the factor 2 being the calibration of δ against true error
//! (calibration.rs).

mod common;

use common::{scene, settings};
use photonfarm::accumulation::LitMask;
use photonfarm::color::luminance_f64;
use photonfarm::image_io::exr_file::{read_exr, LayerImage};
use photonfarm::render::images::luminance_of;
use photonfarm::render::{Engine, Method};
use std::path::Path;

fn reference(name: &str) -> LayerImage {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references").join(name);
    read_exr(&path).unwrap_or_else(|e| panic!("{e}")).remove(0)
}

#[test]
#[ignore = "open: PBPM differs from Mitsuba 3 by 4.1% relative RMSE where δ and the reference's noise give 1.8% \
            (bound 3.5%); the cause (materials, the window's box, the map) is not yet found"]
fn pbpm_and_the_path_tracer_match_mitsuba_3_on_the_outdoor_scene_within_their_error_and_the_references_noise() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/outdoor.toml");
    let text = std::fs::read_to_string(path).unwrap().replace("width = 320\nheight = 240", "width = 80\nheight = 60");
    let sc = scene(&text);
    assert_eq!(sc.camera.pixel_count(), 80 * 60);
    let (mean, sem) = (reference("outdoor-mitsuba-80x60.exr"), reference("outdoor-mitsuba-80x60-sem.exr"));
    assert_eq!((mean.width, mean.height), (80, 60));
    let theirs: Vec<f64> = mean.rgb.iter().map(|&c| luminance_of(c)).collect();
    let norm: f64 = theirs.iter().map(|t| t * t).sum();
    let delta_ref = (sem.rgb.iter().map(|&c| luminance_of(c).powi(2)).sum::<f64>() / norm).sqrt();
    for (method, phases) in [(Method::Pbpm, 1200), (Method::Path, 1200)] {
        let mut engine = Engine::new(&sc, settings(&sc, method, 9));
        for _ in 0..phases {
            engine.run_phase();
        }
        let sums = engine.sums();
        let err2: f64 = theirs.iter().enumerate().map(|(i, t)| (luminance_f64(sums.mean_total(i)) - t).powi(2)).sum();
        let rmse = (err2 / norm).sqrt();
        let delta = sums.error(&LitMask::none(80, 60)).delta_all;
        let bound = 2.0 * (delta * delta + delta_ref * delta_ref).sqrt();
        eprintln!(
            "{method:?}: relative RMSE against Mitsuba 3 {:.2}%, δ {:.2}%, reference δ {:.2}%, bound {:.2}%",
            100.0 * rmse,
            100.0 * delta,
            100.0 * delta_ref,
            100.0 * bound
        );
        assert!(rmse <= bound, "{method:?}: {rmse} against Mitsuba 3, more than {bound}");
    }
}
