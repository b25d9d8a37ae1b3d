//! Texture files to bitmaps: PNG, JPEG and Radiance HDR through the `image` crate, OpenEXR through `exr`, PFM
//! through `pfm` (no maintained crate reads it). The format comes from the file's first bytes, whatever its
//! name says.
//!
//! Integer samples (8 and 16 bits) are sRGB-encoded unless the scene says they are linear (Mitsuba's `raw`);
//! float samples are linear. Grey and grey + alpha files become grey bitmaps, RGB and RGBA colour ones; alpha
//! is never read as colour. Negative float samples, which resampling filters leave in some HDR files, read as
//! zero; a sample that is not a finite number refuses the file. No file may hold more than [`MAX_TEXELS`]
//! pixels, which every decoder checks before it allocates the image.

use super::bitmap::Bitmap;
use super::pfm;
use crate::color::Rgb;
use image::{DynamicImage, ImageDecoder};
use std::fmt;
use std::io::Cursor;
use std::sync::OnceLock;

/// Largest image accepted, in pixels (12 bytes each once decoded in colour): a hostile or mistaken file must
/// not exhaust memory.
pub const MAX_TEXELS: u64 = 16 << 20;

/// What a decoder may allocate beyond that (its own buffers).
const MAX_DECODER_BYTES: u64 = 256 << 20;

/// How the integer samples of a file encode linear values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub enum Encoding {
    /// The sRGB transfer curve (IEC 61966-2-1), what colour images hold whatever their gAMA or ICC data say,
    /// as Mitsuba reads them.
    #[default]
    Srgb,
    /// Linear: the sample over its largest value (Mitsuba's `raw`, for data such as roughness maps).
    Linear,
}

/// The file formats textures are read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Jpeg,
    OpenExr,
    RadianceHdr,
    Pfm,
}

impl fmt::Display for ImageFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ImageFormat::Png => "PNG",
            ImageFormat::Jpeg => "JPEG",
            ImageFormat::OpenExr => "OpenEXR",
            ImageFormat::RadianceHdr => "Radiance HDR",
            ImageFormat::Pfm => "PFM",
        })
    }
}

impl ImageFormat {
    /// The format whose signature the file begins with.
    pub fn from_magic(bytes: &[u8]) -> Option<ImageFormat> {
        if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(ImageFormat::Png)
        } else if bytes.starts_with(b"\xff\xd8\xff") {
            Some(ImageFormat::Jpeg)
        } else if bytes.starts_with(b"\x76\x2f\x31\x01") {
            Some(ImageFormat::OpenExr)
        } else if bytes.starts_with(b"#?") {
            Some(ImageFormat::RadianceHdr)
        } else if pfm::has_magic(bytes) {
            Some(ImageFormat::Pfm)
        } else {
            None
        }
    }

    /// The format a file name's extension names, for error messages.
    pub fn from_extension(name: &str) -> Option<ImageFormat> {
        let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
        match ext.as_str() {
            "png" => Some(ImageFormat::Png),
            "jpg" | "jpeg" => Some(ImageFormat::Jpeg),
            "exr" => Some(ImageFormat::OpenExr),
            "hdr" | "rgbe" | "pic" => Some(ImageFormat::RadianceHdr),
            "pfm" => Some(ImageFormat::Pfm),
            _ => None,
        }
    }
}

/// Why a texture file could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TextureError {
    /// The first bytes are no signature of a format read here.
    #[error(
        "not an image file photonfarm reads: PNG, JPEG, OpenEXR, Radiance HDR and PFM files are recognised by \
         their first bytes{}",
        match named { Some(f) => format!(", and this one does not begin as {f} files do"), None => String::new() }
    )]
    UnknownFormat {
        /// The format the file's name claims.
        named: Option<ImageFormat>,
    },
    /// The decoder refused the file.
    #[error("not a readable {format} file: {message}")]
    Unreadable { format: ImageFormat, message: String },
    /// The file holds a kind of image textures cannot use.
    #[error("the {format} file {what}, which textures do not support")]
    Unsupported { format: ImageFormat, what: String },
    #[error("the {format} file has {width}×{height} pixels, more than the {MAX_TEXELS} a texture may have")]
    TooLarge { format: ImageFormat, width: u64, height: u64 },
    #[error("the {format} file has no pixels")]
    Empty { format: ImageFormat },
    #[error("the {format} file's pixel ({x}, {y}) (from the top left) holds {value}, which is not a finite number")]
    NotFinite { format: ImageFormat, x: u32, y: u32, value: f32 },
}

