//! A picture the `rays` commands draw paths on: anti-aliased lines and dots blended over a background in
//! floating point, then a legend strip below the picture with text in the embedded font, and a PNG.

use crate::bench::charts::{register_embedded_font, FONT};
use anyhow::{Context, Result};
use photonfarm::ray_map::Events;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// Event colours, in the order a segment takes its colour from the events at its end: the first one it has.
pub const EVENT_COLOURS: [(Events, &str, [f32; 3]); 7] = [
    (Events::TIR, "total internal reflection", [1.0, 0.25, 1.0]),
    (Events::REFLECT, "reflection", [1.0, 0.22, 0.18]),
    (Events::REFRACT, "refraction", [0.25, 0.85, 1.0]),
    (Events::DIFFUSE, "diffuse", [0.35, 1.0, 0.35]),
    (Events::EMISSION, "emission", [1.0, 0.88, 0.2]),
    (Events::ESCAPED, "escaped", [0.45, 0.55, 1.0]),
    (Events::SENSOR, "sensor", [1.0, 1.0, 1.0]),
];
/// The colour of a segment whose end has none of the events above (a path stopped by the estimator).
pub const OTHER_COLOUR: [f32; 3] = [0.65, 0.65, 0.65];

/// The colour of a segment ending at a vertex with `events` (and, for segments drawn across vertices that are
/// not shown, theirs too): its first event in `EVENT_COLOURS`' order, and that event's index.
pub fn event_colour(events: Events) -> ([f32; 3], Option<usize>) {
    EVENT_COLOURS
        .iter()
        .position(|(e, _, _)| events.contains(*e))
        .map_or((OTHER_COLOUR, None), |i| (EVENT_COLOURS[i].2, Some(i)))
}

/// An RGB picture in [0, 1] per channel.
pub struct Canvas {
    pub width: usize,
    pub height: usize,
    rgb: Vec<f32>,
}

impl Canvas {
    /// A picture of one colour.
    pub fn filled(width: usize, height: usize, colour: [f32; 3]) -> Self {
        Canvas { width, height, rgb: colour.iter().copied().cycle().take(width * height * 3).collect() }
    }

    /// `image` (8-bit RGB of `w` × `h`) softened by a 3 × 3 binomial filter (a render's noise is no help to
    /// the eye under paths, and costs a PNG much of its size), enlarged `scale` times with bilinear filtering,
    /// its colours halfway to grey and dimmed by `dim`, so that coloured paths stand out on it while it stays
    /// recognisable.
    pub fn from_background(image: &[u8], w: usize, h: usize, scale: usize, dim: f32) -> Self {
        let (width, height) = (w * scale, h * scale);
        let soft = soften(image, w, h);
        let mut rgb = Vec::with_capacity(width * height * 3);
        let at = |x: usize, y: usize, c: usize| soft[(y.min(h - 1) * w + x.min(w - 1)) * 3 + c];
        for y in 0..height {
            let fy = ((y as f32 + 0.5) / scale as f32 - 0.5).max(0.0);
            let (y0, ty) = (fy as usize, fy.fract());
            for x in 0..width {
                let fx = ((x as f32 + 0.5) / scale as f32 - 0.5).max(0.0);
                let (x0, tx) = (fx as usize, fx.fract());
                let mut c = [0.0; 3];
                for (k, v) in c.iter_mut().enumerate() {
                    let top = at(x0, y0, k) * (1.0 - tx) + at(x0 + 1, y0, k) * tx;
                    let bottom = at(x0, y0 + 1, k) * (1.0 - tx) + at(x0 + 1, y0 + 1, k) * tx;
                    *v = top * (1.0 - ty) + bottom * ty;
                }
                let grey = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                rgb.extend(c.map(|v| (0.5 * v + 0.5 * grey) * dim));
            }
        }
        Canvas { width, height, rgb }
    }

    /// Blends `colour` at `alpha` over the pixels a segment of `width` pixels from `a` to `b` covers, with
    /// anti-aliased edges (pixel centres at half-integers).
    pub fn segment(&mut self, a: glam::Vec2, b: glam::Vec2, width: f32, colour: [f32; 3], alpha: f32) {
        if !(a.is_finite() && b.is_finite()) {
            return;
        }
        let half = 0.5 * width.max(0.5);
        let pad = half + 1.0;
        // Segments that leave the picture by far are clipped to its neighbourhood first, so that a point projected
        // near infinity cannot make the loop below long.
        let Some((a, b)) = clip(a, b, -pad, -pad, self.width as f32 + pad, self.height as f32 + pad) else { return };
        let (x0, x1) = ((a.x.min(b.x) - pad).floor().max(0.0) as usize, (a.x.max(b.x) + pad).ceil() as usize);
        let (y0, y1) = ((a.y.min(b.y) - pad).floor().max(0.0) as usize, (a.y.max(b.y) + pad).ceil() as usize);
        let d = b - a;
        let len2 = d.length_squared();
        for y in y0..y1.min(self.height) {
            for x in x0..x1.min(self.width) {
                let p = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let t = if len2 > 0.0 { ((p - a).dot(d) / len2).clamp(0.0, 1.0) } else { 0.0 };
                let dist = (p - (a + d * t)).length();
                let coverage = (half + 0.5 - dist).clamp(0.0, 1.0);
                if coverage > 0.0 {
                    self.blend(x, y, colour, alpha * coverage);
                }
            }
        }
    }

