//! The error of one run, measured from independent runs of the same scene and settings (different seeds): per
//! layer, sqrt(Σ s²_i / Σ m_i²) over the pixels' luminance, s²_i being the variance of pixel i across the runs
//! and m_i its mean. It is δ over all pixels for a single run's image, and works for layers that keep no
//! squares, such as `ghost`.
//!
//! `cargo run --release -p photonfarm --example run_spread -- A.exr B.exr [C.exr …]`

use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let paths: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if paths.len() < 2 {
        return Err("usage: run_spread A.exr B.exr [C.exr …] (two or more independent runs)".into());
    }
    let runs = paths.iter().map(|p| read_exr(p)).collect::<Result<Vec<_>, _>>()?;
    for name in ["total", "visible_lights", "direct", "indirect", "caustic", "ghost"] {
        let layers = runs.iter().zip(&paths).map(|(r, p)| find_layer(r, p, name)).collect::<Result<Vec<_>, _>>()?;
        let (w, h) = (layers[0].width, layers[0].height);
        if layers.iter().any(|l| (l.width, l.height) != (w, h)) {
            return Err(format!("the runs' {name} layers differ in size").into());
        }
        let n = layers.len() as f64;
        let (mut var, mut sq, mut sum) = (0.0, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let v: Vec<f64> = layers.iter().map(|l| luminance_of(l.get(x, y))).collect();
                let m = v.iter().sum::<f64>() / n;
                var += v.iter().map(|a| (a - m) * (a - m)).sum::<f64>() / (n - 1.0);
                sq += m * m;
                sum += m;
            }
        }
        println!(
            "{name:>15}: mean luminance {:.6e}, error of one run {:.4} ({} runs)",
            sum / (w * h) as f64,
            (var / sq).sqrt(),
            layers.len()
        );
    }
    Ok(())
}
