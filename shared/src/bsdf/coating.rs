//! A thin partially reflecting coating (a head-up display's combiner): specular reflection with a
//! reflectance, straight-through transmission with a transmittance, the rest absorbed, the same from both sides.

use super::{grey_at, BsdfSample, DeltaBranches, LobeFlags, Scatter, Transport};
use crate::color::{luminance, Rgb};
use crate::spectrum::Wavelength;
use glam::{Vec2, Vec3};

/// A coating that reflects `reflectance` and transmits `transmittance` of the light, both specularly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coating {
    pub reflectance: Rgb,
    pub transmittance: Rgb,
}

impl Coating {
    /// The probability of reflecting: the reflected share of the luminance that is not absorbed.
    #[inline]
    fn p_reflect(&self) -> Option<f32> {
        let (lr, lt) = (luminance(self.reflectance), luminance(self.transmittance));
        (lr + lt > 0.0).then(|| lr / (lr + lt))
    }

    /// Both delta continuations for `wo` with the probability `sample` picks each.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let mut branches = DeltaBranches::default();
        let Some(p) = self.p_reflect() else { return branches };
        if p > 0.0 {
            let r = BsdfSample::specular(Vec3::new(-wo.x, -wo.y, wo.z), self.reflectance / p, LobeFlags::REFLECTION);
            branches.push(r, p);
        }
        if p < 1.0 {
            let t = BsdfSample::specular(-wo, self.transmittance / (1.0 - p), LobeFlags::TRANSMISSION);
            branches.push(t, 1.0 - p);
        }
        branches
    }
}

impl Scatter for Coating {
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

    #[inline]
    fn sample(&self, wo: Vec3, u: Vec2, _mode: Transport) -> Option<BsdfSample> {
        let p = self.p_reflect()?;
        if u.x < p {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            Some(BsdfSample::specular(wi, self.reflectance / p, LobeFlags::REFLECTION))
        } else {
            Some(BsdfSample::specular(-wo, self.transmittance / (1.0 - p), LobeFlags::TRANSMISSION))
        }
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        Coating { reflectance: grey_at(self.reflectance, w), transmittance: grey_at(self.transmittance, w) }
    }
}
