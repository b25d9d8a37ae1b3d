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
    speedup: f64,
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
    let runs = args.scenes.len() * args.methods.len() * args.threads.len();
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
        for &method in &args.methods {
            let mut base_rays = None;
            for &threads in &args.threads {
                let settings = RenderSettings::for_scene(
                    &scene,
                    if method == MethodArg::Path { Method::Path } else { Method::Pbpm },
                    args.seed,
                );
                let (mut engine, layout): (Box<dyn Progressive + '_>, String) = match parallel_method(method) {
                    None => {
                        if threads != 1 {
                            continue;
                        }
                        (Box::new(Engine::new(&scene, settings)), "1 thread".into())
                    }
                    Some(m) => {
                        let config = EngineConfig::for_method(m, threads, args.group_size.min(threads), cores.clone())?;
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
                let rays = (t.backward_rays + t.forward_rays) as f64;
                // Rays per thread of the method's first run: speedup is against one thread when that run has one thread.
                let base = *base_rays.get_or_insert(rays / threads as f64);
                let truth = reference.as_ref().map(|r| r.compare(engine.sums()));
                let row = Row {
                    scene: name.clone(),
                    method: method.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default(),
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
                    speedup: rays / base,
                };
                eprintln!("{}", text_row(&row));
                rows.push(row);
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

fn text_row(r: &Row) -> String {
    format!(
        "| {} | {} | {} | {} | {:.2} M | {:.2} M | {:.2}× | {:.2}% / {:.2}% | {} / {} | {:.0} |",
        r.scene,
        r.method,
        r.threads,
        r.layout,
        r.forward_rays as f64 / 1e6,
        r.backward_rays as f64 / 1e6,
        r.speedup,
        100.0 * r.delta_unlit,
        100.0 * r.delta_all,
        pct(r.true_unlit),
        pct(r.true_all),
        r.bytes_per_pixel
    )
}

fn report(rows: &[Row], args: &BenchArgs) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Runs of {} s each; speedup = rays traced / (rays per thread of the same method at {} thread(s)).\n",
        args.time, args.threads[0]
    );
    let _ = writeln!(s, "| scene | method | threads | groups×threads | forward rays | backward rays | tracing speedup | δ unlit / all | true error unlit / all | bytes/pixel |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(s, "{}", text_row(r));
    }
    s
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from("scene,method,threads,layout,wall_s,phases,backward_rays,forward_rays,merges,delta_unlit,delta_all,true_unlit,true_all,bytes_per_pixel,speedup\n");
    for r in rows {
        let opt = |x: Option<f64>| x.map(|v| v.to_string()).unwrap_or_default();
        let _ = writeln!(
            s,
            "{},{},{},{},{:.3},{},{},{},{},{},{},{},{},{:.1},{:.4}",
            r.scene,
            r.method,
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
            r.speedup
        );
    }
    s
}