    /// Blends a disc of `radius` pixels at `c`.
    pub fn dot(&mut self, c: glam::Vec2, radius: f32, colour: [f32; 3], alpha: f32) {
        self.segment(c, c, 2.0 * radius, colour, alpha);
    }

    fn blend(&mut self, x: usize, y: usize, colour: [f32; 3], alpha: f32) {
        let i = (y * self.width + x) * 3;
        for (v, c) in self.rgb[i..i + 3].iter_mut().zip(colour) {
            *v += (c - *v) * alpha;
        }
    }

    /// The picture as 8-bit RGB, with a legend strip of `legend` below it (nothing for no entries) that opens
    /// with `caption`, and writes it as a PNG.
    pub fn write_png(&self, path: &Path, caption: &str, legend: &[([f32; 3], String)]) -> Result<()> {
        self.write_png_labelled(path, caption, legend, &[])
    }

    /// `write_png` with `labels` written on the picture, each centred above its point in its colour.
    pub fn write_png_labelled(
        &self,
        path: &Path,
        caption: &str,
        legend: &[([f32; 3], String)],
        labels: &[(glam::Vec2, String, [f32; 3])],
    ) -> Result<()> {
        let mut rgb: Vec<u8> = self.rgb.iter().map(|&v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8).collect();
        let (width, mut height) = (self.width, self.height);
        if !labels.is_empty() {
            register_embedded_font()?;
            let drawing = |e: DrawingAreaErrorKind<_>| anyhow::anyhow!("cannot draw the labels: {e}");
            let area = BitMapBackend::with_buffer(&mut rgb, (width as u32, height as u32)).into_drawing_area();
            for (at, text, colour) in labels {
                let colour = rgb_colour(*colour);
                let font =
                    TextStyle::from((FONT, TEXT).into_font()).color(&colour).pos(Pos::new(HPos::Center, VPos::Bottom));
                area.draw(&Text::new(text.clone(), (at.x as i32, at.y as i32), font)).map_err(drawing)?;
            }
            area.present().map_err(drawing)?;
        }
        if !legend.is_empty() || !caption.is_empty() {
            let strip = legend_strip(width, caption, legend)?;
            height += strip.len() / (width * 3);
            rgb.extend(strip);
        }
        let file = std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::High);
        let mut writer = encoder.write_header().context("PNG header")?;
        writer.write_image_data(&rgb).with_context(|| format!("cannot write {}", path.display()))?;
        Ok(())
    }
}

/// An 8-bit RGB image in [0, 1], filtered by the 3 × 3 binomial kernel (edges repeated).
fn soften(image: &[u8], w: usize, h: usize) -> Vec<f32> {
    let at = |x: isize, y: isize, c: usize| {
        let (x, y) = (x.clamp(0, w as isize - 1) as usize, y.clamp(0, h as isize - 1) as usize);
        image[(y * w + x) * 3 + c] as f32 / 255.0
    };
    let mut out = Vec::with_capacity(w * h * 3);
    for y in 0..h as isize {
        for x in 0..w as isize {
            for c in 0..3 {
                let mut sum = 0.0;
                for (dy, wy) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                    for (dx, wx) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                        sum += wy * wx * at(x + dx, y + dy, c);
                    }
                }
                out.push(sum / 16.0);
            }
        }
    }
    out
}

/// Height of a legend row, in pixels.
const ROW: i32 = 20;
/// Text size of the legend.
const TEXT: f64 = 13.0;
/// The legend strip's background.
const STRIP: RGBColor = RGBColor(24, 24, 24);

