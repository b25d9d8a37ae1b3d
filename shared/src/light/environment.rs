//! Environment lights: a constant radiance from every direction, and an equirectangular (latitude-longitude)
//! RGB image in Mitsuba 3's `envmap` orientation, looked up bilinearly as Mitsuba does and importance-sampled
//! by a piecewise-constant density over the map's luminance weighted by sin θ.
//!
//! # Orientation (Mitsuba 3's convention)
//!
//! In the light's own frame (`to_world` maps it to the world), +Y is up. A W × H map's texel (x, y) (x across
//! a row, y = 0 the top row) is the radiance arriving from the direction with
//! u = (x + ½)/W, v = y/(H − 1), φ = 2π u, θ = π v:
//! ω = (sin φ sin θ, cos θ, −cos φ sin θ).
//! So the top row is the zenith (+Y), the bottom row the nadir (−Y), and along the horizon the map's left edge
//! (u = 0) faces −Z, a quarter across (u = ¼) faces +X, the middle (u = ½) +Z, three quarters (u = ¾) −X.
//! Between texel centres the radiance is bilinear, wrapping around from the last column to the first.
//! `scripts/mitsuba/envmap_orientation.py` prints Mitsuba's values that the tests here restate.
//!
//! # Sampling
//!
//! The bilinear radiance lives on W × (H − 1) cells between texel centres (cell (i, j) spans columns i, i + 1
//! mod W and rows j, j + 1). Each cell's weight is the integral over it of the bilinear luminance times sin θ,
//! so a cell is chosen in proportion to its share of ∫ luminance dω. A point (s, t) of the piecewise-constant
//! density p(s, t) over [0, 1)² becomes u = s + ½/W, v = t, and, since dω = sin θ dθ dφ = 2π² sin θ du dv,
//! the solid-angle density is p(s, t) / (2π² sin θ).

use crate::color::{luminance, Rgb};
use crate::light::infinite::{check_rotation, is_positive_colour, InfiniteLightError, InfiniteSample};
use crate::sampling::{uniform_sphere, DistributionError, Piecewise2d};
use crate::texture::Bitmap;
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// A constant environment: radiance `radiance` from every direction, sampled uniformly over the sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantEnvironment {
    radiance: Rgb,
}

impl ConstantEnvironment {
    /// The environment of radiance `radiance` (W·sr⁻¹·m⁻²; finite, non-negative, not black).
    pub fn new(radiance: Rgb) -> Result<Self, InfiniteLightError> {
        if !is_positive_colour(radiance) {
            return Err(InfiniteLightError::InvalidRadiance { value: radiance.to_array() });
        }
        Ok(ConstantEnvironment { radiance })
    }

    /// The radiance arriving from `direction` (any direction).
    pub fn radiance(&self, _direction: Vec3) -> Rgb {
        self.radiance
    }

    /// A direction uniform over the sphere (pdf 1/4π) and its radiance.
    pub fn sample(&self, u: Vec2) -> InfiniteSample {
        InfiniteSample { direction: uniform_sphere(u), radiance: self.radiance, pdf: 0.25 / PI, delta: false }
    }

    /// The solid-angle density of `sample`'s directions: 1/4π.
    pub fn pdf(&self, _direction: Vec3) -> f32 {
        0.25 / PI
    }

    /// ∫ L dω over the sphere, 4π L.
    pub fn radiance_integral(&self) -> Rgb {
        self.radiance * (4.0 * PI)
    }
}

/// An environment map: an equirectangular RGB image of linear radiance, scaled and rotated into the world.
#[derive(Clone, Debug)]
pub struct EnvironmentMap {
    width: usize,
    height: usize,
    /// Row-major, row 0 the zenith.
    texels: Vec<Rgb>,
    scale: f32,
    to_world: Mat3,
    to_local: Mat3,
    distribution: Piecewise2d,
    radiance_integral: Rgb,
}

/// The integrals over a band of rows θ0..θ1 of the two linear interpolation weights times sin θ:
/// ∫ (1 − t) sin θ dθ and ∫ t sin θ dθ with t = (θ − θ0)/(θ1 − θ0).
fn band_weights(theta0: f32, theta1: f32) -> (f32, f32) {
    let (t0, t1) = (theta0 as f64, theta1 as f64);
    let lower = -t1.cos() + (t1.sin() - t0.sin()) / (t1 - t0);
    let total = t0.cos() - t1.cos();
    ((total - lower) as f32, lower as f32)
}

