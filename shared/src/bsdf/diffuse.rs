//! The Lambertian diffuse reflector: f = ρ/π, sampled by the cosine.

use super::{grey_at, BsdfSample, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::sampling::cosine_hemisphere;
use crate::spectrum::Wavelength;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// A Lambertian surface of reflectance ρ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    pub reflectance: Rgb,
}

impl Scatter for Diffuse {
    #[inline]
    fn flags(&self) -> LobeFlags {
        LobeFlags::DIFFUSE | LobeFlags::REFLECTION | LobeFlags::STORED
    }

    #[inline]
    fn eval(&self, _wo: Vec3, wi: Vec3, _mode: Transport, _stored_only: bool) -> Rgb {
        if wi.z > 0.0 {
            self.reflectance * FRAC_1_PI
        } else {
            Rgb::ZERO
        }
    }

    #[inline]
    fn pdf(&self, _wo: Vec3, wi: Vec3) -> f32 {
        if wi.z > 0.0 {
            wi.z * FRAC_1_PI
        } else {
            0.0
        }
    }

    #[inline]
    fn sample(&self, _wo: Vec3, u: Vec2, _mode: Transport) -> Option<BsdfSample> {
        if self.reflectance == Rgb::ZERO {
            return None;
        }
        let wi = cosine_hemisphere(u);
        if wi.z <= 0.0 {
            return None;
        }
        // f cos / pdf = (ρ/π) cos / (cos/π) = ρ, exactly.
        let lobe = LobeFlags::DIFFUSE | LobeFlags::REFLECTION;
        Some(BsdfSample::single_class(wi, self.reflectance, wi.z * FRAC_1_PI, lobe, true))
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        Diffuse { reflectance: grey_at(self.reflectance, w) }
    }
}
