//! The backward photon: where a camera path met a diffuse surface, and the filter it applies to light arriving
//! there.

use crate::color::Rgb;
use glam::Vec3;

/// A camera-path vertex at a diffuse surface, stored for light paths to gather into (paper §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BackwardPhoton {
    pub position: Vec3,
    /// Geometric normal turned toward the side the camera path came from.
    pub normal: Vec3,
    /// τ · f / (π r²): paper eq. 4's factor before the light path's flux ΔΦ; f is the Lambertian ρ/π.
    pub weight: Rgb,
    /// Squared gather radius.
    pub radius2: f32,
    /// Pixel the camera path belongs to.
    pub pixel: u32,
    /// Which diffuse vertex of its camera path this is (1 or 2).
    pub k: u8,
    /// Camera path segments from the eye to this vertex, for the joined path's `max_depth`.
    pub segments: u8,
    /// 0 when the camera path is RGB; 1 + its wavelength class once it turned spectral, and `weight` then
    /// holds its value at that wavelength in every channel.
    pub spectrum: u8,
    /// The camera path is a ghost path (`crate::ghost`): light gathered here is ghost light too. With
    /// `spectrum` it fills the padding, so a photon stays 48 bytes.
    pub ghost: bool,
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_ghost_bit_fits_in_the_photons_padding() {
        assert_eq!(std::mem::size_of::<super::BackwardPhoton>(), 48);
    }
}
