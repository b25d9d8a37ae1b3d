//! The backward pass (paper §2 step 1): camera paths that add directly visible light and direct light (with
//! MIS, paper eq. 5) to their pixel and store backward photons at their first `backward_diffuse_depth`
//! diffuse vertices.

use super::gather_disc::gather_disc_areas;
use super::inner_disc::inner_share;
use super::photon::BackwardPhoton;
use super::radius::RadiusSchedule;
use super::PhotonKind;
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, Ray};
use crate::integrator::{add_contribution, sample_direct, Layer, LayerValues};
use crate::material::Transport;
use crate::ray_map::{events::scatter_event, Events, RecordedPath};
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, PhaseSpectrum};
use glam::Vec3;

/// What the backward pass needs to know besides the scene.
#[derive(Clone, Copy, Debug)]
pub struct BackwardSettings {
    pub max_depth: u32,
    pub backward_diffuse_depth: u32,
    pub radius: RadiusSchedule,
    /// 1-based phase number, for the radius schedule.
    pub phase: u64,
    /// The phase's wavelengths, for paths that meet dispersion.
    pub spectrum: PhaseSpectrum,
    /// Light paths bring the ghost chains to the sensor: an emitter seen through the lens after a reflection in
    /// it is theirs, not this path's.
    pub sensor_ghosts: bool,
}

/// Counters of the backward pass.
#[derive(Clone, Copy, Debug, Default)]
pub struct BackwardStats {
    /// Rays traced: path segments and shadow rays.
    pub rays: u64,
    /// Backward photons stored.
    pub photons: u64,
}

impl std::ops::Add for BackwardStats {
    type Output = Self;

    /// The counts of two shares of a backward pass together.
    fn add(self, o: Self) -> Self {
        BackwardStats { rays: self.rays + o.rays, photons: self.photons + o.photons }
    }
}

/// Traces one camera path for `pixel`, returns its visible-light and next-event contributions per layer with
/// the part of them that is ghost light (`crate::ghost`), and hands every backward photon to `store`. The
/// camera ray's weight starts the path throughput, so that it also reaches the photons' filter τ and with them
/// the forward pass's gathered light.
pub fn trace_camera_path(
    scene: &Scene,
    settings: &BackwardSettings,
    pixel: u32,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut BackwardStats,
    store: &mut impl FnMut(BackwardPhoton),
) -> (LayerValues, Rgb) {
    trace_camera_path_logged(scene, settings, pixel, camera_ray, sampler, stats, store, None)
}

