//! A rough interface between two dielectrics: microfacet reflection and refraction (Walter et al. 2007), as
//! Mitsuba 3's `roughdielectric`. A microfacet normal is drawn from the distribution of normals visible from
//! `wo`, then reflection or refraction at it is chosen by its Fresnel reflectance; a camera path's refraction
//! scales radiance by (η_o/η_t)² as the smooth interface does.
//!
//! Mitsuba's parameters: `int_ior` (default 1.5046, BK7), `ext_ior` (default 1.000277, air), `distribution`
//! (`beckmann`, the default, or `ggx`), `alpha` or `alpha_u`/`alpha_v` (default 0.1), `specular_reflectance`
//! and `specular_transmittance` (default 1). Visible-normal sampling is always on (Mitsuba's default).

use super::fresnel::fresnel_dielectric;
use super::microfacet::Microfacet;
use super::{grey_at, refract, stores_glossy, third_uniform, BsdfSample, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::spectrum::{RefractiveIndex, Wavelength};
use glam::{Vec2, Vec3};

/// A rough interface seen from one side: `eta_o` on the side the path arrives from, `eta_t` across it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectric {
    pub eta_o: RefractiveIndex,
    pub eta_t: RefractiveIndex,
    pub microfacet: Microfacet,
    /// A factor on the reflection (Mitsuba's `specular_reflectance`), 1 for a physical interface.
    pub specular_reflectance: Rgb,
    /// A factor on the refraction (Mitsuba's `specular_transmittance`), 1 for a physical interface.
    pub specular_transmittance: Rgb,
}

/// The microfacet normal that turns `wo` into `wi`, on `wo`'s side, and whether the pair is a reflection.
#[inline]
fn half_vector(wo: Vec3, wi: Vec3, eta: f32) -> Option<(Vec3, bool)> {
    let reflect = wi.z > 0.0;
    let h = if reflect { wo + wi } else { wo + wi * eta };
    let len2 = h.length_squared();
    if len2.is_nan() || len2 <= 1e-12 {
        return None;
    }
    let h = h / len2.sqrt();
    Some((if h.z < 0.0 { -h } else { h }, reflect))
}

impl RoughDielectric {
    /// η_t / η_o, as an RGB path sees it (at the d line).
    #[inline]
    fn eta(&self) -> f32 {
        self.eta_t.d / self.eta_o.d
    }

    #[inline]
    fn stored(&self) -> bool {
        stores_glossy(self.microfacet.alpha())
    }

    /// The density of the refracted `wi` per unit density of the half vector: dω_h/dω_i (Walter et al. eq. 17).
    #[inline]
    fn refraction_jacobian(cwo: f32, cwi: f32, eta: f32) -> f32 {
        let denom = cwo + eta * cwi;
        eta * eta * cwi.abs() / (denom * denom)
    }
}

impl Scatter for RoughDielectric {
    #[inline]
    fn flags(&self) -> LobeFlags {
        let class = if self.stored() { LobeFlags::STORED } else { LobeFlags::PASS };
        LobeFlags::GLOSSY | LobeFlags::REFLECTION | LobeFlags::TRANSMISSION | class
    }

    fn eval(&self, wo: Vec3, wi: Vec3, mode: Transport, stored_only: bool) -> Rgb {
        if wo.z <= 0.0 || wi.z == 0.0 || (stored_only && !self.stored()) {
            return Rgb::ZERO;
        }
        let eta = self.eta();
        let Some((h, reflect)) = half_vector(wo, wi, eta) else { return Rgb::ZERO };
        let m = &self.microfacet;
        // G1 is zero where either direction sees the back of the facet.
        let dg = m.d(h) * m.g(wo, wi, h);
        if dg == 0.0 {
            return Rgb::ZERO;
        }
        let (cwo, cwi) = (wo.dot(h), wi.dot(h));
        let f = fresnel_dielectric(cwo, self.eta_o.d, self.eta_t.d);
        if reflect {
            self.specular_reflectance * (f * dg / (4.0 * wo.z * wi.z))
        } else {
            let scale = match mode {
                Transport::Radiance => 1.0 / (eta * eta),
                Transport::Importance => 1.0,
            };
            let denom = cwo + eta * cwi;
            let value = ((1.0 - f) * dg * eta * eta * cwo * cwi / (wo.z * wi.z * denom * denom)).abs();
            self.specular_transmittance * (scale * value)
        }
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        let eta = self.eta();
        let Some((h, reflect)) = half_vector(wo, wi, eta) else { return 0.0 };
        let (cwo, cwi) = (wo.dot(h), wi.dot(h));
        // Sampling never returns a direction that sees the back of its facet.
        if cwo <= 0.0 || cwi * wi.z <= 0.0 {
            return 0.0;
        }
        let f = fresnel_dielectric(cwo, self.eta_o.d, self.eta_t.d);
        let pdf_h = self.microfacet.pdf_visible(wo, h);
        if reflect {
            pdf_h * f / (4.0 * cwi)
        } else {
            pdf_h * (1.0 - f) * Self::refraction_jacobian(cwo, cwi, eta)
        }
    }

    fn sample(&self, wo: Vec3, u: Vec2, mode: Transport) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let m = &self.microfacet;
        let h = m.sample_visible(wo, u);
        let cwo = wo.dot(h);
        if cwo <= 0.0 {
            return None;
        }
        let pdf_h = m.pdf_visible(wo, h);
        let f = fresnel_dielectric(cwo, self.eta_o.d, self.eta_t.d);
        let eta = self.eta();
        // The choice depends on the facet just drawn, so it takes a third number (Mitsuba's `sample1`).
        if third_uniform(u) < f {
            let wi = 2.0 * cwo * h - wo;
            if wi.z <= 0.0 {
                return None;
            }
            let pdf = pdf_h * f / (4.0 * wi.dot(h));
            // f cos θ_i / pdf = G1(wi, h) with visible-normal sampling.
            let weight = self.specular_reflectance * m.g1(wi, h);
            if !(pdf > 0.0 && pdf.is_finite()) {
                return None;
            }
            let lobe = LobeFlags::GLOSSY | LobeFlags::REFLECTION;
            Some(BsdfSample::single_class(wi, weight, pdf, lobe, self.stored()))
        } else {
            let wi = refract(wo, h, 1.0 / eta)?;
            if wi.z >= 0.0 {
                return None;
            }
            let cwi = wi.dot(h);
            let pdf = pdf_h * (1.0 - f) * Self::refraction_jacobian(cwo, cwi, eta);
            if !(pdf > 0.0 && pdf.is_finite()) {
                return None;
            }
            let scale = match mode {
                Transport::Radiance => 1.0 / (eta * eta),
                Transport::Importance => 1.0,
            };
            let weight = self.specular_transmittance * (scale * m.g1(wi, h));
            let lobe = LobeFlags::GLOSSY | LobeFlags::TRANSMISSION;
            let s = BsdfSample::single_class(wi, weight, pdf, lobe, self.stored());
            Some(BsdfSample { radiance_scale: scale, ..s })
        }
    }

    fn is_dispersive(&self) -> bool {
        self.eta_o.is_dispersive() || self.eta_t.is_dispersive()
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        RoughDielectric {
            eta_o: RefractiveIndex::constant(self.eta_o.at(w.nm)),
            eta_t: RefractiveIndex::constant(self.eta_t.at(w.nm)),
            microfacet: self.microfacet,
            specular_reflectance: grey_at(self.specular_reflectance, w),
            specular_transmittance: grey_at(self.specular_transmittance, w),
        }
    }
}
