//! A synchronous group (level 1, DESIGN §2.1): g threads pinned to cores of one node, cooperating on every stage
//! of a phase over the group's mask, with rayon's joins as the barriers between stages.

use crate::atomic_image::GatherBuffer;
use crate::map_slot::{Guard, MapSlot, OwnerToken};
use photonfarm::accumulation::{auxiliary::add_phase_to, AuxLayout, AuxSums, PixelSums};
use photonfarm::color::Rgb;
use photonfarm::integrator::{Layer, LayerValues};
use photonfarm::pbpm::backward_pass::BackwardStats;
use photonfarm::pbpm::{
    gather, trace_camera_path, trace_light_path, BackwardPhoton, BackwardSettings, ForwardStats, PhotonMap,
};
use photonfarm::render::RenderSettings;
use photonfarm::sampling::{Pass, Sampler};
use photonfarm::scene::Scene;
use photonfarm::spectrum::{band_values, PhaseSpectrum};
use rayon::iter::Either;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Light paths traced per acquisition of the other groups' maps.
const BATCH: u64 = 16;

/// The map data a group shares through its slot: the photon map and the luminance gathered into it.
#[derive(Default)]
pub struct GroupMap {
    pub photons: PhotonMap,
    pub gathered: GatherBuffer,
}

/// Counters of one group.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GroupStats {
    pub phases: u64,
    pub backward_rays: u64,
    pub forward_rays: u64,
    /// Light paths this group traced.
    pub light_paths: u64,
    /// Light paths counted by this group's maps (its own and other groups' paths).
    pub light_paths_counted: u64,
    /// Foreign maps this group's light paths were traced against.
    pub foreign_acquisitions: u64,
    /// Merges recorded in this group's maps (by any group).
    pub merges: u64,
    pub backward_photons: u64,
    pub capped_light_paths: u64,
    /// Wall nanoseconds of the group in each stage (multiply by the group's threads for thread-time).
    pub nanos: StageNanos,
}

/// Wall nanoseconds a group spent per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageNanos {
    pub backward: u64,
    pub build: u64,
    pub forward: u64,
    pub closing: u64,
}

fn nanos_since(t: Instant) -> u64 {
    t.elapsed().as_nanos() as u64
}

/// What every group of a round shares.
pub struct RoundContext<'a> {
    pub scene: &'a Scene,
    pub settings: &'a RenderSettings,
    pub slots: &'a [MapSlot<GroupMap>],
    pub shared_maps: bool,
    pub stop: &'a AtomicBool,
    pub deal: u64,
    /// Processes rendering the same pixels (three-level, combination) and this one's index among them: the
    /// radius schedule counts their phases too, assuming they progress alike.
    pub process_sharers: u64,
    pub process_index: u64,
    /// Phases every pixel had before this run (a resumed run).
    pub phase_offset: u64,
}

/// One synchronous group and its buffers over its current mask.
pub struct Group {
    pub index: usize,
    pool: Arc<rayon::ThreadPool>,
    pinned: Arc<AtomicUsize>,
    token: OwnerToken,
    mask: Vec<u32>,
    /// Phases each pixel of the mask had before this deal (the radius schedule's j).
    phases_before: Vec<u32>,
    backward: Vec<LayerValues>,
    sums: Vec<PixelSums>,
    /// The image's auxiliary layers, where the ghost layer's channels start among them, the phase's auxiliary
    /// values from the camera pass (channels per mask pixel; empty without auxiliary layers) and their sums.
    aux: AuxLayout,
    ghost: Option<usize>,
    aux_backward: Vec<f32>,
    aux_sums: AuxSums,
    phases_this_deal: u64,
    /// Groups that render the same pixels in a deal (all of them without masks): the radius schedule counts
    /// their phases too, so that j tracks the pixel's total phase count as in a single-threaded run.
    pixel_sharers: u32,
    pub stats: GroupStats,
}

