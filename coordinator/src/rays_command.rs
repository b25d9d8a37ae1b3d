//! `coordinator rays select`: streams a ray map's portions, decompresses and tests them in parallel against a
//! selection expression, and hands the first `--limit` matches to `rays_outputs`.

use crate::cli::RaysSelectArgs;
use crate::rays_outputs;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use photonfarm::ray_map::reader::{open_streams, RawPortion};
use photonfarm::ray_map::select::{parse, Expr};
use photonfarm::ray_map::{MapHeader, RecordedPath};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Portions read ahead per thread before a batch is tested: enough to keep every thread busy.
const BATCH_PER_THREAD: usize = 4;

/// What a selection found.
#[derive(Debug, Default)]
pub struct Selection {
    /// The first matches in map order, up to the limit.
    pub paths: Vec<RecordedPath>,
    pub matched_paths: u64,
    pub matched_segments: u64,
    pub total_paths: u64,
    pub total_segments: u64,
    /// Bytes cut off truncated streams, per stream file.
    pub truncated: Vec<(PathBuf, u64)>,
    /// Damaged portions, skipped (a damaged frame) or ending their stream (a damaged portion header): why.
    pub damaged: Vec<String>,
}

/// Runs `rays select`.
pub fn select(args: RaysSelectArgs) -> Result<()> {
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if threads == 0 {
        bail!("--threads must be at least 1");
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("cannot start the threads")?;
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {bytes}/{total_bytes} {msg} [{elapsed_precise}]")
            .expect("static template"),
    );
    let start = std::time::Instant::now();
    let (header, selection) = pool.install(|| run_selection(&args.map, &args.expr, args.limit, &bar))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    for why in &selection.damaged {
        eprintln!("warning: {why}");
    }
    for (file, bytes) in &selection.truncated {
        eprintln!(
            "note: {} ends inside a portion (a stopped run): its last {bytes} bytes were left, every whole portion was read",
            file.display()
        );
    }
    say!(
        "{} of {} paths match ({} of {} segments) in {:.2} s ({:.1} M segments/s on {threads} threads)",
        selection.matched_paths,
        selection.total_paths,
        selection.matched_segments,
        selection.total_segments,
        seconds,
        selection.total_segments as f64 / seconds.max(1e-9) / 1e6,
    );
    let out = match &args.out {
        Some(dir) => dir.clone(),
        None => default_out(&args.map),
    };
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let written = rays_outputs::write_all(&out, &args.map, &header, &selection, &args.expr, args.colour)?;
    for (what, file) in written {
        say!("{what}: {}", file.display());
    }
    Ok(())
}

/// selection/ in the render's output folder that holds the map.
fn default_out(map: &Path) -> PathBuf {
    render_folder(map).join("selection")
}

/// The render's output folder of a map given as that folder, its raymap/ folder or a stream file in it.
pub fn render_folder(map: &Path) -> PathBuf {
    let dir = if map.is_file() { map.parent().unwrap_or(Path::new(".")) } else { map };
    if dir.join("raymap").is_dir() {
        dir.to_path_buf()
    } else {
        dir.parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf)
    }
}

/// Reads every stream of the map at `map`, tests each path against `expr` and keeps the first `limit` matches
/// in map order. Runs on the current rayon pool.
pub fn run_selection(map: &Path, expr: &str, limit: usize, bar: &ProgressBar) -> Result<(MapHeader, Selection)> {
    let mut streams = open_streams(map)?;
    let header = streams[0].header().clone();
    let expr = parse(expr, &header).map_err(|e| anyhow::anyhow!("--where: {e}"))?;
    bar.set_length(streams.iter().map(|s| s.len()).sum());
    let batch = BATCH_PER_THREAD * rayon::current_num_threads();
    let mut selection = Selection::default();
    for stream in &mut streams {
        let mut portions: Vec<RawPortion> = Vec::with_capacity(batch);
        loop {
            // A damaged portion header leaves no way to find the next portion: the stream ends there.
            let next = stream.next_portion().unwrap_or_else(|e| {
                selection.damaged.push(format!("{e}; the rest of this stream was not read"));
                None
            });
            let end = next.is_none();
            if let Some(p) = next {
                bar.inc((p.frame.len() + photonfarm::ray_map::format::PORTION_HEADER_BYTES) as u64);
                portions.push(p);
            }
            if portions.len() == batch || (end && !portions.is_empty()) {
                test_batch(&portions, &expr, header.width, limit, &mut selection);
                bar.set_message(format!("{} matching paths", selection.matched_paths));
                portions.clear();
            }
            if end {
                break;
            }
        }
        if let Some(bytes) = stream.truncated_bytes() {
            selection.truncated.push((stream.path().to_path_buf(), bytes));
        }
    }
    Ok((header, selection))
}

/// Decompresses and tests a batch of portions in parallel, then adds their results in map order; a portion
/// whose frame is damaged is skipped and noted.
fn test_batch(portions: &[RawPortion], expr: &Expr, width: u32, limit: usize, sel: &mut Selection) {
    let results: Vec<_> = portions
        .par_iter()
        .map(|p| -> Result<_, photonfarm::ray_map::RayMapError> {
            let paths = p.decode()?;
            let mut matched = Vec::new();
            let mut matched_segments = 0;
            for path in paths {
                if expr.matches(&path, width) {
                    matched_segments += path.segments() as u64;
                    matched.push(path);
                }
            }
            Ok((p.header.paths as u64, p.header.segments as u64, matched, matched_segments))
        })
        .collect();
    for r in results {
        let (paths, segments, matched, matched_segments) = match r {
            Ok(r) => r,
            Err(e) => {
                sel.damaged.push(format!("{e}; it was skipped"));
                continue;
            }
        };
        sel.total_paths += paths;
        sel.total_segments += segments;
        sel.matched_paths += matched.len() as u64;
        sel.matched_segments += matched_segments;
        let room = limit.saturating_sub(sel.paths.len());
        sel.paths.extend(matched.into_iter().take(room));
    }
}
