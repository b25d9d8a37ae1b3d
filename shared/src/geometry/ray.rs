//! Rays and the offset that keeps a new ray from re-hitting the surface it leaves.

use glam::Vec3;

/// A ray with a finite or infinite extent.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
    pub t_max: f32,
}

impl Ray {
    /// A ray of unbounded extent; `direction` must be unit length.
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        Ray { origin, direction, t_max: f32::INFINITY }
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }
}

/// Moves `p` off its surface to the side `direction` points to, by a margin relative to the coordinates' size,
/// so that f32 rounding cannot put the new origin behind the surface.
#[inline]
pub fn offset_origin(p: Vec3, ng: Vec3, direction: Vec3) -> Vec3 {
    let eps = 2e-5 * (1.0 + p.abs().max_element());
    if direction.dot(ng) >= 0.0 {
        p + ng * eps
    } else {
        p - ng * eps
    }
}
