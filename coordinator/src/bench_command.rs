//! `coordinator bench`: scenes × methods × core counts × repeats for a time budget, every run a real
//! `coordinator render` process (so its peak memory is its own), reported as the paper's tables (rays, tracing
//! speedup, accuracy, memory) in the terminal, `report.md`, `results.csv` (one row per run) and `series.csv`
//! (error against time and rays, for the charts).

use crate::cli::{BenchArgs, MethodArg};
use crate::output_folder;
use crate::render_command::parallel_method;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use worker::{machine, EngineConfig};

/// Seconds per run and the methods of `--quick`: every method once on both scenes in under five minutes.
const QUICK_TIME: f64 = 8.0;

/// One benchmark run, read back from its `run.json`.
struct Row {
    scene: String,
    method: String,
    /// "this machine" for one process, the synthetic description of a distributed run's nodes.
    topology: String,
    processes: usize,
    groups: usize,
    threads_per_group: usize,
    threads: usize,
    repeat: u32,
    /// Until the last phases were merged (the run's last history entry).
    wall_s: f64,
    phases: u64,
    backward_rays: u64,
    forward_rays: u64,
    merges: u64,
    light_paths: u64,
    /// Light paths counted against the photon maps (once per map a path gathered into).
    map_light_paths: u64,
    delta_unlit: f64,
    delta_all: f64,
    true_unlit: Option<f64>,
    true_all: Option<f64>,
    /// The reference's own δ over unlit pixels: it adds in quadrature to every true error of the run.
    reference_delta_unlit: Option<f64>,
    /// The largest peak resident memory of the run's processes (coordinator and workers).
    peak_memory_bytes: Option<u64>,
    bytes_per_pixel: f64,
    /// Fraction of thread time idle at and between synchronisation rounds (in-process parallel engines).
    idle: Option<f64>,
    /// Distributed runs: mean bytes per snapshot and per second per worker.
    snapshot_bytes: Option<(f64, f64)>,
    series: Vec<SeriesPoint>,
}

/// One point of a run's error against time and rays.
struct SeriesPoint {
    time_s: f64,
    rays: u64,
    delta_unlit: f64,
    delta_all: f64,
    true_unlit: Option<f64>,
    true_all: Option<f64>,
}

impl Row {
    fn rays(&self) -> f64 {
        (self.backward_rays + self.forward_rays) as f64
    }

    fn rays_per_second(&self) -> f64 {
        self.rays() / self.wall_s.max(1e-9)
    }

    /// How many photon maps a light path served on average: above 1 where groups share their maps. None for
    /// runs without light paths (the path tracer) and for records older than the count.
    fn maps_per_light_path(&self) -> Option<f64> {
        (self.light_paths > 0 && self.map_light_paths > 0)
            .then(|| self.map_light_paths as f64 / self.light_paths as f64)
    }

    /// One progress line per finished run.
    fn announce(&self, done: usize, runs: usize) {
        eprintln!(
            "[{done}/{runs}] {} {} {} threads, run {}: {:.2} M rays in {:.1} s, δ unlit {:.2}%{}",
            self.scene,
            self.method,
            self.threads,
            self.repeat + 1,
            self.rays() / 1e6,
            self.wall_s,
            100.0 * self.delta_unlit,
            self.true_unlit.map(|t| format!(", true error {:.2}%", 100.0 * t)).unwrap_or_default()
        );
    }
}

fn method_name(m: MethodArg) -> String {
    m.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()
}

/// The scene's reference image, if one is shipped: the path tracer's, or PBPM's where the path tracer cannot
/// converge.
pub fn reference_of(scene: &str) -> Option<PathBuf> {
    ["path", "pbpm"]
        .iter()
        .map(|m| PathBuf::from("scenes/references").join(format!("{scene}-{m}.exr")))
        .find(|p| p.exists())
}

/// The layout a run will have: (topology, processes, groups, threads per group), or None when the method does
/// not run at this thread count (the single-threaded estimators at more than one thread).
fn layout_of(method: MethodArg, threads: usize, args: &BenchArgs) -> Result<Option<(String, usize, usize, usize)>> {
    Ok(match method {
        MethodArg::Pbpm | MethodArg::Path => (threads == 1).then(|| ("this machine".into(), 1, 1, 1)),
        MethodArg::Combination | MethodArg::ThreeLevel => {
            // One worker per synthetic node of one core: the node's group layout is that of one thread.
            Some((format!("synthetic {}", synthetic_nodes(threads)), threads, threads, 1))
        }
        m => {
            let p = parallel_method(m).expect("in-process parallel method");
            let c = EngineConfig::for_method(p, threads, args.group_size.min(threads), (0..threads).collect())?;
            Some(("this machine".into(), 1, c.groups, c.threads_per_group))
        }
    })
}

