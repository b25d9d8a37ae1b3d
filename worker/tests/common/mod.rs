//! Helpers shared by the worker's integration tests.
#![allow(dead_code)]

use photonfarm::accumulation::{Accumulator, LitMask};
use photonfarm::color::luminance_f64;
use photonfarm::scene::Scene;
use std::path::Path;

/// A shipped scene at a test resolution (size × size pixels).
pub fn scene(name: &str, size: u32) -> Scene {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let text = std::fs::read_to_string(dir.join(name)).unwrap();
    let text =
        text.replace("width = 256", &format!("width = {size}")).replace("height = 256", &format!("height = {size}"));
    Scene::from_toml(&text, Path::new(name), &dir).unwrap()
}

/// Mean over pixels of z² = (a − b)² / (SEM_a² + SEM_b²) of the total luminance, with eq. 7's per-pixel SEMs:
/// 1 when both sums estimate the same image from independent phases, less with quasi-random phases, whose
/// mean eq. 7 overstates (pixels of one phase share light paths, so block SEMs built from pixel SEMs would be
/// too small; z² per pixel is exact).
pub fn mean_z2(a: &Accumulator, b: &Accumulator) -> f64 {
    let n = a.pixels.len();
    (0..n)
        .map(|i| {
            let (x, y) = (luminance_f64(a.mean_total(i)), luminance_f64(b.mean_total(i)));
            let s2 = a.sem2(i) + b.sem2(i);
            if s2 > 0.0 {
                (x - y) * (x - y) / s2
            } else {
                0.0
            }
        })
        .sum::<f64>()
        / n as f64
}

/// Σ (a − b)² / Σ (SEM_a² + SEM_b²) of the total luminance over the pixels `lit` leaves unlit,
/// with the replicate SEMs that δ uses: about 1 when both sums estimate the same image and δ is honest. A sum
/// over pixels has the expectation of its terms however the pixels of one phase are correlated, and it averages
/// out the few degrees of freedom of each pixel's replicate SEM.
pub fn variance_ratio(a: &Accumulator, b: &Accumulator, lit: &LitMask) -> f64 {
    let (mut d2, mut s2) = (0.0, 0.0);
    for i in (0..a.pixels.len()).filter(|&i| !lit.is_lit(i)) {
        let d = luminance_f64(a.mean_total(i)) - luminance_f64(b.mean_total(i));
        d2 += d * d;
        s2 += a.replicate_sem2(i) + b.replicate_sem2(i);
    }
    d2 / s2
}
