//! 8-bit sRGB PNG previews of linear layers, for looking at a render in progress with
//! any image viewer or browser.

use std::io::BufWriter;
use std::path::Path;

use super::exr_file::LayerImage;
use super::{write_atomically, OutputError};

/// Colour of pixels with a NaN or infinite component: loud, so that numerical bugs are
/// noticed instead of disappearing into black or white.
const NON_FINITE_COLOUR: [u8; 3] = [255, 0, 255];

/// Luminance that the 99th percentile is mapped to: a little headroom below white keeps
/// most of the image unclipped while a few fireflies may saturate.
const TARGET_LUMINANCE: f32 = 0.8;

/// Exposure that maps the 99th percentile luminance of the finite pixels to 0.8 after
/// scaling (1.0 if the image is black), so previews of any scene are neither black nor
/// blown out, and a few fireflies cannot darken the whole preview.
pub fn auto_exposure(image: &LayerImage) -> f32 {
    let mut luminances: Vec<f32> = image
        .rgb
        .iter()
        .filter(|pixel| pixel.iter().all(|value| value.is_finite()))
        .map(|pixel| luminance(*pixel))
        .filter(|value| value.is_finite())
        .collect();
    if luminances.is_empty() {
        return 1.0;
    }
    // Nearest-rank percentile: the smallest value with at least 99% of values at or below it.
    let rank = (luminances.len() * 99).div_ceil(100);
    let index = rank.clamp(1, luminances.len()) - 1;
    let (_, percentile, _) = luminances.select_nth_unstable_by(index, f32::total_cmp);
    let exposure = TARGET_LUMINANCE / *percentile;
    if *percentile > 0.0 && exposure.is_finite() {
        exposure
    } else {
        1.0
    }
}

/// Writes an 8-bit sRGB PNG: linear RGB × exposure, the sRGB transfer function
/// (IEC 61966-2-1 piecewise curve), clamped to [0,1]; NaN or infinite pixels are written
/// magenta so they are never hidden. Same atomic temp-file-then-rename as the EXR output,
/// because previews are refreshed while someone may be looking at them.
///
/// `exposure` must be finite and non-negative; use [`auto_exposure`] when in doubt.
pub fn write_preview_png(path: &Path, image: &LayerImage, exposure: f32) -> Result<(), OutputError> {
    let png_error = |message: String| OutputError::Png { path: path.to_path_buf(), message };
    if !exposure.is_finite() || exposure < 0.0 {
        return Err(png_error(format!("exposure must be finite and non-negative, got {exposure}")));
    }
    if image.rgb.len() != image.width * image.height {
        return Err(OutputError::SizeMismatch {
            path: path.to_path_buf(),
            layer: image.name.clone(),
            detail: format!(
                "has {} pixels but {}x{} needs {}",
                image.rgb.len(),
                image.width,
                image.height,
                image.width * image.height
            ),
        });
    }
    let too_large = || png_error(format!("{}x{} is too large", image.width, image.height));
    let width = u32::try_from(image.width).map_err(|_| too_large())?;
    let height = u32::try_from(image.height).map_err(|_| too_large())?;

    let bytes = tonemap_rgb8(image, exposure);

    write_atomically(path, |file| {
        let convert = |error: png::EncodingError| match error {
            png::EncodingError::IoError(source) => OutputError::io(path, "write", source),
            other => png_error(other.to_string()),
        };
        let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        // A preview is rewritten every save and read at once: a 4K one encodes several times faster this way,
        // for a somewhat larger file.
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().map_err(convert)?;
        writer.write_image_data(&bytes).map_err(convert)?;
        writer.finish().map_err(convert)
    })
}

/// The preview's 8-bit sRGB bytes of a layer, three per pixel from the top row: linear RGB × exposure through
/// the sRGB transfer function, clamped; NaN or infinite pixels magenta. The file previews and the live page
/// share it, so both show a layer alike.
pub fn tonemap_rgb8(image: &LayerImage, exposure: f32) -> Vec<u8> {
    image
        .rgb
        .iter()
        .flat_map(|pixel| {
            if pixel.iter().all(|value| value.is_finite()) {
                pixel.map(|value| encode_srgb_byte(value * exposure))
            } else {
                NON_FINITE_COLOUR
            }
        })
        .collect()
}

