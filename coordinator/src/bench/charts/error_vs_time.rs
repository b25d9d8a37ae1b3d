//! The chart of δ and the true error against wall time, per scene.

use super::plot::{Axis, LegendEntry, Plot, Stroke};
use super::series::{series_lines, UNLIT};
use super::style::ThreadMarkers;
use crate::bench::tables::SeriesRow;
use plotters::prelude::*;

pub(super) fn error_vs_time(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
    let (lines, mut legend) = series_lines(
        rows,
        &[(Stroke::Solid, |r| Some((r.time_s, r.delta_unlit))), (Stroke::Dashed, |r| Some((r.time_s, r.true_unlit?)))],
        markers,
    );
    legend.push(LegendEntry::line("δ (estimated)", BLACK, Stroke::Solid));
    legend.push(LegendEntry::line("true error", BLACK, Stroke::Dashed));
    Plot {
        title: format!("{title}: relative error against time, {UNLIT}"),
        x: Axis::log("wall time (s)"),
        y: Axis::log("relative error"),
        lines,
        guides: Vec::new(),
        legend,
        empty_note: "no error in series.csv".into(),
    }
}
