//! One phase of progressive backward photon mapping over a set of pixels (paper §2, docs/estimator.md, "Phases"):
//!
//! 1. the camera pass traces one camera path per pixel, keeps its visible-light and direct-light values and
//!    stores backward photons at its diffuse vertices ([`PhaseBuffers::camera_pass`]);
//! 2. the photon map is built from those photons ([`PhaseBuffers::build_map`]);
//! 3. light paths gather into the map ([`Phase::trace_light_path`], [`Phase::gather`]);
//! 4. the close adds every pixel's phase value to its running sums ([`PhaseBuffers::close`]).
//!
//! The single-threaded engine runs these stages over the whole image on the calling thread; a worker's
//! synchronous group runs them over its tile mask on its pinned threads and drives step 3 itself (its light-path
//! quota, the other groups' maps, the stop). Both reach the same image: the stages are this file's, once.

use super::backward_pass::{trace_camera_path, BackwardSettings, BackwardStats};
use super::executor::Executor;
use super::forward_pass::{gather, trace_light_path, ForwardStats, Gather, LightEvent, LightSettings, SensorHit};
use super::gather_buffer::GatherBuffer;
use super::ghost_paths::trace_ghost_paths;
use super::photon::{BackwardPhoton, PhotonLists, StoredVertex, LAMBERTIAN};
use super::photon_map::PhotonMap;
use super::radius::RadiusSchedule;
use super::sensor_kernel::SensorKernel;
use super::sorted_gather::SortedGathers;
use crate::accumulation::blur::blur_offsets;
use crate::accumulation::{auxiliary::add_phase_to, AuxLayout, AuxSums, PixelSums};
use crate::color::{luminance, Rgb};
use crate::integrator::{Layer, LayerValues};
use crate::ray_map::{PathKind, RecordedPath, Recorder, Unrecorded};
use crate::sampling::{replicate_of, Sampler};
use crate::scene::Scene;
use crate::spectrum::{band_values, join, PhaseSpectrum, Wavelength};
use rayon::iter::Either;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Pixels per unit of work of the camera pass and the close, each with its own photon list.
pub const PIXEL_CHUNK: usize = 256;

/// What every stage of one phase reads: the scene, the estimator's settings, the phase's random key and its
/// wavelengths.
#[derive(Clone, Copy)]
pub struct Phase<'a> {
    pub scene: &'a Scene,
    /// Job seed: with `key` and the pixel or light-path index it seeds every random stream of the phase.
    pub seed: u64,
    /// Tells this phase's random streams from every other phase's of the run.
    pub key: u64,
    pub max_depth: u32,
    pub backward_diffuse_depth: u32,
    pub radius: RadiusSchedule,
    /// The phase's wavelengths: its camera and light paths share them, so their joins are at one wavelength.
    pub spectrum: PhaseSpectrum,
    /// Light paths register ghost chains on the sensor and camera paths leave those chains to them
    /// (`crate::scene::ghost::sensor_ghosts`).
    pub sensor_ghosts: bool,
    /// Ghost paths per light path (`crate::scene::ghost::ghost_paths`).
    pub ghost_paths: u32,
    /// The disc each ghost chain's registration is spread over on the sensor (`Phase::at_pixel_phase`).
    pub sensor_kernel: SensorKernel,
}

/// Which local pixel of a phase an image pixel is, for light that registers on the sensor: the identity when
/// the phase renders the whole image, a table over the image when it renders a mask.
#[derive(Clone, Debug, Default)]
pub enum LocalPixels {
    #[default]
    Image,
    /// Local index of every image pixel, `u32::MAX` outside the mask.
    Mask(Vec<u32>),
}

impl LocalPixels {
    /// The lookup for a phase over `mask` (image pixels) in an image of `pixels` pixels; `needed` is false when
    /// no light will register on the sensor, which keeps the table out of memory.
    pub fn of_mask(mask: &[u32], pixels: usize, needed: bool) -> Self {
        if !needed || (mask.len() == pixels && mask.iter().enumerate().all(|(i, &p)| p as usize == i)) {
            return LocalPixels::Image;
        }
        let mut table = vec![u32::MAX; pixels];
        for (local, &p) in mask.iter().enumerate() {
            table[p as usize] = local as u32;
        }
        LocalPixels::Mask(table)
    }

