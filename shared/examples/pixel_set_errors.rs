//! The true error of render images over pixel sets that are the same for every build: all pixels, the pixels
//! whose reference `visible_lights` layer is zero, the pixels a run's `lit` layer leaves unlit, and the pixels
//! whose reference sees a light (directly or through specular surfaces) from a given row down, such as those
//! of `caustic` that see the ceiling light through the glass sphere. Builds that decide their own lit masks
//! differently are compared over the same pixels this way.
//!
//! `cargo run --release -p photonfarm --example pixel_set_errors -- [--layer NAME] REF.exr MASK.exr FROM_ROW
//! RUN.exr...` (MASK.exr: any image.exr with a `lit` layer). Prints one tab-separated line per run. With
//! `--layer` the runs' and the reference's layer NAME (such as `ghost`) is compared instead of their total.

use photonfarm::image_io::exr_file::{find_layer, read_exr, LayerImage};
use photonfarm::render::images::luminance_of;
use std::path::{Path, PathBuf};

/// Relative RMSE of `image` against `reference` over the pixels `include` accepts (as `run.json` computes it).
fn relative_rmse(image: &[f64], reference: &[f64], include: impl Fn(usize) -> bool) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in image.iter().zip(reference).enumerate().filter(|&(i, _)| include(i)).map(|(_, p)| p) {
        num += (a - b) * (a - b);
        den += b * b;
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        f64::NAN
    }
}

fn layer<'a>(layers: &'a [LayerImage], path: &Path, name: &str) -> Result<&'a LayerImage, Box<dyn std::error::Error>> {
    Ok(find_layer(layers, path, name)?)
}

fn luminances(layer: &LayerImage) -> Vec<f64> {
    layer.rgb.iter().map(|&p| luminance_of(p)).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let compared = match args.first().map(String::as_str) {
        Some("--layer") if args.len() > 1 => {
            let name = args[1].clone();
            args.drain(..2);
            name
        }
        _ => "total".to_string(),
    };
    if args.len() < 4 {
        return Err("usage: pixel_set_errors [--layer NAME] REF.exr MASK.exr FROM_ROW RUN.exr...".into());
    }
    let (ref_path, mask_path) = (PathBuf::from(&args[0]), PathBuf::from(&args[1]));
    let from_row: usize = args[2].parse().map_err(|_| format!("FROM_ROW must be a row number, not {}", args[2]))?;
    let reference_layers = read_exr(&ref_path)?;
    let total = layer(&reference_layers, &ref_path, &compared)?;
    let reference = luminances(total);
    let sees_light: Vec<bool> =
        layer(&reference_layers, &ref_path, "visible_lights")?.rgb.iter().map(|p| p.iter().any(|&c| c > 0.0)).collect();
    let mask_layers = read_exr(&mask_path)?;
    let lit: Vec<bool> = layer(&mask_layers, &mask_path, "lit")?.rgb.iter().map(|p| p[0] > 0.5).collect();
    if lit.len() != reference.len() {
        return Err("the mask and the reference differ in size".into());
    }
    let width = total.width;
    let below: Vec<usize> = (0..reference.len()).filter(|&i| sees_light[i] && i / width >= from_row).collect();
    let at: Vec<String> = below.iter().map(|&i| format!("({}, {})", i % width, i / width)).collect();
    println!("# pixels seeing a light from row {from_row} down: {} at {}", below.len(), at.join(" "));
    println!("run\tall\treference_unlit\tmask_unlit\tfrom_row");
    for run in &args[3..] {
        let path = PathBuf::from(run);
        let layers = read_exr(&path)?;
        let image = luminances(layer(&layers, &path, &compared)?);
        if image.len() != reference.len() {
            return Err(format!("{run} and the reference differ in size").into());
        }
        println!(
            "{run}\t{:.5}\t{:.5}\t{:.5}\t{:.5}",
            relative_rmse(&image, &reference, |_| true),
            relative_rmse(&image, &reference, |i| !sees_light[i]),
            relative_rmse(&image, &reference, |i| !lit[i]),
            relative_rmse(&image, &reference, |i| below.contains(&i)),
        );
    }
    Ok(())
}
