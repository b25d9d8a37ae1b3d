//! Sampling points on the analytic emitters, spheres and discs, as seen from a reference point: a sphere by
//! the cone of directions it subtends (uniform in solid angle over the cone, as pbrt-v4 and Mitsuba 3 do), or
//! by area from inside it; a disc by area. Densities are per unit solid angle at the reference point; an area
//! density p_A becomes p_ω = p_A d² / |cos θ_l| with d the distance and θ_l the angle at the emitter.

use crate::sampling::{concentric_disk, uniform_sphere, Frame};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A point on an emitter sampled from a reference point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeSample {
    /// The point on the emitter's surface.
    pub point: Vec3,
    /// The surface's outward normal there (the disc's own normal, either side).
    pub normal: Vec3,
    /// Unit direction from the reference point to `point`.
    pub direction: Vec3,
    /// Distance from the reference point to `point`.
    pub distance: f32,
    /// Solid-angle density of `direction` at the reference point.
    pub pdf: f32,
}

/// A sphere, sampled by the solid angle it subtends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereSampling {
    pub center: Vec3,
    pub radius: f32,
}

/// 1 − cos θ for sin² θ (θ below 90°), as sin² θ / (1 + cos θ): exact where 1 − cos θ in f32 would lose its
/// digits, for a sphere seen under a fraction of a degree.
fn one_minus_cos(sin2: f32) -> f32 {
    sin2 / (1.0 + (1.0 - sin2).max(0.0).sqrt())
}

/// The nearer (or, from inside, the only forward) distance at which the ray from `origin` along unit
/// `direction` meets the sphere, if it does.
fn ray_sphere(origin: Vec3, direction: Vec3, center: Vec3, radius: f32) -> Option<f32> {
    let oc = origin - center;
    let b = oc.dot(direction);
    // The perpendicular distance from the centre, computed without the cancellation of b² − c.
    let perpendicular = (oc - b * direction).length_squared();
    let disc = radius * radius - perpendicular;
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let near = -b - root;
    let far = -b + root;
    if near > 0.0 {
        Some(near)
    } else if far > 0.0 {
        Some(far)
    } else {
        None
    }
}

impl SphereSampling {
    /// A point of the sphere seen from `from`: from outside, uniform over the cone of directions the sphere
    /// subtends (the point is the nearer intersection); from inside, uniform over its area.
    pub fn sample(&self, from: Vec3, u: Vec2) -> Option<ShapeSample> {
        let to_center = self.center - from;
        let d2 = to_center.length_squared();
        let r2 = self.radius * self.radius;
        if self.radius.is_nan() || self.radius <= 0.0 {
            return None;
        }
        if d2 <= r2 {
            let normal = uniform_sphere(u);
            let point = self.center + self.radius * normal;
            let offset = point - from;
            let distance = offset.length();
            if distance <= 0.0 {
                return None;
            }
            let direction = offset / distance;
            let cos = normal.dot(direction).abs();
            if cos <= 0.0 {
                return None;
            }
            let pdf = distance * distance / (4.0 * PI * r2 * cos);
            return Some(ShapeSample { point, normal, direction, distance, pdf });
        }
        let sin2_max = r2 / d2;
        let sin_max = sin2_max.sqrt();
        let one_minus_cos_max = one_minus_cos(sin2_max);
        // θ: the angle at `from` between the axis and the sampled direction, uniform in solid angle; kept as
        // 1 − cos θ for the same precision.
        let one_minus_cos_theta = u.x * one_minus_cos_max;
        let sin2_theta = one_minus_cos_theta * (2.0 - one_minus_cos_theta);
        let cos_theta = 1.0 - one_minus_cos_theta;
        // α: the angle at the centre between the axis (toward `from`) and the point where the sampled direction
        // first meets the sphere.
        let cos_alpha = sin2_theta / sin_max + cos_theta * (1.0 - sin2_theta / sin2_max).max(0.0).sqrt();
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let frame = Frame::from_normal(to_center / d2.sqrt());
        let normal = frame.to_world(-Vec3::new(sin_alpha * phi.cos(), sin_alpha * phi.sin(), cos_alpha)).normalize();
        let point = self.center + self.radius * normal;
        let offset = point - from;
        let distance = offset.length();
        Some(ShapeSample {
            point,
            normal,
            direction: offset / distance,
            distance,
            pdf: 1.0 / (2.0 * PI * one_minus_cos_max),
        })
    }

