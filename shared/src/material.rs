//! Materials and their scattering: the Lambertian diffuse surface, where photons are stored and gathered, and
//! the delta (specular) surfaces that camera and light paths follow by sampling.

use crate::color::{luminance, Rgb};
use crate::geometry::SurfaceHit;
use crate::sampling::{cosine_hemisphere, Frame};
use crate::spectrum::{Dispersive, RefractiveIndex, Wavelength};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// A surface's scattering behaviour. Emission is a property of the object, not of the material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian reflector, two-sided.
    Diffuse { albedo: Rgb },
    /// Ideal specular reflector, two-sided.
    Mirror { reflectance: Rgb },
    /// Smooth dielectric interface with Fresnel reflection and refraction; `ior` on the back side of the
    /// surface normal (inside), `ext_ior` on the front (outside). With `anti_reflection` the surface has an ideal
    /// anti-reflection coating: it refracts everything except under total internal reflection (a lens without
    /// ghosts, to compare with the uncoated one). Either index may vary with wavelength (dispersion).
    Dielectric { ior: RefractiveIndex, ext_ior: RefractiveIndex, anti_reflection: bool },
    /// A thin partially reflecting coating (e.g. a head-up display combiner): specular reflection with
    /// `reflectance`, straight-through transmission with `transmittance`, the rest absorbed.
    Coating { reflectance: Rgb, transmittance: Rgb },
}

/// Which quantity a path carries across a scattering event: camera paths carry radiance (they are adjoint to
/// light flow), light paths carry flux (importance transport). Veach's thesis §5.2 gives the two rules.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    Radiance,
    Importance,
}

/// How a dielectric chooses between reflection and refraction (`Material::sample_reflecting`).
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

/// The sampled continuation of a path at a surface.
#[derive(Clone, Copy, Debug)]
pub struct ScatterSample {
    /// New direction, pointing away from the surface.
    pub wi: Vec3,
    /// f · |cos| / pdf, including the transport-mode corrections.
    pub weight: Rgb,
    /// Solid-angle pdf for non-delta sampling (MIS needs it); zero for delta events.
    pub pdf: f32,
    /// True for specular (delta) events.
    pub delta: bool,
    /// The (η_o/η_t)² factor that `weight` holds for a camera path refracted across an interface (1 otherwise):
    /// it rescales radiance rather than losing energy, so Russian roulette must not read it as a loss.
    pub radiance_scale: f32,
}

impl ScatterSample {
    /// A delta event in direction `wi` with weight `weight` that rescales no radiance.
    fn specular(wi: Vec3, weight: Rgb) -> Self {
        ScatterSample { wi, weight, pdf: 0.0, delta: true, radiance_scale: 1.0 }
    }
}

impl Material {
    /// True when scattering is a Dirac delta: such vertices are followed, never used for photons or NEE.
    pub fn is_delta(&self) -> bool {
        !matches!(self, Material::Diffuse { .. })
    }

    /// The Lambertian albedo, for diffuse surfaces.
    pub fn diffuse_albedo(&self) -> Option<Rgb> {
        match self {
            Material::Diffuse { albedo } => Some(*albedo),
            _ => None,
        }
    }

    /// Samples an incident direction for outgoing direction `wo` (unit, pointing away from the surface).
    /// Returns None when the path is absorbed or would leave through the wrong side of the geometry.
    pub fn sample(&self, hit: &SurfaceHit, wo: Vec3, u: Vec2, mode: Transport) -> Option<ScatterSample> {
        self.sample_reflecting(hit, wo, u, mode, Reflection::Fresnel)
    }

