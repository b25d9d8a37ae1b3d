//! Bitmaps: images decoded to linear RGB (PNG files from sRGB), looked up with bilinear filtering at texture
//! coordinates.

use crate::color::Rgb;
use glam::{Vec2, Vec3};

/// A decoded image in linear RGB; row 0 is the top of the image, texture coordinate v = 0 its bottom row.
#[derive(Clone, Debug, PartialEq)]
pub struct Bitmap {
    width: u32,
    height: u32,
    texels: Vec<Rgb>,
    mean: Rgb,
    max: Rgb,
}

/// Largest image accepted, in texels (12 bytes each once decoded): a hostile or mistaken file must not
/// exhaust memory.
const MAX_TEXELS: u64 = 16 << 20;

/// What the PNG decoder itself may allocate.
const MAX_DECODER_BYTES: usize = 256 << 20;

/// The sRGB transfer function's inverse (IEC 61966-2-1): an encoded value in [0, 1] to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

impl Bitmap {
    /// A texture from linear texels in row-major order, row 0 at the top; None when the sizes disagree or a
    /// texel is negative or not finite.
    pub fn from_linear(width: u32, height: u32, texels: Vec<Rgb>) -> Option<Bitmap> {
        if width == 0 || height == 0 || texels.len() != width as usize * height as usize {
            return None;
        }
        if !texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0) {
            return None;
        }
        let sum = texels.iter().fold([0.0f64; 3], |s, t| [s[0] + t.x as f64, s[1] + t.y as f64, s[2] + t.z as f64]);
        let n = texels.len() as f64;
        let mean = Vec3::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        let max = texels.iter().fold(Rgb::ZERO, |m, t| m.max(*t));
        Some(Bitmap { width, height, texels, mean, max })
    }

    /// Decodes a PNG (grey, grey + alpha, RGB, RGBA or palette, 8 or 16 bits). Samples are taken as sRGB
    /// encoded whatever the file's gAMA or iCCP chunks say, and alpha is ignored: a texture is a colour.
    pub fn from_png(bytes: &[u8]) -> Result<Bitmap, String> {
        let mut decoder =
            png::Decoder::new_with_limits(std::io::Cursor::new(bytes), png::Limits { bytes: MAX_DECODER_BYTES });
        decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
        let mut reader = decoder.read_info().map_err(|e| format!("not a readable PNG: {e}"))?;
        let (w, h) = (reader.info().width, reader.info().height);
        if w as u64 * h as u64 > MAX_TEXELS {
            return Err(format!("the PNG has {w}×{h} pixels, more than the {MAX_TEXELS} accepted"));
        }
        let size = reader.output_buffer_size().ok_or("the PNG is too large")?;
        let mut buffer = vec![0u8; size];
        let info = reader.next_frame(&mut buffer).map_err(|e| format!("not a readable PNG: {e}"))?;
        let channels = match info.color_type {
            png::ColorType::Grayscale => 1,
            png::ColorType::GrayscaleAlpha => 2,
            png::ColorType::Rgb => 3,
            png::ColorType::Rgba => 4,
            png::ColorType::Indexed => return Err("the PNG's palette was not expanded".into()),
        };
        if info.bit_depth != png::BitDepth::Eight {
            return Err(format!("unsupported PNG bit depth {:?} after expansion", info.bit_depth));
        }
        // One table lookup per sample instead of a powf.
        let table: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f32 / 255.0)).collect();
        let (width, height) = (info.width, info.height);
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height as usize {
            let row = &buffer[y * info.line_size..][..width as usize * channels];
            for px in row.chunks_exact(channels) {
                texels.push(if channels < 3 {
                    Rgb::splat(table[px[0] as usize])
                } else {
                    Rgb::new(table[px[0] as usize], table[px[1] as usize], table[px[2] as usize])
                });
            }
        }
        Bitmap::from_linear(width, height, texels).ok_or_else(|| "the PNG has no pixels".into())
    }

    /// Width in texels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The texel in column `x`, row `y` (row 0 at the top), wrapping around the edges.
    pub fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        self.texels[y * self.width as usize + x]
    }

    /// Mean of all texels: also the texture's mean over any whole period of (u, v), since the bilinear
    /// lookup with wrapping preserves it.
    pub fn mean(&self) -> Rgb {
        self.mean
    }

    /// The largest texel value of each channel.
    pub fn max_texel(&self) -> Rgb {
        self.max
    }

    /// Bilinear lookup at (u, v): u runs left to right, v bottom to top over [0, 1], and the texture repeats
    /// outside. Texel centres sit at half-integer positions. Non-finite coordinates give black.
    pub fn lookup(&self, uv: Vec2) -> Rgb {
        if !uv.is_finite() {
            return Rgb::ZERO;
        }
        // Reduce first so that huge coordinates keep their fractional precision.
        let (u, v) = (uv.x.rem_euclid(1.0), uv.y.rem_euclid(1.0));
        let x = u * self.width as f32 - 0.5;
        let y = (1.0 - v) * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = self.texel(x0, y0) * (1.0 - fx) + self.texel(x0 + 1, y0) * fx;
        let bottom = self.texel(x0, y0 + 1) * (1.0 - fx) + self.texel(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_lookup_hits_texel_centres_and_blends_between_them() {
        let t = Bitmap::from_linear(2, 1, vec![Rgb::ZERO, Rgb::ONE]).unwrap();
        assert_eq!(t.lookup(Vec2::new(0.25, 0.5)), Rgb::ZERO);
        assert_eq!(t.lookup(Vec2::new(0.75, 0.5)), Rgb::ONE);
        assert!((t.lookup(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
        assert_eq!(t.lookup(Vec2::new(f32::NAN, 0.5)), Rgb::ZERO);
    }

    #[test]
    fn row_zero_is_the_top_and_v_runs_upward() {
        let t = Bitmap::from_linear(1, 2, vec![Rgb::ONE, Rgb::ZERO]).unwrap();
        assert_eq!(t.lookup(Vec2::new(0.5, 0.75)), Rgb::ONE);
        assert_eq!(t.lookup(Vec2::new(0.5, 0.25)), Rgb::ZERO);
    }
}
