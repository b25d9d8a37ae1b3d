//! `coordinator bench`: scenes × methods × core counts × repeats for a time budget, every run a real
//! `coordinator render` process (so its peak memory is its own), reported as the paper's tables (rays, tracing
//! speedup, accuracy, memory) in the terminal, `report.md`, `results.csv` (one row per run) and `series.csv`
//! (error against time and rays, for the charts).

pub mod charts;
pub mod tables;

use crate::cli::BenchArgs;
use crate::live::bench_page::BenchLive;
use crate::output_folder;
use anyhow::{bail, Context, Result};
use photonfarm::protocol::Secret;
use photonfarm::render::method::Processes;
use photonfarm::render::{Estimator, Method};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tables::{write_table, ResultsRow, SeriesRow};
use worker::machine;

/// Seconds per run and the methods of `--quick`: every method once on both scenes in under five minutes.
const QUICK_TIME: f64 = 8.0;
/// How long the live page stays up after the bench, so an open page shows its end.
const PAGE_LINGER: std::time::Duration = std::time::Duration::from_secs(2);

/// One benchmark run, read back from its `run.json`: its row of results.csv, its steps for series.csv and,
/// for distributed runs, its traffic.
struct Run {
    row: ResultsRow,
    series: Vec<SeriesRow>,
    /// Distributed runs: mean bytes per snapshot and per second per worker.
    snapshot_bytes: Option<(f64, f64)>,
}

impl Run {
    fn rays(&self) -> f64 {
        (self.row.backward_rays + self.row.forward_rays) as f64
    }

    fn rays_per_second(&self) -> f64 {
        self.rays() / self.row.wall_s.max(1e-9)
    }

    /// How many photon maps a light path served on average: above 1 where groups share their maps. None for
    /// runs without light paths (the path tracer) and for records older than the count.
    fn maps_per_light_path(&self) -> Option<f64> {
        let r = &self.row;
        (r.light_paths > 0 && r.map_light_paths > 0).then(|| r.map_light_paths as f64 / r.light_paths as f64)
    }

    /// What the run gave, in one line.
    fn summary(&self) -> String {
        let r = &self.row;
        format!(
            "{:.2} M rays in {:.1} s, δ unlit {:.2}%{}",
            self.rays() / 1e6,
            r.wall_s,
            100.0 * r.delta_unlit,
            r.true_unlit.map(|t| format!(", true error {:.2}%", 100.0 * t)).unwrap_or_default()
        )
    }
}

/// One run of the plan: a configuration, its repeat and, with `--target-error`, its tiles and target.
#[derive(Clone, Debug)]
struct Entry {
    scene: String,
    method: Method,
    threads: usize,
    repeat: u32,
    /// "adaptive" or "uniform", with the target error; None at equal time.
    target: Option<(&'static str, f64)>,
}

/// A run of the plan in words: scene, method, threads, tiles and repeat.
fn label(e: &Entry) -> String {
    let tiles = e.target.map(|(t, d)| format!(" {t} tiles to {:.1}%", 100.0 * d)).unwrap_or_default();
    format!("{} {} {} threads{tiles}, run {}", e.scene, e.method, e.threads, e.repeat + 1)
}

/// The target error of each scene from `--target-error`: one D for every scene, or SCENE=D pairs naming
/// every scene of the bench.
fn targets(spec: &str, scenes: &[String]) -> Result<std::collections::BTreeMap<String, f64>> {
    let check = |d: &str| -> Result<f64> {
        match d.trim().parse::<f64>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
            _ => bail!("--target-error: {d:?} is not a positive number (e.g. 0.03 for 3%)"),
        }
    };
    if !spec.contains('=') {
        let d = check(spec)?;
        return Ok(scenes.iter().map(|s| (s.clone(), d)).collect());
    }
    let mut out = std::collections::BTreeMap::new();
    for pair in spec.split(',') {
        let Some((scene, d)) = pair.split_once('=') else {
            bail!("--target-error: {pair:?} is not SCENE=D (e.g. cornell=0.03,caustic=0.08)");
        };
        out.insert(scene.trim().to_string(), check(d)?);
    }
    if let Some(missing) = scenes.iter().find(|s| !out.contains_key(*s)) {
        bail!("--target-error gives no target for the scene {missing}");
    }
    Ok(out)
}

/// The scene's reference image, if one is shipped: PBPM's where one was made because the path tracer cannot
/// converge (the lens's ghosts), the path tracer's otherwise.
pub fn reference_of(scene: &str) -> Option<PathBuf> {
    [Estimator::Pbpm, Estimator::Path]
        .iter()
        .map(|e| PathBuf::from("scenes/references").join(format!("{scene}-{}.exr", e.name())))
        .find(|p| p.exists())
}

