//! Camera paths as the path walk's technique: emitters hit along the way (with multiple importance sampling
//! against next-event estimation) and next-event estimation at vertices with non-delta lobes, split into the
//! image layers, with the ghost rule of a sensor behind a lens. The reference path tracer runs it as it is;
//! the PBPM backward pass adds, through `StoredVertices`, the photons it stores where a BSDF has stored lobes
//! and where it ends its paths.
//!
//! # Which paths a PBPM camera path counts
//!
//! A camera path counts everything until its first vertex that stores a photon (k = 1): emitters seen through
//! delta lobes, and next-event estimation with MIS at every vertex with non-delta lobes, stored or not. From a
//! storing vertex on, the photon counts the light that arrives there through the stored lobes after two or
//! more light segments, next-event estimation and the BSDF sample after it the light that arrives straight
//! from an emitter; a continuation through a pass lobe (a delta or a sharp glossy one) is a path on which that
//! vertex did not store, and goes on as before it. A continuation through a stored lobe, where the path may
//! store again (`backward_diffuse_depth` 2), counts only what the second storing vertex's stored lobes bring
//! (next-event estimation of them, and its photon): the light paths that reach the first photon through pass
//! lobes count the rest. docs/estimator.md, "Glossy surfaces", says why and how it was measured.

use super::walk::{walk, Technique, Walk};
use super::{add_contribution, sample_direct, Layer, LayerValues};
use crate::bsdf::{Bsdf, BsdfSample, LobeFlags, Transport};
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::geometry::SurfaceHit;
use crate::ray_map::{Events, PathLog};
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, PhaseSpectrum};
use glam::Vec3;

/// What follows a camera path's sample of a stored lobe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum After {
    /// The path goes on.
    Continue,
    /// The path traces the sampled ray only to find the emitter it may hit, so that the direct layer keeps
    /// both of its strategies.
    EmitterRay,
    /// The path ends here.
    Stop,
}

/// A storing vertex as `StoredVertices::store` is told of it.
#[derive(Clone, Copy, Debug)]
pub struct StoringVertex<'a> {
    pub hit: &'a SurfaceHit,
    pub bsdf: &'a Bsdf,
    /// Points back along the camera path.
    pub wo: Vec3,
    /// Which storing vertex of its path this is (1-based).
    pub k: u32,
    /// True when it is the path's first vertex with non-delta lobes.
    pub first: bool,
    /// True when the path is a ghost path.
    pub ghost: bool,
}

/// What a camera technique does at vertices with stored lobes besides next-event estimation.
pub trait StoredVertices<const S: bool> {
    /// True when the technique stores photons: a storing vertex then changes what the path counts (see the
    /// module's doc). The path tracer stores nothing and counts everything itself.
    const STORES: bool;
    /// The vertex number from which Russian roulette plays.
    const ROULETTE_FROM: u32;

    /// What follows a sample of a stored lobe at storing vertex `k` (1-based).
    fn after(&self, k: u32) -> After;

    /// Called at a storing vertex after its next-event estimate, with the path's walk (whose throughput
    /// reaches the vertex).
    fn store(&mut self, w: &Walk<S>, v: StoringVertex);
}

/// The reference path tracer: every path goes on, nothing is stored.
pub struct TraceOn;

impl<const S: bool> StoredVertices<S> for TraceOn {
    const STORES: bool = false;
    const ROULETTE_FROM: u32 = 3;

    #[inline(always)]
    fn after(&self, _: u32) -> After {
        After::Continue
    }

    #[inline(always)]
    fn store(&mut self, _: &Walk<S>, _: StoringVertex) {}
}

/// The layer light belongs to, given how many vertices with non-delta lobes the camera path had before reaching
/// it and whether the last step before the light was a delta one.
#[inline]
pub fn layer_of(non_delta_vertices: u32, through_specular: bool) -> Layer {
    match (non_delta_vertices, through_specular) {
        (0, _) => Layer::VisibleLights,
        (1, false) => Layer::Direct,
        (1, true) => Layer::Caustic,
        _ => Layer::Indirect,
    }
}

