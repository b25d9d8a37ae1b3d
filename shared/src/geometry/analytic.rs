//! Analytic surfaces: spheres, spherical lens surfaces with a circular aperture and flat annuli (aperture stops
//! and lens mounts), exact where facets would put ghosts and aberrations in the wrong place.

use super::ray::Ray;
use glam::Vec3;

/// A full sphere with outward normals.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Annulus {
    pub center: Vec3,
    pub axis: Vec3,
    pub inner_radius: f32,
    pub outer_radius: f32,
}

/// Any analytic primitive.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
    // The discriminant b² − c is r² − |f|², f being the centre's offset from the ray's line. Written as b² − c
    // it loses the difference of two squares of the origin's distance: from 2 m, 25 µm of a lens surface's
    // roots, so that a refracted light path met the same surface again and crossed the lens in the wrong media.
    let f = oc - b * ray.direction;
    let disc = (radius - f.length()) * (radius + f.length());
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

    /// Surface area.
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

/// An axis-aligned box around an analytic surface, with what it takes to widen it to cover f32 rounding: the
/// points `Analytic::intersect` returns lie on the surface only up to an error that grows with the square of the
/// ray origin's distance from the sphere it solves (its quadratic cancels), so a fixed margin cannot cover every
/// ray, and a box that misses one of those points would change the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// The corners of the box that holds the exact surface.
    pub min: Vec3,
    pub max: Vec3,
    /// The point whose distance from a ray's origin sets the rounding error: the centre of the sphere solved, or
    /// of the plane's disc.
    pub anchor: Vec3,
    /// The error per unit of (distance from `anchor`)², 0 for flat surfaces.
    quadratic: f32,
    /// The error per unit of distance, and the error for an origin at the anchor (rounding of coordinates).
    linear: f32,
    constant: f32,
}

impl Bounds {
    /// How far outside the box a point `intersect` returns can lie, for a ray whose origin lies at most
    /// `distance` from `anchor`.
    #[inline]
    pub fn margin(&self, distance: f32) -> f32 {
        (self.quadratic * distance + self.linear) * distance + self.constant
    }

    /// The margin's coefficients of distance² and distance, and its constant.
    pub(super) fn margin_coefficients(&self) -> (f32, f32, f32) {
        (self.quadratic, self.linear, self.constant)
    }

    /// The smallest box holding both, whose margin bounds both margins.
    pub fn union(&self, other: &Bounds, distance_between_anchors: f32) -> Bounds {
        // Seen from `self.anchor`, the other's origin distance is at most one more `distance_between_anchors`.
        let d = distance_between_anchors;
        let quadratic = self.quadratic.max(other.quadratic);
        Bounds {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
            anchor: self.anchor,
            quadratic,
            linear: self.linear.max(other.linear + 2.0 * other.quadratic * d),
            constant: self.constant.max(other.margin(d)),
        }
    }
}

/// The box around a disc of radius `r` centred at `c` perpendicular to the unit vector `axis`.
fn disc_box(c: Vec3, axis: Vec3, r: f32) -> (Vec3, Vec3) {
    let half = (Vec3::ONE - axis * axis).max(Vec3::ZERO).powf(0.5) * r;
    (c - half, c + half)
}

/// Bounds on the rounding of `sphere_roots` and of the hit point (`Ray::at`), each a generous multiple of the
/// unit roundoff: the discriminant b² − c is off by about 12 u L² for an origin at distance L from the centre,
/// which moves a root off the sphere by about 6 u L² / R; coordinates round by u (|o| + |t|).
const QUADRATIC_ERROR: f32 = 32.0 * f32::EPSILON;
const LINEAR_ERROR: f32 = 32.0 * f32::EPSILON;