impl TextureError {
    /// The decoder's own error, for a file of `format`.
    pub(super) fn unreadable(format: ImageFormat, message: impl fmt::Display) -> Self {
        TextureError::Unreadable { format, message: message.to_string() }
    }
}

/// Refuses an image of more than [`MAX_TEXELS`] pixels, or of none.
pub(super) fn check_size(format: ImageFormat, width: u64, height: u64) -> Result<(), TextureError> {
    if width == 0 || height == 0 {
        return Err(TextureError::Empty { format });
    }
    if width.saturating_mul(height) > MAX_TEXELS {
        return Err(TextureError::TooLarge { format, width, height });
    }
    Ok(())
}

/// The sRGB transfer function's inverse (IEC 61966-2-1): an encoded value in [0, 1] to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The linear value of every 8-bit sample under `encoding`: one table lookup per sample instead of a powf.
fn table_8(encoding: Encoding) -> &'static [f32] {
    static SRGB: OnceLock<Vec<f32>> = OnceLock::new();
    static LINEAR: OnceLock<Vec<f32>> = OnceLock::new();
    let (cell, f): (_, fn(f32) -> f32) = match encoding {
        Encoding::Srgb => (&SRGB, srgb_to_linear),
        Encoding::Linear => (&LINEAR, |v| v),
    };
    cell.get_or_init(|| (0..256).map(|i| f(i as f32 / 255.0)).collect())
}

/// The same for 16-bit samples.
fn table_16(encoding: Encoding) -> &'static [f32] {
    static SRGB: OnceLock<Vec<f32>> = OnceLock::new();
    static LINEAR: OnceLock<Vec<f32>> = OnceLock::new();
    let (cell, f): (_, fn(f32) -> f32) = match encoding {
        Encoding::Srgb => (&SRGB, srgb_to_linear),
        Encoding::Linear => (&LINEAR, |v| v),
    };
    cell.get_or_init(|| (0..65536).map(|i| f(i as f32 / 65535.0)).collect())
}

impl Bitmap {
    /// Decodes a texture file of any format read here, told by its first bytes; `name` (the path the scene
    /// writes, or empty) only serves the error when they are no format's.
    pub fn decode(bytes: &[u8], name: &str, encoding: Encoding) -> Result<Bitmap, TextureError> {
        let format = ImageFormat::from_magic(bytes)
            .ok_or(TextureError::UnknownFormat { named: ImageFormat::from_extension(name) })?;
        match format {
            ImageFormat::Png | ImageFormat::Jpeg | ImageFormat::RadianceHdr => decode_raster(bytes, format, encoding),
            ImageFormat::OpenExr => decode_exr(bytes),
            ImageFormat::Pfm => pfm::decode(bytes),
        }
    }

    /// Decodes a PNG with sRGB-encoded samples.
    pub fn from_png(bytes: &[u8]) -> Result<Bitmap, TextureError> {
        match ImageFormat::from_magic(bytes) {
            Some(ImageFormat::Png) => decode_raster(bytes, ImageFormat::Png, Encoding::Srgb),
            _ => Err(TextureError::UnknownFormat { named: Some(ImageFormat::Png) }),
        }
    }
}

