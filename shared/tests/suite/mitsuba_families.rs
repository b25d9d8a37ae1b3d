//! PBPM against an independent renderer: each material family on a sphere in a small Cornell room
//! (`tests/data/mitsuba-families/*.toml`) matches its Mitsuba 3 reference (made by `scripts/mitsuba/families`,
//! committed beside the scene) per pixel, within the reference's own noise plus photonfarm's.

use crate::common::settings;
use photonfarm::color::luminance_f64;
use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;
use std::path::Path;

/// Renders the family's scene with PBPM and compares it with the reference: the mean over pixels of
/// z² = (a − r)² / (SEM_a² + SEM_r²) must lie within 4 standard deviations of 1 (z² has variance 2), and the
/// image's mean within 4 standard errors of the reference's.
fn check_family(name: &str) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mitsuba-families");
    let scene = Scene::load(&dir.join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"));
    let reference_path = dir.join(format!("{name}.exr"));
    let layers = read_exr(&reference_path).unwrap_or_else(|e| panic!("{e}"));
    let reference = find_layer(&layers, &reference_path, "total").unwrap();
    let reference_sem = find_layer(&layers, &reference_path, "sem").unwrap();

    let mut engine = Engine::new(&scene, settings(&scene, Method::Pbpm, 7));
    for _ in 0..600 {
        engine.run_phase();
    }
    let sums = engine.sums();
    let (w, h) = (sums.width as usize, sums.height as usize);
    assert_eq!((w, h), (reference.width, reference.height), "{name}: the reference has another size");

    let (mut z2, mut compared) = (0.0, 0usize);
    let (mut sum_a, mut sum_r, mut var_a, mut var_r) = (0.0, 0.0, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let a = luminance_f64(sums.mean_total(i));
            let rgb = reference.get(x, y);
            let r = luminance_f64([rgb[0] as f64, rgb[1] as f64, rgb[2] as f64]);
            let (sa2, sr2) = (sums.sem2(i), (reference_sem.get(x, y)[0] as f64).powi(2));
            if sa2 + sr2 > 0.0 {
                z2 += (a - r).powi(2) / (sa2 + sr2);
                compared += 1;
            } else {
                // A pixel without noise in either (one that sees only black surfaces through mirrors).
                assert!((a - r).abs() <= 1e-6 * r.abs().max(1e-6), "{name}: pixel ({x}, {y}) is {a}, Mitsuba's {r}");
            }
            sum_a += a;
            sum_r += r;
            var_a += sa2;
            var_r += sr2;
        }
    }
    let n = (w * h) as f64;
    let mean_z2 = z2 / compared as f64;
    let bound = 1.0 + 4.0 * (2.0 / compared as f64).sqrt();
    eprintln!(
        "{name}: mean z² {mean_z2:.3} (bound {bound:.3}); image mean photonfarm {:.5} ± {:.5}, Mitsuba {:.5} ± {:.5}",
        sum_a / n,
        var_a.sqrt() / n,
        sum_r / n,
        var_r.sqrt() / n
    );
    assert!(mean_z2 < bound, "{name}: mean z² {mean_z2:.3} against Mitsuba 3 exceeds {bound:.3}");
    assert!(
        (sum_a - sum_r).abs() < 4.0 * (var_a + var_r).sqrt(),
        "{name}: the image means differ by more than 4 standard errors"
    );
}

#[test]
fn a_diffuse_sphere_matches_mitsuba_3() {
    check_family("diffuse");
}

#[test]
fn a_smooth_silver_sphere_matches_mitsuba_3() {
    check_family("conductor");
}

#[test]
fn a_rough_gold_sphere_whose_lobe_is_stored_matches_mitsuba_3() {
    check_family("rough-conductor");
}

#[test]
fn a_slightly_rough_copper_sphere_whose_lobe_is_passed_matches_mitsuba_3() {
    check_family("rough-conductor-sharp");
}

#[test]
fn a_rough_glass_sphere_matches_mitsuba_3() {
    check_family("rough-dielectric");
}

#[test]
fn a_thin_glass_shell_matches_mitsuba_3() {
    check_family("thin-dielectric");
}

#[test]
fn a_smooth_plastic_sphere_matches_mitsuba_3() {
    check_family("plastic");
}

#[test]
fn a_rough_plastic_sphere_matches_mitsuba_3() {
    check_family("rough-plastic");
}

#[test]
fn a_principled_sphere_matches_mitsuba_3() {
    check_family("principled");
}
