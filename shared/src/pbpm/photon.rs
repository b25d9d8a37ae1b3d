//! The backward photon: where a camera path met a surface with stored lobes, and the filter it applies to
//! light arriving there.

use crate::bsdf::{Bsdf, LobeFlags, Transport};
use crate::color::Rgb;
use glam::Vec3;

/// `BackwardPhoton::stored` of a photon on a Lambertian surface, whose weight already holds f = ρ/π.
pub const LAMBERTIAN: u32 = u32::MAX;

/// A camera-path vertex at a surface with stored lobes, stored for light paths to gather into (paper §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BackwardPhoton {
    pub position: Vec3,
    /// Geometric normal turned toward the side the camera path came from.
    pub normal: Vec3,
    /// τ · f / (π r²), paper eq. 4's factor before the light path's flux ΔΦ, where f is the Lambertian ρ/π; τ /
    /// (π r²) where the photon's BSDF is evaluated at the gather (`stored`).
    pub weight: Rgb,
    /// Squared gather radius.
    pub radius2: f32,
    /// Pixel the camera path belongs to.
    pub pixel: u32,
    /// Which storing vertex of its camera path this is, whether it is the path's first vertex with non-delta
    /// lobes, and whether the path is a ghost path.
    pub kind: PhotonKind,
    /// Camera path segments from the eye to this vertex, for the joined path's `max_depth`.
    pub segments: u8,
    /// 0 when the camera path is RGB; 1 + its wavelength class once it turned spectral, and `weight` then
    /// holds its value at that wavelength in every channel.
    pub spectrum: u8,
    /// The inner disc's share of the gather area (`inner_disc::InnerShare`), for the blur estimate.
    pub inner_share: u8,
    /// `LAMBERTIAN`, or the index of the photon's `StoredVertex` among its map's.
    pub stored: u32,
}

impl BackwardPhoton {
    /// True when the weight already holds the BSDF (a Lambertian surface).
    #[inline]
    pub fn is_lambertian(&self) -> bool {
        self.stored == LAMBERTIAN
    }
}

/// The BSDF of a photon on a surface other than a plain Lambertian one, which a gather evaluates between the
/// camera path's direction and the light path's.
#[derive(Clone, Copy, Debug)]
pub struct StoredVertex {
    pub bsdf: Bsdf,
    /// Points back along the camera path.
    pub wo: Vec3,
}

impl StoredVertex {
    /// f(wo, wi) of the stored lobes for light arriving from `wi`.
    #[inline]
    pub fn eval(&self, wi: Vec3) -> Rgb {
        self.bsdf.eval_stored(self.wo, wi, Transport::Radiance)
    }

    /// True when some lobe of the BSDF transmits: light from behind the surface may reach the camera path.
    #[inline]
    pub fn transmits(&self) -> bool {
        self.bsdf.flags().contains(LobeFlags::TRANSMISSION)
    }
}

/// Where a camera pass puts what it stores: the photons, and the BSDFs the non-Lambertian ones evaluate.
pub struct PhotonLists<'a> {
    pub photons: &'a mut Vec<BackwardPhoton>,
    pub vertices: &'a mut Vec<StoredVertex>,
}

/// Which storing vertex of its camera path a photon is (1 or 2), whether it is the path's first vertex with
/// non-delta lobes (its gathered light can then be a caustic), and whether that path is a ghost path
/// (`crate::ghost`: light gathered there is ghost light too), in one byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhotonKind(u8);

impl PhotonKind {
    const GHOST: u8 = 0x80;
    const FIRST: u8 = 0x40;

    /// The `k`-th storing vertex (below 64) of a camera path, its first non-delta one or not, a ghost path or
    /// not.
    #[inline]
    pub fn new(k: u8, first: bool, ghost: bool) -> Self {
        debug_assert!(k < Self::FIRST, "storing vertex {k}");
        PhotonKind(k | if first { Self::FIRST } else { 0 } | if ghost { Self::GHOST } else { 0 })
    }

    /// Which storing vertex of its camera path the photon is.
    #[inline]
    pub fn k(self) -> u8 {
        self.0 & !(Self::GHOST | Self::FIRST)
    }

    /// True when the photon is its camera path's first vertex with non-delta lobes.
    #[inline]
    pub fn first(self) -> bool {
        self.0 & Self::FIRST != 0
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
    fn a_photon_with_its_kind_inner_share_and_stored_index_is_52_bytes() {
        assert_eq!(std::mem::size_of::<super::BackwardPhoton>(), 52);
    }

    #[test]
    fn a_kind_gives_back_its_depth_first_and_ghost_bits() {
        for (k, first, ghost) in [(1, true, false), (2, false, true), (1, false, true), (2, true, false)] {
            let kind = PhotonKind::new(k, first, ghost);
            assert_eq!((kind.k(), kind.first(), kind.ghost()), (k, first, ghost));
        }
    }
}
