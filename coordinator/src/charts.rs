//! `coordinator charts DIR`: charts of a bench folder's `results.csv` and `series.csv`, written to `DIR/charts/`
//! as SVG and PNG. The main curves use the error over pixels that do not see a light directly (the `_unlit`
//! columns), where δ is meaningful. Every method has one colour in every chart and every thread count (or, in
//! the charts over cores, every scene) one marker shape; δ is drawn solid and the true error dashed. Every
//! repeat of a series is its own line, so the spread between runs stays visible; only the speedup and memory
//! lines are means over repeats. A scene with more (method, threads) keys than can be told apart gets one chart
//! per thread count.

use crate::bench_tables::{read_table, ResultsRow, SeriesRow};
use crate::cli::ChartsArgs;
use anyhow::{anyhow, bail, Context, Result};
use photonfarm::render::Method;
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, ValueFormatter};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Size of every chart, in pixels for the PNG and in SVG user units.
const CHART_SIZE: (u32, u32) = (1024, 640);
/// Width of the legend panel at the right of every chart: the legend never covers data.
const LEGEND_WIDTH: u32 = 250;
/// plotters looks fonts up by family name; its own default text uses this one.
pub(crate) const FONT: &str = "sans-serif";
/// Embedded so that PNG text does not depend on the machine's fonts (see assets/README.md).
static FONT_DATA: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const UNLIT: &str = "pixels that do not see a light directly";

/// Most (method, threads) keys in one error chart: past this, a scene's error charts are split by thread count.
const MAX_KEYS_PER_CHART: usize = 12;
/// Most markers along one line: enough to tell its shape, few enough not to hide the line.
const MARKERS_PER_LINE: usize = 9;

/// Line colours (matplotlib's "tab10" without its grey, which the guide lines use): one per method, in the order
/// of `Method::ALL`, so a method has the same colour in every chart.
const PALETTE: [RGBColor; 9] = [
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
const GUIDE: RGBColor = RGBColor(90, 90, 90);

/// `coordinator charts DIR`: draws the charts and prints the files written.
pub fn run(args: ChartsArgs) -> Result<()> {
    for path in write_charts(&args.dir)? {
        say!("wrote {}", path.display());
    }
    Ok(())
}

/// Reads `dir/results.csv` and `dir/series.csv` (the bench's output) and writes every chart into `dir/charts/`
/// as SVG and PNG, returning the files written. Per scene of series.csv: error-vs-time, error-vs-rays and
/// calibration; from results.csv: speedup-vs-cores and memory-vs-cores.
pub fn write_charts(dir: &Path) -> Result<Vec<PathBuf>> {
    register_embedded_font()?;
    let results: Vec<ResultsRow> = read_table(&dir.join("results.csv"))?;
    let series: Vec<SeriesRow> = read_table(&dir.join("series.csv"))?;
    let out = dir.join("charts");
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;

    let markers = ThreadMarkers::of(series.iter().map(|r| r.threads));
    let mut plots = Vec::new();
    for scene in first_appearances(series.iter().map(|r| r.scene.as_str())) {
        let rows: Vec<&SeriesRow> = series.iter().filter(|r| r.scene == scene).collect();
        let part = file_name_part(scene);
        for (suffix, title, rows) in chart_groups(&rows) {
            let title = format!("{scene}{title}");
            plots.push((format!("error-vs-time-{part}{suffix}"), error_vs_time(&title, &rows, &markers)));
            plots.push((format!("error-vs-rays-{part}{suffix}"), error_vs_rays(&title, &rows, &markers)));
            plots.push((format!("calibration-{part}{suffix}"), calibration(&title, &rows, &markers)));
        }
    }
    let scenes = first_appearances(results.iter().map(|r| r.scene.as_str()));
    plots.push(("speedup-vs-cores".to_string(), speedup_vs_cores(&results, &scenes)));
    plots.push(("memory-vs-cores".to_string(), memory_vs_cores(&results, &scenes)));

    let mut written = Vec::new();
    for (name, plot) in &plots {
        written.extend(save(plot, &out, name).with_context(|| format!("cannot draw the chart {name}"))?);
    }
    Ok(written)
}

/// Registers the embedded font under `FONT` for plotters (once per process).
pub(crate) fn register_embedded_font() -> Result<()> {
    // plotters keeps registered fonts in a process-wide table, so once is enough (and tests run in parallel).
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| plotters::style::register_font(FONT, FontStyle::Normal, FONT_DATA).is_ok());
    if !ok {
        bail!("the embedded font assets/DejaVuSans.ttf cannot be read");
    }
    Ok(())
}