    /// The solid-angle density with which `sample` from `from` draws `direction` (unit).
    pub fn pdf(&self, from: Vec3, direction: Vec3) -> f32 {
        let to_center = self.center - from;
        let d2 = to_center.length_squared();
        let r2 = self.radius * self.radius;
        if self.radius.is_nan() || self.radius <= 0.0 {
            return 0.0;
        }
        let Some(t) = ray_sphere(from, direction, self.center, self.radius) else {
            return 0.0;
        };
        if d2 <= r2 {
            let normal = (from + t * direction - self.center) / self.radius;
            let cos = normal.dot(direction).abs();
            return if cos > 0.0 { t * t / (4.0 * PI * r2 * cos) } else { 0.0 };
        }
        1.0 / (2.0 * PI * one_minus_cos(r2 / d2))
    }
}

/// A disc (an annulus of inner radius 0), sampled uniformly by area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscSampling {
    pub center: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    pub radius: f32,
}

impl DiscSampling {
    /// The disc's area, π r².
    pub fn area(&self) -> f32 {
        PI * self.radius * self.radius
    }

    /// A point uniform over the disc's area (density 1 / area).
    pub fn sample_point(&self, u: Vec2) -> Vec3 {
        let frame = Frame::from_normal(self.normal);
        let d = concentric_disk(u) * self.radius;
        self.center + frame.s * d.x + frame.t * d.y
    }

    /// A point uniform over the disc's area, with its solid-angle density at `from`; None when `from` lies
    /// in the disc's plane (the disc is seen edge-on).
    pub fn sample(&self, from: Vec3, u: Vec2) -> Option<ShapeSample> {
        let point = self.sample_point(u);
        let offset = point - from;
        let distance = offset.length();
        if distance <= 0.0 {
            return None;
        }
        let direction = offset / distance;
        let cos = self.normal.dot(direction).abs();
        if cos <= 0.0 {
            return None;
        }
        let pdf = distance * distance / (self.area() * cos);
        Some(ShapeSample { point, normal: self.normal, direction, distance, pdf })
    }

    /// The solid-angle density with which `sample` from `from` draws `direction` (unit).
    pub fn pdf(&self, from: Vec3, direction: Vec3) -> f32 {
        let denom = direction.dot(self.normal);
        if denom == 0.0 {
            return 0.0;
        }
        let t = (self.center - from).dot(self.normal) / denom;
        if t.is_nan() || t <= 0.0 {
            return 0.0;
        }
        let hit = from + t * direction;
        if (hit - self.center).length_squared() > self.radius * self.radius {
            return 0.0;
        }
        t * t / (self.area() * denom.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    /// Mean and standard error of `f` over `n` draws of two uniform numbers.
    fn estimate(seed: u64, n: usize, mut f: impl FnMut(Vec2) -> f64) -> (f64, f64) {
        let mut rng = Sampler::new(seed, Pass::Light, 0, 0);
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..n {
            let v = f(rng.next_2d());
            sum += v;
            sum2 += v * v;
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean) / (n - 1) as f64).sqrt())
    }

    /// ∫ pdf dω over the sphere of directions at `from`, by quadrature on an equal-area grid.
    fn pdf_integral(pdf: impl Fn(Vec3) -> f32) -> f64 {
        let (nz, nphi) = (2000, 2000);
        let mut sum = 0.0f64;
        for i in 0..nz {
            let z = -1.0 + 2.0 * (i as f32 + 0.5) / nz as f32;
            let r = (1.0 - z * z).sqrt();
            for j in 0..nphi {
                let phi = 2.0 * PI * (j as f32 + 0.5) / nphi as f32;
                sum += pdf(Vec3::new(r * phi.cos(), r * phi.sin(), z)) as f64;
            }
        }
        sum * 4.0 * std::f64::consts::PI / (nz * nphi) as f64
    }

