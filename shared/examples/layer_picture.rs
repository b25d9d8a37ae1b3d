//! A picture of layers of a render side by side, for the docs: each layer of `coordinator render`'s
//! `image.exr` named on the command line becomes a panel exposed on its own as `preview.png` is (the 99th
//! percentile of its luminance at 0.8), with a white gap of 4 pixels between panels. A layer written
//! `total-visible_lights` is the total without the lights seen through the lens: the scene as it is lit.
//!
//! `cargo run --release -p photonfarm --example layer_picture -- IMAGE.exr OUT.png LAYER [LAYER …]`

use photonfarm::image_io::exr_file::{find_layer, read_exr, LayerImage};
use photonfarm::image_io::preview::{auto_exposure, tonemap_rgb8};
use std::path::PathBuf;

/// White pixels between two panels.
const GAP: usize = 4;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args_os().skip(1);
    let usage = "usage: layer_picture IMAGE.exr OUT.png LAYER [LAYER …]";
    let (input, output) = match (args.next(), args.next()) {
        (Some(i), Some(o)) => (PathBuf::from(i), PathBuf::from(o)),
        _ => return Err(usage.into()),
    };
    let names: Vec<String> = args.map(|a| a.to_string_lossy().into_owned()).collect();
    if names.is_empty() {
        return Err(usage.into());
    }
    let layers = read_exr(&input)?;
    let panels = names
        .iter()
        .map(|name| -> Result<LayerImage, Box<dyn std::error::Error>> {
            match name.split_once('-') {
                Some((a, b)) => {
                    let (a, b) = (find_layer(&layers, &input, a)?, find_layer(&layers, &input, b)?);
                    let mut d = a.clone();
                    for (p, q) in d.rgb.iter_mut().zip(&b.rgb) {
                        *p = std::array::from_fn(|c| p[c] - q[c]);
                    }
                    Ok(d)
                }
                None => Ok(find_layer(&layers, &input, name)?.clone()),
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (w, h) = (panels[0].width, panels[0].height);
    let width = panels.len() * w + (panels.len() - 1) * GAP;
    let mut picture = vec![255u8; width * h * 3];
    for (i, panel) in panels.iter().enumerate() {
        let bytes = tonemap_rgb8(panel, auto_exposure(panel));
        let x0 = i * (w + GAP);
        for y in 0..h {
            let row = &bytes[y * w * 3..(y + 1) * w * 3];
            picture[(y * width + x0) * 3..(y * width + x0 + w) * 3].copy_from_slice(row);
        }
        println!("{}: exposure {:.4e}", names[i], auto_exposure(panel));
    }
    let file = std::io::BufWriter::new(std::fs::File::create(&output)?);
    let mut encoder = png::Encoder::new(file, width as u32, h as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    encoder.write_header()?.write_image_data(&picture)?;
    println!("wrote {}", output.display());
    Ok(())
}
