//! The smooth dielectric interface: Fresnel reflection and refraction between two indices that may vary with
//! wavelength (dispersion), with an ideal anti-reflection coating as an option.

use super::fresnel::fresnel_dielectric;
use super::{BsdfSample, DeltaBranches, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::spectrum::{RefractiveIndex, Wavelength};
use glam::{Vec2, Vec3};

/// How a dielectric chooses between reflection and refraction (`Dielectric::sample_reflecting`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reflection {
    /// With the Fresnel reflectance F, as light does.
    Fresnel,
    /// With probability max(F, q).
    AtLeast(f32),
    /// Never: the path refracts with weight 1 − F, and ends where total internal reflection leaves it no
    /// refraction.
    Never,
}

/// A smooth interface seen from one side: `eta_o` on the side the path arrives from, `eta_t` across it. With
/// `anti_reflection` the surface has an ideal coating: it refracts everything except under total internal
/// reflection (a lens without ghosts, to compare with the uncoated one). Either index may vary with
/// wavelength; a path not yet resolved to a wavelength (an RGB path) sees them at the d line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    pub eta_o: RefractiveIndex,
    pub eta_t: RefractiveIndex,
    pub anti_reflection: bool,
}

impl Dielectric {
    /// The cosine of `wo` and the probability of reflection (1 under total internal reflection).
    #[inline]
    fn reflectance(&self, wo: Vec3) -> (f32, f32) {
        let cos_o = wo.z.clamp(-1.0, 1.0).abs();
        let f = fresnel_dielectric(cos_o, self.eta_o.d, self.eta_t.d);
        // A coating cannot undo total internal reflection (f = 1): there is no transmitted wave.
        let f = if self.anti_reflection && f < 1.0 { 0.0 } else { f };
        (cos_o, f)
    }

    /// `sample` that chooses between reflection and refraction by `choice` rather than by the Fresnel
    /// reflectance F, weighting the choice by F / q or (1 − F) / (1 − q) so that the estimate stays unbiased: a
    /// sampler that looks for reflections inside a lens finds them without changing what they are worth.
    pub fn sample_reflecting(&self, wo: Vec3, u: Vec2, mode: Transport, choice: Reflection) -> Option<BsdfSample> {
        let (cos_o, f) = self.reflectance(wo);
        let q = match choice {
            // Total internal reflection leaves no refraction to take.
            Reflection::Never if f >= 1.0 => return None,
            Reflection::Never => 0.0,
            _ if f >= 1.0 => f,
            Reflection::Fresnel => f,
            Reflection::AtLeast(q) => f.max(q),
        };
        if u.x < q {
            let weight = if q == f { Rgb::ONE } else { Rgb::splat(f / q) };
            let tir = if f >= 1.0 { LobeFlags::TOTAL_INTERNAL } else { LobeFlags::NONE };
            Some(BsdfSample::specular(Vec3::new(-wo.x, -wo.y, wo.z), weight, LobeFlags::REFLECTION | tir))
        } else {
            let eta = self.eta_o.d / self.eta_t.d;
            let sin2_t = eta * eta * (1.0 - cos_o * cos_o);
            let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
            let wi = (-wo * eta + Vec3::Z * (eta * cos_o - cos_t)).normalize();
            // Radiance is not invariant across an interface, L/η² is: the camera side sees the far side's
            // radiance scaled by (η_o/η_t)². Flux (importance transport) needs no factor.
            let scale = match mode {
                Transport::Radiance => eta * eta,
                Transport::Importance => 1.0,
            };
            let choice = if q == f { 1.0 } else { (1.0 - f) / (1.0 - q) };
            let s = BsdfSample::specular(wi, Rgb::splat(scale * choice), LobeFlags::TRANSMISSION);
            Some(BsdfSample { radiance_scale: scale, ..s })
        }
    }

    /// Both delta continuations for `wo` with the probability `sample` picks each.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let p_reflect = self.reflectance(wo).1;
        let mut branches = DeltaBranches::default();
        // `sample` reflects when u.x < F and refracts otherwise.
        for (u, p) in [(0.0, p_reflect), (1.0 - f32::EPSILON / 2.0, 1.0 - p_reflect)] {
            if p > 0.0 {
                if let Some(s) = self.sample(wo, Vec2::new(u, 0.5), Transport::Radiance) {
                    branches.push(s, p);
                }
            }
        }
        branches
    }
}

impl Scatter for Dielectric {
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
    fn sample(&self, wo: Vec3, u: Vec2, mode: Transport) -> Option<BsdfSample> {
        self.sample_reflecting(wo, u, mode, Reflection::Fresnel)
    }

    fn is_dispersive(&self) -> bool {
        self.eta_o.is_dispersive() || self.eta_t.is_dispersive()
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        Dielectric {
            eta_o: RefractiveIndex::constant(self.eta_o.at(w.nm)),
            eta_t: RefractiveIndex::constant(self.eta_t.at(w.nm)),
            anti_reflection: self.anti_reflection,
        }
    }
}
