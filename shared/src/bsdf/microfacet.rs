//! Microfacet distributions of rough surfaces (Walter et al. 2007): Beckmann and GGX (Trowbridge–Reitz),
//! isotropic or anisotropic, with Smith's separable shadowing and masking, and sampling by the distribution of
//! visible normals (Heitz and d'Eon 2014; for GGX the exact routine of Heitz 2018, for Beckmann the numerical
//! inversion of Jakob 2014). The conventions are Mitsuba 3's, so that a scene imported from it renders alike:
//! α along the local x and y axes, Beckmann's shadowing by its rational approximation.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The shape of a microfacet distribution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Distribution {
    /// Gaussian random surfaces: short tails.
    Beckmann,
    /// GGX / Trowbridge–Reitz: long tails.
    Ggx,
}

/// The smallest roughness a distribution takes, as Mitsuba clamps it: below it a smooth model fits better.
pub const MIN_ALPHA: f32 = 1e-4;

/// A microfacet distribution with roughness α_x, α_y along the local frame's x and y axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microfacet {
    pub distribution: Distribution,
    pub alpha_x: f32,
    pub alpha_y: f32,
}

impl Microfacet {
    /// The distribution with its roughness clamped to `MIN_ALPHA`.
    pub fn new(distribution: Distribution, alpha_x: f32, alpha_y: f32) -> Self {
        Microfacet { distribution, alpha_x: alpha_x.max(MIN_ALPHA), alpha_y: alpha_y.max(MIN_ALPHA) }
    }

    /// One roughness for the estimator's rule of which glossy lobes are stored: √(α_x α_y).
    #[inline]
    pub fn alpha(&self) -> f32 {
        (self.alpha_x * self.alpha_y).sqrt()
    }

    /// D(m), the density of microfacet normals per unit projected area: ∫ D(m) cos θ_m dω_m = 1.
    pub fn d(&self, m: Vec3) -> f32 {
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let cos2 = m.z * m.z;
        let d = match self.distribution {
            // exp(−tan²θ (cos²φ/α_x² + sin²φ/α_y²)) / (π α_x α_y cos⁴θ)
            Distribution::Beckmann => {
                (-((m.x / ax).powi(2) + (m.y / ay).powi(2)) / cos2).exp() / (PI * ax * ay * cos2 * cos2)
            }
            // 1 / (π α_x α_y ((m_x/α_x)² + (m_y/α_y)² + m_z²)²)
            Distribution::Ggx => 1.0 / (PI * ax * ay * ((m.x / ax).powi(2) + (m.y / ay).powi(2) + cos2).powi(2)),
        };
        // Grazing normals underflow to garbage in the stages that divide by D.
        if d * m.z > 1e-20 {
            d
        } else {
            0.0
        }
    }

    /// Smith's shadowing-masking G1(v, m) for one direction, zero where `v` sees the back of the facet.
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let xy = (self.alpha_x * v.x).powi(2) + (self.alpha_y * v.y).powi(2);
        if xy == 0.0 {
            return 1.0;
        }
        let tan2_alpha = xy / (v.z * v.z);
        match self.distribution {
            Distribution::Beckmann => {
                // Walter et al.'s rational fit of 1 / (1 + Λ(a)), a = 1 / (α tan θ), within 0.35%.
                let a = 1.0 / tan2_alpha.sqrt();
                if a >= 1.6 {
                    1.0
                } else {
                    (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
                }
            }
            Distribution::Ggx => 2.0 / (1.0 + (1.0 + tan2_alpha).sqrt()),
        }
    }

    /// G(wo, wi, m) = G1(wo, m) G1(wi, m), the separable form.
    #[inline]
    pub fn g(&self, wo: Vec3, wi: Vec3, m: Vec3) -> f32 {
        self.g1(wo, m) * self.g1(wi, m)
    }

    /// The density over normals m with which `sample_visible(v, ·)` returns m: D_v(m) = G1(v, m) |v·m| D(m) /
    /// cos θ_v, for v in the upper hemisphere.
    pub fn pdf_visible(&self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 {
            return 0.0;
        }
        self.d(m) * self.g1(v, m) * v.dot(m).abs() / v.z
    }

    /// A microfacet normal seen from `v` (upper hemisphere), drawn from the distribution of visible normals.
    pub fn sample_visible(&self, v: Vec3, u: Vec2) -> Vec3 {
        match self.distribution {
            Distribution::Ggx => self.sample_visible_ggx(v, u),
            Distribution::Beckmann => self.sample_visible_beckmann(v, u),
        }
    }

