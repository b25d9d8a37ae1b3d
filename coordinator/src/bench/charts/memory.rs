//! The chart of peak memory per process against cores.

use super::over_cores::{by_threads, method_and_scene_legend, scene_marker, ByThreads};
use super::plot::{Axis, LegendEntry, Line, Plot, Stroke};
use super::style::{method_colour, Marker};
use crate::bench::tables::ResultsRow;
use plotters::prelude::*;

/// `peak_memory_bytes` is read as the peak of one process (like run.json's VmHWM), not a sum over processes.
pub(super) fn memory_vs_cores(results: &[ResultsRow], scenes: &[&str]) -> Plot {
    let mut lines = Vec::new();
    let megabytes = |r: &ResultsRow| r.peak_memory_bytes.map(|b| b as f64 / 1e6);
    let keys: Vec<ByThreads> = by_threads(results, megabytes).into_iter().filter(|k| !k.runs.is_empty()).collect();
    for key in &keys {
        let points = key.means.iter().map(|&(t, mb)| (t as f64, mb)).collect();
        let (colour, shape) = (method_colour(key.method), scene_marker(scenes, key.scene));
        lines.push(Line { colour, stroke: Stroke::Solid, marker: None, points });
        lines.push(Line { colour, stroke: Stroke::Points, marker: Some(shape), points: key.runs.clone() });
    }
    let mut legend = method_and_scene_legend(&keys, scenes);
    legend.push(LegendEntry::line("line: mean over repeats", BLACK, Stroke::Solid));
    legend.push(LegendEntry::marker("markers: single runs", Marker::Circle));
    Plot {
        title: "Peak memory per process against cores".into(),
        x: Axis::linear("cores (threads)", true),
        y: Axis::linear("peak memory per process (MB)", false),
        lines,
        guides: Vec::new(),
        legend,
        empty_note: "no peak memory in results.csv".into(),
    }
}
