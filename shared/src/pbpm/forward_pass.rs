//! The forward pass (paper §2 step 3): light paths that gather into the backward photon map at their diffuse
//! vertices y_m, m ≥ 2, adding τ · f · ΔΦ / (π r²) (paper eq. 4) to the photon's pixel.

use super::inner_disc::merge_blur;
use super::photon_map::PhotonMap;
use crate::color::{luminance, Rgb};
use crate::geometry::{ray::offset_origin, Ray, SurfaceHit};
use crate::integrator::Layer;
use crate::material::Transport;
use crate::ray_map::{events::scatter_event, Events, RecordedPath};
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
    /// True when y1 … y_{m−1} are all specular.
    pub all_specular: bool,
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
    /// of a light whose image light paths bring (`crate::ghost::lens_images_by_light_paths`).
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
pub fn trace_light_path(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    index: u64,
    sampler: &mut Sampler,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
) {
    trace_light_path_logged(scene, settings, spectrum, index, sampler, stats, visit, None)
}

/// `trace_light_path` that also records the path's vertices and events into `log` (a ray map's path) when
/// given one, its source being the light's emitter (`ray_map::emitter_of`); the image is the same either way.
#[allow(clippy::too_many_arguments)]
pub fn trace_light_path_logged(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    index: u64,
    sampler: &mut Sampler,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    log: Option<&mut RecordedPath>,
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
    mut log: Option<&mut RecordedPath>,
) {
    let max_depth = settings.max_depth;
    stats.light_paths += 1;
    let u_select = sampler.next_f32();
    let (u_pos, u_dir) = (sampler.next_2d(), sampler.next_2d());
    let Some(e) = scene.lights.sample_emission(&scene.geometry, u_select, u_pos, u_dir) else { return };
    let origin = if e.normal == Vec3::ZERO { e.origin } else { offset_origin(e.origin, e.normal, e.direction) };
    let mut ray = Ray::new(origin, e.direction);
    let mut beta = e.beta;
    let mut path = PathSpectrum::<S>::start(spectrum, PhaseSpectrum::class_of(index), &mut beta);
    let beta0 = beta.max_element();
    let mut all_specular = true;
    // Set once the all-specular chain so far took a reflection at a dielectric: from then on, until a diffuse
    // vertex, a segment that crosses the sensor is a ghost the light side owns.
    let mut ghost_chain = false;
    // The light's image through the lens is the light side's too: a segment after at least one specular vertex
    // that crosses the sensor registers, as a camera path of two segments or more would have hit the light.
    let lens_image = settings.sensor && scene.lights.lens_image_by_light_paths(e.light);
    // What the path registered on the sensor, for its recording.
    let mut registered = Rgb::ZERO;
    let mut m = 0u32;
    if let Some(l) = log.as_deref_mut() {
        l.source = crate::ray_map::emitter_of(scene, e.light);
        l.begin(e.origin, e.normal);
    }
    loop {
        // Segment m + 1 reaches the sensor within max_depth segments, as a camera path's emitter hit does.
        let registers = if ghost_chain { settings.ghost_paths == 0 } else { lens_image && m >= 1 };
        let sensor = (registers && all_specular && m < max_depth).then_some(ghost_chain);
        let segment = Segment { ray: &ray, beta, tag: path.tag(), sensor };
        let Some(hit) = trace_segment(scene, spectrum, segment, stats, visit, log.as_deref_mut(), &mut registered)
        else {
            break;
        };
        m += 1;
        let material = path.material(scene.material(&hit), &mut beta);
        let wi = -ray.direction;
        if material.diffuse_albedo().is_some() {
            if !settings.vertices {
                break;
            }
            if m >= 2 && m < max_depth {
                visit(&LightEvent::Vertex(LightVertex {
                    hit: &hit,
                    wi,
                    flux: beta,
                    m,
                    all_specular,
                    spectrum: path.tag(),
                    phase: spectrum,
                }));
            }
            all_specular = false;
        }
        // The next vertex y_{m+1} can still merge only with a photon one segment from the eye; a ghost chain
        // may still reach the sensor on segment m + 1.
        let sensor_next = settings.sensor && all_specular && m < max_depth;
        if m + 2 > max_depth && !sensor_next {
            if beta != Rgb::ZERO {
                stats.capped += 1;
            }
            break;
        }
        let Some(s) = material.sample(&hit, wi, sampler.next_2d(), Transport::Importance) else {
            if let Some(l) = log.as_deref_mut() {
                l.event(Events::ABSORB);
            }
            break;
        };
        if let Some(l) = log.as_deref_mut() {
            l.event(scatter_event(&material, &hit, wi, s.wi, s.delta));
        }
        if settings.sensor && all_specular && crate::ghost::is_dielectric_reflection(&material, &hit, wi, s.wi) {
            ghost_chain = true;
        }
        beta *= s.weight;
        if m >= 3 {
            let q = (beta.max_element() / beta0).min(1.0);
            if sampler.next_f32() >= q {
                if let Some(l) = log.as_deref_mut() {
                    l.event(Events::ABSORB);
                }
                break;
            }
            beta /= q;
        }
        ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
    }
    if let Some(l) = log {
        let weight = if registered == Rgb::ZERO { e.beta } else { registered };
        l.finish(weight, path.wavelength_nm());
    }
}

