//! What tells the lines of a chart apart: a colour per method, the same in every chart, and a marker shape per
//! thread count (or, over cores, per scene).

use super::first_appearances;
use photonfarm::render::Method;
use plotters::prelude::*;

/// Line colours (matplotlib's "tab10" without its grey, which the guide lines use): one per method, in the order
/// of `Method::ALL`, so a method has the same colour in every chart.
pub(super) const PALETTE: [RGBColor; 9] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];
pub(super) const GUIDE: RGBColor = RGBColor(90, 90, 90);

/// The method's colour, the same in every chart.
pub(super) fn method_colour(method: Method) -> RGBColor {
    let i = Method::ALL.iter().position(|&m| m == method).unwrap_or(0);
    PALETTE[i % PALETTE.len()]
}

/// Marker shapes, one per thread count (or scene), in this order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Marker {
    Circle,
    Square,
    Triangle,
    Cross,
    Ring,
}

pub(super) const MARKERS: [Marker; 5] = [Marker::Circle, Marker::Square, Marker::Triangle, Marker::Cross, Marker::Ring];

/// The marker of the `i`-th thread count or scene (shapes repeat past five, which the split charts avoid).
pub(super) fn marker(i: usize) -> Marker {
    MARKERS[i % MARKERS.len()]
}

/// The marker of every thread count of the bench, from the fewest threads up, so that a thread count has the
/// same marker in every chart.
pub(super) struct ThreadMarkers(Vec<usize>);

impl ThreadMarkers {
    pub(super) fn of(threads: impl Iterator<Item = usize>) -> Self {
        let mut t = first_appearances(threads);
        t.sort_unstable();
        ThreadMarkers(t)
    }

    pub(super) fn get(&self, threads: usize) -> Marker {
        marker(self.0.iter().position(|&t| t == threads).unwrap_or(0))
    }
}
