//! The axes' scales: extents, ticks and tick labels, linear or logarithmic.

use super::plot::Axis;
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};

/// The extent and ticks of a drawn axis, in drawn coordinates (log10 of the value on log axes). Our own
/// coordinate type rather than plotters' log axis, whose ticks vanish within a decade, and rather than its
/// custom key points, which lose the tick label formatting.
#[derive(Clone)]
pub(super) struct Scale {
    log: bool,
    pub(super) lo: f64,
    pub(super) hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Scale {
    pub(super) fn new(axis: &Axis, drawn: &[f64]) -> Scale {
        let min = drawn.iter().copied().fold(f64::INFINITY, f64::min);
        let max = drawn.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if axis.log {
            Self::log(if drawn.is_empty() { (0.0, 1.0) } else { (min, max) })
        } else {
            Self::linear(axis, if drawn.is_empty() { (0.0, 1.0) } else { (min, max) })
        }
    }

    /// The data's extent with a little margin, labelled at decades, or also at 2 and 5 times a decade (or at
    /// every digit) when fewer decades fall inside: plotters' own log axis has no ticks within a decade.
    pub(super) fn log((min, max): (f64, f64)) -> Scale {
        let margin = if max > min { 0.04 * (max - min) } else { 0.5 };
        let (lo, hi) = (min - margin, max + margin);
        let inside = |m: &[u32]| -> Vec<f64> {
            (lo.floor() as i64..=hi.ceil() as i64)
                .flat_map(|k| m.iter().map(move |&m| k as f64 + f64::from(m).log10()))
                .filter(|&at| (lo..=hi).contains(&at))
                .collect()
        };
        let mut bold = inside(&[1]);
        // Beyond a dozen decades, label every few.
        let every = bold.len().div_ceil(12).max(1);
        bold = bold.into_iter().step_by(every).collect();
        if bold.len() < 3 {
            bold = inside(&[1, 2, 5]);
        }
        if bold.len() < 2 {
            bold = inside(&[1, 2, 3, 4, 5, 6, 7, 8, 9]);
        }
        let light = inside(&[1, 2, 3, 4, 5, 6, 7, 8, 9]).into_iter().filter(|at| !bold.contains(at)).collect();
        Scale { log: true, lo, hi, bold, light }
    }

    pub(super) fn linear(axis: &Axis, (min, max): (f64, f64)) -> Scale {
        let min = min.min(0.0);
        let span = if max > min { max - min } else { max.abs().max(1.0) };
        let mut step = nice_step(span / 6.0);
        if axis.integer {
            step = step.max(1.0).round();
        }
        // One step of headroom past the extreme values keeps markers off the frame.
        let lo = if min >= 0.0 { 0.0 } else { ((min / step).ceil() - 1.0) * step };
        let hi = ((max / step).floor() + 1.0) * step;
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let bold = (first..=last).map(|k| k as f64 * step).collect();
        Scale { log: false, lo, hi, bold, light: Vec::new() }
    }

    pub(super) fn label(&self, drawn: f64) -> String {
        format_number(if self.log { 10f64.powf(drawn) } else { drawn })
    }
}

impl Ranged for Scale {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let t = (value - self.lo) / (self.hi - self.lo);
        limit.0 + (t * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Scale {
    fn format_ext(&self, value: &f64) -> String {
        self.label(*value)
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw`.
pub(super) fn nice_step(raw: f64) -> f64 {
    let raw = if raw.is_finite() && raw > 0.0 { raw } else { 1.0 };
    let magnitude = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * magnitude).find(|&s| s >= raw * (1.0 - 1e-9)).unwrap_or(raw)
}

/// At most three significant digits, exponent form outside [0.001, 100 000).
pub(super) fn format_number(v: f64) -> String {
    let a = v.abs();
    if a < 1e-12 {
        return "0".into();
    }
    if (1e-3..1e5).contains(&a) {
        let decimals = (2 - a.log10().floor() as i32).max(0) as usize;
        trim_fraction(&format!("{v:.decimals$}")).to_string()
    } else {
        let s = format!("{v:.2e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim_fraction(mantissa)),
            None => s,
        }
    }
}

pub(super) fn trim_fraction(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}