/// The (u, v) of a direction in the map's own frame, both in [0, 1].
fn uv_of(d: Vec3) -> Vec2 {
    let mut u = d.x.atan2(-d.z) * (0.5 / PI);
    if u < 0.0 {
        u += 1.0;
    }
    Vec2::new(u.min(1.0), d.y.clamp(-1.0, 1.0).acos() / PI)
}

/// The direction of (u, v) in the map's own frame, and sin θ.
fn direction_of(uv: Vec2) -> (Vec3, f32) {
    let (sin_theta, cos_theta) = (PI * uv.y).sin_cos();
    let (sin_phi, cos_phi) = (2.0 * PI * uv.x).sin_cos();
    (Vec3::new(sin_phi * sin_theta, cos_theta, -cos_phi * sin_theta), sin_theta)
}

impl EnvironmentMap {
    /// The map of `width × height` texels (row-major, row 0 the zenith; linear RGB radiance, finite and
    /// non-negative, not all black) times `scale`, with `to_world` (a rotation) from the map's frame to the world.
    pub fn new(
        width: usize,
        height: usize,
        texels: Vec<Rgb>,
        scale: f32,
        to_world: Mat3,
    ) -> Result<Self, InfiniteLightError> {
        if width < 1 || height < 2 {
            return Err(InfiniteLightError::TooSmall { width, height });
        }
        let expected = width * height;
        if texels.len() != expected {
            return Err(InfiniteLightError::WrongLength { width, height, expected, given: texels.len() });
        }
        if let Some(i) = texels.iter().position(|t| !(t.is_finite() && t.min_element() >= 0.0)) {
            return Err(InfiniteLightError::InvalidTexel { x: i % width, y: i / width, value: texels[i].to_array() });
        }
        if !(scale.is_finite() && scale > 0.0) {
            return Err(InfiniteLightError::InvalidScale(scale));
        }
        check_rotation(to_world)?;

        let rows = height - 1;
        let mut weights = Vec::with_capacity(width * rows);
        let mut integral = Rgb::ZERO;
        let row_mean = |y: usize| texels[y * width..(y + 1) * width].iter().copied().sum::<Rgb>() / width as f32;
        for j in 0..rows {
            let (upper, lower) = band_weights(PI * j as f32 / rows as f32, PI * (j + 1) as f32 / rows as f32);
            // Across a row the periodic linear interpolation integrates to the row's mean.
            integral += (row_mean(j) * upper + row_mean(j + 1) * lower) * (2.0 * PI);
            for i in 0..width {
                let lum = |x: usize, y: usize| luminance(texels[y * width + x % width]);
                weights.push(
                    0.5 * (lum(i, j) + lum(i + 1, j)) * upper + 0.5 * (lum(i, j + 1) + lum(i + 1, j + 1)) * lower,
                );
            }
        }
        let distribution = Piecewise2d::new(&weights, width, rows).map_err(|e| match e {
            DistributionError::AllZero => InfiniteLightError::Black,
            // The texels were checked above, so no other error can arise.
            other => unreachable!("{other}"),
        })?;
        Ok(EnvironmentMap {
            width,
            height,
            texels,
            scale,
            to_world,
            to_local: to_world.transpose(),
            distribution,
            radiance_integral: integral * scale,
        })
    }

    /// The map of a decoded image (row 0 the zenith), as `new` takes texels.
    pub fn from_bitmap(bitmap: &Bitmap, scale: f32, to_world: Mat3) -> Result<Self, InfiniteLightError> {
        let (w, h) = (bitmap.width() as usize, bitmap.height() as usize);
        let texels = (0..w * h).map(|k| bitmap.texel((k % w) as i64, (k / w) as i64)).collect();
        EnvironmentMap::new(w, h, texels, scale, to_world)
    }

    /// The bilinear radiance at (u, v) of the map, times the scale.
    fn lookup(&self, uv: Vec2) -> Rgb {
        let (w, h) = (self.width, self.height);
        let gx = (uv.x * w as f32 - 0.5).rem_euclid(w as f32);
        let x0 = (gx as usize).min(w - 1);
        let fx = (gx - x0 as f32).clamp(0.0, 1.0);
        let x1 = (x0 + 1) % w;
        let gy = (uv.y * (h - 1) as f32).clamp(0.0, (h - 1) as f32);
        let y0 = (gy as usize).min(h - 2);
        let fy = gy - y0 as f32;
        let t = |x: usize, y: usize| self.texels[y * w + x];
        let top = t(x0, y0) * (1.0 - fx) + t(x1, y0) * fx;
        let bottom = t(x0, y0 + 1) * (1.0 - fx) + t(x1, y0 + 1) * fx;
        (top * (1.0 - fy) + bottom * fy) * self.scale
    }