    /// The local pixel of image pixel `pixel`, if the phase renders it.
    #[inline]
    pub fn local(&self, pixel: u32) -> Option<u32> {
        match self {
            LocalPixels::Image => Some(pixel),
            LocalPixels::Mask(t) => t.get(pixel as usize).copied().filter(|&l| l != u32::MAX),
        }
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        match self {
            LocalPixels::Image => 0,
            LocalPixels::Mask(t) => t.capacity() * 4,
        }
    }
}

impl Phase<'_> {
    /// The phase with the sensor's disc for ghost chains of the phase whose pixels are at phase j = `j`: their
    /// mean j, where tiles give the pixels different counts, so that one registration keeps one disc.
    pub fn at_pixel_phase(mut self, j: u64) -> Self {
        if self.sensor_ghosts {
            self.sensor_kernel = SensorKernel::at_phase(self.scene.render.ghost_radius, &self.radius, j);
        }
        self
    }

    /// Traces light path number `index` of the phase and hands each vertex that may gather (step 3 above)
    /// and each ghost chain that reaches the sensor to `visit`.
    #[inline]
    pub fn trace_light_path(&self, index: u64, stats: &mut ForwardStats, visit: &mut impl FnMut(&LightEvent)) {
        self.trace_light_path_recorded(index, stats, visit, None);
    }

    /// `trace_light_path` that records the light path (in `log`) and its ghost paths with `recorder` as paths
    /// of phase `number`, when given them.
    #[inline]
    pub fn trace_light_path_recorded(
        &self,
        index: u64,
        stats: &mut ForwardStats,
        visit: &mut impl FnMut(&LightEvent),
        record: Option<(&Recorder, u64, &mut RecordedPath)>,
    ) {
        let mut s = Sampler::light(self.seed, self.key, index);
        let settings = self.light_settings(true);
        let (scene, spectrum) = (self.scene, &self.spectrum);
        match record {
            None => {
                trace_light_path(scene, settings, spectrum, index, &mut s, stats, visit, &mut Unrecorded);
                trace_ghost_paths(scene, settings, spectrum, index, self.seed, self.key, stats, visit, None);
            }
            Some((recorder, number, log)) => {
                (log.phase, log.item) = (number as u32, index as u32);
                trace_light_path(scene, settings, spectrum, index, &mut s, stats, visit, log);
                recorder.record(log);
                let record = Some((recorder, number));
                trace_ghost_paths(scene, settings, spectrum, index, self.seed, self.key, stats, visit, record);
            }
        }
    }

    /// What shapes the phase's light paths: `vertices` says whether they gather at diffuse vertices or only
    /// bring light to the sensor.
    pub fn light_settings(&self, vertices: bool) -> LightSettings {
        LightSettings {
            max_depth: self.max_depth,
            sensor: self.sensor_ghosts,
            vertices,
            ghost_paths: if self.sensor_ghosts { self.ghost_paths } else { 0 },
        }
    }

    /// Gathers what a light path hands over into one phase's target, adding to `sink`: a vertex into the photon
    /// `map` (paper eq. 4), a sensor hit into its pixel if `pixels` has it. Returns the merges.
    #[inline]
    pub fn gather(&self, map: &PhotonMap, pixels: &LocalPixels, e: &LightEvent, sink: &mut impl Gather) -> u64 {
        match e {
            LightEvent::Vertex(v) => gather(map, v, self.max_depth, self.backward_diffuse_depth, sink),
            LightEvent::Sensor(hit) => {
                self.register(pixels, hit, sink);
                0
            }
        }
    }

    /// Adds a chain's light registered on the sensor to its pixel's visible lights, if the phase renders the
    /// pixel; a ghost chain's goes to the pixels of the phase's sensor disc about it, and to the ghost layer.
    #[inline]
    pub fn register(&self, pixels: &LocalPixels, hit: &SensorHit, sink: &mut impl Gather) {
        // A pixel whose camera paths are spectral from their first vertex (spectral output) takes the light of
        // its own wavelength class only, as a photon does.
        let value_at = |local: u32| {
            let tag = if self.spectrum.from_start { PhaseSpectrum::class_of(local as u64) + 1 } else { 0 };
            join(Rgb::ONE, tag, hit.value, hit.spectrum, &self.spectrum)
        };
        if !hit.ghost || self.sensor_kernel.is_point() {
            let Some(local) = pixels.local(hit.pixel) else { return };
            sink.add(local, Layer::VisibleLights, hit.ghost, value_at(local));
            return;
        }
        // A ghost chain is a point of a defocused image: its light is spread over the sensor's disc (eq. 4 on
        // the sensor), and its blur measured against the inner disc's as a photon's is.
        let blur = sink.measures_blur();
        let camera = &self.scene.camera;
        let common = (!self.spectrum.from_start).then(|| value_at(0));
        self.sensor_kernel.spread(hit.pixel, camera.width, camera.height, |pixel, share, d| {
            let Some(local) = pixels.local(pixel) else { return };
            let value = common.unwrap_or_else(|| value_at(local));
            sink.add(local, Layer::VisibleLights, true, value * share);
            if blur {
                sink.add_blur(local, luminance(value) * d);
            }
        });
    }

    /// Traces light paths `indices` into one map and its buffer: the forward pass of a map nobody shares, over
    /// the local `pixels` whose camera paths made the map. The paths' vertices wait in `sorted` and gather in the
    /// map's bucket order (`SortedGathers`), which leaves `sorted` empty.
    pub fn forward_pass(
        &self,
        indices: std::ops::Range<u64>,
        map: &PhotonMap,
        pixels: &LocalPixels,
        gathered: &mut GatherBuffer,
        sorted: &mut SortedGathers,
    ) -> ForwardStats {
        self.forward_pass_recorded(indices, map, pixels, gathered, sorted, None)
    }

    /// `forward_pass` that hands the paths `recorder` keeps of phase `number` to it.
    pub fn forward_pass_recorded(
        &self,
        indices: std::ops::Range<u64>,
        map: &PhotonMap,
        pixels: &LocalPixels,
        gathered: &mut GatherBuffer,
        sorted: &mut SortedGathers,
        recorder: Option<(&Recorder, u64)>,
    ) -> ForwardStats {
        let (mut stats, mut merges) = (ForwardStats::default(), 0);
        let mut log = RecordedPath::new(PathKind::Light, 0, 0, 0);
        let gather = |sorted: &mut SortedGathers, gathered: &mut GatherBuffer| {
            sorted.gather_into(map, &self.spectrum, self.max_depth, self.backward_diffuse_depth, gathered)
        };
        for index in indices {
            // A path hands over fewer than `max_depth` vertices.
            if sorted.room() < self.max_depth as usize {
                merges += gather(sorted, gathered);
            }
            let mut visit = |e: &LightEvent| match e {
                LightEvent::Vertex(v) => sorted.push(map, v.point()),
                LightEvent::Sensor(hit) => self.register(pixels, hit, gathered),
            };
            let kept = recorder.filter(|(r, n)| r.keeps(PathKind::Light, *n, index));
            let record = kept.map(|(r, n)| (r, n, &mut log));
            self.trace_light_path_recorded(index, &mut stats, &mut visit, record);
        }
        merges += gather(sorted, gathered);
        stats.merges = merges;
        stats
    }

    /// The wavelength a local pixel's camera path was carried at (its class among the phase's wavelengths).
    fn wavelength_of(&self, local: usize) -> Option<Wavelength> {
        self.spectrum.wavelength(PhaseSpectrum::class_of(local as u64))
    }
}

