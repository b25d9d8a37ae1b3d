//! Auxiliary layers: extra running sums kept beside the fixed `PixelSums`: the ghost layer where a scene can
//! make ghosts, the blur layers every image has, and per-wavelength bands on request. The ghost layer and the
//! bands are overlays of the total, a part of the light the fixed layers already hold, with no squared sums;
//! the blur layers hold the photon discs' measured blur and its square, which δ adds (`super::blur`).

use super::blur::{BLUR_LAYER, BLUR_SQUARES_LAYER};
use super::non_finite::sanitize_slice;
use crate::ghost::GHOST_LAYER;
use crate::scene::ghost::scene_can_make_ghosts;
use crate::scene::Scene;
use crate::spectrum::band_name;
use serde::{Deserialize, Serialize};

/// One auxiliary layer: its name (the EXR layer's) and 1 (grey) or 3 (RGB) channels.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AuxLayer {
    pub name: String,
    pub channels: u8,
}

/// The auxiliary layers of an image in storage order; a pixel's channels are the layers' channels one after
/// the other. Empty for most scenes.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AuxLayout {
    layers: Vec<AuxLayer>,
}

impl AuxLayout {
    /// The layout of these layers.
    ///
    /// Panics on a layer with other than 1 or 3 channels or a repeated name: layouts are made by code, not
    /// read from users.
    pub fn new(layers: Vec<AuxLayer>) -> Self {
        for (i, l) in layers.iter().enumerate() {
            // Snapshot headers store a name's length in a byte; EXR channel names must be printable.
            assert!(
                !l.name.is_empty() && l.name.len() <= 64 && l.name.bytes().all(|b| b.is_ascii_graphic()),
                "auxiliary layer name {:?} is not 1–64 printable ASCII characters",
                l.name
            );
            assert!(l.channels == 1 || l.channels == 3, "auxiliary layer {} has {} channels", l.name, l.channels);
            assert!(layers[..i].iter().all(|o| o.name != l.name), "auxiliary layer {} appears twice", l.name);
        }
        AuxLayout { layers }
    }

    /// The layers a render of `scene` fills: the ghost layer when the scene can make ghosts
    /// (`ghost::scene_can_make_ghosts`), the two blur layers, then `spectral_bands` wavelength
    /// bands (`--spectral-output`, one grey channel each).
    pub fn for_scene(scene: &Scene, spectral_bands: u32) -> Self {
        let mut layers = Vec::new();
        if scene_can_make_ghosts(scene) {
            layers.push(AuxLayer { name: GHOST_LAYER.into(), channels: 3 });
        }
        layers.push(AuxLayer { name: BLUR_LAYER.into(), channels: 1 });
        layers.push(AuxLayer { name: BLUR_SQUARES_LAYER.into(), channels: 1 });
        for b in 0..spectral_bands {
            layers.push(AuxLayer { name: band_name(b, spectral_bands), channels: 1 });
        }
        AuxLayout::new(layers)
    }

    /// Where the first spectral-output band's channel starts, and how many bands there are.
    pub fn bands(&self) -> Option<(usize, usize)> {
        let first = self.layers.iter().position(|l| l.name.starts_with("band_"))?;
        let offset = self.layers[..first].iter().map(|l| l.channels as usize).sum();
        Some((offset, self.layers.len() - first))
    }

    /// The layers, in storage order.
    pub fn layers(&self) -> &[AuxLayer] {
        &self.layers
    }

    /// True when there is no auxiliary layer.
    pub fn is_empty(&self) -> bool {
        self.layers.is_empty()
    }

    /// Channels per pixel over all layers.
    pub fn channels(&self) -> usize {
        self.layers.iter().map(|l| l.channels as usize).sum()
    }

    /// Where the layer `name`'s channels start among a pixel's channels.
    pub fn offset(&self, name: &str) -> Option<usize> {
        let mut offset = 0;
        for l in &self.layers {
            if l.name == name {
                return Some(offset);
            }
            offset += l.channels as usize;
        }
        None
    }

    /// Bytes of the running sums per pixel (f64 per channel).
    pub fn sum_bytes_per_pixel(&self) -> usize {
        8 * self.channels()
    }

    /// Bytes of one f32 per-phase buffer per pixel (an engine keeps one for the camera pass's values and one
    /// for the gathered light).
    pub fn phase_bytes_per_pixel(&self) -> usize {
        4 * self.channels()
    }
}

