//! Portable float maps (PFM): a text header, `PF` (colour) or `Pf` (grey), the width and height, and a scale
//! whose sign gives the byte order (negative: little-endian) and whose magnitude multiplies every sample, as
//! Mitsuba and pbrt read it; then 32-bit float samples, rows from the bottom of the image to its top.

use super::bitmap::Bitmap;
use super::decode::{check_size, float_grey, float_rgb, ImageFormat, TextureError};
use crate::color::Rgb;

const FORMAT: ImageFormat = ImageFormat::Pfm;

/// True when `bytes` begin as a PFM file does: `PF` or `Pf` and a white-space character.
pub(super) fn has_magic(bytes: &[u8]) -> bool {
    matches!(bytes, [b'P', b'F' | b'f', c, ..] if c.is_ascii_whitespace())
}

/// The header's next white-space-separated token and what follows it, from the white space that ends it on;
/// None when the header ends first.
fn token(bytes: &[u8]) -> Option<(&str, &[u8])> {
    let start = bytes.iter().position(|c| !c.is_ascii_whitespace())?;
    let rest = &bytes[start..];
    let end = rest.iter().position(|c| c.is_ascii_whitespace())?;
    Some((std::str::from_utf8(&rest[..end]).ok()?, &rest[end..]))
}

/// Decodes a PFM file.
pub(super) fn decode(bytes: &[u8]) -> Result<Bitmap, TextureError> {
    let bad = |what: &str| TextureError::unreadable(FORMAT, what);
    let channels = if bytes.get(1) == Some(&b'F') { 3 } else { 1 };
    let header = &bytes[2..];
    let (w, rest) = token(header).ok_or_else(|| bad("the header ends before the width"))?;
    let (h, rest) = token(rest).ok_or_else(|| bad("the header ends before the height"))?;
    let (scale, rest) = token(rest).ok_or_else(|| bad("the header ends before the scale"))?;
    let size =
        |s: &str, what: &str| s.parse::<u32>().map_err(|_| bad(&format!("the {what} '{s}' is not a whole number")));
    let (w, h) = (size(w, "width")?, size(h, "height")?);
    let scale: f32 = scale.parse().map_err(|_| bad(&format!("the scale '{scale}' is not a number")))?;
    if !scale.is_finite() || scale == 0.0 {
        return Err(bad(&format!("the scale {scale} is not a finite non-zero number")));
    }
    check_size(FORMAT, w as u64, h as u64)?;
    // One white-space character ends the header.
    let data = &rest[1..];
    let count = w as usize * h as usize * channels;
    if data.len() < count * 4 {
        return Err(bad(&format!(
            "the file is truncated: {w}×{h} pixels of {channels} samples need {} bytes after the header, it has {}",
            count * 4,
            data.len()
        )));
    }
    let little = scale < 0.0;
    let gain = scale.abs();
    let sample = |i: usize| {
        let b: [u8; 4] = data[4 * i..4 * i + 4].try_into().expect("four bytes");
        gain * if little { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) }
    };
    // Rows come bottom first; the bitmap's row 0 is the top.
    let (wu, hu) = (w as usize, h as usize);
    let index = |x: usize, y: usize| ((hu - 1 - y) * wu + x) * channels;
    if channels == 3 {
        let texels = (0..hu)
            .flat_map(|y| (0..wu).map(move |x| index(x, y)))
            .map(|i| Rgb::new(sample(i), sample(i + 1), sample(i + 2)))
            .collect();
        float_rgb(FORMAT, w, h, texels)
    } else {
        let values = (0..hu).flat_map(|y| (0..wu).map(move |x| index(x, y))).map(sample).collect();
        float_grey(FORMAT, w, h, values)
    }
}
