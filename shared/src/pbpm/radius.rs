//! The photon radius: from the pixel footprint at the photon, shrunk per phase as Knaus & Zwicker (2011)
//! prescribe so that the average over phases converges.

/// Radius schedule r_j = r_1 · j^((α−1)/2) with r_1 = scale × pixel footprint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadiusSchedule {
    /// Initial radius in pixel footprints.
    pub scale: f32,
    /// Knaus–Zwicker α in (0, 1): the fraction of the variance-to-bias trade kept per phase.
    pub alpha: f32,
    /// Angle of one pixel (radians).
    pub pixel_angle: f32,
}

impl RadiusSchedule {
    /// The radius of a photon at camera-path length `path_length` (m) in phase `phase` (1-based).
    #[inline]
    pub fn radius(&self, path_length: f32, phase: u64) -> f32 {
        let r1 = self.scale * self.pixel_angle * path_length;
        r1 * self.shrink(phase)
    }

    /// r_j / r_1 = j^((α−1)/2).
    #[inline]
    pub fn shrink(&self, phase: u64) -> f32 {
        (phase.max(1) as f32).powf((self.alpha - 1.0) * 0.5)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radius_area_shrinks_as_j_to_alpha_minus_one() {
        let s = RadiusSchedule { scale: 2.0, alpha: 2.0 / 3.0, pixel_angle: 0.01 };
        let r1 = s.radius(1.5, 1);
        assert!((r1 - 0.03).abs() < 1e-7);
        let r8 = s.radius(1.5, 8);
        assert!(((r8 * r8) / (r1 * r1) - 8f32.powf(-1.0 / 3.0)).abs() < 1e-5);
    }
}
