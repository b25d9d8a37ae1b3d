//! Texture coordinates: where they come from on a triangle (barycentric interpolation of its vertices'
//! coordinates), the affine transform a texture applies to them (`to_uv`), and the surface tangent ∂p/∂u they
//! define, which orients anisotropic materials.
//!
//! photonfarm's coordinates run u left to right and v bottom to top of an image over [0, 1], as OBJ's `vt`,
//! pbrt and Blender have them. Mitsuba 3 runs v top to bottom (its OBJ and PLY loaders store 1 − v); the two
//! meet through [`UvTransform::from_mitsuba`] and the lookups in `bitmap`.

use glam::{Affine2, Mat2, Vec2, Vec3};

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

/// ∂p/∂u of the triangle `v` whose vertices have texture coordinates `uv` (not normalised); None where the
/// coordinates do not span the plane (all on a line), which leaves u no direction on the triangle.
///
/// It is the same vector in Mitsuba's coordinates, whose v is 1 − ours: only ∂p/∂v changes sign.
pub fn uv_tangent(v: &[Vec3; 3], uv: &[Vec2; 3]) -> Option<Vec3> {
    let (dp1, dp2) = (v[1] - v[0], v[2] - v[0]);
    let (duv1, duv2) = (uv[1] - uv[0], uv[2] - uv[0]);
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    let tangent = (dp1 * duv2.y - dp2 * duv1.y) / det;
    (det != 0.0 && tangent.is_finite()).then_some(tangent)
}

/// An affine map of texture coordinates, applied before a texture reads them (Mitsuba's `to_uv`): u' = a u +
/// b v + c, v' = d u + e v + f.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UvTransform(Affine2);

impl Default for UvTransform {
    fn default() -> Self {
        UvTransform::IDENTITY
    }
}

impl UvTransform {
    /// Leaves the coordinates as they are.
    pub const IDENTITY: UvTransform = UvTransform(Affine2::IDENTITY);

    /// The map with rows [a, b, c] and [d, e, f] (the top two rows of a 3 × 3 homogeneous matrix, in
    /// photonfarm's coordinates); None when an entry is not finite.
    pub fn from_rows(rows: [[f32; 3]; 2]) -> Option<Self> {
        if !rows.iter().flatten().all(|x| x.is_finite()) {
            return None;
        }
        let [[a, b, c], [d, e, f]] = rows;
        Some(UvTransform(Affine2::from_mat2_translation(
            Mat2::from_cols(Vec2::new(a, d), Vec2::new(b, e)),
            Vec2::new(c, f),
        )))
    }

    /// Scales u and v.
    pub fn scale(su: f32, sv: f32) -> Self {
        UvTransform(Affine2::from_scale(Vec2::new(su, sv)))
    }

    /// Moves the coordinates by `offset`.
    pub fn translate(offset: Vec2) -> Self {
        UvTransform(Affine2::from_translation(offset))
    }

    /// The same mapping as Mitsuba's `to_uv` with the rows [a, b, c] and [d, e, f] (its homogeneous matrix's top
    /// two rows; it ignores the third): Mitsuba's v is 1 − ours, so this is F ∘ M ∘ F with F(u, v) = (u, 1 − v).
    pub fn from_mitsuba(rows: [[f32; 3]; 2]) -> Option<Self> {
        let flip = Affine2::from_mat2_translation(Mat2::from_diagonal(Vec2::new(1.0, -1.0)), Vec2::Y);
        let m = UvTransform::from_rows(rows)?;
        Some(UvTransform(flip * m.0 * flip))
    }

    /// The map after `self`: first `self`, then `next`.
    pub fn then(self, next: UvTransform) -> Self {
        UvTransform(next.0 * self.0)
    }

    /// The coordinates the texture reads for `uv`.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        self.0.transform_point2(uv)
    }

    /// True for the identity.
    pub fn is_identity(&self) -> bool {
        *self == UvTransform::IDENTITY
    }
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

    #[test]
    fn the_uv_tangent_is_the_derivative_of_position_along_u() {
        // A triangle whose u runs along world y at 2 units per unit of u, and v along −x.
        let v = [Vec3::ZERO, Vec3::new(0.0, 2.0, 0.0), Vec3::new(-1.0, 0.0, 0.0)];
        let uv = [Vec2::new(0.3, 0.1), Vec2::new(1.3, 0.1), Vec2::new(0.3, 1.1)];
        let t = uv_tangent(&v, &uv).unwrap();
        assert!((t - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6, "{t}");
        // Moving along the tangent by du changes the interpolated u by du: check at the barycentrics of p + t.
        let p = Vec3::new(-0.2, 0.4, 0.0);
        let du = 0.05;
        let (b0, b1) = (barycentric(&v, p), barycentric(&v, p + t * du));
        let (u0, u1) = (interpolate_uv(&uv, b0), interpolate_uv(&uv, b1));
        assert!((u1.x - u0.x - du).abs() < 1e-5 && (u1.y - u0.y).abs() < 1e-5);
        // Coordinates on a line define no tangent.
        assert!(uv_tangent(&v, &[Vec2::ZERO, Vec2::X, Vec2::X * 2.0]).is_none());
    }

    #[test]
    fn a_mitsuba_to_uv_maps_as_mitsuba_does_in_its_own_coordinates() {
        // Mitsuba reads (u, 1 − v) where photonfarm reads (u, v); a transform from Mitsuba must give the same
        // Mitsuba coordinates: F(ours(uv)) = M(F(uv)).
        let rows = [[2.0, 0.5, 0.25], [-0.3, 3.0, 0.7]];
        let mitsuba = |p: Vec2| Vec2::new(2.0 * p.x + 0.5 * p.y + 0.25, -0.3 * p.x + 3.0 * p.y + 0.7);
        let flip = |p: Vec2| Vec2::new(p.x, 1.0 - p.y);
        let ours = UvTransform::from_mitsuba(rows).unwrap();
        for uv in [Vec2::ZERO, Vec2::new(0.3, 0.9), Vec2::new(-1.5, 2.25)] {
            assert!((flip(ours.apply(uv)) - mitsuba(flip(uv))).length() < 1e-5);
        }
        // Scaling about the origin in Mitsuba's coordinates scales about the top edge in ours.
        let s = UvTransform::from_mitsuba([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]).unwrap();
        assert!((s.apply(Vec2::new(0.25, 1.0)) - Vec2::new(0.5, 1.0)).length() < 1e-6);
        assert!((s.apply(Vec2::new(0.25, 0.5)) - Vec2::new(0.5, 0.0)).length() < 1e-6);
    }

    #[test]
    fn rows_compose_in_order_and_refuse_non_finite_entries() {
        let t = UvTransform::from_rows([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]).unwrap();
        assert_eq!(t.apply(Vec2::new(1.0, 1.0)), Vec2::new(6.0, 15.0));
        let then = UvTransform::scale(2.0, 3.0).then(UvTransform::translate(Vec2::new(1.0, -1.0)));
        assert_eq!(then.apply(Vec2::new(1.0, 1.0)), Vec2::new(3.0, 2.0));
        assert!(UvTransform::from_rows([[f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]).is_none());
        assert!(UvTransform::IDENTITY.is_identity() && !then.is_identity());
    }
}
