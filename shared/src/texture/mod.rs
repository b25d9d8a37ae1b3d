//! Textures: what a material parameter reads at a surface point. A constant, or a bitmap (`bitmap`) looked up
//! at the point's texture coordinates; the helpers that find those coordinates on a triangle live here too.

pub mod bitmap;

pub use bitmap::{srgb_to_linear, Bitmap};

use crate::color::{luminance, Rgb};
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A material parameter that may vary over a surface.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// The same value everywhere.
    Constant(Rgb),
    /// A bitmap times a constant factor.
    Bitmap { image: Arc<Bitmap>, factor: Rgb },
}

impl Texture {
    /// A constant grey `v`.
    pub fn grey(v: f32) -> Self {
        Texture::Constant(Rgb::splat(v))
    }

    /// The value at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap { image, factor } => image.lookup(uv) * *factor,
        }
    }

    /// The value of a scalar parameter at `uv`: a colour's luminance, as Mitsuba reads a bitmap where a number
    /// is wanted.
    #[inline]
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        match self {
            Texture::Constant(c) => c.x,
            t => luminance(t.eval(uv)),
        }
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

    /// The largest value any channel reaches anywhere, for the checks a scene's values get.
    pub fn max_value(&self) -> f32 {
        match self {
            Texture::Constant(c) => c.max_element(),
            Texture::Bitmap { image, factor } => image.max_texel().max_element() * factor.max_element(),
        }
    }
}

/// Barycentric coordinates (b1, b2) of `p` on the triangle `v` (p ≈ (1 − b1 − b2) v0 + b1 v1 + b2 v2), found by
/// least squares so that a point slightly off the plane still gets the nearest answer.
pub fn barycentric(v: &[Vec3; 3], p: Vec3) -> Vec2 {
    let (e1, e2, d) = (v[1] - v[0], v[2] - v[0], p - v[0]);
    let (a, b, c) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (r1, r2) = (d.dot(e1), d.dot(e2));
    let det = a * c - b * b;
    if det <= 0.0 || !det.is_finite() {
        return Vec2::ZERO;
    }
    Vec2::new((c * r1 - b * r2) / det, (a * r2 - b * r1) / det)
}

/// Bitmap coordinates at barycentrics `b` of a triangle with vertex coordinates `uv`.
#[inline]
pub fn interpolate_uv(uv: &[Vec2; 3], b: Vec2) -> Vec2 {
    uv[0] * (1.0 - b.x - b.y) + uv[1] * b.x + uv[2] * b.y
}

/// Bitmap coordinates of the two triangles `Mesh::quad` makes: u along edge1, v along edge2, (0, 0) at the
/// corner.
pub fn quad_uvs() -> [[Vec2; 3]; 2] {
    [[Vec2::ZERO, Vec2::X, Vec2::ONE], [Vec2::ZERO, Vec2::ONE, Vec2::Y]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentrics_reproduce_the_point() {
        let v = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 1.0)];
        let p = v[0] * 0.2 + v[1] * 0.5 + v[2] * 0.3;
        let b = barycentric(&v, p);
        assert!((b - Vec2::new(0.5, 0.3)).length() < 1e-6);
    }

    #[test]
    fn quad_uvs_follow_the_quad_triangles() {
        let m = crate::geometry::Mesh::quad(Vec3::ZERO, Vec3::X * 2.0, Vec3::Y * 3.0);
        for (t, uv) in m.triangles.iter().zip(quad_uvs()) {
            for (v, uv) in t.v.iter().zip(uv) {
                assert!((Vec2::new(v.x / 2.0, v.y / 3.0) - uv).length() < 1e-6);
            }
        }
    }
}
