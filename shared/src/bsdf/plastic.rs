//! Plastic: a diffuse base under a dielectric coat, smooth or rough, as Mitsuba 3's `plastic` and
//! `roughplastic`. The coat reflects by its Fresnel reflectance (a delta lobe when smooth, a microfacet lobe
//! when rough); what it transmits scatters diffusely at the base and leaves through the coat again, after any
//! number of reflections inside it, which the closed form of the internal reflectance sums:
//!
//! f_diffuse = ρ / (1 − ρ_i R_i) · (1 − F(θ_o)) (1 − F(θ_i)) / (π η²)   (smooth coat),
//!
//! with R_i the coat's reflectance for diffuse light from inside and ρ_i = 1 (Mitsuba's default, which keeps a
//! texture's colours) or ρ (`nonlinear`, which darkens and saturates as a real varnish does). A rough coat
//! replaces 1 − F by its directional transmittance T(θ) and R_i by its internal albedo, both integrals over the
//! microfacet distribution that `CoatTable` computes once per coat (as Mitsuba precomputes them).
//!
//! Mitsuba's parameters: `diffuse_reflectance` (default 0.5), `specular_reflectance` (default 1), `int_ior`
//! (default 1.49, polypropylene), `ext_ior` (default 1.000277, air), `nonlinear` (default false), and for
//! `roughplastic` `distribution` (`beckmann`, the default, or `ggx`) and `alpha` (default 0.1; isotropic only).
//! The coat is sampled with probability ∝ F · w_s against (1 − F)(1 − w_s) for the diffuse base, where the
//! specular sampling weight w_s = mean(specular) / (mean(diffuse) + mean(specular)) (means over the colour
//! channels), as Mitsuba computes it; Mitsuba takes the means over a whole texture, photonfarm the value at the
//! surface point, which changes the variance only.

use super::fresnel::fresnel_dielectric;
use super::microfacet::{Distribution, Microfacet};
use super::{grey_at, stores_glossy, BsdfSample, ByClass, DeltaBranches, LobeFlags, Scatter, Transport};
use crate::color::Rgb;
use crate::sampling::cosine_hemisphere;
use crate::spectrum::Wavelength;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;
use std::sync::Mutex;

/// Points of the rough coat's transmittance table over cos θ ∈ [0, 1], as Mitsuba's.
pub const COAT_TABLE_POINTS: usize = 64;

/// The coat over the diffuse base.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Coat {
    /// A smooth dielectric: a delta reflection.
    Smooth,
    /// A rough dielectric with its precomputed transmittance and internal albedo.
    Rough { microfacet: Microfacet, table: &'static CoatTable },
}

impl Coat {
    /// A rough coat of `distribution` and isotropic roughness `alpha` with relative index `eta`, with its table
    /// (`CoatTable::get`).
    pub fn rough(distribution: Distribution, alpha: f32, eta: f32) -> Coat {
        let microfacet = Microfacet::new(distribution, alpha, alpha);
        Coat::Rough { microfacet, table: CoatTable::get(distribution, microfacet.alpha_x, eta) }
    }
}

/// A coat as its parameters, which is how it is written (its table is computed again where it is read).
#[derive(serde::Serialize, serde::Deserialize)]
enum CoatParameters {
    Smooth,
    Rough { distribution: Distribution, alpha: f32, eta: f32 },
}

impl serde::Serialize for Coat {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Coat::Smooth => CoatParameters::Smooth,
            Coat::Rough { table, .. } => {
                CoatParameters::Rough { distribution: table.distribution, alpha: table.alpha, eta: table.eta }
            }
        }
        .serialize(s)
    }
}

impl<'de> serde::Deserialize<'de> for Coat {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(match CoatParameters::deserialize(d)? {
            CoatParameters::Smooth => Coat::Smooth,
            CoatParameters::Rough { distribution, alpha, eta } => Coat::rough(distribution, alpha, eta),
        })
    }
}

/// A diffuse base of `diffuse` under a coat of relative index `eta` (interior over exterior).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plastic {
    pub diffuse: Rgb,
    /// A factor on the coat's reflection (Mitsuba's `specular_reflectance`), 1 for a physical coat.
    pub specular: Rgb,
    pub eta: f32,
    /// Mitsuba's `nonlinear`: the base's own albedo weighs the light reflected back inside the coat.
    pub nonlinear: bool,
    /// w_s, the share of samples steered to the coat before the Fresnel weighting.
    pub specular_sampling_weight: f32,
    pub coat: Coat,
}

