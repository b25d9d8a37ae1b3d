//! The work adaptive tiles could save on a finished render: from its EXR's per-pixel SEM and phases, each
//! tile's per-phase variance S_t over the unlit pixels, and the ratio (Σ √S_t)² / (tiles · Σ S_t) of the
//! optimal allocation's phases to a uniform run's at the same δ, for several tile edges (equal cost per
//! pixel-phase assumed).
//!
//! `cargo run --release -p photonfarm --example tile_gain -- OUT/image.exr`

use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path: PathBuf = std::env::args_os().nth(1).map(PathBuf::from).ok_or("usage: tile_gain IMAGE.exr")?;
    let layers = read_exr(&path)?;
    let (sem, phases, lit) =
        (find_layer(&layers, &path, "sem")?, find_layer(&layers, &path, "phases")?, find_layer(&layers, &path, "lit")?);
    let (w, h) = (sem.width, sem.height);
    // The work this render spent, and over the unlit pixels Σ SEM², Λ = Σ m² and each pixel's SEM².
    let total = find_layer(&layers, &path, "total")?;
    let (mut spent, mut sem2, mut lambda, mut shares) = (0.0f64, 0.0f64, 0.0, Vec::new());
    for y in 0..h {
        for x in 0..w {
            spent += phases.get(x, y)[0] as f64;
            if lit.get(x, y)[0] <= 0.5 {
                let e2 = luminance_of(sem.get(x, y)).powi(2);
                sem2 += e2;
                shares.push(e2);
                lambda += luminance_of(total.get(x, y)).powi(2);
            }
        }
    }
    shares.sort_by(|a, b| b.total_cmp(a));
    let top = |f: f64| shares[..(shares.len() as f64 * f) as usize].iter().sum::<f64>() / sem2;
    println!(
        "per-phase δ unlit {:.4}; share of Σ SEM² in the top 0.1% / 1% / 10% of pixels: {:.3} / {:.3} / {:.3}",
        (sem2 / lambda).sqrt(),
        top(0.001),
        top(0.01),
        top(0.1)
    );
    for tile in [64, 32, 16, 8, 4, 2, 1] {
        let (tx, ty) = (w.div_ceil(tile), h.div_ceil(tile));
        let mut s = vec![0.0f64; tx * ty];
        let mut pixels = vec![0usize; tx * ty];
        for y in 0..h {
            for x in 0..w {
                let t = (y / tile) * tx + x / tile;
                pixels[t] += 1;
                if lit.get(x, y)[0] > 0.5 {
                    continue;
                }
                let e = luminance_of(sem.get(x, y)) as f64;
                s[t] += phases.get(x, y)[0] as f64 * e * e;
            }
        }
        // Tile phases cost their pixels: optimal Σ_t c_t N_t with N_t ∝ √(S_t / c_t).
        let roots: f64 = s.iter().zip(&pixels).map(|(s, &c)| (s * c as f64).sqrt()).sum();
        let uniform = s.iter().sum::<f64>() * (w * h) as f64;
        println!(
            "tile {tile:3}: optimal / uniform work {:.3}, optimal / this render's {:.3}",
            roots * roots / uniform,
            roots * roots / (sem2 * spent)
        );
    }
    Ok(())
}
