//! Light sources: emissive triangles (one-sided, front = CCW winding), point lights and spot lights, chosen by
//! power both for next-event estimation and for emitting light paths. Its submodules hold the infinite lights
//! (`environment`: constant and image-based; `directional`: the sun; `infinite`: the start of their light paths
//! and their power over the scene) and the sampling of spherical and disc emitters (`shape_sampling`).

pub mod directional;
pub mod environment;
pub mod infinite;
pub mod shape_sampling;

use crate::camera::RearElement;
use crate::color::{luminance, Rgb};
use crate::geometry::{SceneGeometry, SurfaceHit};
use crate::sampling::{concentric_disk, cosine_hemisphere};
use crate::sampling::{uniform_cone, uniform_sphere, uniform_triangle, Discrete, Frame};
use crate::texture::{barycentric, interpolate_uv, Bitmap};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

/// One light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// One triangle of an emissive object, radiance `emission` (W·sr⁻¹·m⁻²) from its front side.
    Area { triangle: u32, emission: Rgb, area: f32, normal: Vec3 },
    /// Isotropic point light of `intensity` (W/sr).
    Point { position: Vec3, intensity: Rgb },
    /// A point light restricted to a cone, with a smooth falloff between `cos_falloff_start` and `cos_total`.
    Spot { position: Vec3, direction: Vec3, intensity: Rgb, cos_total: f32, cos_falloff_start: f32 },
}

/// Incident light at a point, sampled for next-event estimation.
#[derive(Clone, Copy, Debug)]
pub struct IncidentSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// The point on the light (for the shadow ray).
    pub point: Vec3,
    /// Incident radiance (area lights) or intensity / d² (point and spot lights).
    pub li: Rgb,
    /// Solid-angle pdf including the light's selection probability; for delta lights, the selection
    /// probability alone.
    pub pdf: f32,
    /// True for point and spot lights, which MIS cannot weigh.
    pub delta: bool,
}

/// The start of a light path.
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    pub origin: Vec3,
    /// Surface normal at the origin (zero for point lights): the first ray is offset along it.
    pub normal: Vec3,
    pub direction: Vec3,
    /// Flux carried by the path: Le · cos / (pdf_select · pdf_position · pdf_direction).
    pub beta: Rgb,
    /// Which light emitted it, for per-light statistics.
    pub light: u32,
}

/// How an aimed light path picks its point on the aim disc: a density over the unit disc, in the disc's own
/// frame (`Frame::from_normal(disc.axis)`), that integrates to π like the uniform one.
pub trait AimDensity {
    /// A point of the unit disc for the uniform random numbers `u`.
    fn sample(&self, u: Vec2) -> Vec2;
    /// The density at the unit-disc point `p` relative to the uniform density (1 everywhere for uniform).
    fn relative(&self, p: Vec2) -> f32;
}

/// Every point of the aim disc alike.
#[derive(Clone, Copy, Debug, Default)]
pub struct UniformAim;

impl AimDensity for UniformAim {
    #[inline]
    fn sample(&self, u: Vec2) -> Vec2 {
        concentric_disk(u)
    }

    #[inline]
    fn relative(&self, _: Vec2) -> f32 {
        1.0
    }
}

/// A direction leaving `origin` (on a light with `normal`) toward a point of `disc` drawn from `density` with
/// probability `aimed` (below 1), by the cosine otherwise, chosen by `u.x` and rescaled so that `u` stays
/// stratified. None when it points behind the light, which emits nothing there.
fn aimed_direction(
    disc: &RearElement,
    density: &impl AimDensity,
    origin: Vec3,
    normal: Vec3,
    u: Vec2,
    aimed: f32,
) -> Option<Vec3> {
    let direction = if u.x < aimed {
        let d = density.sample(Vec2::new(u.x / aimed, u.y)) * disc.radius;
        let frame = Frame::from_normal(disc.axis);
        let to = disc.center + frame.s * d.x + frame.t * d.y - origin;
        to.try_normalize()?
    } else {
        let local = cosine_hemisphere(Vec2::new((u.x - aimed) / (1.0 - aimed), u.y));
        Frame::from_normal(normal).to_world(local)
    };
    (direction.dot(normal) > 0.0).then_some(direction)
}

/// Where a ray from `origin` along `direction` crosses `disc`, as a point of the unit disc in the disc's frame,
/// and the distance along the ray; None where it misses the disc.
pub fn disc_crossing(disc: &RearElement, origin: Vec3, direction: Vec3) -> Option<(Vec2, f32)> {
    let along = direction.dot(disc.axis);
    if along == 0.0 {
        return None;
    }
    let t = (disc.center - origin).dot(disc.axis) / along;
    let offset = origin + direction * t - disc.center;
    if t <= 0.0 || offset.length_squared() > disc.radius * disc.radius {
        return None;
    }
    let frame = Frame::from_normal(disc.axis);
    Some((Vec2::new(offset.dot(frame.s), offset.dot(frame.t)) / disc.radius, t))
}

