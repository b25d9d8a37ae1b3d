//! Checks several end-to-end test programs share.

use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use std::path::Path;

/// The run record (`run.json`) of an output folder.
pub fn record(dir: &Path) -> serde_json::Value {
    let path = dir.join("run.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// Mean over pixels of (Y_a − Y_b)² / (SEM_a² + SEM_b²) from two outputs' `total` and `sem` layers: about 1
/// when both estimate the same image.
pub fn mean_z2(a: &Path, b: &Path) -> f64 {
    let (pa, pb) = (a.join("image.exr"), b.join("image.exr"));
    let (la, lb) = (read_exr(&pa).unwrap(), read_exr(&pb).unwrap());
    let (ta, sa) = (find_layer(&la, &pa, "total").unwrap(), find_layer(&la, &pa, "sem").unwrap());
    let (tb, sb) = (find_layer(&lb, &pb, "total").unwrap(), find_layer(&lb, &pb, "sem").unwrap());
    let n = ta.rgb.len();
    (0..n)
        .map(|i| {
            let d = luminance_of(ta.rgb[i]) - luminance_of(tb.rgb[i]);
            let s2 = (sa.rgb[i][0] as f64).powi(2) + (sb.rgb[i][0] as f64).powi(2);
            if s2 > 0.0 {
                d * d / s2
            } else {
                0.0
            }
        })
        .sum::<f64>()
        / n as f64
}

/// Asserts that two outputs estimate the same image: mean z² below 1.5 (about 1 when they agree).
pub fn assert_same_image(a: &Path, b: &Path, what: &str) {
    let z2 = mean_z2(a, b);
    eprintln!("{what}: mean z² {z2:.3}");
    assert!(z2 < 1.5, "{what}: mean z² {z2:.3}, the images disagree beyond their error estimates");
}