/// Where a bench run's processes run and how their threads form groups.
struct Planned {
    /// "this machine", or the synthetic description of a distributed run's nodes.
    topology: String,
    processes: usize,
    /// Groups over all processes.
    groups: usize,
    threads_per_group: usize,
}

/// The layout a run of `method` at `threads` threads will have, from the methods' table, or None when the
/// method does not run at this thread count (the single-threaded estimators at more than one thread). A
/// distributed method runs one worker per synthetic NUMA node of one core, as many nodes as threads.
fn planned(method: Method, threads: usize, group_size: usize) -> Result<Option<Planned>> {
    let layout = method.layout();
    if !layout.runs_on(threads) {
        return Ok(None);
    }
    Ok(Some(match layout.processes {
        Processes::One => {
            let g = layout.grouping.split(threads, group_size)?;
            Planned {
                topology: "this machine".into(),
                processes: 1,
                groups: g.groups,
                threads_per_group: g.threads_per_group,
            }
        }
        Processes::PerNumaNode => {
            let per_node = layout.grouping.split(1, group_size)?;
            Planned {
                topology: format!("synthetic {}", synthetic_nodes(threads)),
                processes: threads,
                groups: threads * per_node.groups,
                threads_per_group: per_node.threads_per_group,
            }
        }
    }))
}

fn synthetic_nodes(n: usize) -> String {
    format!("pack:1 numa:{n} core:1 pu:1")
}

/// Runs `coordinator render` for one configuration and reads its record.
fn run_one(e: &Entry, args: &BenchArgs, dir: &Path) -> Result<Option<Run>> {
    let Some(plan) = planned(e.method, e.threads, args.group_size)? else {
        return Ok(None);
    };
    let tiles = e.target.map(|(t, _)| format!("-{t}")).unwrap_or_default();
    let out = dir.join("runs").join(format!("{}-{}-{}t{tiles}-r{}", e.scene, e.method, e.threads, e.repeat));
    render(e, args, &out)?;
    let key = RunKey { scene: &e.scene, method: e.method, threads: e.threads, repeat: e.repeat, target: e.target };
    read_run(&out.join("run.json"), key, plan).map(Some)
}

/// Which configuration and repeat a run is.
#[derive(Clone, Copy)]
struct RunKey<'a> {
    scene: &'a str,
    method: Method,
    threads: usize,
    repeat: u32,
    target: Option<(&'static str, f64)>,
}

/// Renders one configuration into `out` as a `coordinator render` process.
fn render(e: &Entry, args: &BenchArgs, out: &Path) -> Result<()> {
    let (scene, method, threads) = (e.scene.as_str(), e.method, e.threads);
    let exe = std::env::current_exe().context("cannot find this program")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["render", &format!("scenes/{scene}.toml"), "--quiet", "--method", method.name()])
        .args(["--time", &args.time.to_string(), "--seed", &(args.seed + e.repeat as u64).to_string()])
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::null());
    if let Some(n) = args.phases {
        cmd.args(["--phases", &n.to_string()]);
    }
    if let Some((tiles, d)) = e.target {
        cmd.args(["--target-error", &d.to_string()]);
        if tiles == "uniform" {
            cmd.arg("--uniform");
        } else if let Some(t) = args.adaptive_tile {
            cmd.args(["--adaptive-tile", &t.to_string()]);
        }
    }
    let layout = method.layout();
    match (layout.processes, layout.parallel) {
        (Processes::PerNumaNode, _) => {
            cmd.args(["--topology", &synthetic_nodes(threads), "--group-size", &args.group_size.to_string()]);
        }
        (Processes::One, Some(_)) => {
            cmd.args(["--threads", &threads.to_string(), "--group-size", &args.group_size.to_string()]);
            if let Some(cores) = &args.cores {
                cmd.args(["--cores", cores]);
            }
        }
        (Processes::One, None) => {}
    }
    if let Some(reference) = reference_of(scene) {
        cmd.arg("--reference").arg(reference);
    }
    // The run's notes (flags) are in its run.json; its terminal output only matters when it fails.
    let output = cmd.stderr(std::process::Stdio::piped()).output().context("cannot start the render")?;
    if !output.status.success() {
        bail!(
            "the {method} run on {scene} at {threads} threads failed ({}): {}; its output is in {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim(),
            out.display()
        );
    }
    Ok(())
}

