//! Running sums over phases and the error estimate δ (paper eq. 6–7). Sums from independent workers add, so
//! whoever merges them computes δ over the merged sums.

pub mod auxiliary;
pub mod blur;
pub mod delta;
pub mod lit_mask;
mod non_finite;

pub use auxiliary::{AuxLayer, AuxLayout, AuxSums};
pub use lit_mask::{ErrorOver, LitMask, LitMaskRecord, LIT_LAYER};
pub use non_finite::non_finite_dropped;

use crate::color::{luminance, luminance_f64, Rgb};
use crate::ghost::GHOST_LAYER;
use crate::integrator::{Layer, LayerValues};
use crate::sampling::REPLICATES;
use non_finite::sanitize;
use serde::{Deserialize, Serialize};

/// The sums one pixel keeps (paper §2's layers, in f64 as the final image needs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PixelSums {
    /// Σ_j L_ij per layer and RGB channel.
    pub sum: [[f64; 3]; 4],
    /// Σ_j L_ij² of each layer's luminance, then of the total's.
    pub sum_sq: [f64; 5],
    /// Σ_j of the total's luminance over the phases of each replicate of the pixel's quasi-random sequences.
    pub replicate_sum: [f64; REPLICATES],
    /// Phases closed at this pixel.
    pub phases: u32,
    /// Camera rays started at this pixel.
    pub camera_rays: u32,
    /// Phases of each replicate.
    pub replicate_phases: [u32; REPLICATES],
}

impl PixelSums {
    /// Closes one phase drawn from `replicate`: adds the phase value L_ij of every layer and the squared
    /// luminance of each layer and of the total.
    #[inline]
    pub fn add_phase(&mut self, value: &LayerValues, camera_rays: u32, replicate: usize) {
        let mut total = Rgb::ZERO;
        for (l, v) in value.iter().enumerate() {
            let v = sanitize(*v);
            total += v;
            for c in 0..3 {
                self.sum[l][c] += v[c] as f64;
            }
            let y = luminance(v) as f64;
            self.sum_sq[l] += y * y;
        }
        let y = luminance(total) as f64;
        self.sum_sq[4] += y * y;
        self.replicate_sum[replicate] += y;
        self.replicate_phases[replicate] += 1;
        self.phases += 1;
        self.camera_rays += camera_rays;
    }

    /// Adds the sums of independent phases of the same pixel.
    pub fn merge(&mut self, other: &PixelSums) {
        for l in 0..4 {
            for c in 0..3 {
                self.sum[l][c] += other.sum[l][c];
            }
        }
        for i in 0..5 {
            self.sum_sq[i] += other.sum_sq[i];
        }
        for r in 0..REPLICATES {
            self.replicate_sum[r] += other.replicate_sum[r];
            self.replicate_phases[r] += other.replicate_phases[r];
        }
        self.phases += other.phases;
        self.camera_rays += other.camera_rays;
    }
}

/// The running sums of a whole image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accumulator {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<PixelSums>,
    /// Sums of the auxiliary layers (overlays of the total, no SEM); empty unless the scene needs them.
    pub aux: AuxSums,
}

/// δ over the image and over the pixels that do not see a light directly: the noise of paper eq. 6 and the
/// photon discs' measured blur (`blur`), as √(noise² + blur²).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorEstimate {
    /// δ over every pixel (dominated by directly visible lights).
    pub delta_all: f64,
    /// δ restricted to the pixels the run's `LitMask` leaves unlit: the figure stopping rules use.
    pub delta_unlit: f64,
    /// The blur's part of `delta_all`, relative to the image as δ is (0 where nothing is gathered).
    #[serde(default)]
    pub blur_all: f64,
    /// The blur's part of `delta_unlit`.
    #[serde(default)]
    pub blur_unlit: f64,
    /// Fewest phases at any pixel (δ needs at least two).
    pub min_phases: u32,
}

impl Accumulator {
    /// Empty sums for an image, without auxiliary layers.
    pub fn new(width: u32, height: u32) -> Self {
        Accumulator::with_aux(width, height, AuxLayout::default())
    }

    /// Empty sums for an image with the auxiliary layers of `aux`.
    pub fn with_aux(width: u32, height: u32, aux: AuxLayout) -> Self {
        let n = width as usize * height as usize;
        Accumulator { width, height, pixels: vec![PixelSums::default(); n], aux: AuxSums::new(aux, n) }
    }

    /// Closes one phase drawn from `replicate` at one pixel: adds the phase value L_ij of every layer and of
    /// the total.
    #[inline]
    pub fn add_phase(&mut self, pixel: usize, value: &LayerValues, camera_rays: u32, replicate: usize) {
        self.pixels[pixel].add_phase(value, camera_rays, replicate);
    }

