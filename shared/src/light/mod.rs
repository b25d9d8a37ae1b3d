//! Light sources: emissive triangles (one-sided, front = CCW winding), emitting analytic spheres and discs, point
//! lights, spot lights and lights at infinity (environments and the sun), chosen by power both for next-event
//! estimation and for emitting light paths. Its submodules hold the infinite lights (`environment`: constant and
//! image-based; `directional`: the sun; `infinite`: the start of their light paths and their power over the
//! scene), the sampling of spherical and disc emitters (`shape_sampling`), and the densities over a lens's front
//! element that ghost paths aim by (`ghost_aim`).

pub mod directional;
pub mod environment;
pub mod ghost_aim;
pub mod infinite;
pub mod shape_sampling;

use crate::camera::RearElement;
use crate::color::{luminance, Rgb};
use crate::geometry::{Analytic, SceneGeometry, SurfaceHit};
use crate::sampling::{concentric_disk, cosine_hemisphere};
use crate::sampling::{power_heuristic, uniform_cone, uniform_sphere, uniform_triangle, Discrete, Frame};
use crate::texture::{barycentric, interpolate_uv, Bitmap};
use glam::{Vec2, Vec3};
use infinite::{InfiniteLight, SceneSphere};
use shape_sampling::{DiscSampling, SphereSampling};
use std::f32::consts::PI;
use std::sync::Arc;

/// One light source.
#[derive(Clone, Debug)]
pub enum Light {
    /// One triangle of an emissive object, radiance `emission` (W·sr⁻¹·m⁻²) from its front side.
    Area { triangle: u32, emission: Rgb, area: f32, normal: Vec3 },
    /// Isotropic point light of `intensity` (W/sr).
    Point { position: Vec3, intensity: Rgb },
    /// A point light restricted to a cone, with a smooth falloff between `cos_falloff_start` and `cos_total`.
    Spot { position: Vec3, direction: Vec3, intensity: Rgb, cos_total: f32, cos_falloff_start: f32 },
    /// The analytic sphere of object `object`, radiance `emission` leaving its outside (seen from inside it
    /// is black, as a one-sided emitter's back is).
    Sphere { object: u32, center: Vec3, radius: f32, emission: Rgb },
    /// The analytic disc (an annulus of inner radius 0) of object `object`, radiance `emission` leaving the side
    /// its unit `normal` faces (the surface's normal, −axis).
    Disc { object: u32, center: Vec3, normal: Vec3, radius: f32, emission: Rgb },
    /// A light at infinity: a constant environment, an environment map or the sun.
    Infinite(InfiniteLight),
}

/// Incident light at a point, sampled for next-event estimation.
#[derive(Clone, Copy, Debug)]
pub struct IncidentSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// The point on the light (for the shadow ray).
    pub point: Vec3,
    /// Incident radiance (area, shape and infinite lights), intensity / d² (point and spot lights) or
    /// irradiance (a sun without angular radius).
    pub li: Rgb,
    /// Solid-angle pdf including the light's selection probability; for delta lights, the selection
    /// probability alone.
    pub pdf: f32,
    /// True for point and spot lights and a sun without radius, which MIS cannot weigh.
    pub delta: bool,
}

/// The start of a light path.
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    pub origin: Vec3,
    /// Surface normal at the origin (zero for point lights and infinite lights, whose paths start off every
    /// surface): the first ray is offset along it.
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
    /// Light index of every object up to the last emitting analytic one, u32::MAX for the others.
    light_of_object: Vec<u32>,
    /// The infinite lights a path can hit (all but delta suns): what an escaping path sees.
    escaping: Vec<u32>,
    /// The scene's bounding sphere: where infinite lights' paths start, and what their power is over.
    sphere: SceneSphere,
    /// Emission texture of each light, parallel to `lights` (None for most).
    textures: Vec<Option<EmissionTexture>>,
    /// The disc area lights aim part of their light paths at (a lens's front element), if any.
    aim: Option<RearElement>,
    /// Lights whose image through the lens light paths bring to the sensor, parallel to `lights`
    /// (`crate::scene::ghost::lens_images_by_light_paths`); empty when light paths register ghosts only.
    lens_image_by_light_paths: Vec<bool>,
}

/// The share of an area light's light paths aimed at the disc of `Lights::aim_at`, when the disc is in front of
/// it; the others leave by the cosine as without a disc, so the rest of the scene keeps its light.
pub const AIMED_FRACTION: f32 = 0.5;

impl Light {
    /// The light of object `object`'s analytic surface emitting `emission`; None for the surfaces that cannot
    /// emit (lens surfaces and annuli with a hole).
    pub fn of_analytic(object: u32, shape: &Analytic, emission: Rgb) -> Option<Light> {
        match *shape {
            Analytic::Sphere(sp) => Some(Light::Sphere { object, center: sp.center, radius: sp.radius, emission }),
            // The annulus's surface normal is −axis: a disc emits toward −axis.
            Analytic::Annulus(a) if a.inner_radius == 0.0 => {
                Some(Light::Disc { object, center: a.center, normal: -a.axis, radius: a.outer_radius, emission })
            }
            _ => None,
        }
    }

