//! Textures: what a material parameter reads at a surface point, as Mitsuba 3's textures do. A constant, a
//! bitmap (`bitmap` holds the image and its lookups, `decode` reads PNG, JPEG, OpenEXR, Radiance HDR and PFM
//! files) or a checkerboard (`checkerboard`), the latter two read at the point's texture coordinates (`uv`:
//! where those come from on a triangle, the `to_uv` transform, the tangent they define).
//!
//! A texture gives a colour ([`Texture::eval`]) or, where a parameter is a number (a roughness, an opacity), a
//! scalar ([`Texture::eval_scalar`]) read as Mitsuba's `eval_1` reads it: a grey value as it is, a bitmap's
//! colour by its luminance, a constant colour by the mean of its channels.

pub mod bitmap;
pub mod checkerboard;
pub mod decode;
mod pfm;
pub mod uv;

pub use bitmap::{Bitmap, Filter, Wrap};
pub use checkerboard::Checkerboard;
pub use decode::{srgb_to_linear, Encoding, ImageFormat, TextureError, MAX_TEXELS};
pub use uv::{barycentric, interpolate_uv, quad_uvs, uv_tangent, UvTransform};

use crate::color::{luminance, Rgb};
use glam::Vec2;
use std::sync::Arc;

/// A bitmap read as a texture: the image, a factor multiplying it, and how it is looked up (Mitsuba's
/// `bitmap` with its `filter_type`, `wrap_mode` and `to_uv`). `I` is the image slot: the decoded image in a
/// scene, a reference to its file in a scene description (`crate::scene::description::ImageRef`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BitmapTexture<I = Arc<Bitmap>> {
    pub image: I,
    pub factor: Rgb,
    pub filter: Filter,
    pub wrap: Wrap,
    pub to_uv: UvTransform,
}

impl<I> BitmapTexture<I> {
    /// `image` with Mitsuba's defaults: bilinear, repeating, untransformed, times one.
    pub fn new(image: I) -> Self {
        BitmapTexture {
            image,
            factor: Rgb::ONE,
            filter: Filter::default(),
            wrap: Wrap::default(),
            to_uv: UvTransform::IDENTITY,
        }
    }

    /// The same lookup of another image slot, `f` turning this bitmap into its image.
    pub fn try_map<J, E>(&self, f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>) -> Result<BitmapTexture<J>, E> {
        Ok(BitmapTexture {
            image: f(self)?,
            factor: self.factor,
            filter: self.filter,
            wrap: self.wrap,
            to_uv: self.to_uv,
        })
    }
}

impl BitmapTexture {
    /// The colour at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        self.image.sample(self.to_uv.apply(uv), self.filter, self.wrap) * self.factor
    }

    /// The scalar at `uv`: the luminance of the colour (a grey image's value times a grey factor).
    #[inline]
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        let f = self.factor;
        if f.x == f.y && f.y == f.z {
            self.image.sample_scalar(self.to_uv.apply(uv), self.filter, self.wrap) * f.x
        } else {
            luminance(self.eval(uv))
        }
    }
}

/// A material parameter that may vary over a surface; `I` is the image slot of its bitmaps (see
/// [`BitmapTexture`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Texture<I = Arc<Bitmap>> {
    /// The same value everywhere.
    Constant(Rgb),
    /// A bitmap looked up at the point.
    Bitmap(BitmapTexture<I>),
    /// Two textures in a checkerboard pattern.
    Checkerboard(Box<Checkerboard<I>>),
}

impl<I> Texture<I> {
    /// A constant grey `v`.
    pub fn grey(v: f32) -> Self {
        Texture::Constant(Rgb::splat(v))
    }

    /// `image` times `factor`, looked up as Mitsuba's `bitmap` does by default.
    pub fn bitmap(image: I, factor: Rgb) -> Self {
        Texture::Bitmap(BitmapTexture { factor, ..BitmapTexture::new(image) })
    }

    /// The value, when it is the same everywhere.
    #[inline]
    pub fn constant(&self) -> Option<Rgb> {
        match self {
            Texture::Constant(c) => Some(*c),
            _ => None,
        }
    }

    /// True when the value depends on texture coordinates.
    pub fn varies(&self) -> bool {
        self.constant().is_none()
    }