/// Mitsuba's specular sampling weight: mean(specular) / (mean(diffuse) + mean(specular)).
#[inline]
pub fn specular_sampling_weight(diffuse: Rgb, specular: Rgb) -> f32 {
    let (d, s) = (diffuse.element_sum() / 3.0, specular.element_sum() / 3.0);
    if d + s > 0.0 {
        s / (d + s)
    } else {
        1.0
    }
}

/// The diffuse Fresnel reflectance F_dr(η): the share of uniformly diffuse light that a smooth interface of
/// relative index η reflects, by the fits Mitsuba uses (Egan and Hilgeman 1973 for η < 1, d'Eon and Irving 2011
/// otherwise).
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 * inv
    } else {
        let c = [0.919_317, -3.4793, 6.753_35, -7.809_89, 4.985_54, -1.368_81];
        c.iter().rev().fold(0.0, |acc, &k| acc * inv + k)
    }
}

impl Plastic {
    /// A plastic whose sampling weight is Mitsuba's for its colours.
    pub fn new(diffuse: Rgb, specular: Rgb, eta: f32, nonlinear: bool, coat: Coat) -> Self {
        let specular_sampling_weight = specular_sampling_weight(diffuse, specular);
        Plastic { diffuse, specular, eta, nonlinear, specular_sampling_weight, coat }
    }

    /// The base's albedo with the coat's internal reflections summed: ρ / (1 − ρ_i R_i).
    #[inline]
    fn base(&self, internal_reflectance: f32) -> Rgb {
        let back = if self.nonlinear { self.diffuse * internal_reflectance } else { Rgb::splat(internal_reflectance) };
        self.diffuse / (Rgb::ONE - back)
    }

    /// The coat's transmittance for light arriving at cos θ from outside.
    #[inline]
    fn transmittance(&self, cos: f32) -> f32 {
        match self.coat {
            Coat::Smooth => 1.0 - fresnel_dielectric(cos, 1.0, self.eta),
            Coat::Rough { table, .. } => table.transmittance(cos),
        }
    }

    /// The probability of sampling the coat rather than the base for `wo`.
    #[inline]
    fn p_coat(&self, wo: Vec3) -> f32 {
        let t = self.transmittance(wo.z);
        let ws = self.specular_sampling_weight;
        let (s, d) = ((1.0 - t) * ws, t * (1.0 - ws));
        if s + d > 0.0 {
            s / (s + d)
        } else {
            0.0
        }
    }

    /// True when the coat is a glossy lobe that photons gather.
    #[inline]
    fn coat_stored(&self) -> bool {
        match self.coat {
            Coat::Smooth => false,
            Coat::Rough { microfacet, .. } => stores_glossy(microfacet.alpha()),
        }
    }

    /// The diffuse base's f at the pair (both above the surface).
    #[inline]
    fn f_diffuse(&self, wo: Vec3, wi: Vec3) -> Rgb {
        let internal = match self.coat {
            Coat::Smooth => fresnel_diffuse_reflectance(1.0 / self.eta),
            Coat::Rough { table, .. } => table.internal_reflectance,
        };
        let t = self.transmittance(wo.z) * self.transmittance(wi.z);
        self.base(internal) * (t * FRAC_1_PI / (self.eta * self.eta))
    }

    /// The non-delta BSDF and densities at the pair, by lobe class.
    fn by_class(&self, wo: Vec3, wi: Vec3) -> ByClass {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return ByClass::default();
        }
        let p_coat = self.p_coat(wo);
        let diffuse_f = self.f_diffuse(wo, wi);
        let diffuse_pdf = (1.0 - p_coat) * wi.z * FRAC_1_PI;
        let Coat::Rough { microfacet: m, .. } = self.coat else {
            return ByClass { stored_f: diffuse_f, stored_pdf: diffuse_pdf, ..ByClass::default() };
        };
        let h = (wo + wi).normalize();
        let dg = m.d(h) * m.g(wo, wi, h);
        let (coat_f, coat_pdf) = if dg > 0.0 {
            let f = fresnel_dielectric(wo.dot(h), 1.0, self.eta);
            (self.specular * (f * dg / (4.0 * wo.z * wi.z)), p_coat * m.pdf_visible(wo, h) / (4.0 * wi.dot(h)))
        } else {
            (Rgb::ZERO, 0.0)
        };
        if self.coat_stored() {
            ByClass { stored_f: diffuse_f + coat_f, stored_pdf: diffuse_pdf + coat_pdf, ..ByClass::default() }
        } else {
            ByClass { stored_f: diffuse_f, stored_pdf: diffuse_pdf, pass_f: coat_f, pass_pdf: coat_pdf }
        }
    }

    /// The smooth coat's mirror branch for `wo` with the probability `sample` picks it; none for a rough coat.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let mut branches = DeltaBranches::default();
        if self.coat != Coat::Smooth || wo.z <= 0.0 {
            return branches;
        }
        let p = self.p_coat(wo);
        if p <= 0.0 {
            return branches;
        }
        if let Some(s) = self.sample(wo, Vec2::new(0.0, 0.5), Transport::Radiance) {
            branches.push(s, p);
        }
        branches
    }
}

