//! The semi-synchronous level (paper §4.1, docs/parallel-engine.md) and the parallel methods as its configurations: the
//! main thread deals masks, runs the groups until one of them has finished K phases, stops them all, forms the
//! whole image and deals again.

use super::group::{Group, GroupMap, GroupStats, PhasesBefore, RoundContext};
use super::map_slot::MapSlot;
use super::mask;
use photonfarm::accumulation::delta::Changes;
use photonfarm::accumulation::{Accumulator, AuxLayout};
use photonfarm::pbpm::ProcessShare;
use photonfarm::ray_map::Recorder;
use photonfarm::render::light_balance::LightBalance;
use photonfarm::render::record::StageSeconds;
use photonfarm::render::session::{Deadline, Progressive};
use photonfarm::render::{ActiveTiles, RayTotals, RenderSettings};
use photonfarm::scene::Scene;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use photonfarm::render::ParallelMethod;

/// How the engine is laid out: its method's row of the methods' table (`photonfarm::render::method`) as data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EngineConfig {
    pub method: ParallelMethod,
    pub groups: usize,
    pub threads_per_group: usize,
    /// Groups render random tile masks (otherwise every group renders the whole image).
    pub masks: bool,
    /// Groups gather into each other's open maps.
    pub shared_maps: bool,
    /// Tile edge in pixels.
    pub tile_size: u32,
    /// K: the round ends when one group has finished this many phases.
    pub phases_per_deal: u32,
    /// Cores to pin to; thread t of group k runs on `cores[(k · g + t) mod len]`.
    pub cores: Vec<usize>,
    /// Worker processes rendering the same image, and this one's index (for the radius schedule).
    pub processes_per_pixel: u32,
    pub process_rank: u32,
    /// Phases every pixel had before this run (a resumed run), for the radius schedule.
    pub resumed_phases: u32,
    /// Keeps, for the next snapshot, the earlier sums of the pixels the rounds change (a worker process, whose
    /// snapshots are deltas); an engine in the coordinator's process keeps none.
    pub snapshots: bool,
}

/// Why an engine configuration cannot run.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{0}")]
    Invalid(String),
    #[error("cannot start the worker threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
}

impl EngineConfig {
    /// The configuration of `method` on `threads` threads: its row of the methods' table
    /// ([`photonfarm::render::method`]), with `group_size` the most threads per group for two-level.
    pub fn for_method(
        method: ParallelMethod,
        threads: usize,
        group_size: usize,
        cores: Vec<usize>,
    ) -> Result<Self, ConfigError> {
        if cores.is_empty() {
            return Err(ConfigError::Invalid("the core list is empty".into()));
        }
        let layout = photonfarm::render::Method::from(method).layout();
        let groups = layout.grouping.split(threads, group_size).map_err(|e| ConfigError::Invalid(e.to_string()))?;
        Ok(EngineConfig {
            method,
            groups: groups.groups,
            threads_per_group: groups.threads_per_group,
            masks: layout.masks,
            shared_maps: layout.shared_maps,
            tile_size: if groups.groups > 16 { 64 } else { 32 },
            phases_per_deal: 6,
            cores,
            processes_per_pixel: 1,
            process_rank: 0,
            resumed_phases: 0,
            snapshots: false,
        })
    }

    /// Total threads.
    pub fn threads(&self) -> usize {
        self.groups * self.threads_per_group
    }

