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
    /// Distributed runs: mean bytes per snapshot and per second per worker.
    snapshot_bytes: Option<(f64, f64)>,
}

/// A combination or three-level run as a user starts it (`coordinator render`, real worker processes), on
/// `threads` synthetic NUMA nodes of one core each, read back from its run.json.
fn distributed_run(
    name: &str,
    method: MethodArg,
    threads: usize,
    repeat: u32,
    args: &BenchArgs,
    dir: &Path,
) -> Result<Row> {
    let out = dir.join("runs").join(format!("{name}-{:?}-{threads}-{repeat}", method).to_lowercase());
    let method_name = method.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default();
    let exe = std::env::current_exe().context("cannot find this program")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["render", &format!("scenes/{name}.toml"), "--quiet", "--method", &method_name])
        .args(["--topology", &format!("pack:1 numa:{threads} core:1 pu:1")])
        .args(["--group-size", &args.group_size.to_string(), "--time", &args.time.to_string()])
        .args(["--seed", &(args.seed + repeat as u64).to_string()])
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null());
    let reference = PathBuf::from("scenes/references").join(format!("{name}-path.exr"));
    if reference.exists() {
        cmd.arg("--reference").arg(&reference);
    }
    let status = cmd.status().context("cannot start the render")?;
    if !status.success() {
        bail!("the {method_name} run on {name} failed ({status})");
    }
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("run.json"))?)?;
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let workers = r["workers"].as_array().cloned().unwrap_or_default();
    // Timed like the in-process runs: at the last history entry, when the final snapshots were merged.
    let wall =
        r["history"].as_array().and_then(|h| h.last()).map_or(f(&r["wall_time_s"]), |h| f(&h["time_s"])).max(1e-9);
    let (snaps, bytes): (f64, f64) =
        workers.iter().fold((0.0, 0.0), |(n, b), w| (n + f(&w["snapshots"]), b + f(&w["snapshot_bytes"])));
    Ok(Row {
        scene: name.to_string(),
        method: method_name,
        repeat,
        threads,
        layout: format!("{} processes", workers.len()),
        phases: r["totals"]["phases"].as_u64().unwrap_or(0),
        backward_rays: r["totals"]["backward_rays"].as_u64().unwrap_or(0),
        forward_rays: r["totals"]["forward_rays"].as_u64().unwrap_or(0),
        merges: r["totals"]["merges"].as_u64().unwrap_or(0),
        delta_unlit: f(&r["error"]["delta_unlit"]),
        delta_all: f(&r["error"]["delta_all"]),
        true_unlit: r["true_error"]["rmse_unlit"].as_f64(),
        true_all: r["true_error"]["rmse_all"].as_f64(),
        bytes_per_pixel: f(&r["bytes_per_pixel"]),
        wall_s: wall,
        idle: None,
        snapshot_bytes: Some((bytes / snaps.max(1.0), bytes / wall / workers.len().max(1) as f64)),
    })
}

impl Row {
    fn rays(&self) -> f64 {
        (self.backward_rays + self.forward_rays) as f64
    }

    /// One progress line per finished run.
    fn announce(&self) {
        eprintln!(
            "{} {} {} threads, run {}: {:.2} M rays, δ unlit {:.2}%",
            self.scene,
            self.method,
            self.threads,
            self.repeat + 1,
            self.rays() / 1e6,
            100.0 * self.delta_unlit
        );
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
                    if method.is_distributed() {
                        let row = distributed_run(name, method, threads, repeat, &args, &dir)?;
                        row.announce();
                        rows.push(row);
                        continue;
                    }
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
                        snapshot_bytes: None,
                        idle: engine.stage_seconds().map(|s| {
                            let total = s.backward + s.build + s.forward + s.closing + s.waiting + s.between_rounds;
                            (s.waiting + s.between_rounds) / total.max(1e-12)
                        }),
                    };
                    row.announce();
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
    let snapshot_rows: Vec<&Row> = rows.iter().filter(|r| r.snapshot_bytes.is_some()).collect();
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
    if !snapshot_rows.is_empty() {
        let _ = writeln!(s, "\nDistributed runs (one worker process per synthetic NUMA node of one core):\n");
        let _ = writeln!(s, "| scene | method | threads | rays/s | MB per snapshot | KB/s per worker |");
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        for r in snapshot_rows {
            let (per, rate) = r.snapshot_bytes.unwrap_or_default();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.2} M | {:.2} | {:.0} |",
                r.scene,
                r.method,
                r.threads,
                r.rays() / r.wall_s / 1e6,
                per / 1e6,
                rate / 1e3
            );
        }
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