/// Reads a run's `run.json` into its results row and series, `plan` its layout.
fn read_run(path: &Path, key: RunKey, plan: Planned) -> Result<Run> {
    // Read as JSON values: a δ that is not a number yet is written as null.
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?)
            .with_context(|| format!("{} is not a run record", path.display()))?;
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let u = |v: &serde_json::Value| v.as_u64().unwrap_or(0);
    let history = r["history"].as_array().cloned().unwrap_or_default();
    let series: Vec<SeriesRow> = history
        .iter()
        .map(|h| SeriesRow {
            scene: key.scene.to_string(),
            method: key.method,
            threads: key.threads,
            repeat: key.repeat,
            time_s: f(&h["time_s"]),
            rays: u(&h["backward_rays"]) + u(&h["forward_rays"]),
            delta_unlit: f(&h["delta_unlit"]),
            delta_all: f(&h["delta_all"]),
            true_unlit: h["true_unlit"].as_f64(),
            true_all: h["true_all"].as_f64(),
            tiles: key.target.map(|(t, _)| t.to_string()).unwrap_or_default(),
            blur_unlit: f(&h["blur_unlit"]),
        })
        .collect();
    let reached_s = key.target.and_then(|(_, d)| series.iter().find(|p| p.delta_unlit <= d)).map(|p| p.time_s);
    let workers = r["workers"].as_array().cloned().unwrap_or_default();
    let wall = series.last().map_or(f(&r["wall_time_s"]), |p| p.time_s);
    let peak =
        workers.iter().filter_map(|w| w["peak_memory_bytes"].as_u64()).chain(r["peak_memory_bytes"].as_u64()).max();
    let snapshot_bytes = (!workers.is_empty()).then(|| {
        let (snaps, bytes) =
            workers.iter().fold((0.0, 0.0), |(n, b), w| (n + f(&w["snapshots"]), b + f(&w["snapshot_bytes"])));
        (bytes / f64::max(snaps, 1.0), bytes / wall.max(1e-9) / workers.len() as f64)
    });
    let idle = r["stage_seconds"].as_object().map(|s| {
        let g = |k: &str| s.get(k).and_then(|v| v.as_f64()).unwrap_or(0.0);
        let total: f64 =
            ["backward", "build", "forward", "closing", "waiting", "between_rounds"].iter().map(|k| g(k)).sum();
        (g("waiting") + g("between_rounds")) / total.max(1e-12)
    });
    let row = ResultsRow {
        scene: key.scene.to_string(),
        method: key.method,
        topology: plan.topology,
        processes: if workers.is_empty() { plan.processes } else { workers.len() },
        groups: plan.groups,
        threads_per_group: plan.threads_per_group,
        threads: key.threads,
        repeat: key.repeat,
        wall_s: wall,
        backward_rays: u(&r["totals"]["backward_rays"]),
        forward_rays: u(&r["totals"]["forward_rays"]),
        merges: u(&r["totals"]["merges"]),
        light_paths: u(&r["totals"]["light_paths"]),
        map_light_paths: u(&r["totals"]["map_light_paths"]),
        phases: u(&r["totals"]["phases"]),
        delta_unlit: f(&r["error"]["delta_unlit"]),
        delta_all: f(&r["error"]["delta_all"]),
        true_unlit: r["true_error"]["rmse_unlit"].as_f64(),
        true_all: r["true_error"]["rmse_all"].as_f64(),
        peak_memory_bytes: peak,
        bytes_per_pixel: f(&r["bytes_per_pixel"]),
        idle: if key.method.is_distributed() { None } else { idle },
        reference_delta_unlit: r["true_error"]["reference_delta_unlit"].as_f64(),
        mean_difference_unlit: r["true_error"]["mean_difference_unlit"].as_f64(),
        mean_difference_all: r["true_error"]["mean_difference_all"].as_f64(),
        tiles: key.target.map(|(t, _)| t.to_string()).unwrap_or_default(),
        target_error: key.target.map(|(_, d)| d),
        reached_s,
        blur_unlit: f(&r["error"]["blur_unlit"]),
    };
    Ok(Run { row, series, snapshot_bytes })
}

