//! The lines of the charts drawn from `series.csv` (error against time, against rays, calibration): one per
//! (method, threads) and repeat of a scene, and the split of a scene's keys into charts that can tell them apart.

use super::first_appearances;
use super::plot::{Curve, LegendEntry, Line, Stroke};
use super::style::{method_colour, ThreadMarkers};
use crate::bench::tables::SeriesRow;

/// The pixels the error charts measure over.
pub(super) const UNLIT: &str = "pixels that do not see a light directly";

/// Most (method, threads) keys in one error chart: past this, a scene's error charts are split by thread count.
const MAX_KEYS_PER_CHART: usize = 12;

/// One line per (method, threads) and repeat of a scene's series for each curve, in the method's colour with the
/// thread count's marker; the legend has one row per method and one per thread count that have any point.
pub(super) fn series_lines(
    rows: &[&SeriesRow],
    curves: &[Curve],
    markers: &ThreadMarkers,
) -> (Vec<Line>, Vec<LegendEntry>) {
    let mut lines = Vec::new();
    let keys = first_appearances(rows.iter().map(|r| (r.method, r.threads)));
    let (mut methods, mut threads_drawn) = (Vec::new(), Vec::new());
    for &(method, threads) in &keys {
        let of_key: Vec<&SeriesRow> =
            rows.iter().copied().filter(|r| r.method == method && r.threads == threads).collect();
        // A run is its repeat and, with a target error, its tiles (adaptive and uniform runs share a repeat).
        for (repeat, tiles) in first_appearances(of_key.iter().map(|r| (r.repeat, r.tiles.as_str()))) {
            for &(stroke, point) in curves {
                let mut points: Vec<(f64, f64)> =
                    of_key.iter().filter(|r| r.repeat == repeat && r.tiles == tiles).filter_map(|r| point(r)).collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                if points.is_empty() {
                    continue;
                }
                methods.push(method);
                threads_drawn.push(threads);
                lines.push(Line { colour: method_colour(method), stroke, marker: Some(markers.get(threads)), points });
            }
        }
    }
    let mut legend: Vec<LegendEntry> = first_appearances(methods.into_iter())
        .into_iter()
        .map(|m| LegendEntry::line(m.name(), method_colour(m), Stroke::Solid))
        .collect();
    let mut counts = first_appearances(threads_drawn.into_iter());
    counts.sort_unstable();
    legend.extend(
        counts
            .into_iter()
            .map(|t| LegendEntry::marker(format!("{t} thread{}", if t == 1 { "" } else { "s" }), markers.get(t))),
    );
    (lines, legend)
}

/// The (method, threads) keys of rows, split into groups that one chart can tell apart: all of them, or one
/// group per thread count when there are too many. Each group comes with a file name suffix and a title part.
pub(super) fn chart_groups<'a>(rows: &[&'a SeriesRow]) -> Vec<(String, String, Vec<&'a SeriesRow>)> {
    let keys = first_appearances(rows.iter().map(|r| (r.method, r.threads)));
    if keys.len() <= MAX_KEYS_PER_CHART {
        return vec![(String::new(), String::new(), rows.to_vec())];
    }
    let mut counts = first_appearances(rows.iter().map(|r| r.threads));
    counts.sort_unstable();
    counts
        .into_iter()
        .map(|t| {
            let of: Vec<&SeriesRow> = rows.iter().copied().filter(|r| r.threads == t).collect();
            (format!("-{t}t"), format!(", {t} thread{}", if t == 1 { "" } else { "s" }), of)
        })
        .collect()
}
