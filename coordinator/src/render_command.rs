//! `coordinator render`: the main job, in steps: check the options against the method, settle the settings
//! (the scene's, the overrides, or a checkpoint's), start the method's engine (in this process or as worker
//! processes), run it until the stop rule while refreshing the outputs, and write the image and the record.

use crate::cli::{Display, ErrorOverArg, RenderArgs};
use crate::cluster::launch::{self, LaunchOptions};
use crate::live::feed::LiveFeed;
use crate::live::session::{LiveOptions, LiveSession};
use crate::output_folder::{self, Reference};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use photonfarm::accumulation::{Accumulator, LitMask};
use photonfarm::geometry::BvhCacheUse;
use photonfarm::protocol::Secret;
use photonfarm::ray_map::{self, Recorder};
use photonfarm::render::active_tiles::DEFAULT_TILE;
use photonfarm::render::checkpoint::{Checkpoint, CheckpointError};
use photonfarm::render::engine::CAPPED_PHASE_PIXELS;
use photonfarm::render::forecast::Forecast;
use photonfarm::render::memory::MemoryBudget;
use photonfarm::render::method::{Images, Processes};
use photonfarm::render::record::{flags_of, HistoryEntry, RunRecord, WorkerRecord, WorkerState};
use photonfarm::render::session::{self, ErrorOver, Progressive, StopReason, StopRule, Tracking};
use photonfarm::render::{images, memory, ActiveTiles, Engine, Estimator, Method, RenderSettings};
use photonfarm::scene::ghost::sensor_ghosts;
use photonfarm::scene::{MitsubaOptions, Scene};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use worker::{machine, EngineConfig, ParallelEngine, ParallelMethod};

const DEFAULT_TIME_S: f64 = 30.0;
/// The checkpoint's file name in the output folder.
const CHECKPOINT: &str = "checkpoint.bin";

pub fn run(args: RenderArgs) -> Result<()> {
    let launched = Instant::now();
    let stop = stop_rule(&args)?;
    let distributed = args.method.layout().processes == Processes::PerNumaNode;
    // A distributed run's workers trace the scene and decide its lit mask; this process merges and saves, and
    // builds no BVH, the largest part of a large scene. One that only listens decides the mask itself: its
    // clock runs before any worker has joined.
    let workers_decide_lit = distributed && launch_options(&args).starts_with_workers();
    let mut scene = if workers_decide_lit {
        Scene::load_untraced(&args.scene, &mitsuba_options(&args))?
    } else {
        Scene::load_with_options(&args.scene, &mitsuba_options(&args))?
    };
    let scene_load_s = launched.elapsed().as_secs_f64();
    // A scene loaded untraced built no BVH, so had no use for the cache.
    let bvh_cache = (!workers_decide_lit).then(|| scene.geometry.bvh_cache().clone());
    check_method_options(&args)?;
    let mut settings = settings_of(&args, &scene)?;
    let reference = match &args.reference {
        Some(p) => Some(Reference::load(p, scene.camera.width, scene.camera.height)?),
        None => None,
    };
    let (checkpoint, mut resumed_sums) = load_checkpoint(&args, &scene)?.unzip();
    if let Some(c) = &checkpoint {
        settings = c.settings;
    }
    // Before anything the image's size scales (the lit mask, the engine's buffers, the workers): a render that
    // cannot fit is refused now, and async gives up threads to fit. A distributed run's coordinator renders
    // nothing: what it will hold is known once it holds the scene without its geometry.
    let mut notes = Vec::new();
    let plan = if distributed { None } else { Some(memory_plan(&args, &scene, &settings, &mut notes)?) };
    // Decided once, before the render, from the scene and the path depth alone: every figure over unlit pixels
    // (δ, the stop on the target error, the true error) measures the same pixels from the first phase on.
    // It takes as long as some renders through a lens, so the terminal says what is going on meanwhile. Where
    // the workers decide it, each does so once it has built the scene, and the first one's is taken below.
    let own_lit = (!workers_decide_lit).then(|| {
        let deciding = Instant::now();
        let spinner = progress_bar(args.quiet);
        spinner.set_message("finding the pixels that see a light (δ unlit leaves them out)");
        let lit = Arc::new(LitMask::of_scene(&scene, settings.max_depth));
        spinner.finish_and_clear();
        (lit, deciding.elapsed().as_secs_f64())
    });
    if distributed && !scene.is_released() {
        // The workers trace; this process merges and saves. The mesh and its BVH are let go before the workers
        // load their own.
        scene.release_geometry();
    }
    let MemoryPlan { threads, estimate: memory_estimate } = match plan {
        Some(plan) => plan,
        None => memory_plan(&args, &scene, &settings, &mut notes)?,
    };
    if let (Some(c), Some(sums), Some(from)) = (&checkpoint, &resumed_sums, &args.resume) {
        check_resume_has_work(c, sums, &stop, args.uniform, from, own_lit.as_ref().map(|(l, _)| &**l))?;
    }
    let dir = output_dir(&args)?;
    let interrupted = catch_interrupts()?;
    let bar = progress_bar(args.quiet);

    if stop.target_error.is_some() && !args.uniform && sensor_ghosts_keep_tiles(&args, &scene) {
        notes.push(TILES_OFF_FOR_SENSOR_GHOSTS.to_string());
    }
    let session = checkpoint.as_ref().map_or(1, |c| c.session + 1);
    let recorder = start_ray_map(&args, &scene, &settings, &dir, session)?;
    let (mut engine, layout) = start_engine(
        &args,
        &scene,
        settings,
        &dir,
        checkpoint.as_ref().zip(resumed_sums.take()),
        recorder.clone(),
        threads,
    )?;
    if distributed {
        // The run's clock, and `--time`, start when the first worker renders: a large scene takes its workers a
        // while to receive and load, which is not rendering time.
        bar.set_message("the workers are loading the scene");
        engine.wait_until_rendering(&interrupted);
    }
    // The worker deciding the mask sent it before it began, and the clock waited for it. Without one (that
    // worker failed, or the run was interrupted first) δ unlit is δ over every pixel, and the record says so.
    let (lit, lit_seconds) = match own_lit.or_else(|| engine.take_lit_mask().map(|(m, s)| (Arc::new(m), s))) {
        Some((lit, seconds)) => (lit, Some(seconds)),
        None => {
            if workers_decide_lit && !interrupted.load(Ordering::Relaxed) {
                notes.push(NO_LIT_MASK.to_string());
            }
            (Arc::new(LitMask::none(scene.camera.width, scene.camera.height)), None)
        }
    };
    if let (Some(c), Some(from), true) = (&checkpoint, &args.resume, workers_decide_lit) {
        // What the resumed sums lack against a target error is known once a worker decided the mask.
        check_resume_has_work(c, engine.sums(), &stop, args.uniform, from, Some(&lit))?;
    }
    let mut live =
        LiveSession::start(live_options(&args, &scene, &layout, &dir, engine.as_ref(), &interrupted, &lit)?)?;
    if let Some(url) = live.as_ref().and_then(|l| l.url.as_ref()) {
        say!("live page: {url}  (results in {})", dir.display());
    }
    let outputs = Outputs {
        args: &args,
        scene: &scene,
        dir: &dir,
        layout,
        reference: reference.as_ref(),
        lit: &lit,
        lit_seconds,
        scene_load_s,
        bvh_cache,
        stop: &stop,
        notes,
        memory_estimate,
        session,
        elapsed_before: Duration::from_secs_f64(checkpoint.as_ref().map_or(0.0, |c| c.elapsed_s)),
        launched,
        start: Instant::now(),
        stopping: Arc::new(AtomicBool::new(false)),
    };
    let mut history = checkpoint.map(|c| c.history).unwrap_or_default();
    let mut feed = live.as_mut().map(|l| &mut l.feed);
    let mut forecast = Forecast::new(stop.target_error);
    let mut tiles = adaptive_tiles(&args, &scene, &stop)?;
    let mut saving = None;
    let run = run_until_stop(
        engine.as_mut(),
        &interrupted,
        &outputs,
        &bar,
        &mut history,
        (&mut forecast, tiles.as_mut()),
        (feed.as_deref_mut(), &mut saving),
    );
    outputs.stopping.store(true, Ordering::Relaxed);
    bar.set_message("stopping: collecting the last completed phases");
    if let Some(f) = feed.as_deref_mut() {
        f.stopping(engine.as_ref(), &history, outputs.elapsed_s());
    }
    finish(engine.as_mut(), &outputs, &mut history, &mut forecast);
    bar.finish_and_clear();
    // After the engine's finish: every worker has sent its last portions.
    let ray_map = recorder.map(|r| r.finish().map(|s| (r.path().map(Path::to_path_buf), s)));
    // A periodic save still writing from its copy of the sums (distributed runs) ends before the final save,
    // which it must not overwrite; the workers were stopped and their last snapshots merged meanwhile, so the
    // rendering ended on time however long that save takes.
    let mut save_error = None;
    join_save(&mut saving, &mut save_error);
    let reason = run
        .and_then(|r| save_error.map_or(Ok(r), Err))
        .context("writing the periodic results failed; the run was stopped")?;
    if reason == StopReason::NoWorkers && engine.sums().pixels.iter().all(|p| p.phases == 0) {
        let why: Vec<String> =
            engine.workers().unwrap_or_default().iter().map(|w| format!("{}: {}", w.name, w.state)).collect();
        bail!("no worker rendered anything ({})", why.join("; "));
    }
    let record = outputs.save(engine.as_ref(), &history, reason, &forecast)?;
    if let Some(f) = feed {
        f.finished(engine.as_ref(), &record);
    }
    print_summary(&record, reason, &dir);
    if let Some(m) = ray_map {
        let (file, s) = m.context("the ray map is incomplete (the image and record were written)")?;
        say!(
            "ray map: {} paths, {} segments, {:.1} MB ({:.1} bytes per segment before compression, {:.1} after) in {}",
            s.paths,
            s.segments,
            s.file_bytes as f64 / 1e6,
            s.raw_bytes as f64 / s.segments.max(1) as f64,
            s.file_bytes as f64 / s.segments.max(1) as f64,
            file.map_or_else(|| "the map".to_string(), |f| f.display().to_string())
        );
        if s.dropped_portions > 0 {
            eprintln!(
                "note: the ray map lacks {} of the workers' portions ({} paths): the disk fell too far behind them",
                s.dropped_portions, s.dropped_paths
            );
        }
    }
    if live.as_ref().is_some_and(|l| l.url.is_some()) {
        std::thread::sleep(Duration::from_secs_f64(args.serve_linger));
    }
    Ok(())
}