/// `trace_camera_path` that also records the path's vertices and events into `log` (a ray map's path) when
/// given one; the image is the same either way.
#[allow(clippy::too_many_arguments)]
pub fn trace_camera_path_logged(
    scene: &Scene,
    settings: &BackwardSettings,
    pixel: u32,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut BackwardStats,
    store: &mut impl FnMut(BackwardPhoton),
    log: Option<&mut RecordedPath>,
) -> (LayerValues, Rgb) {
    // An RGB phase runs the instantiation without spectral branches: RGB scenes keep their speed.
    if settings.spectrum.wavelengths.is_some() {
        camera_path::<true>(scene, settings, pixel, camera_ray, sampler, stats, store, log)
    } else {
        camera_path::<false>(scene, settings, pixel, camera_ray, sampler, stats, store, log)
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn camera_path<const S: bool>(
    scene: &Scene,
    settings: &BackwardSettings,
    pixel: u32,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut BackwardStats,
    store: &mut impl FnMut(BackwardPhoton),
    mut log: Option<&mut RecordedPath>,
) -> (LayerValues, Rgb) {
    let mut out: LayerValues = [Rgb::ZERO; 4];
    // Some(light so far) once the path is a ghost path.
    let mut ghost: Option<Rgb> = None;
    let weight = camera_ray.weight;
    if !(weight > 0.0 && weight.is_finite()) {
        return (out, Rgb::ZERO);
    }
    let mut ray = camera_ray.ray;
    let mut beta = Rgb::splat(weight);
    // Roulette's unit: the camera ray's weight times the radiance rescalings of the refractions so far.
    let mut roulette_unit = weight;
    let mut path = PathSpectrum::<S>::start(&settings.spectrum, PhaseSpectrum::class_of(pixel as u64), &mut beta);
    let mut k = 0u32; // diffuse vertices so far
    let mut segments = 0u32;
    let mut path_length = 0.0f32;
    // Set when the previous vertex was diffuse vertex D_k at `p` with BSDF pdf `pdf`: an emitter hit now is
    // D_k's direct light, weighted against its next-event estimate.
    let mut from_diffuse: Option<(Vec3, f32)> = None;
    // Set when the path ends at its first diffuse vertex but traces one more BSDF-sampled ray there, only to
    // find the emitter it may hit: the direct layer keeps both of eq. 5's strategies.
    let mut emitter_ray = false;
    if let Some(l) = log.as_deref_mut() {
        l.begin(ray.origin, Vec3::ZERO);
    }
    loop {
        stats.rays += 1;
        let Some(hit) = scene.geometry.intersect(&ray) else {
            if let Some(l) = log.as_deref_mut() {
                l.escape(ray.direction);
            }
            break;
        };
        segments += 1;
        path_length += hit.t;
        if let Some(l) = log.as_deref_mut() {
            l.hit(&hit);
        }
        let le = scene.lights.emitted(&hit, ray.direction);
        if le != Rgb::ZERO {
            if let Some(l) = log.as_deref_mut() {
                l.event(Events::EMISSION);
            }
            let le = path.quantity(le);
            match (k, from_diffuse) {
                (0, _)
                    if settings.sensor_ghosts
                        && crate::ghost::light_side_owns(scene, &hit, ghost.is_some(), segments) => {}
                (0, _) => add_contribution(&mut out, &mut ghost, Layer::VisibleLights, path.to_image(beta * le)),
                (_, Some((p, pdf))) => {
                    let w = power_heuristic(pdf, scene.lights.pdf_incident(p, &hit));
                    add_contribution(&mut out, &mut ghost, direct_layer(k), path.to_image(beta * le * w));
                }
                // Emitter reached from a diffuse vertex through specular surfaces: a caustic, which the forward
                // pass counts.
                _ => {}
            }
        }
        if emitter_ray || segments >= settings.max_depth {
            break;
        }
        let material = path.material(scene.material(&hit), &mut beta);
        let wo = -ray.direction;
        let continues;
        if let Some(albedo) = material.diffuse_albedo() {
            if albedo == Rgb::ZERO {
                if let Some(l) = log.as_deref_mut() {
                    l.event(Events::ABSORB);
                }
                break;
            }
            if let Some(l) = log.as_deref_mut() {
                l.event(Events::DIFFUSE);
            }
            k += 1;
            continues = k < settings.backward_diffuse_depth;
            // Where the path ends at its first diffuse vertex, one BSDF ray still looks for an emitter: next-event
            // estimation alone is noisy where an emitter is large or near (its solid angle, not its area, is
            // then what to sample), and the direct layer is then the same estimator at either depth.
            emitter_ray = !continues && k == 1;
            stats.rays += 1;
            if let Some(d) = sample_direct(scene, &hit, wo, albedo, &path, sampler) {
                // Without a BSDF ray nothing else finds this light: next-event estimation takes it all.
                let w =
                    if d.delta || !(continues || emitter_ray) { 1.0 } else { power_heuristic(d.light_pdf, d.bsdf_pdf) };
                add_contribution(&mut out, &mut ghost, direct_layer(k), path.to_image(beta * d.value * w));
            }
            // A merge needs at least two light segments (y1 is next-event estimation's).
            if segments + 2 <= settings.max_depth {
                let r = settings.radius.radius(path_length, settings.phase);
                let normal = if wo.dot(hit.ng) >= 0.0 { hit.ng } else { -hit.ng };
                // eq. 4's τ · f / (π r²), with the disc's area on the surface for π r² (`gather_disc`).
                let areas = gather_disc_areas(&scene.geometry, &hit, r);
                let weight = beta * albedo * (std::f32::consts::FRAC_1_PI / areas.whole);
                if weight.is_finite() && r > 0.0 {
                    stats.photons += 1;
                    store(BackwardPhoton {
                        position: hit.p,
                        normal,
                        weight,
                        radius2: r * r,
                        pixel,
                        kind: PhotonKind::new(k as u8, ghost.is_some()),
                        segments: segments.min(255) as u8,
                        spectrum: path.tag(),
                        inner_share: inner_share(areas),
                    });
                }
            }
            if !(continues || emitter_ray) {
                break;
            }
        }
        let Some(s) = material.sample(&hit, wo, sampler.next_2d(), Transport::Radiance) else {
            if let Some(l) = log.as_deref_mut() {
                l.event(Events::ABSORB);
            }
            break;
        };
        if let Some(l) = log.as_deref_mut() {
            l.event(scatter_event(&material, &hit, wo, s.wi, s.delta));
        }
        if k == 0 && ghost.is_none() && crate::ghost::is_dielectric_reflection(&material, &hit, wo, s.wi) {
            ghost = Some(Rgb::ZERO);
        }
        beta *= s.weight;
        roulette_unit *= s.radiance_scale;
        from_diffuse = (!s.delta).then_some((hit.p, s.pdf));
        if segments >= 4 {
            // Long specular chains (light trapped in glass) end by roulette, unbiased. Relative to the camera
            // ray's weight, which is a unit of measurement (a sensor camera's is far below one), and to the
            // (η_o/η_t)² of refractions, which rescale radiance without losing energy (pbrt-v4's etaScale):
            // glass would otherwise kill most paths inside it.
            let q = (beta.max_element() / roulette_unit).min(1.0);
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
        l.finish(out.iter().copied().sum(), path.wavelength_nm());
    }
    (out, ghost.unwrap_or(Rgb::ZERO))
}

/// The layer of light that arrives at diffuse vertex k straight from an emitter.
fn direct_layer(k: u32) -> Layer {
    if k == 1 {
        Layer::Direct
    } else {
        Layer::Indirect
    }
}
