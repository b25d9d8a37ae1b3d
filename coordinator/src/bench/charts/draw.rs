//! Drawing a `Plot` with plotters as SVG and PNG (through the workspace's `png` encoder), each file written
//! atomically, with the embedded font.

use super::plot::{Guide, LegendEntry, Line, Plot, Stroke};
use super::scale::Scale;
use super::style::{Marker, GUIDE};
use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Size of every chart, in pixels for the PNG and in SVG user units.
pub(super) const CHART_SIZE: (u32, u32) = (1024, 640);
/// Width of the legend panel at the right of every chart: the legend never covers data.
pub(super) const LEGEND_WIDTH: u32 = 250;
/// plotters looks fonts up by family name; its own default text uses this one (the rays pictures too).
pub(crate) const FONT: &str = "sans-serif";
/// Embedded so that PNG text does not depend on the machine's fonts (see assets/README.md).
pub(super) static FONT_DATA: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");
/// Most markers along one line: enough to tell its shape, few enough not to hide the line.
pub(super) const MARKERS_PER_LINE: usize = 9;

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

/// plotters' drawing errors are generic over the backend; the message is all the caller can use.
pub(super) fn drawing<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("{e}")
}

pub(super) fn draw<DB: DrawingBackend>(plot: &Plot, root: &DrawingArea<DB, Shift>) -> Result<()> {
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

pub(super) fn draw_line<DB: DrawingBackend>(
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

pub(super) fn draw_markers<DB: DrawingBackend>(
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

pub(super) fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, entries: &[LegendEntry]) -> Result<()> {
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
pub(super) fn save(plot: &Plot, dir: &Path, name: &str) -> Result<[PathBuf; 2]> {
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
pub(super) fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    write(&tmp)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// plotters' own PNG encoder would pull in the `image` crate; the workspace already has `png`.
pub(super) fn write_png(path: &Path, rgb: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path)?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), CHART_SIZE.0, CHART_SIZE.1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(())
}