/// What the live view shows the run on (`--serve`, `--display`), with the run's settings for the page.
fn live_options(
    args: &RenderArgs,
    scene: &Scene,
    layout: &str,
    dir: &Path,
    engine: &dyn Progressive,
    interrupted: &Arc<AtomicBool>,
    lit: &Arc<LitMask>,
) -> Result<LiveOptions> {
    if !(args.serve_linger.is_finite() && args.serve_linger >= 0.0) {
        bail!("--serve-linger must be a number of seconds, 0 or more");
    }
    let serve = match args.serve {
        Some(addr) => {
            let secret = match &args.secret_file {
                Some(f) => Some(Secret::from_file(f)?),
                None => Secret::from_env()?,
            };
            Some((addr, secret))
        }
        None => None,
    };
    let settings = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "width": scene.camera.width,
        "height": scene.camera.height,
        "method": args.method.name(),
        "layout": layout,
        "seed": args.seed,
        "output_folder": dir.display().to_string(),
        "reference": args.reference.as_ref().map(|p| p.display().to_string()),
        "stop": {
            "time_s": args.time,
            "phases": args.phases,
            "target_error": args.target_error,
            "error_over": format!("{:?}", args.error_over).to_lowercase(),
        },
        "save_interval_s": args.save_interval,
        "settings": engine.settings(),
    });
    let sums = engine.sums();
    Ok(LiveOptions {
        serve,
        tev: args.display.as_ref().map(|Display::Tev(address)| address.clone()),
        image: (sums.width, sums.height, sums.aux.layout().clone()),
        lit: lit.clone(),
        settings,
        dir: dir.to_path_buf(),
        interrupted: interrupted.clone(),
    })
}

/// Refuses options that the method does not take.
fn check_method_options(args: &RenderArgs) -> Result<()> {
    let layout = args.method.layout();
    let in_process_parallel = layout.processes == Processes::One && layout.parallel.is_some();
    if !in_process_parallel && (args.threads.is_some() || args.cores.is_some()) {
        if args.method.is_distributed() {
            bail!("--threads and --cores apply to the in-process methods; combination and three-level take their cores from the NUMA nodes (see --topology)");
        }
        bail!("--threads and --cores apply to the parallel methods (sync, async, two-level); pbpm and path run on one thread");
    }
    if !args.method.is_distributed()
        && (!args.workers.is_empty() || args.listen.is_some() || args.remote_only || args.topology.is_some())
    {
        bail!("--worker, --listen, --remote-only and --topology apply to --method combination and three-level");
    }
    Ok(())
}

