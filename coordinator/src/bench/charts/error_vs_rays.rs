//! The chart of δ against the rays traced, per scene.

use super::plot::{Axis, Plot, Stroke};
use super::series::{series_lines, UNLIT};
use super::style::ThreadMarkers;
use crate::bench::tables::SeriesRow;

pub(super) fn error_vs_rays(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
    let (lines, legend) = series_lines(rows, &[(Stroke::Solid, |r| Some((r.rays as f64, r.delta_unlit)))], markers);
    Plot {
        title: format!("{title}: δ against rays traced, {UNLIT}"),
        x: Axis::log("rays traced"),
        y: Axis::log("relative error δ"),
        lines,
        guides: Vec::new(),
        legend,
        empty_note: "no δ in series.csv".into(),
    }
}