/// A phase's per-pixel buffers over the local pixels it renders (the whole image, or a group's mask), kept
/// from phase to phase so that memory stays flat.
#[derive(Debug)]
pub struct PhaseBuffers {
    aux: AuxLayout,
    /// Where the ghost layer's channels start among a pixel's auxiliary channels, when the image has one.
    ghost: Option<usize>,
    /// The camera pass's layer values per local pixel.
    camera: Vec<LayerValues>,
    /// The replicate of each local pixel's quasi-random sequence its phase was drawn from.
    replicates: Vec<u8>,
    /// The camera pass's auxiliary values, channels per local pixel (empty without auxiliary layers).
    aux_camera: Vec<f32>,
    /// The camera pass's photons, one list per `chunk` local pixels, in pixel order.
    photon_lists: Vec<Vec<BackwardPhoton>>,
    /// The BSDFs of the non-Lambertian photons of each list, parallel to `photon_lists`.
    vertex_lists: Vec<Vec<StoredVertex>>,
    /// Local pixels per unit of work: `PIXEL_CHUNK`, or every pixel on the calling thread, whose one list then
    /// becomes the map's photons without a copy (and takes the map's buffer back for the next phase), so that
    /// the single-threaded engine holds its photons once.
    chunk: usize,
    single_list: bool,
    /// Records the kept camera paths into a ray map.
    recorder: Option<std::sync::Arc<Recorder>>,
}

