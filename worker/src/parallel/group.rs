//! A synchronous group (level 1, docs/parallel-engine.md): g threads pinned to cores of one node, cooperating on every stage
//! of a phase over the group's mask, with rayon's joins as the barriers between stages.

use super::map_slot::{Guard, MapSlot, OwnerToken};
use super::thread_gathers::{batch_per_map, GatherRules, ThreadGathers};
use photonfarm::accumulation::AuxLayout;
use photonfarm::accumulation::{AuxSums, PixelSums};
use photonfarm::pbpm::{
    mean_phase, AtomicGatherBuffer, Executor, ForwardStats, LightEvent, LocalPixels, Phase, PhaseBuffers,
    PhaseNumbering, PhotonMap,
};
use photonfarm::ray_map::{PathKind, RecordedPath, Recorder};
use photonfarm::render::session::Deadline;
use photonfarm::render::RenderSettings;
use photonfarm::scene::Scene;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
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
    /// Light gathered by other groups' paths; the group's own paths add into its threads' plain buffers
    /// instead, without atomics.
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
    /// The round is over: a group stops after its current phase, once it has rendered one this round.
    pub stop: &'a AtomicBool,
    /// The user interrupted or the deadline passed: a group stops even before its first phase of the round.
    pub cut: &'a AtomicBool,
    /// The round has lasted long enough: a group finishes the phase under way (whole, its light paths not cut
    /// short) and starts no other, once it has rendered one this round.
    pub wind_down: &'a AtomicBool,
    /// A timed run's end: a group starts no phase that, lasting as long as its previous one, would end past it.
    pub deadline: Option<Deadline>,
    pub deal: u64,
    /// Pixels the round renders over all groups (every pixel unless tiles retired): the light-path quota is
    /// L per rendered pixel.
    pub rendered_pixels: usize,
    /// The processes rendering the same pixels, for the radius schedule (each group adds the groups of its
    /// deal).
    pub numbering: PhaseNumbering,
    /// Records the light paths it keeps into a ray map (the camera paths are recorded by each group's buffers).
    pub recorder: Option<&'a Recorder>,
}

/// A mask pixel's phases before a deal.
#[derive(Clone, Copy, Debug, Default)]
pub struct PhasesBefore {
    /// Over every process rendering the image (`ProcessShare::phases_before`).
    pub all: u32,
    /// This process's own.
    pub own: u32,
}

/// One synchronous group and its buffers over its current mask.
pub struct Group {
    pub index: usize,
    pool: Arc<rayon::ThreadPool>,
    pinned: Arc<AtomicUsize>,
    token: OwnerToken,
    mask: Vec<u32>,
    /// Phases each pixel of the mask had before this deal: over every process (the radius schedule's j), and
    /// this process's own (the point of its quasi-random sequences).
    phases_before: Vec<PhasesBefore>,
    buffers: PhaseBuffers,
    /// Each thread's plain buffer for the group's own paths and its held-back vertices, by the thread's index
    /// in the pool; the phase closes from thread 0's buffer once the others and the map's shared buffer are
    /// added into it. A thread locks its own entry once per forward pass, so the locks are never contended.
    threads: Vec<Mutex<ThreadGathers>>,
    sums: Vec<PixelSums>,
    aux_sums: AuxSums,
    phases_this_deal: u64,
    /// Groups that render the same pixels in a deal (all of them without masks): the radius schedule counts
    /// their phases too, so that j tracks the pixel's total phase count as in a single-threaded run.
    groups_per_pixel: u32,
    /// The mask changed since the map's `pixels` lookup was made.
    new_mask: bool,
    /// How long the group's latest phase took, to start none that would end past a timed run's deadline.
    last_phase: Option<std::time::Duration>,
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
        let threads = (0..cores.len().max(1)).map(|_| Mutex::default()).collect();
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
            threads,
            sums: Vec::new(),
            aux_sums: AuxSums::new(aux, 0),
            phases_this_deal: 0,
            groups_per_pixel: 1,
            new_mask: true,
            last_phase: None,
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

