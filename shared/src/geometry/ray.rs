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

/// 1 / direction for slab tests against boxes: a zero (or subnormal) component gives ±MAX instead of ±inf,
/// which keeps 0 × inf = NaN out of the test; a ray that never moves along that axis cannot enter a box through
/// it anyway (every box here holds its surfaces with a margin to spare).
#[inline]
pub fn slab_inverse(direction: Vec3) -> Vec3 {
    let inv = direction.recip();
    Vec3::select(inv.is_finite_mask(), inv, Vec3::splat(f32::MAX).copysign(direction))
}

/// Where the segment [t0, t1] of the ray from `origin` with `inv` = `slab_inverse(direction)` enters the box
/// [`min`, `max`], if it crosses it.
#[inline]
pub fn slab_entry(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, t0: f32, t1: f32) -> Option<f32> {
    let a = (min - origin) * inv;
    let c = (max - origin) * inv;
    let enter = a.min(c).max_element().max(t0);
    (enter <= a.max(c).min_element().min(t1)).then_some(enter)
}
