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

/// The fraction of a phase's light paths a stopped group still traces. A phase cut at fraction f has the
/// variance a + b / f per pixel (camera side a, light side b at f = 1). At 1/16, one cut phase in every round of
/// a one-group engine raised the variance per phase by 4% on `cornell`, where b is about a twentieth of a
/// (`--light-paths-per-pixel` 0.5, 1 and 2 on one thread), and made one-thread parallel runs of the HUD, where
/// b dominates, lose to `pbpm`.
const STOP_FRACTION: f64 = 0.25;

/// Mask pixels per photon list of the backward pass: a unit of work for the group's threads.
const PHOTON_CHUNK: usize = 256;

/// The map data a group shares through its slot: the photon map, the luminance gathered into it, and the
/// phase's light-path quota with the indices the owner has claimed towards it.
#[derive(Default)]
pub struct GroupMap {
    pub photons: PhotonMap,
    pub gathered: GatherBuffer,
    /// Light paths the phase needs counted against the map, the owner's and other groups' together.
    quota: u64,
    /// Light-path indices the owning group has handed to its threads this phase.
    claimed: AtomicU64,
}

impl GroupMap {
    /// Readies the quota for a new phase (owner, map closed).
    fn start_phase(&mut self, quota: u64) {
        self.quota = quota;
        *self.claimed.get_mut() = 0;
    }

    /// Light paths the map still lacks, given the `foreign` paths other groups counted against it so far.
    fn lacking(&self, foreign: u64) -> u64 {
        self.quota.saturating_sub(self.claimed.load(Ordering::Relaxed) + foreign)
    }

    /// Claims the next indices towards the quota, at most `n` (owner's threads): None once the owner's claims
    /// and the `foreign` paths meet it.
    fn claim_towards_quota(&self, n: u64, foreign: u64) -> Option<(u64, u64)> {
        let mut first = self.claimed.load(Ordering::Relaxed);
        loop {
            let count = n.min(self.quota.checked_sub(first + foreign).filter(|&left| left > 0)?);
            match self.claimed.compare_exchange_weak(first, first + count, Ordering::Relaxed, Ordering::Relaxed) {
                Ok(_) => return Some((first, count)),
                Err(now) => first = now,
            }
        }
    }

    /// Claims `n` indices beyond the quota (owner's threads): paths that help other maps, or that the owner
    /// traces while it waits to close.
    fn claim_beyond_quota(&self, n: u64) -> u64 {
        self.claimed.fetch_add(n, Ordering::Relaxed)
    }
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

/// What one thread's share of a forward pass counted.
#[derive(Default)]
struct ForwardTally {
    stats: ForwardStats,
    traced: u64,
    own_merges: u64,
    foreign: u64,
}

impl ForwardTally {
    fn add(self, other: Self) -> Self {
        ForwardTally {
            stats: self.stats + other.stats,
            traced: self.traced + other.traced,
            own_merges: self.own_merges + other.own_merges,
            foreign: self.foreign + other.foreign,
        }
    }
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
    /// The backward pass's photons, one list per `PHOTON_CHUNK` mask pixels, copied into the map each phase.
    photon_lists: Vec<Vec<BackwardPhoton>>,
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
            photon_lists: Vec::new(),
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
            + self.photon_lists.iter().map(Vec::capacity).sum::<usize>() * std::mem::size_of::<BackwardPhoton>()
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

