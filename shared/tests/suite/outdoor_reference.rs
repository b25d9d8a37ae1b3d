//! The outdoor scene against Mitsuba 3: `scenes/references/outdoor-mitsuba-80x60.exr` is Mitsuba 3.9.1's image of
//! `scenes/outdoor.toml` at 80 × 60 pixels (`scripts/mitsuba/reference scenes/outdoor.toml OUT --size 80 60
//! --spp 1024 --batches 16`: the mean of 16 independent images and, in its `sem` layer, each pixel's standard
//! error from their spread). PBPM's and the path tracer's images must agree with it pixel by pixel within both
//! renderers' standard errors (the mean of z² over the pixels), over the whole image within 4 combined standard
//! errors, and over the pixels that see no light to within 2 √(δ² + δ_ref²) relative RMSE, the factor 2 being
//! the calibration of δ against true error (calibration.rs). Pixels that see the sun through the glass ball are
//! left to the z² test: their heavy-tailed noise dominates a squared error.

use crate::common::{scene, settings};
use photonfarm::accumulation::LitMask;
use photonfarm::color::luminance_f64;
use photonfarm::image_io::exr_file::{find_layer, read_exr, LayerImage};
use photonfarm::render::images::luminance_of;
use photonfarm::render::{Engine, Method};
use std::path::Path;

/// The reference's mean image and its per-pixel standard error.
fn reference(name: &str) -> (LayerImage, LayerImage) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references").join(name);
    let layers = read_exr(&path).unwrap_or_else(|e| panic!("{e}"));
    let layer = |n| find_layer(&layers, &path, n).unwrap_or_else(|e| panic!("{e}")).clone();
    (layer("total"), layer("sem"))
}

#[test]
fn pbpm_and_the_path_tracer_match_mitsuba_3_on_the_outdoor_scene_within_their_error_and_the_references_noise() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/outdoor.toml");
    let text = std::fs::read_to_string(path).unwrap().replace("width = 320\nheight = 240", "width = 80\nheight = 60");
    let sc = scene(&text);
    assert_eq!(sc.camera.pixel_count(), 80 * 60);
    let (mean, sem) = reference("outdoor-mitsuba-80x60.exr");
    assert_eq!((mean.width, mean.height), (80, 60));
    let theirs: Vec<f64> = mean.rgb.iter().map(|&c| luminance_of(c)).collect();
    let theirs_sem2: Vec<f64> = sem.rgb.iter().map(|&c| luminance_of(c).powi(2)).collect();
    let lit = LitMask::of_scene(&sc, sc.render.max_depth);
    let unlit: Vec<usize> = (0..theirs.len()).filter(|&i| !lit.is_lit(i)).collect();
    assert!(unlit.len() > theirs.len() / 2, "most pixels see no light");
    let norm_unlit: f64 = unlit.iter().map(|&i| theirs[i].powi(2)).sum();
    let delta_ref_unlit = (unlit.iter().map(|&i| theirs_sem2[i]).sum::<f64>() / norm_unlit).sqrt();
    for (method, phases) in [(Method::Pbpm, 1200), (Method::Path, 1200)] {
        let mut engine = Engine::new(&sc, settings(&sc, method, 9));
        for _ in 0..phases {
            engine.run_phase();
        }
        let sums = engine.sums();
        let ours: Vec<f64> = (0..theirs.len()).map(|i| luminance_f64(sums.mean_total(i))).collect();

        // Pixel by pixel: z² = (a − r)² / (SEM_a² + SEM_r²) has mean 1 (variance 2) where both are unbiased.
        let mut z2: Vec<(f64, usize)> = (0..theirs.len())
            .map(|i| (i, sums.sem2(i) + theirs_sem2[i]))
            .filter(|&(_, v)| v > 0.0)
            .map(|(i, v)| ((ours[i] - theirs[i]).powi(2) / v, i))
            .collect();
        let mean_z2 = z2.iter().map(|z| z.0).sum::<f64>() / z2.len() as f64;
        let z2_bound = 1.0 + 4.0 * (2.0 / z2.len() as f64).sqrt();
        z2.sort_by(|a, b| b.0.total_cmp(&a.0));
        let worst: Vec<String> = z2[..5].iter().map(|&(z, i)| format!("({}, {}) z² {z:.0}", i % 80, i / 80)).collect();

        // The whole image: its mean within 4 combined standard errors.
        let n = theirs.len() as f64;
        let (mean_ours, mean_theirs) = (ours.iter().sum::<f64>() / n, theirs.iter().sum::<f64>() / n);
        let sem_means = ((0..theirs.len()).map(|i| sums.sem2(i) + theirs_sem2[i]).sum::<f64>()).sqrt() / n;

        // The pixels that see no light: relative RMSE within the calibrated δ of both.
        let err2: f64 = unlit.iter().map(|&i| (ours[i] - theirs[i]).powi(2)).sum();
        let rmse_unlit = (err2 / norm_unlit).sqrt();
        let delta_unlit = sums.error(&lit).delta_unlit;
        let rmse_bound = 2.0 * (delta_unlit.powi(2) + delta_ref_unlit.powi(2)).sqrt();
        eprintln!(
            "{method:?}: mean z² {mean_z2:.3} (bound {z2_bound:.3}; worst {}); image mean {mean_ours:.5}, Mitsuba's \
             {mean_theirs:.5} ± {sem_means:.5}; unlit relative RMSE {:.2}% (δ {:.2}%, reference's {:.2}%, bound {:.2}%)",
            worst.join(", "),
            100.0 * rmse_unlit,
            100.0 * delta_unlit,
            100.0 * delta_ref_unlit,
            100.0 * rmse_bound
        );
        assert!(mean_z2 <= z2_bound, "{method:?}: mean z² {mean_z2} above {z2_bound}; worst {worst:?}");
        assert!(
            (mean_ours - mean_theirs).abs() <= 4.0 * sem_means,
            "{method:?}: image mean {mean_ours} against {mean_theirs}"
        );
        assert!(rmse_unlit <= rmse_bound, "{method:?}: unlit relative RMSE {rmse_unlit} above {rmse_bound}");
    }
}