impl Group {
    /// A group of `cores.len()` threads, thread t pinned to `cores[t]`, keeping the auxiliary layers of `aux`.
    pub fn new(
        index: usize,
        cores: Vec<usize>,
        token: OwnerToken,
        aux: AuxLayout,
    ) -> Result<Self, rayon::ThreadPoolBuildError> {
        let pinned = Arc::new(AtomicUsize::new(0));
        let pin_count = pinned.clone();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(cores.len())
            .thread_name(move |t| format!("group{index}-t{t}"))
            .start_handler(move |t| {
                if core_affinity::set_for_current(core_affinity::CoreId { id: cores[t] }) {
                    pin_count.fetch_add(1, Ordering::Relaxed);
                }
            })
            .build()?;
        Ok(Group {
            index,
            pool: Arc::new(pool),
            pinned,
            token,
            mask: Vec::new(),
            phases_before: Vec::new(),
            backward: Vec::new(),
            sums: Vec::new(),
            ghost: aux.offset(photonfarm::ghost::GHOST_LAYER),
            aux_backward: Vec::new(),
            aux_sums: AuxSums::new(aux.clone(), 0),
            aux,
            phases_this_deal: 0,
            pixel_sharers: 1,
            stats: GroupStats::default(),
        })
    }

    /// Threads whose pinning the OS accepted.
    pub fn pinned_threads(&self) -> usize {
        self.pinned.load(Ordering::Relaxed)
    }

    /// The current mask.
    pub fn mask(&self) -> &[u32] {
        &self.mask
    }

    /// The sums of the current deal, per mask pixel.
    pub fn local_sums(&self) -> &[PixelSums] {
        &self.sums
    }

    /// The auxiliary layers' sums of the current deal, per mask pixel.
    pub fn local_aux(&self) -> &AuxSums {
        &self.aux_sums
    }

    /// Bytes of the group's buffers, including its map slot.
    pub fn capacity_bytes(&mut self, slot: &MapSlot<GroupMap>) -> usize {
        let own = self.mask.capacity() * 4
            + self.phases_before.capacity() * 4
            + self.backward.capacity() * std::mem::size_of::<LayerValues>()
            + self.sums.capacity() * std::mem::size_of::<PixelSums>()
            + self.aux_backward.capacity() * 4
            + self.aux_sums.capacity_bytes();
        // Asked between rounds, when every map is closed.
        let data = slot.data_mut(&mut self.token);
        own + data.photons.capacity_bytes() + data.gathered.capacity_bytes()
    }

    /// Takes a new mask for the next deal; `phases_before[i]` is how many phases mask pixel i already had.
    pub fn start_deal(&mut self, mask: Vec<u32>, phases_before: Vec<u32>, pixel_sharers: u32) {
        self.pixel_sharers = pixel_sharers.max(1);
        self.backward.clear();
        self.backward.resize(mask.len(), [Rgb::ZERO; 4]);
        self.sums.clear();
        self.sums.resize(mask.len(), PixelSums::default());
        self.aux_backward.clear();
        self.aux_backward.resize(mask.len() * self.aux.channels(), 0.0);
        self.aux_sums.reset(mask.len());
        self.mask = mask;
        self.phases_before = phases_before;
        self.phases_this_deal = 0;
    }

