//! What the charts over cores (speedup, memory) share: `results.csv` per (scene, method) against thread counts,
//! and their legend.

use super::first_appearances;
use super::plot::{LegendEntry, Stroke};
use super::style::{marker, method_colour, Marker};
use crate::bench::tables::ResultsRow;
use photonfarm::render::Method;

/// Rays traced per second of a run, if its columns allow one.
pub(super) fn ray_rate(r: &ResultsRow) -> Option<f64> {
    let rate = (r.backward_rays + r.forward_rays) as f64 / r.wall_s;
    (rate.is_finite() && rate > 0.0).then_some(rate)
}

pub(super) fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// One (scene, method) of results.csv: a value per thread count, ascending, as the mean over repeats, and every
/// single run's value as (threads, value).
pub(super) struct ByThreads<'a> {
    pub(super) scene: &'a str,
    pub(super) method: Method,
    pub(super) means: Vec<(usize, f64)>,
    pub(super) runs: Vec<(f64, f64)>,
}

/// Per (scene, method), the runs' finite values of `value` against their thread counts.
pub(super) fn by_threads(results: &[ResultsRow], value: fn(&ResultsRow) -> Option<f64>) -> Vec<ByThreads<'_>> {
    let keys = first_appearances(results.iter().map(|r| (r.scene.as_str(), r.method)));
    keys.into_iter()
        .map(|(scene, method)| {
            let values: Vec<(usize, f64)> = results
                .iter()
                .filter(|r| r.scene == scene && r.method == method)
                .filter_map(|r| value(r).filter(|v| v.is_finite()).map(|v| (r.threads, v)))
                .collect();
            let mut counts = first_appearances(values.iter().map(|v| v.0));
            counts.sort_unstable();
            let means = counts
                .iter()
                .map(|&t| {
                    let at: Vec<f64> = values.iter().filter(|v| v.0 == t).map(|v| v.1).collect();
                    (t, mean(&at))
                })
                .collect();
            let runs = values.iter().map(|&(t, v)| (t as f64, v)).collect();
            ByThreads { scene, method, means, runs }
        })
        .collect()
}

/// The marker of a scene in the charts over cores, by its place in `scenes`.
pub(super) fn scene_marker(scenes: &[&str], scene: &str) -> Marker {
    marker(scenes.iter().position(|&s| s == scene).unwrap_or(0))
}

/// Legend rows of the charts over cores: one per method drawn (its colour), one per scene drawn (its marker).
pub(super) fn method_and_scene_legend(keys: &[ByThreads], scenes: &[&str]) -> Vec<LegendEntry> {
    let mut legend: Vec<LegendEntry> = first_appearances(keys.iter().map(|k| k.method))
        .into_iter()
        .map(|m| LegendEntry::line(m.name(), method_colour(m), Stroke::Solid))
        .collect();
    let drawn = first_appearances(keys.iter().map(|k| k.scene));
    legend.extend(
        scenes
            .iter()
            .filter(|s| drawn.contains(s))
            .map(|s| LegendEntry::marker(s.to_string(), scene_marker(scenes, s))),
    );
    legend
}
