//! The pixels that see a light: decided once per scene before the render, so that δ over the other pixels
//! (δ unlit), the `--target-error` stop and the true error all measure the same pixels from the first phase on.

use crate::integrator::lit_pixels::{lit_pixels, LIT_MASK_SAMPLES};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};

/// Which δ a target error refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorOver {
    /// Pixels the lit mask leaves unlit (default: the lights would flatter δ).
    Unlit,
    /// Every pixel, the paper's eq. 6.
    All,
}

/// Which pixels see an emitter directly or through specular surfaces only (the `visible_lights` layer's
/// pixels): found from `LIT_MASK_SAMPLES` stratified primary rays per pixel that follow every specular branch,
/// so the mask is the same whatever the seed, the method and the noise of the run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LitMask {
    pub width: u32,
    pub height: u32,
    lit: Vec<bool>,
    /// Primary rays traced per pixel to decide it.
    pub samples_per_pixel: u32,
}

/// What the run record says of the mask: how many pixels are lit and where the mask is kept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LitMaskRecord {
    /// Pixels that see a light (left out of δ unlit and the true error over unlit pixels).
    pub lit_pixels: u64,
    /// Pixels δ unlit is computed over.
    pub unlit_pixels: u64,
    /// Primary rays per pixel the mask was decided from.
    pub samples_per_pixel: u32,
    /// The EXR layer of `image.exr` that holds the mask (1 where a pixel is lit, 0 elsewhere).
    pub exr_layer: String,
    /// Wall seconds deciding the mask took, before the render started.
    #[serde(default)]
    pub seconds: f64,
}

/// The name of the mask's EXR layer.
pub const LIT_LAYER: &str = "lit";

impl LitMask {
    /// The mask of `scene`: the pixels that see an emitter directly or through specular surfaces only within
    /// `max_depth` segments (`crate::integrator::lit_pixels`), and the pixels next to those (`with_neighbours_lit`).
    pub fn of_scene(scene: &Scene, max_depth: u32) -> LitMask {
        scene.assert_traceable();
        let (width, height) = (scene.camera.width, scene.camera.height);
        LitMask::from_flags(width, height, lit_pixels(scene, max_depth), LIT_MASK_SAMPLES).with_neighbours_lit()
    }

    /// A mask from one flag per pixel, row by row.
    pub fn from_flags(width: u32, height: u32, lit: Vec<bool>, samples_per_pixel: u32) -> Self {
        assert_eq!(lit.len(), width as usize * height as usize, "one flag per pixel");
        LitMask { width, height, lit, samples_per_pixel }
    }

    /// The mask with every pixel next to a lit one (of its eight neighbours) lit too: a light's edge or corner
    /// may cover a sliver of such a pixel that a few rays per pixel miss, and the sliver's rare, bright samples
    /// would then hold most of δ unlit.
    pub fn with_neighbours_lit(self) -> Self {
        use rayon::prelude::*;
        let (w, h) = (self.width as usize, self.height as usize);
        let lit = (0..w * h)
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                (y.saturating_sub(1)..(y + 2).min(h))
                    .any(|ny| (x.saturating_sub(1)..(x + 2).min(w)).any(|nx| self.lit[ny * w + nx]))
            })
            .collect();
        LitMask { lit, ..self }
    }

    /// A mask in which no pixel is lit: δ unlit is then δ over every pixel.
    pub fn none(width: u32, height: u32) -> Self {
        LitMask::from_flags(width, height, vec![false; width as usize * height as usize], 0)
    }

    /// True when pixel `i` sees a light.
    #[inline]
    pub fn is_lit(&self, i: usize) -> bool {
        self.lit[i]
    }

    /// Pixels that see a light.
    pub fn lit_count(&self) -> u64 {
        self.lit.iter().filter(|&&l| l).count() as u64
    }

    /// Pixels of the image.
    pub fn len(&self) -> usize {
        self.lit.len()
    }

    /// True for an image without pixels.
    pub fn is_empty(&self) -> bool {
        self.lit.is_empty()
    }

    /// The flags eight to a byte, pixel i in bit i % 8 of byte i / 8: how a worker sends the mask it decided.
    pub fn to_bits(&self) -> Vec<u8> {
        self.lit.chunks(8).map(|c| c.iter().enumerate().fold(0u8, |b, (i, &l)| b | (u8::from(l) << i))).collect()
    }

    /// The mask `to_bits` gave, for a `width` × `height` image; None unless `bits` is one bit per pixel (with
    /// the last byte's spare bits clear).
    pub fn from_bits(width: u32, height: u32, bits: &[u8], samples_per_pixel: u32) -> Option<Self> {
        let pixels = width as usize * height as usize;
        let spare = (!pixels.is_multiple_of(8)).then(|| bits.last().map_or(0, |b| b >> (pixels % 8)));
        if bits.len() != pixels.div_ceil(8) || spare.is_some_and(|s| s != 0) {
            return None;
        }
        let lit = (0..pixels).map(|i| bits[i / 8] >> (i % 8) & 1 == 1).collect();
        Some(LitMask { width, height, lit, samples_per_pixel })
    }

    /// The summary kept in the run record; deciding the mask took `seconds`.
    pub fn record(&self, seconds: f64) -> LitMaskRecord {
        let lit = self.lit_count();
        LitMaskRecord {
            lit_pixels: lit,
            unlit_pixels: self.len() as u64 - lit,
            samples_per_pixel: self.samples_per_pixel,
            exr_layer: LIT_LAYER.to_string(),
            seconds,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mask_survives_its_bits_and_malformed_bits_are_refused() {
        let flags: Vec<bool> = (0..7 * 3).map(|i| i % 3 == 0 || i == 20).collect();
        let mask = LitMask::from_flags(7, 3, flags, 16);
        let bits = mask.to_bits();
        assert_eq!(bits.len(), 3);
        assert_eq!(LitMask::from_bits(7, 3, &bits, 16), Some(mask.clone()));
        assert_eq!(LitMask::from_bits(7, 4, &bits, 16), None, "too few bytes");
        assert_eq!(LitMask::from_bits(3, 7, &bits[..2], 16), None, "too few bytes");
        let mut spare = bits.clone();
        *spare.last_mut().unwrap() |= 0x80;
        assert_eq!(LitMask::from_bits(7, 3, &spare, 16), None, "a spare bit set");
        assert_eq!(LitMask::from_bits(8, 3, &bits, 16).map(|m| m.lit_count()), Some(mask.lit_count()));
    }

    #[test]
    fn a_lit_pixel_lights_its_eight_neighbours_and_no_pixel_further_away() {
        // 6 × 4 pixels, lit at a corner (0, 0) and inside (4, 2).
        let (w, h) = (6usize, 4usize);
        let mut flags = vec![false; w * h];
        flags[0] = true;
        flags[2 * w + 4] = true;
        let grown = LitMask::from_flags(w as u32, h as u32, flags, 16).with_neighbours_lit();
        let expected = |x: usize, y: usize| (x <= 1 && y <= 1) || ((3..=5).contains(&x) && (1..=3).contains(&y));
        for y in 0..h {
            for x in 0..w {
                assert_eq!(grown.is_lit(y * w + x), expected(x, y), "pixel ({x}, {y})");
            }
        }
        assert_eq!(grown.samples_per_pixel, 16);
    }
}
