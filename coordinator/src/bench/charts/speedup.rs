//! The chart of the tracing speedup against cores.

use super::over_cores::{by_threads, method_and_scene_legend, ray_rate, scene_marker, ByThreads};
use super::plot::{Axis, Guide, LegendEntry, Line, Plot, Stroke};
use super::style::{method_colour, GUIDE};
use crate::bench::tables::ResultsRow;

/// Speedup at t threads = mean rays per second at t / the same at the smallest thread count t₀ of the same scene
/// and method, × t₀: against one thread when there are one-thread runs, and comparable across methods otherwise.
pub(super) fn speedup_vs_cores(results: &[ResultsRow], scenes: &[&str]) -> Plot {
    let mut lines = Vec::new();
    let keys: Vec<ByThreads> = by_threads(results, ray_rate).into_iter().filter(|k| !k.means.is_empty()).collect();
    for key in &keys {
        let (base_threads, base_rate) = key.means[0];
        let points: Vec<(f64, f64)> =
            key.means.iter().map(|&(t, rate)| (t as f64, rate / base_rate * base_threads as f64)).collect();
        let (colour, shape) = (method_colour(key.method), scene_marker(scenes, key.scene));
        lines.push(Line { colour, stroke: Stroke::Solid, marker: None, points: points.clone() });
        lines.push(Line { colour, stroke: Stroke::Points, marker: Some(shape), points });
    }
    let mut legend = method_and_scene_legend(&keys, scenes);
    legend.push(LegendEntry::line("ideal: speedup = cores", GUIDE, Stroke::Dashed));
    Plot {
        title: "Tracing speedup against cores (rays per second, mean over repeats)".into(),
        x: Axis::linear("cores (threads)", true),
        y: Axis::linear("speedup against the fewest threads", false),
        lines,
        guides: vec![Guide::Diagonal],
        legend,
        empty_note: "no runs with rays and wall time in results.csv".into(),
    }
}