    /// Adds sums kept for a subset of pixels (a group's mask: `local[i]` and `local_aux`'s pixel i belong to
    /// pixel `mask[i]`).
    pub fn merge_local(&mut self, mask: &[u32], local: &[PixelSums], local_aux: &AuxSums) {
        for (&p, l) in mask.iter().zip(local) {
            self.pixels[p as usize].merge(l);
        }
        self.aux.merge_local(mask, local_aux);
    }

    /// Adds another worker's sums for the same image.
    pub fn merge(&mut self, other: &Accumulator) {
        assert_eq!((self.width, self.height), (other.width, other.height), "merging sums of different images");
        for (a, b) in self.pixels.iter_mut().zip(&other.pixels) {
            a.merge(b);
        }
        self.aux.merge(&other.aux);
    }

    /// Mean of one layer at a pixel.
    pub fn mean(&self, pixel: usize, layer: Layer) -> [f64; 3] {
        let px = &self.pixels[pixel];
        let n = px.phases.max(1) as f64;
        let s = px.sum[layer as usize];
        [s[0] / n, s[1] / n, s[2] / n]
    }

    /// Mean of an auxiliary layer at a pixel (a one-channel layer as grey), None when the image has no such
    /// layer.
    pub fn aux_mean(&self, pixel: usize, name: &str) -> Option<[f64; 3]> {
        let layout = self.aux.layout();
        let offset = layout.offset(name)?;
        let channels = layout.layers().iter().find(|l| l.name == name)?.channels;
        Some(self.aux_mean_at(pixel, offset, channels))
    }

    /// `aux_mean` of the layer of `channels` channels at `offset` in the auxiliary layout, found once for many
    /// pixels.
    #[inline]
    pub fn aux_mean_at(&self, pixel: usize, offset: usize, channels: u8) -> [f64; 3] {
        let n = self.pixels[pixel].phases.max(1) as f64;
        let s = &self.aux.pixel(pixel)[offset..offset + channels as usize];
        if channels == 3 {
            [s[0] / n, s[1] / n, s[2] / n]
        } else {
            [s[0] / n; 3]
        }
    }

    /// Mean of the total at a pixel.
    pub fn mean_total(&self, pixel: usize) -> [f64; 3] {
        let mut t = [0.0; 3];
        for l in Layer::ALL {
            let m = self.mean(pixel, l);
            for c in 0..3 {
                t[c] += m[c];
            }
        }
        t
    }

    /// Squared standard error of the mean of the total luminance at a pixel from its phases as independent
    /// samples (paper eq. 7). Phases of one quasi-random sequence are not independent: their mean is usually
    /// more accurate than this says, so δ uses `replicate_sem2`; this per-pixel figure, with all its phases'
    /// degrees of freedom, is the steadier one for per-pixel comparisons and the SEM layer.
    pub fn sem2(&self, pixel: usize) -> f64 {
        let px = &self.pixels[pixel];
        if px.phases < 2 {
            return f64::INFINITY;
        }
        let n = px.phases as f64;
        let mean = luminance_f64(self.mean_total(pixel));
        ((px.sum_sq[4] / n - mean * mean) / n).max(0.0)
    }

    /// Squared standard error of the mean of the total luminance at a pixel from the spread of its replicate
    /// means, which are independent (random groups: SEM² = Σ_r (m_r − m̄)² / (R (R − 1)) over the R replicates
    /// that have phases). It replaces eq. 7 where phases share a quasi-random sequence; with pseudo-random
    /// phases both estimate the same variance.
    pub fn replicate_sem2(&self, pixel: usize) -> f64 {
        let px = &self.pixels[pixel];
        if px.phases < 2 {
            return f64::INFINITY;
        }
        let mut means = [0.0; REPLICATES];
        let mut r = 0;
        for (s, &n) in px.replicate_sum.iter().zip(&px.replicate_phases) {
            if n > 0 {
                means[r] = s / n as f64;
                r += 1;
            }
        }
        if r < 2 {
            // Every phase came from one replicate (a merge of renderers that skipped the others): only the
            // per-phase spread is left.
            return self.sem2(pixel);
        }
        let means = &means[..r];
        let mean = means.iter().sum::<f64>() / r as f64;
        means.iter().map(|m| (m - mean) * (m - mean)).sum::<f64>() / (r * (r - 1)) as f64
    }

