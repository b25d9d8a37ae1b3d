//! Bitmaps: images decoded to linear values (grey or RGB; `decode` reads the files) and their lookups at
//! texture coordinates, filtered and wrapped as Mitsuba 3's `bitmap` texture does.
//!
//! # Coordinates
//!
//! Row 0 is the top of the image. photonfarm's v runs bottom to top, so a lookup first turns (u, v) into
//! Mitsuba's (u, 1 − v), whose v runs down the rows, and from there follows Mitsuba's arithmetic: texel (x, y)
//! covers [x, x + 1) / width × [y, y + 1) / height, a bilinear lookup blends the four texels whose centres
//! surround the point, and the wrap mode decides which texel an index outside the image reads.

use crate::color::{luminance, Rgb};
use glam::{Vec2, Vec3};
use std::ops::{Add, Mul};

/// How a lookup reconstructs the image between texel centres (Mitsuba's `filter_type`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Filter {
    /// Blends the four nearest texels by their distance to the point (no prefiltering).
    #[default]
    Bilinear,
    /// Reads the texel the point lies in.
    Nearest,
}

/// What a lookup reads outside the image (Mitsuba's `wrap_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Wrap {
    /// The image tiles the plane.
    #[default]
    Repeat,
    /// The image tiles the plane mirrored at every edge, so neighbouring tiles meet seamlessly.
    Mirror,
    /// The edge texels extend outward.
    Clamp,
}

impl Wrap {
    /// The texel that index `i` of a row or column of `n` texels reads.
    #[inline]
    fn index(self, i: i64, n: i64) -> usize {
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Mirror => {
                let m = i.rem_euclid(n);
                if i.div_euclid(n) % 2 == 0 {
                    m
                } else {
                    n - 1 - m
                }
            }
        }) as usize
    }

    /// A coordinate moved by whole periods of the wrap (clamped far outside for `Clamp`), which reads the same
    /// texels: the texel arithmetic then keeps its precision and its integers stay small.
    #[inline]
    fn reduce(self, x: f32) -> f32 {
        match self {
            Wrap::Repeat => x.rem_euclid(1.0),
            Wrap::Mirror => x.rem_euclid(2.0),
            Wrap::Clamp => x.clamp(-1.0, 2.0),
        }
    }
}

/// The texels of a bitmap: one channel for grey images (roughness and opacity maps are), three otherwise.
#[derive(Clone, Debug, PartialEq)]
enum Texels {
    Grey(Vec<f32>),
    Rgb(Vec<Rgb>),
}

/// A decoded image in linear values, row 0 at the top, with the mean and largest value of each channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Bitmap {
    width: u32,
    height: u32,
    texels: Texels,
    mean: Rgb,
    max: Rgb,
}