    /// Runs phases until the round's stop flag is set; reports on `done` when it has finished
    /// `phases_per_deal` phases, the signal for the main thread to stop every group.
    pub fn run_round(&mut self, ctx: &RoundContext, phases_per_deal: u64, done: &std::sync::mpsc::Sender<usize>) {
        if self.mask.is_empty() {
            // More groups than tiles: nothing to render this deal.
            while !ctx.stop.load(Ordering::Acquire) {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            return;
        }
        let pool = self.pool.clone();
        pool.install(|| {
            while !ctx.stop.load(Ordering::Acquire) {
                self.run_phase(ctx);
                self.phases_this_deal += 1;
                if self.phases_this_deal == phases_per_deal {
                    let _ = done.send(self.index);
                }
            }
        });
    }

    fn phase_key(&self, deal: u64) -> u64 {
        (deal << 32) | ((self.index as u64) << 20) | self.phases_this_deal
    }

    /// One phase over the mask: backward pass, map build, forward pass with the map open, close.
    fn run_phase<'c>(&mut self, ctx: &RoundContext<'c>) {
        let scene = ctx.scene;
        let settings = ctx.settings;
        let key = self.phase_key(ctx.deal);
        let cam = &scene.camera;
        let radius = settings.radius_schedule(scene);
        let (max_depth, bdd) = (settings.max_depth, settings.backward_diffuse_depth);
        let sharers = self.pixel_sharers as u64;
        let index = if sharers > 1 { self.index as u64 } else { 0 };
        // Wavelengths per group phase: its camera and light paths join only among themselves.
        let spectrum = settings.phase_spectrum(scene, key);
        let (aux_channels, ghost_offset) = (self.aux.channels(), self.ghost);

        // 1. Backward pass over the mask, in parallel.
        let t0 = Instant::now();
        let (photons, backward_rays) = self
            .mask
            .par_iter()
            .zip(self.backward.par_iter_mut())
            .zip(self.sums.par_iter().zip(self.phases_before.par_iter()))
            .zip(aux_slots(&mut self.aux_backward, aux_channels, self.mask.len()))
            .enumerate()
            .fold(
                || (Vec::<BackwardPhoton>::new(), 0u64),
                |(mut photons, rays), (local, (((&pixel, out), (sums, &before)), aux))| {
                    let bs = BackwardSettings {
                        max_depth,
                        backward_diffuse_depth: bdd,
                        radius,
                        // Phases of this pixel by every group so far, assuming sharers progress alike.
                        phase: (before as u64 + sums.phases as u64 * sharers + index) * ctx.process_sharers
                            + ctx.process_index
                            + ctx.phase_offset
                            + 1,
                        spectrum,
                    };
                    let (x, y) = (pixel % cam.width, pixel / cam.width);
                    let mut s = Sampler::new(settings.seed, Pass::Camera, key, pixel as u64);
                    let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
                    let mut st = BackwardStats::default();
                    let (values, ghost) =
                        trace_camera_path(scene, &bs, local as u32, ray, &mut s, &mut st, &mut |b| photons.push(b));
                    *out = values;
                    if let Some(aux) = aux {
                        aux.fill(0.0);
                        if let Some(o) = ghost_offset {
                            aux[o..o + 3].copy_from_slice(&[ghost.x, ghost.y, ghost.z]);
                        }
                    }
                    (photons, rays + st.rays)
                },
            )
            .reduce(
                || (Vec::new(), 0),
                |(mut a, ra), (mut b, rb)| {
                    a.append(&mut b);
                    (a, ra + rb)
                },
            );
        self.stats.backward_rays += backward_rays;
        self.stats.backward_photons += photons.len() as u64;

        // 2. Build the map while it is closed.
        self.stats.nanos.backward += nanos_since(t0);
        let t0 = Instant::now();
        let slot = &ctx.slots[self.index];
        {
            let data = slot.data_mut(&mut self.token);
            data.photons.clear();
            data.photons.extend(&photons);
            // The parallel build costs a one-thread group 20–40% more than the sequential one (the
            // photon_map micro-benchmark): it splits the work into chunks and copies them back together.
            if self.pool.current_num_threads() > 1 {
                data.photons.build_parallel();
            } else {
                data.photons.build();
            }
            data.gathered.reset(self.mask.len(), &self.aux);
        }
        drop(photons);
        self.stats.nanos.build += nanos_since(t0);

        // 3. Forward pass with the map open to every group.
        let t0 = Instant::now();
        slot.open(&self.token);
        let required = settings.light_paths_per_phase(self.mask.len());
        // A stop is honoured once a sixteenth of the paths are traced, so no phase is closed on a handful.
        let minimum = (required / 16).max(1);
        let traced = AtomicU64::new(0);
        let forward_rays = AtomicU64::new(0);
        let capped = AtomicU64::new(0);
        let foreign = AtomicU64::new(0);
        let own = slot.owner_data(&self.token);
        // Light paths are traced in batches: foreign maps are acquired once per batch and each batch's paths
        // are counted in them at once, so the counters' cache lines move between cores once per batch, not per
        // path. `guards` and `merges` are per-thread scratch, reused from batch to batch.
        let trace_batch =
            |first: u64, count: u64, closing: bool, guards: &mut Vec<Guard<'c, GroupMap>>, merges: &mut Vec<u64>| {
                // While closing, the owner takes no other map: two closing owners never wait on each other.
                guards.clear();
                if ctx.shared_maps && !closing {
                    guards.extend(
                        ctx.slots
                            .iter()
                            .enumerate()
                            .filter(|&(k, _)| k != self.index)
                            .filter_map(|(_, sl)| sl.try_acquire()),
                    );
                }
                merges.clear();
                merges.resize(guards.len() + 1, 0);
                let mut fs = ForwardStats::default();
                let mut done = 0;
                for index in first..first + count {
                    if !closing && ctx.stop.load(Ordering::Relaxed) && traced.load(Ordering::Relaxed) + done >= minimum
                    {
                        break;
                    }
                    let mut s = Sampler::new(settings.seed, Pass::Light, key, index);
                    trace_light_path(scene, max_depth, &spectrum, index, &mut s, &mut fs, &mut |v| {
                        merges[0] += gather(&own.photons, v, max_depth, bdd, &mut own.gathered.sink());
                        for (g, m) in guards.iter().zip(merges[1..].iter_mut()) {
                            *m += gather(&g.data().photons, v, max_depth, bdd, &mut g.data().gathered.sink());
                        }
                    });
                    done += 1;
                }
                own.gathered.add_merges(merges[0]);
                for (g, &m) in guards.iter().zip(&merges[1..]) {
                    g.data().gathered.add_merges(m);
                    g.count_light_paths(done);
                }
                foreign.fetch_add(guards.len() as u64 * done, Ordering::Relaxed);
                forward_rays.fetch_add(fs.rays, Ordering::Relaxed);
                capped.fetch_add(fs.capped, Ordering::Relaxed);
                traced.fetch_add(done, Ordering::Relaxed);
                guards.clear();
            };
        let batches = required.div_ceil(BATCH);
        (0..batches as usize).into_par_iter().for_each_init(
            || (Vec::new(), Vec::new()),
            |(guards, merges), b| {
                let first = b as u64 * BATCH;
                trace_batch(first, BATCH.min(required - first), false, guards, merges);
            },
        );
        self.stats.nanos.forward += nanos_since(t0);
        let t0 = Instant::now();
        // Keep tracing useful paths until no other group is inside the map (paper Fig. 9).
        let mut extra = required;
        let (mut guards, mut merges) = (Vec::new(), Vec::new());
        while !slot.try_close(&self.token) {
            trace_batch(extra, 1, true, &mut guards, &mut merges);
            extra += 1;
        }
        let traced = traced.into_inner();
        slot.count_owner_paths(&self.token, traced);
        self.stats.light_paths += traced;
        self.stats.forward_rays += forward_rays.into_inner();
        self.stats.capped_light_paths += capped.into_inner();
        self.stats.foreign_acquisitions += foreign.into_inner();