    /// Phases per pixel, averaged over the image: the work the sums hold, whichever masks it was rendered over.
    pub fn image_phases(&self) -> f64 {
        let total: u64 = self.pixels.iter().map(|p| p.phases as u64).sum();
        total as f64 / self.pixels.len().max(1) as f64
    }

    /// Fewest phases at any pixel (0 for an image without pixels).
    pub fn min_phases(&self) -> u32 {
        self.pixels.iter().map(|p| p.phases).min().unwrap_or(0)
    }

    /// δ over all pixels and over the pixels `lit` does not mark as seeing a light: paper eq. 6 with
    /// `replicate_sem2` for the SEM², plus each pixel's estimated squared blur (`blur::pixel_bias2`) where the
    /// image keeps the blur layers.
    pub fn error(&self, lit: &LitMask) -> ErrorEstimate {
        assert_eq!(lit.len(), self.pixels.len(), "a lit mask of another image");
        let blur_offsets = blur::blur_offsets(self.aux.layout());
        let (mut noise_all, mut blur_all, mut den_all) = (0.0, 0.0, 0.0);
        let (mut noise_unlit, mut blur_unlit, mut den_unlit) = (0.0, 0.0, 0.0);
        for i in 0..self.pixels.len() {
            let l = luminance_f64(self.mean_total(i));
            let s = self.replicate_sem2(i);
            let b = self.blur2_at(blur_offsets, i);
            noise_all += s;
            blur_all += b;
            den_all += l * l;
            if !lit.is_lit(i) {
                noise_unlit += s;
                blur_unlit += b;
                den_unlit += l * l;
            }
        }
        // The squared blur is summed unbiased, so noise can take it below zero where there is no blur.
        let (blur_all, blur_unlit) = (blur_all.max(0.0), blur_unlit.max(0.0));
        let ratio = |n: f64, d: f64| if d > 0.0 { (n / d).sqrt() } else { f64::INFINITY };
        ErrorEstimate {
            delta_all: ratio(noise_all + blur_all, den_all),
            delta_unlit: ratio(noise_unlit + blur_unlit, den_unlit),
            blur_all: ratio(blur_all, den_all),
            blur_unlit: ratio(blur_unlit, den_unlit),
            min_phases: self.min_phases(),
        }
    }

    /// Each pixel's estimated squared blur (`blur::pixel_bias2`), pixel by index, and that estimate's variance
    /// where there is no blur (`blur::pixel_bias2_noise`). The estimate is unbiased and so sometimes negative,
    /// to be summed over pixels before clamping; both are zero when the image keeps no blur layers.
    pub fn blur2_by_pixel(&self) -> impl Fn(usize) -> (f64, f64) + '_ {
        let offsets = blur::blur_offsets(self.aux.layout());
        move |pixel| {
            let noise = offsets.map_or(0.0, |(d, d2)| {
                let aux = self.aux.pixel(pixel);
                blur::pixel_bias2_noise(self.pixels[pixel].phases, aux[d], aux[d2])
            });
            (self.blur2_at(offsets, pixel), noise)
        }
    }

    #[inline]
    fn blur2_at(&self, offsets: Option<(usize, usize)>, pixel: usize) -> f64 {
        offsets.map_or(0.0, |(d, d2)| {
            let aux = self.aux.pixel(pixel);
            blur::pixel_bias2(self.pixels[pixel].phases, aux[d], aux[d2])
        })
    }

    /// Σ over pixels of the luminance of the ghost layer's sums and of the total's sums (sums, not means: their
    /// differences between two moments are the image sums of the phases in between). None without a ghost layer.
    pub fn ghost_luminance_sums(&self) -> Option<(f64, f64)> {
        let offset = self.aux.layout().offset(GHOST_LAYER)?;
        let (mut ghost, mut total) = (0.0, 0.0);
        for p in 0..self.pixels.len() {
            let g = &self.aux.pixel(p)[offset..offset + 3];
            ghost += luminance_f64([g[0], g[1], g[2]]);
            total += self.pixels[p].sum.iter().map(|l| luminance_f64(*l)).sum::<f64>();
        }
        Some((ghost, total))
    }

    /// Bytes of the sums per pixel with the auxiliary layers of `aux`.
    pub fn bytes_per_pixel(aux: &AuxLayout) -> usize {
        std::mem::size_of::<PixelSums>() + aux.sum_bytes_per_pixel()
    }
}

/// Relative RMSE of `image` against `reference` in luminance, over the pixels `include` selects: the true
/// error that δ estimates.
pub fn relative_rmse(image: &[[f64; 3]], reference: &[[f64; 3]], include: impl Fn(usize) -> bool) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for i in 0..image.len().min(reference.len()) {
        if !include(i) {
            continue;
        }
        let a = luminance_f64(image[i]);
        let b = luminance_f64(reference[i]);
        num += (a - b) * (a - b);
        den += b * b;
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        f64::INFINITY
    }
}