impl Bitmap {
    /// A colour bitmap from linear texels in row-major order, row 0 at the top; None when the sizes disagree or
    /// a texel is negative or not finite.
    pub fn from_linear(width: u32, height: u32, texels: Vec<Rgb>) -> Option<Bitmap> {
        if !sizes_agree(width, height, texels.len()) || !texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0)
        {
            return None;
        }
        let sum = texels.iter().fold([0.0f64; 3], |s, t| [s[0] + t.x as f64, s[1] + t.y as f64, s[2] + t.z as f64]);
        let n = texels.len() as f64;
        let mean = Vec3::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        let max = texels.iter().fold(Rgb::ZERO, |m, t| m.max(*t));
        Some(Bitmap { width, height, texels: Texels::Rgb(texels), mean, max })
    }

    /// A grey bitmap from linear values in row-major order, row 0 at the top; None when the sizes disagree or a
    /// value is negative or not finite.
    pub fn from_grey(width: u32, height: u32, values: Vec<f32>) -> Option<Bitmap> {
        if !sizes_agree(width, height, values.len()) || !values.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return None;
        }
        let mean = (values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64) as f32;
        let max = values.iter().fold(0.0f32, |m, &v| m.max(v));
        Some(Bitmap { width, height, texels: Texels::Grey(values), mean: Rgb::splat(mean), max: Rgb::splat(max) })
    }

    /// Width in texels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// True when the image has one channel (read as the same value in red, green and blue).
    pub fn is_grey(&self) -> bool {
        matches!(self.texels, Texels::Grey(_))
    }

    /// The texel in column `x`, row `y` (row 0 at the top), wrapping around the edges.
    pub fn texel(&self, x: i64, y: i64) -> Rgb {
        let i = self.offset(Wrap::Repeat, x, y);
        self.rgb_at(i)
    }

    /// Mean of all texels: also the texture's mean over any whole period of (u, v), since the bilinear
    /// lookup with wrapping preserves it.
    pub fn mean(&self) -> Rgb {
        self.mean
    }

    /// The largest texel value of each channel.
    pub fn max_texel(&self) -> Rgb {
        self.max
    }

    /// Bilinear lookup at (u, v) with the texture repeating outside [0, 1]: what emission textures read.
    #[inline]
    pub fn lookup(&self, uv: Vec2) -> Rgb {
        self.sample(uv, Filter::Bilinear, Wrap::Repeat)
    }

    /// The colour at (u, v) (u left to right, v bottom to top over [0, 1]) read with `filter` and `wrap`; black
    /// at coordinates that are not finite.
    #[inline]
    pub fn sample(&self, uv: Vec2, filter: Filter, wrap: Wrap) -> Rgb {
        match &self.texels {
            Texels::Grey(g) => Rgb::splat(self.filtered(uv, filter, wrap, |i| g[i])),
            Texels::Rgb(c) => self.filtered(uv, filter, wrap, |i| c[i]),
        }
    }

    /// The value at (u, v) where a number is wanted: a grey image's value, a colour image's luminance (as
    /// Mitsuba's `eval_1` reads a bitmap); zero at coordinates that are not finite.
    #[inline]
    pub fn sample_scalar(&self, uv: Vec2, filter: Filter, wrap: Wrap) -> f32 {
        match &self.texels {
            Texels::Grey(g) => self.filtered(uv, filter, wrap, |i| g[i]),
            Texels::Rgb(c) => luminance(self.filtered(uv, filter, wrap, |i| c[i])),
        }
    }

    /// The texel at linear index `i` as a colour.
    #[inline]
    fn rgb_at(&self, i: usize) -> Rgb {
        match &self.texels {
            Texels::Grey(g) => Rgb::splat(g[i]),
            Texels::Rgb(c) => c[i],
        }
    }

    /// The linear index of texel (x, y) after wrapping.
    #[inline]
    fn offset(&self, wrap: Wrap, x: i64, y: i64) -> usize {
        wrap.index(y, self.height as i64) * self.width as usize + wrap.index(x, self.width as i64)
    }

    /// The filtered value at `uv` of the texels `fetch` reads by linear index.
    #[inline]
    fn filtered<T>(&self, uv: Vec2, filter: Filter, wrap: Wrap, fetch: impl Fn(usize) -> T) -> T
    where
        T: Copy + Default + Add<Output = T> + Mul<f32, Output = T>,
    {
        if !uv.is_finite() {
            return T::default();
        }
        // Mitsuba's coordinates: v runs down the rows.
        let (u, v) = (wrap.reduce(uv.x), wrap.reduce(1.0 - uv.y));
        let (w, h) = (self.width as f32, self.height as f32);
        match filter {
            Filter::Nearest => fetch(self.offset(wrap, (u * w).floor() as i64, (v * h).floor() as i64)),
            Filter::Bilinear => {
                let (x, y) = (u * w - 0.5, v * h - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let (x0, y0) = (x0 as i64, y0 as i64);
                let at = |dx: i64, dy: i64| fetch(self.offset(wrap, x0 + dx, y0 + dy));
                let top = at(0, 0) * (1.0 - fx) + at(1, 0) * fx;
                let bottom = at(0, 1) * (1.0 - fx) + at(1, 1) * fx;
                top * (1.0 - fy) + bottom * fy
            }
        }
    }
}

