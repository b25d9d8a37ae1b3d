//! The path walk: the one bounce loop that every kind of path runs. It traces a segment, resolves the surface's
//! BSDF at the hit, samples the continuation, multiplies the throughput, plays Russian roulette and records all
//! of it into the path's log. What differs between camera paths, light paths and ghost paths (what an emitter
//! hit adds, what a vertex stores or gathers, how a dielectric chooses, when roulette starts) is the
//! `Technique`'s; the recorder is a type parameter, so a path nobody records pays nothing for it.

use crate::bsdf::{Bsdf, BsdfSample, Reflection, Transport};
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, Ray, SurfaceHit};
use crate::ray_map::{events::scatter_event, Events, PathLog};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::PathSpectrum;
use glam::Vec3;

/// What a path carries from vertex to vertex, which every technique reads.
pub struct Walk<'a, const S: bool> {
    pub scene: &'a Scene,
    /// The segment about to be traced, or, at a vertex, the one that reached it.
    pub ray: Ray,
    /// The path throughput.
    pub beta: Rgb,
    /// The path's colour state (RGB until it meets dispersion).
    pub spectrum: PathSpectrum<S>,
    /// Segments that reached a surface so far: at a vertex, its number along the path.
    pub segments: u32,
    /// The path's length up to the current vertex.
    pub length: f32,
    /// Rays traced: the walk's segments and the technique's shadow rays.
    pub rays: u64,
}

impl<'a, const S: bool> Walk<'a, S> {
    /// A walk of `scene` starting along `ray` with throughput `beta` and colour state `spectrum`.
    pub fn new(scene: &'a Scene, ray: Ray, beta: Rgb, spectrum: PathSpectrum<S>) -> Self {
        Walk { scene, ray, beta, spectrum, segments: 0, length: 0.0, rays: 0 }
    }
}

/// What a kind of path does besides walking. Every hook but `at_vertex` and `after_sample` has a default that
/// does nothing; a hook that returns false ends the path there.
pub trait Technique<const S: bool> {
    /// What the path carries: radiance (camera paths) or flux (light paths).
    const MODE: Transport;

    /// Before a segment is traced.
    #[inline(always)]
    fn before_segment(&mut self, _w: &Walk<S>) {}

    /// After a segment is traced, before its end is recorded (`hit` is None when it left the scene): a light
    /// path registers where it crossed the sensor.
    #[inline(always)]
    fn on_segment<L: PathLog>(&mut self, _w: &Walk<S>, _hit: Option<&SurfaceHit>, _log: &mut L) {}

    /// When the segment left the scene without a hit: a camera path adds the infinite lights' radiance.
    #[inline(always)]
    fn on_escape<L: PathLog>(&mut self, _w: &Walk<S>, _log: &mut L) {}

    /// At a surface hit, before its BSDF is resolved: a camera path adds an emitter's light.
    #[inline(always)]
    fn on_hit<L: PathLog>(&mut self, _w: &mut Walk<S>, _hit: &SurfaceHit, _log: &mut L) -> bool {
        true
    }

    /// At the vertex's BSDF, before the continuation is sampled: next-event estimation, photons, gathers, and
    /// where the path ends. `wo` points back along the path.
    fn at_vertex<L: PathLog>(
        &mut self,
        w: &mut Walk<S>,
        hit: &SurfaceHit,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut Sampler,
        log: &mut L,
    ) -> bool;

    /// How a dielectric at `hit` chooses between reflection and refraction.
    #[inline(always)]
    fn choice(&self, _hit: &SurfaceHit) -> Reflection {
        Reflection::Fresnel
    }

    /// After the continuation `s` was sampled and the throughput multiplied by its weight; `direct` is the
    /// throughput an emitter hit right after this vertex carries (`BsdfSample::direct`).
    fn after_sample(&mut self, w: &mut Walk<S>, hit: &SurfaceHit, bsdf: &Bsdf, s: &BsdfSample, direct: Rgb) -> bool;

    /// The unit Russian roulette compares the throughput's largest channel with at this vertex (the path
    /// survives with probability min(1, max β / unit)), or None where it does not play.
    fn roulette_unit(&self, w: &Walk<S>) -> Option<f32>;

    /// The path survived roulette with probability `q`: whatever the technique carries besides the walk's
    /// throughput is divided by it as the throughput was.
    #[inline(always)]
    fn survived(&mut self, _q: f32) {}
}

/// Walks one path from `w`'s ray until it escapes, is absorbed, loses at roulette or its technique ends it.
#[inline(always)]
pub fn walk<const S: bool, T: Technique<S>, L: PathLog>(
    w: &mut Walk<S>,
    technique: &mut T,
    sampler: &mut Sampler,
    log: &mut L,
) {
    let scene = w.scene;
    loop {
        technique.before_segment(w);
        w.rays += 1;
        let hit = scene.geometry.intersect(&w.ray);
        technique.on_segment(w, hit.as_ref(), log);
        let Some(hit) = hit else {
            technique.on_escape(w, log);
            log.escape(w.ray.direction);
            break;
        };
        w.segments += 1;
        w.length += hit.t;
        log.hit(&hit);
        if !technique.on_hit(w, &hit, log) {
            break;
        }
        let wo = -w.ray.direction;
        let bsdf = w.spectrum.material(scene.bsdf(&hit, wo), &mut w.beta);
        if !technique.at_vertex(w, &hit, &bsdf, wo, sampler, log) {
            break;
        }
        let choice = technique.choice(&hit);
        let Some(s) = bsdf.sample_reflecting(wo, sampler.next_2d(), T::MODE, choice) else {
            log.event(Events::ABSORB);
            break;
        };
        log.event(scatter_event(&s));
        let before = w.beta;
        w.beta *= s.weight;
        let direct = if s.direct == s.weight { w.beta } else { before * s.direct };
        if !technique.after_sample(w, &hit, &bsdf, &s, direct) {
            break;
        }
        if let Some(unit) = technique.roulette_unit(w) {
            let q = (w.beta.max_element() / unit).min(1.0);
            if sampler.next_f32() >= q {
                log.event(Events::ABSORB);
                break;
            }
            w.beta /= q;
            technique.survived(q);
        }
        w.ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
    }
}
