//! What the infinite lights (environments and the sun) share: the direction sample next-event estimation
//! draws, the errors of their parameters, the start of their light paths on a disc that covers the scene's
//! bounding sphere (as pbrt-v4 does), and their power over that sphere, by which lights are chosen.
//!
//! A photon from an infinite light travels along −ω, where ω (unit, world space) points from the scene toward
//! the light. Its origin is uniform on the disc of the scene's bounding sphere (centre c, radius r) that faces
//! ω, moved out to the sphere's edge: o = c + r ω + r (x s + y t) with (x, y) uniform on the unit disc and
//! (s, t, ω) a frame. Every ray that crosses the sphere starts on that disc, so the photon's flux weight is
//! L(ω) / (p(ω) · 1/(π r²)), and the power over the sphere is its expectation, π r² ∫ L(ω) dω.

use crate::color::Rgb;
use crate::light::directional::Sun;
use crate::light::environment::{ConstantEnvironment, EnvironmentMap};
use crate::sampling::{concentric_disk, Frame};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;
use thiserror::Error;

/// Light arriving from an infinite light along one direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InfiniteSample {
    /// Unit direction (world) from the scene toward the light.
    pub direction: Vec3,
    /// Radiance arriving along `-direction`; for a delta light (the sun without a radius), its irradiance on a
    /// plane facing it.
    pub radiance: Rgb,
    /// Solid-angle density of `direction`; 1 for a delta light.
    pub pdf: f32,
    /// True for a delta direction, which MIS cannot weigh and a path can never hit.
    pub delta: bool,
}

/// Why an infinite light's parameters are refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum InfiniteLightError {
    #[error("an environment map needs at least 1 × 2 texels, this one is {width} × {height}")]
    TooSmall { width: usize, height: usize },
    #[error("an environment map of {width} × {height} texels needs {expected} RGB values, {given} were given")]
    WrongLength { width: usize, height: usize, expected: usize, given: usize },
    #[error("texel ({x}, {y}) is {value:?}: radiance must be finite and non-negative")]
    InvalidTexel { x: usize, y: usize, value: [f32; 3] },
    #[error("the environment map is black everywhere: it emits nothing")]
    Black,
    #[error("the radiance {value:?} must be finite and non-negative, and not all zero")]
    InvalidRadiance { value: [f32; 3] },
    #[error("the irradiance {value:?} must be finite and non-negative, and not all zero")]
    InvalidIrradiance { value: [f32; 3] },
    #[error("the scale {0} must be finite and positive")]
    InvalidScale(f32),
    #[error("the transform is not a rotation (orthonormal with determinant 1)")]
    NotARotation,
    #[error("the direction {value:?} must be finite and non-zero")]
    InvalidDirection { value: [f32; 3] },
    #[error("the angular radius {0} rad must be finite, at least 0 and below π/2")]
    InvalidAngularRadius(f32),
}

/// Checks that a colour is finite, non-negative and not black.
pub(crate) fn is_positive_colour(c: Rgb) -> bool {
    c.is_finite() && c.min_element() >= 0.0 && c.max_element() > 0.0
}

/// Checks that `m` is a rotation, allowing f32 rounding of a composed transform.
pub(crate) fn check_rotation(m: Mat3) -> Result<(), InfiniteLightError> {
    let error = (m.transpose() * m - Mat3::IDENTITY).to_cols_array().iter().fold(0.0f32, |a, &e| a.max(e.abs()));
    if m.is_finite() && error < 1e-4 && m.determinant() > 0.0 {
        Ok(())
    } else {
        Err(InfiniteLightError::NotARotation)
    }
}

/// The scene's bounding sphere, which light paths from infinite lights must cover.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneSphere {
    pub center: Vec3,
    pub radius: f32,
}

/// The start of a light path from an infinite light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InfiniteRay {
    /// On the disc of the scene's bounding sphere that faces the light.
    pub origin: Vec3,
    /// The direction of travel, into the scene: minus the sampled direction toward the light.
    pub direction: Vec3,
    /// Solid-angle density of the direction (1 for a delta light).
    pub pdf_direction: f32,
    /// Area density of the origin on the disc, 1/(π r²).
    pub pdf_area: f32,
}

