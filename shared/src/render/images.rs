//! Images made from the running sums: the mean of every layer, the total and the per-pixel SEM.

use crate::accumulation::blur::{BIAS_PER_DIFFERENCE, BLUR_LAYER, BLUR_SQUARES_LAYER};
use crate::accumulation::{Accumulator, AuxLayout, LitMask, LIT_LAYER};
use crate::color::luminance_f64;
use crate::image_io::exr_file::LayerImage;
use crate::integrator::Layer;

/// Layers written to the EXR: the four components, their total, the total's standard error (grey), and the
/// auxiliary layers the image has (e.g. `ghost`; a one-channel layer as grey), with `blur` as each pixel's
/// estimated bias (signed) and without the squares behind it.
pub fn layer_images(sums: &Accumulator) -> Vec<LayerImage> {
    let (w, h) = (sums.width as usize, sums.height as usize);
    let mut out: Vec<LayerImage> = Layer::ALL.iter().map(|l| LayerImage::new(l.name(), w, h)).collect();
    let mut sem = LayerImage::new("sem", w, h);
    for i in 0..w * h {
        for (k, l) in Layer::ALL.iter().enumerate() {
            let m = sums.mean(i, *l);
            out[k].rgb[i] = [m[0] as f32, m[1] as f32, m[2] as f32];
        }
        let s = sums.sem2(i);
        let s = if s.is_finite() { s.sqrt() as f32 } else { 0.0 };
        sem.rgb[i] = [s; 3];
    }
    out.push(total_layer(sums));
    out.push(sem);
    for layer in sums.aux.layout().layers().iter().filter(|l| l.name != BLUR_SQUARES_LAYER) {
        let mut image = LayerImage::new(layer.name.clone(), w, h);
        for (i, px) in image.rgb.iter_mut().enumerate() {
            let m = sums.aux_mean(i, &layer.name).expect("the layer is in the layout");
            *px = if layer.name == BLUR_LAYER {
                [(BIAS_PER_DIFFERENCE * m[0]) as f32; 3]
            } else {
                [m[0] as f32, m[1] as f32, m[2] as f32]
            };
        }
        out.push(image);
    }
    out
}

/// Bytes per pixel that writing the EXR of sums with the auxiliary layers `layout` holds besides the sums: the
/// file's f32 channels of `layer_images` with the lit and phases layers, and the one layer being made into
/// channels.
pub fn exr_bytes_per_pixel(layout: &AuxLayout) -> usize {
    let aux = layout.layers().iter().filter(|l| l.name != BLUR_SQUARES_LAYER).count();
    let layers = Layer::ALL.len() + 2 + aux + 2;
    (layers + 1) * std::mem::size_of::<[f32; 3]>()
}

/// The mean total image as the `total` layer, alone: the preview's image.
pub fn total_layer(sums: &Accumulator) -> LayerImage {
    let mut total = LayerImage::new("total", sums.width as usize, sums.height as usize);
    for (i, px) in total.rgb.iter_mut().enumerate() {
        let t = sums.mean_total(i);
        *px = [t[0] as f32, t[1] as f32, t[2] as f32];
    }
    total
}

/// The lit mask as a grey layer: 1 where a pixel sees a light, 0 where δ unlit counts it.
pub fn lit_layer(lit: &LitMask) -> LayerImage {
    let mut image = LayerImage::new(LIT_LAYER, lit.width as usize, lit.height as usize);
    for (i, px) in image.rgb.iter_mut().enumerate() {
        *px = [if lit.is_lit(i) { 1.0 } else { 0.0 }; 3];
    }
    image
}

/// Phases per pixel as a grey layer: where adaptive tiles spent the work (uniform where every tile rendered
/// every round).
pub fn phases_layer(sums: &Accumulator) -> LayerImage {
    let mut image = LayerImage::new(PHASES_LAYER, sums.width as usize, sums.height as usize);
    for (px, p) in image.rgb.iter_mut().zip(&sums.pixels) {
        *px = [p.phases as f32; 3];
    }
    image
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