/// The scene's settings for the method, with the command line's overrides.
fn settings_of(args: &RenderArgs, scene: &Scene) -> Result<RenderSettings> {
    let mut settings = RenderSettings::for_scene(scene, args.method, args.seed);
    if let Some(d) = args.max_depth {
        if d == 0 {
            bail!("--max-depth must be at least 1");
        }
        settings.max_depth = d;
    }
    if let Some(d) = args.backward_diffuse_depth {
        if !(1..=2).contains(&d) {
            bail!("--backward-diffuse-depth must be 1 or 2");
        }
        settings.backward_diffuse_depth = d;
        settings.adaptive_depth = false;
    }
    if let Some(r) = args.radius_scale {
        if !(r.is_finite() && r > 0.0) {
            bail!("--radius-scale must be a positive number");
        }
        settings.radius_scale = r;
    }
    if let Some(l) = args.light_paths_per_pixel {
        if !(l.is_finite() && l > 0.0) {
            bail!("--light-paths-per-pixel must be a positive number");
        }
        settings.light_paths_per_pixel = l;
        settings.adaptive_light = false;
    }
    if let Some(n) = args.spectral_output {
        if !photonfarm::spectrum::ENABLED {
            bail!("--spectral-output needs spectral rendering, which this build leaves out (built without the `spectral` feature)");
        }
        if !(1..=photonfarm::spectrum::MAX_BANDS).contains(&n) {
            bail!(
                "--spectral-output must be between 1 and {} bands (1 nm each at most)",
                photonfarm::spectrum::MAX_BANDS
            );
        }
        settings.spectral_bands = n;
    }
    Ok(settings)
}

/// The checkpoint `--resume` continues from and its sums, checked against the method, the options and the scene.
fn load_checkpoint(args: &RenderArgs, scene: &Scene) -> Result<Option<(Checkpoint, Accumulator)>> {
    let Some(from) = &args.resume else { return Ok(None) };
    if !args.method.is_distributed() {
        bail!("--resume continues combination and three-level runs; --method {} has no checkpoint", args.method);
    }
    if args.max_depth.is_some()
        || args.backward_diffuse_depth.is_some()
        || args.radius_scale.is_some()
        || args.light_paths_per_pixel.is_some()
        || args.spectral_output.is_some()
    {
        bail!("a resumed run keeps the settings of its checkpoint: drop --max-depth, --backward-diffuse-depth, --radius-scale, --light-paths-per-pixel and --spectral-output");
    }
    let (_, path) = resume_paths(from);
    let (c, sums) = Checkpoint::load(&path, scene)?;
    if c.method != args.method {
        bail!(
            "the checkpoint in {} is of a --method {} run, and --method {} cannot continue it (three-level is the \
             default when --method is not given): resume it with --method {}",
            from.display(),
            c.method,
            args.method,
            c.method
        );
    }
    Ok(Some((c, sums)))
}

/// The output folder of the run `--resume` names and the checkpoint file it continues from: FROM/checkpoint.bin,
/// or FROM itself when it is a file (`checkpoint-previous.bin`), in its folder.
fn resume_paths(from: &Path) -> (PathBuf, PathBuf) {
    if from.is_file() {
        let dir = from.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        (dir.to_path_buf(), from.to_path_buf())
    } else {
        (from.to_path_buf(), from.join(CHECKPOINT))
    }
}

/// Refuses to resume a run whose checkpoint already meets the stop rule: starting workers only to stop them at
/// once would add nothing and say nothing about why.
fn check_resume_has_work(
    c: &Checkpoint,
    sums: &Accumulator,
    stop: &StopRule,
    args_uniform: bool,
    from: &Path,
    lit: Option<&LitMask>,
) -> Result<()> {
    let place = from.display();
    if let Some(t) = stop.time {
        if c.elapsed_s >= t.as_secs_f64() {
            bail!(
                "the checkpoint in {place} already has {:.1} s of rendering, which meets --time {}: nothing to \
                render. Ask for more time than that (e.g. --time {:.0}) or another stop rule",
                c.elapsed_s,
                t.as_secs_f64(),
                (c.elapsed_s + t.as_secs_f64()).ceil()
            );
        }
    }
    if let Some(n) = stop.phases {
        // The run's adaptive tiles (a target without --uniform) count the pixels' mean phases.
        let adaptive = stop.target_error.is_some() && !args_uniform;
        let done = stop.phases_done(sums, adaptive);
        if done >= n as f64 {
            let counted = if adaptive { "on average over the pixels" } else { "in every pixel" };
            bail!(
                "the checkpoint in {place} already has {done:.0} phases {counted}, which meets --phases {n}: \
                nothing to render. Ask for more phases than that"
            );
        }
    }
    // A target error is checked once the mask is known.
    if let (Some(target), Some(lit)) = (stop.target_error, lit) {
        let e = sums.error(lit);
        let (d, over) = match stop.error_over {
            ErrorOver::Unlit => (e.delta_unlit, "unlit pixels"),
            ErrorOver::All => (e.delta_all, "all pixels"),
        };
        if d <= target {
            bail!(
                "the checkpoint in {place} already has δ {:.2}% ({over}), which meets --target-error {target}: \
                nothing to render. Ask for a smaller target",
                100.0 * d
            );
        }
    }
    Ok(())
}

/// The output folder (`--out`, the resumed run's, or a new one under out/), created.
fn output_dir(args: &RenderArgs) -> Result<PathBuf> {
    let dir = args
        .out
        .clone()
        .or_else(|| args.resume.as_deref().map(|r| resume_paths(r).0))
        .unwrap_or_else(|| output_folder::default_dir(&args.scene));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    Ok(dir)
}

/// A flag that Ctrl-C sets, so the run stops after its current phase and writes what it has.
fn catch_interrupts() -> Result<Arc<AtomicBool>> {
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    // A second Ctrl-C while results are being written still ends the process.
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(interrupted)
}

