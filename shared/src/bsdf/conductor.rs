//! Conductors (metals): a smooth mirror, or a rough surface of microfacets (Beckmann or GGX, isotropic or
//! anisotropic, sampled by their visible normals), with the Fresnel reflectance of a complex index of
//! refraction η + i k (or none: a perfect mirror), times an optional specular reflectance.

use super::fresnel::fresnel_conductor_rgb;
use super::metals::{self, UnknownMetal};
use super::microfacet::Microfacet;
use super::{grey_at, stores_glossy, BsdfSample, DeltaBranches, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::spectrum::Wavelength;
use glam::{Vec2, Vec3};

/// How much a conductor reflects at each angle.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ConductorFresnel {
    /// Everything, at every angle: an ideal mirror.
    Perfect,
    /// The Fresnel reflectance of the complex index η + i k relative to the outside medium, per channel.
    Complex { eta: Rgb, k: Rgb },
}

impl ConductorFresnel {
    /// The conductor called `name` in Mitsuba 3's table (`super::metals`, Mitsuba's `material` parameter), in
    /// air; `none` is the perfect mirror, as in Mitsuba. An unknown name's error lists the known ones.
    pub fn named(name: &str) -> Result<Self, UnknownMetal> {
        if name == "none" {
            return Ok(ConductorFresnel::Perfect);
        }
        let (eta, k) = metals::index_of(name).ok_or_else(|| UnknownMetal { name: name.to_string() })?;
        Ok(ConductorFresnel::Complex { eta, k })
    }

    /// The reflectance at cos θ.
    #[inline]
    pub fn at(&self, cos: f32) -> Rgb {
        match *self {
            ConductorFresnel::Perfect => Rgb::ONE,
            ConductorFresnel::Complex { eta, k } => fresnel_conductor_rgb(cos, eta, k),
        }
    }
}

/// A conductor: `fresnel` times `specular` reflected into the mirror direction, or spread by `roughness`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor {
    pub fresnel: ConductorFresnel,
    /// A factor on the reflectance (Mitsuba's `specular_reflectance`), 1 for a physical metal.
    pub specular: Rgb,
    /// None for a smooth surface.
    pub roughness: Option<Microfacet>,
}

impl Conductor {
    /// A perfect mirror that reflects `reflectance` (a scene's `mirror`).
    pub fn mirror(reflectance: Rgb) -> Self {
        Conductor { fresnel: ConductorFresnel::Perfect, specular: reflectance, roughness: None }
    }

    /// True when photons gather this conductor's lobe.
    #[inline]
    fn stored(&self) -> bool {
        self.roughness.is_some_and(|m| stores_glossy(m.alpha()))
    }

    /// The mirror branch of a smooth conductor, with probability 1; none for a rough one.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let mut branches = DeltaBranches::default();
        if self.roughness.is_none() {
            if let Some(s) = self.sample(wo, Vec2::ZERO, Transport::Radiance) {
                branches.push(s, 1.0);
            }
        }
        branches
    }
}

impl Scatter for Conductor {
    #[inline]
    fn flags(&self) -> LobeFlags {
        match self.roughness {
            None => LobeFlags::SPECULAR | LobeFlags::REFLECTION,
            Some(_) if self.stored() => LobeFlags::GLOSSY | LobeFlags::REFLECTION | LobeFlags::STORED,
            Some(_) => LobeFlags::GLOSSY | LobeFlags::REFLECTION | LobeFlags::PASS,
        }
    }

    fn eval(&self, wo: Vec3, wi: Vec3, _mode: Transport, stored_only: bool) -> Rgb {
        let Some(m) = self.roughness else { return Rgb::ZERO };
        if wo.z <= 0.0 || wi.z <= 0.0 || (stored_only && !self.stored()) {
            return Rgb::ZERO;
        }
        let h = (wo + wi).normalize();
        // f = F(wo·h) D(h) G(wo, wi, h) / (4 cos θ_o cos θ_i)
        let dg = m.d(h) * m.g(wo, wi, h);
        if dg == 0.0 {
            return Rgb::ZERO;
        }
        self.fresnel.at(wo.dot(h)) * self.specular * (dg / (4.0 * wo.z * wi.z))
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let Some(m) = self.roughness else { return 0.0 };
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize();
        // The visible-normal density of h over the reflection's Jacobian 4 (wi·h).
        m.pdf_visible(wo, h) / (4.0 * wi.dot(h))
    }

    fn sample(&self, wo: Vec3, u: Vec2, _mode: Transport) -> Option<BsdfSample> {
        let Some(m) = self.roughness else {
            let cos = wo.z.abs();
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample::specular(wi, self.fresnel.at(cos) * self.specular, LobeFlags::REFLECTION));
        };
        if wo.z <= 0.0 {
            return None;
        }
        let h = m.sample_visible(wo, u);
        let wi = 2.0 * wo.dot(h) * h - wo;
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = m.pdf_visible(wo, h) / (4.0 * wi.dot(h));
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        // f cos θ_i / pdf = F G1(wi, h) with visible-normal sampling.
        let weight = self.fresnel.at(wo.dot(h)) * self.specular * m.g1(wi, h);
        let lobe = LobeFlags::GLOSSY | LobeFlags::REFLECTION;
        Some(BsdfSample::single_class(wi, weight, pdf, lobe, self.stored()))
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        let fresnel = match self.fresnel {
            ConductorFresnel::Perfect => ConductorFresnel::Perfect,
            ConductorFresnel::Complex { eta, k } => {
                ConductorFresnel::Complex { eta: grey_at(eta, w), k: grey_at(k, w) }
            }
        };
        Conductor { fresnel, specular: grey_at(self.specular, w), roughness: self.roughness }
    }
}
