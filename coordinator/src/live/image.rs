//! A layer of the running sums as a PNG, made when a client asks: the colour layers tonemapped exactly as the
//! output folder's preview.png, and the per-pixel standard error and phase counts as heat maps.

use photonfarm::accumulation::Accumulator;
use photonfarm::image_io::exr_file::LayerImage;
use photonfarm::image_io::preview::{auto_exposure, tonemap_rgb8};
use photonfarm::integrator::Layer;
use photonfarm::render::images::{layer_images, luminance_of};

/// Relative standard error shown at the top of the SEM heat map at exposure 0 EV: a pixel this noisy or more
/// is white, so the map darkens as the run converges.
const SEM_FULL_SCALE: f64 = 0.25;
/// The heat maps' colour ramp, from cold to hot (black, purple, red, orange, pale yellow).
const HEAT: [[f64; 3]; 5] =
    [[0.0, 0.0, 0.0], [0.33, 0.06, 0.43], [0.80, 0.16, 0.20], [0.98, 0.55, 0.04], [0.99, 1.0, 0.75]];

/// How bright to draw a layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// `ev` stops above the automatic exposure (the one of preview.png).
    Auto { ev: f32 },
    /// A fixed linear factor.
    Factor(f32),
}

/// Why no image was made.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("no layer '{asked}' in this render (its layers: {})", .known.join(", "))]
    UnknownLayer { asked: String, known: Vec<String> },
    #[error("exposure must be a finite, non-negative factor or a finite number of stops")]
    BadExposure,
    #[error("cannot encode the PNG: {0}")]
    Encode(#[from] png::EncodingError),
}

/// The layers a client may ask for: the EXR's layers, and `phases` (phases per pixel as a heat map). `sem` is
/// drawn as a heat map of the relative standard error.
pub fn layer_names(sums: &Accumulator) -> Vec<String> {
    let mut names = vec!["total".to_string()];
    names.extend(Layer::ALL.iter().map(|l| l.name().to_string()));
    names.extend(sums.aux.layout().layers().iter().map(|l| l.name.clone()));
    names.extend(["sem".to_string(), "phases".to_string()]);
    names
}

/// The 8-bit RGB pixels of `layer` (from the top row) and its size.
pub fn layer_rgb8(sums: &Accumulator, layer: &str, exposure: Exposure) -> Result<(u32, u32, Vec<u8>), ImageError> {
    let gain = |auto: f32| match exposure {
        Exposure::Auto { ev } if ev.is_finite() => Ok(auto * ev.exp2()),
        Exposure::Factor(f) if f.is_finite() && f >= 0.0 => Ok(f),
        _ => Err(ImageError::BadExposure),
    };
    let size = (sums.width, sums.height);
    if layer == "phases" {
        let phases: Vec<f64> = sums.pixels.iter().map(|p| f64::from(p.phases)).collect();
        let most = phases.iter().copied().fold(0.0, f64::max).max(1.0);
        let g = f64::from(gain(1.0)?);
        return Ok((size.0, size.1, phases.iter().flat_map(|&p| heat(g * p / most)).collect()));
    }
    let layers = layer_images(sums);
    let find = |name: &str| layers.iter().find(|l| l.name == name);
    let unknown = || ImageError::UnknownLayer { asked: layer.to_string(), known: layer_names(sums) };
    if layer == "sem" {
        let (sem, total) = (find("sem").ok_or_else(unknown)?, find("total").ok_or_else(unknown)?);
        let g = f64::from(gain(1.0)?) / SEM_FULL_SCALE;
        return Ok((size.0, size.1, relative_sem(sem, total).iter().flat_map(|&r| heat(g * r)).collect()));
    }
    let image = find(layer).filter(|_| layer_names(sums).iter().any(|n| n == layer)).ok_or_else(unknown)?;
    Ok((size.0, size.1, tonemap_rgb8(image, gain(auto_exposure(image))?)))
}

/// `layer` as a PNG file's bytes.
pub fn layer_png(sums: &Accumulator, layer: &str, exposure: Exposure) -> Result<Vec<u8>, ImageError> {
    let (width, height, rgb) = layer_rgb8(sums, layer, exposure)?;
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&rgb)?;
    writer.finish()?;
    Ok(bytes)
}

/// Standard error over mean, per pixel, by luminance; a pixel with no light has no relative error unless it has
/// some error, which then counts as full scale.
fn relative_sem(sem: &LayerImage, total: &LayerImage) -> Vec<f64> {
    sem.rgb
        .iter()
        .zip(&total.rgb)
        .map(|(&s, &t)| {
            let (s, t) = (luminance_of(s), luminance_of(t));
            if t > 0.0 {
                s / t
            } else if s > 0.0 {
                SEM_FULL_SCALE
            } else {
                0.0
            }
        })
        .collect()
}

/// The ramp's colour at `t` (0 cold, 1 hot, clamped; not a number is hot so that it is seen).
fn heat(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let at = t * (HEAT.len() - 1) as f64;
    let i = (at.floor() as usize).min(HEAT.len() - 2);
    let f = at - i as f64;
    std::array::from_fn(|c| ((HEAT[i][c] * (1.0 - f) + HEAT[i + 1][c] * f) * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heat_ramp_runs_from_black_to_pale_yellow_and_shows_nan_as_hot() {
        assert_eq!(heat(0.0), [0, 0, 0]);
        assert_eq!(heat(-3.0), [0, 0, 0]);
        assert_eq!(heat(1.0), heat(7.0));
        assert_eq!(heat(f64::NAN), heat(1.0));
        let brightness = |c: [u8; 3]| c.iter().map(|&v| u32::from(v)).sum::<u32>();
        assert!((0..10).all(|k| brightness(heat(k as f64 / 10.0)) < brightness(heat((k + 1) as f64 / 10.0))));
    }

    #[test]
    fn an_unknown_layer_or_a_bad_exposure_is_refused_with_the_layers_named() {
        let sums = Accumulator::new(4, 3);
        let e = layer_rgb8(&sums, "beauty", Exposure::Auto { ev: 0.0 }).unwrap_err().to_string();
        assert!(e.contains("'beauty'") && e.contains("total") && e.contains("sem"), "{e}");
        assert!(layer_rgb8(&sums, "total", Exposure::Factor(f32::NAN)).is_err());
        assert!(layer_rgb8(&sums, "total", Exposure::Factor(-1.0)).is_err());
        for layer in layer_names(&sums) {
            let (w, h, rgb) = layer_rgb8(&sums, &layer, Exposure::Auto { ev: 1.0 }).unwrap();
            assert_eq!((w, h, rgb.len()), (4, 3, 36), "{layer}");
        }
    }
}
