//! A chart described apart from the backend that draws it, so that the SVG and the PNG come from the same code:
//! its axes, lines, guides and legend.

use super::style::Marker;
use crate::bench::tables::SeriesRow;
use plotters::prelude::*;

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Stroke {
    Solid,
    Dashed,
    /// Markers only, no connecting line.
    Points,
}

/// A polyline or a set of markers, in data coordinates.
pub(super) struct Line {
    pub(super) colour: RGBColor,
    pub(super) stroke: Stroke,
    /// Drawn at a few of the points, or at every point for `Stroke::Points`.
    pub(super) marker: Option<Marker>,
    pub(super) points: Vec<(f64, f64)>,
}

/// A legend row: a line sample (None: no line), a marker, or both.
pub(super) struct LegendEntry {
    pub(super) text: String,
    pub(super) colour: RGBColor,
    pub(super) stroke: Option<Stroke>,
    pub(super) marker: Option<Marker>,
}

impl LegendEntry {
    pub(super) fn line(text: impl Into<String>, colour: RGBColor, stroke: Stroke) -> Self {
        LegendEntry { text: text.into(), colour, stroke: Some(stroke), marker: None }
    }

    pub(super) fn marker(text: impl Into<String>, marker: Marker) -> Self {
        LegendEntry { text: text.into(), colour: BLACK, stroke: None, marker: Some(marker) }
    }
}

pub(super) struct Axis {
    pub(super) label: String,
    /// Linear axes start at zero (or below, for negative values).
    pub(super) log: bool,
    /// Linear axes only: ticks at whole numbers (cores).
    pub(super) integer: bool,
}

impl Axis {
    pub(super) fn log(label: &str) -> Self {
        Axis { label: label.into(), log: true, integer: false }
    }

    pub(super) fn linear(label: &str, integer: bool) -> Self {
        Axis { label: label.into(), log: false, integer }
    }

    /// Where a data value goes on the drawn axis (log10 on log axes), or None if it cannot be drawn.
    pub(super) fn place(&self, v: f64) -> Option<f64> {
        if !v.is_finite() || (self.log && v <= 0.0) {
            return None;
        }
        Some(if self.log { v.log10() } else { v })
    }
}

/// Reference lines drawn under the data.
pub(super) enum Guide {
    /// y = x, for an ideal speedup.
    Diagonal,
    Horizontal(f64, Stroke),
}

/// A chart described independently of the backend, so that the SVG and the PNG are drawn by the same code.
pub(super) struct Plot {
    pub(super) title: String,
    pub(super) x: Axis,
    pub(super) y: Axis,
    pub(super) lines: Vec<Line>,
    pub(super) guides: Vec<Guide>,
    pub(super) legend: Vec<LegendEntry>,
    /// Shown in place of the data when there is nothing to draw.
    pub(super) empty_note: String,
}

/// A curve drawn from series rows: its stroke and the point of a row, if the row has one.
pub(super) type Curve = (Stroke, fn(&SeriesRow) -> Option<(f64, f64)>);
