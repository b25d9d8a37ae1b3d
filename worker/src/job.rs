//! Running a job inside a worker process: the engine renders rounds on a plain thread and, after a round,
//! hands over a snapshot of the phases completed since the previous one. Only whole rounds are sent, so
//! every snapshot is a consistent estimate.

use crate::machine;
use crate::memory_binding::{self, MemoryBinding};
use crate::parallel::engine::RoundTiming;
use crate::parallel::{EngineConfig, ParallelEngine};
use photonfarm::accumulation::delta::{encode_changes, Compression};
use photonfarm::geometry::BvhCacheUse;
use photonfarm::pbpm::ProcessShare;
use photonfarm::protocol::{Job, Share, Snapshot, WorkerInfo};
use photonfarm::ray_map::{self, PortionSink, Recorder};
use photonfarm::render::light_balance::LightBalance;
use photonfarm::render::memory::MemoryBudget;
use photonfarm::render::session::{self, Deadline, Progressive};
use photonfarm::render::ActiveTiles;
use photonfarm::scene::Scene;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// What the engine thread reports to the link.
#[derive(Debug)]
pub enum JobEvent {
    Started(WorkerInfo),
    Snapshot(Snapshot),
    /// The last snapshot has been handed over.
    Finished,
    Failed(String),
}

/// Builds the job's scene from its description and the files received, once the description is checked to be
/// the coordinator's (the files are checked against the hashes it names as the scene is built).
pub fn load_scene(job: &Job, files: &BTreeMap<String, Vec<u8>>) -> Result<Scene, String> {
    let hash = job.scene.hash();
    if hash != job.scene_hash {
        return Err(format!(
            "the scene description received hashes to {} but the coordinator's is {}",
            &hash[..12],
            &job.scene_hash[..job.scene_hash.len().min(12)]
        ));
    }
    // The file cache checked every file against its hash as it arrived.
    let scene = Scene::from_hashed_files(&job.scene, files).map_err(|e| e.to_string())?;
    // The ghost pairs' pilot, part of building a sensor scene, runs here rather than in the job's first phase.
    photonfarm::pbpm::ghost_pairs(&scene);
    Ok(scene)
}

/// Mixes the job seed with the worker's stream so that every worker draws different samples.
pub fn stream_seed(seed: u64, stream: u64) -> u64 {
    // SplitMix64 finaliser over the pair.
    let mut z = seed ^ stream.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The engine configuration a job asks for, on this machine's cores.
pub fn engine_config(job: &Job) -> Result<EngineConfig, String> {
    let spec = &job.engine;
    let cores = match &spec.cores {
        Some(c) if !c.is_empty() => c.clone(),
        Some(_) => return Err("the job gives an empty core list".into()),
        None => machine::all_cores(),
    };
    let mut config =
        EngineConfig::for_method(spec.method, cores.len(), spec.group_size, cores).map_err(|e| e.to_string())?;
    if let Some(t) = spec.tile_size {
        config.tile_size = t;
    }
    if let Some(k) = spec.phases_per_deal {
        config.phases_per_deal = k;
    }
    config.processes_per_pixel = spec.processes_per_pixel.max(1);
    config.process_rank = spec.process_rank.min(config.processes_per_pixel - 1);
    config.resumed_phases = spec.resumed_phases;
    config.snapshots = true;
    Ok(config)
}

/// The peak memory an engine of `config` will need: what this process holds now (the scene loaded) plus the
/// engine's buffers, estimated before it allocates them; and what it holds now.
fn memory_need(config: &EngineConfig, scene: &Scene, settings: &photonfarm::render::RenderSettings) -> (u64, u64) {
    let base = photonfarm::render::memory::current_rss_bytes().unwrap_or(0);
    let pixels = scene.camera.pixel_count();
    let aux = photonfarm::accumulation::AuxLayout::for_scene(scene, settings.spectral_bands);
    let round = crate::parallel::engine::max_round_pixels(pixels);
    let per_pixel = config.bytes_per_pixel(pixels, round, settings.backward_diffuse_depth, &aux);
    (base + (per_pixel * pixels as f64) as u64, base)
}

/// Refuses an engine of `config` that needs `need` bytes (`base` of them held now) when that does not fit in
/// `budget` (`--memory-limit` per worker process, or the machine's available memory), before it allocates.
fn check_memory(budget: MemoryBudget, config: &EngineConfig, need: u64, base: u64) -> Result<(), String> {
    if need <= budget.bytes() {
        return Ok(());
    }
    let detail =
        format!(" on this worker's {} thread{}", config.threads(), if config.threads() == 1 { "" } else { "s" });
    Err(photonfarm::render::memory::over_limit(budget, need, base, &detail))
}

/// Tiles the coordinator restricted a job to and the engine has not taken yet: the tile edge and one flag per
/// tile.
pub type PendingTiles = std::sync::Mutex<Option<(u32, Vec<bool>)>>;

/// The latest share of the image's phases the coordinator announced and the engine has not taken yet.
pub type PendingShare = std::sync::Mutex<Option<Share>>;

/// When the coordinator said the run stops, and the engine has not taken yet.
pub type PendingDeadline = std::sync::Mutex<Option<Deadline>>;

/// What the link changes while a job runs.
pub struct Control<'a> {
    /// Set to end the job after its current round.
    pub stop: &'a AtomicBool,
    /// The time between snapshots; the link lengthens it on slow links.
    pub interval_ms: &'a AtomicU64,
    /// How long the latest snapshot took from its sending until the coordinator acknowledged it (merged).
    pub send_ms: &'a AtomicU64,
    /// Tiles the coordinator restricted the job to since the last round (tile edge, one flag per tile).
    pub tiles: &'a PendingTiles,
    /// The processes rendering the image, announced since the last round.
    pub share: &'a PendingShare,
    /// When a timed run stops, announced since the last round.
    pub deadline: &'a PendingDeadline,
    /// Where the portions of the job's ray map go (the link), when the job asks for one.
    pub ray_map: Option<Box<dyn PortionSink>>,
}