impl Scatter for Plastic {
    #[inline]
    fn flags(&self) -> LobeFlags {
        let base = LobeFlags::DIFFUSE | LobeFlags::REFLECTION | LobeFlags::STORED;
        match self.coat {
            Coat::Smooth => base | LobeFlags::SPECULAR,
            Coat::Rough { .. } if self.coat_stored() => base | LobeFlags::GLOSSY,
            Coat::Rough { .. } => base | LobeFlags::GLOSSY | LobeFlags::PASS,
        }
    }

    fn eval(&self, wo: Vec3, wi: Vec3, _mode: Transport, stored_only: bool) -> Rgb {
        self.by_class(wo, wi).f(stored_only)
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.by_class(wo, wi).pdf()
    }

    fn pdf_stored(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.by_class(wo, wi).stored_pdf
    }

    fn sample(&self, wo: Vec3, u: Vec2, _mode: Transport) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let p_coat = self.p_coat(wo);
        if u.x < p_coat {
            let u = Vec2::new(u.x / p_coat, u.y);
            match self.coat {
                Coat::Smooth => {
                    let f = fresnel_dielectric(wo.z, 1.0, self.eta);
                    let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                    Some(BsdfSample::specular(wi, self.specular * (f / p_coat), LobeFlags::REFLECTION))
                }
                Coat::Rough { microfacet, .. } => {
                    let h = microfacet.sample_visible(wo, u);
                    let wi = 2.0 * wo.dot(h) * h - wo;
                    if wi.z <= 0.0 {
                        return None;
                    }
                    let lobe = LobeFlags::GLOSSY | LobeFlags::REFLECTION;
                    self.by_class(wo, wi).sample(wi, lobe, self.coat_stored(), 1.0)
                }
            }
        } else {
            let u = Vec2::new(((u.x - p_coat) / (1.0 - p_coat)).min(1.0 - f32::EPSILON / 2.0), u.y);
            let wi = cosine_hemisphere(u);
            if wi.z <= 0.0 {
                return None;
            }
            self.by_class(wo, wi).sample(wi, LobeFlags::DIFFUSE | LobeFlags::REFLECTION, true, 1.0)
        }
    }

    fn at_wavelength(&self, w: &Wavelength) -> Self {
        Plastic { diffuse: grey_at(self.diffuse, w), specular: grey_at(self.specular, w), ..*self }
    }
}

/// What a rough coat lets through, integrated over its microfacets once per coat: the transmittance T(θ) of
/// light arriving from outside at the points cos θ = i / 63 (interpolated linearly between them), and the
/// albedo of the coat's inside for uniformly diffuse light. Both are Mitsuba's integrals, computed the same way:
/// Gauss–Legendre quadrature over the two numbers that draw a visible normal (32 × 32 nodes where the light
/// enters the denser medium, 128 × 128 where it may be totally reflected), with the refracted or reflected
/// direction's masking and the Fresnel term as the integrand; the albedo is 2 × the mean of R(θ) cos θ over the
/// 64 points.
#[derive(Clone, Debug, PartialEq)]
pub struct CoatTable {
    pub distribution: Distribution,
    pub alpha: f32,
    pub eta: f32,
    pub transmittance: [f32; COAT_TABLE_POINTS],
    pub internal_reflectance: f32,
}

/// The tables computed so far: a scene loaded again (or another material with the same coat) reuses its table.
static COAT_TABLES: Mutex<Vec<&'static CoatTable>> = Mutex::new(Vec::new());

