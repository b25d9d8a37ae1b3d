//! The sun: a distant light of irradiance E (W/m² on a plane facing it) from a direction, either a delta
//! direction or a cone of angular radius α of uniform radiance, so that sun shadows can be soft.
//!
//! A cone of uniform radiance L delivers at normal incidence E = ∫ L cos θ dω = L · 2π ∫₀^α cos θ sin θ dθ
//! = L π sin² α, so the sun's radiance is L = E / (π sin² α). Its directions are sampled uniformly over the
//! cone's solid angle Ω = 2π (1 − cos α), and ∫ L dω = L Ω = 2E / (1 + cos α), slightly above E.

use crate::color::Rgb;
use crate::light::infinite::{is_positive_colour, InfiniteLightError, InfiniteSample};
use crate::sampling::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A sun: irradiance `irradiance` arriving from around `direction`.
#[derive(Clone, Copy, Debug)]
pub struct Sun {
    frame: Frame,
    irradiance: Rgb,
    /// 1 − cos α, computed as 2 sin²(α/2) so that a sun of a fraction of a degree keeps its precision.
    one_minus_cos: f32,
    sin2_radius: f32,
    /// Radiance inside the cone (zero for a delta sun).
    radiance: Rgb,
}

impl Sun {
    /// The sun seen toward `direction` (from the scene toward the sun; need not be unit), of irradiance
    /// `irradiance` at normal incidence and angular radius `angular_radius` radians (0 for a delta direction,
    /// below π/2).
    pub fn new(direction: Vec3, irradiance: Rgb, angular_radius: f32) -> Result<Self, InfiniteLightError> {
        if !(direction.is_finite() && direction.length_squared() > 0.0) {
            return Err(InfiniteLightError::InvalidDirection { value: direction.to_array() });
        }
        if !is_positive_colour(irradiance) {
            return Err(InfiniteLightError::InvalidIrradiance { value: irradiance.to_array() });
        }
        if !(angular_radius.is_finite() && (0.0..PI / 2.0).contains(&angular_radius)) {
            return Err(InfiniteLightError::InvalidAngularRadius(angular_radius));
        }
        let half = (0.5 * angular_radius).sin();
        let sin2_radius = angular_radius.sin().powi(2);
        let radiance = if angular_radius > 0.0 { irradiance / (PI * sin2_radius) } else { Rgb::ZERO };
        Ok(Sun {
            frame: Frame::from_normal(direction.normalize()),
            irradiance,
            one_minus_cos: 2.0 * half * half,
            sin2_radius,
            radiance,
        })
    }

    /// True for a sun without angular radius.
    pub fn is_delta(&self) -> bool {
        self.one_minus_cos == 0.0
    }

    /// The unit direction from the scene toward the sun's centre.
    pub fn direction(&self) -> Vec3 {
        self.frame.n
    }

    /// True when `direction` (unit) lies in the sun's cone; tested by the sine, which keeps its precision
    /// for small cones where the cosine is 1 to f32 precision.
    fn in_cone(&self, direction: Vec3) -> bool {
        !self.is_delta()
            && direction.dot(self.frame.n) > 0.0
            && direction.cross(self.frame.n).length_squared() <= self.sin2_radius
    }

    /// The radiance arriving from `direction` (unit): L inside the cone, zero elsewhere and for a delta sun.
    pub fn radiance(&self, direction: Vec3) -> Rgb {
        if self.in_cone(direction) {
            self.radiance
        } else {
            Rgb::ZERO
        }
    }

    /// A direction uniform in the cone with its radiance and pdf 1/Ω, or for a delta sun its direction with
    /// the irradiance as "radiance", pdf 1 and `delta` set.
    pub fn sample(&self, u: Vec2) -> InfiniteSample {
        if self.is_delta() {
            return InfiniteSample { direction: self.frame.n, radiance: self.irradiance, pdf: 1.0, delta: true };
        }
        let one_minus_z = u.x * self.one_minus_cos;
        let r = (one_minus_z * (2.0 - one_minus_z)).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let local = Vec3::new(r * phi.cos(), r * phi.sin(), 1.0 - one_minus_z);
        InfiniteSample {
            direction: self.frame.to_world(local).normalize(),
            radiance: self.radiance,
            pdf: 1.0 / (2.0 * PI * self.one_minus_cos),
            delta: false,
        }
    }

