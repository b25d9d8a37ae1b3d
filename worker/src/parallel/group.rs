//! A synchronous group (level 1, DESIGN §2.1): g threads pinned to cores of one node, cooperating on every stage
//! of a phase over the group's mask, with rayon's joins as the barriers between stages.

use super::map_slot::{Guard, MapSlot, OwnerToken};
use photonfarm::accumulation::AuxLayout;
use photonfarm::accumulation::{AuxSums, PixelSums};
use photonfarm::color::Rgb;
use photonfarm::integrator::Layer;
use photonfarm::pbpm::{
    AtomicGatherBuffer, AtomicSink, Executor, ForwardStats, Gather, GatherBuffer, LocalPixels, Phase, PhaseBuffers,
    PhaseNumbering, PhotonMap,
};
use photonfarm::render::RenderSettings;
use photonfarm::scene::Scene;
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

/// The map data a group shares through its slot: the photon map, the light gathered into it from several
/// threads, and the phase's light-path quota with the indices the owner has claimed towards it.
#[derive(Default)]
pub struct GroupMap {
    pub photons: PhotonMap,
    /// Light gathered by other groups' paths, and by the group's own paths when it has several threads; the
    /// owner's paths of a one-thread group add into its plain buffer instead, without atomics.
    pub shared: AtomicGatherBuffer,
    /// Which local pixel of the owner's phase an image pixel is, for light paths registering on the sensor.
    pub pixels: LocalPixels,
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
    /// Two groups of one thread each: the other group's thread is the only one adding into a group's open map,
    /// so it adds without compare-and-swap.
    pub sole_foreign_writer: bool,
    pub stop: &'a AtomicBool,
    pub deal: u64,
    /// Pixels the round renders over all groups (every pixel unless tiles retired): the light-path quota is
    /// L per rendered pixel.
    pub rendered_pixels: usize,
    /// The processes rendering the same pixels and the phases before this run, for the radius schedule (each
    /// group adds the groups of its deal).
    pub numbering: PhaseNumbering,
}