    /// `sample` that chooses between reflection and refraction at a dielectric by `choice` rather than by the
    /// Fresnel reflectance F, weighting the choice by F / q or (1 − F) / (1 − q) so that the estimate stays
    /// unbiased: a sampler that looks for reflections inside a lens finds them without changing what they are
    /// worth. Other materials sample as `sample` does.
    pub fn sample_reflecting(
        &self,
        hit: &SurfaceHit,
        wo: Vec3,
        u: Vec2,
        mode: Transport,
        choice: Reflection,
    ) -> Option<ScatterSample> {
        let front = wo.dot(hit.ng) >= 0.0;
        // Normals turned to the side wo lies on: every material here is two-sided or handles sides itself.
        let (ng, ns) = if front { (hit.ng, hit.ns) } else { (-hit.ng, -hit.ns) };
        let sample = match *self {
            Material::Diffuse { albedo } => {
                if albedo == Rgb::ZERO {
                    return None;
                }
                let local = cosine_hemisphere(u);
                let wi = Frame::from_normal(ns).to_world(local);
                if wi.dot(ng) <= 0.0 || local.z <= 0.0 {
                    return None;
                }
                ScatterSample { wi, weight: albedo, pdf: local.z * FRAC_1_PI, delta: false, radiance_scale: 1.0 }
            }
            Material::Mirror { reflectance } => ScatterSample::specular(reflect(wo, ns), reflectance),
            Material::Coating { reflectance, transmittance } => {
                let (lr, lt) = (luminance(reflectance), luminance(transmittance));
                if lr + lt <= 0.0 {
                    return None;
                }
                let p_reflect = lr / (lr + lt);
                if u.x < p_reflect {
                    ScatterSample::specular(reflect(wo, ns), reflectance / p_reflect)
                } else {
                    ScatterSample::specular(-wo, transmittance / (1.0 - p_reflect))
                }
            }
            Material::Dielectric { ior, ext_ior, anti_reflection } => {
                let (eta_o, eta_t, cos_o, f) = dielectric_reflectance(ior, ext_ior, anti_reflection, front, wo, ns);
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
                    ScatterSample::specular(reflect(wo, ns), weight)
                } else {
                    let eta = eta_o / eta_t;
                    let sin2_t = eta * eta * (1.0 - cos_o * cos_o);
                    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
                    let wi = (-wo * eta + ns * (eta * cos_o - cos_t)).normalize();
                    // Radiance is not invariant across an interface, L/η² is: the camera side sees the far
                    // side's radiance scaled by (η_o/η_t)². Flux (importance transport) needs no factor.
                    let scale = match mode {
                        Transport::Radiance => eta * eta,
                        Transport::Importance => 1.0,
                    };
                    let choice = if q == f { 1.0 } else { (1.0 - f) / (1.0 - q) };
                    ScatterSample { radiance_scale: scale, ..ScatterSample::specular(wi, Rgb::splat(scale * choice)) }
                }
            }
        };
        if mode == Transport::Importance {
            // Shading normals make BSDFs non-reciprocal; the adjoint carries this factor (Veach §5.3).
            let num = wo.dot(hit.ns).abs() * sample.wi.dot(hit.ng).abs();
            let den = wo.dot(hit.ng).abs() * sample.wi.dot(hit.ns).abs();
            if den <= 0.0 {
                return None;
            }
            return Some(ScatterSample { weight: sample.weight * (num / den), ..sample });
        }
        Some(sample)
    }
}

impl Material {
    /// Every continuation a delta event can take for outgoing direction `wo`, with the probability that
    /// `sample` picks it: a reflection, a transmission, or both. Empty at a diffuse surface. Lets a caller
    /// follow every specular branch of a camera path instead of sampling one.
    pub fn delta_branches(&self, hit: &SurfaceHit, wo: Vec3) -> Vec<(ScatterSample, f32)> {
        let front = wo.dot(hit.ng) >= 0.0;
        let p_reflect = match *self {
            Material::Diffuse { .. } => return Vec::new(),
            Material::Mirror { .. } => 1.0,
            Material::Coating { reflectance, transmittance } => {
                let (lr, lt) = (luminance(reflectance), luminance(transmittance));
                if lr + lt <= 0.0 {
                    return Vec::new();
                }
                lr / (lr + lt)
            }
            Material::Dielectric { ior, ext_ior, anti_reflection } => {
                let ns = if front { hit.ns } else { -hit.ns };
                dielectric_reflectance(ior, ext_ior, anti_reflection, front, wo, ns).3
            }
        };
        // `sample` reflects when u.x < p_reflect and transmits otherwise.
        let mut branches = Vec::with_capacity(2);
        for (u, p) in [(0.0, p_reflect), (1.0 - f32::EPSILON / 2.0, 1.0 - p_reflect)] {
            if p > 0.0 {
                if let Some(s) = self.sample(hit, wo, Vec2::new(u, 0.5), Transport::Radiance) {
                    branches.push((s, p));
                }
            }
        }
        branches
    }
}

/// A dielectric interface seen from the side of `wo` (`front` of the geometric normal, `ns` the shading normal
/// turned to that side): the indices on either side, the cosine of `wo` and the probability of reflection.
fn dielectric_reflectance(
    ior: RefractiveIndex,
    ext_ior: RefractiveIndex,
    anti_reflection: bool,
    front: bool,
    wo: Vec3,
    ns: Vec3,
) -> (f32, f32, f32, f32) {
    // A dispersive index not yet resolved to a wavelength (an RGB path) acts at the d line.
    let (eta_o, eta_t) = if front { (ext_ior.d, ior.d) } else { (ior.d, ext_ior.d) };
    let cos_o = wo.dot(ns).clamp(-1.0, 1.0).abs();
    let f = fresnel_dielectric(cos_o, eta_o, eta_t);
    // A coating cannot undo total internal reflection (f = 1): there is no transmitted wave.
    let f = if anti_reflection && f < 1.0 { 0.0 } else { f };
    (eta_o, eta_t, cos_o, f)
}

