//! Settings of one rendering run.

use crate::pbpm::{Phase, RadiusSchedule};
use crate::sampling::{Pass, Sampler};
use crate::scene::{Scene, SceneRenderSettings};
use crate::spectrum::PhaseSpectrum;
use serde::{Deserialize, Serialize};

/// The estimator a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Progressive backward photon mapping, single thread.
    Pbpm,
    /// The reference path tracer (one sample per pixel per phase).
    Path,
}

impl Method {
    /// The name used on the command line and in records.
    pub fn name(self) -> &'static str {
        match self {
            Method::Pbpm => "pbpm",
            Method::Path => "path",
        }
    }
}

/// Everything that, with the scene, determines a run's result.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    pub method: Method,
    /// Job seed: with the phase and the pixel or light-path index it seeds every random stream.
    pub seed: u64,
    pub max_depth: u32,
    pub backward_diffuse_depth: u32,
    /// Initial photon radius in pixel footprints.
    pub radius_scale: f32,
    /// Knaus–Zwicker α.
    pub radius_alpha: f32,
    /// Light paths per phase, per pixel.
    pub light_paths_per_pixel: f32,
    /// Wavelength bands written as layers (`--spectral-output`); 0 for none. Any band makes every path spectral
    /// from its first vertex.
    pub spectral_bands: u32,
}

impl RenderSettings {
    /// The scene's own settings with the given method and seed.
    pub fn for_scene(scene: &Scene, method: Method, seed: u64) -> Self {
        let SceneRenderSettings { max_depth, backward_diffuse_depth, radius_scale, light_paths_per_pixel } =
            scene.render;
        RenderSettings {
            method,
            seed,
            max_depth,
            backward_diffuse_depth,
            radius_scale,
            radius_alpha: 2.0 / 3.0,
            light_paths_per_pixel,
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
        Phase {
            scene,
            seed: self.seed,
            key,
            max_depth: self.max_depth,
            backward_diffuse_depth: self.backward_diffuse_depth,
            radius: self.radius_schedule(scene),
            spectrum: self.phase_spectrum(scene, key),
        }
    }

    /// Light paths traced per phase for an image of `pixels` pixels.
    pub fn light_paths_per_phase(&self, pixels: usize) -> u64 {
        ((self.light_paths_per_pixel as f64 * pixels as f64).round() as u64).max(1)
    }
}

/// The parallel methods of DESIGN §2 that run inside one process.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ParallelMethod {
    /// One group of n threads over the whole image.
    Sync,
    /// n groups of one thread, each over the whole image with a private map and image.
    Async,
    /// n/g groups of g threads over random tile masks, sharing their maps.
    TwoLevel,
}

impl ParallelMethod {
    /// The name used on the command line and in records.
    pub fn name(self) -> &'static str {
        match self {
            ParallelMethod::Sync => "sync",
            ParallelMethod::Async => "async",
            ParallelMethod::TwoLevel => "two-level",
        }
    }
}
