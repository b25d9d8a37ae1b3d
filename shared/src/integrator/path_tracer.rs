//! The reference path tracer: unidirectional, next-event estimation with MIS (power heuristic), Russian
//! roulette. It splits its estimate into the same layers as PBPM so that every layer can be compared.

use super::{add_contribution, sample_direct, Layer, LayerValues};
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, Ray};
use crate::material::Transport;
use crate::ray_map::{events::scatter_event, Events, RecordedPath};
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, PhaseSpectrum};
use glam::Vec3;

/// What the previous vertex of a camera path was, which decides how an emitter hit is counted.
#[derive(Clone, Copy)]
enum Previous {
    /// The camera or a specular vertex.
    Specular,
    /// A diffuse vertex at `p` whose cosine sample had solid-angle pdf `pdf`.
    Diffuse { p: Vec3, pdf: f32 },
}

/// Counters of one path.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathStats {
    /// Rays traced: path segments and shadow rays.
    pub rays: u64,
}

/// The layer light belongs to, given how many diffuse vertices the camera path had before reaching it and
/// whether the last step before the light was specular.
fn layer_of(diffuse_vertices: u32, through_specular: bool) -> Layer {
    match (diffuse_vertices, through_specular) {
        (0, _) => Layer::VisibleLights,
        (1, false) => Layer::Direct,
        (1, true) => Layer::Caustic,
        _ => Layer::Indirect,
    }
}

/// Estimates the camera ray's weight times the radiance arriving along it (the pixel measurement), split into
/// layers, with the part of it that is ghost light (`crate::ghost`, as the PBPM backward pass decides it);
/// `max_depth` counts path segments. `spectrum` holds the wavelength the path takes if it meets dispersion (a
/// path tracer can draw one per path). With `sensor_ghosts`, emitters seen through the lens after a reflection
/// in it are left to light paths, as in the PBPM backward pass.
pub fn trace(
    scene: &Scene,
    max_depth: u32,
    sensor_ghosts: bool,
    spectrum: &PhaseSpectrum,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut PathStats,
) -> (LayerValues, Rgb) {
    trace_logged(scene, max_depth, sensor_ghosts, spectrum, camera_ray, sampler, stats, None)
}

/// `trace` that also records the path's vertices and events into `log` (a ray map's path) when given one; the
/// estimate is the same either way.
#[allow(clippy::too_many_arguments)]
pub fn trace_logged(
    scene: &Scene,
    max_depth: u32,
    sensor_ghosts: bool,
    spectrum: &PhaseSpectrum,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut PathStats,
    log: Option<&mut RecordedPath>,
) -> (LayerValues, Rgb) {
    // RGB paths run the instantiation without spectral branches: RGB scenes keep their speed.
    if spectrum.wavelengths.is_some() {
        trace_in::<true>(scene, max_depth, sensor_ghosts, spectrum, camera_ray, sampler, stats, log)
    } else {
        trace_in::<false>(scene, max_depth, sensor_ghosts, spectrum, camera_ray, sampler, stats, log)
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn trace_in<const S: bool>(
    scene: &Scene,
    max_depth: u32,
    sensor_ghosts: bool,
    spectrum: &PhaseSpectrum,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut PathStats,
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
    let mut path = PathSpectrum::<S>::start(spectrum, 0, &mut beta);
    let mut previous = Previous::Specular;
    let mut diffuse_vertices = 0u32;
    let mut segments = 0u32;
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
        if let Some(l) = log.as_deref_mut() {
            l.hit(&hit);
        }
        let le = scene.lights.emitted(&hit, ray.direction);
        if le != Rgb::ZERO {
            if let Some(l) = log.as_deref_mut() {
                l.event(Events::EMISSION);
            }
            let le = path.quantity(le);
            match previous {
                Previous::Specular
                    if diffuse_vertices == 0
                        && sensor_ghosts
                        && crate::ghost::light_side_owns(scene, &hit, ghost.is_some(), segments) => {}
                Previous::Specular => add_contribution(
                    &mut out,
                    &mut ghost,
                    layer_of(diffuse_vertices, diffuse_vertices > 0),
                    path.to_image(beta * le),
                ),
                Previous::Diffuse { p, pdf } => {
                    let w = power_heuristic(pdf, scene.lights.pdf_incident(p, &hit));
                    add_contribution(
                        &mut out,
                        &mut ghost,
                        layer_of(diffuse_vertices, false),
                        path.to_image(beta * le * w),
                    );
                }
            }
        }
        if segments >= max_depth {
            break;
        }
        let material = path.material(scene.material(&hit), &mut beta);
        let wo = -ray.direction;
        if let Some(albedo) = material.diffuse_albedo() {
            diffuse_vertices += 1;
            stats.rays += 1;
            if let Some(d) = sample_direct(scene, &hit, wo, albedo, &path, sampler) {
                let w = if d.delta { 1.0 } else { power_heuristic(d.light_pdf, d.bsdf_pdf) };
                add_contribution(
                    &mut out,
                    &mut ghost,
                    layer_of(diffuse_vertices, false),
                    path.to_image(beta * d.value * w),
                );
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
        if diffuse_vertices == 0 && ghost.is_none() && crate::ghost::is_dielectric_reflection(&material, &hit, wo, s.wi)
        {
            ghost = Some(Rgb::ZERO);
        }
        beta *= s.weight;
        roulette_unit *= s.radiance_scale;
        previous = if s.delta { Previous::Specular } else { Previous::Diffuse { p: hit.p, pdf: s.pdf } };
        if segments >= 3 {
            // Relative to the camera ray's weight and the refractions' (η_o/η_t)², which are units of
            // measurement rather than losses.
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