fn progress_bar(quiet: bool) -> ProgressBar {
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
    bar.set_style(ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}").expect("static template"));
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// The ray map recorder `--ray-map` asks for, writing into raymap/ of the output folder: stream 0, or for a
/// resumed run stream `session − 1`, so that every session's paths stay in the map.
fn start_ray_map(
    args: &RenderArgs,
    scene: &Scene,
    settings: &RenderSettings,
    dir: &Path,
    session: u32,
) -> Result<Option<Arc<Recorder>>> {
    if !args.ray_map {
        return Ok(None);
    }
    // A path has at most max_depth segments and one origin.
    if settings.max_depth as usize >= ray_map::format::MAX_VERTICES {
        bail!(
            "--ray-map stores paths of fewer than {} segments; max_depth is {}",
            ray_map::format::MAX_VERTICES,
            settings.max_depth
        );
    }
    let header =
        ray_map::header_for(scene, args.method.name(), args.seed, args.ray_map_fraction, session.saturating_sub(1));
    let recorder = Recorder::create(&dir.join("raymap"), &header)?;
    Ok(Some(Arc::new(recorder)))
}

/// Starts the method's engine, as its table row says: worker processes, the single-threaded engine, or a
/// parallel engine in this process. Returns it with its layout in words.
fn start_engine<'s>(
    args: &RenderArgs,
    scene: &'s Scene,
    settings: RenderSettings,
    dir: &Path,
    checkpoint: Option<(&Checkpoint, Accumulator)>,
    recorder: Option<Arc<Recorder>>,
    threads: Option<usize>,
) -> Result<(Box<dyn Progressive + 's>, String)> {
    let layout = args.method.layout();
    match (layout.processes, layout.parallel) {
        (Processes::PerNumaNode, _) => {
            let resume = checkpoint.map(|(c, sums)| launch::Resume { session: c.session + 1, sums, totals: c.totals });
            let (cluster, layout) = launch::launch(&launch_options(args), scene, settings, dir, resume, recorder)?;
            Ok((Box::new(cluster), layout))
        }
        (Processes::One, None) => {
            let base = memory::current_rss_bytes().unwrap_or(0);
            let budget = MemoryBudget::new(args.memory_limit);
            let mut engine = Engine::new(scene, settings);
            if scene.camera.pixel_count() > CAPPED_PHASE_PIXELS {
                engine.set_phase_cap(CAPPED_PHASE_PIXELS, DEFAULT_TILE);
            }
            if let Some(budget) = budget {
                // The engine's buffers are sized once, for the whole image: what it holds now is what it needs.
                let need = base + (engine.bytes_per_pixel() * scene.camera.pixel_count() as f64) as u64;
                if need > budget.bytes() {
                    bail!("{}", memory::over_limit(budget, need, base, ""));
                }
            }
            engine.set_recorder(recorder);
            Ok((Box::new(engine), "1 thread".to_string()))
        }
        (Processes::One, Some(method)) => {
            let cores = cores_of(args)?;
            let threads = threads.unwrap_or_else(|| args.threads.unwrap_or(cores.len()));
            let mut config = EngineConfig::for_method(method, threads, args.group_size, cores)?;
            if let Some(t) = args.tile_size {
                config.tile_size = t;
            }
            config.phases_per_deal = args.phases_per_deal;
            let layout = config.layout();
            let mut engine = ParallelEngine::new(scene, settings, config)?;
            engine.set_recorder(recorder);
            Ok((Box::new(engine), layout))
        }
    }
}

/// The tile edge of an adaptive run: with a target error, unless `--uniform`, `--adaptive-tile`'s, else
/// `--tile-size`'s, by default the masks' 32 pixels. A scene whose light paths register ghosts on its sensor
/// renders every tile unless `--adaptive-tile` is given (`sensor_ghosts_keep_tiles`).
fn adaptive_tile_edge(args: &RenderArgs, scene: &Scene, stop: &StopRule) -> Option<u32> {
    if stop.target_error.is_none() || args.uniform || sensor_ghosts_keep_tiles(args, scene) {
        return None;
    }
    Some(args.adaptive_tile.or(args.tile_size).unwrap_or(DEFAULT_TILE))
}

/// True when `scene`'s light paths register ghosts on its sensor and `--adaptive-tile` does not ask for tiles
/// anyway: every tile then renders every round.
fn sensor_ghosts_keep_tiles(args: &RenderArgs, scene: &Scene) -> bool {
    args.adaptive_tile.is_none() && sensor_ghosts(scene)
}

/// What the record says when the worker deciding the lit mask ended before it did.
const NO_LIT_MASK: &str = "the worker deciding the lit mask ended before it did: δ unlit and the error over \
     unlit pixels are over every pixel";

/// Why a run with a target error renders every tile of a scene whose light paths register ghosts on its sensor.
const TILES_OFF_FOR_SENSOR_GHOSTS: &str = "adaptive tiles are off: this scene's light paths register its \
    ghosts on the sensor, a round's light paths shrink with the tiles it renders, and once tiles retire the \
    others get fewer ghost registrations per phase, which slows the run (--adaptive-tile PX turns tiles on)";

/// The tiles of an adaptive run (`adaptive_tile_edge`), every one active.
fn adaptive_tiles(args: &RenderArgs, scene: &Scene, stop: &StopRule) -> Result<Option<ActiveTiles>> {
    let Some(tile) = adaptive_tile_edge(args, scene, stop) else { return Ok(None) };
    Ok(Some(
        ActiveTiles::all(scene.camera.width, scene.camera.height, tile)
            .map_err(|e| anyhow::anyhow!("--adaptive-tile / --tile-size: {e}"))?,
    ))
}

/// How the command line imports a Mitsuba scene.
fn mitsuba_options(args: &RenderArgs) -> MitsubaOptions {
    MitsubaOptions { defines: args.defines.clone(), approximate: args.approximate }
}

/// What the launcher of worker processes takes from the command line.
fn launch_options(args: &RenderArgs) -> LaunchOptions {
    LaunchOptions {
        method: args.method,
        scene_path: args.scene.clone(),
        topology: args.topology.clone(),
        remote_workers: args.workers.clone(),
        listen: args.listen,
        remote_only: args.remote_only,
        secret_file: args.secret_file.clone(),
        insecure: args.insecure,
        tls_dir: args.tls_dir.clone(),
        worker_timeout_s: args.worker_timeout,
        max_worker_failures: args.max_worker_failures,
        snapshot_interval_s: args.snapshot_interval,
        group_size: args.group_size,
        tile_size: args.tile_size,
        phases_per_deal: args.phases_per_deal,
        ray_map_fraction: args.ray_map.then_some(args.ray_map_fraction),
        memory_limit: args.memory_limit,
    }
}

/// Everything the outputs are written from besides the engine and its history.
struct Outputs<'a> {
    args: &'a RenderArgs,
    scene: &'a Scene,
    dir: &'a Path,
    /// The engine's layout in words.
    layout: String,
    reference: Option<&'a Reference>,
    /// The pixels that see a light, decided before the render (here or by the first worker), and the seconds
    /// that took; None when no worker got as far as deciding it.
    lit: &'a LitMask,
    lit_seconds: Option<f64>,
    /// Seconds this process took to read and build the scene.
    scene_load_s: f64,
    /// What the BVH cache did for this process's scene, when it built a BVH.
    bvh_cache: Option<BvhCacheUse>,
    /// The stop rule, whose δ the forecast follows.
    stop: &'a StopRule,
    /// What the run changed from what it was asked (flags of the record).
    notes: Vec<String>,
    /// This process's peak memory as estimated before it allocated (`memory_plan`).
    memory_estimate: u64,
    /// This session of the run (1 unless resumed).
    session: u32,
    /// Rendering time of the earlier sessions.
    elapsed_before: Duration,
    /// When the command started, and when this session's rendering did.
    launched: Instant,
    start: Instant,
    /// Set once the run has stopped: a periodic save still under way abandons what it has left, which the
    /// final save writes anyway, and lets the sums go.
    stopping: Arc<AtomicBool>,
}

