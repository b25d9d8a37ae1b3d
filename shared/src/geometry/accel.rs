//! The scene's acceleration structure: an obvhs compressed-wide BVH over all triangles, plus the analytic
//! surfaces, which are few and tested directly.

use super::{analytic::Analytic, hit::SurfaceHit, mesh::MeshTriangle, ray::Ray};
use glam::{Vec3, Vec3A};
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, CwBvh},
    ray::{Ray as BvhRay, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};
use std::time::Duration;

/// Shading data of one triangle, stored in BVH order next to its vertices.
#[derive(Clone, Copy, Debug)]
struct TriangleData {
    object: u32,
    /// Index in the order triangles were added (stable across BVH builds).
    index: u32,
    normals: Option<[Vec3; 3]>,
}

/// All surfaces of a scene, ready for intersection queries.
pub struct SceneGeometry {
    bvh: Option<CwBvh>,
    /// Triangles in BVH leaf order, so traversal reads them without indirection.
    triangles: Vec<Triangle>,
    data: Vec<TriangleData>,
    /// Triangles in the order they were added, for light sampling.
    by_index: Vec<MeshTriangle>,
    analytic: Vec<(u32, Analytic)>,
    t_min: f32,
}

/// Minimum hit distance relative to the scene size: rays start on surfaces, offset by `offset_origin`.
const RELATIVE_T_MIN: f32 = 1e-7;

impl SceneGeometry {
    /// Builds the BVH. `triangles` pairs each triangle with the object it belongs to.
    pub fn build(triangles: Vec<(u32, MeshTriangle)>, analytic: Vec<(u32, Analytic)>) -> Self {
        let tris: Vec<Triangle> = triangles
            .iter()
            .map(|(_, t)| Triangle { v0: Vec3A::from(t.v[0]), v1: Vec3A::from(t.v[1]), v2: Vec3A::from(t.v[2]) })
            .collect();
        let mut extent = 0.0f32;
        for (_, t) in &triangles {
            for v in t.v {
                extent = extent.max(v.abs().max_element());
            }
        }
        for (_, a) in &analytic {
            let (c, r) = match a {
                Analytic::Sphere(s) => (s.center, s.radius),
                Analytic::Lens(l) => (l.vertex, l.curvature_radius.abs().max(l.aperture_radius)),
                Analytic::Annulus(a) => (a.center, a.outer_radius),
            };
            extent = extent.max(c.abs().max_element() + r);
        }
        let (bvh, triangles_bvh, data) = if tris.is_empty() {
            (None, Vec::new(), Vec::new())
        } else {
            let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::fastest_build(), &mut Duration::default());
            let order: Vec<usize> = bvh.primitive_indices.iter().map(|&i| i as usize).collect();
            let triangles_bvh = order.iter().map(|&i| tris[i]).collect();
            let data = order
                .iter()
                .map(|&i| TriangleData { object: triangles[i].0, index: i as u32, normals: triangles[i].1.n })
                .collect();
            (Some(bvh), triangles_bvh, data)
        };
        SceneGeometry {
            bvh,
            triangles: triangles_bvh,
            data,
            by_index: triangles.into_iter().map(|(_, t)| t).collect(),
            analytic,
            t_min: RELATIVE_T_MIN * (1.0 + extent),
        }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.by_index.len()
    }

    /// A triangle by the index it was added with.
    pub fn triangle(&self, index: u32) -> &MeshTriangle {
        &self.by_index[index as usize]
    }

    /// The closest surface along the ray, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let mut best_t = ray.t_max;
        let mut best: Option<(usize, bool, Vec3)> = None; // (id, is_triangle, analytic normal)
        if let Some(bvh) = &self.bvh {
            let bray = BvhRay::new(Vec3A::from(ray.origin), Vec3A::from(ray.direction), self.t_min, ray.t_max);
            let mut hit = RayHit::none();
            if bvh.ray_traverse(bray, &mut hit, |r, id| self.triangles[id].intersect(r)) && hit.t < best_t {
                best_t = hit.t;
                best = Some((hit.primitive_id as usize, true, Vec3::ZERO));
            }
        }
        for (i, (_, a)) in self.analytic.iter().enumerate() {
            let r = Ray { t_max: best_t, ..*ray };
            if let Some((t, n)) = a.intersect(&r, self.t_min) {
                best_t = t;
                best = Some((i, false, n));
            }
        }
        let (id, is_triangle, n) = best?;
        let p = ray.at(best_t);
        if is_triangle {
            let tri = &self.triangles[id];
            let data = &self.data[id];
            let ng = Vec3::from((tri.v1 - tri.v0).cross(tri.v2 - tri.v0)).normalize();
            let ns = match data.normals {
                Some(vn) => {
                    let (u, v) = barycentrics(tri, ray);
                    let n = (vn[0] * (1.0 - u - v) + vn[1] * u + vn[2] * v).normalize_or_zero();
                    if n == Vec3::ZERO || !n.is_finite() {
                        ng
                    } else if n.dot(ng) < 0.0 {
                        -n
                    } else {
                        n
                    }
                }
                None => ng,
            };
            Some(SurfaceHit { t: best_t, p, ng, ns, object: data.object, triangle: data.index })
        } else {
            Some(SurfaceHit { t: best_t, p, ng: n, ns: n, object: self.analytic[id].0, triangle: u32::MAX })
        }
    }

    /// True when nothing blocks the open segment from `from` to `to`; `from` must already be offset.
    pub fn unoccluded(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        let dist = d.length();
        if dist <= 0.0 {
            return true;
        }
        let dir = d / dist;
        let t_max = dist * (1.0 - 1e-4);
        if let Some(bvh) = &self.bvh {
            let bray = BvhRay::new(Vec3A::from(from), Vec3A::from(dir), self.t_min, t_max);
            if !bvh.ray_traverse_miss(bray, |r, id| self.triangles[id].intersect(r)) {
                return false;
            }
        }
        let r = Ray { origin: from, direction: dir, t_max };
        !self.analytic.iter().any(|(_, a)| a.intersect(&r, self.t_min).is_some())
    }
}

