//! Analytic surfaces: spheres, spherical lens surfaces with a circular aperture and flat annuli (aperture stops
//! and lens mounts), exact where facets would put ghosts and aberrations in the wrong place.

use super::ray::Ray;
use glam::Vec3;

/// A full sphere with outward normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
}

/// A rotationally symmetric optical surface: a spherical cap (or a flat disk) cut by a circular aperture.
///
/// The optical axis `axis` points in the direction light travels through the system; the surface's vertex is
/// the point where it crosses the axis; the signed `curvature_radius` puts the centre of curvature at
/// `vertex + curvature_radius · axis` (lens-design sign convention: positive means convex toward incoming
/// light); zero means flat. The normal faces the front (−axis) side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LensSurface {
    pub vertex: Vec3,
    pub axis: Vec3,
    pub curvature_radius: f32,
    pub aperture_radius: f32,
}

/// A flat ring: the points of the plane through `center` perpendicular to `axis` whose distance from `center`
/// lies in [`inner_radius`, `outer_radius`]. With an opaque material it is an aperture stop (the hole is the
/// opening) or a lens mount that keeps light from going around an element. The normal faces −axis, like a lens
/// surface's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Annulus {
    pub center: Vec3,
    pub axis: Vec3,
    pub inner_radius: f32,
    pub outer_radius: f32,
}

/// Any analytic primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Analytic {
    Sphere(Sphere),
    Lens(LensSurface),
    Annulus(Annulus),
}

/// Both roots of |o + t d − c|² = r² for unit d, in increasing order, computed without cancellation.
fn sphere_roots(ray: &Ray, center: Vec3, radius: f32) -> Option<(f32, f32)> {
    let oc = ray.origin - center;
    let b = oc.dot(ray.direction);
    // c = |oc|² − r², written as a product to keep precision when the origin lies on the sphere.
    let c = (oc.length() - radius) * (oc.length() + radius);
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (q, c / q) };
    Some((t0.min(t1), t0.max(t1)))
}

impl Analytic {
    /// The nearest intersection within (t_min, ray.t_max) and its unit geometric normal.
    pub fn intersect(&self, ray: &Ray, t_min: f32) -> Option<(f32, Vec3)> {
        match self {
            Analytic::Sphere(s) => {
                let (t0, t1) = sphere_roots(ray, s.center, s.radius)?;
                let t = if t0 > t_min { t0 } else { t1 };
                if t <= t_min || t >= ray.t_max {
                    return None;
                }
                // Normalised rather than divided by the radius: the root is off the sphere by rounding that grows
                // with the origin's distance squared, and a normal off unit length reflects rays into
                // directions off unit length, which every later intersection assumes.
                Some((t, (ray.at(t) - s.center).normalize()))
            }
            Analytic::Lens(l) => l.intersect(ray, t_min),
            Analytic::Annulus(a) => a.intersect(ray, t_min),
        }
    }

    /// Surface area (for diagnostics; analytic surfaces cannot emit).
    pub fn area(&self) -> f32 {
        match self {
            Analytic::Sphere(s) => 4.0 * std::f32::consts::PI * s.radius * s.radius,
            Analytic::Lens(l) => l.area(),
            Analytic::Annulus(a) => {
                std::f32::consts::PI * (a.outer_radius * a.outer_radius - a.inner_radius * a.inner_radius)
            }
        }
    }
}

impl Annulus {
    fn intersect(&self, ray: &Ray, t_min: f32) -> Option<(f32, Vec3)> {
        let denom = ray.direction.dot(self.axis);
        if denom == 0.0 {
            return None;
        }
        let t = (self.center - ray.origin).dot(self.axis) / denom;
        if t <= t_min || t >= ray.t_max {
            return None;
        }
        let r2 = (ray.at(t) - self.center).length_squared();
        if r2 < self.inner_radius * self.inner_radius || r2 > self.outer_radius * self.outer_radius {
            return None;
        }
        Some((t, -self.axis))
    }
}

impl LensSurface {
    /// Axial distance from the vertex to the plane of the aperture's rim (signed along `axis`): the sag of the
    /// cap at the aperture radius, zero for a flat surface.
    pub fn rim_sag(&self) -> f32 {
        let (r, h) = (self.curvature_radius, self.aperture_radius);
        if r == 0.0 {
            return 0.0;
        }
        r - r.signum() * (r * r - h * h).max(0.0).sqrt()
    }

    fn within_aperture(&self, p: Vec3) -> bool {
        let v = p - self.vertex;
        let along = v.dot(self.axis);
        (v - self.axis * along).length_squared() <= self.aperture_radius * self.aperture_radius
    }