    /// Bytes per image pixel of an engine with this configuration over an image of `pixels` pixels, rounds of at
    /// most `round_pixels` (`max_round_pixels`) and the auxiliary layers of `aux`: over the whole image, the
    /// merged sums, the process share, the run's light balance and, with snapshots, the changed pixels' earlier
    /// sums; over the pixels of a round, each group's per-pixel buffers over the pixels it renders (its mask, or
    /// all of the round's without masks) and its photons. Known before anything is allocated, so
    /// `--memory-limit` can be checked up front.
    pub fn bytes_per_pixel(
        &self,
        pixels: usize,
        round_pixels: usize,
        backward_diffuse_depth: u32,
        aux: &AuxLayout,
    ) -> f64 {
        use photonfarm::accumulation::PixelSums;
        use photonfarm::integrator::LayerValues;
        // Masks partition a round's pixels among the groups; without masks every group covers all of them.
        let coverage = if self.masks { 1 } else { self.groups };
        // A photon is held twice (the backward pass's list, then the map's copy), and the grid enters it in at
        // most eight cells (its sphere spans at most two cells of three mean radii per axis), each entry a u32
        // plus the build's u64 (cell, photon) pair, in buffers that grow by doubling as the count varies from
        // phase to phase, with a table of half a bucket per photon and the u32 of its place in grid order.
        let photon = 2 * std::mem::size_of::<photonfarm::pbpm::BackwardPhoton>() + 2 * 8 * (4 + 8) + 2 + 4;
        // Gathered light: a plain buffer per thread of the group for its own paths, and the map's atomic one
        // where other groups add into it; each holds (indirect, caustic) RGB in f32 and the auxiliary channels,
        // and with a ghost layer the visible light registered on the sensor. A group with a mask then also
        // holds the sensor's image-pixel-to-mask table, over the whole image.
        let sensor = aux.offset(photonfarm::ghost::GHOST_LAYER).is_some();
        let gather_buffers = self.threads_per_group + self.shared_maps as usize;
        let gathered = gather_buffers * (6 * 4 + aux.phase_bytes_per_pixel() + if sensor { 12 } else { 0 });
        let sensor_tables = if sensor && self.masks { self.groups * 4 } else { 0 };
        // Per pixel of a round: the camera pass's values and replicate, the group's sums, and the mask and the
        // phases before the deal (over every process and this one's own), 12 bytes.
        let per_round_pixel = std::mem::size_of::<LayerValues>()
            + 1
            + std::mem::size_of::<PixelSums>()
            + 12
            + gathered
            + backward_diffuse_depth as usize * photon
            + aux.phase_bytes_per_pixel()
            + aux.sum_bytes_per_pixel();
        // Snapshots keep a changed pixel's flag, index and earlier sums, at most every pixel's.
        let snapshot = if self.snapshots { 1 + 4 + Accumulator::bytes_per_pixel(aux) } else { 0 };
        // The light vertices held back for sorted gathers: bounded over the whole engine, not per group.
        let held_back = super::thread_gathers::held_back_bytes_per_pixel(pixels);
        // A worker process also holds the share of the pixels' phases the coordinator announces to it.
        let share = ProcessShare::BYTES_PER_PIXEL;
        let whole_image =
            Accumulator::bytes_per_pixel(aux) + sensor_tables + share + LightBalance::BYTES_PER_PIXEL + snapshot;
        let round_share = round_pixels.min(pixels) as f64 / pixels.max(1) as f64;
        whole_image as f64 + (coverage * per_round_pixel) as f64 * round_share + held_back
    }

    /// The layout in words, e.g. "2 groups × 1 thread, 32-pixel tile masks, shared maps".
    pub fn layout(&self) -> String {
        format!(
            "{} group{} × {} thread{}{}{}",
            self.groups,
            if self.groups == 1 { "" } else { "s" },
            self.threads_per_group,
            if self.threads_per_group == 1 { "" } else { "s" },
            if self.masks { format!(", {}-pixel tile masks", self.tile_size) } else { String::new() },
            if self.shared_maps { ", shared maps" } else { "" },
        )
    }
}

/// How long an in-process round goes on before it winds down, like a worker's round at its default snapshot
/// interval: on a large image a phase lasts seconds, and rounds of K phases would leave the image unmerged,
/// without δ or a preview, for K of them.
pub const ROUND_LENGTH: Duration = Duration::from_secs(1);

/// How long a group's phase lasts at most, about, on a large image: a phase's light is merged (δ, the preview)
/// only once it ends, and a timed run can end only between phases.
pub const PHASE_TARGET: Duration = Duration::from_secs(1);

/// The fewest pixels a round renders under `PhaseCap::Duration`, and the first round's (a pilot that measures the
/// time per pixel-phase). Every image up to 512 × 512 (every shipped scene) keeps whole-image masks, and so
/// its images for a fixed seed.
pub const MIN_CAPPED_ROUND_PIXELS: usize = 512 * 512;

