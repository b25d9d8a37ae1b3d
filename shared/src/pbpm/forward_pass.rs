//! The forward pass (paper §2 step 3): light paths that gather into the backward photon map at their diffuse
//! vertices y_m, m ≥ 2, adding τ · f · ΔΦ / (π r²) (paper eq. 4) to the photon's pixel.

use super::inner_disc::merge_blur;
use super::photon_map::PhotonMap;
use crate::bsdf::{Bsdf, BsdfSample, Transport};
use crate::color::{luminance, Rgb};
use crate::geometry::{ray::offset_origin, Ray, SurfaceHit};
use crate::integrator::walk::{walk, Technique, Walk};
use crate::integrator::Layer;
use crate::ray_map::PathLog;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::{join, PathSpectrum, PhaseSpectrum};
use glam::Vec3;

/// Counters of the forward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ForwardStats {
    /// Light paths traced.
    pub light_paths: u64,
    /// Rays traced along light paths.
    pub rays: u64,
    /// Light-path vertices that found a backward photon (intersections of forward rays with backward photons).
    pub merges: u64,
    /// Paths that `max_depth` stopped while they still carried flux.
    pub capped: u64,
}

impl std::ops::Add for ForwardStats {
    type Output = Self;

    /// The counts of two shares of a forward pass together.
    fn add(self, o: Self) -> Self {
        ForwardStats {
            light_paths: self.light_paths + o.light_paths,
            rays: self.rays + o.rays,
            merges: self.merges + o.merges,
            capped: self.capped + o.capped,
        }
    }
}

/// Where gathered light goes: (pixel, layer, whether the photon's camera path is a ghost path so that the
/// light is ghost light too, τ · f · ΔΦ / (π r²)).
pub trait Gather {
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb);

    /// True when the sink keeps the pixels' blur difference D (`inner_disc`); gathers skip it otherwise.
    fn measures_blur(&self) -> bool {
        false
    }

    /// Adds a merge's part of a pixel's blur difference D.
    fn add_blur(&mut self, _pixel: u32, _d: f32) {}
}

impl<F: FnMut(u32, Layer, bool, Rgb)> Gather for F {
    #[inline]
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb) {
        self(pixel, layer, ghost, value)
    }
}

/// Normals of a photon's surface and the gathering surface must agree this well (cos 25°), so that light on
/// one wall of a corner is not gathered by photons on the other; the surface's edges are found by the same rule.
const NORMAL_AGREEMENT: f32 = crate::geometry::SAME_SURFACE_COS;

/// A diffuse light-path vertex y_m (m ≥ 2) where backward photons may gather light.
#[derive(Clone, Copy, Debug)]
pub struct LightVertex<'a> {
    pub hit: &'a SurfaceHit,
    /// Unit direction toward the previous light-path vertex.
    pub wi: Vec3,
    /// ΔΦ: the flux the path carries into this vertex.
    pub flux: Rgb,
    /// Light segments from the light to this vertex.
    pub m: u32,
    /// True when y1 … y_{m−1} all scattered through delta lobes.
    pub all_specular: bool,
    /// True when y1 … y_{m−1} all scattered through pass lobes (delta or sharp glossy: none a photon could
    /// have gathered).
    pub all_pass: bool,
    /// 0 for an RGB light path; 1 + its wavelength class once it turned spectral, and `flux` then holds its
    /// value at that wavelength in every channel.
    pub spectrum: u8,
    /// The phase's wavelengths, for the join with a photon of another class.
    pub phase: &'a PhaseSpectrum,
}

/// A light path reaching a sensor camera after an all-specular chain with a reflection at a dielectric: the
/// ghost chains the light side owns (`crate::ghost`). It registers on its pixel like a gather.
#[derive(Clone, Copy, Debug)]
pub struct SensorHit<'a> {
    /// The image pixel it crosses the sensor in.
    pub pixel: u32,
    /// ΔΦ times the pixel's importance (`Camera::sensor_pixel`): the path's value for the pixel before the
    /// division by the phase's light paths, in the path's colour terms.
    pub value: Rgb,
    /// As `LightVertex::spectrum`.
    pub spectrum: u8,
    /// The phase's wavelengths.
    pub phase: &'a PhaseSpectrum,
    /// The chain took a reflection at a dielectric: a ghost, for the ghost layer. Otherwise it is the lens image
    /// of a light whose image light paths bring (`crate::scene::ghost::lens_images_by_light_paths`).
    pub ghost: bool,
}

