//! The camera: a pinhole, a thin lens, or a sensor behind a real lens modelled in the scene (paper §6.1,
//! Fig. 14), with the pixel footprint that sets the photon radius.

use crate::geometry::Ray;
use crate::sampling::{concentric_disk, Frame};
use glam::{Vec2, Vec3};

/// The disc a sensor camera aims its rays at: the clear aperture of the rear lens element, in the plane of its
/// rim. It stands in for the exit pupil: every ray that can leave the lens toward the sensor passes through it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RearElement {
    /// Centre of the disc (on the optical axis).
    pub center: Vec3,
    /// Unit normal of the disc (the lens's optical axis; either orientation).
    pub axis: Vec3,
    /// Radius of the clear aperture (m).
    pub radius: f32,
}

/// Which projection the camera uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lens {
    /// Every ray starts at the eye point: everything is in focus.
    Pinhole,
    /// A thin lens of `radius` (m) focused at `focus_distance` (m) along the view direction.
    Thin { radius: f32, focus_distance: f32 },
    /// A sensor `width` metres wide (its height follows from the pixel aspect) at the camera's position, facing
    /// the rear element of a lens that is part of the scene geometry; the scene's lens surfaces form the image.
    Sensor { width: f32, rear: RearElement },
}

/// A camera ray and the weight of its contribution to the pixel measurement.
#[derive(Clone, Copy, Debug)]
pub struct CameraRay {
    pub ray: Ray,
    /// Factor every contribution of the path is multiplied by: 1 for the pinhole and the thin lens (the pixel is
    /// the box-filtered radiance), the irradiance estimator's weight for the sensor camera.
    pub weight: f32,
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

    /// A sensor camera: the sensor's centre at `position`, facing `look_at` (along the optical axis, toward the
    /// lens), `sensor_width` metres wide, aiming its rays at `rear`.
    pub fn sensor(
        position: Vec3,
        look_at: Vec3,
        up: Vec3,
        sensor_width: f32,
        width: u32,
        height: u32,
        rear: RearElement,
    ) -> Self {
        let mut camera =
            Camera::new(position, look_at, up, 90.0, width, height, Lens::Sensor { width: sensor_width, rear });
        // Only `pixel_angle` reads the field of view here: a pixel seen from the rear element, which is close to
        // the angle it subtends through the lens (exactly so from the rear principal plane).
        let distance = (rear.center - position).dot(camera.forward).abs().max(f32::MIN_POSITIVE);
        camera.tan_half_fov_y = 0.5 * sensor_width * height as f32 / width as f32 / distance;
        camera
    }

    /// Unit view direction (a sensor camera's: along the optical axis, toward the lens).
    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// Unit direction of the image's up (rows decrease along it).
    pub fn up(&self) -> Vec3 {
        self.up
    }