pub fn run(mut args: BenchArgs) -> Result<()> {
    if args.quick {
        args.time = QUICK_TIME;
        args.repeats = 1;
    }
    if !(args.time.is_finite() && args.time > 0.0) {
        bail!("--time must be a positive number of seconds");
    }
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    if args.phases == Some(0) {
        bail!("--phases must be at least 1");
    }
    let all = match &args.cores {
        Some(list) => machine::parse_cores(list).map_err(|e| anyhow::anyhow!("--cores: {e}"))?.len(),
        None => machine::all_cores().len(),
    };
    let threads: Vec<usize> = match &args.threads {
        Some(t) if t.is_empty() || t.contains(&0) => bail!("--threads needs positive thread counts, e.g. 1,2"),
        Some(t) => t.clone(),
        // 1, 2, 4, … and every core.
        None => {
            let mut t: Vec<usize> =
                std::iter::successors(Some(1usize), |&n| Some(n * 2)).take_while(|&n| n < all).collect();
            t.push(all);
            t
        }
    };
    for scene in &args.scenes {
        let path = PathBuf::from("scenes").join(format!("{scene}.toml"));
        if !path.is_file() {
            bail!("no scene {} (run the bench from the repository's top folder)", path.display());
        }
    }
    let dir = args.out.clone().unwrap_or_else(|| output_folder::default_dir(Path::new("bench")));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let targets = args.target_error.as_deref().map(|spec| targets(spec, &args.scenes)).transpose()?;
    let mut plan = Vec::new();
    for repeat in 0..args.repeats {
        for scene in &args.scenes {
            for &method in &args.methods {
                for &t in &threads {
                    if planned(method, t, args.group_size)?.is_none() {
                        continue;
                    }
                    let entry = |target| Entry { scene: scene.clone(), method, threads: t, repeat, target };
                    match &targets {
                        // Adaptive and uniform back to back: the pair shares the machine's drift.
                        Some(d) => {
                            plan.push(entry(Some(("adaptive", d[scene]))));
                            plan.push(entry(Some(("uniform", d[scene]))));
                        }
                        None => plan.push(entry(None)),
                    }
                }
            }
        }
    }
    match args.phases {
        None => eprintln!(
            "{} runs of {} s each, about {:.0} minutes; results in {}",
            plan.len(),
            args.time,
            plan.len() as f64 * (args.time + 0.7) / 60.0,
            dir.display()
        ),
        Some(n) => eprintln!(
            "{} runs of {n} phases each (at most {} s each); results in {}",
            plan.len(),
            args.time,
            dir.display()
        ),
    }
    let page = match args.serve {
        Some(addr) => {
            let secret = match &args.secret_file {
                Some(f) => Some(Secret::from_file(f)?),
                None => Secret::from_env()?,
            };
            let labels = plan.iter().map(label).collect();
            let page = BenchLive::start(addr, secret, labels, dir.join("charts"))?;
            say!("live page: {}  (results in {})", page.url, dir.display());
            Some(page)
        }
        None => None,
    };
    let result = run_plan(&plan, &args, &dir, page.as_ref());
    if let Some(page) = &page {
        page.end(result.as_ref().err().map(|e| format!("{e:#}")));
    }
    let runs = result?;
    let report = report(&runs, &args, &threads);
    say!("{report}");
    let path = dir.join("report.md");
    std::fs::write(&path, &report).with_context(|| format!("cannot write {}", path.display()))?;
    let charts = charts::write_charts(&dir)?;
    say!("{} charts in {}", charts.len(), dir.join("charts").display());
    say!("wrote {}", dir.display());
    if page.is_some() {
        std::thread::sleep(PAGE_LINGER);
    }
    Ok(())
}

/// Runs every configuration of `plan` in turn, writing results.csv and series.csv after each; with a live page,
/// shows each run's state and redraws the charts after each.
fn run_plan(plan: &[Entry], args: &BenchArgs, dir: &Path, page: Option<&BenchLive>) -> Result<Vec<Run>> {
    let mut runs: Vec<Run> = Vec::new();
    for (i, entry) in plan.iter().enumerate() {
        if let Some(p) = page {
            p.running(i);
        }
        let Some(run) = run_one(entry, args, dir)? else { continue };
        eprintln!("[{}/{}] {}: {}", i + 1, plan.len(), label(entry), run.summary());
        let summary = run.summary();
        runs.push(run);
        // Written after every run, so an interrupted bench keeps what it measured.
        let rows: Vec<&ResultsRow> = runs.iter().map(|r| &r.row).collect();
        write_table(&dir.join("results.csv"), &rows)?;
        let steps: Vec<&SeriesRow> = runs.iter().flat_map(|r| &r.series).collect();
        write_table(&dir.join("series.csv"), &steps)?;
        if let Some(p) = page {
            let charts = charts::write_charts(dir)?;
            let pngs = charts
                .iter()
                .filter(|c| c.extension().is_some_and(|e| e == "png"))
                .filter_map(|c| c.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            p.done(i, summary, pngs);
        }
    }
    Ok(runs)
}

fn pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:.2}%", 100.0 * v)).unwrap_or_else(|| "–".into())
}

/// A signed percentage with the precision a bias of a few hundredths of a percent needs.
fn signed_pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:+.3}%", 100.0 * v)).unwrap_or_else(|| "–".into())
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn opt_mean(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = values.flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The runs of `method` on `scene` at `threads` threads.
fn runs_of<'a>(runs: &'a [Run], scene: &str, method: Method, threads: usize) -> Vec<&'a Run> {
    runs.iter().filter(|r| r.row.scene == scene && r.row.method == method && r.row.threads == threads).collect()
}

/// The scenes of the runs, sorted.
fn scenes_of(runs: &[Run]) -> std::collections::BTreeSet<&str> {
    runs.iter().map(|r| r.row.scene.as_str()).collect()
}