/// The previous vertex's non-delta sample, whose emitter hit is weighted against its next-event estimate.
#[derive(Clone, Copy, Debug)]
struct FromVertex {
    p: Vec3,
    /// The BSDF's pdf of the sampled direction over its non-delta lobes.
    pdf: f32,
    /// The throughput an emitter hit carries (`BsdfSample::direct`).
    direct: Rgb,
}

/// What a vertex decided before its sample, for `after_sample`.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Storing vertices counting this one, if it stores.
    k: u32,
    /// Vertices with non-delta lobes counting this one.
    n: u32,
    /// What follows a sample of a stored lobe.
    after: After,
    /// True when the path had stored before this vertex.
    stored_before: bool,
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
    /// Storing vertices whose stored lobe the path continued through.
    k: u32,
    /// Vertices with non-delta lobes whose non-delta lobe the path continued through.
    n: u32,
    from: Option<FromVertex>,
    plan: Option<Plan>,
    emitter_ray: bool,
    /// Roulette's unit: the camera ray's weight times the radiance rescalings of the refractions so far.
    roulette_unit: f32,
}

impl<const S: bool, V: StoredVertices<S>> Technique<S> for CameraPath<'_, V> {
    const MODE: Transport = Transport::Radiance;

    #[inline(always)]
    fn on_escape<L: PathLog>(&mut self, w: &Walk<S>, log: &mut L) {
        let lights = &self.scene.lights;
        if !lights.any_escaping() {
            return;
        }
        let direction = w.ray.direction;
        // The infinite lights are emitters like any other: the same layers, MIS against next-event estimation
        // after a non-delta sample, and the same rule for what a storing vertex leaves to light paths.
        let (beta, le) = match self.from {
            Some(f) => (f.direct, lights.escaped(direction, Some(f.pdf))),
            None if V::STORES && self.k > 0 => return,
            None => (w.beta, lights.escaped(direction, None)),
        };
        if le == Rgb::ZERO {
            return;
        }
        log.event(Events::EMISSION);
        let value = w.spectrum.to_image(beta * w.spectrum.quantity(le));
        let (out, ghost) = (&mut self.out, &mut self.ghost);
        match self.from {
            Some(_) => add_contribution(out, ghost, layer_of(self.n, false), value),
            None if self.n == 0 => {
                // A ghost path's view of the sky through the lens is the light paths' where they bring ghosts.
                if !(self.sensor_ghosts && ghost.is_some()) {
                    add_contribution(out, ghost, Layer::VisibleLights, value);
                }
            }
            None => add_contribution(out, ghost, layer_of(self.n, true), value),
        }
    }

    #[inline(always)]
    fn on_hit<L: PathLog>(&mut self, w: &mut Walk<S>, hit: &SurfaceHit, log: &mut L) -> bool {
        let le = self.scene.lights.emitted(hit, w.ray.direction);
        if le != Rgb::ZERO {
            log.event(Events::EMISSION);
            let le = w.spectrum.quantity(le);
            let (out, ghost) = (&mut self.out, &mut self.ghost);
            match self.from {
                Some(f) => {
                    let m = power_heuristic(f.pdf, self.scene.lights.pdf_incident(f.p, hit));
                    add_contribution(out, ghost, layer_of(self.n, false), w.spectrum.to_image(f.direct * le * m));
                }
                None if self.n == 0 => {
                    let owned = self.sensor_ghosts
                        && crate::ghost::light_side_owns(self.scene, hit, ghost.is_some(), w.segments);
                    if !owned {
                        add_contribution(out, ghost, Layer::VisibleLights, w.spectrum.to_image(w.beta * le));
                    }
                }
                // Reached through delta lobes after a storing vertex: the light paths' caustic.
                None if V::STORES && self.k > 0 => {}
                None => add_contribution(out, ghost, layer_of(self.n, true), w.spectrum.to_image(w.beta * le)),
            }
        }
        !(self.emitter_ray || w.segments >= self.max_depth)
    }

    #[inline(always)]
    fn at_vertex<L: PathLog>(
        &mut self,
        w: &mut Walk<S>,
        hit: &SurfaceHit,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut Sampler,
        log: &mut L,
    ) -> bool {
        self.plan = None;
        if bsdf.is_black() {
            log.event(Events::ABSORB);
            return false;
        }
        if !bsdf.has_non_delta() {
            return true;
        }
        let stores = V::STORES && bsdf.has_stored();
        let stored_before = V::STORES && self.k > 0;
        if stored_before && !stores {
            // A pass vertex after a storing one: the light paths gathered by that one's photon count it.
            return true;
        }
        let plan = Plan {
            k: self.k + stores as u32,
            n: self.n + 1,
            after: if stores { self.vertices.after(self.k + 1) } else { After::Continue },
            stored_before,
        };
        self.plan = Some(plan);
        if stores && bsdf.flags().contains(LobeFlags::DIFFUSE) {
            log.event(Events::DIFFUSE);
        }
        w.rays += 1;
        if let Some(d) = sample_direct(self.scene, hit, bsdf, wo, stored_before, &w.spectrum, sampler) {
            // After a storing vertex the BSDF sample finds no emitter that counts: next-event estimation of the
            // stored lobes takes it all.
            let m = if d.delta || stored_before { 1.0 } else { power_heuristic(d.light_pdf, d.bsdf_pdf) };
            let value = w.spectrum.to_image(w.beta * d.value * m);
            add_contribution(&mut self.out, &mut self.ghost, layer_of(plan.n, false), value);
        }
        if stores {
            let v = StoringVertex { hit, bsdf, wo, k: plan.k, first: plan.n == 1, ghost: self.ghost.is_some() };
            self.vertices.store(w, v);
            if plan.after == After::Stop && !bsdf.has_pass() {
                return false;
            }
        }
        true
    }

    #[inline(always)]
    fn after_sample(&mut self, _: &mut Walk<S>, hit: &SurfaceHit, bsdf: &Bsdf, s: &BsdfSample, direct: Rgb) -> bool {
        if self.n == 0 && self.ghost.is_none() && bsdf.is_dielectric_reflection(s) {
            self.ghost = Some(Rgb::ZERO);
        }
        self.roulette_unit *= s.radiance_scale;
        self.from = None;
        if s.is_delta() {
            return true;
        }
        let Some(plan) = self.plan else {
            self.n += 1;
            return true;
        };
        self.n = plan.n;
        if !plan.stored_before {
            self.from = Some(FromVertex { p: hit.p, pdf: s.pdf, direct });
        }
        if !s.stored || !V::STORES {
            return true;
        }
        self.k = plan.k;
        match plan.after {
            After::Continue => true,
            After::EmitterRay => {
                self.emitter_ray = true;
                true
            }
            After::Stop => false,
        }
    }

    #[inline(always)]
    fn roulette_unit(&self, w: &Walk<S>) -> Option<f32> {
        // Relative to the camera ray's weight, which is a unit of measurement (a sensor camera's is far below
        // one), and to the (η_o/η_t)² of refractions, which rescale radiance without losing energy (pbrt-v4's
        // etaScale): glass would otherwise kill most paths inside it.
        (w.segments >= V::ROULETTE_FROM).then_some(self.roulette_unit)
    }

    #[inline(always)]
    fn survived(&mut self, q: f32) {
        if let Some(f) = &mut self.from {
            f.direct /= q;
        }
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
/// decides what happens at storing vertices besides next-event estimation.
pub fn trace_camera<V, L: PathLog>(
    run: CameraRun,
    camera_ray: CameraRay,
    vertices: &mut V,
    sampler: &mut Sampler,
    log: &mut L,
) -> (LayerValues, Rgb, u64)
where
    V: StoredVertices<true> + StoredVertices<false>,
{
    // An RGB phase runs the instantiation without spectral branches: RGB scenes keep their speed.
    if run.spectrum.wavelengths.is_some() {
        camera::<true, V, L>(run, camera_ray, vertices, sampler, log)
    } else {
        camera::<false, V, L>(run, camera_ray, vertices, sampler, log)
    }
}

#[inline(always)]
fn camera<const S: bool, V: StoredVertices<S>, L: PathLog>(
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
        n: 0,
        from: None,
        plan: None,
        emitter_ray: false,
        roulette_unit: weight,
    };
    log.begin(w.ray.origin, Vec3::ZERO);
    walk(&mut w, &mut path, sampler, log);
    log.finish(path.out.iter().copied().sum(), w.spectrum.wavelength_nm());
    (path.out, path.ghost.unwrap_or(Rgb::ZERO), w.rays)
}
