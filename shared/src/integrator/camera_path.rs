//! Camera paths as the path walk's technique: emitters hit along the way (with multiple importance sampling
//! against next-event estimation) and next-event estimation at diffuse vertices, split into the image layers,
//! with the ghost rule of a sensor behind a lens. The reference path tracer runs it as it is; the PBPM backward
//! pass adds, through `DiffuseVertices`, the photons it stores and where it ends its paths.

use super::walk::{walk, Technique, Walk};
use super::{add_contribution, sample_direct, Layer, LayerValues};
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::geometry::SurfaceHit;
use crate::material::{Material, ScatterSample, Transport};
use crate::ray_map::{Events, PathLog};
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, PhaseSpectrum};
use glam::Vec3;

/// What follows a camera path's diffuse vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum After {
    /// The path goes on.
    Continue,
    /// The path traces one more BSDF-sampled ray, only to find the emitter it may hit, so that the direct
    /// layer keeps both of its strategies.
    EmitterRay,
    /// The path ends here.
    Stop,
}

/// What a camera technique does at diffuse vertices besides next-event estimation.
pub trait DiffuseVertices<const S: bool> {
    /// The vertex number from which Russian roulette plays.
    const ROULETTE_FROM: u32;
    /// True when emitters reached through specular surfaces after a diffuse vertex are left to light paths
    /// (PBPM's caustics); the path tracer counts them.
    const LEAVES_CAUSTICS: bool;

    /// What follows diffuse vertex `k` (1-based).
    fn after(&self, k: u32) -> After;

    /// Called at diffuse vertex `k` of albedo `albedo` after its next-event estimate, with the path's walk
    /// (whose throughput reaches the vertex) and whether the path is a ghost path.
    fn store(&mut self, w: &Walk<S>, hit: &SurfaceHit, wo: Vec3, albedo: Rgb, k: u32, ghost: bool);
}

/// The reference path tracer's diffuse vertices: every path goes on, nothing is stored.
pub struct TraceOn;

impl<const S: bool> DiffuseVertices<S> for TraceOn {
    const ROULETTE_FROM: u32 = 3;
    const LEAVES_CAUSTICS: bool = false;

    #[inline(always)]
    fn after(&self, _: u32) -> After {
        After::Continue
    }

    #[inline(always)]
    fn store(&mut self, _: &Walk<S>, _: &SurfaceHit, _: Vec3, _: Rgb, _: u32, _: bool) {}
}

/// The layer light belongs to, given how many diffuse vertices the camera path had before reaching it and
/// whether the last step before the light was specular.
#[inline]
pub fn layer_of(diffuse_vertices: u32, through_specular: bool) -> Layer {
    match (diffuse_vertices, through_specular) {
        (0, _) => Layer::VisibleLights,
        (1, false) => Layer::Direct,
        (1, true) => Layer::Caustic,
        _ => Layer::Indirect,
    }
}

/// A camera path's state as a technique of the walk.
struct CameraPath<'a, V> {
    scene: &'a Scene,
    max_depth: u32,
    /// Emitters seen through the lens after a reflection in it are the light paths' (`crate::ghost`).
    sensor_ghosts: bool,
    vertices: &'a mut V,
    out: LayerValues,
    /// Some(light so far) once the path is a ghost path.
    ghost: Option<Rgb>,
    /// Diffuse vertices so far.
    k: u32,
    /// Set when the previous vertex was diffuse, at `p`, with BSDF pdf `pdf`: an emitter hit now is that
    /// vertex's direct light, weighted against its next-event estimate.
    from_diffuse: Option<(Vec3, f32)>,
    emitter_ray: bool,
    /// Roulette's unit: the camera ray's weight times the radiance rescalings of the refractions so far.
    roulette_unit: f32,
}