impl Outputs<'_> {
    /// Rendering time of every session so far, seconds.
    fn elapsed_s(&self) -> f64 {
        self.elapsed_before.as_secs_f64() + self.start.elapsed().as_secs_f64()
    }

    fn record(
        &self,
        engine: &dyn Progressive,
        history: &[HistoryEntry],
        reason: StopReason,
        forecast: &Forecast,
    ) -> RunRecord {
        let workers = engine.workers();
        let dropped = photonfarm::accumulation::non_finite_dropped()
            + workers.iter().flatten().map(|w| w.non_finite_dropped).sum::<u64>();
        let scene = self.scene;
        RunRecord {
            photonfarm_version: env!("CARGO_PKG_VERSION").to_string(),
            scene: self.args.scene.display().to_string(),
            scene_hash: scene.hash.clone(),
            width: scene.camera.width,
            height: scene.camera.height,
            method: self.args.method,
            layout: self.layout.clone(),
            pinned_threads: engine.pinned_threads(),
            settings: engine.settings().as_recorded(),
            radius_at_1m: engine.settings().radius_schedule(scene).radius(1.0, 1),
            threads: engine.threads() as u32,
            stop_reason: reason,
            totals: engine.totals(),
            stage_seconds: engine.stage_seconds(),
            wall_time_s: self.elapsed_s(),
            started_s: Some(self.start.duration_since(self.launched).as_secs_f64()),
            scene_load_s: Some(self.scene_load_s),
            bvh_cache: self.bvh_cache.clone(),
            peak_memory_bytes: memory::peak_rss_bytes(),
            memory_estimate_bytes: Some(self.memory_estimate),
            bytes_per_pixel: engine.bytes_per_pixel(),
            error: engine.sums().error(self.lit),
            lit_mask: self.lit_seconds.map(|s| self.lit.record(s)),
            adaptive_tile: adaptive_tile_edge(self.args, self.scene, self.stop),
            forecast: forecast.record(),
            pixel_phases: engine.sums().pixels.iter().map(|p| p.phases as u64).sum(),
            session: self.session,
            true_error: self.reference.map(|r| r.compare(engine.sums(), self.lit)),
            history: history.to_vec(),
            flags: scene
                .notes
                .iter()
                .map(|n| format!("scene import: {n}"))
                .chain(self.notes.iter().cloned())
                .chain(flags_of(&engine.totals(), dropped, workers.as_deref()))
                .collect(),
            workers,
        }
    }

    /// Writes the checkpoint (distributed methods), the image and the record: the run's final save, whose
    /// record's wall time includes the checkpoint.
    fn save(
        &self,
        engine: &dyn Progressive,
        history: &[HistoryEntry],
        reason: StopReason,
        forecast: &Forecast,
    ) -> Result<RunRecord> {
        write_checkpoint(self.dir, engine.sums(), self.checkpoint_inputs(engine, history), None)?;
        let record = self.record(engine, history, reason, forecast);
        output_folder::save(self.dir, engine.sums(), self.lit, &record, || Ok(()))?;
        Ok(record)
    }

    /// `save` on a thread of its own, reading the sums the engine shares (`Progressive::shared_sums`, which
    /// holds its merges back meanwhile rather than copy a large image), or a copy of them: encoding a large
    /// image's checkpoint and EXR takes seconds, which would hold back receiving the workers' snapshots and
    /// acknowledging them (which paces their snapshot interval).
    fn save_in_background(
        &self,
        engine: &dyn Progressive,
        history: &[HistoryEntry],
        forecast: &Forecast,
    ) -> std::io::Result<std::thread::JoinHandle<Result<()>>> {
        let record = self.record(engine, history, StopReason::Running, forecast);
        let checkpoint = self.checkpoint_inputs(engine, history);
        let sums = engine.shared_sums().unwrap_or_else(|| Arc::new(engine.sums().clone()));
        let (dir, lit, stopping) = (self.dir.to_path_buf(), self.lit.clone(), self.stopping.clone());
        std::thread::Builder::new()
            .name("save".into())
            .spawn(move || save_periodically(&dir, sums, &lit, &record, checkpoint, &stopping))
    }

    /// What a checkpoint of this moment holds besides the sums (distributed methods only).
    fn checkpoint_inputs(&self, engine: &dyn Progressive, history: &[HistoryEntry]) -> Option<CheckpointInputs> {
        self.args.method.is_distributed().then(|| CheckpointInputs {
            scene_hash: self.scene.hash.clone(),
            method: self.args.method,
            settings: *engine.settings(),
            session: self.session,
            elapsed_s: self.elapsed_s(),
            totals: engine.totals(),
            history: history.to_vec(),
        })
    }
}

/// A checkpoint's fields besides the sums, taken when a save starts.
struct CheckpointInputs {
    scene_hash: String,
    method: Method,
    settings: RenderSettings,
    session: u32,
    elapsed_s: f64,
    totals: photonfarm::render::RayTotals,
    history: Vec<HistoryEntry>,
}

/// A periodic save on a thread of its own: the preview first (what a user waits for), then the checkpoint (what
/// a resumed run needs), then the image, its layers made from the shared sums as it is compressed, and the
/// record. Merges wait for all of it (on a 4K image, seconds): making the EXR's f32 layers first, to let the
/// sums go before the compression, would hold about 130 bytes a pixel more at the run's peak. Once the run
/// stops, what is left of the save is abandoned, as the final save writes everything again.
fn save_periodically(
    dir: &Path,
    sums: Arc<Accumulator>,
    lit: &LitMask,
    record: &RunRecord,
    checkpoint: Option<CheckpointInputs>,
    stopping: &AtomicBool,
) -> Result<()> {
    let stopped = || stopping.load(Ordering::Relaxed);
    output_folder::write_preview(dir, &sums)?;
    if stopped() {
        return Ok(());
    }
    match write_checkpoint(dir, &sums, checkpoint, Some(stopping)) {
        Err(CheckpointError::Abandoned { .. }) => return Ok(()),
        written => written?,
    }
    if stopped() {
        return Ok(());
    }
    // The workers render meanwhile: one thread.
    let compressing = photonfarm::image_io::exr_file::Compressing::OnThisThread;
    output_folder::write_image_and_record(dir, &sums, lit, record, compressing, Some(stopping))?;
    Ok(())
}

