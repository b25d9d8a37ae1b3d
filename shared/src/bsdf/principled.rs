//! Mitsuba 3's `principled` BSDF (Burley's "Physically Based Shading at Disney", 2012, extended to
//! transmission in 2015), the material that Blender scenes arrive with. Its lobes, as Mitsuba writes them:
//!
//! - a diffuse lobe (1 − metallic)(1 − spec_trans) · base_color / π · (Burley's diffuse with retro-reflection,
//!   blended toward the Hanrahan–Krueger "fake subsurface" by `flatness`), and a sheen lobe on top of it;
//! - a GGX specular reflection whose Fresnel term blends the dielectric's (weighted by (1 − metallic)
//!   (1 − spec_tint)), a Schlick term of base_color (weighted by metallic) and a Schlick term tinted toward
//!   base_color (weighted by (1 − metallic) spec_tint);
//! - a GGX transmission (1 − metallic) spec_trans · √base_color · (1 − F) as a rough dielectric refracts;
//! - a clearcoat: a GTR1 lobe of roughness lerp(0.1, 0.001, clearcoat_gloss) with a Schlick Fresnel of
//!   F₀ = 0.04, weighted by clearcoat / 4 and, as in Mitsuba, without the 1 / (4 cos θ_o cos θ_i) of a
//!   microfacet lobe.
//!
//! From inside (the back of the surface, reached only through transmission) it reflects and refracts with the
//! dielectric's Fresnel term alone, weighted by (1 − metallic) spec_trans. Sampling picks the diffuse lobe,
//! the clearcoat and the specular lobes with probabilities ∝ (1 − metallic)(1 − spec_trans) ·
//! `diffuse_reflectance_sampling_rate`, clearcoat / 4 · `clearcoat_sampling_rate` and
//! `main_specular_sampling_rate`, and among the specular lobes reflection or refraction by the Fresnel term of
//! the sampled normal, all as Mitsuba does.
//!
//! Mitsuba's parameters and defaults: `base_color` 0.5, `roughness` 0.5, `anisotropic` 0, `metallic` 0,
//! `spec_trans` 0, `eta` (interior over exterior) or `specular` 0.5 (η = 2 / (1 − √(0.08 specular)) − 1, so
//! 0.5 gives 1.5), `spec_tint` 0, `sheen` 0, `sheen_tint` 0, `flatness` 0, `clearcoat` 0, `clearcoat_gloss` 0,
//! and the three sampling rates 1. Mitsuba's scalar variants evaluate the sheen only where the diffuse lobe is
//! on ((1 − metallic)(1 − spec_trans) > 0); so does this one.

use super::fresnel::fresnel_dielectric;
use super::microfacet::{Distribution, Microfacet};
use super::{grey_at, refract, stores_glossy, third_uniform, BsdfSample, ByClass, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::sampling::cosine_hemisphere;
use crate::spectrum::Wavelength;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// The parameters of a principled surface at one point, with Mitsuba's names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipledParams {
    pub base_color: Rgb,
    pub roughness: f32,
    pub anisotropic: f32,
    pub metallic: f32,
    pub spec_trans: f32,
    /// Interior over exterior index.
    pub eta: f32,
    pub spec_tint: f32,
    pub sheen: f32,
    pub sheen_tint: f32,
    pub flatness: f32,
    pub clearcoat: f32,
    pub clearcoat_gloss: f32,
    pub diffuse_reflectance_sampling_rate: f32,
    pub main_specular_sampling_rate: f32,
    pub clearcoat_sampling_rate: f32,
}

impl Default for PrincipledParams {
    /// Mitsuba's defaults.
    fn default() -> Self {
        PrincipledParams {
            base_color: Rgb::splat(0.5),
            roughness: 0.5,
            anisotropic: 0.0,
            metallic: 0.0,
            spec_trans: 0.0,
            eta: eta_of_specular(0.5),
            spec_tint: 0.0,
            sheen: 0.0,
            sheen_tint: 0.0,
            flatness: 0.0,
            clearcoat: 0.0,
            clearcoat_gloss: 0.0,
            diffuse_reflectance_sampling_rate: 1.0,
            main_specular_sampling_rate: 1.0,
            clearcoat_sampling_rate: 1.0,
        }
    }
}