/// The most pixels a round renders under `PhaseCap::Duration`, however fast its phases: the groups' per-pixel
/// buffers and photons then stay within what the memory estimate counts for a round (a 1080p image renders
/// whole; a 4K image a quarter at a time at most).
pub const MAX_CAPPED_ROUND_PIXELS: usize = 2048 * 1024;

/// The most pixels a round of the parallel engine renders on an image of `pixels` pixels.
pub fn max_round_pixels(pixels: usize) -> usize {
    pixels.min(MAX_CAPPED_ROUND_PIXELS)
}

/// How many pixels a group's phase covers at most (docs/parallel-engine.md, "Phase cap"): beyond it a round
/// renders only the tiles with the fewest phases.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhaseCap {
    /// As many as the previous round's time per pixel-phase fits in this duration, and never fewer than
    /// `MIN_CAPPED_ROUND_PIXELS` per round.
    Duration(Duration),
    /// At most this many, whatever a phase costs; tests force the cap on small images with it.
    Pixels(usize),
}

impl Default for PhaseCap {
    fn default() -> Self {
        PhaseCap::Duration(PHASE_TARGET)
    }
}

/// When a round ends besides its K phases (`ParallelEngine::run_timed_round`).
#[derive(Clone, Copy, Debug, Default)]
pub struct RoundTiming {
    /// The groups are cut: they start no phase, and the phases under way stop their light paths once a quarter
    /// of them are counted.
    pub cut_at: Option<Instant>,
    /// The groups finish the phases under way, whole, and start no other once each has rendered one.
    pub wind_down_at: Option<Instant>,
    /// A timed run's deadline: no group starts a phase that, lasting as long as its previous one, would end
    /// past it.
    pub finish_by: Option<Deadline>,
}

/// The multi-threaded engine of one process.
pub struct ParallelEngine<'s> {
    scene: &'s Scene,
    settings: RenderSettings,
    config: EngineConfig,
    groups: Vec<Group>,
    slots: Vec<MapSlot<GroupMap>>,
    sums: Accumulator,
    deals: u64,
    /// The tiles rounds render (adaptive tiles); None renders every tile.
    tiles: Option<ActiveTiles>,
    phase_cap: PhaseCap,
    /// A group's wall nanoseconds per pixel-phase in the latest round that closed a phase, for the cap.
    nanos_per_pixel_phase: Option<f64>,
    /// How this process counts a pixel's phases over every process rendering the image (the radius schedule).
    share: ProcessShare,
    /// Thread-nanoseconds idle at round ends and between rounds.
    waiting_nanos: u64,
    between_nanos: u64,
    last_round_end: Option<Instant>,
    /// Records the kept camera and light paths of every group into a ray map.
    recorder: Option<Arc<Recorder>>,
    /// Pixels whose sums a round changed since `take_changed` last ran: a snapshot sends only these.
    changed: Vec<bool>,
    /// Those pixels' sums before their first change since then, which a snapshot's delta subtracts: kept for
    /// them alone, so that a worker holds no second image of sums.
    changes: Changes,
}

