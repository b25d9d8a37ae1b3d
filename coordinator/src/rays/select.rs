//! `coordinator rays select`: the rayon threads take a ray map's portions in map order, one at a time, and each
//! decompresses its portion straight from the stream's mapping and tests it against a selection expression, each
//! path read in place; the portions' results are combined in map order, and the first `--limit` matches go to
//! `outputs`.

use super::overlay::OverlayStyle;
use super::{outputs, render_folder, Selection};
use crate::cli::RaysSelectArgs;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use photonfarm::ray_map::format::PORTION_HEADER_BYTES;
use photonfarm::ray_map::reader::{open_streams, RawPortion, StreamReader};
use photonfarm::ray_map::select::{parse, Expr};
use photonfarm::ray_map::{MapHeader, RecordedPath};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

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
        tracing::warn!("{why}");
    }
    for (file, bytes) in &selection.truncated {
        tracing::warn!(
            "{} ends inside a portion (a stopped run): its last {bytes} bytes were left, every whole portion was read",
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
    let pictures =
        outputs::Pictures { overlay: OverlayStyle { colour: args.colour, max_paths: args.draw }, glb: !args.no_glb };
    let written = outputs::write_all(&out, &args.map, &header, &selection, &args.expr, pictures)?;
    for (what, file) in written {
        say!("{what}: {}", file.display());
    }
    Ok(())
}

/// selection/ in the render's output folder that holds the map.
fn default_out(map: &Path) -> PathBuf {
    render_folder(map).join("selection")
}

/// Reads every stream of the map at `map`, tests each path against `expr` and keeps the first `limit` matches
/// in map order, whatever the number of threads. Runs on every thread of the current rayon pool.
pub fn run_selection(map: &Path, expr: &str, limit: usize, bar: &ProgressBar) -> Result<(MapHeader, Selection)> {
    let streams = open_streams(map)?;
    let header = streams[0].header().clone();
    let expr = parse(expr, &header).map_err(|e| anyhow::anyhow!("--where: {e}"))?;
    bar.set_length(streams.iter().map(|s| s.len()).sum());
    let walk = Mutex::new(Walk { streams: streams.into_iter(), current: None, number: 0, bar });
    let merger = Mutex::new(Merger { limit, ..Merger::default() });
    // Portions from this number on need not keep their matches: the first `limit` are in before them.
    let unneeded_from = AtomicUsize::new(if limit == 0 { 0 } else { usize::MAX });
    // No reader thread: taking the next portion of a mapped stream is reading its 20-byte header, so each thread
    // takes its own and decompresses it from the mapping, and the work stays in map order.
    rayon::broadcast(|_| {
        // An unmapped stream's frames are read into this thread's buffer, reused from portion to portion.
        let mut buffer = Vec::new();
        loop {
            let next = walk.lock().unwrap_or_else(PoisonError::into_inner).next(&mut buffer);
            let Some((number, item)) = next else { break };
            let keep = if number < unneeded_from.load(Ordering::Relaxed) { limit } else { 0 };
            let (outcome, frame) = test_item(item, &expr, header.width, keep);
            if let Some(frame) = frame {
                buffer = frame;
            }
            let mut merger = merger.lock().unwrap_or_else(PoisonError::into_inner);
            merger.add(number, outcome, &unneeded_from);
            if !bar.is_hidden() {
                bar.set_message(format!("{} matching paths", merger.selection.matched_paths));
            }
        }
    });
    let merger = merger.into_inner().unwrap_or_else(PoisonError::into_inner);
    Ok((header, merger.selection))
}

/// What the walk hands on, numbered in map order: a portion, or how a stream ended before its end.
enum Item {
    Portion(RawPortion),
    /// A damaged portion header, which ends its stream: why.
    Damaged(String),
    /// A stream that ends inside a portion: the file and the bytes after its last whole portion.
    Truncated(PathBuf, u64),
}

/// The streams' portions in map order, handed out one at a time to whichever thread asks next.
struct Walk<'b> {
    streams: std::vec::IntoIter<StreamReader>,
    current: Option<StreamReader>,
    number: usize,
    bar: &'b ProgressBar,
}

impl Walk<'_> {
    /// The next item and its number, None once every stream is done. An unmapped stream's frame is read into
    /// `buffer`'s allocation.
    fn next(&mut self, buffer: &mut Vec<u8>) -> Option<(usize, Item)> {
        loop {
            let stream = match &mut self.current {
                Some(stream) => stream,
                None => self.current.insert(self.streams.next()?),
            };
            let item = match stream.next_portion_into(buffer) {
                Ok(Some(p)) => {
                    self.bar.inc((p.frame.len() + PORTION_HEADER_BYTES) as u64);
                    Item::Portion(p)
                }
                Ok(None) => {
                    let (file, cut) = (stream.path().to_path_buf(), stream.truncated_bytes());
                    self.current = None;
                    match cut {
                        Some(bytes) => Item::Truncated(file, bytes),
                        None => continue,
                    }
                }
                // A damaged portion header leaves no way to find the next portion: the stream ends there.
                Err(e) => {
                    self.current = None;
                    Item::Damaged(format!("{e}; the rest of this stream was not read"))
                }
            };
            self.number += 1;
            return Some((self.number - 1, item));
        }
    }
}

/// What testing one portion found.
#[derive(Default)]
struct Tested {
    paths: u64,
    segments: u64,
    matched_paths: u64,
    matched_segments: u64,
    /// The portion's first matches, up to the number asked for.
    kept: Vec<RecordedPath>,
}