    /// The radiance arriving from `direction` (unit, world, pointing from the scene toward the environment).
    pub fn radiance(&self, direction: Vec3) -> Rgb {
        self.lookup(uv_of(self.to_local * direction))
    }

    /// A direction drawn in proportion to luminance (see the module doc), its radiance and solid-angle pdf;
    /// None in the rare case of a sample exactly at a pole.
    pub fn sample(&self, u: Vec2) -> Option<InfiniteSample> {
        let (p, pdf) = self.distribution.sample(u);
        let mut s = p.x + 0.5 / self.width as f32;
        if s >= 1.0 {
            s -= 1.0;
        }
        let uv = Vec2::new(s, p.y);
        let (local, sin_theta) = direction_of(uv);
        if !(pdf > 0.0 && sin_theta > 0.0) {
            return None;
        }
        Some(InfiniteSample {
            direction: (self.to_world * local).normalize(),
            radiance: self.lookup(uv),
            pdf: pdf / (2.0 * PI * PI * sin_theta),
            delta: false,
        })
    }

    /// The solid-angle density with which `sample` draws `direction`.
    pub fn pdf(&self, direction: Vec3) -> f32 {
        let local = self.to_local * direction;
        let sin_theta = (local.x * local.x + local.z * local.z).sqrt();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let uv = uv_of(local);
        let mut s = uv.x - 0.5 / self.width as f32;
        if s < 0.0 {
            s += 1.0;
        }
        // At the nadir v rounds to 1, the edge of the last row of cells, which still holds it.
        let below_one = 1.0 - f32::EPSILON / 2.0;
        self.distribution.pdf(Vec2::new(s.min(below_one), uv.y.min(below_one))) / (2.0 * PI * PI * sin_theta)
    }

    /// ∫ L dω over the sphere (exact for the bilinear map), for the light's power over the scene.
    pub fn radiance_integral(&self) -> Rgb {
        self.radiance_integral
    }