impl Dispersive for Material {
    /// True when the material's behaviour depends on wavelength: a path that meets it becomes spectral.
    fn is_dispersive(&self) -> bool {
        matches!(self, Material::Dielectric { ior, ext_ior, .. } if ior.is_dispersive() || ext_ior.is_dispersive())
    }

    /// The material as a path at one wavelength sees it: colours read at the wavelength (the same value in
    /// every channel), indices evaluated there.
    fn at_wavelength(&self, w: &Wavelength) -> Material {
        let v = |c: Rgb| Rgb::splat(w.value_of(c));
        match *self {
            Material::Diffuse { albedo } => Material::Diffuse { albedo: v(albedo) },
            Material::Mirror { reflectance } => Material::Mirror { reflectance: v(reflectance) },
            Material::Coating { reflectance, transmittance } => {
                Material::Coating { reflectance: v(reflectance), transmittance: v(transmittance) }
            }
            Material::Dielectric { ior, ext_ior, anti_reflection } => Material::Dielectric {
                ior: RefractiveIndex::constant(ior.at(w.nm)),
                ext_ior: RefractiveIndex::constant(ext_ior.at(w.nm)),
                anti_reflection,
            },
        }
    }
}

/// Mirror reflection of `wo` about `n`.
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * wo.dot(n) * n - wo
}

/// Unpolarised Fresnel reflectance at a smooth interface for light arriving at cos θ_i from the medium of
/// index `eta_i` (1 under total internal reflection).
pub fn fresnel_dielectric(cos_i: f32, eta_i: f32, eta_t: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t = eta_i / eta_t * (1.0 - cos_i * cos_i).max(0.0).sqrt();
    if sin_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t * sin_t).max(0.0).sqrt();
    let r_parl = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    let r_perp = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Lambertian BSDF value for the pair of directions, zero when they lie on different sides of the surface.