    /// The same texture with every bitmap's image turned by `f` into another slot's (a file reference into the
    /// decoded image), in the order the bitmaps appear.
    pub fn try_map<J, E>(&self, f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>) -> Result<Texture<J>, E> {
        Ok(match self {
            Texture::Constant(c) => Texture::Constant(*c),
            Texture::Bitmap(b) => Texture::Bitmap(b.try_map(f)?),
            Texture::Checkerboard(c) => Texture::Checkerboard(Box::new(Checkerboard {
                color0: c.color0.try_map(f)?,
                color1: c.color1.try_map(f)?,
                to_uv: c.to_uv,
            })),
        })
    }
}

impl Texture {
    /// The value at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap(b) => b.eval(uv),
            Texture::Checkerboard(c) => c.eval(uv),
        }
    }

    /// The value at `uv` where a number is wanted, as Mitsuba reads a texture there (see the module's doc).
    #[inline]
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        match self {
            Texture::Constant(c) => {
                if c.x == c.y && c.y == c.z {
                    c.x
                } else {
                    (c.x + c.y + c.z) / 3.0
                }
            }
            Texture::Bitmap(b) => b.eval_scalar(uv),
            Texture::Checkerboard(c) => c.eval_scalar(uv),
        }
    }

    /// The largest value any channel reaches anywhere, for the checks a scene's values get.
    pub fn max_value(&self) -> f32 {
        match self {
            Texture::Constant(c) => c.max_element(),
            Texture::Bitmap(b) => b.image.max_texel().max_element() * b.factor.max_element(),
            Texture::Checkerboard(c) => c.color0.max_value().max(c.color1.max_value()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_reads_the_same_everywhere_and_its_scalar_is_the_channel_mean() {
        let t = Texture::Constant(Rgb::new(0.2, 0.5, 0.9));
        assert_eq!(t.eval(Vec2::new(7.0, -3.0)), Rgb::new(0.2, 0.5, 0.9));
        assert!((t.eval_scalar(Vec2::ZERO) - 1.6 / 3.0).abs() < 1e-7);
        // A grey constant is read exactly (no rounding through the mean: thresholds on roughness rely on it).
        for v in [0.1f32, 0.3, 0.7] {
            assert_eq!(Texture::grey(v).eval_scalar(Vec2::ZERO), v);
        }
        assert!(!t.varies() && t.constant().is_some());
    }

    #[test]
    fn a_bitmap_texture_applies_to_uv_filter_wrap_and_factor() {
        let image = Arc::new(Bitmap::from_linear(2, 1, vec![Rgb::new(0.2, 0.4, 0.6), Rgb::ONE]).unwrap());
        let mut t = BitmapTexture::new(image.clone());
        assert_eq!(t.eval(Vec2::new(0.25, 0.5)), Rgb::new(0.2, 0.4, 0.6));
        // Shifted by half a period, the same point reads the other texel.
        t.to_uv = UvTransform::translate(Vec2::new(0.5, 0.0));
        assert_eq!(t.eval(Vec2::new(0.25, 0.5)), Rgb::ONE);
        t.factor = Rgb::new(0.5, 0.5, 0.5);
        assert_eq!(t.eval(Vec2::new(0.25, 0.5)), Rgb::splat(0.5));
        assert!((t.eval_scalar(Vec2::new(0.25, 0.5)) - 0.5).abs() < 1e-6);
        // Clamped and nearest, far to the right reads the right texel whole.
        t.to_uv = UvTransform::IDENTITY;
        t.wrap = Wrap::Clamp;
        t.filter = Filter::Nearest;
        assert_eq!(t.eval(Vec2::new(5.0, 0.5)), Rgb::splat(0.5));
        // A colour factor: the scalar is the luminance of the product.
        t.factor = Rgb::new(1.0, 0.0, 0.0);
        assert!((t.eval_scalar(Vec2::new(0.25, 0.5)) - 0.2126 * 0.2).abs() < 1e-6);
        let textured = Texture::bitmap(image, Rgb::splat(2.0));
        assert!(textured.varies() && textured.constant().is_none());
        assert_eq!(textured.max_value(), 2.0);
    }

    #[test]
    fn a_checkerboard_texture_reads_its_colours_and_their_maximum() {
        let t = Texture::Checkerboard(Box::default());
        assert_eq!(t.eval(Vec2::new(0.25, 0.75)), Rgb::splat(0.4));
        assert_eq!(t.eval_scalar(Vec2::new(0.25, 0.25)), 0.2);
        assert_eq!(t.max_value(), 0.4);
        assert!(t.varies());
    }
}