    /// Records the camera paths `recorder` keeps from the next camera pass on.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        self.buffers.set_recorder(recorder);
    }

    /// Bytes of the group's buffers, including its map slot.
    pub fn capacity_bytes(&mut self, slot: &MapSlot<GroupMap>) -> usize {
        let own = self.mask.capacity() * 4
            + self.phases_before.capacity() * std::mem::size_of::<PhasesBefore>()
            + self.buffers.capacity_bytes()
            + self.threads.iter_mut().map(|t| thread_mut(t).capacity_bytes()).sum::<usize>()
            + self.sums.capacity() * std::mem::size_of::<PixelSums>()
            + self.aux_sums.capacity_bytes();
        // Asked between rounds, when every map is closed.
        let data = slot.data_mut(&mut self.token);
        own + data.photons.capacity_bytes() + data.shared.capacity_bytes() + data.pixels.capacity_bytes()
    }

    /// Takes a new mask for the next deal; `phases_before[i]` is how many phases mask pixel i already had.
    pub fn start_deal(&mut self, mask: Vec<u32>, phases_before: Vec<PhasesBefore>, groups_per_pixel: u32) {
        self.groups_per_pixel = groups_per_pixel.max(1);
        self.buffers.resize(mask.len());
        for t in &mut self.threads {
            thread_mut(t).reset(mask.len(), self.buffers.aux());
        }
        self.sums.clear();
        self.sums.resize(mask.len(), PixelSums::default());
        self.aux_sums.reset(mask.len());
        self.mask = mask;
        self.phases_before = phases_before;
        self.phases_this_deal = 0;
        self.new_mask = true;
    }

    /// Runs phases until the round's stop flag is set; reports on `done` when it has finished
    /// `phases_per_deal` phases, the signal for the main thread to stop every group. A group renders at least
    /// one phase per round unless the round is cut: on a small mask another group can finish its phases before
    /// this group's thread is even scheduled, and the work would then fall to one group round after round.
    pub fn run_round(&mut self, ctx: &RoundContext, phases_per_deal: u64, done: &std::sync::mpsc::Sender<usize>) {
        if self.mask.is_empty() {
            // More groups than tiles: nothing to render this deal.
            while !ctx.stop.load(Ordering::Acquire) && !ctx.wind_down.load(Ordering::Acquire) {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            return;
        }
        let pool = self.pool.clone();
        pool.install(|| {
            let ended = || ctx.stop.load(Ordering::Acquire) || ctx.wind_down.load(Ordering::Acquire);
            while !ctx.cut.load(Ordering::Acquire) && (self.phases_this_deal == 0 || !ended()) {
                if let (Some(d), Some(last)) = (ctx.deadline, self.last_phase) {
                    if d.too_late_for(last) {
                        // Idle until the deadline cuts the round: a phase started now would end too late.
                        let wound_down = || self.phases_this_deal > 0 && ctx.wind_down.load(Ordering::Acquire);
                        while !ctx.cut.load(Ordering::Acquire) && !ctx.stop.load(Ordering::Acquire) && !wound_down() {
                            std::thread::sleep(std::time::Duration::from_millis(5));
                        }
                        break;
                    }
                }
                let started = Instant::now();
                if !self.run_phase(ctx) {
                    break;
                }
                self.last_phase = Some(started.elapsed());
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
    /// quota, the other groups' open maps and the round's stop; false when a cut left it out whole.
    fn run_phase(&mut self, ctx: &RoundContext) -> bool {
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
        let next_phase = |local: usize| {
            let before = phases_before[local];
            numbering.next_phase(before.all as u64, before.own as u64, sums[local].phases as u64)
        };
        // The phase's j for its ghost chains, and the phase number its recorded light paths carry (a camera
        // path carries its own pixel's radius j).
        let number = mean_phase(self.mask.len(), |i| next_phase(i).radius);
        let phase = phase.at_pixel_phase(number);
        let map = &mut slot.data_mut(&mut self.token).photons;
        let backward = self.buffers.camera_pass(exec, &phase, Some(&self.mask), next_phase, map, Some(ctx.cut));
        self.stats.backward_rays += backward.rays;
        self.stats.backward_photons += backward.photons;
        self.stats.nanos.backward += nanos_since(t0);
        if backward.abandoned_chunks > 0 {
            // Cut in its camera pass: the rest of the phase would take most of a phase past the deadline, and the
            // map was never opened, so leaving the phase out touches nothing another group holds.
            return false;
        }

        // 2. Build the map while it is closed. The phase's quota counts every light path traced against the map,
        // its own group's and the other groups' (paper §4.2): a light path that gathers into several open maps
        // serves each of them, so a group whose map others trace against needs fewer paths of its own for the
        // same light per pixel. The quota is per pixel the round renders, not per mask pixel: light paths leave
        // the lights over the whole scene, so a pixel's gathered estimate has the variance of the map's
        // light-path count, and every method gives a pixel the same light at the same `light_paths_per_pixel`.
        // Where tiles retired, the round's light shrinks with its camera paths.
        let required = ctx.settings.light_paths_per_phase(ctx.rendered_pixels);
        let t0 = Instant::now();
        {
            let data = slot.data_mut(&mut self.token);
            if std::mem::take(&mut self.new_mask) {
                data.pixels = LocalPixels::of_mask(&self.mask, ctx.scene.camera.pixel_count(), phase.sensor_ghosts);
            }
            self.buffers.build_map(exec, &mut data.photons);
            if ctx.shared_maps {
                data.shared.reset(self.mask.len(), self.buffers.aux());
            }
            data.start_phase(required);
        }
        self.stats.nanos.build += nanos_since(t0);

        // 3. Forward pass with the map open to every group.
        let t0 = Instant::now();
        let tally = self.forward_pass(ctx, &phase, required, number);
        self.stats.nanos.forward += nanos_since(t0);
        let t0 = Instant::now();
        self.stats.forward_rays += tally.stats.rays;
        self.stats.capped_light_paths += tally.stats.capped;
        self.stats.foreign_acquisitions += tally.foreign;

        // 4. Close the phase: gathered luminance normalised by every light path traced against the map.
        let counted = slot.light_paths();
        if ctx.cut.load(Ordering::Acquire) && counted < minimum_paths(required) {
            // Cut before it had the light a stopped phase keeps: left out whole, its light discarded.
            for t in &mut self.threads {
                thread_mut(t).gathered.clear();
            }
            self.stats.nanos.closing += nanos_since(t0);
            return false;
        }
        // A phase left out keeps its rays in the work done but not its light paths, which brought no light: the
        // light paths traced and those counted in maps then agree wherever a group's map is its own.
        self.stats.light_paths += tally.traced;
        self.stats.light_paths_counted += counted;
        let data = slot.data_mut(&mut self.token);
        self.stats.merges += tally.own_merges;
        let (first, others) = self.threads.split_first_mut().expect("a group has at least one thread");
        let gathered = &mut thread_mut(first).gathered;
        for t in others {
            gathered.absorb_plain(&mut thread_mut(t).gathered);
        }
        if ctx.shared_maps {
            self.stats.merges += data.shared.merges();
            gathered.absorb(&mut data.shared);
        }
        self.buffers.close(exec, &phase, gathered, counted, &mut self.sums, &mut self.aux_sums);
        self.stats.nanos.closing += nanos_since(t0);
        self.stats.phases += 1;
        true
    }

    /// Stage 3 with the map open: traces the phase's light paths on the group's threads until the quota is met
    /// (and, while another group's map still lacks light, helps it), then keeps tracing until no other group is
    /// inside the map, and closes it. Every vertex is held back per map and gathered in that map's bucket order
    /// (`ThreadGathers`); none is left held back when the pass returns. The light paths the round's recorder
    /// keeps are recorded as paths of phase `number`.
    fn forward_pass<'c>(&mut self, ctx: &RoundContext<'c>, phase: &Phase, required: u64, number: u64) -> ForwardTally {
        let me = self.index;
        let slot = &ctx.slots[me];
        slot.open(&self.token);
        let minimum = minimum_paths(required);
        let own = slot.owner_data(&self.token);
        let rules = GatherRules::of(phase);
        let sole = ctx.sole_foreign_writer;
        let threads = rayon::current_num_threads();
        let maps = if ctx.shared_maps { ctx.slots.len() } else { 1 };
        let batch_size = batch_per_map(ctx.scene.camera.pixel_count(), threads * ctx.slots.len(), maps);
        for t in &mut self.threads {
            thread_mut(t).prepare(ctx.slots.len(), batch_size);
        }
        // Gathers what `thread` held back for map k and releases the map.
        let release = |thread: &mut ThreadGathers, k: usize, held: &mut Option<Guard<'c, GroupMap>>| {
            if let Some(g) = held.take() {
                thread.flush_foreign(k, &g.data().photons, &g.data().shared, sole, rules);
            }
        };
        // Light paths are traced in batches: foreign maps are acquired for a batch and each batch's paths are
        // counted in them at once, so the counters' cache lines move between cores once per batch, not per
        // path. A thread keeps an acquired map from batch to batch while it still lacks light (its owner is
        // still tracing towards its quota, so the hold delays nobody), so that the vertices held back for it
        // gather in large sorted batches; it gathers them and releases the map once the map's quota is met or
        // the round stops, so that the owner can close. `held` is the thread's maps by slot index, and its
        // tallies stay with it until the pass ends. Returns whether the stop cut the batch short and whether a
        // foreign map it served still lacks light.
        let trace_batch = |batch: Batch,
                           thread: &mut ThreadGathers,
                           held: &mut [Option<Guard<'c, GroupMap>>],
                           tally: &mut ForwardTally,
                           log: &mut RecordedPath| {
            // While closing, the owner takes no other map: two closing owners never wait on each other.
            if ctx.shared_maps && !batch.closing {
                for (k, (h, sl)) in held.iter_mut().zip(ctx.slots).enumerate() {
                    if k != me && h.is_none() {
                        *h = sl.try_acquire();
                    }
                }
            }
            let (mut done, mut own_merges) = (0, 0);
            for index in batch.first..batch.first + batch.count {
                // A cut does not wait for the minimum: the phase is then closed if it has it, left out if not.
                if ctx.cut.load(Ordering::Relaxed) || (index >= batch.stop_from && ctx.stop.load(Ordering::Relaxed)) {
                    break;
                }
                let kept = ctx.recorder.filter(|r| r.keeps(PathKind::Light, number, index));
                let record = kept.map(|r| (r, number, &mut *log));
                phase.trace_light_path_recorded(
                    index,
                    &mut tally.stats,
                    &mut |e| match e {
                        LightEvent::Vertex(v) => {
                            let point = v.point();
                            own_merges += thread.push_own(&own.photons, point, rules);
                            for (k, g) in held.iter().enumerate() {
                                if let Some(g) = g {
                                    thread.push_foreign(k, &g.data().photons, &g.data().shared, sole, point, rules);
                                }
                            }
                        }
                        LightEvent::Sensor(hit) => {
                            phase.register(&own.pixels, hit, &mut thread.gathered);
                            for g in held.iter().flatten() {
                                let shared = &g.data().shared;
                                let mut sink = if sole { shared.sole_writer_sink() } else { shared.sink() };
                                phase.register(&g.data().pixels, hit, &mut sink);
                            }
                        }
                    },
                    record,
                );
                done += 1;
            }
            let stopping = ctx.stop.load(Ordering::Relaxed);
            let mut others_lack = false;
            for (k, h) in held.iter_mut().enumerate() {
                let Some(g) = h else { continue };
                g.count_light_paths(done);
                tally.foreign += done;
                if !stopping && g.data().lacking(g.light_paths()) > 0 {
                    others_lack = true;
                } else {
                    release(thread, k, h);
                }
            }
            tally.own_merges += own_merges;
            tally.traced += done;
            (done < batch.count, others_lack)
        };
        // Every thread of the group claims batches of path indices until the paths counted against the map
        // (its own claims plus the other groups' paths, which the slot counts as they come) meet the quota.
        // Without foreign paths this traces indices 0..required, whatever the thread count. Then, while another
        // group's open map still lacks light, the threads help it: a path traced now fills that quota faster,
        // costs no more thread time than the owner tracing it alone, and adds light to this phase too.
        // Groups then leave their forward passes together, so their next forward passes overlap again instead
        // of drifting apart by the differences in their backward passes.
        let thread_pass = |thread: &mut ThreadGathers| {
            let mut held: Vec<Option<Guard<'c, GroupMap>>> = ctx.slots.iter().map(|_| None).collect();
            let mut tally = ForwardTally::default();
            let mut others_lack = false;
            let mut log = RecordedPath::new(PathKind::Light, 0, 0, 0);
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
                (cut, others_lack) = trace_batch(batch, thread, &mut held, &mut tally, &mut log);
                if cut {
                    break;
                }
            }
            for (k, h) in held.iter_mut().enumerate() {
                release(thread, k, h);
            }
            tally.own_merges += thread.flush_own(&own.photons, rules);
            tally
        };
        let mut tally = if threads == 1 {
            thread_pass(thread_mut(&mut self.threads[0]))
        } else {
            let states = &self.threads;
            rayon::broadcast(|b| thread_pass(&mut states[b.index()].lock().unwrap_or_else(PoisonError::into_inner)))
                .into_iter()
                .fold(ForwardTally::default(), ForwardTally::add)
        };
        // Keep tracing useful paths until no other group is inside the map (paper Fig. 9).
        let thread = thread_mut(&mut self.threads[0]);
        let mut held: Vec<Option<Guard<'c, GroupMap>>> = Vec::new();
        let mut log = RecordedPath::new(PathKind::Light, 0, 0, 0);
        while !slot.try_close(&self.token) {
            if ctx.cut.load(Ordering::Relaxed) {
                // The others leave at the cut too: no path traced now would be counted.
                std::thread::yield_now();
                continue;
            }
            let batch = Batch { first: own.claim_beyond_quota(1), count: 1, stop_from: u64::MAX, closing: true };
            trace_batch(batch, thread, &mut held, &mut tally, &mut log);
        }
        // The owner's own photons stay as they are until the phase closes: its last vertices may gather after
        // the map closed to other groups.
        tally.own_merges += thread.flush_own(&own.photons, rules);
        debug_assert!(self.threads.iter_mut().all(|t| thread_mut(t).is_empty()));
        slot.count_owner_paths(&self.token, tally.traced);
        tally
    }
}

/// The light paths a stopped phase needs counted to be closed: a phase cut shorter has too few light paths for
/// its camera paths, and its gathered light's variance grows as 1 / paths (see STOP_FRACTION).
fn minimum_paths(required: u64) -> u64 {
    ((required as f64 * STOP_FRACTION) as u64).max(1)
}

/// A thread's gathers, from a group that holds `&mut` to them (no other thread locks them then).
fn thread_mut(t: &mut Mutex<ThreadGathers>) -> &mut ThreadGathers {
    t.get_mut().unwrap_or_else(PoisonError::into_inner)
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
