//! The single-threaded progressive engine: the reference every parallel method must agree with.

use super::method::Estimator;
use super::settings::RenderSettings;
use crate::accumulation::{Accumulator, AuxLayout};
use crate::color::Rgb;
use crate::integrator::{path_tracer, Layer, LayerValues};
use crate::pbpm::{
    backward_pass::BackwardStats, gather, trace_camera_path, trace_light_path, BackwardSettings, ForwardStats,
    PhotonMap,
};
use crate::sampling::{Pass, Sampler};
use crate::scene::Scene;
use crate::spectrum::{band_values, PhaseSpectrum, Wavelength};
use serde::{Deserialize, Serialize};

/// Counts accumulated over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RayTotals {
    pub phases: u64,
    /// Rays of camera paths (segments and shadow rays).
    pub backward_rays: u64,
    /// Rays of light paths.
    pub forward_rays: u64,
    pub light_paths: u64,
    /// Light paths counted against the photon maps: a light path counts once per map it gathered into, so this
    /// exceeds `light_paths` where groups share their maps (two-level) and equals it elsewhere.
    pub map_light_paths: u64,
    pub backward_photons: u64,
    /// Light-path vertices that met a backward photon.
    pub merges: u64,
    /// Light paths stopped by `max_depth` while still carrying flux.
    pub capped_light_paths: u64,
}

impl std::ops::AddAssign for RayTotals {
    fn add_assign(&mut self, o: RayTotals) {
        self.phases += o.phases;
        self.backward_rays += o.backward_rays;
        self.forward_rays += o.forward_rays;
        self.light_paths += o.light_paths;
        self.map_light_paths += o.map_light_paths;
        self.backward_photons += o.backward_photons;
        self.merges += o.merges;
        self.capped_light_paths += o.capped_light_paths;
    }
}

/// What one phase did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseReport {
    pub phase: u64,
    pub backward_rays: u64,
    pub forward_rays: u64,
    pub light_paths: u64,
    pub merges: u64,
}

/// Runs phases over the whole image on the calling thread and keeps the running sums.
pub struct Engine<'s> {
    scene: &'s Scene,
    settings: RenderSettings,
    sums: Accumulator,
    map: PhotonMap,
    phase_values: Vec<LayerValues>,
    /// Gathered (indirect, caustic) luminance of the phase, before division by the light-path count.
    gathered: Vec<[Rgb; 2]>,
    /// The phase's auxiliary values per pixel (`sums.aux`'s layout), from the camera pass, and the auxiliary
    /// light gathered (before division by the light-path count); both empty without auxiliary layers.
    aux_phase: Vec<f32>,
    aux_gathered: Vec<f32>,
    /// Where the ghost layer's channels start among a pixel's auxiliary channels, when the scene has one.
    ghost: Option<usize>,
    totals: RayTotals,
}

impl<'s> Engine<'s> {
    /// An engine with empty sums.
    pub fn new(scene: &'s Scene, settings: RenderSettings) -> Self {
        let pixels = scene.camera.pixel_count();
        let mut map = PhotonMap::new();
        // At most one photon per diffuse vertex of each camera path.
        map.reserve(pixels * settings.backward_diffuse_depth as usize);
        let aux = AuxLayout::for_scene(scene, settings.spectral_bands);
        let aux_channels = aux.channels();
        Engine {
            scene,
            settings,
            ghost: aux.offset(crate::ghost::GHOST_LAYER),
            sums: Accumulator::with_aux(scene.camera.width, scene.camera.height, aux),
            map,
            phase_values: vec![[Rgb::ZERO; 4]; pixels],
            gathered: vec![[Rgb::ZERO; 2]; pixels],
            aux_phase: vec![0.0; pixels * aux_channels],
            aux_gathered: vec![0.0; pixels * aux_channels],
            totals: RayTotals::default(),
        }
    }