        // 1. Backward pass over the mask, in parallel, each chunk of the mask into its own photon list, so that
        // the lists keep their buffers from phase to phase and the photons their pixel order.
        let t0 = Instant::now();
        self.photon_lists.resize_with(self.mask.len().div_ceil(PHOTON_CHUNK), Vec::new);
        let (phases_before, sums) = (&self.phases_before, &self.sums);
        let backward_rays: u64 = self
            .mask
            .par_chunks(PHOTON_CHUNK)
            .zip(self.backward.par_chunks_mut(PHOTON_CHUNK))
            .zip(self.photon_lists.par_iter_mut())
            .zip(aux_chunks(&mut self.aux_backward, aux_channels, PHOTON_CHUNK, self.mask.len()))
            .enumerate()
            .map(|(chunk, (((pixels, values), photons), mut aux))| {
                photons.clear();
                // A camera path stores at most one photon per diffuse vertex it continues from: at full size
                // from the first phase, a list never grows, and holds what `--memory-limit` assumed.
                photons.reserve_exact(pixels.len() * bdd as usize);
                let mut st = BackwardStats::default();
                for (i, (&pixel, out)) in pixels.iter().zip(values.iter_mut()).enumerate() {
                    let local = chunk * PHOTON_CHUNK + i;
                    let bs = BackwardSettings {
                        max_depth,
                        backward_diffuse_depth: bdd,
                        radius,
                        // Phases of this pixel by every group so far, assuming sharers progress alike.
                        phase: (phases_before[local] as u64 + sums[local].phases as u64 * sharers + index)
                            * ctx.process_sharers
                            + ctx.process_index
                            + ctx.phase_offset
                            + 1,
                        spectrum,
                    };
                    let (x, y) = (pixel % cam.width, pixel / cam.width);
                    let mut s = Sampler::new(settings.seed, Pass::Camera, key, pixel as u64);
                    let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
                    let (v, ghost) =
                        trace_camera_path(scene, &bs, local as u32, ray, &mut s, &mut st, &mut |b| photons.push(b));
                    *out = v;
                    if let Some(aux) = aux.as_deref_mut() {
                        let aux = &mut aux[i * aux_channels..(i + 1) * aux_channels];
                        aux.fill(0.0);
                        if let Some(o) = ghost_offset {
                            aux[o..o + 3].copy_from_slice(&[ghost.x, ghost.y, ghost.z]);
                        }
                    }
                }
                st.rays
            })
            .sum();
        self.stats.backward_rays += backward_rays;
        self.stats.backward_photons += self.photon_lists.iter().map(|l| l.len() as u64).sum::<u64>();

        // 2. Build the map while it is closed. The phase's quota counts every light path traced against the map,
        // its own group's and the other groups' (paper §4.2): a light path that gathers into several open maps
        // serves each of them, so a group whose map others trace against needs fewer paths of its own for the
        // same light per pixel.
        self.stats.nanos.backward += nanos_since(t0);
        let required = settings.light_paths_per_phase(self.mask.len());
        let t0 = Instant::now();
        let slot = &ctx.slots[self.index];
        {
            let data = slot.data_mut(&mut self.token);
            data.photons.copy_from_lists(&self.photon_lists);
            data.photons.build_parallel();
            data.gathered.reset(self.mask.len(), &self.aux);
            data.start_phase(required);
        }
        self.stats.nanos.build += nanos_since(t0);