/// The report: Table 1 (rays, tracing speedup against the same method at the fewest threads, accuracy,
/// memory), the distributed runs' traffic, and the comparisons the runs allow: PBPM against the path tracer,
/// the calibration of δ, and two-level against sync and async.
fn report(runs: &[Run], args: &BenchArgs, threads: &[usize]) -> String {
    let mut s = String::new();
    let budget = match args.phases {
        Some(n) => format!("{n} phases (at most {} s)", args.time),
        None => format!("{} s", args.time),
    };
    let _ = writeln!(
        s,
        "{} run(s) of {budget} per configuration. Tracing speedup = rays per second / (rays per second of the same \
         method at {} thread(s)) × {}; δ range over runs in brackets; \"unlit\" = pixels that do not see a light \
         directly.\n",
        args.repeats, threads[0], threads[0]
    );
    let _ = writeln!(s, "| scene | method | threads | processes × groups × threads | forward rays | backward rays | tracing speedup | δ unlit / all | true error unlit / all | mean against the reference unlit / all | peak memory | bytes/pixel | idle | maps per light path |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut keys: Vec<(&str, Method, usize, &str)> = Vec::new();
    for r in runs {
        let k = (r.row.scene.as_str(), r.row.method, r.row.threads, r.row.tiles.as_str());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for &(scene, method, t, tiles) in &keys {
        let group: Vec<&Run> = runs_of(runs, scene, method, t).into_iter().filter(|r| r.row.tiles == tiles).collect();
        let shown = if tiles.is_empty() { method.to_string() } else { format!("{method} ({tiles} tiles)") };
        let first = runs
            .iter()
            .filter(|r| r.row.scene == scene && r.row.method == method)
            .map(|r| r.row.threads)
            .min()
            .unwrap_or(t);
        let base = runs_of(runs, scene, method, first);
        let speedup = mean(group.iter().map(|r| r.rays_per_second())) / mean(base.iter().map(|r| r.rays_per_second()))
            * first as f64;
        let (lo, hi) = group
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(r.row.delta_unlit), hi.max(r.row.delta_unlit)));
        let range = if group.len() > 1 { format!(" [{:.2}–{:.2}%]", 100.0 * lo, 100.0 * hi) } else { String::new() };
        let g = &group[0].row;
        let _ = writeln!(
            s,
            "| {scene} | {shown} | {t} | {}×{}×{} | {:.2} M | {:.2} M | {:.2}× | {:.2}%{range} / {:.2}% | {} / {} | {} / {} | {} | {:.0} | {} | {} |",
            g.processes,
            g.groups / g.processes.max(1),
            g.threads_per_group,
            mean(group.iter().map(|r| r.row.forward_rays as f64)) / 1e6,
            mean(group.iter().map(|r| r.row.backward_rays as f64)) / 1e6,
            speedup,
            100.0 * mean(group.iter().map(|r| r.row.delta_unlit)),
            100.0 * mean(group.iter().map(|r| r.row.delta_all)),
            pct(opt_mean(group.iter().map(|r| r.row.true_unlit))),
            pct(opt_mean(group.iter().map(|r| r.row.true_all))),
            signed_pct(opt_mean(group.iter().map(|r| r.row.mean_difference_unlit))),
            signed_pct(opt_mean(group.iter().map(|r| r.row.mean_difference_all))),
            opt_mean(group.iter().map(|r| r.row.peak_memory_bytes.map(|b| b as f64)))
                .map(|b| format!("{:.0} MB", b / 1e6))
                .unwrap_or_else(|| "–".into()),
            mean(group.iter().map(|r| r.row.bytes_per_pixel)),
            pct(opt_mean(group.iter().map(|r| r.row.idle))),
            opt_mean(group.iter().map(|r| r.maps_per_light_path())).map_or_else(|| "–".into(), |m| format!("{m:.2}")),
        );
    }
    let distributed: Vec<&Run> = runs.iter().filter(|r| r.snapshot_bytes.is_some()).collect();
    if !distributed.is_empty() {
        let _ = writeln!(s, "\nDistributed runs (one worker process per synthetic NUMA node of one core):\n");
        let _ = writeln!(s, "| scene | method | threads | run | rays/s | MB per snapshot | KB/s per worker |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in distributed {
            let (per, rate) = r.snapshot_bytes.unwrap_or_default();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.2} M | {:.2} | {:.0} |",
                r.row.scene,
                r.row.method,
                r.row.threads,
                r.row.repeat + 1,
                r.rays_per_second() / 1e6,
                per / 1e6,
                rate / 1e3
            );
        }
    }
    let comparisons = [
        (
            "PBPM against the path tracer (true error = relative RMSE against the scene's reference, unlit pixels)",
            pbpm_against_path(runs),
        ),
        (
            "Calibration of δ: true error / √(δ² + δ_ref²) at every step of the PBPM runs with δ < 10%, δ_ref the \
             reference's own δ",
            calibration(runs),
        ),
        ("Two-level against sync and async", two_level_against_sync_and_async(runs)),
        (
            "Time to the target error (δ unlit), adaptive tiles against uniform: seconds until δ unlit first met \
             the target, and adaptive / uniform as the mean ratio over runs paired by repeat",
            time_to_target(runs),
        ),
    ];
    if comparisons.iter().all(|(_, lines)| lines.is_empty()) {
        let _ = writeln!(s, "\n(Comparisons need path and pbpm runs on scenes with a reference, or two-level runs.)");
    }
    for (heading, lines) in comparisons.iter().filter(|(_, lines)| !lines.is_empty()) {
        let _ = write!(s, "\n{heading}:\n\n{lines}");
    }
    s
}