/// Where a group's own light paths add their gathered light.
enum OwnSink<'a> {
    /// The group's plain buffer: one thread traces all its paths.
    Plain(&'a mut GatherBuffer),
    /// The map's atomic buffer: several threads trace them.
    Shared(AtomicSink<'a>),
}

impl Gather for OwnSink<'_> {
    #[inline]
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb) {
        match self {
            OwnSink::Plain(b) => b.add(pixel, layer, ghost, value),
            OwnSink::Shared(s) => s.add(pixel, layer, ghost, value),
        }
    }
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
    buffers: PhaseBuffers,
    /// Light gathered by the group's own paths when it has one thread, and where the phase closes from.
    gathered: GatherBuffer,
    sums: Vec<PixelSums>,
    aux_sums: AuxSums,
    phases_this_deal: u64,
    /// Groups that render the same pixels in a deal (all of them without masks): the radius schedule counts
    /// their phases too, so that j tracks the pixel's total phase count as in a single-threaded run.
    groups_per_pixel: u32,
    /// The mask changed since the map's `pixels` lookup was made.
    new_mask: bool,
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
        // A thread runs its start handler before any work: once every thread has run one task, the pinned count
        // is final, and the run record does not report threads as unpinned that were only not started yet.
        pool.broadcast(|_| ());
        Ok(Group {
            index,
            pool: Arc::new(pool),
            pinned,
            token,
            mask: Vec::new(),
            phases_before: Vec::new(),
            buffers: PhaseBuffers::new(aux.clone(), Executor::CurrentPool),
            gathered: GatherBuffer::default(),
            sums: Vec::new(),
            aux_sums: AuxSums::new(aux, 0),
            phases_this_deal: 0,
            groups_per_pixel: 1,
            new_mask: true,
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
            + self.buffers.capacity_bytes()
            + self.gathered.capacity_bytes()
            + self.sums.capacity() * std::mem::size_of::<PixelSums>()
            + self.aux_sums.capacity_bytes();
        // Asked between rounds, when every map is closed.
        let data = slot.data_mut(&mut self.token);
        own + data.photons.capacity_bytes() + data.shared.capacity_bytes() + data.pixels.capacity_bytes()
    }

    /// Takes a new mask for the next deal; `phases_before[i]` is how many phases mask pixel i already had.
    pub fn start_deal(&mut self, mask: Vec<u32>, phases_before: Vec<u32>, groups_per_pixel: u32) {
        self.groups_per_pixel = groups_per_pixel.max(1);
        self.buffers.resize(mask.len());
        self.gathered.reset(mask.len(), self.buffers.aux());
        self.sums.clear();
        self.sums.resize(mask.len(), PixelSums::default());
        self.aux_sums.reset(mask.len());
        self.mask = mask;
        self.phases_before = phases_before;
        self.phases_this_deal = 0;
        self.new_mask = true;
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

    /// One phase over the mask (the stages of `pbpm::phase`), with the forward pass driven by the light-path
    /// quota, the other groups' open maps and the round's stop.
    fn run_phase(&mut self, ctx: &RoundContext) {
        let exec = Executor::CurrentPool;
        // Wavelengths per group phase: its camera and light paths join only among themselves.
        let phase = ctx.settings.phase(ctx.scene, self.phase_key(ctx.deal));
        let sharers = self.groups_per_pixel as u64;
        let numbering =
            PhaseNumbering { groups: sharers, group: if sharers > 1 { self.index as u64 } else { 0 }, ..ctx.numbering };

        // 1. Camera pass over the mask.
        let t0 = Instant::now();
        let slot = &ctx.slots[self.index];
        let (phases_before, sums) = (&self.phases_before, &self.sums);
        let next_phase = |local: usize| numbering.next_phase(phases_before[local] as u64, sums[local].phases as u64);
        let map = &mut slot.data_mut(&mut self.token).photons;
        let backward = self.buffers.camera_pass(exec, &phase, Some(&self.mask), next_phase, map);
        self.stats.backward_rays += backward.rays;
        self.stats.backward_photons += backward.photons;
        self.stats.nanos.backward += nanos_since(t0);

        // 2. Build the map while it is closed. The phase's quota counts every light path traced against the map,
        // its own group's and the other groups' (paper §4.2): a light path that gathers into several open maps
        // serves each of them, so a group whose map others trace against needs fewer paths of its own for the
        // same light per pixel. The quota is per pixel the round renders, not per mask pixel: light paths leave
        // the lights over the whole scene, so a pixel's gathered estimate has the variance of the map's
        // light-path count, and every method gives a pixel the same light at the same `light_paths_per_pixel`.
        // Where tiles retired, the round's light shrinks with its camera paths.
        let required = ctx.settings.light_paths_per_phase(ctx.rendered_pixels);
        let t0 = Instant::now();
        // One thread adds its own paths' light without atomics; several share the map's atomic buffer.
        let one_thread = rayon::current_num_threads() == 1;
        let uses_shared = ctx.shared_maps || !one_thread;
        {
            let data = slot.data_mut(&mut self.token);
            if std::mem::take(&mut self.new_mask) {
                data.pixels = LocalPixels::of_mask(&self.mask, ctx.scene.camera.pixel_count(), phase.sensor_ghosts);
            }
            self.buffers.build_map(exec, &mut data.photons);
            if uses_shared {
                data.shared.reset(self.mask.len(), self.buffers.aux());
            }
            data.start_phase(required);
        }
        self.stats.nanos.build += nanos_since(t0);

        // 3. Forward pass with the map open to every group.
        let t0 = Instant::now();
        let tally = self.forward_pass(ctx, &phase, required, one_thread);
        self.stats.nanos.forward += nanos_since(t0);
        let t0 = Instant::now();
        self.stats.light_paths += tally.traced;
        self.stats.forward_rays += tally.stats.rays;
        self.stats.capped_light_paths += tally.stats.capped;
        self.stats.foreign_acquisitions += tally.foreign;

        // 4. Close the phase: gathered luminance normalised by every light path traced against the map.
        let counted = slot.light_paths();
        self.stats.light_paths_counted += counted;
        let data = slot.data_mut(&mut self.token);
        self.stats.merges += tally.own_merges + data.shared.merges();
        if uses_shared {
            self.gathered.absorb(&mut data.shared);
        }
        self.buffers.close(exec, &phase, &mut self.gathered, counted, &mut self.sums, &mut self.aux_sums);
        self.stats.nanos.closing += nanos_since(t0);
        self.stats.phases += 1;
    }

    /// Stage 3 with the map open: traces the phase's light paths on the group's threads until the quota is met
    /// (and, while another group's map still lacks light, helps it), then keeps tracing until no other group is
    /// inside the map, and closes it.
    fn forward_pass<'c>(
        &mut self,
        ctx: &RoundContext<'c>,
        phase: &Phase,
        required: u64,
        one_thread: bool,
    ) -> ForwardTally {
        let me = self.index;
        let slot = &ctx.slots[me];
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
        let trace_batch = |batch: Batch,
                           sink: &mut OwnSink,
                           guards: &mut Vec<Guard<'c, GroupMap>>,
                           merges: &mut Vec<u64>,
                           tally: &mut ForwardTally| {
            // While closing, the owner takes no other map: two closing owners never wait on each other.
            guards.clear();
            if ctx.shared_maps && !batch.closing {
                guards.extend(
                    ctx.slots.iter().enumerate().filter(|&(k, _)| k != me).filter_map(|(_, sl)| sl.try_acquire()),
                );
            }
            merges.clear();
            merges.resize(guards.len() + 1, 0);
            let mut done = 0;
            for index in batch.first..batch.first + batch.count {
                if index >= batch.stop_from && ctx.stop.load(Ordering::Relaxed) {
                    break;
                }
                phase.trace_light_path(index, &mut tally.stats, &mut |v| {
                    merges[0] += phase.gather(&own.photons, &own.pixels, v, sink);
                    for (g, m) in guards.iter().zip(merges[1..].iter_mut()) {
                        let shared = &g.data().shared;
                        let mut sink = if ctx.sole_foreign_writer { shared.sole_writer_sink() } else { shared.sink() };
                        *m += phase.gather(&g.data().photons, &g.data().pixels, v, &mut sink);
                    }
                });
                done += 1;
            }
            for (g, &m) in guards.iter().zip(&merges[1..]) {
                g.data().shared.add_merges(m);
                g.count_light_paths(done);
            }
            let others_lack = guards.iter().any(|g| g.data().lacking(g.light_paths()) > 0);
            tally.own_merges += merges[0];
            tally.foreign += guards.len() as u64 * done;
            tally.traced += done;
            guards.clear();
            (done < batch.count, others_lack)
        };
        // Every thread of the group claims batches of path indices until the paths counted against the map
        // (its own claims plus the other groups' paths, which the slot counts as they come) meet the quota.
        // Without foreign paths this traces indices 0..required, whatever the thread count. Then, while another
        // group's open map still lacks light, the threads help it: a path traced now fills that quota faster,
        // costs no more thread time than the owner tracing it alone, and adds light to this phase too.
        // Groups then leave their forward passes together, so their next forward passes overlap again instead
        // of drifting apart by the differences in their backward passes.
        let thread_pass = |sink: &mut OwnSink| {
            let (mut guards, mut merges, mut tally) = (Vec::new(), Vec::new(), ForwardTally::default());
            let mut others_lack = false;
            loop {
                let foreign = slot.light_paths();
                let batch = match own.claim_towards_quota(BATCH, foreign) {
                    Some((first, count)) => {
                        Batch { first, count, stop_from: minimum.saturating_sub(foreign), closing: false }
                    }
                    None if others_lack && !ctx.stop.load(Ordering::Relaxed) => {
                        Batch { first: own.claim_beyond_quota(BATCH), count: BATCH, stop_from: 0, closing: false }
                    }
                    None => break,
                };
                let cut;
                (cut, others_lack) = trace_batch(batch, sink, &mut guards, &mut merges, &mut tally);
                if cut {
                    break;
                }
            }
            tally
        };
        let mut sink = if one_thread { OwnSink::Plain(&mut self.gathered) } else { OwnSink::Shared(own.shared.sink()) };
        let mut tally = if one_thread {
            thread_pass(&mut sink)
        } else {
            rayon::broadcast(|_| thread_pass(&mut OwnSink::Shared(own.shared.sink())))
                .into_iter()
                .fold(ForwardTally::default(), ForwardTally::add)
        };
        // Keep tracing useful paths until no other group is inside the map (paper Fig. 9).
        let (mut guards, mut merges) = (Vec::new(), Vec::new());
        while !slot.try_close(&self.token) {
            let batch = Batch { first: own.claim_beyond_quota(1), count: 1, stop_from: u64::MAX, closing: true };
            trace_batch(batch, &mut sink, &mut guards, &mut merges, &mut tally);
        }
        slot.count_owner_paths(&self.token, tally.traced);
        tally
    }
}

/// Light-path indices a thread traces in one go: `first..first + count`, of which those from `stop_from` on
/// give way to the round's stop; `closing` while the owner waits to close its map.
#[derive(Clone, Copy)]
struct Batch {
    first: u64,
    count: u64,
    stop_from: u64,
    closing: bool,
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

    #[test]
    fn a_new_groups_pinned_count_is_final_when_it_is_returned() {
        let cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
        // Whether this machine lets a thread pin itself at all, asked the same way the group's threads ask.
        let can_pin =
            std::thread::spawn(|| core_affinity::set_for_current(core_affinity::CoreId { id: 0 })).join().unwrap();
        let threads = cores.len().clamp(1, 2);
        for _ in 0..20 {
            let slot = MapSlot::new(GroupMap::default());
            let group = Group::new(0, vec![0; threads], slot.take_owner(), AuxLayout::default()).unwrap();
            assert_eq!(group.pinned_threads(), if can_pin { threads } else { 0 });
        }
    }
}
