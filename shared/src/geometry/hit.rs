//! What a ray learns where it meets a surface.

use glam::Vec3;

/// The closest intersection of a ray with the scene.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    /// Distance along the ray.
    pub t: f32,
    /// World position.
    pub p: Vec3,
    /// Unit geometric normal, oriented as the surface defines it (CCW winding for triangles, outward for
    /// spheres, toward the front of a lens surface); never flipped toward the ray.
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normals), on the same side as `ng`.
    pub ns: Vec3,
    /// Index of the scene object the surface belongs to.
    pub object: u32,
    /// Triangle index in the scene's triangle list, or `u32::MAX` for analytic surfaces.
    pub triangle: u32,
}