/// Mitsuba's η for a `specular` value: 2 / (1 − √(0.08 specular)) − 1 (the index whose normal reflectance is
/// 0.08 specular).
pub fn eta_of_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (0.08 * specular).sqrt()) - 1.0
}

/// Mitsuba's luminance of a linear RGB colour (its weights, which differ from Rec. 709's in the fourth digit).
#[inline]
fn luminance(c: Rgb) -> f32 {
    0.212_671 * c.x + 0.715_16 * c.y + 0.072_169 * c.z
}

/// The principled BSDF at one point, seen from the side the path arrived from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Principled {
    pub base_color: Rgb,
    /// base_color / its luminance (1 for black): the tint of `spec_tint` and `sheen_tint`.
    pub tint: Rgb,
    /// √base_color, the transmission's colour.
    pub sqrt_base: Rgb,
    pub roughness: f32,
    /// The main specular lobes' GGX distribution (Burley's mapping: α = roughness², stretched by anisotropy).
    pub microfacet: Microfacet,
    pub metallic: f32,
    pub spec_trans: f32,
    pub eta: f32,
    pub spec_tint: f32,
    pub sheen: f32,
    pub sheen_tint: f32,
    pub flatness: f32,
    pub clearcoat: f32,
    /// The clearcoat's GTR1 roughness, lerp(0.1, 0.001, clearcoat_gloss).
    pub clearcoat_alpha: f32,
    /// The sampling rates of the diffuse, main specular and clearcoat lobes.
    pub rates: [f32; 3],
    /// True when the path arrived from inside the material (the back of the surface).
    pub inside: bool,
}

/// The Schlick weight (1 − cos)⁵.
#[inline]
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// The weight w of Schlick's reflectance r0 + (1 − r0) w for light arriving at cos (> 0) from the side of
/// relative index η = η_t/η_i: (1 − cos)⁵, or (1 − cos θ_t)⁵ of the transmitted angle where η ≤ 1, as Mitsuba's
/// `calc_schlick`.
#[inline]
fn schlick(cos: f32, eta: f32) -> f32 {
    if eta > 1.0 {
        schlick_weight(cos.abs())
    } else {
        let cos_t2 = 1.0 - (1.0 - cos * cos) / (eta * eta);
        schlick_weight(cos_t2.max(0.0).sqrt())
    }
}

/// GTR1's density of normals D(m) (per projected area) for roughness α, as Mitsuba's clearcoat.
#[inline]
fn gtr1_d(m: Vec3, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let d = (a2 - 1.0) / (PI * a2.ln() * (1.0 + (a2 - 1.0) * m.z * m.z));
    if d * m.z > 1e-20 {
        d
    } else {
        0.0
    }
}

/// A GTR1 normal drawn with density D(m) cos θ_m.
#[inline]
fn gtr1_sample(u: Vec2, alpha: f32) -> Vec3 {
    let a2 = alpha * alpha;
    let (sin_phi, cos_phi) = (2.0 * PI * u.x).sin_cos();
    let cos2 = ((1.0 - a2.powf(1.0 - u.y)) / (1.0 - a2)).max(0.0);
    let sin = (1.0 - cos2).max(0.0).sqrt();
    Vec3::new(cos_phi * sin, sin_phi * sin, cos2.sqrt())
}

/// The clearcoat's separable GGX masking with its fixed α = 0.25, as Mitsuba's `smith_ggx1`.
#[inline]
fn smith_ggx1(v: Vec3, h: Vec3) -> f32 {
    if v.dot(h) * v.z <= 0.0 {
        return 0.0;
    }
    if v.z == 1.0 {
        return 1.0;
    }
    let c2 = v.z * v.z;
    let tan2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + 0.0625 * tan2).sqrt())
}

