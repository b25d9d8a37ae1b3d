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
    /// Which diffuse vertex of its camera path this is, and whether the path is a ghost path.
    pub kind: PhotonKind,
    /// Camera path segments from the eye to this vertex, for the joined path's `max_depth`.
    pub segments: u8,
    /// 0 when the camera path is RGB; 1 + its wavelength class once it turned spectral, and `weight` then
    /// holds its value at that wavelength in every channel.
    pub spectrum: u8,
    /// The inner disc's share of the gather area (`inner_disc::InnerShare`), for the blur estimate.
    pub inner_share: u8,
}

/// Which diffuse vertex of its camera path a photon is (1 or 2), and whether that path is a ghost path
/// (`crate::ghost`: light gathered there is ghost light too), in one byte so that a photon stays 48 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhotonKind(u8);

impl PhotonKind {
    const GHOST: u8 = 0x80;

    /// The `k`-th diffuse vertex (below 128) of a camera path that is a ghost path or not.
    #[inline]
    pub fn new(k: u8, ghost: bool) -> Self {
        debug_assert!(k < Self::GHOST, "diffuse vertex {k}");
        PhotonKind(k & !Self::GHOST | if ghost { Self::GHOST } else { 0 })
    }

    /// Which diffuse vertex of its camera path the photon is.
    #[inline]
    pub fn k(self) -> u8 {
        self.0 & !Self::GHOST
    }

    /// True when the camera path is a ghost path.
    #[inline]
    pub fn ghost(self) -> bool {
        self.0 & Self::GHOST != 0
    }
}

#[cfg(test)]
mod tests {
    use super::PhotonKind;

    #[test]
    fn a_photon_with_its_kind_and_inner_share_stays_48_bytes() {
        assert_eq!(std::mem::size_of::<super::BackwardPhoton>(), 48);
    }

    #[test]
    fn a_kind_gives_back_its_depth_and_ghost_bit() {
        for (k, ghost) in [(1, false), (2, true), (1, true), (2, false)] {
            let kind = PhotonKind::new(k, ghost);
            assert_eq!((kind.k(), kind.ghost()), (k, ghost));
        }
    }
}
