//! `coordinator render`: the main job.

use crate::cli::{ErrorOverArg, MethodArg, RenderArgs};
use crate::cluster;
use crate::output_folder::{self, Reference};
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use photonfarm::render::checkpoint::Checkpoint;
use photonfarm::render::record::{flags_of, HistoryEntry, RunRecord};
use photonfarm::render::session::{self, ErrorOver, Progressive, StopReason, StopRule};
use photonfarm::render::{memory, Engine, Method, RenderSettings};
use photonfarm::scene::Scene;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use worker::{machine, EngineConfig, ParallelEngine, ParallelMethod};

const DEFAULT_TIME_S: f64 = 30.0;
/// The checkpoint's file name in the output folder.
const CHECKPOINT: &str = "checkpoint.bin";

pub fn run(args: RenderArgs) -> Result<()> {
    let stop = stop_rule(&args)?;
    let scene = Scene::load(&args.scene)?;
    let method = if args.method == MethodArg::Path { Method::Path } else { Method::Pbpm };
    if parallel_method(args.method).is_none() && (args.threads.is_some() || args.cores.is_some()) {
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
    let mut settings = RenderSettings::for_scene(&scene, method, args.seed);
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
    let reference = match &args.reference {
        Some(p) => Some(Reference::load(p, scene.camera.width, scene.camera.height)?),
        None => None,
    };
    let checkpoint = match &args.resume {
        Some(from) => {
            if !args.method.is_distributed() {
                bail!(
                    "--resume continues combination and three-level runs; --method {method_name_arg} has no checkpoint",
                    method_name_arg =
                        args.method.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()
                );
            }
            if args.max_depth.is_some()
                || args.backward_diffuse_depth.is_some()
                || args.radius_scale.is_some()
                || args.light_paths_per_pixel.is_some()
                || args.spectral_output.is_some()
            {
                bail!("a resumed run keeps the settings of its checkpoint: drop --max-depth, --backward-diffuse-depth, --radius-scale, --light-paths-per-pixel and --spectral-output");
            }
            let c = Checkpoint::load(&from.join(CHECKPOINT))?;
            if c.scene_hash != scene.hash {
                bail!(
                    "{} was made from another scene, or the scene or its meshes changed since",
                    from.join(CHECKPOINT).display()
                );
            }
            settings = c.settings;
            Some(c)
        }
        None => None,
    };
    let dir =
        args.out.clone().or_else(|| args.resume.clone()).unwrap_or_else(|| output_folder::default_dir(&args.scene));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the output folder {}", dir.display()))?;

    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        // A second Ctrl-C while results are being written still ends the process.
        ctrlc::set_handler(move || {
            if flag.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        })
        .context("cannot install the Ctrl-C handler")?;
    }

    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
    bar.set_style(ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}").expect("static template"));
    bar.enable_steady_tick(Duration::from_millis(200));

    // What the run changed from what it was asked (flags of the record).
    let mut notes: Vec<String> = Vec::new();
    let (mut engine, layout): (Box<dyn Progressive + '_>, String) = match parallel_method(args.method) {
        None if args.method.is_distributed() => {
            let resume = match &checkpoint {
                Some(c) => Some(cluster::launch::Resume {
                    session: c.session + 1,
                    sums: c.sums().map_err(|e| anyhow::anyhow!("the checkpoint's sums: {e}"))?,
                    totals: c.totals,
                }),
                None => None,
            };
            let (cluster, layout, _) = cluster::launch::launch(&args, &scene, settings, &dir, resume)?;
            (Box::new(cluster), layout)
        }
        None => (Box::new(Engine::new(&scene, settings)), "1 thread".to_string()),
        Some(m) => {
            let cores = match &args.cores {
                Some(list) => machine::parse_cores(list).map_err(|e| anyhow::anyhow!("--cores: {e}"))?,
                None => machine::all_cores(),
            };
            let mut threads = args.threads.unwrap_or(cores.len());
            if let Some(limit) = args.memory_limit {
                threads = fit_memory(limit, m, threads, &args, &scene, &settings, &cores, &mut notes)?;
            }
            let mut config = EngineConfig::for_method(m, threads, args.group_size, cores)?;
            if let Some(t) = args.tile_size {
                config.tile_size = t;
            }
            config.phases_per_deal = args.phases_per_deal;
            let layout = config.layout();
            (Box::new(ParallelEngine::new(&scene, settings, config)?), layout)
        }
    };
    let session_number = checkpoint.as_ref().map_or(1, |c| c.session + 1);
    let elapsed_before = Duration::from_secs_f64(checkpoint.as_ref().map_or(0.0, |c| c.elapsed_s));
    let mut history: Vec<HistoryEntry> = checkpoint.as_ref().map(|c| c.history.clone()).unwrap_or_default();
    let distributed = args.method.is_distributed();
    let start = Instant::now();
    let mut last_save = Instant::now();
    let mut save_error: Option<anyhow::Error> = None;
    let save_interval = Duration::from_secs_f64(args.save_interval.max(0.5));
    let method_name = args.method.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default();
    let record_of = |engine: &dyn Progressive, history: &[HistoryEntry], reason: &str| {
        let workers = engine.workers();
        let dropped = photonfarm::accumulation::non_finite_dropped()
            + workers.iter().flatten().map(|w| w.non_finite_dropped).sum::<u64>();
        RunRecord {
            photonfarm_version: env!("CARGO_PKG_VERSION").to_string(),
            scene: args.scene.display().to_string(),
            scene_hash: scene.hash.clone(),
            width: scene.camera.width,
            height: scene.camera.height,
            method: method_name.clone(),
            layout: layout.clone(),
            pinned_threads: engine.pinned_threads(),
            settings: *engine.settings(),
            radius_at_1m: engine.settings().radius_schedule(&scene).radius(1.0, 1),
            threads: engine.threads() as u32,
            stop_reason: reason.to_string(),
            totals: engine.totals(),
            stage_seconds: engine.stage_seconds(),
            wall_time_s: elapsed_before.as_secs_f64() + start.elapsed().as_secs_f64(),
            peak_memory_bytes: memory::peak_rss_bytes(),
            bytes_per_pixel: engine.bytes_per_pixel(),
            error: engine.sums().error(),
            pixel_phases: engine.sums().pixels.iter().map(|p| p.phases as u64).sum(),
            session: session_number,
            true_error: reference.as_ref().map(|r| r.compare(engine.sums())),
            history: history.to_vec(),
            flags: notes.iter().cloned().chain(flags_of(&engine.totals(), dropped, workers.as_deref())).collect(),
            workers,
        }
    };

    let save_all = |engine: &dyn Progressive, history: &[HistoryEntry], reason: &str| -> Result<RunRecord> {
        if distributed {
            // The checkpoint first: it is what a resumed run needs.
            let elapsed = elapsed_before.as_secs_f64() + start.elapsed().as_secs_f64();
            Checkpoint::new(
                engine.sums(),
                &scene.hash,
                &method_name,
                *engine.settings(),
                session_number,
                elapsed,
                engine.totals(),
                history,
            )
            .save(&dir.join(CHECKPOINT))?;
        }
        let record = record_of(engine, history, reason);
        output_folder::save(&dir, engine.sums(), &record)?;
        Ok(record)
    };
    let reason = session::run(engine.as_mut(), &stop, &interrupted, &mut history, elapsed_before, |engine, history| {
        let Some(entry) = history.last_mut() else { return };
        if let Some(r) = &reference {
            let t = r.compare(engine.sums());
            (entry.true_all, entry.true_unlit) = (Some(t.rmse_all), Some(t.rmse_unlit));
        }
        let entry = *entry;
        let secs = entry.time_s.max(1e-9);
        let rays = (entry.backward_rays + entry.forward_rays) as f64;
        let delta = match stop.error_over {
            ErrorOver::Unlit => entry.delta_unlit,
            ErrorOver::All => entry.delta_all,
        };
        let workers = engine.workers().map(|w| {
            let count = |p: &dyn Fn(&str) -> bool| w.iter().filter(|w| p(&w.state)).count();
            format!(
                "  workers: {} running, {} connecting, {} finished, {} lost",
                count(&|s| s == "running"),
                count(&|s| s == "connecting"),
                count(&|s| s == "finished"),
                count(&|s| s.starts_with("lost")),
            )
        });
        bar.set_message(format!(
            "phase {}  {:.2} Mrays/s  δ {} {}{}",
            entry.phase,
            rays / secs / 1e6,
            if delta.is_finite() { format!("{:.2}%", 100.0 * delta) } else { "–".to_string() },
            if stop.error_over == ErrorOver::Unlit { "(unlit pixels)" } else { "(all pixels)" },
            workers.unwrap_or_default(),
        ));
        if last_save.elapsed() >= save_interval && save_error.is_none() {
            last_save = Instant::now();
            if let Err(e) = save_all(engine, history, "running") {
                save_error = Some(e);
            }
        }
    });
    bar.set_message("stopping: collecting the last completed phases");
    engine.finish();
    if distributed {
        // The last snapshots arrived after the run loop ended: one more history entry for them, timed when
        // they were merged.
        let time_s = elapsed_before.as_secs_f64() + start.elapsed().as_secs_f64();
        let (e, t) = (engine.sums().error(), engine.totals());
        let truth = reference.as_ref().map(|r| r.compare(engine.sums()));
        history.push(HistoryEntry {
            phase: t.phases,
            time_s,
            delta_all: e.delta_all,
            delta_unlit: e.delta_unlit,
            backward_rays: t.backward_rays,
            forward_rays: t.forward_rays,
            true_all: truth.as_ref().map(|t| t.rmse_all),
            true_unlit: truth.as_ref().map(|t| t.rmse_unlit),
        });
    }
    bar.finish_and_clear();
    if let Some(e) = save_error {
        return Err(e.context("writing the periodic results failed; the run was stopped"));
    }
    if reason == StopReason::NoWorkers && engine.sums().pixels.iter().all(|p| p.phases == 0) {
        let why: Vec<String> =
            engine.workers().unwrap_or_default().iter().map(|w| format!("{}: {}", w.name, w.state)).collect();
        bail!("no worker rendered anything ({})", why.join("; "));
    }
    let record = save_all(engine.as_ref(), &history, reason.name())?;
    let e = record.error;
    println!(
        "{} phases in {:.1} s ({}), {:.2} M backward + {:.2} M forward rays, δ {:.2}% (unlit pixels) / {:.2}% (all pixels)",
        record.totals.phases,
        record.wall_time_s,
        reason.name(),
        record.totals.backward_rays as f64 / 1e6,
        record.totals.forward_rays as f64 / 1e6,
        100.0 * e.delta_unlit,
        100.0 * e.delta_all
    );
    for flag in &record.flags {
        eprintln!("note: {flag}");
    }
    if let Some(t) = &record.true_error {
        println!(
            "true relative RMSE against {}: {:.2}% (unlit pixels) / {:.2}% (all pixels)",
            t.reference,
            100.0 * t.rmse_unlit,
            100.0 * t.rmse_all
        );
    }
    if reason == StopReason::Interrupted {
        println!("interrupted: the results of every completed phase were written");
    }
    println!("wrote {}", dir.display());
    Ok(())
}