/// PNG, JPEG or Radiance HDR through the `image` crate.
fn decode_raster(bytes: &[u8], format: ImageFormat, encoding: Encoding) -> Result<Bitmap, TextureError> {
    let kind = match format {
        ImageFormat::Png => image::ImageFormat::Png,
        ImageFormat::Jpeg => image::ImageFormat::Jpeg,
        _ => image::ImageFormat::Hdr,
    };
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), kind);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_TEXELS * 16 + MAX_DECODER_BYTES);
    reader.limits(limits);
    let decoder = reader.into_decoder().map_err(|e| TextureError::unreadable(format, e))?;
    let (w, h) = decoder.dimensions();
    check_size(format, w as u64, h as u64)?;
    let image = DynamicImage::from_decoder(decoder).map_err(|e| TextureError::unreadable(format, e))?;
    let (t8, t16) = (table_8(encoding), table_16(encoding));
    let grey = |values: Vec<f32>| Bitmap::from_grey(w, h, values);
    let colour = |texels: Vec<Rgb>| Bitmap::from_linear(w, h, texels);
    let bitmap = match image {
        DynamicImage::ImageLuma8(b) => grey(b.as_raw().iter().map(|&v| t8[v as usize]).collect()),
        DynamicImage::ImageLumaA8(b) => grey(b.as_raw().chunks_exact(2).map(|p| t8[p[0] as usize]).collect()),
        DynamicImage::ImageRgb8(b) => colour(rgb(b.as_raw(), 3, |v| t8[v as usize])),
        DynamicImage::ImageRgba8(b) => colour(rgb(b.as_raw(), 4, |v| t8[v as usize])),
        DynamicImage::ImageLuma16(b) => grey(b.as_raw().iter().map(|&v| t16[v as usize]).collect()),
        DynamicImage::ImageLumaA16(b) => grey(b.as_raw().chunks_exact(2).map(|p| t16[p[0] as usize]).collect()),
        DynamicImage::ImageRgb16(b) => colour(rgb(b.as_raw(), 3, |v| t16[v as usize])),
        DynamicImage::ImageRgba16(b) => colour(rgb(b.as_raw(), 4, |v| t16[v as usize])),
        DynamicImage::ImageRgb32F(b) => return float_rgb(format, w, h, rgb(b.as_raw(), 3, |v| v)),
        DynamicImage::ImageRgba32F(b) => return float_rgb(format, w, h, rgb(b.as_raw(), 4, |v| v)),
        other => {
            return Err(TextureError::Unsupported { format, what: format!("decodes to {:?} samples", other.color()) })
        }
    };
    // Integer samples map into [0, 1]: the bitmap takes them whole.
    bitmap.ok_or(TextureError::Empty { format })
}

/// The colours of interleaved samples with `channels` per pixel (the first three are red, green and blue).
fn rgb<T: Copy>(samples: &[T], channels: usize, linear: impl Fn(T) -> f32) -> Vec<Rgb> {
    samples.chunks_exact(channels).map(|p| Rgb::new(linear(p[0]), linear(p[1]), linear(p[2]))).collect()
}

/// A colour bitmap from linear float samples: refused at the first sample that is not finite, negative ones
/// read as zero.
pub(super) fn float_rgb(format: ImageFormat, w: u32, h: u32, mut texels: Vec<Rgb>) -> Result<Bitmap, TextureError> {
    if let Some(i) = texels.iter().position(|t| !t.is_finite()) {
        let t = texels[i];
        let value = if t.x.is_finite() {
            if t.y.is_finite() {
                t.z
            } else {
                t.y
            }
        } else {
            t.x
        };
        return Err(TextureError::NotFinite { format, x: i as u32 % w, y: i as u32 / w, value });
    }
    for t in &mut texels {
        *t = t.max(Rgb::ZERO);
    }
    Bitmap::from_linear(w, h, texels).ok_or(TextureError::Empty { format })
}

/// A grey bitmap from linear float samples, under the same rules as [`float_rgb`].
pub(super) fn float_grey(format: ImageFormat, w: u32, h: u32, mut values: Vec<f32>) -> Result<Bitmap, TextureError> {
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(TextureError::NotFinite { format, x: i as u32 % w, y: i as u32 / w, value: values[i] });
    }
    for v in &mut values {
        *v = v.max(0.0);
    }
    Bitmap::from_grey(w, h, values).ok_or(TextureError::Empty { format })
}