    /// Unit direction of the image's right.
    pub fn right(&self) -> Vec3 {
        self.right
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The ray for image position (x + jitter.x, y + jitter.y) in pixels; `lens_u` samples the aperture (the
    /// thin lens's disc or the sensor camera's rear element).
    pub fn generate_ray(&self, x: u32, y: u32, jitter: Vec2, lens_u: Vec2) -> CameraRay {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * (x as f32 + jitter.x) / self.width as f32 - 1.0) * self.tan_half_fov_y * aspect;
        let sy = (1.0 - 2.0 * (y as f32 + jitter.y) / self.height as f32) * self.tan_half_fov_y;
        let dir = (self.forward + self.right * sx + self.up * sy).normalize();
        // The box-filtered pixel measurement of radiance gives every pinhole and thin-lens ray weight one.
        let ray = match self.lens {
            Lens::Pinhole => Ray::new(self.position, dir),
            Lens::Thin { radius, focus_distance } => {
                let focus = self.position + dir * (focus_distance / dir.dot(self.forward));
                let d = concentric_disk(lens_u) * radius;
                let origin = self.position + self.right * d.x + self.up * d.y;
                Ray::new(origin, (focus - origin).normalize())
            }
            Lens::Sensor { width, rear } => return self.sensor_ray(width, &rear, x, y, jitter, lens_u),
        };
        CameraRay { ray, weight: 1.0 }
    }

    /// A sensor camera's ray: from a uniform point of the pixel on the sensor toward a uniform point of the rear
    /// element's disc.
    ///
    /// A pixel measures the sensor irradiance averaged over the pixel, E = ∫ L cos θ_s dω (W·m⁻² per channel),
    /// from the light that leaves the lens through the rear element. Written over the disc's area A,
    /// E = ∫_A L cos θ_s cos θ_d / d² dA, and a uniform point of the disc (pdf 1/A) gives the weight
    /// A cos θ_s cos θ_d / d², θ_s and θ_d being the ray's angles to the sensor's and the disc's normals and d the
    /// distance between the two points. Light arriving from outside the disc's solid angle is blocked by the
    /// lens barrel in a real camera, and here by the scene's mounts around the elements.
    fn sensor_ray(&self, width: f32, rear: &RearElement, x: u32, y: u32, jitter: Vec2, lens_u: Vec2) -> CameraRay {
        let height = width * self.height as f32 / self.width as f32;
        let u = (x as f32 + jitter.x) / self.width as f32 - 0.5;
        let v = (y as f32 + jitter.y) / self.height as f32 - 0.5;
        // The lens forms an inverted image; the sensor is read out rotated by 180°, like a real camera's, so that
        // image row 0 shows the top of the scene and the image's right is forward × up as for the other cameras.
        let origin = self.position - self.right * (u * width) + self.up * (v * height);
        let frame = Frame::from_normal(rear.axis);
        let d = concentric_disk(lens_u) * rear.radius;
        let target = rear.center + frame.s * d.x + frame.t * d.y;
        let to = target - origin;
        let dist2 = to.length_squared();
        let dir = to / dist2.sqrt();
        let cos_s = dir.dot(self.forward);
        let cos_d = dir.dot(rear.axis).abs();
        let area = std::f32::consts::PI * rear.radius * rear.radius;
        let weight = if cos_s > 0.0 && dist2 > 0.0 { area * cos_s * cos_d / dist2 } else { 0.0 };
        CameraRay { ray: Ray::new(origin, dir), weight: if weight.is_finite() { weight } else { 0.0 } }
    }

    /// Where a world point appears on the image, in pixels (x right, y down), or None behind the camera. A
    /// sensor camera projects through the rear element's centre onto the sensor, as a pinhole there would: the
    /// lens's image to first order, which is what an overlay of paths needs, not an exact trace through it.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let (w, h) = (self.width as f32, self.height as f32);
        match self.lens {
            Lens::Pinhole | Lens::Thin { .. } => {
                let d = p - self.position;
                let z = d.dot(self.forward);
                if z <= 0.0 {
                    return None;
                }
                let sx = d.dot(self.right) / (z * self.tan_half_fov_y * w / h);
                let sy = d.dot(self.up) / (z * self.tan_half_fov_y);
                Some(Vec2::new((sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h))
            }
            Lens::Sensor { width, rear } => {
                let d = p - rear.center;
                let along = d.dot(self.forward);
                let distance = (rear.center - self.position).dot(self.forward);
                if along <= 0.0 || distance <= 0.0 {
                    return None;
                }
                let s = rear.center - d * (distance / along) - self.position;
                let height = width * h / w;
                let (u, v) = (-s.dot(self.right) / width, s.dot(self.up) / height);
                Some(Vec2::new((u + 0.5) * w, (v + 0.5) * h))
            }
        }
    }

    /// Where the line `origin + t · direction` meets the sensor's plane (the plane through the camera's position
    /// across its forward axis), for a ray that `sensor_pixel` registered.
    pub fn sensor_point(&self, origin: Vec3, direction: Vec3) -> Vec3 {
        let forward = self.forward();
        origin + direction * ((self.position - origin).dot(forward) / direction.dot(forward))
    }

    /// Where a light ray registers on a sensor camera: the pixel its segment from `origin` along the unit
    /// `direction` crosses the sensor in (before `t_max`), with the pixel's importance, 1 over the pixel's area.
    /// None for other cameras, for a ray arriving from behind the sensor, and for one whose line back from the
    /// sensor misses the rear element's disc: that is the measurement `sensor_ray` estimates from the camera
    /// side, so that a light path registering here and a camera path estimate the same pixel value.
    pub fn sensor_pixel(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<(u32, f32)> {
        let Lens::Sensor { width, rear } = self.lens else { return None };
        let toward = direction.dot(self.forward);
        if toward >= 0.0 {
            return None;
        }
        let t = (self.position - origin).dot(self.forward) / toward;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        let p = origin + direction * t;
        let height = width * self.height as f32 / self.width as f32;
        // The inverse of `sensor_ray`'s placement of a pixel point on the rotated sensor.
        let u = -(p - self.position).dot(self.right) / width + 0.5;
        let v = (p - self.position).dot(self.up) / height + 0.5;
        if !((0.0..1.0).contains(&u) && (0.0..1.0).contains(&v)) {
            return None;
        }
        let (x, y) = (
            ((u * self.width as f32) as u32).min(self.width - 1),
            ((v * self.height as f32) as u32).min(self.height - 1),
        );
        let back = -direction;
        let along = back.dot(rear.axis);
        if along == 0.0 {
            return None;
        }
        let s = (rear.center - p).dot(rear.axis) / along;
        if s.is_nan() || s <= 0.0 || (p + back * s - rear.center).length_squared() > rear.radius * rear.radius {
            return None;
        }
        let pixel_area = (width / self.width as f32) * (height / self.height as f32);
        Some((y * self.width + x, 1.0 / pixel_area))
    }

    /// Angle one pixel subtends at the image centre (radians): the footprint of a pixel at distance d is
    /// d times this. For a sensor camera, the pixel pitch over the sensor's distance to the rear element.
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
    fn a_pinhole_projects_points_on_its_rays_back_to_their_pixels() {
        let cam = cornell_camera();
        for (x, y) in [(0, 0), (128, 128), (255, 3), (17, 200)] {
            let r = cam.generate_ray(x, y, Vec2::splat(0.5), Vec2::ZERO).ray;
            let p = cam.project(r.origin + r.direction * 1.7).unwrap();
            assert!((p - Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).length() < 1e-2, "{x} {y} → {p}");
        }
        assert_eq!(cam.project(Vec3::new(0.278, 0.273, -2.0)), None);
    }

    #[test]
    fn row_zero_is_the_top_and_right_is_minus_x_looking_down_plus_z() {
        let c = cornell_camera();
        let top_left = c.generate_ray(0, 0, Vec2::ZERO, Vec2::ZERO).ray;
        assert!(top_left.direction.y > 0.0, "row 0 looks up");
        assert!(top_left.direction.x > 0.0, "column 0 is at +x (the red wall's side)");
        let centre = c.generate_ray(128, 128, Vec2::ZERO, Vec2::ZERO).ray;
        assert!((centre.direction - Vec3::Z).length() < 1e-5);
    }

    #[test]
    fn field_of_view_spans_the_image_height() {
        let c = cornell_camera();
        let top = c.generate_ray(128, 0, Vec2::new(0.0, 0.0), Vec2::ZERO).ray.direction;
        let half = top.y.atan2(top.z).to_degrees();
        assert!((half - 39.3076 / 2.0).abs() < 1e-3, "{half}");
    }

    #[test]
    fn thin_lens_rays_meet_at_the_focus_distance() {
        let mut c = cornell_camera();
        c.lens = Lens::Thin { radius: 0.05, focus_distance: 1.0 };
        let a = c.generate_ray(100, 70, Vec2::splat(0.5), Vec2::new(0.1, 0.9)).ray;
        let b = c.generate_ray(100, 70, Vec2::splat(0.5), Vec2::new(0.8, 0.3)).ray;
        let pa = a.at((1.0 - (a.origin.z + 0.8)) / a.direction.z);
        let pb = b.at((1.0 - (b.origin.z + 0.8)) / b.direction.z);
        assert!((pa - pb).length() < 1e-4);
        assert!((a.origin - b.origin).length() > 0.01);
    }

    fn sensor_camera() -> Camera {
        // A 36 × 24 mm sensor 50 mm behind a rear element of radius 10 mm, looking down +z.
        let rear = RearElement { center: Vec3::new(0.0, 0.0, 0.05), axis: -Vec3::Z, radius: 0.01 };
        Camera::sensor(Vec3::ZERO, Vec3::Z, Vec3::Y, 0.036, 360, 240, rear)
    }

    #[test]
    fn sensor_rays_start_on_the_rotated_sensor_and_aim_at_the_rear_element() {
        let c = sensor_camera();
        let top_left = c.generate_ray(0, 0, Vec2::ZERO, Vec2::splat(0.5)).ray;
        // Row 0 images the top of the scene, so it lies at the bottom of the sensor; column 0 images the scene's
        // left (−right = +x looking down +z), so it lies at −x.
        assert!((top_left.origin - Vec3::new(-0.018, -0.012, 0.0)).length() < 1e-6, "{:?}", top_left.origin);
        assert!((top_left.at(0.05 / top_left.direction.z) - Vec3::new(0.0, 0.0, 0.05)).length() < 1e-6);
        for i in 0..64 {
            let u = Vec2::new((i % 8) as f32 / 8.0 + 0.01, (i / 8) as f32 / 8.0 + 0.02);
            let r = c.generate_ray(200, 90, Vec2::splat(0.5), u).ray;
            let p = r.at((0.05 - r.origin.z) / r.direction.z);
            assert!(p.truncate().length() <= 0.01 + 1e-6, "lands on the disc: {p:?}");
        }
    }

    #[test]
    fn sensor_weights_average_to_the_solid_angle_integral_of_the_rear_element() {
        // With unit radiance the pixel value is the irradiance from the disc, which for the centre of the sensor
        // is π sin²α with tan α = 10/50 (a disc seen on axis).
        let c = sensor_camera();
        let n = 64;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                // Pixel (180, 120) with zero jitter starts exactly at the sensor's centre.
                sum += c.generate_ray(180, 120, Vec2::ZERO, u).weight as f64;
            }
        }
        let estimate = sum / (n * n) as f64;
        let sin2 = 0.01f64.powi(2) / (0.01f64.powi(2) + 0.05f64.powi(2));
        let exact = std::f64::consts::PI * sin2;
        assert!((estimate / exact - 1.0).abs() < 2e-3, "{estimate} vs {exact}");
    }

