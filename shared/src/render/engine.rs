//! The single-threaded progressive engine: the reference every parallel method must agree with. It renders
//! the whole image each phase, or only the active tiles once some have retired (adaptive tiles).

use super::active_tiles::ActiveTiles;
use super::method::Estimator;
use super::settings::RenderSettings;
use super::totals::{PhaseReport, RayTotals};
use crate::accumulation::{Accumulator, AuxLayout, AuxSums, PixelSums};
use crate::integrator::path_tracer;
use crate::pbpm::forward_pass::{trace_light_path, LightEvent};
use crate::pbpm::ghost_paths::trace_ghost_paths;
use crate::pbpm::phase::{start_aux, Closing, LocalPixels};
use crate::pbpm::{
    mean_phase, Executor, ForwardStats, GatherBuffer, PhaseBuffers, PhotonMap, PixelPhase, SortedGathers,
};
use crate::ray_map::{PathKind, RecordedPath, Recorder, Unrecorded};
use crate::sampling::{replicate_of, Sampler};
use crate::scene::Scene;
use crate::spectrum::PhaseSpectrum;
use std::sync::Arc;

/// Runs phases over the image (or its active tiles) on the calling thread and keeps the running sums: one group
/// of one thread whose map nobody shares, running the stages of `pbpm::phase`.
pub struct Engine<'s> {
    scene: &'s Scene,
    settings: RenderSettings,
    sums: Accumulator,
    buffers: PhaseBuffers,
    map: PhotonMap,
    gathered: GatherBuffer,
    /// Light vertices waiting for the forward pass's gather in bucket order.
    sorted: SortedGathers,
    totals: RayTotals,
    /// Records the kept camera and light paths into a ray map.
    recorder: Option<Arc<Recorder>>,
    /// The pixels of the active tiles once some have retired (None: every pixel).
    tiles: Option<TilePixels>,
    /// How long the latest phase took: a timed run starts no phase it expects to end past its deadline.
    last_phase: Option<std::time::Duration>,
    /// At most how many pixels a phase renders (`set_phase_cap`), and the tiles a capped phase chooses among.
    cap: Option<PhaseCap>,
}

/// Above this many pixels a phase renders only the tiles with the fewest phases, about this many pixels of
/// them (`Engine::set_phase_cap`): on a large image a whole-image phase lasts a minute, and a timed run can
/// stop, and show its image, only between phases. Every image up to 512 × 512 (every shipped scene) renders
/// whole, and so keeps its images for a fixed seed.
pub const CAPPED_PHASE_PIXELS: usize = 512 * 512;

/// A phase cap: at most `pixels` a phase, in whole tiles, chosen among `wanted`'s active tiles (the run's
/// adaptive tiles) or, without them, among `all` the image's tiles.
struct PhaseCap {
    pixels: usize,
    all: ActiveTiles,
    wanted: Option<ActiveTiles>,
}

/// The pixels a phase renders when some tiles have retired, and the phase's sums over them: a phase closes
/// into these and they are added to the image's sums, as a worker's group does with its mask.
struct TilePixels {
    /// Image pixel of each local pixel.
    mask: Vec<u32>,
    /// Local pixel of each image pixel, for light that registers on the sensor.
    local: LocalPixels,
    sums: Vec<PixelSums>,
    aux: AuxSums,
}

/// The sensor's lookup of a phase over the whole image.
static WHOLE_IMAGE: LocalPixels = LocalPixels::Image;

impl TilePixels {
    /// The local pixels of a phase with `tiles` (None: the whole image) and how many there are.
    fn rendered<'a>(tiles: &'a Option<TilePixels>, scene: &Scene) -> (&'a LocalPixels, usize) {
        match tiles {
            Some(t) => (&t.local, t.mask.len()),
            None => (&WHOLE_IMAGE, scene.camera.pixel_count()),
        }
    }
}