        // 3. Forward pass with the map open to every group.
        let t0 = Instant::now();
        slot.open(&self.token);
        // A stop is honoured once `minimum` paths are counted: a phase cut shorter has too few light paths for
        // its camera paths, and its gathered light's variance grows as 1 / paths (see STOP_FRACTION).
        let minimum = ((required as f64 * STOP_FRACTION) as u64).max(1);
        let own = slot.owner_data(&self.token);
        // Light paths are traced in batches: foreign maps are acquired once per batch and each batch's paths
        // are counted in them at once, so the counters' cache lines move between cores once per batch, not per
        // path. The group's own tallies stay with each thread until the pass ends, and `guards` and `merges`
        // are per-thread scratch, reused from batch to batch. Returns whether the stop cut the batch short and
        // whether a foreign map it served still lacks light.
        let trace_batch = |first: u64,
                           count: u64,
                           stop_from: u64,
                           closing: bool,
                           guards: &mut Vec<Guard<'c, GroupMap>>,
                           merges: &mut Vec<u64>,
                           tally: &mut ForwardTally| {
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
            let mut done = 0;
            for index in first..first + count {
                if index >= stop_from && ctx.stop.load(Ordering::Relaxed) {
                    break;
                }
                let mut s = Sampler::new(settings.seed, Pass::Light, key, index);
                trace_light_path(scene, max_depth, &spectrum, index, &mut s, &mut tally.stats, &mut |v| {
                    merges[0] += gather(&own.photons, v, max_depth, bdd, &mut own.gathered.sink());
                    for (g, m) in guards.iter().zip(merges[1..].iter_mut()) {
                        *m += gather(&g.data().photons, v, max_depth, bdd, &mut g.data().gathered.sink());
                    }
                });
                done += 1;
            }
            for (g, &m) in guards.iter().zip(&merges[1..]) {
                g.data().gathered.add_merges(m);
                g.count_light_paths(done);
            }
            let others_lack = guards.iter().any(|g| g.data().lacking(g.light_paths()) > 0);
            tally.own_merges += merges[0];
            tally.foreign += guards.len() as u64 * done;
            tally.traced += done;
            guards.clear();
            (done < count, others_lack)
        };
        // Every thread of the group claims batches of path indices until the paths counted against the map
        // (its own claims plus the other groups' paths, which the slot counts as they come) meet the quota.
        // Without foreign paths this traces indices 0..required, whatever the thread count. Then, while another
        // group's open map still lacks light, the threads help it: a path traced now fills that quota faster,
        // costs no more thread time than the owner tracing it alone, and adds light to this phase too.
        // Groups then leave their forward passes together, so their next forward passes overlap again instead
        // of drifting apart by the differences in their backward passes.
        let mut tally = rayon::broadcast(|_| {
            let (mut guards, mut merges, mut tally) = (Vec::new(), Vec::new(), ForwardTally::default());
            let mut others_lack = false;
            loop {
                let foreign = slot.light_paths();
                let (first, count, stop_from) = match own.claim_towards_quota(BATCH, foreign) {
                    Some((first, count)) => (first, count, minimum.saturating_sub(foreign)),
                    None if others_lack && !ctx.stop.load(Ordering::Relaxed) => {
                        (own.claim_beyond_quota(BATCH), BATCH, 0)
                    }
                    None => break,
                };
                let cut;
                (cut, others_lack) = trace_batch(first, count, stop_from, false, &mut guards, &mut merges, &mut tally);
                if cut {
                    break;
                }
            }
            tally
        })
        .into_iter()
        .fold(ForwardTally::default(), ForwardTally::add);
        self.stats.nanos.forward += nanos_since(t0);
        let t0 = Instant::now();
        // Keep tracing useful paths until no other group is inside the map (paper Fig. 9).
        let (mut guards, mut merges) = (Vec::new(), Vec::new());
        while !slot.try_close(&self.token) {
            trace_batch(own.claim_beyond_quota(1), 1, u64::MAX, true, &mut guards, &mut merges, &mut tally);
        }
        own.gathered.add_merges(tally.own_merges);
        let traced = tally.traced;
        slot.count_owner_paths(&self.token, traced);
        self.stats.light_paths += traced;
        self.stats.forward_rays += tally.stats.rays;
        self.stats.capped_light_paths += tally.stats.capped;
        self.stats.foreign_acquisitions += tally.foreign;

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
        data.gathered.clear_parallel();
        self.stats.nanos.closing += nanos_since(t0);
        self.stats.phases += 1;
    }
}

/// The auxiliary values of each chunk of `chunk` pixels (`pixels` of them, `channels` values each), or None for
/// every chunk when there are no channels: an image without auxiliary layers iterates as it did without them.
fn aux_chunks(
    buffer: &mut [f32],
    channels: usize,
    chunk: usize,
    pixels: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [f32]>> {
    if channels == 0 {
        Either::Right((0..pixels.div_ceil(chunk)).into_par_iter().map(|_| None))
    } else {
        Either::Left(buffer.par_chunks_mut(chunk * channels).map(Some))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn claims_hand_out_every_index_once_until_own_and_foreign_paths_meet_the_quota() {
        let mut map = GroupMap::default();
        map.start_phase(100);
        assert_eq!(map.lacking(0), 100);
        let foreign = 10;
        let claims: Vec<(u64, u64)> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|_| s.spawn(|| std::iter::from_fn(|| map.claim_towards_quota(16, foreign)).collect::<Vec<_>>()))
                .collect();
            handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
        });
        let mut indices: Vec<u64> = claims.iter().flat_map(|&(first, n)| first..first + n).collect();
        indices.sort_unstable();
        assert_eq!(indices, (0..90).collect::<Vec<_>>(), "each index once, 90 own + 10 foreign = the quota");
        assert!(claims.iter().all(|&(_, n)| (1..=16).contains(&n)));
        assert_eq!(map.lacking(foreign), 0);
        // Helping and closing paths take fresh indices beyond the quota.
        assert_eq!(map.claim_beyond_quota(16), 90);
        assert_eq!(map.claim_beyond_quota(1), 106);
        // More foreign paths than the quota: the owner claims none, and the next phase starts afresh.
        map.start_phase(50);
        assert_eq!(map.claim_towards_quota(16, 60), None);
        assert_eq!(map.claim_towards_quota(16, 40), Some((0, 10)));
    }
}
