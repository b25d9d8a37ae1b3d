//! PBPM's density estimate divides the light a photon gathers by the area of its disc that lies on its own
//! surface. Normalised by the whole disc, every pixel within a radius of a wall's edge or corner would come
//! out too dark. Rendered at 64 × 64, where a photon's radius (three pixel footprints) is four times its size
//! at the shipped 256 × 256 and the darkening four times as strong, `cornell`'s image mean must match the long
//! path-traced reference in `scenes/references/` (averaged over each 4 × 4 block of its pixels, which is the
//! box-filtered pixel of the smaller image) within 0.1% plus three standard errors, over all pixels and over
//! the pixels that do not see a light. Divided by πr² instead, the mean over all pixels sits 0.5% low, and the
//! test fails.

use crate::common::{mean_sem, regions_phase_means, scene, settings};
use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use photonfarm::render::{Engine, Method};
use std::path::Path;

/// The side of the shipped image and of the reference.
const SHIPPED: usize = 256;
/// The side of the test's image.
const SIDE: usize = 64;

/// A layer of the reference as luminance averaged over each block of the smaller image's pixel.
fn downsampled(rgb: &[[f32; 3]]) -> Vec<f64> {
    let k = SHIPPED / SIDE;
    (0..SIDE * SIDE)
        .map(|i| {
            let (x, y) = (i % SIDE, i / SIDE);
            let block = (0..k * k).map(|j| rgb[(y * k + j / k) * SHIPPED + x * k + j % k]);
            block.map(luminance_of).sum::<f64>() / (k * k) as f64
        })
        .collect()
}

#[test]
fn cornells_image_mean_matches_the_path_traced_reference_along_edges_and_corners() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let text = std::fs::read_to_string(root.join("cornell.toml")).unwrap();
    let small =
        text.replace("width = 256", &format!("width = {SIDE}")).replace("height = 256", &format!("height = {SIDE}"));
    assert_ne!(small, text, "cornell.toml no longer says its size as the test expects");
    let sc = scene(&small);

    let path = root.join("references/cornell-path.exr");
    let layers = read_exr(&path).unwrap_or_else(|e| panic!("{e}"));
    let reference = downsampled(&find_layer(&layers, &path, "total").unwrap().rgb);
    // A pixel of the smaller image sees a light where any of its block's pixels does.
    let visible = downsampled(&find_layer(&layers, &path, "visible_lights").unwrap().rgb);
    let all: Vec<usize> = (0..SIDE * SIDE).collect();
    let unlit: Vec<usize> = all.iter().copied().filter(|&i| visible[i] <= 0.0).collect();

    let mut engine = Engine::new(&sc, settings(&sc, Method::Pbpm, 7));
    // Each phase's image mean is one sample: a phase's light paths reach every pixel, so pixels' errors are
    // correlated and only per-phase means give the mean's standard error.
    let means = regions_phase_means(&mut engine, 1200, &[(&all, None), (&unlit, None)]);
    for (name, pixels, samples) in [("all pixels", &all, &means[0]), ("unlit pixels", &unlit, &means[1])] {
        let expect = pixels.iter().map(|&i| reference[i]).sum::<f64>() / pixels.len() as f64;
        let (mean, sem) = mean_sem(samples);
        let (difference, sem) = (mean / expect - 1.0, sem / expect);
        eprintln!("{name}: mean {:+.3}% against the reference, SEM {:.3}%", 100.0 * difference, 100.0 * sem);
        // The check must be able to tell the whole disc's darkening from noise.
        assert!(sem < 0.0015, "{name}: the mean's standard error {:.3}% is too large to judge", 100.0 * sem);
        assert!(
            difference.abs() < 0.001 + 3.0 * sem,
            "{name}: image mean {:+.3}% off the reference (SEM {:.3}%)",
            100.0 * difference,
            100.0 * sem
        );
    }
}