impl<'s> Engine<'s> {
    /// An engine with empty sums.
    pub fn new(scene: &'s Scene, settings: RenderSettings) -> Self {
        scene.assert_traceable();
        let pixels = scene.camera.pixel_count();
        let aux = AuxLayout::for_scene(scene, settings.spectral_bands);
        let mut buffers = PhaseBuffers::new(aux.clone(), Executor::CallingThread);
        buffers.resize(pixels);
        let mut gathered = GatherBuffer::default();
        gathered.reset(pixels, &aux);
        // At most one photon per diffuse vertex of each camera path: room made once, so memory stays flat.
        let mut map = PhotonMap::new();
        map.reserve(pixels * settings.backward_diffuse_depth as usize);
        Engine {
            scene,
            settings,
            sums: Accumulator::with_aux(scene.camera.width, scene.camera.height, aux),
            buffers,
            map,
            gathered,
            sorted: SortedGathers::new(),
            totals: RayTotals::default(),
            recorder: None,
            tiles: None,
            last_phase: None,
            cap: None,
        }
    }

    /// Renders at most `pixels` pixels a phase from the next phase on: the tiles (of `tile` pixels) with the
    /// fewest phases, whole, as many as fit (`ActiveTiles::fewest_phases_first`, as the parallel engine's cap
    /// chooses them). Each pixel's phase j and radius stay its own, and a
    /// phase's light shrinks with its pixels, as with adaptive tiles; an image of at most `pixels` pixels
    /// renders whole.
    pub fn set_phase_cap(&mut self, pixels: usize, tile: u32) {
        let cam = &self.scene.camera;
        let all = ActiveTiles::all(cam.width, cam.height, tile.max(1)).expect("a tile of at least one pixel");
        let wanted = self.cap.take().and_then(|c| c.wanted);
        self.cap = Some(PhaseCap { pixels: pixels.max(1), all, wanted });
    }

    /// Renders only `tiles`' active tiles from the next phase on (adaptive tiles); every pixel keeps its own
    /// phase count, so each pixel's phase j and radius are its own. Under a phase cap, a phase renders some of
    /// them.
    pub fn set_active_tiles(&mut self, tiles: &ActiveTiles) {
        if let Some(cap) = &mut self.cap {
            cap.wanted = (!tiles.all_active()).then(|| tiles.clone());
            return;
        }
        self.render_tiles(tiles);
    }

    /// Renders `tiles`' active tiles from the next phase on.
    fn render_tiles(&mut self, tiles: &ActiveTiles) {
        let cam = &self.scene.camera;
        assert_eq!((tiles.width, tiles.height), (cam.width, cam.height), "tiles of another image");
        let aux = self.sums.aux.layout().clone();
        self.tiles = (!tiles.all_active()).then(|| {
            let mask = tiles.active_pixels();
            let local = LocalPixels::of_mask(&mask, cam.pixel_count(), true);
            let sums = vec![PixelSums::default(); mask.len()];
            let aux = AuxSums::new(aux.clone(), mask.len());
            TilePixels { mask, local, sums, aux }
        });
        let rendered = self.tiles.as_ref().map_or(cam.pixel_count(), |t| t.mask.len());
        self.buffers.resize(rendered);
        self.gathered.reset(rendered, &aux);
    }

    /// Records the paths `recorder` keeps (a ray map) from the next phase on; recording does not change the
    /// image.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        self.buffers.set_recorder(recorder.clone());
        self.recorder = recorder;
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

    /// Sets the light paths per pixel of the phases to come.
    pub fn set_light_paths_per_pixel(&mut self, l: f32) {
        self.settings.light_paths_per_pixel = l;
    }

    /// Sets the camera paths' diffuse depth (1 or 2) of the phases to come.
    pub fn set_backward_diffuse_depth(&mut self, depth: u32) {
        self.settings.backward_diffuse_depth = depth;
    }

    /// Bytes held per pixel by the sums, the phase buffers and the photon map.
    pub fn bytes_per_pixel(&self) -> f64 {
        let pixels = self.scene.camera.pixel_count().max(1);
        let sums = self.sums.pixels.capacity() * std::mem::size_of::<crate::accumulation::PixelSums>()
            + self.sums.aux.capacity_bytes();
        let phase = self.buffers.capacity_bytes()
            + self.gathered.capacity_bytes()
            + self.sorted.capacity_bytes()
            + self.map.capacity_bytes()
            + self.tiles.as_ref().map_or(0, |t| {
                t.mask.capacity() * 4
                    + t.local.capacity_bytes()
                    + t.sums.capacity() * std::mem::size_of::<crate::accumulation::PixelSums>()
                    + t.aux.capacity_bytes()
            });
        (sums + phase) as f64 / pixels as f64
    }