/// Which lobe a sample takes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Lobe {
    Diffuse,
    Clearcoat,
    Specular,
}

impl Principled {
    /// The BSDF of `p` seen from outside (`inside` false) or from inside.
    pub fn new(p: &PrincipledParams, inside: bool) -> Self {
        let r2 = p.roughness * p.roughness;
        let aspect = (1.0 - 0.9 * p.anisotropic).max(0.0).sqrt();
        let (ax, ay) = ((r2 / aspect).max(0.001), (r2 * aspect).max(0.001));
        let lum = luminance(p.base_color);
        let tint = if lum > 0.0 { p.base_color / lum } else { Rgb::ONE };
        Principled {
            base_color: p.base_color,
            tint,
            sqrt_base: p.base_color.max(Rgb::ZERO).powf(0.5),
            roughness: p.roughness,
            microfacet: Microfacet::new(Distribution::Ggx, ax, ay),
            metallic: p.metallic,
            spec_trans: p.spec_trans,
            eta: p.eta,
            spec_tint: p.spec_tint,
            sheen: p.sheen,
            sheen_tint: p.sheen_tint,
            flatness: p.flatness,
            clearcoat: p.clearcoat,
            clearcoat_alpha: 0.1 + (0.001 - 0.1) * p.clearcoat_gloss,
            rates: [p.diffuse_reflectance_sampling_rate, p.main_specular_sampling_rate, p.clearcoat_sampling_rate],
            inside,
        }
    }

    /// The weights of the diffuse (BRDF) and transmitting (BSDF) major lobes.
    #[inline]
    fn weights(&self) -> (f32, f32) {
        let dielectric = 1.0 - self.metallic;
        (dielectric * (1.0 - self.spec_trans), dielectric * self.spec_trans)
    }

    /// η_t / η_o for the path.
    #[inline]
    fn eta_path(&self) -> f32 {
        if self.inside {
            1.0 / self.eta
        } else {
            self.eta
        }
    }

    /// True when the main specular lobes are stored.
    #[inline]
    fn specular_stored(&self) -> bool {
        stores_glossy(self.microfacet.alpha())
    }

    /// The probabilities of picking the diffuse lobe, the clearcoat and the specular lobes, or None where the
    /// surface scatters nothing (the inside of a material that transmits nothing).
    #[inline]
    fn lobe_probabilities(&self) -> Option<[f32; 3]> {
        let (brdf, bsdf) = self.weights();
        if self.inside {
            return (bsdf > 0.0).then_some([0.0, 0.0, 1.0]);
        }
        let d = brdf * self.rates[0];
        let c = 0.25 * self.clearcoat * self.rates[2];
        let s = self.rates[1];
        let total = d + c + s;
        (total > 0.0 && total.is_finite()).then(|| [d / total, c / total, s / total])
    }

    /// The share of the specular lobes' probability that reflection takes, for a facet of Fresnel reflectance f.
    #[inline]
    fn p_reflect(&self, f: f32) -> f32 {
        let (_, bsdf) = self.weights();
        if self.inside {
            f
        } else {
            1.0 - bsdf * (1.0 - f)
        }
    }