fn write_checkpoint(
    dir: &Path,
    sums: &Accumulator,
    checkpoint: Option<CheckpointInputs>,
    periodic_until: Option<&AtomicBool>,
) -> Result<(), CheckpointError> {
    if let Some(c) = checkpoint {
        let c =
            Checkpoint::new(sums, &c.scene_hash, c.method, c.settings, c.session, c.elapsed_s, c.totals, &c.history);
        let path = dir.join(CHECKPOINT);
        match periodic_until {
            Some(stop) => c.save_unless(&path, sums, stop)?,
            None => c.save(&path, sums)?,
        }
    }
    Ok(())
}

/// Waits for the save under way, if any, and keeps its error unless one came before.
fn join_save(saving: &mut Saving, save_error: &mut Option<anyhow::Error>) {
    if let Some(h) = saving.take() {
        let done = h.join().unwrap_or_else(|_| Err(anyhow::anyhow!("the thread saving the outputs panicked")));
        if let Err(e) = done {
            save_error.get_or_insert(e);
        }
    }
}

/// A periodic save writing on a thread of its own (distributed methods).
type Saving = Option<std::thread::JoinHandle<Result<()>>>;

/// Runs the engine until the stop rule or Ctrl-C, showing progress and refreshing the outputs every
/// `--save-interval`. A refresh that fails stops the run, and is the error returned; a refresh still under way at
/// the stop is left in `saving` for the caller to join once the engine has finished.
fn run_until_stop(
    engine: &mut dyn Progressive,
    interrupted: &AtomicBool,
    outputs: &Outputs,
    bar: &ProgressBar,
    history: &mut Vec<HistoryEntry>,
    (forecast, tiles): (&mut Forecast, Option<&mut ActiveTiles>),
    (mut feed, saving): (Option<&mut LiveFeed>, &mut Saving),
) -> Result<StopReason> {
    let save_interval = Duration::from_secs_f64(outputs.args.save_interval.max(0.5));
    // The first step is saved at once: on a large image it comes a phase or so into the run, and the preview
    // and δ should not wait a whole interval more. `last_save` is when the latest save ended.
    let mut last_save: Option<Instant> = None;
    let mut save_error: Option<anyhow::Error> = None;
    // A save falls due only once the previous one (`saving`: distributed methods, whose engine is the workers)
    // has ended, and the interval after it is at least as long as it took: merges (distributed) or the
    // engine (in-process) wait while a save reads the sums, which on a large image takes seconds, and get at
    // least half the time. How long the latest save took also keeps a timed run from starting one that would
    // still be writing at its end, where the final save waits for it.
    let (mut save_started, mut save_took) = (Instant::now(), Duration::ZERO);
    let stop = outputs.stop;
    let tracking = Tracking { lit: outputs.lit, forecast, elapsed_before: outputs.elapsed_before, tiles };
    let reason = session::run(engine, stop, interrupted, history, tracking, |engine, history, forecast| {
        let Some(entry) = history.last_mut() else { return };
        if let Some(r) = outputs.reference {
            let t = r.compare(engine.sums(), outputs.lit);
            (entry.true_all, entry.true_unlit) = (Some(t.rmse_all), Some(t.rmse_unlit));
        }
        bar.set_message(progress(entry, stop.error_over, forecast, engine.workers().as_deref()));
        if let Some(f) = feed.as_deref_mut() {
            f.after_merge(engine, history, outputs.elapsed_s(), forecast.latest());
        }
        // A step that ends at the deadline is saved by the run's final save, which follows at once.
        let over = stop.time.is_some_and(|t| outputs.elapsed_s() >= t.as_secs_f64());
        if saving.as_ref().is_some_and(|h| h.is_finished()) {
            join_save(saving, &mut save_error);
            save_took = save_started.elapsed();
            last_save = Some(Instant::now());
        }
        let due = last_save.is_none_or(|t| t.elapsed() >= save_interval.max(save_took));
        let ends_in_time = stop.time.is_none_or(|t| outputs.elapsed_s() + save_took.as_secs_f64() < t.as_secs_f64());
        if !over && due && ends_in_time && saving.is_none() && save_error.is_none() {
            save_started = Instant::now();
            if outputs.args.method.is_distributed() {
                match outputs.save_in_background(engine, history, forecast) {
                    Ok(h) => *saving = Some(h),
                    Err(e) => {
                        save_error = Some(anyhow::Error::new(e).context("cannot start the thread saving the outputs"))
                    }
                }
            } else {
                // An engine in this process renders only between steps, so a save here holds back no merging,
                // and a copy of its sums would be memory that --memory-limit's estimate does not count.
                save_error = outputs.save(engine, history, StopReason::Running, forecast).err();
                save_took = save_started.elapsed();
                last_save = Some(Instant::now());
            }
        }
    });
    match save_error {
        Some(e) => Err(e),
        None => Ok(reason),
    }
}

/// The progress line after a step: phases, ray rate, δ, the time still needed to reach a target error, and the
/// workers' states.
fn progress(
    entry: &HistoryEntry,
    error_over: ErrorOver,
    forecast: &Forecast,
    workers: Option<&[WorkerRecord]>,
) -> String {
    let secs = entry.time_s.max(1e-9);
    let rays = (entry.backward_rays + entry.forward_rays) as f64;
    let (delta, blur) = match error_over {
        ErrorOver::Unlit => (entry.delta_unlit, entry.blur_unlit),
        ErrorOver::All => (entry.delta_all, entry.blur_all),
    };
    let workers = workers.map(|w| {
        let count = |p: &dyn Fn(&WorkerState) -> bool| w.iter().filter(|w| p(&w.state)).count();
        format!(
            "  workers: {} running, {} connecting, {} finished, {} lost",
            count(&|s| *s == WorkerState::Running),
            count(&|s| *s == WorkerState::Connecting),
            count(&|s| *s == WorkerState::Finished),
            count(&|s| matches!(s, WorkerState::Lost(_))),
        )
    });
    let left = forecast.latest().map(|f| format!("  about {} to the target", short_duration(f.remaining_s)));
    format!(
        "phase {}  {:.2} Mrays/s  δ {} ({}{}){}{}",
        entry.phase,
        rays / secs / 1e6,
        if delta.is_finite() { format!("{:.2}%", 100.0 * delta) } else { "–".to_string() },
        if error_over == ErrorOver::Unlit { "unlit pixels" } else { "all pixels" },
        // The blur's part only once it is a visible share of δ: elsewhere it is its estimate's noise.
        if delta.is_finite() && blur > 0.1 * delta { format!(", blur {:.2}%", 100.0 * blur) } else { String::new() },
        left.unwrap_or_default(),
        workers.unwrap_or_default(),
    )
}