        // 4. Close the phase: gathered luminance normalised by every light path traced against the map.
        let counted = slot.light_paths();
        self.stats.light_paths_counted += counted;
        let data = slot.data_mut(&mut self.token);
        self.stats.merges += data.gathered.merges();
        let inv_n = 1.0 / counted as f32;
        let gathered = &data.gathered;
        self.backward.par_iter().zip(self.sums.par_iter_mut()).enumerate().for_each(|(i, (b, sums))| {
            let g = gathered.get(i);
            let mut v = *b;
            v[Layer::Indirect as usize] += g[0] * inv_n;
            v[Layer::Caustic as usize] += g[1] * inv_n;
            sums.add_phase(&v, 1);
        });
        if aux_channels > 0 {
            let (bands, backward) = (self.aux.bands(), &self.backward);
            self.aux_backward
                .par_chunks_mut(aux_channels)
                .zip(self.aux_sums.values_mut().par_chunks_mut(aux_channels))
                .enumerate()
                .for_each(|(i, (b, sums))| {
                    for (c, v) in b.iter_mut().enumerate() {
                        *v += gathered.get_aux(i, c) * inv_n;
                    }
                    // Spectral output: the pixel's phase total was carried at its class's wavelength (the
                    // backward pass dealt classes by mask index).
                    if let (Some((offset, n)), Some(w)) =
                        (bands, spectrum.wavelength(PhaseSpectrum::class_of(i as u64)))
                    {
                        let g = gathered.get(i);
                        let total = backward[i].iter().sum::<Rgb>() + (g[0] + g[1]) * inv_n;
                        band_values(total, &w, &mut b[offset..offset + n]);
                    }
                    add_phase_to(sums, b);
                });
        }
        self.stats.nanos.closing += nanos_since(t0);
        self.stats.phases += 1;
    }
}

/// One slot of `channels` values of `buffer` per pixel (`pixels` of them), or None for every pixel when there
/// are no channels: an image without auxiliary layers iterates as it did without them.
fn aux_slots(
    buffer: &mut [f32],
    channels: usize,
    pixels: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [f32]>> {
    if channels == 0 {
        Either::Right((0..pixels).into_par_iter().map(|_| None))
    } else {
        Either::Left(buffer.par_chunks_mut(channels).map(Some))
    }
}
