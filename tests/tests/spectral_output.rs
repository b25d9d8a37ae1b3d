//! `--spectral-output N` through the real programs: a three-level render (worker processes on a synthetic
//! two-node topology, band sums carried in snapshots) writes N grey band layers into its EXR, and bad band
//! counts are refused with a reason.

use end_to_end::{cornell_at, render_output as render, scratch_dir};
use photonfarm::image_io::exr_file::{find_layer, read_exr};

#[test]
fn a_three_level_render_with_spectral_output_writes_one_layer_per_band() {
    let dir = scratch_dir("spectral-output");
    let scene = cornell_at(&dir, 16);
    let run = dir.join("run");
    let args = ["--method", "three-level", "--topology", "pack:1 numa:2 core:1 pu:1", "--group-size", "1"];
    let o = render(&scene, &run, &[&args[..], &["--phases", "8", "--spectral-output", "4"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = run.join("image.exr");
    let layers = read_exr(&path).unwrap();
    let mut lit = 0.0;
    for name in ["band_380-480nm", "band_480-580nm", "band_580-680nm", "band_680-780nm"] {
        let band = find_layer(&layers, &path, name).unwrap_or_else(|e| panic!("{e}"));
        for p in &band.rgb {
            assert!(p[0].is_finite() && p[0] >= 0.0 && p[0] == p[1] && p[1] == p[2], "{name}: {p:?}");
        }
        let mean = band.rgb.iter().map(|p| p[0] as f64).sum::<f64>() / band.rgb.len() as f64;
        println!("{name}: mean {mean:.4}");
        lit += mean;
    }
    assert!(lit > 0.0, "every band is black");
    assert!(find_layer(&layers, &path, "band_380-430nm").is_err());
}

#[test]
fn bad_band_counts_are_refused_with_a_reason() {
    let dir = scratch_dir("spectral-output-bad");
    let scene = cornell_at(&dir, 8);
    for bad in ["0", "401", "many"] {
        let o = render(&scene, &dir.join("run"), &["--method", "pbpm", "--phases", "1", "--spectral-output", bad]);
        assert!(!o.status.success(), "--spectral-output {bad} was accepted");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("spectral-output") && !err.contains("panicked"), "{bad}: {err}");
    }
}