/// What a light path hands its phase: a diffuse vertex to gather into photon maps, or a ghost reaching the
/// sensor.
#[derive(Clone, Copy, Debug)]
pub enum LightEvent<'a> {
    Vertex(LightVertex<'a>),
    Sensor(SensorHit<'a>),
}

/// What shapes a light path besides the scene: the longest path, and which events it looks for.
#[derive(Clone, Copy, Debug)]
pub struct LightSettings {
    pub max_depth: u32,
    /// Look for ghost chains reaching the sensor (`SensorHit`).
    pub sensor: bool,
    /// Hand diffuse vertices to the visitor; without them a path ends at its first diffuse vertex.
    pub vertices: bool,
    /// Ghost paths traced for every light path (`trace_ghost_paths`); when non-zero, they bring the ghost
    /// chains to the sensor and light paths leave those chains to them.
    pub ghost_paths: u32,
}

/// Traces light path number `index` of a phase and hands every diffuse vertex with m ≥ 2 and every sensor hit
/// to `visit`, which gathers them into one or more phases. The index deals the path its wavelength class.
/// `log` records the path (a ray map's, its source the light's emitter, `ray_map::emitter_of`) or, as
/// `Unrecorded`, costs nothing; the image is the same either way.
#[allow(clippy::too_many_arguments)]
pub fn trace_light_path(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    index: u64,
    sampler: &mut Sampler,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    log: &mut impl PathLog,
) {
    // An RGB phase runs the instantiation without spectral branches: RGB scenes keep their speed.
    if spectrum.wavelengths.is_some() {
        light_path::<true>(scene, settings, spectrum, index, sampler, stats, visit, log)
    } else {
        light_path::<false>(scene, settings, spectrum, index, sampler, stats, visit, log)
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn light_path<const S: bool>(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    index: u64,
    sampler: &mut Sampler,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    log: &mut impl PathLog,
) {
    stats.light_paths += 1;
    let u_select = sampler.next_f32();
    let (u_pos, u_dir) = (sampler.next_2d(), sampler.next_2d());
    let Some(e) = scene.lights.sample_emission(&scene.geometry, u_select, u_pos, u_dir) else { return };
    let origin = if e.normal == Vec3::ZERO { e.origin } else { offset_origin(e.origin, e.normal, e.direction) };
    let mut beta = e.beta;
    let path = PathSpectrum::<S>::start(spectrum, PhaseSpectrum::class_of(index), &mut beta);
    let mut w = Walk::new(scene, Ray::new(origin, e.direction), beta, path);
    let mut light = LightPath {
        settings,
        spectrum,
        visit,
        beta0: beta.max_element(),
        all_specular: true,
        all_pass: true,
        ghost_chain: false,
        // The light's image through the lens is the light side's too: a segment after at least one specular
        // vertex that crosses the sensor registers, as a camera path of two segments or more would have hit
        // the light.
        lens_image: settings.sensor && scene.lights.lens_image_by_light_paths(e.light),
        sensor: None,
        registered: Rgb::ZERO,
        capped: false,
    };
    log.set_source(crate::ray_map::emitter_of(scene, e.light));
    log.begin(e.origin, e.normal);
    walk(&mut w, &mut light, sampler, log);
    stats.rays += w.rays;
    stats.capped += light.capped as u64;
    let weight = if light.registered == Rgb::ZERO { e.beta } else { light.registered };
    log.finish(weight, w.spectrum.wavelength_nm());
}

/// A light path's state as a technique of the walk.
struct LightPath<'a, V> {
    settings: LightSettings,
    spectrum: &'a PhaseSpectrum,
    visit: &'a mut V,
    /// The throughput's largest channel at the light, roulette's unit.
    beta0: f32,
    /// True while y1 … y_m all scattered through delta lobes.
    all_specular: bool,
    /// True while y1 … y_m all scattered through pass lobes.
    all_pass: bool,
    /// Set once the all-specular chain so far took a reflection at a dielectric: from then on, until a diffuse
    /// vertex, a segment that crosses the sensor is a ghost the light side owns.
    ghost_chain: bool,
    lens_image: bool,
    /// Whether the segment being traced registers where it crosses the sensor, and if so whether as a ghost.
    sensor: Option<bool>,
    /// What the path registered on the sensor, for its recording.
    registered: Rgb,
    /// `max_depth` stopped the path while it still carried flux.
    capped: bool,
}

impl<const S: bool, V: FnMut(&LightEvent)> Technique<S> for LightPath<'_, V> {
    const MODE: Transport = Transport::Importance;

    #[inline(always)]
    fn before_segment(&mut self, w: &Walk<S>) {
        // Segment m + 1 reaches the sensor within max_depth segments, as a camera path's emitter hit does.
        let m = w.segments;
        let registers = if self.ghost_chain { self.settings.ghost_paths == 0 } else { self.lens_image && m >= 1 };
        self.sensor = (registers && self.all_specular && m < self.settings.max_depth).then_some(self.ghost_chain);
    }

    #[inline(always)]
    fn on_segment<L: PathLog>(&mut self, w: &Walk<S>, hit: Option<&SurfaceHit>, log: &mut L) {
        if let Some(ghost) = self.sensor {
            let t_max = hit.map_or(f32::INFINITY, |h| h.t);
            let crossing = Crossing { ray: &w.ray, t_max, beta: w.beta, tag: w.spectrum.tag(), ghost };
            self.registered += register_crossing(w.scene, self.spectrum, crossing, self.visit, log);
        }
    }

    #[inline(always)]
    fn at_vertex<L: PathLog>(
        &mut self,
        w: &mut Walk<S>,
        hit: &SurfaceHit,
        bsdf: &Bsdf,
        wo: Vec3,
        _sampler: &mut Sampler,
        _log: &mut L,
    ) -> bool {
        let (m, max_depth) = (w.segments, self.settings.max_depth);
        let delta = bsdf.flags().is_specular();
        if !self.settings.vertices && !delta {
            return false;
        }
        if self.settings.vertices && bsdf.has_stored() && m >= 2 && m < max_depth {
            (self.visit)(&LightEvent::Vertex(LightVertex {
                hit,
                wi: wo,
                flux: w.beta,
                m,
                all_specular: self.all_specular,
                all_pass: self.all_pass,
                spectrum: w.spectrum.tag(),
                phase: self.spectrum,
            }));
        }
        // The next vertex y_{m+1} can still merge only with a photon one segment from the eye; a ghost chain may
        // still reach the sensor on segment m + 1.
        let sensor_next = self.settings.sensor && self.all_specular && delta && m < max_depth;
        if m + 2 > max_depth && !sensor_next {
            self.capped = w.beta != Rgb::ZERO;
            return false;
        }
        true
    }

    #[inline(always)]
    fn after_sample(&mut self, _: &mut Walk<S>, _: &SurfaceHit, bsdf: &Bsdf, s: &BsdfSample, _: Rgb) -> bool {
        if self.settings.sensor && self.all_specular && bsdf.is_dielectric_reflection(s) {
            self.ghost_chain = true;
        }
        self.all_specular &= s.is_delta();
        self.all_pass &= !s.stored;
        // A path that only brings chains to the sensor ends where its chain leaves the delta lobes.
        self.settings.vertices || s.is_delta()
    }

    #[inline(always)]
    fn roulette_unit(&self, w: &Walk<S>) -> Option<f32> {
        (w.segments >= 3).then_some(self.beta0)
    }
}

/// A light-path segment that crosses the sensor: the ray up to `t_max`, the flux it carries and its colour
/// terms, and whether its chain is a ghost.
pub(super) struct Crossing<'a> {
    pub ray: &'a Ray,
    pub t_max: f32,
    pub beta: Rgb,
    pub tag: u8,
    pub ghost: bool,
}