/// True when `len` texels fill a non-empty `width` × `height` image.
fn sizes_agree(width: u32, height: u32, len: usize) -> bool {
    width > 0 && height > 0 && len as u64 == width as u64 * height as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 × 2 colour bitmap whose texel (x, y) is (x, y, 10) (row 0 at the top).
    fn ramp() -> Bitmap {
        let texels = (0..2).flat_map(|y| (0..4).map(move |x| Rgb::new(x as f32, y as f32, 10.0))).collect();
        Bitmap::from_linear(4, 2, texels).unwrap()
    }

    /// The photonfarm coordinates of a point given in texel units of the ramp (x right, y down the rows).
    fn at(x: f32, y: f32) -> Vec2 {
        Vec2::new(x / 4.0, 1.0 - y / 2.0)
    }

    #[test]
    fn bilinear_lookup_hits_texel_centres_and_blends_between_them() {
        let t = Bitmap::from_linear(2, 1, vec![Rgb::ZERO, Rgb::ONE]).unwrap();
        assert_eq!(t.lookup(Vec2::new(0.25, 0.5)), Rgb::ZERO);
        assert_eq!(t.lookup(Vec2::new(0.75, 0.5)), Rgb::ONE);
        assert!((t.lookup(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
        assert_eq!(t.lookup(Vec2::new(f32::NAN, 0.5)), Rgb::ZERO);
        assert_eq!(t.sample_scalar(Vec2::new(0.5, f32::INFINITY), Filter::Nearest, Wrap::Clamp), 0.0);
    }

    #[test]
    fn row_zero_is_the_top_and_v_runs_upward() {
        let t = Bitmap::from_linear(1, 2, vec![Rgb::ONE, Rgb::ZERO]).unwrap();
        assert_eq!(t.lookup(Vec2::new(0.5, 0.75)), Rgb::ONE);
        assert_eq!(t.lookup(Vec2::new(0.5, 0.25)), Rgb::ZERO);
    }

    #[test]
    fn nearest_reads_the_texel_the_point_lies_in() {
        let t = ramp();
        for (x, y) in [(0.1f32, 0.1f32), (3.9, 0.5), (2.5, 1.99), (1.0, 1.0)] {
            let expected = Rgb::new(x.floor(), y.floor(), 10.0);
            assert_eq!(t.sample(at(x, y), Filter::Nearest, Wrap::Repeat), expected, "({x}, {y})");
        }
    }

    #[test]
    fn bilinear_blends_by_distance_to_the_texel_centres() {
        let t = ramp();
        // Inside the centres' hull the ramp's value is linear in the texel position: x − 0.5, y − 0.5.
        for (x, y) in [(1.2, 0.7), (2.5, 1.5), (0.5, 0.5), (3.1, 1.2)] {
            let c = t.sample(at(x, y), Filter::Bilinear, Wrap::Clamp);
            assert!((c - Rgb::new(x - 0.5, y - 0.5, 10.0)).abs().max_element() < 1e-5, "({x}, {y}): {c}");
        }
    }

    #[test]
    fn repeat_tiles_the_image() {
        let t = ramp();
        for (x, y) in [(0.3, 0.2), (1.7, 1.4), (3.8, 0.9)] {
            let inside = t.sample(at(x, y), Filter::Bilinear, Wrap::Repeat);
            for (kx, ky) in [(1.0, 0.0), (-3.0, 2.0), (250.0, -17.0)] {
                let shifted = at(x, y) + Vec2::new(kx, ky);
                let c = t.sample(shifted, Filter::Bilinear, Wrap::Repeat);
                assert!((c - inside).abs().max_element() < 1e-3, "({x}, {y}) + ({kx}, {ky}): {c} vs {inside}");
            }
        }
        // Across the left edge a bilinear lookup blends the last column with the first.
        let edge = t.sample(at(0.0, 0.5), Filter::Bilinear, Wrap::Repeat);
        assert!((edge.x - 1.5).abs() < 1e-6, "{edge}");
    }

    #[test]
    fn mirror_reflects_the_image_at_every_edge() {
        let t = ramp();
        // Texel index −1 reads 0, 4 reads 3, 5 reads 2, 8 reads 0 (the next tile is upright again).
        for (x, expected) in [(-0.5, 0.0), (4.5, 3.0), (5.5, 2.0), (8.5, 0.0), (-4.5, 3.0)] {
            let c = t.sample(at(x, 0.5), Filter::Nearest, Wrap::Mirror);
            assert_eq!(c.x, expected, "x = {x}");
        }
        // Rows too: row −1 reads row 0, row 2 reads row 1, row 3 reads row 0.
        for (y, expected) in [(-0.5, 0.0), (2.5, 1.0), (3.5, 0.0)] {
            assert_eq!(t.sample(at(1.5, y), Filter::Nearest, Wrap::Mirror).y, expected, "y = {y}");
        }
        // Seamless at the edge: bilinear blends the edge texel with itself.
        assert!((t.sample(at(4.0, 0.5), Filter::Bilinear, Wrap::Mirror).x - 3.0).abs() < 1e-6);
        assert!((t.sample(at(0.0, 0.5), Filter::Bilinear, Wrap::Mirror).x - 0.0).abs() < 1e-6);
    }

    #[test]
    fn clamp_extends_the_edge_texels() {
        let t = ramp();
        for (x, y, expected) in [(-3.0, 0.5, Rgb::new(0.0, 0.0, 10.0)), (9.0, 7.0, Rgb::new(3.0, 1.0, 10.0))] {
            for filter in [Filter::Nearest, Filter::Bilinear] {
                assert_eq!(t.sample(at(x, y), filter, Wrap::Clamp), expected, "({x}, {y}) {filter:?}");
            }
        }
        // Far outside too, where the coordinate is no longer a small integer.
        assert_eq!(t.sample(Vec2::new(1e30, -1e30), Filter::Bilinear, Wrap::Clamp), Rgb::new(3.0, 1.0, 10.0));
        // Between the last centre and the edge the value stays the edge's.
        assert!((t.sample(at(3.8, 0.5), Filter::Bilinear, Wrap::Clamp).x - 3.0).abs() < 1e-6);
    }

    #[test]
    fn a_scalar_read_is_the_grey_value_or_the_luminance() {
        let grey = Bitmap::from_grey(2, 1, vec![0.2, 0.6]).unwrap();
        assert!(grey.is_grey());
        assert!((grey.sample_scalar(Vec2::new(0.5, 0.5), Filter::Bilinear, Wrap::Repeat) - 0.4).abs() < 1e-6);
        assert_eq!(grey.sample(Vec2::new(0.25, 0.5), Filter::Nearest, Wrap::Repeat), Rgb::splat(0.2));
        let colour = Bitmap::from_linear(1, 1, vec![Rgb::new(1.0, 0.5, 0.25)]).unwrap();
        let y = colour.sample_scalar(Vec2::new(0.5, 0.5), Filter::Bilinear, Wrap::Repeat);
        assert!((y - (0.2126 + 0.7152 * 0.5 + 0.0722 * 0.25)).abs() < 1e-6, "{y}");
    }

    #[test]
    fn mean_and_max_are_per_channel() {
        let t = ramp();
        assert!((t.mean() - Rgb::new(1.5, 0.5, 10.0)).abs().max_element() < 1e-6);
        assert_eq!(t.max_texel(), Rgb::new(3.0, 1.0, 10.0));
        let g = Bitmap::from_grey(2, 2, vec![0.0, 1.0, 2.0, 5.0]).unwrap();
        assert_eq!((g.mean(), g.max_texel()), (Rgb::splat(2.0), Rgb::splat(5.0)));
    }

    #[test]
    fn sizes_and_values_are_checked() {
        assert!(Bitmap::from_linear(2, 2, vec![Rgb::ONE; 3]).is_none());
        assert!(Bitmap::from_linear(0, 0, vec![]).is_none());
        assert!(Bitmap::from_linear(1, 1, vec![Rgb::new(-0.1, 0.0, 0.0)]).is_none());
        assert!(Bitmap::from_grey(1, 1, vec![f32::NAN]).is_none());
        assert!(Bitmap::from_grey(1, 2, vec![1.0]).is_none());
    }
}