fn synthetic_nodes(n: usize) -> String {
    format!("pack:1 numa:{n} core:1 pu:1")
}

/// Runs `coordinator render` for one configuration and reads its record.
fn run_one(
    scene: &str,
    method: MethodArg,
    threads: usize,
    repeat: u32,
    args: &BenchArgs,
    dir: &Path,
) -> Result<Option<Row>> {
    let Some((topology, processes, groups, threads_per_group)) = layout_of(method, threads, args)? else {
        return Ok(None);
    };
    let name = method_name(method);
    let out = dir.join("runs").join(format!("{scene}-{name}-{threads}t-r{repeat}"));
    let exe = std::env::current_exe().context("cannot find this program")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["render", &format!("scenes/{scene}.toml"), "--quiet", "--method", &name])
        .args(["--time", &args.time.to_string(), "--seed", &(args.seed + repeat as u64).to_string()])
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null());
    if method.is_distributed() {
        cmd.args(["--topology", &synthetic_nodes(threads), "--group-size", &args.group_size.to_string()]);
    } else if parallel_method(method).is_some() {
        cmd.args(["--threads", &threads.to_string(), "--group-size", &args.group_size.min(threads).to_string()]);
        if let Some(cores) = &args.cores {
            cmd.args(["--cores", cores]);
        }
    }
    if let Some(reference) = reference_of(scene) {
        cmd.arg("--reference").arg(reference);
    }
    // The run's notes (flags) are in its run.json; its terminal output only matters when it fails.
    let output = cmd.stderr(std::process::Stdio::piped()).output().context("cannot start the render")?;
    if !output.status.success() {
        bail!(
            "the {name} run on {scene} at {threads} threads failed ({}): {}; its output is in {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim(),
            out.display()
        );
    }
    let path = out.join("run.json");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?)
            .with_context(|| format!("{} is not a run record", path.display()))?;
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let u = |v: &serde_json::Value| v.as_u64().unwrap_or(0);
    let history = r["history"].as_array().cloned().unwrap_or_default();
    let series: Vec<SeriesPoint> = history
        .iter()
        .map(|h| SeriesPoint {
            time_s: f(&h["time_s"]),
            rays: u(&h["backward_rays"]) + u(&h["forward_rays"]),
            delta_unlit: f(&h["delta_unlit"]),
            delta_all: f(&h["delta_all"]),
            true_unlit: h["true_unlit"].as_f64(),
            true_all: h["true_all"].as_f64(),
        })
        .collect();
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
    let row = Row {
        scene: scene.to_string(),
        method: name,
        topology,
        processes: if workers.is_empty() { processes } else { workers.len() },
        groups,
        threads_per_group,
        threads,
        repeat,
        wall_s: wall,
        phases: u(&r["totals"]["phases"]),
        backward_rays: u(&r["totals"]["backward_rays"]),
        forward_rays: u(&r["totals"]["forward_rays"]),
        merges: u(&r["totals"]["merges"]),
        light_paths: u(&r["totals"]["light_paths"]),
        map_light_paths: u(&r["totals"]["map_light_paths"]),
        delta_unlit: f(&r["error"]["delta_unlit"]),
        delta_all: f(&r["error"]["delta_all"]),
        true_unlit: r["true_error"]["rmse_unlit"].as_f64(),
        true_all: r["true_error"]["rmse_all"].as_f64(),
        reference_delta_unlit: r["true_error"]["reference_delta_unlit"].as_f64(),
        peak_memory_bytes: peak,
        bytes_per_pixel: f(&r["bytes_per_pixel"]),
        idle: if method.is_distributed() { None } else { idle },
        snapshot_bytes,
        series,
    };
    Ok(Some(row))
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
    let mut plan = Vec::new();
    for repeat in 0..args.repeats {
        for scene in &args.scenes {
            for &method in &args.methods {
                for &t in &threads {
                    if layout_of(method, t, &args)?.is_some() {
                        plan.push((scene.clone(), method, t, repeat));
                    }
                }
            }
        }
    }
    eprintln!(
        "{} runs of {} s each, about {:.0} minutes; results in {}",
        plan.len(),
        args.time,
        plan.len() as f64 * (args.time + 0.7) / 60.0,
        dir.display()
    );
    let mut rows: Vec<Row> = Vec::new();
    let mut series =
        String::from("scene,method,threads,repeat,time_s,rays,delta_unlit,delta_all,true_unlit,true_all\n");
    for (i, (scene, method, t, repeat)) in plan.iter().enumerate() {
        let Some(row) = run_one(scene, *method, *t, *repeat, &args, &dir)? else { continue };
        row.announce(i + 1, plan.len());
        for p in &row.series {
            let _ = writeln!(
                series,
                "{},{},{},{},{:.4},{},{},{},{},{}",
                row.scene,
                row.method,
                row.threads,
                row.repeat,
                p.time_s,
                p.rays,
                p.delta_unlit,
                p.delta_all,
                opt(p.true_unlit),
                opt(p.true_all)
            );
        }
        rows.push(row);
        // Written after every run, so an interrupted bench keeps what it measured.
        write(&dir.join("results.csv"), &csv(&rows))?;
        write(&dir.join("series.csv"), &series)?;
    }
    let report = report(&rows, &args, &threads);
    println!("{report}");
    write(&dir.join("report.md"), &report)?;
    let charts = crate::charts::write_charts(&dir)?;
    println!("{} charts in {}", charts.len(), dir.join("charts").display());
    println!("wrote {}", dir.display());
    Ok(())
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