/// The image's luminance summed over the included pixels relative to the reference's, minus one: a systematic
/// bias (density estimation losing light along edges) shows here long after the noise has averaged out.
pub fn relative_mean_difference(image: &[[f64; 3]], reference: &[[f64; 3]], include: impl Fn(usize) -> bool) -> f64 {
    let (mut a, mut b) = (0.0, 0.0);
    for i in (0..image.len().min(reference.len())).filter(|&i| include(i)) {
        a += luminance_f64(image[i]);
        b += luminance_f64(reference[i]);
    }
    if b > 0.0 {
        a / b - 1.0
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sem_of_known_samples_matches_the_textbook_formula() {
        let mut acc = Accumulator::new(1, 1);
        let samples = [1.0f32, 2.0, 3.0, 6.0];
        for (j, s) in samples.into_iter().enumerate() {
            acc.add_phase(0, &[Rgb::ZERO, Rgb::splat(s), Rgb::ZERO, Rgb::ZERO], 1, j % REPLICATES);
        }
        // Luminance of grey s is s. Population variance of {1,2,3,6} = 3.5, SEM² = 3.5 / 4.
        assert!((acc.sem2(0) - 3.5 / 4.0).abs() < 1e-6);
        // One phase per replicate: the replicate means are the samples, SEM² = Σ (x − 3)² / (4 · 3) = 14 / 12.
        assert!((acc.replicate_sem2(0) - 14.0 / 12.0).abs() < 1e-6);
        let e = acc.error(&LitMask::none(1, 1));
        assert!((e.delta_all - (14.0f64 / 12.0).sqrt() / 3.0).abs() < 1e-6);
        assert_eq!(e.min_phases, 4);
    }

    #[test]
    fn merged_sums_equal_sums_of_all_phases() {
        let v = |x: f32| [Rgb::splat(x), Rgb::ZERO, Rgb::splat(2.0 * x), Rgb::ZERO];
        let mut a = Accumulator::new(2, 1);
        let mut b = Accumulator::new(2, 1);
        let mut all = Accumulator::new(2, 1);
        for (i, x) in [0.5f32, 1.5, 2.5, 4.0].iter().enumerate() {
            if i % 2 == 0 { &mut a } else { &mut b }.add_phase(1, &v(*x), 1, i % REPLICATES);
            all.add_phase(1, &v(*x), 1, i % REPLICATES);
        }
        a.merge(&b);
        assert_eq!(a, all);
    }

    #[test]
    fn non_finite_samples_never_reach_the_sums() {
        let mut acc = Accumulator::new(1, 1);
        acc.add_phase(0, &[Rgb::splat(f32::NAN), Rgb::splat(f32::INFINITY), Rgb::ONE, Rgb::ZERO], 1, 0);
        assert!(acc.pixels[0].sum.iter().flatten().all(|v| v.is_finite()));
        assert_eq!(acc.mean_total(0), [1.0, 1.0, 1.0]);
    }

    #[test]
    fn unlit_delta_is_computed_over_the_pixels_the_mask_leaves_unlit_whatever_their_samples() {
        let mut acc = Accumulator::new(3, 1);
        for (j, x) in [1.0f32, 3.0].into_iter().enumerate() {
            acc.add_phase(0, &[Rgb::splat(100.0), Rgb::ZERO, Rgb::ZERO, Rgb::ZERO], 1, j);
            acc.add_phase(1, &[Rgb::ZERO, Rgb::splat(x), Rgb::ZERO, Rgb::ZERO], 1, j);
            // Pixel 2 sees a light through glass in its first phase only: the mask keeps it lit anyway.
            let light = if j == 0 { 50.0 } else { 0.0 };
            acc.add_phase(2, &[Rgb::splat(light), Rgb::splat(x), Rgb::ZERO, Rgb::ZERO], 1, j);
        }
        let mask = LitMask::from_flags(3, 1, vec![true, false, true], 16);
        let e = acc.error(&mask);
        // Pixel 1 alone: replicate means 1 and 3, SEM² = (1 + 1) / (2 · 1) = 1.
        assert!((e.delta_unlit - 1.0 / 2.0).abs() < 1e-9);
        assert!(e.delta_all < e.delta_unlit);
        // Over a mask without lit pixels δ unlit is δ over all of them.
        let none = acc.error(&LitMask::none(3, 1));
        assert_eq!(none.delta_unlit, none.delta_all);
    }
}