    /// Emitted power in luminance units, the weight that chooses this light (without an emission texture:
    /// `Lights::with_textures` weighs a textured one by the texture's mean over its triangle); an infinite
    /// light's is what it sends through the scene's bounding sphere `scene`, π r² ∫ L dω.
    pub fn power(&self, scene: &SceneSphere) -> f32 {
        match self {
            Light::Area { emission, area, .. } => PI * area * luminance(*emission),
            Light::Point { intensity, .. } => 4.0 * PI * luminance(*intensity),
            Light::Spot { intensity, cos_total, cos_falloff_start, .. } => {
                2.0 * PI * (1.0 - 0.5 * (cos_total + cos_falloff_start)) * luminance(*intensity)
            }
            // Φ = π A L for a Lambertian emitter of area A.
            Light::Sphere { radius, emission, .. } => PI * 4.0 * PI * radius * radius * luminance(*emission),
            Light::Disc { radius, emission, .. } => PI * PI * radius * radius * luminance(*emission),
            Light::Infinite(l) => luminance(scene.power(l.radiance_integral())),
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
    /// Collects the lights; `triangle_count` sizes the triangle → light table, `sphere` bounds the scene.
    pub fn new(lights: Vec<Light>, triangle_count: usize, sphere: SceneSphere) -> Self {
        let textures = vec![None; lights.len()];
        Lights::with_textures(lights, textures, triangle_count, sphere)
    }

    /// Collects the lights with the emission texture of each (parallel to `lights`). A textured light's power,
    /// which chooses it, is its emission times the texture's mean over its triangle; the emitted flux Φ = π A
    /// E[Le] is then what the sampled paths carry on average, since their positions stay uniform on the
    /// triangle and each carries the texture's value at its point. Infinite lights start their paths on, and
    /// are weighed by their power through, the scene's bounding sphere `sphere`.
    pub fn with_textures(
        lights: Vec<Light>,
        textures: Vec<Option<EmissionTexture>>,
        triangle_count: usize,
        sphere: SceneSphere,
    ) -> Self {
        let mut light_of_triangle = vec![u32::MAX; triangle_count];
        let mut light_of_object = Vec::new();
        let mut escaping = Vec::new();
        for (i, l) in lights.iter().enumerate() {
            match l {
                Light::Area { triangle, .. } => light_of_triangle[*triangle as usize] = i as u32,
                Light::Sphere { object, .. } | Light::Disc { object, .. } => {
                    let o = *object as usize;
                    if light_of_object.len() <= o {
                        light_of_object.resize(o + 1, u32::MAX);
                    }
                    light_of_object[o] = i as u32;
                }
                Light::Infinite(inf) if !inf.is_delta() => escaping.push(i as u32),
                _ => {}
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
                _ => l.power(&sphere),
            })
            .collect();
        Lights {
            by_power: Discrete::new(&powers),
            lights,
            light_of_triangle,
            light_of_object,
            escaping,
            sphere,
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

    /// The light whose surface `hit` is on, if it emits.
    #[inline]
    fn light_at(&self, hit: &SurfaceHit) -> Option<usize> {
        let l = if hit.triangle == u32::MAX {
            self.light_of_object.get(hit.object as usize)
        } else {
            self.light_of_triangle.get(hit.triangle as usize)
        };
        l.filter(|&&l| l != u32::MAX).map(|&l| l as usize)
    }

    /// The scene's bounding sphere, over which infinite lights start their paths.
    pub fn scene_sphere(&self) -> SceneSphere {
        self.sphere
    }

    /// True when some infinite light can be seen by a path that leaves the scene.
    pub fn any_escaping(&self) -> bool {
        !self.escaping.is_empty()
    }

    /// The radiance a path that leaves the scene along `direction` (unit) receives from the infinite lights.
    /// With `bsdf_pdf` (the solid-angle pdf of the BSDF sample that left), each light's share is weighted by
    /// the power heuristic against the pdf with which next-event estimation would have chosen the direction:
    /// w = p_bsdf² / (p_bsdf² + (P_select p_light)²).
    pub fn escaped(&self, direction: Vec3, bsdf_pdf: Option<f32>) -> Rgb {
        let mut sum = Rgb::ZERO;
        for &l in &self.escaping {
            let Light::Infinite(inf) = &self.lights[l as usize] else { continue };
            let le = inf.radiance(direction);
            if le == Rgb::ZERO {
                continue;
            }
            let m = bsdf_pdf.map_or(1.0, |p| power_heuristic(p, self.selection_pmf(l as usize) * inf.pdf(direction)));
            sum += le * m;
        }
        sum
    }

    /// Radiance leaving an emitter hit toward the viewer at `-ray_dir` (zero from the back side).
    pub fn emitted(&self, hit: &SurfaceHit, ray_dir: Vec3) -> Rgb {
        if hit.triangle == u32::MAX {
            return match self.light_at(hit).map(|l| &self.lights[l]) {
                Some(Light::Sphere { emission, .. } | Light::Disc { emission, .. }) if ray_dir.dot(hit.ng) < 0.0 => {
                    *emission
                }
                _ => Rgb::ZERO,
            };
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
        let Some(l) = self.light_at(hit) else { return 0.0 };
        let (area, normal) = match self.lights[l] {
            Light::Area { area, normal, .. } => (area, normal),
            Light::Sphere { center, radius, .. } => {
                let Some(direction) = (hit.p - from).try_normalize() else { return 0.0 };
                return dist.pmf(l) * SphereSampling { center, radius }.pdf(from, direction);
            }
            Light::Disc { center, normal, radius, .. } => {
                let Some(direction) = (hit.p - from).try_normalize() else { return 0.0 };
                return dist.pmf(l) * DiscSampling { center, normal, radius }.pdf(from, direction);
            }
            _ => return 0.0,
        };
        let d = hit.p - from;
        let d2 = d.length_squared();
        let cos_l = (-d.normalize()).dot(normal);
        if cos_l <= 0.0 {
            return 0.0;
        }
        dist.pmf(l) * d2 / (area * cos_l)
    }

    /// Samples light arriving at `p` (paper eq. 3/5's light-sampling term).
    pub fn sample_incident(&self, geometry: &SceneGeometry, p: Vec3, u_select: f32, u: Vec2) -> Option<IncidentSample> {
        let (index, pmf) = self.by_power.as_ref()?.sample(u_select);
        match self.lights[index] {
            Light::Sphere { center, radius, emission, .. } => {
                let s = SphereSampling { center, radius }.sample(p, u)?;
                // From inside, the sample is on the sphere's inside, which emits nothing.
                if s.normal.dot(s.direction) >= 0.0 {
                    return None;
                }
                Some(IncidentSample { wi: s.direction, point: s.point, li: emission, pdf: pmf * s.pdf, delta: false })
            }
            Light::Disc { center, normal, radius, emission, .. } => {
                let s = DiscSampling { center, normal, radius }.sample(p, u)?;
                if s.direction.dot(normal) >= 0.0 {
                    return None;
                }
                Some(IncidentSample { wi: s.direction, point: s.point, li: emission, pdf: pmf * s.pdf, delta: false })
            }
            Light::Infinite(ref inf) => {
                let s = inf.sample(u)?;
                if s.radiance == Rgb::ZERO {
                    return None;
                }
                Some(IncidentSample {
                    wi: s.direction,
                    point: self.sphere.beyond(p, s.direction),
                    li: s.radiance,
                    pdf: pmf * s.pdf,
                    delta: s.delta,
                })
            }
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

    /// A light path leaving `origin` on a Lambertian emitter of area `area` with `normal`, by the cosine:
    /// Le cos / ((1/A) (cos/π) P_select) = Le π A / P_select.
    fn lambertian_emission(
        origin: Vec3,
        normal: Vec3,
        u_dir: Vec2,
        emission: Rgb,
        area: f32,
        pmf: f32,
        index: usize,
    ) -> Option<EmissionSample> {
        let local = cosine_hemisphere(u_dir);
        if local.z <= 0.0 {
            return None;
        }
        Some(EmissionSample {
            origin,
            normal,
            direction: Frame::from_normal(normal).to_world(local),
            beta: emission * (PI * area / pmf),
            light: index as u32,
        })
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
            Light::Sphere { center, radius, emission, .. } => {
                let normal = uniform_sphere(u_pos);
                Self::lambertian_emission(
                    center + radius * normal,
                    normal,
                    u_dir,
                    emission,
                    4.0 * PI * radius * radius,
                    pmf,
                    index,
                )?
            }
            Light::Disc { center, normal, radius, emission, .. } => {
                let disc = DiscSampling { center, normal, radius };
                Self::lambertian_emission(disc.sample_point(u_pos), normal, u_dir, emission, disc.area(), pmf, index)?
            }
            Light::Infinite(ref inf) => {
                // Photons start on the disc facing the sampled direction that covers the scene's bounding sphere:
                // β = L(ω) / (p(ω) · 1/(π r²) · P_select).
                let s = inf.sample(u_dir)?;
                let ray = self.sphere.ray_from(&s, u_pos)?;
                EmissionSample {
                    origin: ray.origin,
                    normal: Vec3::ZERO,
                    direction: ray.direction,
                    beta: ray.flux(s.radiance) / pmf,
                    light: index as u32,
                }
            }
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