/// Renders `job` until `control.stop` is set, calling `emit` with its events (it returns false when nobody
/// listens any more). Snapshots are deltas since the previous one, so a snapshot that never arrives is lost,
/// never counted twice.
pub fn run(
    scene: &Scene,
    job: &Job,
    control: Control,
    slowdown: f64,
    compression: Compression,
    mut emit: impl FnMut(JobEvent) -> bool,
) {
    let config = match engine_config(job) {
        Ok(c) => c,
        Err(e) => {
            emit(JobEvent::Failed(e));
            return;
        }
    };
    // Before the engine allocates, so that its buffers come from the node's memory.
    let memory = match job.engine.numa_node {
        Some(_) if job.engine.synthetic_topology => {
            MemoryBinding::FirstTouch("synthetic topology: the node is not this machine's".into())
        }
        Some(node) => memory_binding::bind_memory(node),
        None => MemoryBinding::FirstTouch("no NUMA node given".into()),
    };
    let (memory_estimate, base) = memory_need(&config, scene, &job.settings);
    if let Some(budget) = MemoryBudget::new(job.engine.memory_limit) {
        if let Err(reason) = check_memory(budget, &config, memory_estimate, base) {
            emit(JobEvent::Failed(reason));
            return;
        }
    }
    let mut settings = job.settings;
    settings.seed = stream_seed(job.settings.seed, job.stream);
    let layout = config.layout();
    let cores = config.cores.clone();
    let threads = config.threads();
    let mut engine = match ParallelEngine::new(scene, settings, config) {
        Ok(e) => e,
        Err(e) => {
            emit(JobEvent::Failed(e.to_string()));
            return;
        }
    };
    let recorder = match (job.ray_map, control.ray_map) {
        (Some(request), Some(sink)) => {
            // The worker's own seed: its paths and its choice of them are its own.
            let header = ray_map::header_for(scene, job.engine.method.name(), settings.seed, request.fraction, 0);
            match Recorder::with_sink(sink, &header) {
                Ok(r) => Some(std::sync::Arc::new(r)),
                Err(e) => {
                    emit(JobEvent::Failed(format!("cannot record the ray map: {e}")));
                    return;
                }
            }
        }
        (Some(_), None) => {
            emit(JobEvent::Failed("the job asks for a ray map, but its portions have nowhere to go".into()));
            return;
        }
        _ => None,
    };
    engine.set_recorder(recorder.clone());
    let pinned = engine.pinned_threads();
    let info = WorkerInfo {
        hostname: machine::hostname(),
        threads,
        cores: cores.clone(),
        numa_node: job.engine.numa_node,
        binding: format!(
            "{pinned} of {threads} threads pinned to cores {}{}; {memory}{}",
            cores.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(","),
            if job.engine.synthetic_topology { " (synthetic topology: nodes mapped onto real cores)" } else { "" },
            if slowdown > 1.0 { format!("; slowed down {slowdown}× (--slowdown)") } else { String::new() }
        ),
        layout,
        // The link, which loaded the scene, fills this in.
        scene_load_s: 0.0,
        bvh_cache: BvhCacheUse::Off,
    };
    if !emit(JobEvent::Started(info)) {
        return;
    }
    // Each worker chooses its own light paths per pixel and camera paths' depth from its own phases, unless the
    // job fixes them.
    let mut balance = LightBalance::for_run(&settings, engine.sums(), engine.totals());
    let mut seq = 0;
    let mut last = Instant::now();
    let Control { stop, interval_ms, send_ms, tiles, share, deadline, .. } = control;
    let mut finish_by = None;
    let mut sent_phases = 0;
    // How long the latest snapshot took to encode.
    let mut encoding = Duration::ZERO;
    loop {
        if let Some(d) = deadline.lock().unwrap_or_else(|e| e.into_inner()).take() {
            finish_by = Some(d);
        }
        // The run ends when the coordinator has merged every worker's last snapshot, so rendering stops
        // early by as long as the latest snapshot took to encode, send and merge: on a large image that is
        // seconds, which the last one would otherwise add past the deadline.
        let collecting = encoding + Duration::from_millis(send_ms.load(Ordering::Relaxed));
        let render_until =
            finish_by.map(|d: Deadline| Deadline { at: d.at.checked_sub(collecting).unwrap_or(d.at), ..d });
        let announced = share.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(announced) = announced {
            // What this worker has sent, which the coordinator's merged phases include (or will): its phases but
            // those of the rounds since the previous snapshot.
            let own: Vec<u32> = engine.sums().pixels.iter().map(|p| p.phases).collect();
            let mut sent = own.clone();
            for (i, phases) in engine.phases_before_changes() {
                sent[i] = phases;
            }
            let share = announced
                .merged_phases(own.len())
                .map_err(|e| e.to_string())
                .and_then(|merged| ProcessShare::announced(announced.processes, announced.rank, &merged, &own, &sent));
            match share {
                Ok(s) => engine.set_share(s),
                Err(e) => {
                    emit(JobEvent::Failed(format!(
                        "the coordinator's share of the phases does not fit the image: {e}"
                    )));
                    return;
                }
            }
        }
        let pending = tiles.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some((tile, flags)) = pending {
            match ActiveTiles::from_flags(scene.camera.width, scene.camera.height, tile, flags) {
                Ok(t) => engine.set_active_tiles(&t),
                Err(e) => {
                    emit(JobEvent::Failed(format!("the coordinator's active tiles do not fit the image: {e}")));
                    return;
                }
            }
        }
        if render_until.is_some_and(|d| Instant::now() >= d.at) {
            // Past the time to stop rendering nothing more is rendered: the coordinator's stop follows.
            while !stop.load(Ordering::Acquire) {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        let stopping = stop.load(Ordering::Acquire);
        if !stopping {
            let round = Instant::now();
            if let Some(b) = &balance {
                session::set_balance(&mut engine, b);
            }
            // A round ends when the next snapshot is due, so that a large image, whose phases last seconds,
            // is sent after its first phase and then at every interval, not after K phases.
            let interval = Duration::from_millis(interval_ms.load(Ordering::Relaxed).max(1));
            let timing = RoundTiming {
                cut_at: render_until.map(|d| d.at),
                wind_down_at: Some(last + interval),
                finish_by: render_until,
            };
            engine.run_timed_round(stop, timing);
            if let Some(b) = &mut balance {
                let comparing = b.is_comparing_depths();
                b.observe(engine.sums(), engine.totals());
                if comparing && !b.is_comparing_depths() {
                    tracing::info!(
                        "backward_diffuse_depth {} from here on, chosen from the first rounds",
                        b.depth().expect("a chosen depth once the comparison has ended")
                    );
                }
            }
            // A straggler idles (slowdown − 1) round times after each round, but still answers a stop at once.
            let idle_until = Instant::now() + round.elapsed().mul_f64(slowdown - 1.0);
            while Instant::now() < idle_until && !stop.load(Ordering::Acquire) {
                std::thread::sleep(Duration::from_millis(5).min(idle_until.saturating_duration_since(Instant::now())));
            }
        }
        let stopping = stop.load(Ordering::Acquire);
        let interval = Duration::from_millis(interval_ms.load(Ordering::Relaxed).max(1));
        // A snapshot without a new phase would add nothing, also at the stop, unless it is the worker's first.
        // Past the time to stop rendering, the last phases go at once rather than at the coordinator's stop.
        let news = engine.totals().phases > sent_phases;
        let over = render_until.is_some_and(|d| Instant::now() >= d.at);
        if (stopping && (news || seq == 0)) || (news && (over || last.elapsed() >= interval)) {
            sent_phases = engine.totals().phases;
            seq += 1;
            // Only the pixels the rounds since the previous snapshot rendered: with the phase cap a round
            // renders a part of a large image, and a pass over all of it would cost more than the round.
            let encoding_since = Instant::now();
            let changes = engine.take_changed();
            let delta = encode_changes(engine.sums(), &changes, compression);
            encoding = encoding_since.elapsed();
            let snapshot = Snapshot {
                seq,
                totals: engine.totals(),
                checksum: Snapshot::checksum_of(&delta),
                delta,
                interval_ms: interval.as_millis() as u64,
                previous_send_ms: 0,
                peak_memory_bytes: photonfarm::render::memory::peak_rss_bytes().unwrap_or(0),
                memory_estimate_bytes: memory_estimate,
                non_finite_dropped: photonfarm::accumulation::non_finite_dropped(),
            };
            last = Instant::now();
            if !emit(JobEvent::Snapshot(snapshot)) {
                return;
            }
        }
        if stopping {
            // The map's last portions go to the link before `Finished`, which the coordinator reads after them.
            if let Some(r) = &recorder {
                match r.finish() {
                    Ok(s) => tracing::info!("ray map: {} paths, {} segments sent", s.paths, s.segments),
                    Err(e) => tracing::warn!("the ray map is incomplete: {e}"),
                }
            }
            emit(JobEvent::Finished);
            return;
        }
    }
}