/// A light-path segment about to be traced: its ray, the flux it carries and its colour terms, and, when it
/// registers where it crosses the sensor, whether its chain is a ghost.
pub(super) struct Segment<'a> {
    pub ray: &'a Ray,
    pub beta: Rgb,
    pub tag: u8,
    pub sensor: Option<bool>,
}

/// Traces a light-path segment: counts its ray, registers it on the sensor where `s.sensor` asks (adding what it
/// recorded to `registered`), and records where it ends into `log`. Returns its hit, None when it escaped.
#[inline(always)]
pub(super) fn trace_segment(
    scene: &Scene,
    spectrum: &PhaseSpectrum,
    s: Segment,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    mut log: Option<&mut RecordedPath>,
    registered: &mut Rgb,
) -> Option<SurfaceHit> {
    stats.rays += 1;
    let hit = scene.geometry.intersect(s.ray);
    if let Some(ghost) = s.sensor {
        let t_max = hit.as_ref().map_or(f32::INFINITY, |h| h.t);
        let crossing = Crossing { ray: s.ray, t_max, beta: s.beta, tag: s.tag, ghost };
        *registered += register_crossing(scene, spectrum, crossing, visit, log.as_deref_mut());
    }
    if let Some(l) = log {
        match &hit {
            Some(h) => l.hit(h),
            None => l.escape(s.ray.direction),
        }
    }
    hit
}

/// A light-path segment that crosses the sensor: the ray up to `t_max`, the flux it carries and its colour
/// terms, and whether its chain is a ghost.
struct Crossing<'a> {
    ray: &'a Ray,
    t_max: f32,
    beta: Rgb,
    tag: u8,
    ghost: bool,
}

/// Registers a segment that crosses the sensor on its pixel: hands the hit to `visit` and records its sensor
/// vertex into `log`. Returns what it registered in image terms (as a pixel whose camera paths start in RGB
/// reads it) when it records, zero otherwise.
#[inline(always)]
fn register_crossing(
    scene: &Scene,
    spectrum: &PhaseSpectrum,
    c: Crossing,
    visit: &mut impl FnMut(&LightEvent),
    log: Option<&mut RecordedPath>,
) -> Rgb {
    let Some((pixel, importance)) = scene.camera.sensor_pixel(c.ray.origin, c.ray.direction, c.t_max) else {
        return Rgb::ZERO;
    };
    let value = c.beta * importance;
    if value == Rgb::ZERO {
        return Rgb::ZERO;
    }
    visit(&LightEvent::Sensor(SensorHit { pixel, value, spectrum: c.tag, phase: spectrum, ghost: c.ghost }));
    let Some(l) = log else { return Rgb::ZERO };
    l.sensor(scene.camera.sensor_point(c.ray.origin, c.ray.direction), pixel);
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
            spectrum: self.spectrum,
        }
    }
}

/// Gathers a light vertex into `map`: every photon whose sphere contains the vertex, whose surface agrees and
/// on whose side the light arrives receives τ · f · ΔΦ / (π r²). Returns the number of merges.
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
        if v.wi.dot(b.normal) <= 0.0
            || v.ng.dot(b.normal).abs() < NORMAL_AGREEMENT
            || b.segments as u32 + v.m > max_depth
        {
            continue;
        }
        // DESIGN §1's partition: every light path is counted by exactly one photon depth.
        let layer = match (b.kind.k(), v.all_specular) {
            (1, true) => Layer::Caustic,
            (1, false) if backward_diffuse_depth == 1 => Layer::Indirect,
            (1, false) => continue,
            _ => Layer::Indirect,
        };
        merges += 1;
        // eq. 4
        let value = if S { join(b.weight, b.spectrum, v.flux, v.spectrum, phase) } else { b.weight * v.flux };
        sink.add(b.pixel, layer, b.kind.ghost(), value);
        if blur {
            sink.add_blur(b.pixel, merge_blur(luminance(value), d2, b));
        }
    }
    merges
}