/// A strip `width` pixels wide: the caption on its first row, then each entry's colour as a short line and its
/// name, flowing into as many rows as they need.
fn legend_strip(width: usize, caption: &str, entries: &[([f32; 3], String)]) -> Result<Vec<u8>> {
    register_embedded_font()?;
    let font = TextStyle::from((FONT, TEXT).into_font())
        .color(&RGBColor(225, 225, 225))
        .pos(Pos::new(HPos::Left, VPos::Center));
    let drawing = |e: DrawingAreaErrorKind<_>| anyhow::anyhow!("cannot draw the legend: {e}");
    // Lay the entries out first, measured in the font, to know the rows.
    let mut placed = Vec::new();
    let (mut x, mut row) = (8i32, if caption.is_empty() { 0 } else { 1 });
    {
        let mut probe = vec![0u8; 3];
        let area = BitMapBackend::with_buffer(&mut probe, (1, 1)).into_drawing_area();
        for (colour, name) in entries {
            let (text_w, _) = area.estimate_text_size(name, &font).map_err(drawing)?;
            let w = 22 + text_w as i32 + 16;
            if x + w > width as i32 && x > 8 {
                (x, row) = (8, row + 1);
            }
            placed.push((x, row, *colour, name));
            x += w;
        }
    }
    let rows = (row + 1) as usize;
    let height = rows * ROW as usize + 4;
    let mut rgb = vec![0u8; width * height * 3];
    {
        let area = BitMapBackend::with_buffer(&mut rgb, (width as u32, height as u32)).into_drawing_area();
        area.fill(&STRIP).map_err(drawing)?;
        if !caption.is_empty() {
            area.draw(&Text::new(caption.to_string(), (8, 2 + ROW / 2), font.clone())).map_err(drawing)?;
        }
        for (x, row, colour, name) in placed {
            let y = 2 + row * ROW + ROW / 2;
            area.draw(&Rectangle::new([(x, y - 2), (x + 16, y + 2)], rgb_colour(colour).filled())).map_err(drawing)?;
            area.draw(&Text::new(name.clone(), (x + 22, y), font.clone())).map_err(drawing)?;
        }
        area.present().map_err(drawing)?;
    }
    Ok(rgb)
}

fn rgb_colour(c: [f32; 3]) -> RGBColor {
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    RGBColor(byte(c[0]), byte(c[1]), byte(c[2]))
}

/// The part of the segment from `a` to `b` inside the rectangle [x0, x1] × [y0, y1] (Liang–Barsky), or None.
/// It is found in f64 from the endpoint nearer the origin, so that a point projected far away costs no
/// precision where the segment crosses the picture.
fn clip(a: glam::Vec2, b: glam::Vec2, x0: f32, y0: f32, x1: f32, y1: f32) -> Option<(glam::Vec2, glam::Vec2)> {
    let (a, b) = (a.as_dvec2(), b.as_dvec2());
    let (p, q) = if a.length_squared() <= b.length_squared() { (a, b) } else { (b, a) };
    let d = q - p;
    let (x0, y0, x1, y1) = (x0 as f64, y0 as f64, x1 as f64, y1 as f64);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (dp, dq) in [(-d.x, p.x - x0), (d.x, x1 - p.x), (-d.y, p.y - y0), (d.y, y1 - p.y)] {
        if dp == 0.0 {
            if dq < 0.0 {
                return None;
            }
        } else {
            let r = dq / dp;
            if dp < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then(|| ((p + d * t0).as_vec2(), (p + d * t1).as_vec2()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn a_segment_covers_the_pixels_along_it_with_soft_edges_and_none_beyond() {
        let mut c = Canvas::filled(20, 10, [0.0; 3]);
        // Two pixels wide along y = 5.25: row 5 fully covered, rows 4 and 6 in part (their centres 0.75 and 1.25
        // away), none further.
        c.segment(Vec2::new(2.0, 5.25), Vec2::new(18.0, 5.25), 2.0, [1.0, 1.0, 1.0], 1.0);
        let at = |c: &Canvas, x: usize, y: usize| c.rgb[(y * c.width + x) * 3];
        assert_eq!(at(&c, 10, 5), 1.0);
        assert!((at(&c, 10, 4) - 0.75).abs() < 1e-6 && (at(&c, 10, 6) - 0.25).abs() < 1e-6, "no soft edges");
        assert_eq!(at(&c, 10, 3), 0.0);
        assert_eq!(at(&c, 10, 7), 0.0);
        assert_eq!(at(&c, 0, 5), 0.0, "drawn beyond its end");
        // Far beyond the picture: clipped, drawn where it crosses, and quick.
        let mut c = Canvas::filled(20, 10, [0.0; 3]);
        c.segment(Vec2::new(-1e30, 5.5), Vec2::new(10.5, 5.5), 1.0, [1.0, 0.0, 0.0], 0.5);
        assert!((at(&c, 0, 5) - 0.5).abs() < 1e-6 && (at(&c, 9, 5) - 0.5).abs() < 1e-6);
        assert_eq!((at(&c, 15, 5), at(&c, 0, 4)), (0.0, 0.0));
        assert!(clip(Vec2::new(-5.0, -5.0), Vec2::new(-1.0, -9.0), 0.0, 0.0, 10.0, 10.0).is_none());
    }

    #[test]
    fn a_segment_takes_the_colour_of_its_first_event_in_legend_order() {
        assert_eq!(event_colour(Events::REFLECT | Events::TIR).1, Some(0));
        assert_eq!(event_colour(Events::DIFFUSE | Events::EMISSION).1, Some(3));
        assert_eq!(event_colour(Events::default()), (OTHER_COLOUR, None));
    }
}