/// Barycentrics (u, v) of the hit with p = (1−u−v) v0 + u v1 + v v2 (Embree's convention; obvhs 0.4's own
/// `compute_barycentric` is wrong).
fn barycentrics(tri: &Triangle, ray: &Ray) -> (f32, f32) {
    let o = Vec3A::from(ray.origin);
    let d = Vec3A::from(ray.direction);
    let e1 = tri.v0 - tri.v1;
    let e2 = tri.v2 - tri.v0;
    let n = e1.cross(e2);
    let r = d.cross(tri.v0 - o);
    let inv = 1.0 / n.dot(d);
    (r.dot(e2) * inv, r.dot(e1) * inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{analytic::Sphere, mesh::Mesh};

    fn two_quads() -> SceneGeometry {
        let mut tris = Vec::new();
        for t in Mesh::quad(Vec3::new(-1.0, -1.0, 1.0), Vec3::X * 2.0, Vec3::Y * 2.0).triangles {
            tris.push((0, t));
        }
        for t in Mesh::quad(Vec3::new(-1.0, -1.0, 2.0), Vec3::X * 2.0, Vec3::Y * 2.0).triangles {
            tris.push((1, t));
        }
        SceneGeometry::build(tris, vec![])
    }

    #[test]
    fn closest_hit_is_the_nearer_quad_with_its_winding_normal() {
        let g = two_quads();
        let h = g.intersect(&Ray::new(Vec3::new(0.2, 0.3, 0.0), Vec3::Z)).unwrap();
        assert_eq!(h.object, 0);
        assert!((h.t - 1.0).abs() < 1e-5);
        assert!((h.ng - Vec3::Z).length() < 1e-5);
    }

    #[test]
    fn occlusion_sees_the_blocker_between_the_points() {
        let g = two_quads();
        // Off the quads' shared diagonal: obvhs's Möller test is not watertight exactly on an edge.
        assert!(!g.unoccluded(Vec3::new(0.1, -0.2, 0.0), Vec3::new(0.1, -0.2, 1.5)));
        assert!(g.unoccluded(Vec3::new(0.1, -0.2, 1.2), Vec3::new(0.1, -0.2, 1.8)));
    }

    #[test]
    fn interpolated_normals_use_the_right_barycentrics() {
        // A triangle whose vertex normals differ: the normal at a point near v1 must be close to v1's normal.
        let n0 = Vec3::Z;
        let n1 = Vec3::new(1.0, 0.0, 1.0).normalize();
        let n2 = Vec3::new(0.0, 1.0, 1.0).normalize();
        let t = MeshTriangle {
            v: [Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(0.0, 1.0, 1.0)],
            n: Some([n0, n1, n2]),
        };
        let g = SceneGeometry::build(vec![(0, t)], vec![]);
        let h = g.intersect(&Ray::new(Vec3::new(0.9, 0.05, 0.0), Vec3::Z)).unwrap();
        let expect = (n0 * 0.05 + n1 * 0.9 + n2 * 0.05).normalize();
        assert!((h.ns - expect).length() < 1e-4, "{:?} vs {:?}", h.ns, expect);
    }

    #[test]
    fn analytic_sphere_in_front_of_a_quad_wins() {
        let tris = Mesh::quad(Vec3::new(-1.0, -1.0, 2.0), Vec3::X * 2.0, Vec3::Y * 2.0)
            .triangles
            .into_iter()
            .map(|t| (0, t))
            .collect();
        let g = SceneGeometry::build(
            tris,
            vec![(1, Analytic::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 1.0), radius: 0.25 }))],
        );
        let h = g.intersect(&Ray::new(Vec3::ZERO, Vec3::Z)).unwrap();
        assert_eq!(h.object, 1);
        assert!((h.t - 0.75).abs() < 1e-5);
        assert_eq!(h.triangle, u32::MAX);
    }
}