    /// Heitz 2018: the visible part of the stretched hemisphere is sampled as a disc projected from `v`.
    fn sample_visible_ggx(&self, v: Vec3, u: Vec2) -> Vec3 {
        let vh = Vec3::new(self.alpha_x * v.x, self.alpha_y * v.y, v.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        Vec3::new(self.alpha_x * nh.x, self.alpha_y * nh.y, nh.z.max(1e-7)).normalize()
    }

    /// Heitz and d'Eon 2014 with Jakob's numerical inversion: stretch `v` to α = 1, draw the slopes of the
    /// visible facets there, rotate and unstretch them.
    fn sample_visible_beckmann(&self, v: Vec3, u: Vec2) -> Vec3 {
        let vs = Vec3::new(self.alpha_x * v.x, self.alpha_y * v.y, v.z).normalize();
        let sin_theta = (1.0 - vs.z * vs.z).max(0.0).sqrt();
        let (sin_phi, cos_phi) = if sin_theta > 1e-7 { (vs.y / sin_theta, vs.x / sin_theta) } else { (0.0, 1.0) };
        let slope = beckmann_visible_slopes(vs.z, u);
        let sx = (cos_phi * slope.x - sin_phi * slope.y) * self.alpha_x;
        let sy = (sin_phi * slope.x + cos_phi * slope.y) * self.alpha_y;
        Vec3::new(-sx, -sy, 1.0).normalize()
    }
}

/// The slopes of a visible facet of the α = 1 Beckmann surface seen at cos θ = `cos_theta`: the slope along the
/// direction of view by inverting its CDF with Newton's method in the erf domain, the other one Gaussian.
fn beckmann_visible_slopes(cos_theta: f32, u: Vec2) -> Vec2 {
    const INV_SQRT_PI: f64 = std::f64::consts::FRAC_2_SQRT_PI / 2.0;
    let c = cos_theta as f64;
    let tan_theta = (1.0 - c * c).max(0.0).sqrt() / c;
    let cot_theta = 1.0 / tan_theta;
    let max = erf(cot_theta);
    let ux = (u.x as f64).clamp(1e-6, 1.0 - 1e-6);
    let uy = (u.y as f64).clamp(1e-6, 1.0 - 1e-6);
    // The analytic solution for θ = π/2, the most nonlinear case, starts the search.
    let mut x = max - (max + 1.0) * erf((-ux.ln()).sqrt());
    let exp_term = if tan_theta > 0.0 { INV_SQRT_PI * tan_theta * (-cot_theta * cot_theta).exp() } else { 0.0 };
    let target = ux * (1.0 + max + exp_term);
    for _ in 0..3 {
        let slope = erfinv(x);
        let value = 1.0 + x + INV_SQRT_PI * tan_theta * (-slope * slope).exp() - target;
        let derivative = 1.0 - slope * tan_theta;
        x -= value / derivative;
    }
    Vec2::new(erfinv(x) as f32, erfinv(2.0 * uy - 1.0) as f32)
}

/// The error function, by Abramowitz and Stegun 7.1.26 (absolute error below 1.5·10⁻⁷).
pub fn erf(x: f64) -> f64 {
    if x.is_infinite() {
        return x.signum();
    }
    let sign = x.signum();
    let x = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    sign * (1.0 - poly * (-x * x).exp())
}

/// The inverse error function on (−1, 1), by Giles 2010's polynomial fits refined by two Newton steps.
pub fn erfinv(x: f64) -> f64 {
    let x = x.clamp(-1.0 + 1e-15, 1.0 - 1e-15);
    let w = -((1.0 - x) * (1.0 + x)).ln();
    let mut p = if w < 5.0 {
        let w = w - 2.5;
        let mut p = 2.810_226_36e-08;
        for c in [
            3.432_739_39e-07,
            -3.523_387_7e-06,
            -4.391_506_54e-06,
            2.185_808_7e-04,
            -1.253_725_03e-03,
            -4.177_681_64e-03,
            2.466_407_27e-01,
            1.501_409_41,
        ] {
            p = c + p * w;
        }
        p
    } else {
        let w = w.sqrt() - 3.0;
        let mut p = -2.002_142_57e-04;
        for c in [
            1.009_505_58e-04,
            1.349_343_22e-03,
            -3.673_428_44e-03,
            5.739_507_73e-03,
            -7.622_461_3e-03,
            9.438_870_47e-03,
            1.001_674_06,
            2.832_976_82,
        ] {
            p = c + p * w;
        }
        p
    } * x;
    // The fit's single-precision accuracy is refined against `erf`, whose own error then bounds the result.
    for _ in 0..2 {
        let err = erf(p) - x;
        p -= err / (std::f64::consts::FRAC_2_SQRT_PI * (-p * p).exp());
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Directions over the sphere by the midpoint rule in θ and φ, with their solid angle sin θ dθ dφ: fine
    /// at the pole, where sharp lobes peak.
    fn sphere_grid(n: usize) -> impl Iterator<Item = (Vec3, f32)> {
        let (n_theta, n_phi) = (2 * n, n);
        let (d_theta, d_phi) = (PI / n_theta as f32, 2.0 * PI / n_phi as f32);
        (0..n_theta * n_phi).map(move |i| {
            let theta = ((i / n_phi) as f32 + 0.5) * d_theta;
            let phi = ((i % n_phi) as f32 + 0.5) * d_phi;
            let (st, ct) = theta.sin_cos();
            (Vec3::new(st * phi.cos(), st * phi.sin(), ct), st * d_theta * d_phi)
        })
    }

    fn distributions() -> Vec<Microfacet> {
        let mut all = Vec::new();
        for d in [Distribution::Beckmann, Distribution::Ggx] {
            for (ax, ay) in [(0.1, 0.1), (0.4, 0.4), (0.8, 0.8), (0.1, 0.5)] {
                all.push(Microfacet::new(d, ax, ay));
            }
        }
        all
    }

    #[test]
    fn projected_normals_integrate_to_one() {
        for m in distributions() {
            let sum: f32 = sphere_grid(1000).filter(|(w, _)| w.z > 0.0).map(|(w, dw)| m.d(w) * w.z * dw).sum();
            assert!((sum - 1.0).abs() < 0.01, "{m:?}: ∫ D cos = {sum}");
        }
    }

    #[test]
    fn visible_normal_densities_integrate_to_one_for_every_view() {
        for m in distributions() {
            for v in [
                Vec3::Z,
                Vec3::new(0.6, 0.0, 0.8),
                Vec3::new(-0.5, 0.7, 0.5).normalize(),
                Vec3::new(0.0, 0.98, 0.2).normalize(),
            ] {
                let sum: f32 = sphere_grid(1000).map(|(w, dw)| m.pdf_visible(v, w) * dw).sum();
                assert!((sum - 1.0).abs() < 0.02, "{m:?} from {v}: ∫ D_v = {sum}");
            }
        }
    }

    #[test]
    fn sampled_visible_normals_follow_their_density() {
        // The mean of a test function under the samples equals its integral against the density.
        for m in distributions() {
            for v in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.3, -0.8, 0.52).normalize()] {
                let g = |n: Vec3| n.x + 2.0 * n.y * n.y + n.z;
                let expected: f32 = sphere_grid(1000).map(|(w, dw)| g(w) * m.pdf_visible(v, w) * dw).sum();
                let k = 256;
                let mut mean = 0.0f64;
                for i in 0..k * k {
                    let u = Vec2::new(((i % k) as f32 + 0.5) / k as f32, ((i / k) as f32 + 0.5) / k as f32);
                    let n = m.sample_visible(v, u);
                    assert!(n.z > 0.0 && (n.length() - 1.0).abs() < 1e-4, "{m:?}: normal {n}");
                    mean += g(n) as f64;
                }
                let mean = mean / (k * k) as f64;
                assert!((mean - expected as f64).abs() < 0.01, "{m:?} from {v}: mean {mean}, expected {expected}");
            }
        }
    }

    #[test]
    fn erf_and_its_inverse_agree() {
        assert!((erf(0.5) - 0.520_499_877_813_046_5).abs() < 2e-7);
        assert!((erf(-1.5) + 0.966_105_146_475_310_7).abs() < 2e-7);
        for x in [-0.999, -0.9, -0.5, -0.1, 0.0, 0.2, 0.7, 0.95, 0.9999] {
            let y = erfinv(x);
            assert!((erf(y) - x).abs() < 1e-6, "erf(erfinv({x})) = {}", erf(y));
        }
    }
}