impl InfiniteRay {
    /// The flux a photon on this ray carries: radiance / (pdf_direction · pdf_area); for a delta light, whose
    /// "radiance" is its irradiance E with pdf 1, E π r².
    pub fn flux(&self, radiance: Rgb) -> Rgb {
        radiance / (self.pdf_direction * self.pdf_area)
    }
}

impl SceneSphere {
    /// The sphere around the box `bounds` (its centre and half its diagonal); for a scene without surfaces, the
    /// unit sphere, which only keeps the light's power finite (no photon can land anywhere).
    pub fn around(bounds: Option<(Vec3, Vec3)>) -> SceneSphere {
        match bounds {
            Some((lo, hi)) if (hi - lo).length() > 0.0 => {
                SceneSphere { center: 0.5 * (lo + hi), radius: 0.5 * (hi - lo).length() }
            }
            Some((lo, _)) => SceneSphere { center: lo, radius: 1.0 },
            None => SceneSphere { center: Vec3::ZERO, radius: 1.0 },
        }
    }

    /// A point past the sphere along `direction` (unit) from `p`: the end of a shadow ray toward an infinite
    /// light, beyond every surface.
    #[inline]
    pub fn beyond(&self, p: Vec3, direction: Vec3) -> Vec3 {
        p + direction * (2.0 * ((p - self.center).length() + self.radius))
    }

    /// The light path that arrives along `sample` (a direction sampled from an infinite light), starting on the
    /// disc facing it at the point `u` (uniform in [0, 1)²) chooses. None for a zero pdf or a degenerate sphere.
    pub fn ray_from(&self, sample: &InfiniteSample, u: Vec2) -> Option<InfiniteRay> {
        if !(sample.pdf > 0.0 && self.radius > 0.0) {
            return None;
        }
        let toward_light = sample.direction;
        let frame = Frame::from_normal(toward_light);
        let d = concentric_disk(u) * self.radius;
        let origin = self.center + self.radius * toward_light + frame.s * d.x + frame.t * d.y;
        Some(InfiniteRay {
            origin,
            direction: -toward_light,
            pdf_direction: sample.pdf,
            pdf_area: 1.0 / (PI * self.radius * self.radius),
        })
    }

    /// The power an infinite light sends through this sphere, π r² ∫ L(ω) dω, from the light's
    /// `radiance_integral` (∫ L dω over all directions; E for a delta sun).
    pub fn power(&self, radiance_integral: Rgb) -> Rgb {
        radiance_integral * (PI * self.radius * self.radius)
    }
}

/// A light at infinity, as the scene's light list holds it.
#[derive(Clone, Debug)]
pub enum InfiniteLight {
    /// Uniform radiance from every direction.
    Constant(ConstantEnvironment),
    /// An equirectangular image of radiance; shared, since a map can be large.
    Map(Arc<EnvironmentMap>),
    /// The sun, a delta direction or a cone.
    Sun(Sun),
}

impl InfiniteLight {
    /// The radiance arriving from `direction` (unit, from the scene toward the light); zero for a delta sun,
    /// which no path can hit.
    #[inline]
    pub fn radiance(&self, direction: Vec3) -> Rgb {
        match self {
            InfiniteLight::Constant(c) => c.radiance(direction),
            InfiniteLight::Map(m) => m.radiance(direction),
            InfiniteLight::Sun(s) => s.radiance(direction),
        }
    }

    /// A direction toward the light with its radiance and solid-angle pdf (see `InfiniteSample`).
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<InfiniteSample> {
        match self {
            InfiniteLight::Constant(c) => Some(c.sample(u)),
            InfiniteLight::Map(m) => m.sample(u),
            InfiniteLight::Sun(s) => Some(s.sample(u)),
        }
    }

