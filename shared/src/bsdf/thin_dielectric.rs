//! A thin dielectric pane, as Mitsuba 3's `thindielectric`: a sheet of glass so thin that its two faces are one
//! surface. Light reflects specularly or passes straight through, with the reflections inside the pane summed:
//! with the Fresnel reflectance R of one face and T = 1 − R, the pane reflects R' = R + T²R / (1 − R²) = 2R / (1 + R)
//! and transmits 1 − R', the same from both sides.
//!
//! Mitsuba's parameters: `int_ior` (default 1.5046, BK7), `ext_ior` (default 1.000277, air),
//! `specular_reflectance` and `specular_transmittance` (default 1, factors on the two lobes).

use super::fresnel::fresnel_dielectric;
use super::{grey_at, BsdfSample, DeltaBranches, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::spectrum::{RefractiveIndex, Wavelength};
use glam::{Vec2, Vec3};

/// A pane of index `int_ior` in a medium of index `ext_ior`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinDielectric {
    pub int_ior: RefractiveIndex,
    pub ext_ior: RefractiveIndex,
    /// A factor on the reflected light (Mitsuba's `specular_reflectance`), 1 for a physical pane.
    pub specular_reflectance: Rgb,
    /// A factor on the transmitted light (Mitsuba's `specular_transmittance`), 1 for a physical pane.
    pub specular_transmittance: Rgb,
}

impl ThinDielectric {
    /// The pane's reflectance R' = 2R / (1 + R) for light arriving at `wo`, which is also the probability of
    /// sampling the reflection.
    #[inline]
    pub fn reflectance(&self, wo: Vec3) -> f32 {
        let r = fresnel_dielectric(wo.z.abs().min(1.0), self.ext_ior.d, self.int_ior.d);
        2.0 * r / (1.0 + r)
    }

    /// Both delta continuations for `wo` with the probability `sample` picks each.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let r = self.reflectance(wo);
        let mut branches = DeltaBranches::default();
        for (u, p) in [(0.0, r), (1.0 - f32::EPSILON / 2.0, 1.0 - r)] {
            if p > 0.0 {
                if let Some(s) = self.sample(wo, Vec2::new(u, 0.5), Transport::Radiance) {
                    branches.push(s, p);
                }
            }
        }
        branches
    }
}

impl Scatter for ThinDielectric {
    #[inline]
    fn flags(&self) -> LobeFlags {
        LobeFlags::SPECULAR | LobeFlags::REFLECTION | LobeFlags::TRANSMISSION
    }

    #[inline]
    fn eval(&self, _: Vec3, _: Vec3, _: Transport, _: bool) -> Rgb {
        Rgb::ZERO
    }

    #[inline]
    fn pdf(&self, _: Vec3, _: Vec3) -> f32 {
        0.0
    }

    /// Reflects with probability R' (Mitsuba's choice), else passes straight through; both weigh their factor.
    #[inline]
    fn sample(&self, wo: Vec3, u: Vec2, _mode: Transport) -> Option<BsdfSample> {
        let r = self.reflectance(wo);
        if u.x < r {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            Some(BsdfSample::specular(wi, self.specular_reflectance, LobeFlags::REFLECTION))
        } else {
            // Straight through: the two refractions of a parallel pane cancel, so radiance keeps its scale.
            Some(BsdfSample::specular(-wo, self.specular_transmittance, LobeFlags::TRANSMISSION))
        }
    }

    fn is_dispersive(&self) -> bool {
        self.int_ior.is_dispersive() || self.ext_ior.is_dispersive()
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        ThinDielectric {
            int_ior: RefractiveIndex::constant(self.int_ior.at(w.nm)),
            ext_ior: RefractiveIndex::constant(self.ext_ior.at(w.nm)),
            specular_reflectance: grey_at(self.specular_reflectance, w),
            specular_transmittance: grey_at(self.specular_transmittance, w),
        }
    }
}