impl Analytic {
    /// The box that holds every point `intersect` can return, and its rounding margin.
    pub fn bounds(&self) -> Bounds {
        let flat = |c: Vec3, min: Vec3, max: Vec3, size: f32| Bounds {
            min,
            max,
            anchor: c,
            quadratic: 0.0,
            linear: LINEAR_ERROR,
            constant: LINEAR_ERROR * (c.abs().max_element() + size),
        };
        match self {
            Analytic::Sphere(s) => Bounds {
                min: s.center - Vec3::splat(s.radius),
                max: s.center + Vec3::splat(s.radius),
                anchor: s.center,
                quadratic: QUADRATIC_ERROR / s.radius,
                linear: LINEAR_ERROR,
                constant: LINEAR_ERROR * (s.center.abs().max_element() + s.radius),
            },
            Analytic::Annulus(a) => {
                let (min, max) = disc_box(a.center, a.axis, a.outer_radius);
                flat(a.center, min, max, a.outer_radius)
            }
            Analytic::Lens(l) if l.curvature_radius == 0.0 => {
                let (min, max) = disc_box(l.vertex, l.axis, l.aperture_radius);
                flat(l.vertex, min, max, l.aperture_radius)
            }
            Analytic::Lens(l) => {
                let (r, h) = (l.curvature_radius, l.aperture_radius);
                let center = l.vertex + l.axis * r;
                // The cap lies in the aperture's cylinder between the vertex plane and the rim plane. A point off
                // the sphere by e near the rim is off the rim plane by up to e / cos θ (θ the rim's angle from the
                // axis): that slope multiplies the margin, unless the rim is so steep that the centre's plane,
                // which the cap never crosses, bounds it better.
                let cos_rim = (r * r - h * h).max(0.0).sqrt() / r.abs();
                let (far, slope) = if cos_rim >= 0.125 { (l.rim_sag(), 1.0 / cos_rim) } else { (r, 1.0) };
                let (a0, a1) = disc_box(l.vertex, l.axis, h);
                let (b0, b1) = disc_box(l.vertex + l.axis * far, l.axis, h);
                let size = r.abs().max(h);
                Bounds {
                    min: a0.min(b0),
                    max: a1.max(b1),
                    anchor: center,
                    quadratic: slope * QUADRATIC_ERROR / r.abs(),
                    linear: slope * LINEAR_ERROR,
                    constant: slope * LINEAR_ERROR * (center.abs().max_element() + size),
                }
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
    fn a_lens_surface_hit_from_far_away_lies_on_it_and_the_refracted_ray_does_not_meet_it_again() {
        // The scene lens's front surface seen from its lamp, 2 m away: the root must lie on the sphere to well
        // below the origin offset, or the refracted ray starts outside the glass and meets the surface again.
        let lens =
            LensSurface { vertex: Vec3::ZERO, axis: -Vec3::Z, curvature_radius: 0.029475, aperture_radius: 0.0126 };
        let center = lens.vertex + lens.axis * lens.curvature_radius;
        let origin = Vec3::new(0.52, 0.33, 1.9);
        let mut worst = 0.0f32;
        for i in 0..2000 {
            let target = Vec3::new(0.012 * ((i % 50) as f32 / 25.0 - 1.0), 0.012 * ((i / 50) as f32 / 20.0 - 1.0), 0.0);
            let ray = Ray::new(origin, (target - origin).normalize());
            let Some((t, n)) = Analytic::Lens(lens).intersect(&ray, 1e-7) else { continue };
            let p = ray.at(t);
            worst = worst.max(((p - center).length() - lens.curvature_radius).abs());
            // Refracted into n = 1.67 glass, leaving the surface from the offset origin the integrators use.
            let d = ray.direction;
            let (eta, cos_i) = (1.0 / 1.67, -d.dot(n));
            let cos_t = (1.0 - eta * eta * (1.0 - cos_i * cos_i)).sqrt();
            let inside = (d * eta + n * (eta * cos_i - cos_t)).normalize();
            let next = Ray::new(crate::geometry::ray::offset_origin(p, n, inside), inside);
            assert!(Analytic::Lens(lens).intersect(&next, 1e-7).is_none(), "refracted ray meets the surface again");
        }
        assert!(worst < 1e-6, "a root lies {worst} m off the surface");
    }

    #[test]
    fn normals_are_unit_length_for_rays_from_far_away() {
        // The roots of a small sphere seen from 2 m are off it by about 0.1% of its radius.
        let lens =
            LensSurface { vertex: Vec3::ZERO, axis: -Vec3::Z, curvature_radius: 0.029475, aperture_radius: 0.0126 };
        let sphere = Sphere { center: Vec3::new(0.0, 0.0, -0.03), radius: 0.0126 };
        for i in 0..1000 {
            let target = Vec3::new(0.012 * ((i % 40) as f32 / 20.0 - 1.0), 0.012 * ((i / 40) as f32 / 12.5 - 1.0), 0.0);
            let origin = Vec3::new(0.46, 0.3, 1.85);
            let ray = Ray::new(origin, (target - origin).normalize());
            for a in [Analytic::Lens(lens), Analytic::Sphere(sphere)] {
                if let Some((_, n)) = a.intersect(&ray, 1e-7) {
                    assert!((n.length() - 1.0).abs() < 1e-6, "{a:?}: |n| = {} for {ray:?}", n.length());
                }
            }
        }
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