    /// The solid-angle density with which `sample` draws `direction` (0 for a delta sun).
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        match self {
            InfiniteLight::Constant(c) => c.pdf(direction),
            InfiniteLight::Map(m) => m.pdf(direction),
            InfiniteLight::Sun(s) => s.pdf(direction),
        }
    }

    /// ∫ L dω over all directions (E for a delta sun), from which the power over the scene follows.
    pub fn radiance_integral(&self) -> Rgb {
        match self {
            InfiniteLight::Constant(c) => c.radiance_integral(),
            InfiniteLight::Map(m) => m.radiance_integral(),
            InfiniteLight::Sun(s) => s.radiance_integral(),
        }
    }

    /// True for a sun without angular radius: only next-event estimation and light paths find it.
    pub fn is_delta(&self) -> bool {
        matches!(self, InfiniteLight::Sun(s) if s.is_delta())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    /// The distance along a ray to a sphere it enters, if it does.
    fn hits_sphere(origin: Vec3, direction: Vec3, center: Vec3, radius: f32) -> bool {
        let oc = origin - center;
        let b = oc.dot(direction);
        let c = oc.length_squared() - radius * radius;
        b * b - c >= 0.0 && (-b + (b * b - c).max(0.0).sqrt()) > 0.0
    }

    /// The flux that photons of an infinite light deliver to a small sphere inside the scene sphere, as a mean
    /// and standard error over `n` photons.
    fn flux_into_small_sphere(sample: impl Fn(Vec2) -> Option<InfiniteSample>, n: usize) -> (f64, f64) {
        let scene = SceneSphere { center: Vec3::new(1.0, -2.0, 0.5), radius: 3.0 };
        let (target, rho) = (scene.center + Vec3::new(0.8, 0.5, -0.6), 1.2);
        let mut rng = Sampler::new(11, Pass::Light, 0, 0);
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let u_dir = rng.next_2d();
            let u_pos = rng.next_2d();
            let Some(s) = sample(u_dir) else { continue };
            let ray = scene.ray_from(&s, u_pos).unwrap();
            assert!((ray.origin - scene.center).length() <= scene.radius * 1.4143);
            if hits_sphere(ray.origin, ray.direction, target, rho) {
                let f = crate::color::luminance(ray.flux(s.radiance)) as f64;
                sum += f;
                sum2 += f * f;
            }
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean) / (n - 1) as f64).sqrt())
    }

    const RHO: f64 = 1.2;

    #[test]
    fn photons_of_a_constant_environment_deliver_pi_rho_squared_times_4_pi_l_to_a_sphere() {
        // A sphere of radius ρ in uniform radiance L receives E = π L on every point of its 4π ρ² of area.
        let env = ConstantEnvironment::new(Rgb::splat(0.7)).unwrap();
        let (flux, sem) = flux_into_small_sphere(|u| Some(env.sample(u)), 200_000);
        let expected = std::f64::consts::PI * RHO * RHO * 4.0 * std::f64::consts::PI * 0.7;
        assert!((flux - expected).abs() < 4.0 * sem, "{flux} ± {sem} vs {expected}");
        let scene = SceneSphere { center: Vec3::ZERO, radius: 2.0 };
        let power = scene.power(env.radiance_integral()).x as f64;
        assert!((power - 4.0 * std::f64::consts::PI.powi(2) * 4.0 * 0.7).abs() < 1e-3 * power);
    }

    #[test]
    fn photons_of_an_environment_map_and_a_sun_deliver_pi_rho_squared_times_their_radiance_integral() {
        let (w, h) = (12, 7);
        let texels: Vec<Rgb> =
            (0..w * h).map(|i| Rgb::new(0.2 + (i % 5) as f32, 0.1 * (i % 3) as f32, 1.0 + (i % 7) as f32)).collect();
        let rotation = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
        let map = EnvironmentMap::new(w, h, texels, 1.5, rotation).unwrap();
        let (flux, sem) = flux_into_small_sphere(|u| map.sample(u), 200_000);
        let expected = std::f64::consts::PI * RHO * RHO * crate::color::luminance(map.radiance_integral()) as f64;
        assert!((flux - expected).abs() < 4.0 * sem, "{flux} ± {sem} vs {expected}");

        for radius in [0.0, 0.2] {
            let sun = Sun::new(Vec3::new(0.3, 1.0, -0.2), Rgb::new(3.0, 2.0, 1.0), radius).unwrap();
            let (flux, sem) = flux_into_small_sphere(|u| Some(sun.sample(u)), 50_000);
            let expected = std::f64::consts::PI * RHO * RHO * crate::color::luminance(sun.radiance_integral()) as f64;
            // A delta sun always hits with the same flux: its error is rounding.
            assert!((flux - expected).abs() < 4.0 * sem + 1e-4 * expected, "{flux} ± {sem} vs {expected}");
        }
    }
}