/// An OpenEXR file's first layer: its R, G and B channels, or its Y (luminance) channel for a grey image.
fn decode_exr(bytes: &[u8]) -> Result<Bitmap, TextureError> {
    use exr::prelude::*;
    let format = ImageFormat::OpenExr;
    let bad = |e: exr::error::Error| TextureError::unreadable(format, e);
    // The headers first, to refuse a huge image before anything is allocated for it.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(bad)?;
    for header in &meta.headers {
        check_size(format, header.layer_size.0 as u64, header.layer_size.1 as u64)?;
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(bad)?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.0 as u32, layer.size.1 as u32);
    let channels = &layer.channel_data.list;
    let find = |name: &str| channels.iter().position(|c| c.name.eq(name) && c.sampling == Vec2(1, 1));
    let values = |i: usize| channels[i].sample_data.values_as_f32();
    match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => {
            let texels = values(r).zip(values(g)).zip(values(b)).map(|((r, g), b)| Rgb::new(r, g, b)).collect();
            float_rgb(format, w, h, texels)
        }
        (_, _, _, Some(y)) => float_grey(format, w, h, values(y).collect()),
        _ => {
            let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
            Err(TextureError::Unsupported {
                format,
                what: format!(
                    "has no full-resolution R, G and B channels nor a Y channel in its first layer (it has {})",
                    names.join(", ")
                ),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_told_by_their_first_bytes() {
        assert_eq!(ImageFormat::from_magic(b"\x89PNG\r\n\x1a\n...."), Some(ImageFormat::Png));
        assert_eq!(ImageFormat::from_magic(b"\xff\xd8\xff\xe0"), Some(ImageFormat::Jpeg));
        assert_eq!(ImageFormat::from_magic(b"\x76\x2f\x31\x01\x02"), Some(ImageFormat::OpenExr));
        assert_eq!(ImageFormat::from_magic(b"#?RADIANCE\n"), Some(ImageFormat::RadianceHdr));
        assert_eq!(ImageFormat::from_magic(b"PF\n2 2\n-1\n"), Some(ImageFormat::Pfm));
        assert_eq!(ImageFormat::from_magic(b"Pf 2 2 -1\n"), Some(ImageFormat::Pfm));
        assert_eq!(ImageFormat::from_magic(b"v 0 0 0\n"), None);
        assert_eq!(ImageFormat::from_magic(b""), None);
        assert_eq!(ImageFormat::from_extension("dir/a.b/x.JPG"), Some(ImageFormat::Jpeg));
        assert_eq!(ImageFormat::from_extension("noext"), None);
    }

    #[test]
    fn an_unknown_file_is_refused_naming_what_its_name_claims() {
        let e = Bitmap::decode(b"v 0 0 0\nf 1 2 3\n", "floor.exr", Encoding::Srgb).unwrap_err();
        let message = e.to_string();
        assert!(message.contains("PNG, JPEG, OpenEXR, Radiance HDR and PFM"), "{message}");
        assert!(message.contains("does not begin as OpenEXR files do"), "{message}");
        let e = Bitmap::decode(b"", "mesh.obj", Encoding::Srgb).unwrap_err();
        assert_eq!(e, TextureError::UnknownFormat { named: None });
    }

    #[test]
    fn the_srgb_tables_follow_the_curve() {
        let t = table_8(Encoding::Srgb);
        assert_eq!((t[0], t[255]), (0.0, 1.0));
        assert!((t[128] - 0.215_861).abs() < 1e-6);
        assert!((table_16(Encoding::Srgb)[32768] - srgb_to_linear(32768.0 / 65535.0)).abs() < 1e-7);
        assert!((table_8(Encoding::Linear)[51] - 0.2).abs() < 1e-7);
        assert!((table_16(Encoding::Linear)[65535] - 1.0).abs() < 1e-7);
    }
}
