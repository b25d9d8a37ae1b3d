//! The chart of the true error over δ against wall time, per scene: how well δ predicts the error.

use super::plot::{Axis, Guide, LegendEntry, Plot, Stroke};
use super::series::{series_lines, UNLIT};
use super::style::{ThreadMarkers, GUIDE};
use crate::bench::tables::SeriesRow;

pub(super) fn calibration(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
    let (lines, mut legend) =
        series_lines(rows, &[(Stroke::Solid, |r| Some((r.time_s, r.true_unlit? / r.delta_unlit)))], markers);
    legend.push(LegendEntry::line("δ exact", GUIDE, Stroke::Solid));
    legend.push(LegendEntry::line("off by a factor of 2", GUIDE, Stroke::Dashed));
    Plot {
        title: format!("{title}: true error / δ against time, {UNLIT}"),
        x: Axis::log("wall time (s)"),
        y: Axis::linear("true error / δ", false),
        lines,
        guides: vec![
            Guide::Horizontal(0.5, Stroke::Dashed),
            Guide::Horizontal(1.0, Stroke::Solid),
            Guide::Horizontal(2.0, Stroke::Dashed),
        ],
        legend,
        empty_note: "no true error in series.csv (no reference image?)".into(),
    }
}
