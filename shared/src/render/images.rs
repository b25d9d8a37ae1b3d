//! Images made from the running sums: the mean of every layer, the total and the per-pixel SEM.

use crate::accumulation::blur::{BIAS_PER_DIFFERENCE, BLUR_LAYER, BLUR_SQUARES_LAYER};
use crate::accumulation::{Accumulator, LitMask, LIT_LAYER};
use crate::color::luminance_f64;
use crate::image_io::exr_file::{ComputedLayer, LayerImage};
use crate::integrator::Layer;

/// Layers written to the EXR: the four components, their total, the total's standard error (grey), and the
/// auxiliary layers the image has (e.g. `ghost`; a one-channel layer as grey), with `blur` as each pixel's
/// estimated bias (signed) and without the squares behind it.
pub fn layer_images(sums: &Accumulator) -> Vec<LayerImage> {
    let (w, h) = (sums.width as usize, sums.height as usize);
    computed_layers(sums).iter().map(|layer| layer.to_image(w, h)).collect()
}

/// The layers of [`layer_images`], each pixel made from the sums when it is read.
pub fn computed_layers(sums: &Accumulator) -> Vec<ComputedLayer<'_>> {
    let f32s = |m: [f64; 3]| [m[0] as f32, m[1] as f32, m[2] as f32];
    let mut out: Vec<ComputedLayer> =
        Layer::ALL.iter().map(|&l| ComputedLayer::new(l.name(), move |i| f32s(sums.mean(i, l)))).collect();
    out.push(computed_total_layer(sums));
    out.push(ComputedLayer::new("sem", move |i| {
        let s = sums.sem2(i);
        [if s.is_finite() { s.sqrt() as f32 } else { 0.0 }; 3]
    }));
    let layout = sums.aux.layout();
    for layer in layout.layers().iter().filter(|l| l.name != BLUR_SQUARES_LAYER) {
        let (offset, channels) = (layout.offset(&layer.name).expect("the layer is in the layout"), layer.channels);
        let blur = layer.name == BLUR_LAYER;
        out.push(ComputedLayer::new(layer.name.clone(), move |i| {
            let m = sums.aux_mean_at(i, offset, channels);
            if blur {
                [(BIAS_PER_DIFFERENCE * m[0]) as f32; 3]
            } else {
                f32s(m)
            }
        }));
    }
    out
}

/// Bytes per pixel that a save of the outputs holds besides the sums, at most: the preview's total layer in f32
/// and its 8-bit pixels. The EXR's layers are made a row at a time as the file is compressed.
pub const SAVE_BYTES_PER_PIXEL: usize = std::mem::size_of::<[f32; 3]>() + 4;

/// The mean total image as the `total` layer, alone: the preview's image.
pub fn total_layer(sums: &Accumulator) -> LayerImage {
    computed_total_layer(sums).to_image(sums.width as usize, sums.height as usize)
}

/// [`total_layer`], each pixel made when it is read.
pub fn computed_total_layer(sums: &Accumulator) -> ComputedLayer<'_> {
    ComputedLayer::new("total", move |i| {
        let t = sums.mean_total(i);
        [t[0] as f32, t[1] as f32, t[2] as f32]
    })
}

/// The lit mask as a grey layer: 1 where a pixel sees a light, 0 where δ unlit counts it.
pub fn lit_layer(lit: &LitMask) -> LayerImage {
    computed_lit_layer(lit).to_image(lit.width as usize, lit.height as usize)
}

/// [`lit_layer`], each pixel made when it is read.
pub fn computed_lit_layer(lit: &LitMask) -> ComputedLayer<'_> {
    ComputedLayer::new(LIT_LAYER, move |i| [if lit.is_lit(i) { 1.0 } else { 0.0 }; 3])
}

/// Phases per pixel as a grey layer: where adaptive tiles spent the work (uniform where every tile rendered
/// every round).
pub fn phases_layer(sums: &Accumulator) -> LayerImage {
    computed_phases_layer(sums).to_image(sums.width as usize, sums.height as usize)
}

/// [`phases_layer`], each pixel made when it is read.
pub fn computed_phases_layer(sums: &Accumulator) -> ComputedLayer<'_> {
    ComputedLayer::new(PHASES_LAYER, move |i| [sums.pixels[i].phases as f32; 3])
}

/// The name of the phases-per-pixel EXR layer.
pub const PHASES_LAYER: &str = "phases";

/// The mean total image, f64 per channel.
pub fn total_image(sums: &Accumulator) -> Vec<[f64; 3]> {
    (0..sums.pixels.len()).map(|i| sums.mean_total(i)).collect()
}

/// Luminance of an RGB f32 pixel, in f64.
pub fn luminance_of(p: [f32; 3]) -> f64 {
    luminance_f64([p[0] as f64, p[1] as f64, p[2] as f64])
}