#[inline]
pub fn diffuse_f(albedo: Rgb, ng: Vec3, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.dot(ng) * wi.dot(ng) > 0.0 {
        albedo * FRAC_1_PI
    } else {
        Rgb::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_hit(n: Vec3) -> SurfaceHit {
        SurfaceHit { t: 1.0, p: Vec3::ZERO, ng: n, ns: n, object: 0, triangle: 0 }
    }

    #[test]
    fn fresnel_at_normal_incidence_is_four_percent_for_glass() {
        assert!((fresnel_dielectric(1.0, 1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(1.0, 1.5, 1.0) - 0.04).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(0.1, 1.5, 1.0), 1.0, "total internal reflection");
    }

    #[test]
    fn refraction_obeys_snell_and_radiance_scales_by_eta_squared() {
        let glass = Material::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: false,
        };
        let hit = flat_hit(Vec3::Z);
        let wo = Vec3::new(0.5, 0.0, 0.75f32.sqrt());
        // u.x = 0.999 selects transmission (F is small here).
        let s = glass.sample(&hit, wo, Vec2::new(0.999, 0.0), Transport::Radiance).unwrap();
        let sin_o = 0.5f32;
        let sin_t = (s.wi.x * s.wi.x + s.wi.y * s.wi.y).sqrt();
        assert!((sin_o - 1.5 * sin_t).abs() < 1e-5);
        assert!(s.wi.z < 0.0 && s.wi.x < 0.0);
        assert!((s.weight.x - 1.0 / 2.25).abs() < 1e-5);
        let s = glass.sample(&hit, wo, Vec2::new(0.999, 0.0), Transport::Importance).unwrap();
        assert!((s.weight.x - 1.0).abs() < 1e-5);
    }

    #[test]
    fn a_raised_reflection_probability_keeps_the_expected_reflected_and_transmitted_weights() {
        let glass = Material::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: false,
        };
        let hit = flat_hit(Vec3::Z);
        for (wo, f) in [(Vec3::Z, 0.04f32), (Vec3::new(0.8, 0.0, 0.6), fresnel_dielectric(0.6, 1.0, 1.5))] {
            for (mode, refract) in [(Transport::Importance, 1.0), (Transport::Radiance, 1.0 / 2.25)] {
                // Stratified u.x: the sums are the expectations up to 1/n.
                let n = 4000;
                let (mut reflected, mut transmitted, mut reflections) = (0.0f64, 0.0f64, 0);
                for i in 0..n {
                    let u = Vec2::new((i as f32 + 0.5) / n as f32, 0.5);
                    let s = glass.sample_reflecting(&hit, wo, u, mode, Reflection::AtLeast(0.3)).unwrap();
                    if s.wi.z > 0.0 {
                        reflected += s.weight.x as f64 / n as f64;
                        reflections += 1;
                    } else {
                        transmitted += s.weight.x as f64 / n as f64;
                    }
                }
                assert_eq!(reflections, (0.3 * n as f32).round() as usize, "reflects with the raised probability");
                assert!((reflected - f as f64).abs() < 1e-3, "E[reflected weight] {reflected} ≠ F {f}");
                let t = (1.0 - f as f64) * refract;
                assert!((transmitted - t).abs() < 1e-3, "E[transmitted weight] {transmitted} ≠ {t}");
            }
        }
        // Below the raised probability nothing changes; total internal reflection stays certain.
        let s = glass
            .sample_reflecting(&hit, Vec3::Z, Vec2::new(0.5, 0.0), Transport::Importance, Reflection::Fresnel)
            .unwrap();
        assert_eq!(s.weight, glass.sample(&hit, Vec3::Z, Vec2::new(0.5, 0.0), Transport::Importance).unwrap().weight);
        let wo = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
        let s =
            glass.sample_reflecting(&hit, wo, Vec2::new(0.999, 0.0), Transport::Importance, Reflection::AtLeast(0.3));
        let s = s.unwrap();
        assert!(s.wi.z < 0.0 && s.weight == Rgb::ONE, "total internal reflection, weight 1");
    }

    #[test]
    fn a_dielectric_told_never_to_reflect_refracts_with_weight_one_minus_f_and_ends_at_total_internal_reflection() {
        let glass = Material::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: false,
        };
        let hit = flat_hit(Vec3::Z);
        let wo = Vec3::new(0.8, 0.0, 0.6);
        let f = fresnel_dielectric(0.6, 1.0, 1.5);
        for u in [0.0, 0.5, 0.999] {
            let s = glass.sample_reflecting(&hit, wo, Vec2::new(u, 0.5), Transport::Importance, Reflection::Never);
            let s = s.unwrap();
            assert!(s.wi.z < 0.0, "refracts whatever u");
            assert!((s.weight.x - (1.0 - f)).abs() < 1e-5, "weight {} ≠ 1 − F = {}", s.weight.x, 1.0 - f);
        }
        let inside = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
        let s = glass.sample_reflecting(&hit, inside, Vec2::new(0.0, 0.5), Transport::Importance, Reflection::Never);
        assert!(s.is_none(), "total internal reflection leaves nothing to refract");
    }

    #[test]
    fn anti_reflection_coating_refracts_everything_but_total_internal_reflection() {
        let coated = Material::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: true,
        };
        let hit = flat_hit(Vec3::Z);
        // u.x = 0 would pick reflection whenever F > 0.
        let s = coated.sample(&hit, Vec3::Z, Vec2::ZERO, Transport::Radiance).unwrap();
        assert!(s.wi.z < 0.0, "refracted into the glass");
        // From inside at a grazing angle: total internal reflection stays.
        let wo = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
        let s = coated.sample(&hit, wo, Vec2::new(0.999, 0.0), Transport::Radiance).unwrap();
        assert!(s.wi.z < 0.0, "reflected back inside");
    }

    #[test]
    fn diffuse_sampling_stays_on_the_side_of_the_outgoing_direction() {
        let m = Material::Diffuse { albedo: Rgb::splat(0.5) };
        let hit = flat_hit(Vec3::Z);
        for i in 0..64 {
            let u = Vec2::new((i as f32 + 0.5) / 64.0, ((i * 37 % 64) as f32 + 0.5) / 64.0);
            let s = m.sample(&hit, -Vec3::Z, u, Transport::Radiance).unwrap();
            assert!(s.wi.z < 0.0);
            assert_eq!(s.weight, Rgb::splat(0.5));
        }
    }

    #[test]
    fn coating_splits_energy_between_reflection_and_transmission() {
        let m = Material::Coating { reflectance: Rgb::splat(0.25), transmittance: Rgb::splat(0.7) };
        let hit = flat_hit(Vec3::Z);
        let wo = Vec3::new(0.0, 0.6, 0.8);
        let mut sum = Rgb::ZERO;
        let n = 1000;
        for i in 0..n {
            let s = m.sample(&hit, wo, Vec2::new((i as f32 + 0.5) / n as f32, 0.5), Transport::Radiance).unwrap();
            sum += s.weight;
        }
        assert!(((sum / n as f32).x - 0.95).abs() < 1e-3);
    }
}