fn opt(x: Option<f64>) -> String {
    x.map(|v| v.to_string()).unwrap_or_default()
}

fn pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:.2}%", 100.0 * v)).unwrap_or_else(|| "–".into())
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn opt_mean(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = values.flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The report: Table 1 (rays, tracing speedup against the same method at the fewest threads, accuracy,
/// memory), the distributed runs' traffic, and the goals computed from the runs.
fn report(rows: &[Row], args: &BenchArgs, threads: &[usize]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} run(s) of {} s per configuration. Tracing speedup = rays per second / (rays per second of the same \
         method at {} thread(s)) × {}; δ range over runs in brackets; \"unlit\" = pixels that do not see a light \
         directly.\n",
        args.repeats, args.time, threads[0], threads[0]
    );
    let _ = writeln!(s, "| scene | method | threads | processes × groups × threads | forward rays | backward rays | tracing speedup | δ unlit / all | true error unlit / all | peak memory | bytes/pixel | idle | maps per light path |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut keys: Vec<(&str, &str, usize)> = Vec::new();
    for r in rows {
        let k = (r.scene.as_str(), r.method.as_str(), r.threads);
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for &(scene, method, t) in &keys {
        let group: Vec<&Row> =
            rows.iter().filter(|r| (r.scene.as_str(), r.method.as_str(), r.threads) == (scene, method, t)).collect();
        let first =
            rows.iter().filter(|r| r.scene == scene && r.method == method).map(|r| r.threads).min().unwrap_or(t);
        let base: Vec<&Row> =
            rows.iter().filter(|r| r.scene == scene && r.method == method && r.threads == first).collect();
        let speedup = mean(group.iter().map(|r| r.rays_per_second())) / mean(base.iter().map(|r| r.rays_per_second()))
            * first as f64;
        let (lo, hi) =
            group.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(r.delta_unlit), hi.max(r.delta_unlit)));
        let range = if group.len() > 1 { format!(" [{:.2}–{:.2}%]", 100.0 * lo, 100.0 * hi) } else { String::new() };
        let g = group[0];
        let _ = writeln!(
            s,
            "| {scene} | {method} | {t} | {}×{}×{} | {:.2} M | {:.2} M | {:.2}× | {:.2}%{range} / {:.2}% | {} / {} | {} | {:.0} | {} | {} |",
            g.processes,
            g.groups / g.processes.max(1),
            g.threads_per_group,
            mean(group.iter().map(|r| r.forward_rays as f64)) / 1e6,
            mean(group.iter().map(|r| r.backward_rays as f64)) / 1e6,
            speedup,
            100.0 * mean(group.iter().map(|r| r.delta_unlit)),
            100.0 * mean(group.iter().map(|r| r.delta_all)),
            pct(opt_mean(group.iter().map(|r| r.true_unlit))),
            pct(opt_mean(group.iter().map(|r| r.true_all))),
            opt_mean(group.iter().map(|r| r.peak_memory_bytes.map(|b| b as f64)))
                .map(|b| format!("{:.0} MB", b / 1e6))
                .unwrap_or_else(|| "–".into()),
            mean(group.iter().map(|r| r.bytes_per_pixel)),
            pct(opt_mean(group.iter().map(|r| r.idle))),
            opt_mean(group.iter().map(|r| r.maps_per_light_path())).map_or_else(|| "–".into(), |m| format!("{m:.2}")),
        );
    }
    let distributed: Vec<&Row> = rows.iter().filter(|r| r.snapshot_bytes.is_some()).collect();
    if !distributed.is_empty() {
        let _ = writeln!(s, "\nDistributed runs (one worker process per synthetic NUMA node of one core):\n");
        let _ = writeln!(s, "| scene | method | threads | run | rays/s | MB per snapshot | KB/s per worker |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in distributed {
            let (per, rate) = r.snapshot_bytes.unwrap_or_default();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.2} M | {:.2} | {:.0} |",
                r.scene,
                r.method,
                r.threads,
                r.repeat + 1,
                r.rays_per_second() / 1e6,
                per / 1e6,
                rate / 1e3
            );
        }
    }
    goals(&mut s, rows);
    s
}