/// Seconds as "42 s", "3 min 20 s" or "2 h 05 min".
fn short_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..=99 => format!("{s} s"),
        100..=5999 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, s / 60 % 60),
    }
}

/// Stops the engine. Worker processes send their last snapshots only now: one more history entry for them,
/// timed when they were merged.
fn finish(engine: &mut dyn Progressive, outputs: &Outputs, history: &mut Vec<HistoryEntry>, forecast: &mut Forecast) {
    engine.finish();
    if !outputs.args.method.is_distributed() {
        return;
    }
    let ended_s = outputs.elapsed_s();
    let e = engine.sums().error(outputs.lit);
    forecast.step(ended_s, engine.sums().image_phases(), outputs.stop.delta_of(&e));
    let s = engine.settings();
    let light = (!s.adaptive_light).then_some(s.light_paths_per_pixel);
    let depth = (!s.adaptive_depth).then_some(s.backward_diffuse_depth);
    let tiles = history.last().and_then(|h| h.active_tiles);
    let mut entry = HistoryEntry::after_step(ended_s, &e, &engine.totals(), light, depth, tiles);
    if let Some(truth) = outputs.reference.map(|r| r.compare(engine.sums(), outputs.lit)) {
        (entry.true_all, entry.true_unlit) = (Some(truth.rmse_all), Some(truth.rmse_unlit));
    }
    history.push(entry);
}

fn print_summary(record: &RunRecord, reason: StopReason, dir: &Path) {
    let e = record.error;
    say!(
        "{} phases in {:.1} s ({}), {:.2} M backward + {:.2} M forward rays, δ {:.2}% (unlit pixels) / {:.2}% (all \
         pixels), the photon discs' blur {:.2}% / {:.2}% of it (in quadrature)",
        record.totals.phases,
        record.wall_time_s,
        reason.name(),
        record.totals.backward_rays as f64 / 1e6,
        record.totals.forward_rays as f64 / 1e6,
        100.0 * e.delta_unlit,
        100.0 * e.delta_all,
        100.0 * e.blur_unlit,
        100.0 * e.blur_all
    );
    for flag in &record.flags {
        eprintln!("note: {flag}");
    }
    if let Some(t) = &record.true_error {
        say!(
            "true relative RMSE against {}: {:.2}% (unlit pixels) / {:.2}% (all pixels)",
            t.reference,
            100.0 * t.rmse_unlit,
            100.0 * t.rmse_all
        );
        if let (Some(unlit), Some(all)) = (t.mean_difference_unlit, t.mean_difference_all) {
            say!(
                "mean against the reference: {:+.3}% (unlit pixels) / {:+.3}% (all pixels)",
                100.0 * unlit,
                100.0 * all
            );
        }
    }
    if reason == StopReason::Interrupted {
        say!("interrupted: the results of every completed phase were written");
    }
    say!("wrote {}", dir.display());
}

/// The cores an in-process parallel method runs on: `--cores`, or all of this machine's.
fn cores_of(args: &RenderArgs) -> Result<Vec<usize>> {
    match &args.cores {
        Some(list) => machine::parse_cores(list).map_err(|e| anyhow::anyhow!("--cores: {e}")),
        None => Ok(machine::all_cores()),
    }
}

/// What `memory_plan` decided: the threads an in-process parallel method runs with (async gives up threads to
/// fit; None: the method's own choice), and this process's estimated peak, kept in the run record.
struct MemoryPlan {
    threads: Option<usize>,
    estimate: u64,
}

/// Checks the render's memory estimate against its budget (`--memory-limit`, or what the machine has available)
/// before anything the image's size scales is allocated.
fn memory_plan(
    args: &RenderArgs,
    scene: &Scene,
    settings: &RenderSettings,
    notes: &mut Vec<String>,
) -> Result<MemoryPlan> {
    let base = memory::current_rss_bytes().unwrap_or(0);
    let pixels = scene.camera.pixel_count();
    let aux = photonfarm::accumulation::AuxLayout::for_scene(scene, settings.spectral_bands);
    let of_pixels = |bytes_per_pixel: f64| base + (bytes_per_pixel * pixels as f64) as u64;
    let layout = args.method.layout();
    match (layout.processes, layout.parallel) {
        (Processes::PerNumaNode, _) => {
            // The coordinator renders nothing, so --memory-limit (per worker process) is not its budget. It
            // holds the merged sums and the lit mask and, at its peak, a snapshot being merged (its frame
            // and the message read from it, then the message and its decompressed delta; a whole image's at
            // most, which zstd bounds by the raw size) and a save (the preview's layer, a checkpoint piece, or a
            // row of each EXR layer, one after the other; merges wait while a save reads the sums). The workers
            // check their own engines when their job arrives.
            // Planned once the scene is held without its geometry: the process's peak may already be behind it
            // (reading the scene, and building it where this process decides the lit mask).
            let sums = photonfarm::accumulation::Accumulator::bytes_per_pixel(&aux) as u64 * pixels as u64;
            let merge = 2 * photonfarm::accumulation::delta::max_delta_bytes(pixels as u64, &aux);
            let save = (images::SAVE_BYTES_PER_PIXEL as u64 * pixels as u64).max(Checkpoint::max_save_bytes(&aux));
            let need = (base + sums + pixels as u64 + merge + save).max(memory::peak_rss_bytes().unwrap_or(0));
            if let Some(budget) = MemoryBudget::new(None) {
                if need > budget.bytes() {
                    let detail = " in the coordinator, which merges the workers' sums and writes the image from them";
                    bail!("{}", memory::over_limit(budget, need, base, detail));
                }
            }
            Ok(MemoryPlan { threads: None, estimate: need })
        }
        (Processes::One, None) => {
            // The one-thread engine's buffers are a one-group engine's without its grid entries and shared
            // buffers: that engine's estimate bounds them before they exist, and the engine checks its exact
            // size again once it has allocated.
            let depth = if settings.estimator == Estimator::Path { 0 } else { settings.backward_diffuse_depth };
            let one = EngineConfig::for_method(ParallelMethod::Sync, 1, 1, machine::all_cores())?;
            // Its phase buffers are sized for the whole image, even where its phases are capped.
            let need = of_pixels(one.bytes_per_pixel(pixels, pixels, depth, &aux));
            if let Some(budget) = MemoryBudget::new(args.memory_limit) {
                if need > budget.bytes() {
                    bail!("{}", memory::over_limit(budget, need, base, ""));
                }
            }
            Ok(MemoryPlan { threads: None, estimate: need })
        }
        (Processes::One, Some(method)) => {
            let cores = cores_of(args)?;
            let threads = args.threads.unwrap_or(cores.len());
            let need = |t: usize| -> Result<u64> {
                let c = EngineConfig::for_method(method, t, args.group_size, cores.clone())?;
                let round = worker::parallel::engine::max_round_pixels(pixels);
                Ok(of_pixels(c.bytes_per_pixel(pixels, round, settings.backward_diffuse_depth, &aux)))
            };
            let threads = match MemoryBudget::new(args.memory_limit) {
                Some(budget) => fit_memory(budget, method, threads, base, need, notes)?,
                None => threads,
            };
            Ok(MemoryPlan { threads: Some(threads), estimate: need(threads)? })
        }
    }
}