    /// The non-delta BSDF and densities at the pair, by lobe class.
    fn by_class(&self, wo: Vec3, wi: Vec3, mode: Transport) -> ByClass {
        let mut out = ByClass::default();
        if wo.z <= 0.0 || wi.z == 0.0 {
            return out;
        }
        let Some([p_diffuse, p_clearcoat, p_specular]) = self.lobe_probabilities() else { return out };
        let (brdf, bsdf) = self.weights();
        let front = !self.inside;
        let eta = self.eta_path();
        let reflect = wi.z > 0.0;
        let h = if reflect { wo + wi } else { wo + wi * eta };
        let len2 = h.length_squared();
        if len2.is_nan() || len2 <= 1e-12 {
            return out;
        }
        let h = h / len2.sqrt();
        let h = if h.z < 0.0 { -h } else { h };
        let (cwo, cwi) = (wo.dot(h), wi.dot(h));
        // The facet must face both directions (reflection) or face `wo` and turn its back to `wi` (refraction).
        let facing = cwo > 0.0 && if reflect { cwi > 0.0 } else { cwi < 0.0 };
        let m = &self.microfacet;
        let f_dielectric = fresnel_dielectric(cwo, 1.0, eta);
        let specular_stored = self.specular_stored();
        let mut specular_f = Rgb::ZERO;
        let mut specular_pdf = 0.0;
        if facing {
            let pdf_h = m.pdf_visible(wo, h);
            let dg = m.d(h) * m.g(wo, wi, h);
            if reflect {
                if f_dielectric > 0.0 && dg > 0.0 {
                    let fresnel = if front {
                        let dielectric = (1.0 - self.metallic) * (1.0 - self.spec_tint) * f_dielectric;
                        let w = schlick(cwo, self.eta);
                        let metal = (self.base_color + (Rgb::ONE - self.base_color) * w) * self.metallic;
                        let r0 = self.tint * ((eta - 1.0) / (eta + 1.0)).powi(2);
                        let tinted = (r0 + (Rgb::ONE - r0) * w) * ((1.0 - self.metallic) * self.spec_tint);
                        Rgb::splat(dielectric) + metal + tinted
                    } else {
                        Rgb::splat(bsdf * f_dielectric)
                    };
                    specular_f = fresnel * (dg / (4.0 * wo.z * wi.z));
                }
                specular_pdf = p_specular * self.p_reflect(f_dielectric) * pdf_h / (4.0 * cwi);
            } else if bsdf > 0.0 {
                let denom = cwo + eta * cwi;
                let jacobian = eta * eta * cwi.abs() / (denom * denom);
                if f_dielectric < 1.0 && dg > 0.0 {
                    let scale = match mode {
                        Transport::Radiance => 1.0 / (eta * eta),
                        Transport::Importance => 1.0,
                    };
                    let value = (1.0 - f_dielectric) * dg * jacobian * cwo / (wo.z * wi.z.abs());
                    specular_f = self.sqrt_base * (bsdf * scale * value);
                }
                specular_pdf = p_specular * (1.0 - self.p_reflect(f_dielectric)) * pdf_h * jacobian;
            }
        }
        if specular_stored {
            out.stored_f += specular_f;
            out.stored_pdf += specular_pdf;
        } else {
            out.pass_f += specular_f;
            out.pass_pdf += specular_pdf;
        }
        if front && reflect {
            if self.clearcoat > 0.0 && facing {
                let fresnel = 0.04 + 0.96 * schlick(cwo, self.eta);
                let d = gtr1_d(h, self.clearcoat_alpha);
                let g = smith_ggx1(wo, h) * smith_ggx1(wi, h);
                out.pass_f += Rgb::splat(0.25 * self.clearcoat * fresnel * d * g);
                out.pass_pdf += p_clearcoat * d * h.z / (4.0 * cwi);
            }
            if brdf > 0.0 {
                let (fo, fi) = (schlick_weight(wi.z), schlick_weight(wo.z));
                let diffuse = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
                let cos_d = h.dot(wi);
                let rr = 2.0 * self.roughness * cos_d * cos_d;
                let retro = rr * (fo + fi + fo * fi * (rr - 1.0));
                let mut shape = diffuse + retro;
                if self.flatness != 0.0 {
                    let fss90 = rr / 2.0;
                    let fss = (1.0 + (fss90 - 1.0) * fo) * (1.0 + (fss90 - 1.0) * fi);
                    let subsurface = 1.25 * (fss * (1.0 / (wo.z + wi.z) - 0.5) + 0.5);
                    shape += (subsurface - shape) * self.flatness;
                }
                out.stored_f += self.base_color * (brdf * FRAC_1_PI * shape);
                if self.sheen > 0.0 && self.metallic < 1.0 {
                    let tint = Rgb::ONE + (self.tint - Rgb::ONE) * self.sheen_tint;
                    out.stored_f += tint * (self.sheen * (1.0 - self.metallic) * schlick_weight(cos_d.abs()));
                }
                out.stored_pdf += p_diffuse * wi.z * FRAC_1_PI;
            }
        }
        out
    }
}

