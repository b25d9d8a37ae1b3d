//! A scene's surfaces as triangles, object by object: its meshes as they are, its analytic surfaces (spheres,
//! lens surfaces, annuli) tessellated finely enough to look smooth, for the pictures and files that show paths
//! with the geometry they met.

use glam::Vec3;
use photonfarm::geometry::analytic::{Analytic, Annulus, LensSurface, Sphere};
use photonfarm::scene::Scene;
use std::f32::consts::TAU;

/// Segments around a circle and rings from a lens surface's axis to its rim (or a sphere's pole to pole).
const AROUND: usize = 64;
const RINGS: usize = 16;

/// The triangles of every object, by object index.
pub fn object_triangles(scene: &Scene) -> Vec<Vec<[Vec3; 3]>> {
    let mut objects = vec![Vec::new(); scene.objects.len()];
    let g = &scene.geometry;
    for i in 0..g.triangle_count() as u32 {
        if let Some(list) = objects.get_mut(g.object_of_triangle(i) as usize) {
            list.push(g.triangle(i).v);
        }
    }
    for (object, surface) in g.analytic_surfaces() {
        if let Some(list) = objects.get_mut(*object as usize) {
            tessellate(surface, list);
        }
    }
    objects
}

/// Two unit vectors across `axis`, and `axis` with them a right-handed frame.
fn across(axis: Vec3) -> (Vec3, Vec3) {
    let u = axis.any_orthonormal_vector();
    (u, axis.cross(u))
}

/// Adds a surface's triangles: a grid of `rings` + 1 rings of `AROUND` points each, `point(ring, angle)`.
fn grid(out: &mut Vec<[Vec3; 3]>, rings: usize, point: impl Fn(usize, f32) -> Vec3) {
    for r in 0..rings {
        for k in 0..AROUND {
            let (a0, a1) = (TAU * k as f32 / AROUND as f32, TAU * (k + 1) as f32 / AROUND as f32);
            let (p00, p01, p10, p11) = (point(r, a0), point(r, a1), point(r + 1, a0), point(r + 1, a1));
            // Rings that shrink to a point (a cap's centre, a sphere's poles) give triangles of no area: skipped.
            for t in [[p00, p10, p11], [p00, p11, p01]] {
                if (t[1] - t[0]).cross(t[2] - t[0]).length_squared() > 0.0 {
                    out.push(t);
                }
            }
        }
    }
}

fn tessellate(surface: &Analytic, out: &mut Vec<[Vec3; 3]>) {
    match *surface {
        Analytic::Sphere(Sphere { center, radius }) => {
            grid(out, RINGS * 2, |r, a| {
                let theta = std::f32::consts::PI * r as f32 / (RINGS * 2) as f32;
                center + radius * Vec3::new(theta.sin() * a.cos(), theta.cos(), theta.sin() * a.sin())
            });
        }
        Analytic::Lens(LensSurface { vertex, axis, curvature_radius, aperture_radius }) => {
            let (u, v) = across(axis);
            let r = curvature_radius;
            grid(out, RINGS, |ring, a| {
                let rho = aperture_radius * ring as f32 / RINGS as f32;
                // The sag of the sphere through the vertex whose centre is at vertex + r · axis.
                let sag = if r == 0.0 { 0.0 } else { r - r.signum() * (r * r - rho * rho).max(0.0).sqrt() };
                vertex + axis * sag + (u * a.cos() + v * a.sin()) * rho
            });
        }
        Analytic::Annulus(Annulus { center, axis, inner_radius, outer_radius }) => {
            let (u, v) = across(axis);
            grid(out, 1, |ring, a| {
                let rho = if ring == 0 { inner_radius } else { outer_radius };
                center + (u * a.cos() + v * a.sin()) * rho
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lens_surface_is_tessellated_on_its_sphere_within_its_aperture() {
        let lens = LensSurface {
            vertex: Vec3::new(0.0, 0.0, 1.0),
            axis: Vec3::Z,
            curvature_radius: -0.05,
            aperture_radius: 0.02,
        };
        let mut t = Vec::new();
        tessellate(&Analytic::Lens(lens), &mut t);
        assert!(t.len() > AROUND * RINGS);
        let centre = lens.vertex + lens.axis * lens.curvature_radius;
        for p in t.iter().flatten() {
            assert!(((*p - centre).length() - 0.05).abs() < 1e-6, "{p} is off the sphere");
            assert!(p.truncate().length() <= 0.02 + 1e-6, "{p} is outside the aperture");
            // Concave toward the front: the rim lies before the vertex.
            assert!(p.z <= 1.0 + 1e-6);
        }
    }
}