    /// The running sums.
    pub fn sums(&self) -> &Accumulator {
        &self.sums
    }

    /// Totals so far.
    pub fn totals(&self) -> RayTotals {
        self.totals
    }

    /// The settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Bytes held per pixel by the sums, the phase buffers and the photon map.
    pub fn bytes_per_pixel(&self) -> f64 {
        let pixels = self.phase_values.len().max(1);
        let fixed = self.sums.pixels.capacity() * std::mem::size_of::<crate::accumulation::PixelSums>()
            + self.phase_values.capacity() * std::mem::size_of::<LayerValues>()
            + self.gathered.capacity() * std::mem::size_of::<[Rgb; 2]>();
        let aux = self.sums.aux.capacity_bytes() + (self.aux_phase.capacity() + self.aux_gathered.capacity()) * 4;
        (fixed + aux + self.map.capacity_bytes()) as f64 / pixels as f64
    }

    /// Starts a pixel's auxiliary values of the phase from its camera path: its ghost light in the ghost layer
    /// (nothing without auxiliary layers).
    #[inline]
    fn start_aux(&mut self, pixel: usize, ghost: Rgb) {
        let n = self.sums.aux.layout().channels();
        self.aux_phase[pixel * n..(pixel + 1) * n].fill(0.0);
        if let Some(o) = self.ghost {
            let base = pixel * n + o;
            self.aux_phase[base..base + 3].copy_from_slice(&[ghost.x, ghost.y, ghost.z]);
        }
    }

    /// Closes a pixel's auxiliary values of the phase, adding the gathered ones divided by the light paths, and
    /// its spectral-output bands from its phase total at its wavelength.
    #[inline]
    fn close_aux(&mut self, pixel: usize, inv_n: f32, total: Rgb, wavelength: Option<Wavelength>) {
        let n = self.sums.aux.layout().channels();
        if n == 0 {
            return;
        }
        let range = pixel * n..(pixel + 1) * n;
        for (v, g) in self.aux_phase[range.clone()].iter_mut().zip(&self.aux_gathered[range.clone()]) {
            *v += g * inv_n;
        }
        if let (Some((offset, bands)), Some(w)) = (self.sums.aux.layout().bands(), wavelength) {
            let start = pixel * n + offset;
            band_values(total, &w, &mut self.aux_phase[start..start + bands]);
        }
        self.sums.aux.add_phase(pixel, &self.aux_phase[range]);
    }

    /// Renders one more phase and closes it into the sums.
    pub fn run_phase(&mut self) -> PhaseReport {
        let report = match self.settings.estimator {
            Estimator::Pbpm => self.pbpm_phase(),
            Estimator::Path => self.path_phase(),
        };
        self.totals.phases += 1;
        self.totals.backward_rays += report.backward_rays;
        self.totals.forward_rays += report.forward_rays;
        self.totals.light_paths += report.light_paths;
        self.totals.map_light_paths += report.light_paths;
        self.totals.merges += report.merges;
        report
    }

    fn path_phase(&mut self) -> PhaseReport {
        let phase = self.totals.phases + 1;
        let scene = self.scene;
        let cam = &scene.camera;
        let mut stats = path_tracer::PathStats::default();
        let spectral = self.settings.is_spectral(scene);
        for pixel in 0..cam.pixel_count() {
            let (x, y) = ((pixel % cam.width as usize) as u32, (pixel / cam.width as usize) as u32);
            let mut s = Sampler::new(self.settings.seed, Pass::Path, phase, pixel as u64);
            let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
            // Paths of a path tracer never join: each draws its own wavelength.
            let spectrum = if spectral {
                self.settings.phase_spectrum(scene, phase << 32 | pixel as u64)
            } else {
                PhaseSpectrum::RGB
            };
            let (v, ghost) = path_tracer::trace(scene, self.settings.max_depth, &spectrum, ray, &mut s, &mut stats);
            self.sums.add_phase(pixel, &v, 1);
            self.start_aux(pixel, ghost);
            // Nothing is gathered: the gathered buffer stays zero.
            self.close_aux(pixel, 0.0, v.iter().sum(), spectrum.wavelength(0));
        }
        PhaseReport { phase, backward_rays: stats.rays, ..Default::default() }
    }