impl<'s> ParallelEngine<'s> {
    /// Starts the groups' threads (pinned) with empty sums.
    pub fn new(scene: &'s Scene, settings: RenderSettings, mut config: EngineConfig) -> Result<Self, ConfigError> {
        scene.assert_traceable();
        // In a spectral scene each group phase has its own wavelength, and a light path at one wavelength cannot
        // join camera paths at another: every group gathers only into its own map.
        if settings.is_spectral(scene) {
            config.shared_maps = false;
        }
        if !(1..=64).contains(&config.phases_per_deal) {
            return Err(ConfigError::Invalid(format!(
                "phases per deal must be 1..=64, got {}",
                config.phases_per_deal
            )));
        }
        if config.tile_size == 0 {
            return Err(ConfigError::Invalid("the tile size must be at least one pixel".into()));
        }
        let slots: Vec<MapSlot<GroupMap>> = (0..config.groups).map(|_| MapSlot::new(GroupMap::default())).collect();
        let aux = AuxLayout::for_scene(scene, settings.spectral_bands);
        // Groups own their slot's token; the slots live in a Vec that is never resized.
        let mut groups = Vec::with_capacity(config.groups);
        for (k, slot) in slots.iter().enumerate() {
            let cores = (0..config.threads_per_group)
                .map(|t| config.cores[(k * config.threads_per_group + t) % config.cores.len()])
                .collect();
            groups.push(Group::new(k, cores, slot.take_owner(), aux.clone())?);
        }
        let share = ProcessShare::planned(config.processes_per_pixel, config.process_rank, config.resumed_phases);
        let changed = if config.snapshots { vec![false; scene.camera.pixel_count()] } else { Vec::new() };
        Ok(ParallelEngine {
            scene,
            settings,
            sums: Accumulator::with_aux(scene.camera.width, scene.camera.height, aux),
            config,
            groups,
            slots,
            deals: 0,
            tiles: None,
            phase_cap: PhaseCap::default(),
            nanos_per_pixel_phase: None,
            share,
            waiting_nanos: 0,
            between_nanos: 0,
            last_round_end: None,
            recorder: None,
            changed,
            changes: Changes::default(),
        })
    }