/// An item's result, to be combined in map order.
enum Outcome {
    Tested(Tested),
    Damaged(String),
    Truncated(PathBuf, u64),
}

/// Decompresses a portion and tests its paths in place, decoding only its first `keep` matches; a portion whose
/// frame is damaged is skipped and noted. Also gives back the buffer of a frame that was read, for reuse.
fn test_item(item: Item, expr: &Expr, width: u32, keep: usize) -> (Outcome, Option<Vec<u8>>) {
    let portion = match item {
        Item::Portion(p) => p,
        Item::Damaged(why) => return (Outcome::Damaged(why), None),
        Item::Truncated(file, bytes) => return (Outcome::Truncated(file, bytes), None),
    };
    let tested = portion.with_paths(|views| {
        let mut t = Tested {
            paths: portion.header.paths as u64,
            segments: portion.header.segments as u64,
            ..Tested::default()
        };
        for view in views {
            let view = view?;
            if expr.matches(&view, width) {
                t.matched_paths += 1;
                t.matched_segments += view.segments() as u64;
                if t.kept.len() < keep {
                    t.kept.push(view.to_path());
                }
            }
        }
        Ok(t)
    });
    let outcome = match tested {
        Ok(t) => Outcome::Tested(t),
        Err(e) => Outcome::Damaged(format!("{e}; it was skipped")),
    };
    (outcome, portion.into_buffer())
}

/// Combines the portions' outcomes in map order, whatever order they arrive in.
#[derive(Default)]
struct Merger {
    limit: usize,
    /// The number of the next outcome to combine.
    next: usize,
    waiting: BTreeMap<usize, Outcome>,
    selection: Selection,
}

impl Merger {
    /// Adds outcome `number`, combines every outcome now in order, and lowers `unneeded_from` once the first
    /// `limit` matches are in.
    fn add(&mut self, number: usize, outcome: Outcome, unneeded_from: &AtomicUsize) {
        self.waiting.insert(number, outcome);
        while let Some(outcome) = self.waiting.remove(&self.next) {
            self.next += 1;
            let sel = &mut self.selection;
            match outcome {
                Outcome::Tested(t) => {
                    sel.total_paths += t.paths;
                    sel.total_segments += t.segments;
                    sel.matched_paths += t.matched_paths;
                    sel.matched_segments += t.matched_segments;
                    let room = self.limit.saturating_sub(sel.paths.len());
                    sel.paths.extend(t.kept.into_iter().take(room));
                }
                Outcome::Damaged(why) => sel.damaged.push(why),
                Outcome::Truncated(file, bytes) => sel.truncated.push((file, bytes)),
            }
            if sel.paths.len() >= self.limit {
                unneeded_from.fetch_min(self.next, Ordering::Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::ray_map::PathKind;

    /// Portion `n`'s outcome: `matches` matches numbered after the portion, or a damaged portion or a cut stream.
    fn outcome(n: usize, matches: usize) -> Outcome {
        match n % 5 {
            3 => Outcome::Damaged(format!("portion {n}")),
            4 => Outcome::Truncated(PathBuf::from(format!("stream-{n}")), n as u64),
            _ => Outcome::Tested(Tested {
                paths: 10,
                segments: 30,
                matched_paths: matches as u64,
                matched_segments: 3 * matches as u64,
                kept: (0..matches).map(|i| RecordedPath::new(PathKind::Camera, 1, (100 * n + i) as u32, 0)).collect(),
            }),
        }
    }

    fn merged(order: &[usize], limit: usize) -> (String, usize) {
        let (mut merger, unneeded_from) = (Merger { limit, ..Merger::default() }, AtomicUsize::new(usize::MAX));
        for &n in order {
            merger.add(n, outcome(n, 4), &unneeded_from);
        }
        assert!(merger.waiting.is_empty() && merger.next == order.len());
        (format!("{:?}", merger.selection), unneeded_from.into_inner())
    }

    #[test]
    fn outcomes_arriving_in_any_order_are_combined_in_map_order_up_to_the_limit() {
        let in_order: Vec<usize> = (0..12).collect();
        let shuffled = [5, 0, 11, 2, 1, 9, 3, 4, 10, 7, 6, 8];
        let (first, unneeded) = merged(&in_order, 6);
        assert_eq!(merged(&shuffled, 6), (first.clone(), unneeded));
        assert_eq!(merged(&in_order.iter().rev().copied().collect::<Vec<_>>(), 6).0, first);
        // Portions 0 and 1 hold the first 8 matches: from portion 2 on, none needs keeping.
        assert_eq!(unneeded, 2);
        let mut merger = Merger { limit: 6, ..Merger::default() };
        for n in shuffled {
            merger.add(n, outcome(n, 4), &AtomicUsize::new(usize::MAX));
        }
        let sel = merger.selection;
        let items: Vec<u32> = sel.paths.iter().map(|p| p.item).collect();
        assert_eq!(items, [0, 1, 2, 3, 100, 101]);
        assert_eq!((sel.total_paths, sel.matched_paths, sel.matched_segments), (80, 32, 96));
        assert_eq!(sel.damaged, ["portion 3", "portion 8"]);
        assert_eq!(sel.truncated.iter().map(|t| t.1).collect::<Vec<_>>(), [4, 9]);
    }
}