/// Rec.709 luminance, the brightness measure matching the sRGB primaries of the preview.
fn luminance([r, g, b]: [f32; 3]) -> f32 {
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

/// Clamps a linear value to [0, 1], applies the IEC 61966-2-1 sRGB transfer function
/// and quantises it to the nearest 8-bit code.
fn encode_srgb_byte(linear: f32) -> u8 {
    let linear = linear.clamp(0.0, 1.0);
    let encoded = if linear <= 0.003_130_8 { 12.92 * linear } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 };
    (encoded * 255.0).round().clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A fresh, empty directory for one test, so tests can run in parallel.
    fn test_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("photonfarm-output-png-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Decodes an 8-bit RGB PNG into (width, height, bytes) with the png crate.
    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let file = std::fs::File::open(path).unwrap();
        let decoder = png::Decoder::new(std::io::BufReader::new(file));
        let mut reader = decoder.read_info().unwrap();
        let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buffer).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buffer.truncate(info.buffer_size());
        (info.width, info.height, buffer)
    }

    fn filled(width: usize, height: usize, value: [f32; 3]) -> LayerImage {
        let mut image = LayerImage::new("total", width, height);
        image.rgb.fill(value);
        image
    }

    #[test]
    fn preview_maps_linear_half_to_srgb_188() {
        let dir = test_dir("half");
        let path = dir.join("preview.png");
        write_preview_png(&path, &filled(2, 2, [0.5; 3]), 1.0).unwrap();
        let (width, height, bytes) = decode(&path);
        assert_eq!((width, height), (2, 2));
        assert_eq!(bytes, vec![188; 12]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn preview_applies_exposure_then_clamps() {
        let dir = test_dir("exposure");
        let path = dir.join("preview.png");
        let mut image = LayerImage::new("total", 3, 1);
        image.rgb = vec![[0.25, 0.25, 0.25], [10.0, -1.0, 0.0], [0.5, 1.0, 0.0]];
        write_preview_png(&path, &image, 2.0).unwrap();
        let (_, _, bytes) = decode(&path);
        assert_eq!(bytes, [188, 188, 188, 255, 0, 0, 255, 255, 0]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn srgb_encoding_follows_the_piecewise_iec_curve() {
        assert_eq!(encode_srgb_byte(0.0), 0);
        assert_eq!(encode_srgb_byte(1.0), 255);
        // Linear segment: 12.92 * 0.002 * 255 = 6.59.
        assert_eq!(encode_srgb_byte(0.002), 7);
        // Power segment: 1.055 * 0.18^(1/2.4) - 0.055 = 0.4614 -> 117.7.
        assert_eq!(encode_srgb_byte(0.18), 118);
        // The two segments meet at 0.0031308 (0.04045 encoded).
        assert_eq!(encode_srgb_byte(0.003_130_8), 10);
        assert_eq!(encode_srgb_byte(0.003_131), 10);
    }

    #[test]
    fn preview_rows_start_at_the_top() {
        let dir = test_dir("rows");
        let path = dir.join("preview.png");
        let mut image = LayerImage::new("total", 2, 2);
        image.rgb[1] = [1.0, 1.0, 1.0]; // (x=1, y=0)
        write_preview_png(&path, &image, 1.0).unwrap();
        let (_, _, bytes) = decode(&path);
        assert_eq!(&bytes[..6], [0, 0, 0, 255, 255, 255]);
        assert_eq!(&bytes[6..], [0; 6]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn preview_marks_nan_pixels_magenta() {
        let dir = test_dir("nan");
        let path = dir.join("preview.png");
        let mut image = filled(4, 1, [0.0; 3]);
        image.rgb[0] = [f32::NAN, 0.0, 0.0];
        image.rgb[1] = [0.0, f32::INFINITY, 0.0];
        image.rgb[2] = [0.0, 0.0, f32::NEG_INFINITY];
        write_preview_png(&path, &image, 1.0).unwrap();
        let (_, _, bytes) = decode(&path);
        assert_eq!(bytes, [255, 0, 255, 255, 0, 255, 255, 0, 255, 0, 0, 0]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn preview_write_into_missing_directory_names_the_path() {
        let dir = test_dir("missing-dir");
        let path = dir.join("no/such/dir/preview.png");
        let error = write_preview_png(&path, &filled(1, 1, [0.5; 3]), 1.0).unwrap_err();
        assert!(matches!(error, OutputError::Io { .. }), "{error:?}");
        let message = error.to_string();
        assert!(message.starts_with(&format!("cannot write {}", path.display())), "{message}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn preview_rejects_bad_exposure_and_inconsistent_layers() {
        let dir = test_dir("invalid");
        let path = dir.join("preview.png");
        for exposure in [f32::NAN, f32::INFINITY, -1.0] {
            let error = write_preview_png(&path, &filled(1, 1, [0.5; 3]), exposure).unwrap_err();
            assert!(matches!(error, OutputError::Png { .. }), "{error:?}");
        }
        let mut short = filled(2, 2, [0.5; 3]);
        short.rgb.pop();
        let error = write_preview_png(&path, &short, 1.0).unwrap_err();
        assert!(matches!(error, OutputError::SizeMismatch { .. }), "{error:?}");
        let error = write_preview_png(&path, &filled(0, 3, [0.5; 3]), 1.0).unwrap_err();
        assert!(matches!(error, OutputError::Png { .. }), "{error:?}");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "no files left");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn auto_exposure_of_black_image_is_one() {
        assert_eq!(auto_exposure(&filled(5, 5, [0.0; 3])), 1.0);
        assert_eq!(auto_exposure(&LayerImage::new("total", 0, 0)), 1.0);
    }

    #[test]
    fn auto_exposure_maps_99th_percentile_luminance_to_0_8() {
        let mut image = LayerImage::new("total", 100, 1);
        for (i, pixel) in image.rgb.iter_mut().enumerate() {
            *pixel = [(i + 1) as f32; 3]; // grey, so luminance = value = 1..=100
        }
        let exposure = auto_exposure(&image);
        assert!((exposure - 0.8 / 99.0).abs() < 1e-6, "{exposure}");

        // Coloured pixels use Rec.709 luminance.
        let green = filled(10, 10, [0.0, 2.0, 0.0]);
        let exposure = auto_exposure(&green);
        assert!((exposure * 0.7152 * 2.0 - 0.8).abs() < 1e-6, "{exposure}");
    }

    #[test]
    fn auto_exposure_ignores_non_finite_pixels() {
        let mut image = filled(10, 10, [0.4; 3]);
        image.rgb[0] = [f32::NAN; 3];
        image.rgb[1] = [f32::INFINITY, 0.0, 0.0];
        assert!((auto_exposure(&image) - 2.0).abs() < 1e-6);
    }
}
