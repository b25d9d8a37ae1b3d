//! `coordinator bench`: every parallel method at several thread counts for a fixed time on the shipped scenes,
//! reported as the paper's Table 1 (rays, tracing speedup against one thread of the same method, accuracy,
//! memory), in the terminal, `results.csv` and `report.md`.

use crate::cli::{BenchArgs, MethodArg};
use crate::output_folder::{self, Reference};
use crate::render_command::parallel_method;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use photonfarm::render::session::{self, ErrorOver, Progressive, StopRule};
use photonfarm::render::{Engine, Method, RenderSettings};
use photonfarm::scene::Scene;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use worker::{topology, EngineConfig, ParallelEngine};

/// One benchmark run.
struct Row {
    scene: String,
    method: String,
    repeat: u32,
    threads: usize,
    layout: String,
    phases: u64,
    backward_rays: u64,
    forward_rays: u64,
    merges: u64,
    delta_unlit: f64,
    delta_all: f64,
    true_unlit: Option<f64>,
    true_all: Option<f64>,
    bytes_per_pixel: f64,
    wall_s: f64,
    /// Fraction of thread time idle at and between synchronisation rounds (parallel engines).
    idle: Option<f64>,
}

impl Row {
    fn rays(&self) -> f64 {
        (self.backward_rays + self.forward_rays) as f64
    }
}

pub fn run(args: BenchArgs) -> Result<()> {
    if !(args.time.is_finite() && args.time > 0.0) {
        bail!("--time must be a positive number of seconds");
    }
    if args.threads.is_empty() || args.threads.contains(&0) {
        bail!("--threads needs positive thread counts, e.g. 1,2");
    }
    let cores = match &args.cores {
        Some(list) => topology::parse_cores(list).map_err(|e| anyhow::anyhow!("--cores: {e}"))?,
        None => topology::all_cores(),
    };
    let dir = args.out.clone().unwrap_or_else(|| output_folder::default_dir(Path::new("bench")));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let interrupted = AtomicBool::new(false);
    let mut rows: Vec<Row> = Vec::new();
    if let Some(m) = args.methods.iter().find(|m| m.is_distributed()) {
        bail!("the bench runs the in-process methods (pbpm, path, sync, async, two-level); {m:?} runs worker processes: time it with `coordinator render --method three-level`");
    }
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    let runs = args.scenes.len() * args.methods.len() * args.threads.len() * args.repeats as usize;
    eprintln!("{runs} runs of {} s each, about {:.0} minutes", args.time, runs as f64 * args.time / 60.0);
    for name in &args.scenes {
        let path = PathBuf::from("scenes").join(format!("{name}.toml"));
        let scene = Scene::load(&path)?;
        let ref_path = PathBuf::from("scenes/references").join(format!("{name}-path.exr"));
        let reference = if ref_path.exists() {
            Some(Reference::load(&ref_path, scene.camera.width, scene.camera.height)?)
        } else {
            None
        };
        for repeat in 0..args.repeats {
            for &method in &args.methods {
                for &threads in &args.threads {
                    let seed = args.seed + repeat as u64;
                    let estimator = if method == MethodArg::Path { Method::Path } else { Method::Pbpm };
                    let settings = RenderSettings::for_scene(&scene, estimator, seed);
                    let (mut engine, layout): (Box<dyn Progressive + '_>, String) = match parallel_method(method) {
                        None => {
                            if threads != 1 {
                                continue;
                            }
                            (Box::new(Engine::new(&scene, settings)), "1 thread".into())
                        }
                        Some(m) => {
                            let config =
                                EngineConfig::for_method(m, threads, args.group_size.min(threads), cores.clone())?;
                            let layout = format!("{}×{}", config.groups, config.threads_per_group);
                            (Box::new(ParallelEngine::new(&scene, settings, config)?), layout)
                        }
                    };
                    let stop = StopRule {
                        time: Some(Duration::from_secs_f64(args.time)),
                        phases: None,
                        target_error: None,
                        error_over: ErrorOver::Unlit,
                    };
                    let mut history = Vec::new();
                    session::run(engine.as_mut(), &stop, &interrupted, &mut history, Duration::ZERO, |_, _| {});
                    let t = engine.totals();
                    let e = engine.sums().error();
                    let truth = reference.as_ref().map(|r| r.compare(engine.sums()));
                    let row = Row {
                        scene: name.clone(),
                        method: method.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default(),
                        repeat,
                        threads,
                        layout,
                        phases: t.phases,
                        backward_rays: t.backward_rays,
                        forward_rays: t.forward_rays,
                        merges: t.merges,
                        delta_unlit: e.delta_unlit,
                        delta_all: e.delta_all,
                        true_unlit: truth.as_ref().map(|x| x.rmse_unlit),
                        true_all: truth.as_ref().map(|x| x.rmse_all),
                        bytes_per_pixel: engine.bytes_per_pixel(),
                        wall_s: history.last().map(|h| h.time_s).unwrap_or(0.0),
                        idle: engine.stage_seconds().map(|s| {
                            let total = s.backward + s.build + s.forward + s.closing + s.waiting + s.between_rounds;
                            (s.waiting + s.between_rounds) / total.max(1e-12)
                        }),
                    };
                    eprintln!(
                        "{} {} {} threads, run {}: {:.2} M rays, δ unlit {:.2}%",
                        row.scene,
                        row.method,
                        row.threads,
                        repeat + 1,
                        row.rays() / 1e6,
                        100.0 * row.delta_unlit
                    );
                    rows.push(row);
                }
            }
        }
    }
    let report = report(&rows, &args);
    println!("{report}");
    std::fs::write(dir.join("report.md"), &report)
        .with_context(|| format!("cannot write {}", dir.join("report.md").display()))?;
    std::fs::write(dir.join("results.csv"), csv(&rows))
        .with_context(|| format!("cannot write {}", dir.join("results.csv").display()))?;
    println!("wrote {}", dir.display());
    Ok(())
}

