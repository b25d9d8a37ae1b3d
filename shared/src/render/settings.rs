//! Settings of one rendering run.

use super::method::{Estimator, Method};
use crate::pbpm::{Phase, RadiusSchedule};
use crate::sampling::{Pass, Sampler};
use crate::scene::{Scene, SceneRenderSettings};
use crate::spectrum::PhaseSpectrum;
use serde::{Deserialize, Serialize};

/// The camera paths' diffuse depth a run that chooses its own starts from (the deeper of the two, so that memory
/// is sized for it), and keeps where the comparison cannot tell them apart.
pub const START_DEPTH: u32 = 2;

/// The light paths per pixel a run that chooses its own (`light_balance`) starts from.
pub const START_LIGHT_PATHS: f32 = 1.0;

/// Everything that, with the scene, determines a run's result.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Named "method" in records and jobs: it is the method's estimator.
    #[serde(rename = "method")]
    pub estimator: Estimator,
    /// Job seed: with the phase and the pixel or light-path index it seeds every random stream.
    pub seed: u64,
    pub max_depth: u32,
    pub backward_diffuse_depth: u32,
    /// Initial photon radius in pixel footprints.
    pub radius_scale: f32,
    /// Knaus–Zwicker α.
    pub radius_alpha: f32,
    /// Light paths per phase, per pixel: fixed, or where `adaptive_light` starts (and, in a record, ends).
    pub light_paths_per_pixel: f32,
    /// True when the run chooses the light paths per pixel as it goes (`light_balance`); the scene's
    /// `[render]` table or `--light-paths-per-pixel` fixes them.
    #[serde(default)]
    pub adaptive_light: bool,
    /// True when the run chooses `backward_diffuse_depth` in its first steps (`light_balance`); the scene's
    /// `[render]` table or `--backward-diffuse-depth` fixes it.
    #[serde(default)]
    pub adaptive_depth: bool,
    /// Wavelength bands written as layers (`--spectral-output`); 0 for none. Any band makes every path spectral
    /// from its first vertex.
    pub spectral_bands: u32,
}

impl RenderSettings {
    /// The scene's own settings for a run of `method` (its estimator) with the given seed.
    pub fn for_scene(scene: &Scene, method: Method, seed: u64) -> Self {
        let SceneRenderSettings { max_depth, backward_diffuse_depth, radius_scale, light_paths_per_pixel, .. } =
            scene.render;
        RenderSettings {
            estimator: method.estimator(),
            seed,
            max_depth,
            backward_diffuse_depth: backward_diffuse_depth.unwrap_or(START_DEPTH),
            radius_scale,
            radius_alpha: 2.0 / 3.0,
            light_paths_per_pixel: light_paths_per_pixel.unwrap_or(START_LIGHT_PATHS),
            adaptive_light: light_paths_per_pixel.is_none(),
            adaptive_depth: backward_diffuse_depth.is_none(),
            spectral_bands: 0,
        }
    }

    /// The photon radius schedule for this scene's camera.
    pub fn radius_schedule(&self, scene: &Scene) -> RadiusSchedule {
        RadiusSchedule { scale: self.radius_scale, alpha: self.radius_alpha, pixel_angle: scene.camera.pixel_angle() }
    }

    /// The wavelengths of the phase (or path) identified by `key` in a spectral scene; RGB otherwise. The
    /// camera and light paths of a phase share them, so that their joins are at one wavelength.
    pub fn phase_spectrum(&self, scene: &Scene, key: u64) -> PhaseSpectrum {
        if !self.is_spectral(scene) {
            return PhaseSpectrum::RGB;
        }
        PhaseSpectrum::sample(&mut Sampler::new(self.seed, Pass::Wavelength, key, 0), self.spectral_bands > 0)
    }

    /// True when the run renders spectrally: the scene disperses, or spectral output is asked for.
    pub fn is_spectral(&self, scene: &Scene) -> bool {
        crate::spectrum::ENABLED && (self.spectral_bands > 0 || scene.is_spectral())
    }

    /// The phase whose random streams `key` names, with its wavelengths.
    pub fn phase<'a>(&self, scene: &'a Scene, key: u64) -> Phase<'a> {
        // The ghost pairs' pilot runs in parallel: here, before the phase's parallel stages, rather than on the
        // first ghost path inside them.
        crate::pbpm::ghost_pairs(scene);
        Phase {
            scene,
            seed: self.seed,
            key,
            max_depth: self.max_depth,
            backward_diffuse_depth: self.backward_diffuse_depth,
            radius: self.radius_schedule(scene),
            spectrum: self.phase_spectrum(scene, key),
            sensor_ghosts: crate::scene::ghost::sensor_ghosts(scene),
            ghost_paths: crate::scene::ghost::ghost_paths(scene),
            sensor_kernel: crate::pbpm::SensorKernel::POINT,
        }
    }

    /// The settings a record keeps: a run that chose its light paths per pixel or its depth as it went keeps
    /// where it started, which with the rest determines its result (its history says what each step had).
    pub fn as_recorded(&self) -> Self {
        let mut s = *self;
        if s.adaptive_light {
            s.light_paths_per_pixel = START_LIGHT_PATHS;
        }
        if s.adaptive_depth {
            s.backward_diffuse_depth = START_DEPTH;
        }
        s
    }

    /// Light paths traced per phase for an image of `pixels` pixels.
    pub fn light_paths_per_phase(&self, pixels: usize) -> u64 {
        ((self.light_paths_per_pixel as f64 * pixels as f64).round() as u64).max(1)
    }
}
