//! `coordinator rays select`: runs a selection over a map (`selection`) on `--threads` threads, says what it
//! found and writes the outputs (`outputs`).

use super::overlay::OverlayStyle;
use super::selection::run_selection;
use super::{outputs, render_folder};
use crate::cli::RaysSelectArgs;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

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
    let out = args.out.clone().unwrap_or_else(|| render_folder(&args.map).join("selection"));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let pictures =
        outputs::Pictures { overlay: OverlayStyle { colour: args.colour, max_paths: args.draw }, glb: !args.no_glb };
    let written = outputs::write_all(&out, &args.map, &header, &selection, &args.expr, pictures)?;
    for (what, file) in written {
        say!("{what}: {}", file.display());
    }
    Ok(())
}