    /// Records the paths `recorder` keeps (a ray map) from the next round on, on every thread of every group;
    /// recording does not change the image.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        for g in &mut self.groups {
            g.set_recorder(recorder.clone());
        }
        self.recorder = recorder;
    }

    /// The configuration.
    pub fn config(&self) -> &EngineConfig {
        &self.config
    }

    /// Renders only the active tiles of `tiles` from the next round on (every tile when all are active).
    pub fn set_active_tiles(&mut self, tiles: &ActiveTiles) {
        assert_eq!(
            (tiles.width, tiles.height),
            (self.scene.camera.width, self.scene.camera.height),
            "tiles of another image"
        );
        self.tiles = (!tiles.all_active()).then(|| tiles.clone());
    }

    /// Bounds the pixels of a group's phase with `cap` from the next round on.
    pub fn set_phase_cap(&mut self, cap: PhaseCap) {
        self.phase_cap = cap;
    }

    /// The tiles the next round renders when the phase cap leaves some of the active ones out: the most pixels
    /// the cap allows, taken from the tiles with the fewest phases, so that over rounds every tile gets the same
    /// phases. The caller's active tiles (adaptive tiles) choose which tiles need work; the cap, how many of
    /// them one round renders.
    fn capped_tiles(&self) -> Option<ActiveTiles> {
        let (w, h) = (self.scene.camera.width, self.scene.camera.height);
        // Masks split a round's pixels among the groups; without them every group renders all of them.
        let groups_per_round = if self.config.masks { self.config.groups } else { 1 };
        let max_pixels = match self.phase_cap {
            PhaseCap::Pixels(n) => n.saturating_mul(groups_per_round),
            PhaseCap::Duration(target) => {
                let per_group = self.nanos_per_pixel_phase.map_or(0.0, |r| target.as_nanos() as f64 / r);
                ((per_group * groups_per_round as f64) as usize).clamp(MIN_CAPPED_ROUND_PIXELS, MAX_CAPPED_ROUND_PIXELS)
            }
        };
        if (w as usize * h as usize) <= max_pixels {
            return None;
        }
        let all;
        let candidates = match &self.tiles {
            Some(t) => t,
            None => {
                all = ActiveTiles::all(w, h, self.config.tile_size).expect("a tile of at least one pixel");
                &all
            }
        };
        let pixels = &self.sums.pixels;
        candidates.fewest_phases_first(|p| pixels[p as usize].phases, max_pixels, self.settings.seed, self.deals)
    }

    /// Records the round's wall time per pixel-phase of the groups' closed phases from the stats they had
    /// before it (phases, stage nanoseconds); a round that closed none keeps the previous figure.
    fn measure_phases(&mut self, before: &[(u64, u64)]) {
        let (mut nanos, mut pixel_phases) = (0u64, 0u64);
        for (g, &(phases, spent)) in self.groups.iter().zip(before) {
            nanos += stage_nanos(&g.stats) - spent;
            pixel_phases += (g.stats.phases - phases) * g.mask().len() as u64;
        }
        if pixel_phases > 0 {
            self.nanos_per_pixel_phase = Some(nanos as f64 / pixel_phases as f64);
        }
    }

    /// Counts the pixels' phases with `share` from the next round on: the coordinator announced a change of
    /// the processes rendering the image.
    pub fn set_share(&mut self, share: ProcessShare) {
        self.share = share;
    }

    /// Per-group counters.
    pub fn group_stats(&self) -> Vec<GroupStats> {
        self.groups.iter().map(|g| g.stats).collect()
    }

    /// Threads whose pinning the OS accepted, over all groups.
    pub fn pinned_threads(&self) -> usize {
        self.groups.iter().map(Group::pinned_threads).sum()
    }

    /// Bytes of every buffer of the engine (sums, groups' buffers and maps), measured between rounds.
    pub fn capacity_bytes(&mut self) -> usize {
        let sums = self.sums.pixels.capacity() * std::mem::size_of::<photonfarm::accumulation::PixelSums>()
            + self.sums.aux.capacity_bytes();
        let snapshots = self.changed.capacity() + self.changes.capacity_bytes();
        sums + snapshots + self.groups.iter_mut().zip(&self.slots).map(|(g, s)| g.capacity_bytes(s)).sum::<usize>()
    }

    /// One synchronisation round: deal masks, run every group until one has finished K phases (or the
    /// deadline passes, or the user interrupts), stop them, add their sums to the whole image.
    pub fn run_round(&mut self, interrupted: &AtomicBool, deadline: Option<Instant>) {
        self.run_timed_round(interrupted, RoundTiming { cut_at: deadline, ..RoundTiming::default() });
    }

    /// A synchronisation round that also ends as `timing` says: wound down after a while (each group finishes
    /// its phase under way), and with no phase started that would end past a timed run's deadline.
    pub fn run_timed_round(&mut self, interrupted: &AtomicBool, timing: RoundTiming) {
        let RoundTiming { cut_at: deadline, wind_down_at, finish_by } = timing;
        let threads = self.config.threads() as u64;
        let round_start = Instant::now();
        if let Some(end) = self.last_round_end {
            // Between two rounds: the previous merge (timed at its end) plus the caller's work since.
            self.between_nanos += threads * round_start.duration_since(end).as_nanos() as u64;
        }
        self.deals += 1;
        let (w, h) = (self.scene.camera.width, self.scene.camera.height);
        let (groups, seed) = (self.config.groups, self.settings.seed);
        let capped = self.capped_tiles();
        let masks = match (capped.as_ref().or(self.tiles.as_ref()), self.config.masks) {
            (None, true) => mask::deal(w, h, self.config.tile_size, groups, seed, self.deals),
            (None, false) => vec![mask::whole_image(w, h); groups],
            (Some(t), true) => mask::deal_tiles(t, groups, seed, self.deals),
            (Some(t), false) => vec![t.active_pixels(); groups],
        };
        // The pixels of the round: the light-path quota is L per pixel rendered.
        let rendered_pixels = if self.config.masks { masks.iter().map(Vec::len).sum() } else { masks[0].len() };
        for (g, m) in self.groups.iter_mut().zip(masks) {
            let (share, pixels) = (&self.share, &self.sums.pixels);
            let before = m
                .iter()
                .map(|&p| {
                    let own = pixels[p as usize].phases;
                    PhasesBefore { all: share.phases_before(p as usize, own).min(u32::MAX as u64) as u32, own }
                })
                .collect();
            g.start_deal(m, before, if self.config.masks { 1 } else { self.config.groups as u32 });
        }
        let stats_before: Vec<(u64, u64)> =
            self.groups.iter().map(|g| (g.stats.phases, stage_nanos(&g.stats))).collect();
        let (stop, cut, wind_down) = (AtomicBool::new(false), AtomicBool::new(false), AtomicBool::new(false));
        let ctx = RoundContext {
            scene: self.scene,
            settings: &self.settings,
            slots: &self.slots,
            shared_maps: self.config.shared_maps,
            sole_foreign_writer: self.config.groups == 2 && self.config.threads_per_group == 1,
            stop: &stop,
            cut: &cut,
            wind_down: &wind_down,
            deadline: finish_by,
            deal: self.deals,
            rendered_pixels,
            numbering: self.share.numbering(1, 0),
            recorder: self.recorder.as_deref(),
        };
        let k = self.config.phases_per_deal as u64;
        let (tx, rx) = mpsc::channel();
        let per_group = self.config.threads_per_group as u64;
        let ends = std::thread::scope(|s| {
            let handles: Vec<_> = self
                .groups
                .iter_mut()
                .map(|g| {
                    let (tx, ctx) = (tx.clone(), &ctx);
                    s.spawn(move || {
                        g.run_round(ctx, k, &tx);
                        Instant::now()
                    })
                })
                .collect();
            drop(tx);
            loop {
                match rx.recv_timeout(Duration::from_millis(5)) {
                    Ok(_) | Err(RecvTimeoutError::Disconnected) => break,
                    Err(RecvTimeoutError::Timeout) => {
                        if interrupted.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
                            cut.store(true, Ordering::Release);
                            break;
                        }
                        // The groups leave one by one as their phases end; the last one ends the round.
                        if wind_down_at.is_some_and(|w| Instant::now() >= w) {
                            wind_down.store(true, Ordering::Release);
                        }
                    }
                }
            }
            stop.store(true, Ordering::Release);
            handles.into_iter().map(|h| h.join().expect("a group thread panicked")).collect::<Vec<_>>()
        });
        let round_end = Instant::now();
        for end in ends {
            self.waiting_nanos += per_group * round_end.duration_since(end).as_nanos() as u64;
        }
        self.measure_phases(&stats_before);
        if self.config.snapshots {
            for g in &self.groups {
                for &p in g.mask() {
                    if !std::mem::replace(&mut self.changed[p as usize], true) {
                        self.changes.keep(p as usize, &self.sums);
                    }
                }
            }
        }
        for g in &self.groups {
            self.sums.merge_local(g.mask(), g.local_sums(), g.local_aux());
        }
        // The merge is between-rounds time; it is added when the next round starts.
        self.last_round_end = Some(round_end);
    }

    /// The pixels whose sums changed since the previous call (every pixel a round's masks held), in increasing
    /// order with the sums each had at that call, and forgets them: only their sums differ from the sums then.
    /// None without `EngineConfig::snapshots`.
    pub fn take_changed(&mut self) -> Changes {
        let changes = std::mem::take(&mut self.changes).into_sorted();
        for i in changes.pixels() {
            self.changed[i] = false;
        }
        changes
    }

    /// The pixels changed since `take_changed` last ran, with the phases each had then.
    pub fn phases_before_changes(&self) -> impl Iterator<Item = (usize, u32)> + '_ {
        self.changes.phases_before()
    }

    /// Thread-seconds per stage so far.
    pub fn stage_seconds(&self) -> StageSeconds {
        let per_group = self.config.threads_per_group as f64 * 1e-9;
        let mut s = StageSeconds {
            waiting: self.waiting_nanos as f64 * 1e-9,
            between_rounds: self.between_nanos as f64 * 1e-9,
            ..StageSeconds::default()
        };
        for g in &self.groups {
            let n = g.stats.nanos;
            s.backward += n.backward as f64 * per_group;
            s.build += n.build as f64 * per_group;
            s.forward += n.forward as f64 * per_group;
            s.closing += n.closing as f64 * per_group;
        }
        s
    }
}