/// Running f64 sums of the auxiliary layers over a set of pixels, `layout.channels()` values per pixel. A
/// pixel's phase count is its `PixelSums::phases`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AuxSums {
    layout: AuxLayout,
    values: Vec<f64>,
}

impl AuxSums {
    /// Zero sums of `layout` for `pixels` pixels (no memory at all for an empty layout).
    pub fn new(layout: AuxLayout, pixels: usize) -> Self {
        let values = vec![0.0; layout.channels() * pixels];
        AuxSums { layout, values }
    }

    /// The layout.
    pub fn layout(&self) -> &AuxLayout {
        &self.layout
    }

    /// Zeroes the sums and sizes them for `pixels` pixels, keeping the layout (a group's next deal).
    pub fn reset(&mut self, pixels: usize) {
        self.values.clear();
        self.values.resize(self.layout.channels() * pixels, 0.0);
    }

    /// The channels of one pixel.
    pub fn pixel(&self, pixel: usize) -> &[f64] {
        let n = self.layout.channels();
        &self.values[pixel * n..(pixel + 1) * n]
    }

    /// Every pixel's channels, pixel after pixel (for parallel closing and for snapshots).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Every pixel's channels, mutable.
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// Closes one phase at a pixel: adds its value of every auxiliary channel.
    #[inline]
    pub fn add_phase(&mut self, pixel: usize, value: &[f32]) {
        let n = self.layout.channels();
        add_phase_to(&mut self.values[pixel * n..(pixel + 1) * n], value);
    }

    /// Adds the sums of independent phases of the same pixels.
    pub fn merge(&mut self, other: &AuxSums) {
        assert_eq!(self.layout, other.layout, "merging auxiliary sums of different layouts");
        for (a, b) in self.values.iter_mut().zip(&other.values) {
            *a += b;
        }
    }

    /// Adds sums kept for a subset of pixels (`local` pixel i is pixel `mask[i]`).
    pub fn merge_local(&mut self, mask: &[u32], local: &AuxSums) {
        assert_eq!(self.layout, local.layout, "merging auxiliary sums of different layouts");
        let n = self.layout.channels();
        if n == 0 {
            return;
        }
        for (&p, l) in mask.iter().zip(local.values.chunks_exact(n)) {
            for (a, b) in self.values[p as usize * n..(p as usize + 1) * n].iter_mut().zip(l) {
                *a += b;
            }
        }
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.values.capacity() * 8
    }
}

/// Adds one phase's auxiliary values of a pixel to its sums. Like the fixed layers' values, a value with a NaN
/// or an infinity never reaches the sums: it is dropped and counted.
#[inline]
pub fn add_phase_to(sums: &mut [f64], value: &[f32]) {
    debug_assert_eq!(sums.len(), value.len());
    if sanitize_slice(value) {
        for (s, v) in sums.iter_mut().zip(value) {
            *s += *v as f64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> AuxLayout {
        AuxLayout::new(vec![
            AuxLayer { name: "ghost".into(), channels: 3 },
            AuxLayer { name: "band_550".into(), channels: 1 },
        ])
    }

    #[test]
    fn layers_are_laid_out_one_after_the_other() {
        let l = layout();
        assert_eq!(l.channels(), 4);
        assert_eq!((l.offset("ghost"), l.offset("band_550"), l.offset("nope")), (Some(0), Some(3), None));
        assert_eq!(AuxLayout::default().channels(), 0);
        assert_eq!(AuxSums::new(AuxLayout::default(), 1000).capacity_bytes(), 0);
    }

    #[test]
    fn local_sums_merge_into_their_mask_pixels() {
        let mut whole = AuxSums::new(layout(), 3);
        let mut local = AuxSums::new(layout(), 2);
        local.add_phase(0, &[1.0, 2.0, 3.0, 4.0]);
        local.add_phase(1, &[0.5, 0.5, 0.5, 0.5]);
        local.add_phase(1, &[f32::NAN, 0.5, 0.5, 0.5]);
        whole.merge_local(&[2, 0], &local);
        assert_eq!(whole.pixel(2), &[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(whole.pixel(0), &[0.5; 4], "the phase with a NaN was dropped");
        assert_eq!(whole.pixel(1), &[0.0; 4]);
    }

    #[test]
    #[should_panic(expected = "appears twice")]
    fn a_layout_refuses_a_repeated_name() {
        AuxLayout::new(vec![AuxLayer { name: "g".into(), channels: 1 }, AuxLayer { name: "g".into(), channels: 3 }]);
    }
}
