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

/// Σ (a − b)² / Σ (SEM_a² + SEM_b²) of the total luminance over the pixels `lit` leaves unlit, with the
/// replicate SEMs that δ uses, and its standard error: about 1 when both sums estimate the same image and δ is
/// honest. A sum over pixels has the expectation of its terms however the pixels of one phase are correlated,
/// and it averages out the few degrees of freedom of each pixel's replicate SEM.
pub struct VarianceRatio {
    pub value: f64,
    /// Delete-one-block jackknife over 4 × 4-pixel blocks. Their sums are nearly independent: on the 64² test
    /// scenes the jackknife gives the same standard error with blocks of 4, 8 and 16 pixels, which it would not
    /// if neighbouring blocks shared much of their noise. Many small blocks keep the estimate itself steady: from 64
    /// blocks of 8 pixels it varies by a factor of two from run to run, enough for a 4-SE check to fail on a
    /// difference of under three true standard errors.
    pub standard_error: f64,
}

pub fn variance_ratio(a: &Accumulator, b: &Accumulator, lit: &LitMask) -> VarianceRatio {
    const BLOCK: u32 = 4;
    let (bw, bh) = (a.width.div_ceil(BLOCK), a.height.div_ceil(BLOCK));
    let (mut d2, mut s2) = (vec![0.0; (bw * bh) as usize], vec![0.0; (bw * bh) as usize]);
    for i in (0..a.pixels.len()).filter(|&i| !lit.is_lit(i)) {
        let (x, y) = (i as u32 % a.width, i as u32 / a.width);
        let block = ((y / BLOCK) * bw + x / BLOCK) as usize;
        let d = luminance_f64(a.mean_total(i)) - luminance_f64(b.mean_total(i));
        d2[block] += d * d;
        s2[block] += a.replicate_sem2(i) + b.replicate_sem2(i);
    }
    let (d2_all, s2_all): (f64, f64) = (d2.iter().sum(), s2.iter().sum());
    let n = d2.len() as f64;
    let left_out: Vec<f64> = d2.iter().zip(&s2).map(|(d, s)| (d2_all - d) / (s2_all - s)).collect();
    let mean = left_out.iter().sum::<f64>() / n;
    let spread = left_out.iter().map(|r| (r - mean) * (r - mean)).sum::<f64>();
    VarianceRatio { value: d2_all / s2_all, standard_error: ((n - 1.0) / n * spread).sqrt() }
}

/// The true error of `sums` over the pixels `lit` leaves unlit, against the shipped reference
/// `scenes/references/NAME.exr`, and that reference's own δ over the same pixels: sqrt(Σ (m − ref)² / Σ ref²)
/// and sqrt(Σ SEM_ref² / Σ ref²), in luminance.
pub fn true_error_unlit(sums: &Accumulator, lit: &LitMask, reference: &str) -> (f64, f64) {
    use photonfarm::image_io::exr_file::{find_layer, read_exr};
    use photonfarm::render::images::luminance_of;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references").join(format!("{reference}.exr"));
    let layers = read_exr(&path).unwrap();
    let total = find_layer(&layers, &path, "total").unwrap();
    let sem = find_layer(&layers, &path, "sem").unwrap();
    let (mut err2, mut sem2, mut norm) = (0.0, 0.0, 0.0);
    for i in (0..sums.pixels.len()).filter(|&i| !lit.is_lit(i)) {
        let theirs = luminance_of(total.rgb[i]);
        err2 += (luminance_f64(sums.mean_total(i)) - theirs).powi(2);
        sem2 += luminance_of(sem.rgb[i]).powi(2);
        norm += theirs * theirs;
    }
    ((err2 / norm).sqrt(), (sem2 / norm).sqrt())
}
