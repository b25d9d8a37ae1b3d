//! The reference path tracer: unidirectional, next-event estimation with MIS (power heuristic), Russian
//! roulette. It splits its estimate into the same layers as PBPM so that every layer can be compared.

use super::camera_path::{trace_camera, CameraRun, TraceOn};
use super::LayerValues;
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::ray_map::PathLog;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::PhaseSpectrum;

/// Counters of one path.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathStats {
    /// Rays traced: path segments and shadow rays.
    pub rays: u64,
}

/// Estimates the camera ray's weight times the radiance arriving along it (the pixel measurement), split into
/// layers, with the part of it that is ghost light (`crate::ghost`, as the PBPM backward pass decides it);
/// `max_depth` counts path segments. `spectrum` holds the wavelength the path takes if it meets dispersion (a
/// path tracer can draw one per path). With `sensor_ghosts`, emitters seen through the lens after a reflection
/// in it are left to light paths, as in the PBPM backward pass. `log` records the path (a ray map's) or, as
/// `Unrecorded`, costs nothing.
#[allow(clippy::too_many_arguments)]
pub fn trace(
    scene: &Scene,
    max_depth: u32,
    sensor_ghosts: bool,
    spectrum: &PhaseSpectrum,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut PathStats,
    log: &mut impl PathLog,
) -> (LayerValues, Rgb) {
    let run = CameraRun { scene, max_depth, sensor_ghosts, spectrum, class: 0 };
    let (out, ghost, rays) = trace_camera(run, camera_ray, &mut TraceOn, sampler, log);
    stats.rays += rays;
    (out, ghost)
}