    fn pbpm_phase(&mut self) -> PhaseReport {
        let phase = self.totals.phases + 1;
        let scene = self.scene;
        let cam = &scene.camera;
        let bs = BackwardSettings {
            max_depth: self.settings.max_depth,
            backward_diffuse_depth: self.settings.backward_diffuse_depth,
            radius: self.settings.radius_schedule(scene),
            phase,
            spectrum: self.settings.phase_spectrum(scene, phase),
        };
        // 1. Backward pass.
        self.map.clear();
        let mut bstats = BackwardStats::default();
        for pixel in 0..cam.pixel_count() {
            let (x, y) = ((pixel % cam.width as usize) as u32, (pixel / cam.width as usize) as u32);
            let mut s = Sampler::new(self.settings.seed, Pass::Camera, phase, pixel as u64);
            let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
            let map = &mut self.map;
            let (v, ghost) =
                trace_camera_path(scene, &bs, pixel as u32, ray, &mut s, &mut bstats, &mut |b| map.push(b));
            self.phase_values[pixel] = v;
            self.start_aux(pixel, ghost);
        }
        // 2. Backward photon map.
        self.map.build();
        // 3. Forward pass.
        let n = self.settings.light_paths_per_phase(cam.pixel_count());
        let mut fstats = ForwardStats::default();
        for g in self.gathered.iter_mut() {
            *g = [Rgb::ZERO; 2];
        }
        self.aux_gathered.fill(0.0);
        let gathered = &mut self.gathered;
        let (aux_gathered, aux_channels, ghost_offset) =
            (&mut self.aux_gathered, self.sums.aux.layout().channels(), self.ghost);
        let mut sink = |pixel: u32, layer: Layer, ghost: bool, v: Rgb| {
            let slot = if layer == Layer::Caustic { 1 } else { 0 };
            gathered[pixel as usize][slot] += v;
            if let (true, Some(o)) = (ghost, ghost_offset) {
                let base = pixel as usize * aux_channels + o;
                for (a, c) in aux_gathered[base..base + 3].iter_mut().zip([v.x, v.y, v.z]) {
                    *a += c;
                }
            }
        };
        let (max_depth, bdd) = (self.settings.max_depth, self.settings.backward_diffuse_depth);
        let map = &self.map;
        let mut merges = 0;
        for i in 0..n {
            let mut s = Sampler::new(self.settings.seed, Pass::Light, phase, i);
            trace_light_path(scene, max_depth, &bs.spectrum, i, &mut s, &mut fstats, &mut |v| {
                merges += gather(map, v, max_depth, bdd, &mut sink)
            });
        }
        fstats.merges = merges;
        // 4. Close the phase: the gathered sums are normalised by the number of light paths traced against
        // the map.
        let inv_n = 1.0 / n as f32;
        for pixel in 0..cam.pixel_count() {
            let mut v = self.phase_values[pixel];
            v[Layer::Indirect as usize] += self.gathered[pixel][0] * inv_n;
            v[Layer::Caustic as usize] += self.gathered[pixel][1] * inv_n;
            self.sums.add_phase(pixel, &v, 1);
            let w = bs.spectrum.wavelength(PhaseSpectrum::class_of(pixel as u64));
            self.close_aux(pixel, inv_n, v.iter().sum(), w);
        }
        self.totals.backward_photons += bstats.photons;
        self.totals.capped_light_paths += fstats.capped;
        PhaseReport {
            phase,
            backward_rays: bstats.rays,
            forward_rays: fstats.rays,
            light_paths: fstats.light_paths,
            merges: fstats.merges,
        }
    }
}