/// Distinct values in the order they first appear: the bench writes methods and thread counts in the order the
/// user asked for them, which reads better than sorted.
fn first_appearances<T: PartialEq>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut seen = Vec::new();
    for item in items {
        if !seen.contains(&item) {
            seen.push(item);
        }
    }
    seen
}

/// A scene name as part of a file name: it comes from a CSV file and must not escape the charts folder.
fn file_name_part(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

/// The method's colour, the same in every chart.
fn method_colour(method: Method) -> RGBColor {
    let i = Method::ALL.iter().position(|&m| m == method).unwrap_or(0);
    PALETTE[i % PALETTE.len()]
}

/// Marker shapes, one per thread count (or scene), in this order.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Marker {
    Circle,
    Square,
    Triangle,
    Cross,
    Ring,
}

const MARKERS: [Marker; 5] = [Marker::Circle, Marker::Square, Marker::Triangle, Marker::Cross, Marker::Ring];

/// The marker of the `i`-th thread count or scene (shapes repeat past five, which the split charts avoid).
fn marker(i: usize) -> Marker {
    MARKERS[i % MARKERS.len()]
}

/// The marker of every thread count of the bench, from the fewest threads up, so that a thread count has the
/// same marker in every chart.
struct ThreadMarkers(Vec<usize>);

impl ThreadMarkers {
    fn of(threads: impl Iterator<Item = usize>) -> Self {
        let mut t = first_appearances(threads);
        t.sort_unstable();
        ThreadMarkers(t)
    }

