//! The procedural checkerboard of Mitsuba 3 (`checkerboard`): two textures alternating over the squares of
//! half a unit of (transformed) texture coordinates.

use super::uv::UvTransform;
use super::Texture;
use crate::color::Rgb;
use glam::Vec2;

/// Two textures in a checkerboard pattern. Each unit square of the coordinates `to_uv` gives is cut into
/// four: seen with v upward, `color0` fills the top-left and bottom-right quarters and `color1` the other two.
/// The colours themselves are read at the point's own coordinates, as Mitsuba reads them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Checkerboard<I = std::sync::Arc<super::Bitmap>> {
    pub color0: Texture<I>,
    pub color1: Texture<I>,
    pub to_uv: UvTransform,
}

impl<I> Default for Checkerboard<I> {
    /// Mitsuba's defaults: greys of 0.4 and 0.2, coordinates untransformed.
    fn default() -> Self {
        Checkerboard { color0: Texture::grey(0.4), color1: Texture::grey(0.2), to_uv: UvTransform::IDENTITY }
    }
}

impl Checkerboard {
    /// True when the point at `uv` shows `color0`.
    ///
    /// In Mitsuba's coordinates (v downward, 1 − ours) a point shows `color0` when its u and its v both lie in
    /// the first half of their unit interval or both in the second; the comparison is written in those
    /// coordinates so that the squares' edges fall on the same side as in Mitsuba.
    #[inline]
    pub fn shows_color0(&self, uv: Vec2) -> bool {
        let p = self.to_uv.apply(uv);
        let second_half = |t: f32| t - t.floor() > 0.5;
        second_half(p.x) == second_half(1.0 - p.y)
    }

    /// The colour at `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        if self.shows_color0(uv) {
            self.color0.eval(uv)
        } else {
            self.color1.eval(uv)
        }
    }

    /// The value at `uv` where a number is wanted: that of the colour the point shows. (Mitsuba 3.9's own
    /// `eval_1` swaps the two colours, unlike its `eval`; see scenes/README.md, "Textures".)
    #[inline]
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        if self.shows_color0(uv) {
            self.color0.eval_scalar(uv)
        } else {
            self.color1.eval_scalar(uv)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pattern_matches_hand_computed_squares() {
        let c = Checkerboard::default();
        // Seen with v upward: colour0 (0.4) top-left and bottom-right of each unit square.
        for (u, v, expected) in [
            (0.25, 0.75, 0.4),
            (0.75, 0.25, 0.4),
            (0.25, 0.25, 0.2),
            (0.75, 0.75, 0.2),
            // The next squares repeat it, also below zero.
            (1.25, 0.75, 0.4),
            (-0.75, -0.25, 0.4),
            (-0.25, 0.25, 0.4),
            (3.6, 2.1, 0.4),
            (3.4, 2.1, 0.2),
            (0.1, 0.6, 0.4),
        ] {
            assert_eq!(c.eval(Vec2::new(u, v)), Rgb::splat(expected), "({u}, {v})");
            assert_eq!(c.eval_scalar(Vec2::new(u, v)), expected, "({u}, {v})");
        }
    }

    #[test]
    fn to_uv_scales_the_squares_and_the_colours_are_textures() {
        let c = Checkerboard {
            color0: Texture::Constant(Rgb::new(1.0, 0.0, 0.0)),
            color1: Texture::Constant(Rgb::new(0.0, 0.0, 1.0)),
            to_uv: UvTransform::scale(4.0, 4.0),
        };
        // Four times finer: (0.0625, 0.1875) maps to (0.25, 0.75), a colour0 quarter.
        assert_eq!(c.eval(Vec2::new(0.0625, 0.1875)), Rgb::X);
        assert_eq!(c.eval(Vec2::new(0.0625, 0.0625)), Rgb::Z);
        // A colour's scalar is the mean of its channels (Mitsuba's reading of an RGB constant).
        assert!((c.eval_scalar(Vec2::new(0.0625, 0.1875)) - 1.0 / 3.0).abs() < 1e-7);
    }
}