    #[test]
    fn a_sphere_sampled_by_its_cone_gives_the_irradiance_of_a_uniform_sphere() {
        // A sphere of radiance 1 seen face-on from distance d gives E = π (r/d)²; the far one is seen under
        // 0.6°, where 1 − cos θ_max in f32 would have lost its digits.
        for (sphere, from) in [
            (SphereSampling { center: Vec3::new(1.0, 2.0, 3.0), radius: 1.0 }, Vec3::new(1.0, 2.0, 0.0)),
            (SphereSampling { center: Vec3::new(0.0, 0.0, 200.0), radius: 2.0 }, Vec3::ZERO),
        ] {
            let axis = (sphere.center - from).normalize();
            let (mean, sem) = estimate(21, 50_000, |u| {
                let s = sphere.sample(from, u).unwrap();
                assert!(
                    ((s.point - sphere.center).length() - sphere.radius).abs() < 1e-4 * sphere.center.length().max(1.0)
                );
                // The point is the nearer intersection: its normal faces the reference point.
                assert!(s.normal.dot(-s.direction) >= -1e-3, "{}", s.normal.dot(-s.direction));
                let pdf = sphere.pdf(from, s.direction);
                assert!((pdf - s.pdf).abs() <= 1e-4 * s.pdf, "{pdf} vs {}", s.pdf);
                (s.direction.dot(axis) / s.pdf) as f64
            });
            let d2 = (sphere.center - from).length_squared() as f64;
            let expected = std::f64::consts::PI * (sphere.radius as f64).powi(2) / d2;
            assert!((mean - expected).abs() < 4.0 * sem + 1e-5 * expected, "{mean} ± {sem} vs {expected}");
        }
    }

    #[test]
    fn the_sphere_pdf_integrates_to_one_from_outside_and_inside() {
        let sphere = SphereSampling { center: Vec3::new(0.5, -1.0, 2.0), radius: 1.5 };
        for from in [Vec3::new(3.0, 1.0, 0.0), sphere.center + Vec3::new(0.3, 0.9, -0.2)] {
            let integral = pdf_integral(|d| sphere.pdf(from, d));
            assert!((integral - 1.0).abs() < 3e-3, "from {from}: {integral}");
        }
    }

    #[test]
    fn from_inside_a_sphere_area_sampling_covers_every_direction() {
        let sphere = SphereSampling { center: Vec3::ZERO, radius: 2.0 };
        let from = Vec3::new(0.4, -1.1, 0.7);
        // E[1/pdf] is the solid angle covered: all of it.
        let (mean, sem) = estimate(22, 50_000, |u| {
            let s = sphere.sample(from, u).unwrap();
            assert!((sphere.pdf(from, s.direction) - s.pdf).abs() <= 1e-3 * s.pdf);
            1.0 / s.pdf as f64
        });
        let expected = 4.0 * std::f64::consts::PI;
        assert!((mean - expected).abs() < 4.0 * sem, "{mean} ± {sem} vs {expected}");
    }

    #[test]
    fn a_disc_sampled_by_area_gives_the_irradiance_on_its_axis() {
        // A disc of radius R and radiance 1 seen from its axis at height h gives E = π R² / (h² + R²).
        let disc = DiscSampling { center: Vec3::new(1.0, 1.0, 1.0), normal: Vec3::new(0.0, 0.6, 0.8), radius: 0.7 };
        let h = 1.3;
        let from = disc.center + disc.normal * h;
        let (mean, sem) = estimate(23, 50_000, |u| {
            let s = disc.sample(from, u).unwrap();
            assert!((disc.pdf(from, s.direction) - s.pdf).abs() <= 1e-3 * s.pdf);
            assert!((s.point - disc.center).dot(disc.normal).abs() < 1e-5);
            (s.direction.dot(-disc.normal) / s.pdf) as f64
        });
        let expected = std::f64::consts::PI * 0.49 / (1.69 + 0.49);
        assert!((mean - expected).abs() < 4.0 * sem, "{mean} ± {sem} vs {expected}");
        let integral = pdf_integral(|d| disc.pdf(from + Vec3::new(0.2, 0.0, 0.1), d));
        assert!((integral - 1.0).abs() < 3e-3, "{integral}");
    }
}