/// One chunk's auxiliary values, or None for every chunk when there are no auxiliary channels, so that an image
/// without auxiliary layers iterates as it would without them.
fn aux_chunks<T: Send>(
    buffer: &mut [T],
    channels: usize,
    pixels: usize,
    chunk: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [T]>> {
    if channels == 0 {
        Either::Right((0..pixels.div_ceil(chunk)).into_par_iter().map(|_| None))
    } else {
        Either::Left(buffer.par_chunks_mut(chunk * channels).map(Some))
    }
}

impl PhaseBuffers {
    /// Empty buffers for an image with the auxiliary layers of `aux`, for stages that `exec` runs.
    pub fn new(aux: AuxLayout, exec: Executor) -> Self {
        PhaseBuffers {
            ghost: aux.offset(crate::ghost::GHOST_LAYER),
            aux,
            camera: Vec::new(),
            replicates: Vec::new(),
            aux_camera: Vec::new(),
            photon_lists: Vec::new(),
            vertex_lists: Vec::new(),
            chunk: PIXEL_CHUNK,
            single_list: exec == Executor::CallingThread,
            recorder: None,
        }
    }

    /// Records the camera paths `recorder` keeps from the next camera pass on.
    pub fn set_recorder(&mut self, recorder: Option<std::sync::Arc<Recorder>>) {
        self.recorder = recorder;
    }

    /// The auxiliary layers.
    pub fn aux(&self) -> &AuxLayout {
        &self.aux
    }

    /// Sizes the buffers for `pixels` local pixels (a new mask).
    pub fn resize(&mut self, pixels: usize) {
        self.camera.clear();
        self.camera.resize(pixels, [Rgb::ZERO; 4]);
        self.replicates.clear();
        self.replicates.resize(pixels, 0);
        self.aux_camera.clear();
        self.aux_camera.resize(pixels * self.aux.channels(), 0.0);
        self.chunk = if self.single_list { pixels.max(1) } else { PIXEL_CHUNK };
        self.photon_lists.resize_with(pixels.div_ceil(self.chunk), Vec::new);
        self.vertex_lists.resize_with(pixels.div_ceil(self.chunk), Vec::new);
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.camera.capacity() * std::mem::size_of::<LayerValues>()
            + self.replicates.capacity()
            + self.aux_camera.capacity() * 4
            + self.photon_lists.iter().map(Vec::capacity).sum::<usize>() * std::mem::size_of::<BackwardPhoton>()
            + self.vertex_lists.iter().map(Vec::capacity).sum::<usize>() * std::mem::size_of::<StoredVertex>()
    }

    /// Stage 1: one camera path per local pixel; `pixels[i]` is local pixel i's image pixel (None: the whole
    /// image, local pixel i being image pixel i), and `next_phase(i)` its phase numbers: the radius's j, and the
    /// j that picks the point and replicate of the pixel's quasi-random sequences (`PixelPhase`). `map` is the
    /// previous phase's, whose photon buffer a single list takes back. Once `abandon` is set, the chunks not yet
    /// started are skipped and counted: the phase must then be left out. Returns the rays traced and the photons
    /// stored.
    pub fn camera_pass(
        &mut self,
        exec: Executor,
        phase: &Phase,
        pixels: Option<&[u32]>,
        next_phase: impl Fn(usize) -> super::PixelPhase + Sync,
        map: &mut PhotonMap,
        abandon: Option<&AtomicBool>,
    ) -> BackwardStats {
        let count = pixels.map_or(phase.scene.camera.pixel_count(), <[u32]>::len);
        assert_eq!(count, self.camera.len(), "camera pass over pixels the buffers were not sized for");
        if let ([list], true) = (&mut self.photon_lists[..], self.single_list) {
            *list = map.take_photons();
        }
        let chunk_len = self.chunk;
        let cam = &phase.scene.camera;
        let (channels, ghost_offset) = (self.aux.channels(), self.ghost);
        let bdd = phase.backward_diffuse_depth;
        let recorder = self.recorder.as_deref();
        let chunks = self
            .camera
            .par_chunks_mut(chunk_len)
            .zip(self.replicates.par_chunks_mut(chunk_len))
            .zip(self.photon_lists.par_iter_mut().zip(self.vertex_lists.par_iter_mut()))
            .zip(aux_chunks(&mut self.aux_camera, channels, count, chunk_len))
            .enumerate();
        exec.run(chunks)
            .map(|(chunk, (((values, replicate), (photons, vertices)), mut aux))| {
                photons.clear();
                vertices.clear();
                // A phase cut at a deadline long before its end is left out whole rather than finished late.
                if abandon.is_some_and(|a| a.load(Ordering::Relaxed)) {
                    return BackwardStats { abandoned_chunks: 1, ..BackwardStats::default() };
                }
                // A camera path stores at most one photon per diffuse vertex it continues from: at full size
                // from the first phase, a list never grows, and holds what `--memory-limit` assumed.
                photons.reserve_exact(values.len() * bdd as usize);
                let mut stats = BackwardStats::default();
                let mut log = RecordedPath::new(PathKind::Camera, 0, 0, 0);
                for (i, out) in values.iter_mut().enumerate() {
                    let local = chunk * chunk_len + i;
                    let pixel = pixels.map_or(local as u32, |p| p[local]);
                    let super::PixelPhase { radius: radius_j, sample: j } = next_phase(local);
                    replicate[i] = replicate_of(j).0 as u8;
                    let bs = BackwardSettings {
                        max_depth: phase.max_depth,
                        backward_diffuse_depth: bdd,
                        radius: phase.radius,
                        phase: radius_j,
                        spectrum: phase.spectrum,
                        sensor_ghosts: phase.sensor_ghosts,
                    };
                    let (x, y) = (pixel % cam.width, pixel / cam.width);
                    let mut s = Sampler::camera(phase.seed, phase.key, pixel as u64, j);
                    let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
                    // A recorded camera path carries its pixel's radius j, which counts every process's phases of the
                    // pixel (docs/ray-maps.md, "Phase numbers"): two processes never give one pixel the same number.
                    let kept = recorder.filter(|r| r.keeps(PathKind::Camera, radius_j, pixel as u64));
                    if kept.is_some() {
                        (log.phase, log.item, log.source) = (radius_j as u32, pixel, pixel);
                    }
                    let store = &mut PhotonLists { photons, vertices };
                    let (v, ghost) = match kept {
                        Some(_) => {
                            trace_camera_path(phase.scene, &bs, local as u32, ray, &mut s, &mut stats, store, &mut log)
                        }
                        None => {
                            let log = &mut Unrecorded;
                            trace_camera_path(phase.scene, &bs, local as u32, ray, &mut s, &mut stats, store, log)
                        }
                    };
                    if let Some(r) = kept {
                        r.record(&log);
                    }
                    *out = v;
                    if let Some(aux) = aux.as_deref_mut() {
                        start_aux(&mut aux[i * channels..(i + 1) * channels], ghost_offset, ghost);
                    }
                }
                stats
            })
            .reduce(BackwardStats::default, |a, b| a + b)
    }

    /// Stage 2: the photon map of the camera pass's photons, in pixel order, with the BSDFs of its
    /// non-Lambertian photons.
    pub fn build_map(&mut self, exec: Executor, map: &mut PhotonMap) {
        if self.vertex_lists.iter().any(|v| !v.is_empty()) {
            // A list's photons count their BSDFs within the list: the map holds all lists' one after another.
            let mut first = 0u32;
            for (photons, vertices) in self.photon_lists.iter_mut().zip(&self.vertex_lists) {
                if first > 0 {
                    photons.iter_mut().filter(|p| p.stored != LAMBERTIAN).for_each(|p| p.stored += first);
                }
                first += vertices.len() as u32;
            }
        }
        match (&mut self.photon_lists[..], self.single_list) {
            ([list], true) => map.build_from(std::mem::take(list), exec),
            (lists, _) => map.build_from_lists(lists, exec),
        }
        map.set_vertices(&self.vertex_lists);
    }

    /// Stage 4: closes the phase at every local pixel into `sums` and `aux_sums`, with the gathered light divided
    /// by the `light_paths` counted against the map, and leaves `gathered` zero for the next phase.
    pub fn close(
        &mut self,
        exec: Executor,
        phase: &Phase,
        gathered: &mut GatherBuffer,
        light_paths: u64,
        sums: &mut [PixelSums],
        aux_sums: &mut AuxSums,
    ) {
        let pixels = self.camera.len();
        let visible = gathered.visible_offset();
        let expected = 6 + self.aux.channels() + if visible.is_some() { 3 } else { 0 };
        assert_eq!((sums.len(), gathered.stride()), (pixels, expected), "closing other pixels");
        let stride = gathered.stride();
        let closing = Closing::new(light_paths, &self.aux, visible);
        let channels = self.aux.channels();
        let chunk_len = self.chunk;
        let chunks = self
            .camera
            .par_chunks(chunk_len)
            .zip(self.replicates.par_chunks(chunk_len))
            .zip(sums.par_chunks_mut(chunk_len))
            .zip(gathered.values_mut().par_chunks_mut(chunk_len * stride))
            .zip(aux_chunks(&mut self.aux_camera, channels, pixels, chunk_len))
            .zip(aux_chunks(aux_sums.values_mut(), channels, pixels, chunk_len))
            .enumerate();
        exec.run(chunks).for_each(|(chunk, (((((camera, replicates), sums), gathered), mut aux), mut aux_sums))| {
            for (i, ((value, &replicate), sums)) in camera.iter().zip(replicates).zip(sums).enumerate() {
                let local = chunk * chunk_len + i;
                let aux =
                    aux.as_deref_mut().map(|a| (&mut a[i * channels..(i + 1) * channels], phase.wavelength_of(local)));
                let aux_sums = aux_sums.as_deref_mut().map(|s| &mut s[i * channels..(i + 1) * channels]);
                let gathered = Some(&mut gathered[i * stride..(i + 1) * stride]);
                closing.close_pixel(value, replicate as usize, gathered, aux, sums, aux_sums);
            }
        });
    }
}

/// Starts a pixel's auxiliary values of the phase from its camera path: its ghost light in the ghost layer.
#[inline]
pub fn start_aux(aux: &mut [f32], ghost_offset: Option<usize>, ghost: Rgb) {
    aux.fill(0.0);
    if let Some(o) = ghost_offset {
        aux[o..o + 3].copy_from_slice(&[ghost.x, ghost.y, ghost.z]);
    }
}

/// How a phase closes at each pixel.
#[derive(Clone, Copy, Debug)]
pub struct Closing {
    /// One over the light paths counted against the map.
    pub inv_n: f32,
    /// Where the spectral-output bands lie among the auxiliary channels, and how many there are.
    pub bands: Option<(usize, usize)>,
    /// Where the visible light registered on the sensor lies among a pixel's gathered values, if anywhere.
    pub visible: Option<usize>,
    /// Where the blur difference D and its square lie among the auxiliary channels.
    pub blur: Option<(usize, usize)>,
}

impl Closing {
    /// Closing over `light_paths` light paths counted against the map, with the auxiliary layers `aux` and the
    /// sensor's visible light at `visible` among the gathered values.
    pub fn new(light_paths: u64, aux: &AuxLayout, visible: Option<usize>) -> Self {
        Closing { inv_n: 1.0 / light_paths.max(1) as f32, bands: aux.bands(), visible, blur: blur_offsets(aux) }
    }

    /// Closes one pixel: its phase value L_ij is the camera pass's `value` plus the `gathered` light over the
    /// light paths (step 4 above), counted in the pixel's `replicate`; the auxiliary channels (`aux`,
    /// started by `start_aux`, and the pixel's wavelength) get their gathered light too and the spectral bands
    /// of the phase total. Leaves `gathered` zero.
    #[inline]
    pub fn close_pixel(
        &self,
        value: &LayerValues,
        replicate: usize,
        gathered: Option<&mut [f32]>,
        aux: Option<(&mut [f32], Option<Wavelength>)>,
        sums: &mut PixelSums,
        aux_sums: Option<&mut [f64]>,
    ) {
        let mut v = *value;
        let mut gathered_aux: &[f32] = &[];
        if let Some(g) = gathered.as_deref() {
            v[Layer::Indirect as usize] += Rgb::new(g[0], g[1], g[2]) * self.inv_n;
            v[Layer::Caustic as usize] += Rgb::new(g[3], g[4], g[5]) * self.inv_n;
            if let Some(o) = self.visible {
                v[Layer::VisibleLights as usize] += Rgb::new(g[o], g[o + 1], g[o + 2]) * self.inv_n;
            }
            gathered_aux = &g[6..self.visible.unwrap_or(g.len())];
        }
        sums.add_phase(&v, 1, replicate);
        if let (Some((aux, wavelength)), Some(aux_sums)) = (aux, aux_sums) {
            for (a, g) in aux.iter_mut().zip(gathered_aux) {
                *a += g * self.inv_n;
            }
            if let (Some((offset, n)), Some(w)) = (self.bands, wavelength) {
                band_values(v.iter().sum(), &w, &mut aux[offset..offset + n]);
            }
            if let Some((d, d2)) = self.blur {
                aux[d2] = aux[d] * aux[d];
            }
            add_phase_to(aux_sums, aux);
        }
        if let Some(g) = gathered {
            g.fill(0.0);
        }
    }
}