    #[test]
    fn a_camera_ray_reversed_registers_on_its_own_pixel_and_light_from_outside_the_rear_element_does_not() {
        let c = sensor_camera();
        for (x, y) in [(0, 0), (359, 239), (200, 90), (17, 230)] {
            let r = c.generate_ray(x, y, Vec2::new(0.3, 0.7), Vec2::new(0.9, 0.2)).ray;
            let far = r.at(0.2);
            let (pixel, importance) = c.sensor_pixel(far, -r.direction, f32::INFINITY).expect("registers");
            assert_eq!(pixel, y * 360 + x);
            assert!((importance - 1.0 / (1e-4 * 1e-4)).abs() < 1e-3 / (1e-4 * 1e-4), "{importance}");
            assert_eq!(c.sensor_pixel(far, -r.direction, 0.1), None, "stopped before the sensor");
            assert_eq!(c.sensor_pixel(r.origin - r.direction * 0.1, r.direction, f32::INFINITY), None, "from behind");
        }
        // Aimed at the sensor's centre from well outside the rear element's disc.
        let from = Vec3::new(0.03, 0.0, 0.05);
        assert_eq!(c.sensor_pixel(from, (Vec3::ZERO - from).normalize(), f32::INFINITY), None);
    }

    #[test]
    fn sensor_pixel_angle_is_the_pitch_over_the_rear_element_distance() {
        let c = sensor_camera();
        assert!((c.pixel_angle() - 0.0001 / 0.05).abs() < 1e-7, "{}", c.pixel_angle());
    }
}