/// Solid-angle pdf of aiming at a point of `disc` drawn from `density` from `origin` and leaving along
/// `direction`: d² ρ / (A cos θ_d) where the ray crosses the disc at relative density ρ, zero where it misses.
fn disc_pdf(disc: &RearElement, density: &impl AimDensity, origin: Vec3, direction: Vec3) -> f32 {
    let Some((p, t)) = disc_crossing(disc, origin, direction) else { return 0.0 };
    t * t * density.relative(p) / (PI * disc.radius * disc.radius * direction.dot(disc.axis).abs())
}

/// An emission texture on one emitting triangle: its radiance is `emission` times the texture at the point.
#[derive(Clone, Debug)]
pub struct EmissionTexture {
    pub texture: Arc<Bitmap>,
    /// The triangle's vertices, to find the texture coordinates of a point hit on it.
    pub vertices: [Vec3; 3],
    /// Texture coordinates of the vertices.
    pub uv: [Vec2; 3],
}

impl EmissionTexture {
    /// The texture's value at barycentrics `b`.
    #[inline]
    fn at_barycentric(&self, b: Vec2) -> Rgb {
        self.texture.lookup(interpolate_uv(&self.uv, b))
    }

    /// Mean of the texture over the triangle, estimated on a stratified grid of 16 × 16 cells. Light selection
    /// only needs it roughly (every estimator divides by the probability it used), but it must not be zero
    /// where the texture is not: it is kept at least 1/1000 of the whole texture's mean.
    pub fn mean_over_triangle(&self) -> Rgb {
        const N: usize = 16;
        let mut sum = Rgb::ZERO;
        for i in 0..N {
            for j in 0..N {
                let u = Vec2::new((i as f32 + 0.5) / N as f32, (j as f32 + 0.5) / N as f32);
                sum += self.at_barycentric(uniform_triangle(u));
            }
        }
        (sum / (N * N) as f32).max(self.texture.mean() * 1e-3)
    }
}

/// All lights of a scene and the power distribution that selects among them.
pub struct Lights {
    lights: Vec<Light>,
    by_power: Option<Discrete>,
    /// Light index of every scene triangle, u32::MAX for non-emitters.
    light_of_triangle: Vec<u32>,
    /// Emission texture of each light, parallel to `lights` (None for most).
    textures: Vec<Option<EmissionTexture>>,
    /// The disc area lights aim part of their light paths at (a lens's front element), if any.
    aim: Option<RearElement>,
    /// Lights whose image through the lens light paths bring to the sensor, parallel to `lights`
    /// (`crate::ghost::lens_images_by_light_paths`); empty when light paths register ghosts only.
    lens_image_by_light_paths: Vec<bool>,
}

/// The share of an area light's light paths aimed at the disc of `Lights::aim_at`, when the disc is in front of
/// it; the others leave by the cosine as without a disc, so the rest of the scene keeps its light.
pub const AIMED_FRACTION: f32 = 0.5;

impl Light {
    /// Emitted power in luminance units, the weight that chooses this light (without an emission texture:
    /// `Lights::with_textures` weighs a textured one by the texture's mean over its triangle).
    pub fn power(&self) -> f32 {
        match *self {
            Light::Area { emission, area, .. } => PI * area * luminance(emission),
            Light::Point { intensity, .. } => 4.0 * PI * luminance(intensity),
            Light::Spot { intensity, cos_total, cos_falloff_start, .. } => {
                2.0 * PI * (1.0 - 0.5 * (cos_total + cos_falloff_start)) * luminance(intensity)
            }
        }
    }
}

