//! The inner disc that measures a photon's blur. Eq. 4 estimates the flux density averaged over the photon's
//! disc, not at its centre, so where the light changes within r a pixel is off by a bias that the spread of its
//! phases cannot show. Every merge is therefore counted a second time, for the photon's inner disc of radius
//! r/√2: the difference D of the two estimates has the expectation b(r) − b(r/√2), where b is the bias at a
//! radius. A pixel's D of each phase goes into the `blur` layers, and `accumulation::blur` turns them into the
//! bias it adds to δ.

use super::BackwardPhoton;

/// The inner disc's r², as a share of the photon's r²: half the disc's area.
pub const INNER_RADIUS2: f32 = 0.5;

/// A merge's part of its pixel's D: the luminance `y` it adds to the whole disc's estimate, less the
/// y · A(r) / A(r/√2) it adds to the inner disc's when it lies there (`d2` is its squared distance from the
/// photon).
#[inline]
pub fn merge_blur(y: f32, d2: f32, photon: &BackwardPhoton) -> f32 {
    if d2 <= photon.radius2 * INNER_RADIUS2 {
        y * (1.0 - 256.0 / photon.inner_share as f32)
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::pbpm::photon::PhotonKind;
    use glam::Vec3;

    #[test]
    fn merges_spread_evenly_over_a_whole_disc_leave_no_blur() {
        // Equal light at every point of a whole disc: the inner disc holds half the merges at twice the
        // weight, so the two estimates agree and D sums to zero.
        let photon = BackwardPhoton {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            weight: Rgb::ONE,
            radius2: 1.0,
            pixel: 0,
            kind: PhotonKind::new(1, true, false),
            segments: 1,
            spectrum: 0,
            inner_share: 128,
            stored: crate::pbpm::photon::LAMBERTIAN,
        };
        let n = 1000;
        let d: f32 = (0..n).map(|i| merge_blur(1.0, (i as f32 + 0.5) / n as f32, &photon)).sum();
        assert!(d.abs() < 1e-3, "{d}");
        // Light only in the outer ring: the inner disc sees none, so D is the whole estimate.
        let ring: f32 = (0..n).map(|i| merge_blur(1.0, 0.5 + (i as f32 + 0.5) / (2 * n) as f32, &photon)).sum();
        assert_eq!(ring, n as f32);
    }
}
