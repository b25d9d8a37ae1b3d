//! The watertight ray–triangle test of Woop, Benthin and Wald (JCGT 2(1), 2013), as pbrt and Embree's robust
//! mode use it. The ray is sheared so that it runs along +z from the origin; each triangle's vertices are
//! transformed the same way, and the hit is decided by the signs of three 2D edge functions. An edge shared by two
//! triangles gives each of them exactly the negated value of the other's (the same vertices, the same
//! arithmetic), so a ray through the edge, or through a vertex, is taken by at least one of them: nothing leaks
//! through a closed mesh. Möller and Trumbore's test, obvhs's own, computes barycentrics per triangle and can
//! reject a ray at an edge on both sides.

use glam::{Mat3A, Vec3A};

/// A ray prepared for the test: the shear that maps its direction onto +z, after a permutation of the axes that
/// makes z the direction's largest component.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    origin: Vec3A,
    direction: Vec3A,
    /// x' = p[kx] + sx p[kz], y' = p[ky] + sy p[kz], z' = sz p[kz], as a matrix: each row has one or two
    /// non-zero entries, so its products with a vertex add exact zeros and give the same bits as the formulas.
    shear: Mat3A,
}

impl ShearedRay {
    /// The ray from `origin` along `direction` (not zero).
    #[inline]
    pub fn new(origin: Vec3A, direction: Vec3A) -> Self {
        let a = direction.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        // Keep the winding: a negative z axis flips it, so swap x and y.
        if direction[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = direction[kz];
        let (sx, sy, sz) = (-direction[kx] / dz, -direction[ky] / dz, 1.0 / dz);
        // Columns of the matrix: what each input axis adds to (x', y', z').
        let mut columns = [Vec3A::ZERO; 3];
        columns[kx].x = 1.0;
        columns[ky].y = 1.0;
        columns[kz] = Vec3A::new(sx, sy, sz);
        ShearedRay { origin, direction, shear: Mat3A::from_cols(columns[0], columns[1], columns[2]) }
    }

    /// The distance along the ray to triangle `v0 v1 v2` when it lies in [t_min, t_max] (the direction's
    /// units), or None. The edge functions decide whether the ray meets the triangle, the plane how far along:
    /// a ray through an edge or a vertex hits every triangle that shares it.
    #[inline]
    pub fn intersect(&self, v0: Vec3A, v1: Vec3A, v2: Vec3A, t_min: f32, t_max: f32) -> Option<f32> {
        let a = v0 - self.origin;
        let (pa, pb, pc) = (self.shear * a, self.shear * (v1 - self.origin), self.shear * (v2 - self.origin));
        let (ax, ay, bx, by, cx, cy) = (pa.x, pa.y, pb.x, pb.y, pc.x, pc.y);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // Exactly on an edge in single precision: decide in double, where the products are exact.
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let d = |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
            u = d(cx, by, cy, bx);
            v = d(ax, cy, ay, cx);
            w = d(bx, ay, by, ax);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        // The distance from the triangle's plane, as Embree computes it: the sheared coordinates mix the axes, and
        // near a large triangle far from the scene's origin their t loses digits that the plane keeps.
        let n = (v0 - v1).cross(v2 - v0);
        let t = n.dot(a) / n.dot(self.direction);
        let t = if t.is_finite() { t } else { (u * pa.z + v * pb.z + w * pc.z) / det };
        (t >= t_min && t <= t_max).then_some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn a_ray_through_a_triangle_hits_it_at_its_distance_from_either_side() {
        let (v0, v1, v2) = (Vec3A::new(-1.0, -1.0, 2.0), Vec3A::new(1.0, -1.0, 2.0), Vec3A::new(0.0, 1.0, 2.0));
        let r = ShearedRay::new(Vec3A::ZERO, Vec3A::from(Vec3::new(0.1, 0.2, 1.0).normalize()));
        let t = r.intersect(v0, v1, v2, 0.0, f32::INFINITY).unwrap();
        assert!((t - 2.0 / Vec3::new(0.1, 0.2, 1.0).normalize().z).abs() < 1e-5);
        let reversed = r.intersect(v2, v1, v0, 0.0, f32::INFINITY).unwrap();
        assert!((reversed - t).abs() <= 1e-6 * t, "the winding does not matter");
        assert!(r.intersect(v0, v1, v2, 0.0, t * 0.99).is_none(), "beyond t_max");
        assert!(r.intersect(v0, v1, v2, t * 1.01, f32::INFINITY).is_none(), "before t_min");
        let back = ShearedRay::new(Vec3A::new(0.0, 0.0, 4.0), Vec3A::NEG_Z);
        assert_eq!(back.intersect(v0, v1, v2, 0.0, f32::INFINITY), Some(2.0));
        let away = ShearedRay::new(Vec3A::ZERO, Vec3A::NEG_Z);
        assert!(away.intersect(v0, v1, v2, 0.0, f32::INFINITY).is_none());
        let beside = ShearedRay::new(Vec3A::new(3.0, 0.0, 0.0), Vec3A::Z);
        assert!(beside.intersect(v0, v1, v2, 0.0, f32::INFINITY).is_none());
    }
}