fn smoothstep(x: f32, a: f32, b: f32) -> f32 {
    if a == b {
        return if x < a { 0.0 } else { 1.0 };
    }
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn spot_falloff(cos_theta: f32, cos_total: f32, cos_falloff_start: f32) -> f32 {
    smoothstep(cos_theta, cos_total, cos_falloff_start)
}

impl Lights {
    /// Collects the lights; `triangle_count` sizes the triangle → light table.
    pub fn new(lights: Vec<Light>, triangle_count: usize) -> Self {
        let textures = vec![None; lights.len()];
        Lights::with_textures(lights, textures, triangle_count)
    }

    /// Collects the lights with the emission texture of each (parallel to `lights`). A textured light's power,
    /// which chooses it, is its emission times the texture's mean over its triangle; the emitted flux Φ = π A
    /// E[Le] is then what the sampled paths carry on average, since their positions stay uniform on the
    /// triangle and each carries the texture's value at its point.
    pub fn with_textures(lights: Vec<Light>, textures: Vec<Option<EmissionTexture>>, triangle_count: usize) -> Self {
        let mut light_of_triangle = vec![u32::MAX; triangle_count];
        for (i, l) in lights.iter().enumerate() {
            if let Light::Area { triangle, .. } = l {
                light_of_triangle[*triangle as usize] = i as u32;
            }
        }
        let mut textures = textures;
        textures.resize(lights.len(), None);
        let powers: Vec<f32> = lights
            .iter()
            .zip(&textures)
            .map(|(l, t)| match (l, t) {
                (Light::Area { emission, area, .. }, Some(t)) => {
                    PI * area * luminance(*emission * t.mean_over_triangle())
                }
                _ => l.power(),
            })
            .collect();
        Lights {
            by_power: Discrete::new(&powers),
            lights,
            light_of_triangle,
            textures,
            aim: None,
            lens_image_by_light_paths: Vec::new(),
        }
    }

    /// The emission texture's factor for light `l` at barycentrics `b` (one when it has none).
    #[inline]
    fn texture_factor(&self, l: usize, b: impl FnOnce(&EmissionTexture) -> Vec2) -> Rgb {
        match &self.textures[l] {
            Some(t) => t.at_barycentric(b(t)),
            None => Rgb::ONE,
        }
    }

    /// Every light, area lights (one per emitting triangle) first, then the `[[lights]]` entries in order.
    pub fn all(&self) -> &[Light] {
        &self.lights
    }

    /// Makes area lights aim `AIMED_FRACTION` of their light paths at `disc` (those that have it in front of
    /// them), with the pdf of the mixture of the two ways of leaving, so that estimates keep their expectation.
    pub fn aim_at(&mut self, disc: RearElement) {
        self.aim = Some(disc);
    }

    /// The disc light paths aim at, if any.
    pub fn aim(&self) -> Option<RearElement> {
        self.aim
    }

    /// The probability with which a light path starts at light `l`.
    pub fn selection_pmf(&self, l: usize) -> f32 {
        self.by_power.as_ref().map_or(0.0, |d| d.pmf(l))
    }

    /// Hands the image through the lens of each light flagged in `by_light_paths` (parallel to `all()`) to
    /// light paths: they register it on the sensor and camera paths leave it to them.
    pub fn set_lens_images_by_light_paths(&mut self, by_light_paths: Vec<bool>) {
        assert_eq!(by_light_paths.len(), self.lights.len(), "one flag per light");
        self.lens_image_by_light_paths = by_light_paths;
    }

    /// True when light paths bring light `l`'s image through the lens to the sensor.
    #[inline]
    pub fn lens_image_by_light_paths(&self, l: u32) -> bool {
        self.lens_image_by_light_paths.get(l as usize).copied().unwrap_or(false)
    }

    /// True when the emitter at `hit` is a light whose image through the lens light paths bring.
    #[inline]
    pub fn lens_image_by_light_paths_at(&self, hit: &SurfaceHit) -> bool {
        !self.lens_image_by_light_paths.is_empty()
            && self.light_of_triangle.get(hit.triangle as usize).is_some_and(|&l| self.lens_image_by_light_paths(l))
    }

    /// True when the scene has at least one light with power.
    pub fn any(&self) -> bool {
        self.by_power.is_some()
    }

    /// Radiance leaving an emitter hit toward the viewer at `-ray_dir` (zero from the back side).
    pub fn emitted(&self, hit: &SurfaceHit, ray_dir: Vec3) -> Rgb {
        if hit.triangle == u32::MAX {
            return Rgb::ZERO;
        }
        match self.light_of_triangle.get(hit.triangle as usize) {
            Some(&l) if l != u32::MAX => match self.lights[l as usize] {
                Light::Area { emission, normal, .. } if ray_dir.dot(normal) < 0.0 => {
                    emission * self.texture_factor(l as usize, |t| barycentric(&t.vertices, hit.p))
                }
                _ => Rgb::ZERO,
            },
            _ => Rgb::ZERO,
        }
    }

    /// Solid-angle pdf with which next-event estimation from `from` would have chosen the emitter point `hit`.
    pub fn pdf_incident(&self, from: Vec3, hit: &SurfaceHit) -> f32 {
        let Some(dist) = &self.by_power else { return 0.0 };
        let Some(&l) = self.light_of_triangle.get(hit.triangle as usize) else {
            return 0.0;
        };
        if l == u32::MAX {
            return 0.0;
        }
        let Light::Area { area, normal, .. } = self.lights[l as usize] else {
            return 0.0;
        };
        let d = hit.p - from;
        let d2 = d.length_squared();
        let cos_l = (-d.normalize()).dot(normal);
        if cos_l <= 0.0 {
            return 0.0;
        }
        dist.pmf(l as usize) * d2 / (area * cos_l)
    }

    /// Samples light arriving at `p` (paper eq. 3/5's light-sampling term).
    pub fn sample_incident(&self, geometry: &SceneGeometry, p: Vec3, u_select: f32, u: Vec2) -> Option<IncidentSample> {
        let (index, pmf) = self.by_power.as_ref()?.sample(u_select);
        match self.lights[index] {
            Light::Area { triangle, emission, area, normal } => {
                let tri = geometry.triangle(triangle);
                let b = uniform_triangle(u);
                let q = tri.v[0] * (1.0 - b.x - b.y) + tri.v[1] * b.x + tri.v[2] * b.y;
                let d = q - p;
                let d2 = d.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let wi = d / d2.sqrt();
                let cos_l = (-wi).dot(normal);
                if cos_l <= 0.0 {
                    return None;
                }
                let li = emission * self.texture_factor(index, |_| b);
                Some(IncidentSample { wi, point: q, li, pdf: pmf * d2 / (area * cos_l), delta: false })
            }
            Light::Point { position, intensity } => {
                let d = position - p;
                let d2 = d.length_squared();
                Some(IncidentSample { wi: d / d2.sqrt(), point: position, li: intensity / d2, pdf: pmf, delta: true })
            }
            Light::Spot { position, direction, intensity, cos_total, cos_falloff_start } => {
                let d = position - p;
                let d2 = d.length_squared();
                let wi = d / d2.sqrt();
                let falloff = spot_falloff((-wi).dot(direction), cos_total, cos_falloff_start);
                if falloff <= 0.0 {
                    return None;
                }
                Some(IncidentSample { wi, point: position, li: intensity * falloff / d2, pdf: pmf, delta: true })
            }
        }
    }

    /// Starts a light path: a light chosen by power, a point on it and a direction.
    pub fn sample_emission(
        &self,
        geometry: &SceneGeometry,
        u_select: f32,
        u_pos: Vec2,
        u_dir: Vec2,
    ) -> Option<EmissionSample> {
        self.sample_emission_aimed(geometry, u_select, u_pos, u_dir, AIMED_FRACTION, &UniformAim)
    }

    /// `sample_emission` with `aimed` (in (0, 1)) of an area light's paths aimed at the disc of `aim_at`
    /// instead of `AIMED_FRACTION`, at points of it drawn from `density`.
    pub fn sample_emission_aimed(
        &self,
        geometry: &SceneGeometry,
        u_select: f32,
        u_pos: Vec2,
        u_dir: Vec2,
        aimed: f32,
        density: &impl AimDensity,
    ) -> Option<EmissionSample> {
        let (index, pmf) = self.by_power.as_ref()?.sample(u_select);
        let sample = match self.lights[index] {
            Light::Area { triangle, emission, area, normal } => {
                let tri = geometry.triangle(triangle);
                let b = uniform_triangle(u_pos);
                let origin = tri.v[0] * (1.0 - b.x - b.y) + tri.v[1] * b.x + tri.v[2] * b.y;
                if let Some(disc) = self.aim.filter(|d| (d.center - tri.v[0]).dot(normal) > 0.0) {
                    let direction = aimed_direction(&disc, density, origin, normal, u_dir, aimed)?;
                    let cos = direction.dot(normal);
                    let pdf = (1.0 - aimed) * cos * std::f32::consts::FRAC_1_PI
                        + aimed * disc_pdf(&disc, density, origin, direction);
                    return Some(EmissionSample {
                        origin,
                        normal,
                        direction,
                        beta: emission * self.texture_factor(index, |_| b) * (cos * area / (pmf * pdf)),
                        light: index as u32,
                    });
                }
                let local = cosine_hemisphere(u_dir);
                if local.z <= 0.0 {
                    return None;
                }
                // Le cos / ((1/A) (cos/π)) = Le π A
                EmissionSample {
                    origin,
                    normal,
                    direction: Frame::from_normal(normal).to_world(local),
                    beta: emission * self.texture_factor(index, |_| b) * (PI * area / pmf),
                    light: index as u32,
                }
            }
            Light::Point { position, intensity } => EmissionSample {
                origin: position,
                normal: Vec3::ZERO,
                direction: uniform_sphere(u_dir),
                beta: intensity * (4.0 * PI / pmf),
                light: index as u32,
            },
            Light::Spot { position, direction, intensity, cos_total, cos_falloff_start } => {
                let local = uniform_cone(u_dir, cos_total);
                let falloff = spot_falloff(local.z, cos_total, cos_falloff_start);
                EmissionSample {
                    origin: position,
                    normal: Vec3::ZERO,
                    direction: Frame::from_normal(direction).to_world(local),
                    beta: intensity * (falloff * 2.0 * PI * (1.0 - cos_total) / pmf),
                    light: index as u32,
                }
            }
        };
        Some(sample)
    }
}