/// The threads an in-process method may use within its memory budget (`--memory-limit` or what the machine has
/// available), where `need(t)` is the memory a run of `t` threads needs (`base` in use now, the scene loaded,
/// plus the engine's buffers). A method whose groups each keep their own image (async) gives up threads to fit,
/// and `notes` says so; the others refuse.
fn fit_memory(
    budget: MemoryBudget,
    method: ParallelMethod,
    threads: usize,
    base: u64,
    need: impl Fn(usize) -> Result<u64>,
    notes: &mut Vec<String>,
) -> Result<usize> {
    let mb = |b: u64| format!("{:.0} MiB", b as f64 / (1u64 << 20) as f64);
    let limit = budget.bytes();
    let asked = need(threads)?;
    if asked <= limit {
        return Ok(threads);
    }
    let grows_with_threads = Method::from(method).layout().images == Images::PerGroup;
    if grows_with_threads {
        if let Some(t) = (1..threads).rev().find(|&t| need(t).is_ok_and(|n| n <= limit)) {
            notes.push(format!(
                "{}: {} needs about {} at {threads} threads (its buffers grow with its threads), so it ran \
                 with {t}",
                budget.describe(),
                method.name(),
                mb(asked)
            ));
            return Ok(t);
        }
    }
    let least = need(if grows_with_threads { 1 } else { threads })?;
    bail!("{}", memory::over_limit(budget, least, base, if grows_with_threads { " even with one thread" } else { "" }))
}

fn stop_rule(args: &RenderArgs) -> Result<StopRule> {
    if let Some(t) = args.time {
        if !(t.is_finite() && t > 0.0) {
            bail!("--time must be a positive number of seconds");
        }
    }
    if args.phases == Some(0) {
        bail!("--phases must be at least 1");
    }
    if let Some(d) = args.target_error {
        if !(d.is_finite() && d > 0.0) {
            bail!("--target-error must be a positive number, e.g. 0.05 for 5%");
        }
    }
    let time = match (args.time, args.phases, args.target_error) {
        (None, None, None) => Some(DEFAULT_TIME_S),
        (t, _, _) => t,
    };
    Ok(StopRule {
        time: time.map(Duration::from_secs_f64),
        phases: args.phases,
        target_error: args.target_error,
        error_over: match args.error_over {
            ErrorOverArg::Unlit => ErrorOver::Unlit,
            ErrorOverArg::All => ErrorOver::All,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Cli, Command};
    use clap::Parser;

    fn render_args(extra: &[&str]) -> RenderArgs {
        let argv = [&["coordinator", "render", "scene.toml"][..], extra].concat();
        let Command::Render(args) = Cli::try_parse_from(argv).unwrap().command else { panic!("not a render") };
        *args
    }

    #[test]
    fn the_progress_line_names_the_blur_once_it_is_a_visible_share_of_delta() {
        let entry = |blur_unlit| HistoryEntry {
            phase: 12,
            time_s: 2.0,
            delta_unlit: 0.08,
            delta_all: 0.02,
            blur_unlit,
            ..HistoryEntry::default()
        };
        let line = |blur| progress(&entry(blur), ErrorOver::Unlit, &Forecast::new(None), None);
        assert!(line(0.05).contains("δ 8.00% (unlit pixels, blur 5.00%)"), "{}", line(0.05));
        assert!(line(0.001).contains("δ 8.00% (unlit pixels)"), "{}", line(0.001));
        let all = progress(&entry(0.05), ErrorOver::All, &Forecast::new(None), None);
        assert!(all.contains("δ 2.00% (all pixels)"), "{all}");
    }

    #[test]
    fn adaptive_tiles_take_their_edge_from_adaptive_tile_then_tile_size_then_the_default_and_only_with_a_target() {
        let scene = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml")).unwrap();
        let tiles = |extra: &[&str]| {
            let args = render_args(extra);
            adaptive_tiles(&args, &scene, &stop_rule(&args).unwrap())
        };
        let target = ["--target-error", "0.05"];
        for (extra, edge) in [
            (&[][..], DEFAULT_TILE),
            (&["--tile-size", "16"][..], 16),
            (&["--tile-size", "16", "--adaptive-tile", "8"][..], 8),
            (&["--adaptive-tile", "8"][..], 8),
        ] {
            let args = render_args(&[&target[..], extra].concat());
            let stop = stop_rule(&args).unwrap();
            assert_eq!(adaptive_tile_edge(&args, &scene, &stop), Some(edge), "{extra:?}");
            let t = adaptive_tiles(&args, &scene, &stop).unwrap().expect("adaptive tiles");
            assert_eq!(t.tile, edge, "{extra:?}");
        }
        assert!(tiles(&["--adaptive-tile", "8"]).unwrap().is_none(), "no target, no adaptive tiles");
        assert!(tiles(&[&target[..], &["--uniform", "--adaptive-tile", "8"]].concat()).unwrap().is_none());
        let e = tiles(&[&target[..], &["--adaptive-tile", "0"]].concat()).unwrap_err().to_string();
        assert!(e.contains("--adaptive-tile"), "{e}");
    }

    #[test]
    fn a_lens_whose_light_paths_register_ghosts_renders_every_tile_unless_adaptive_tile_asks() {
        let lens = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lens.toml")).unwrap();
        assert!(sensor_ghosts(&lens));
        let edge = |extra: &[&str]| {
            let args = render_args(&[&["--target-error", "0.5"][..], extra].concat());
            adaptive_tile_edge(&args, &lens, &stop_rule(&args).unwrap())
        };
        assert_eq!(edge(&[]), None);
        assert_eq!(edge(&["--tile-size", "16"]), None);
        assert_eq!(edge(&["--adaptive-tile", "16"]), Some(16));
    }
}