    /// The map's (width, height) in texels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The rotation from the map's frame to the world.
    pub fn to_world(&self) -> Mat3 {
        self.to_world
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    /// The 8 × 5 map of scripts/mitsuba/envmap_orientation.py: texel (x, y) holds (x + 1, y + 1, 10 x + y + 1).
    fn labelled_map(to_world: Mat3) -> EnvironmentMap {
        let (w, h) = (8, 5);
        let texels =
            (0..w * h).map(|i| Rgb::new((i % w) as f32 + 1.0, (i / w) as f32 + 1.0, (10 * (i % w) + i / w + 1) as f32));
        EnvironmentMap::new(w, h, texels.collect(), 1.0, to_world).unwrap()
    }

    #[test]
    fn radiance_matches_mitsuba_orientation() {
        // Printed by Mitsuba 3.9.1 (scalar_rgb): direction toward the environment, and its radiance.
        let identity: [([f32; 3], [f32; 3]); 8] = [
            ([0.0, 0.0, -1.0], [4.5, 3.0, 38.0]),
            ([1.0, 0.0, 0.0], [2.5, 3.0, 18.0]),
            ([0.0, 0.0, 1.0], [4.5, 3.0, 38.0]),
            ([-1.0, 0.0, 0.0], [6.5, 3.0, 58.0]),
            ([0.0, 1.0, 0.0], [4.5, 1.0, 36.0]),
            ([0.0, -1.0, 0.0], [4.5, 5.0, 40.0]),
            ([0.3, 0.5, -0.8], [1.302394, 2.325857, 5.3498]),
            ([-0.6, -0.2, 0.4], [5.751331, 3.344475, 50.857788]),
        ];
        // `to_world` a rotation by +90° about y; the poles are left out, where φ is arbitrary.
        let rotated: [([f32; 3], [f32; 3]); 6] = [
            ([0.0, 0.0, -1.0], [2.5, 3.0, 18.0]),
            ([1.0, 0.0, 0.0], [4.5, 3.0, 38.0]),
            ([0.0, 0.0, 1.0], [6.5, 3.0, 58.0]),
            ([-1.0, 0.0, 0.0], [4.5, 3.0, 38.0]),
            ([0.3, 0.5, -0.8], [2.9568, 2.325858, 21.893862]),
            ([-0.6, -0.2, 0.4], [7.751331, 3.344475, 70.85779]),
        ];
        let cases = [
            (labelled_map(Mat3::IDENTITY), &identity[..]),
            (labelled_map(Mat3::from_rotation_y(PI / 2.0)), &rotated[..]),
        ];
        for (map, table) in cases {
            for &(d, expected) in table {
                let got = map.radiance(Vec3::from(d).normalize());
                let expected = Rgb::from(expected);
                assert!(
                    (got - expected).abs().max_element() < 1e-4 * expected.max_element(),
                    "{d:?}: {got} vs {expected}"
                );
            }
        }
    }

    /// A map with detail, rotated off the axes.
    fn busy_map() -> EnvironmentMap {
        let (w, h) = (16, 9);
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                Rgb::new(0.05 + ((x * 7 + y * 3) % 11) as f32, if x == 3 { 0.0 } else { 1.0 }, (y * y) as f32 * 0.1)
            })
            .collect();
        let rotation = Mat3::from_axis_angle(Vec3::new(0.2, 1.0, 0.4).normalize(), 1.1);
        EnvironmentMap::new(w, h, texels, 2.0, rotation).unwrap()
    }

    /// The direction of the equal-area cell (z, φ) of a grid with `nz` × `nphi` cells at fractions (a, b).
    fn equal_area_direction(k: usize, nz: usize, nphi: usize, a: f32, b: f32) -> Vec3 {
        let z = -1.0 + 2.0 * ((k / nphi) as f32 + a) / nz as f32;
        let phi = 2.0 * PI * ((k % nphi) as f32 + b) / nphi as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    #[test]
    fn the_pdf_integrates_to_one_over_the_sphere() {
        let map = busy_map();
        let (nz, nphi) = (600, 1200);
        let sum: f64 = (0..nz * nphi).map(|k| map.pdf(equal_area_direction(k, nz, nphi, 0.5, 0.5)) as f64).sum();
        let integral = sum * 4.0 * std::f64::consts::PI / (nz * nphi) as f64;
        assert!((integral - 1.0).abs() < 2e-3, "{integral}");
    }

    #[test]
    fn sampled_directions_follow_the_pdf_by_chi_square() {
        let map = busy_map();
        // Bins equal in solid angle, in a frame unrelated to the map's cells.
        let (nz, nphi) = (12, 24);
        let q = 8;
        let expected: Vec<f64> = (0..nz * nphi)
            .map(|k| {
                let mut s = 0.0f64;
                for a in 0..q {
                    for b in 0..q {
                        let d =
                            equal_area_direction(k, nz, nphi, (a as f32 + 0.5) / q as f32, (b as f32 + 0.5) / q as f32);
                        s += map.pdf(d) as f64;
                    }
                }
                s / (q * q) as f64 * 4.0 * std::f64::consts::PI / (nz * nphi) as f64
            })
            .collect();
        let n = 100_000;
        let mut observed = vec![0u32; nz * nphi];
        let mut rng = Sampler::new(5, Pass::Light, 0, 0);
        for _ in 0..n {
            let s = map.sample(rng.next_2d()).unwrap();
            // At the poles the azimuth, and with it the radiance, and sin θ, and with it the pdf, turn on the
            // last bits of the direction.
            let local = map.to_local * s.direction;
            if local.y.abs() < 0.9999 {
                let pdf = map.pdf(s.direction);
                assert!((s.pdf - pdf).abs() < 1e-3 * s.pdf, "{} vs {pdf}", s.pdf);
                let radiance = map.radiance(s.direction);
                assert!((s.radiance - radiance).abs().max_element() < 1e-3 * s.radiance.max_element(), "{radiance}");
            }
            let d = s.direction;
            let iz = (((d.z + 1.0) * 0.5 * nz as f32) as usize).min(nz - 1);
            let mut phi = d.y.atan2(d.x);
            if phi < 0.0 {
                phi += 2.0 * PI;
            }
            let iphi = ((phi / (2.0 * PI) * nphi as f32) as usize).min(nphi - 1);
            observed[iz * nphi + iphi] += 1;
        }
        let (mut stat, mut df) = (0.0, 0usize);
        for (&o, &e) in observed.iter().zip(&expected) {
            let e = e * n as f64;
            // Bins the quadrature puts near zero get no weight in the statistic but must stay empty.
            if e > 5.0 {
                stat += (o as f64 - e).powi(2) / e;
                df += 1;
            }
        }
        let df = (df - 1) as f64;
        assert!(stat < df + 6.0 * (2.0 * df).sqrt(), "chi-square {stat} with {df} degrees of freedom");
    }

    #[test]
    fn radiance_over_pdf_estimates_the_radiance_integral() {
        let map = busy_map();
        let mut rng = Sampler::new(6, Pass::Light, 0, 0);
        let n = 50_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let s = map.sample(rng.next_2d()).unwrap();
            let f = luminance(s.radiance) as f64 / s.pdf as f64;
            sum += f;
            sum2 += f * f;
        }
        let mean = sum / n as f64;
        let sem = ((sum2 / n as f64 - mean * mean) / (n - 1) as f64).sqrt();
        let exact = luminance(map.radiance_integral()) as f64;
        assert!((mean - exact).abs() < 4.0 * sem + 1e-4 * exact, "{mean} ± {sem} vs {exact}");
    }

    #[test]
    fn a_map_with_one_bright_texel_is_sampled_toward_it() {
        let (w, h) = (32, 17);
        let (bx, by) = (21, 5);
        let mut texels = vec![Rgb::splat(1e-3); w * h];
        texels[by * w + bx] = Rgb::new(5e4, 4e4, 3e4);
        let rotation = Mat3::from_rotation_x(0.4);
        let map = EnvironmentMap::new(w, h, texels, 1.0, rotation).unwrap();
        // The texel's centre in Mitsuba's convention.
        let (centre, _) = direction_of(Vec2::new((bx as f32 + 0.5) / w as f32, by as f32 / (h - 1) as f32));
        let centre = rotation * centre;
        assert!(map.radiance(centre).x > 4.9e4);
        // Its bilinear footprint reaches the neighbouring texel centres: one texel step in φ or θ.
        let reach = (2.0 * PI / w as f32).max(PI / (h - 1) as f32) * 1.5;
        let mut rng = Sampler::new(7, Pass::Light, 0, 0);
        let near = (0..2000).filter(|_| map.sample(rng.next_2d()).unwrap().direction.dot(centre) > reach.cos()).count();
        assert!(near >= 1990, "{near} of 2000 samples near the bright texel");
    }

    #[test]
    fn a_constant_environment_is_uniform() {
        let env = ConstantEnvironment::new(Rgb::new(1.0, 2.0, 0.5)).unwrap();
        let mut rng = Sampler::new(8, Pass::Light, 0, 0);
        let mut mean = Vec3::ZERO;
        for _ in 0..10_000 {
            let s = env.sample(rng.next_2d());
            assert!((s.direction.length() - 1.0).abs() < 1e-5 && s.pdf == env.pdf(s.direction));
            mean += s.direction / 10_000.0;
        }
        // The mean of uniform directions is 0 with a standard error of 1/√(3n) per axis.
        assert!(mean.abs().max_element() < 4.0 / (3.0f32 * 10_000.0).sqrt(), "{mean}");
        assert_eq!(env.radiance(Vec3::X), Rgb::new(1.0, 2.0, 0.5));
    }

    #[test]
    fn bad_maps_are_errors() {
        let ok = vec![Rgb::ONE; 4 * 3];
        assert!(matches!(
            EnvironmentMap::new(4, 1, vec![Rgb::ONE; 4], 1.0, Mat3::IDENTITY),
            Err(InfiniteLightError::TooSmall { .. })
        ));
        assert!(matches!(
            EnvironmentMap::new(4, 3, vec![Rgb::ONE; 11], 1.0, Mat3::IDENTITY),
            Err(InfiniteLightError::WrongLength { .. })
        ));
        let mut nan = ok.clone();
        nan[6] = Rgb::new(1.0, f32::NAN, 0.0);
        assert!(matches!(
            EnvironmentMap::new(4, 3, nan, 1.0, Mat3::IDENTITY),
            Err(InfiniteLightError::InvalidTexel { x: 2, y: 1, .. })
        ));
        let mut negative = ok.clone();
        negative[0] = Rgb::new(-1.0, 0.0, 0.0);
        assert!(matches!(
            EnvironmentMap::new(4, 3, negative, 1.0, Mat3::IDENTITY),
            Err(InfiniteLightError::InvalidTexel { x: 0, y: 0, .. })
        ));
        assert_eq!(
            EnvironmentMap::new(4, 3, vec![Rgb::ZERO; 12], 1.0, Mat3::IDENTITY).unwrap_err(),
            InfiniteLightError::Black
        );
        assert_eq!(
            EnvironmentMap::new(4, 3, ok.clone(), 0.0, Mat3::IDENTITY).unwrap_err(),
            InfiniteLightError::InvalidScale(0.0)
        );
        assert_eq!(
            EnvironmentMap::new(4, 3, ok, 1.0, Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0))).unwrap_err(),
            InfiniteLightError::NotARotation
        );
        assert!(ConstantEnvironment::new(Rgb::new(1.0, f32::INFINITY, 0.0)).is_err());
        assert!(ConstantEnvironment::new(Rgb::ZERO).is_err());
    }
}