impl<const S: bool, V: DiffuseVertices<S>> Technique<S> for CameraPath<'_, V> {
    const MODE: Transport = Transport::Radiance;

    #[inline(always)]
    fn on_hit<L: PathLog>(&mut self, w: &mut Walk<S>, hit: &SurfaceHit, log: &mut L) -> bool {
        let le = self.scene.lights.emitted(hit, w.ray.direction);
        if le != Rgb::ZERO {
            log.event(Events::EMISSION);
            let le = w.spectrum.quantity(le);
            let (out, ghost) = (&mut self.out, &mut self.ghost);
            match (self.k, self.from_diffuse) {
                (0, _)
                    if self.sensor_ghosts
                        && crate::ghost::light_side_owns(self.scene, hit, ghost.is_some(), w.segments) => {}
                (0, _) => add_contribution(out, ghost, Layer::VisibleLights, w.spectrum.to_image(w.beta * le)),
                (k, Some((p, pdf))) => {
                    let m = power_heuristic(pdf, self.scene.lights.pdf_incident(p, hit));
                    add_contribution(out, ghost, layer_of(k, false), w.spectrum.to_image(w.beta * le * m));
                }
                _ if V::LEAVES_CAUSTICS => {}
                (k, None) => add_contribution(out, ghost, layer_of(k, true), w.spectrum.to_image(w.beta * le)),
            }
        }
        !(self.emitter_ray || w.segments >= self.max_depth)
    }

    #[inline(always)]
    fn at_vertex<L: PathLog>(
        &mut self,
        w: &mut Walk<S>,
        hit: &SurfaceHit,
        material: &Material,
        wo: Vec3,
        sampler: &mut Sampler,
        log: &mut L,
    ) -> bool {
        let Some(albedo) = material.diffuse_albedo() else { return true };
        if albedo == Rgb::ZERO {
            log.event(Events::ABSORB);
            return false;
        }
        log.event(Events::DIFFUSE);
        self.k += 1;
        let after = self.vertices.after(self.k);
        self.emitter_ray = after == After::EmitterRay;
        w.rays += 1;
        if let Some(d) = sample_direct(self.scene, hit, wo, albedo, &w.spectrum, sampler) {
            // Without a BSDF ray nothing else finds this light: next-event estimation takes it all.
            let m = if d.delta || after == After::Stop { 1.0 } else { power_heuristic(d.light_pdf, d.bsdf_pdf) };
            let value = w.spectrum.to_image(w.beta * d.value * m);
            add_contribution(&mut self.out, &mut self.ghost, layer_of(self.k, false), value);
        }
        self.vertices.store(w, hit, wo, albedo, self.k, self.ghost.is_some());
        after != After::Stop
    }

    #[inline(always)]
    fn after_sample(
        &mut self,
        _: &mut Walk<S>,
        hit: &SurfaceHit,
        material: &Material,
        wo: Vec3,
        s: &ScatterSample,
    ) -> bool {
        if self.k == 0 && self.ghost.is_none() && crate::ghost::is_dielectric_reflection(material, hit, wo, s.wi) {
            self.ghost = Some(Rgb::ZERO);
        }
        self.roulette_unit *= s.radiance_scale;
        self.from_diffuse = (!s.delta).then_some((hit.p, s.pdf));
        true
    }

    #[inline(always)]
    fn roulette_unit(&self, w: &Walk<S>) -> Option<f32> {
        // Relative to the camera ray's weight, which is a unit of measurement (a sensor camera's is far below
        // one), and to the (η_o/η_t)² of refractions, which rescale radiance without losing energy (pbrt-v4's
        // etaScale): glass would otherwise kill most paths inside it.
        (w.segments >= V::ROULETTE_FROM).then_some(self.roulette_unit)
    }
}

/// How a camera path runs: its scene, longest path, ghost rule and the wavelength class it takes if it meets
/// dispersion.
#[derive(Clone, Copy)]
pub struct CameraRun<'a> {
    pub scene: &'a Scene,
    /// Longest path in segments.
    pub max_depth: u32,
    /// Emitters seen through the lens after a reflection in it are left to light paths.
    pub sensor_ghosts: bool,
    pub spectrum: &'a PhaseSpectrum,
    /// The path's wavelength class among the phase's wavelengths.
    pub class: u8,
}

/// Walks one camera path from `camera_ray` and returns its contribution per layer (the camera ray's weight
/// times the radiance along it) with the part of it that is ghost light, and the rays it traced; `vertices`
/// decides what happens at diffuse vertices besides next-event estimation.
pub fn trace_camera<V, L: PathLog>(
    run: CameraRun,
    camera_ray: CameraRay,
    vertices: &mut V,
    sampler: &mut Sampler,
    log: &mut L,
) -> (LayerValues, Rgb, u64)
where
    V: DiffuseVertices<true> + DiffuseVertices<false>,
{
    // An RGB phase runs the instantiation without spectral branches: RGB scenes keep their speed.
    if run.spectrum.wavelengths.is_some() {
        camera::<true, V, L>(run, camera_ray, vertices, sampler, log)
    } else {
        camera::<false, V, L>(run, camera_ray, vertices, sampler, log)
    }
}

#[inline(always)]
fn camera<const S: bool, V: DiffuseVertices<S>, L: PathLog>(
    run: CameraRun,
    camera_ray: CameraRay,
    vertices: &mut V,
    sampler: &mut Sampler,
    log: &mut L,
) -> (LayerValues, Rgb, u64) {
    let weight = camera_ray.weight;
    if !(weight > 0.0 && weight.is_finite()) {
        return ([Rgb::ZERO; 4], Rgb::ZERO, 0);
    }
    let mut beta = Rgb::splat(weight);
    let spectrum = PathSpectrum::<S>::start(run.spectrum, run.class, &mut beta);
    let mut w = Walk::new(run.scene, camera_ray.ray, beta, spectrum);
    let mut path = CameraPath {
        scene: run.scene,
        max_depth: run.max_depth,
        sensor_ghosts: run.sensor_ghosts,
        vertices,
        out: [Rgb::ZERO; 4],
        ghost: None,
        k: 0,
        from_diffuse: None,
        emitter_ray: false,
        roulette_unit: weight,
    };
    log.begin(w.ray.origin, Vec3::ZERO);
    walk(&mut w, &mut path, sampler, log);
    log.finish(path.out.iter().copied().sum(), w.spectrum.wavelength_nm());
    (path.out, path.ghost.unwrap_or(Rgb::ZERO), w.rays)
}