    /// Renders one more phase and closes it into the sums.
    pub fn run_phase(&mut self) -> PhaseReport {
        let started = std::time::Instant::now();
        if let Some(cap) = &self.cap {
            let candidates = cap.wanted.as_ref().unwrap_or(&cap.all);
            let phases = &self.sums.pixels;
            let (seed, number) = (self.settings.seed, self.totals.phases);
            let next = match candidates.fewest_phases_first(|p| phases[p as usize].phases, cap.pixels, seed, number) {
                Some(tiles) => Some(tiles),
                // Every candidate fits: a phase over the whole image needs no new tiles.
                None if candidates.all_active() && self.tiles.is_none() => None,
                None => Some(candidates.clone()),
            };
            if let Some(tiles) = next {
                self.render_tiles(&tiles);
            }
        }
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
        self.last_phase = Some(started.elapsed());
        report
    }

    /// How long the latest phase took (None before the first).
    pub fn last_phase_duration(&self) -> Option<std::time::Duration> {
        self.last_phase
    }

    fn path_phase(&mut self) -> PhaseReport {
        let phase = self.totals.phases + 1;
        let scene = self.scene;
        let cam = &scene.camera;
        let mut stats = path_tracer::PathStats::default();
        let spectral = self.settings.is_spectral(scene);
        let aux = self.sums.aux.layout().clone();
        let (channels, ghost_offset) = (aux.channels(), aux.offset(crate::ghost::GHOST_LAYER));
        // Ghost chains come from light paths, as in PBPM. Spectral output reads a pixel's bands at its camera
        // path's own wavelength, which light paths of other wavelengths would not match: with it the camera
        // paths keep the ghost chains.
        let sensor_ghosts = crate::scene::ghost::sensor_ghosts(scene) && self.settings.spectral_bands == 0;
        let light = if sensor_ghosts { self.sensor_light_paths(phase) } else { ForwardStats::default() };
        let closing = Closing::new(light.light_paths, &aux, self.gathered.visible_offset());
        let stride = self.gathered.stride();
        let mut aux_phase = vec![0.0; channels];
        let mut log = RecordedPath::new(PathKind::Camera, 0, 0, 0);
        let mask = self.tiles.as_ref().map(|t| &t.mask[..]);
        for local in 0..mask.map_or(cam.pixel_count(), <[u32]>::len) {
            let pixel = mask.map_or(local, |m| m[local] as usize);
            let (x, y) = ((pixel % cam.width as usize) as u32, (pixel / cam.width as usize) as u32);
            // The pixel's own phase number: the engine's phase count unless tiles have retired.
            let j = self.sums.pixels[pixel].phases as u64 + 1;
            let (replicate, _) = replicate_of(j);
            let mut s = Sampler::path(self.settings.seed, pixel as u64, j);
            let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
            // Paths of a path tracer never join: each draws its own wavelength.
            let spectrum = if spectral {
                self.settings.phase_spectrum(scene, phase << 32 | pixel as u64)
            } else {
                PhaseSpectrum::RGB
            };
            let kept = self.recorder.as_deref().filter(|r| r.keeps(PathKind::Camera, phase, pixel as u64));
            if kept.is_some() {
                (log.phase, log.item, log.source) = (phase as u32, pixel as u32, pixel as u32);
            }
            let max_depth = self.settings.max_depth;
            let trace = |log: &mut _, s: &mut Sampler, stats: &mut _| {
                path_tracer::trace(scene, max_depth, sensor_ghosts, &spectrum, ray, s, stats, log)
            };
            let (v, ghost) = match kept {
                Some(_) => trace(&mut log, &mut s, &mut stats),
                None => path_tracer::trace(
                    scene,
                    max_depth,
                    sensor_ghosts,
                    &spectrum,
                    ray,
                    &mut s,
                    &mut stats,
                    &mut Unrecorded,
                ),
            };
            if let Some(r) = kept {
                r.record(&log);
            }
            start_aux(&mut aux_phase, ghost_offset, ghost);
            // Only the light paths' sensor hits are gathered.
            let gathered = sensor_ghosts.then(|| &mut self.gathered.values_mut()[local * stride..(local + 1) * stride]);
            let aux_sums = &mut self.sums.aux.values_mut()[pixel * channels..(pixel + 1) * channels];
            let (aux, aux_sums) = if channels == 0 {
                (None, None)
            } else {
                (Some((&mut aux_phase[..], spectrum.wavelength(0))), Some(aux_sums))
            };
            closing.close_pixel(&v, replicate, gathered, aux, &mut self.sums.pixels[pixel], aux_sums);
        }
        PhaseReport {
            phase,
            backward_rays: stats.rays,
            forward_rays: light.rays,
            light_paths: light.light_paths,
            ..Default::default()
        }
    }

