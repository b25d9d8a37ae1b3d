//! The Embree backend (the `embree` feature): one Embree triangle mesh holding every triangle of the scene,
//! its primitive ids the triangles' indices, traced one ray at a time through the `embree3` crate's safe API.

use super::ray::Ray;
use embree3::{
    BufferUsage, Device, Format, GeometryKind, IntersectContext, Ray as EmbreeRay, RayHit as EmbreeRayHit, Scene,
    SceneFlags, INVALID_ID,
};
use glam::Vec3;

/// A scene's triangles in an Embree BVH.
pub(super) struct EmbreeTriangles {
    scene: Scene<'static>,
    /// The triangles' objects and vertices by index, for shading and light sampling.
    by_index: Vec<(u32, [Vec3; 3])>,
}

/// A ray's closest triangle as Embree reports it.
pub(super) struct EmbreeHit {
    pub t: f32,
    /// The triangle's index in the order it was added.
    pub index: u32,
    /// Barycentrics with p = (1−u−v) v0 + u v1 + v v2.
    pub u: f32,
    pub v: f32,
}

impl EmbreeTriangles {
    /// Builds the BVH over `triangles` (not empty), each triangle's three vertices stored apart so that the
    /// primitive id is the triangle's index. The error is Embree's reason; the caller names the backend.
    pub(super) fn build(triangles: Vec<(u32, [Vec3; 3])>) -> Result<Self, String> {
        let count = triangles.len();
        let vertices = count
            .checked_mul(3)
            .filter(|&n| u32::try_from(n).is_ok())
            .ok_or_else(|| format!("{count} triangles are more than a 32-bit vertex index can address"))?;
        let device = Device::new().map_err(|e| format!("no Embree device: {e}"))?;
        let mut mesh = device.create_geometry(GeometryKind::TRIANGLE).map_err(|e| e.to_string())?;
        {
            let mut buffer = mesh
                .set_new_buffer::<[f32; 3]>(BufferUsage::VERTEX, 0, Format::FLOAT3, 12, vertices)
                .map_err(|e| format!("vertex buffer of {vertices} vertices: {e}"))?;
            for (slot, (_, t)) in buffer.chunks_exact_mut(3).zip(&triangles) {
                for (out, v) in slot.iter_mut().zip(t) {
                    *out = v.to_array();
                }
            }
        }
        {
            let mut buffer = mesh
                .set_new_buffer::<[u32; 3]>(BufferUsage::INDEX, 0, Format::UINT3, 12, count)
                .map_err(|e| format!("index buffer of {count} triangles: {e}"))?;
            for (i, slot) in buffer.iter_mut().enumerate() {
                let first = 3 * i as u32;
                *slot = [first, first + 1, first + 2];
            }
        }
        let mesh = mesh.commit();
        let mut scene = device.create_scene().map_err(|e| format!("no Embree scene: {e}"))?;
        // Robust traversal and watertight triangle tests: without it, Embree lets rays aimed at the shared
        // edges and vertices of a closed mesh through (`accel`'s tests).
        scene.set_flags(scene.get_flags() | SceneFlags::ROBUST);
        scene.attach_geometry(&mesh);
        scene.commit();
        // Embree reports failures of the build (out of memory, above all) through the device, not the call.
        match device.get_error() {
            embree3::Error::NONE => Ok(EmbreeTriangles { scene, by_index: triangles }),
            e => Err(format!("building the BVH over {count} triangles: {e}")),
        }
    }

    /// The closest triangle along the ray with t in [t_min, ray.t_max].
    /// Number of triangles.
    pub(super) fn count(&self) -> usize {
        self.by_index.len()
    }

    /// The object and vertices of the triangle added `index`-th.
    #[inline]
    pub(super) fn triangle(&self, index: u32) -> (u32, [Vec3; 3]) {
        self.by_index[index as usize]
    }

    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_min: f32) -> Option<EmbreeHit> {
        let mut rh =
            EmbreeRayHit::from(EmbreeRay::segment(ray.origin.to_array(), ray.direction.to_array(), t_min, ray.t_max));
        self.scene.intersect(&mut IntersectContext::incoherent(), &mut rh);
        (rh.hit.geomID != INVALID_ID).then_some(EmbreeHit {
            t: rh.ray.tfar,
            index: rh.hit.primID,
            u: rh.hit.u,
            v: rh.hit.v,
        })
    }

    /// True when a triangle lies along the segment from `origin` in the unit direction `dir`, t in [t_min, t_max].
    #[inline]
    pub(super) fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut ray = EmbreeRay::segment(origin.to_array(), dir.to_array(), t_min, t_max);
        self.scene.occluded(&mut IntersectContext::incoherent(), &mut ray)
    }
}