    fn get(&self, threads: usize) -> Marker {
        marker(self.0.iter().position(|&t| t == threads).unwrap_or(0))
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Stroke {
    Solid,
    Dashed,
    /// Markers only, no connecting line.
    Points,
}

/// A polyline or a set of markers, in data coordinates.
struct Line {
    colour: RGBColor,
    stroke: Stroke,
    /// Drawn at a few of the points, or at every point for `Stroke::Points`.
    marker: Option<Marker>,
    points: Vec<(f64, f64)>,
}

/// A legend row: a line sample (None: no line), a marker, or both.
struct LegendEntry {
    text: String,
    colour: RGBColor,
    stroke: Option<Stroke>,
    marker: Option<Marker>,
}

impl LegendEntry {
    fn line(text: impl Into<String>, colour: RGBColor, stroke: Stroke) -> Self {
        LegendEntry { text: text.into(), colour, stroke: Some(stroke), marker: None }
    }

    fn marker(text: impl Into<String>, marker: Marker) -> Self {
        LegendEntry { text: text.into(), colour: BLACK, stroke: None, marker: Some(marker) }
    }
}

struct Axis {
    label: String,
    /// Linear axes start at zero (or below, for negative values).
    log: bool,
    /// Linear axes only: ticks at whole numbers (cores).
    integer: bool,
}

impl Axis {
    fn log(label: &str) -> Self {
        Axis { label: label.into(), log: true, integer: false }
    }

    fn linear(label: &str, integer: bool) -> Self {
        Axis { label: label.into(), log: false, integer }
    }

    /// Where a data value goes on the drawn axis (log10 on log axes), or None if it cannot be drawn.
    fn place(&self, v: f64) -> Option<f64> {
        if !v.is_finite() || (self.log && v <= 0.0) {
            return None;
        }
        Some(if self.log { v.log10() } else { v })
    }
}

/// Reference lines drawn under the data.
enum Guide {
    /// y = x, for an ideal speedup.
    Diagonal,
    Horizontal(f64, Stroke),
}

/// A chart described independently of the backend, so that the SVG and the PNG are drawn by the same code.
struct Plot {
    title: String,
    x: Axis,
    y: Axis,
    lines: Vec<Line>,
    guides: Vec<Guide>,
    legend: Vec<LegendEntry>,
    /// Shown in place of the data when there is nothing to draw.
    empty_note: String,
}

/// A curve drawn from series rows: its stroke and the point of a row, if the row has one.
type Curve = (Stroke, fn(&SeriesRow) -> Option<(f64, f64)>);

/// One line per (method, threads) and repeat of a scene's series for each curve, in the method's colour with the
/// thread count's marker; the legend has one row per method and one per thread count that have any point.
fn series_lines(rows: &[&SeriesRow], curves: &[Curve], markers: &ThreadMarkers) -> (Vec<Line>, Vec<LegendEntry>) {
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
fn chart_groups<'a>(rows: &[&'a SeriesRow]) -> Vec<(String, String, Vec<&'a SeriesRow>)> {
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

fn error_vs_time(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
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

fn error_vs_rays(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
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

fn calibration(title: &str, rows: &[&SeriesRow], markers: &ThreadMarkers) -> Plot {
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

/// Rays traced per second of a run, if its columns allow one.
fn ray_rate(r: &ResultsRow) -> Option<f64> {
    let rate = (r.backward_rays + r.forward_rays) as f64 / r.wall_s;
    (rate.is_finite() && rate > 0.0).then_some(rate)
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// One (scene, method) of results.csv: a value per thread count, ascending, as the mean over repeats, and every
/// single run's value as (threads, value).
struct ByThreads<'a> {
    scene: &'a str,
    method: Method,
    means: Vec<(usize, f64)>,
    runs: Vec<(f64, f64)>,
}

/// Per (scene, method), the runs' finite values of `value` against their thread counts.
fn by_threads(results: &[ResultsRow], value: fn(&ResultsRow) -> Option<f64>) -> Vec<ByThreads<'_>> {
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
fn scene_marker(scenes: &[&str], scene: &str) -> Marker {
    marker(scenes.iter().position(|&s| s == scene).unwrap_or(0))
}

/// Legend rows of the charts over cores: one per method drawn (its colour), one per scene drawn (its marker).
fn method_and_scene_legend(keys: &[ByThreads], scenes: &[&str]) -> Vec<LegendEntry> {
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

/// Speedup at t threads = mean rays per second at t / the same at the smallest thread count t₀ of the same scene
/// and method, × t₀: against one thread when there are one-thread runs, and comparable across methods otherwise.
fn speedup_vs_cores(results: &[ResultsRow], scenes: &[&str]) -> Plot {
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

/// `peak_memory_bytes` is read as the peak of one process (like run.json's VmHWM), not a sum over processes.
fn memory_vs_cores(results: &[ResultsRow], scenes: &[&str]) -> Plot {
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

/// The extent and ticks of a drawn axis, in drawn coordinates (log10 of the value on log axes). Our own
/// coordinate type rather than plotters' log axis, whose ticks vanish within a decade, and rather than its
/// custom key points, which lose the tick label formatting.
#[derive(Clone)]
struct Scale {
    log: bool,
    lo: f64,
    hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Scale {
    fn new(axis: &Axis, drawn: &[f64]) -> Scale {
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
    fn log((min, max): (f64, f64)) -> Scale {
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

    fn linear(axis: &Axis, (min, max): (f64, f64)) -> Scale {
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

    fn label(&self, drawn: f64) -> String {
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
fn nice_step(raw: f64) -> f64 {
    let raw = if raw.is_finite() && raw > 0.0 { raw } else { 1.0 };
    let magnitude = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * magnitude).find(|&s| s >= raw * (1.0 - 1e-9)).unwrap_or(raw)
}

/// At most three significant digits, exponent form outside [0.001, 100 000).
fn format_number(v: f64) -> String {
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

fn trim_fraction(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// plotters' drawing errors are generic over the backend; the message is all the caller can use.
fn drawing<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("{e}")
}

fn draw<DB: DrawingBackend>(plot: &Plot, root: &DrawingArea<DB, Shift>) -> Result<()> {
    root.fill(&WHITE).map_err(drawing)?;
    let body = root.titled(&plot.title, (FONT, 20)).map_err(drawing)?;
    let (width, _) = body.dim_in_pixel();
    let (chart_area, legend_area) = body.split_horizontally(width.saturating_sub(LEGEND_WIDTH));

    let lines: Vec<(&Line, Vec<(f64, f64)>)> = plot
        .lines
        .iter()
        .map(|line| {
            let drawn = line.points.iter().filter_map(|&(x, y)| Some((plot.x.place(x)?, plot.y.place(y)?))).collect();
            (line, drawn)
        })
        .collect();
    let has_data = lines.iter().any(|(_, p)| !p.is_empty());
    let xs: Vec<f64> = lines.iter().flat_map(|(_, p)| p.iter().map(|q| q.0)).collect();
    let x = Scale::new(&plot.x, &xs);
    let mut ys: Vec<f64> = lines.iter().flat_map(|(_, p)| p.iter().map(|q| q.1)).collect();
    for guide in &plot.guides {
        match guide {
            // An ideal line that leaves the frame at once says little: show it up to the largest x.
            Guide::Diagonal => ys.extend(xs.iter().copied().reduce(f64::max)),
            Guide::Horizontal(v, _) => ys.extend(plot.y.place(*v)),
        }
    }
    let y = Scale::new(&plot.y, &ys);

    let mut chart = ChartBuilder::on(&chart_area)
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(x.clone(), y.clone())
        .map_err(drawing)?;
    chart
        .configure_mesh()
        .x_desc(plot.x.label.as_str())
        .y_desc(plot.y.label.as_str())
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .bold_line_style(RGBColor(210, 210, 210))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(drawing)?;

    for guide in &plot.guides {
        let (points, stroke) = match *guide {
            Guide::Diagonal => {
                let (from, to) = (x.lo.max(y.lo), x.hi.min(y.hi));
                (vec![(from, from), (to, to)], Stroke::Dashed)
            }
            Guide::Horizontal(v, stroke) => match plot.y.place(v) {
                Some(v) => (vec![(x.lo, v), (x.hi, v)], stroke),
                None => continue,
            },
        };
        draw_line(&mut chart, &points, GUIDE, stroke, 1)?;
    }
    for (line, points) in &lines {
        draw_line(&mut chart, points, line.colour, line.stroke, 2)?;
        let every = if line.stroke == Stroke::Points { 1 } else { points.len().div_ceil(MARKERS_PER_LINE).max(1) };
        if let Some(m) = line.marker {
            // From the last point back, so that every line's end, where the runs are compared, has a marker.
            let at: Vec<(f64, f64)> = points.iter().rev().step_by(every).copied().collect();
            draw_markers(&mut chart, &at, line.colour, m)?;
        }
    }
    if !has_data {
        let style = TextStyle::from((FONT, 18).into_font()).pos(Pos::new(HPos::Center, VPos::Center));
        let middle = ((x.lo + x.hi) / 2.0, (y.lo + y.hi) / 2.0);
        chart.plotting_area().draw(&Text::new(plot.empty_note.clone(), middle, style)).map_err(drawing)?;
    }

    draw_legend(&legend_area, &plot.legend)
}

fn draw_line<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<Scale, Scale>>,
    points: &[(f64, f64)],
    colour: RGBColor,
    stroke: Stroke,
    width: u32,
) -> Result<()> {
    let style = ShapeStyle::from(&colour).stroke_width(width);
    let points = points.iter().copied();
    match stroke {
        Stroke::Solid => chart.draw_series(LineSeries::new(points, style)).map(|_| ()),
        Stroke::Dashed => chart.draw_series(DashedLineSeries::new(points, 8, 5, style)).map(|_| ()),
        // The markers are drawn by `draw_markers`.
        Stroke::Points => Ok(()),
    }
    .map_err(drawing)
}

fn draw_markers<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<Scale, Scale>>,
    points: &[(f64, f64)],
    colour: RGBColor,
    marker: Marker,
) -> Result<()> {
    let fill = ShapeStyle::from(&colour).filled();
    let line = ShapeStyle::from(&colour).stroke_width(2);
    let points = points.iter().copied();
    match marker {
        Marker::Circle => chart.draw_series(points.map(|p| Circle::new(p, 4, fill))).map(|_| ()),
        Marker::Square => chart
            .draw_series(points.map(|p| EmptyElement::at(p) + Rectangle::new([(-4, -4), (4, 4)], fill)))
            .map(|_| ()),
        Marker::Triangle => chart.draw_series(points.map(|p| TriangleMarker::new(p, 6, fill))).map(|_| ()),
        Marker::Cross => chart.draw_series(points.map(|p| Cross::new(p, 5, line))).map(|_| ()),
        Marker::Ring => chart.draw_series(points.map(|p| Circle::new(p, 5, line))).map(|_| ()),
    }
    .map_err(drawing)
}

fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, entries: &[LegendEntry]) -> Result<()> {
    let (_, height) = area.dim_in_pixel();
    let top = 16;
    // Many keys shrink the rows rather than run off the bottom.
    let row = ((height as i32 - top) / entries.len().max(1) as i32).clamp(8, 24);
    let font = TextStyle::from((FONT, (row as f64 * 0.62).clamp(9.0, 15.0)).into_font())
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (i, entry) in entries.iter().enumerate() {
        let y = top + i as i32 * row + row / 2;
        let style = ShapeStyle::from(&entry.colour).stroke_width(2);
        match entry.stroke {
            Some(Stroke::Solid) => area.draw(&PathElement::new(vec![(6, y), (40, y)], style)),
            Some(Stroke::Dashed) => area.draw(&DashedPathElement::new(vec![(6, y), (40, y)], 8, 5, style)),
            Some(Stroke::Points) | None => Ok(()),
        }
        .map_err(drawing)?;
        let fill = style.filled();
        match entry.marker {
            Some(Marker::Circle) => area.draw(&Circle::new((23, y), 4, fill)),
            Some(Marker::Square) => area.draw(&Rectangle::new([(19, y - 4), (27, y + 4)], fill)),
            Some(Marker::Triangle) => area.draw(&TriangleMarker::new((23, y), 6, fill)),
            Some(Marker::Cross) => area.draw(&Cross::new((23, y), 5, style)),
            Some(Marker::Ring) => area.draw(&Circle::new((23, y), 5, style)),
            None => Ok(()),
        }
        .map_err(drawing)?;
        area.draw(&Text::new(entry.text.clone(), (48, y), font.clone())).map_err(drawing)?;
    }
    Ok(())
}

/// Draws a chart as `dir/name.svg` and `dir/name.png`.
fn save(plot: &Plot, dir: &Path, name: &str) -> Result<[PathBuf; 2]> {
    let svg_path = dir.join(format!("{name}.svg"));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, CHART_SIZE).into_drawing_area();
        draw(plot, &root)?;
        root.present().map_err(drawing)?;
    }
    write_atomically(&svg_path, |path| Ok(std::fs::write(path, &svg)?))
        .with_context(|| format!("cannot write {}", svg_path.display()))?;

    let png_path = dir.join(format!("{name}.png"));
    let (width, height) = CHART_SIZE;
    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, CHART_SIZE).into_drawing_area();
        draw(plot, &root)?;
        root.present().map_err(drawing)?;
    }
    write_atomically(&png_path, |path| write_png(path, &rgb))
        .with_context(|| format!("cannot write {}", png_path.display()))?;
    Ok([svg_path, png_path])
}

/// Writes `path` through `write` into a temporary file beside it, then renames it into place: the bench's live
/// page serves the charts while they are redrawn, and must never send half a file.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    write(&tmp)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// plotters' own PNG encoder would pull in the `image` crate; the workspace already has `png`.
fn write_png(path: &Path, rgb: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path)?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), CHART_SIZE.0, CHART_SIZE.1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const RESULTS_HEADER: &str = "scene,method,topology,processes,groups,threads_per_group,threads,repeat,wall_s,\
        backward_rays,forward_rays,merges,phases,delta_unlit,delta_all,true_unlit,true_all,peak_memory_bytes,\
        bytes_per_pixel,idle_fraction";
    const SERIES_HEADER: &str = "scene,method,threads,repeat,time_s,rays,delta_unlit,delta_all,true_unlit,true_all";
    const SCENES: [&str; 2] = ["cornell", "caustic"];

    /// A fresh, empty folder for one test, so tests can run in parallel.
    fn test_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("photonfarm-charts-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A bench folder of 2 scenes × 3 methods × threads 1 and 2 × 2 repeats, where caustic's async runs have no
    /// true error, and with values the log axes cannot show.
    fn write_bench_folder(dir: &Path) {
        let mut results = format!("{RESULTS_HEADER}\n");
        let mut series = format!("{SERIES_HEADER}\n");
        for (s, scene) in SCENES.iter().enumerate() {
            for (m, method) in ["sync", "async", "two-level"].iter().enumerate() {
                for threads in [1u32, 2] {
                    for repeat in 0..2u32 {
                        let rate =
                            1e6 * f64::from(threads).powf(0.9) * (1.0 + 0.1 * m as f64 + 0.02 * f64::from(repeat));
                        let error = |rays: f64| 3.0 * (1.0 + 0.2 * s as f64) / rays.powf(1.0 / 3.0);
                        let no_truth = *scene == "caustic" && *method == "async";
                        let truth = |delta: f64| {
                            if no_truth {
                                String::new()
                            } else {
                                (delta * (0.6 + 0.3 * m as f64)).to_string()
                            }
                        };
                        let wall = 10.0;
                        let delta = error(rate * wall);
                        let memory = 40e6 + 5e6 * f64::from(threads) + 1e6 * f64::from(repeat);
                        results.push_str(&format!(
                            "{scene},{method},in-process,1,{threads},1,{threads},{repeat},{wall},{},{},0,100,{delta},\
                             {delta},{},{},{memory},120.5,0.05\n",
                            (rate * wall * 0.7).round(),
                            (rate * wall * 0.3).round(),
                            truth(delta),
                            truth(delta),
                        ));
                        for k in 0..8 {
                            let time = 0.25 * 2f64.powi(k);
                            let rays = (rate * time).round();
                            let delta = error(rays);
                            series.push_str(&format!(
                                "{scene},{method},{threads},{repeat},{time},{rays},{delta},{delta},{},{}\n",
                                truth(delta),
                                truth(delta)
                            ));
                        }
                    }
                }
            }
        }
        series.push_str("cornell,sync,1,0,0,0,0,0,0,0\n");
        series.push_str("cornell,sync,1,0,-1,0,NaN,inf,-0.5,\n");
        std::fs::write(dir.join("results.csv"), results).unwrap();
        std::fs::write(dir.join("series.csv"), series).unwrap();
    }

    /// Decodes an 8-bit RGB PNG into (width, height, bytes).
    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let file = std::fs::File::open(path).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
        let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buffer).unwrap();
        assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgb, png::BitDepth::Eight), "{path:?}");
        buffer.truncate(info.buffer_size());
        (info.width, info.height, buffer)
    }

    #[test]
    fn every_chart_is_written_as_svg_and_a_png_with_lines_and_text() {
        let dir = test_dir("all");
        write_bench_folder(&dir);
        let written = write_charts(&dir).unwrap();

        let mut names: Vec<String> = vec!["speedup-vs-cores".into(), "memory-vs-cores".into()];
        for scene in SCENES {
            names.extend(["error-vs-time", "error-vs-rays", "calibration"].map(|chart| format!("{chart}-{scene}")));
        }
        let mut expected: Vec<PathBuf> = names
            .iter()
            .flat_map(|name| ["svg", "png"].map(|ext| dir.join("charts").join(format!("{name}.{ext}"))))
            .collect();
        let mut written_sorted = written.clone();
        written_sorted.sort();
        expected.sort();
        assert_eq!(written_sorted, expected);

        for path in &written {
            if path.extension().unwrap() == "svg" {
                let svg = std::fs::read_to_string(path).unwrap();
                assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"), "{path:?}");
                let per_scene = SCENES.iter().any(|s| path.to_string_lossy().ends_with(&format!("-{s}.svg")));
                assert!(!per_scene || svg.contains(UNLIT), "{path:?} does not say which pixels");
                continue;
            }
            let (width, height, rgb) = decode(path);
            assert_eq!((width, height), CHART_SIZE, "{path:?}");
            let pixels: Vec<(usize, &[u8])> =
                rgb.chunks_exact(3).enumerate().map(|(i, p)| (i % width as usize, p)).collect();
            let not_white = pixels.iter().filter(|(_, p)| p.iter().any(|&c| c < 250)).count();
            assert!(not_white > pixels.len() / 100, "{path:?} is nearly blank: {not_white} drawn pixels");
            // The data lines are the only saturated colours.
            let coloured =
                pixels.iter().filter(|(_, p)| p.iter().max().unwrap() - p.iter().min().unwrap() > 80).count();
            assert!(coloured > 200, "{path:?} has no data lines: {coloured} coloured pixels");
            // Legend text, drawn with the embedded font: black pixels right of the legend's line samples.
            let text_from = (width - LEGEND_WIDTH) as usize + 46;
            let text = pixels.iter().filter(|(x, p)| *x >= text_from && p.iter().all(|&c| c < 90)).count();
            assert!(text > 100, "{path:?} has no legend text: {text} dark pixels");
        }
        let calibration = std::fs::read_to_string(dir.join("charts/calibration-caustic.svg")).unwrap();
        // plotters writes each text on a line of its own.
        assert!(!calibration.contains("\nasync\n"), "caustic's async runs have no true error to calibrate");
        assert!(calibration.contains("\nsync\n") && calibration.contains("\n2 threads\n"), "the legend names the keys");
        std::fs::remove_dir_all(&dir).ok();
    }

    fn series_row(method: Method, threads: usize, repeat: u32) -> SeriesRow {
        SeriesRow {
            scene: "caustic".into(),
            method,
            threads,
            repeat,
            time_s: 1.0,
            rays: 1000,
            delta_unlit: 0.1,
            delta_all: 0.1,
            true_unlit: Some(0.12),
            true_all: Some(0.12),
            tiles: String::new(),
            blur_unlit: 0.0,
        }
    }

    #[test]
    fn a_method_keeps_its_colour_a_thread_count_its_marker_and_true_error_is_dashed() {
        let rows = [
            series_row(Method::Path, 1, 0),
            series_row(Method::Combination, 2, 0),
            series_row(Method::Pbpm, 1, 0),
            series_row(Method::ThreeLevel, 1, 0),
            series_row(Method::ThreeLevel, 2, 0),
        ];
        let refs: Vec<&SeriesRow> = rows.iter().collect();
        let markers = ThreadMarkers::of(rows.iter().map(|r| r.threads));
        let plot = error_vs_time("caustic", &refs, &markers);
        assert_eq!(plot.lines.len(), 10, "δ and true error for each key");
        let colours: Vec<RGBColor> = Method::ALL.iter().map(|&m| method_colour(m)).collect();
        assert!(colours.iter().enumerate().all(|(i, c)| !colours[..i].contains(c)), "every method its own colour");
        for (row, pair) in rows.iter().zip(plot.lines.chunks(2)) {
            assert!(pair
                .iter()
                .all(|l| l.colour == method_colour(row.method) && l.marker == Some(markers.get(row.threads))));
            assert_eq!((pair[0].stroke, pair[1].stroke), (Stroke::Solid, Stroke::Dashed));
        }
        assert_ne!(markers.get(1), markers.get(2));
        let texts: Vec<&str> = plot.legend.iter().map(|e| e.text.as_str()).collect();
        assert_eq!(
            texts,
            ["path", "combination", "pbpm", "three-level", "1 thread", "2 threads", "δ (estimated)", "true error"]
        );
    }

    #[test]
    fn a_scene_with_more_keys_than_can_be_told_apart_gets_a_chart_per_thread_count() {
        // The bench's default on two cores: pbpm and path at one thread, the five parallel methods at one and two.
        let few: Vec<SeriesRow> = Method::ALL
            .iter()
            .flat_map(|&m| if m.layout().runs_on(2) { vec![1, 2] } else { vec![1] }.into_iter().map(move |t| (m, t)))
            .map(|(m, t)| series_row(m, t, 0))
            .collect();
        let refs: Vec<&SeriesRow> = few.iter().collect();
        assert_eq!((refs.len(), chart_groups(&refs).len()), (12, 1));
        let many: Vec<SeriesRow> = [1, 2, 4].iter().flat_map(|&t| Method::ALL.map(|m| series_row(m, t, 0))).collect();
        let refs: Vec<&SeriesRow> = many.iter().collect();
        let groups = chart_groups(&refs);
        let suffixes: Vec<&str> = groups.iter().map(|g| g.0.as_str()).collect();
        assert_eq!(suffixes, ["-1t", "-2t", "-4t"]);
        assert!(groups.iter().all(|g| g.2.len() == Method::ALL.len()));
    }

    fn error_with(test: &str, file: &str, edit: impl Fn(&str) -> String) -> String {
        let dir = test_dir(test);
        write_bench_folder(&dir);
        let path = dir.join(file);
        std::fs::write(&path, edit(&std::fs::read_to_string(&path).unwrap())).unwrap();
        let message = format!("{:#}", write_charts(&dir).expect_err("bad input accepted"));
        std::fs::remove_dir_all(&dir).ok();
        message
    }

    /// Replaces field `column` of line `line` (1-based, the header is line 1).
    fn set_field(text: &str, line: usize, column: usize, value: &str) -> String {
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let mut fields: Vec<&str> = lines[line - 1].split(',').collect();
        fields[column] = value;
        lines[line - 1] = fields.join(",");
        lines.join("\n") + "\n"
    }

    #[test]
    fn malformed_csv_is_refused_with_file_line_and_column() {
        let m = error_with("number", "results.csv", |t| set_field(t, 3, 8, "fast"));
        assert!(m.contains("results.csv, line 3, column wall_s"), "{m}");

        let m = error_with("threads", "series.csv", |t| set_field(t, 5, 2, "1.5"));
        assert!(m.contains("series.csv, line 5, column threads"), "{m}");

        let m = error_with("fields", "series.csv", |t| {
            let mut lines: Vec<&str> = t.lines().collect();
            lines[3] = "cornell,sync,1,0,0.5";
            lines.join("\n")
        });
        assert!(m.contains("series.csv, line 4") && m.contains("5 fields where the header has 10"), "{m}");

        let m = error_with("header", "results.csv", |t| t.replacen("peak_memory_bytes", "peak_rss", 1));
        assert!(m.contains("results.csv, line 1") && m.contains("peak_memory_bytes"), "{m}");

        let dir = test_dir("missing");
        let m = format!("{:#}", write_charts(&dir).expect_err("no results.csv accepted"));
        assert!(m.contains("results.csv"), "{m}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