/// The first time a run's true error (unlit pixels) is at or below `target`.
fn time_to_reach(run: &Row, target: f64) -> Option<f64> {
    run.series.iter().find(|p| p.true_unlit.is_some_and(|e| e <= target)).map(|p| p.time_s)
}

/// Issue 5's goals, computed from the single-threaded PBPM and path-tracer runs and every run's series.
fn goals(s: &mut String, rows: &[Row]) {
    let _ = writeln!(
        s,
        "
Goals (true error = relative RMSE against the scene's reference, unlit pixels):
"
    );
    let one = |scene: &str, method: &str| -> Vec<&Row> {
        rows.iter().filter(|r| r.scene == scene && r.method == method && r.threads == 1).collect()
    };
    let mut any = false;
    for scene in rows.iter().map(|r| r.scene.as_str()).collect::<std::collections::BTreeSet<_>>() {
        let (path, pbpm) = (one(scene, "path"), one(scene, "pbpm"));
        let path_error = opt_mean(path.iter().map(|r| r.true_unlit));
        let pbpm_error = opt_mean(pbpm.iter().map(|r| r.true_unlit));
        if let (Some(e_path), Some(e_pbpm)) = (path_error, pbpm_error) {
            any = true;
            let t_path = mean(path.iter().map(|r| r.wall_s));
            let reach: Vec<Option<f64>> = pbpm.iter().map(|r| time_to_reach(r, e_path)).collect();
            let reach_text = if reach.iter().all(Option::is_some) {
                let t = mean(reach.iter().flatten().copied());
                format!("{t:.1} s = {:.2} of the path tracer's time (goal on caustic ≤ 0.25)", t / t_path)
            } else {
                "not within the run".into()
            };
            let _ = writeln!(
                s,
                "- {scene}: path tracer {:.2}% after {t_path:.0} s, PBPM {:.2}% at equal time (ratio {:.2}; goal on cornell ≤ 1.5). PBPM reaches the path tracer's final error: {reach_text}.",
                100.0 * e_path,
                100.0 * e_pbpm,
                e_pbpm / e_path
            );
        }
        // Calibration: true error / δ wherever δ < 10%, δ combined in quadrature with the reference's own.
        let ratios: Vec<f64> = rows
            .iter()
            .filter(|r| r.scene == scene && r.method != "path")
            .flat_map(|r| r.series.iter().map(move |p| (p, r.reference_delta_unlit.unwrap_or(0.0))))
            .filter(|(p, _)| p.delta_unlit < 0.10)
            .filter_map(|(p, d_ref)| p.true_unlit.map(|t| t / p.delta_unlit.hypot(d_ref)))
            .filter(|x| x.is_finite())
            .collect();
        if !ratios.is_empty() {
            any = true;
            let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = ratios.iter().copied().fold(0.0, f64::max);
            let d_ref = rows.iter().find(|r| r.scene == scene).and_then(|r| r.reference_delta_unlit);
            let _ = writeln!(
                s,
                "- {scene}: the reference's own δ {}; calibration, true error / √(δ² + δ_ref²) over {} points of PBPM runs with δ < 10%: {lo:.2} … {hi:.2} (goal within 0.5 … 2).",
                pct(d_ref),
                ratios.len()
            );
        }
    }
    any |= parallel_goals(s, rows);
    if !any {
        let _ = writeln!(s, "- (needs path and pbpm runs on scenes with a reference)");
    }
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

/// Issue 3's goals at every thread count above the fewest: two-level's tracing speedup, and its δ at equal time
/// against sync and async as the mean ratio over runs paired by repeat, with its standard error. Repeats are
/// interleaved, so the two runs of a pair share the machine's drift, and the pairing cancels most of it.
fn parallel_goals(s: &mut String, rows: &[Row]) -> bool {
    let mut any = false;
    let of = |scene: &str, method: &str, t: usize| -> Vec<&Row> {
        rows.iter().filter(|r| r.scene == scene && r.method == method && r.threads == t).collect()
    };
    let scenes: std::collections::BTreeSet<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    for scene in scenes {
        let counts: std::collections::BTreeSet<usize> =
            rows.iter().filter(|r| r.scene == scene && r.method == "two-level").map(|r| r.threads).collect();
        let Some(&fewest) = counts.first() else { continue };
        for &t in counts.iter().filter(|&&t| t > fewest) {
            let two = of(scene, "two-level", t);
            let speedup = mean(two.iter().map(|r| r.rays_per_second()))
                / mean(of(scene, "two-level", fewest).iter().map(|r| r.rays_per_second()))
                * fewest as f64;
            let mut line = format!("- {scene}, {t} threads: two-level tracing speedup {speedup:.2}× (goal ≥ 1.9)");
            for other in ["sync", "async"] {
                let ratios: Vec<f64> = two
                    .iter()
                    .filter_map(|a| {
                        of(scene, other, t)
                            .into_iter()
                            .find(|b| b.repeat == a.repeat)
                            .map(|b| a.delta_unlit / b.delta_unlit)
                    })
                    .collect();
                if !ratios.is_empty() {
                    let (m, se) = mean_and_sem(&ratios);
                    let _ = write!(line, "; δ unlit two-level / {other} {m:.3} ± {se:.3}");
                }
            }
            let _ = writeln!(s, "{line} (mean ± standard error over runs paired by repeat; goal ≤ 1).");
            any = true;
        }
    }
    any
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "scene,method,topology,processes,groups,threads_per_group,threads,repeat,wall_s,backward_rays,forward_rays,\
         merges,light_paths,map_light_paths,phases,delta_unlit,delta_all,true_unlit,true_all,peak_memory_bytes,\
         bytes_per_pixel,idle_fraction,reference_delta_unlit\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{:.4},{},{},{},{},{},{},{},{},{},{},{},{:.1},{},{}",
            r.scene,
            r.method,
            r.topology.replace(',', ";"),
            r.processes,
            r.groups,
            r.threads_per_group,
            r.threads,
            r.repeat,
            r.wall_s,
            r.backward_rays,
            r.forward_rays,
            r.merges,
            r.light_paths,
            r.map_light_paths,
            r.phases,
            r.delta_unlit,
            r.delta_all,
            opt(r.true_unlit),
            opt(r.true_all),
            r.peak_memory_bytes.map(|b| b.to_string()).unwrap_or_default(),
            r.bytes_per_pixel,
            opt(r.idle),
            opt(r.reference_delta_unlit)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, threads: usize, repeat: u32, delta_unlit: f64, rays: u64) -> Row {
        Row {
            scene: "cornell".into(),
            method: method.into(),
            topology: "this machine".into(),
            processes: 1,
            groups: 1,
            threads_per_group: threads,
            threads,
            repeat,
            wall_s: 10.0,
            phases: 100,
            backward_rays: rays,
            forward_rays: 0,
            merges: 0,
            light_paths: 0,
            map_light_paths: 0,
            delta_unlit,
            delta_all: delta_unlit,
            true_unlit: None,
            true_all: None,
            reference_delta_unlit: None,
            peak_memory_bytes: None,
            bytes_per_pixel: 0.0,
            idle: None,
            snapshot_bytes: None,
            series: Vec::new(),
        }
    }

    #[test]
    fn two_level_is_compared_with_sync_and_async_run_by_run_of_the_same_repeat() {
        let rows = vec![
            row("two-level", 1, 0, 0.06, 100),
            row("two-level", 2, 0, 0.044, 190),
            row("async", 2, 0, 0.040, 200),
            row("two-level", 2, 1, 0.036, 194),
            row("async", 2, 1, 0.040, 200),
            // No sync run of repeat 0: the one sync pair is repeat 1's.
            row("sync", 2, 1, 0.045, 180),
        ];
        let mut s = String::new();
        assert!(parallel_goals(&mut s, &rows));
        // Ratios to async 1.1 and 0.9: mean 1, standard error 0.1; the speedup from the mean rays per second.
        assert!(s.contains("- cornell, 2 threads: two-level tracing speedup 1.92× (goal ≥ 1.9)"), "{s}");
        assert!(s.contains("two-level / sync 0.800 ± 0.000"), "{s}");
        assert!(s.contains("two-level / async 1.000 ± 0.100"), "{s}");
        // Without two-level at two thread counts there is nothing to compare.
        let mut none = String::new();
        assert!(!parallel_goals(&mut none, &rows[2..3]));
        assert!(none.is_empty());
    }
}