    /// The path tracer's light paths: they only bring the ghost chains to the sensor, so each ends at its first
    /// diffuse vertex; their light waits in the gather buffer for the phase's pixels.
    fn sensor_light_paths(&mut self, phase: u64) -> ForwardStats {
        let scene = self.scene;
        // The camera paths' wavelength keys are phase << 32 | pixel; this one is no pixel's.
        // The reference path tracer stays unbiased: its ghost chains register on their own pixels, without the
        // sensor's disc.
        let mut p = self.settings.phase(scene, phase);
        p.spectrum = self.settings.phase_spectrum(scene, phase << 32 | u32::MAX as u64);
        let light = p.light_settings(false);
        let mut stats = ForwardStats::default();
        let gathered = &mut self.gathered;
        let (pixels, rendered) = TilePixels::rendered(&self.tiles, scene);
        let mut log = RecordedPath::new(PathKind::Light, phase as u32, 0, 0);
        for index in 0..self.settings.light_paths_per_phase(rendered) {
            let mut s = Sampler::light(self.settings.seed, p.key, index);
            let kept = self.recorder.as_deref().filter(|r| r.keeps(PathKind::Light, phase, index));
            log.item = index as u32;
            let mut visit = |e: &LightEvent| {
                if let LightEvent::Sensor(hit) = e {
                    p.register(pixels, hit, gathered);
                }
            };
            match kept {
                Some(_) => trace_light_path(scene, light, &p.spectrum, index, &mut s, &mut stats, &mut visit, &mut log),
                None => {
                    let log = &mut Unrecorded;
                    trace_light_path(scene, light, &p.spectrum, index, &mut s, &mut stats, &mut visit, log)
                }
            }
            if let Some(r) = kept {
                r.record(&log);
            }
            let record = kept.map(|r| (r, phase));
            trace_ghost_paths(scene, light, &p.spectrum, index, p.seed, p.key, &mut stats, &mut visit, record);
        }
        stats
    }

    fn pbpm_phase(&mut self) -> PhaseReport {
        let number = self.totals.phases + 1;
        let exec = Executor::CallingThread;
        let mask = self.tiles.as_ref().map(|t| &t.mask[..]);
        let pixels = &self.sums.pixels;
        // A pixel's phase j is its own phase count plus one: the engine's phase count unless tiles have retired.
        let next_phase =
            |local: usize| PixelPhase::alone(pixels[mask.map_or(local, |m| m[local] as usize)].phases as u64 + 1);
        let rendered = mask.map_or(pixels.len(), <[u32]>::len);
        let mean = mean_phase(rendered, |i| next_phase(i).radius);
        let phase = self.settings.phase(self.scene, number).at_pixel_phase(mean);
        let backward = self.buffers.camera_pass(exec, &phase, mask, next_phase, &mut self.map, None);
        self.buffers.build_map(exec, &mut self.map);
        let (local, rendered) = TilePixels::rendered(&self.tiles, self.scene);
        // Light per rendered pixel: where tiles retired, the phase's light shrinks with its camera paths.
        let n = self.settings.light_paths_per_phase(rendered);
        let recorder = self.recorder.as_deref().map(|r| (r, number));
        let forward =
            phase.forward_pass_recorded(0..n, &self.map, local, &mut self.gathered, &mut self.sorted, recorder);
        match &mut self.tiles {
            None => self.buffers.close(exec, &phase, &mut self.gathered, n, &mut self.sums.pixels, &mut self.sums.aux),
            Some(t) => {
                self.buffers.close(exec, &phase, &mut self.gathered, n, &mut t.sums, &mut t.aux);
                self.sums.merge_local(&t.mask, &t.sums, &t.aux);
                t.sums.fill(PixelSums::default());
                t.aux.reset(t.mask.len());
            }
        }
        self.totals.backward_photons += backward.photons;
        self.totals.capped_light_paths += forward.capped;
        PhaseReport {
            phase: number,
            backward_rays: backward.rays,
            forward_rays: forward.rays,
            light_paths: forward.light_paths,
            merges: forward.merges,
        }
    }
}
