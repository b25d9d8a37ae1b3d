//! The backward pass (paper §2 step 1): camera paths that add directly visible light and direct light (with
//! MIS, paper eq. 5) to their pixel and store backward photons at their first `backward_diffuse_depth`
//! diffuse vertices.

use super::gather_disc::gather_disc_areas;
use super::photon::{BackwardPhoton, PhotonLists, StoredVertex, LAMBERTIAN};
use super::radius::RadiusSchedule;
use super::PhotonKind;
use crate::camera::CameraRay;
use crate::color::Rgb;
use crate::integrator::camera_path::{trace_camera, After, CameraRun, StoredVertices, StoringVertex};
use crate::integrator::walk::Walk;
use crate::integrator::LayerValues;
use crate::ray_map::PathLog;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::PhaseSpectrum;

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
    /// Chunks of pixels left untraced because the pass was abandoned (the phase is then left out whole).
    pub abandoned_chunks: u64,
}

impl std::ops::Add for BackwardStats {
    type Output = Self;

    /// The counts of two shares of a backward pass together.
    fn add(self, o: Self) -> Self {
        BackwardStats {
            rays: self.rays + o.rays,
            photons: self.photons + o.photons,
            abandoned_chunks: self.abandoned_chunks + o.abandoned_chunks,
        }
    }
}

/// Traces one camera path for `pixel`, returns its visible-light and next-event contributions per layer with
/// the part of them that is ghost light (`crate::ghost`), and adds every backward photon to `store`. The
/// camera ray's weight starts the path throughput, so that it also reaches the photons' filter τ and with them
/// the forward pass's gathered light. `log` records the path (a ray map's) or, as `Unrecorded`, costs nothing;
/// the image is the same either way.
#[allow(clippy::too_many_arguments)]
pub fn trace_camera_path(
    scene: &Scene,
    settings: &BackwardSettings,
    pixel: u32,
    camera_ray: CameraRay,
    sampler: &mut Sampler,
    stats: &mut BackwardStats,
    store: &mut PhotonLists,
    log: &mut impl PathLog,
) -> (LayerValues, Rgb) {
    let run = CameraRun {
        scene,
        max_depth: settings.max_depth,
        sensor_ghosts: settings.sensor_ghosts,
        spectrum: &settings.spectrum,
        class: PhaseSpectrum::class_of(pixel as u64),
    };
    let mut photons = Photons { settings, pixel, store, stored: 0 };
    let (out, ghost, rays) = trace_camera(run, camera_ray, &mut photons, sampler, log);
    stats.rays += rays;
    stats.photons += photons.stored;
    (out, ghost)
}

/// The backward pass's storing vertices: a photon at each of the first `backward_diffuse_depth`, and the path
/// ends at the last of them.
struct Photons<'a, 'b> {
    settings: &'a BackwardSettings,
    pixel: u32,
    store: &'a mut PhotonLists<'b>,
    stored: u64,
}

impl<const S: bool> StoredVertices<S> for Photons<'_, '_> {
    const STORES: bool = true;
    // Long specular chains (light trapped in glass) end by roulette, unbiased.
    const ROULETTE_FROM: u32 = 4;

    #[inline(always)]
    fn after(&self, k: u32) -> After {
        if k < self.settings.backward_diffuse_depth {
            After::Continue
        } else if k == 1 {
            // Where the path ends at its first storing vertex, one BSDF ray still looks for an emitter:
            // next-event estimation alone is noisy where an emitter is large or near (its solid angle, not its
            // area, is then what to sample), and the direct layer is then the same estimator at either depth.
            After::EmitterRay
        } else {
            After::Stop
        }
    }

    #[inline(always)]
    fn store(&mut self, w: &Walk<S>, v: StoringVertex) {
        let settings = self.settings;
        // A merge needs at least two light segments (y1 is next-event estimation's).
        if w.segments + 2 > settings.max_depth {
            return;
        }
        let r = settings.radius.radius(w.length, settings.phase);
        // eq. 4's τ · f / (π r²), with the disc's area on the surface for π r² (`gather_disc`); a Lambertian
        // photon carries f = ρ/π, any other carries its BSDF to evaluate at the gather.
        let areas = gather_disc_areas(&w.scene.geometry, v.hit, r);
        let (weight, stored) = match v.bsdf.lambertian() {
            Some(albedo) => (w.beta * albedo * (std::f32::consts::FRAC_1_PI / areas.whole), LAMBERTIAN),
            None => (w.beta * (1.0 / areas.whole), self.store.vertices.len() as u32),
        };
        if weight.is_finite() && r > 0.0 {
            if stored != LAMBERTIAN {
                self.store.vertices.push(StoredVertex { bsdf: *v.bsdf, wo: v.wo });
            }
            self.stored += 1;
            self.store.photons.push(BackwardPhoton {
                position: v.hit.p,
                normal: v.bsdf.geometric_normal(),
                weight,
                radius2: r * r,
                pixel: self.pixel,
                kind: PhotonKind::new(v.k as u8, v.first, v.ghost),
                segments: w.segments.min(255) as u8,
                spectrum: w.spectrum.tag(),
                inner_share: areas.inner_share(),
                stored,
            });
        }
    }
}