fn pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:.2}%", 100.0 * v)).unwrap_or_else(|| "–".into())
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Table-1 rows: one per (scene, method, threads), averaged over repeats; the speedup is against the mean rays
/// per thread of the same method at the first thread count.
fn report(rows: &[Row], args: &BenchArgs) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} run(s) of {} s per configuration; speedup = rays traced / (rays per thread of the same method at {} thread(s)); \
         δ range over runs in brackets.\n",
        args.repeats, args.time, args.threads[0]
    );
    let _ = writeln!(s, "| scene | method | threads | groups×threads | forward rays | backward rays | tracing speedup | δ unlit / all | true error unlit / all | bytes/pixel | idle |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    let mut keys: Vec<(&str, &str, usize)> = Vec::new();
    for r in rows {
        let k = (r.scene.as_str(), r.method.as_str(), r.threads);
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for &(scene, method, threads) in &keys {
        let group: Vec<&Row> = rows
            .iter()
            .filter(|r| (r.scene.as_str(), r.method.as_str(), r.threads) == (scene, method, threads))
            .collect();
        let base: Vec<&Row> =
            rows.iter().filter(|r| r.scene == scene && r.method == method && r.threads == args.threads[0]).collect();
        let base_per_thread = mean(base.iter().map(|r| r.rays())) / args.threads[0] as f64;
        let (lo, hi) =
            group.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(r.delta_unlit), hi.max(r.delta_unlit)));
        let range = if group.len() > 1 { format!(" [{:.2}–{:.2}%]", 100.0 * lo, 100.0 * hi) } else { String::new() };
        let opt_mean = |f: &dyn Fn(&Row) -> Option<f64>| -> Option<f64> {
            let v: Vec<f64> = group.iter().filter_map(|r| f(r)).collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        let _ = writeln!(
            s,
            "| {scene} | {method} | {threads} | {} | {:.2} M | {:.2} M | {:.2}× | {:.2}%{range} / {:.2}% | {} / {} | {:.0} | {} |",
            group[0].layout,
            mean(group.iter().map(|r| r.forward_rays as f64)) / 1e6,
            mean(group.iter().map(|r| r.backward_rays as f64)) / 1e6,
            mean(group.iter().map(|r| r.rays())) / base_per_thread,
            100.0 * mean(group.iter().map(|r| r.delta_unlit)),
            100.0 * mean(group.iter().map(|r| r.delta_all)),
            pct(opt_mean(&|r| r.true_unlit)),
            pct(opt_mean(&|r| r.true_all)),
            mean(group.iter().map(|r| r.bytes_per_pixel)),
            pct(opt_mean(&|r| r.idle)),
        );
    }
    s
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from("scene,method,repeat,threads,layout,wall_s,phases,backward_rays,forward_rays,merges,delta_unlit,delta_all,true_unlit,true_all,bytes_per_pixel,idle_fraction\n");
    for r in rows {
        let opt = |x: Option<f64>| x.map(|v| v.to_string()).unwrap_or_default();
        let _ = writeln!(
            s,
            "{},{},{},{},{},{:.3},{},{},{},{},{},{},{},{},{:.1},{}",
            r.scene,
            r.method,
            r.repeat,
            r.threads,
            r.layout,
            r.wall_s,
            r.phases,
            r.backward_rays,
            r.forward_rays,
            r.merges,
            r.delta_unlit,
            r.delta_all,
            opt(r.true_unlit),
            opt(r.true_all),
            r.bytes_per_pixel,
            opt(r.idle)
        );
    }
    s
}