/// A group's wall nanoseconds in its phases' stages so far.
fn stage_nanos(stats: &GroupStats) -> u64 {
    let n = stats.nanos;
    n.backward + n.build + n.forward + n.closing
}

impl Progressive for ParallelEngine<'_> {
    fn step(&mut self, interrupted: &AtomicBool, deadline: Option<Deadline>) {
        let timing = RoundTiming {
            cut_at: deadline.map(|d| d.at),
            wind_down_at: Some(Instant::now() + ROUND_LENGTH),
            finish_by: deadline,
        };
        self.run_timed_round(interrupted, timing);
    }

    fn sums(&self) -> &Accumulator {
        &self.sums
    }

    fn totals(&self) -> RayTotals {
        let mut t = RayTotals::default();
        for g in &self.groups {
            let s = g.stats;
            t += RayTotals {
                phases: s.phases,
                backward_rays: s.backward_rays,
                forward_rays: s.forward_rays,
                light_paths: s.light_paths,
                map_light_paths: s.light_paths_counted,
                backward_photons: s.backward_photons,
                merges: s.merges,
                capped_light_paths: s.capped_light_paths,
            };
        }
        t
    }

    fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    fn bytes_per_pixel(&self) -> f64 {
        // A formula, not a measurement: exact capacities need the owner tokens (`capacity_bytes`, between rounds).
        let pixels = self.scene.camera.pixel_count();
        let round = max_round_pixels(pixels);
        self.config.bytes_per_pixel(pixels, round, self.settings.backward_diffuse_depth, self.sums.aux.layout())
    }

    fn threads(&self) -> usize {
        self.config.threads()
    }

    fn set_light_paths_per_pixel(&mut self, l: f32) -> bool {
        self.settings.light_paths_per_pixel = l;
        true
    }

    fn set_backward_diffuse_depth(&mut self, depth: u32) -> bool {
        self.settings.backward_diffuse_depth = depth;
        true
    }

    fn pinned_threads(&self) -> usize {
        ParallelEngine::pinned_threads(self)
    }

    fn stage_seconds(&self) -> Option<StageSeconds> {
        Some(ParallelEngine::stage_seconds(self))
    }

    fn set_active_tiles(&mut self, tiles: &ActiveTiles) {
        ParallelEngine::set_active_tiles(self, tiles);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn methods_map_to_the_layouts_of_the_design_table() {
        let c = |m, t, g| EngineConfig::for_method(m, t, g, vec![0, 1]).unwrap();
        let sync = c(ParallelMethod::Sync, 4, 2);
        assert_eq!((sync.groups, sync.threads_per_group, sync.masks, sync.shared_maps), (1, 4, false, false));
        let asy = c(ParallelMethod::Async, 4, 2);
        assert_eq!((asy.groups, asy.threads_per_group, asy.masks, asy.shared_maps), (4, 1, false, false));
        let two = c(ParallelMethod::TwoLevel, 8, 4);
        assert_eq!((two.groups, two.threads_per_group, two.masks, two.shared_maps), (2, 4, true, true));
        // Three cores with the default group size 2: three groups of one, every core used.
        let three = c(ParallelMethod::TwoLevel, 3, 2);
        assert_eq!((three.groups, three.threads_per_group), (3, 1));
        let six = c(ParallelMethod::TwoLevel, 6, 4);
        assert_eq!((six.groups, six.threads_per_group), (3, 2));
        // Never one group of several threads: two cores make two groups of one, four with g = 4 two of two.
        let two_cores = c(ParallelMethod::TwoLevel, 2, 2);
        assert_eq!((two_cores.groups, two_cores.threads_per_group), (2, 1));
        let four = c(ParallelMethod::TwoLevel, 4, 4);
        assert_eq!((four.groups, four.threads_per_group), (2, 2));
        let one = c(ParallelMethod::TwoLevel, 1, 2);
        assert_eq!((one.groups, one.threads_per_group), (1, 1));
        assert!(EngineConfig::for_method(ParallelMethod::TwoLevel, 4, 3, vec![0]).is_err());
        assert!(EngineConfig::for_method(ParallelMethod::Sync, 0, 1, vec![0]).is_err());
        // Every configuration is its method's row of the table.
        for m in [ParallelMethod::Sync, ParallelMethod::Async, ParallelMethod::TwoLevel] {
            let row = photonfarm::render::Method::from(m).layout();
            for (t, g) in [(1, 2), (2, 2), (3, 2), (4, 2), (4, 4), (6, 2), (6, 4), (8, 1), (8, 2), (8, 4)] {
                let config = c(m, t, g);
                let groups = row.grouping.split(t, g).unwrap();
                assert_eq!(
                    (config.groups, config.threads_per_group, config.masks, config.shared_maps),
                    (groups.groups, groups.threads_per_group, row.masks, row.shared_maps),
                    "{m:?} on {t} threads, group size {g}"
                );
            }
        }
    }
}