/// Per configuration run with `--target-error`: the mean time to the target with adaptive and with uniform
/// tiles, their ratio over runs paired by repeat, and the adaptive runs' true error / √(δ² + δ_ref²) at the
/// end.
fn time_to_target(runs: &[Run]) -> String {
    let mut s = String::new();
    let mut keys: Vec<(&str, Method, usize)> = Vec::new();
    for r in runs.iter().filter(|r| r.row.tiles == "adaptive") {
        let k = (r.row.scene.as_str(), r.row.method, r.row.threads);
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    if keys.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "| scene | method | threads | target | uniform | adaptive | adaptive / uniform | true error / δ (adaptive) |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    let secs = |t: Option<f64>| t.map_or_else(|| "not reached".to_string(), |t| format!("{t:.1} s"));
    for (scene, method, t) in keys {
        let of = |tiles: &str| -> Vec<&Run> {
            runs_of(runs, scene, method, t).into_iter().filter(|r| r.row.tiles == tiles).collect()
        };
        let (adaptive, uniform) = (of("adaptive"), of("uniform"));
        let all_reached = |v: &[&Run]| v.iter().all(|r| r.row.reached_s.is_some());
        let mean_reached = |v: &[&Run]| all_reached(v).then(|| mean(v.iter().filter_map(|r| r.row.reached_s)));
        let ratios: Vec<f64> = adaptive
            .iter()
            .filter_map(|a| {
                let u = uniform.iter().find(|u| u.row.repeat == a.row.repeat)?;
                Some(a.row.reached_s? / u.row.reached_s?)
            })
            .collect();
        let ratio = if ratios.is_empty() {
            "–".to_string()
        } else {
            let (m, se) = mean_and_sem(&ratios);
            format!("{m:.2} ± {se:.2}")
        };
        let calibration = opt_mean(adaptive.iter().map(|r| {
            let d_ref = r.row.reference_delta_unlit.unwrap_or(0.0);
            r.row.true_unlit.map(|e| e / r.row.delta_unlit.hypot(d_ref))
        }));
        let _ = writeln!(
            s,
            "| {scene} | {method} | {t} | {:.1}% | {} | {} | {ratio} | {} |",
            100.0 * adaptive[0].row.target_error.unwrap_or(f64::NAN),
            secs(mean_reached(&uniform)),
            secs(mean_reached(&adaptive)),
            calibration.map_or_else(|| "–".into(), |c| format!("{c:.2}")),
        );
    }
    s
}

/// The first time a run's true error (unlit pixels) is at or below `target`.
fn time_to_reach(run: &Run, target: f64) -> Option<f64> {
    run.series.iter().find(|p| p.true_unlit.is_some_and(|e| e <= target)).map(|p| p.time_s)
}

/// Per scene with single-threaded path-tracer and PBPM runs that have a true error: both errors at equal time,
/// and when PBPM reaches the path tracer's final error.
fn pbpm_against_path(runs: &[Run]) -> String {
    let mut s = String::new();
    for scene in scenes_of(runs) {
        let (path, pbpm) = (runs_of(runs, scene, Method::Path, 1), runs_of(runs, scene, Method::Pbpm, 1));
        let path_error = opt_mean(path.iter().map(|r| r.row.true_unlit));
        let pbpm_error = opt_mean(pbpm.iter().map(|r| r.row.true_unlit));
        let (Some(e_path), Some(e_pbpm)) = (path_error, pbpm_error) else { continue };
        let t_path = mean(path.iter().map(|r| r.row.wall_s));
        let reach: Vec<Option<f64>> = pbpm.iter().map(|r| time_to_reach(r, e_path)).collect();
        let reach_text = if reach.iter().all(Option::is_some) {
            let t = mean(reach.iter().flatten().copied());
            format!("{t:.1} s = {:.2} of the path tracer's time", t / t_path)
        } else {
            "not within the run".into()
        };
        let _ = writeln!(
            s,
            "- {scene}: path tracer {:.2}% after {t_path:.0} s, PBPM {:.2}% at equal time (ratio {:.2}). PBPM reaches the path tracer's final error: {reach_text}.",
            100.0 * e_path,
            100.0 * e_pbpm,
            e_pbpm / e_path
        );
    }
    s
}

/// Per scene, the range of true error / δ over every step of the PBPM runs where δ < 10%, δ combined in
/// quadrature with the reference's own.
fn calibration(runs: &[Run]) -> String {
    let mut s = String::new();
    for scene in scenes_of(runs) {
        let ratios: Vec<f64> = runs
            .iter()
            .filter(|r| r.row.scene == scene && r.row.method.estimator() == Estimator::Pbpm)
            .flat_map(|r| r.series.iter().map(move |p| (p, r.row.reference_delta_unlit.unwrap_or(0.0))))
            .filter(|(p, _)| p.delta_unlit < 0.10)
            .filter_map(|(p, d_ref)| p.true_unlit.map(|t| t / p.delta_unlit.hypot(d_ref)))
            .filter(|x| x.is_finite())
            .collect();
        if ratios.is_empty() {
            continue;
        }
        let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ratios.iter().copied().fold(0.0, f64::max);
        let d_ref = runs.iter().find(|r| r.row.scene == scene).and_then(|r| r.row.reference_delta_unlit);
        let _ = writeln!(
            s,
            "- {scene}: the reference's own δ {}; {lo:.2} … {hi:.2} over {} points.",
            pct(d_ref),
            ratios.len()
        );
    }
    s
}

/// The mean and standard error of the mean of some ratios (standard error 0 for a single one).
fn mean_and_sem(x: &[f64]) -> (f64, f64) {
    let m = mean(x.iter().copied());
    if x.len() < 2 {
        return (m, 0.0);
    }
    let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
    (m, (var / x.len() as f64).sqrt())
}

/// At every thread count above the fewest: two-level's tracing speedup, and its δ at equal time against sync
/// and async as the mean ratio over runs paired by repeat, with its standard error. Repeats are interleaved,
/// so the two runs of a pair share the machine's drift, and the pairing cancels most of it.
fn two_level_against_sync_and_async(runs: &[Run]) -> String {
    let mut s = String::new();
    for scene in scenes_of(runs) {
        let counts: std::collections::BTreeSet<usize> = runs
            .iter()
            .filter(|r| r.row.scene == scene && r.row.method == Method::TwoLevel)
            .map(|r| r.row.threads)
            .collect();
        let Some(&fewest) = counts.first() else { continue };
        for &t in counts.iter().filter(|&&t| t > fewest) {
            let two = runs_of(runs, scene, Method::TwoLevel, t);
            let speedup = mean(two.iter().map(|r| r.rays_per_second()))
                / mean(runs_of(runs, scene, Method::TwoLevel, fewest).iter().map(|r| r.rays_per_second()))
                * fewest as f64;
            let mut line = format!("- {scene}, {t} threads: two-level tracing speedup {speedup:.2}×");
            for other in [Method::Sync, Method::Async] {
                let ratios: Vec<f64> = two
                    .iter()
                    .filter_map(|a| {
                        runs_of(runs, scene, other, t)
                            .into_iter()
                            .find(|b| b.row.repeat == a.row.repeat)
                            .map(|b| a.row.delta_unlit / b.row.delta_unlit)
                    })
                    .collect();
                if !ratios.is_empty() {
                    let (m, se) = mean_and_sem(&ratios);
                    let _ = write!(line, "; δ unlit two-level / {other} {m:.3} ± {se:.3}");
                }
            }
            let _ = writeln!(s, "{line} (mean ± standard error over runs paired by repeat).");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(method: Method, threads: usize, repeat: u32, delta_unlit: f64, rays: u64) -> Run {
        let row = ResultsRow {
            scene: "cornell".into(),
            method,
            topology: "this machine".into(),
            processes: 1,
            groups: 1,
            threads_per_group: threads,
            threads,
            repeat,
            wall_s: 10.0,
            backward_rays: rays,
            forward_rays: 0,
            merges: 0,
            light_paths: 0,
            map_light_paths: 0,
            phases: 100,
            delta_unlit,
            delta_all: delta_unlit,
            true_unlit: None,
            true_all: None,
            peak_memory_bytes: None,
            bytes_per_pixel: 0.0,
            idle: None,
            reference_delta_unlit: None,
            mean_difference_unlit: None,
            mean_difference_all: None,
            tiles: String::new(),
            target_error: None,
            reached_s: None,
            blur_unlit: 0.0,
        };
        Run { row, series: Vec::new(), snapshot_bytes: None }
    }

    #[test]
    fn two_level_is_compared_with_sync_and_async_run_by_run_of_the_same_repeat() {
        let runs = vec![
            run(Method::TwoLevel, 1, 0, 0.06, 100),
            run(Method::TwoLevel, 2, 0, 0.044, 190),
            run(Method::Async, 2, 0, 0.040, 200),
            run(Method::TwoLevel, 2, 1, 0.036, 194),
            run(Method::Async, 2, 1, 0.040, 200),
            // No sync run of repeat 0: the one sync pair is repeat 1's.
            run(Method::Sync, 2, 1, 0.045, 180),
        ];
        let s = two_level_against_sync_and_async(&runs);
        // Ratios to async 1.1 and 0.9: mean 1, standard error 0.1; the speedup from the mean rays per second.
        assert!(s.contains("- cornell, 2 threads: two-level tracing speedup 1.92×;"), "{s}");
        assert!(s.contains("two-level / sync 0.800 ± 0.000"), "{s}");
        assert!(s.contains("two-level / async 1.000 ± 0.100"), "{s}");
        // Without two-level at two thread counts there is nothing to compare.
        assert!(two_level_against_sync_and_async(&runs[2..3]).is_empty());
    }

    #[test]
    fn the_report_states_figures_under_neutral_headings() {
        let runs = vec![run(Method::TwoLevel, 1, 0, 0.06, 100), run(Method::TwoLevel, 2, 0, 0.044, 190)];
        let args = BenchArgs {
            time: 1.0,
            phases: None,
            quick: false,
            scenes: vec!["cornell".into()],
            methods: vec![Method::TwoLevel],
            threads: None,
            group_size: 2,
            cores: None,
            repeats: 1,
            seed: 1,
            target_error: None,
            adaptive_tile: None,
            out: None,
            serve: None,
            secret_file: None,
        };
        let report = report(&runs, &args, &[1, 2]);
        assert!(report.contains("\nTwo-level against sync and async:\n\n- cornell, 2 threads:"), "{report}");
        assert!(!report.contains("PBPM against the path tracer"), "no path and pbpm runs: {report}");
        for graded in ["goal", "Goal", "not met"] {
            assert!(!report.contains(graded), "{graded}: {report}");
        }
    }

    #[test]
    fn time_to_target_pairs_adaptive_and_uniform_runs_by_repeat() {
        let timed = |tiles: &str, repeat, reached: Option<f64>| {
            let mut r = run(Method::TwoLevel, 2, repeat, 0.03, 100);
            (r.row.tiles, r.row.target_error, r.row.reached_s) = (tiles.into(), Some(0.03), reached);
            r.row.true_unlit = Some(0.033);
            r
        };
        let runs = vec![
            timed("adaptive", 0, Some(6.0)),
            timed("uniform", 0, Some(10.0)),
            timed("adaptive", 1, Some(4.0)),
            timed("uniform", 1, Some(10.0)),
        ];
        let s = time_to_target(&runs);
        assert!(s.contains("| cornell | two-level | 2 | 3.0% | 10.0 s | 5.0 s | 0.50 ± 0.10 | 1.10 |"), "{s}");
        let unreached = vec![timed("adaptive", 0, Some(6.0)), timed("uniform", 0, None)];
        assert!(time_to_target(&unreached).contains("| not reached | 6.0 s | – |"), "{}", time_to_target(&unreached));
        assert!(time_to_target(&runs[..0]).is_empty());
        let scenes = vec!["cornell".to_string(), "caustic".to_string()];
        assert_eq!(targets("cornell=0.03,caustic=0.08", &scenes).unwrap()["caustic"], 0.08);
        assert_eq!(targets("0.05", &scenes).unwrap()["cornell"], 0.05);
        assert!(targets("cornell=0.03", &scenes).is_err());
        assert!(targets("cornell=-1,caustic=0.1", &scenes).is_err());
    }

    #[test]
    fn runs_are_planned_from_the_methods_table() {
        let p = |m, t, g| planned(m, t, g).unwrap().map(|p| (p.processes, p.groups, p.threads_per_group));
        assert_eq!(p(Method::Path, 1, 2), Some((1, 1, 1)));
        assert_eq!(p(Method::Pbpm, 2, 2), None);
        assert_eq!(p(Method::Sync, 4, 2), Some((1, 1, 4)));
        assert_eq!(p(Method::Async, 4, 2), Some((1, 4, 1)));
        assert_eq!(p(Method::TwoLevel, 2, 2), Some((1, 2, 1)));
        assert_eq!(p(Method::TwoLevel, 8, 4), Some((1, 2, 4)));
        // One worker per synthetic node of one core: one group of one thread in each.
        assert_eq!(p(Method::Combination, 4, 2), Some((4, 4, 1)));
        assert_eq!(p(Method::ThreeLevel, 2, 4), Some((2, 2, 1)));
        assert!(planned(Method::TwoLevel, 4, 3).is_err());
    }
}