impl CoatTable {
    /// The table of the coat of roughness `alpha` and relative index `eta`, computed on first use (a few
    /// milliseconds to a few tenths of a second) and kept for the life of the process.
    pub fn get(distribution: Distribution, alpha: f32, eta: f32) -> &'static CoatTable {
        let mut tables = COAT_TABLES.lock().unwrap_or_else(|e| e.into_inner());
        let found = tables.iter().find(|t| t.distribution == distribution && t.alpha == alpha && t.eta == eta).copied();
        if let Some(t) = found {
            return t;
        }
        let table: &'static CoatTable = Box::leak(Box::new(CoatTable::compute(distribution, alpha, eta)));
        tables.push(table);
        table
    }

    fn compute(distribution: Distribution, alpha: f32, eta: f32) -> CoatTable {
        let m = Microfacet::new(distribution, alpha, alpha);
        // Light entering the denser medium needs fewer nodes than light that may be totally reflected.
        let (outer_nodes, inner_nodes) = (gauss_legendre(32), gauss_legendre(128));
        let mut transmittance = [0.0; COAT_TABLE_POINTS];
        let mut albedo = 0.0f64;
        for (i, t) in transmittance.iter_mut().enumerate() {
            let mu = (i as f32 / (COAT_TABLE_POINTS - 1) as f32).max(1e-6);
            let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            *t = integrate_visible(
                &m,
                if eta > 1.0 { &outer_nodes } else { &inner_nodes },
                |h| {
                    let c = wi.dot(h);
                    let f = fresnel_dielectric(c, 1.0, eta);
                    match super::refract(wi, h, 1.0 / eta) {
                        Some(wt) if wt.z < 0.0 => m.g1(wt, h) * (1.0 - f),
                        _ => 0.0,
                    }
                },
                wi,
            ) as f32;
            let r = integrate_visible(
                &m,
                if eta > 1.0 { &inner_nodes } else { &outer_nodes },
                |h| {
                    let wr = 2.0 * wi.dot(h) * h - wi;
                    if wr.z <= 0.0 {
                        return 0.0;
                    }
                    m.g1(wr, h) * fresnel_dielectric(wi.dot(h), eta, 1.0)
                },
                wi,
            );
            albedo += r * mu as f64;
        }
        let internal_reflectance = (2.0 * albedo / COAT_TABLE_POINTS as f64) as f32;
        CoatTable { distribution, alpha, eta, transmittance, internal_reflectance }
    }

    /// T(θ) at cos θ = `cos`, interpolated linearly in the table.
    #[inline]
    pub fn transmittance(&self, cos: f32) -> f32 {
        let x = cos.clamp(0.0, 1.0) * (COAT_TABLE_POINTS - 1) as f32;
        let i = (x as usize).min(COAT_TABLE_POINTS - 2);
        let t = x - i as f32;
        self.transmittance[i] * (1.0 - t) + self.transmittance[i + 1] * t
    }
}

/// ∫∫ g(h(u)) du over the unit square, where h(u) is the visible normal `sample_visible(wi, u)` draws, by
/// Gauss–Legendre quadrature on `nodes` per axis.
fn integrate_visible(m: &Microfacet, nodes: &[(f64, f64)], g: impl Fn(Vec3) -> f32, wi: Vec3) -> f64 {
    let mut sum = 0.0f64;
    for &(x, wx) in nodes {
        for &(y, wy) in nodes {
            let u = Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32);
            sum += g(m.sample_visible(wi, u)) as f64 * wx * wy;
        }
    }
    0.25 * sum
}

/// The nodes and weights of n-point Gauss–Legendre quadrature on [−1, 1], by Newton's method on the Legendre
/// polynomial from the usual starting guesses.
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let p = if n == 0 { 1.0 } else { p1 };
            let pm1 = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (x * p - pm1) / (x * x - 1.0);
            let dx = p / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let rule = gauss_legendre(8);
        assert!((rule.iter().map(|(_, w)| w).sum::<f64>() - 2.0).abs() < 1e-12);
        // Degree 2n − 1 = 15 is exact: ∫ x¹⁴ = 2/15.
        let i: f64 = rule.iter().map(|(x, w)| w * x.powi(14)).sum();
        assert!((i - 2.0 / 15.0).abs() < 1e-12, "{i}");
    }

    #[test]
    fn the_diffuse_fresnel_reflectance_fits_give_glass_its_known_values() {
        // F_dr for light from inside glass (η = 1/1.5) is about 0.596, from outside about 0.092.
        assert!((fresnel_diffuse_reflectance(1.0 / 1.5) - 0.596).abs() < 0.005);
        assert!((fresnel_diffuse_reflectance(1.5) - 0.092).abs() < 0.005);
    }

    #[test]
    fn a_nearly_smooth_rough_coat_transmits_as_the_smooth_one() {
        let t = CoatTable::get(Distribution::Ggx, 0.001, 1.5);
        for cos in [1.0, 0.7, 0.4] {
            let smooth = 1.0 - fresnel_dielectric(cos, 1.0, 1.5);
            assert!((t.transmittance(cos) - smooth).abs() < 2e-3, "cos {cos}: {} vs {smooth}", t.transmittance(cos));
        }
        let smooth_internal = fresnel_diffuse_reflectance(1.0 / 1.5);
        assert!(
            (t.internal_reflectance - smooth_internal).abs() < 0.01,
            "{} vs {smooth_internal}",
            t.internal_reflectance
        );
    }
}