/// Registers a segment that crosses the sensor on its pixel: hands the hit to `visit` and records its sensor
/// vertex into `log`. Returns what it registered in image terms (as a pixel whose camera paths start in RGB
/// reads it) when it records, zero otherwise.
#[inline(always)]
pub(super) fn register_crossing<L: PathLog>(
    scene: &Scene,
    spectrum: &PhaseSpectrum,
    c: Crossing,
    visit: &mut impl FnMut(&LightEvent),
    log: &mut L,
) -> Rgb {
    let Some((pixel, importance)) = scene.camera.sensor_pixel(c.ray.origin, c.ray.direction, c.t_max) else {
        return Rgb::ZERO;
    };
    let value = c.beta * importance;
    if value == Rgb::ZERO {
        return Rgb::ZERO;
    }
    visit(&LightEvent::Sensor(SensorHit { pixel, value, spectrum: c.tag, phase: spectrum, ghost: c.ghost }));
    if !L::RECORDS {
        return Rgb::ZERO;
    }
    log.sensor(scene.camera.sensor_point(c.ray.origin, c.ray.direction), pixel);
    join(Rgb::ONE, 0, value, c.tag, spectrum)
}

/// What a gather needs of a light vertex, owned, so that vertices can wait for a sorted gather
/// (`SortedGathers`) after their light path's hit is gone.
#[derive(Clone, Copy, Debug)]
pub struct GatherPoint {
    /// The vertex's position and the geometric normal of its surface.
    pub p: Vec3,
    pub ng: Vec3,
    /// As in `LightVertex`.
    pub wi: Vec3,
    pub flux: Rgb,
    pub m: u32,
    pub all_specular: bool,
    pub all_pass: bool,
    pub spectrum: u8,
}