/// The parallel engine behind a method, None for the single-threaded ones.
pub fn parallel_method(m: MethodArg) -> Option<ParallelMethod> {
    match m {
        MethodArg::Pbpm | MethodArg::Path | MethodArg::Combination | MethodArg::ThreeLevel => None,
        MethodArg::Sync => Some(ParallelMethod::Sync),
        MethodArg::Async => Some(ParallelMethod::Async),
        MethodArg::TwoLevel => Some(ParallelMethod::TwoLevel),
    }
}

/// The threads an in-process method may use under `--memory-limit`: memory in use now (the scene loaded) plus
/// the engine's buffers must fit. `async` gives up threads to fit (and `notes` says so); the others refuse.
#[allow(clippy::too_many_arguments)]
fn fit_memory(
    limit: u64,
    method: ParallelMethod,
    threads: usize,
    args: &RenderArgs,
    scene: &Scene,
    settings: &RenderSettings,
    cores: &[usize],
    notes: &mut Vec<String>,
) -> Result<usize> {
    let base = memory::current_rss_bytes().unwrap_or(0);
    let pixels = scene.camera.width as u64 * scene.camera.height as u64;
    let need = |t: usize| -> Result<u64> {
        let c = EngineConfig::for_method(method, t, args.group_size, cores.to_vec())?;
        let aux = photonfarm::accumulation::AuxLayout::for_scene(scene, settings.spectral_bands);
        Ok(base + (c.bytes_per_pixel(settings.backward_diffuse_depth, &aux) * pixels as f64) as u64)
    };
    let mb = |b: u64| format!("{:.0} MiB", b as f64 / (1u64 << 20) as f64);
    let asked = need(threads)?;
    if asked <= limit {
        return Ok(threads);
    }
    if method == ParallelMethod::Async {
        if let Some(t) = (1..threads).rev().find(|&t| need(t).is_ok_and(|n| n <= limit)) {
            notes.push(format!(
                "--memory-limit {}: async needs about {} at {threads} threads (its buffers grow with its threads), \
                 so it ran with {t}",
                mb(limit),
                mb(asked)
            ));
            return Ok(t);
        }
    }
    bail!(
        "--memory-limit {} is too small: this render needs about {} ({} in use after loading the scene, plus the \
         engine's buffers){}",
        mb(limit),
        mb(need(if method == ParallelMethod::Async { 1 } else { threads })?),
        mb(base),
        if method == ParallelMethod::Async { " even with one thread" } else { "" }
    )
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