impl Scatter for Principled {
    fn flags(&self) -> LobeFlags {
        let (brdf, bsdf) = self.weights();
        if self.inside && bsdf <= 0.0 {
            return LobeFlags::NONE;
        }
        let mut flags = LobeFlags::GLOSSY | LobeFlags::REFLECTION;
        let diffuse = !self.inside && brdf > 0.0;
        let clearcoat = !self.inside && self.clearcoat > 0.0;
        if bsdf > 0.0 {
            flags = flags | LobeFlags::TRANSMISSION;
        }
        if diffuse {
            flags = flags | LobeFlags::DIFFUSE;
        }
        if diffuse || self.specular_stored() {
            flags = flags | LobeFlags::STORED;
        }
        if clearcoat || !self.specular_stored() {
            flags = flags | LobeFlags::PASS;
        }
        flags
    }

    fn eval(&self, wo: Vec3, wi: Vec3, mode: Transport, stored_only: bool) -> Rgb {
        self.by_class(wo, wi, mode).f(stored_only)
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.by_class(wo, wi, Transport::Radiance).pdf()
    }

    fn pdf_stored(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.by_class(wo, wi, Transport::Radiance).stored_pdf
    }

    fn sample(&self, wo: Vec3, u: Vec2, mode: Transport) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let [p_diffuse, p_clearcoat, p_specular] = self.lobe_probabilities()?;
        // u.x picks the lobe and, rescaled, draws its direction with u.y.
        let (lobe, x) = if u.x < p_diffuse {
            (Lobe::Diffuse, u.x / p_diffuse)
        } else if u.x < p_diffuse + p_clearcoat {
            (Lobe::Clearcoat, (u.x - p_diffuse) / p_clearcoat)
        } else {
            (Lobe::Specular, (u.x - p_diffuse - p_clearcoat) / p_specular)
        };
        let v = Vec2::new(x.clamp(0.0, 1.0 - f32::EPSILON / 2.0), u.y);
        let (wi, flags, stored, scale) = match lobe {
            Lobe::Diffuse => (cosine_hemisphere(v), LobeFlags::DIFFUSE | LobeFlags::REFLECTION, true, 1.0),
            Lobe::Clearcoat => {
                let h = gtr1_sample(v, self.clearcoat_alpha);
                (2.0 * wo.dot(h) * h - wo, LobeFlags::GLOSSY | LobeFlags::REFLECTION, false, 1.0)
            }
            Lobe::Specular => {
                let h = self.microfacet.sample_visible(wo, v);
                let cwo = wo.dot(h);
                if cwo <= 0.0 {
                    return None;
                }
                let eta = self.eta_path();
                let f = fresnel_dielectric(cwo, 1.0, eta);
                let stored = self.specular_stored();
                // The split depends on the facet just drawn: it takes a third number.
                if third_uniform(u) < self.p_reflect(f) {
                    (2.0 * cwo * h - wo, LobeFlags::GLOSSY | LobeFlags::REFLECTION, stored, 1.0)
                } else {
                    let scale = match mode {
                        Transport::Radiance => 1.0 / (eta * eta),
                        Transport::Importance => 1.0,
                    };
                    (refract(wo, h, 1.0 / eta)?, LobeFlags::GLOSSY | LobeFlags::TRANSMISSION, stored, scale)
                }
            }
        };
        let reflects = flags.contains(LobeFlags::REFLECTION);
        if (wi.z > 0.0) != reflects || wi.z == 0.0 {
            return None;
        }
        self.by_class(wo, wi, mode).sample(wi, flags, stored, scale)
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        Principled {
            base_color: grey_at(self.base_color, w),
            tint: grey_at(self.tint, w),
            sqrt_base: grey_at(self.sqrt_base, w),
            ..*self
        }
    }
}