impl LightVertex<'_> {
    /// The vertex as a gather needs it.
    #[inline]
    pub fn point(&self) -> GatherPoint {
        GatherPoint {
            p: self.hit.p,
            ng: self.hit.ng,
            wi: self.wi,
            flux: self.flux,
            m: self.m,
            all_specular: self.all_specular,
            all_pass: self.all_pass,
            spectrum: self.spectrum,
        }
    }
}

/// Gathers a light vertex into `map`: every photon whose sphere contains the vertex, whose surface agrees and
/// on whose side the light arrives (or either side, where its stored lobes transmit) receives
/// τ · f · ΔΦ / (π r²). Returns the number of merges.
#[inline]
pub fn gather(
    map: &PhotonMap,
    v: &LightVertex,
    max_depth: u32,
    backward_diffuse_depth: u32,
    sink: &mut impl Gather,
) -> u64 {
    gather_point(map, &v.point(), v.phase, max_depth, backward_diffuse_depth, sink)
}

/// `gather` of a vertex of a light path of the phase of wavelengths `phase`.
#[inline]
pub fn gather_point(
    map: &PhotonMap,
    v: &GatherPoint,
    phase: &PhaseSpectrum,
    max_depth: u32,
    backward_diffuse_depth: u32,
    sink: &mut impl Gather,
) -> u64 {
    gather_in_bucket(map, map.bucket_of(v.p), v, phase, max_depth, backward_diffuse_depth, sink)
}

/// `gather_point` of a vertex in `bucket`, found before by `PhotonMap::bucket_of`.
#[inline]
pub fn gather_in_bucket(
    map: &PhotonMap,
    bucket: u32,
    v: &GatherPoint,
    phase: &PhaseSpectrum,
    max_depth: u32,
    backward_diffuse_depth: u32,
    sink: &mut impl Gather,
) -> u64 {
    if phase.wavelengths.is_some() {
        gather_in::<true>(map, bucket, v, phase, max_depth, backward_diffuse_depth, sink)
    } else {
        gather_in::<false>(map, bucket, v, phase, max_depth, backward_diffuse_depth, sink)
    }
}

#[inline(always)]
fn gather_in<const S: bool>(
    map: &PhotonMap,
    bucket: u32,
    v: &GatherPoint,
    phase: &PhaseSpectrum,
    max_depth: u32,
    backward_diffuse_depth: u32,
    sink: &mut impl Gather,
) -> u64 {
    let mut merges = 0;
    let blur = sink.measures_blur();
    for (b, d2) in map.containing_in(bucket, v.p) {
        if v.ng.dot(b.normal).abs() < NORMAL_AGREEMENT || b.segments as u32 + v.m > max_depth {
            continue;
        }
        // Light that arrives from behind the photon's surface reaches its camera path only through a stored
        // transmissive lobe (rough glass), whose f below then tells the two sides apart.
        if v.wi.dot(b.normal) <= 0.0 && (b.is_lambertian() || !map.vertex(b.stored).transmits()) {
            continue;
        }
        // The partition of docs/estimator.md ("Layers"): every light path is counted by exactly one photon
        // depth; light reaching a camera path's first non-delta vertex through delta lobes alone is a caustic.
        let layer = match (b.kind.k(), v.all_pass) {
            (1, true) if b.kind.first() && v.all_specular => Layer::Caustic,
            (1, true) => Layer::Indirect,
            (1, false) if backward_diffuse_depth == 1 => Layer::Indirect,
            (1, false) => continue,
            _ => Layer::Indirect,
        };
        // eq. 4's τ · f / (π r²), f evaluated here for a photon that is not Lambertian.
        let weight = if b.is_lambertian() {
            b.weight
        } else {
            let f = map.vertex(b.stored).eval(v.wi);
            if f == Rgb::ZERO {
                continue;
            }
            b.weight * f
        };
        merges += 1;
        // eq. 4
        let value = if S { join(weight, b.spectrum, v.flux, v.spectrum, phase) } else { weight * v.flux };
        sink.add(b.pixel, layer, b.kind.ghost(), value);
        if blur {
            sink.add_blur(b.pixel, merge_blur(luminance(value), d2, b));
        }
    }
    merges
}
