//! The camera: a pinhole or a thin lens, with the pixel footprint that sets the photon radius.

use crate::geometry::Ray;
use crate::sampling::concentric_disk;
use glam::{Vec2, Vec3};

/// Which projection the camera uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lens {
    /// Every ray starts at the eye point: everything is in focus.
    Pinhole,
    /// A thin lens of `radius` (m) focused at `focus_distance` (m) along the view direction.
    Thin { radius: f32, focus_distance: f32 },
}

/// A perspective camera; image row 0 is the top of the image.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    tan_half_fov_y: f32,
    pub width: u32,
    pub height: u32,
    pub lens: Lens,
}

impl Camera {
    /// A camera at `position` looking at `look_at`, `fov_y_deg` being the full vertical field of view. The
    /// image's right is forward × up in the right-handed world, as in the neutral scene format.
    pub fn new(position: Vec3, look_at: Vec3, up: Vec3, fov_y_deg: f32, width: u32, height: u32, lens: Lens) -> Self {
        let forward = (look_at - position).normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        Camera {
            position,
            forward,
            right,
            up,
            tan_half_fov_y: (fov_y_deg.to_radians() * 0.5).tan(),
            width,
            height,
            lens,
        }
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The ray through image position (x + jitter.x, y + jitter.y) in pixels; `lens_u` samples the aperture.
    /// The box-filtered pixel measurement gives every such ray weight one.
    pub fn generate_ray(&self, x: u32, y: u32, jitter: Vec2, lens_u: Vec2) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * (x as f32 + jitter.x) / self.width as f32 - 1.0) * self.tan_half_fov_y * aspect;
        let sy = (1.0 - 2.0 * (y as f32 + jitter.y) / self.height as f32) * self.tan_half_fov_y;
        let dir = (self.forward + self.right * sx + self.up * sy).normalize();
        match self.lens {
            Lens::Pinhole => Ray::new(self.position, dir),
            Lens::Thin { radius, focus_distance } => {
                let focus = self.position + dir * (focus_distance / dir.dot(self.forward));
                let d = concentric_disk(lens_u) * radius;
                let origin = self.position + self.right * d.x + self.up * d.y;
                Ray::new(origin, (focus - origin).normalize())
            }
        }
    }

    /// Angle one pixel subtends at the image centre (radians): the footprint of a pixel at distance d is
    /// d times this.
    pub fn pixel_angle(&self) -> f32 {
        2.0 * self.tan_half_fov_y / self.height as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cornell_camera() -> Camera {
        Camera::new(
            Vec3::new(0.278, 0.273, -0.8),
            Vec3::new(0.278, 0.273, 0.0),
            Vec3::Y,
            39.3076,
            256,
            256,
            Lens::Pinhole,
        )
    }

    #[test]
    fn row_zero_is_the_top_and_right_is_minus_x_looking_down_plus_z() {
        let c = cornell_camera();
        let top_left = c.generate_ray(0, 0, Vec2::ZERO, Vec2::ZERO);
        assert!(top_left.direction.y > 0.0, "row 0 looks up");
        assert!(top_left.direction.x > 0.0, "column 0 is at +x (the red wall's side)");
        let centre = c.generate_ray(128, 128, Vec2::ZERO, Vec2::ZERO);
        assert!((centre.direction - Vec3::Z).length() < 1e-5);
    }

    #[test]
    fn field_of_view_spans_the_image_height() {
        let c = cornell_camera();
        let top = c.generate_ray(128, 0, Vec2::new(0.0, 0.0), Vec2::ZERO).direction;
        let half = top.y.atan2(top.z).to_degrees();
        assert!((half - 39.3076 / 2.0).abs() < 1e-3, "{half}");
    }

    #[test]
    fn thin_lens_rays_meet_at_the_focus_distance() {
        let mut c = cornell_camera();
        c.lens = Lens::Thin { radius: 0.05, focus_distance: 1.0 };
        let a = c.generate_ray(100, 70, Vec2::splat(0.5), Vec2::new(0.1, 0.9));
        let b = c.generate_ray(100, 70, Vec2::splat(0.5), Vec2::new(0.8, 0.3));
        let pa = a.at((1.0 - (a.origin.z + 0.8)) / a.direction.z);
        let pb = b.at((1.0 - (b.origin.z + 0.8)) / b.direction.z);
        assert!((pa - pb).length() < 1e-4);
        assert!((a.origin - b.origin).length() > 0.01);
    }
}