    fn intersect(&self, ray: &Ray, t_min: f32) -> Option<(f32, Vec3)> {
        let front = -self.axis;
        if self.curvature_radius == 0.0 {
            let denom = ray.direction.dot(self.axis);
            if denom == 0.0 {
                return None;
            }
            let t = (self.vertex - ray.origin).dot(self.axis) / denom;
            if t <= t_min || t >= ray.t_max || !self.within_aperture(ray.at(t)) {
                return None;
            }
            return Some((t, front));
        }
        let r = self.curvature_radius;
        let center = self.vertex + self.axis * r;
        let (t0, t1) = sphere_roots(ray, center, r.abs())?;
        for t in [t0, t1] {
            if t <= t_min || t >= ray.t_max {
                continue;
            }
            let p = ray.at(t);
            // Only the cap on the vertex's side of the centre is part of the surface.
            if (p - center).dot(self.axis) * r >= 0.0 || !self.within_aperture(p) {
                continue;
            }
            // Normalised, not divided by |r|, for the reason the sphere's normal is.
            let n = (p - center).normalize();
            return Some((t, if n.dot(front) < 0.0 { -n } else { n }));
        }
        None
    }

    /// Area of the cap inside the aperture.
    pub fn area(&self) -> f32 {
        let h = self.aperture_radius;
        if self.curvature_radius == 0.0 {
            return std::f32::consts::PI * h * h;
        }
        let r = self.curvature_radius.abs();
        let sag = r - (r * r - h * h).max(0.0).sqrt();
        2.0 * std::f32::consts::PI * r * sag
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_hit_from_outside_and_inside_has_outward_normal() {
        let s = Analytic::Sphere(Sphere { center: Vec3::ZERO, radius: 1.0 });
        let (t, n) = s.intersect(&Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z), 1e-4).unwrap();
        assert!((t - 2.0).abs() < 1e-5 && (n + Vec3::Z).length() < 1e-5);
        let (t, n) = s.intersect(&Ray::new(Vec3::ZERO, Vec3::Z), 1e-4).unwrap();
        assert!((t - 1.0).abs() < 1e-5 && (n - Vec3::Z).length() < 1e-5);
    }

    #[test]
    fn lens_surface_normal_faces_the_front_for_both_curvature_signs() {
        for r in [0.5f32, -0.5, 0.0] {
            let l = Analytic::Lens(LensSurface {
                vertex: Vec3::ZERO,
                axis: Vec3::Z,
                curvature_radius: r,
                aperture_radius: 0.2,
            });
            let (t, n) = l.intersect(&Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z), 1e-4).unwrap();
            assert!((t - 1.0).abs() < 1e-4, "r = {r}: t = {t}");
            assert!((n + Vec3::Z).length() < 1e-4);
        }
    }

    #[test]
    fn lens_surface_misses_outside_its_aperture_and_the_far_cap() {
        let l = Analytic::Lens(LensSurface {
            vertex: Vec3::ZERO,
            axis: Vec3::Z,
            curvature_radius: 0.5,
            aperture_radius: 0.2,
        });
        assert!(l.intersect(&Ray::new(Vec3::new(0.3, 0.0, -1.0), Vec3::Z), 1e-4).is_none());
        // From inside the sphere toward the far side: only the far cap lies there, which is not the surface.
        assert!(l.intersect(&Ray::new(Vec3::new(0.0, 0.0, 0.5), Vec3::Z), 1e-4).is_none());
    }

    #[test]
    fn rim_sag_puts_the_rim_on_the_cap_for_both_curvature_signs() {
        for r in [0.5f32, -0.5] {
            let l = LensSurface { vertex: Vec3::ZERO, axis: Vec3::Z, curvature_radius: r, aperture_radius: 0.2 };
            let rim = Vec3::new(0.2, 0.0, l.rim_sag());
            let center = Vec3::Z * r;
            assert!(((rim - center).length() - 0.5).abs() < 1e-6, "r = {r}");
            assert!(l.rim_sag() * r > 0.0, "the rim lies on the centre's side of the vertex");
        }
    }

    #[test]
    fn annulus_blocks_the_ring_and_lets_the_hole_through() {
        let a = Analytic::Annulus(Annulus { center: Vec3::ZERO, axis: Vec3::Z, inner_radius: 0.1, outer_radius: 0.3 });
        let (t, n) = a.intersect(&Ray::new(Vec3::new(0.2, 0.0, -1.0), Vec3::Z), 1e-4).unwrap();
        assert!((t - 1.0).abs() < 1e-5 && (n + Vec3::Z).length() < 1e-6);
        assert!(a.intersect(&Ray::new(Vec3::new(0.05, 0.0, -1.0), Vec3::Z), 1e-4).is_none(), "the hole");
        assert!(a.intersect(&Ray::new(Vec3::new(0.4, 0.0, -1.0), Vec3::Z), 1e-4).is_none(), "outside");
        assert!((a.area() - std::f32::consts::PI * 0.08).abs() < 1e-6);
    }
}