    /// The solid-angle density with which `sample` draws `direction`: 1/Ω inside the cone, else 0 (and 0 for
    /// a delta sun, whose direction no other technique can find).
    pub fn pdf(&self, direction: Vec3) -> f32 {
        if self.in_cone(direction) {
            1.0 / (2.0 * PI * self.one_minus_cos)
        } else {
            0.0
        }
    }

    /// ∫ L dω, L Ω for a cone and E for a delta sun, for the light's power over the scene.
    pub fn radiance_integral(&self) -> Rgb {
        if self.is_delta() {
            self.irradiance
        } else {
            self.radiance * (2.0 * PI * self.one_minus_cos)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    #[test]
    fn a_sun_with_a_radius_delivers_its_irradiance_at_normal_incidence() {
        // The real sun's radius (0.267°) and a large one; E = ∫ L cos θ dω by the sampled directions.
        for radius in [0.267f32.to_radians(), 0.3] {
            let sun = Sun::new(Vec3::new(1.0, 2.0, 0.5), Rgb::new(1000.0, 900.0, 800.0), radius).unwrap();
            let mut rng = Sampler::new(9, Pass::Light, 0, 0);
            let n = 20_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let s = sun.sample(rng.next_2d());
                assert!(sun.pdf(s.direction) > 0.0, "a sampled direction lies in the cone");
                assert_eq!(sun.radiance(s.direction), s.radiance);
                let f = (s.radiance.x * s.direction.dot(sun.direction()) / s.pdf) as f64;
                sum += f;
                sum2 += f * f;
            }
            let mean = sum / n as f64;
            let sem = ((sum2 / n as f64 - mean * mean) / (n - 1) as f64).sqrt();
            assert!((mean - 1000.0).abs() < 4.0 * sem + 1e-2, "radius {radius}: {mean} ± {sem}");
        }
    }

    #[test]
    fn the_cone_pdf_integrates_to_one() {
        let radius = 0.25f32;
        let sun = Sun::new(Vec3::Z, Rgb::ONE, radius).unwrap();
        // Quadrature over a polar grid around the axis, out past the cone's edge.
        let (nt, np) = (2000, 64);
        let theta_max = 1.5 * radius;
        let mut integral = 0.0f64;
        for i in 0..nt {
            let theta = (i as f32 + 0.5) / nt as f32 * theta_max;
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                let d = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                integral += (sun.pdf(d) * theta.sin()) as f64 * (theta_max / nt as f32 * 2.0 * PI / np as f32) as f64;
            }
        }
        assert!((integral - 1.0).abs() < 2e-3, "{integral}");
        assert_eq!(sun.pdf(Vec3::new(0.0, (radius * 1.01).sin(), (radius * 1.01).cos())), 0.0);
    }

    #[test]
    fn a_delta_sun_gives_its_direction_and_irradiance() {
        let sun = Sun::new(Vec3::new(0.0, 3.0, 4.0), Rgb::new(5.0, 4.0, 3.0), 0.0).unwrap();
        let s = sun.sample(Vec2::new(0.3, 0.9));
        assert!(s.delta && s.pdf == 1.0 && s.radiance == Rgb::new(5.0, 4.0, 3.0));
        assert!((s.direction - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-6);
        assert_eq!((sun.pdf(s.direction), sun.radiance(s.direction)), (0.0, Rgb::ZERO));
        assert_eq!(sun.radiance_integral(), Rgb::new(5.0, 4.0, 3.0));
    }

    #[test]
    fn bad_suns_are_errors() {
        assert!(matches!(Sun::new(Vec3::ZERO, Rgb::ONE, 0.0), Err(InfiniteLightError::InvalidDirection { .. })));
        assert!(matches!(
            Sun::new(Vec3::Y, Rgb::new(1.0, -1.0, 1.0), 0.0),
            Err(InfiniteLightError::InvalidIrradiance { .. })
        ));
        assert!(matches!(Sun::new(Vec3::Y, Rgb::ONE, -0.1), Err(InfiniteLightError::InvalidAngularRadius(_))));
        assert!(matches!(Sun::new(Vec3::Y, Rgb::ONE, 2.0), Err(InfiniteLightError::InvalidAngularRadius(_))));
        assert!(matches!(Sun::new(Vec3::Y, Rgb::ONE, f32::NAN), Err(InfiniteLightError::InvalidAngularRadius(_))));
    }
}
